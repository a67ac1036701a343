"""A batch from the command line: options and frames from the flags, progress on stderr, signals, the summary line.

SIGINT and SIGTERM stop the batch (exit codes 130 and 143) with its finished
rows kept; :func:`~sparsedepth.batch.run_batch` (or
:func:`~sparsedepth.batch.distributed.run_batch_on_cluster` with a Dask
scheduler) does the work.  A ``--colmap`` run reads the model once here (its
views, the depth range that sets the PNG scale) and writes ``scene.json`` in
``--outdir`` at the end of every run, interrupted ones included
(:func:`~sparsedepth.batch.write_colmap_scene`).  Imports
:mod:`sparsedepth.batch`, :mod:`sparsedepth.io` (the NYU and COLMAP
readers) and the other modules of :mod:`sparsedepth.cli` except the command
and the one-frame mode.
"""

from __future__ import annotations

import contextlib
import shlex
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from ..batch import (
    BatchOptions,
    ColmapFrame,
    FileFrame,
    colmap_depth_range,
    colmap_frames,
    find_frame_pairs,
    find_frames,
    nyu_frames,
    nyu_h5_frames,
    png_depth_scale,
    run_batch,
    settings_path,
    unregistered_images,
    write_colmap_scene,
)
from ..batch.csvlog import lock_path
from ..io import NYUDepthV2Labeled, read_colmap_model, resolve_scale
from ..io.colmap import MODEL_FILES
from .checks import COLMAP_SCENE, cluster_address
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
    "max_depth": "--max-depth", "max_pixels": "--max-pixels", "quality": "--fast or --best", "image_shift": "--image-shift",
    "uncertainty_dir": "--uncertainty", "colmap_max_error": "--colmap-max-error",
    "colmap_min_track": "--colmap-min-track",
}


_SCHEDULER_FLAGS = {"address": "--scheduler", "scheduler_file": "--scheduler-file"}


class _Terminated(BaseException):
    """Raised in the batch driver by SIGTERM (a BaseException, like KeyboardInterrupt)."""


@dataclass(frozen=True)
class _ColmapScene:
    """What a --colmap run reads once: the model's views, the depth range of its points, the unregistered files."""

    frames: list
    depth_range: tuple | None
    unregistered: list


def _out_format(args) -> str:
    """The extension of the per-frame outputs: --out-format, else png for --colmap and npy for other batches."""
    if args.colmap is not None and not getattr(args, "out_format_given", False):
        return ".png"
    return "." + args.out_format


def _colmap_scene(args) -> _ColmapScene:
    """Read the --colmap model once: its views (files under --images), their depth range, the unregistered files."""
    model = read_colmap_model(args.colmap, name="--colmap", max_pixels=args.max_pixels)
    try:
        frames = colmap_frames(args.colmap, args.images, model=model)
    except FileNotFoundError as exc:
        raise UsageError(f"--images: {one_line(exc)}") from None
    except ValueError as exc:
        raise UsageError(f"--colmap: {one_line(exc)}") from None
    depth_range = colmap_depth_range(model=model, max_error=args.colmap_max_error, min_track=args.colmap_min_track)
    if depth_range is None:
        filters = " with --colmap-max-error/--colmap-min-track" if (
            args.colmap_max_error is not None or args.colmap_min_track is not None) else ""
        raise UsageError(f"--colmap '{args.colmap}': no view of the model observes a 3-D point in front of it"
                          f"{filters}; there is nothing to complete from")
    return _ColmapScene(frames, depth_range, unregistered_images(args.images, model=model))


def _out_scale(args, scene: _ColmapScene | None):
    """--out-scale; else --depth-scale, or for --colmap the round scale that holds 1.05 x the largest depth."""
    if args.out_scale is not None:
        return args.out_scale
    if scene is not None:
        return png_depth_scale(scene.depth_range[1])
    return args.depth_scale or 1000.0  # for --colmap, a stand-in until the model is read


def _batch_options(args, weights, scene: _ColmapScene | None = None) -> BatchOptions:
    """The options of every frame; a bad one is a usage error naming its flag (a --colmap run's PNG scale comes
    from ``scene``; without it the options are only checked, at a stand-in scale)."""
    colmap = args.colmap is not None
    try:
        return BatchOptions(
            task="fill" if args.fill_holes else "complete",
            keep_fraction=args.keep_fraction, keep_count=args.keep_count, seed=args.seed,
            fill_method=args.fill_method, weights=weights, solver=args.solver or "auto",
            tol=args.tol, max_iter=args.max_iter, depth_scale=args.depth_scale,
            downsample=args.downsample or 1, out_dir=args.outdir, out_format=_out_format(args),
            out_scale=_out_scale(args, scene),
            byteorder=args.byteorder, invalid_values=tuple(args.invalid_values or ()), min_depth=args.min_depth,
            max_depth=args.max_depth, max_pixels=args.max_pixels, clip_to_observed=args.clip_to_observed,
            quality="fast" if args.fast else "best" if args.best else "default", image_shift=args.image_shift,
            uncertainty_dir=args.uncertainty if colmap else None,
            colmap_max_error=args.colmap_max_error, colmap_min_track=args.colmap_min_track,
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
    extension = _out_format(args)
    if args.colmap is not None:
        inputs += [Named("--colmap", args.colmap, Path(args.colmap) / (stem + ext)) for stem in MODEL_FILES
                   for ext in (".bin", ".txt")]
    for frame in frames:
        if isinstance(frame, ColmapFrame):
            inputs.append(Named("--images", args.images, Path(frame.image_path)))
        elif isinstance(frame, FileFrame):
            paths = (frame.image, frame.depth, frame.truth)
            inputs += [Named(flag, given, Path(path)) for (flag, given), path in zip(_file_sources(args), paths)
                       if path is not None]
        else:
            flag, given = ("--nyu-mat", args.nyu_mat) if args.nyu_mat is not None else ("--batch", args.batch)
            inputs.append(Named(flag, given, Path(frame.path)))
    outputs = [Named("--csv", args.csv, Path(args.csv)), Named("--csv", args.csv, settings_path(args.csv)),
               Named("--csv", args.csv, lock_path(args.csv))]
    colmap = args.colmap is not None  # a view's image name may have sub-folders, which the worker creates
    if args.outdir is not None:
        outputs += [Named("--outdir", args.outdir, Path(args.outdir) / f"{frame.name}{extension}",
                          create_parent=colmap) for frame in frames]
    if colmap:
        outputs.append(Named("--outdir", args.outdir, Path(args.outdir) / COLMAP_SCENE))
        if args.uncertainty is not None:
            outputs += [Named("--uncertainty", args.uncertainty, Path(args.uncertainty) / f"{frame.name}{extension}",
                              create_parent=True) for frame in frames]
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


def _check_png_range(options: BatchOptions, scene: _ColmapScene) -> None:
    """Refuse an --out-scale at which the model's deepest point overflows a 16-bit PNG (every view would fail)."""
    if options.out_format != ".png":
        return
    scale, deepest = resolve_scale(options.out_scale), scene.depth_range[1]
    if round(deepest * scale) > 65535:
        raise UsageError(f"--out-scale {scale:g} stores depth up to {65535 / scale:.6g} in a 16-bit PNG but the "
                          f"model's points reach {deepest:.6g} (model units); give --out-scale "
                          f"{png_depth_scale(deepest):g} (the default) or a float --out-format (npy, pfm, tif)")


def _scale_text(options: BatchOptions) -> str:
    if options.out_format == ".png":
        return f"16-bit PNG, model units = value / {options.out_scale:g}"
    return f"{options.out_format[1:]}, float, model units"


def _write_scene(args, argv, scene: _ColmapScene, options: BatchOptions) -> None:
    """Write --outdir/scene.json for the files there now (:func:`~sparsedepth.batch.write_colmap_scene`); ``argv``:
    the command's arguments as given."""
    command = shlex.join([*PROG.split(), *map(str, argv)])
    write_colmap_scene(Path(args.outdir) / COLMAP_SCENE, scene.frames, args.csv, options, images_dir=args.images,
                       depth_range=scene.depth_range, command=command)


def _scene_after_stop(args, argv, scene, options) -> None:
    """After an interrupted --colmap run: scene.json for the views done so far (a failure to write it is left for the
    next run, which rewrites it)."""
    if scene is not None:
        with contextlib.suppress(OSError, ValueError):
            _write_scene(args, argv, scene, options)


def _on_signal(signum, frame):  # noqa: ARG001 - signal handler API
    # the first signal decides; the driver then cleans up without being interrupted again
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise _Terminated


def run_batch_mode(args, stderr, argv=()) -> int:
    """Run the batch of the options; print the summary line; return the exit code (see :mod:`sparsedepth.cli.command`).

    With ``--image-shift`` a second line gives the shift the batch used; ``argv`` (the arguments as given) is the
    command a ``--colmap`` run records in its scene.json.  SIGINT and SIGTERM stop the batch with its finished rows kept (exit codes
    130 and 143); the previous signal handlers are restored at the end.
    """
    cluster = cluster_address(args)
    if cluster is not None:
        _check_scheduler(args)
    weights, _ = weights_of(args)
    options = _batch_options(args, weights)  # every flag checked before the inputs are read
    scene = None
    if args.colmap is not None:
        scene = _colmap_scene(args)
        frames = scene.frames
        options = _batch_options(args, weights, scene)
        _check_png_range(options, scene)
    else:
        frames = _batch_frames(args)
    _check_batch_files(args, frames)
    if scene is not None and scene.unregistered and not args.quiet:
        shown = ", ".join(scene.unregistered[:3]) + (", ..." if len(scene.unregistered) > 3 else "")
        count = len(scene.unregistered)
        print(f"{count} image file{'' if count == 1 else 's'} under --images {'is' if count == 1 else 'are'} not "
              f"registered in the model and skipped ({shown})", file=stderr)
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
        _scene_after_stop(args, argv, scene, options)
        print(f"{PROG}: interrupted; the rows of finished frames are in {args.csv}: run the same command to resume",
              file=stderr)
        return 130
    except _Terminated:
        _scene_after_stop(args, argv, scene, options)
        print(f"{PROG}: terminated (SIGTERM); the rows of finished frames are in {args.csv}: run the same command "
              "to resume", file=stderr)
        return 143
    finally:
        reporter.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if scene is not None:
        _write_scene(args, argv, scene, options)
        print(f"{summary.succeeded} of {summary.total} views done, {summary.failed} failed, {summary.skipped} "
              f"skipped (done before); depth in {args.outdir} ({_scale_text(options)}), described in "
              f"{Path(args.outdir) / COLMAP_SCENE}; rows in {summary.csv_path}", file=sys.stdout)
        return 1 if summary.failed else 0
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
