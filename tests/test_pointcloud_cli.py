"""The --ply, --intrinsics and --camera options of the command line.

Every written point is checked against the pinhole formula evaluated pixel by
pixel from the depth written with --out, every PLY file with a small parser.
"""

import os

import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd
from conftest import make_scene
from sparsedepth.cli.camera import CAMERA_PRESETS
from sparsedepth.cli.parser import DEMO_DOWNSAMPLE
from sparsedepth.complete import main
from test_pointcloud import HEADER_RGB, parse_ply, pinhole

FAST = ["--gamma", "0", "--solver", "direct"]


def _written_cloud_matches(ply, depth, intrinsics, image):
    """The PLY (read twice, independently) holds the pinhole points and colours of every finite depth pixel."""
    lines, count, xyz, rgb = parse_ply(ply)
    expected_header = list(HEADER_RGB)
    expected_header[3] = f"element vertex {count}"
    assert lines == expected_header
    assert count == int(np.isfinite(depth).sum()) > 0
    points, colors = pinhole(depth, intrinsics, image)
    np.testing.assert_allclose(xyz, points, rtol=2e-6, atol=1e-6)
    np.testing.assert_array_equal(rgb, colors)
    back, back_colors = sd.read_ply(ply)
    np.testing.assert_array_equal(back, xyz)
    np.testing.assert_array_equal(back_colors, rgb)


def test_demo_ply_is_the_completed_depth_through_the_demo_camera(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    # the grid-multigrid solver: the direct solve of the demo frame's 25-point system takes seconds
    assert main(["-q", "--ply", str(out / "c.ply"), "--out", str(out / "d.npy"), "--outdir", str(tmp_path / "o"),
                 "--gamma", "0", "--solver", "amg"]) == 0
    frame = sd.load_motorcycle()
    n = DEMO_DOWNSAMPLE
    intrinsics = [v / n for v in frame.intrinsics]
    depth = np.load(out / "d.npy")
    _written_cloud_matches(out / "c.ply", depth, intrinsics, frame.image[::n, ::n])
    assert (tmp_path / "o" / "points.ply").read_bytes() == (out / "c.ply").read_bytes()
    assert f"wrote {out / 'c.ply'}" in capsys.readouterr().out


@pytest.fixture
def scene_files(tmp_path):
    image, depth = make_scene((30, 44))
    iio.imwrite(tmp_path / "rgb.png", image)
    iio.imwrite(tmp_path / "grey.png", image[:, :, 1])
    sparse, _ = sd.sample_depth(depth, fraction=0.2, seed=1)
    sd.write_depth(tmp_path / "sparse.png", sparse, scale=1000)
    return tmp_path, image


def test_ply_with_intrinsics_and_downsample(scene_files):
    folder, image = scene_files
    intrinsics = (300.0, 310.0, 21.3, 14.6)
    assert main(["-q", "--image", str(folder / "rgb.png"), "--depth", str(folder / "sparse.png"), "--depth-scale",
                 "mm", "--intrinsics", ",".join(map(str, intrinsics)), "--downsample", "2", "--out",
                 str(folder / "d.npy"), "--ply", str(folder / "c.ply"), *FAST]) == 0
    depth = np.load(folder / "d.npy")
    assert depth.shape == (15, 22)
    _written_cloud_matches(folder / "c.ply", depth, [v / 2 for v in intrinsics], image[::2, ::2])
    # the same points through the full-resolution camera at pixel (2 v, 2 u)
    fx, fy, cx, cy = intrinsics
    xyz = parse_ply(folder / "c.ply")[2]
    v, u = np.nonzero(np.isfinite(depth))
    np.testing.assert_allclose(xyz[:, 0], (2 * u - cx) * depth[v, u] / fx, rtol=2e-6, atol=1e-6)
    np.testing.assert_allclose(xyz[:, 1], (2 * v - cy) * depth[v, u] / fy, rtol=2e-6, atol=1e-6)


def test_grey_image_gives_grey_colours_and_outdir_writes_points(scene_files):
    folder, image = scene_files
    (folder / "o").mkdir()
    assert main(["-q", "--image", str(folder / "grey.png"), "--depth", str(folder / "sparse.png"), "--depth-scale",
                 "mm", "--intrinsics", "100,100,20,15", "--outdir", str(folder / "o"), *FAST]) == 0
    depth = np.load(folder / "o" / "depth.npy")
    _written_cloud_matches(folder / "o" / "points.ply", depth, (100, 100, 20, 15), image[:, :, 1])
    rgb = parse_ply(folder / "o" / "points.ply")[3]
    assert np.all(rgb[:, 0] == rgb[:, 1]) and np.all(rgb[:, 1] == rgb[:, 2])


def test_outdir_without_intrinsics_writes_no_points(scene_files):
    folder, _ = scene_files
    (folder / "o").mkdir()
    assert main(["-q", "--image", str(folder / "rgb.png"), "--depth", str(folder / "sparse.png"), "--depth-scale",
                 "mm", "--outdir", str(folder / "o"), *FAST]) == 0
    assert "points.ply" not in os.listdir(folder / "o") and "depth.npy" in os.listdir(folder / "o")


def test_ply_intrinsics_from_calib_txt(tmp_path):
    image, depth = make_scene((24, 32))
    f, baseline, doffs = 400.0, 100.0, 2.0
    disparity = f * baseline / 1000.0 / depth - doffs
    disparity[np.random.default_rng(0).random(depth.shape) > 0.2] = np.nan
    np.save(tmp_path / "disp.npy", disparity)
    iio.imwrite(tmp_path / "rgb.png", image)
    (tmp_path / "calib.txt").write_text(f"cam0=[{f} 0 15.5; 0 {f} 11.25; 0 0 1]\ndoffs={doffs}\n"
                                        f"baseline={baseline}\nwidth=32\nheight=24\n")
    assert main(["-q", "--image", str(tmp_path / "rgb.png"), "--depth", str(tmp_path / "disp.npy"), "--calib",
                 str(tmp_path / "calib.txt"), "--out", str(tmp_path / "d.npy"), "--ply", str(tmp_path / "c.ply"),
                 *FAST]) == 0
    _written_cloud_matches(tmp_path / "c.ply", np.load(tmp_path / "d.npy"), (f, f, 15.5, 11.25), image)


def test_camera_preset_of_the_right_size(tmp_path):
    image, depth = make_scene((480, 640))
    iio.imwrite(tmp_path / "rgb.png", image)
    sparse, _ = sd.sample_depth(depth, fraction=0.05, seed=1)
    sd.write_depth(tmp_path / "sparse.png", sparse, scale=1000)
    assert main(["-q", "--image", str(tmp_path / "rgb.png"), "--depth", str(tmp_path / "sparse.png"),
                 "--depth-scale", "mm", "--camera", "nyu", "--downsample", "4", "--out", str(tmp_path / "d.npy"),
                 "--ply", str(tmp_path / "c.ply"), *FAST]) == 0
    assert CAMERA_PRESETS["nyu"].intrinsics == sd.datasets.frame.NYU_RGB_INTRINSICS
    _written_cloud_matches(tmp_path / "c.ply", np.load(tmp_path / "d.npy"),
                           [v / 4 for v in sd.datasets.frame.NYU_RGB_INTRINSICS], image[::4, ::4])


def test_kitti_preset_is_the_calibration_of_the_shared_frames(shared_data):
    frame = sd.load_shared_frame("kitti/0000000005", root=shared_data)
    preset = CAMERA_PRESETS["kitti"]
    assert preset.intrinsics == frame.intrinsics
    assert (preset.height, preset.width) == frame.shape


def _run_bad(argv, capsys, folder, expect):
    before = sorted(p.name for p in folder.rglob("*"))
    rc = main([str(a) for a in argv])
    captured = capsys.readouterr()
    assert rc == 2
    assert captured.err.endswith("\n") and captured.err.count("\n") == 1, captured.err
    for text in expect:
        assert text in captured.err, captured.err
    assert sorted(p.name for p in folder.rglob("*")) == before  # nothing written
    assert "wrote" not in captured.out


def test_ply_without_intrinsics_is_refused_before_any_work(scene_files, capsys, monkeypatch):
    folder, _ = scene_files
    monkeypatch.setattr("sparsedepth.cli.single.read_image", lambda *a, **k: pytest.fail("read before the check"))
    _run_bad(["--image", folder / "rgb.png", "--depth", folder / "sparse.png", "--depth-scale", "mm", "--out",
              folder / "d.npy", "--ply", folder / "c.ply"], capsys, folder,
             ["--ply", "--intrinsics", "--camera", "--calib"])
    _run_bad(["--image", folder / "rgb.png", "--depth", folder / "sparse.png", "--depth-scale", "mm", "--calib",
              "kinect-nyu", "--ply", folder / "c.ply"], capsys, folder, ["--ply needs the camera intrinsics"])


@pytest.mark.parametrize("value", ["1,2,3", "a,b,c,d", "0,1,2,3", "1,-1,2,3", "1,1,nan,3", "1,1,2,3,4"])
def test_bad_intrinsics_option(scene_files, capsys, value):
    folder, _ = scene_files
    _run_bad(["--image", folder / "rgb.png", "--depth", folder / "sparse.png", "--depth-scale", "mm",
              f"--intrinsics={value}", "--ply", folder / "c.ply"], capsys, folder, ["--intrinsics", value])


def test_camera_preset_of_another_size_is_refused(scene_files, capsys):
    folder, _ = scene_files
    _run_bad(["--image", folder / "rgb.png", "--depth", folder / "sparse.png", "--depth-scale", "mm",
              "--camera", "kitti", "--out", folder / "d.npy", "--ply", folder / "c.ply", *FAST], capsys, folder,
             ["--camera kitti", "1242x375", "44x30", "--intrinsics"])


@pytest.mark.parametrize("extra, expect", [
    (["--ply", "c.xyz", "--intrinsics", "1,1,0,0"], "--ply"),
    (["--ply", "c.ply", "--intrinsics", "1,1,0,0", "--calib", "calib.txt"], "drop --intrinsics"),
    (["--ply", "c.ply", "--intrinsics", "1,1,0,0", "--camera", "nyu"], "not allowed with argument"),
])
def test_camera_option_combinations(scene_files, capsys, extra, expect):
    folder, _ = scene_files
    (folder / "calib.txt").write_text("cam0=[1 0 0; 0 1 0; 0 0 1]\nbaseline=1\n")
    extra = [str(folder / e) if e.startswith(("c.", "calib")) else e for e in extra]
    _run_bad(["--image", folder / "rgb.png", "--depth", folder / "sparse.png", "--depth-scale", "mm", *extra],
             capsys, folder, [expect])


def test_demo_and_batch_refuse_camera_options(tmp_path, capsys):
    _run_bad(["--intrinsics", "1,1,0,0"], capsys, tmp_path, ["--intrinsics", "demo"])
    _run_bad(["--camera", "nyu", "--ply", tmp_path / "c.ply"], capsys, tmp_path, ["--camera", "demo"])
    _run_bad(["--batch", tmp_path, "--csv", tmp_path / "m.csv", "--keep-fraction", "0.1", "--ply",
              tmp_path / "c.ply"], capsys, tmp_path, ["--ply", "--batch"])


def test_ply_is_one_of_the_outputs_written_all_or_nothing(scene_files, capsys):
    folder, _ = scene_files
    (folder / "c.ply").mkdir()  # the PLY target is a folder: refused before any work, --out not written
    _run_bad(["--image", folder / "rgb.png", "--depth", folder / "sparse.png", "--depth-scale", "mm",
              "--intrinsics", "1,1,0,0", "--out", folder / "d.npy", "--ply", folder / "c.ply"], capsys, folder,
             ["--ply", "directory"])
    (folder / "o").mkdir()
    _run_bad(["--image", folder / "rgb.png", "--depth", folder / "sparse.png", "--depth-scale", "mm",
              "--intrinsics", "1,1,0,0", "--outdir", folder / "o", "--ply", folder / "o" / "points.ply"], capsys,
             folder, ["same file", "--ply"])


def test_help_lists_the_camera_options(capsys):
    assert main(["--help-all"]) == 0
    out = capsys.readouterr().out
    for option in ("--ply", "--intrinsics", "--camera", "points.ply"):
        assert option in out
    for preset in CAMERA_PRESETS:
        assert preset in out


def test_json_report_records_the_intrinsics_of_the_cloud(scene_files):
    folder, _ = scene_files
    assert main(["-q", "--image", str(folder / "rgb.png"), "--depth", str(folder / "sparse.png"), "--depth-scale",
                 "mm", "--intrinsics", "40,41.5,21,14.5", "--downsample", "2", "--ply", str(folder / "c.ply"),
                 "--json", str(folder / "r.json"), *FAST]) == 0
    import json
    report = json.loads((folder / "r.json").read_text())
    assert report["intrinsics"] == {"fx": 20.0, "fy": 20.75, "cx": 10.5, "cy": 7.25}


def test_a_camera_preset_says_which_calibration_it_assumed(tmp_path, capsys, monkeypatch):
    import imageio.v3 as iio

    from sparsedepth.complete import main

    monkeypatch.chdir(tmp_path)
    rng = np.random.default_rng(0)
    iio.imwrite(tmp_path / "rgb.png", rng.integers(0, 255, (375, 1242, 3), dtype=np.uint8))
    depth = np.where(rng.random((375, 1242)) < 0.05, rng.uniform(5, 50, (375, 1242)), 0.0)
    iio.imwrite(tmp_path / "depth.png", np.round(depth * 256).astype(np.uint16))
    assert main(["--image", "rgb.png", "--depth", "depth.png", "--depth-scale", "kitti", "--camera", "kitti",
                 "--fast", "--ply", "c.ply"]) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if line.startswith("note: --camera kitti")]
    assert len(notes) == 1 and "707.049" in notes[0] and "--intrinsics calib_cam_to_cam.txt" in notes[0]
    assert main(["--image", "rgb.png", "--depth", "depth.png", "--depth-scale", "kitti", "--camera", "kitti",
                 "--fast", "--ply", "d.ply", "-q"]) == 0
    assert "note: --camera" not in capsys.readouterr().err  # -q: no note
