"""sample_mask / sample_depth patterns (uniform, keypoints, scan lines, sensor holes) and corrupt_samples."""

import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.sampling import HOLE_EDGE_JUMP, PATTERNS, corrupt_samples


def _squares_scene(h=60, w=80):
    """Two bright squares on a dark-grey ground (their corners are the image's corners), a tilted plane of depth."""
    image = np.full((h, w, 3), 0.3)
    image[10:25, 12:30] = 0.9
    image[35:50, 45:70] = 0.9
    depth = 2.0 + 0.01 * np.arange(h)[:, None] + 0.005 * np.arange(w)[None, :]
    return image, depth


def test_keypoints_sit_on_the_corners_of_the_image():
    image, depth = _squares_scene()
    mask = sd.sample_mask(depth, count=8, pattern="keypoints", image=image, seed=0)
    assert mask.sum() == 8
    corners = np.array([(y, x) for y0, y1, x0, x1 in ((10, 24, 12, 29), (35, 49, 45, 69))
                        for y in (y0, y1) for x in (x0, x1)])
    for y, x in np.argwhere(mask):  # every keypoint within 2 pixels of a corner of a square
        assert np.min(np.abs(corners - (y, x)).max(axis=1)) <= 2
    hidden = depth.copy()
    hidden[:30] = np.nan  # no keypoint on an invalid pixel
    mask = sd.sample_mask(hidden, count=4, pattern="keypoints", image=image, seed=0)
    assert mask.sum() == 4 and not mask[:30].any()


def test_keypoints_beyond_the_corners_take_the_strongest_remaining_pixels():
    image, depth = _squares_scene()
    mask = sd.sample_mask(depth, count=300, pattern="keypoints", image=image, seed=0)
    assert mask.sum() == 300
    again = sd.sample_mask(depth, count=300, pattern="keypoints", image=image, seed=0)
    np.testing.assert_array_equal(mask, again)


@pytest.mark.parametrize("spacing", [1, 3, 8])
def test_scan_lines_are_every_spacing_th_row_of_valid_pixels(spacing):
    depth = np.full((20, 7), 3.0)
    depth[:, 2] = np.nan
    mask = sd.sample_mask(depth, pattern="scan_lines", spacing=spacing, seed=4)
    rows = np.flatnonzero(mask.any(axis=1))
    assert len(set(np.diff(rows))) <= 1 and (len(rows) < 2 or np.diff(rows)[0] == spacing)
    assert rows[0] < spacing and rows[-1] + spacing >= 20
    assert not mask[:, 2].any() and mask[rows][:, [0, 1, 3, 4, 5, 6]].all()


def test_holes_leave_the_asked_share_and_remove_dark_bright_and_edge_pixels():
    rng = np.random.default_rng(0)
    h, w = 60, 80
    image = np.clip(0.5 + 0.1 * rng.standard_normal((h, w, 3)), 0.2, 0.8)
    image[5:8, 5:20] = 0.0  # a black object
    image[50:53, 60:75] = 1.0  # a saturated one
    depth = np.full((h, w), 2.0)
    depth[:, 40:] = 4.0  # a depth step between columns 39 and 40
    mask = sd.sample_mask(depth, fraction=0.7, pattern="holes", image=image, seed=1)
    share = mask.mean()
    assert 0.6 <= share <= 0.7  # at most the asked share, less by one blob at most
    assert not mask[5:8, 5:20].any() and not mask[50:53, 60:75].any()
    assert not mask[:, 38:42].any()  # the step's 3x3 band (columns 39, 40) widened by one pixel
    assert HOLE_EDGE_JUMP * 2.0 < 2.0  # the step is an edge by the stated rule
    again = sd.sample_mask(depth, fraction=0.7, pattern="holes", image=image, seed=1)
    np.testing.assert_array_equal(mask, again)


def test_uniform_pattern_is_the_default():
    depth = np.random.default_rng(2).uniform(1, 5, (30, 40))
    np.testing.assert_array_equal(sd.sample_mask(depth, fraction=0.1, seed=3),
                                  sd.sample_mask(depth, fraction=0.1, seed=3, pattern="uniform"))


def test_pattern_arguments_are_checked():
    image, depth = _squares_scene()
    with pytest.raises(ValueError, match="unknown sampling pattern"):
        sd.sample_mask(depth, fraction=0.1, pattern="lidar")
    for pattern in [p for p, needs in PATTERNS.items() if needs]:
        with pytest.raises(ValueError, match="needs the image"):
            sd.sample_mask(depth, fraction=0.1, pattern=pattern)
    with pytest.raises(ValueError, match="spacing=, not fraction"):
        sd.sample_mask(depth, fraction=0.1, pattern="scan_lines")
    with pytest.raises(ValueError, match="image"):
        sd.sample_mask(depth, count=3, pattern="keypoints", image=image[:-1])
    with pytest.raises(ValueError, match="spacing"):
        sd.sample_mask(depth, pattern="scan_lines", spacing=0)


def test_corrupt_samples_noise_and_outliers():
    n = 20000
    sparse = np.full((100, 200), 5.0)
    mask = np.ones((100, 200), dtype=bool)
    mask[:, :100] = False
    sparse[~mask] = np.nan
    out = corrupt_samples(sparse, mask, noise=0.02, outliers=0.0, seed=0)
    ratio = out[mask] / 5.0
    assert abs(np.std(ratio) - 0.02) < 0.002 and abs(np.mean(ratio) - 1) < 0.002
    assert np.isnan(out[~mask]).all() and np.isnan(sparse[~mask]).all() and (sparse[mask] == 5.0).all()
    out = corrupt_samples(sparse, mask, outliers=0.02, outlier_range=(0.7, 1.3), seed=0)
    moved = out[mask] != 5.0
    assert moved.sum() == round(0.02 * n / 2)
    assert np.all((out[mask][moved] >= 5 * 0.7) & (out[mask][moved] <= 5 * 1.3))
    with pytest.raises(ValueError, match="outliers"):
        corrupt_samples(sparse, mask, outliers=1.5)
    with pytest.raises(ValueError, match="noise"):
        corrupt_samples(sparse, mask, noise=-1)
    with pytest.raises(ValueError, match="outlier_range"):
        corrupt_samples(sparse, mask, outliers=0.1, outlier_range=(0, 1))


def test_sample_depth_with_a_pattern_on_a_real_frame():
    frame = sd.load_motorcycle()
    image, depth = frame.image[::4, ::4], np.asarray(frame.depth, dtype=float)[::4, ::4]
    sparse, mask = sd.sample_depth(depth, count=300, pattern="keypoints", image=image, seed=0, noise=0.01,
                                   outliers=0.02)
    assert mask.sum() == 300 and np.isfinite(sparse[mask]).all() and np.isnan(sparse[~mask]).all()
    relative = np.abs(sparse[mask] / depth[mask] - 1)
    assert np.count_nonzero(relative > 0.06) <= 6 + 1  # the 6 outliers, and Gaussian tails beyond 6 sigma are rare
    result = sd.complete_depth(image, sparse, mask)
    assert np.isfinite(result.depth).all()
