"""fill_holes: both methods against the functions they are defined by, input checks, a real NYU frame."""

import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.holes.colorization import colorization_fill


def _raw_frame(shape=(24, 32), seed=0):
    rng = np.random.default_rng(seed)
    ii, jj = np.mgrid[0 : shape[0], 0 : shape[1]]
    truth = 1.0 + 0.05 * ii + 0.02 * jj
    image = rng.random(shape + (3,))
    raw = truth.copy()
    raw[rng.random(shape) < 0.2] = 0.0
    raw[3:8, 4:12] = np.nan  # a hole marked with NaN
    return image, raw, truth


def test_colorization_is_colorization_fill():
    image, raw, _ = _raw_frame()
    out = sd.fill_holes(image, raw)
    expected = colorization_fill(image, np.nan_to_num(raw), mask=np.isfinite(raw) & (raw > 0))
    np.testing.assert_array_equal(out, expected)
    assert np.all(np.isfinite(out))


def test_complete_is_complete_depth_with_every_valid_pixel_observed():
    image, raw, _ = _raw_frame()
    weights = sd.Weights(gamma=0.0)
    out = sd.fill_holes(image, raw, method="complete", weights=weights, solver="direct")
    valid = np.isfinite(raw) & (raw > 0)
    expected = sd.complete_depth(image, raw, valid, weights=weights, solver="direct").depth
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12)
    assert np.all(np.isfinite(out)) and out.shape == raw.shape


@pytest.mark.parametrize("method", ["colorization", "complete"])
def test_plane_holes_are_filled_close_to_the_plane(method):
    # a smooth plane: both methods must fill the holes far better than a constant guess
    image, raw, truth = _raw_frame()
    kwargs = {"weights": sd.Weights(gamma=0.0), "solver": "direct"} if method == "complete" else {}
    out = sd.fill_holes(image, raw, method=method, **kwargs)
    holes = ~(np.isfinite(raw) & (raw > 0))
    err = np.abs(out - truth)[holes].mean()
    constant = np.abs(np.nanmean(np.where(holes, np.nan, raw)) - truth)[holes].mean()
    assert err < 0.2 * constant


def test_mask_excludes_clipped_values():
    image, raw, _ = _raw_frame()
    clipped = raw.copy()
    clipped[10:14, 20:26] = 10.0  # the Kinect maximum, as the NYU toolbox treats it
    mask = np.isfinite(clipped) & (clipped > 0) & (clipped != 10.0)
    out = sd.fill_holes(image, clipped, mask=mask)
    assert out[10:14, 20:26].max() < 5.0
    np.testing.assert_array_equal(out, sd.fill_holes(image, np.where(mask, clipped, 0.0)))


def test_inputs_not_modified():
    image, raw, _ = _raw_frame()
    image0, raw0 = image.copy(), raw.copy()
    sd.fill_holes(image, raw)
    np.testing.assert_array_equal(image, image0)
    np.testing.assert_array_equal(raw, raw0)


def test_unknown_method():
    image, raw, _ = _raw_frame()
    with pytest.raises(ValueError, match="unknown hole-filling method"):
        sd.fill_holes(image, raw, method="inpaint")


def test_option_of_the_other_method():
    image, raw, _ = _raw_frame()
    with pytest.raises(ValueError, match="only apply to method='complete'"):
        sd.fill_holes(image, raw, solver="direct")
    with pytest.raises(ValueError, match="alpha only applies"):
        sd.fill_holes(image, raw, method="complete", alpha=2.0)


def test_size_mismatch():
    image, raw, _ = _raw_frame()
    with pytest.raises(ValueError, match="image has shape"):
        sd.fill_holes(image[:-1], raw)


def test_no_valid_pixel():
    image, raw, _ = _raw_frame()
    with pytest.raises(ValueError, match="no valid pixel"):
        sd.fill_holes(image, np.zeros_like(raw))


def test_negative_depth():
    image, raw, _ = _raw_frame()
    raw[0, 0] = -1.0
    with pytest.raises(ValueError, match="negative"):
        sd.fill_holes(image, raw, mask=np.isfinite(raw) & (raw != 0))


def test_real_nyu_frame_matches_nyu_filled_depth_on_the_holes(shared_data):
    # NYU Depth V2 labeled 'depths' were made by the toolbox colorization fill of 'rawDepths':
    # ours must agree on the holes far better than a nearest-neighbour fill does
    frame = sd.load_shared_frame("nyu_rcnn_depth/demo", root=shared_data)
    raw = frame.raw_depth
    holes = np.isnan(raw)
    assert 0.1 < holes.mean() < 0.3
    ours = sd.fill_holes(frame.image, raw)
    nearest = sd.nearest_fill(raw)
    m_ours = sd.depth_metrics(ours, frame.depth, mask=holes)
    m_nn = sd.depth_metrics(nearest, frame.depth, mask=holes)
    assert m_ours.mae < 0.02  # metres: about 6 mm measured
    assert m_ours.mae < 0.1 * m_nn.mae
    assert m_ours.rmse < 0.25 * m_nn.rmse
