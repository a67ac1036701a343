"""The duality-gap certificate: result.gap bounds F(z) − F* for every solver; ADMM converges only when it is small."""

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.sparse.linalg import spsolve

import sparsedepth as sd
from sparsedepth import Weights, build_objective
from sparsedepth.objective.l1 import StackedL1
from sparsedepth.solvers.certificate import Certificate, curvature_lower_bound, duality_gap
from sparsedepth.solvers import SOLVER_OPTIONS, check_solver_arguments, solve

from conftest import make_problem

L1 = Weights.paper(alpha=1.0, beta=0.2, gamma=0.05, delta=0.01, kappa=5.0)
#: the ADMM false-convergence example: delta = 0, kappa = 0 (before the certificate: F = 53.14, converged=True)
FALSE_W = Weights(alpha=4.853213859737187, beta=0.001753763688944511, gamma=0.2302580400763616, delta=0, kappa=0,
                  beta_image=0.0061036840889917435, beta_second=0, beta_second_image=0.003532944157929304)


def _false_convergence_problem():
    rng = np.random.default_rng(0)
    h, w = rng.integers(2, 13, 2)
    image = rng.random((h, w, 3))
    depth = rng.uniform(0.5, 10, (h, w))
    mask = rng.random((h, w)) < rng.uniform(0, 0.6)
    mask.flat[rng.choice(h * w, 2, replace=False)] = True
    return image, np.where(mask, depth, np.nan), mask


def _reference(obj, coarse):
    """F* from two independent runs that must agree: a long plain ADMM run (no polish) and a polished one."""
    plain, _ = solve(obj, coarse.ravel(), solver="admm", tol=1e-10, max_iter=20000, options={"polish": False})
    polished, _ = solve(obj, coarse.ravel(), solver="admm", options={"polish_rtol": 1e-12})
    F_plain, F_pol = obj.value(plain.z), obj.value(polished.z)
    assert abs(F_plain - F_pol) <= 1e-7 * F_pol, (F_plain, F_pol)
    return min(F_plain, F_pol)


@pytest.fixture(scope="module")
def l1_problem():
    image, sparse, mask, _ = make_problem((14, 18))
    obj, coarse, _ = build_objective(image, sparse, mask, weights=L1)
    return obj, coarse, _reference(obj, coarse)


@pytest.mark.parametrize("solver,max_iter", [("irls", None), ("irls", 3), ("admm", None), ("admm", 4),
                                             ("lbfgsb", None), ("lbfgsb", 15), ("adam", None), ("adam", 200)])
def test_gap_bounds_the_true_gap_for_every_l1_solver(l1_problem, solver, max_iter):
    obj, coarse, F_ref = l1_problem
    out, _ = solve(obj, coarse.ravel(), solver=solver, max_iter=max_iter)
    F = obj.value(out.z)
    assert np.isfinite(out.gap) and out.gap >= 0
    # F_ref >= F*, so F − F_ref <= F − F* <= gap; capped runs are far from the optimum and test the bound there
    assert out.gap >= F - F_ref - 1e-12 * F_ref, (solver, out.gap, F - F_ref)
    if out.converged:
        assert out.gap <= SOLVER_OPTIONS[solver]["gap_tol"] * F * (1 + 1e-12)


def test_gap_is_tight_at_a_converged_admm_result(l1_problem):
    obj, coarse, F_ref = l1_problem
    out, _ = solve(obj, coarse.ravel(), solver="admm")
    assert out.converged, out.message
    assert out.gap <= 1e-6 * obj.value(out.z)
    assert obj.value(out.z) - out.gap <= F_ref * (1 + 1e-12)


def test_gap_is_in_user_units():
    image, sparse, mask, _ = make_problem((10, 12))
    base = sd.complete_depth(image, sparse, mask, weights=L1, solver="admm", max_iter=5, clip_to_observed=False)
    # depth x 1000 with gamma x 1000 is the same problem with F x 1e6 (the normalised units are identical)
    big = sd.complete_depth(image, sparse * 1000.0, mask, weights=L1.replace(gamma=L1.gamma * 1000.0), solver="admm",
                            max_iter=5, clip_to_observed=False)
    assert big.objective == pytest.approx(1e6 * base.objective, rel=1e-9)
    assert big.gap == pytest.approx(1e6 * base.gap, rel=1e-6)
    assert base.gap > 0


@pytest.mark.parametrize("solver,max_iter", [("direct", None), ("cg", 3), ("amg", None), ("cg", None), ("admm", None)])
def test_quadratic_gap_equals_the_true_gap(solver, max_iter):
    image, sparse, mask, _ = make_problem((12, 15))
    obj, coarse, _ = build_objective(image, sparse, mask, weights=L1.replace(gamma=0.0))
    A, b, c = obj.normal_equations()
    F_star = obj.value(spsolve(sp.csc_matrix(A), b))  # the unconstrained minimum
    out, _ = solve(obj, coarse.ravel(), solver=solver, max_iter=max_iter)
    true_gap = obj.value(out.z) - F_star
    # a bound: ¼ ‖r‖² / λ_min(A) where that is already within gap_tol, else ¼ rᵀA⁻¹r = F(z) − F* exactly
    assert out.gap >= true_gap * (1 - 1e-6) - 1e-12 * F_star
    if max_iter is not None:
        assert true_gap > 1e-6 * F_star  # a capped run leaves a gap to measure
        assert out.gap == pytest.approx(true_gap, rel=1e-6, abs=1e-12 * F_star)
        assert not out.converged
    else:
        assert out.converged and out.gap <= 1e-6 * obj.value(out.z)


def test_dual_point_from_admm_multiplier_and_the_nonnegativity_multiplier():
    """Independent check of the bound at an arbitrary point: against F(z) − F* computed from a reference."""
    image, sparse, mask, _ = make_problem((10, 11))
    obj, coarse, _ = build_objective(image, sparse, mask, weights=L1)
    F_ref = _reference(obj, coarse)
    rng = np.random.default_rng(3)
    z = np.maximum(coarse.ravel() + 0.3 * rng.standard_normal(obj.size), 0.0)
    z[:5] = 0.0  # points on the bound z >= 0
    gap = duality_gap(obj, z)
    assert gap >= obj.value(z) - F_ref
    assert curvature_lower_bound(obj) == pytest.approx(L1.delta)


def test_dual_point_is_the_clipped_sign_of_the_edges_with_its_edges_and_weights():
    """Without fits, the public dual point is c·sign(Kz) off the tied rows and within [−c, c] on all of them."""
    image, sparse, mask, _ = make_problem((10, 11))
    obj, coarse, _ = build_objective(image, sparse, mask, weights=L1)
    l1 = StackedL1(obj)
    z = np.maximum(coarse.ravel() + 0.3 * np.random.default_rng(6).standard_normal(obj.size), 0.0)
    assert l1.grid_gradient
    p, t, c = Certificate(obj, fit_steps=0, fit_max_iter=0).dual_point(z, np.zeros(obj.size))
    np.testing.assert_allclose(t, sd.grid.gradient(obj.shape) @ z, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(c, l1.weights)
    assert np.all(np.abs(p) <= c)
    moving = np.abs(t) > 1e-12 * (1.0 + z.max())
    assert moving.any()
    np.testing.assert_allclose(p[moving], c[moving] * np.sign(t[moving]), rtol=1e-15)


@pytest.mark.parametrize("fit", [dict(fit_steps=0, fit_max_iter=30, fit_correction=True),
                                 dict(fit_steps=0, fit_max_iter=0)], ids=["corrected", "unfitted"])
@pytest.mark.parametrize("eps", [0.0, 1e-4, 1e-2])
def test_dual_fit_correcting_a_start_keeps_the_bound(eps, fit):
    """The least-squares correction of a given dual start (ADMM's polished-point certificate), or the start as it
    is on the tied rows (IRLS's hand-over check): still a bound."""
    image, sparse, mask, _ = make_problem((10, 11))
    obj, coarse, _ = build_objective(image, sparse, mask, weights=L1)
    F_ref = _reference(obj, coarse)
    out, _ = solve(obj, coarse.ravel(), solver="admm")
    c = StackedL1(obj).weights
    rng = np.random.default_rng(4)
    cert = Certificate(obj, **fit)
    points = [out.z, np.maximum(out.z + 1e-3 * rng.standard_normal(obj.size), 0.0),
              np.maximum(coarse.ravel() + 0.3 * rng.standard_normal(obj.size), 0.0)]
    for z in points:
        for p in (np.zeros_like(c), c * rng.uniform(-1.0, 1.0, c.size), 3.0 * c):
            gap = cert.gap(z, p=p, eps=eps)
            assert np.isfinite(gap) and gap >= 0.0
            assert gap >= obj.value(z) - F_ref - 1e-12 * F_ref, (eps, gap, obj.value(z) - F_ref)


def test_false_convergence_example_is_no_longer_reported_converged():
    image, sparse, mask = _false_convergence_problem()
    obj, coarse, _ = build_objective(image, sparse, mask, weights=FALSE_W)
    ref, _ = solve(obj, coarse.ravel(), solver="admm", tol=1e-10, max_iter=20000, options={"polish": False})
    F_ref = obj.value(ref.z)
    lb, _ = solve(obj, coarse.ravel(), solver="lbfgsb", tol=1e-8)
    assert abs(obj.value(lb.z) - F_ref) <= 1e-4 * F_ref  # the two references agree (lbfgsb: smoothed problem)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = sd.complete_depth(image, sparse, mask, weights=FALSE_W, solver="admm", clip_to_observed=False)
    assert res.objective == pytest.approx(obj.value(res.depth.ravel()))
    if res.converged:
        assert res.objective <= F_ref * (1 + 1e-6), res.message
    else:
        assert "gap" in res.message
    assert res.objective - res.gap <= F_ref * (1 + 1e-9)


def test_other_solvers_report_a_refused_certificate():
    image, sparse, mask, _ = make_problem((10, 12))
    res = sd.complete_depth(image, sparse, mask, weights=L1, solver="lbfgsb", options={"gap_tol": 1e-12})
    assert not res.converged and "duality gap" in res.message and "gap_tol" in res.message
    ok = sd.complete_depth(image, sparse, mask, weights=L1, solver="lbfgsb")
    assert ok.converged, ok.message


def test_admm_keeps_iterating_while_the_certificate_refuses():
    image, sparse, mask, _ = make_problem((12, 14))
    default = sd.complete_depth(image, sparse, mask, weights=L1, solver="admm")
    assert default.converged and "duality gap" in default.message, default.message
    strict = sd.complete_depth(image, sparse, mask, weights=L1, solver="admm", max_iter=400,
                               options={"gap_tol": 1e-30})
    # the polishes agreed (as in the default run) but the certificate refused: it went on to max_iter
    assert not strict.converged and "polishes agreed" in strict.message, strict.message
    assert strict.message.startswith("reached max_iter = 400")


def test_gap_tol_is_a_checked_option():
    for solver in ("direct", "cg", "amg", "irls", "admm", "lbfgsb", "adam"):
        assert check_solver_arguments(solver, options={"gap_tol": 0.5})[2]["gap_tol"] == 0.5
        with pytest.raises(ValueError, match="gap_tol"):
            check_solver_arguments(solver, options={"gap_tol": -1.0})


@st.composite
def _problems(draw):
    h = draw(st.integers(2, 7))
    w = draw(st.integers(2, 7))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    image = rng.random((h, w, 3))
    depth = rng.uniform(0.5, 10.0, (h, w))
    mask = rng.random((h, w)) < draw(st.floats(0.1, 0.6))
    mask.flat[rng.choice(h * w, 2, replace=False)] = True
    weights = Weights(alpha=draw(st.floats(0.5, 5.0)), beta=draw(st.floats(1e-3, 0.3)),
                      gamma=draw(st.floats(0.01, 0.3)), delta=draw(st.sampled_from([0.0, 1e-3, 1e-2])),
                      kappa=draw(st.floats(0.0, 10.0)), beta_image=draw(st.sampled_from([0.0, 0.01])))
    return image, np.where(mask, depth, np.nan), mask, weights


@settings(derandomize=True, database=None, deadline=None, max_examples=12,
          suppress_health_check=[HealthCheck.too_slow])
@given(problem=_problems())
def test_converged_admm_and_irls_at_gap_tol_1e6_are_within_their_gap_of_lbfgsb(problem):
    """Each solver's gap bounds F − F_ref (F* <= F_ref, one tight L-BFGS-B run per problem); converged means
    gap <= 1e-6 F.  ADMM with its defaults, IRLS with gap_tol 1e-6."""
    image, sparse, mask, weights = problem
    obj, coarse, _ = build_objective(image, sparse, mask, weights=weights)
    # 100 correction pairs: the ill-conditioned draws (delta = 0) reach the tolerance in a fraction of the steps
    ref, _ = solve(obj, coarse.ravel(), solver="lbfgsb", tol=1e-15, max_iter=20000, options={"maxcor": 100})
    F_ref = obj.value(ref.z)
    rounding = 1e-10 * F_ref
    for solver, options in (("admm", None), ("irls", {"gap_tol": 1e-6})):
        out, _ = solve(obj, coarse.ravel(), solver=solver, options=options)
        F = obj.value(out.z)
        assert out.gap >= F - F_ref - rounding, solver  # gap >= F − F_ref >= ... (F* <= F_ref)
        if out.converged:
            assert out.gap <= 1e-6 * F * (1 + 1e-12), solver
            assert F - out.gap <= F_ref + rounding, solver


def test_gap_is_nan_where_the_quadratic_part_is_singular():
    """delta = 0 and no quadratic smoothness: A = alpha M is singular, no bound; the solvers' own rules decide."""
    rng = np.random.default_rng(1)
    image = rng.random((6, 7, 3))
    depth = rng.uniform(1, 3, (6, 7))
    mask = rng.random((6, 7)) < 0.4
    mask[0, 0] = True
    w = Weights(alpha=1.0, beta=0.0, gamma=0.1, delta=0.0, kappa=0.0, beta_image=0.0, beta_second=0.0,
                beta_second_image=0.0, beta_local_linear=0.0)
    for solver in ("admm", "irls"):
        res = sd.complete_depth(image, np.where(mask, depth, np.nan), mask, weights=w, solver=solver,
                                clip_to_observed=False)
        assert np.isnan(res.gap) and "not available" in res.message
        assert res.converged, res.message


def test_irls_to_gap_tol_1e6_is_certified_by_its_finishing_phase(l1_problem):
    obj, coarse, F_ref = l1_problem
    out, _ = solve(obj, coarse.ravel(), solver="irls", options={"gap_tol": 1e-6})
    F = obj.value(out.z)
    assert out.converged, out.message
    assert out.gap <= 1e-6 * F * (1 + 1e-12)
    assert out.gap >= F - F_ref - 1e-12 * F_ref
    assert F - out.gap <= F_ref * (1 + 1e-12)
    assert "finished by" in out.message and "ADMM iterations" in out.message
    steps = [h.iteration for h in out.history]
    assert steps == sorted(set(steps)) and steps[-1] > out.iterations // 2  # one history, numbered on
    assert out.history[-1].objective == pytest.approx(F, rel=1e-12)


def test_irls_finish_none_is_newton_steps_only(l1_problem):
    obj, coarse, F_ref = l1_problem
    newton, _ = solve(obj, coarse.ravel(), solver="irls", options={"finish": "none"})
    handed, _ = solve(obj, coarse.ravel(), solver="irls", options={"newton_gap": 1e-4})
    assert "ADMM" not in newton.message
    # with newton_gap = gap_tol a Newton phase that certifies by itself is the whole run: the same run either way
    if handed.converged and "finished by" not in handed.message:
        np.testing.assert_array_equal(handed.z, newton.z)
    assert newton.gap >= obj.value(newton.z) - F_ref - 1e-12 * F_ref


def test_certificate_of_a_general_sparse_operator_with_gradient_steps():
    """A non-gradient L1 operator (the Hessian rows): the FISTA steps' ‖K‖² bound and the gap bound both hold."""
    from sparsedepth.grid.operators import hessian_operator
    from sparsedepth.objective import AbsTerm, Objective, QuadraticTerm

    shape = (6, 7)
    n = shape[0] * shape[1]
    rng = np.random.default_rng(7)
    K = sp.csr_matrix(hessian_operator(shape))
    data = rng.random(n) < 0.3
    obj = Objective(shape, [QuadraticTerm("data", 1.0, None, data, np.where(data, 1.0 + rng.random(n), 0.0)),
                            QuadraticTerm("prior", 0.05, None, None, 1.0 + rng.random(n)),
                            AbsTerm("edge", 0.3, K, rng.random(K.shape[0]))])
    cert = Certificate(obj, fit_steps=20)
    assert not cert.l1.grid_gradient
    assert cert.k_norm_squared() >= np.linalg.norm(K.toarray(), 2) ** 2 * (1 - 1e-12)
    # any feasible point's value bounds F* from above: the best of two long ADMM runs
    runs = [solve(obj, np.ones(n), solver="admm", tol=1e-10, max_iter=20000, options={"polish": False})[0],
            solve(obj, np.ones(n), solver="admm", options={"polish_rtol": 1e-12})[0]]
    F_ref = min(obj.value(out.z) for out in runs)
    for z in (np.ones(n), 1.0 + rng.random(n)):
        gap = cert.gap(z)
        assert np.isfinite(gap) and gap >= obj.value(z) - F_ref - 1e-12 * F_ref


@pytest.mark.parametrize("fit", [dict(fit_steps=0, fit_max_iter=30, fit_correction=True),
                                 dict(fit_steps=20, fit_max_iter=0)], ids=["corrected", "gradient-steps"])
def test_low_memory_certificate_and_a_p_overwritten_give_the_same_gap(fit):
    """low_memory (term-by-term gradient, a hierarchy per call, A not cached) and overwrite_p change no bound."""
    image, sparse, mask, _ = make_problem((12, 13))
    obj, coarse, _ = build_objective(image, sparse, mask, weights=L1)
    out, _ = solve(obj, coarse.ravel(), solver="admm")
    c = StackedL1(obj).weights
    rng = np.random.default_rng(5)
    p = c * rng.uniform(-1.0, 1.0, c.size)
    z = np.maximum(out.z + 1e-3 * rng.standard_normal(obj.size), 0.0)
    obj.clear_cache()
    kept = Certificate(obj, **fit)
    reference = [kept.gap(point, p=p, eps=1e-4) for point in (out.z, z)]
    assert kept._precondition is not None  # kept for the next call
    obj.clear_cache()
    lean = Certificate(obj, low_memory=True, **fit)
    for point, expected in zip((out.z, z), reference):
        work = p.copy()
        gap = lean.gap(point, p=work, eps=1e-4, overwrite_p=True)
        assert gap == pytest.approx(expected, rel=1e-9, abs=1e-15)
        assert lean._precondition is None and obj._normal is None  # nothing kept between calls
    # overwrite_p alone: bit for bit the gap of an untouched p
    work = p.copy()
    assert kept.gap(z, p=work, eps=1e-4, overwrite_p=True) == reference[1]
    assert not np.array_equal(work, p)  # its memory held the dual point


def test_objective_constant_and_uncached_normal_equations():
    image, sparse, mask, _ = make_problem((9, 10))
    obj, _, _ = build_objective(image, sparse, mask, weights=L1)
    constant = obj.constant()
    A, b, c = obj.normal_equations(form="stencil", cache=False)
    assert obj._normal is None
    assert c == constant
    z = np.random.default_rng(2).random(obj.size)
    quadratic = sum(t.value(z) for t in obj.quadratic_terms)
    assert float(z @ (A @ z) - 2 * b @ z + c) == pytest.approx(quadratic, rel=1e-12)
    cached = obj.normal_equations(form="stencil")
    assert obj._normal is not None and cached[2] == constant == obj.constant()


@pytest.mark.parametrize("box", [(-np.inf, np.inf), "clamp"])
def test_a_target_stops_the_certificate_early_with_a_bound_still_above_the_true_gap(box):
    image, sparse, mask, _ = make_problem(shape=(30, 40), fraction=0.08)
    obj, coarse, _ = build_objective(image, sparse, mask, weights=Weights.paper(alpha=1.0, beta=0.1, gamma=0.0,
                                                                                delta=1e-3, kappa=10.0))
    A, b, _ = obj.normal_equations()
    z_star = spsolve(sp.csc_matrix(A), b)
    if box == "clamp":  # a clamp range that cuts the minimiser: the box's own minimum by L-BFGS-B
        from scipy.optimize import minimize

        low, high = np.percentile(z_star, [10, 90])
        F_box = minimize(lambda z: (obj.value(z), obj.quadratic_gradient(z)), np.clip(z_star, low, high), jac=True,
                         method="L-BFGS-B", bounds=[(low, high)] * obj.size,
                         options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 20000}).fun
        bounds = (low, high)
    else:
        F_box, bounds = obj.value(z_star), box
    rng = np.random.default_rng(0)
    z = np.clip(z_star + 0.05 * rng.standard_normal(obj.size), *bounds)  # a point to certify, inside the box
    true_gap = obj.value(z) - F_box
    tight = Certificate(obj, bounds=bounds, rtol=1e-10).gap(z)
    cheap = Certificate(obj, bounds=bounds).cheap_gap(z)
    assert true_gap * (1 - 1e-6) <= tight <= cheap
    for target in np.geomspace(tight * 1.5, cheap, 4):
        certificate = Certificate(obj, bounds=bounds, rtol=1e-10)
        early = certificate.gap(z, target=target)
        assert true_gap * (1 - 1e-6) <= tight * (1 - 1e-9) <= early <= target  # proven, and answers the question
    # a target below the true gap cannot be met: the solve runs to rtol and returns the tight bound
    unreachable = Certificate(obj, bounds=bounds, rtol=1e-10).gap(z, target=0.5 * true_gap)
    assert unreachable == pytest.approx(tight, rel=1e-6)
