"""python -m sparsedepth.complete: inputs are never overwritten; outputs are checked first and written all or nothing."""

import errno
import json
import os
import pathlib
import sys

import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd
import sparsedepth.cli.single as cli

from conftest import make_scene as _scene
from sparsedepth.cli.command import PROG, main

FAST = ["--gamma", "0", "--solver", "direct"]  # quadratic objective, exact direct solve


@pytest.fixture
def files(tmp_path):
    """rgb.png, dense.png (mm), sparse.png (10 % of dense, mm), mask.npy and calib.txt."""
    image, depth = _scene()
    iio.imwrite(tmp_path / "rgb.png", image)
    sd.write_depth(tmp_path / "dense.png", depth, scale=1000)
    sparse, mask = sd.sample_depth(depth, fraction=0.1, seed=1)
    sd.write_depth(tmp_path / "sparse.png", sparse, scale=1000)
    np.save(tmp_path / "mask.npy", np.ones(depth.shape, bool))
    return tmp_path


def _snapshot(folder):
    """{relative path: bytes (files) or None (folders and links)} of everything under ``folder``."""
    return {str(p.relative_to(folder)): (None if p.is_dir() or p.is_symlink() else p.read_bytes())
            for p in sorted(folder.rglob("*"))}


def _run_refused(argv, capsys, folder, *expect):
    """main(argv) exits 2 with one line on stderr holding every ``expect``, and ``folder`` is unchanged."""
    before = _snapshot(folder)
    rc = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2, err
    # one error line; a warning of the solve (e.g. the range clamp) may come before it on its own line
    errors = [line for line in err.splitlines() if not line.startswith("warning: ")]
    assert err.endswith("\n") and len(errors) == 1 and errors[0].startswith(f"{PROG}: error: "), err
    for text in expect:
        assert text in err, err
    assert _snapshot(folder) == before  # same names, same bytes: no temporary file, no output
    return err


def _one(files, *extra):
    return ["--image", files / "rgb.png", "--depth", files / "sparse.png", "--depth-scale", "mm", "-q", *FAST,
            *extra]


def _expected(files):
    image, sparse = sd.read_image(files / "rgb.png"), sd.read_depth(files / "sparse.png", scale=1000)
    return sd.complete_depth(image, sparse, weights=sd.DEFAULT_SCHEDULE.replace(gamma=0.0), solver="direct").depth


# ----------------------------------------------------------------------------- inputs are never outputs
def test_out_equal_to_depth_is_refused(files, capsys):
    err = _run_refused(_one(files, "--out", files / "sparse.png"), capsys, files,
                       "--out", "is the same file as --depth", "choose another --out")
    assert err.count(str(files / "sparse.png")) == 2  # both paths as the user typed them


@pytest.mark.parametrize("spelling", ["dotdot", "symlink", "hardlink"])
def test_out_is_the_depth_under_another_name(files, capsys, spelling):
    (files / "sub").mkdir()
    if spelling == "dotdot":
        out = files / "sub" / ".." / "sparse.png"
    elif spelling == "symlink":
        out = files / "sub" / "link.png"
        out.symlink_to(files / "sparse.png")
    else:
        out = files / "sub" / "hard.png"
        os.link(files / "sparse.png", out)
    _run_refused(_one(files, "--out", out), capsys, files, "--out", "is the same file as --depth")


@pytest.mark.parametrize("flag, name, out_flag", [
    ("--image", "rgb.png", "--out"), ("--truth", "dense.png", "--out"), ("--mask", "mask.npy", "--out"),
    ("--depth", "sparse.png", "--json"),
])
def test_every_input_is_protected(files, capsys, flag, name, out_flag):
    extra = [] if flag in ("--image", "--depth") else [flag, files / name]
    target = files / name
    if out_flag == "--json":  # a .json name that is a symbolic link to the depth file
        target = files / "link.json"
        target.symlink_to(files / name)
    _run_refused(_one(files, *extra, out_flag, target), capsys, files,
                 f"{out_flag} '{target}' is the same file as {flag} '{files / name}'")


def test_calib_is_protected(files, capsys):
    image, depth = _scene()
    disparity = np.where(np.random.default_rng(0).random(depth.shape) < 0.1, 50.0 / depth, np.inf)
    sd.io.write_pfm(files / "disp.pfm", disparity)
    (files / "calib.txt").write_text("cam0=[500 0 30; 0 500 20; 0 0 1]\ncam1=[500 0 30; 0 500 20; 0 0 1]\n"
                                     "doffs=0\nbaseline=100\nwidth=60\nheight=40\n")
    (files / "calib.npy").symlink_to(files / "calib.txt")
    _run_refused(["--image", files / "rgb.png", "--depth", files / "disp.pfm", "--calib", files / "calib.txt",
                  "--out", files / "calib.npy", "-q", *FAST], capsys, files, "same file as --calib")


def test_figure_equal_to_image_is_refused(files, capsys):
    # refused for the clash, whether or not matplotlib is installed
    _run_refused(_one(files, "--figure", files / "rgb.png"), capsys, files,
                 f"--figure '{files / 'rgb.png'}' is the same file as --image")


def test_outdir_dot_holding_the_depth_is_refused(files, capsys, monkeypatch):
    (files / "depth.png").write_bytes((files / "sparse.png").read_bytes())
    monkeypatch.chdir(files)
    _run_refused(["--image", "rgb.png", "--depth", "depth.png", "--depth-scale", "mm", "--outdir", ".", "-q",
                  *FAST], capsys, files, "--outdir '.' file 'depth.png' is the same file as --depth 'depth.png'")


@pytest.mark.parametrize("first, name", [("--out", "depth.npy"), ("--json", "metrics.json")])
def test_two_outputs_on_one_file_are_refused(files, capsys, first, name):
    (files / "d").mkdir()
    _run_refused(_one(files, first, files / "d" / name, "--outdir", files / "d"), capsys, files,
                 f"{first} '{files / 'd' / name}' and --outdir", "are the same file")


def _batch_folder(folder, n=2):
    for i in range(n):
        image, depth = _scene(seed=i)
        iio.imwrite(folder / f"rgb_{i:04d}.png", image)
        sparse, _ = sd.sample_depth(depth, fraction=0.1, seed=i)
        np.save(folder / f"d{i:04d}.npy", sparse)
        (folder / f"depth_{i:04d}.npy").symlink_to(folder / f"d{i:04d}.npy")


def test_batch_output_onto_an_input_is_refused(tmp_path, capsys):
    # depth_0001.npy is a link to 0001.npy, the per-frame output of frame 0001 in --outdir
    _batch_folder(tmp_path)
    os.replace(tmp_path / "d0001.npy", tmp_path / "0001.npy")
    (tmp_path / "depth_0001.npy").unlink()
    (tmp_path / "depth_0001.npy").symlink_to(tmp_path / "0001.npy")
    _run_refused(["--batch", tmp_path, "--csv", tmp_path / "m.csv", "--outdir", tmp_path, "--workers", "1",
                  "-q", *FAST], capsys, tmp_path,
                 f"--outdir '{tmp_path}' file '{tmp_path / '0001.npy'}' is the same file as --batch")


def test_batch_csv_onto_an_input_is_refused(tmp_path, capsys):
    _batch_folder(tmp_path)
    (tmp_path / "m.csv").symlink_to(tmp_path / "rgb_0000.png")
    _run_refused(["--batch", tmp_path, "--csv", tmp_path / "m.csv", "--workers", "1", "-q", *FAST], capsys,
                 tmp_path, "--csv", "is the same file as --batch")


# ----------------------------------------------------------------------------- every output checked first
def test_json_directory_refused_before_anything_is_written(files, capsys):
    (files / "m.json").mkdir()
    _run_refused(_one(files, "--out", files / "o.npy", "--json", files / "m.json"), capsys, files,
                 f"--json '{files / 'm.json'}' is a directory")


def test_figure_directory_refused_before_anything_is_written(files, capsys):
    pytest.importorskip("matplotlib")
    (files / "fig.png").mkdir()
    _run_refused(_one(files, "--out", files / "o.npy", "--figure", files / "fig.png"), capsys, files,
                 f"--figure '{files / 'fig.png'}' is a directory")


def test_folder_that_is_a_file_is_refused(files, capsys):
    (files / "plain").write_text("a file, not a folder")
    _run_refused(_one(files, "--out", files / "o.npy", "--json", files / "plain" / "m.json"), capsys, files,
                 "--json", "not a folder")


def _unwritable_folder(tmp_path):
    """A folder where creating a file fails for this user (root ignores permission bits)."""
    folder = tmp_path / "readonly"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        (folder / "probe").write_bytes(b"")
    except OSError:
        return folder
    (folder / "probe").unlink()
    folder.chmod(0o755)
    proc = pathlib.Path("/proc")
    if sys.platform.startswith("linux") and proc.is_dir():
        try:
            (proc / "sparsedepth-probe.json").write_bytes(b"")
        except OSError:
            return proc
    pytest.skip("no folder this user cannot write to")


def test_unwritable_json_folder_refused_before_anything_is_written(files, capsys):
    folder = _unwritable_folder(files)
    try:
        _run_refused(_one(files, "--out", files / "o.npy", "--json", folder / "m.json"), capsys, files,
                     f"--json '{folder / 'm.json'}': cannot create a file in folder '{folder}'")
    finally:
        if folder.parent == files:
            folder.chmod(0o755)


def test_png_overflow_predicted_before_the_solve(files, capsys, monkeypatch):
    def no_solve(*args, **kwargs):
        raise AssertionError("the solve ran although the PNG output cannot hold the depth")

    monkeypatch.setattr(cli, "evaluate_frame", no_solve)
    # the depth reaches 2.87 m: 2.87 * 50000 > 65535
    _run_refused(_one(files, "--out", files / "o.png", "--out-scale", "50000"), capsys, files,
                 f"--out '{files / 'o.png'}': the depth of --depth reaches", "overflows", "--out-scale")
    (files / "d").mkdir()
    _run_refused(_one(files, "--outdir", files / "d", "--out-scale", "50000"), capsys, files,
                 f"--outdir '{files / 'd'}' file '{files / 'd' / 'depth.png'}'", "overflows")
    # 1 m at scale 0.1 stores 0 (invalid)
    _run_refused(_one(files, "--out", files / "o.png", "--out-scale", "0.1"), capsys, files, "rounds to 0")


def test_png_overflow_of_the_completed_depth_writes_nothing(files, capsys, monkeypatch):
    # a completed map beyond the observed range (tripled here) is checked again before any file is written
    real = cli.evaluate_frame

    def tripled(*args, **kwargs):
        outcome = real(*args, **kwargs)
        object.__setattr__(outcome, "depth", outcome.depth * 3)
        return outcome

    monkeypatch.setattr(cli, "evaluate_frame", tripled)
    _run_refused(_one(files, "--out", files / "o.npy", "--json", files / "m.json", "--outdir", files,
                      "--out-scale", "20000"), capsys, files, "the completed depth reaches", "overflows")


# ----------------------------------------------------------------------------- all or nothing
def _old_outputs(files):
    (files / "d").mkdir()
    for path in (files / "o.npy", files / "m.json", files / "d" / "depth.npy", files / "d" / "depth.png",
                 files / "d" / "metrics.json"):
        path.write_bytes(b"old " + path.name.encode())
    return _one(files, "--out", files / "o.npy", "--outdir", files / "d", "--json", files / "m.json")


def test_failed_write_keeps_every_old_file(files, capsys, monkeypatch):
    argv = _old_outputs(files)
    real = pathlib.Path.write_bytes

    def full_disk(self, data):
        if self.suffix == ".json":
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, data)

    monkeypatch.setattr(pathlib.Path, "write_bytes", full_disk)
    _run_refused(argv, capsys, files, "No space left on device")


@pytest.mark.parametrize("failing_call", [1, 2, 4])
def test_failed_rename_puts_every_old_file_back(files, capsys, monkeypatch, failing_call):
    argv = _old_outputs(files)
    real, calls = os.replace, []

    def flaky(src, dst, **kwargs):
        calls.append(dst)
        if len(calls) == failing_call:
            raise OSError(errno.EIO, "Input/output error")
        return real(src, dst, **kwargs)

    monkeypatch.setattr(os, "replace", flaky)
    _run_refused(argv, capsys, files, "Input/output error")


def test_demo_folder_created_only_when_everything_is_written(tmp_path, capsys, monkeypatch):
    real = pathlib.Path.write_bytes

    def full_disk(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(pathlib.Path, "write_bytes", full_disk)
    _run_refused(["--outdir", tmp_path / "new" / "demo", "--downsample", "8", "-q", *FAST], capsys, tmp_path,
                 "--outdir", "No space left on device")
    monkeypatch.setattr(pathlib.Path, "write_bytes", real)
    assert main(["--outdir", str(tmp_path / "new" / "demo"), "--downsample", "8", "-q", *FAST]) == 0
    assert {"depth.npy", "depth.png", "metrics.json"} <= set(os.listdir(tmp_path / "new" / "demo"))


def test_success_replaces_old_outputs_and_leaves_no_temporary_file(files, capsys):
    argv = _old_outputs(files)
    rc = main([str(a) for a in argv])
    assert rc == 0, capsys.readouterr().err
    expected = _expected(files)
    np.testing.assert_allclose(np.load(files / "o.npy"), expected, atol=1e-12)
    np.testing.assert_allclose(np.load(files / "d" / "depth.npy"), expected, atol=1e-12)
    np.testing.assert_array_equal(iio.imread(files / "d" / "depth.png"), np.rint(expected * 1000).astype(np.uint16))
    assert json.loads((files / "m.json").read_text()) == json.loads((files / "d" / "metrics.json").read_text())
    assert not [p for p in files.rglob(".*")]  # no temporary, probe or backup file


def test_batch_csv_directory_refused(tmp_path, capsys):
    _batch_folder(tmp_path)
    (tmp_path / "m.csv").mkdir()
    _run_refused(["--batch", tmp_path, "--csv", tmp_path / "m.csv", "--workers", "1", "-q", *FAST], capsys,
                 tmp_path, f"--csv '{tmp_path / 'm.csv'}' is a directory")


def test_batch_outdir_missing_refused(tmp_path, capsys):
    _batch_folder(tmp_path)
    _run_refused(["--batch", tmp_path, "--csv", tmp_path / "m.csv", "--outdir", tmp_path / "absent", "--workers",
                  "1", "-q", *FAST], capsys, tmp_path, "--outdir", "does not exist")


def test_demo_outdir_that_is_a_file_is_refused(tmp_path, capsys):
    (tmp_path / "plain").write_text("a file, not a folder")
    _run_refused(["--outdir", tmp_path / "plain" / "demo", "--downsample", "8", "-q", *FAST], capsys, tmp_path,
                 "--outdir", f"'{tmp_path / 'plain'}' is not a folder")


def test_commit_removes_everything_when_a_writer_raises(tmp_path):
    from sparsedepth.cli.outputs import Named, commit

    (tmp_path / "old.txt").write_bytes(b"old")
    targets = [Named("--a", str(tmp_path / "old.txt"), tmp_path / "old.txt"),
               Named("--b", str(tmp_path / "new" / "b.txt"), tmp_path / "new" / "b.txt", create_parent=True)]

    def broken(tmp):
        tmp.write_bytes(b"half")
        raise RuntimeError("encoder failed")

    with pytest.raises(RuntimeError, match="encoder failed"):
        commit([(targets[0], lambda tmp: tmp.write_bytes(b"new")), (targets[1], broken)])
    assert _snapshot(tmp_path) == {"old.txt": b"old"}  # no new folder, no temporary file
    commit([(targets[0], lambda tmp: tmp.write_bytes(b"new")), (targets[1], lambda tmp: tmp.write_bytes(b"b"))])
    assert _snapshot(tmp_path) == {"new": None, "new/b.txt": b"b", "old.txt": b"new"}
