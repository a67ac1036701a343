"""Batch throughput: the local process pool against a Dask LocalCluster with as many workers.

The same frames (640x480 NYU Depth V2 / TUM frames of ``../shared/data`` or
``$SPARSEDEPTH_DATA``, written to a temporary folder as ``rgb_*.png`` /
``depth_*.npy``, each used ``--repeat`` times; the embedded 160x120 NYU frame
when that folder is absent) go through ``sparsedepth.batch.run_batch`` twice
per round:

* ``pool`` - a ``ProcessPoolExecutor(max_workers=W)``;
* ``dask`` - ``sparsedepth.batch.distributed.run_batch_on_cluster`` on a
  ``LocalCluster(n_workers=W, threads_per_worker=1, processes=True)`` over
  TCP on 127.0.0.1.

Both executors are started and warmed up (every worker has imported
sparsedepth) before the clock starts, so frames/s is the batch alone; their
start-up times are reported separately.  Rounds alternate the engines.  Two
tasks: ``complete`` (keep 5 % of the depth, default weights and solver) and
``fill`` (hole filling by colorization of the raw depth of the NYU frame that has it and of the
TUM frame, both raw sensor depth with holes).

Prints a markdown table and writes it, with the command, date, machine and
versions, to ``docs/batch_scale.md`` (``--out`` to change, ``--out -`` for
none).  From the repository root::

    python -m bench.batch_scale

May import :mod:`sparsedepth` (also ``sparsedepth.batch`` and ``sparsedepth.batch.distributed``), numpy, imageio,
dask and distributed, and :mod:`bench.harness`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread(("OPENBLAS_NUM_THREADS",))  # before numpy: one BLAS thread per worker in both engines

import argparse  # noqa: E402
import datetime  # noqa: E402
import os  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.batch import BatchOptions, find_frames, run_batch  # noqa: E402

from . import harness as H  # noqa: E402

COMPLETE_FRAMES = ("nyu_metric3d/00000", "nyu_metric3d/00050", "nyu_metric3d/00100", "tum/0")
FILL_FRAMES = ("nyu_rcnn_depth/demo", "tum/0")  # raw sensor depth with holes


def _warm(_):
    import sparsedepth  # noqa: F401 - imports the package in the worker

    return os.getpid()


def _write_frames(folder: Path, task: str, repeat: int, quick: bool) -> list[str]:
    """Write the frames of ``task`` into ``folder``; return the names of their sources."""
    import imageio.v3 as iio

    names = COMPLETE_FRAMES if task == "complete" else FILL_FRAMES
    available = set(sd.list_shared_frames()) if not quick else set()
    frames = [sd.load_shared_frame(n) for n in names if n in available]
    if not frames:
        frames = [sd.load_embedded_frame()]
    sources = []
    for k in range(repeat * len(COMPLETE_FRAMES)):  # the same number of frames for both tasks
        frame = frames[k % len(frames)]
        # fill: the raw depth where the frame has one apart from its ground truth, else its depth (TUM: raw)
        depth = frame.raw_depth if task == "fill" and frame.raw_depth is not None else frame.depth
        iio.imwrite(folder / f"rgb_{k:03d}.png", frame.image)
        np.save(folder / f"depth_{k:03d}.npy", np.nan_to_num(depth, nan=0.0))
        sources.append(frame.name)
    return sources


def _run(engine, frames, csv_path, options, workers, executor=None, client=None) -> float:
    start = time.perf_counter()
    if engine == "pool":
        summary = run_batch(frames, csv_path, options=options, executor=executor, max_workers=workers)
    else:
        from sparsedepth.batch.distributed import run_batch_on_cluster

        summary = run_batch_on_cluster(frames, csv_path, options=options, client=client)
    elapsed = time.perf_counter() - start
    if summary.failed:
        raise RuntimeError(f"{engine}: {summary.failed} frames failed, see {csv_path}")
    return elapsed


def _mean_runtime(csv_path) -> float:
    import csv

    with open(csv_path, newline="") as fh:
        return statistics.fmean(float(row["runtime"]) for row in csv.DictReader(fh))


def parse_args(argv):
    """The command line of :func:`main`."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, default=2, help="workers of each engine, 1 thread each (default 2)")
    parser.add_argument("--repeat", type=int, default=3, help="times each source frame is used (default 3)")
    parser.add_argument("--rounds", type=int, default=2, help="alternating rounds per engine (default 2)")
    parser.add_argument("--tasks", default="complete,fill", help="comma-separated: complete, fill")
    parser.add_argument("--dask-profile", action="store_true",
                        help="keep Dask's worker profiler on (default off, as docs/cluster.md recommends)")
    parser.add_argument("--malloc-trim", action="store_true",
                        help="keep Dask's MALLOC_TRIM_THRESHOLD_=65536 in the workers (default: removed)")
    parser.add_argument("--quick", action="store_true", help="embedded 160x120 frame, 1 round: a smoke test")
    parser.add_argument("--dataset-frames", type=int, default=400_000,
                        help="frames of the dataset to estimate for (default 400000, NYU Depth V2 raw)")
    parser.add_argument("--estimate-workers", default="16,64,256,1024",
                        help="comma-separated worker counts of the estimate (default 16,64,256,1024)")
    parser.add_argument("--out", default=str(H.DOCS / "batch_scale.md"), help="markdown output ('-': none)")
    args = parser.parse_args(argv)
    if args.quick:
        args.rounds, args.repeat = 1, 1
    return args


def configure_dask(args) -> None:
    """Dask's worker profiler and the nanny's ``MALLOC_TRIM_THRESHOLD_`` as ``args`` ask."""
    import dask

    # Dask's statistical profiler samples every worker thread every 10 ms; on a loaded machine the GIL
    # hand-offs it forces slow a CPU-bound task down, so the bench (and docs/cluster.md) turns it off
    dask.config.set({"distributed.worker.profile.enabled": args.dask_profile})
    if not args.malloc_trim:
        # the nanny sets MALLOC_TRIM_THRESHOLD_=65536 in its workers, which also fixes glibc's mmap threshold at
        # 128 KiB: every frame-sized array is then mmapped, page-faulted and unmapped again
        environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ"))
        environ.pop("MALLOC_TRIM_THRESHOLD_", None)
        dask.config.set({"distributed.nanny.pre-spawn-environ": environ})


def measure_task(task, tmp, args, pool, client):
    """Both engines on the frames of ``task``, rounds alternating: ``(table row, detail line)``."""
    folder = tmp / task
    folder.mkdir()
    sources = _write_frames(folder, task, args.repeat, args.quick)
    frames = find_frames(folder)
    options = BatchOptions(task=task, keep_fraction=0.05 if task == "complete" else None,
                           seed=0, out_dir=str(tmp), out_format=".npy")
    times = {"pool": [], "dask": []}
    runtimes = {"pool": [], "dask": []}
    for r in range(args.rounds):
        for engine in (("pool", "dask") if r % 2 == 0 else ("dask", "pool")):
            csv_path = tmp / f"{task}_{engine}_{r}.csv"
            times[engine].append(_run(engine, frames, csv_path, options, args.workers, executor=pool,
                                      client=client))
            runtimes[engine].append(_mean_runtime(csv_path))
            print(f"{task} {engine} round {r}: {len(frames)} frames in {times[engine][-1]:.2f} s",
                  file=sys.stderr, flush=True)
    n = len(frames)
    best = {e: min(t) for e, t in times.items()}
    fps = {e: n / best[e] for e in best}
    shapes = sorted({sd.read_depth(f.depth).shape for f in frames})
    row = (task, n, ", ".join(f"{w}x{h}" for h, w in shapes), fps["pool"], fps["dask"], fps["dask"] / fps["pool"],
           args.workers * best["dask"] / n, statistics.fmean(runtimes["dask"]))
    detail = (f"- {task}: sources {', '.join(sorted(set(sources)))}; wall times (s) pool "
              f"{', '.join(f'{t:.2f}' for t in times['pool'])}, dask "
              f"{', '.join(f'{t:.2f}' for t in times['dask'])}")
    return row, detail


def tables(rows, args) -> str:
    """The throughput table and the estimate for ``--dataset-frames`` frames."""
    counts = [int(c) for c in args.estimate_workers.split(",")]
    text = H.markdown_table(
        ["task", "frames", "size", "pool frames/s", "Dask frames/s", "Dask / pool", "worker-s per frame (Dask)",
         "mean solve s per frame (CSV runtime)"],
        [[task, n, size, f"{fp:.3f}", f"{fd:.3f}", f"{ratio:.3f}", f"{per_frame:.3f}", f"{solve:.3f}"]
         for task, n, size, fp, fd, ratio, per_frame, solve in rows])
    estimate = [[task, f"{args.dataset_frames * per_frame / 3600:.0f}",
                 *(f"{args.dataset_frames * per_frame / 3600 / c:.2f}" for c in counts)]
                for task, n, size, fp, fd, ratio, per_frame, solve in rows]
    return "\n".join([
        text, "",
        f"Estimate for {args.dataset_frames} frames of this size (worker-s per frame above x frames; wall time "
        "assumes the per-worker cost stays the same and ignores start-up and file-system limits):",
        "",
        H.markdown_table(["task", "core-hours", *(f"wall h, {c} workers" for c in counts)], estimate)])


def header(args, argv, pool_start, dask_start) -> str:
    """Title, command, date, machine and versions, and what the columns mean."""
    import dask
    import distributed

    command = H.command_line("batch_scale", argv if argv is not None else sys.argv[1:])
    return "\n".join([
        "# Batch throughput: process pool vs Dask LocalCluster",
        "",
        f"Written by `{command}` on {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC; "
        f"{platform.platform()}, {os.cpu_count()} CPUs, Python "
        f"{platform.python_version()}, numpy {np.__version__}, scipy {H.version('scipy')}, dask "
        f"{dask.__version__}, distributed {distributed.__version__}.",
        "",
        f"{args.workers} workers with 1 thread each in both engines, OPENBLAS_NUM_THREADS="
        f"{os.environ.get('OPENBLAS_NUM_THREADS')}, Dask worker profiler "
        f"{'on' if args.dask_profile else 'off (distributed.worker.profile.enabled=False)'}, "
        f"MALLOC_TRIM_THRESHOLD_ {'65536 (the Dask nanny default)' if args.malloc_trim else 'unset (not the Dask nanny default)'}; best of {args.rounds} alternating rounds; "
        f"start-up (not in frames/s): process pool {pool_start:.2f} s, LocalCluster + client "
        f"{dask_start:.2f} s.  Worker-s per frame = workers x best Dask wall time / frames (the cost to "
        "multiply by a dataset's frame count); the solve column is the mean `runtime` of the CSV rows "
        "(method only, without reading, the nearest-neighbour baseline, scoring and writing).",
        "",
        "",
    ])


def main(argv=None) -> int:
    args = parse_args(argv)
    from distributed import Client, LocalCluster

    configure_dask(args)
    rows, details = [], []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        start = time.perf_counter()
        pool = ProcessPoolExecutor(max_workers=args.workers)
        list(pool.map(_warm, range(args.workers)))
        pool_start = time.perf_counter() - start
        start = time.perf_counter()
        cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, protocol="tcp://",
                               host="127.0.0.1", dashboard_address=None, silence_logs=40)
        client = Client(cluster, set_as_default=False)
        client.run(_warm, None)
        dask_start = time.perf_counter() - start
        try:
            for task in args.tasks.split(","):
                row, detail = measure_task(task, tmp, args, pool, client)
                rows.append(row)
                details.append(detail)
        finally:
            client.close()
            cluster.close()
            pool.shutdown()
    text = tables(rows, args)
    print(text)
    if args.out != "-":
        footer = ["", *details, ""]
        Path(args.out).write_text(header(args, argv, pool_start, dask_start) + text + "\n" + "\n".join(footer),
                                  encoding="utf-8")
        print(f"wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
