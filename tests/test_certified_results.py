"""The numbers on a result are true of the depth it returns: ``gap``, ``solver_gap``, ``gap_proven``, ``converged``.

Every bound is checked against an independent minimum of the objective over the clamp range: SciPy's SLSQP on the
split form of the problem (small grids), or L-BFGS-B with bounds for the quadratic one.
"""

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import minimize

import sparsedepth as sd
from sparsedepth.objective.l1 import StackedL1
from sparsedepth.objective.objective import build_objective
from sparsedepth.solvers.options import DEFAULT_GAP_TOL

L1_SOLVERS = ["irls", "admm", "lbfgsb", "adam"]
#: Shorter runs of the gradient solvers on the few pixels of these scenes, converged all the same: Adam's cosine
#: schedule over 200 steps (it ends at the gap of its default horizon), L-BFGS-B to tol 1e-6.
SOLVER_ARGS = {"adam": {"options": {"horizon": 200}}, "lbfgsb": {"tol": 1e-6}}
#: The default model with the edge-aware L1 term: its second-order terms overshoot the samples at a depth step.
L1_WEIGHTS = sd.default_weights(0.3).replace(gamma=0.05)


def _step_scene(shape=(4, 5), seed=0):
    """A depth step with an image edge beside it and a few samples: its completion overshoots the samples' range."""
    rng = np.random.default_rng(seed)
    h, w = shape
    image = np.full(shape + (3,), 0.2)
    image[:, w // 2:] = 0.8
    truth = np.where(np.arange(w)[None, :] < w // 2 + 1, 1.0, 3.0) * np.ones((h, 1))
    mask = rng.random(shape) < 0.35
    mask[0, 0] = mask[-1, -1] = True
    sparse = np.where(mask, truth, 0.0)
    return image, sparse, mask


def _quiet(function, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        return function(*args, **kwargs)


def _box_minimum(objective, low, high):
    """``min F`` over ``low <= z <= high``: SLSQP on ``zᵀAz − 2bᵀz + c + Σ w (u + v)`` with ``Kz = u − v``."""
    A, b, c = objective.normal_equations()
    A = sp.csr_matrix(A)
    n = objective.size
    if objective.has_l1:
        l1 = StackedL1(objective)
        K, w = sp.csr_matrix(l1.matrix), np.asarray(l1.weights, dtype=float)
    else:
        K, w = sp.csr_matrix((0, n)), np.zeros(0)
    m = K.shape[0]

    def f(x):
        z, u, v = x[:n], x[n:n + m], x[n + m:]
        return float(z @ (A @ z) - 2 * b @ z + c + w @ (u + v))

    def grad(x):
        z = x[:n]
        return np.concatenate([2 * (A @ z) - 2 * b, w, w])

    Kd = K.toarray()
    constraint = {"type": "eq", "fun": lambda x: K @ x[:n] - x[n:n + m] + x[n + m:],
                  "jac": lambda x: np.hstack([Kd, -np.eye(m), np.eye(m)])}
    z0 = np.clip(sp.linalg.spsolve(A.tocsc(), b), low, high)
    t0 = K @ z0
    x0 = np.concatenate([z0, np.maximum(t0, 0), np.maximum(-t0, 0)])
    bounds = [(low, high)] * n + [(0, None)] * (2 * m)
    best = minimize(f, x0, jac=grad, bounds=bounds, constraints=[constraint] if m else [], method="SLSQP",
                    options={"ftol": 1e-15, "maxiter": 2000})
    # the exact F of the clipped z is an upper bound on the minimum: use the smaller of the two numbers
    z = np.clip(best.x[:n], low, high)
    return min(objective.value(z), best.fun)


@pytest.mark.parametrize("solver", L1_SOLVERS)
def test_gap_bounds_the_clamped_depth_that_is_returned(solver):
    image, sparse, mask = _step_scene()
    weights = L1_WEIGHTS
    result = _quiet(sd.complete_depth, image, sparse, mask, weights=weights, solver=solver,
                    **SOLVER_ARGS.get(solver, {}))
    assert result.clamped > 0  # the scene exercises the clamp
    objective, _, _ = build_objective(image, sparse, mask, weights=weights)
    F = objective.value(result.depth)
    assert F == pytest.approx(result.objective, rel=1e-9)
    low, high = result.depth_range
    F_star = _box_minimum(objective, low, high)
    # gap is an upper bound on F(returned) − min over the range (SLSQP's own accuracy: 1e-9 F)
    assert F - F_star <= result.gap + 1e-9 * F
    if result.converged:
        assert result.gap <= DEFAULT_GAP_TOL * F


def test_a_clamp_that_moves_pixels_is_certified_for_the_depth_returned():
    """The solver's point overshoots; the clamped depth gets its own bound, the solver's is kept beside it."""
    image, sparse, mask = _step_scene()
    weights = L1_WEIGHTS
    free = _quiet(sd.complete_depth, image, sparse, mask, weights=weights, solver="admm", clip_to_observed=False)
    low, high = float(sparse[mask].min()), float(sparse[mask].max())
    assert np.any((free.depth < low - 1e-9) | (free.depth > high + 1e-9))  # the scene exercises the clamp
    result = _quiet(sd.complete_depth, image, sparse, mask, weights=weights, solver="admm")
    assert result.clamped > 0
    objective, _, _ = build_objective(image, sparse, mask, weights=weights)
    F = objective.value(result.depth)
    assert F - _box_minimum(objective, low, high) <= result.gap + 1e-9 * F
    # the solver's own bound is that of its unclamped point over z >= 0
    F_free = objective.value(free.depth)
    assert F_free - _box_minimum(objective, 0.0, np.inf) <= result.solver_gap + 1e-9 * F_free
    assert "moved" in result.message


def test_the_quadratic_default_reports_a_bound_that_is_a_bound_and_names_its_stopping_rule():
    """γ = 0, the depth rule: gap >= the true F(returned) − F* in the range, and not needlessly above gap_tol · F."""
    frame = sd.load_motorcycle()
    image, truth = frame.image[::8, ::8], frame.depth[::8, ::8]
    sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=0)
    result = _quiet(sd.complete_depth, image, sparse, mask)
    assert result.solver == "amg" and "estimated remaining change" in result.message
    objective, _, _ = build_objective(image, sparse, mask, weights=result.weights)
    A, b, c = objective.normal_equations()
    low, high = result.depth_range

    def f(z):
        return float(z @ (A @ z) - 2 * b @ z + c)

    best = minimize(f, np.clip(result.depth.ravel(), low, high), jac=lambda z: 2 * (A @ z) - 2 * b,
                    bounds=[(low, high)] * objective.size, method="L-BFGS-B",
                    options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 20000})
    F = objective.value(result.depth)
    true_gap = F - best.fun
    assert true_gap <= result.gap + 1e-10 * F
    assert result.gap <= max(10 * true_gap, DEFAULT_GAP_TOL * F)
    assert result.gap_proven


def test_every_solver_has_the_same_default_gap_tol():
    defaults = {name: options["gap_tol"] for name, options in sd.SOLVER_OPTIONS.items()}
    assert set(defaults.values()) == {DEFAULT_GAP_TOL}, defaults


@pytest.mark.parametrize("solver", L1_SOLVERS)
def test_converged_means_the_gap_passed_gap_tol(solver):
    image, sparse, mask = _step_scene((5, 6), seed=1)
    weights = L1_WEIGHTS
    result = _quiet(sd.complete_depth, image, sparse, mask, weights=weights, solver=solver,
                    **SOLVER_ARGS.get(solver, {}))
    floor = 1e-7 * build_objective(image, sparse, mask, weights=weights)[0].constant()
    if result.converged:
        assert result.gap <= DEFAULT_GAP_TOL * max(result.objective, floor)
    starved = _quiet(sd.complete_depth, image, sparse, mask, weights=weights, solver=solver, max_iter=1)
    if starved.gap > DEFAULT_GAP_TOL * max(starved.objective, floor):
        assert not starved.converged, starved.message


def test_adam_with_a_loose_tol_is_not_converged_above_gap_tol():
    """Adam's own stop at tol=1e-2 ends between a 1 % and a 10 % gap here: converged is then False."""
    image, sparse, mask = _step_scene((6, 7), seed=2)
    weights = L1_WEIGHTS
    result = _quiet(sd.complete_depth, image, sparse, mask, weights=weights, solver="adam", tol=1e-2,
                    options={"horizon": 100})
    assert DEFAULT_GAP_TOL * result.objective < result.gap < 0.1 * result.objective
    assert not result.converged and "NOT converged" in result.message


def test_without_the_prior_term_the_gap_is_marked_an_estimate():
    image, sparse, mask = _step_scene()
    result = _quiet(sd.complete_depth, image, sparse, mask, weights=sd.Weights.paper(gamma=0.0, delta=0.0),
                    solver="amg")
    assert not result.gap_proven
    assert "an estimate, not a proven bound" in result.message
    proven = _quiet(sd.complete_depth, image, sparse, mask, weights=sd.Weights.paper(gamma=0.0), solver="amg")
    assert proven.gap_proven and "an estimate, not a proven bound" not in proven.message


def test_with_a_prior_the_gap_is_that_of_the_returned_depth():
    """The residual problem is certified at the residual of the depth returned (clamped per pixel)."""
    image, sparse, mask = _step_scene((8, 9), seed=4)
    prior = np.linspace(0.5, 4.0, 72).reshape(8, 9)
    result = _quiet(sd.complete_depth, image, sparse, mask, prior=prior, prior_alignment="none")
    low, high = result.depth_range
    assert np.all((result.depth >= low) & (result.depth <= high))
    assert np.isfinite(result.gap) and result.gap >= 0
    if result.converged:
        assert result.gap <= DEFAULT_GAP_TOL * result.objective


# ----------------------------------------------------------------------------- quiet when all is well
def test_the_readme_example_and_an_ordinary_overshoot_emit_no_warning():
    frame = sd.load_motorcycle()
    image, truth = frame.image[::4, ::4], frame.depth[::4, ::4]
    sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = sd.complete_depth(image, sparse, mask)
    assert 0 < result.clamped < sd.completion.CLAMP_WARNING_SHARE * result.depth.size


def test_an_outlier_sample_is_warned_about_once():
    image, sparse, mask = _step_scene((20, 24), seed=5)
    sparse = sparse.copy()
    sparse[mask.nonzero()[0][3], mask.nonzero()[1][3]] = 65.5  # a 65.5 m reading in a 1-3 m scene
    with pytest.warns(sd.ClampWarning) as record:
        sd.complete_depth(image, sparse, mask)
    assert len([r for r in record if "far outside the other observations" in str(r.message)]) == 1


def test_range_outliers_rule():
    room = np.concatenate([np.linspace(1.0, 4.0, 500), [65.5]])
    assert sd.completion.range_outliers(room) == 1
    lidar = np.concatenate([np.linspace(5.0, 85.0, 500), [100.0]])
    assert sd.completion.range_outliers(lidar) == 0
    assert sd.completion.range_outliers(np.linspace(1.0, 4.0, 500)) == 0


def test_a_sizeable_clamp_is_warned_about():
    """Many pixels beyond the samples' range: the second-order term alone overshoots on both sides of a step."""
    image, sparse, mask = _step_scene((6, 7))
    weights = sd.Weights.paper(gamma=0.0, beta=0.0).replace(beta_second=1.0)
    with pytest.warns(sd.ClampWarning, match=r"pixels \(\d+\.\d%\) were outside the depth range"):
        result = sd.complete_depth(image, sparse, mask, weights=weights)
    assert result.clamped >= sd.completion.CLAMP_WARNING_SHARE * result.depth.size


def test_the_json_report_carries_the_certificate_of_the_depth_written(tmp_path):
    import json

    import imageio.v3 as iio

    from sparsedepth.complete import main

    image, sparse, mask = _step_scene((20, 24), seed=6)
    iio.imwrite(tmp_path / "rgb.png", (image * 255).astype(np.uint8))
    np.save(tmp_path / "sparse.npy", np.where(mask, sparse, np.nan))
    assert main(["--image", str(tmp_path / "rgb.png"), "--depth", str(tmp_path / "sparse.npy"),
                 "--out", str(tmp_path / "dense.npy"), "--json", str(tmp_path / "r.json")]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    expected = _quiet(sd.complete_depth, iio.imread(tmp_path / "rgb.png"), np.where(mask, sparse, np.nan))
    assert report["gap"] == pytest.approx(expected.gap, rel=1e-6)
    assert report["solver_gap"] == pytest.approx(expected.solver_gap, rel=1e-6)
    assert report["gap_proven"] is True and report["converged"] == expected.converged
