"""A batch from the command line: options and frames from the flags, progress on stderr, signals, the summary line.

SIGINT and SIGTERM stop the batch (exit codes 130 and 143) with its finished
rows kept; :func:`~sparsedepth.batch.run_batch` (or
:func:`~sparsedepth.batch.distributed.run_batch_on_cluster` with a Dask
scheduler) does the work.  Imports :mod:`sparsedepth.batch`,
:class:`~sparsedepth.io.NYUDepthV2Labeled` and the other modules of
:mod:`sparsedepth.cli` except the command and the one-frame mode.
"""

from __future__ import annotations

import signal
import sys
import time
from pathlib import Path

from ..batch import (
    BatchOptions,
    FileFrame,
    find_frame_pairs,
    find_frames,
    nyu_frames,
    nyu_h5_frames,
    run_batch,
    settings_path,
)
from ..batch.csvlog import lock_path
from ..io import NYUDepthV2Labeled
from .checks import cluster_address
from .messages import UsageError, one_line, warnings_as_lines
from .outputs import Named, check_distinct, check_writable
from .parser import PROG, weights_of

__all__ = ["run_batch_mode"]

_OPTION_FLAGS = {
    "task": "--fill-holes", "keep_fraction": "--keep-fraction", "keep_count": "--keep-count", "seed": "--seed",
    "fill_method": "--fill-method", "weights": "the weight options", "solver": "--solver", "tol": "--tol",
    "max_iter": "--max-iter", "depth_scale": "--depth-scale", "downsample": "--downsample", "out_dir": "--outdir",
    "out_format": "--out-format", "out_scale": "--out-scale", "clip_to_observed": "--no-clip",
    "byteorder": "--byteorder", "invalid_values": "--invalid-value", "min_depth": "--min-depth",
    "max_depth": "--max-depth", "max_pixels": "--max-pixels", "quality": "--fast", "image_shift": "--image-shift",
}


_SCHEDULER_FLAGS = {"address": "--scheduler", "scheduler_file": "--scheduler-file"}


class _Terminated(BaseException):
    """Raised in the batch driver by SIGTERM (a BaseException, like KeyboardInterrupt)."""


def _batch_options(args, weights) -> BatchOptions:
    """The options of every frame; a bad one is a usage error naming its flag."""
    try:
        return BatchOptions(
            task="fill" if args.fill_holes else "complete",
            keep_fraction=args.keep_fraction, keep_count=args.keep_count, seed=args.seed,
            fill_method=args.fill_method, weights=weights, solver=args.solver or "auto",
            tol=args.tol, max_iter=args.max_iter, depth_scale=args.depth_scale,
            downsample=args.downsample or 1, out_dir=args.outdir, out_format="." + args.out_format,
            out_scale=args.out_scale if args.out_scale is not None else (args.depth_scale or 1000.0),
            byteorder=args.byteorder, invalid_values=tuple(args.invalid_values or ()), min_depth=args.min_depth,
            max_depth=args.max_depth, max_pixels=args.max_pixels, clip_to_observed=args.clip_to_observed,
            quality="fast" if args.fast else "default", image_shift=args.image_shift,
        )
    except (ValueError, TypeError, OSError) as exc:
        flag = _OPTION_FLAGS.get(getattr(exc, "option", None))
        if flag is None:
            raise
        raise UsageError(f"{flag}: {one_line(exc)}") from None


def _check_scheduler(args) -> None:
    """Refuse a malformed --scheduler, --scheduler-file or $DASK_SCHEDULER_ADDRESS before anything else runs.

    Without either flag the library reads the environment variable itself,
    so that its message names it.
    """
    from ..batch.distributed import scheduler_address

    try:
        scheduler_address(args.scheduler, scheduler_file=args.scheduler_file)
    except (ValueError, OSError) as exc:
        flag = _SCHEDULER_FLAGS.get(getattr(exc, "option", None))
        if flag is None:
            raise
        raise UsageError(f"{flag}: {one_line(exc)}") from None


def _batch_frames(args):
    """The frames of --nyu-mat, --batch with --batch-depths, a folder of NYU .h5 files, or a --batch folder."""
    if args.nyu_mat is not None:
        with NYUDepthV2Labeled(args.nyu_mat, name="--nyu-mat"):  # a bad file is an error naming the flag
            pass
        return nyu_frames(args.nyu_mat, args.indices)
    if args.batch_depths is not None:
        return find_frame_pairs(args.batch, args.batch_depths, truth_folder=args.batch_truths)
    folder = Path(args.batch)
    if folder.is_dir():
        has_images = any(p.is_file() and p.name.startswith(args.image_prefix) for p in folder.iterdir())
        if not has_images and any(p.suffix.lower() in (".h5", ".hdf5") for p in folder.rglob("*")):
            return nyu_h5_frames(folder)
    return find_frames(folder, image_prefix=args.image_prefix, depth_prefix=args.depth_prefix,
                       truth_prefix=args.truth_prefix)


def _check_batch_files(args, frames) -> None:
    """Refuse a --csv or --outdir file that is an input or another output; prove every output can be created."""
    inputs = []
    for frame in frames:
        if isinstance(frame, FileFrame):
            paths = (frame.image, frame.depth, frame.truth)
            inputs += [Named(flag, given, Path(path)) for (flag, given), path in zip(_file_sources(args), paths)
                       if path is not None]
        else:
            flag, given = ("--nyu-mat", args.nyu_mat) if args.nyu_mat is not None else ("--batch", args.batch)
            inputs.append(Named(flag, given, Path(frame.path)))
    outputs = [Named("--csv", args.csv, Path(args.csv)), Named("--csv", args.csv, settings_path(args.csv)),
               Named("--csv", args.csv, lock_path(args.csv))]
    if args.outdir is not None:
        outputs += [Named("--outdir", args.outdir, Path(args.outdir) / f"{frame.name}.{args.out_format}")
                    for frame in frames]
    check_distinct(outputs, inputs)
    check_writable(outputs)


def _file_sources(args):
    """The flag and value each of a file frame's image, depth and truth paths comes from."""
    batch = ("--batch", args.batch)
    depths = ("--batch-depths", args.batch_depths) if args.batch_depths is not None else batch
    truths = ("--batch-truths", args.batch_truths) if args.batch_truths is not None else batch
    return batch, depths, truths


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"


class _BatchProgress:
    """Progress of a batch on stderr: a tqdm bar on a terminal if tqdm is installed, else one line per frame."""

    def __init__(self, stream, enabled: bool, frames: int):
        self.stream, self.enabled, self.frames = stream, enabled, frames
        self.start = time.monotonic()
        self.bar = None
        self.tqdm = None
        if enabled and getattr(stream, "isatty", lambda: False)():
            try:
                from tqdm import tqdm
            except ImportError:
                pass
            else:
                self.tqdm = tqdm

    def __call__(self, done, total, row):
        if not self.enabled:
            return
        if done == 1 and total < self.frames:
            self._write(f"resuming: {self.frames - total} of {self.frames} frames already done, skipped")
        if row["status"] == "ok":
            score = f"RMSE {float(row['rmse']):.4f} m, " if row.get("rmse") else ""
            text = f"ok, {score}{row.get('runtime', '?')} s"
        else:
            text = f"FAILED: {row.get('error', '')}"
        if self.tqdm is not None:
            if self.bar is None:
                self.bar = self.tqdm(total=total, initial=0, file=self.stream, unit="frame")
            self.bar.update(1)
            if row["status"] != "ok":
                self.bar.write(f"{row['name']}: {text}", file=self.stream)
            return
        elapsed = time.monotonic() - self.start
        rate = done / elapsed if elapsed > 0 else float("inf")
        eta = (total - done) / rate if rate > 0 else 0.0
        self._write(f"[{done}/{total}] {row['name']}: {text}; {rate:.3g} frames/s, ETA {_duration(eta)}")

    def _write(self, text):
        if self.bar is not None:
            self.bar.write(text, file=self.stream)
        else:
            print(text, file=self.stream, flush=True)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _on_signal(signum, frame):  # noqa: ARG001 - signal handler API
    # the first signal decides; the driver then cleans up without being interrupted again
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise _Terminated


def run_batch_mode(args, stderr) -> int:
    """Run the batch of the options; print the summary line; return the exit code (see :mod:`sparsedepth.cli.command`).

    With ``--image-shift`` a second line gives the shift the batch used.
    SIGINT and SIGTERM stop the batch with its finished rows kept (exit codes
    130 and 143); the previous signal handlers are restored at the end.
    """
    cluster = cluster_address(args)
    if cluster is not None:
        _check_scheduler(args)
    weights, _ = weights_of(args)
    options = _batch_options(args, weights)
    frames = _batch_frames(args)
    _check_batch_files(args, frames)
    reporter = _BatchProgress(stderr, not args.quiet, len(frames))
    previous = {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, _on_signal)
    except ValueError:  # not the main thread: signals stay as they are
        pass
    try:
        if cluster is not None:
            from ..batch.distributed import DEFAULT_TIMEOUT, run_batch_on_cluster
            with warnings_as_lines(stderr):
                summary = run_batch_on_cluster(frames, args.csv, options=options, progress=reporter,
                                               address=args.scheduler, scheduler_file=args.scheduler_file,
                                               timeout=args.scheduler_timeout or DEFAULT_TIMEOUT,
                                               overwrite=args.overwrite)
        else:
            summary = run_batch(frames, args.csv, options=options, max_workers=args.workers, progress=reporter,
                                overwrite=args.overwrite)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; the rows of finished frames are in {args.csv}: run the same command to resume",
              file=stderr)
        return 130
    except _Terminated:
        print(f"{PROG}: terminated (SIGTERM); the rows of finished frames are in {args.csv}: run the same command "
              "to resume", file=stderr)
        return 143
    finally:
        reporter.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    ratio = "" if summary.rmse_ratio is None else \
        f"; mean RMSE / nearest-neighbour RMSE {summary.rmse_ratio:.3f} over {summary.scored} scored frames"
    print(f"{summary.succeeded} of {summary.total} frames done, {summary.failed} failed, {summary.skipped} skipped "
          f"(done before){ratio}; metrics in {summary.csv_path}", file=sys.stdout)
    if summary.image_shift is not None:
        dy, dx = summary.image_shift
        how = "given" if summary.image_shift_frames is None else \
            f"measured on {summary.image_shift_frames} frame{'' if summary.image_shift_frames == 1 else 's'}"
        print(f"image shift for the batch: dy = {dy}, dx = {dx} ({how})", file=sys.stdout)
    return 1 if summary.failed else 0
