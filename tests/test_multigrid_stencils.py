"""The multigrid's stencil sources (sparsedepth.linalg.multigrid.stencils) on CSR matrices in the full in-grid pattern."""

import numpy as np
import pytest
import scipy.sparse as sp

from sparsedepth.grid.stencil import csr_to_stencil, stencil_to_csr
from sparsedepth.linalg.multigrid import GridMultigrid, grid_stencil
from sparsedepth.linalg.multigrid.stencils import (StencilSource, extract_stencil, fine_stencil_source,
                                                   full_pattern_within)

FIVE = [(-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)]
THIRTEEN = sorted(FIVE + [(-1, -1), (-1, 1), (1, -1), (1, 1), (-2, 0), (0, -2), (0, 2), (2, 0)])
TWENTY_ONE = [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3) if abs(dy) + abs(dx) < 4]


@pytest.mark.parametrize("offsets", [FIVE, THIRTEEN, TWENTY_ONE], ids=["5", "13", "21"])
@pytest.mark.parametrize("shape", [(1, 6), (5, 1), (3, 3), (6, 7), (9, 8), (16, 13)])
def test_a_csr_source_hands_out_what_an_array_source_does(offsets, shape):
    """Read by position, band by band and class by class; offsets the matrix lacks read as zero."""
    rng = np.random.default_rng(len(offsets) + 5 * shape[0] + shape[1])
    S = rng.uniform(0.5, 1.5, (len(offsets),) + shape)
    A = stencil_to_csr(offsets, S)
    images = csr_to_stencil(A, shape, offsets=offsets)[1]  # 0 where the neighbour is outside the grid
    wider = sorted(set(offsets) | {(-2, -2), (2, 2)})
    padded = np.zeros((len(wider),) + shape)
    padded[[wider.index(o) for o in offsets]] = images
    for hierarchy_offsets, array in ((offsets, images), (wider, padded)):
        csr = StencilSource(hierarchy_offsets, shape, csr=A, csr_offsets=offsets)
        dense = StencilSource(hierarchy_offsets, shape, array=array)
        for py, px in [(None, None), (0, 0), (1, 0), (0, 1), (1, 1)]:
            if py is None or (py < shape[0] and px < shape[1]):
                np.testing.assert_array_equal(csr.parity_class(py, px), dense.parity_class(py, px))
        rows = csr.row_reader()
        for y0, y1 in [(0, shape[0]), (0, 1), (shape[0] // 2, shape[0])]:
            np.testing.assert_array_equal(rows(y0, y1), array[:, y0:y1])


def test_full_pattern_within_the_radius():
    shape = (9, 10)
    S = np.random.default_rng(1).uniform(0.5, 1.5, (len(THIRTEEN),) + shape)
    A = stencil_to_csr(THIRTEEN, S)
    assert full_pattern_within(A, shape).offsets == THIRTEEN
    assert full_pattern_within(A, shape, radius=1) is None  # (±2, 0), (0, ±2) lie beyond radius 1
    wide = [(-3, 0), (0, 0), (3, 0)]
    W = stencil_to_csr(wide, np.ones((3,) + shape))
    assert full_pattern_within(W, shape) is None
    assert full_pattern_within(W, shape, radius=3).offsets == wide
    with pytest.raises(ValueError, match="radius 2"):
        grid_stencil(W, shape)  # neither read by position nor extracted within radius 2
    offsets, read = grid_stencil(W, shape, radius=3)
    assert offsets == wide
    np.testing.assert_array_equal(read, extract_stencil(W, shape, wide))
    offsets, source = fine_stencil_source(A, shape)
    assert offsets == THIRTEEN and source.csr is A and source.pattern.offsets == THIRTEEN


@pytest.mark.parametrize("shape", [(1, 7), (6, 1), (7, 9)])
def test_extract_stencil_reads_each_diagonal_within_the_grid(shape):
    rng = np.random.default_rng(2)
    S = rng.uniform(0.5, 1.5, (len(THIRTEEN),) + shape)
    A = sp.csr_array(stencil_to_csr(THIRTEEN, S).toarray())  # not in the full pattern: read by diagonals
    np.testing.assert_array_equal(extract_stencil(A, shape, THIRTEEN), csr_to_stencil(stencil_to_csr(THIRTEEN, S),
                                                                                     shape, offsets=THIRTEEN)[1])


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
