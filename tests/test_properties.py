"""Properties of complete_depth on small random problems (hypothesis, derandomized: the same examples on every run).

Each problem is a random image, random depths in [0.5, 10] and a random mask; the properties are checked against
independent computations (a dense eigenvalue bound, a hand-built normal-equation system solved by spsolve), never
against recorded results.
"""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import ndimage

import sparsedepth as sd
from sparsedepth import build_objective

QUADRATIC_SOLVERS = ("direct", "cg", "amg")
L1_SOLVERS = ("irls", "admm", "lbfgsb", "adam")
#: the gradient-based solvers are slow to converge: smaller frames and fewer examples for them
SLOW = ("lbfgsb", "adam")


def _settings(max_examples):
    return settings(derandomize=True, database=None, deadline=None, max_examples=max_examples,
                    suppress_health_check=[HealthCheck.too_slow])


@st.composite
def problems(draw, max_side=20, min_observed=1):
    """(image, sparse, mask): image in [0, 1], depth uniform in [0.5, 10], at least `min_observed` observed pixels."""
    h = draw(st.integers(1, max_side))
    w = draw(st.integers(2 if h == 1 and min_observed > 1 else 1, max_side))
    fraction = draw(st.floats(0.0, 0.6))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    image = rng.random((h, w, 3))
    depth = rng.uniform(0.5, 10.0, (h, w))
    mask = rng.random((h, w)) < fraction
    mask.flat[rng.choice(h * w, min_observed, replace=False)] = True
    return image, np.where(mask, depth, np.nan), mask


def _log_uniform(lo, hi):
    return st.floats(np.log10(lo), np.log10(hi)).map(lambda e: float(10.0**e))


def _maybe_zero(lo, hi):
    return st.one_of(st.just(0.0), _log_uniform(lo, hi))


@st.composite
def weights(draw, *, gamma=False, delta=True, kappa=True, second_order=True):
    """Random weights; beta > 0 always, so that the quadratic part is positive definite with one observation."""
    return sd.Weights(
        alpha=draw(_log_uniform(0.1, 10.0)),
        beta=draw(_log_uniform(1e-3, 1.0)),
        gamma=draw(_log_uniform(1e-3, 0.5)) if gamma else 0.0,
        delta=draw(_maybe_zero(1e-4, 0.1)) if delta else 0.0,
        kappa=draw(st.floats(0.0, 30.0)) if kappa else 0.0,
        beta_image=draw(_maybe_zero(1e-3, 1.0)),
        beta_second=draw(_maybe_zero(1e-3, 1.0)) if second_order else 0.0,
        beta_second_image=draw(_maybe_zero(1e-3, 1.0)) if second_order else 0.0,
        edge_sigma=0.0, fill_contrast=0.0,  # the references below use the raw image's weights and nearest z_c
        beta_local_linear=0.0,  # and the first- and second-order terms only
    )


def _lambda_min(image, sparse, mask, w):
    """Smallest eigenvalue of the quadratic part's matrix A (dense: the frames are small)."""
    obj, _, _ = build_objective(image, sparse, mask, weights=w.replace(gamma=0.0))
    A, b, _ = obj.normal_equations()
    return float(np.linalg.eigvalsh(A.toarray())[0]), A, b


# --------------------------------------------------------------------------
# z >= 0
# --------------------------------------------------------------------------
def _nonnegative(solver, problem, w):
    image, sparse, mask = problem
    # lbfgsb and adam are capped: the bound must hold at any iterate they return, converged or not
    max_iter = 100 if solver in SLOW else None
    res = sd.complete_depth(image, sparse, mask, weights=w, solver=solver, max_iter=max_iter)
    assert res.depth.shape == mask.shape
    assert np.all(np.isfinite(res.depth))
    assert res.depth.min() >= 0.0


@pytest.mark.parametrize("solver", QUADRATIC_SOLVERS)
@_settings(25)
@given(problem=problems(), w=weights())
def test_depth_is_nonnegative_quadratic_solvers(solver, problem, w):
    _nonnegative(solver, problem, w)


@pytest.mark.parametrize("solver", L1_SOLVERS)
@_settings(8)
@given(data=st.data())
def test_depth_is_nonnegative_l1_solvers(solver, data):
    # at least two observed pixels: with one, the optimum is a constant with F* = 0, which ADMM's relative
    # stopping rule does not handle (a separate issue)
    problem = data.draw(problems(max_side=8 if solver in SLOW else 20, min_observed=2), label="problem")
    _nonnegative(solver, problem, data.draw(weights(gamma=True), label="weights"))


# --------------------------------------------------------------------------
# equivariance under flips
# --------------------------------------------------------------------------
#: the iterative L1 solvers, each with its options and its tolerances (depth, relative to the largest observed
#: depth; objective, relative), about 100 times the differences measured on random examples, as the results are
#: exact only up to each stopping rule. ADMM runs without its active-set polish, to a tight residual: the polish's
#: stopping test can end at a point a few % above the optimum when delta = 0, and the two orders of the pixels
#: then end at different points. Adam is left out: converging it to an accuracy worth comparing takes seconds per
#: solve.
L1_FLIP = {
    "irls": ({"options": {"gap_tol": 1e-8}}, 1e-3, 1e-6),
    "admm": ({"tol": 1e-7, "max_iter": 10000, "options": {"polish": False}}, 1e-4, 1e-6),
    "lbfgsb": ({}, 1e-3, 1e-5),
}


def _complete_flipped(problem, axis, w, solver, **kwargs):
    image, sparse, mask = (np.flip(a, axis) for a in problem)
    return sd.complete_depth(image, sparse, mask, weights=w, solver=solver, **kwargs)


@pytest.mark.parametrize("solver", QUADRATIC_SOLVERS)
@_settings(15)
@given(problem=problems(), w=weights(delta=False))
def test_flip_equivariance_quadratic_solvers(solver, problem, w):
    # delta = 0: the nearest-neighbour prior z_c breaks distance ties in scan order, so it is not flip-equivariant
    # where two observations are equally near; every other quadratic term is (pair weights, centred second
    # differences, the 2x2 mixed difference)
    image, sparse, mask = problem
    kwargs = {} if solver == "direct" else {"tol": 1e-10}
    res = sd.complete_depth(image, sparse, mask, weights=w, solver=solver, **kwargs)
    if solver != "direct":
        lam, A, b = _lambda_min(image, sparse, mask, w)
    for axis in (0, 1):  # vertical, horizontal
        back = np.flip(_complete_flipped(problem, axis, w, solver, **kwargs).depth, axis)
        if solver == "direct":
            np.testing.assert_allclose(back, res.depth, rtol=0, atol=1e-9 * np.nanmax(sparse), err_msg=f"axis {axis}")
            continue
        # both are within ‖b − A z‖₂ / λ_min(A) of the one exact solution z*, whose flip is the flipped solution
        bound = sum(np.linalg.norm(b - A @ z.ravel()) for z in (res.depth, back)) / lam
        assert np.linalg.norm(back - res.depth) <= bound + 1e-12 * np.linalg.norm(res.depth), f"axis {axis}"


@pytest.mark.parametrize("solver", sorted(L1_FLIP))
@_settings(6)
@given(data=st.data())
def test_flip_equivariance_l1_solvers(solver, data):
    # kappa = 0: the edge term's per-pixel weight exp(-kappa |grad I|) uses forward differences at the pixel,
    # so for kappa > 0 an edge is weighted by its left / upper pixel's gradient and the term is not symmetric;
    # delta = 0 as for the quadratic solvers
    problem = data.draw(problems(max_side=6 if solver in SLOW else 12, min_observed=2), label="problem")
    w = data.draw(weights(gamma=True, delta=False, kappa=False), label="weights")
    kwargs, depth_tol, objective_tol = L1_FLIP[solver]
    image, sparse, mask = problem
    res = sd.complete_depth(image, sparse, mask, weights=w, solver=solver, **kwargs)
    for axis in (0, 1):  # vertical, horizontal
        flipped = _complete_flipped(problem, axis, w, solver, **kwargs)
        # (converged flags are not compared: where every edge ties at the optimum, K z -> 0 and ADMM's relative
        # primal residual may stay above tol in one pixel order and reach 0 in the other, at the same point)
        np.testing.assert_allclose(np.flip(flipped.depth, axis), res.depth, rtol=0,
                                   atol=depth_tol * np.nanmax(sparse), err_msg=f"axis {axis}")
        assert flipped.objective == pytest.approx(res.objective, rel=objective_tol), f"axis {axis}"


# --------------------------------------------------------------------------
# depth scaling (gamma = 0)
# --------------------------------------------------------------------------
@_settings(30)
@given(problem=problems(), w=weights(), scale=_log_uniform(1e-3, 1e3))
def test_depth_scaling_commutes_with_completion(problem, w, scale):
    # gamma = 0: every term is quadratic in the depth, so F(s z; s data) = s² F(z; data) and the minimiser scales
    image, sparse, mask = problem
    res = sd.complete_depth(image, sparse, mask, weights=w, solver="direct")
    scaled = sd.complete_depth(image, scale * sparse, mask, weights=w, solver="direct")
    np.testing.assert_allclose(scaled.depth, scale * res.depth, rtol=1e-8, atol=1e-12 * scale * np.nanmax(sparse))
    assert scaled.objective == pytest.approx(scale**2 * res.objective, rel=1e-8, abs=1e-20 * scale**2)


# --------------------------------------------------------------------------
# maximum principle of the first-order L2 model
# --------------------------------------------------------------------------
def _first_order_system(image, sparse, mask, w):
    """(alpha M + delta I + beta L + beta_image L_I) z = alpha M d + delta z_c, built from the definitions.

    L = Dxᵀ Dx + Dyᵀ Dy with forward differences (zero rows at the last column / row), L_I the same with the
    per-pair weights exp(-kappa ‖I[i, j+1] − I[i, j]‖) (rows) and exp(-kappa ‖I[i+1, j] − I[i, j]‖)
    (columns); z_c the nearest observation (scipy.ndimage.distance_transform_edt, as sparsedepth.nearest_fill).
    """
    h, w_ = mask.shape

    def diff(m):
        main = -np.ones(m)
        main[-1] = 0.0
        return sp.diags([main, np.ones(m - 1)], [0, 1], shape=(m, m))

    Dx = sp.kron(sp.eye(h), diff(w_))
    Dy = sp.kron(diff(h), sp.eye(w_))
    wx = np.ones((h, w_))
    wy = np.ones((h, w_))
    wx[:, :-1] = np.exp(-w.kappa * np.linalg.norm(np.diff(image, axis=1), axis=2))
    wy[:-1] = np.exp(-w.kappa * np.linalg.norm(np.diff(image, axis=0), axis=2))
    m = mask.ravel().astype(float)
    d = np.where(mask, sparse, 0.0).ravel()
    _, (ii, jj) = ndimage.distance_transform_edt(~mask, return_indices=True)
    z_c = np.where(mask, sparse, 0.0)[ii, jj].ravel()
    A = (sp.diags(w.alpha * m + w.delta) + w.beta * (Dx.T @ Dx + Dy.T @ Dy)
         + w.beta_image * (Dx.T @ sp.diags(wx.ravel()) @ Dx + Dy.T @ sp.diags(wy.ravel()) @ Dy))
    return sp.csc_matrix(A), w.alpha * m * d + w.delta * z_c


@_settings(25)
@given(problem=problems(), w=weights(second_order=False))
def test_first_order_l2_solution_lies_within_the_observed_range(problem, w):
    # A = alpha M + delta I + (weighted graph Laplacians) is an M-matrix whose row sums equal the right-hand side's
    # weights, so z is a convex combination of the observations and of z_c (itself observations)
    image, sparse, mask = problem
    res = sd.complete_depth(image, sparse, mask, weights=w, solver="direct")
    lo, hi = np.nanmin(sparse), np.nanmax(sparse)
    assert lo - 1e-12 * hi <= res.depth.min() and res.depth.max() <= hi + 1e-12 * hi
    # and it is the solution of the system written from the definitions (not through sparsedepth's operators)
    A, rhs = _first_order_system(image, sparse, mask, w)
    z = spla.spsolve(A, rhs).reshape(mask.shape)
    np.testing.assert_allclose(res.depth, z, rtol=0, atol=1e-9 * hi)
    # the same bounds hold for the multigrid-PCG path, to its residual bound
    amg = sd.complete_depth(image, sparse, mask, weights=w, solver="amg", tol=1e-10)
    lam = float(np.linalg.eigvalsh(A.toarray())[0])
    slack = np.linalg.norm(rhs - A @ amg.depth.ravel()) / lam + 1e-12 * hi
    assert lo - slack <= amg.depth.min() and amg.depth.max() <= hi + slack
