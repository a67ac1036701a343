"""Baselines: linear, biharmonic and colorization fills against independent computations."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

import sparsedepth as sd


def plane_problem(shape=(30, 40), fraction=0.05, seed=0):
    H, W = shape
    ii, jj = np.mgrid[0:H, 0:W]
    truth = 1.0 + 0.02 * ii + 0.01 * jj
    mask = np.random.default_rng(seed).random(shape) < fraction
    return truth, mask, np.where(mask, truth, np.nan)


def test_linear_fill_exact_on_plane_inside_hull_and_nearest_outside():
    truth, mask, sparse = plane_problem()
    out = sd.linear_fill(sparse, mask)
    points = np.argwhere(mask)
    inside = (Delaunay(points).find_simplex(np.argwhere(np.ones(mask.shape, bool))) >= 0).reshape(mask.shape)
    assert inside.sum() > 0.5 * mask.size and (~inside).any()
    np.testing.assert_allclose(out[inside], truth[inside], atol=1e-12)
    np.testing.assert_array_equal(out[~inside], sd.nearest_fill(sparse, mask)[~inside])


def test_linear_fill_barycentric_value_of_one_triangle():
    # three observations: the interpolant inside their triangle is the plane through them
    depth = np.zeros((5, 5))
    depth[0, 0], depth[0, 4], depth[4, 0] = 1.0, 3.0, 2.0
    out = sd.linear_fill(depth)
    # plane z = 1 + 0.25 i + 0.5 j through (0,0,1), (0,4,3), (4,0,2)
    assert out[1, 1] == pytest.approx(1.75)
    assert out[2, 2] == pytest.approx(2.5)
    assert out[4, 4] == depth[4, 0] or out[4, 4] == depth[0, 4]  # outside the hull: a nearest observation


def test_linear_fill_degenerate_inputs_fall_back_to_nearest():
    depth = np.zeros((6, 7))
    depth[2, 1], depth[2, 5] = 1.0, 4.0  # two points: no triangle
    np.testing.assert_array_equal(sd.linear_fill(depth), sd.nearest_fill(depth))
    depth[2, 3] = 2.0  # three collinear points: still no triangle
    np.testing.assert_array_equal(sd.linear_fill(depth), sd.nearest_fill(depth))


@pytest.mark.parametrize("fill", [sd.linear_fill, sd.biharmonic_fill, sd.nearest_fill])
def test_fills_keep_observed_values_and_do_not_modify_input(fill):
    rng = np.random.default_rng(1)
    truth = 1.0 + rng.random((25, 30))
    mask = rng.random(truth.shape) < 0.1
    sparse = np.where(mask, truth, 0.0)
    before = sparse.copy()
    out = fill(sparse, mask)
    assert out.shape == truth.shape and out.dtype == np.float64 and np.all(np.isfinite(out))
    np.testing.assert_allclose(out[mask], truth[mask], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(sparse, before)


def test_biharmonic_fill_exact_on_plane_with_observed_border():
    truth, mask, _ = plane_problem()
    mask[:2, :] = mask[-2:, :] = True
    mask[:, :2] = mask[:, -2:] = True
    out = sd.biharmonic_fill(np.where(mask, truth, 0.0), mask)
    np.testing.assert_allclose(out, truth, atol=1e-10)


def test_biharmonic_fill_much_better_than_nearest_on_plane():
    truth, mask, sparse = plane_problem()
    err_b = np.sqrt(np.mean((sd.biharmonic_fill(sparse, mask) - truth)[~mask] ** 2))
    err_n = np.sqrt(np.mean((sd.nearest_fill(sparse, mask) - truth)[~mask] ** 2))
    assert err_b < 0.5 * err_n


def test_colorization_baseline_matches_colorization_fill_and_constant():
    pytest.importorskip("sparsedepth.holes.colorization")
    from sparsedepth.holes.colorization import colorization_fill

    rng = np.random.default_rng(3)
    image = rng.random((20, 30, 3))
    truth = 1.0 + rng.random((20, 30))
    mask = rng.random(truth.shape) < 0.1
    out = sd.colorization_baseline(image, np.where(mask, truth, np.nan), mask)
    np.testing.assert_allclose(out, colorization_fill(image, np.where(mask, truth, 0.0), mask=mask), atol=1e-12)
    const = sd.colorization_baseline(image, np.where(mask, 2.5, 0.0), mask)
    np.testing.assert_allclose(const, 2.5, atol=1e-6)


def test_colorization_baseline_image_shape_must_match():
    with pytest.raises(ValueError, match="image has shape"):
        sd.colorization_baseline(np.zeros((4, 5, 3)), np.ones((4, 6)))


@pytest.mark.parametrize("fill", [sd.linear_fill, sd.biharmonic_fill])
def test_fill_input_checks(fill):
    with pytest.raises(ValueError, match="2-D"):
        fill(np.ones((3, 4, 2)))
    with pytest.raises(ValueError, match="no observed pixel"):
        fill(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="mask has shape"):
        fill(np.ones((3, 4)), np.ones((4, 3), bool))
    with pytest.raises(ValueError, match="negative"):
        fill(-np.ones((3, 4)), np.ones((3, 4), bool))
