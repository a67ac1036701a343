"""The uncertainty map: its cues, calibration and the complete_depth arguments."""

import warnings

import numpy as np
import pytest
from scipy import spatial

import sparsedepth as sd
from sparsedepth import uncertainty
from sparsedepth.uncertainty import (MIN_OBSERVED, NOVELTY_WEIGHT, TARGET_COVERAGE, colour_novelty, error_cues,
                                     estimate_uncertainty, fit_calibration, split_samples)


def _scene(shape=(40, 56), fraction=0.06, seed=0):
    rng = np.random.default_rng(seed)
    h, w = shape
    rows, cols = np.mgrid[0:h, 0:w].astype(float)
    box = (rows > h / 4) & (rows < 3 * h / 4) & (cols > w / 3) & (cols < 2 * w / 3)
    truth = np.where(box, 1.5 + 0.01 * cols, 3.0 + 0.02 * rows - 0.01 * cols)
    image = np.where(box[..., None], [0.8, 0.2, 0.1], [0.1, 0.3, 0.7]) + 0.02 * rng.standard_normal((h, w, 3))
    sparse, mask = sd.sample_depth(truth, fraction=fraction, seed=seed)
    return np.clip(image, 0, 1), truth, sparse, mask


def _brute_force_cue(depth, sparse, observed, nearest):
    """error_cues by loops, given a nearest fill (checked against exhaustive search by the caller)."""
    h, w = depth.shape
    distance = np.empty((h, w))
    samples = np.argwhere(observed)
    for i in range(h):
        for j in range(w):
            distance[i, j] = np.sqrt(((samples - (i, j)) ** 2).sum(axis=1).min())
    spacing = 1 / np.sqrt(observed.mean())
    r = int(np.ceil(spacing))
    local_range = np.empty((h, w))
    slope = np.empty((h, w))
    for i in range(h):
        for j in range(w):
            window = nearest[max(i - r, 0): i + r + 1, max(j - r, 0): j + r + 1]
            local_range[i, j] = window.max() - window.min()
            up, down = max(i - 1, 0), min(i + 1, h - 1)
            left, right = max(j - 1, 0), min(j + 1, w - 1)
            gy = (depth[down, j] - depth[up, j]) / (down - up)
            gx = (depth[i, right] - depth[i, left]) / (right - left)
            slope[i, j] = np.hypot(gx, gy)
    return np.abs(depth - nearest) + slope * distance + local_range * distance / spacing


def test_split_samples_halves_the_observations_disjointly():
    observed = np.random.default_rng(3).random((30, 40)) < 0.1
    a, b = split_samples(observed, seed=5)
    assert not np.any(a & b)
    np.testing.assert_array_equal(a | b, observed)
    assert abs(int(a.sum()) - int(b.sum())) <= 1
    a2, b2 = split_samples(observed, seed=5)
    np.testing.assert_array_equal(a, a2)


def test_error_cues_match_a_brute_force_computation():
    rng = np.random.default_rng(1)
    depth = 2 + rng.random((17, 23)).cumsum(axis=1) / 10
    observed = rng.random(depth.shape) < 0.12
    sparse = np.where(observed, depth + 0.05 * rng.standard_normal(depth.shape), np.nan)
    nearest = sd.nearest_fill(sparse, observed)
    samples = np.argwhere(observed)
    for i, j in np.ndindex(depth.shape):  # the fill takes one of the equally near samples
        d2 = ((samples - (i, j)) ** 2).sum(axis=1)
        assert nearest[i, j] in sparse[tuple(samples[d2 == d2.min()].T)]
    np.testing.assert_allclose(error_cues(depth, sparse, observed), _brute_force_cue(depth, sparse, observed, nearest),
                               rtol=1e-12, atol=1e-12)


def test_error_cues_vanish_on_a_constant_scene():
    depth = np.full((20, 30), 4.0)
    observed = np.zeros(depth.shape, bool)
    observed[::5, ::5] = True
    np.testing.assert_array_equal(error_cues(depth, np.where(observed, 4.0, np.nan), observed), 0.0)


def _calibration_loss(errors, sigma):
    c1, c2 = np.mean(np.abs(errors) <= sigma), np.mean(np.abs(errors) <= 2 * sigma)
    return max(abs(c1 - TARGET_COVERAGE[0]) / 0.08, abs(c2 - TARGET_COVERAGE[1]) / 0.04)


def test_colour_novelty_by_hand():
    image = np.zeros((3, 4, 3), np.uint8)
    image[:, 2:] = (255, 0, 0)          # red right half
    observed = np.zeros((3, 4), bool)
    observed[1, 0] = True               # one sample, in the black half
    depth = np.full((3, 4), 2.0)
    expected = np.where(np.arange(4) >= 2, NOVELTY_WEIGHT * 2.0 * 1.0, 0.0)[None, :].repeat(3, axis=0)
    np.testing.assert_allclose(colour_novelty(depth, image, observed), expected)
    grey = np.array([[0.0, 0.0, 0.5, 0.5]] * 3)
    np.testing.assert_allclose(colour_novelty(depth, grey, observed), expected * 0.5)
    observed[1, 3] = True               # a red sample too: every colour is shared by a nearby sample
    np.testing.assert_allclose(colour_novelty(depth, image, observed), 0.0)
    image[1, 1] = (255, 0, 0)           # red, next to the black sample: only the second nearest shares it
    assert colour_novelty(depth, image, observed, neighbours=2)[1, 1] == 0.0
    assert colour_novelty(depth, image, observed, neighbours=1)[1, 1] == pytest.approx(NOVELTY_WEIGHT * 2.0)


def test_colour_novelty_against_a_brute_force_search():
    rng = np.random.default_rng(4)
    image = rng.random((14, 19, 3))
    observed = rng.random((14, 19)) < 0.15
    depth = 1 + rng.random((14, 19))
    k = 3
    got = colour_novelty(depth, image, observed, neighbours=k) / (NOVELTY_WEIGHT * depth)
    samples = np.argwhere(observed)
    colours = image[observed]
    for i, j in np.ndindex(depth.shape):
        d2 = ((samples - (i, j)) ** 2).sum(axis=1)
        kth = np.sort(d2)[k - 1]
        distances = np.linalg.norm(colours - image[i, j], axis=1)
        low = distances[d2 <= kth].min()                      # ties at the k-th distance: any of them may count
        high = distances[d2 < kth].min() if np.any(d2 < kth) else np.inf
        assert low - 1e-12 <= got[i, j] <= high + 1e-12


def _kd_tree_novelty(image, observed, k):
    """The least RGB distance to the k nearest samples, one KD-tree query per pixel (as scipy picks among ties)."""
    colours = sd._validation.as_float_image(image)
    samples = np.argwhere(observed)
    k = min(k, len(samples))
    _, nearest = spatial.KDTree(samples).query(np.argwhere(np.ones(observed.shape, bool)), k=k)
    nearest = samples[nearest.reshape(observed.size, k)]
    flat = colours.reshape(observed.size, -1)
    distance = np.linalg.norm(flat[:, None, :] - colours[nearest[..., 0], nearest[..., 1]], axis=-1)
    return distance.min(axis=1).reshape(observed.shape)


def _novelty_frames():
    """Images (uint8 RGB, RGBA, grey; float RGB) with samples at random, on a lattice (many equally near samples),
    around a large gap, fewer than a block's candidates, and thousands of pixels away."""
    rng = np.random.default_rng(8)
    shape = (47, 83)  # not a multiple of the block side
    rgb = rng.integers(0, 256, shape + (3,), dtype=np.uint8)
    rgb[rng.random(shape) < 0.5] = (40, 90, 200)  # repeated colours: ties in colour too
    lattice = np.zeros(shape, bool)
    lattice[1::4, 2::3] = True
    gap = rng.random(shape) < 0.2
    gap[5:40, 10:70] = False
    few = np.zeros(shape, bool)
    few.flat[rng.choice(few.size, 11, replace=False)] = True
    yield rgb, rng.random(shape) < 0.06
    yield rgb, lattice
    yield rgb, gap
    yield rgb, few
    yield np.concatenate([rgb, np.full(shape + (1,), 7, np.uint8)], axis=-1), lattice
    yield rgb[..., 1], rng.random(shape) < 0.1
    yield rgb.astype(float) / 255, lattice
    yield rng.random(shape + (3,)), rng.random(shape) < 0.3
    tall = np.zeros((3100, 4), bool)  # candidates ~3000 pixels away: the block places need float64
    tall[:12] = rng.random((12, 4)) < 0.5
    yield rng.integers(0, 256, tall.shape + (3,), dtype=np.uint8), tall


@pytest.mark.parametrize("neighbours", [1, 3, 8, 20])
def test_colour_novelty_is_the_per_pixel_kd_tree_query(neighbours):
    for image, observed in _novelty_frames():
        depth = np.full(observed.shape, 2.0)
        expected = NOVELTY_WEIGHT * depth * _kd_tree_novelty(image, observed, neighbours)
        np.testing.assert_allclose(colour_novelty(depth, image, observed, neighbours=neighbours), expected,
                                   rtol=1e-12, atol=1e-15)


def test_colour_novelty_blocks_decide_most_pixels():
    image, observed = next(_novelty_frames())
    colours = sd._validation.as_float_image(image)
    samples = np.argwhere(observed)
    decided = uncertainty._nearest_sample_colour_distance(image, colours, samples, spatial.KDTree(samples), 8)
    assert np.mean(np.isfinite(decided)) > 0.5
    reference = _kd_tree_novelty(image, observed, 8)
    np.testing.assert_allclose(decided[np.isfinite(decided)], reference[np.isfinite(decided)], rtol=1e-12, atol=1e-15)


def test_quantile_map_is_interpolation_at_the_sorted_values():
    rng = np.random.default_rng(5)
    values = rng.integers(0, 40, (30, 20)).astype(float)  # many equal values
    reference = rng.random((30, 20))
    where = rng.random((30, 20)) < 0.7
    expected = np.interp(values, np.sort(values[where]), np.sort(reference[where]))[where]
    np.testing.assert_array_equal(uncertainty._quantile_map(values, reference, where), expected)
    values[3, 4] = np.nan
    where[3, 4] = True
    expected = np.interp(values, np.sort(values[where]), np.sort(reference[where]))[where]
    np.testing.assert_array_equal(uncertainty._quantile_map(values, reference, where), expected)


def test_covered_counts_the_ratios_below_each_slope():
    rng = np.random.default_rng(6)
    slopes = np.geomspace(0.1, 3.0, 50)
    ratios = np.concatenate([rng.normal(1.0, 1.0, 500), slopes[::7], [np.inf, -np.inf]])  # some exactly on a slope
    expected = np.array([np.count_nonzero(ratios <= slope) for slope in slopes]) / ratios.size
    np.testing.assert_array_equal(uncertainty._covered(ratios, slopes), expected)


@pytest.mark.parametrize("shape", [(17, 23), (2, 9), (9, 2)])
def test_error_cues_at_pixels_are_the_map_there(shape):
    rng = np.random.default_rng(2)
    depth = 2 + rng.random(shape).cumsum(axis=1) / 10
    observed = rng.random(shape) < 0.2
    observed.flat[[0, -1]] = True
    sparse = np.where(observed, depth + 0.05 * rng.standard_normal(shape), np.nan)
    pixels = np.flatnonzero(rng.random(shape) < 0.5)
    np.testing.assert_array_equal(uncertainty._error_cues_at(depth, sparse, observed, pixels),
                                  error_cues(depth, sparse, observed).ravel()[pixels])


@pytest.mark.parametrize("radius", [0.5, 2.3, 30.0])
def test_local_range_at_pixels_is_the_filtered_range_there(radius):
    image = np.random.default_rng(3).random((13, 21))
    rows, cols = np.divmod(np.arange(image.size), image.shape[1])
    np.testing.assert_array_equal(uncertainty._local_range_at(image, radius, rows, cols),
                                  uncertainty._local_range(image, radius).ravel())


@pytest.mark.parametrize("tail", ["laplace", "student3"])
def test_fit_calibration_is_as_good_as_a_grid_search(tail):
    rng = np.random.default_rng(11)
    cue = rng.uniform(0.05, 2.0, 4000)
    noise = rng.laplace(size=cue.size) if tail == "laplace" else rng.standard_t(3, cue.size)
    errors = cue * noise
    slope, offset = fit_calibration(errors, cue)
    scale = np.median(np.abs(errors))
    best = min(_calibration_loss(errors, s * cue + t)
               for s in np.geomspace(0.01, 10, 150) for t in scale * np.linspace(0, 2, 41))
    assert _calibration_loss(errors, slope * cue + offset) <= max(best + 0.05, 0.5)


@pytest.mark.parametrize("tail", ["normal"])
def test_fit_calibration_meets_both_coverages_on_its_data(tail):
    rng = np.random.default_rng(7)
    cue = rng.uniform(0.05, 2.0, 20000)
    noise = {"normal": rng.standard_normal, "student3": lambda n: rng.standard_t(3, n)}[tail](cue.size)
    errors = cue * noise
    slope, offset = fit_calibration(errors, cue)
    sigma = slope * cue + offset
    cover_1 = np.mean(np.abs(errors) <= sigma)
    cover_2 = np.mean(np.abs(errors) <= 2 * sigma)
    assert slope > 0 and offset >= 0
    assert abs(cover_1 - TARGET_COVERAGE[0]) <= 0.08
    assert abs(cover_2 - TARGET_COVERAGE[1]) <= 0.04


def test_fit_calibration_recovers_a_gaussian_scale():
    rng = np.random.default_rng(2)
    cue = rng.uniform(0.5, 1.5, 50000)
    errors = 0.3 * cue * rng.standard_normal(cue.size)
    slope, offset = fit_calibration(errors, cue)
    # sigma = 0.3 cue covers 68.3 % and 95.4 %; the fit may trade slope for offset but not by much
    probe = np.array([0.5, 1.0, 1.5])
    np.testing.assert_allclose(slope * probe + offset, 0.3 * probe, rtol=0.15)


def _three_completions():
    """``_scene()``'s image, samples and mask, a seeded split of the samples into halves, and the completions
    from all samples and from each half."""
    image, _, sparse, mask = _scene()
    a, b = split_samples(mask, seed=0)
    full = sd.complete_depth(image, sparse, mask).depth
    za = sd.complete_depth(image, np.where(a, sparse, np.nan), a).depth
    zb = sd.complete_depth(image, np.where(b, sparse, np.nan), b).depth
    return image, sparse, mask, a, b, full, za, zb


def test_estimate_uncertainty_orders_pixels_by_the_cue_and_is_the_residual_at_observations():
    image, sparse, mask, a, b, full, za, zb = _three_completions()
    sigma, cal = estimate_uncertainty(full, za, zb, sparse, a, b, image=image)
    np.testing.assert_allclose(sigma[mask], np.abs(full - sparse)[mask])
    held = np.zeros(mask.shape)
    held[b], held[a] = np.abs(za - sparse)[b], np.abs(zb - sparse)[a]
    spacing = 1 / np.sqrt(mask.mean())
    r = int(np.ceil(spacing))
    held_filled = sd.nearest_fill(np.where(mask, held, np.nan), mask)
    padded = np.pad(held_filled, r, mode="symmetric")
    local_mean = np.array([[padded[i:i + 2 * r + 1, j:j + 2 * r + 1].mean() for j in range(mask.shape[1])]
                           for i in range(mask.shape[0])])
    colour = colour_novelty(full, image, mask)  # checked in the two colour_novelty tests
    cue = (error_cues(full, sparse, mask) + np.abs(za - zb) + np.maximum(np.abs(full - za), np.abs(full - zb))
           + local_mean + colour)
    samples = np.argwhere(mask)
    distance = np.array([[np.sqrt(((samples - (i, j)) ** 2).sum(axis=1).min()) for j in range(mask.shape[1])]
                         for i in range(mask.shape[0])])
    gy, gx = np.gradient(full)
    steep = np.percentile(np.hypot(gx, gy)[(distance <= spacing) & ~mask], 90)
    extrapolation = steep * np.maximum(distance - spacing, 0)
    assert extrapolation.max() > 0
    unobserved = ~mask
    order = np.argsort(cue[unobserved], kind="stable")
    calibrated = (sigma - extrapolation)[unobserved][order]
    assert np.all(np.diff(calibrated) >= -1e-12)
    assert calibrated[0] >= cal.offset - 1e-12
    assert np.all(np.isfinite(sigma)) and np.all(sigma >= 0)
    assert cal.held_out == mask.sum()
    held = np.concatenate([np.abs(za - sparse)[b], np.abs(zb - sparse)[a]])
    held_cue = np.concatenate([error_cues(za, sparse, a)[b], error_cues(zb, sparse, b)[a]])
    assert cal.coverage_1sigma == pytest.approx(np.mean(held <= cal.slope * held_cue + cal.offset))


def test_precision_is_the_least_sigma_of_an_unobserved_pixel():
    image, sparse, mask, a, b, full, za, zb = _three_completions()
    plain, cal = estimate_uncertainty(full, za, zb, sparse, a, b, image=image)
    precision = float(np.median(plain[~mask]))
    floored, cal_floored = estimate_uncertainty(full, za, zb, sparse, a, b, image=image, precision=precision)
    np.testing.assert_array_equal(floored[mask], plain[mask])
    np.testing.assert_array_equal(floored[~mask], np.maximum(plain[~mask], precision))
    assert cal_floored == cal
    with pytest.raises(ValueError, match="precision"):
        estimate_uncertainty(full, za, zb, sparse, a, b, precision=-1.0)


@pytest.mark.parametrize("flat, options, least", [
    (True, None, lambda scale: 3e-4 * scale),             # the default solve's depth_rtol times the depth scale
    (False, {"depth_atol": 0.05}, lambda scale: 0.05),    # the user's own depth tolerance
])
def test_complete_depth_floors_sigma_at_the_solve_precision(flat, options, least):
    image, truth, sparse, mask = _scene()
    if flat:  # every completion fits the samples exactly: the cues and the fitted line are all but 0
        sparse = np.where(mask, 3.0, np.nan)
    result = sd.complete_depth(image, sparse, mask, uncertainty=True, options=options)
    sigma = result.uncertainty[~mask]
    scale = 2.0 ** np.round(np.log2(np.median(sparse[mask])))
    assert sigma.min() >= least(scale) * (1 - 1e-12)
    if flat:
        assert np.median(sigma) == pytest.approx(least(scale), rel=1e-9)


def test_complete_depth_uncertainty_keeps_the_depth_and_fills_the_fields():
    image, truth, sparse, mask = _scene()
    plain = sd.complete_depth(image, sparse, mask)
    result = sd.complete_depth(image, sparse, mask, uncertainty=True)
    np.testing.assert_array_equal(result.depth, plain.depth)
    assert plain.uncertainty is None and plain.uncertainty_calibration is None and plain.removed == 0
    assert result.uncertainty.shape == truth.shape
    assert result.uncertainty_calibration.held_out == mask.sum()
    assert result.removed == 0


def test_max_uncertainty_removes_exactly_the_pixels_above_it():
    image, truth, sparse, mask = _scene()
    full = sd.complete_depth(image, sparse, mask, uncertainty=True)
    threshold = float(np.median(full.uncertainty[~mask]))
    cut = sd.complete_depth(image, sparse, mask, max_uncertainty=threshold)
    np.testing.assert_array_equal(cut.uncertainty, full.uncertainty)
    removed = full.uncertainty > threshold
    np.testing.assert_array_equal(np.isnan(cut.depth), removed)
    np.testing.assert_array_equal(cut.depth[~removed], full.depth[~removed])
    assert cut.removed == removed.sum() > 0


def test_uncertainty_ranks_errors_on_a_real_frame():
    frame = sd.load_embedded_frame()
    truth = np.array(frame.depth, dtype=float)
    sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        result = sd.complete_depth(frame.image, sparse, mask, uncertainty=True)
    hidden = np.isfinite(truth) & (truth > 0) & ~mask
    errors = np.abs(result.depth - truth)[hidden]
    sigma = result.uncertainty[hidden]
    better_half = errors[np.argsort(sigma)[: errors.size // 2]]
    worse_half = errors[np.argsort(sigma)[errors.size // 2:]]
    assert np.sqrt(np.mean(better_half ** 2)) < 0.5 * np.sqrt(np.mean(worse_half ** 2))
    assert 0.5 <= np.mean(errors <= sigma) <= 0.9
    assert 0.8 <= np.mean(errors <= 2 * sigma) <= 1.0


@pytest.mark.parametrize("kwargs, error", [
    (dict(uncertainty=1), TypeError),
    (dict(uncertainty="yes"), TypeError),
    (dict(max_uncertainty=-1.0), ValueError),
    (dict(max_uncertainty=float("nan")), ValueError),
    (dict(max_uncertainty="far"), TypeError),
])
def test_bad_uncertainty_arguments(kwargs, error):
    image, truth, sparse, mask = _scene()
    with pytest.raises(error, match="uncertainty"):
        sd.complete_depth(image, sparse, mask, **kwargs)


def test_too_few_samples_for_uncertainty():
    image, truth, _, _ = _scene()
    mask = np.zeros(truth.shape, bool)
    mask.flat[:: truth.size // (MIN_OBSERVED - 1)] = True
    mask.flat[-1] = False
    mask &= np.cumsum(mask.ravel()).reshape(mask.shape) < MIN_OBSERVED
    sparse = np.where(mask, truth, np.nan)
    assert mask.sum() == MIN_OBSERVED - 1
    sd.complete_depth(image, sparse, mask)  # fine without uncertainty
    with pytest.raises(ValueError, match=f"at least {MIN_OBSERVED} observed"):
        sd.complete_depth(image, sparse, mask, uncertainty=True)


def test_the_halves_clamp_warnings_stay_quiet():
    image, truth, sparse, mask = _scene()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plain = sd.complete_depth(image, sparse, mask)
        n_plain = len(caught)
        sd.complete_depth(image, sparse, mask, uncertainty=True)
    assert len(caught) == 2 * n_plain
    assert all(w.filename == __file__ for w in caught) or not caught
    assert plain.clamped >= 0
