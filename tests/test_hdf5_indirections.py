"""HDF5 indirections: external raw storage, external links and virtual datasets are refused before any read.

Each of them makes HDF5 open a file the user never named; a FIFO there would block the reader forever. The files
are built with h5py in ``tmp_path``; the FIFO cases run in a subprocess with a timeout, so a hang fails the test
instead of stopping the suite.
"""

import json
import os
import subprocess
import sys

import h5py
import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd
from conftest import REPO
from sparsedepth.complete import main

SHAPE = (4, 5)


def _depth():
    return (1.0 + np.arange(SHAPE[0] * SHAPE[1], dtype=np.float32).reshape(SHAPE) / 10).astype(np.float32)


def _rgb():
    return np.full((3,) + SHAPE, 100, np.uint8)


def _write_raw(path):
    """A raw file holding :func:`_depth` as float32 bytes (a harmless external target)."""
    path.write_bytes(_depth().tobytes())
    return path


def _nyu_h5(path, depth_maker):
    """The one-frame NYU .h5 layout (``rgb`` + ``depth``) with ``depth`` made by ``depth_maker(file)``."""
    with h5py.File(path, "w") as fh:
        fh.create_dataset("rgb", data=_rgb())
        depth_maker(fh)
    return path


def _external_raw(target):
    def make(fh):
        fh.create_dataset("depth", shape=SHAPE, dtype="f4", external=[(str(target), 0, 4 * SHAPE[0] * SHAPE[1])])
    return make


def _external_link(target_file, name="depth"):
    def make(fh):
        fh[name] = h5py.ExternalLink(str(target_file), "/" + name)
    return make


def _virtual(source_file):
    def make(fh):
        layout = h5py.VirtualLayout(shape=SHAPE, dtype="f4")
        layout[:] = h5py.VirtualSource(str(source_file), "depth", shape=SHAPE)
        fh.create_virtual_dataset("depth", layout, fillvalue=0)
    return make


def _plain_h5(path):
    with h5py.File(path, "w") as fh:
        fh.create_dataset("depth", data=_depth())
    return path


@pytest.fixture
def indirect_files(tmp_path):
    """Each kind of indirection, pointing at harmless regular files, in the one-frame NYU .h5 layout."""
    raw = _write_raw(tmp_path / "depth.raw")
    other = _plain_h5(tmp_path / "other.h5")
    return {
        "external raw": _nyu_h5(tmp_path / "external_raw.h5", _external_raw(raw)),
        "external link": _nyu_h5(tmp_path / "external_link.h5", _external_link(other)),
        "virtual": _nyu_h5(tmp_path / "virtual.h5", _virtual(other)),
    }


EXPECT = {"external raw": "external raw file", "external link": "external link", "virtual": "virtual dataset"}


@pytest.mark.parametrize("kind", sorted(EXPECT))
def test_depth_and_nyu_readers_refuse_an_indirection_naming_file_and_dataset(indirect_files, kind):
    path = indirect_files[kind]
    for read in (lambda: sd.read_depth(path), lambda: sd.io.read_nyu_h5(path)):
        with pytest.raises(ValueError, match=EXPECT[kind]) as info:
            read()
        assert str(path) in str(info.value) and "'depth'" in str(info.value)


def test_a_mask_behind_an_external_link_is_refused(tmp_path):
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as fh:
        fh.create_dataset("mask", data=np.ones(SHAPE, bool))
    with h5py.File(tmp_path / "mask.h5", "w") as fh:
        fh["mask"] = h5py.ExternalLink(str(other), "/mask")
    with pytest.raises(ValueError, match="external link"):
        sd.io.read_mask(tmp_path / "mask.h5")


def test_links_are_checked_on_every_step_of_the_path(tmp_path):
    """A group reached through an external link, and a soft link that leads to one, are refused; soft links that
    stay in the file are followed."""
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as fh:
        fh.create_dataset("grp/depth", data=_depth())
    path = tmp_path / "links.h5"
    with h5py.File(path, "w") as fh:
        fh["outside"] = h5py.ExternalLink(str(other), "/grp")
        fh["via_soft"] = h5py.SoftLink("/outside/depth")
        fh.create_dataset("inside/depth", data=_depth())
        fh["alias"] = h5py.SoftLink("/inside")
        fh["loop"] = h5py.SoftLink("/loop")
    assert np.allclose(sd.read_depth(path, key="alias/depth"), _depth())
    for key in ("outside/depth", "via_soft"):
        with pytest.raises(ValueError, match="external link") as info:
            sd.read_depth(path, key=key)
        assert "other.h5" in str(info.value)
    with pytest.raises(ValueError, match="no dataset 'loop'|soft links"):
        sd.read_depth(path, key="loop")


def _write_nyu_mat(path, raw_maker=None, depth_maker=None):
    """The MATLAB v7.3 layout of nyu_depth_v2_labeled.mat: images (N, 3, W, H), depths and rawDepths (N, W, H)."""
    depth = np.ones((1, SHAPE[1], SHAPE[0]), np.float32)
    with h5py.File(path, "w") as fh:
        fh.create_dataset("images", data=np.full((1, 3, SHAPE[1], SHAPE[0]), 100, np.uint8))
        if depth_maker is None:
            fh.create_dataset("depths", data=depth)
        else:
            depth_maker(fh)
        if raw_maker is not None:
            raw_maker(fh)
    return path


def test_nyu_labeled_reader_refuses_indirect_depths_and_raw_depths(tmp_path):
    raw = tmp_path / "raw.bin"
    raw.write_bytes(np.ones((1, SHAPE[1], SHAPE[0]), np.float32).tobytes())

    def external_depths(fh):
        fh.create_dataset("depths", shape=(1, SHAPE[1], SHAPE[0]), dtype="f4",
                          external=[(str(raw), 0, raw.stat().st_size)])

    def linked_raw(fh):
        fh["rawDepths"] = h5py.ExternalLink(str(tmp_path / "absent.mat"), "/rawDepths")

    with pytest.raises(ValueError, match="'depths'.*external raw file"):
        sd.io.NYUDepthV2Labeled(_write_nyu_mat(tmp_path / "a.mat", depth_maker=external_depths))
    with pytest.raises(ValueError, match="'rawDepths'.*external link"):
        sd.io.NYUDepthV2Labeled(_write_nyu_mat(tmp_path / "b.mat", raw_maker=linked_raw))


def test_command_line_refuses_an_indirection_with_one_line_and_exit_2(indirect_files, tmp_path, capsys):
    rgb = tmp_path / "rgb.png"
    iio.imwrite(rgb, np.full(SHAPE + (3,), 100, np.uint8))
    code = main(["--image", str(rgb), "--depth", str(indirect_files["external link"]), "--out",
                 str(tmp_path / "out.npy")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--depth" in err and "external link" in err, err
    assert not (tmp_path / "out.npy").exists()

    raw = _write_raw(tmp_path / "depths.raw")
    mat = _write_nyu_mat(tmp_path / "nyu.mat", depth_maker=lambda fh: fh.create_dataset(
        "depths", shape=(1, SHAPE[1], SHAPE[0]), dtype="f4", external=[(str(raw), 0, raw.stat().st_size)]))
    code = main(["--nyu-mat", str(mat), "--fill-holes", "--csv", str(tmp_path / "m.csv"), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--nyu-mat" in err and "external raw file" in err, err
    assert not (tmp_path / "m.csv").exists()


# ----------------------------------------------------------------------------- a FIFO behind the indirection
_CHILD = r"""
import json, sys
import sparsedepth as sd
from sparsedepth.complete import main

results = {}
for name, call in [
    ("read_depth external raw", lambda: sd.read_depth(sys.argv[1])),
    ("read_nyu_h5 external link", lambda: sd.io.read_nyu_h5(sys.argv[2])),
    ("read_depth virtual", lambda: sd.read_depth(sys.argv[3])),
]:
    try:
        call()
        results[name] = "read"
    except ValueError as exc:
        results[name] = "ValueError: " + str(exc)
results["cli --nyu-mat"] = main(["--nyu-mat", sys.argv[4], "--fill-holes", "--csv", sys.argv[5], "-q"])
print(json.dumps(results))
"""


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="os.mkfifo is not available on this platform")
def test_a_fifo_behind_an_indirection_is_never_opened(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    external_raw = _nyu_h5(tmp_path / "external_raw.h5", _external_raw(fifo))
    external_link = _nyu_h5(tmp_path / "external_link.h5", _external_link(fifo))
    virtual = _nyu_h5(tmp_path / "virtual.h5", _virtual(fifo))
    mat = _write_nyu_mat(tmp_path / "nyu.mat", depth_maker=_external_link(fifo, "depths"))
    args = [str(external_raw), str(external_link), str(virtual), str(mat), str(tmp_path / "m.csv")]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    try:
        out = subprocess.run([sys.executable, "-c", _CHILD, *args], cwd=REPO, capture_output=True, text=True,
                             timeout=60, env=env)
    except subprocess.TimeoutExpired:
        pytest.fail("a reader blocked on the FIFO an HDF5 indirection points at")
    assert out.returncode == 0, out.stderr
    results = json.loads(out.stdout.strip().splitlines()[-1])
    for name in ("read_depth external raw", "read_nyu_h5 external link", "read_depth virtual"):
        assert results[name].startswith("ValueError"), (name, results[name])
    assert results["cli --nyu-mat"] == 2
    assert "external link" in out.stderr and out.stderr.count("\n") == 1, out.stderr
