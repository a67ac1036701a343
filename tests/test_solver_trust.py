"""Trustworthy results: the range clamp, solvers without division by zero, unit independence, strict arguments."""

import functools
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sparsedepth as sd
from sparsedepth import Weights, build_objective, complete_depth

from conftest import make_problem

L1 = Weights.paper(alpha=1.0, beta=0.2, gamma=0.05, delta=0.01, kappa=5.0)
L1_SOLVERS = ["irls", "admm", "lbfgsb", "adam"]


def _outlier_frame(fraction=0.02, seed=0):
    """The shipped NYU frame (1.5-10 m) sampled at 2 %, one sample replaced by 65.535 m (uint16 mm maximum)."""
    frame = sd.load_embedded_frame()
    rng = np.random.default_rng(seed)
    mask = frame.valid & (rng.random(frame.shape) < fraction)
    sparse = np.where(mask, frame.depth, 0.0)
    ys, xs = np.nonzero(mask)
    sparse[ys[ys.size // 2], xs[ys.size // 2]] = 65.535
    return frame.image, sparse


def _quiet(fn, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kwargs)


# --------------------------------------------------------------------------------------------------
# 5. a dense map is dense and plausible
# --------------------------------------------------------------------------------------------------
def test_outlier_sample_leaves_no_zero_pixels_and_the_clamp_is_counted_and_warned():
    image, sparse = _outlier_frame()
    observed = sparse[sparse > 0]
    with pytest.warns(sd.ClampWarning, match="clamped"):
        res = complete_depth(image, sparse)
    assert res.depth_range == (observed.min(), observed.max())
    assert res.depth.min() >= observed.min() and res.depth.max() <= observed.max()
    assert np.count_nonzero(res.depth == 0) == 0
    # the same solve without the clamp: the clamp moved exactly the pixels outside the range, to its ends
    raw = _quiet(complete_depth, image, sparse, clip_to_observed=False)
    assert raw.depth_range == (0.0, np.inf)
    outside = (raw.depth < observed.min()) | (raw.depth > observed.max())
    assert outside.sum() > 0 and res.clamped == int(outside.sum())
    np.testing.assert_array_equal(res.depth, np.clip(raw.depth, observed.min(), observed.max()))
    # unclamped, the count is the pixels held at the bound 0
    assert raw.clamped == int(np.count_nonzero(raw.depth == 0))


def test_no_warning_when_nothing_is_clamped():
    image = np.full((12, 15, 3), 0.4)
    sparse = np.where(np.random.default_rng(1).random((12, 15)) < 0.2, 2.5, 0.0)
    sparse[0, 0] = 2.5
    with warnings.catch_warnings():
        warnings.simplefilter("error", sd.ClampWarning)
        res = complete_depth(image, sparse)
    assert res.clamped == 0
    np.testing.assert_allclose(res.depth, 2.5, rtol=1e-12)


def test_fill_holes_inherits_the_range_clamp():
    image, sparse = _outlier_frame()
    observed = sparse[sparse > 0]
    with pytest.warns(sd.ClampWarning):
        dense = sd.fill_holes(image, sparse, method="complete")
    assert dense.min() >= observed.min() and dense.max() <= observed.max()


# --------------------------------------------------------------------------------------------------
# 6. no division by zero, no false convergence, any unit
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("shape", [(1, 1), (1, 2), (2, 2)])
@pytest.mark.parametrize("solver", L1_SOLVERS)
def test_constant_input_with_zero_optimum_converges(shape, solver):
    image = np.full(shape + (3,), 0.5)
    res = complete_depth(image, np.full(shape, 2.0), weights=L1, solver=solver)
    assert res.converged, res.message
    np.testing.assert_allclose(res.depth, 2.0, rtol=1e-9)
    assert res.objective <= 1e-12


def test_an_all_zero_depth_marked_observed_is_refused_as_a_flipped_mask():
    shape = (5, 6)
    with pytest.raises(ValueError, match="pass ~mask"):
        complete_depth(np.full(shape + (3,), 0.5), np.zeros(shape), np.ones(shape, bool), weights=L1)


@pytest.mark.parametrize("solver", L1_SOLVERS)
def test_an_objective_with_zero_data_converges_to_zero(solver):
    """``F* = 0`` at ``z = 0``: every solver's relative tests have a floor there (the objective's own solve)."""
    shape = (5, 6)
    objective = sd.objective.Objective(shape, [
        sd.objective.QuadraticTerm("data", 1.0, None, None, np.zeros(30)),
        sd.objective.AbsTerm("edge", 0.1, sd.grid.gradient(shape), None)])
    out, _ = sd.solvers.solve(objective, np.zeros(30), solver=solver)
    assert out.converged, out.message
    assert np.all(out.z == 0) and objective.value(out.z) == 0


@pytest.mark.parametrize("solver", L1_SOLVERS)
def test_flat_wall_converges_well_before_max_iter(solver):
    rng = np.random.default_rng(0)
    sparse = np.where(rng.random((30, 40)) < 0.1, 2.5, 0.0)
    sparse[0, 0] = 2.5
    res = complete_depth(np.full((30, 40, 3), 0.5), sparse, weights=L1, solver=solver)
    assert res.converged, res.message
    assert res.iterations < sd.solvers.DEFAULT_MAX_ITER[solver] // 2
    np.testing.assert_allclose(res.depth, 2.5, rtol=1e-6)


def _reference(image, sparse, mask, weights):
    """A tight plain-ADMM run (no polish): the optimum to ~1e-9 relative in F."""
    return _quiet(complete_depth, image, sparse, mask, weights=weights, solver="admm", tol=1e-11, max_iter=50000,
                  options={"polish": False}, clip_to_observed=False)


@pytest.mark.parametrize("s", [1e6, 1e154, 1e-170])
def test_lbfgsb_in_large_and_tiny_units_reaches_the_optimum(s):
    image, sparse, mask, _ = make_problem((8, 10), fraction=0.2)
    ref = _reference(image, sparse, mask, L1)
    weights = L1.replace(gamma=L1.gamma * s)
    res = _quiet(complete_depth, image, sparse * s, mask, weights=weights, solver="lbfgsb", l1_smoothing=1e-4 * s,
                 clip_to_observed=False)
    assert res.converged, res.message
    obj, coarse, _ = build_objective(image, sparse, mask, weights=L1)
    assert np.max(np.abs(res.depth / s - coarse)) > 0.05  # not the nearest-neighbour start
    np.testing.assert_allclose(res.depth / s, ref.depth, rtol=0, atol=5e-3)
    # the smoothed objective's minimiser (eps = 1e-4 m) is within 1e-3 of the exact optimum in F
    assert obj.value(res.depth.ravel() / s) <= ref.objective * (1 + 1e-3)
    metres = _in_metres("lbfgsb", None, (8, 10), 0.2, 0)
    assert obj.value(res.depth.ravel() / s) == pytest.approx(metres.objective, rel=1e-6)  # (s² F overflows at 1e154)


def test_a_solver_stopping_at_a_non_optimal_start_is_not_converged():
    image, sparse, mask, _ = make_problem((16, 20))
    res = _quiet(complete_depth, image, sparse, mask, weights=L1, solver="lbfgsb", options={"gtol": 1e6})
    assert not res.converged and "projected gradient" in res.message


@pytest.mark.parametrize("solver", ["cg", "irls", "admm", "lbfgsb", "adam"])
def test_history_and_callback_are_in_user_units(solver):
    image, sparse, mask, _ = make_problem((12, 16))
    s = 1000.0  # not a power of two: the solver's units differ from the user's
    weights = L1.replace(gamma=L1.gamma * s) if solver != "cg" else Weights.paper(gamma=0.0)
    obj, _, _ = build_objective(image, sparse * s, mask, weights=weights)
    states = []
    res = _quiet(complete_depth, image, sparse * s, mask, weights=weights, solver=solver, max_iter=5,
                 callback=states.append, clip_to_observed=False)
    assert len(states) == len(res.history) >= 2
    for state, record in zip(states, res.history):
        assert state.objective == pytest.approx(record.objective, rel=1e-9)  # cg: the last entry re-evaluated
        assert state.objective == pytest.approx(obj.value(state.depth), rel=1e-9)
        assert np.median(state.depth) > 100  # metres x 1000
    assert res.objective == pytest.approx(obj.value(res.depth), rel=1e-12)


@functools.lru_cache(maxsize=None)
def _in_metres(solver, max_iter=None, shape=(6, 8), fraction=0.3, seed=3):
    """One run in metres per configuration, shared by the tests that scale it (read only)."""
    image, sparse, mask, _ = make_problem(shape, fraction=fraction, seed=seed)
    return _quiet(complete_depth, image, sparse, mask, weights=L1, solver=solver, max_iter=max_iter,
                  clip_to_observed=False)


def _scaled_pair(solver, s, *, max_iter=None, shape=(6, 8), seed=3):
    image, sparse, mask, _ = make_problem(shape, fraction=0.3, seed=seed)
    base = _in_metres(solver, max_iter, shape, 0.3, seed)
    scaled = _quiet(complete_depth, image, sparse * s, mask, weights=L1.replace(gamma=L1.gamma * s), solver=solver,
                    max_iter=max_iter, l1_smoothing=1e-4 * s, clip_to_observed=False)
    return base, scaled


@settings(max_examples=4, derandomize=True, deadline=None)
@given(exponent=st.integers(min_value=-19, max_value=9))
@pytest.mark.parametrize("solver", L1_SOLVERS)
def test_powers_of_two_units_give_the_same_answer_exactly(solver, exponent):
    """s = 2^k from 2e-6 to 512: the normalised problems are the same numbers, so every solver follows the same path
    (whether it has converged or not: at most 40 iterations here) and agrees to rounding."""
    s = 2.0 ** exponent
    base, scaled = _scaled_pair(solver, s, max_iter=40)
    np.testing.assert_allclose(scaled.depth / s, base.depth, rtol=1e-12, atol=0)
    assert scaled.converged == base.converged


@settings(max_examples=6, derandomize=True, deadline=None)
@given(s=st.floats(min_value=1e-6, max_value=1e3))
@pytest.mark.parametrize("solver", ["irls", "admm"])
def test_any_unit_gives_the_same_answer(solver, s):
    """Completing s * depth (with gamma * s) gives s * result to 1e-6 for any s."""
    base, scaled = _scaled_pair(solver, s)
    assert scaled.converged and base.converged
    np.testing.assert_allclose(scaled.depth / s, base.depth, rtol=1e-6, atol=0)


@pytest.mark.parametrize("solver,rel", [("lbfgsb", 1e-6), ("adam", 1e-3)])
@pytest.mark.parametrize("s", [1e-6, 1e3])
def test_any_unit_gives_the_same_objective_with_the_gradient_solvers(solver, rel, s):
    """L-BFGS-B and Adam stop at a point that moves with rounding-level changes of the input by up to their accuracy
    (1e-5 and 5e-3 in depth here), so for s that is not a power of two their objective must agree instead."""
    base, scaled = _scaled_pair(solver, s)
    assert scaled.converged and base.converged
    assert scaled.objective / (s * s) == pytest.approx(base.objective, rel=rel)


def test_l1_solvers_reach_the_reference_optimum():
    image, sparse, mask, _ = make_problem((8, 10), fraction=0.2, seed=3)
    ref = _reference(image, sparse, mask, L1)
    # IRLS stalls about 1e-6 above the optimum; L-BFGS-B and Adam minimise the objective smoothed with eps = 1e-4
    for solver, rel in (("irls", 5e-6), ("admm", 1e-9), ("lbfgsb", 3e-4), ("adam", 3e-3)):
        res = _quiet(complete_depth, image, sparse, mask, weights=L1, solver=solver, clip_to_observed=False)
        assert res.converged, (solver, res.message)
        assert res.objective == pytest.approx(ref.objective, rel=rel), solver
        assert res.objective >= ref.objective * (1 - 1e-9), solver


# --------------------------------------------------------------------------------------------------
# 7. strict arguments
# --------------------------------------------------------------------------------------------------
@pytest.fixture
def problem():
    image, sparse, mask, _ = make_problem((10, 12))
    return image, sparse, mask


@pytest.mark.parametrize("solver,key", [("admm", "tolerance"), ("admm", "rh0"), ("irls", "rho"), ("amg", "gtol"),
                                        ("direct", "preconditioner")])
def test_unknown_option_names_the_key_and_the_valid_ones(problem, solver, key):
    image, sparse, mask = problem
    weights = L1 if solver in L1_SOLVERS else Weights.paper(gamma=0.0)
    with pytest.raises(ValueError, match=rf"unknown option '{key}' for solver '{solver}'") as info:
        complete_depth(image, sparse, mask, weights=weights, solver=solver, options={key: 1e-3})
    for valid in sd.SOLVER_OPTIONS[solver]:
        assert valid in str(info.value)


def test_unknown_option_rejected_by_solve_too(problem):
    image, sparse, mask = problem
    obj, coarse, _ = build_objective(image, sparse, mask, weights=L1)
    with pytest.raises(ValueError, match="unknown option 'rh0'"):
        sd.solvers.solve(obj, coarse.ravel(), solver="admm", options={"rh0": 1.0})


@pytest.mark.parametrize("kwargs,match", [
    (dict(max_iter=2.5), r"max_iter must be an int; got float 2.5: pass e.g. max_iter=2"),
    (dict(max_iter=True), r"max_iter must be an int; got bool"),
    (dict(tol="x"), r"tol must be a number; got str"),
    (dict(options=[("rho", 1.0)]), r"options must be a dict; got list"),
    (dict(options={"rho": "big"}), r"options\['rho'\] of solver 'admm' must be a number; got str"),
    (dict(options={"polish": 1}), r"options\['polish'\] of solver 'admm' must be True or False; got int"),
    (dict(options={"check_every": 2.0}), r"options\['check_every'\] of solver 'admm' must be an int; got float"),
    (dict(weights={"gamma": 0.1}), r"weights must be a sparsedepth.Weights \(or a sparsedepth.DensitySchedule.*\); got dict: use sd.Weights\(\*\*d\)"),
    (dict(clip_to_observed="yes"), r"clip_to_observed must be True or False; got str"),
])
def test_wrong_types_raise_type_error_with_the_fix(problem, kwargs, match):
    image, sparse, mask = problem
    kwargs = {"weights": L1, "solver": "admm", **kwargs}
    with pytest.raises(TypeError, match=match):
        complete_depth(image, sparse, mask, **kwargs)


@pytest.mark.parametrize("options,match", [
    ({"preconditioner": "ilu"}, r"options\['preconditioner'\] of solver 'admm' must be one of \['grid', 'amg'\]"),
    ({"rho": -1.0}, r"options\['rho'\] of solver 'admm' must be finite and > 0"),
    ({"polish_rounds": 0}, r"options\['polish_rounds'\] of solver 'admm' must be >= 1"),
])
def test_option_values_out_of_range(problem, options, match):
    image, sparse, mask = problem
    with pytest.raises(ValueError, match=match):
        complete_depth(image, sparse, mask, weights=L1, solver="admm", options=options)


def test_numpy_integers_and_given_options_are_accepted(problem):
    image, sparse, mask = problem
    res = _quiet(complete_depth, image, sparse, mask, weights=L1, solver="admm", max_iter=np.int64(3), tol=np.float32(1e-3),
                 options={"rho": 2, "polish": np.bool_(False)})
    assert res.iterations <= 3


def test_negative_depth_without_mask_is_rejected(problem):
    image, sparse, _ = problem
    bad = np.nan_to_num(sparse, nan=0.0)
    bad[3, 4] = -1.0
    with pytest.raises(ValueError, match=r"sparse_depth has 1 negative values \(min -1\) and no mask.*0 or NaN"):
        complete_depth(image, bad)


# --------------------------------------------------------------------------------------------------
# 8. IRLS's plain reweighting never increases the exact objective
# --------------------------------------------------------------------------------------------------
@settings(max_examples=25, derandomize=True, deadline=None)
@given(seed=st.integers(0, 10_000), height=st.integers(2, 9), width=st.integers(2, 9),
       gamma=st.floats(1e-3, 1.0), beta=st.floats(0.0, 1.0), fraction=st.floats(0.05, 0.6))
def test_irls_never_increases_the_exact_objective(seed, height, width, gamma, beta, fraction):
    image, sparse, mask, _ = make_problem((height, width), fraction=fraction, seed=seed)
    weights = Weights.paper(alpha=1.0, beta=beta, gamma=gamma, delta=0.01, kappa=5.0)
    obj, _, _ = build_objective(image, sparse, mask, weights=weights)
    values = []
    res = _quiet(complete_depth, image, sparse, mask, weights=weights, solver="irls", max_iter=40,
                 callback=lambda state: values.append(obj.value(state.depth)), clip_to_observed=False,
                 options={"method": "reweighting"})
    values = np.array(values)
    # exact F recomputed independently from each iterate; allow only evaluation rounding
    assert np.all(np.diff(values) <= 1e-12 * values[:-1]), np.diff(values).max()
    np.testing.assert_allclose(res.history_array("objective"), values, rtol=1e-12)
