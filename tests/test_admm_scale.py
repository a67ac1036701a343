"""ADMM on larger grids: the penalty that grows with the side length, and the optimum it still reaches."""

import numpy as np
import pytest

from sparsedepth import Weights, build_objective, complete_depth
from sparsedepth.solvers import admm

from conftest import make_problem
from test_l1 import _kkt_gap_bound

L1 = Weights.paper(alpha=1.0, beta=0.2, gamma=0.05, delta=0.01, kappa=5.0)


def _rho_in(message):
    """The ``rho = ...`` the ADMM message reports."""
    return float(message.split("rho = ")[1].split(")")[0])


@pytest.mark.parametrize("reference_over_n, factor", [(1.0, 1.0), (4.0, 1.0), (0.25, 2.0), (1 / 9, 3.0)])
def test_default_rho_grows_with_the_side_length_above_the_reference(monkeypatch, reference_over_n, factor):
    image, sparse, mask, _ = make_problem((24, 30))
    obj, _, _ = build_objective(image, sparse, mask, weights=L1)
    monkeypatch.setattr(admm, "RHO_REFERENCE_PIXELS", obj.size * reference_over_n)
    for max_weight, depth_scale in ((0.0, 1.0), (0.05, 1.0), (1e-4, 3.0)):
        # 1.5 max(alpha, 300 c / s) written out, alpha = 1 here, times the side-length factor
        expected = 1.5 * max(1.0, 300.0 * max_weight / depth_scale) * factor
        assert admm.default_rho(obj, max_weight, depth_scale) == pytest.approx(expected, rel=1e-12)


def test_admm_with_the_grid_scaled_rho_reaches_the_certified_optimum(monkeypatch):
    """ρ four times the 640x480 rule (as on a frame 4x per side): the same optimum, by an independent bound."""
    image, sparse, mask, _ = make_problem((24, 30))
    obj, _, _ = build_objective(image, sparse, mask, weights=L1)
    base = complete_depth(image, sparse, mask, weights=L1, solver="admm")
    monkeypatch.setattr(admm, "RHO_REFERENCE_PIXELS", obj.size / 16.0)
    scaled = complete_depth(image, sparse, mask, weights=L1, solver="admm")
    assert base.converged and scaled.converged, (base.message, scaled.message)
    assert _rho_in(scaled.message) == pytest.approx(4.0 * _rho_in(base.message), rel=1e-2)
    assert scaled.depth.min() > 0  # the bound ignores z >= 0, valid as no bound is active
    bound = _kkt_gap_bound(obj, scaled.depth.ravel())
    assert bound <= 1e-7 * scaled.objective, (bound, scaled.message)
    assert scaled.objective == pytest.approx(base.objective, rel=1e-6)
    np.testing.assert_allclose(scaled.depth, base.depth, atol=1e-3 * float(np.median(base.depth)))
