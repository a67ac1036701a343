"""The geodesic fill's shortest-path search (nearest_sources) against SciPy's Dijkstra and hand-computed arrays."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from sparsedepth.grid.geodesic import geodesic_fill, nearest_sources, step_costs


def _graph(cx, cy):
    """The undirected 4-connected grid graph from (row, column, cost) lists."""
    H, W = cy.shape[0] + 1, cx.shape[1] + 1
    index = np.arange(H * W).reshape(H, W)
    rows = np.concatenate([index[:, :-1].ravel(), index[:-1, :].ravel()])
    cols = np.concatenate([index[:, 1:].ravel(), index[1:, :].ravel()])
    return sp.csr_array((np.concatenate([cx.ravel(), cy.ravel()]), (rows, cols)), shape=(H * W, H * W))


def _source_distances(cx, cy, sources):
    """Path costs from every source to every pixel, shape (number of sources, H W): one Dijkstra per source."""
    return dijkstra(_graph(cx, cy), directed=False, indices=np.flatnonzero(sources))


def _check_against_dijkstra(cx, cy, sources):
    """The distance is the least source distance, and the chosen source is at that distance; returns the ties."""
    distance, nearest = nearest_sources(cx, cy, sources)
    per_source = _source_distances(cx, cy, sources)
    least = per_source.min(axis=0)
    np.testing.assert_allclose(distance.ravel(), least, rtol=1e-12, atol=0)
    assert nearest.dtype == np.intp and nearest.shape == sources.shape
    assert np.all(sources.ravel()[nearest.ravel()])
    rank = np.searchsorted(np.flatnonzero(sources), nearest.ravel())  # the chosen source's row of per_source
    chosen = per_source[rank, np.arange(least.size)]
    np.testing.assert_allclose(chosen, least, rtol=1e-12, atol=0)
    ties = np.sum(np.isclose(per_source, least, rtol=1e-12, atol=0), axis=0)
    return distance, nearest, ties


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("shape", [(5, 7), (13, 9), (24, 31)])
def test_random_costs_equal_dijkstra(shape, seed):
    """Costs from 1 to 40 (a pixel can wait many rounds before it is final), random sources."""
    rng = np.random.default_rng(seed)
    H, W = shape
    cx = 1.0 + 39.0 * rng.random((H, W - 1)) ** 4
    cy = 1.0 + 39.0 * rng.random((H - 1, W)) ** 4
    sources = rng.random(shape) < 0.08
    sources.flat[rng.integers(H * W)] = True
    _check_against_dijkstra(cx, cy, sources)


@pytest.mark.parametrize("low", [0.01, 0.3, 2.5])
def test_least_step_other_than_one_equal_dijkstra(low):
    """The rounds are as wide as the least step cost, whatever it is."""
    rng = np.random.default_rng(11)
    cx = low * (1.0 + 5.0 * rng.random((17, 20)))
    cy = low * (1.0 + 5.0 * rng.random((16, 21)))
    sources = rng.random((17, 21)) < 0.05
    sources[0, 0] = True
    _check_against_dijkstra(cx, cy, sources)


@pytest.mark.parametrize("seed", range(4))
def test_ties_choose_a_source_at_the_least_distance(seed):
    """Integer costs: many pixels at exactly equal cost from two or more sources."""
    rng = np.random.default_rng(seed)
    cx = rng.integers(1, 3, (20, 25)).astype(float)
    cy = rng.integers(1, 3, (19, 26)).astype(float)
    sources = rng.random((20, 26)) < 0.1
    sources[5, 5] = True
    _, _, ties = _check_against_dijkstra(cx, cy, sources)
    assert np.count_nonzero(ties > 1) > 20  # the case is really tied


def test_unit_costs_give_the_city_block_distance():
    """λ = 0: the distance to the nearest source is min |Δi| + |Δj|, computed directly."""
    rng = np.random.default_rng(3)
    H, W = 15, 22
    sources = rng.random((H, W)) < 0.04
    sources[H - 1, 0] = True
    image = rng.random((H, W, 3))
    fill, distance = geodesic_fill(image, np.where(sources, 1.0 + rng.random((H, W)), 0.0), sources, contrast=0.0,
                                   return_distance=True)
    si, sj = np.nonzero(sources)
    i, j = np.indices((H, W))
    city = np.abs(i[..., None] - si) + np.abs(j[..., None] - sj)
    np.testing.assert_array_equal(distance, city.min(axis=-1))
    _, nearest = nearest_sources(*step_costs(image, 0.0), sources)
    np.testing.assert_array_equal(city.reshape(H * W, -1)[np.arange(H * W), np.searchsorted(
        np.flatnonzero(sources), nearest.ravel())], city.min(axis=-1).ravel())


def test_single_source():
    rng = np.random.default_rng(5)
    cx, cy = 1.0 + rng.random((9, 11)), 1.0 + rng.random((8, 12))
    sources = np.zeros((9, 12), dtype=bool)
    sources[4, 7] = True
    distance, nearest, _ = _check_against_dijkstra(cx, cy, sources)
    assert np.all(nearest == 4 * 12 + 7)
    assert distance[4, 7] == 0.0 and np.all(np.delete(distance.ravel(), 4 * 12 + 7) >= 1.0)


def test_one_row_hand_computed():
    cx = np.array([[1.0, 3.0, 1.5, 2.0, 1.0]])
    sources = np.array([[True, False, False, False, False, True]])
    distance, nearest = nearest_sources(cx, np.empty((0, 6)), sources)
    # from the left: 0, 1, 4, 5.5, 7.5, 8.5; from the right: 8.5, 7.5, 4.5, 3, 1, 0
    np.testing.assert_array_equal(distance, [[0.0, 1.0, 4.0, 3.0, 1.0, 0.0]])
    np.testing.assert_array_equal(nearest, [[0, 0, 0, 5, 5, 5]])


def test_one_column_hand_computed():
    cy = np.array([[2.0], [1.0], [1.0], [5.0]])
    sources = np.array([[False], [True], [False], [False], [True]])
    distance, nearest = nearest_sources(np.empty((5, 0)), cy, sources)
    np.testing.assert_array_equal(distance.ravel(), [2.0, 0.0, 1.0, 2.0, 0.0])
    np.testing.assert_array_equal(nearest.ravel(), [1, 1, 1, 1, 4])


def test_one_pixel():
    distance, nearest = nearest_sources(np.empty((1, 0)), np.empty((0, 1)), np.ones((1, 1), dtype=bool))
    np.testing.assert_array_equal(distance, [[0.0]])
    np.testing.assert_array_equal(nearest, [[0]])


def test_a_wall_sends_pixels_round_it_hand_computed():
    """A wall of cost 10 between columns 1 and 2 with a gap in the last row: the path goes round it."""
    cx = np.ones((3, 3))
    cx[:2, 1] = 10.0
    cy = np.ones((2, 4))
    sources = np.zeros((3, 4), dtype=bool)
    sources[0, 0] = True
    distance, nearest = nearest_sources(cx, cy, sources)
    np.testing.assert_array_equal(distance, [[0, 1, 6, 7], [1, 2, 5, 6], [2, 3, 4, 5]])
    assert np.all(nearest == 0)


def test_all_pixels_observed():
    rng = np.random.default_rng(2)
    depth = 1.0 + rng.random((6, 8))
    fill, distance = geodesic_fill(rng.random((6, 8, 3)), depth, np.ones((6, 8), dtype=bool), contrast=20.0,
                                   return_distance=True)
    np.testing.assert_array_equal(fill, depth)
    np.testing.assert_array_equal(distance, np.zeros((6, 8)))


@pytest.mark.parametrize("shape", [(1, 9), (9, 1), (16, 23)])
def test_geodesic_fill_takes_the_depth_of_a_least_cost_source(shape):
    """On an image: the distance equals Dijkstra's and the fill is the depth of a source at that distance."""
    rng = np.random.default_rng(sum(shape))
    image = rng.integers(0, 3, shape + (3,)) / 2.0  # three levels: ties and edges
    depth = 1.0 + rng.random(shape)
    mask = rng.random(shape) < 0.2
    mask.flat[-1] = True
    fill, distance = geodesic_fill(image, np.where(mask, depth, 0.0), mask, contrast=20.0, return_distance=True)
    cx, cy = step_costs(image, 20.0)
    per_source = _source_distances(cx, cy, mask)
    least = per_source.min(axis=0)
    np.testing.assert_allclose(distance.ravel(), least, rtol=1e-12, atol=0)
    at_least = np.isclose(per_source, least, rtol=1e-12, atol=0)
    assert np.all(np.any(at_least & (depth[mask][:, None] == fill.ravel()), axis=0))


def test_arguments_are_checked():
    ones = np.ones((3, 4), dtype=bool)
    with pytest.raises(ValueError, match="do not fit"):
        nearest_sources(np.ones((3, 4)), np.ones((2, 4)), ones)
    with pytest.raises(ValueError, match="finite and > 0"):
        nearest_sources(np.zeros((3, 3)), np.ones((2, 4)), ones)
    with pytest.raises(ValueError, match="finite and > 0"):
        nearest_sources(np.full((3, 3), np.inf), np.ones((2, 4)), ones)
    with pytest.raises(ValueError, match="no True"):
        nearest_sources(np.ones((3, 3)), np.ones((2, 4)), ~ones)
    with pytest.raises(ValueError, match="2-D"):
        nearest_sources(np.ones((3, 3)), np.ones((2, 4)), np.ones(12, dtype=bool))


@pytest.mark.parametrize("transpose", [False, True])
def test_long_line_hand_computed(transpose):
    """A line of 3000 pixels, a source at one end (one round per pixel): the distance is the cumulative cost."""
    rng = np.random.default_rng(9)
    steps = 1.0 + rng.random((1, 2999))
    sources = np.zeros((1, 3000), dtype=bool)
    sources[0, 0] = True
    expected = np.concatenate([[0.0], np.cumsum(steps)])
    if transpose:
        distance, nearest = nearest_sources(np.empty((3000, 0)), steps.T, sources.T)
    else:
        distance, nearest = nearest_sources(steps, np.empty((0, 3000)), sources)
    np.testing.assert_allclose(distance.ravel(), expected, rtol=1e-12, atol=0)
    assert np.all(nearest == 0)


def test_narrow_strip_equals_dijkstra():
    """Three pixels wide and 400 long, two sources: many rounds of few pixels."""
    rng = np.random.default_rng(4)
    cx, cy = 1.0 + 3.0 * rng.random((400, 2)), 1.0 + 3.0 * rng.random((399, 3))
    sources = np.zeros((400, 3), dtype=bool)
    sources[0, 1] = sources[-1, 0] = True
    _check_against_dijkstra(cx, cy, sources)
