"""The normal stencils of the grid operators against ``Kᵀ diag(w) K`` built independently with scipy.sparse.

:meth:`StencilOperator.add_normal_stencil` and :meth:`LocalLinearOperator.add_normal_stencil` write the
stencil of ``scale · Kᵀ diag(w) K`` directly, a band of rows at a time.  Here ``K`` is built from its
definition, one row per anchor pixel with explicit loops (for the local-linear operator one window at a time
with dense linear algebra), the product is formed by scipy.sparse, and the stencil is read back into a matrix
with loops, for both the full stencil and its stored half (offsets ``>= (0, 0)``).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from sparsedepth.grid.affinity import local_linear_operator
from sparsedepth.grid.operators import StencilOperator, gradient_stencil, hessian_stencil

#: Window shapes of the local-linear operator, written out (offsets from the anchor pixel, C order).
WINDOW_PIXELS = {
    "3x3": [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)],
    "cross": [(-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)],
    "2x2": [(0, 0), (0, 1), (1, 0), (1, 1)],
}


def _stencil_operator_by_loop(shape, blocks):
    """``K`` of a list of blocks of taps: row ``p`` of block ``b`` is ``Σ c z[p + o]`` if all taps are inside, else 0."""
    H, W = shape
    n = H * W
    rows, cols, vals = [], [], []
    for b, taps in enumerate(blocks):
        for y in range(H):
            for x in range(W):
                if all(0 <= y + dy < H and 0 <= x + dx < W for (dy, dx), _ in taps):
                    for (dy, dx), c in taps:
                        rows.append(b * n + y * W + x)
                        cols.append((y + dy) * W + x + dx)
                        vals.append(c)
    return sp.csr_matrix((vals, (rows, cols)), shape=(len(blocks) * n, n))


def _local_linear_by_loop(image, eps, window):
    """``K`` of the local-linear term, window by window: residual rows ``C z_w − X M Xᵀ z_w``, ridge rows ``√ε M Xᵀ z_w``."""
    H, W, C = image.shape
    n_pixels = H * W
    offsets = WINDOW_PIXELS[window]
    n = len(offsets)
    rows, cols, vals = [], [], []
    for y in range(H):
        for x in range(W):
            if not all(0 <= y + dy < H and 0 <= x + dx < W for dy, dx in offsets):
                continue
            idx = [(y + dy) * W + x + dx for dy, dx in offsets]
            X = image.reshape(n_pixels, C)[idx]
            X = X - X.mean(axis=0)
            M = np.linalg.inv(X.T @ X + eps * np.eye(C))
            fit = M @ X.T  # a = fit @ z_w
            residual = np.eye(n) - np.ones((n, n)) / n - X @ fit
            block_rows = np.vstack([residual, np.sqrt(eps) * fit])  # blocks 0 .. n - 1, then n .. n + C - 1
            for b in range(n + C):
                for k, column in enumerate(idx):
                    rows.append(b * n_pixels + y * W + x)
                    cols.append(column)
                    vals.append(block_rows[b, k])
    return sp.csr_matrix((vals, (rows, cols)), shape=((n + C) * n_pixels, n_pixels))


def _matrix_of_stencil(offsets, stencil, *, symmetric):
    """The dense matrix of stencil images, by loops (the stored half mirrored when ``symmetric``)."""
    _, H, W = stencil.shape
    A = np.zeros((H * W, H * W))
    for k, (dy, dx) in enumerate(offsets):
        for y in range(H):
            for x in range(W):
                if 0 <= y + dy < H and 0 <= x + dx < W:
                    A[y * W + x, (y + dy) * W + x + dx] += stencil[k, y, x]
                    if symmetric and (dy, dx) != (0, 0):
                        A[(y + dy) * W + x + dx, y * W + x] += stencil[k, y, x]
    return A


def _assemble(op, offsets, weights, scale, symmetric, start=None):
    stored = [o for o in offsets if o >= (0, 0)] if symmetric else offsets
    stencil = np.zeros((len(stored),) + op.grid_shape) if start is None else start.copy()
    op.add_normal_stencil(stencil, stored, weights, scale, symmetric=symmetric)
    return stored, stencil


def _random_blocks(rng, count):
    """Blocks of 1-4 distinct taps with offsets in [-2, 2]², some coefficients repeated (as in difference operators)."""
    blocks = []
    for _ in range(count):
        taps = rng.choice(25, size=rng.integers(1, 5), replace=False)
        values = rng.choice([-2.0, 1.0, np.sqrt(2.0), rng.standard_normal()], size=taps.size)
        blocks.append([((int(t) // 5 - 2, int(t) % 5 - 2), float(v)) for t, v in zip(taps, values)])
    return blocks


@pytest.mark.parametrize("symmetric", [False, True], ids=["full", "stored half"])
@pytest.mark.parametrize("weighted", [False, True], ids=["unweighted", "row weights"])
@pytest.mark.parametrize("band_values", [1, 23, 1 << 16], ids=["row bands", "odd bands", "one band"])
@pytest.mark.parametrize("seed", range(4))
def test_stencil_operator_normal_stencil_is_KT_diag_w_K(set_limits, seed, band_values, weighted, symmetric):
    set_limits(operator_band_values=band_values)
    rng = np.random.default_rng(seed)
    shape = tuple(int(s) for s in rng.integers(4, 9, size=2))
    blocks = _random_blocks(rng, int(rng.integers(1, 4)))
    op = StencilOperator(shape, blocks)
    K = _stencil_operator_by_loop(shape, blocks)
    w = rng.random(K.shape[0]) + 0.1 if weighted else None
    scale = 0.7
    expected = scale * (K.T @ (K if w is None else sp.diags(w) @ K)).toarray()
    offsets = op.offsets()
    start = rng.standard_normal((len(offsets) if not symmetric else sum(o >= (0, 0) for o in offsets),) + shape)
    stored, stencil = _assemble(op, offsets, w, scale, symmetric)
    np.testing.assert_allclose(_matrix_of_stencil(stored, stencil, symmetric=symmetric), expected,
                               rtol=0, atol=1e-13 * max(1.0, np.abs(expected).max()))
    # the images are added to (not overwritten)
    _, accumulated = _assemble(op, offsets, w, scale, symmetric, start=start)
    np.testing.assert_allclose(accumulated, start + stencil, rtol=0, atol=1e-13 * np.abs(start + stencil).max())


@pytest.mark.parametrize("symmetric", [False, True], ids=["full", "stored half"])
@pytest.mark.parametrize("make", [gradient_stencil, hessian_stencil])
def test_difference_operators_with_lazily_read_row_weights(set_limits, make, symmetric):
    """Row weights that are read a block at a time (as the edge weights are) give the stencil of the dense weights."""
    set_limits(operator_band_values=40)

    class BlockRows:
        def __init__(self, values):
            self.values = values
            self.shape = values.shape

        def __getitem__(self, key):
            return self.values[key].copy()

    rng = np.random.default_rng(5)
    op = make((7, 10))
    K = _stencil_operator_by_loop(op.grid_shape, op.blocks)
    w = rng.random(K.shape[0])
    expected = (K.T @ sp.diags(w) @ K).toarray()
    stored, stencil = _assemble(op, op.offsets(), BlockRows(w), 1.0, symmetric)
    np.testing.assert_allclose(_matrix_of_stencil(stored, stencil, symmetric=symmetric), expected,
                               rtol=0, atol=1e-13 * np.abs(expected).max())


def test_stencil_operator_whose_taps_never_fit_writes_nothing():
    op = StencilOperator((2, 3), [[((0, 0), 1.0), ((0, 3), -1.0)]])
    offsets = op.offsets()
    stencil = np.zeros((len(offsets), 2, 3))
    op.add_normal_stencil(stencil, offsets, np.ones(6), 2.0)
    assert not stencil.any()


@pytest.mark.parametrize("op", [hessian_stencil((5, 6)), local_linear_operator(np.random.default_rng(1).random((5, 6, 3)),
                                                                                1e-2, window="cross")],
                         ids=["hessian", "local linear"])
def test_a_stencil_that_is_not_contiguous_is_refused(op):
    offsets = op.offsets()
    stencil = np.zeros((len(offsets), 5, 12))[:, :, ::2]
    with pytest.raises(ValueError, match="contiguous"):
        op.add_normal_stencil(stencil, offsets)


@pytest.mark.parametrize("symmetric", [False, True], ids=["full", "stored half"])
@pytest.mark.parametrize("window", sorted(WINDOW_PIXELS))
@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("band_pixels", [1, 17, 1 << 15], ids=["row bands", "odd bands", "one band"])
def test_local_linear_normal_stencil_is_KT_K(set_limits, band_pixels, channels, window, symmetric):
    set_limits(affinity_band_pixels=band_pixels)
    rng = np.random.default_rng(channels + len(window))
    image = rng.random((6, 7, channels))
    eps = 0.05
    op = local_linear_operator(image if channels > 1 else image[..., 0], eps, window=window)
    K = _local_linear_by_loop(image, eps, window)
    scale = 1.3
    expected = scale * (K.T @ K).toarray()
    stored, stencil = _assemble(op, op.offsets(), None, scale, symmetric)
    np.testing.assert_allclose(_matrix_of_stencil(stored, stencil, symmetric=symmetric), expected,
                               rtol=0, atol=1e-11 * np.abs(expected).max())


@pytest.mark.parametrize("window", sorted(WINDOW_PIXELS))
def test_local_linear_stencil_images_do_not_depend_on_the_band(set_limits, window):
    """Every stencil value receives its terms in the same order whatever the band height: the same numbers."""
    rng = np.random.default_rng(9)
    image = rng.random((11, 9, 3))
    image[3:7, 2:6] = 0.25  # flat windows
    op = local_linear_operator(image, 1e-4, window=window)
    offsets = op.offsets()
    start = rng.standard_normal((len(offsets), 11, 9))
    results = []
    for band_pixels in (1, 9, 20, 1 << 15):
        set_limits(affinity_band_pixels=band_pixels)
        stencil = start.copy()
        op.add_normal_stencil(stencil, offsets, scale=0.3)
        results.append(stencil)
    for other in results[1:]:
        np.testing.assert_array_equal(other, results[0])


@pytest.mark.parametrize("window", sorted(WINDOW_PIXELS))
def test_local_linear_products_are_those_of_K(set_limits, window):
    """``K z`` (whole and in row pieces) and ``Kᵀ v`` against the matrix built window by window."""
    set_limits(affinity_band_pixels=20)
    rng = np.random.default_rng(11)
    image = rng.random((7, 8, 3))
    op = local_linear_operator(image, 0.02, window=window)
    K = _local_linear_by_loop(image, 0.02, window)
    z, v = rng.standard_normal(K.shape[1]), rng.standard_normal(K.shape[0])
    Kz = K @ z
    tolerance = 1e-11 * np.abs(Kz).max()
    np.testing.assert_allclose(op @ z, Kz, rtol=0, atol=tolerance)
    pieced = np.full(K.shape[0], np.nan)
    for rows, values in op.row_pieces(z):
        assert np.all(np.isnan(pieced[rows]))  # every row once
        pieced[rows] = values
    np.testing.assert_allclose(pieced, Kz, rtol=0, atol=tolerance)
    KTv = K.T @ v
    np.testing.assert_allclose(op.rmatvec(v), KTv, rtol=0, atol=1e-11 * np.abs(KTv).max())
    n = K.shape[1]
    total = np.zeros(n)
    for b in range(len(op.blocks)):
        np.testing.assert_allclose(op.block_matvec(z, b), Kz[b * n:(b + 1) * n], rtol=0, atol=tolerance)
        op.block_rmatvec_add(total, b, v[b * n:(b + 1) * n])
    np.testing.assert_allclose(total, KTv, rtol=0, atol=1e-11 * np.abs(KTv).max())


@pytest.mark.parametrize("window", sorted(WINDOW_PIXELS))
@pytest.mark.parametrize("shape", [(2, 2), (3, 2), (2, 5), (5, 3), (1, 6), (4, 1)])
@pytest.mark.parametrize("band_pixels", [1, 1 << 15], ids=["row bands", "one band"])
def test_local_linear_on_grids_a_window_or_two_wide(set_limits, band_pixels, shape, window):
    """Grids with one or two window columns or rows (or none): every row of a run is its last."""
    set_limits(affinity_band_pixels=band_pixels)
    rng = np.random.default_rng(shape[0] * 10 + shape[1])
    image = rng.random(shape + (3,))
    op = local_linear_operator(image, 0.1, window=window)
    K = _local_linear_by_loop(image, 0.1, window)
    expected = (K.T @ K).toarray()
    for symmetric in (False, True):
        stored, stencil = _assemble(op, op.offsets(), None, 1.0, symmetric)
        np.testing.assert_allclose(_matrix_of_stencil(stored, stencil, symmetric=symmetric), expected,
                                   rtol=0, atol=1e-11 * max(1.0, np.abs(expected).max()))
    z = rng.standard_normal(K.shape[1])
    pieced = np.full(K.shape[0], np.nan)
    for rows, values in op.row_pieces(z):
        pieced[rows] = values
    np.testing.assert_allclose(pieced, K @ z, rtol=0, atol=1e-11 * max(1.0, np.abs(K @ z).max()))
    np.testing.assert_allclose(op.rmatvec(np.ones(K.shape[0])), K.T @ np.ones(K.shape[0]), rtol=0, atol=1e-10)
