"""Tests for sparsedepth.linalg.multigrid: hierarchy algebra, symmetry, PCG, update()."""

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from sparsedepth.linalg.multigrid import (
    GridMultigrid,
    SolveInfo,
    grid_multigrid,
    grid_stencil,
    solve_spd,
)

from conftest import DOUBLE, linear_interpolation_1d
from conftest import forward_difference_1d as forward_diff

# --------------------------------------------------------------------------
# test systems, built from the plain definition with scipy products
# --------------------------------------------------------------------------


def gradient(shape):
    h, w = shape
    Dx = sp.kron(sp.eye(h), forward_diff(w), format="csr")
    Dy = sp.kron(forward_diff(h), sp.eye(w), format="csr")
    return Dx, Dy


def grid_system(shape, a, wx, wy):
    """A = diag(a) + Dx^T diag(wx) Dx + Dy^T diag(wy) Dy (CSR)."""
    Dx, Dy = gradient(shape)
    n = shape[0] * shape[1]
    A = sp.diags(np.broadcast_to(a, n)) + Dx.T @ sp.diags(np.broadcast_to(wx, n)) @ Dx \
        + Dy.T @ sp.diags(np.broadcast_to(wy, n)) @ Dy
    return sp.csr_array(A)


def random_system(shape, rng, *, delta=1e-2, frac=0.05, jump=False):
    """Random data mask; weights near 1, or (jump=True) constant on 4x4 blocks
    with values 10**U(-2, 2), jumping across block edges."""
    h, w = shape
    n = h * w
    mask = rng.random(n) < frac
    a = mask * 1.0 + delta
    if jump:
        blocks = 10.0 ** rng.uniform(-2, 2, (2, (h + 3) // 4, (w + 3) // 4))
        c = np.kron(blocks, np.ones((1, 4, 4)))[:, :h, :w]
        wx, wy = c[0].ravel(), c[1].ravel()
    else:
        wx = rng.uniform(0.5, 2.0, n)
        wy = rng.uniform(0.5, 2.0, n)
    return grid_system(shape, a, wx, wy)


def biharmonic_system(shape, rng):
    """13-point: delta I + diag(mask) + L^T L with L the 5-point Laplacian."""
    Dx, Dy = gradient(shape)
    L = Dx.T @ Dx + Dy.T @ Dy
    n = shape[0] * shape[1]
    mask = rng.random(n) < 0.05
    return sp.csr_array(sp.diags(1e-2 + mask * 1.0) + L.T @ L)


# --------------------------------------------------------------------------
# structure
# --------------------------------------------------------------------------
@pytest.mark.parametrize("shape", [(7, 9), (8, 10), (1, 9), (9, 1), (2, 2), (33, 47)])
def test_bilinear_prolongation_is_kron_of_1d_interpolation(shape):
    rng = np.random.default_rng(0)
    A = random_system(shape, rng)
    mg = GridMultigrid(A, shape, max_coarse=1)
    P = mg.levels[0].P.toarray()
    expected = np.kron(linear_interpolation_1d(shape[0]), linear_interpolation_1d(shape[1]))
    np.testing.assert_array_equal(P, expected)
    # applied matrix-free, one axis at a time: same products as the dense matrix
    x = rng.standard_normal(expected.shape[1])
    r = rng.standard_normal(expected.shape[0])
    np.testing.assert_allclose(mg.levels[0].P @ x, expected @ x, atol=1e-14)
    np.testing.assert_allclose(mg.levels[0].P.T @ r, expected.T @ r, atol=1e-13)
    # the V-cycle's in-place form: out += P x, by slicing
    np.testing.assert_allclose(mg.levels[0].P.add_prolonged(r.copy(), x), r + expected @ x, atol=1e-14)


@pytest.fixture(params=["kept", "read back"])
def stencil_path(request, set_limits):
    """Both set-up paths: stencils kept as arrays (small grids) or read back from the CSR class by class (large)."""
    import sparsedepth.linalg.multigrid.hierarchy as multigrid

    if request.param == "read back":
        set_limits(keep_stencil_pixels=0)
    return request.param


@pytest.mark.parametrize("interpolation", ["bilinear", "operator"])
@pytest.mark.parametrize("shape", [(7, 9), (8, 10), (1, 12), (12, 1), (2, 2), (33, 47)])
def test_galerkin_equals_scipy_triple_product(shape, interpolation, stencil_path):
    rng = np.random.default_rng(1)
    A = random_system(shape, rng, jump=True)
    mg = GridMultigrid(A, shape, max_coarse=1, interpolation=interpolation, **DOUBLE)
    assert len(mg.levels) >= 2
    for fine, coarse in zip(mg.levels[:-1], mg.levels[1:]):
        P = sp.csr_array(fine.P if sp.issparse(fine.P) else fine.P.tocsr())
        expected = (P.T @ fine.A @ P).toarray()
        # rounding is relative to the terms summed, not to the (cancelled) result
        scale = (abs(P).T @ abs(fine.A) @ abs(P)).toarray()
        np.testing.assert_allclose(coarse.A.toarray(), expected, rtol=0,
                                   atol=1e-13 * scale.max())


@pytest.mark.parametrize("interpolation", ["bilinear", "operator"])
@pytest.mark.parametrize("shape", [(9, 11), (10, 12)])
def test_galerkin_of_13_point_operator(shape, interpolation, stencil_path):
    A = biharmonic_system(shape, np.random.default_rng(2))
    mg = GridMultigrid(A, shape, max_coarse=1, interpolation=interpolation, **DOUBLE)
    for fine, coarse in zip(mg.levels[:-1], mg.levels[1:]):
        P = sp.csr_array(fine.P if sp.issparse(fine.P) else fine.P.tocsr())
        expected = (P.T @ fine.A @ P).toarray()
        np.testing.assert_allclose(coarse.A.toarray(), expected, rtol=0,
                                   atol=1e-13 * np.abs(expected).max())


def test_operator_interpolation_reproduces_constants_without_reaction():
    shape = (9, 12)
    rng = np.random.default_rng(3)
    n = shape[0] * shape[1]
    A = grid_system(shape, 0.0, 10.0 ** rng.uniform(-3, 3, n),
                    10.0 ** rng.uniform(-3, 3, n))
    mg = GridMultigrid(A, shape, max_coarse=1, interpolation="operator", **DOUBLE)
    P = mg.levels[0].P
    np.testing.assert_allclose(P @ np.ones(P.shape[1]), 1.0, rtol=1e-10)


def test_coarse_grid_shapes_halve_with_ceiling():
    A = random_system((33, 47), np.random.default_rng(4))
    mg = GridMultigrid(A, (33, 47), max_coarse=1)
    shapes = [lvl.shape for lvl in mg.levels]
    assert shapes == [(33, 47), (17, 24), (9, 12), (5, 6), (3, 3), (2, 2), (1, 1)]


def test_grid_stencil_literal():
    A = grid_system((2, 3), 0.5, 1.0, 2.0)
    offsets, S = grid_stencil(A, (2, 3))
    assert offsets == [(-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)]
    centre = np.array([[0.5 + 1 + 2, 0.5 + 2 + 2, 0.5 + 1 + 2],
                       [0.5 + 1 + 2, 0.5 + 2 + 2, 0.5 + 1 + 2]])
    np.testing.assert_allclose(S[2], centre)
    np.testing.assert_allclose(S[0], [[0, 0, 0], [-2, -2, -2]])
    np.testing.assert_allclose(S[3], [[-1, -1, 0], [-1, -1, 0]])


# --------------------------------------------------------------------------
# the V-cycle as a preconditioner
# --------------------------------------------------------------------------
@pytest.mark.parametrize("smoother,sweeps", [("gauss_seidel", 1), ("gauss_seidel", 2),
                                             ("jacobi", 1)])
@pytest.mark.parametrize("interpolation", ["bilinear", "operator"])
def test_vcycle_is_symmetric_positive_definite(interpolation, smoother, sweeps):
    shape = (33, 47)
    rng = np.random.default_rng(5)
    A = random_system(shape, rng, jump=True)
    mg = GridMultigrid(A, shape, interpolation=interpolation, smoother=smoother,
                       sweeps=sweeps, max_coarse=16, **DOUBLE)
    M = mg.aspreconditioner()
    for _ in range(3):
        u, v = rng.standard_normal((2, A.shape[0]))
        Mu, Mv = M @ u, M @ v
        assert abs(u @ Mv - Mu @ v) <= 1e-11 * np.linalg.norm(u) * np.linalg.norm(Mv)
        assert u @ Mu > 0


@pytest.mark.parametrize("interpolation", ["bilinear", "operator"])
def test_vcycle_symmetric_for_13_point_operator(interpolation):
    shape = (21, 26)
    rng = np.random.default_rng(6)
    A = biharmonic_system(shape, rng)
    mg = GridMultigrid(A, shape, max_coarse=16, interpolation=interpolation, **DOUBLE)
    u, v = rng.standard_normal((2, A.shape[0]))
    Mu, Mv = mg.vcycle(u), mg.vcycle(v)
    assert abs(u @ Mv - Mu @ v) <= 1e-11 * np.linalg.norm(u) * np.linalg.norm(Mv)
    assert u @ Mu > 0


@pytest.mark.parametrize("interpolation", ["bilinear", "operator"])
@pytest.mark.parametrize("shape", [(33, 47), (1, 50), (50, 1), (2, 2), (1, 1), (16, 17)])
def test_pcg_matches_spsolve(shape, interpolation):
    rng = np.random.default_rng(7)
    A = random_system(shape, rng, jump=True)
    b = rng.standard_normal(A.shape[0])
    x, info = solve_spd(A, b, shape, rtol=1e-12, preconditioner="grid",
                        interpolation=interpolation, max_coarse=1)
    assert info.converged
    assert info.relative_residual < 1e-10
    x_ref = spla.spsolve(sp.csc_matrix(A), b)
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-8 * np.abs(x_ref).max())


def test_pcg_13_point_matches_spsolve():
    shape = (24, 31)
    rng = np.random.default_rng(8)
    A = biharmonic_system(shape, rng)
    b = rng.standard_normal(A.shape[0])
    x, info = solve_spd(A, b, shape, rtol=1e-12, max_coarse=16)
    assert info.converged
    x_ref = spla.spsolve(sp.csc_matrix(A), b)
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-8 * np.abs(x_ref).max())


def _border_system(n):
    """n x n 5-point system with data on the border only (Dirichlet-like): condition number grows like n²."""
    border = np.zeros((n, n), dtype=bool)
    border[[0, -1], :] = border[:, [0, -1]] = True
    b = np.random.default_rng(9).standard_normal(n * n)
    return grid_system((n, n), border.ravel() * 1.0 + 1e-6, 1.0, 1.0), b


def test_iterations_bounded_as_grid_grows():
    """h-independence: multigrid-PCG needs about as many iterations on 257x257 as on 65x65, on a problem where
    Jacobi-PCG's count grows with the grid."""
    grid = []
    for n in (65, 257):
        A, b = _border_system(n)
        x, info = solve_spd(A, b, (n, n), rtol=1e-8, max_coarse=64)
        assert info.converged
        assert np.linalg.norm(b - A @ x) <= 1e-8 * np.linalg.norm(b)
        x_ref = spla.spsolve(sp.csc_matrix(A), b)
        np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-6 * np.abs(x_ref).max())
        grid.append(info.iterations)
    jacobi = []
    for n in (17, 65):  # Jacobi on smaller grids: its count on 257x257 is costly to reach
        A, b = _border_system(n)
        _, info = solve_spd(A, b, (n, n), rtol=1e-8, preconditioner="jacobi", maxiter=10**5)
        assert info.converged
        jacobi.append(info.iterations)
    # loose bounds on purpose (rounding moves counts by an iteration or two): measured 7 and 7 with the grid
    # cycle, 56 and 202 with Jacobi (about 4x for a 4x finer grid, as sqrt(condition number) predicts)
    assert grid[1] <= 2 * grid[0], (grid, jacobi)
    assert jacobi[1] > 2 * jacobi[0], (grid, jacobi)  # the problem is not h-independent by itself
    assert jacobi[1] > 10 * grid[0], (grid, jacobi)  # both on 65x65


def test_stationary_vcycle_iteration_converges():
    shape = (40, 50)
    rng = np.random.default_rng(10)
    A = random_system(shape, rng)
    b = rng.standard_normal(A.shape[0])
    mg = GridMultigrid(A, shape)
    x, info = mg.solve(b, accel=None, rtol=1e-8, maxiter=60)
    assert info.converged
    assert info.residuals.shape == (info.iterations + 1,)
    assert np.linalg.norm(b - A @ x) <= 1e-8 * np.linalg.norm(b)
    # λ_min(A) >= delta = 1e-2, so ‖x − x*‖₂ <= ‖b − A x‖₂ / 1e-2
    x_ref = spla.spsolve(sp.csc_matrix(A), b)
    assert np.linalg.norm(x - x_ref) <= np.linalg.norm(b - A @ x) / 1e-2 + 1e-12 * np.linalg.norm(x_ref)
    # each cycle reduces the residual substantially: a contraction property of the cycle, not a count
    # (measured about 0.3 per cycle; a cycle with a broken smoother or coarse correction contracts by > 0.9)
    assert info.residuals[-1] / info.residuals[0] < 0.5 ** info.iterations


# --------------------------------------------------------------------------
# update()
# --------------------------------------------------------------------------
@pytest.mark.parametrize("interpolation", ["bilinear", "operator"])
def test_update_equals_fresh_build(interpolation):
    shape = (37, 42)
    rng = np.random.default_rng(11)
    A1 = random_system(shape, rng, jump=True)
    A2 = random_system(shape, rng, jump=True)
    mg = GridMultigrid(A1, shape, interpolation=interpolation, max_coarse=8)
    before = [lvl.A.data.copy() for lvl in mg.levels[1:]]
    assert mg.update(A2) is mg
    fresh = GridMultigrid(A2, shape, interpolation=interpolation, max_coarse=8)
    assert len(mg.levels) == len(fresh.levels)
    for old, new, data in zip(mg.levels, fresh.levels, [None] + before):
        assert old.shape == new.shape
        np.testing.assert_array_equal(old.A.indptr, new.A.indptr)
        np.testing.assert_array_equal(old.A.indices, new.A.indices)
        np.testing.assert_allclose(old.A.data, new.A.data, rtol=1e-13,
                                   atol=1e-13 * np.abs(new.A.data).max())
        if data is not None:
            assert not np.allclose(old.A.data, data)
        if new.P is not None:
            np.testing.assert_allclose(old.P.toarray(), new.P.toarray(), rtol=1e-13,
                                       atol=1e-15)
    u = rng.standard_normal(A2.shape[0])
    np.testing.assert_allclose(mg.vcycle(u), fresh.vcycle(u), rtol=1e-10, atol=1e-12)


def test_update_with_wider_stencil_rebuilds():
    shape = (20, 22)
    rng = np.random.default_rng(12)
    A1 = random_system(shape, rng)
    mg = GridMultigrid(A1, shape)
    A2 = biharmonic_system(shape, rng)
    mg.update(A2)
    fresh = GridMultigrid(A2, shape)
    u = rng.standard_normal(A2.shape[0])
    np.testing.assert_allclose(mg.vcycle(u), fresh.vcycle(u), rtol=1e-10, atol=1e-12)


def test_update_rejects_other_grid():
    mg = GridMultigrid(random_system((10, 12), np.random.default_rng(13)), (10, 12))
    with pytest.raises(ValueError, match="shape"):
        mg.update(random_system((12, 10), np.random.default_rng(13)).tocsr()[:100, :100])


# --------------------------------------------------------------------------
# solve_spd
# --------------------------------------------------------------------------
@pytest.mark.parametrize("preconditioner", ["grid", "amg", "sa", "jacobi", "none"])
def test_solve_spd_preconditioners(preconditioner):
    shape = (24, 30)
    rng = np.random.default_rng(14)
    A = random_system(shape, rng)
    b = rng.standard_normal(shape)
    x, info = solve_spd(A, b, shape, rtol=1e-10, preconditioner=preconditioner)
    assert isinstance(info, SolveInfo)
    assert info.converged and info.status == 0 and info.message == "converged"
    assert x.shape == shape
    assert info.residuals.shape == (info.iterations + 1,)
    assert info.residuals[0] == pytest.approx(np.linalg.norm(b))
    assert info.relative_residual < 1e-9
    assert info.preconditioner == preconditioner


def test_solve_spd_reuses_hierarchy_and_linear_operator():
    shape = (24, 30)
    rng = np.random.default_rng(15)
    A = random_system(shape, rng)
    b = rng.standard_normal(A.shape[0])
    mg = grid_multigrid(A, shape)
    x1, info1 = solve_spd(A, b, shape, preconditioner=mg)
    x2, info2 = solve_spd(A, b, shape, preconditioner=mg.aspreconditioner())
    assert info1.converged and info2.converged
    assert info1.preconditioner == "GridMultigrid"
    # the same preconditioner either way: the same PCG residual history (its early, large entries to 1e-6;
    # rounding may move the last ones and the stopping iteration) ...
    k = min(len(info1.residuals), len(info2.residuals))
    assert k >= 3
    np.testing.assert_allclose(info1.residuals[:k], info2.residuals[:k], rtol=1e-6, atol=1e-10 * info1.residuals[0])
    # ... and both are the solution: λ_min(A) >= delta = 1e-2, so ‖x − x*‖₂ <= ‖b − A x‖₂ / 1e-2
    x_ref = spla.spsolve(sp.csc_matrix(A), b)
    for x in (x1, x2):
        assert np.linalg.norm(x - x_ref) <= np.linalg.norm(b - A @ x) / 1e-2 + 1e-12 * np.linalg.norm(x_ref)


def test_solve_spd_initial_residual_and_inputs_untouched():
    shape = (20, 25)
    rng = np.random.default_rng(16)
    A = random_system(shape, rng)
    A_copy = A.copy()
    b = rng.standard_normal(A.shape[0])
    x0 = rng.standard_normal(A.shape[0])
    x0_copy = x0.copy()
    x, info = solve_spd(A, b, shape, x0=x0)
    assert info.residuals[0] == pytest.approx(np.linalg.norm(b - A @ x0))
    np.testing.assert_array_equal(x0, x0_copy)
    np.testing.assert_array_equal(A.data, A_copy.data)
    assert info.converged


def test_solve_spd_zero_rhs():
    shape = (10, 10)
    A = random_system(shape, np.random.default_rng(17))
    x, info = solve_spd(A, np.zeros(100), shape)
    assert info.converged and info.iterations == 0  # exact by construction: b = 0 is solved before iterating
    np.testing.assert_array_equal(x, 0.0)


def test_solve_spd_callback_can_stop():
    shape = (30, 30)
    rng = np.random.default_rng(18)
    A = random_system(shape, rng)
    b = rng.standard_normal(A.shape[0])
    seen = []

    def stop_after_two(xk):
        seen.append(xk)
        if len(seen) == 2:
            raise StopIteration

    x, info = solve_spd(A, b, shape, preconditioner="jacobi", callback=stop_after_two)
    assert not info.converged
    assert info.status == -1 and info.message == "stopped by callback"
    assert info.iterations == 2  # set by the callback, not by rounding (Jacobi-PCG needs far more here)
    np.testing.assert_array_equal(x, seen[-1])


def test_solve_spd_reports_non_convergence():
    shape = (30, 30)
    rng = np.random.default_rng(19)
    A = random_system(shape, rng, delta=1e-4)
    b = rng.standard_normal(A.shape[0])
    _, info = solve_spd(A, b, shape, preconditioner="none", maxiter=3)
    assert not info.converged and info.status > 0
    assert info.iterations == 3  # the limit itself: 3 plain CG steps are far from rtol on this system


def test_singular_neumann_problem_uses_pseudo_inverse():
    shape = (8, 8)
    A = grid_system(shape, 0.0, 1.0, 1.0)  # constants in the null space
    mg = GridMultigrid(A, shape, max_coarse=4)
    assert "pinv" in repr(mg)
    rng = np.random.default_rng(20)
    b = rng.standard_normal(64)
    b -= b.mean()  # consistent right-hand side
    x, info = solve_spd(A, b, shape, preconditioner=mg, rtol=1e-10)
    assert info.converged
    assert np.linalg.norm(b - A @ x) <= 1e-9 * np.linalg.norm(b)


def test_to_pyamg_multilevel_solver():
    shape = (33, 40)
    rng = np.random.default_rng(21)
    A = random_system(shape, rng)
    b = rng.standard_normal(A.shape[0])
    mg = GridMultigrid(A, shape, max_coarse=32, **DOUBLE)
    ml = mg.to_pyamg()
    assert len(ml.levels) == len(mg.levels)
    assert ml.operator_complexity() == pytest.approx(mg.operator_complexity())
    residuals = []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        x = ml.solve(b, tol=1e-10, accel="cg", residuals=residuals)
    assert np.linalg.norm(b - A @ x) <= 1e-9 * np.linalg.norm(b)
    np.testing.assert_allclose(ml.aspreconditioner() @ b, mg.vcycle(b), rtol=1e-12)
    # a float32 hierarchy converts: pyamg's cycle is then the float64 form of ours
    single = GridMultigrid(A, shape, max_coarse=32)
    assert single.coarse_dtype == np.float32
    ml = single.to_pyamg()
    assert all(level.A.dtype == np.float64 for level in ml.levels)
    expected = mg.vcycle(b)
    np.testing.assert_allclose(ml.aspreconditioner() @ b, expected, rtol=0, atol=1e-5 * np.abs(expected).max())


def test_repr_lists_levels_and_nonzeros():
    A = random_system((33, 47), np.random.default_rng(22))
    mg = GridMultigrid(A, (33, 47), max_coarse=100)
    text = repr(mg)
    assert len(mg.levels) == 4
    assert "Number of Levels:     4" in text
    assert "Operator Complexity" in text
    for lvl in mg.levels:
        assert str(lvl.A.nnz) in text


# --------------------------------------------------------------------------
# input checks: one pytest.raises per raise
# --------------------------------------------------------------------------
def test_wrong_shape_is_rejected():
    A = random_system((10, 12), np.random.default_rng(23))
    with pytest.raises(ValueError, match=r"needs \(100, 100\)"):
        GridMultigrid(A, (10, 10))


def test_transposed_shape_is_not_a_grid_operator():
    A = random_system((10, 12), np.random.default_rng(24))
    with pytest.raises(ValueError, match="stencil of radius"):
        GridMultigrid(A, (12, 10))


def test_bad_shape_argument():
    A = random_system((4, 4), np.random.default_rng(25))
    with pytest.raises(ValueError, match="pair"):
        GridMultigrid(A, 16)


def test_dense_input_rejected():
    with pytest.raises(TypeError, match="scipy.sparse"):
        GridMultigrid(np.eye(4), (2, 2))


def test_unknown_options_rejected():
    A = random_system((4, 4), np.random.default_rng(26))
    with pytest.raises(ValueError, match="interpolation"):
        GridMultigrid(A, (4, 4), interpolation="cubic")
    with pytest.raises(ValueError, match="smoother"):
        GridMultigrid(A, (4, 4), smoother="sor")
    with pytest.raises(ValueError, match="preconditioner"):
        solve_spd(A, np.ones(16), (4, 4), preconditioner="ilu")
    with pytest.raises(TypeError, match="no options"):
        solve_spd(A, np.ones(16), (4, 4), preconditioner="jacobi", sweeps=2)


def test_operator_interpolation_of_a_wide_stencil_reads_it_collapsed_to_radius_one():
    """Each coupling of a 13-point stencil is moved to the neighbour in its direction; row sums are kept."""
    from sparsedepth.linalg.multigrid.stencils import CollapsedSource, StencilSource

    shape = (7, 8)
    A = biharmonic_system(shape, np.random.default_rng(27))
    offsets, S = grid_stencil(A, shape)
    assert max(max(abs(dy), abs(dx)) for dy, dx in offsets) == 2
    collapsed = CollapsedSource(StencilSource(offsets, shape, array=S))
    assert collapsed.offsets == [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    whole = np.zeros((9,) + shape)
    for (dy, dx), image in zip(offsets, S):  # the rule written out: (±2, 0) -> (±1, 0), (1, -1) stays, ...
        whole[collapsed.offsets.index((int(np.sign(dy)), int(np.sign(dx))))] += image
    for py, px in ((0, 0), (0, 1), (1, 0), (1, 1)):
        np.testing.assert_array_equal(collapsed.parity_class(py, px), whole[:, py::2, px::2])
    np.testing.assert_allclose(whole.sum(axis=0), S.sum(axis=0), rtol=0, atol=1e-12)
    assert GridMultigrid(A, shape, interpolation="auto", max_coarse=1, **DOUBLE).interpolation == "bilinear"
    mg = GridMultigrid(A, shape, interpolation="operator", max_coarse=1, **DOUBLE)
    x = np.random.default_rng(28).standard_normal(A.shape[0])
    solution, info = mg.solve(A @ x, rtol=1e-12)
    assert info.converged
    np.testing.assert_allclose(solution, x, rtol=0, atol=1e-8 * np.abs(x).max())


def test_rhs_size_checked():
    A = random_system((4, 4), np.random.default_rng(28))
    with pytest.raises(ValueError, match="`b` has 15 entries"):
        solve_spd(A, np.ones(15), (4, 4))


def test_single_precision_coarse_levels_round_the_double_ones_and_converge():
    shape = (40, 56)
    rng = np.random.default_rng(11)
    A = random_system(shape, rng, jump=True)
    double = GridMultigrid(A, shape, coarse_precision="double")
    single = GridMultigrid(A, shape, coarse_precision="single")
    assert single.levels[0].A.dtype == np.float64  # the fine operator is never rounded
    for a, b in zip(double.levels[1:], single.levels[1:]):
        assert b.A.dtype == np.float32
        scale = abs(a.A).max()
        np.testing.assert_allclose(b.A.toarray(), a.A.toarray(), rtol=0, atol=1e-6 * scale)
    rhs = rng.standard_normal(A.shape[0])
    x, info = single.solve(rhs, rtol=1e-10)
    assert info.converged
    assert np.linalg.norm(rhs - A @ x) <= 1e-10 * np.linalg.norm(rhs)
    with pytest.raises(ValueError, match="coarse_precision"):
        GridMultigrid(A, shape, coarse_precision="half")


def test_single_precision_cycle_rounds_the_double_one_and_solves_to_double_accuracy(set_limits):
    import sparsedepth.linalg.multigrid.hierarchy as multigrid

    shape = (40, 56)
    rng = np.random.default_rng(12)
    A = random_system(shape, rng, jump=True).tocsr()
    double = GridMultigrid(A, shape, **DOUBLE)
    single = GridMultigrid(A, shape)  # below 2**21 pixels: the whole cycle in float32
    assert single.fine_dtype == np.float32 and single.coarse_dtype == np.float32
    assert single.levels[0].A is A  # the operator itself is kept as given
    # the float32 copy of the fine values shares A's index arrays
    assert single._fine_cycle_A.dtype == np.float32
    assert np.shares_memory(single._fine_cycle_A.indices, A.indices)
    r = rng.standard_normal(A.shape[0])
    expected = double.vcycle(r)
    got = single.vcycle(r)
    assert got.dtype == np.float64
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-5 * np.abs(expected).max())
    assert np.abs(got - expected).max() > 0  # it is really another precision
    # the Jacobi smoother and operator-dependent interpolation in float32 too
    for options in (dict(smoother="jacobi"), dict(interpolation="operator")):
        want = GridMultigrid(A, shape, **options, **DOUBLE).vcycle(r)
        np.testing.assert_allclose(GridMultigrid(A, shape, **options).vcycle(r), want, rtol=0,
                                   atol=1e-5 * np.abs(want).max())
    # the residuals stay float64: PCG with the float32 cycle goes far below float32 rounding and reaches the
    # solution of the float64 cycle's PCG (iteration counts are not compared: rounding moves them by CPU)
    x, info = single.solve(r, rtol=1e-11)
    x_double, info_double = double.solve(r, rtol=1e-11)
    assert info.converged and info_double.converged
    assert np.linalg.norm(r - A @ x) <= 1e-11 * np.linalg.norm(r)
    x_ref = spla.spsolve(A.tocsc(), r)
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-8 * np.abs(x).max())
    # λ_min(A) >= delta = 1e-2, so ‖x − x*‖₂ <= ‖r − A x‖₂ / 1e-2 for either
    for y in (x, x_double):
        assert np.linalg.norm(y - x_ref) <= np.linalg.norm(r - A @ y) / 1e-2 + 1e-12 * np.linalg.norm(x_ref)
    np.testing.assert_allclose(x, x_double, rtol=0, atol=1e-8 * np.abs(x_double).max())
    # and so does the plain V-cycle iteration (iterative refinement), on a system without jumps
    B = random_system(shape, rng).tocsr()
    x, info = GridMultigrid(B, shape).solve(r, rtol=1e-11, accel=None)
    assert info.converged
    np.testing.assert_allclose(x, spla.spsolve(B.tocsc(), r), rtol=0, atol=1e-9 * np.abs(x).max())
    # operators with too many non-zeros for a float32 copy are smoothed in float64 (no copy) on the fine level;
    # their coarse levels are float32 only on large grids
    set_limits(single_fine_values=A.nnz - 1)
    no_copy = GridMultigrid(A, shape)
    assert no_copy.fine_dtype == np.float64 and no_copy.coarse_dtype == np.float64
    assert no_copy._fine_cycle_A is A
    np.testing.assert_array_equal(no_copy.vcycle(r), expected)
    set_limits(single_coarse_pixels=100)
    large = GridMultigrid(A, shape)
    assert large.fine_dtype == np.float64 and large.coarse_dtype == np.float32
    assert large._fine_cycle_A is A
    np.testing.assert_allclose(large.vcycle(r), expected, rtol=0, atol=1e-5 * np.abs(expected).max())
    with pytest.raises(ValueError, match="fine_precision"):
        GridMultigrid(A, shape, fine_precision="half")


@pytest.mark.parametrize("shape", [(7, 9), (8, 10), (1, 6), (6, 1), (2, 2), (5, 4)])
def test_operator_prolongation_by_classes_equals_its_dense_matrix(shape):
    """P x, out += P x and Pᵀ r of the class-wise operator-dependent P, against a matrix built pixel by pixel."""
    rng = np.random.default_rng(5)
    A = random_system(shape, rng, jump=True)
    mg = GridMultigrid(A, shape, max_coarse=1, interpolation="operator")
    for fine in mg.levels[:-1]:
        P = fine.P
        (h, w), (hc, wc) = P.fine_shape, P.coarse_shape
        weights = P.dense_weights()
        dense = np.zeros(P.shape)
        for y in range(h):  # P[(y, x), (y//2 + ey, x//2 + ex)] = weights[ey, ex, y, x]
            for x in range(w):
                for ey in range(2):
                    for ex in range(2):
                        Y, X = y // 2 + ey, x // 2 + ex
                        if weights[ey, ex, y, x] != 0:
                            assert Y < hc and X < wc  # no weight on a parent outside the coarse grid
                            dense[y * w + x, Y * wc + X] = weights[ey, ex, y, x]
        for y in range(0, h, 2):  # a pixel at a coarse point copies it
            for x in range(0, w, 2):
                expected_row = np.zeros(P.shape[1])
                expected_row[(y // 2) * wc + x // 2] = 1.0
                np.testing.assert_array_equal(dense[y * w + x], expected_row)
        x = rng.standard_normal(P.shape[1])
        out = rng.standard_normal(P.shape[0])
        np.testing.assert_allclose(P @ x, dense @ x, atol=1e-14)
        np.testing.assert_allclose(P.add_prolonged(out.copy(), x), out + dense @ x, atol=1e-14)
        np.testing.assert_allclose(P.T @ out, dense.T @ out, atol=1e-13)
        np.testing.assert_array_equal(P.toarray(), dense)


@pytest.mark.parametrize("shape", [(1, 5), (2, 3), (7, 6), (12, 9), (13, 16)])
@pytest.mark.parametrize("band_pixels", [1, 20, 1 << 16], ids=["two-row bands", "a few rows", "one band"])
def test_separable_prolongation_band_by_band_equals_its_csr_form(set_limits, shape, band_pixels):
    """P x and Pᵀ r, a band of rows at a time: the same bits for every band height, and the CSR product."""
    from sparsedepth.linalg.multigrid import transfer

    P = transfer.SeparableProlongation(shape)
    csr = P.tocsr()
    rng = np.random.default_rng(9)
    for dtype in (np.float64, np.float32):
        x = rng.standard_normal(P.shape[1]).astype(dtype)
        r = rng.standard_normal(P.shape[0]).astype(dtype)
        out = rng.standard_normal(P.shape[0]).astype(dtype)
        whole = (P.add_prolonged(out.copy(), x), P.T @ r)
        set_limits(transfer_band_pixels=band_pixels)
        banded = (P.add_prolonged(out.copy(), x), P.T @ r)
        set_limits(transfer_band_pixels=1 << 16)
        for ours, ref in zip(banded, whole):
            assert ours.dtype == dtype
            np.testing.assert_array_equal(ours, ref)
        tol = 1e-5 if dtype == np.float32 else 1e-12
        np.testing.assert_allclose(banded[0], out + csr @ x, rtol=tol, atol=tol)
        np.testing.assert_allclose(banded[1], csr.T @ r, rtol=tol, atol=tol)


@pytest.mark.parametrize("shape", [(1, 5), (2, 3), (7, 6), (12, 9), (13, 16)])
def test_restriction_of_rows_handed_out_band_by_band_equals_the_whole_product(set_limits, shape):
    from sparsedepth.linalg.multigrid import transfer

    set_limits(transfer_band_pixels=20)
    P = transfer.SeparableProlongation(shape)
    rng = np.random.default_rng(10)
    for dtype in (np.float64, np.float32):
        r = rng.standard_normal(shape).astype(dtype)
        read = []

        def rows_of(y0, y1):
            read.append((y0, y1))
            return r[y0:y1].copy()

        ours = P.restrict_rows(rows_of, dtype)
        assert ours.dtype == dtype and len(read) > (1 if shape[0] > 4 else 0)
        np.testing.assert_array_equal(ours, P.T @ r.ravel())


@pytest.mark.parametrize("shape", [(1, 5), (4, 1), (2, 3), (7, 8), (8, 7)])
def test_operator_weights_per_class_equal_the_dense_weights(shape):
    """Class storage (padded once): every class, padding and the prolongation read the weights the dense form has."""
    from sparsedepth.linalg.multigrid.interpolation import operator_weights
    from sparsedepth.linalg.multigrid.stencils import StencilSource, grid_stencil
    from sparsedepth.linalg.multigrid.transfer import ClassProlongation

    rng = np.random.default_rng(3)
    A = random_system(shape, rng, jump=True)
    offsets, S = grid_stencil(A, shape)
    weights = operator_weights(offsets, StencilSource(offsets, shape, array=S), shape)
    dense = ClassProlongation(weights, shape, np.float64).dense_weights()
    h, w = shape
    for py in range(min(h, 2)):
        for px in range(min(w, 2)):
            np.testing.assert_array_equal(weights.class_weights(py, px), dense[:, :, py::2, px::2])
            for ey in (0, 1):
                for ex in (0, 1):
                    np.testing.assert_array_equal(weights.cls(ey, ex, py, px), dense[ey, ex, py::2, px::2])
            for pad in (0, 1, 2):
                expected = np.pad(dense[:, :, py::2, px::2], ((0, 0), (0, 0), (pad, pad + 1), (pad, pad + 1)))
                np.testing.assert_array_equal(weights.padded_cls(py, px, pad), expected)
