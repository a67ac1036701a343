"""--sensor: a sensor's depth files read as the explicit flags it stands for would read them."""

import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.complete import main
from sparsedepth.io.depth import DEPTH_SCALES, SENSOR_PRESETS

from conftest import make_scene


def _files(tmp_path):
    image, depth = make_scene(shape=(30, 40))
    stored = np.round(depth * 1000).astype(np.uint16)  # millimetres, as RealSense / Azure Kinect / NYU store them
    rng = np.random.default_rng(0)
    hidden = rng.random(stored.shape) > 0.2
    stored[hidden] = 0
    stored[0, :5] = 65535  # a recorder's "no depth" code
    stored[1, :3] = 50  # 5 cm: nearer than any of these sensors measures
    iio.imwrite(tmp_path / "rgb.png", image)
    iio.imwrite(tmp_path / "depth.png", stored)
    return stored


def test_a_preset_reads_like_its_explicit_flags(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _files(tmp_path)
    preset = SENSOR_PRESETS["realsense-d4xx"]
    common = ["--image", "rgb.png", "--depth", "depth.png", "-q"]
    assert main([*common, "--sensor", "realsense-d4xx", "--out", "preset.npy"]) == 0
    explicit = ["--depth-scale", f"{preset.scale:g}", "--min-depth", f"{preset.min_depth:g}", "--max-depth",
                f"{preset.max_depth:g}", *[a for v in preset.invalid_values for a in ("--invalid-value", f"{v:g}")]]
    assert main([*common, *explicit, "--out", "explicit.npy"]) == 0
    np.testing.assert_array_equal(np.load("preset.npy"), np.load("explicit.npy"))
    read = sd.read_depth(tmp_path / "depth.png", scale=preset.scale, invalid_values=preset.invalid_values,
                         min_depth=preset.min_depth, max_depth=preset.max_depth)
    assert np.isnan(read[0, :5]).all() and np.isnan(read[1, :3]).all()  # the code and the too-near readings


def test_an_explicit_flag_wins_over_the_preset(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _files(tmp_path)
    common = ["--image", "rgb.png", "--depth", "depth.png", "-q", "--sensor", "azure-kinect"]
    assert main([*common, "--max-depth", "1.5", "--out", "near.npy"]) == 0
    assert main([*common, "--out", "all.npy"]) == 0
    assert np.nanmax(np.load("near.npy")) <= 1.5 + 1e-9 < np.nanmax(np.load("all.npy"))


@pytest.mark.parametrize("extra, match", [([], "the demo has its own"),
                                          (["--colmap", "sparse", "--images", "img", "--outdir", "."], "--colmap")])
def test_refused_where_there_are_no_depth_files(extra, match, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["--sensor", "tum", *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--sensor tum" in err[0] and match in err[0]


def test_every_preset_is_consistent_and_sourced():
    for name, preset in SENSOR_PRESETS.items():
        assert preset.scale in DEPTH_SCALES.values() and 0 <= preset.min_depth < preset.max_depth
        assert len(preset.source) > 40, name
    assert SENSOR_PRESETS["tum"].scale == DEPTH_SCALES["tum"] and SENSOR_PRESETS["kitti-lidar"].scale == 256
