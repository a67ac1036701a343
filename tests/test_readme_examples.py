"""The command-line examples of README.md, run as written on a shared KITTI frame.

Every ```bash block line that calls ``python -m sparsedepth.complete`` or ``sparsedepth`` with files is run with
``main(argv)`` in a folder holding the files it names: ``rgb.png`` (the KITTI image), ``sparse.png`` (its LiDAR
depth, KITTI scale) and ``mono.npy`` (a dense prior in the file scale of ``sparse.png``); or, for the example of a
dense NYU map, ``rgb.png`` and ``depth.png`` (millimetres) of the shared NYU labeled frame.  The frames keep their
size (``--camera kitti`` requires KITTI's 1242x375).  Examples
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


@pytest.fixture(scope="module")
def kitti_files(tmp_path_factory):
    """rgb.png, sparse.png and mono.npy, written once from the shared KITTI frame."""
    rgb, depth = _shared(KITTI)
    out = tmp_path_factory.mktemp("kitti")
    iio.imwrite(out / "rgb.png", sd.read_image(rgb))
    metres = sd.read_depth(depth, scale="kitti")
    sd.write_depth(out / "sparse.png", metres, scale="kitti")
    rows, cols = ndimage.distance_transform_edt(~np.isfinite(metres), return_distances=False, return_indices=True)
    np.save(out / "mono.npy", metres[rows, cols] * 256.0)  # dense, in the file scale of sparse.png
    return out


@pytest.fixture(scope="module")
def nyu_files(tmp_path_factory):
    """rgb.png and depth.png (dense, millimetres), written once from the shared NYU labeled frame."""
    rgb, depth = _shared(NYU)
    out = tmp_path_factory.mktemp("nyu")
    iio.imwrite(out / "rgb.png", sd.read_image(rgb))
    sd.write_depth(out / "depth.png", sd.read_depth(depth, scale="mm"), scale="mm")
    return out


@pytest.mark.parametrize("argv", EXAMPLES, ids=[" ".join(a)[:60] for a in EXAMPLES])
def test_readme_example_runs(argv, tmp_path, monkeypatch, capsys, request):
    provided = request.getfixturevalue("nyu_files" if "depth.png" in argv else "kitti_files")
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
            if path.suffix in (".png", ".npy", ".tif", ".pfm") and flag != "--depth-vis":
                scale = ("kitti" if "kitti" in argv else "mm") if path.suffix == ".png" else None
                assert np.isfinite(sd.read_depth(path, scale=scale)).any()
