"""Batches: resuming, settings fingerprint, option checks, layouts, killed workers, signals (real subprocesses)."""

import contextlib
import csv
import errno
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import h5py
import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd
import sparsedepth.batch.csvlog
from conftest import REPO
from conftest import make_scene as _scene
from sparsedepth.batch import (
    BatchOptions,
    NYUH5Frame,
    find_frame_pairs,
    find_frames,
    nyu_h5_frames,
    run_batch,
    settings_path,
)
from sparsedepth.complete import main

FAST = sd.Weights(gamma=0.0)  # quadratic objective: the direct solver is exact and fast
FAST_FLAGS = ["--gamma", "0", "--solver", "direct"]
FLAGS_WEIGHTS = sd.DEFAULT_SCHEDULE.replace(gamma=0.0)  # what FAST_FLAGS select on the command line


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _lines(path):
    with open(path, newline="") as fh:
        return fh.read().split("\r\n")


def _write_frame(folder, key, seed=0, shape=(40, 60)):
    image, depth = _scene(shape=shape, seed=seed)
    iio.imwrite(folder / f"rgb_{key}.png", image)
    sd.write_depth(folder / f"depth_{key}.png", depth, scale=1000)
    return image, depth


def _expected(folder, key, position, seed=7):
    """The completed depth of one frame, computed directly from its files."""
    image = sd.read_image(folder / f"rgb_{key}.png")
    depth = sd.read_depth(folder / f"depth_{key}.png", scale=1000)
    mask = sd.sample_mask(depth, fraction=0.1, seed=np.random.default_rng([seed, position]))
    return sd.complete_depth(image, np.where(mask, depth, np.nan), mask, weights=FAST, solver="direct").depth


def _temporaries(folder):
    return [p.name for p in Path(folder).rglob("*") if ".tmp" in p.name]


@pytest.fixture
def batch(tmp_path):
    frames = tmp_path / "frames"
    out = tmp_path / "out"
    frames.mkdir()
    out.mkdir()
    for i, key in enumerate("abc"):
        _write_frame(frames, key, seed=i)
    options = BatchOptions(keep_fraction=0.1, seed=7, weights=FAST, solver="direct", depth_scale="mm",
                           out_dir=str(out))
    return frames, out, options, tmp_path / "m.csv"


def _run(frames, csv_path, options, calls=None, **kwargs):
    with ThreadPoolExecutor(max_workers=2) as pool:
        return run_batch(find_frames(frames), csv_path, options=options, executor=pool,
                         progress=None if calls is None else lambda d, t, row: calls.append((d, t, row["name"])),
                         **kwargs)


# ----------------------------------------------------------------------------- resume
def test_rerun_runs_only_failed_frames_and_keeps_ok_rows_byte_for_byte(batch):
    frames, out, options, csv_path = batch
    good_b = (frames / "depth_b.png").read_bytes()
    (frames / "depth_b.png").write_bytes(b"\x89PNG\r\n\x1a\n corrupt")
    first = _run(frames, csv_path, options)
    assert (first.succeeded, first.failed, first.skipped) == (2, 1, 0)
    before = _lines(csv_path)
    stats = {k: os.stat(out / f"{k}.npy") for k in "ac"}

    (frames / "depth_b.png").write_bytes(good_b)  # repaired: the rerun runs b alone
    calls = []
    second = _run(frames, csv_path, options, calls)
    assert calls == [(1, 1, "b")]
    assert (second.succeeded, second.failed, second.skipped) == (3, 0, 2)
    rows = _rows(csv_path)
    assert sorted(r["name"] for r in rows) == ["a", "b", "c"]  # the error row of b is replaced
    assert all(r["status"] == "ok" for r in rows)
    after = _lines(csv_path)
    for line in before[1:-1]:
        if ",a," in line or ",c," in line:
            assert line in after  # the ok rows, byte for byte
    for key in "ac":
        now = os.stat(out / f"{key}.npy")
        assert (now.st_ino, now.st_mtime_ns) == (stats[key].st_ino, stats[key].st_mtime_ns)  # not rewritten
    np.testing.assert_allclose(np.load(out / "b.npy"), _expected(frames, "b", 1), atol=1e-12)
    assert second.rmse_ratio == pytest.approx(
        np.mean([float(r["rmse"]) / float(r["nn_rmse"]) for r in rows]), rel=1e-12)

    content, mtime = csv_path.read_bytes(), os.stat(csv_path).st_mtime_ns
    calls.clear()
    third = _run(frames, csv_path, options, calls)  # nothing to do: nothing runs, nothing is rewritten
    assert calls == [] and third.skipped == 3 and third.succeeded == 3
    assert csv_path.read_bytes() == content and os.stat(csv_path).st_mtime_ns == mtime


def test_output_without_ok_row_or_ok_row_without_output_is_recomputed(batch):
    frames, out, options, csv_path = batch
    np.save(out / "b.npy", np.zeros((2, 2)))  # an output with no row: a stale file of another run
    (out / ".b.npy.0123456789ab.tmp.npy").write_bytes(b"partial")  # a temporary left by a killed worker
    _run(frames, csv_path, options)
    np.testing.assert_allclose(np.load(out / "b.npy"), _expected(frames, "b", 1), atol=1e-12)
    assert _temporaries(out) == []
    (out / "c.npy").unlink()  # an ok row whose output is gone is not done
    calls = []
    _run(frames, csv_path, options, calls)
    assert [c[2] for c in calls] == ["c"]
    assert sorted(r["name"] for r in _rows(csv_path)) == ["a", "b", "c"]
    np.testing.assert_allclose(np.load(out / "c.npy"), _expected(frames, "c", 2), atol=1e-12)


def test_other_settings_are_refused_unless_overwrite(batch):
    frames, out, options, csv_path = batch
    _run(frames, csv_path, options)
    content = csv_path.read_bytes()
    other = BatchOptions(keep_fraction=0.1, seed=8, weights=FAST, solver="direct", depth_scale="mm",
                         out_dir=str(out))
    with pytest.raises(ValueError, match="other settings.*seed.*overwrite"):
        _run(frames, csv_path, other)
    (frames / "rgb_d.png").write_bytes((frames / "rgb_a.png").read_bytes())  # one frame more
    (frames / "depth_d.png").write_bytes((frames / "depth_a.png").read_bytes())
    with pytest.raises(ValueError, match="frame list"):
        _run(frames, csv_path, options)
    with pytest.raises(ValueError, match="exists"):
        _run(frames, csv_path, options, resume=False)
    assert csv_path.read_bytes() == content  # refused runs change nothing
    calls = []
    summary = _run(frames, csv_path, other, calls, overwrite=True)
    assert sorted(c[2] for c in calls) == ["a", "b", "c", "d"] and summary.skipped == 0
    assert sorted(r["name"] for r in _rows(csv_path)) == ["a", "b", "c", "d"]
    assert '"seed": 8' in settings_path(csv_path).read_text()


def test_csv_without_settings_is_refused(batch):
    frames, _, options, csv_path = batch
    _run(frames, csv_path, options)
    settings_path(csv_path).unlink()
    with pytest.raises(ValueError, match="no settings file"):
        _run(frames, csv_path, options)


def test_interrupted_batch_keeps_rows_and_resumes_to_one_row_per_frame(batch):
    frames, out, options, csv_path = batch

    def stop(done, total, row):
        if done == 1:
            raise KeyboardInterrupt

    with ThreadPoolExecutor(max_workers=1) as pool, pytest.raises(KeyboardInterrupt):
        run_batch(find_frames(frames), csv_path, options=options, executor=pool, max_in_flight=1, progress=stop)
    assert len(_rows(csv_path)) == 1
    _run(frames, csv_path, options)
    rows = _rows(csv_path)
    assert sorted(r["name"] for r in rows) == ["a", "b", "c"] and all(r["status"] == "ok" for r in rows)
    assert _temporaries(out) == [] and sorted(p.name for p in out.iterdir()) == ["a.npy", "b.npy", "c.npy"]


def test_second_batch_on_the_same_csv_is_refused_while_the_first_runs(batch):
    # a second batch used to compact (replace) the CSV under the first one, whose later rows then went to the
    # replaced file: the first reported every frame done while the CSV lacked their rows
    frames, out, options, csv_path = batch
    (frames / "depth_b.png").write_bytes(b"\x89PNG\r\n\x1a\n corrupt")
    _run(frames, csv_path, options)  # b fails: its rerun appends a second row, so a start would compact
    (frames / "depth_b.png").write_bytes((frames / "depth_a.png").read_bytes())
    (out / "c.npy").unlink()  # c runs again too
    refused = []

    def second_batch(done, total, row):
        before = csv_path.read_bytes()
        with pytest.raises(ValueError, match="another batch"):
            _run(frames, csv_path, options)
        assert csv_path.read_bytes() == before  # the refused batch changed nothing
        refused.append(row["name"])

    with ThreadPoolExecutor(max_workers=1) as pool:
        summary = run_batch(find_frames(frames), csv_path, options=options, executor=pool, max_in_flight=1,
                            progress=second_batch)
    assert refused == ["b", "c"] and summary.succeeded == 3
    rows = _rows(csv_path)
    assert sorted(r["name"] for r in rows) == ["a", "b", "c"] and all(r["status"] == "ok" for r in rows)
    assert not sparsedepth.batch.csvlog.lock_path(csv_path).exists()
    calls = []
    _run(frames, csv_path, options, calls)  # the lock ended with the batch
    assert calls == []


_KILLED_DRIVER = """
import multiprocessing, os, pathlib, sys, time
from sparsedepth.batch.csvlog import locked
with locked(pathlib.Path(sys.argv[1])):
    worker = multiprocessing.get_context("fork").Process(target=time.sleep, args=(60,))
    worker.start()  # forked while the lock is held, as the default pool's workers are
    print(worker.pid, flush=True)
    os._exit(0)  # killed: no clean-up, the lock file stays and the worker lives on
"""

_PROBE = """
import pathlib, sys
from sparsedepth.batch.csvlog import locked
try:
    with locked(pathlib.Path(sys.argv[1])):
        pass
except ValueError as exc:
    print(exc)
    sys.exit(3)
"""


@pytest.mark.skipif(sparsedepth.batch.csvlog.fcntl is None or "fork" not in multiprocessing.get_all_start_methods(),
                    reason="POSIX file locks and fork")
def test_batch_lock_holds_across_processes_but_not_in_workers_of_a_killed_driver(tmp_path):
    csv_path = tmp_path / "m.csv"
    env = {**os.environ, "PYTHONPATH": str(REPO)}

    def probe():
        return subprocess.run([sys.executable, "-c", _PROBE, str(csv_path)], env=env, capture_output=True,
                              text=True, timeout=120)

    with sparsedepth.batch.csvlog.locked(csv_path):
        refused = probe()
    assert refused.returncode == 3 and "another batch" in refused.stdout, refused.stderr
    with open(tmp_path / "pid", "w") as out:  # a file, not a pipe the orphan would keep open
        subprocess.run([sys.executable, "-c", _KILLED_DRIVER, str(csv_path)], env=env, stdout=out, timeout=120)
    orphan = int((tmp_path / "pid").read_text())
    try:
        assert sparsedepth.batch.csvlog.lock_path(csv_path).exists()
        os.kill(orphan, 0)  # the worker lives on
        again = probe()  # the orphaned worker must not keep the next run out
        assert again.returncode == 0, again.stdout + again.stderr
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(orphan, signal.SIGKILL)


def test_torn_last_line_of_a_killed_driver_is_dropped(batch):
    frames, _, options, csv_path = batch
    _run(frames, csv_path, options)
    with open(csv_path, "a", newline="") as fh:
        fh.write("3,zz,ok,40")  # half a row, no line end
    calls = []
    _run(frames, csv_path, options, calls)
    assert calls == [] and sorted(r["name"] for r in _rows(csv_path)) == ["a", "b", "c"]


def test_full_disk_while_writing_the_csv_loses_nothing(batch, monkeypatch):
    frames, out, options, csv_path = batch
    real = sparsedepth.batch.csvlog.csv_line
    lines = []

    def full_after_one(row):
        if lines:
            raise OSError(errno.ENOSPC, "No space left on device")
        lines.append(row["name"])
        return real(row)

    monkeypatch.setattr(sparsedepth.batch.csvlog, "csv_line", full_after_one)
    with pytest.raises(OSError, match="No space"):
        _run(frames, csv_path, options)
    assert [r["name"] for r in _rows(csv_path)] == lines  # the row written before is kept
    assert _temporaries(out) == [] and _temporaries(csv_path.parent) == []
    monkeypatch.setattr(sparsedepth.batch.csvlog, "csv_line", real)
    calls = []
    summary = _run(frames, csv_path, options, calls)
    assert sorted(c[2] for c in calls) == sorted(set("abc") - set(lines)) and summary.skipped == 1
    assert sorted(r["name"] for r in _rows(csv_path)) == ["a", "b", "c"]


def test_killed_worker_is_replaced_and_its_frames_run_again(tmp_path):
    for i in range(6):
        _write_frame(tmp_path, f"{i}", seed=i)
    options = BatchOptions(keep_fraction=0.1, seed=7, weights=FAST, solver="direct", depth_scale="mm")
    killed = []

    def kill_workers(done, total, row):
        if done == 1:
            for child in multiprocessing.active_children():
                os.kill(child.pid, signal.SIGKILL)
                killed.append(child.pid)

    summary = run_batch(find_frames(tmp_path), tmp_path / "m.csv", options=options, max_workers=1,
                        max_in_flight=2, progress=kill_workers)
    assert killed
    rows = _rows(tmp_path / "m.csv")
    assert sorted(r["name"] for r in rows) == [str(i) for i in range(6)]  # exactly one row each
    assert all(r["status"] == "ok" for r in rows) and summary.failed == 0
    for row in rows:  # the frames run again give the same result as a direct computation
        position = int(row["position"])
        depth = sd.read_depth(tmp_path / f"depth_{position}.png", scale=1000)
        mask = sd.sample_mask(depth, fraction=0.1, seed=np.random.default_rng([7, position]))
        assert int(row["observed"]) == mask.sum()


# ----------------------------------------------------------------------------- options
@pytest.mark.parametrize(
    "kwargs, option, kind",
    [
        ({"keep_fraction": 2}, "keep_fraction", ValueError),
        ({"keep_fraction": 0.0}, "keep_fraction", ValueError),
        ({"keep_fraction": "0.1"}, "keep_fraction", TypeError),
        ({"keep_count": 0}, "keep_count", ValueError),
        ({"keep_count": 2.5}, "keep_count", ValueError),
        ({"keep_fraction": 0.1, "keep_count": 5}, "keep_count", ValueError),
        ({"task": "fill", "keep_fraction": 0.1}, "keep_fraction", ValueError),
        ({"seed": -1}, "seed", ValueError),
        ({"solver": "bogus"}, "solver", ValueError),
        ({"tol": -1}, "tol", ValueError),
        ({"tol": float("nan")}, "tol", ValueError),
        ({"tol": float("inf")}, "tol", ValueError),
        ({"max_iter": 0}, "max_iter", ValueError),
        ({"max_iter": 1.5}, "max_iter", ValueError),
        ({"weights": {"gamma": 0}}, "weights", TypeError),
        ({"depth_scale": "furlong"}, "depth_scale", ValueError),
        ({"depth_scale": -3}, "depth_scale", ValueError),
        ({"out_scale": 0}, "out_scale", ValueError),
        ({"out_format": ".jpg"}, "out_format", ValueError),
        ({"downsample": 0}, "downsample", ValueError),
        ({"task": "guess"}, "task", ValueError),
        ({"image_shift": "left"}, "image_shift", ValueError),
        ({"image_shift": (1, 0.5)}, "image_shift", TypeError),
        ({"image_shift": (1, 2, 3)}, "image_shift", TypeError),
        ({"image_shift": 2}, "image_shift", TypeError),
    ],
)
def test_bad_batch_options_are_one_error(kwargs, option, kind):
    with pytest.raises(kind) as info:
        BatchOptions(**kwargs)
    assert info.value.option == option and option in str(info.value)


def test_good_batch_options_are_accepted(tmp_path):
    options = BatchOptions(keep_count=10, tol=0.0, max_iter=3, depth_scale="kitti", out_scale=256.0,
                           solver="amg", out_dir=str(tmp_path), seed=np.int64(3))
    assert options.keep_count == 10 and options.solver == "amg"


@pytest.mark.parametrize("argv, flag", [(["--tol", "-1"], "--tol"), (["--tol", "nan"], "--tol")])
def test_cli_bad_batch_option_exits_2_before_any_frame(batch, capsys, argv, flag):
    frames, _, _, csv_path = batch
    rc = main(["--batch", str(frames), "--depth-scale", "mm", "--keep-fraction", "0.1", "--csv", str(csv_path),
               "--gamma", "0", *argv])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and flag in err, err
    assert not csv_path.exists() and not settings_path(csv_path).exists()


def test_cli_rerun_with_other_settings_exits_2_then_overwrite(batch, capsys):
    frames, _, _, csv_path = batch
    argv = ["--batch", str(frames), "--depth-scale", "mm", "--keep-fraction", "0.1", "--csv", str(csv_path),
            "--workers", "1", "-q", *FAST_FLAGS]
    assert main(argv) == 0
    capsys.readouterr()
    assert main(argv) == 0
    assert "0 failed, 3 skipped" in capsys.readouterr().out
    assert main([*argv, "--seed", "4"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--overwrite" in err and "seed" in err
    assert main([*argv, "--seed", "4", "--overwrite"]) == 0
    out = capsys.readouterr().out
    assert "3 of 3 frames done, 0 failed, 0 skipped" in out and "nearest-neighbour RMSE" in out


# ----------------------------------------------------------------------------- layouts
def test_prefix_matching_nothing_lists_the_files_found(batch, capsys):
    frames, _, _, csv_path = batch
    with pytest.raises(ValueError, match=r"depth_a\.png.*depth_prefix.*--depth-prefix"):
        find_frames(frames, depth_prefix="sync_depth_")
    with pytest.raises(ValueError, match=r"rgb_a\.png.*--image-prefix"):
        find_frames(frames, image_prefix="im_")
    rc = main(["--batch", str(frames), "--depth-prefix", "sync_depth_", "--depth-scale", "mm", "--keep-fraction",
               "0.1", "--csv", str(csv_path)])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "depth_a.png" in err and "--depth-prefix" in err
    assert not csv_path.exists()


def test_kitti_style_folder_pair(tmp_path, capsys):
    images, depths = tmp_path / "image_02", tmp_path / "groundtruth"
    images.mkdir()
    depths.mkdir()
    for i, key in enumerate(["0000000005", "0000000050"]):
        image, depth = _scene(seed=i)
        iio.imwrite(images / f"{key}.png", image)
        sd.write_depth(depths / f"{key}.png", depth, scale=256)
    iio.imwrite(images / "0000000099.png", image)  # no depth of that name: a failed frame
    frames = find_frame_pairs(images, depths)
    assert [(f.name, f.depth) for f in frames] == [
        ("0000000005", str(depths / "0000000005.png")), ("0000000050", str(depths / "0000000050.png")),
        ("0000000099", None)]
    with pytest.raises(ValueError, match="0000000005.png"):
        find_frame_pairs(images, tmp_path)  # a depth folder with nothing of those names
    rc = main(["--batch", str(images), "--batch-depths", str(depths), "--depth-scale", "kitti", "--keep-fraction",
               "0.1", "--csv", str(tmp_path / "k.csv"), "--workers", "1", "-q", *FAST_FLAGS])
    assert rc == 1  # 0000000099 failed
    rows = {r["name"]: r for r in _rows(tmp_path / "k.csv")}
    assert rows["0000000005"]["status"] == rows["0000000050"]["status"] == "ok"
    assert rows["0000000099"]["status"] == "error"
    image = sd.read_image(images / "0000000050.png")
    depth = sd.read_depth(depths / "0000000050.png", scale=256)
    mask = sd.sample_mask(depth, fraction=0.1, seed=np.random.default_rng([0, 1]))
    completed = sd.complete_depth(image, np.where(mask, depth, np.nan), mask, weights=FLAGS_WEIGHTS,
                                  solver="direct").depth
    assert float(rows["0000000050"]["rmse"]) == pytest.approx(sd.depth_metrics(completed, depth, mask=~mask).rmse,
                                                              rel=1e-5)


def _write_h5(path, image, depth):
    with h5py.File(path, "w") as fh:
        fh.create_dataset("rgb", data=np.transpose(image, (2, 0, 1)))
        fh.create_dataset("depth", data=depth.astype(np.float32))


def test_folder_of_nyu_h5_files(tmp_path, capsys):
    root = tmp_path / "val"
    (root / "official").mkdir(parents=True)
    scenes = {}
    for i in range(2):
        scenes[i] = _scene(seed=i)
        _write_h5(root / "official" / f"0000{i}.h5", *scenes[i])
    frames = nyu_h5_frames(root)
    assert frames == [NYUH5Frame("official_00000", str(root / "official" / "00000.h5")),
                      NYUH5Frame("official_00001", str(root / "official" / "00001.h5"))]
    with pytest.raises(ValueError, match="no .h5"):
        nyu_h5_frames(_empty(tmp_path))
    rc = main(["--batch", str(root), "--keep-fraction", "0.1", "--csv", str(tmp_path / "h.csv"), "--workers", "1",
               "-q", *FAST_FLAGS])
    assert rc == 0, capsys.readouterr().err
    rows = {r["name"]: r for r in _rows(tmp_path / "h.csv")}
    image, depth = scenes[1]
    depth32 = depth.astype(np.float32).astype(float)
    mask = sd.sample_mask(depth32, fraction=0.1, seed=np.random.default_rng([0, 1]))
    completed = sd.complete_depth(image, np.where(mask, depth32, np.nan), mask, weights=FLAGS_WEIGHTS,
                                  solver="direct").depth
    assert float(rows["official_00001"]["rmse"]) == pytest.approx(
        sd.depth_metrics(completed, depth32, mask=~mask).rmse, rel=1e-5)


def _empty(tmp_path):
    folder = tmp_path / "empty"
    folder.mkdir()
    return folder


def test_frames_are_sent_with_absolute_paths(tmp_path, monkeypatch):
    _write_frame(tmp_path, "a")
    monkeypatch.chdir(tmp_path)
    seen = []

    class Recording(ThreadPoolExecutor):
        def submit(self, fn, *args, **kwargs):
            seen.append(args)
            return super().submit(fn, *args, **kwargs)

    (tmp_path / "out").mkdir()
    options = BatchOptions(keep_fraction=0.1, weights=FAST, solver="direct", depth_scale="mm", out_dir="out")
    with Recording(max_workers=1) as pool:
        run_batch(find_frames("."), "m.csv", options=options, executor=pool)
    (position, source, sent), = seen
    assert os.path.isabs(source.image) and os.path.isabs(source.depth) and os.path.isabs(sent.out_dir)


# ----------------------------------------------------------------------------- signals, real processes
def _descendants(pid):
    found, todo = [], [pid]
    while todo:
        parent = todo.pop()
        for children in Path(f"/proc/{parent}/task").glob("*/children"):
            with open(children) as fh:
                for child in fh.read().split():
                    found.append(int(child))
                    todo.append(int(child))
    return found


def _alive(pid):
    try:
        with open(f"/proc/{pid}/stat") as fh:
            state = fh.read().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs /proc to see the worker processes")
@pytest.mark.parametrize("signum, code, group", [(signal.SIGTERM, 143, False), (signal.SIGINT, 130, True)])
def test_signal_stops_workers_keeps_rows_and_rerun_completes(tmp_path, signum, code, group):
    # group: the signal goes to the whole process group, as Ctrl-C in a terminal does
    frames, out = tmp_path / "frames", tmp_path / "out"
    frames.mkdir()
    out.mkdir()
    n = 4  # two rounds of the two workers: the signal lands in the second, the rerun completes it
    for i in range(n):
        _write_frame(frames, f"{i:02d}", seed=i, shape=(60, 80))
    csv_path = tmp_path / "m.csv"
    # Adam with tol 0 runs all its iterations: each frame takes a while (about 0.5 s here), so the signal lands mid-batch
    argv = [sys.executable, "-m", "sparsedepth.complete", "--batch", str(frames), "--depth-scale", "mm",
            "--keep-fraction", "0.05", "--solver", "adam", "--tol", "0", "--max-iter", "50", "--csv", str(csv_path),
            "--outdir", str(out), "--workers", "2", "-q"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    log = tmp_path / "stderr.txt"
    workers = set()
    with open(log, "wb") as stderr:  # not a pipe: a worker left alive must not block the test
        proc = subprocess.Popen(argv, cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=stderr,
                                start_new_session=group)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            workers.update(_descendants(proc.pid))
            if csv_path.exists() and len(_lines(csv_path)) > 2:  # header, one row, the empty tail
                break
            time.sleep(0.02)
        workers.update(_descendants(proc.pid))
        assert proc.poll() is None, "the batch finished before the signal: make the frames slower"
        if group:
            os.killpg(proc.pid, signum)
        else:
            proc.send_signal(signum)
        proc.wait(timeout=60)
        assert proc.returncode == code, log.read_text()
        message = log.read_text()
        assert message.count("\n") == 1 and "run the same command to resume" in message, message  # no traceback
        assert workers, "no worker process was seen"
        deadline = time.monotonic() + 10
        while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not [pid for pid in workers if _alive(pid)], "worker processes outlived the batch"
    finally:  # whatever failed, leave no process behind
        for pid in [proc.pid, *workers]:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
        proc.wait(timeout=60)
    rows = _rows(csv_path)
    assert 1 <= len(rows) < n and len({r["name"] for r in rows}) == len(rows)
    assert all(r["status"] == "ok" and Path(r["output"]).is_file() for r in rows)
    assert _temporaries(out) == [] and _temporaries(tmp_path) == []

    rerun = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr.decode()
    assert f"{len(rows)} skipped" in rerun.stdout.decode()
    final = _rows(csv_path)
    assert sorted(r["name"] for r in final) == [f"{i:02d}" for i in range(n)]
    for row in rows:  # the rows of the first run are kept as they were
        assert row in final
    assert sorted(p.name for p in out.iterdir()) == [f"{i:02d}.npy" for i in range(n)]
    assert _temporaries(tmp_path) == []


def test_real_nyu_folder_prefix_error_names_the_files(shared_data, tmp_path):
    folder = shared_data / "nyu_metric3d"
    with pytest.raises(ValueError, match=r"sync_depth_00000\.png.*--depth-prefix"):
        find_frames(folder)  # the default depth_ prefix matches nothing in the BTS layout
    frames = find_frames(folder, depth_prefix="sync_depth_")
    assert [f.name for f in frames] == ["00000", "00050", "00100"]
    # one real frame at 1/8 resolution, run twice: the second run skips it and leaves the CSV as it was
    options = BatchOptions(keep_fraction=0.05, depth_scale="mm", downsample=8, weights=FAST, solver="direct")
    with ThreadPoolExecutor(1) as pool:
        first = run_batch(frames[:1], tmp_path / "r.csv", options=options, executor=pool)
        content = (tmp_path / "r.csv").read_bytes()
        second = run_batch(frames[:1], tmp_path / "r.csv", options=options, executor=pool)
    assert (first.succeeded, second.skipped) == (1, 1) and (tmp_path / "r.csv").read_bytes() == content
    (row,) = _rows(tmp_path / "r.csv")
    assert second.rmse_ratio == pytest.approx(float(row["rmse"]) / float(row["nn_rmse"]), rel=1e-12)


@pytest.mark.parametrize("argv, expect", [
    (["--overwrite"], "--overwrite"),
    (["--batch-depths", "x"], "--batch-depths"),
    (["--batch", "{tmp}", "--batch-truths", "{tmp}", "--csv", "{tmp}/m.csv"], "--batch-truths goes with"),
    (["--nyu-mat", "{tmp}/n.mat", "--batch-depths", "{tmp}", "--fill-holes", "--csv", "{tmp}/m.csv"],
     "pairs with --batch"),
])
def test_cli_batch_only_flags(tmp_path, capsys, argv, expect):
    rc = main([a.format(tmp=tmp_path) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and expect in err, err
    assert list(tmp_path.iterdir()) == []


def test_folder_pair_with_truth_folder(tmp_path):
    for sub in ("img", "raw", "gt"):
        (tmp_path / sub).mkdir()
    image, depth = _scene()
    iio.imwrite(tmp_path / "img" / "f1.png", image)
    sd.write_depth(tmp_path / "raw" / "f1.png", depth, scale=1000)
    sd.write_depth(tmp_path / "gt" / "f1.npy", depth)
    (frame,) = find_frame_pairs(tmp_path / "img", tmp_path / "raw", truth_folder=tmp_path / "gt")
    assert frame.truth == str(tmp_path / "gt" / "f1.npy") and frame.name == "f1"


@pytest.mark.parametrize("folder, flag", [("raw", "--batch-depths"), ("gt", "--batch-truths"), ("img", "--batch")])
def test_batch_output_onto_a_paired_input_names_its_folder_flag(tmp_path, capsys, folder, flag):
    for sub in ("img", "raw", "gt"):
        (tmp_path / sub).mkdir()
    image, depth = _scene()
    iio.imwrite(tmp_path / "img" / "f1.png", image)
    sd.write_depth(tmp_path / "raw" / "f1.png", depth, scale=1000)
    sd.write_depth(tmp_path / "gt" / "f1.png", depth, scale=1000)
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    rc = main(["--batch", str(tmp_path / "img"), "--batch-depths", str(tmp_path / "raw"), "--batch-truths",
               str(tmp_path / "gt"), "--outdir", str(tmp_path / folder), "--out-format", "png",
               "--csv", str(tmp_path / "m.csv"), "--workers", "1", "-q", *FAST_FLAGS])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1, err
    assert f"is the same file as {flag} '{tmp_path / folder}'" in err, err
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before
