"""The fast solver paths: grid-multigrid PCG, ADMM with one hierarchy, IRLS with update(), linear.pcg."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from sparsedepth import Weights, build_objective, complete_depth
from sparsedepth.linalg import make_preconditioner, pcg
from sparsedepth.linalg.multigrid import GridMultigrid, grid_stencil

from conftest import make_problem

# 13-point second-order term plus image-weighted first-order rows (the likely new defaults)
QUAD13 = Weights(
    alpha=1.0, beta=0.05, gamma=0.0, delta=1e-3, kappa=5.0, beta_image=0.5, beta_second=0.3, beta_second_image=0.0,
    beta_local_linear=0.0,  # the default local-linear term would make the system 25-point
)
L1_13 = QUAD13.replace(gamma=0.03)


@pytest.fixture(scope="module", params=[(40, 50), (37, 53)], ids=["40x50", "37x53"])
def problem(request):
    return make_problem(request.param)


def test_grid_pcg_reaches_direct_solution_on_13_point_problem(problem):
    image, sparse, mask, _ = problem
    obj, _, _ = build_objective(image, sparse, mask, weights=QUAD13)
    A, b, _ = obj.normal_equations()
    offsets, _ = grid_stencil(A, obj.shape)
    assert len(offsets) == 13  # the second-order term widens the stencil
    z_ref = spla.spsolve(A.tocsc(), b)
    res = complete_depth(image, sparse, mask, weights=QUAD13, solver="amg", tol=1e-8)
    assert res.solver == "amg" and res.converged
    z = res.depth.ravel()
    assert np.linalg.norm(b - A @ z) <= 1e-8 * np.linalg.norm(b) * (1 + 1e-6)
    # error bound: ‖z − z*‖ ≤ ‖A⁻¹‖ ‖r‖, and the objective matches the direct one
    assert np.abs(z - z_ref).max() < 1e-4
    assert res.objective == pytest.approx(obj.value(z_ref), rel=1e-9)
    # the multigrid preconditioner is working: Jacobi-CG reaches the same point in far more iterations
    # (a loose bound on purpose: measured 12 vs 214 and 11 vs 195, far from rounding's iteration or two)
    cg = complete_depth(image, sparse, mask, weights=QUAD13, solver="cg", tol=1e-8)
    assert cg.converged
    assert np.linalg.norm(b - A @ cg.depth.ravel()) <= 1e-8 * np.linalg.norm(b) * (1 + 1e-6)
    assert cg.iterations > 3 * res.iterations


def test_pyamg_option_still_available(problem):
    image, sparse, mask, _ = problem
    grid = complete_depth(image, sparse, mask, weights=QUAD13, solver="amg", tol=1e-8)
    amg = complete_depth(image, sparse, mask, weights=QUAD13, solver="amg", tol=1e-8, options={"preconditioner": "amg"})
    assert amg.converged
    assert amg.objective == pytest.approx(grid.objective, rel=1e-9)


def test_admm_irls_lbfgsb_agree_on_13_point_l1_problem(problem):
    image, sparse, mask, _ = problem
    admm = complete_depth(image, sparse, mask, weights=L1_13, solver="admm")
    irls = complete_depth(image, sparse, mask, weights=L1_13, solver="irls", tol=1e-8)
    # L-BFGS-B at tol 1e-8 ends within 3e-5 of the optimum here, well inside the 1e-4 compared
    lbfgsb = complete_depth(image, sparse, mask, weights=L1_13, solver="lbfgsb", l1_smoothing=1e-5, tol=1e-8)
    assert abs(admm.objective - lbfgsb.objective) / lbfgsb.objective < 1e-4
    assert abs(irls.objective - lbfgsb.objective) / lbfgsb.objective < 1e-4
    assert admm.objective <= irls.objective * (1 + 1e-7)
    F = irls.history_array("objective")
    if "finished by" in irls.message:  # the ADMM finish returns its best polish: within its certified gap of every iterate
        assert irls.converged and 0.0 <= irls.objective - F.min() <= irls.gap * (1 + 1e-9) + 1e-12 * irls.objective
    else:
        assert irls.objective == pytest.approx(F.min(), rel=1e-12)  # Newton returns its best point
    # pyamg-preconditioned ADMM reaches the same point
    admm_amg = complete_depth(image, sparse, mask, weights=L1_13, solver="admm", options={"preconditioner": "amg"})
    assert admm_amg.objective == pytest.approx(admm.objective, rel=1e-6)
    # auto picks ADMM for gamma > 0
    auto = complete_depth(image, sparse, mask, weights=L1_13)
    assert auto.solver == "admm" and auto.objective == pytest.approx(admm.objective, rel=1e-12)


def test_admm_one_hierarchy_matches_rebuilding_with_rho_adaptation(problem):
    image, sparse, mask, _ = problem
    fixed = complete_depth(image, sparse, mask, weights=L1_13, solver="admm", tol=1e-5)
    adapted = complete_depth(image, sparse, mask, weights=L1_13, solver="admm", tol=1e-5,
                             options={"adapt_iters": 50, "rho": 0.1})
    assert adapted.objective == pytest.approx(fixed.objective, rel=1e-6)


def _spd_system(shape=(30, 41), seed=1):
    rng = np.random.default_rng(seed)
    image, sparse, mask, _ = make_problem(shape, seed=seed)
    obj, _, _ = build_objective(image, sparse, mask, weights=QUAD13)
    A, b, _ = obj.normal_equations()
    return A, b + 0.1 * rng.standard_normal(b.shape), obj.shape


def test_pcg_stopping_rule_is_the_true_residual():
    A, b, shape = _spd_system()
    M = make_preconditioner(A, "grid", shape=shape)
    x0 = np.ones_like(b)
    keep = x0.copy()
    for rtol in (1e-4, 1e-10):
        x, it, ok, rel = pcg(A, b, x0=x0, M=M, rtol=rtol)
        assert ok and it > 0
        assert rel == pytest.approx(np.linalg.norm(b - A @ x) / np.linalg.norm(b), rel=1e-9)
        assert rel <= rtol
    np.testing.assert_array_equal(x0, keep)  # x0 not modified
    # atol: an absolute target
    r0 = np.linalg.norm(b - A @ x0)
    x, it, ok, rel = pcg(A, b, x0=x0, M=M, rtol=0.0, atol=0.1 * r0)
    assert ok and np.linalg.norm(b - A @ x) <= 0.1 * r0
    # maxiter reached: converged is False and the residual is reported honestly
    x, it, ok, rel = pcg(A, b, rtol=1e-14, maxiter=2)
    assert not ok and it == 2 and rel > 1e-14  # the count is the limit itself, not a rounding-dependent one
    assert rel == pytest.approx(np.linalg.norm(b - A @ x) / np.linalg.norm(b), rel=1e-9)
    # b = 0: solved before any iteration
    x, it, ok, rel = pcg(A, np.zeros_like(b))
    assert ok and it == 0 and not x.any()


def test_make_preconditioner_grid_needs_shape_and_accepts_a_hierarchy():
    A, b, shape = _spd_system()
    with pytest.raises(ValueError, match="shape"):
        make_preconditioner(A, "grid")
    with pytest.raises(ValueError, match="unknown preconditioner"):
        make_preconditioner(A, "ilu", shape=shape)
    mg = GridMultigrid(A, shape)
    x1, *_ = pcg(A, b, M=make_preconditioner(A, mg), rtol=1e-10)
    x2, *_ = pcg(A, b, M=make_preconditioner(A, "grid", shape=shape), rtol=1e-10)
    np.testing.assert_allclose(x1, x2, atol=1e-8 * np.abs(x1).max())


def test_stencil_check_is_exact():
    """A coupling outside the stencil is caught however small it is (the old Frobenius check missed it)."""
    A, _, shape = _spd_system()
    H, W = shape
    A = A.tolil()
    i = 5 * W + (W - 1)  # last pixel of row 5 ...
    A[i, i + 1] = A[i + 1, i] = -1e-9  # ... coupled to the first pixel of row 6: not a grid neighbour
    with pytest.raises(ValueError, match="stencil of radius"):
        GridMultigrid(A.tocsr(), shape)
    # explicit zeros outside the stencil are harmless
    A[i, i + 1] = A[i + 1, i] = 0.0
    B = A.tocsr()
    B.data[B.data == 0] = 0.0
    GridMultigrid(B, shape)


def test_update_keeps_hierarchy_and_matches_fresh_build():
    A, b, shape = _spd_system()
    mg = GridMultigrid(A, shape)
    A2 = (A + sp.diags(np.linspace(0.5, 2.0, A.shape[0]))).tocsr()
    mg.update(A2)
    fresh = GridMultigrid(A2, shape)
    r = np.random.default_rng(0).standard_normal(A.shape[0])
    np.testing.assert_allclose(mg.vcycle(r), fresh.vcycle(r), rtol=1e-10, atol=1e-12)
