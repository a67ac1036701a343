"""--depth-vis and --outdir's depth_vis.png: a colour picture of the output depth, planned with the other outputs."""

import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.complete import main

FAST = ["--gamma", "0", "--solver", "direct", "-q"]


@pytest.fixture
def files(scene_files):
    return scene_files




def _one(files, *extra):
    return ["--image", str(files / "rgb.png"), "--depth", str(files / "sparse.png"), "--depth-scale", "mm",
            *map(str, extra), *FAST]


def _check_picture(path, depth):
    picture = iio.imread(path)
    assert picture.shape == depth.shape + (3,) and picture.dtype == np.uint8
    assert picture.max() > 100  # not the black of a 16-bit metric PNG in a viewer
    np.testing.assert_array_equal(picture, sd.colorize_depth(depth))


def test_depth_vis_is_the_colourised_output(files, capsys):
    rc = main(_one(files, "--out", files / "o.npy", "--depth-vis", files / "vis.png"))
    assert rc == 0, capsys.readouterr().err
    _check_picture(files / "vis.png", np.load(files / "o.npy"))


def test_outdir_writes_depth_vis(files, capsys):
    outdir = files / "out"
    outdir.mkdir()
    rc = main(_one(files, "--outdir", outdir))
    assert rc == 0, capsys.readouterr().err
    _check_picture(outdir / "depth_vis.png", np.load(outdir / "depth.npy"))


def test_depth_vis_works_without_matplotlib(files, capsys, monkeypatch):
    for name in ("matplotlib", "matplotlib.figure", "matplotlib.backends.backend_agg"):
        monkeypatch.setitem(__import__("sys").modules, name, None)  # import raises ImportError
    rc = main(_one(files, "--out", files / "o.npy", "--depth-vis", files / "vis.png"))
    assert rc == 0, capsys.readouterr().err
    _check_picture(files / "vis.png", np.load(files / "o.npy"))


def _refused(argv, files, capsys, expect):
    before = sorted(p.name for p in files.rglob("*"))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and expect in err, err
    assert sorted(p.name for p in files.rglob("*")) == before  # nothing written


def test_depth_vis_must_be_png(files, capsys):
    _refused(_one(files, "--out", files / "o.npy", "--depth-vis", files / "vis.jpg"), files, capsys,
             f"--depth-vis '{files / 'vis.jpg'}': unsupported extension '.jpg'; use .png")


def test_depth_vis_is_never_an_input(files, capsys):
    _refused(_one(files, "--out", files / "o.npy", "--depth-vis", files / "rgb.png"), files, capsys,
             "is the same file as --image")


def test_depth_vis_in_a_missing_folder_writes_nothing(files, capsys):
    _refused(_one(files, "--out", files / "o.npy", "--depth-vis", files / "nope" / "vis.png"), files, capsys,
             "does not exist")


def test_depth_vis_is_for_one_frame(files, capsys):
    _refused(["--batch", str(files), "--csv", str(files / "m.csv"), "--depth-vis", str(files / "vis.png"),
              "--keep-fraction", "0.1", *FAST], files, capsys, "--depth-vis is for one frame")
