"""The depth stopping rule of the quadratic solvers (options depth_rtol / depth_atol, RemainingChange, pcg's stop hook).

Every check is against a direct sparse solve (spsolve) or hand-computed numbers; no iteration count is asserted.
"""

import math
import re

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import sparsedepth as sd
from sparsedepth.problem import CompletionProblem
from sparsedepth.linalg import pcg, pcg_info
from sparsedepth.linalg.preconditioners import make_preconditioner
from sparsedepth.solvers import check_solver_arguments, depth_unit
from sparsedepth.solvers.options import DEFAULT_GAP_TOL, AmgOptions, CgOptions
from sparsedepth.solvers.quadratic import DEFAULT_DEPTH_RTOL, RemainingChange

from conftest import make_problem

#: Stated factor: at the stop, the true RMS remaining change is at most K times the depth tolerance
K = 3.0


def _rms(v):
    return float(np.sqrt(np.mean(np.square(v))))


def _exact(image, sparse, mask, weights=None):
    """The unclamped minimiser in the user's units, by a direct sparse solve (independent of CG); ``weights=None``:
    the library's default weights for the mask's observed fraction, as ``complete_depth`` picks them."""
    weights = sd.resolve_weights(weights, sd.observed_fraction(np.asarray(mask)))
    problem = CompletionProblem(image, sparse, mask, weights=weights, l1_smoothing=1e-6, clip_to_observed=False)
    obj, scale = problem.objective, problem.scale
    A, b, _ = obj.normal_equations()
    return spla.spsolve(sp.csc_matrix(A), b).reshape(obj.shape) * scale, scale


# ----------------------------------------------------------------------------- the estimator on hand-made steps
def test_remaining_change_is_the_geometric_tail_of_the_steps():
    n = 4
    rule = RemainingChange(n, tol=1e-3, window=3)
    direction = np.full(n, 2.0)  # ‖d‖₂ / √N = 2
    steps = [0.5, 0.25, 0.125, 0.0625, 0.03125]  # RMS steps 1, 0.5, ... : rate 1/2
    met = [rule(s, direction) for s in steps]
    assert rule.steps == pytest.approx([1.0, 0.5, 0.25, 0.125, 0.0625])
    # the tail Σ_{j>k} s_j of a geometric series of rate ρ is s_k ρ / (1 − ρ) = s_k here
    assert rule.estimate == pytest.approx(0.0625)
    assert not any(met)
    # a sudden small step (ratio 0.0032): the rate is the window's largest, still 1/2, so the tail is the step
    assert rule(0.0001, direction) is True
    assert rule.estimate == pytest.approx(0.0002)


def test_remaining_change_has_no_estimate_before_the_window_or_without_contraction():
    rule = RemainingChange(1, tol=10.0, window=3)
    d = np.ones(1)
    for s in (1.0, 0.5, 0.25):
        assert rule(s, d) is False and rule.estimate == math.inf
    assert rule(0.125, d) is True and rule.estimate == pytest.approx(0.125)
    growing = RemainingChange(1, tol=10.0, window=2)
    for s in (1.0, 0.5, 0.49, 0.48):  # rate 0.98 > max_rate 0.95: no estimate
        growing(s, d)
    assert growing.estimate == math.inf
    exact = RemainingChange(1, tol=0.0)
    assert exact(0.0, d) is True and exact.estimate == 0.0  # a zero step: CG is at the solution


# ----------------------------------------------------------------------------- the hook of pcg
def test_pcg_stop_hook_sees_every_step_and_ends_the_solve():
    n = 15
    d = sp.diags([-np.ones(n), np.r_[np.ones(n - 1), 0.0]], [0, 1])
    A = (sp.kron(sp.eye(n), d.T @ d) + sp.kron(d.T @ d, sp.eye(n)) + 0.05 * sp.eye(n * n)).tocsr()
    b = np.random.default_rng(0).standard_normal(n * n)
    x0 = np.random.default_rng(1).standard_normal(n * n)
    moved = np.zeros(n * n)
    calls = []

    def stop(step, direction):
        moved[:] += step * direction
        calls.append(step)
        return len(calls) == 7

    result = pcg_info(A, b, x0=x0, rtol=1e-14, stop=stop)
    assert result.rule_met and not result.stopped and result.message == "stopping rule met"
    assert result.iterations == len(calls)
    np.testing.assert_allclose(x0 + moved, result.x, rtol=0, atol=1e-12 * np.abs(result.x).max())
    true = np.linalg.norm(b - A @ result.x)
    assert result.converged == (true <= 1e-14 * np.linalg.norm(b))
    assert result.relative_residual == pytest.approx(true / np.linalg.norm(b), rel=1e-10)
    # without the hook the same solve goes on to the residual target
    plain = pcg_info(A, b, x0=x0, rtol=1e-10)
    assert not plain.rule_met and plain.converged


# ----------------------------------------------------------------------------- the estimate against spsolve
@pytest.mark.parametrize("shape, seed", [((40, 50), 0), ((64, 80), 1), ((97, 123), 2)])
@pytest.mark.parametrize("preconditioner", ["grid", "jacobi"])
@pytest.mark.parametrize("tol", [1e-3, 1e-5])
def test_estimate_approximates_the_true_remaining_change(shape, seed, preconditioner, tol):
    image, sparse, mask, _ = make_problem(shape, fraction=0.05, seed=seed)
    problem = CompletionProblem(image, sparse, mask, weights=sd.DEFAULT_WEIGHTS, l1_smoothing=1e-6,
                                clip_to_observed=False)
    obj, coarse = problem.objective, problem.fill
    A, b, _ = obj.normal_equations()
    z_star = spla.spsolve(sp.csc_matrix(A), b)
    rule = RemainingChange(b.size, tol)
    x, _, _, _ = pcg(A, b, x0=coarse.ravel(), M=make_preconditioner(A, preconditioner, shape=obj.shape),
                     rtol=1e-14, maxiter=5000, stop=rule)
    true = _rms(x - z_star)
    assert rule.estimate <= tol
    assert true <= K * tol  # the stop honours the tolerance
    assert rule.estimate / 10 <= true <= K * rule.estimate  # and the estimate is of the size of the truth


# ----------------------------------------------------------------------------- complete_depth
@pytest.fixture(scope="module")
def frame():
    return make_problem((60, 80), fraction=0.05, seed=3)


def test_default_solve_stops_on_the_depth_rule_within_its_tolerance(frame):
    image, sparse, mask, _ = frame
    res = sd.complete_depth(image, sparse, mask, clip_to_observed=False)
    assert res.solver == "amg" and res.converged
    z_star, scale = _exact(image, sparse, mask)
    assert scale == depth_unit(sparse[mask])
    tol = DEFAULT_DEPTH_RTOL * scale
    assert _rms(res.depth - z_star) <= K * tol
    match = re.search(r"estimated remaining change (\S+) \(RMS, depth units\) <= depth tolerance (\S+)", res.message)
    assert match, res.message
    estimate, told = float(match.group(1)), float(match.group(2))
    assert told == pytest.approx(tol, rel=0.05)  # printed to 2 digits
    assert estimate <= told * 1.05
    # the reported gap is a proven bound on F − F* (checked against the direct minimiser)
    F_star = sd.build_objective(image, sparse, mask)[0].value(z_star.ravel())
    assert res.gap >= (res.objective - F_star) * (1 - 1e-9)


def test_explicit_tol_keeps_the_residual_rule(frame):
    image, sparse, mask, _ = frame
    res = sd.complete_depth(image, sparse, mask, clip_to_observed=False, tol=1e-10)
    assert res.converged and "remaining change" not in res.message
    obj = sd.build_objective(image, sparse, mask)[0]
    A, b, _ = obj.normal_equations()
    r = b - A @ res.depth.ravel()
    assert np.linalg.norm(r) <= 1e-10 * np.linalg.norm(b) * (1 + 1e-6)
    z_star, _ = _exact(image, sparse, mask)
    np.testing.assert_allclose(res.depth, z_star, rtol=0, atol=1e-6)


def test_tighter_depth_tolerances_get_closer_to_the_minimiser(frame):
    image, sparse, mask, _ = frame
    z_star, scale = _exact(image, sparse, mask)
    for rtol in (1e-2, 1e-4, 1e-6):
        res = sd.complete_depth(image, sparse, mask, clip_to_observed=False, options={"depth_rtol": rtol})
        assert res.converged
        assert _rms(res.depth - z_star) <= K * rtol * scale


@pytest.mark.parametrize("solver", ["cg", "amg"])
def test_depth_atol_is_in_depth_units(frame, solver):
    image, sparse, mask, _ = frame
    z_star, _ = _exact(image, sparse, mask)
    res = sd.complete_depth(image, sparse, mask, solver=solver, clip_to_observed=False, options={"depth_atol": 2e-4})
    assert res.converged and "remaining change" in res.message
    assert _rms(res.depth - z_star) <= K * 2e-4
    # in millimetres: the same tolerance is 1000 times larger, the same solve
    mm = sd.complete_depth(image, sparse * 1000, mask, solver=solver, clip_to_observed=False,
                           options={"depth_atol": 0.2})
    np.testing.assert_allclose(mm.depth, res.depth * 1000, rtol=1e-7)  # units differ by 1000, the scales by a power of 2: rounding only


def test_the_larger_of_the_two_tolerances_counts(frame):
    image, sparse, mask, _ = frame
    loose = sd.complete_depth(image, sparse, mask, options={"depth_rtol": 1e-2, "depth_atol": 1e-9})
    same = sd.complete_depth(image, sparse, mask, options={"depth_rtol": 1e-2})
    np.testing.assert_array_equal(loose.depth, same.depth)


def test_an_explicit_gap_tol_still_vetoes_converged(frame):
    image, sparse, mask, _ = frame
    res = sd.complete_depth(image, sparse, mask, options={"depth_rtol": 1e-1, "gap_tol": 1e-12})
    assert not res.converged and "NOT converged: > gap_tol 1.0e-12" in res.message


# ----------------------------------------------------------------------------- the options
@pytest.mark.parametrize("cls", [AmgOptions, CgOptions])
def test_depth_options_are_checked(cls):
    solver = cls.solver
    with pytest.raises(ValueError, match=r"options\['depth_rtol'\] of solver .* must be finite and > 0; got -0.001"):
        check_solver_arguments(solver, options={"depth_rtol": -1e-3})
    with pytest.raises(ValueError, match="depth_atol"):
        check_solver_arguments(solver, options={"depth_atol": 0.0})
    with pytest.raises(ValueError, match="depth_atol"):
        check_solver_arguments(solver, options={"depth_atol": float("inf")})
    with pytest.raises(TypeError, match=r"options\['depth_rtol'\].*must be a number; got str"):
        check_solver_arguments(solver, options={"depth_rtol": "1e-3"})
    with pytest.raises(ValueError, match="unknown option 'depth_tol'.*depth_rtol=None, depth_atol=None"):
        check_solver_arguments(solver, options={"depth_tol": 1e-3})
    assert cls().in_depth_units(4.0).gap_tol == DEFAULT_GAP_TOL
    scaled = cls(depth_atol=2.0).in_depth_units(4.0)
    assert scaled.depth_atol == 0.5 and scaled.gap_tol == DEFAULT_GAP_TOL  # the depth rule keeps the gap test
    assert cls(depth_rtol=1e-3, gap_tol=1e-5).in_depth_units(4.0).gap_tol == 1e-5


def test_other_solvers_have_no_depth_rule():
    with pytest.raises(ValueError, match="unknown option 'depth_rtol' for solver 'direct'"):
        check_solver_arguments("direct", options={"depth_rtol": 1e-3})


def test_an_explicit_tol_and_a_depth_tolerance_stop_at_whichever_comes_first(frame):
    image, sparse, mask, _ = frame
    z_star, scale = _exact(image, sparse, mask)
    depth_first = sd.complete_depth(image, sparse, mask, clip_to_observed=False, tol=1e-14,
                                    options={"depth_rtol": 1e-2})
    assert depth_first.converged and "remaining change" in depth_first.message
    assert _rms(depth_first.depth - z_star) <= K * 1e-2 * scale
    residual_first = sd.complete_depth(image, sparse, mask, clip_to_observed=False, tol=1e-5,
                                       options={"depth_rtol": 1e-12})
    assert residual_first.converged and "remaining change" not in residual_first.message.split(";")[0]
    obj = sd.build_objective(image, sparse, mask)[0]
    A, b, _ = obj.normal_equations()
    assert np.linalg.norm(b - A @ residual_first.depth.ravel()) <= 1e-5 * np.linalg.norm(b) * (1 + 1e-6)
