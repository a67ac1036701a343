"""Image-to-depth registration: shift_image against explicit loops, estimate_image_shift on scenes of known shift."""

import numpy as np
import pytest

import sparsedepth as sd


def _loop_shift(image, dy, dx):
    H, W = image.shape[:2]
    out = np.empty_like(image)
    for y in range(H):
        for x in range(W):
            out[y, x] = image[min(max(y - dy, 0), H - 1), min(max(x - dx, 0), W - 1)]
    return out


@pytest.mark.parametrize("shift", [(0, 0), (1, 0), (0, -2), (-3, 2), (2, 5), (-4, -1)])
@pytest.mark.parametrize("channels", [None, 3])
def test_shift_image_matches_an_explicit_loop(shift, channels):
    rng = np.random.default_rng(1)
    shape = (5, 6) if channels is None else (5, 6, channels)
    image = rng.integers(0, 255, size=shape, dtype=np.uint8)
    out = sd.shift_image(image, shift)
    assert out.dtype == image.dtype and out.shape == image.shape
    np.testing.assert_array_equal(out, _loop_shift(image, *shift))


def test_shift_image_accepts_numpy_integers_and_keeps_the_input():
    image = np.arange(12.0).reshape(3, 4)
    before = image.copy()
    out = sd.shift_image(image, np.array([1, -1]))
    np.testing.assert_array_equal(image, before)
    np.testing.assert_array_equal(out[1:, :-1], image[:-1, 1:])


@pytest.mark.parametrize("shift", [(1.0, 0), (True, 0), "ab", 3, (1, 2, 3), None])
def test_shift_image_refuses_a_shift_that_is_not_two_integers(shift):
    with pytest.raises(TypeError, match="shift"):
        sd.shift_image(np.zeros((3, 3)), shift)


def test_shift_image_refuses_a_one_dimensional_image():
    with pytest.raises(ValueError, match="image"):
        sd.shift_image(np.zeros(5), (0, 1))


def _scene(offset, shape=(64, 80), regions=14, seed=0):
    """A piecewise-constant scene: Voronoi regions with random depth and colour; the image moved by ``offset``."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform((0, 0), shape, size=(regions, 2))
    yy, xx = np.mgrid[:shape[0], :shape[1]]
    labels = np.argmin((yy[..., None] - centres[:, 0]) ** 2 + (xx[..., None] - centres[:, 1]) ** 2, axis=-1)
    depth = rng.uniform(1.0, 5.0, regions)[labels]
    image = sd.shift_image(rng.uniform(0.0, 1.0, (regions, 3))[labels], offset)
    mask = rng.random(shape) < 0.2
    return image, np.where(mask, depth, 0.0), mask


@pytest.mark.parametrize("offset", [(0, 0), (0, 2), (-1, 0), (2, -1), (-2, -2)])
def test_estimate_recovers_the_shift_that_undoes_a_known_offset(offset):
    image, sparse, mask = _scene(offset)
    estimate = sd.estimate_image_shift(image, sparse, mask, max_shift=2)
    assert estimate.shift == (-offset[0], -offset[1])
    assert estimate.errors.shape == (5, 5)
    assert estimate.errors.min() == estimate.errors[2 - offset[0], 2 - offset[1]]
    if offset == (0, 0):
        assert estimate.gain == 1.0
    else:
        assert estimate.gain == pytest.approx(estimate.errors[2, 2] / estimate.errors.min()) and estimate.gain > 1
    # the estimated shift moves the image back onto the depth (away from the repeated border)
    truth_image, _, _ = _scene((0, 0))
    np.testing.assert_array_equal(sd.shift_image(image, estimate.shift)[2:-2, 2:-2], truth_image[2:-2, 2:-2])


def test_errors_are_the_held_out_mean_absolute_error_of_a_geodesic_fill():
    """One candidate's error recomputed from geodesic_fill and the documented split (every group predicted)."""
    image, sparse, mask = _scene((1, 0), shape=(24, 30), regions=6)
    estimate = sd.estimate_image_shift(image, sparse, mask, max_shift=1, folds=3, fill_contrast=5.0, seed=4)
    samples = np.flatnonzero(mask)
    group = np.empty(samples.size, dtype=int)
    group[np.random.default_rng(4).permutation(samples.size)] = np.arange(samples.size) % 3
    total = 0.0
    for g in range(3):
        kept = mask.copy()
        kept.ravel()[samples[group == g]] = False
        fill = sd.geodesic_fill(sd.shift_image(image, (-1, 1)), sparse, kept, contrast=5.0)
        total += np.abs(fill.ravel() - sparse.ravel())[samples[group == g]].sum()
    assert estimate.errors[0, 2] == pytest.approx(total / samples.size, rel=1e-12)


def test_without_image_contrast_every_shift_scores_alike_and_none_is_taken():
    image, sparse, mask = _scene((0, 2))
    estimate = sd.estimate_image_shift(image, sparse, mask, max_shift=1, fill_contrast=0.0)
    np.testing.assert_allclose(estimate.errors, estimate.errors[1, 1], rtol=1e-12)
    assert estimate.shift == (0, 0) and estimate.gain == pytest.approx(1.0)


def test_min_gain_keeps_the_unshifted_image_unless_the_shift_wins_by_that_factor():
    image, sparse, mask = _scene((0, 2))
    estimate = sd.estimate_image_shift(image, sparse, mask, max_shift=2)
    assert estimate.gain > 1
    held = sd.estimate_image_shift(image, sparse, mask, max_shift=2, min_gain=estimate.gain * 1.01)
    assert held.shift == (0, 0) and held.best == estimate.shift == (0, -2)
    np.testing.assert_array_equal(held.errors, estimate.errors)


def test_the_estimate_is_deterministic_for_a_seed():
    image, sparse, mask = _scene((1, 1), seed=3)
    a = sd.estimate_image_shift(image, sparse, mask, max_shift=1, seed=7)
    b = sd.estimate_image_shift(image, sparse, mask, max_shift=1, seed=7)
    np.testing.assert_array_equal(a.errors, b.errors)


@pytest.mark.parametrize("kwargs, error, match", [
    (dict(max_shift=-1), ValueError, "max_shift"),
    (dict(max_shift=1.5), ValueError, "max_shift"),
    (dict(folds=1), ValueError, "folds"),
    (dict(fill_contrast=-1.0), ValueError, "fill_contrast"),
    (dict(fill_contrast="5"), TypeError, "fill_contrast"),
    (dict(min_gain=0.5), ValueError, "min_gain"),
    (dict(seed=-1), ValueError, "seed"),
    (dict(seed=1.0), ValueError, "seed"),
    (dict(seed=True), ValueError, "seed"),
])
def test_estimate_refuses_bad_arguments(kwargs, error, match):
    image, sparse, mask = _scene((0, 0), shape=(16, 16), regions=4)
    with pytest.raises(error, match=match):
        sd.estimate_image_shift(image, sparse, mask, **kwargs)


def test_estimate_needs_two_samples_per_fold_and_matching_shapes():
    image = np.zeros((10, 10))
    mask = np.zeros((10, 10), bool)
    mask.ravel()[:7] = True
    with pytest.raises(ValueError, match="at least 8 observed"):
        sd.estimate_image_shift(image, np.where(mask, 1.0, 0.0), mask, folds=4)
    with pytest.raises(ValueError):
        sd.estimate_image_shift(np.zeros((9, 10)), np.ones((10, 10)))


def test_the_estimate_counts_its_samples():
    image, sparse, mask = _scene((0, 2), shape=(24, 30), regions=6)
    assert sd.estimate_image_shift(image, sparse, mask, max_shift=1).samples == int(mask.sum())


def _made(errors, samples, shift=(0, 0)):
    return sd.ImageShift(shift=shift, errors=np.asarray(errors, float), gain=1.0, samples=samples)


def test_pool_averages_the_error_maps_weighted_by_their_samples():
    rng = np.random.default_rng(5)
    maps = [rng.uniform(1.0, 2.0, (5, 5)) for _ in range(3)]
    counts = [7, 40, 13]
    pooled = sd.pool_image_shifts([_made(e, n) for e, n in zip(maps, counts)])
    expected = (7 * maps[0] + 40 * maps[1] + 13 * maps[2]) / 60
    np.testing.assert_allclose(pooled.errors, expected, rtol=1e-12)
    assert pooled.samples == 60
    assert pooled.gain == pytest.approx(expected[2, 2] / expected.min(), rel=1e-12)
    k = np.unravel_index(np.argmin(expected), expected.shape)
    best = (int(k[0]) - 2, int(k[1]) - 2)
    assert pooled.best == best
    assert pooled.shift == (best if expected[2, 2] > expected.min() else (0, 0))


def test_pool_lets_many_samples_outvote_a_strong_sparse_preference():
    centre = np.array([[5.0, 5, 5], [5, 1, 5], [5, 5, 5]])   # unshifted best by 1
    corner = np.array([[0.5, 5, 5], [5, 2, 5], [5, 5, 5]])   # (-1, -1) best by 1.5
    # 30 x 1 + 10 x 2 = 50 at the centre against 30 x 5 + 10 x 0.5 = 155 at the corner: no shift
    pooled = sd.pool_image_shifts([_made(centre, 30), _made(corner, 10, shift=(-1, -1))])
    assert pooled.shift == (0, 0) and pooled.gain == pytest.approx(1.0)
    np.testing.assert_allclose(pooled.errors[1, 1], 50 / 40)
    # 1 x 1 + 10 x 2 = 21 at the centre against 1 x 5 + 10 x 0.5 = 10 at the corner: the corner, gain 2.1
    pooled = sd.pool_image_shifts([_made(centre, 1), _made(corner, 10)])
    assert pooled.shift == (-1, -1) and pooled.gain == pytest.approx(2.1)
    np.testing.assert_allclose(pooled.errors[0, 0], 10 / 11)


def test_pool_min_gain_keeps_the_unshifted_image_unless_the_pool_wins_by_that_factor():
    centre = np.array([[5.0, 5, 5], [5, 1, 5], [5, 5, 5]])
    corner = np.array([[0.5, 5, 5], [5, 2, 5], [5, 5, 5]])
    estimates = [_made(centre, 1), _made(corner, 10)]
    assert sd.pool_image_shifts(estimates, min_gain=2.0).shift == (-1, -1)
    held = sd.pool_image_shifts(estimates, min_gain=2.2)
    assert held.shift == (0, 0) and held.best == (-1, -1) and held.gain == pytest.approx(2.1)


def test_pooling_one_estimate_gives_that_estimate():
    image, sparse, mask = _scene((0, 2))
    estimate = sd.estimate_image_shift(image, sparse, mask, max_shift=2)
    pooled = sd.pool_image_shifts([estimate])
    assert pooled.shift == estimate.shift == (0, -2)
    np.testing.assert_allclose(pooled.errors, estimate.errors, rtol=1e-12)
    assert pooled.samples == estimate.samples and pooled.gain == pytest.approx(estimate.gain, rel=1e-12)
    held = sd.estimate_image_shift(image, sparse, mask, max_shift=2, min_gain=estimate.gain * 1.01)
    assert sd.pool_image_shifts([held], min_gain=estimate.gain * 1.01).shift == held.shift == (0, 0)


def test_pooling_two_frames_of_one_offset_finds_it():
    estimates = [sd.estimate_image_shift(*_scene((1, 0), seed=s), max_shift=2) for s in (0, 1)]
    pooled = sd.pool_image_shifts(estimates)
    assert pooled.shift == (-1, 0)
    assert pooled.samples == sum(e.samples for e in estimates)


def test_pool_refuses_nothing_other_types_and_maps_of_different_sizes():
    with pytest.raises(ValueError, match="at least one"):
        sd.pool_image_shifts([])
    with pytest.raises(TypeError, match="ImageShift"):
        sd.pool_image_shifts([_made(np.ones((3, 3)), 4), np.ones((3, 3))])
    with pytest.raises(ValueError, match="same size"):
        sd.pool_image_shifts([_made(np.ones((3, 3)), 4), _made(np.ones((5, 5)), 4)])
    with pytest.raises(ValueError, match="min_gain"):
        sd.pool_image_shifts([_made(np.ones((3, 3)), 4)], min_gain=0.5)
