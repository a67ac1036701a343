"""The command-line examples of README.md, run as written on a shared KITTI frame.

Every ```bash block line that calls ``python -m sparsedepth.complete`` or ``sparsedepth`` with files is run with
``main(argv)`` in a folder holding the files it names: ``rgb.png`` (the KITTI image), ``sparse.png`` (its LiDAR
depth, KITTI scale) and ``mono.npy`` (a dense prior in the file scale of ``sparse.png``); or, for the example of a
dense NYU map, ``rgb.png`` and ``depth.png`` (millimetres) of the shared NYU labeled frame.  An example with
``--camera`` runs on the full frame (``--camera kitti`` requires KITTI's 1242x375); the others on every second row and
column of it (the same scene and about the same share of observed pixels, a quarter of the pixels).  Examples
naming a file that is not there (the NYU ``.mat``, a scheduler file) are skipped with the reason; without
matplotlib, ``--figure PATH`` is left out of an example (the rest of it still runs).
"""

import importlib.util
import re
import shlex

import imageio.v3 as iio
import numpy as np
import pytest
from scipy import ndimage

import sparsedepth as sd
from conftest import REPO, SHARED_DATA
from sparsedepth.complete import main

KITTI = ("kitti_metric3d", "rgb_0000000005.png", "depth_0000000005.png")
NYU = ("nyu_rcnn_depth", "images.png", "depth.png")
OUTPUT_FLAGS = ("--out", "--uncertainty", "--json", "--figure", "--ply", "--depth-vis", "--csv")


def _examples():
    """Every command of a ```bash block of README.md that runs the completion on files (continuations joined)."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.split(" #")[0].strip()
            if line.startswith("#") or "--image" not in line and "--nyu-mat" not in line:
                continue
            words = shlex.split(line)
            if words[:3] == ["python", "-m", "sparsedepth.complete"]:
                commands.append(words[3:])
            elif words[:1] == ["sparsedepth"]:
                commands.append(words[1:])
    return commands


EXAMPLES = _examples()


def test_the_readme_has_command_line_examples():
    assert len(EXAMPLES) >= 6 and any("--uncertainty" in argv for argv in EXAMPLES)


def _shared(source):
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real-data folder {SHARED_DATA} not present (set SPARSEDEPTH_DATA)")
    folder, image, depth = source
    paths = SHARED_DATA / folder / image, SHARED_DATA / folder / depth
    for path in paths:
        if not path.is_file():
            pytest.skip(f"{path} missing")
    return paths


def _kitti_files(tmp_path_factory, step):
    """rgb.png, sparse.png and mono.npy from the shared KITTI frame, every ``step``-th row and column."""
    rgb, depth = _shared(KITTI)
    out = tmp_path_factory.mktemp(f"kitti_step{step}")
    iio.imwrite(out / "rgb.png", sd.read_image(rgb)[::step, ::step])
    metres = sd.read_depth(depth, scale="kitti")[::step, ::step]
    sd.write_depth(out / "sparse.png", metres, scale="kitti")
    rows, cols = ndimage.distance_transform_edt(~np.isfinite(metres), return_distances=False, return_indices=True)
    np.save(out / "mono.npy", metres[rows, cols] * 256.0)  # dense, in the file scale of sparse.png
    return out


@pytest.fixture(scope="module")
def kitti_files(tmp_path_factory):
    """The full KITTI frame's files, written once."""
    return _kitti_files(tmp_path_factory, 1)


@pytest.fixture(scope="module")
def kitti_half_files(tmp_path_factory):
    """The KITTI frame's files at every second row and column, written once."""
    return _kitti_files(tmp_path_factory, 2)


def _nyu_files(tmp_path_factory, step):
    """rgb.png and depth.png (dense, millimetres) from the shared NYU labeled frame, every ``step``-th row and
    column."""
    rgb, depth = _shared(NYU)
    out = tmp_path_factory.mktemp(f"nyu_step{step}")
    iio.imwrite(out / "rgb.png", sd.read_image(rgb)[::step, ::step])
    sd.write_depth(out / "depth.png", sd.read_depth(depth, scale="mm")[::step, ::step], scale="mm")
    return out


@pytest.fixture(scope="module")
def nyu_files(tmp_path_factory):
    """The full NYU frame's files, written once."""
    return _nyu_files(tmp_path_factory, 1)


@pytest.fixture(scope="module")
def nyu_half_files(tmp_path_factory):
    """The NYU frame's files at every second row and column, written once."""
    return _nyu_files(tmp_path_factory, 2)


@pytest.mark.parametrize("argv", EXAMPLES, ids=[" ".join(a)[:60] for a in EXAMPLES])
def test_readme_example_runs(argv, tmp_path, monkeypatch, capsys, request):
    dataset = "nyu" if "depth.png" in argv else "kitti"
    provided = request.getfixturevalue(f"{dataset}_files" if "--camera" in argv else f"{dataset}_half_files")
    for path in provided.iterdir():
        (tmp_path / path.name).symlink_to(path)
    for flag in ("--nyu-mat", "--scheduler-file", "--calib", "--batch"):
        if flag in argv and not (tmp_path / argv[argv.index(flag) + 1]).exists():
            pytest.skip(f"{flag} {argv[argv.index(flag) + 1]}: no such file here")
    argv = list(argv)
    if "--figure" in argv and importlib.util.find_spec("matplotlib") is None:
        del argv[argv.index("--figure"):argv.index("--figure") + 2]  # the figure needs the plot extra
    monkeypatch.chdir(tmp_path)
    rc = main([*argv, "-q"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    for flag in OUTPUT_FLAGS:
        if flag in argv:
            path = tmp_path / argv[argv.index(flag) + 1]
            assert path.is_file() and path.stat().st_size > 0, flag
            if path.suffix in (".png", ".npy", ".tif", ".pfm") and flag not in ("--depth-vis", "--figure"):  # pictures
                scale = ("kitti" if "kitti" in argv else "mm") if path.suffix == ".png" else None
                assert np.isfinite(sd.read_depth(path, scale=scale)).any()
