"""The examples of README.md, run as written on the shared real frames.

Every command of a ```bash block that runs the completion on files (``sparsedepth ...`` or ``python -m
sparsedepth.complete ...``, after an optional ``mkdir -p DIR &&``) is run with ``main(argv)`` in a folder holding the
files it names, written under those names from the shared frame of the input the command is for:

=========================================  ==============================================================
the command has                            files made from
=========================================  ==============================================================
``--sensor realsense-d4xx``                ``realsense_cleargrasp`` (its metres as a 16-bit mm PNG, its YAML)
``--sensor kinect-v1``                     ``nyu_metric3d`` (raw Kinect depth, mm PNG, 640x480)
``--sensor tum``                           ``tum_open3d``
``--sensor kitti-lidar``                   ``kitti_raw_0023`` (its LiDAR as a KITTI PNG, its calibration)
``--depth-scale nyu``                      ``nyu_rcnn_depth`` (the dense map)
``--calib`` with a ``.pfm`` depth          ``middlebury2014_skimage`` (its disparity and calibration)
``--colmap``                               ``colmap_maupertuis`` (images and model at a quarter of the size)
=========================================  ==============================================================

A command with ``--camera`` (whose presets refuse other image sizes) or a disparity runs on the full frame, the others
on every second row and column (an intrinsics file scaled to match): the same scene, a quarter of the pixels.  Without
matplotlib, ``--figure PATH`` is left out of a command (the rest of it still runs).  The README's Python block runs
on the KITTI LiDAR frame's files.  Also here: ``help(sparsedepth)`` opens with the user's API, and the package
docstring's example runs as shown (the docstring tests cover the subpackages only).
"""

import dataclasses
import doctest
import functools
import importlib.util
import json
import pydoc
import re
import shlex

import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd
from conftest import REPO, SHARED_DATA
from sparsedepth.complete import main
from sparsedepth.io.pfm import write_pfm

README = (REPO / "README.md").read_text(encoding="utf-8")
OUTPUT_FLAGS = ("--out", "--uncertainty", "--json", "--figure", "--ply", "--depth-vis", "--csv")
SKIPPED_INPUTS = {"--nyu-mat": "the NYU Depth V2 labeled .mat is not among the shared frames",
                  "--scheduler-file": "needs a running Dask scheduler"}
MIDDLEBURY_CALIB = ("cam0=[994.978 0 311.193; 0 994.978 254.877; 0 0 1]\n"  # ../shared/data/SOURCES.md
                    "cam1=[994.978 0 342.279; 0 994.978 254.877; 0 0 1]\n"
                    "doffs=31.086\nbaseline=193.001\nwidth=741\nheight=500\nndisp=270\n")


@dataclasses.dataclass(frozen=True)
class Source:
    """A shared frame standing in for one kind of input: its image, its depth in metres, the file scale."""

    folder: str
    image: str
    depth: str
    scale: float  # stored value / scale = metres, for the PNG files of this kind of input
    key: str | None = None  # array of an .npz depth file (float metres, 0 or NaN = none)
    intrinsics: str | None = None  # intrinsics file in the folder


SOURCES = {
    "realsense-d4xx": Source("realsense_cleargrasp", "rgb_000000080.jpg", "depth_000000080.npz", 1000.0, "depth",
                             "camera_intrinsics.yaml"),
    "kinect-v1": Source("nyu_metric3d", "rgb_00000.jpg", "sync_depth_00000.png", 1000.0),
    "tum": Source("tum_open3d", "TUM_color.png", "TUM_depth.png", 5000.0),
    "kitti-lidar": Source("kitti_raw_0023", "rgb_0000000000.png", "velodyne_0000000000.npz", 256.0, "velodyne_depth",
                          "calib_cam_to_cam.txt"),
    "nyu": Source("nyu_rcnn_depth", "images.png", "depth.png", 1000.0),
}


@dataclasses.dataclass(frozen=True)
class Example:
    """One README command: the arguments of ``main`` and the folders its ``mkdir -p`` creates."""

    argv: tuple
    folders: tuple = ()

    def value(self, flag):
        return self.argv[self.argv.index(flag) + 1] if flag in self.argv else None


def _examples(text=README):
    """Every command of a ```bash block that runs the completion on files (continuations joined)."""
    examples = []
    for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.split(" #")[0].strip()
            if line.startswith("#") or not any(flag in line for flag in ("--image", "--nyu-mat", "--colmap")):
                continue
            folders, argv = [], None
            for part in line.split("&&"):
                words = shlex.split(part)
                if words[:2] == ["mkdir", "-p"]:
                    folders += words[2:]
                elif words[:3] == ["python", "-m", "sparsedepth.complete"]:
                    argv = words[3:]
                elif words[:1] == ["sparsedepth"]:
                    argv = words[1:]
            if argv is not None:
                examples.append(Example(tuple(argv), tuple(folders)))
    return examples


EXAMPLES = _examples()


def _kind(example):
    """The input an example is for: a key of SOURCES, "disparity" or "colmap"."""
    if example.value("--colmap"):
        return "colmap"
    if example.value("--sensor"):
        return example.value("--sensor")
    if example.value("--calib") and example.value("--depth").endswith(".pfm"):
        return "disparity"
    return example.value("--depth-scale")


def test_the_readme_has_a_command_for_every_input_on_its_first_screen():
    kinds = {_kind(example) for example in EXAMPLES}
    assert {"realsense-d4xx", "kinect-v1", "kitti-lidar", "disparity", "colmap"} <= kinds
    assert any("--uncertainty" in example.argv for example in EXAMPLES)
    first_screen = "\n".join(README.splitlines()[:50])
    for sensor in ("realsense-d4xx", "kinect-v1", "kitti-lidar"):
        assert f"--sensor {sensor}" in first_screen, sensor


def test_the_readme_has_one_accuracy_block_for_the_benchmark_to_fill():
    lines = README.splitlines()
    starts = [i for i, line in enumerate(lines) if line.strip() == "<!-- scene-disjoint:start -->"]
    ends = [i for i, line in enumerate(lines) if line.strip() == "<!-- scene-disjoint:end -->"]
    assert len(starts) == 1 and len(ends) == 1 and starts[0] < ends[0]


def test_every_file_the_readme_links_to_exists():
    targets = re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", README)
    assert "docs/figures/overview.png" in targets
    missing = [target for target in targets if not (REPO / target).exists()]
    assert not missing


def test_the_two_set_up_commands_are_in_the_readme():
    assert "python -m pip install -e . && python -m sparsedepth.complete\n" in README
    assert ('python -m pip install -q -e ".[test,distributed,docs]" && python -m mkdocs build --strict -q && '
            "python -m pytest -q\n") in README


def _shared(*parts):
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real-data folder {SHARED_DATA} not present (set SPARSEDEPTH_DATA)")
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"{path} missing")
    return path


@functools.lru_cache(maxsize=None)
def _frame(kind):
    """The image and the depth in metres (NaN = none) of a kind of input, full size."""
    source = SOURCES[kind]
    image = sd.read_image(_shared(source.folder, source.image))
    path = _shared(source.folder, source.depth)
    if source.key:
        depth = np.load(path)[source.key].astype(float)
        depth[~(depth > 0)] = np.nan
    else:
        depth = sd.read_depth(path, scale=source.scale)
    return image, depth


def _scaled_intrinsics_file(text, step):
    """An intrinsics file's text (RealSense YAML or KITTI calib_cam_to_cam.txt) for every ``step``-th pixel."""
    def yaml_line(match):
        return f"{match[1]}{float(match[2]) / step!r}"

    def kitti_line(match):
        values = np.array(match[2].split(), dtype=float)
        values[:8] /= step  # the first two rows of P (pixel centres at integer coordinates)
        return match[1] + " ".join(repr(float(v)) for v in values)

    text = re.sub(r"(?m)^(\s*(?:fx|fy|cx|cy):\s*)([-+0-9.eE]+)", yaml_line, text)
    return re.sub(r"(?m)^(P_rect_02:\s*)(.*)$", kitti_line, text)


def _write_frame_files(example, kind, folder, step):
    """The files the example reads, under its names, from the shared frame of ``kind``."""
    source = SOURCES[kind]
    image, depth = _frame(kind)
    iio.imwrite(folder / example.value("--image"), image[::step, ::step])
    depth = depth[::step, ::step]
    sd.write_depth(folder / example.value("--depth"), depth, scale=source.scale)
    intrinsics = example.value("--intrinsics")
    if intrinsics and "," not in intrinsics:
        text = _shared(source.folder, source.intrinsics).read_text()
        (folder / intrinsics).write_text(_scaled_intrinsics_file(text, step))


def _write_disparity_files(example, folder):
    """A Middlebury image, its disparity as a PFM (inf = none) and its calib.txt, full size."""
    image = sd.read_image(_shared("middlebury2014_skimage", "motorcycle_left.png"))
    disparity = np.load(_shared("middlebury2014_skimage", "motorcycle_disp.npz"))["arr_0"].astype(np.float32)
    iio.imwrite(folder / example.value("--image"), image)
    write_pfm(folder / example.value("--depth"), np.where(np.isfinite(disparity), disparity, np.inf))
    (folder / example.value("--calib")).write_text(MIDDLEBURY_CALIB)


def _write_colmap_files(example, folder, step=4):
    """The shared COLMAP scene at every ``step``-th pixel: images, and a text model with its camera and keypoints
    moved to the smaller images (COLMAP's pixel centres sit at 0.5: x' = (x - 0.5) / step + 0.5)."""
    model_in = _shared("colmap_maupertuis", "reconstruction")
    images_in = _shared("colmap_maupertuis", "images")
    model_out = folder / example.value("--colmap")
    images_out = folder / example.value("--images")
    model_out.mkdir(parents=True)
    images_out.mkdir(parents=True)
    for path in sorted(images_in.iterdir()):
        iio.imwrite(images_out / path.name, sd.read_image(path)[::step, ::step], quality=95)

    def pixel(value):
        return repr((float(value) - 0.5) / step + 0.5)

    cameras = []
    for line in (model_in / "cameras.txt").read_text().splitlines():
        if line.startswith("#") or not line.strip():
            cameras.append(line)
            continue
        camera_id, model, width, height, *params = line.split()
        assert model == "SIMPLE_PINHOLE", model
        f, cx, cy = params
        cameras.append(f"{camera_id} {model} {-(-int(width) // step)} {-(-int(height) // step)} "
                       f"{float(f) / step!r} {pixel(cx)} {pixel(cy)}")
    (model_out / "cameras.txt").write_text("\n".join(cameras) + "\n")
    images, data_lines = [], 0
    for line in (model_in / "images.txt").read_text().splitlines():
        if line.startswith("#"):
            images.append(line)
            continue
        data_lines += 1
        if data_lines % 2:  # IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME
            images.append(line)
        else:  # X Y POINT3D_ID triples
            words = line.split()
            images.append(" ".join(pixel(w) if i % 3 < 2 else w for i, w in enumerate(words)))
    (model_out / "images.txt").write_text("\n".join(images) + "\n")
    (model_out / "points3D.txt").write_text((model_in / "points3D.txt").read_text())
    return sorted(path.name for path in images_in.iterdir())


def _png_scale(example, kind):
    if example.value("--out-scale"):
        return sd.io.resolve_scale(example.value("--out-scale"))
    return SOURCES[kind].scale if kind in SOURCES else 1000.0


@pytest.mark.parametrize("example", EXAMPLES, ids=[" ".join(e.argv)[:60] for e in EXAMPLES])
def test_readme_example_runs(example, tmp_path, monkeypatch, capsys):
    for flag, reason in SKIPPED_INPUTS.items():
        if flag in example.argv:
            pytest.skip(f"{flag}: {reason}")
    kind = _kind(example)
    step = 1 if "--camera" in example.argv else 2
    if kind == "colmap":
        views = _write_colmap_files(example, tmp_path)
    elif kind == "disparity":
        _write_disparity_files(example, tmp_path)
    elif kind in SOURCES:
        _write_frame_files(example, kind, tmp_path, step)
    else:
        pytest.fail(f"no shared frame stands in for this README command's input ({kind}): add one to SOURCES")
    for name in example.folders:
        (tmp_path / name).mkdir(parents=True, exist_ok=True)
    argv = list(example.argv)
    if "--figure" in argv and importlib.util.find_spec("matplotlib") is None:
        del argv[argv.index("--figure"):argv.index("--figure") + 2]  # the figure needs the plot extra
    monkeypatch.chdir(tmp_path)
    rc = main([*argv, "-q"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    for flag in OUTPUT_FLAGS:
        if flag in argv:
            path = tmp_path / example.value(flag)
            assert path.is_file() and path.stat().st_size > 0, flag
    if kind == "colmap":
        outdir = tmp_path / example.value("--outdir")
        scene = json.loads((outdir / "scene.json").read_text())
        assert sorted(view["image"] for view in scene["views"]) == views and not scene["failed"]
        for view in scene["views"]:
            assert np.isfinite(sd.read_depth(outdir / view["depth"], scale=scene["png_scale"])).any()
        return
    if example.value("--json"):
        json.loads((tmp_path / example.value("--json")).read_text())
    out = tmp_path / example.value("--out") if example.value("--out") else None
    if out is not None:
        scale = _png_scale(example, kind) if out.suffix == ".png" else None
        depth = sd.read_depth(out, scale=scale)
        assert depth.shape == sd.read_image(tmp_path / example.value("--image")).shape[:2]
        if "--fill-holes" in argv:  # a hole fill leaves no pixel without depth
            assert np.isfinite(depth).all()
        else:
            assert np.isfinite(depth).any()
        if example.value("--ply"):  # one point per pixel with depth, at that depth
            points, _ = sd.read_ply(tmp_path / example.value("--ply"))
            assert len(points) == np.isfinite(depth).sum()
            step_of_file = 1.0 / scale if scale else 0.0
            np.testing.assert_allclose(np.sort(points[:, 2]), np.sort(depth[np.isfinite(depth)]),
                                       rtol=1e-6, atol=step_of_file)
    if example.value("--uncertainty"):
        sigma = sd.read_depth(tmp_path / example.value("--uncertainty"))
        assert np.isfinite(sigma).any() and np.nanmin(sigma) >= 0


def _python_blocks(text=README):
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def test_the_readme_python_block_runs_and_writes_what_it_says(tmp_path, monkeypatch):
    blocks = _python_blocks()
    assert len(blocks) == 1
    example = Example(("--image", "image_02.png", "--depth", "velodyne.png", "--intrinsics", "calib_cam_to_cam.txt"))
    for name in ("image_02.png", "velodyne.png", "calib_cam_to_cam.txt"):
        assert name in blocks[0], name
    _write_frame_files(example, "kitti-lidar", tmp_path, 2)
    monkeypatch.chdir(tmp_path)
    namespace = {}
    exec(compile(blocks[0], "README.md python block", "exec"), namespace)
    result = namespace["result"]
    np.testing.assert_array_equal(sd.read_depth(tmp_path / "dense.tif"), result.depth.astype(np.float32))
    assert result.uncertainty.shape == result.depth.shape
    points, colors = sd.read_ply(tmp_path / "cloud.ply")
    assert len(points) == np.isfinite(result.depth).sum() == len(colors)


def test_help_sparsedepth_opens_with_the_users_api_and_points_to_the_guides():
    page = pydoc.render_doc(sd, renderer=pydoc.plaintext).splitlines()
    first_screen = "\n".join(page[:60])
    for name in ("The user's API", "complete_depth", "CompletionResult", "fill_holes", "read_depth", "write_depth",
                 "sample_depth", "sample_mask", "python -m sparsedepth.complete", "docs/guides/"):
        assert name in first_screen, name
    missing = [page for page in re.findall(r"docs/[\w/]+\.md", sd.__doc__) if not (REPO / page).is_file()]
    assert not missing


def test_the_package_docstring_example_runs_as_shown():
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    tests = [test for test in doctest.DocTestFinder(recurse=False).find(sd, "sparsedepth") if test.examples]
    assert tests
    for test in tests:
        runner.run(test, out=lambda text: None)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of help(sparsedepth) fail"
