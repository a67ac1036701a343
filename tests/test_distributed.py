"""Batches on a Dask cluster: in-process LocalCluster, the CLI flags, and real scheduler/worker processes."""

import csv
import dataclasses
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd
from conftest import REPO, make_scene
from sparsedepth.batch import BatchOptions, FileFrame, NYUFrame, evaluate_frame, find_frames, run_batch

FAST = sd.Weights(gamma=0.0)


def _read_csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _write_frames(folder, count, shape=(40, 60)):
    folder.mkdir()
    for i in range(count):
        image, depth = make_scene(shape, seed=i)
        iio.imwrite(folder / f"rgb_{i:02d}.png", image)
        np.save(folder / f"depth_{i:02d}.npy", depth)
    return folder


# ----------------------------------------------------------------------------- no dask needed
def test_importing_sparsedepth_never_imports_dask():
    code = ("import sys, sparsedepth, sparsedepth.complete, sparsedepth.batch.distributed; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_absolute_frames_resolve_in_the_current_folder(tmp_path, monkeypatch):
    from sparsedepth.batch.distributed import absolute_frames

    monkeypatch.chdir(tmp_path)
    given = [FileFrame("a", "rgb_a.png", "depth_a.npy", "sub/truth_a.npy"), FileFrame("b", "/x/rgb_b.png", None),
             NYUFrame("nyu_0001", "nyu.mat", 1)]
    out = absolute_frames(given)
    assert out[0] == FileFrame("a", str(tmp_path / "rgb_a.png"), str(tmp_path / "depth_a.npy"),
                               str(tmp_path / "sub" / "truth_a.npy"))
    assert out[1] == FileFrame("b", "/x/rgb_b.png", None)
    assert out[2] == NYUFrame("nyu_0001", str(tmp_path / "nyu.mat"), 1)
    assert given[0].image == "rgb_a.png"  # inputs are not modified


def test_remove_temporaries_removes_only_temporaries_of_the_batch(tmp_path):
    from sparsedepth.batch import BatchOptions
    from sparsedepth.batch.worker import remove_temporaries

    out, sigma = tmp_path / "out", tmp_path / "sigma"
    (out / "cam1").mkdir(parents=True)
    sigma.mkdir()
    stale = [out / ".f1.npy.0123456789ab.tmp.npy", out / ".f2.npy.abcdefabcdef.tmp.npy",
             out / "cam1" / ".f4.npy.00000000abcd.tmp.npy",  # a view's sub-folder
             sigma / ".f1.npy.0123456789ab.tmp.npy"]  # the uncertainty folder
    kept = [out / "f1.npy", out / ".other.npy.0123456789ab.tmp.npy",  # not a frame of the batch
            out / ".f1.npy.0123456789ab.tmp.png",  # another format
            out / ".f1.npy.xyz.tmp.npy", out / "notes.txt", out / "cam1" / ".f1.npy.0123456789ab.tmp.npy"]
    for path in stale + kept:
        path.write_bytes(b"x")
    options = BatchOptions(out_dir=str(out), out_format=".npy", uncertainty_dir=str(sigma))
    removed = remove_temporaries(["f1", "f2", "f3", "cam1/f4"], options)
    assert sorted(removed) == sorted(stale)
    assert not any(p.exists() for p in stale) and all(p.exists() for p in kept)
    assert remove_temporaries(["f1"], BatchOptions()) == []  # no output folder: nothing to do


def test_connect_checks_its_arguments(tmp_path, monkeypatch):
    from sparsedepth.batch.distributed import connect

    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS", raising=False)
    with pytest.raises(ValueError, match="DASK_SCHEDULER_ADDRESS"):
        connect()
    with pytest.raises(ValueError, match="not both"):
        connect("tcp://127.0.0.1:1", scheduler_file=tmp_path / "s.json")
    with pytest.raises(ValueError, match="timeout"):
        connect("tcp://127.0.0.1:1", timeout=0)
    with pytest.raises(FileNotFoundError, match="dask scheduler --scheduler-file"):
        connect(scheduler_file=tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(ValueError, match="'address'"):
        connect(scheduler_file=tmp_path / "bad.json")


@pytest.mark.parametrize("timeout", [np.int64(3), np.float32(2.5), 7])
def test_connect_takes_a_numpy_timeout_like_a_python_number(tmp_path, timeout):
    # the timeout is checked first; a positive one of any real type reaches the scheduler-file check
    from sparsedepth.batch.distributed import connect

    with pytest.raises(FileNotFoundError, match="dask scheduler --scheduler-file"):
        connect(scheduler_file=tmp_path / "missing.json", timeout=timeout)
    for bad in (True, np.bool_(True), "5", np.float64(-1.0), np.int64(0), float("nan")):
        with pytest.raises(ValueError, match="timeout must be a positive number of seconds"):
            connect(scheduler_file=tmp_path / "missing.json", timeout=bad)


def test_cli_cluster_options_are_checked(tmp_path, capsys):
    from sparsedepth.complete import main

    frames = _write_frames(tmp_path / "frames", 1)
    assert main(["--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "need --batch/--nyu-mat" in capsys.readouterr().err
    assert main(["--batch", str(frames), "--csv", str(tmp_path / "a.csv"), "--keep-fraction", "0.1",
                 "--scheduler", "tcp://127.0.0.1:1", "--workers", "2"]) == 2
    assert "--workers sizes the local process pool" in capsys.readouterr().err
    assert main(["--batch", str(frames), "--csv", str(tmp_path / "a.csv"), "--keep-fraction", "0.1",
                 "--scheduler-file", str(tmp_path / "missing.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "missing.json" in err and "does not exist" in err


# ----------------------------------------------------------------------------- in-process cluster
distributed = pytest.importorskip("distributed", reason="dask.distributed is not installed: "
                                  "pip install -e '.[test,distributed]' (CI installs it)")


@pytest.fixture(scope="module")
def cluster():
    """An in-process LocalCluster on 127.0.0.1 (TCP, so the CLI can reach it): 2 workers, 1 thread each."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address=None, silence_logs=40) as local:
        yield local


def test_cluster_threads_sum_the_workers_threads():
    from sparsedepth.batch.distributed import cluster_threads

    with distributed.LocalCluster(n_workers=2, threads_per_worker=3, processes=False, dashboard_address=None,
                                  silence_logs=40) as local, distributed.Client(local, set_as_default=False) as c:
        assert cluster_threads(c) == 6


def test_cluster_batch_matches_the_local_batch(cluster, tmp_path, monkeypatch):
    from sparsedepth.batch.distributed import run_batch_on_cluster

    _write_frames(tmp_path / "frames", 5)
    (tmp_path / "out").mkdir()
    (tmp_path / "local").mkdir()
    monkeypatch.chdir(tmp_path)  # relative paths: made absolute by the driver
    frames = find_frames("frames")
    options = BatchOptions(keep_fraction=0.1, weights=FAST, solver="direct", out_dir="out")
    seen = []
    with distributed.Client(cluster, set_as_default=False) as client:
        summary = run_batch_on_cluster(frames, "cluster.csv", options=options, client=client,
                                       progress=lambda done, total, row: seen.append((done, total, row["name"])))
        assert client.status == "running"  # a given client is left open
    assert (summary.total, summary.succeeded, summary.failed) == (5, 5, 0)
    assert [d for d, _, _ in seen] == [1, 2, 3, 4, 5] and {t for _, t, _ in seen} == {5}
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(1) as pool:
        run_batch(frames, "local.csv", options=dataclasses.replace(options, out_dir="local"), executor=pool)
    rows = {r["name"]: r for r in _read_csv("cluster.csv")}
    local = {r["name"]: r for r in _read_csv("local.csv")}
    assert sorted(rows) == [f.name for f in frames]
    for name, row in rows.items():
        assert row["status"] == "ok"
        assert row["output"] == str(tmp_path / "out" / f"{name}.npy")
        for key in ("position", "observed", "scored", "rmse", "nn_rmse", "delta1"):
            assert row[key] == local[name][key]
        np.testing.assert_allclose(np.load(row["output"]), np.load(local[name]["output"]), rtol=0, atol=1e-12)
    # an independent computation of one frame: the sampling of frame i uses default_rng([seed, i])
    image, depth = make_scene((40, 60), seed=3)
    expected = evaluate_frame(image, depth, keep_fraction=0.1, seed=np.random.default_rng([0, 3]), weights=FAST,
                              solver="direct")
    np.testing.assert_allclose(np.load(rows["03"]["output"]), expected.depth, rtol=0, atol=1e-9)


def test_workers_with_malloc_trim_threshold_are_warned_about(cluster, tmp_path, monkeypatch):
    import warnings

    from sparsedepth.batch.distributed import run_batch_on_cluster

    frames = find_frames(_write_frames(tmp_path / "frames", 1))
    options = BatchOptions(keep_fraction=0.1, weights=FAST, solver="direct")
    with distributed.Client(cluster, set_as_default=False) as client:
        monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)  # in-process workers share this environment
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            assert run_batch_on_cluster(frames, tmp_path / "a.csv", options=options, client=client).succeeded == 1
        monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
        with pytest.warns(RuntimeWarning, match="MALLOC_TRIM_THRESHOLD_=65536"):
            assert run_batch_on_cluster(frames, tmp_path / "b.csv", options=options, client=client).succeeded == 1


def test_cli_batch_on_scheduler_address_file_and_environment(cluster, tmp_path, monkeypatch, capsys):
    from sparsedepth.complete import main

    frames = _write_frames(tmp_path / "frames", 3)
    address = cluster.scheduler_address
    assert address.startswith("tcp://127.0.0.1:")
    (tmp_path / "scheduler.json").write_text(json.dumps({"address": address}))
    common = ["--batch", str(frames), "--keep-fraction", "0.1", "--gamma", "0", "--solver", "direct", "-q"]
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS", raising=False)
    runs = {"address": ["--scheduler", address], "file": ["--scheduler-file", str(tmp_path / "scheduler.json")],
            "env": []}
    for name, extra in runs.items():
        if name == "env":
            monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", address)
        assert main([*common, "--csv", str(tmp_path / f"{name}.csv"), *extra]) == 0
        assert "3 of 3 frames done, 0 failed" in capsys.readouterr().out
    baseline = _read_csv(tmp_path / "address.csv")
    for name in ("file", "env"):
        assert sorted(r["rmse"] for r in _read_csv(tmp_path / f"{name}.csv")) == sorted(r["rmse"] for r in baseline)


def test_cli_unreachable_scheduler_is_one_line_and_exit_2(tmp_path, capsys):
    from sparsedepth.complete import main

    frames = _write_frames(tmp_path / "frames", 1)
    address = f"tcp://127.0.0.1:{_free_port()}"  # nothing listens there
    code = main(["--batch", str(frames), "--csv", str(tmp_path / "a.csv"), "--keep-fraction", "0.1",
                 "--scheduler", address, "--scheduler-timeout", "1"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and address in err and "no Dask scheduler answered" in err
    assert not (tmp_path / "a.csv").exists()


# ----------------------------------------------------------------------------- real processes
def _stop(processes):
    for proc in processes:
        if proc.poll() is None:
            proc.kill()
    for proc in processes:
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:  # pragma: no cover
            pass


def test_a_worker_killed_mid_frame_costs_a_retry_not_a_frame(tmp_path, monkeypatch):
    """Real `dask scheduler` and two `dask worker` processes; one is SIGKILLed while it runs a frame."""
    from sparsedepth.batch.distributed import run_batch_on_cluster

    folder = _write_frames(tmp_path / "frames", 4)
    out = tmp_path / "out"
    out.mkdir()
    scheduler_file = tmp_path / "scheduler.json"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]),
               OPENBLAS_NUM_THREADS="1", DASK_DISTRIBUTED__WORKER__DAEMON="False")
    env.pop("DASK_SCHEDULER_ADDRESS", None)
    dask_cli = [sys.executable, "-m", "dask"]
    processes = []
    try:
        processes.append(subprocess.Popen(
            [*dask_cli, "scheduler", "--host", "127.0.0.1", "--port", str(_free_port()), "--no-dashboard",
             "--scheduler-file", str(scheduler_file)],
            env=env, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        workers = {}
        for name in ("w0", "w1"):
            workers[name] = subprocess.Popen(
                [*dask_cli, "worker", "--scheduler-file", str(scheduler_file), "--host", "127.0.0.1",
                 "--nthreads", "1", "--no-nanny", "--no-dashboard", "--name", name],
                env=env, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            processes.append(workers[name])
        deadline = time.monotonic() + 120
        while not scheduler_file.exists():
            assert time.monotonic() < deadline, "the dask scheduler did not start"
            time.sleep(0.2)
        client = distributed.Client(scheduler_file=str(scheduler_file), set_as_default=False, timeout=60)
        try:
            client.wait_for_workers(2, timeout=120)
            killed = {}

            def worker_names(dask_scheduler=None):
                return {addr: ws.name for addr, ws in dask_scheduler.workers.items()}

            def suspicious(keys, dask_scheduler=None):  # local, so pickled by value for the scheduler
                """How many workers died while running each task (None: the task is already gone)."""
                return {key: getattr(dask_scheduler.tasks.get(key), "suspicious", None) for key in keys}

            def kill_a_busy_worker(done, total, row):
                if killed:
                    return
                names = client.run_on_scheduler(worker_names)  # scheduler_info() may be a cached copy
                deadline = time.monotonic() + 2
                while not (busy := [addr for addr, keys in client.processing().items() if keys]):
                    if time.monotonic() > deadline:  # the frames in flight ended before this call: try at the next
                        return
                    time.sleep(0.05)
                addr = busy[0]
                time.sleep(0.1)  # inside the frame (its solve takes about 0.4 s)
                keys = client.processing([addr])[addr]
                if not keys:
                    return
                workers[names[addr]].send_signal(signal.SIGKILL)
                killed.update(name=names[addr], keys=list(keys), done=done)
                while len(client.run_on_scheduler(worker_names)) > 1:  # the scheduler notices the lost worker
                    time.sleep(0.05)
                killed["suspicious"] = client.run_on_scheduler(suspicious, keys=killed["keys"])

            options = BatchOptions(keep_fraction=0.1, solver="adam", tol=1e-30, max_iter=60, out_dir=str(out))
            monkeypatch.chdir(tmp_path.parent)  # relative paths here do not exist in the workers' folder (tmp_path)
            relative = Path(tmp_path.name)
            options = dataclasses.replace(options, out_dir=str(relative / "out"))
            summary = run_batch_on_cluster(find_frames(relative / "frames"), relative / "batch.csv", options=options,
                                           client=client, progress=kill_a_busy_worker)
        finally:
            client.close()
        assert killed, "no worker was busy when a frame ended"
        # a task the dead worker was running was rescheduled: the scheduler counts it as run on a dead worker
        assert 1 in killed["suspicious"].values() and set(killed["suspicious"].values()) <= {0, 1}
        assert workers[killed["name"]].wait(timeout=30) == -signal.SIGKILL
        assert all(w.poll() is None for n, w in workers.items() if n != killed["name"])  # the other one stays
        rows = _read_csv(tmp_path / "batch.csv")
        assert (summary.total, summary.succeeded, summary.failed) == (4, 4, 0)
        assert sorted(int(r["position"]) for r in rows) == list(range(4))  # exactly one row per frame
        assert all(r["status"] == "ok" and r["error"] == "" for r in rows)
        assert all(r["output"] == str(out / f"{r['name']}.npy") for r in rows)
        assert sorted(p.name for p in out.iterdir()) == sorted(f"{r['name']}.npy" for r in rows)  # no temporaries
        # every frame, the one of the killed worker included, has the output of a full local run
        for r in rows:
            image, depth = make_scene((40, 60), seed=int(r["position"]))
            expected = evaluate_frame(image, depth, keep_fraction=0.1, seed=np.random.default_rng([0, int(r["position"])]),
                                      solver="adam", tol=1e-30, max_iter=60)
            np.testing.assert_allclose(np.load(r["output"]), expected.depth, rtol=0, atol=1e-6)  # metres
    finally:
        _stop(processes)
