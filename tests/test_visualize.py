"""colorize_depth: the colour map's order, missing pixels, the range, and bad input, on hand-made arrays."""

import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.visualize import DEPTH_COLORMAP, DEPTH_COLORMAP_ANCHORS, MISSING_COLOUR

GREY = np.array(MISSING_COLOUR, dtype=np.uint8)


def cie_lightness(rgb):
    """CIE 1976 L* of 8-bit sRGB colours (IEC 61966-2-1 transfer curve, D65 luminance weights)."""
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    y = linear @ np.array([0.2126, 0.7152, 0.0722])
    return np.where(y > (6 / 29) ** 3, 116 * np.cbrt(y) - 16, y * (29 / 3) ** 3)


def test_colour_map_lightness_rises_from_far_to_near():
    lightness = cie_lightness(DEPTH_COLORMAP)
    assert DEPTH_COLORMAP.shape == (256, 3) and DEPTH_COLORMAP.dtype == np.uint8
    assert np.all(np.diff(lightness) > 0)
    assert lightness[0] < 15 and lightness[-1] > 85  # dark far end, bright near end
    np.testing.assert_array_equal(DEPTH_COLORMAP[[0, -1]], DEPTH_COLORMAP_ANCHORS[[0, -1]])


def test_ramp_gets_monotone_colours_near_bright():
    depth = np.linspace(1.0, 10.0, 200)[None, :].repeat(3, axis=0)
    rgb = sd.colorize_depth(depth)
    assert rgb.shape == (3, 200, 3) and rgb.dtype == np.uint8
    lightness = cie_lightness(rgb[0])
    assert np.all(np.diff(lightness) <= 1e-9)  # farther is never lighter
    assert lightness[0] - lightness[-1] > 70  # and the ramp spans the map


def test_missing_pixels_are_grey_and_the_input_is_kept():
    depth = np.array([[1.0, np.nan, 0.0], [-2.0, np.inf, 3.0]])
    before = depth.copy()
    rgb = sd.colorize_depth(depth)
    np.testing.assert_array_equal(depth, before)
    for pixel in [(0, 1), (0, 2), (1, 0), (1, 1)]:
        np.testing.assert_array_equal(rgb[pixel], GREY)
    for pixel in [(0, 0), (1, 2)]:
        assert not np.array_equal(rgb[pixel], GREY)
    custom = sd.colorize_depth(depth, missing=(0, 255, 0))
    np.testing.assert_array_equal(custom[0, 1], [0, 255, 0])
    np.testing.assert_array_equal(custom[0, 0], rgb[0, 0])


def test_all_missing_and_constant_input():
    np.testing.assert_array_equal(sd.colorize_depth(np.full((2, 3), np.nan)), np.broadcast_to(GREY, (2, 3, 3)))
    rgb = sd.colorize_depth(np.full((4, 5), 2.5))
    assert np.all(rgb == rgb[0, 0]) and not np.array_equal(rgb[0, 0], GREY)
    # the middle of the map: neither end
    assert not np.array_equal(rgb[0, 0], DEPTH_COLORMAP[0]) and not np.array_equal(rgb[0, 0], DEPTH_COLORMAP[-1])


def test_vmin_vmax_respected():
    depth = np.array([[0.5, 1.0, 1.5, 2.0, 3.0, 9.0]])
    rgb = sd.colorize_depth(depth, vmin=1.0, vmax=3.0)
    # Notes: entry round(255 (1 - t)), t = (d - vmin) / (vmax - vmin) clipped to [0, 1]
    t = np.clip((depth[0] - 1.0) / 2.0, 0, 1)
    np.testing.assert_array_equal(rgb[0], DEPTH_COLORMAP[np.rint(255 * (1 - t)).astype(int)])
    np.testing.assert_array_equal(rgb[0, 0], DEPTH_COLORMAP[-1])  # nearer than vmin: the nearest colour
    np.testing.assert_array_equal(rgb[0, -1], DEPTH_COLORMAP[0])  # farther than vmax: the farthest colour


def test_one_limit_given_the_other_from_the_data():
    depth = np.linspace(1.0, 2.0, 50)[None, :]
    np.testing.assert_array_equal(sd.colorize_depth(depth, vmin=5.0), np.broadcast_to(DEPTH_COLORMAP[-1], (1, 50, 3)))
    np.testing.assert_array_equal(sd.colorize_depth(depth, vmax=0.5), np.broadcast_to(DEPTH_COLORMAP[0], (1, 50, 3)))
    half = sd.colorize_depth(depth, vmax=1.5)
    np.testing.assert_array_equal(half[0, -1], DEPTH_COLORMAP[0])
    assert not np.array_equal(half[0, 0], DEPTH_COLORMAP[0])


def test_default_range_ignores_a_few_outliers():
    depth = np.linspace(1.0, 2.0, 1000)[None, :].copy()
    depth[0, 500] = 1000.0  # one wild pixel
    rgb = sd.colorize_depth(depth)
    colours = {tuple(c) for c in rgb[0]}
    assert len(colours) > 150  # the 1-2 m ramp still uses most of the map


@pytest.mark.parametrize("dtype", [np.uint16, np.int32, np.float32, np.float64])
def test_integer_and_float_depth_give_the_same_picture(dtype):
    depth = np.array([[0, 1000, 2000], [3000, 4000, 0]])
    expected = sd.colorize_depth(depth.astype(np.float64), vmin=1000, vmax=4000)
    np.testing.assert_array_equal(sd.colorize_depth(depth.astype(dtype), vmin=1000, vmax=4000), expected)


@pytest.mark.parametrize("depth, error, words", [
    (np.ones((2, 2, 3)), ValueError, "2-D"),
    (np.ones(4), ValueError, "2-D"),
    (np.ones((2, 2), dtype=bool), TypeError, "dtype bool"),
    (np.array([["a", "b"]]), TypeError, "real-valued"),
    (np.ones((2, 2), dtype=complex), TypeError, "real-valued"),
])
def test_bad_depth(depth, error, words):
    with pytest.raises(error, match=words):
        sd.colorize_depth(depth)


@pytest.mark.parametrize("options, error, words", [
    (dict(vmin=2.0, vmax=1.0), ValueError, "vmin must be below vmax"),
    (dict(vmin=1.0, vmax=1.0), ValueError, "vmin must be below vmax"),
    (dict(vmin="1"), TypeError, "vmin must be a real number"),
    (dict(vmax=np.nan), ValueError, "vmax must be finite"),
    (dict(missing=(300, 0, 0)), ValueError, "missing must be 3 integers"),
    (dict(missing=(1, 2)), ValueError, "missing must be 3 integers"),
    (dict(missing=(0.5, 0, 0)), ValueError, "missing must be 3 integers"),
    (dict(missing="grey"), TypeError, "missing must be"),
    (dict(missing=None), TypeError, "missing must be a sequence"),
])
def test_bad_options(options, error, words):
    with pytest.raises(error, match=words):
        sd.colorize_depth(np.ones((2, 2)), **options)


def test_options_are_keyword_only():
    with pytest.raises(TypeError):
        sd.colorize_depth(np.ones((2, 2)), 0.0, 1.0)


def test_inverse_depth_scale_spaces_colours_in_one_over_depth():
    from sparsedepth.visualize import INVERSE_DEPTH_RATIO

    depth = np.array([[2.0, 4.0, 80.0]])
    rgb = sd.colorize_depth(depth, vmin=2.0, vmax=80.0, scale="inverse")
    t = (1 / 2.0 - 1 / 4.0) / (1 / 2.0 - 1 / 80.0)  # by hand
    assert rgb[0, 1].tolist() == DEPTH_COLORMAP[round(255 * (1 - t))].tolist()
    assert rgb[0, 0].tolist() == DEPTH_COLORMAP[255].tolist() and rgb[0, 2].tolist() == DEPTH_COLORMAP[0].tolist()
    linear = sd.colorize_depth(depth, vmin=2.0, vmax=80.0, scale="linear")
    assert linear[0, 1].tolist() == DEPTH_COLORMAP[round(255 * (1 - 2.0 / 78.0))].tolist()
    # auto: inverse from a range ratio of INVERSE_DEPTH_RATIO on (a street), linear below (a room)
    np.testing.assert_array_equal(sd.colorize_depth(depth, vmin=2.0, vmax=80.0), rgb)
    room = np.array([[1.0, 2.0, 4.0]])
    assert 4.0 < INVERSE_DEPTH_RATIO * 1.0
    np.testing.assert_array_equal(sd.colorize_depth(room, vmin=1.0, vmax=4.0),
                                  sd.colorize_depth(room, vmin=1.0, vmax=4.0, scale="linear"))
    with pytest.raises(ValueError, match="scale"):
        sd.colorize_depth(depth, scale="log")


def test_colour_scale_is_the_one_colorize_depth_uses():
    """depth_colour_scale: the limits and spacing colorize_depth takes with the same arguments; the colour at a
    depth is DEPTH_COLORMAP[round(255 (1 - position))]."""
    from sparsedepth.visualize import depth_colour_scale

    depth = np.array([[2.0, 3.0, 5.0, 10.0, 30.0, 60.0, np.nan, 0.0]])
    for options in (dict(vmin=2.0, vmax=60.0), dict(vmin=2.0, vmax=60.0, scale="linear"), dict(vmax=8.0), {}):
        colours = depth_colour_scale(depth, **options)
        rgb = sd.colorize_depth(depth, **options)
        valid = depth[0, :6]
        index = np.rint(255 * (1 - colours.position(valid))).astype(int)
        np.testing.assert_array_equal(rgb[0, :6], DEPTH_COLORMAP[index])
    street = depth_colour_scale(depth, vmin=2.0, vmax=60.0)
    assert (street.vmin, street.vmax, street.scale) == (2.0, 60.0, "inverse")  # 60 >= 8 x 2: auto is inverse
    assert depth_colour_scale(depth, vmin=2.0, vmax=10.0).scale == "linear"
    # the default limits: the 2nd and 98th percentiles of the valid pixels
    low, high = np.percentile(depth[0, :6], [2, 98])
    default = depth_colour_scale(depth)
    assert default.vmin == pytest.approx(low) and default.vmax == pytest.approx(high)
    # inverse spacing, by hand: 1/d between 1/2 (place 0) and 1/60 (place 1)
    assert street.position(np.array([4.0]))[0] == pytest.approx((1 / 2 - 1 / 4) / (1 / 2 - 1 / 60))
    with pytest.raises(ValueError, match="no valid pixel"):
        depth_colour_scale(np.full((2, 2), np.nan))
    with pytest.raises(ValueError, match="vmin must be below vmax"):
        depth_colour_scale(depth, vmin=3.0, vmax=2.0)


@pytest.mark.parametrize("vmin, vmax, scale, expected", [
    (1.0, 4.0, "linear", [1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0]),  # step 0.5 >= 3 / 7
    (0.44, 0.92, "linear", [0.5, 0.6, 0.7, 0.8, 0.9]),
    (1.3, 7.6, "linear", [2.0, 3.0, 4.0, 5.0, 6.0, 7.0]),
    (3.0, 80.0, "inverse", [3.0, 4.0, 5.0, 7.0, 10.0, 20.0]),
])
def test_colour_bar_ticks_are_round_depths_in_range(vmin, vmax, scale, expected):
    from sparsedepth.visualize import DepthColourScale

    colours = DepthColourScale(vmin, vmax, scale)
    ticks = colours.ticks()
    np.testing.assert_allclose(ticks, expected)
    places = colours.position(ticks)
    assert np.all((ticks >= vmin) & (ticks <= vmax)) and np.all(np.diff(places) > 0)
    if scale == "inverse":  # Notes: kept when at least 0.75 / count beyond the last one kept
        assert np.all(np.diff(places) >= 0.75 / 6 - 1e-12)
    assert DepthColourScale(2.0, 2.0, "linear").ticks().tolist() == [2.0]
