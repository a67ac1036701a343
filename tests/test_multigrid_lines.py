"""Line Gauss--Seidel smoothing of the fine level: block steps, symmetry, solves (against dense and direct algebra),
and the hierarchy of the default solve built with it."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import sparsedepth as sd
from sparsedepth.problem import CompletionProblem
from sparsedepth.grid.stencil import SymmetricStencil
from sparsedepth.linalg import pcg
from sparsedepth.linalg.multigrid import GridMultigrid, solve_spd
from sparsedepth.linalg.multigrid.smoothers import LineGaussSeidel, anisotropic_pixels, stencil_rows_product
from sparsedepth.solvers.quadratic import default_hierarchy

from conftest import DOUBLE, make_problem
from conftest import forward_difference_1d as _first_difference


def _second_difference(n):
    """Rows 1 .. n-2 of the 1-D second difference (Neumann: no rows at the ends), as an (n, n) matrix."""
    if n < 3:
        return sp.csr_matrix((n, n))
    D = sp.diags([np.ones(n - 2), -2 * np.ones(n - 2), np.ones(n - 2)], [0, 1, 2], shape=(n - 2, n))
    return sp.vstack([sp.csr_matrix((1, n)), D, sp.csr_matrix((1, n))]).tocsr()


def edge_system(shape, rng, *, strip=True):
    r"""A 25-point SPD system with jumping, direction-dependent weights.

    ``δ I + M + Σ_d D_dᵀ diag(w_d) D_d`` over the first differences along x and y, the second differences
    along x and y and the mixed difference ``D_x D_y``; the weights are constant on 4x4 blocks with values
    10**U(-2, 2), and with ``strip`` the weights across a one-pixel horizontal line (row H // 2 + 1) are 1e-4 of
    those along it (an image edge pair).
    """
    h, w = shape
    n = h * w
    Iy, Ix = sp.eye(h), sp.eye(w)
    Dx, Dy = sp.kron(Iy, _first_difference(w)), sp.kron(_first_difference(h), Ix)
    Dxx, Dyy = sp.kron(Iy, _second_difference(w)), sp.kron(_second_difference(h), Ix)
    ops = [Dx, Dy, Dxx, Dyy, Dx @ Dy]
    blocks = 10.0 ** rng.uniform(-2, 2, (len(ops), (h + 3) // 4, (w + 3) // 4))
    weights = np.kron(blocks, np.ones((1, 4, 4)))[:, :h, :w]
    if strip and h > 4:
        y = h // 2 + 1
        weights[[1, 3], y - 2:y + 1] *= 1e-4  # vertical differences touching row y
        weights[4, y - 1:y + 1] *= 1e-4
    mask = rng.random(n) < 0.05
    A = sp.diags(1e-3 + mask * 1.0)
    for D, wd in zip(ops, weights):
        A = A + D.T @ sp.diags(wd.ravel()) @ D
    return sp.csr_array(A)


def stencil_form(A, shape):
    """``(S, A_sym)``: the 25-point SymmetricStencil of ``(A + Aᵀ) / 2`` (read entry by entry) and that CSR matrix.

    The average makes the matrix exactly symmetric in floating point, so that both forms hold the same numbers.
    """
    h, w = shape
    A_sym = sp.csr_matrix((A + A.T) / 2)
    dense = A_sym.toarray()
    offsets = [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3)]
    upper = [o for o in offsets if o >= (0, 0)]
    images = np.zeros((len(upper), h, w))
    for k, (dy, dx) in enumerate(upper):
        for y in range(max(0, -dy), min(h, h - dy)):
            for x in range(max(0, -dx), min(w, w - dx)):
                images[k, y, x] = dense[y * w + x, (y + dy) * w + x + dx]
    return SymmetricStencil(offsets, images), A_sym


def dense_bands(A, shape):
    """``{offset: image}`` of the couplings ``A[(y, x), (y + dy, x + dx)]`` read entry by entry (0 outside)."""
    h, w = shape
    dense = A.toarray()
    bands = {}
    for dy, dx in ((0, 0), (0, 1), (0, 2), (1, 0), (2, 0)):
        image = np.zeros(shape)
        for y in range(h - dy):
            for x in range(w - dx):
                image[y, x] = dense[y * w + x, (y + dy) * w + x + dx]
        bands[dy, dx] = image
    return bands


def block_sets(shape, select=None):
    """The pixel sets of the six block steps, built from their definition (rows, then columns, y or x mod 3)."""
    h, w = shape
    yy, xx = np.mgrid[:h, :w]
    sets = []
    for axis, coord in ((0, yy), (1, xx)):
        for c in range(3):
            chosen = coord % 3 == c
            if select is not None:
                chosen &= select[axis]
            idx = np.flatnonzero(chosen.ravel())
            if idx.size:
                sets.append(idx)
    return sets


@pytest.mark.parametrize("selected", [False, True])
@pytest.mark.parametrize("shape", [(13, 17), (1, 9), (9, 1), (5, 5), (2, 2), (4, 1)])
def test_forward_sweep_is_block_gauss_seidel_over_lines(shape, selected):
    rng = np.random.default_rng(1)
    A = edge_system(shape, rng)
    anisotropy = 2.0 if selected else None
    select = anisotropic_pixels(dense_bands(A, shape), anisotropy) if selected else None
    b = rng.standard_normal(A.shape[0])
    x = rng.standard_normal(A.shape[0])
    expected = x.copy()
    dense = A.toarray()
    for idx in block_sets(shape, select):
        r = b[idx] - dense[idx] @ expected
        expected[idx] += np.linalg.solve(dense[np.ix_(idx, idx)], r)
    smoother = LineGaussSeidel(sp.csr_matrix(A), shape, anisotropy=anisotropy)
    smoother.forward(x, b)
    np.testing.assert_allclose(x, expected, rtol=1e-10, atol=1e-10 * np.abs(expected).max())


@pytest.mark.parametrize("shape", [(13, 17), (1, 9), (9, 1), (5, 5), (2, 2), (4, 1), (3, 2)])
def test_stencil_rows_product_is_the_csr_product(shape):
    rng = np.random.default_rng(6)
    S, A = stencil_form(edge_system(shape, rng), shape)
    x = rng.standard_normal(A.shape[0])
    idx = rng.permutation(A.shape[0])  # every pixel, the border ones included, in no particular order
    out = stencil_rows_product(S, idx, x, np.empty(idx.size))
    np.testing.assert_allclose(out, (A @ x)[idx], rtol=1e-13, atol=1e-13 * np.abs(A @ x).max())


@pytest.mark.parametrize("selected", [False, True])
@pytest.mark.parametrize("shape", [(13, 17), (1, 9), (9, 1), (5, 5), (2, 2), (4, 1)])
def test_stencil_form_sweeps_are_those_of_the_csr_form(shape, selected):
    rng = np.random.default_rng(7)
    S, A = stencil_form(edge_system(shape, rng), shape)
    anisotropy = 2.0 if selected else None
    b, x = rng.standard_normal((2, A.shape[0]))
    ours, ref = x.copy(), x.copy()
    on_stencil = LineGaussSeidel(S, shape, anisotropy=anisotropy)
    on_csr = LineGaussSeidel(A, shape, anisotropy=anisotropy)
    assert len(on_stencil.blocks) == len(on_csr.blocks)
    for sweep in ("forward", "forward", "backward"):
        getattr(on_stencil, sweep)(ours, b)
        getattr(on_csr, sweep)(ref, b)
        np.testing.assert_allclose(ours, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())


def test_backward_sweep_is_adjoint_of_forward_in_the_energy_inner_product():
    # error propagation E of the forward sweep and E* of the backward one: <E u, v>_A = <u, E* v>_A
    shape = (14, 11)
    rng = np.random.default_rng(2)
    A = sp.csr_matrix(edge_system(shape, rng))
    smoother = LineGaussSeidel(A, shape, anisotropy=2.0)
    zero = np.zeros(A.shape[0])

    def forward_error(u):
        e = u.copy()
        smoother.forward(e, zero)
        return e

    def backward_error(u):
        e = u.copy()
        smoother.backward(e, zero)
        return e

    u, v = rng.standard_normal((2, A.shape[0]))
    left = forward_error(u) @ (A @ v)
    right = u @ (A @ backward_error(v))
    assert abs(left - right) <= 1e-10 * abs(left)


@pytest.mark.parametrize("line_anisotropy", [None, 4.0])
def test_vcycle_with_line_smoothing_is_symmetric_positive_definite(line_anisotropy):
    shape = (29, 37)
    rng = np.random.default_rng(3)
    A = edge_system(shape, rng)
    mg = GridMultigrid(A, shape, smoother="line_gauss_seidel", line_anisotropy=line_anisotropy, max_coarse=16,
                       **DOUBLE)
    for _ in range(3):
        u, v = rng.standard_normal((2, A.shape[0]))
        Mu, Mv = mg.vcycle(u), mg.vcycle(v)
        assert abs(u @ Mv - Mu @ v) <= 1e-11 * np.linalg.norm(u) * np.linalg.norm(Mv)
        assert u @ Mu > 0


@pytest.mark.parametrize("shape", [(29, 37), (30, 2), (1, 40), (16, 17)])
@pytest.mark.parametrize("precision", ["double", "auto"])
def test_pcg_with_line_smoothing_matches_spsolve(shape, precision):
    rng = np.random.default_rng(4)
    A = edge_system(shape, rng)
    b = rng.standard_normal(A.shape[0])
    x, info = solve_spd(A, b, shape, rtol=1e-11, preconditioner="grid", smoother="line_gauss_seidel", max_coarse=4,
                        fine_precision=precision, coarse_precision=precision)
    assert info.converged
    x_ref = spla.spsolve(sp.csc_matrix(A), b)
    # condition numbers up to 1e6: a relative residual of 1e-11 leaves at most ~1e-5 of the solution
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-5 * np.abs(x_ref).max())


@pytest.mark.parametrize("shape", [(29, 37), (30, 2), (1, 40), (16, 17)])
def test_vcycle_and_pcg_with_line_smoothing_of_a_stencil_form(shape):
    rng = np.random.default_rng(8)
    S, A = stencil_form(edge_system(shape, rng), shape)
    mg = GridMultigrid(S, shape, smoother="line_gauss_seidel", max_coarse=4, **DOUBLE)
    assert mg._line.stencil is S  # the line steps gather from the stencil, no CSR rows
    u, v = rng.standard_normal((2, A.shape[0]))
    Mu, Mv = mg.vcycle(u), mg.vcycle(v)
    assert abs(u @ Mv - Mu @ v) <= 1e-11 * np.linalg.norm(u) * np.linalg.norm(Mv)
    assert u @ Mu > 0
    b = rng.standard_normal(A.shape[0])
    x, _, converged, _ = pcg(S, b, M=mg.aspreconditioner(), rtol=1e-11, maxiter=500)
    assert converged
    x_ref = spla.spsolve(sp.csc_matrix(A), b)
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-5 * np.abs(x_ref).max())


def test_anisotropic_pixels_of_a_strip():
    # weights across (y) 1e-3 of those along x for the differences touching rows 4..6 of a 5-point operator:
    # those rows' pixels are x-line pixels; elsewhere the operator is isotropic enough and none is chosen
    shape = (11, 9)
    h, w = shape
    wy = np.ones(shape)
    wy[3:7] = 1e-3  # the differences (y, y+1) for y = 3..6 touch rows 3..7
    Dx, Dy = sp.kron(sp.eye(h), _first_difference(w)), sp.kron(_first_difference(h), sp.eye(w))
    A = sp.csr_matrix(sp.eye(h * w) + Dx.T @ Dx + Dy.T @ sp.diags(wy.ravel()) @ Dy)
    along_x, along_y = anisotropic_pixels(dense_bands(A, shape), 4.0)
    assert not along_y.any()
    np.testing.assert_array_equal(np.flatnonzero(along_x.any(axis=1)), [4, 5, 6])
    assert along_x[4:7].all()


def test_line_options_checked():
    A = edge_system((8, 8), np.random.default_rng(5))
    with pytest.raises(ValueError, match="line_anisotropy"):
        GridMultigrid(A, (8, 8), smoother="line_gauss_seidel", line_anisotropy=0.5)
    with pytest.raises(ValueError, match="unknown smoother"):
        GridMultigrid(A, (8, 8), smoother="line")


# ----------------------------------------------------------------------------- the hierarchy of complete_depth
@pytest.mark.parametrize("form", ["csr", "stencil"])
def test_default_hierarchy_is_a_symmetric_preconditioner_reaching_spsolve(form):
    image, sparse, mask, _ = make_problem((61, 83), fraction=0.05, seed=4)
    problem = CompletionProblem(image, sparse, mask, weights=sd.DEFAULT_WEIGHTS, l1_smoothing=1e-6,
                                clip_to_observed=False)
    obj, coarse = problem.objective, problem.fill
    A, b, _ = obj.normal_equations(form=form)
    mg = default_hierarchy(A, obj.shape)
    rng = np.random.default_rng(0)
    u, v = rng.standard_normal((2, b.size))
    Mu, Mv = mg.vcycle(u), mg.vcycle(v)
    assert abs(u @ Mv - v @ Mu) <= 1e-5 * abs(u @ Mv)  # float32 cycle
    assert u @ Mu > 0 and v @ Mv > 0
    A_csr = A.tocsr() if form == "stencil" else A
    z_star = spla.spsolve(sp.csc_matrix(A_csr), b)
    x, _, converged, _ = pcg(A, b, x0=coarse.ravel(), M=mg.aspreconditioner(), rtol=1e-10, maxiter=200)
    assert converged
    assert np.linalg.norm(x - z_star) <= 1e-7 * np.linalg.norm(z_star)
