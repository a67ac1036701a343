"""Dense depth for every view of a COLMAP model from the command line (--colmap, --images, --outdir): one map per
view at the model's points' depths, scene.json, resume, failed views, flag errors, workers, Dask, the shared scene."""

import csv
import json
import os
import warnings
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.batch import (
    BatchOptions,
    ColmapFrame,
    colmap_depth_range,
    colmap_frames,
    png_depth_scale,
    run_batch,
    unregistered_images,
    write_colmap_scene,
)
from sparsedepth.complete import main
from sparsedepth.io import read_colmap_model, view_depth, write_colmap_model
from sparsedepth.io.colmap import Camera, ColmapModel, Image, Points3D

WIDTH, HEIGHT, FOCAL = 64, 48, 50.0
#: x translation (world-to-camera) and image name of each view; one image in a sub-folder
VIEWS = ((-0.4, "v1.png"), (0.0, "v2.png"), (0.4, "cam/v3.png"))
NEAR, FAR = 4.0, 6.0  # the two walls: x < 0 at depth NEAR, x > 0 at depth FAR (identity rotations)
FAST_SOLVE = ["--gamma", "0", "--solver", "direct"]  # a quadratic objective, solved exactly and quickly


def _render(tx):
    """(image, depth) seen by the camera with translation (tx, 0, 0): the ray of each pixel centre hits a wall."""
    u, v = np.meshgrid(np.arange(WIDTH) + 0.5, np.arange(HEIGHT) + 0.5)  # COLMAP's pixel centres
    ray_x = (u - WIDTH / 2) / FOCAL
    near_x = -tx + NEAR * ray_x  # world x where the ray meets the near wall's plane
    left = near_x < 0
    depth = np.where(left, NEAR, FAR)
    rng = np.random.default_rng(int(10 * tx) + 5)
    colour = np.where(left[..., None], np.array([200, 60, 40]), np.array([40, 90, 200]))
    image = np.clip(colour + rng.integers(-8, 9, (HEIGHT, WIDTH, 3)), 0, 255).astype(np.uint8)
    return image, depth


def _model(count=300, seed=0):
    """Points on the two walls, each observed by the views that see it (its pixel's ray meets its wall)."""
    rng = np.random.default_rng(seed)
    near = rng.random(count) < 0.5
    z = np.where(near, NEAR, FAR)
    x = np.where(near, rng.uniform(-1.6, -0.05, count), rng.uniform(0.05, 2.4, count))
    y = rng.uniform(-0.45, 0.45, count) * z * HEIGHT / FOCAL
    xyz = np.column_stack([x, y, z])
    images, tracks = {}, [[] for _ in range(count)]
    for image_id, (tx, name) in enumerate(VIEWS, start=1):
        _, depth = _render(tx)
        px = FOCAL * (xyz[:, 0] + tx) / z + WIDTH / 2
        py = FOCAL * xyz[:, 1] / z + HEIGHT / 2
        inside = (px >= 0) & (px < WIDTH) & (py >= 0) & (py < HEIGHT)
        seen = np.flatnonzero(inside)
        seen = seen[depth[py[seen].astype(int), px[seen].astype(int)] == z[seen]]  # not hidden by the other wall
        for k, point in enumerate(seen):
            tracks[point].append((image_id, k))
        images[image_id] = Image(image_id, np.array([1.0, 0.0, 0.0, 0.0]), np.array([tx, 0.0, 0.0]), 1, name,
                                 np.column_stack([px[seen], py[seen]]), seen.astype(np.int64))
    kept = np.array([bool(t) for t in tracks])
    assert kept.all()
    flat = [element for track in tracks for element in track]
    points = Points3D(ids=np.arange(count, dtype=np.int64), xyz=xyz, rgb=np.zeros((count, 3), np.uint8),
                      error=np.full(count, 0.5), track_lengths=np.array([len(t) for t in tracks]),
                      track_image_ids=np.array([e[0] for e in flat]),
                      track_point2d_idxs=np.array([e[1] for e in flat]))
    camera = Camera(1, "PINHOLE", WIDTH, HEIGHT, np.array([FOCAL, FOCAL, WIDTH / 2, HEIGHT / 2]))
    return ColmapModel({1: camera}, images, points)


def _expected_points(model, name):
    """{(row, column): depth} of one view computed directly: identity rotation, so depth = z + tz; nearest per pixel."""
    view = next(image for image in model.images.values() if image.name == name)
    found = {}
    for (x, y), point in zip(view.xys, view.point3d_ids):
        depth = model.points3d.xyz[point, 2] + view.tvec[2]
        key = (int(np.floor(y)), int(np.floor(x)))
        found[key] = min(depth, found.get(key, np.inf))
    return found


@pytest.fixture
def scene(tmp_path, monkeypatch):
    """A model of 3 views written by write_colmap_model (binary), their images, an empty output folder."""
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS", raising=False)
    model = _model()
    (tmp_path / "sparse").mkdir()
    write_colmap_model(model, tmp_path / "sparse")
    for tx, name in VIEWS:
        path = tmp_path / "images" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        iio.imwrite(path, _render(tx)[0])
    (tmp_path / "out").mkdir()
    return tmp_path, model


def _args(root, *extra):
    return ["--colmap", str(root / "sparse"), "--images", str(root / "images"), "--outdir", str(root / "out"),
            "-q", *extra]


def _rows(path):
    with open(path, newline="") as handle:
        return {row["name"]: row for row in csv.DictReader(handle)}


def _scene_json(root):
    return json.loads((root / "out" / "scene.json").read_text())


# ----------------------------------------------------------------------------- one map per view
@pytest.mark.parametrize("file_format", ["binary", "text"])
def test_each_view_gets_a_dense_map_equal_to_its_points_depths(scene, file_format, capsys):
    root, model = scene
    if file_format == "text":
        for path in (root / "sparse").iterdir():
            path.unlink()
        write_colmap_model(model, root / "sparse", file_format="text")
    assert main(_args(root, "--fast")) == 0
    assert "3 of 3 views done, 0 failed" in capsys.readouterr().out
    scale = 10000.0  # the largest of 1, 2, 5 x 10^k at most 65535 / (1.05 * 6) = 10402
    meta = _scene_json(root)
    assert meta["png_scale"] == scale and meta["depth_format"] == ".png"
    assert meta["units"] == "model units (arbitrary SfM scale)"
    assert meta["model"] == str((root / "sparse").resolve()) and meta["sparsedepth_version"] == sd.__version__
    assert meta["command"].startswith("python -m sparsedepth.complete --colmap ") and "--fast" in meta["command"]
    assert meta["observed_depth_range"] == [NEAR, FAR] and meta["failed"] == [] and meta["pending"] == []
    by_image = {view["image"]: view for view in meta["views"]}
    assert sorted(by_image) == sorted(name for _, name in VIEWS)
    for _, name in VIEWS:
        expected = _expected_points(model, name)
        output = root / "out" / Path(name).with_suffix(".png")  # 00.png for 00.jpg, sub-folders kept
        assert by_image[name]["depth"] == Path(name).with_suffix(".png").as_posix()
        assert by_image[name]["points"] == len(expected) > 50
        stored = iio.imread(output)
        assert stored.dtype == np.uint16 and stored.shape == (HEIGHT, WIDTH) and np.all(stored > 0)
        depth = stored / scale
        rows, columns = np.array(list(expected)).T
        np.testing.assert_allclose(depth[rows, columns], list(expected.values()), rtol=0, atol=0.5 / scale + 1e-12)
        assert depth.min() >= NEAR - 0.5 / scale and depth.max() <= FAR + 0.5 / scale


def test_the_default_solve_and_the_uncertainty_are_the_librarys(scene):
    root, model = scene
    (root / "sigma").mkdir()
    assert main(_args(root, *FAST_SOLVE, "--out-format", "npy", "--uncertainty", str(root / "sigma"))) == 0
    meta = _scene_json(root)
    assert meta["png_scale"] is None and meta["uncertainty"] == "../sigma"
    weights = sd.DEFAULT_SCHEDULE.replace(gamma=0.0)
    for _, name in VIEWS:
        image = sd.read_image(root / "images" / name)
        sparse, mask, _ = view_depth(model, name)
        with warnings.catch_warnings():  # the walls' step overshoots and is clamped, as in the batch's rows
            warnings.simplefilter("ignore", sd.ClampWarning)
            expected = sd.complete_depth(image, sparse, mask, weights=weights, solver="direct", uncertainty=True)
        stem = Path(name).with_suffix(".npy")
        np.testing.assert_allclose(np.load(root / "out" / stem), expected.depth, rtol=1e-9, atol=0)
        np.testing.assert_allclose(np.load(root / "sigma" / stem), expected.uncertainty, rtol=1e-6, atol=1e-12)
        view = next(v for v in meta["views"] if v["image"] == name)
        assert view["uncertainty"] == "../sigma/" + stem.as_posix()


# ----------------------------------------------------------------------------- resume, failures
def test_a_rerun_redoes_only_the_view_whose_output_and_row_were_deleted(scene, capsys):
    root, _ = scene
    assert main(_args(root, "--fast")) == 0
    capsys.readouterr()
    outputs = {name: root / "out" / Path(name).with_suffix(".png") for _, name in VIEWS}
    for path in outputs.values():
        os.utime(path, ns=(10**18, 10**18))  # a time no write of this run can give
    outputs["v2.png"].unlink()
    csv_path = root / "out" / "views.csv"
    lines = csv_path.read_bytes().split(b"\r\n")
    csv_path.write_bytes(b"\r\n".join(line for line in lines if b",v2,ok," not in line))
    assert len(_rows(csv_path)) == 2 and len(_scene_json(root)["views"]) == 3
    assert main(_args(root, "--fast")) == 0
    assert "3 of 3 views done, 0 failed, 2 skipped (done before)" in capsys.readouterr().out
    assert os.stat(outputs["v1.png"]).st_mtime_ns == os.stat(outputs["cam/v3.png"]).st_mtime_ns == 10**18
    assert outputs["v2.png"].is_file() and os.stat(outputs["v2.png"]).st_mtime_ns != 10**18
    assert sorted(_rows(csv_path)) == ["cam/v3", "v1", "v2"]
    assert len(_scene_json(root)["views"]) == 3  # rewritten: consistent with the files again


def test_scene_json_lists_only_the_views_whose_files_are_there(scene):
    root, _ = scene
    assert main(_args(root, "--fast")) == 0
    (root / "out" / "v1.png").unlink()
    frames = colmap_frames(root / "sparse", root / "images")
    options = BatchOptions(quality="fast", out_dir=str(root / "out"), out_format=".png", out_scale=10000.0)
    meta = write_colmap_scene(root / "out" / "scene.json", frames, root / "out" / "views.csv", options,
                              images_dir=root / "images")
    assert [view["image"] for view in meta["views"]] == ["cam/v3.png", "v2.png"] and meta["pending"] == ["v1.png"]
    assert _scene_json(root) == meta


def test_a_registered_image_without_its_file_is_a_failed_row(scene, capsys):
    root, _ = scene
    (root / "images" / "v2.png").unlink()
    iio.imwrite(root / "images" / "extra.png", _render(0.0)[0])  # not registered: skipped and counted
    assert main([item for item in _args(root, "--fast") if item != "-q"]) == 1  # the skipped files are reported
    captured = capsys.readouterr()
    assert "1 image file under --images is not registered in the model and skipped (extra.png)" in captured.err
    assert "2 of 3 views done, 1 failed" in captured.out
    rows = _rows(root / "out" / "views.csv")
    assert rows["v2"]["status"] == "error" and "'v2.png'" in rows["v2"]["error"]
    assert "does not exist" in rows["v2"]["error"] and rows["v1"]["status"] == rows["cam/v3"]["status"] == "ok"
    meta = _scene_json(root)
    assert [f["image"] for f in meta["failed"]] == ["v2.png"] and len(meta["views"]) == 2
    assert not (root / "out" / "v2.png").exists() and not (root / "out" / "extra.png").exists()


_BAD_FLAGS = {  # argv after the defaults are changed ({flag: None} drops it), and the flags the error must name
    "--images missing": ({"--images": None}, [], ["--images"]),
    "not a model": ({"--colmap": "images"}, [], ["--colmap"]),
    "with --batch": ({}, ["--batch", "images"], ["--colmap", "--batch"]),
    "sampling": ({}, ["--keep-fraction", "0.1"], ["--keep-fraction"]),
    "hole filling": ({}, ["--fill-holes"], ["--fill-holes"]),
    "--outdir missing": ({"--outdir": None}, [], ["--outdir"]),
    "uncertainty in outdir": ({}, ["--uncertainty", "out"], ["--uncertainty"]),
    "uncertainty with fast": ({}, ["--uncertainty", "sigma", "--fast"], ["--fast", "--uncertainty"]),
    "min track": ({}, ["--colmap-min-track", "0"], ["--colmap-min-track"]),
    "max error": ({}, ["--colmap-max-error", "-1"], ["--colmap-max-error"]),
    "no image folder": ({"--images": "nowhere"}, [], ["--images"]),
    "png overflow": ({}, ["--out-scale", "20000"], ["--out-scale"]),  # stores up to 3.28, the points reach 6
}


@pytest.mark.parametrize("case", sorted(_BAD_FLAGS))
def test_bad_flags_are_one_line_naming_the_flag_and_exit_2(scene, case, capsys):
    root, _ = scene
    (root / "sigma").mkdir()
    changes, extra, flags = _BAD_FLAGS[case]
    given = {"--colmap": "sparse", "--images": "images", "--outdir": "out", **changes}
    folders = ("sparse", "images", "out", "sigma", "nowhere")
    argv = [item for flag, value in given.items() if value is not None for item in (flag, str(root / value))]
    argv += [str(root / item) if item in folders else item for item in extra]
    assert main([*argv, "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for flag in flags:
        assert flag in err[0], err
    assert list((root / "out").iterdir()) == []  # refused before anything is written


def test_images_without_colmap_is_refused(tmp_path, capsys):
    assert main(["--batch", str(tmp_path), "--csv", str(tmp_path / "a.csv"), "--images", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--images goes with --colmap" in err[0]


# ----------------------------------------------------------------------------- executors
def test_two_workers_write_the_same_files_as_one(scene):
    root, _ = scene
    (root / "one").mkdir()
    (root / "two").mkdir()
    base = ["--colmap", str(root / "sparse"), "--images", str(root / "images"), "-q", *FAST_SOLVE]
    assert main([*base, "--outdir", str(root / "one"), "--workers", "1"]) == 0
    assert main([*base, "--outdir", str(root / "two"), "--workers", "2"]) == 0
    for _, name in VIEWS:
        stem = Path(name).with_suffix(".png")
        assert (root / "one" / stem).read_bytes() == (root / "two" / stem).read_bytes()
    one, two = (json.loads((root / d / "scene.json").read_text()) for d in ("one", "two"))
    assert one["views"] == two["views"] and one["png_scale"] == two["png_scale"]


def test_a_dask_cluster_writes_the_same_files(scene):
    distributed = pytest.importorskip("distributed", reason="dask.distributed is not installed")
    root, _ = scene
    (root / "local").mkdir()
    base = ["--colmap", str(root / "sparse"), "--images", str(root / "images"), "-q", "--fast"]
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address=None, silence_logs=40) as cluster:
        assert main([*base, "--outdir", str(root / "out"), "--scheduler", cluster.scheduler_address]) == 0
    assert main([*base, "--outdir", str(root / "local"), "--workers", "1"]) == 0
    for _, name in VIEWS:
        stem = Path(name).with_suffix(".png")
        assert (root / "out" / stem).read_bytes() == (root / "local" / stem).read_bytes()
    assert len(_scene_json(root)["views"]) == 3


# ----------------------------------------------------------------------------- the library's pieces
def test_png_depth_scale_is_the_largest_round_value_that_holds_the_range():
    for max_depth in (0.37, 1.0, 6.0, 10.0, 38.3, 512.0, 9000.0):
        scale = png_depth_scale(max_depth)
        mantissa, exponent = f"{scale:e}".split("e")
        assert float(mantissa) in (1.0, 2.0, 5.0)
        assert round(1.05 * max_depth * scale) <= 65535  # the headroom is storable
        next_round = {1.0: 2.0, 2.0: 5.0, 5.0: 10.0}[float(mantissa)] * 10.0 ** int(exponent)
        assert 1.05 * max_depth * next_round > 65535  # and the next round value would not hold it
    with pytest.raises(ValueError, match="max_depth"):
        png_depth_scale(float("nan"))


def test_colmap_frames_name_outputs_after_the_images_and_refuse_clashes(scene):
    root, model = scene
    frames = colmap_frames(root / "sparse", root / "images")
    assert [f.name for f in frames] == ["cam/v3", "v1", "v2"]
    assert frames[0] == ColmapFrame("cam/v3", str((root / "sparse").resolve()), str(root / "images" / "cam/v3.png"), 3)
    assert colmap_depth_range(root / "sparse") == (NEAR, FAR)
    iio.imwrite(root / "images" / "cam" / "extra.jpg", _render(0.0)[0])
    assert unregistered_images(root / "images", root / "sparse") == ["cam/extra.jpg"]
    for names, match in ((("a.png", "a.jpg", "b.png"), "would both write the output 'a'"),
                         (("../a.png", "b.png", "c.png"), "not a path inside the image folder")):
        images = {i: Image(i, v.qvec, v.tvec, v.camera_id, n, v.xys, v.point3d_ids)
                  for (i, v), n in zip(model.images.items(), names)}
        with pytest.raises(ValueError, match=match):
            colmap_frames(root / "sparse", root / "images", model=ColmapModel(model.cameras, images, model.points3d))


def test_run_batch_on_colmap_frames_with_a_thread_pool(scene, recwarn):
    from concurrent.futures import ThreadPoolExecutor

    root, model = scene
    frames = colmap_frames(root / "sparse", root / "images")
    options = BatchOptions(quality="fast", out_dir=str(root / "out"), out_format=".npy", colmap_min_track=2)
    with ThreadPoolExecutor(2) as pool:
        summary = run_batch(frames, root / "views.csv", options=options, executor=pool)
    assert not [w for w in recwarn if issubclass(w.category, sd.ClampWarning)]  # workers in threads never print
    assert (summary.succeeded, summary.failed) == (3, 0)
    rows = _rows(root / "views.csv")
    for frame in frames:
        _, mask, _ = view_depth(read_colmap_model(root / "sparse"), frame.image_id, min_track=2)
        assert int(rows[frame.name]["observed"]) == int(mask.sum())
        assert rows[frame.name]["rmse"] == "" and rows[frame.name]["scored"] == ""  # no ground truth


# ----------------------------------------------------------------------------- the shared scene
def test_the_shared_colmap_scene_gets_four_full_size_maps(shared_data, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS", raising=False)
    folder = shared_data / "colmap_maupertuis"
    if not folder.is_dir():
        pytest.skip(f"{folder} is not present")
    out = tmp_path / "depth"
    out.mkdir()
    argv = ["--colmap", str(folder / "reconstruction"), "--images", str(folder / "images"), "--outdir", str(out),
            "--fast", "--workers", "1", "-q"]
    assert main(argv) == 0
    assert "4 of 4 views done, 0 failed" in capsys.readouterr().out
    meta = json.loads((out / "scene.json").read_text())
    scale = meta["png_scale"]
    assert scale == 1000.0  # 65535 / (1.05 * 38.3) = 1630
    model = read_colmap_model(folder / "reconstruction")
    assert len(meta["views"]) == 4
    for view in meta["views"]:
        stored = iio.imread(out / view["depth"])
        assert stored.shape == (1079, 1919) and stored.dtype == np.uint16
        depth = stored / scale
        sparse, mask, _ = view_depth(model, view["image"])
        assert view["points"] == int(mask.sum()) > 500
        assert np.all(np.isfinite(depth)) and np.all(stored > 0)
        low, high = sparse[mask].min(), sparse[mask].max()
        assert depth.min() >= low - 0.5 / scale and depth.max() <= high + 0.5 / scale
