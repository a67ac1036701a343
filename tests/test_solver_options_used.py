"""Every solver option earns its place: each is read by its solver (or by the front door's certificate test) in at
least one run below.  An option no code reads fails here."""

import dataclasses
import sys
import warnings

import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.solvers.registry import REGISTRY

#: Runs per solver that together reach every option: (options, weights to solve with).
RUNS = {
    "direct": [{}],
    "cg": [{}, {"depth_rtol": 1e-3}, {"depth_atol": 1e-3}],
    "amg": [{}, {"depth_rtol": 1e-3, "preconditioner": "amg"}, {"depth_atol": 1e-3}],
    "irls": [{}, {"method": "reweighting", "inner_max_iter": 20, "eps_start": 1e-2, "eps_min": 1e-5, "scale": 2.0},
             {"finish": "none", "tie_band": 1e-3, "certify_below": 1e-2, "newton_rtol": 0.1, "newton_max_inner": 5,
              "newton_tol": 1e-2, "level_steps": 3, "preconditioner": "amg"}],
    "admm": [{}, {"inner_max_iter": 3, "inner_rtol": 1e-8, "inner_factor": 0.5, "adapt_iters": 10, "rho": 1.0,
                  "restart_from_polish": True, "polish_preconditioner": "amg", "preconditioner": "amg"},
             {"polish": False}, {"warm_start": "coarse", "coarse_above": 50, "coarse_gap_tol": 1e-3}],
    "lbfgsb": [{"maxfun": 200, "gtol": 1e-10, "maxcor": 5}],
    "adam": [{"schedule": "cosine", "horizon": 30, "record_every": 2},
             {"schedule": "inverse_sqrt", "decay_steps": 50.0, "learning_rate": 0.01, "beta1": 0.8, "beta2": 0.99,
              "window": 10}],
}


def _scene():
    rng = np.random.default_rng(0)
    h, w = 14, 16
    image = np.full((h, w, 3), 0.2)
    image[:, w // 2:] = 0.8
    truth = np.where(np.arange(w)[None, :] < w // 2 + 1, 1.0, 3.0) * np.ones((h, 1))
    sparse, mask = sd.sample_depth(truth + 0.05 * rng.random((h, w)), fraction=0.2, seed=0)
    return image, sparse, mask


def _spy(cls, reads):
    """A subclass of the options class ``cls`` that records every field read outside ``solvers/options.py``."""
    fields = {f.name for f in dataclasses.fields(cls)}

    class Spy(cls):
        def __getattribute__(self, name):
            if name in fields and not sys._getframe(1).f_code.co_filename.endswith("options.py"):
                reads.add(name)
            return super().__getattribute__(name)

    Spy.__name__ = cls.__name__
    return Spy


@pytest.mark.parametrize("solver", sorted(REGISTRY))
def test_every_option_is_read(solver, monkeypatch):
    image, sparse, mask = _scene()
    entry = REGISTRY[solver]
    weights = sd.default_weights(0.2) if entry.quadratic else sd.default_weights(0.2).replace(gamma=0.05)
    reads = set()
    monkeypatch.setitem(REGISTRY, solver, dataclasses.replace(entry, options=_spy(entry.options, reads)))
    for options in RUNS[solver]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sd.ClampWarning)
            result = sd.complete_depth(image, sparse, mask, weights=weights, solver=solver, options=options,
                                       max_iter=None if solver not in ("adam", "lbfgsb") else 200)
        assert np.all(np.isfinite(result.depth))
    unread = {f.name for f in dataclasses.fields(entry.options)} - reads
    assert not unread, f"options of {solver!r} that no run read: {sorted(unread)}"
