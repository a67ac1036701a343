"""read_intrinsics and --intrinsics FILE: the calibration files cameras come with, against hand-written numbers."""

import json

import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.complete import main
from sparsedepth.io.calibration import read_intrinsics

FX, FY, CX, CY = 721.5377, 721.5377, 609.5593, 172.854


@pytest.mark.parametrize("name, content", [
    ("cam.txt", f"{FX} 0 {CX}\n0 {FY} {CY}\n0 0 1\n"),  # KITTI's cam.txt: a 3x3 K
    ("k.txt", f"{FX} {FY} {CX} {CY}\n"),
    ("intrinsics.yaml", f"# camera\ncamera_name: 'D435'\nfx: {FX}  # px\nfy: {FY}\ncx: {CX}\ncy: {CY}\n"),
    ("calib_cam_to_cam.txt", "calib_time: 09-Jan-2012 13:57:47\n"
                             "P_rect_00: 7.215377e+02 0 6.095593e+02 0 0 7.215377e+02 1.728540e+02 0 0 0 1 0\n"
                             f"P_rect_02: {FX} 0 {CX} 44.85728 0 {FY} {CY} 0.2163791 0 0 1 0.002745884\n"),
    ("cameras.txt", f"# Camera list\n1 PINHOLE 1242 375 {FX} {FY} {CX + 0.5} {CY + 0.5}\n"),
    ("k.json", json.dumps({"fx": FX, "fy": FY, "cx": CX, "cy": CY})),
    ("k_matrix.json", json.dumps({"K": [[FX, 0, CX], [0, FY, CY], [0, 0, 1]]})),
    ("open3d.json", json.dumps({"width": 1242, "height": 375,
                                "intrinsic_matrix": [FX, 0, 0, 0, FY, 0, CX, CY, 1]})),  # column-major
])
def test_each_format_gives_the_same_intrinsics(tmp_path, name, content):
    path = tmp_path / name
    path.write_text(content)
    assert read_intrinsics(path) == pytest.approx((FX, FY, CX, CY), rel=1e-12)


def test_npy_and_colmap_simple_pinhole(tmp_path):
    np.save(tmp_path / "k.npy", np.array([[FX, 0, CX], [0, FX, CY], [0, 0, 1]]))
    assert read_intrinsics(tmp_path / "k.npy") == pytest.approx((FX, FX, CX, CY))
    (tmp_path / "cameras.txt").write_text("1 SIMPLE_PINHOLE 1919 1079 1847.53 959.5 539.5\n")
    assert read_intrinsics(tmp_path / "cameras.txt") == pytest.approx((1847.53, 1847.53, 959.0, 539.0))


@pytest.mark.parametrize("name, content, match", [
    ("cameras.txt", "1 OPENCV 640 480 500 500 320 240 0.1 0.01 0 0\n", "image_undistorter"),
    ("cameras.txt", "1 PINHOLE 640 480 500 500 320 240\n2 PINHOLE 640 480 500 500 320 240\n", "2 cameras"),
    ("k.txt", "1 2 3\n", "no camera intrinsics"),
    ("k.txt", "500 0.3 320\n0 500 240\n0 0 1\n", "skew"),
    ("k.json", "[1, 2]", "JSON object"),
    ("k.json", "{\"f\": 3}", "none of"),
    ("k.yaml", "fx: 500\nfy: 500\ncx: 320\n", "fx, fy, cx, cy"),
])
def test_what_is_not_intrinsics_is_one_error_naming_the_file(tmp_path, name, content, match):
    path = tmp_path / name
    path.write_text(content)
    with pytest.raises(ValueError, match=match) as info:
        read_intrinsics(path, name="--intrinsics")
    assert str(path) in str(info.value)
    with pytest.raises(FileNotFoundError):
        read_intrinsics(tmp_path / "missing.txt")


def test_command_line_takes_a_file_and_names_the_flag_when_it_is_wrong(tmp_path, capsys, monkeypatch):
    import imageio.v3 as iio

    monkeypatch.chdir(tmp_path)
    frame = sd.load_motorcycle()
    iio.imwrite(tmp_path / "rgb.png", np.ascontiguousarray(frame.image[::8, ::8]))
    sparse, _ = sd.sample_depth(np.asarray(frame.depth, dtype=float)[::8, ::8], fraction=0.2, seed=0)
    np.save(tmp_path / "sparse.npy", np.nan_to_num(sparse))
    fx, fy, cx, cy = (v / 8 for v in frame.intrinsics)
    (tmp_path / "cam.txt").write_text(f"{fx!r} 0 {cx!r}\n0 {fy!r} {cy!r}\n0 0 1\n")
    common = ["--image", "rgb.png", "--depth", "sparse.npy", "-q"]
    assert main([*common, "--intrinsics", f"{fx!r},{fy!r},{cx!r},{cy!r}", "--ply", "numbers.ply"]) == 0
    assert main([*common, "--intrinsics", "cam.txt", "--ply", "file.ply"]) == 0
    assert (tmp_path / "numbers.ply").read_bytes() == (tmp_path / "file.ply").read_bytes()
    (tmp_path / "bad.txt").write_text("not a camera\n")
    capsys.readouterr()
    for value in ("bad.txt", "nothing-here.txt"):
        assert main([*common, "--intrinsics", value, "--ply", "x.ply"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--intrinsics" in err[0]
