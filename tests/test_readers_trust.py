"""Readers: honest units, sensor conventions, non-regular files and pixel limits (library and CLI)."""

import json
import os
import struct
import threading
import warnings
import zlib

import h5py
import imageio.v3 as iio
import numpy as np
import pytest
import tifffile
from PIL import Image

import sparsedepth as sd
from sparsedepth import io as sio
from sparsedepth.complete import main

from conftest import make_scene

FAST = ["--gamma", "0", "--solver", "direct", "-q"]


def _png_header_only(width, height):
    """A PNG whose IHDR declares width x height, with no image data (hand-encoded)."""
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IEND", b"")


def _pgm16(values, *, little):
    """Binary 16-bit PGM (header maxval 65535) with the raster in the given byte order."""
    values = np.asarray(values, dtype=np.uint16)
    height, width = values.shape
    raster = values.astype("<u2" if little else ">u2").tobytes()
    return f"P5\n{width} {height}\n65535\n".encode() + raster


def _smooth_uint16(shape=(24, 32)):
    ii, jj = np.mgrid[0 : shape[0], 0 : shape[1]]
    return (800 + 7 * ii + 3 * jj).astype(np.uint16)  # a slanted plane in raw sensor units


def _one_line(err):
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def _finishes(function, seconds=20.0):
    """Run function in a thread; return ('ok', value) / ('raised', exc) or None if still blocked."""
    outcome = []

    def target():
        try:
            outcome.append(("ok", function()))
        except BaseException as exc:  # noqa: BLE001 - reported to the test
            outcome.append(("raised", exc))

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    thread.join(seconds)
    return outcome[0] if outcome else None


def _unblock_fifo(path):
    """Open the FIFO for writing once, so that a reader blocked on it returns (cleanup)."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
    except OSError:
        return
    os.close(fd)


# ------------------------------------------------------------------------------------
# integer data need a scale, whatever the container
# ------------------------------------------------------------------------------------
def _write_stored(path, stored):
    ext = path.suffix
    if ext == ".npy":
        np.save(path, stored)
    elif ext == ".npz":
        np.savez(path, depth=stored)
    elif ext == ".h5":
        with h5py.File(path, "w") as f:
            f.create_dataset("depth", data=stored)
    elif ext == ".tif":
        tifffile.imwrite(path, stored)
    else:
        iio.imwrite(path, stored)


@pytest.mark.parametrize("ext", [".npy", ".npz", ".h5", ".tif", ".png"])
def test_integer_depth_needs_a_scale_in_every_format(tmp_path, ext):
    stored = np.array([[0, 1500], [2500, 40000]], dtype=np.uint16)
    path = tmp_path / f"d{ext}"
    _write_stored(path, stored)
    with pytest.raises(ValueError, match=r"`scale` is required for integer depth \(uint16\)"):
        sio.read_depth(path)
    np.testing.assert_array_equal(sio.read_depth(path, scale="mm"), [[np.nan, 1.5], [2.5, 40.0]])


@pytest.mark.parametrize("ext", [".npy", ".npz", ".h5", ".tif"])
def test_float_depth_keeps_scale_one(tmp_path, ext):
    stored = np.array([[0.0, 1.25], [np.inf, 7.5]], dtype=np.float32)
    path = tmp_path / f"d{ext}"
    _write_stored(path, stored)
    np.testing.assert_array_equal(sio.read_depth(path), [[np.nan, 1.25], [np.nan, 7.5]])


def test_tiff_depth_16bit_and_float32_match_the_stored_values(tmp_path):
    rng = np.random.default_rng(3)
    mm = rng.integers(0, 65536, size=(9, 13)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "mm.tiff", mm)
    expected = np.where(mm == 0, np.nan, mm / 1000.0)
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "mm.tiff", scale=1000), expected)
    metres = rng.uniform(0.5, 9.0, size=(9, 13)).astype(np.float32)
    tifffile.imwrite(tmp_path / "m.tif", metres)
    np.testing.assert_array_equal(sio.read_depth(tmp_path / "m.tif"), metres.astype(np.float64))
    tifffile.imwrite(tmp_path / "rgb.tif", np.zeros((4, 4, 3), np.uint16))
    with pytest.raises(ValueError, match="single-channel"):
        sio.read_depth(tmp_path / "rgb.tif", scale=1)


# ------------------------------------------------------------------------------------
# sensor conventions: invalid codes, depth range, Kinect disparity, byte order
# ------------------------------------------------------------------------------------
def test_invalid_values_and_depth_range(tmp_path):
    stored = np.array([[0, 2047, 500], [65535, 1200, 9000]], dtype=np.uint16)
    iio.imwrite(tmp_path / "d.png", stored)
    out = sio.read_depth(tmp_path / "d.png", scale=1000, invalid_values=[2047, 65535])
    np.testing.assert_array_equal(out, [[np.nan, np.nan, 0.5], [np.nan, 1.2, 9.0]])
    out = sio.read_depth(tmp_path / "d.png", scale=1000, invalid_values=[2047, 65535], min_depth=0.6, max_depth=8)
    np.testing.assert_array_equal(out, [[np.nan, np.nan, np.nan], [np.nan, 1.2, np.nan]])
    with pytest.raises(ValueError, match="`min_depth` .* larger than `max_depth`"):
        sio.read_depth(tmp_path / "d.png", scale=1000, min_depth=3, max_depth=2)
    with pytest.raises(ValueError, match="`invalid_values` must hold finite numbers"):
        sio.read_depth(tmp_path / "d.png", scale=1000, invalid_values=[float("nan")])


def test_frequent_sensor_code_warns_unless_declared(tmp_path):
    stored = np.full((10, 10), 900, np.uint16)
    stored[:3] = 2047  # 30 % "no measurement" codes
    iio.imwrite(tmp_path / "d.png", stored)
    with pytest.warns(UserWarning, match=r"30\.0% of the pixels hold 2047"):
        sio.read_depth(tmp_path / "d.png", scale=1000)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = sio.read_depth(tmp_path / "d.png", scale=1000, invalid_values=[2047])
    assert np.isnan(out[:3]).all() and np.all(out[3:] == 0.9)


def test_kinect_disparity_matches_the_nyu_toolbox_formula(tmp_path):
    raw = np.array([[600, 2047, 1000], [1092, 1093, 0]], dtype=np.uint16)
    expected = np.array([[351.3 / (1092.5 - 600), np.nan, 351.3 / 92.5], [351.3 / 0.5, np.nan, np.nan]])
    # 0 is invalid on disk for every integer format (read_depth), 1093 > 1092.5 is behind the camera
    (tmp_path / "raw.pgm").write_bytes(_pgm16(raw, little=True))
    out = sio.read_depth(tmp_path / "raw.pgm", byteorder="little", calib=sio.KINECT_NYU)
    np.testing.assert_allclose(out, expected, rtol=1e-15)
    direct = sio.KINECT_NYU.depth_from_disparity(raw.astype(float))
    np.testing.assert_allclose(direct[0], expected[0], rtol=1e-15)


def test_byte_swapped_16bit_netpbm_is_refused_by_default(tmp_path):
    values = _smooth_uint16()
    (tmp_path / "little.pgm").write_bytes(_pgm16(values, little=True))
    (tmp_path / "big.pgm").write_bytes(_pgm16(values, little=False))
    with pytest.raises(ValueError, match=r"look byte-swapped.*pass `byteorder` little"):
        sio.read_image(tmp_path / "little.pgm")
    with pytest.raises(ValueError, match="byte-swapped"):
        sio.read_depth(tmp_path / "little.pgm", scale=1)
    np.testing.assert_array_equal(sio.read_image(tmp_path / "little.pgm", byteorder="little"), values)
    np.testing.assert_array_equal(sio.read_image(tmp_path / "little.pgm", byteorder="big"), values.byteswap())
    np.testing.assert_array_equal(sio.read_image(tmp_path / "big.pgm"), values)
    noise = np.random.default_rng(0).integers(0, 65536, size=(20, 20)).astype(np.uint16)
    (tmp_path / "noise.pgm").write_bytes(_pgm16(noise, little=False))
    np.testing.assert_array_equal(sio.read_image(tmp_path / "noise.pgm"), noise)


def test_nyu_raw_kinect_pgm(shared_data):
    path = shared_data / "nyu_raw_open3d" / "NYU_depth.pgm"
    with pytest.raises(ValueError, match="byte-swapped"):
        sio.read_depth(path, scale=1000)
    raw = sio.read_image(path, byteorder="little")
    assert raw.shape == (480, 640) and raw.max() == 2047
    np.testing.assert_allclose((raw == 2047).mean(), 0.072, atol=0.001)  # SOURCES.md: 7.2 % invalid
    depth = sio.read_depth(path, byteorder="little", calib=sio.KINECT_NYU)
    valid = np.isfinite(depth)
    np.testing.assert_array_equal(valid, raw != 2047)
    assert 1.38 < np.nanmin(depth) < 1.40 and 6.68 < np.nanmax(depth) < 6.70  # SOURCES.md: 1.39-6.69 m
    np.testing.assert_allclose(depth[valid], 351.3 / (1092.5 - raw[valid].astype(float)), rtol=1e-15)


# ------------------------------------------------------------------------------------
# 1-bit images and masks
# ------------------------------------------------------------------------------------
def test_one_bit_png_reads_as_image_and_mask(tmp_path):
    bits = np.random.default_rng(5).random((7, 11)) < 0.3
    Image.fromarray(bits).save(tmp_path / "m.png")
    assert Image.open(tmp_path / "m.png").mode == "1"
    image = sio.read_image(tmp_path / "m.png")
    assert image.dtype == np.uint8
    np.testing.assert_array_equal(image, bits.astype(np.uint8) * 255)
    np.testing.assert_array_equal(sio.read_mask(tmp_path / "m.png"), bits)


def test_read_mask_arrays(tmp_path):
    bits = np.array([[True, False], [False, True]])
    np.save(tmp_path / "b.npy", bits)
    np.save(tmp_path / "i.npy", bits.astype(np.uint8))
    np.savez(tmp_path / "m.npz", mask=bits)
    with h5py.File(tmp_path / "m.h5", "w") as f:
        f.create_dataset("mask", data=bits.astype(np.float32))
    for name in ("b.npy", "i.npy", "m.npz", "m.h5"):
        np.testing.assert_array_equal(sio.read_mask(tmp_path / name), bits)
    np.save(tmp_path / "two.npy", np.array([[0, 2]]))
    with pytest.raises(ValueError, match="only 0 and 1"):
        sio.read_mask(tmp_path / "two.npy")


# ------------------------------------------------------------------------------------
# non-regular files and pixel limits
# ------------------------------------------------------------------------------------
_EVERY_READER = [
    ("image.png", lambda p: sio.read_image(p)),
    ("depth.png", lambda p: sio.read_depth(p, scale=1)),
    ("depth.pfm", lambda p: sio.read_pfm(p)),
    ("depth.npy", lambda p: sio.read_depth_array(p)),
    ("depth.h5", lambda p: sio.read_depth(p)),
    ("frame.h5", lambda p: sio.read_nyu_h5(p)),
    ("labeled.mat", lambda p: sio.NYUDepthV2Labeled(p)),
    ("calib.txt", lambda p: sio.read_calib(p)),
    ("mask.png", lambda p: sio.read_mask(p)),
    ("depth.tif", lambda p: sio.read_depth(p, scale=1)),
]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
@pytest.mark.parametrize("name, reader", _EVERY_READER, ids=[n for n, _ in _EVERY_READER])
def test_fifo_is_refused_without_blocking(tmp_path, name, reader):
    fifo = tmp_path / name
    os.mkfifo(fifo)
    try:
        outcome = _finishes(lambda: reader(fifo))
    finally:
        _unblock_fifo(fifo)
    assert outcome is not None, f"reading a FIFO named {name} blocked"
    kind, exc = outcome
    assert kind == "raised" and type(exc) is ValueError and "FIFO" in str(exc), outcome


@pytest.mark.parametrize("name, reader", _EVERY_READER, ids=[n for n, _ in _EVERY_READER])
def test_directory_and_device_are_refused(tmp_path, name, reader):
    folder = tmp_path / name
    folder.mkdir()
    with pytest.raises(ValueError, match="is a directory; expected a regular file"):
        reader(folder)
    if os.path.exists(os.devnull) and os.devnull == "/dev/null":
        with pytest.raises(ValueError, match="character device"):
            reader(os.devnull)


def test_declared_size_above_the_limit_is_refused_before_decoding(tmp_path):
    (tmp_path / "huge.png").write_bytes(_png_header_only(100_000, 100_000))
    with pytest.raises(ValueError, match=r"declares 100000x100000 = 10000000000 pixels.*`max_pixels`"):
        sio.read_image(tmp_path / "huge.png")
    (tmp_path / "huge.pfm").write_bytes(b"Pf\n100000 100000\n-1\n" + bytes(16))
    with pytest.raises(ValueError, match="declares 100000x100000"):
        sio.read_pfm(tmp_path / "huge.pfm")
    (tmp_path / "huge.pgm").write_bytes(b"P5\n60000 60000\n65535\n" + bytes(16))
    with pytest.raises(ValueError, match="declares 60000x60000"):
        sio.read_depth(tmp_path / "huge.pgm", scale=1)
    with open(tmp_path / "huge.npy", "wb") as fh:  # header only: the data would be 80 GB
        np.lib.format.write_array_header_1_0(fh, {"descr": "<f8", "fortran_order": False, "shape": (100_000, 100_000)})
    with pytest.raises(ValueError, match="declares 100000x100000"):
        sio.read_depth(tmp_path / "huge.npy")
    with h5py.File(tmp_path / "huge.h5", "w") as f:  # chunked and never written: a few kB on disk
        f.create_dataset("depth", shape=(100_000, 100_000), dtype="f4", chunks=(64, 64))
    with pytest.raises(ValueError, match="declares 100000x100000"):
        sio.read_depth(tmp_path / "huge.h5")
    # the limit is an option, in every reader
    small = np.ones((20, 30), np.uint16)
    iio.imwrite(tmp_path / "small.png", small)
    tifffile.imwrite(tmp_path / "small.tif", small)
    np.save(tmp_path / "small.npy", small.astype(float))
    for path, kwargs in (("small.png", {"scale": 1}), ("small.tif", {"scale": 1}), ("small.npy", {})):
        with pytest.raises(ValueError, match="declares 30x20 = 600 pixels, more than the limit 599"):
            sio.read_depth(tmp_path / path, max_pixels=599, **kwargs)
        assert sio.read_depth(tmp_path / path, max_pixels=600, **kwargs).shape == (20, 30)
    with pytest.raises(ValueError, match="limit 599"):
        sio.read_image(tmp_path / "small.png", max_pixels=599)


def test_names_label_paths_and_options_in_messages(tmp_path):
    np.save(tmp_path / "mm.npy", np.ones((2, 2), np.uint16))
    labels = {"scale": "--depth-scale", "max_pixels": "--max-pixels"}
    with pytest.raises(ValueError, match=r"^--depth-scale is required .* --depth '.*mm\.npy'"):
        sio.read_depth(tmp_path / "mm.npy", name="--depth", option_names=labels)
    with pytest.raises(ValueError, match=r"\(--max-pixels\)"):
        sio.read_depth(tmp_path / "mm.npy", scale=1, max_pixels=3, name="--depth", option_names=labels)
    with pytest.raises(FileNotFoundError, match=r"^--truth: no such file"):
        sio.read_depth(tmp_path / "nope.png", name="--truth")
    with pytest.raises(FileNotFoundError, match=r"^`path`: no such file"):
        sio.read_depth(tmp_path / "nope.png")
    with pytest.raises(ValueError, match=r"^--calib '.*c\.txt'.*required entry `cam0`"):
        (tmp_path / "c.txt").write_text("baseline=1\n")
        sio.read_calib(tmp_path / "c.txt", name="--calib")


# ------------------------------------------------------------------------------------
# command line
# ------------------------------------------------------------------------------------
@pytest.fixture
def scene(tmp_path):
    image, depth = make_scene()
    iio.imwrite(tmp_path / "rgb.png", image)
    sparse, _ = sd.sample_depth(depth, fraction=0.1, seed=1)
    return tmp_path, image, depth, sparse


def _bad(argv, capsys, *needles):
    rc = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2, err
    line = _one_line(err)
    for needle in needles:
        assert needle in line, line
    return line


def test_cli_integer_npy_needs_depth_scale(scene, capsys):
    folder, _, _, sparse = scene
    np.save(folder / "mm.npy", np.nan_to_num(np.rint(sparse * 1000)).astype(np.uint16))
    base = ["--image", folder / "rgb.png", "--depth", folder / "mm.npy", "--out", folder / "o.npy"]
    _bad(base + FAST, capsys, "--depth-scale is required", "--depth '")
    assert not (folder / "o.npy").exists()
    assert main([str(a) for a in base + ["--depth-scale", "mm"] + FAST]) == 0
    mm = sd.read_depth(folder / "mm.npy", scale=1000)
    expected = sd.complete_depth(sd.read_image(folder / "rgb.png"), mm, weights=sd.DEFAULT_SCHEDULE.replace(gamma=0.0),
                                 solver="direct").depth
    np.testing.assert_allclose(np.load(folder / "o.npy"), expected, atol=1e-12)


def test_cli_pfm_needs_calib_or_scale(scene, capsys):
    folder, _, _, sparse = scene
    sio.write_pfm(folder / "d.pfm", np.where(np.isnan(sparse), np.inf, sparse))
    base = ["--image", folder / "rgb.png", "--depth", folder / "d.pfm"]
    _bad(base + FAST, capsys, "--depth '", "--calib", "--depth-scale m")
    assert main([str(a) for a in base + ["--depth-scale", "m"] + FAST]) == 0


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
def test_cli_fifo_depth_exits_2_quickly(scene, capsys):
    folder = scene[0]
    os.mkfifo(folder / "fifo.png")
    argv = ["--image", str(folder / "rgb.png"), "--depth", str(folder / "fifo.png"), "--depth-scale", "mm", *FAST]
    try:
        outcome = _finishes(lambda: main(argv))
    finally:
        _unblock_fifo(folder / "fifo.png")
    assert outcome == ("ok", 2), outcome
    assert "--depth '" in _one_line(capsys.readouterr().err)


def test_cli_huge_png_header_exits_2(scene, capsys):
    folder, _, _, sparse = scene
    sd.write_depth(folder / "sparse.png", sparse, scale=1000)
    (folder / "huge.png").write_bytes(_png_header_only(100_000, 100_000))
    _bad(["--image", folder / "huge.png", "--depth", folder / "sparse.png", "--depth-scale", "mm", *FAST],
         capsys, "--image '", "declares 100000x100000", "--max-pixels")
    _bad(["--image", folder / "rgb.png", "--depth", folder / "sparse.png", "--depth-scale", "mm",
          "--max-pixels", "100", *FAST], capsys, "--image '", "limit 100 (--max-pixels)")


def test_cli_one_bit_png_mask(scene, capsys):
    folder, image, depth, _ = scene
    mask = np.random.default_rng(4).random(depth.shape) < 0.1
    Image.fromarray(mask).save(folder / "mask.png")
    sd.write_depth(folder / "dense.png", depth, scale=1000)
    rc = main([str(a) for a in ["--image", folder / "rgb.png", "--depth", folder / "dense.png", "--depth-scale",
                                "mm", "--mask", folder / "mask.png", "--out", folder / "o.npy", *FAST]])
    assert rc == 0, capsys.readouterr().err
    dense = sd.read_depth(folder / "dense.png", scale=1000)
    expected = sd.complete_depth(image, dense, mask, weights=sd.DEFAULT_SCHEDULE.replace(gamma=0.0), solver="direct").depth
    np.testing.assert_allclose(np.load(folder / "o.npy"), expected, atol=1e-12)


def test_cli_invalid_value_and_depth_range_remove_pixels(scene, capsys):
    folder, _, depth, sparse = scene
    stored = np.nan_to_num(np.rint(sparse * 1000)).astype(np.uint16)
    stored[0, :5] = 65535
    np.save(folder / "mm.npy", stored)
    rc = main([str(a) for a in ["--image", folder / "rgb.png", "--depth", folder / "mm.npy", "--depth-scale", "mm",
                                "--invalid-value", "65535", "--invalid-value", "2047", "--min-depth", "1.2",
                                "--max-depth", "1.9", "--json", folder / "r.json", *FAST]])
    assert rc == 0, capsys.readouterr().err
    metres = stored / 1000.0
    expected = (stored != 0) & (stored != 65535) & (metres >= 1.2) & (metres <= 1.9)
    assert json.loads((folder / "r.json").read_text())["observed"] == int(expected.sum())
    assert 0 < expected.sum() < (stored != 0).sum()
    capsys.readouterr()  # the successful run's warnings are not the next run's
    _bad(["--image", folder / "rgb.png", "--depth", folder / "mm.npy", "--depth-scale", "mm", "--min-depth", "3",
          "--max-depth", "2", *FAST], capsys, "--min-depth", "--max-depth")


def test_cli_errors_name_the_flag(scene, capsys):
    folder, _, _, sparse = scene
    sd.write_depth(folder / "sparse.png", sparse, scale=1000)
    base = ["--image", folder / "rgb.png", "--depth", folder / "sparse.png", "--depth-scale", "mm"]
    _bad(base + ["--truth", folder / "nope.png", *FAST], capsys, "--truth: no such file")
    (folder / "m.npy").write_bytes(b"junk")
    _bad(base + ["--mask", folder / "m.npy", *FAST], capsys, "--mask '")
    (folder / "c.txt").write_text("cam0=[1 0 0; 0 1 0; 0 0 1]\n")
    _bad(base + ["--calib", folder / "c.txt", *FAST], capsys, "--calib '", "baseline")
    (folder / "bad.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(30))
    _bad(["--image", folder / "bad.png", *base[2:], *FAST], capsys, "--image '")


def test_cli_nyu_raw_pgm(shared_data, tmp_path, capsys):
    folder = shared_data / "nyu_raw_open3d"
    base = ["--image", folder / "NYU_color.ppm", "--depth", folder / "NYU_depth.pgm"]
    _bad(base + ["--depth-scale", "mm", "--fill-holes"], capsys, "byte-swapped", "--byteorder little")
    rc = main([str(a) for a in base + ["--byteorder", "little", "--calib", "kinect-nyu", "--downsample", "4",
                                       "--fill-holes", "--json", tmp_path / "r.json", "-q"]])
    assert rc == 0, capsys.readouterr().err
    raw = sio.read_image(folder / "NYU_depth.pgm", byteorder="little")[::4, ::4]
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["observed"] == int((raw != 2047).sum()) < raw.size  # not "observed 100 %"
