"""The modelling options of issue 21: geodesic prior fill, blurred edge weights, depth-aware re-solve, prior=."""

from __future__ import annotations

import heapq
import warnings

import numpy as np
import pytest
import scipy.sparse.linalg as spla
from scipy import ndimage

import sparsedepth as sd
from sparsedepth.completion import depth_jump_factor
from sparsedepth.grid.edges import pair_edge_weights, smoothed_image
from sparsedepth.grid.geodesic import geodesic_fill, step_costs
from sparsedepth.objective.objective import build_objective
from sparsedepth.priors import align_prior


def _wall_image():
    """3x5 grey image: dark columns 0-2, bright columns 3-4 (an image edge between columns 2 and 3)."""
    image = np.zeros((3, 5))
    image[:, 3:] = 1.0
    return image


# -- geodesic fill -------------------------------------------------------------------------------------------------

def test_geodesic_fill_stays_on_its_side_of_a_wall_hand_computed():
    image = _wall_image()
    depth = np.zeros((3, 5))
    depth[1, 0], depth[1, 3] = 1.0, 5.0
    fill, distance = geodesic_fill(image, depth, contrast=10.0, return_distance=True)
    # crossing the edge costs 1 + 10 * 1 = 11, so every dark pixel takes A = 1, every bright pixel B = 5
    expected = np.array([[1, 1, 1, 5, 5]] * 3, dtype=float)
    np.testing.assert_array_equal(fill, expected)
    rows = np.abs(np.arange(3) - 1)[:, None]
    expected_distance = rows + np.array([0, 1, 2, 0, 1])[None, :]  # city-block steps to the sample on its side
    np.testing.assert_array_equal(distance, expected_distance)
    # the Euclidean nearest fill gives pixel (1, 2) the bright side's 5 (one pixel away, A is two)
    assert sd.nearest_fill(depth)[1, 2] == 5.0


def test_geodesic_step_cost_of_a_grey_step():
    image = np.array([[0.0, 0.5, 0.5]])
    depth = np.array([[2.0, 0.0, 0.0]])
    _, distance = geodesic_fill(image, depth, contrast=4.0, return_distance=True)
    np.testing.assert_allclose(distance, [[0.0, 1 + 4 * 0.5, 1 + 4 * 0.5 + 1]], rtol=0, atol=1e-12)
    cx, cy = step_costs(np.dstack([image] * 3), 4.0)  # three equal channels: the norm is sqrt(3) times
    np.testing.assert_allclose(cx, [[1 + 4 * 0.5 * np.sqrt(3), 1.0]], rtol=1e-14)
    assert cy.shape == (0, 3)


def _dijkstra(costs_x, costs_y, sources):
    """Independent multi-source Dijkstra (heapq) on the 4-connected grid: the distance per pixel."""
    H, W = costs_y.shape[0] + 1, costs_x.shape[1] + 1
    dist = np.full((H, W), np.inf)
    heap = [(0.0, i, j) for i, j in sources]
    for _, i, j in heap:
        dist[i, j] = 0.0
    heapq.heapify(heap)
    while heap:
        d, i, j = heapq.heappop(heap)
        if d > dist[i, j]:
            continue
        for ni, nj, c in ((i, j + 1, costs_x[i, j] if j + 1 < W else None),
                          (i, j - 1, costs_x[i, j - 1] if j > 0 else None),
                          (i + 1, j, costs_y[i, j] if i + 1 < H else None),
                          (i - 1, j, costs_y[i - 1, j] if i > 0 else None)):
            if c is not None and d + c < dist[ni, nj]:
                dist[ni, nj] = d + c
                heapq.heappush(heap, (d + c, ni, nj))
    return dist


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_geodesic_fill_takes_a_sample_at_the_least_path_cost(seed):
    rng = np.random.default_rng(seed)
    image = rng.random((9, 11, 3))
    sparse, mask = sd.sample_depth(1.0 + rng.random((9, 11)), fraction=0.1, seed=seed)
    fill, distance = geodesic_fill(image, sparse, mask, contrast=7.0, return_distance=True)
    cx, cy = step_costs(image, 7.0)
    sources = list(zip(*np.nonzero(mask)))
    np.testing.assert_allclose(distance, _dijkstra(cx, cy, sources), rtol=1e-12)
    # the value is that of a sample whose own distance to the pixel is the minimum
    for i, j in np.ndindex(fill.shape):
        takers = [(a, b) for a, b in sources if sparse[a, b] == fill[i, j]]
        assert any(np.isclose(_dijkstra(cx, cy, [s])[i, j], distance[i, j], rtol=1e-12) for s in takers)


def test_geodesic_fill_checks_its_arguments():
    with pytest.raises(ValueError, match="contrast"):
        geodesic_fill(_wall_image(), np.ones((3, 5)), contrast=-1.0)
    with pytest.raises(ValueError, match="image"):
        geodesic_fill(np.zeros((4, 5)), np.ones((3, 5)))


# -- edge_sigma and fill_contrast in the objective ----------------------------------------------------------------

def _frame(seed=0, shape=(24, 32)):
    rng = np.random.default_rng(seed)
    H, W = shape
    ii, jj = np.mgrid[0:H, 0:W].astype(float)
    box = (ii > 6) & (ii < 18) & (jj > 10) & (jj < 24)
    truth = np.where(box, 1.5 + 0.01 * jj, 3.0 + 0.02 * ii)
    image = np.where(box[..., None], [200, 60, 40], [40, 90, 180]) + 10 * rng.standard_normal((H, W, 3))
    image = np.clip(image, 0, 255).astype(np.uint8)
    sparse, mask = sd.sample_depth(truth, fraction=0.08, seed=seed)
    return image, truth, sparse, mask


def test_edge_sigma_zero_reproduces_the_unblurred_weights_exactly():
    image, _, sparse, mask = _frame()
    w = sd.Weights(edge_sigma=0.0, fill_contrast=0.0)
    objective, coarse, _ = build_objective(image, sparse, mask, weights=w)
    np.testing.assert_array_equal(objective.term("smooth_image").row_weights, pair_edge_weights(image, w.kappa))
    np.testing.assert_array_equal(coarse, sd.nearest_fill(sparse, mask))
    assert smoothed_image(image, 0.0).tolist() == (image / 255.0).tolist()


def test_edge_sigma_weights_are_those_of_the_gaussian_blurred_image():
    image, _, sparse, mask = _frame()
    w = sd.Weights(edge_sigma=1.5, fill_contrast=0.0)
    objective, _, _ = build_objective(image, sparse, mask, weights=w)
    blurred = np.stack([ndimage.gaussian_filter(image[..., c] / 255.0, 1.5, mode="reflect") for c in range(3)], -1)
    np.testing.assert_allclose(objective.term("smooth_image").row_weights, pair_edge_weights(blurred, w.kappa),
                               rtol=1e-12)
    constant = np.full((6, 7, 3), 0.3)
    np.testing.assert_allclose(smoothed_image(constant, 2.0), constant, rtol=1e-14)


def test_fill_contrast_makes_the_prior_target_the_geodesic_fill():
    image, _, sparse, mask = _frame()
    w = sd.Weights(fill_contrast=12.0, edge_sigma=1.0)
    objective, coarse, _ = build_objective(image, sparse, mask, weights=w)
    np.testing.assert_array_equal(coarse, geodesic_fill(smoothed_image(image, 1.0), sparse, mask, contrast=12.0))
    np.testing.assert_array_equal(objective.term("prior").target, coarse.ravel())


def test_geodesic_fill_is_closer_to_a_piecewise_truth_than_the_nearest_fill():
    image, truth, sparse, mask = _frame()
    err = lambda z: np.sqrt(np.mean((z - truth)[~mask] ** 2))  # noqa: E731
    assert err(geodesic_fill(image, sparse, mask, contrast=20.0)) < err(sd.nearest_fill(sparse, mask))


@pytest.mark.parametrize("field", ["edge_sigma", "fill_contrast", "depth_jump"])
@pytest.mark.parametrize("bad, error", [(-1.0, ValueError), (float("nan"), ValueError), ("x", TypeError),
                                        ("1", TypeError), (True, TypeError), (None, TypeError)])
def test_modelling_fields_reject_bad_values_naming_the_field(field, bad, error):
    with pytest.raises(error, match=field):
        sd.Weights(**{field: bad})


@pytest.mark.parametrize("value", [2, np.float32(2.0), np.int64(2), np.array(2.0)])
def test_weights_take_any_real_number_as_a_float(value):
    weights = sd.Weights(alpha=value, kappa=value)
    assert type(weights.alpha) is float and weights.alpha == 2.0 and weights.kappa == 2.0


def test_paper_weights_switch_the_modelling_fields_off():
    w = sd.Weights.paper()
    assert (w.edge_sigma, w.fill_contrast, w.depth_jump) == (0.0, 0.0, 0.0)


# -- depth_jump ----------------------------------------------------------------------------------------------------

def test_depth_jump_factor_hand_computed():
    z = np.array([[1.0, 1.0, 2.0], [1.0, 3.0, 2.0]])
    f = depth_jump_factor(z, 0.1)
    fx, fy = f[:6].reshape(2, 3), f[6:].reshape(2, 3)
    cauchy = lambda a, b: 1.0 / (1.0 + ((b - a) / (0.1 * (a + b) / 2)) ** 2)  # noqa: E731
    np.testing.assert_allclose(fx, [[1.0, cauchy(1, 2), 1.0], [cauchy(1, 3), cauchy(3, 2), 1.0]], rtol=1e-14)
    np.testing.assert_allclose(fy, [[1.0, cauchy(1, 3), 1.0], [1.0, 1.0, 1.0]], rtol=1e-14)
    np.testing.assert_allclose(depth_jump_factor(1000 * z, 0.1), f, rtol=1e-14)  # scale-free
    np.testing.assert_array_equal(depth_jump_factor(z, 0.0), np.ones(12))


def test_depth_jump_is_a_second_solve_with_the_relaxed_pair_weights():
    image, _, sparse, mask = _frame()
    w0 = sd.Weights(edge_sigma=1.0)
    first = sd.complete_depth(image, sparse, mask, weights=w0, solver="direct", clip_to_observed=False)
    factor = depth_jump_factor(first.depth, 0.05)
    objective, _, _ = build_objective(image, sparse, mask, weights=w0, pair_factor=factor)
    A, b, _ = objective.normal_equations()
    expected = spla.spsolve(A.tocsc(), b).reshape(first.depth.shape)
    second = sd.complete_depth(image, sparse, mask, weights=w0.replace(depth_jump=0.05), solver="direct",
                               clip_to_observed=False)
    np.testing.assert_allclose(second.depth, expected, rtol=1e-8, atol=1e-10)
    assert second.iterations >= first.iterations
    assert not np.allclose(second.depth, first.depth, rtol=1e-6)


def test_build_objective_rejects_a_bad_pair_factor():
    image, _, sparse, mask = _frame()
    with pytest.raises(ValueError, match="pair_factor"):
        build_objective(image, sparse, mask, pair_factor=np.ones(5))
    with pytest.raises(ValueError, match="pair_factor"):
        build_objective(image, sparse, mask, pair_factor=np.full(2 * sparse.size, 2.0))


# -- prior= ----------------------------------------------------------------------------------------------------------

def test_align_prior_recovers_scale_and_shift_exactly():
    truth = np.add.outer(np.linspace(1.0, 2.0, 6), np.linspace(0.0, 3.0, 7))
    mask = np.zeros(truth.shape, bool)
    mask[::2, ::3] = True
    relative = (truth - 0.75) / 2.5
    aligned, s, t = align_prior(relative, truth, mask)
    assert s == pytest.approx(2.5, rel=1e-12) and t == pytest.approx(0.75, rel=1e-12)
    np.testing.assert_allclose(aligned, truth, rtol=1e-12)
    _, s, t = align_prior(truth / 4.0, truth, mask, alignment="scale")
    assert (s, t) == (pytest.approx(4.0, rel=1e-12), 0.0)
    aligned, s, t = align_prior(relative, truth, mask, alignment="none")
    assert (s, t) == (1.0, 0.0) and aligned.tolist() == relative.tolist()


def test_a_constant_prior_with_exact_samples_gives_back_the_samples_plane():
    H, W = 20, 26
    ii, jj = np.mgrid[0:H, 0:W].astype(float)
    plane = 2.0 + 0.03 * ii + 0.02 * jj
    sparse, mask = sd.sample_depth(plane, fraction=0.05, seed=3)
    image = np.random.default_rng(0).random((H, W, 3))
    thin_plate = sd.Weights.paper(beta=0.0, gamma=0.0, delta=0.0).replace(beta_second=1.0)
    result = sd.complete_depth(image, sparse, mask, weights=thin_plate, solver="direct", clip_to_observed=False,
                               prior=np.full((H, W), 7.0))
    np.testing.assert_allclose(result.depth, plane, rtol=0, atol=1e-9)


def test_an_affine_copy_of_the_truth_as_prior_gives_back_the_truth():
    image, truth, sparse, mask = _frame()
    prior = 0.2 * truth - 0.1
    kept = prior.copy()
    result = sd.complete_depth(image, sparse, mask, prior=prior, clip_to_observed=False, solver="direct")
    np.testing.assert_allclose(result.depth, truth, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(prior, kept)  # the input is not modified


def test_a_smoothly_distorted_prior_lowers_the_error_on_a_piecewise_scene():
    image, truth, sparse, mask = _frame()
    jj = np.arange(truth.shape[1])[None, :]
    prior = 3.0 * (truth + 0.1 * np.sin(jj / 7.0)) + 1.0  # relative: scaled, shifted, and a smooth error
    err = lambda z: np.sqrt(np.mean((z - truth)[~mask] ** 2))  # noqa: E731
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        plain = sd.complete_depth(image, sparse, mask).depth
        fused = sd.complete_depth(image, sparse, mask, prior=prior).depth
    assert err(fused) < 0.5 * err(plain)


def test_prior_arguments_are_checked():
    image, _, sparse, mask = _frame()
    with pytest.raises(ValueError, match="prior"):
        sd.complete_depth(image, sparse, mask, prior=np.ones((3, 3)))
    bad = np.ones(sparse.shape)
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="prior has 1 NaN"):
        sd.complete_depth(image, sparse, mask, prior=bad)
    with pytest.raises(TypeError, match="prior"):
        sd.complete_depth(image, sparse, mask, prior=np.full(sparse.shape, "a"))
    with pytest.raises(ValueError, match="prior_alignment"):
        sd.complete_depth(image, sparse, mask, prior=np.ones(sparse.shape), prior_alignment="affine")
    with pytest.raises(TypeError, match="prior_alignment"):
        sd.complete_depth(image, sparse, mask, prior=np.ones(sparse.shape), prior_alignment=1)
    with pytest.raises(ValueError, match="uncertainty"):
        sd.complete_depth(image, sparse, mask, prior=np.ones(sparse.shape), uncertainty=True)


# -- the benchmark pieces ------------------------------------------------------------------------------------------

def test_tune_formats_weights_with_a_named_penalty():
    from bench import tune

    text = tune._fmt(sd.Weights(gamma=0.01, edge_penalty="cauchy", fill_contrast=5.0))
    assert "edge_penalty=cauchy" in text and "fill_contrast=5" in text and "alpha=1" in text


def test_accuracy_quick_run_writes_its_report(tmp_path):
    from bench import accuracy

    out = tmp_path / "accuracy.md"
    assert accuracy.main(["--quick", "--out", str(out)]) == 0
    text = out.read_text()
    assert "python -m bench.accuracy --quick" in text and "Leave-one-dataset-out" in text
    assert "mechanism check only" in text


def test_accuracy_dataset_families():
    from bench.accuracy import dataset_of

    assert [dataset_of(n) for n in ("nyu_metric3d/00050", "nyu_rcnn_depth/demo", "kitti/0000000050",
                                    "middlebury2003/teddy", "eth3d/terrace", "tum/0")] == [
        "NYU", "NYU", "KITTI", "Middlebury", "ETH3D", "TUM"]


@pytest.mark.parametrize("seed", range(6))
def test_first_order_solution_with_the_geodesic_prior_stays_in_the_observed_range(seed):
    # z_c is still made of observations, so the M-matrix argument holds: z is a convex combination of them
    rng = np.random.default_rng(seed)
    image = rng.random((9, 12, 3))
    sparse, mask = sd.sample_depth(rng.uniform(0.5, 10.0, (9, 12)), fraction=0.15, seed=seed)
    w = sd.Weights(beta=0.1, beta_second=0.0, beta_second_image=0.0, edge_sigma=0.8, fill_contrast=30.0)
    depth = sd.complete_depth(image, sparse, mask, weights=w, solver="direct", clip_to_observed=False).depth
    lo, hi = sparse[mask].min(), sparse[mask].max()
    assert lo - 1e-12 * hi <= depth.min() and depth.max() <= hi + 1e-12 * hi


def test_prior_with_a_starting_depth_reaches_the_same_minimiser():
    image, truth, sparse, mask = _frame()
    prior = 2.0 * truth + np.sin(np.arange(truth.shape[1]) / 5.0)[None, :]
    settings = dict(prior=prior, solver="direct", clip_to_observed=False)
    plain = sd.complete_depth(image, sparse, mask, **settings).depth
    started = sd.complete_depth(image, sparse, mask, x0=np.full(truth.shape, 2.0), **settings).depth
    np.testing.assert_allclose(started, plain, rtol=1e-10)
    with pytest.raises(ValueError, match="x0 has shape"):
        sd.complete_depth(image, sparse, mask, x0=np.ones((2, 2)), prior=prior)
