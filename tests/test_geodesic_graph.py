"""The grid graph of the geodesic fill, written straight into CSR, against the coordinate-list construction; the fill
against Dijkstra on that graph."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from sparsedepth.grid.geodesic import grid_graph, geodesic_fill


def _coo_graph(cx, cy):
    """The same graph from (row, column, cost) lists: right edges, then down edges."""
    H, W = cy.shape[0] + 1, cx.shape[1] + 1
    index = np.arange(H * W).reshape(H, W)
    rows = np.concatenate([index[:, :-1].ravel(), index[:-1, :].ravel()])
    cols = np.concatenate([index[:, 1:].ravel(), index[1:, :].ravel()])
    return sp.csr_array((np.concatenate([cx.ravel(), cy.ravel()]), (rows, cols)), shape=(H * W, H * W))


@pytest.mark.parametrize("shape", [(1, 1), (1, 2), (2, 1), (1, 9), (9, 1), (2, 2), (3, 7), (8, 5), (31, 40)])
def test_grid_graph_equals_coordinate_construction(shape):
    H, W = shape
    rng = np.random.default_rng(H * 100 + W)
    cx = 1.0 + rng.random((H, W - 1))
    cy = 1.0 + rng.random((H - 1, W))
    ours, ref = grid_graph(cx, cy), _coo_graph(cx, cy)
    ref.sum_duplicates()
    ref.sort_indices()
    assert ours.shape == ref.shape
    np.testing.assert_array_equal(ours.indptr, ref.indptr)
    np.testing.assert_array_equal(ours.indices, ref.indices)
    np.testing.assert_array_equal(ours.data, ref.data)


@pytest.mark.parametrize("shape", [(1, 6), (6, 1), (12, 17), (40, 33)])
def test_geodesic_fill_equals_dijkstra_on_coordinate_graph(shape):
    """Ties included (a two-level image: many equal path costs): Dijkstra's distances, and a fill from a source at
    the least distance (where sources tie, either)."""
    H, W = shape
    rng = np.random.default_rng(7)
    image = rng.integers(0, 2, (H, W, 3)).astype(float)
    depth = 1.0 + rng.random((H, W))
    mask = rng.random((H, W)) < 0.15
    mask.flat[0] = True
    fill, distance = geodesic_fill(image, np.where(mask, depth, 0.0), mask, contrast=20.0, return_distance=True)
    dx = np.sqrt(np.sum(np.diff(image, axis=1) ** 2, axis=-1))
    dy = np.sqrt(np.sum(np.diff(image, axis=0) ** 2, axis=-1))
    graph = _coo_graph(1.0 + 20.0 * dx, 1.0 + 20.0 * dy)
    ref_distance = dijkstra(graph, directed=False, indices=np.flatnonzero(mask), min_only=True)
    np.testing.assert_allclose(distance.ravel(), ref_distance, rtol=1e-12)
    per_source = dijkstra(graph, directed=False, indices=np.flatnonzero(mask))
    at_least = np.isclose(per_source, ref_distance, rtol=1e-12, atol=0)
    assert np.all(np.any(at_least & (depth[mask][:, None] == fill.ravel()), axis=0))
