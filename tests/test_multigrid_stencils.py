"""Reading and assembling the CSR form of grid stencils in sparsedepth.linalg.multigrid.stencils."""

import numpy as np
import pytest
import scipy.sparse as sp

from sparsedepth.grid.stencil import csr_to_stencil, full_pattern_offsets, stencil_to_csr
from sparsedepth.linalg.multigrid import GridMultigrid
from sparsedepth.linalg.multigrid.stencils import assemble_csr, centre_row_holds, read_full_pattern

FIVE = [(-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)]
THIRTEEN = sorted(FIVE + [(-1, -1), (-1, 1), (1, -1), (1, 1), (-2, 0), (0, -2), (0, 2), (2, 0)])
TWENTY_ONE = [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3) if abs(dy) + abs(dx) < 4]
SHAPES = [(1, 1), (1, 6), (5, 1), (2, 3), (3, 3), (4, 5), (5, 4), (6, 7), (9, 8)]


def dense_from_stencil(offsets, S):
    """The matrix of a stencil, entry by entry: ``A[(y, x), (y + dy, x + dx)] = S[k, y, x]`` inside the grid."""
    _, h, w = S.shape
    A = np.zeros((h * w, h * w))
    for k, (dy, dx) in enumerate(offsets):
        for y in range(h):
            for x in range(w):
                if 0 <= y + dy < h and 0 <= x + dx < w:
                    A[y * w + x, (y + dy) * w + x + dx] = S[k, y, x]
    return A


@pytest.mark.parametrize("offsets", [[(0, 0)], FIVE, THIRTEEN, TWENTY_ONE], ids=["1", "5", "13", "21"])
@pytest.mark.parametrize("shape", SHAPES)
def test_assemble_csr_is_the_stencils_matrix_in_the_full_pattern(offsets, shape):
    rng = np.random.default_rng(len(offsets) + 7 * shape[0] + shape[1])
    S = rng.uniform(0.5, 1.5, (len(offsets),) + shape)  # no zero inside the grid: every entry is stored
    for dtype in (np.float64, np.float32):
        A = assemble_csr(offsets, S, dtype)
        assert A.dtype == dtype and A.has_canonical_format
        np.testing.assert_array_equal(A.toarray(), dense_from_stencil(offsets, S).astype(dtype))
        # the pattern of stencil_to_csr, entry for entry
        reference = stencil_to_csr(offsets, S, dtype=dtype)
        np.testing.assert_array_equal(A.indptr, reference.indptr)
        np.testing.assert_array_equal(A.indices, reference.indices)
        np.testing.assert_array_equal(A.data, reference.data)


@pytest.mark.parametrize("offsets", [FIVE, THIRTEEN, TWENTY_ONE], ids=["5", "13", "21"])
@pytest.mark.parametrize("shape", SHAPES)
def test_read_full_pattern_returns_the_stencil_or_none(offsets, shape):
    rng = np.random.default_rng(len(offsets) + 5 * shape[0] + shape[1])
    S = rng.uniform(0.5, 1.5, (len(offsets),) + shape)
    A = stencil_to_csr(offsets, S)
    read = read_full_pattern(A, shape)
    expected = full_pattern_offsets(A, shape)
    # read back with the offsets it was assembled from exactly when its centre row holds them all
    assert (expected == offsets) == centre_row_holds(offsets, shape)
    if expected is None:
        assert read is None
        return
    got_offsets, got = read
    assert got_offsets == expected
    np.testing.assert_array_equal(got, csr_to_stencil(A, shape, offsets=expected)[1])
    np.testing.assert_array_equal(dense_from_stencil(got_offsets, got), A.toarray())
    # the same with 64-bit index arrays
    wide = sp.csr_array((A.data, A.indices.astype(np.int64), A.indptr.astype(np.int64)), shape=A.shape)
    assert wide.indices.dtype == np.int64
    wide_offsets, wide_stencil = read_full_pattern(wide, shape)
    assert wide_offsets == got_offsets
    np.testing.assert_array_equal(wide_stencil, got)


@pytest.mark.parametrize("position", ["first", "inner", "last"])
def test_read_full_pattern_rejects_a_moved_column(position):
    shape = (9, 11)
    S = np.random.default_rng(0).uniform(0.5, 1.5, (len(THIRTEEN),) + shape)
    A = stencil_to_csr(THIRTEEN, S)
    assert read_full_pattern(A, shape) is not None
    entry = {"first": 0, "inner": A.nnz // 2, "last": A.nnz - 1}[position]
    B = A.copy()
    B.indices[entry] += 1 if position == "first" else -1  # still sorted, no longer the pattern
    assert read_full_pattern(B, shape) is None
    assert full_pattern_offsets(B, shape) is None
    # row pointers of another pattern
    D = A.copy()
    D.indptr[1:-1] += 1
    assert read_full_pattern(D, shape) is None
    # another layout of the same matrix (the entries of a row not in column order) is not read by position
    C = sp.csr_array(A.toarray())
    C.indices[:] = C.indices[::-1].copy()  # unsorted: columns no longer those of the pattern
    assert read_full_pattern(C, shape) is None


def test_update_with_fewer_offsets_reads_them_into_the_hierarchys_stencil():
    """A 5-point operator given to a hierarchy of a 13-point one: the missing offsets read as zero."""
    shape = (12, 14)
    rng = np.random.default_rng(5)
    wide = stencil_to_csr(THIRTEEN, np.where(np.array(THIRTEEN)[:, :1, None] == 0, 1.0, 0.1)[:, :, :1]
                          * rng.uniform(0.5, 1.5, (len(THIRTEEN),) + shape))
    wide = sp.csr_array((wide + wide.T) / 2 + 10 * sp.eye(wide.shape[0]))
    narrow_images = rng.uniform(0.5, 1.5, (len(FIVE),) + shape)
    narrow = stencil_to_csr(FIVE, narrow_images)
    narrow = sp.csr_array((narrow + narrow.T) / 2 + 10 * sp.eye(narrow.shape[0]))
    mg = GridMultigrid(wide, shape, max_coarse=1)
    mg.update(narrow)
    fresh = GridMultigrid(narrow, shape, max_coarse=1)
    for updated, built in zip(mg.levels[1:], fresh.levels[1:]):
        np.testing.assert_allclose(updated.A.toarray(), built.A.toarray(), rtol=1e-13, atol=1e-13)
