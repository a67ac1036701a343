"""Float32 TIFF depth output: write_depth, read_depth, --out x.tif and the batch's --out-format tif."""

import csv
import os

import imageio.v3 as iio
import numpy as np
import pytest
import tifffile

import sparsedepth as sd
from conftest import make_scene
from sparsedepth.complete import main

FAST = ["--gamma", "0", "--solver", "direct"]


@pytest.mark.parametrize("name", ["d.tif", "d.TIFF"])
def test_tiff_round_trip_is_exact_in_float32(tmp_path, name):
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.1, 80.0, (17, 23))
    depth[3, 4] = np.nan
    depth[5, 6] = 0.0  # invalid: written as NaN
    depth[7, 8] = np.inf
    before = depth.copy()
    sd.write_depth(tmp_path / name, depth)
    np.testing.assert_array_equal(depth, before)  # input untouched
    with tifffile.TiffFile(tmp_path / name) as handle:
        assert len(handle.pages) == 1
    stored = tifffile.imread(tmp_path / name)
    assert stored.dtype == np.float32 and stored.shape == depth.shape
    expected = depth.astype(np.float32)
    expected[~np.isfinite(expected) | (expected == 0)] = np.nan
    np.testing.assert_array_equal(stored, expected)  # NaN where missing, every value the float32 of the input
    back = sd.read_depth(tmp_path / name)
    assert back.dtype == np.float64
    np.testing.assert_array_equal(back, expected.astype(np.float64))
    assert os.listdir(tmp_path) == [name]


def test_tiff_refuses_what_float32_cannot_hold(tmp_path):
    with pytest.raises(ValueError, match="float32 range"):
        sd.write_depth(tmp_path / "d.tif", np.array([[1.0, 1e39]]))
    with pytest.raises(ValueError, match="negative"):
        sd.write_depth(tmp_path / "d.tif", np.array([[1.0, -1.0]]))
    assert os.listdir(tmp_path) == []


def test_a_tiff_of_several_images_is_refused_and_its_previews_are_ignored(tmp_path, capsys):
    rng = np.random.default_rng(1)
    stack = rng.uniform(0.5, 9.0, (2, 12, 14)).astype(np.float32)
    tifffile.imwrite(tmp_path / "stack.tif", stack)  # two full pages: which one is the depth?
    with pytest.raises(ValueError, match="TIFF of 2 images"):
        sd.read_depth(tmp_path / "stack.tif")
    tifffile.imwrite(tmp_path / "frames.tif", rng.integers(0, 255, (3, 12, 14, 3), dtype=np.uint8))
    with pytest.raises(ValueError, match="TIFF of 3 images"):
        sd.read_image(tmp_path / "frames.tif")
    with tifffile.TiffWriter(tmp_path / "pyramid.tif") as writer:  # a full page and a reduced preview
        writer.write(stack[1])
        writer.write(stack[1][::2, ::2], subfiletype=1)
    np.testing.assert_array_equal(sd.read_depth(tmp_path / "pyramid.tif"), stack[1].astype(np.float64))
    image, _ = make_scene()
    iio.imwrite(tmp_path / "rgb.png", image)
    rc = main(["--image", str(tmp_path / "rgb.png"), "--depth", str(tmp_path / "stack.tif"),
               "--out", str(tmp_path / "out.npy"), *FAST])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "--depth" in err and "TIFF of 2 images" in err, err
    assert not (tmp_path / "out.npy").exists()


def test_cli_out_tif_is_the_completed_depth_in_float32(tmp_path, capsys):
    image, depth = make_scene((20, 30))
    iio.imwrite(tmp_path / "rgb.png", image)
    sparse, _ = sd.sample_depth(depth, fraction=0.2, seed=1)
    sd.write_depth(tmp_path / "sparse.png", sparse, scale=1000)
    base = ["-q", "--image", str(tmp_path / "rgb.png"), "--depth", str(tmp_path / "sparse.png"), "--depth-scale",
            "mm", *FAST]
    assert main([*base, "--out", str(tmp_path / "d.tif")]) == 0
    assert main([*base, "--out", str(tmp_path / "d.npy")]) == 0
    stored = tifffile.imread(tmp_path / "d.tif")
    assert stored.dtype == np.float32
    np.testing.assert_array_equal(stored, np.load(tmp_path / "d.npy").astype(np.float32))


def test_batch_out_format_tif(tmp_path, capsys):
    frames = tmp_path / "frames"
    frames.mkdir()
    for key in ("0001", "0002"):
        image, depth = make_scene((16, 24), seed=int(key))
        iio.imwrite(frames / f"rgb_{key}.png", image)
        sd.write_depth(frames / f"depth_{key}.png", depth, scale=1000)
    outputs = {}
    for fmt in ("tif", "npy"):
        (tmp_path / fmt).mkdir()
        assert main(["-q", "--batch", str(frames), "--depth-scale", "mm", "--keep-fraction", "0.2", "--csv",
                     str(tmp_path / f"{fmt}.csv"), "--workers", "1", "--outdir", str(tmp_path / fmt),
                     "--out-format", fmt, *FAST]) == 0
        with open(tmp_path / f"{fmt}.csv", newline="") as fh:
            assert [row["status"] for row in csv.DictReader(fh)] == ["ok", "ok"]
        outputs[fmt] = sorted(os.listdir(tmp_path / fmt))
    assert outputs["tif"] == ["0001.tif", "0002.tif"]
    for key in ("0001", "0002"):
        stored = tifffile.imread(tmp_path / "tif" / f"{key}.tif")
        assert stored.dtype == np.float32
        np.testing.assert_array_equal(stored, np.load(tmp_path / "npy" / f"{key}.npy").astype(np.float32))
