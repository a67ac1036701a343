"""Tests for sparsedepth.io: every format is built by hand in tmp_path and checked exactly."""

import os
import struct

import h5py
import imageio.v3 as iio
import numpy as np
import pytest

from sparsedepth import io as sio
from sparsedepth.io import arrays as sio_arrays
from sparsedepth.io import images as sio_images
from sparsedepth.io import pfm as sio_pfm


# ------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------
def _listing(folder):
    return sorted(p.name for p in folder.iterdir())


def _pfm_bytes(rows_top_to_bottom, *, little=True, colour=False, scale=1.0):
    """Hand-encode a PFM with struct, independently of sparsedepth.io.write_pfm."""
    rows = np.asarray(rows_top_to_bottom, dtype=np.float64)
    height, width = rows.shape[:2]
    magic = "PF" if colour else "Pf"
    header = f"{magic}\n{width} {height}\n{-scale if little else scale:g}\n".encode()
    fmt = "<" if little else ">"
    body = b"".join(
        struct.pack(f"{fmt}{rows[r].size}f", *rows[r].ravel()) for r in range(height - 1, -1, -1)
    )
    return header + body


# ------------------------------------------------------------------------------------
# read_image
# ------------------------------------------------------------------------------------
def test_read_image_png_rgb_grey_16bit_and_alpha(tmp_path):
    rgb = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3) * 7
    iio.imwrite(tmp_path / "rgb.png", rgb)
    np.testing.assert_array_equal(sio.read_image(tmp_path / "rgb.png"), rgb)

    grey16 = np.array([[0, 1, 65535], [300, 40000, 2]], dtype=np.uint16)
    iio.imwrite(tmp_path / "g16.png", grey16)
    out = sio.read_image(str(tmp_path / "g16.png"))
    assert out.dtype == np.uint16
    np.testing.assert_array_equal(out, grey16)

    rgba = np.concatenate([rgb, np.full((2, 3, 1), 9, np.uint8)], axis=2)
    iio.imwrite(tmp_path / "rgba.png", rgba)
    np.testing.assert_array_equal(sio.read_image(tmp_path / "rgba.png"), rgb)


def test_read_image_jpeg(tmp_path):
    rgb = np.full((16, 16, 3), 128, dtype=np.uint8)
    iio.imwrite(tmp_path / "a.jpg", rgb)
    out = sio.read_image(tmp_path / "a.jpg")
    assert out.shape == (16, 16, 3) and out.dtype == np.uint8
    assert np.abs(out.astype(int) - 128).max() <= 2


def test_read_image_binary_netpbm(tmp_path):
    rgb = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    (tmp_path / "a.ppm").write_bytes(b"P6\n# a comment\n3 2\n255\n" + rgb.tobytes())
    np.testing.assert_array_equal(sio.read_image(tmp_path / "a.ppm"), rgb)

    grey = np.array([[1, 2], [3, 250]], dtype=np.uint8)
    (tmp_path / "a.pgm").write_bytes(b"P5 2 2 255\n" + grey.tobytes())
    np.testing.assert_array_equal(sio.read_image(tmp_path / "a.pgm"), grey)

    # 16-bit: big endian per the standard; little endian on request (NYU raw PGMs)
    raw = bytes([0x07, 0xFF, 0x01, 0x02])
    (tmp_path / "b.pgm").write_bytes(b"P5 2 1 65535\n" + raw)
    big = sio.read_image(tmp_path / "b.pgm")
    assert big.dtype == np.uint16
    np.testing.assert_array_equal(big, [[0x07FF, 0x0102]])
    np.testing.assert_array_equal(
        sio.read_image(tmp_path / "b.pgm", byteorder="little"), [[0xFF07, 0x0201]]
    )


def test_read_image_ascii_netpbm(tmp_path):
    (tmp_path / "a.pgm").write_text("P2\n# c\n3 2\n1000\n0 1 2\n3 4 1000\n")
    out = sio.read_image(tmp_path / "a.pgm")
    assert out.dtype == np.uint16
    np.testing.assert_array_equal(out, [[0, 1, 2], [3, 4, 1000]])
    (tmp_path / "b.ppm").write_text("P3 1 1 255 10 20 30")
    np.testing.assert_array_equal(sio.read_image(tmp_path / "b.ppm"), [[[10, 20, 30]]])


@pytest.mark.parametrize(
    "content, match",
    [
        (b"P5 2 2 255\n\x01\x02\x03", "3 bytes, expected 4"),
        (b"P5 2 2 255\n\x01\x02\x03\x04\x05", "5 bytes, expected 4"),
        (b"P4 2 2\n\x00", "not a supported Netpbm"),
        (b"P5 2 x 255\n\x00", "malformed Netpbm header"),
        (b"P5 2 2 70000\n" + bytes(8), "invalid Netpbm header"),
        (b"P5 2 2", "truncated Netpbm header"),
        (b"P2 2 1 5\n1 9\n", "outside 0..5"),
        (b"P2 2 1 5\n1\n", "1 samples, expected 2"),
    ],
)
def test_read_image_bad_netpbm(tmp_path, content, match):
    (tmp_path / "bad.pgm").write_bytes(content)
    with pytest.raises(ValueError, match=match):
        sio.read_image(tmp_path / "bad.pgm")


def test_read_image_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such file"):
        sio.read_image(tmp_path / "missing.png")
    (tmp_path / "x.gif").write_bytes(b"GIF89a")
    with pytest.raises(ValueError, match=r"unsupported extension '\.gif'.*\.png"):
        sio.read_image(tmp_path / "x.gif")
    (tmp_path / "junk.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match="could not decode"):
        sio.read_image(tmp_path / "junk.png")
    with pytest.raises(ValueError, match="is a directory"):
        sio.read_image(tmp_path)
    iio.imwrite(tmp_path / "ok.png", np.zeros((2, 2), np.uint8))
    with pytest.raises(ValueError, match="byteorder"):
        sio.read_image(tmp_path / "ok.png", byteorder="middle")


# ------------------------------------------------------------------------------------
# read_depth_png
# ------------------------------------------------------------------------------------
def test_read_depth_png_scales(tmp_path):
    stored = np.array([[0, 1000], [2500, 65535]], dtype=np.uint16)
    iio.imwrite(tmp_path / "d.png", stored)
    expected = np.array([[np.nan, 1.0], [2.5, 65.535]])
    np.testing.assert_array_equal(sio.read_depth_png(tmp_path / "d.png", 1000), expected)
    np.testing.assert_array_equal(sio.read_depth_png(tmp_path / "d.png", "nyu"), expected)
    np.testing.assert_array_equal(
        sio.read_depth_png(tmp_path / "d.png", "kitti"), [[np.nan, 1000 / 256], [2500 / 256, 65535 / 256]]
    )
    np.testing.assert_array_equal(
        sio.read_depth_png(tmp_path / "d.png", "tum"), [[np.nan, 0.2], [0.5, 13.107]]
    )
    assert sio.read_depth_png(tmp_path / "d.png", 1.0).dtype == np.float64
    assert sio.DEPTH_SCALES["mm"] == 1000.0 and sio.DEPTH_SCALES["m"] == 1.0


def test_read_depth_png_8bit_pgm(tmp_path):
    (tmp_path / "disp.pgm").write_bytes(b"P5 3 1 255\n" + bytes([0, 16, 224]))
    np.testing.assert_array_equal(sio.read_depth_png(tmp_path / "disp.pgm", 16), [[np.nan, 1.0, 14.0]])


@pytest.mark.parametrize("scale, exc", [(0, ValueError), (-1.0, ValueError), (np.nan, ValueError),
                                        ("furlongs", ValueError), (True, TypeError), (None, TypeError)])
def test_read_depth_png_bad_scale(tmp_path, scale, exc):
    iio.imwrite(tmp_path / "d.png", np.ones((2, 2), np.uint16))
    with pytest.raises(exc, match="scale"):
        sio.read_depth_png(tmp_path / "d.png", scale)


@pytest.mark.parametrize("reader", ["read_depth", "read_depth_png"])
@pytest.mark.parametrize("scale, exc, text", [
    ("furlongs", ValueError, ": unknown preset 'furlongs'"),
    (-1.0, ValueError, " must be a finite positive number, got -1.0."),
    ([1000], TypeError, " must be a positive number or a preset name, got list."),
])
def test_scale_messages_name_the_keyword_once(tmp_path, reader, scale, exc, text):
    iio.imwrite(tmp_path / "d.png", np.ones((2, 2), np.uint16))
    read = getattr(sio, reader)
    args = (scale,) if reader == "read_depth_png" else ()
    kwargs = {} if reader == "read_depth_png" else {"scale": scale}
    with pytest.raises(exc) as info:
        read(tmp_path / "d.png", *args, **kwargs)
    assert str(info.value).startswith("`scale`" + text)
    with pytest.raises(exc) as info:
        read(tmp_path / "d.png", *args, **kwargs, option_names={"scale": "--depth-scale"})
    assert str(info.value).startswith("--depth-scale" + text)


def test_sensor_code_warning_points_at_the_caller(tmp_path):
    sio.write_depth(tmp_path / "d.png", np.full((4, 4), 2.047), scale=1000)
    with pytest.warns(UserWarning, match="2047") as record:
        sio.read_depth(tmp_path / "d.png", scale=1000)
    assert [w.filename for w in record] == [__file__]


def test_read_depth_png_rejects_colour_and_other_formats(tmp_path):
    iio.imwrite(tmp_path / "c.png", np.ones((2, 2, 3), np.uint8))
    with pytest.raises(ValueError, match="single-channel"):
        sio.read_depth_png(tmp_path / "c.png", 1000)
    iio.imwrite(tmp_path / "c.jpg", np.ones((8, 8), np.uint8))
    with pytest.raises(ValueError, match="unsupported extension"):
        sio.read_depth_png(tmp_path / "c.jpg", 1000)


# ------------------------------------------------------------------------------------
# PFM
# ------------------------------------------------------------------------------------
@pytest.mark.parametrize("little", [True, False])
def test_read_pfm_hand_encoded(tmp_path, little):
    rows = [[1.0, 2.0, 3.0], [4.0, np.inf, -0.5]]
    (tmp_path / "a.pfm").write_bytes(_pfm_bytes(rows, little=little, scale=2.0))
    out = sio.read_pfm(tmp_path / "a.pfm")
    assert out.dtype == np.float32 and out.dtype.isnative
    np.testing.assert_array_equal(out, rows)  # first row on top: the file order is reversed


def test_read_pfm_colour_hand_encoded(tmp_path):
    rows = np.arange(2 * 2 * 3, dtype=np.float64).reshape(2, 2, 3)
    (tmp_path / "c.pfm").write_bytes(_pfm_bytes(rows, colour=True))
    np.testing.assert_array_equal(sio.read_pfm(tmp_path / "c.pfm"), rows)


@pytest.mark.parametrize("byteorder", ["little", "big"])
@pytest.mark.parametrize("shape", [(3, 4), (2, 5, 3)])
def test_pfm_round_trip(tmp_path, byteorder, shape):
    rng = np.random.default_rng(0)
    array = rng.normal(size=shape).astype(np.float32)
    array.flat[0] = np.inf
    array.flat[1] = np.nan
    sio.write_pfm(tmp_path / "r.pfm", array, byteorder=byteorder)
    header = (tmp_path / "r.pfm").read_bytes()[:20]
    assert header.startswith(b"PF\n" if len(shape) == 3 else b"Pf\n")
    assert (b"\n-1\n" in header) == (byteorder == "little")
    out = sio.read_pfm(tmp_path / "r.pfm")
    np.testing.assert_array_equal(out, array)  # NaN == NaN for assert_array_equal


def test_write_pfm_matches_hand_encoding(tmp_path):
    rows = [[1.0, 2.0], [3.0, 4.5]]
    sio.write_pfm(tmp_path / "w.pfm", rows, byteorder="big")
    assert (tmp_path / "w.pfm").read_bytes() == _pfm_bytes(rows, little=False)


@pytest.mark.parametrize(
    "content, match",
    [
        (b"P6\n2 1\n-1\n" + bytes(8), "not a PFM"),
        (b"Pf\n2 1\n0\n" + bytes(8), "non-zero"),
        (b"Pf\n2 1\nnan\n" + bytes(8), "non-zero"),
        (b"Pf\n2 1\n-1\n" + bytes(7), "7 bytes, expected 8"),
        (b"PF\n2 1\n-1\n" + bytes(8), "8 bytes, expected 24"),
        (b"Pf\n0 1\n-1\n", "must be positive"),
        (b"Pf\n2 1\n-x\n" + bytes(8), "not a number"),
    ],
)
def test_read_pfm_bad(tmp_path, content, match):
    (tmp_path / "bad.pfm").write_bytes(content)
    with pytest.raises(ValueError, match=match):
        sio.read_pfm(tmp_path / "bad.pfm")


def test_write_pfm_bad_input(tmp_path):
    with pytest.raises(ValueError, match=r"\(H, W\) or \(H, W, 3\)"):
        sio.write_pfm(tmp_path / "a.pfm", np.zeros((2, 2, 2)))
    with pytest.raises(ValueError, match="float32 range"):
        sio.write_pfm(tmp_path / "a.pfm", np.array([[1e300]]))
    with pytest.raises(ValueError, match="byteorder"):
        sio.write_pfm(tmp_path / "a.pfm", np.zeros((2, 2)), byteorder="native")
    with pytest.raises(TypeError, match="real numbers"):
        sio.write_pfm(tmp_path / "a.pfm", np.zeros((2, 2), complex))
    assert _listing(tmp_path) == []
    with pytest.raises(FileNotFoundError):
        sio.read_pfm(tmp_path / "a.pfm")


# ------------------------------------------------------------------------------------
# calibration and disparity
# ------------------------------------------------------------------------------------
MIDDLEBURY_CALIB = """cam0=[3997.684 0 1176.728; 0 3997.684 1011.728; 0 0 1]
cam1=[3997.684 0 1307.839; 0 3997.684 1011.728; 0 0 1]
doffs=131.111
baseline=193.001
width=2964
height=1988
ndisp=280
isint=0
vmin=27
vmax=250
dyavg=0
dymax=0
"""


def test_read_calib_middlebury(tmp_path):
    (tmp_path / "calib.txt").write_text(MIDDLEBURY_CALIB)
    calib = sio.read_calib(tmp_path / "calib.txt")
    np.testing.assert_array_equal(
        calib.cam0, [[3997.684, 0, 1176.728], [0, 3997.684, 1011.728], [0, 0, 1]]
    )
    assert calib.cam1[0, 2] == 1307.839
    assert calib.focal_px == 3997.684 and calib.cx == 1176.728 and calib.cy == 1011.728
    assert calib.intrinsics == (3997.684, 3997.684, 1176.728, 1011.728)
    assert calib.doffs == 131.111 and calib.baseline_mm == 193.001
    assert (calib.width, calib.height, calib.ndisp) == (2964, 1988, 280)
    assert dict(calib.extra) == {"isint": 0.0, "vmin": 27.0, "vmax": 250.0, "dyavg": 0.0, "dymax": 0.0}
    assert not calib.cam0.flags.writeable
    with pytest.raises(AttributeError):
        calib.doffs = 0.0
    # Z = f B / (d + doffs), mm -> m
    np.testing.assert_allclose(
        calib.depth_from_disparity(np.array([[100.0]])), [[3997.684 * 193.001 / 1000 / 231.111]]
    )


def test_read_calib_eth3d_minimal(tmp_path):
    (tmp_path / "calib.txt").write_text("cam0=[711.499 0 376.135; 0 711.499 227.447; 0 0 1]\nbaseline=59.9432\n")
    calib = sio.read_calib(tmp_path / "calib.txt")
    assert calib.doffs == 0.0 and calib.cam1 is None and calib.width is None and calib.ndisp is None


@pytest.mark.parametrize(
    "text, match",
    [
        ("baseline=1\n", "`cam0` is missing"),
        ("cam0=[1 0 0; 0 1 0; 0 0 1]\n", "`baseline` is missing"),
        ("cam0=[1 0 0; 0 1 0]\nbaseline=1\n", "3x3"),
        ("cam0=1 0 0; 0 1 0; 0 0 1\nbaseline=1\n", "must look like"),
        ("cam0=[1 0 0; 0 1 0; 0 0 a]\nbaseline=1\n", "non-numeric"),
        ("cam0=[1 0 0; 0 1 0; 0 0 1]\nbaseline=abc\n", "`baseline` is not a number"),
        ("cam0=[1 0 0; 0 1 0; 0 0 1]\nbaseline=-5\n", "baseline_mm"),
        ("cam0=[1 0 0; 0 1 0; 0 0 1]\nbaseline=1\nwidth=2.5\n", "`width` must be a non-negative integer"),
        ("cam0=[1 0 0; 0 1 0; 0 0 1]\nbaseline=1\nbaseline=2\n", "given twice"),
        ("cam0=[1 0 0; 0 1 0; 0 0 1]\njunk line\n", "line 2: expected 'key=value'"),
        ("cam0=[0 0 0; 0 1 0; 0 0 1]\nbaseline=1\n", "focal lengths must be positive"),
    ],
)
def test_read_calib_bad(tmp_path, text, match):
    (tmp_path / "calib.txt").write_text(text)
    with pytest.raises(ValueError, match=match):
        sio.read_calib(tmp_path / "calib.txt")


def test_read_calib_missing(tmp_path):
    with pytest.raises(FileNotFoundError):
        sio.read_calib(tmp_path / "calib.txt")


def test_disparity_to_depth_values():
    disp = np.array([[10.0, 20.0, 0.0], [-5.0, np.inf, np.nan]])
    depth = sio.disparity_to_depth(disp, 1000.0, 100.0)  # f*B = 100 m*px
    np.testing.assert_array_equal(depth, [[10.0, 5.0, np.nan], [np.nan, np.nan, np.nan]])
    shifted = sio.disparity_to_depth(disp, 1000.0, 100.0, doffs=10.0)
    np.testing.assert_array_equal(shifted, [[5.0, 100 / 30, 10.0], [20.0, np.nan, np.nan]])
    assert not np.shares_memory(depth, disp)
    np.testing.assert_array_equal(disp[0], [10.0, 20.0, 0.0])  # input untouched
    np.testing.assert_array_equal(sio.disparity_to_depth([4], 2.0, 2000.0), [1.0])


@pytest.mark.parametrize(
    "args, kwargs, exc, match",
    [
        (([1.0], 0.0, 1.0), {}, ValueError, "focal_px"),
        (([1.0], 1.0, np.inf), {}, ValueError, "baseline_mm"),
        (([1.0], 1.0, 1.0), {"doffs": np.nan}, ValueError, "doffs"),
        ((["a"], 1.0, 1.0), {}, TypeError, "disparity"),
        (([1.0], "1", 1.0), {}, TypeError, "focal_px"),
    ],
)
def test_disparity_to_depth_bad(args, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        sio.disparity_to_depth(*args, **kwargs)


@pytest.mark.parametrize("value", [-2, 0, -0.5, np.nan, np.inf])
def test_positive_quantities_share_one_rule(value):
    """Scale, focal length and baseline refuse the same values with the same message."""
    cases = [
        ("`scale`", lambda: sio.read_depth_png(__file__, value)),
        ("`focal_px`", lambda: sio.disparity_to_depth([1.0], value, 1.0)),
        ("`baseline_mm`", lambda: sio.disparity_to_depth([1.0], 1.0, value)),
        ("`baseline_mm`", lambda: sio.StereoCalibration(cam0=np.eye(3), baseline_mm=value)),
    ]
    for label, call in cases:
        with pytest.raises(ValueError) as info:
            call()
        assert str(info.value) == f"{label} must be a finite positive number, got {value!r}."
    with pytest.raises(TypeError, match=r"^`focal_px` must be a real number, got bool\.$"):
        sio.disparity_to_depth([1.0], True, 1.0)
    with pytest.raises(TypeError, match=r"^`scale` must be a positive number or a preset name, got NoneType\.$"):
        sio.read_depth_png(__file__, None)


def test_disparity_to_depth_doffs_is_keyword_only():
    with pytest.raises(TypeError):
        sio.disparity_to_depth([1.0], 1.0, 1.0, 2.0)


# ------------------------------------------------------------------------------------
# NPY / NPZ
# ------------------------------------------------------------------------------------
def test_read_depth_array(tmp_path):
    depth = np.array([[0.0, 1.5], [np.inf, 3.0]], dtype=np.float32)
    np.save(tmp_path / "d.npy", depth)
    expected = np.array([[np.nan, 1.5], [np.nan, 3.0]])
    np.testing.assert_array_equal(sio.read_depth_array(tmp_path / "d.npy"), expected)

    np.savez(tmp_path / "one.npz", whatever=depth)
    np.testing.assert_array_equal(sio.read_depth_array(tmp_path / "one.npz"), expected)
    np.savez(tmp_path / "two.npz", depth=depth, other=np.ones((2, 2)))
    np.testing.assert_array_equal(sio.read_depth_array(tmp_path / "two.npz"), expected)
    np.testing.assert_array_equal(sio.read_depth_array(tmp_path / "two.npz", key="other"), np.ones((2, 2)))
    np.savez(tmp_path / "ints.npz", a=np.array([[0, 1000]], np.uint16), b=np.ones((1, 1)))
    np.testing.assert_array_equal(sio.read_depth_array(tmp_path / "ints.npz", key="a"), [[np.nan, 1000.0]])


def test_read_depth_array_errors(tmp_path):
    np.savez(tmp_path / "two.npz", a=np.ones((2, 2)), b=np.ones((2, 2)))
    with pytest.raises(ValueError, match=r"several arrays \['a', 'b'\]"):
        sio.read_depth_array(tmp_path / "two.npz")
    with pytest.raises(ValueError, match="'c' is not in"):
        sio.read_depth_array(tmp_path / "two.npz", key="c")
    np.save(tmp_path / "cube.npy", np.ones((2, 2, 2)))
    with pytest.raises(ValueError, match=r"2-D \(H, W\) depth map, got shape \(2, 2, 2\)"):
        sio.read_depth_array(tmp_path / "cube.npy")
    np.save(tmp_path / "neg.npy", np.array([[1.0, -2.0]]))
    with pytest.raises(ValueError, match="negative depth"):
        sio.read_depth_array(tmp_path / "neg.npy")
    np.save(tmp_path / "bool.npy", np.ones((2, 2), bool))
    with pytest.raises(ValueError, match="dtype bool"):
        sio.read_depth_array(tmp_path / "bool.npy")
    np.save(tmp_path / "obj.npy", np.array([[None]], dtype=object), allow_pickle=True)
    with pytest.raises(ValueError, match="could not load"):
        sio.read_depth_array(tmp_path / "obj.npy")
    with pytest.raises(ValueError, match="`key` only applies"):
        sio.read_depth_array(tmp_path / "neg.npy", key="x")
    (tmp_path / "bad.npz").write_bytes(b"nonsense")
    with pytest.raises(ValueError, match="could not load"):
        sio.read_depth_array(tmp_path / "bad.npz")
    with pytest.raises(FileNotFoundError):
        sio.read_depth_array(tmp_path / "missing.npy")


# ------------------------------------------------------------------------------------
# NYU HDF5 layouts
# ------------------------------------------------------------------------------------
def _nyu_labeled_frames(n=2, height=4, width=5):
    rng = np.random.default_rng(1)
    images = rng.integers(0, 256, size=(n, height, width, 3), dtype=np.uint8)
    depths = rng.uniform(0.5, 9.5, size=(n, height, width)).astype(np.float32)
    raws = depths.copy()
    raws[:, 0, :] = 0.0  # missing raw Kinect depth
    raws[:, 1, 2] = 0.0
    return images, depths, raws


def _write_nyu_labeled(path, images, depths, raws=None):
    """Store (N, H, W, 3) / (N, H, W) frames as MATLAB v7.3 would: axes reversed per frame."""
    with h5py.File(path, "w") as f:
        f.create_dataset("images", data=images.transpose(0, 3, 2, 1))  # (N, 3, W, H)
        f.create_dataset("depths", data=depths.transpose(0, 2, 1))  # (N, W, H)
        if raws is not None:
            f.create_dataset("rawDepths", data=raws.transpose(0, 2, 1))
        f.create_dataset("labels", data=np.zeros(depths.transpose(0, 2, 1).shape, np.uint16))


def test_nyu_labeled_reader(tmp_path):
    images, depths, raws = _nyu_labeled_frames()
    _write_nyu_labeled(tmp_path / "nyu.mat", images, depths, raws)
    with sio.NYUDepthV2Labeled(tmp_path / "nyu.mat") as nyu:
        assert len(nyu) == 2 and nyu.shape == (4, 5) and nyu.has_raw
        assert "frames=2" in repr(nyu)
        for i in (0, 1):
            image, depth, raw = nyu[i]
            assert image.dtype == np.uint8 and image.shape == (4, 5, 3)
            np.testing.assert_array_equal(image, images[i])
            assert depth.dtype == np.float64
            np.testing.assert_array_equal(depth, depths[i].astype(np.float64))
            expected_raw = raws[i].astype(np.float64)
            expected_raw[expected_raw == 0] = np.nan
            np.testing.assert_array_equal(raw, expected_raw)
        np.testing.assert_array_equal(nyu[-1][0], images[1])
        assert [frame[0][0, 0, 0] for frame in nyu] == [images[0, 0, 0, 0], images[1, 0, 0, 0]]
        with pytest.raises(IndexError, match="out of range for 2 frames"):
            nyu[2]
        with pytest.raises(TypeError, match="integer"):
            nyu[0.5]
    with pytest.raises(ValueError, match="closed"):
        nyu[0]


def test_nyu_labeled_reader_without_raw_and_bad_files(tmp_path):
    images, depths, _ = _nyu_labeled_frames(n=1)
    _write_nyu_labeled(tmp_path / "noraw.mat", images, depths)
    with sio.NYUDepthV2Labeled(tmp_path / "noraw.mat") as nyu:
        assert not nyu.has_raw
        assert nyu[0][2] is None

    (tmp_path / "v5.mat").write_bytes(b"MATLAB 5.0 MAT-file" + bytes(200))
    with pytest.raises(ValueError, match="not a readable HDF5 file"):
        sio.NYUDepthV2Labeled(tmp_path / "v5.mat")
    with h5py.File(tmp_path / "nodepth.mat", "w") as f:
        f.create_dataset("images", data=np.zeros((1, 3, 5, 4), np.uint8))
    with pytest.raises(ValueError, match="no dataset 'depths'"):
        sio.NYUDepthV2Labeled(tmp_path / "nodepth.mat")
    with h5py.File(tmp_path / "mismatch.mat", "w") as f:
        f.create_dataset("images", data=np.zeros((1, 3, 5, 4), np.uint8))
        f.create_dataset("depths", data=np.zeros((1, 4, 5), np.float32))
    with pytest.raises(ValueError, match="'depths' has shape"):
        sio.NYUDepthV2Labeled(tmp_path / "mismatch.mat")
    with pytest.raises(FileNotFoundError):
        sio.NYUDepthV2Labeled(tmp_path / "missing.mat")


def test_nyu_labeled_reads_one_frame_only(tmp_path, monkeypatch):
    images, depths, raws = _nyu_labeled_frames(n=3)
    _write_nyu_labeled(tmp_path / "nyu.mat", images, depths, raws)
    requested = []
    original = h5py.Dataset.__getitem__

    def spy(self, args, *rest, **kw):
        requested.append((self.name, args))
        return original(self, args, *rest, **kw)

    with sio.NYUDepthV2Labeled(tmp_path / "nyu.mat") as nyu:
        monkeypatch.setattr(h5py.Dataset, "__getitem__", spy)
        nyu[1]
    assert sorted(requested) == [("/depths", 1), ("/images", 1), ("/rawDepths", 1)]


def test_read_nyu_h5(tmp_path):
    rng = np.random.default_rng(2)
    rgb = rng.integers(0, 256, size=(3, 4, 6), dtype=np.uint8)
    depth = rng.uniform(0.5, 5.0, size=(4, 6)).astype(np.float32)
    depth[0, 0] = 0.0
    with h5py.File(tmp_path / "00001.h5", "w") as f:
        f.create_dataset("rgb", data=rgb)
        f.create_dataset("depth", data=depth)
    image, out = sio.read_nyu_h5(tmp_path / "00001.h5")
    np.testing.assert_array_equal(image, rgb.transpose(1, 2, 0))
    expected = depth.astype(np.float64)
    expected[0, 0] = np.nan
    np.testing.assert_array_equal(out, expected)
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "00001.h5"), expected)

    with h5py.File(tmp_path / "bad.h5", "w") as f:
        f.create_dataset("rgb", data=rgb.transpose(1, 2, 0))
        f.create_dataset("depth", data=depth)
    with pytest.raises(ValueError, match=r"'rgb' must be \(3, H, W\) uint8"):
        sio.read_nyu_h5(tmp_path / "bad.h5")
    with h5py.File(tmp_path / "nodepth.h5", "w") as f:
        f.create_dataset("rgb", data=rgb)
    with pytest.raises(ValueError, match=r"no dataset 'depth'; available datasets: \['rgb'\]"):
        sio.read_nyu_h5(tmp_path / "nodepth.h5")


# ------------------------------------------------------------------------------------
# read_depth dispatcher
# ------------------------------------------------------------------------------------
def test_read_depth_dispatch(tmp_path):
    iio.imwrite(tmp_path / "d.png", np.array([[0, 256]], np.uint16))
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "d.png", scale="kitti"), [[np.nan, 1.0]])
    (tmp_path / "d.pgm").write_bytes(b"P5 2 1 65535\n\x00\x00\x13\x88")
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "d.pgm", scale=5000), [[np.nan, 1.0]])
    np.save(tmp_path / "d.npy", np.array([[2000.0, 0.0]]))
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "d.npy"), [[2000.0, np.nan]])
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "d.npy", scale="mm"), [[2.0, np.nan]])
    np.savez(tmp_path / "d.npz", a=np.ones((1, 2)), b=np.full((1, 2), 3.0))
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "d.npz", key="b"), [[3.0, 3.0]])
    with h5py.File(tmp_path / "d.hdf5", "w") as f:
        f.create_dataset("z", data=np.array([[4.0, np.nan]]))
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "d.hdf5", key="z"), [[4.0, np.nan]])
    (tmp_path / "d.pfm").write_bytes(_pfm_bytes([[1.0, np.inf], [0.0, 2.0]]))
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "d.pfm"), [[1.0, np.nan], [np.nan, 2.0]])


def test_read_depth_pfm_with_calib(tmp_path):
    (tmp_path / "disp0.pfm").write_bytes(_pfm_bytes([[10.0, np.inf], [20.0, 40.0]]))
    (tmp_path / "calib.txt").write_text("cam0=[1000 0 5; 0 1000 5; 0 0 1]\ndoffs=0\nbaseline=100\n")
    expected = [[10.0, np.nan], [5.0, 2.5]]
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "disp0.pfm", calib=tmp_path / "calib.txt"), expected)
    calib = sio.read_calib(tmp_path / "calib.txt")
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "disp0.pfm", calib=calib), expected)
    # an integer disparity image (e.g. disparity * 4) combined with a calibration
    iio.imwrite(tmp_path / "disp.png", np.array([[40, 0]], np.uint8))
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "disp.png", scale=4, calib=calib), [[10.0, np.nan]])


def test_read_depth_errors(tmp_path):
    (tmp_path / "d.exr").write_bytes(b"x")
    with pytest.raises(ValueError, match=r"unsupported extension '\.exr'.*\.png, \.pgm.*\.pfm.*\.npy.*\.h5"):
        sio.read_depth(tmp_path / "d.exr")
    with pytest.raises(FileNotFoundError):
        sio.read_depth(tmp_path / "missing.png", scale=1000)
    iio.imwrite(tmp_path / "d.png", np.ones((2, 2), np.uint16))
    with pytest.raises(ValueError, match="`scale` is required"):
        sio.read_depth(tmp_path / "d.png")
    with pytest.raises(ValueError, match="`key` only applies"):
        sio.read_depth(tmp_path / "d.png", scale=1, key="depth")
    with pytest.raises(TypeError, match="calib"):
        sio.read_depth(tmp_path / "d.png", scale=1, calib=3.0)
    (tmp_path / "c.pfm").write_bytes(_pfm_bytes(np.ones((1, 1, 3)), colour=True))
    with pytest.raises(ValueError, match="colour PFM"):
        sio.read_depth(tmp_path / "c.pfm")


# ------------------------------------------------------------------------------------
# write_depth
# ------------------------------------------------------------------------------------
DEPTH = np.array([[np.nan, 1.0, 2.5004], [0.0012, 65.535, np.inf]])


def test_write_depth_png_exact(tmp_path):
    sio.write_depth(tmp_path / "d.png", DEPTH)  # default scale 1000
    stored = iio.imread(tmp_path / "d.png")
    assert stored.dtype == np.uint16
    np.testing.assert_array_equal(stored, [[0, 1000, 2500], [1, 65535, 0]])
    sio.write_depth(tmp_path / "k.png", np.array([[1.0, 2.0]]), scale="kitti")
    np.testing.assert_array_equal(iio.imread(tmp_path / "k.png"), [[256, 512]])
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "k.png", scale=256), [[1.0, 2.0]])
    assert _listing(tmp_path) == ["d.png", "k.png"]


@pytest.mark.parametrize("name", ["d.npy", "d.npz", "d.h5", "d.hdf5", "d.pfm"])
def test_write_depth_float_round_trip(tmp_path, name):
    depth = np.array([[np.nan, 1.25, 3.0], [0.0, 7.5, np.inf]])
    sio.write_depth(tmp_path / name, depth, scale=1000)  # scale only matters for PNG
    expected = np.array([[np.nan, 1.25, 3.0], [np.nan, 7.5, np.nan]])
    np.testing.assert_array_equal(sio.read_depth(tmp_path / name), expected)
    assert _listing(tmp_path) == [name]


def test_write_depth_on_disk_conventions(tmp_path):
    depth = np.array([[np.nan, 1.25]])
    sio.write_depth(tmp_path / "d.npz", depth)
    with np.load(tmp_path / "d.npz") as z:
        assert z.files == ["depth"]
    sio.write_depth(tmp_path / "d.h5", depth)
    with h5py.File(tmp_path / "d.h5", "r") as f:
        np.testing.assert_array_equal(f["depth"][()], depth)
    sio.write_depth(tmp_path / "d.pfm", depth)
    np.testing.assert_array_equal(sio.read_pfm(tmp_path / "d.pfm"), [[np.inf, 1.25]])


@pytest.mark.parametrize(
    "depth, scale, match",
    [
        (np.array([[65.5356]]), 1000, "overflows 16-bit PNG"),
        (np.array([[300.0]]), 256, "overflows 16-bit PNG"),
        (np.array([[0.0004]]), 1000, "round to 0"),
    ],
)
def test_write_depth_png_out_of_range(tmp_path, depth, scale, match):
    with pytest.raises(ValueError, match=match):
        sio.write_depth(tmp_path / "d.png", depth, scale=scale)
    assert _listing(tmp_path) == []


def test_write_depth_bad_input(tmp_path):
    with pytest.raises(ValueError, match=r"unsupported extension '\.jpg'.*\.png.*\.pfm.*\.tif.*\.npy"):
        sio.write_depth(tmp_path / "d.jpg", np.ones((2, 2)))
    with pytest.raises(ValueError, match="negative"):
        sio.write_depth(tmp_path / "d.npy", np.array([[1.0, -1.0]]))
    with pytest.raises(ValueError, match="2-D"):
        sio.write_depth(tmp_path / "d.npy", np.ones(3))
    with pytest.raises(TypeError, match="real numbers"):
        sio.write_depth(tmp_path / "d.npy", np.array([["a"]]))
    with pytest.raises(ValueError, match="scale"):
        sio.write_depth(tmp_path / "d.npy", np.ones((2, 2)), scale="bogus")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        sio.write_depth(tmp_path / "nodir" / "d.npy", np.ones((2, 2)))
    assert _listing(tmp_path) == []


def test_write_depth_does_not_modify_input(tmp_path):
    depth = np.array([[np.inf, 0.0, 1.0]])
    sio.write_depth(tmp_path / "d.npy", depth)
    np.testing.assert_array_equal(depth, [[np.inf, 0.0, 1.0]])


@pytest.mark.parametrize(
    "name, module, writer",
    [("d.png", sio_images, "write_png_file"), ("d.npy", sio_arrays, "write_npy_file"),
     ("d.npz", sio_arrays, "write_npz_file"), ("d.h5", sio_arrays, "write_hdf5_file"),
     ("d.pfm", sio_pfm, "write_pfm_file")],
)
def test_write_is_atomic(tmp_path, monkeypatch, name, module, writer):
    def half_then_fail(path, *args):
        with open(path, "wb") as fh:
            fh.write(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(module, writer, half_then_fail)
    with pytest.raises(OSError, match="disk full"):
        sio.write_depth(tmp_path / name, np.ones((2, 2)))
    assert _listing(tmp_path) == []  # neither the target nor a temporary file

    # an existing file survives a failed overwrite unchanged
    (tmp_path / name).write_bytes(b"previous")
    with pytest.raises(OSError, match="disk full"):
        sio.write_depth(tmp_path / name, np.ones((2, 2)))
    assert _listing(tmp_path) == [name]
    assert (tmp_path / name).read_bytes() == b"previous"


def test_write_pfm_is_atomic(tmp_path, monkeypatch):
    monkeypatch.setattr(sio_pfm, "write_pfm_file", lambda *a: (_ for _ in ()).throw(KeyboardInterrupt()))
    with pytest.raises(KeyboardInterrupt):
        sio.write_pfm(tmp_path / "a.pfm", np.ones((2, 2)))
    assert _listing(tmp_path) == []


def test_write_replaces_existing_file(tmp_path):
    target = tmp_path / "d.npy"
    target.write_bytes(b"old")
    sio.write_depth(target, np.full((2, 2), 2.0))
    np.testing.assert_array_equal(sio.read_depth(target), np.full((2, 2), 2.0))
    assert _listing(tmp_path) == ["d.npy"]
    mask = os.umask(0)
    os.umask(mask)
    assert (target.stat().st_mode & 0o777) == (0o666 & ~mask)
