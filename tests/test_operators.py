import numpy as np
import pytest
import scipy.sparse as sp

from sparsedepth.grid.operators import (
    StencilOperator,
    forward_diff,
    gradient,
    gradient_stencil,
    hessian_operator,
    hessian_stencil,
    mixed_diff,
    second_diff,
)
from sparsedepth.grid.rowbands import row_bands, rows_per_band


@pytest.mark.parametrize("shape", [(1, 1), (1, 5), (6, 1), (4, 7), (9, 3)])
def test_forward_diff_matches_numpy(shape):
    rng = np.random.default_rng(1)
    z = rng.standard_normal(shape)
    dx = np.zeros(shape)
    dx[:, :-1] = np.diff(z, axis=1)
    dy = np.zeros(shape)
    dy[:-1, :] = np.diff(z, axis=0)
    np.testing.assert_allclose((forward_diff(shape, 1) @ z.ravel()).reshape(shape), dx, atol=1e-14)
    np.testing.assert_allclose((forward_diff(shape, 0) @ z.ravel()).reshape(shape), dy, atol=1e-14)
    g = gradient(shape) @ z.ravel()
    np.testing.assert_allclose(g, np.concatenate([dx.ravel(), dy.ravel()]), atol=1e-14)


def test_hand_made_3x3():
    Dx = forward_diff((2, 2), 1).toarray()
    expected = np.array([[-1, 1, 0, 0], [0, 0, 0, 0], [0, 0, -1, 1], [0, 0, 0, 0]], float)
    np.testing.assert_array_equal(Dx, expected)
    Dy = forward_diff((2, 2), 0).toarray()
    expected = np.array([[-1, 0, 1, 0], [0, -1, 0, 1], [0, 0, 0, 0], [0, 0, 0, 0]], float)
    np.testing.assert_array_equal(Dy, expected)


def test_adjoint_dot_test():
    shape = (7, 11)
    G = gradient(shape)
    rng = np.random.default_rng(2)
    u = rng.standard_normal(G.shape[1])
    v = rng.standard_normal(G.shape[0])
    assert np.isclose(v @ (G @ u), (G.T @ v) @ u, rtol=1e-12)


def test_laplacian_is_neumann_and_constant_in_kernel():
    shape = (5, 6)
    G = gradient(shape)
    L = (G.T @ G).toarray()
    np.testing.assert_allclose(L @ np.ones(30), 0, atol=1e-12)
    # corner pixel has two neighbours, interior four
    assert L[0, 0] == 2 and L[7, 7] == 4


def test_second_order_annihilates_affine_and_matches_numpy():
    shape = (6, 8)
    ii, jj = np.mgrid[0:6, 0:8].astype(float)
    ramp = 2.0 + 0.3 * ii - 0.7 * jj
    np.testing.assert_allclose(hessian_operator(shape) @ ramp.ravel(), 0, atol=1e-12)
    z = np.random.default_rng(3).standard_normal(shape)
    dxx = np.zeros(shape)
    dxx[:, 1:-1] = z[:, :-2] - 2 * z[:, 1:-1] + z[:, 2:]
    np.testing.assert_allclose((second_diff(shape, 1) @ z.ravel()).reshape(shape), dxx, atol=1e-13)
    dxy = np.zeros(shape)
    dxy[:-1, :-1] = z[1:, 1:] - z[1:, :-1] - z[:-1, 1:] + z[:-1, :-1]
    np.testing.assert_allclose((mixed_diff(shape) @ z.ravel()).reshape(shape), dxy, atol=1e-13)


def test_operators_are_cached_and_sparse():
    assert forward_diff((30, 40), 1) is forward_diff((30, 40), 1)
    assert sp.issparse(gradient((30, 40))) and gradient((30, 40)).nnz <= 4 * 30 * 40


@pytest.mark.parametrize("bad", [(0, 3), (3,), (2, 3, 4)])
def test_bad_shape(bad):
    with pytest.raises(ValueError, match="shape"):
        forward_diff(bad, 1)


SHAPES = [(1, 1), (1, 5), (6, 1), (2, 2), (4, 7), (9, 3), (2, 9)]


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("pair", [(gradient_stencil, gradient), (hessian_stencil, hessian_operator)])
def test_stencil_operator_equals_the_csr_operator(shape, pair):
    stencil_form, csr_form = pair
    K, C = stencil_form(shape), csr_form(shape)
    assert K.shape == C.shape
    assert abs(K.tocsr() - C).max() == 0 if C.nnz else K.tocsr().nnz == 0
    rng = np.random.default_rng(4)
    z, v = rng.standard_normal(C.shape[1]), rng.standard_normal(C.shape[0])
    np.testing.assert_allclose(K @ z, C @ z, atol=1e-13)
    np.testing.assert_allclose(K.T @ v, C.T @ v, atol=1e-13)
    assert np.isclose(v @ (K @ z), (K.T @ v) @ z, rtol=1e-12)  # dot test


@pytest.mark.parametrize("band_rows", [1, 2, 3])
@pytest.mark.parametrize("pair", [(gradient_stencil, gradient), (hessian_stencil, hessian_operator)])
def test_stencil_product_over_row_bands_equals_the_csr_product(set_limits, band_rows, pair):
    import sparsedepth.grid.operators as operators

    shape = (8, 5)
    set_limits(operator_band_values=band_rows * shape[1])
    stencil_form, csr_form = pair
    K, C = stencil_form(shape), csr_form(shape)
    z = np.random.default_rng(6).standard_normal(C.shape[1])
    out = np.full(C.shape[0], np.nan)  # every row written, also those outside the anchor regions
    n = shape[0] * shape[1]
    for b in range(len(K.blocks)):
        K.block_matvec(z, b, out=out[b * n:(b + 1) * n])
    np.testing.assert_allclose(out, C @ z, rtol=0, atol=1e-13)


@pytest.mark.parametrize("shape", [(3, 3), (5, 4), (7, 9), (2, 6)])
def test_normal_stencil_is_KT_diag_r_K(shape):
    rng = np.random.default_rng(5)
    K = hessian_stencil(shape)
    r = rng.random(K.shape[0])
    offsets = K.offsets()
    S = np.zeros((len(offsets),) + shape)
    K.add_normal_stencil(S, offsets, r, scale=0.3)
    expected = 0.3 * (K.tocsr().T @ sp.diags(r) @ K.tocsr()).toarray()
    H, W = shape
    got = np.zeros((H * W, H * W))
    for k, (dy, dx) in enumerate(offsets):  # the stencil definition, pixel by pixel
        for y in range(H):
            for x in range(W):
                if 0 <= y + dy < H and 0 <= x + dx < W:
                    got[y * W + x, (y + dy) * W + x + dx] = S[k, y, x]
    np.testing.assert_allclose(got, expected, atol=1e-14)


def test_stencil_operator_rejects_bad_vectors_and_blocks():
    K = gradient_stencil((3, 4))
    with pytest.raises(ValueError, match="length 12"):
        K @ np.zeros(11)
    with pytest.raises(ValueError, match="length 24"):
        K.T @ np.zeros(12)
    with pytest.raises(ValueError, match="at least one"):
        StencilOperator((3, 4), [])


@pytest.mark.parametrize("start, stop, rows", [(0, 7, 3), (2, 9, 2), (0, 5, 5), (0, 4, 9), (3, 3, 2), (4, 1, 2)])
def test_row_bands_cover_the_rows_once_in_order(start, stop, rows):
    bands = row_bands(start, stop, rows)
    covered = [y for band in bands for y in range(band.start, band.stop)]
    assert covered == list(range(start, stop))
    assert all(0 < band.stop - band.start <= rows for band in bands)
    assert all(band.stop - band.start == rows for band in bands[:-1])


@pytest.mark.parametrize("width, values, multiple, expected", [
    (10, 35, 1, 3), (10, 35, 2, 2), (10, 5, 1, 1), (10, 5, 2, 2), (0, 8, 1, 8), (7, 70, 4, 8), (7, 84, 4, 12)])
def test_rows_per_band(width, values, multiple, expected):
    assert rows_per_band(width, values, multiple=multiple) == expected
