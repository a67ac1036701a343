"""A batch: frames run on an executor, one CSV row per frame, resuming an earlier run.

:func:`run_batch` runs :func:`~sparsedepth.batch.evaluate_frame` over frames
read lazily from disk - a folder of image/depth pairs
(:func:`~sparsedepth.batch.find_frames`), an image folder and a depth folder
with the same file names (:func:`~sparsedepth.batch.find_frame_pairs`, the
KITTI layout), a folder of preprocessed NYU ``.h5`` files
(:func:`~sparsedepth.batch.nyu_h5_frames`) or an index range of the NYU
Depth V2 labeled ``.mat`` (:func:`~sparsedepth.batch.nyu_frames`) - on any
:class:`concurrent.futures.Executor` (a process pool by default).  Each frame
is read inside the worker, which writes its output atomically and returns
only a small row of metrics; the driver alone writes the CSV, one row per
frame, flushed as the frame finishes.  A rerun with the same settings
resumes: frames already done are skipped and the others run.  With
``image_shift="auto"`` one image shift is measured on a few frames of the
batch before the frames run, and used for all of them.  The library
never prints: progress goes to an optional callback.

Imports NumPy, :mod:`sparsedepth.registration` (the pooling of shift
estimates) and the other modules of :mod:`sparsedepth.batch`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
from collections import deque
from concurrent.futures import FIRST_COMPLETED, BrokenExecutor, CancelledError, Executor, wait
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from .._validation import is_int
from ..io import resolve_scale
from ..registration import pool_image_shifts
from . import csvlog
from .frames import ColmapFrame, absolute_frame
from .options import BatchOptions, BatchSummary
from .pool import default_workers, new_pool, stop_pool
from .worker import error_text, estimate_frame_shift, process_frame, remove_temporaries, uncertainty_path

__all__ = ["run_batch", "SHIFT_FRAMES", "shift_positions", "SCENE_UNITS", "colmap_scene", "write_colmap_scene"]

#: With ``image_shift="auto"``, the batch's one shift is measured on this many of its frames (at most).
SHIFT_FRAMES = 8


def _is_done(row: dict, options: BatchOptions) -> bool:
    if row.get("status") != "ok":
        return False
    if options.out_dir is None:
        return True
    output = row.get("output", "")
    if not (output and Path(output).is_file()):
        return False
    return options.uncertainty_dir is None or uncertainty_path(row.get("name", ""), options).is_file()


class _Dispatch:
    """Frames submitted to an executor, at most ``in_flight`` at a time, each row appended to the CSV as it finishes.

    With the default pool (``executor`` None) a pool that breaks is replaced,
    and the frames a dead worker was running are run once more before they
    count as failed.
    """

    def __init__(self, frames, options, executor, workers, progress, todo, latest):
        self.frames, self.options, self.progress, self.latest = frames, options, progress, latest
        self.own = executor is None
        self.workers = workers
        self.executor = new_pool(workers) if self.own else executor
        self.total = len(todo)
        self.todo_left, self.retry, self.retried = deque(todo), deque(), set()
        self.pending: dict = {}
        self.appended = 0
        self.handle = None

    def _error_row(self, position, exc) -> dict:
        return {"position": position, "name": self.frames[position].name, "status": "error",
                "error": error_text(exc)}

    def record(self, row: dict) -> None:
        csvlog.append_row(self.handle, row)
        self.appended += 1
        self.latest[row["name"]] = row
        if self.progress is not None:
            self.progress(self.appended, self.total, row)

    def submit_next(self) -> None:
        while self.retry or self.todo_left:
            position = self.retry.popleft() if self.retry else self.todo_left.popleft()
            try:
                future = self.executor.submit(process_frame, position, self.frames[position], self.options)
            except BrokenExecutor as exc:
                if not self.own:  # a given executor that takes no more work: the frame fails
                    self.record(self._error_row(position, exc))
                    continue
                stop_pool(self.executor, terminate=True)
                self.executor = new_pool(self.workers)
                future = self.executor.submit(process_frame, position, self.frames[position], self.options)
            self.pending[future] = position
            return

    def finish(self, future) -> None:
        position = self.pending.pop(future)
        try:
            row = future.result()
        except (Exception, CancelledError) as exc:  # noqa: BLE001 - the executor failed
            if self.own and isinstance(exc, BrokenExecutor) and position not in self.retried:
                self.retried.add(position)  # a worker died (killed, out of memory): once more
                self.retry.append(position)
                self.submit_next()
                return
            row = self._error_row(position, exc)
        self.record(row)
        self.submit_next()

    def run(self, csv_path: Path, in_flight: int) -> None:
        with open(csv_path, "a", newline="", encoding="utf-8") as self.handle:
            for _ in range(in_flight):
                self.submit_next()
            while self.pending:
                finished, _ = wait(self.pending, return_when=FIRST_COMPLETED)
                for future in finished:
                    self.finish(future)

    def stop(self, *, stopped: bool) -> None:
        """End the default pool (terminating its workers if ``stopped``) or cancel what a given executor holds."""
        if self.own:  # the stopped pool fails its pending futures itself (cancelling them first upsets it)
            stop_pool(self.executor, terminate=stopped)
        else:
            for future in self.pending:
                future.cancel()
        remove_temporaries([self.frames[p].name for p in self.pending.values()], self.options)


def _run_frames(frames, todo, csv_path, options, executor, max_workers, max_in_flight, progress, latest) -> None:
    """Run the frames at positions ``todo``; however it ends, stop the pool and leave the CSV compacted."""
    workers = max_workers or default_workers()
    dispatch = _Dispatch(frames, options, executor, workers, progress, todo, latest)
    stopped = False
    try:
        dispatch.run(csv_path, max_in_flight or 2 * workers)
    except BaseException:
        stopped = True
        raise
    finally:
        dispatch.stop(stopped=stopped)
        if dispatch.appended:
            with contextlib.suppress(OSError):  # a full disk: the appended log stays, compacted next run
                csvlog.compact_file(csv_path, [f.name for f in frames])


def _checked_frames(frames) -> list:
    frames = [absolute_frame(f) for f in frames]
    if not frames:
        raise ValueError("no frame to process")
    names = [f.name for f in frames]
    if len(set(names)) != len(names):
        duplicate = next(n for n in names if names.count(n) > 1)
        raise ValueError(f"frame names must be unique (they name the CSV rows and outputs); {duplicate!r} repeats")
    return frames


def _checked_options(options, max_workers, max_in_flight) -> BatchOptions:
    for value, name in ((max_workers, "max_workers"), (max_in_flight, "max_in_flight")):
        if value is not None and (not is_int(value) or value < 1):
            raise ValueError(f"{name} must be a positive integer or None, got {value!r}")
    options = BatchOptions() if options is None else options
    if not isinstance(options, BatchOptions):
        raise TypeError(f"options must be a BatchOptions, got {type(options).__name__}")
    if options.out_dir is not None:
        options = dataclasses.replace(options, out_dir=os.path.abspath(options.out_dir))
    return options


def shift_positions(n: int, k: int = SHIFT_FRAMES) -> list[int]:
    """Positions of the (at most ``k``) frames of ``n`` a batch measures its image shift on: spread evenly.

    ``round(linspace(0, n - 1, min(k, n)))``: the first and the last frame
    and the others evenly between (distinct, as the step is at least 1).
    """
    return [int(p) for p in np.round(np.linspace(0, n - 1, min(k, n)))]


def _measured_shift(frames, options, executor, max_workers):
    """(the pooled ImageShift or None, frames it pools) of the frames at :func:`shift_positions`.

    Each estimate runs on the executor (a pool of ``max_workers`` made and
    ended here by default); one the executor fails to return is computed in
    this process, so that the measurement does not depend on the executor.
    """
    positions = shift_positions(len(frames))
    own = executor is None
    pool = new_pool(min(max_workers or default_workers(), len(positions))) if own else executor
    futures = []
    stopped = False
    try:
        for position in positions:
            try:
                futures.append(pool.submit(estimate_frame_shift, position, frames[position], options))
            except Exception:  # noqa: BLE001 - an executor that takes no work: estimated here
                futures.append(None)
        estimates = [_returned_or_here(future, position, frames, options)
                     for position, future in zip(positions, futures)]
    except BaseException:
        stopped = True
        raise
    finally:
        if own:
            stop_pool(pool, terminate=stopped)
        elif stopped:
            for future in futures:
                if future is not None:
                    future.cancel()
    estimates = [e for e in estimates if e is not None]
    return (pool_image_shifts(estimates) if estimates else None), len(estimates)


def _returned_or_here(future, position, frames, options):
    """The estimate ``future`` returns, or one computed in this process if the executor took or returned none."""
    if future is not None:
        try:
            return future.result()
        except (Exception, CancelledError):  # noqa: BLE001 - the executor failed, not the frame
            pass
    return estimate_frame_shift(position, frames[position], options)


def _batch_shift(frames, options, executor, max_workers):
    """(options with the batch's shift, the shift or None, frames measured on or None).

    ``image_shift="auto"`` becomes the shift pooled over the frames at
    :func:`shift_positions` ((0, 0) when none gives an estimate); other
    options are as given.
    """
    if options.image_shift != "auto":
        return options, options.image_shift, None
    pooled, measured = _measured_shift(frames, options, executor, max_workers)
    shift = (0, 0) if pooled is None else pooled.shift
    return dataclasses.replace(options, image_shift=shift), shift, measured


def _summary(frames, latest, csv_path, skipped) -> BatchSummary:
    rows = [latest[f.name] for f in frames if f.name in latest]
    succeeded = sum(row.get("status") == "ok" for row in rows)
    ratios = []
    for row in rows:
        if row.get("status") == "ok" and row.get("rmse") and row.get("nn_rmse"):
            with contextlib.suppress(ValueError, ZeroDivisionError):
                ratios.append(float(row["rmse"]) / float(row["nn_rmse"]))
    ratios = [r for r in ratios if math.isfinite(r)]
    return BatchSummary(
        total=len(frames), succeeded=succeeded, failed=len(frames) - succeeded, csv_path=str(csv_path),
        skipped=skipped, rmse_ratio=float(np.mean(ratios)) if ratios else None, scored=len(ratios),
    )


# the numpydoc docstring (the resume and interruption rules in Notes) is most of this function; its code is about
# 15 lines of named steps
def run_batch(
    frames: Sequence,
    csv_path,
    *,
    options: BatchOptions | None = None,
    executor: Executor | None = None,
    max_workers: int | None = None,
    max_in_flight: int | None = None,
    progress: Callable[[int, int, dict], None] | None = None,
    resume: bool = True,
    overwrite: bool = False,
) -> BatchSummary:
    """Process frames on an executor, one CSV row per frame, resuming an earlier run.

    Parameters
    ----------
    frames : sequence of FileFrame, NYUFrame or NYUH5Frame
        From :func:`find_frames`, :func:`find_frame_pairs`,
        :func:`nyu_frames`, :func:`nyu_h5_frames` or built by hand; names
        must be unique.  Paths are made absolute before the frames are sent
        to the executor.
    csv_path : str or os.PathLike
        The CSV (its folder must exist); columns :data:`CSV_COLUMNS`, one row
        per frame at the end.  The settings of the run (options and frame
        list) are kept beside it in :func:`settings_path`.
    options : BatchOptions, optional
        What to do with each frame; default ``BatchOptions()``.
    executor : concurrent.futures.Executor, optional
        Where frames run (e.g. a thread pool or a Dask client's executor).
        Default: a :class:`~concurrent.futures.ProcessPoolExecutor` of
        ``max_workers`` processes, ended with the batch.  A given executor
        is left running.
    max_workers : int, optional
        Processes of the default pool; default :func:`default_workers`.
    max_in_flight : int, optional
        Frames submitted and not yet finished, for any executor; default
        ``2 * max_workers``.
    progress : callable, optional
        ``progress(done, total, row)`` in the calling process after every
        frame run, ``total`` being the frames this call runs (skipped frames
        excluded) and ``row`` the CSV row as a dict.
    resume : bool
        If the CSV exists (and ``overwrite`` is False): keep the frames it
        already has done and run only the others.  With ``resume=False`` an
        existing CSV is an error.
    overwrite : bool
        Start afresh: replace an existing CSV and its settings file and run
        every frame.

    Returns
    -------
    BatchSummary

    Raises
    ------
    FileNotFoundError
        If the CSV folder does not exist.
    ValueError
        If ``frames`` is empty or has duplicate names, ``max_workers`` or
        ``max_in_flight`` is not a positive integer, or the CSV exists and
        was written with other settings (or ``resume=False``) while
        ``overwrite`` is False, or another batch is running on the same CSV
        (it holds ``<csv>.lock``, see :func:`~sparsedepth.batch.csvlog.locked`).
    TypeError
        If a frame is not one of the frame types.
    OSError
        If the CSV or its settings file cannot be written (e.g. a full
        disk): the message names the file, ``csv_path`` (``--csv``) and the
        system's reason; the rows written so far are kept.

    Notes
    -----
    *Done.*  A frame is done when the CSV has an ``ok`` row for it and, with
    ``options.out_dir``, its output file exists.  A rerun with the same
    settings runs only the frames that are not done: done frames are not
    recomputed and their rows are kept byte for byte; a run with nothing to
    do leaves the CSV untouched.

    *One row per frame.*  While the batch runs, each finished frame's row is
    appended to the CSV and flushed, so rows survive any interruption.  A
    rerun of a failed frame appends a second row for it, so the CSV is then
    compacted: it is rewritten atomically (temporary file, then
    :func:`os.replace`) with the last row of every frame, in the order those
    rows were written.  The compaction happens when the batch ends, however
    it ends, and, for a CSV left uncompacted by a killed driver, when the
    next run starts.

    *Interruptions.*  On any exception in the driver (``KeyboardInterrupt``,
    a signal handler's exception, a full disk, an exception raised by
    ``progress``) no more frames are submitted, pending ones are cancelled,
    the default pool's worker processes are terminated and joined, the
    temporary output files of the frames without a row are removed, the
    CSV is compacted, and the exception propagates.  Those frames have no
    row and run again on the next call.  A given executor cannot be made to
    stop running frames: such a frame may still write its output, which,
    having no ``ok`` row, is recomputed and replaced on the next call.

    *Failures.*  A frame that raises (unreadable file, size mismatch, no
    valid depth, ...) becomes a row with ``status=error`` and the message
    in ``error``; the other frames go on.  If the executor fails for a
    frame, the frame gets an error row, except that when a worker process
    of the default pool dies (killed, out of memory), the pool is replaced
    and the frames it was running are run once more before they count as
    failed.

    *Image shift.*  With ``options.image_shift="auto"`` the batch first
    measures one shift: :func:`estimate_frame_shift` on the frames at
    :func:`shift_positions` (up to :data:`SHIFT_FRAMES`, spread evenly over
    ``frames``, done frames included), each read and sampled as it is
    completed; the estimates are pooled (:func:`~sparsedepth.pool_image_shifts`)
    and every frame runs with that shift ((0, 0) when no frame gives an
    estimate).  The measurement depends only on the frames and the options,
    so a rerun uses the same shift; it runs on the executor, also when
    every frame is done (the summary reports it).  The settings file keeps
    ``"auto"``.

    Memory is bounded by the frames in flight: each worker reads its own
    frame from disk and returns only a row.
    """
    frames = _checked_frames(frames)
    names = [f.name for f in frames]
    options = _checked_options(options, max_workers, max_in_flight)
    csv_path = Path(os.path.abspath(csv_path))
    if not csv_path.parent.is_dir():
        raise FileNotFoundError(f"folder of the CSV file '{csv_path}' does not exist")
    with csvlog.locked(csv_path):
        kept = csvlog.start_log(csv_path, csvlog.fingerprint(frames, options), names, resume=resume,
                                overwrite=overwrite)
        latest = {name: row for name, row, _ in kept}
        done_before = {name for name, row in latest.items() if _is_done(row, options)}
        todo = [position for position, name in enumerate(names) if name not in done_before]
        remove_temporaries([names[p] for p in todo], options)
        options, shift, measured = _batch_shift(frames, options, executor, max_workers)
        if todo:
            _run_frames(frames, todo, csv_path, options, executor, max_workers, max_in_flight, progress, latest)
    summary = _summary(frames, latest, csv_path, skipped=len(frames) - len(todo))
    return dataclasses.replace(summary, image_shift=shift, image_shift_frames=measured)


#: The unit of a COLMAP model's depth maps, as ``scene.json`` states it.
SCENE_UNITS = "model units (arbitrary SfM scale)"

_SCENE_FORMAT = "sparsedepth.colmap_depth/1"


def _relative(path, folder) -> str:
    """``path`` relative to ``folder``, ``/``-separated (``..`` where it is outside)."""
    return Path(os.path.relpath(path, folder)).as_posix()


def colmap_scene(frames: Sequence, csv_path, options: BatchOptions, *, images_dir, folder=None,
                 depth_range=None, command: str | None = None) -> dict:
    """The ``scene.json`` of a batch of COLMAP views: what the output folder holds, as it is now.

    Parameters
    ----------
    frames : sequence of ColmapFrame
        The batch's frames (:func:`~sparsedepth.batch.colmap_frames`), of one model.
    csv_path : str or os.PathLike
        The batch's CSV: a view is listed when its row is ``ok`` and its
        output files exist; a view with an error row is listed under
        ``"failed"``, one without a row under ``"pending"``.
    options : BatchOptions
        The batch's options (``out_dir`` set).
    images_dir : str or os.PathLike
        The image folder (image names are given relative to it).
    folder : str or os.PathLike, optional
        Paths of the maps are given relative to it; default ``out_dir``
        (where ``scene.json`` goes).
    depth_range : (float, float), optional
        The observed depth range of the model's views
        (:func:`~sparsedepth.batch.colmap_depth_range`).
    command : str, optional
        The command line that made the maps.

    Returns
    -------
    dict
        JSON data: ``format``, ``sparsedepth_version``, ``command``,
        ``model`` (the model folder), ``images``, ``units``
        (:data:`SCENE_UNITS`), ``depth_format`` (the extension),
        ``png_scale`` (stored value = depth x ``png_scale``, 0 = no depth;
        None for the float formats, which store the depth itself),
        ``observed_depth_range``, ``uncertainty`` (the folder or None),
        ``views`` (each: ``image``, ``image_id``, ``depth``, ``uncertainty``,
        ``width``, ``height``, ``points`` - pixels holding a model point,
        the samples of the completion - and ``method``), ``failed`` (each:
        ``image``, ``image_id``, ``error``) and ``pending`` (image names).

    Raises
    ------
    ValueError
        If a frame is not a :class:`ColmapFrame` or the frames come from
        several models, or the CSV is not a batch CSV.
    """
    from .. import __version__

    if options.out_dir is None:
        raise ValueError("a COLMAP scene needs options.out_dir (the folder of the depth maps)")
    if not frames or not all(isinstance(f, ColmapFrame) for f in frames):
        raise ValueError("colmap_scene describes ColmapFrame frames (sparsedepth.batch.colmap_frames)")
    models = {os.path.abspath(f.model_dir) for f in frames}
    if len(models) != 1:
        raise ValueError(f"the frames come from {len(models)} COLMAP models; a scene has one")
    folder = Path(options.out_dir if folder is None else folder)
    images_dir = os.path.abspath(images_dir)
    latest = {}
    if Path(csv_path).is_file():
        _, entries = csvlog.read_log(Path(csv_path))
        latest = {name: row for name, row, _ in entries}
    views, failed, pending = [], [], []
    for frame in frames:
        image_name = _relative(frame.image_path, images_dir)
        row = latest.get(frame.name)
        if row is not None and _is_done(row, options):
            sigma = None
            if options.uncertainty_dir is not None:
                sigma = _relative(uncertainty_path(frame.name, options), folder)
            views.append({"image": image_name, "image_id": frame.image_id,
                          "depth": _relative(row["output"], folder), "uncertainty": sigma,
                          "width": int(row["width"]), "height": int(row["height"]), "points": int(row["observed"]),
                          "method": row.get("method", "")})
        elif row is not None and row.get("status") == "error":
            failed.append({"image": image_name, "image_id": frame.image_id, "error": row.get("error", "")})
        else:
            pending.append(image_name)
    png = options.out_format == ".png"
    return {
        "format": _SCENE_FORMAT,
        "sparsedepth_version": __version__,
        "command": command,
        "model": models.pop(),
        "images": images_dir,
        "units": SCENE_UNITS,
        "depth_format": options.out_format,
        "png_scale": resolve_scale(options.out_scale) if png else None,
        "observed_depth_range": None if depth_range is None else [float(depth_range[0]), float(depth_range[1])],
        "uncertainty": None if options.uncertainty_dir is None else _relative(options.uncertainty_dir, folder),
        "views": views,
        "failed": failed,
        "pending": pending,
    }


def write_colmap_scene(path, frames: Sequence, csv_path, options: BatchOptions, *, images_dir, depth_range=None,
                       command: str | None = None) -> dict:
    """Write :func:`colmap_scene` as JSON to ``path`` atomically (paths of the maps relative to its folder).

    Call it after every run of the batch (also an interrupted one, and a
    resumed one): it describes the files present then, so it stays
    consistent with the folder.  Returns the data written.

    Raises
    ------
    OSError
        If the file cannot be written (its message names the file).
    ValueError
        As :func:`colmap_scene`.
    """
    path = Path(path)
    scene = colmap_scene(frames, csv_path, options, images_dir=images_dir, folder=path.parent,
                         depth_range=depth_range, command=command)
    try:
        csvlog.write_text_atomic(path, json.dumps(scene, indent=1, allow_nan=False) + "\n")
    except OSError as exc:
        error = OSError(f"could not write the scene file '{path}' (command line --outdir): "
                        f"{exc.strerror or ' '.join(str(exc).split())}")
        error.errno = exc.errno
        raise error from exc
    return scene
