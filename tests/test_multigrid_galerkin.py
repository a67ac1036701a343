"""The stencil Galerkin products of sparsedepth.linalg.multigrid against P^T A P formed with scipy.sparse."""

import numpy as np
import pytest
import scipy.sparse as sp

from sparsedepth.grid.stencil import SymmetricStencil, stencil_to_csr
from sparsedepth.linalg.multigrid.galerkin import galerkin_offsets, galerkin_stencil, separable_galerkin_stencil
from sparsedepth.linalg.multigrid.interpolation import bilinear_weights, linear_weights_1d
from sparsedepth.linalg.multigrid.stencils import StencilSource, mirrored_image

from conftest import linear_interpolation_1d, stencil_images

FIVE = [(-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)]
NINE = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
THIRTEEN = sorted(FIVE + [(-1, -1), (-1, 1), (1, -1), (1, 1), (-2, 0), (0, -2), (0, 2), (2, 0)])
TWENTY_FIVE = [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3)]


def symmetric_matrix(offsets, shape, rng):
    """A random symmetric matrix with the given (negation-closed) stencil, built entry by entry in COO form."""
    h, w = shape
    rows, cols, vals = [], [], []
    for dy, dx in offsets:
        if (dy, dx) < (0, 0):
            continue
        for y in range(h):
            for x in range(w):
                if 0 <= y + dy < h and 0 <= x + dx < w:
                    p, q = y * w + x, (y + dy) * w + x + dx
                    v = rng.uniform(0.5, 2.0) * (1 if (dy, dx) == (0, 0) else -1) * 10.0 ** rng.uniform(-3, 3)
                    rows += [p] if p == q else [p, q]
                    cols += [q] if p == q else [q, p]
                    vals += [v] if p == q else [v, v]
    n = h * w
    return sp.csr_array(sp.coo_array((vals, (rows, cols)), shape=(n, n)))


def expected_product(A, shape):
    P = sp.csr_array(np.kron(linear_interpolation_1d(shape[0]), linear_interpolation_1d(shape[1])))
    product = (P.T @ A @ P).toarray()
    scale = (abs(P).T @ abs(A) @ abs(P)).toarray()  # rounding is relative to the terms summed
    return product, scale


SHAPES = [(1, 1), (1, 7), (6, 1), (2, 2), (3, 4), (4, 3), (5, 5), (6, 8), (9, 7), (10, 12), (13, 11)]


@pytest.mark.parametrize("band_values", [1, 100, None], ids=["one row", "a few rows", "default"])
@pytest.mark.parametrize("offsets", [FIVE, NINE, THIRTEEN, TWENTY_FIVE], ids=["5", "9", "13", "25"])
@pytest.mark.parametrize("shape", SHAPES)
def test_separable_galerkin_equals_scipy_triple_product(offsets, shape, band_values):
    rng = np.random.default_rng(sum(shape) + len(offsets))
    A = symmetric_matrix(offsets, shape, rng)
    S = stencil_images(A.toarray(), offsets, shape)
    coarse = galerkin_offsets(offsets)
    C = separable_galerkin_stencil(offsets, lambda y0, y1: S[:, y0:y1], linear_weights_1d(shape[0]),
                                   linear_weights_1d(shape[1]), coarse, band_values=band_values)
    hc, wc = (shape[0] + 1) // 2, (shape[1] + 1) // 2
    assert C.shape == (len(coarse), hc, wc)
    product, scale = expected_product(A, shape)
    np.testing.assert_allclose(stencil_to_csr(coarse, C).toarray(), product, rtol=0, atol=1e-13 * scale.max())
    # and the images themselves: zero wherever the neighbour is outside the coarse grid
    np.testing.assert_allclose(C, stencil_images(sp.csr_array(product).toarray(), coarse, (hc, wc)), rtol=0,
                               atol=1e-13 * scale.max())


@pytest.mark.parametrize("shape", [(7, 9), (8, 10), (2, 5)])
def test_galerkin_stencil_of_each_source_equals_scipy_triple_product(shape):
    """Array, symmetric-stencil and CSR sources (read by bands of rows): the same product."""
    rng = np.random.default_rng(3)
    A = symmetric_matrix(THIRTEEN, shape, rng)
    S = stencil_images(A.toarray(), THIRTEEN, shape)
    coarse = galerkin_offsets(THIRTEEN)
    product, scale = expected_product(A, shape)
    symmetric = SymmetricStencil.from_stencil(THIRTEEN, S)
    sources = [StencilSource(THIRTEEN, shape, array=S), StencilSource(THIRTEEN, shape, symmetric=symmetric),
               StencilSource(THIRTEEN, shape, csr=stencil_to_csr(THIRTEEN, S), csr_offsets=THIRTEEN)]
    for source in sources:
        for as_list in (False, True):
            C = galerkin_stencil(THIRTEEN, source, bilinear_weights(shape), shape, coarse, as_list=as_list)
            np.testing.assert_allclose(stencil_to_csr(coarse, np.asarray(C)).toarray(), product, rtol=0,
                                       atol=1e-13 * scale.max())


def test_mirrored_image_is_the_transposed_coupling():
    rng = np.random.default_rng(4)
    shape = (5, 6)
    A = symmetric_matrix(THIRTEEN, shape, rng)
    S = stencil_images(A.toarray(), THIRTEEN, shape)
    images = dict(zip(THIRTEEN, S))
    for (dy, dx), image in images.items():
        np.testing.assert_array_equal(mirrored_image(image, (dy, dx)), images[-dy, -dx])
        out = np.full(shape, np.nan)
        assert mirrored_image(image, (dy, dx), out=out) is out
        np.testing.assert_array_equal(out, images[-dy, -dx])
