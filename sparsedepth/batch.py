"""Many frames, one at a time: evaluation of one frame and a batch runner with a CSV log.

:func:`evaluate_frame` is the per-frame pipeline shared by the command line
(one frame) and :func:`run_batch` (many frames): optionally simulate sparse
input from a dense map, complete it (or fill the holes of raw depth), compute
the nearest-neighbour baseline and score both against ground truth on the
pixels the method did not see.

:func:`run_batch` runs :func:`evaluate_frame` over frames read lazily from
disk - a folder of image/depth pairs (:func:`find_frames`) or an index range
of the NYU Depth V2 labeled ``.mat`` (:func:`nyu_frames`) - on any
:class:`concurrent.futures.Executor` (a process pool by default).  Each frame
is read inside the worker, only a small row of metrics comes back, and each
row is appended to a CSV file and flushed as soon as the frame is done, so a
failing frame becomes a row with an ``error`` and an interrupted batch keeps
the rows already written.  The library never prints: progress goes to an
optional callback.
"""

from __future__ import annotations

import csv
import math
import os
import time
from concurrent.futures import FIRST_COMPLETED, Executor, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ._validation import check_same_shape
from .baselines import nearest_fill
from .completion import complete_depth
from .holes import FILL_METHODS, fill_holes
from .io import NYUDepthV2Labeled, read_depth, read_image, write_depth
from .metrics import DepthMetrics, depth_metrics
from .result import CompletionResult
from .sampling import sample_mask, valid_depth_mask
from .weights import DEFAULT_WEIGHTS, Weights

__all__ = [
    "TASKS",
    "CSV_COLUMNS",
    "FrameOutcome",
    "evaluate_frame",
    "FileFrame",
    "NYUFrame",
    "find_frames",
    "nyu_frames",
    "BatchOptions",
    "BatchSummary",
    "run_batch",
]

#: ``"complete"``: depth completion from (possibly simulated) sparse input;
#: ``"fill"``: hole filling of raw depth (every valid pixel observed).
TASKS = ("complete", "fill")

#: Columns of the batch CSV, in order.
CSV_COLUMNS = (
    "position", "name", "status", "height", "width", "observed", "scored", "method",
    "rmse", "mae", "rel", "delta1", "nn_rmse", "nn_mae", "nn_rel", "nn_delta1",
    "runtime", "converged", "output", "error",
)

_DEPTH_EXTENSIONS = (".png", ".pgm", ".pnm", ".pfm", ".npy", ".npz", ".h5", ".hdf5")
_IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".ppm", ".pgm", ".pnm", ".bmp", ".tif", ".tiff")


# --------------------------------------------------------------------------------------
# one frame
# --------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class FrameOutcome:
    """What :func:`evaluate_frame` returns.

    Attributes
    ----------
    depth : ndarray, (H, W)
        The dense output (completed or hole-filled).
    observed : ndarray of bool, (H, W)
        Pixels given to the method as observations.
    sparse : ndarray, (H, W)
        The input depth at ``observed``, NaN elsewhere.
    nearest : ndarray, (H, W)
        Nearest-neighbour fill of the same observations (the baseline).
    truth : ndarray or None, (H, W)
        Ground truth used for scoring, NaN where unknown.
    scored : ndarray of bool or None, (H, W)
        Pixels scored: valid ``truth`` and not ``observed``.
    metrics, nearest_metrics : DepthMetrics or None
        Scores of ``depth`` and ``nearest`` on ``scored`` (None without
        ground truth or without a pixel to score).
    method : str
        ``"complete (<solver>)"``, ``"fill colorization"`` or
        ``"fill complete (<solver>)"``.
    runtime, nearest_runtime : float
        Wall-clock seconds of the method and of the baseline.
    result : CompletionResult or None
        The solver result (None for the colorization fill).
    """

    depth: np.ndarray
    observed: np.ndarray
    sparse: np.ndarray
    nearest: np.ndarray
    truth: np.ndarray | None
    scored: np.ndarray | None
    metrics: DepthMetrics | None
    nearest_metrics: DepthMetrics | None
    method: str
    runtime: float
    nearest_runtime: float
    result: CompletionResult | None = None


def _depth_2d(depth, name):
    arr = np.asarray(depth)
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a 2-D (H, W) array, got shape {arr.shape}")
    return arr.astype(np.float64)  # a copy: inputs are never modified


def evaluate_frame(
    image,
    depth,
    *,
    mask=None,
    truth=None,
    task: str = "complete",
    keep_fraction: float | None = None,
    keep_count: int | None = None,
    seed=0,
    fill_method: str = "colorization",
    weights: Weights | None = None,
    solver: str = "auto",
    tol: float | None = None,
    max_iter: int | None = None,
    callback=None,
) -> FrameOutcome:
    """Complete (or hole-fill) one frame and score it and the nearest-neighbour baseline.

    Parameters
    ----------
    image : ndarray, (H, W, 3) or (H, W)
        Guide image (uint8, uint16 or float in [0, 1]).
    depth : ndarray, (H, W)
        Input depth in metres, NaN/0/inf where invalid: sparse or raw depth,
        or a dense map to sample from (``keep_fraction``/``keep_count``).
    mask : ndarray of bool, (H, W), optional
        Restricts the valid pixels of ``depth`` (default: finite and > 0).
    truth : ndarray, (H, W), optional
        Ground truth for scoring.  With ``keep_fraction``/``keep_count`` it
        defaults to ``depth`` itself.
    task : {"complete", "fill"}
        ``"complete"``: :func:`~sparsedepth.complete_depth`; ``"fill"``:
        :func:`~sparsedepth.fill_holes` with ``fill_method``.
    keep_fraction, keep_count : optional
        ``"complete"`` only: keep this fraction of the valid pixels (or this
        many), chosen at random with ``seed``, and hide the rest.
    seed : int or numpy.random.Generator
        Seed of the sampling.
    fill_method : {"colorization", "complete"}
        ``"fill"`` only.
    weights, solver, tol, max_iter, callback
        Passed to :func:`~sparsedepth.complete_depth` (not used by the
        colorization fill).

    Returns
    -------
    FrameOutcome
        Scores are on ``scored = valid(truth) & ~observed``: the pixels the
        method did not see.

    Raises
    ------
    ValueError
        Unknown task or fill method, inconsistent shapes, no valid depth, a
        sampling option with ``task="fill"``, and the errors of the functions
        called.
    """
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; choose one of {list(TASKS)}")
    if task == "fill" and fill_method not in FILL_METHODS:
        raise ValueError(f"unknown fill method {fill_method!r}; choose one of {list(FILL_METHODS)}")
    if task == "fill" and (keep_fraction is not None or keep_count is not None):
        raise ValueError("keep_fraction/keep_count simulate sparse input; they do not apply to task='fill'")
    weights = DEFAULT_WEIGHTS if weights is None else weights
    values = _depth_2d(depth, "depth")
    shape = values.shape
    check_same_shape(np.shape(image)[:2], shape, "image", "depth")
    valid = valid_depth_mask(values)
    if mask is not None:
        mask = np.asarray(mask)
        if mask.dtype != bool:
            raise ValueError(f"mask must be a boolean array, got dtype {mask.dtype}")
        check_same_shape(mask.shape, shape, "mask", "depth")
        valid &= mask
    if not valid.any():
        raise ValueError("depth has no valid pixel (all 0, NaN or inf, or outside the mask); nothing to complete from")
    sampled = keep_fraction is not None or keep_count is not None
    if truth is not None:
        truth = _depth_2d(truth, "truth")
        check_same_shape(truth.shape, shape, "truth", "depth")
    elif sampled:
        truth = np.where(valid, values, np.nan)

    if sampled:
        observed = sample_mask(np.where(valid, values, np.nan), fraction=keep_fraction, count=keep_count, seed=seed)
    else:
        observed = valid
    sparse = np.where(observed, values, np.nan)

    result = None
    start = time.perf_counter()
    if task == "fill" and fill_method == "colorization":
        dense = fill_holes(image, sparse, mask=observed, method="colorization")
        method = "fill colorization"
    else:
        # fill_holes(method="complete") is exactly this call; calling it here keeps the solver result
        result = complete_depth(
            image, sparse, observed, weights=weights, solver=solver, tol=tol, max_iter=max_iter, callback=callback
        )
        dense = result.depth
        method = f"{'fill complete' if task == 'fill' else 'complete'} ({result.solver})"
    runtime = time.perf_counter() - start
    start = time.perf_counter()
    nearest = nearest_fill(sparse, observed)
    nearest_runtime = time.perf_counter() - start

    scored = metrics = nearest_metrics = None
    if truth is not None:
        scored = valid_depth_mask(truth) & ~observed
        if scored.any():
            metrics = depth_metrics(dense, truth, mask=scored)
            nearest_metrics = depth_metrics(nearest, truth, mask=scored)
    return FrameOutcome(
        depth=dense,
        observed=observed,
        sparse=sparse,
        nearest=nearest,
        truth=truth,
        scored=scored,
        metrics=metrics,
        nearest_metrics=nearest_metrics,
        method=method,
        runtime=runtime,
        nearest_runtime=nearest_runtime,
        result=result,
    )


# --------------------------------------------------------------------------------------
# frame sources
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FileFrame:
    """One frame stored as files.

    ``depth`` is None when no depth file was found for the image (the frame
    is then reported as failed); ``truth`` is an optional ground-truth depth.
    """

    name: str
    image: str
    depth: str | None
    truth: str | None = None


@dataclass(frozen=True)
class NYUFrame:
    """Frame ``index`` of an NYU Depth V2 labeled ``.mat`` (read lazily in the worker)."""

    name: str
    path: str
    index: int


def _stem_map(folder: Path, prefix: str, extensions) -> dict[str, list[Path]]:
    found: dict[str, list[Path]] = {}
    for path in folder.iterdir():
        if path.is_file() and path.name.startswith(prefix) and path.suffix.lower() in extensions:
            found.setdefault(path.stem[len(prefix):], []).append(path)
    return found


def find_frames(folder, *, image_prefix: str = "rgb_", depth_prefix: str = "depth_",
                truth_prefix: str | None = None) -> list[FileFrame]:
    """Pair the images and depth maps of a folder by name.

    The convention is ``<image_prefix><id>.<image ext>`` with
    ``<depth_prefix><id>.<depth ext>`` (and, optionally,
    ``<truth_prefix><id>.<depth ext>``): by default ``rgb_0001.png`` goes
    with ``depth_0001.png`` (the KITTI/Metric3D demo layout; use
    ``depth_prefix="sync_depth_"`` for the BTS NYU layout).  Image extensions:
    png, jpg, jpeg, ppm, pgm, pnm, bmp, tif, tiff; depth: png, pgm, pnm, pfm,
    npy, npz, h5, hdf5.  Frames are sorted by id.

    Parameters
    ----------
    folder : str or os.PathLike
    image_prefix, depth_prefix : str
        Non-empty, different file-name prefixes.
    truth_prefix : str, optional
        Prefix of ground-truth depth files (e.g. inpainted depth for a raw
        ``depth``).

    Returns
    -------
    list of FileFrame
        One per image.  An image with no depth file (or several candidates)
        still gets an entry with ``depth=None``, so that the batch reports it
        as a failed frame instead of silently dropping it.

    Raises
    ------
    FileNotFoundError
        If ``folder`` is not a directory.
    ValueError
        If the prefixes are empty or equal, or no image matches.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"batch folder '{folder}' does not exist or is not a directory")
    prefixes = [p for p in (image_prefix, depth_prefix, truth_prefix) if p is not None]
    if any(not p for p in prefixes) or len(set(prefixes)) != len(prefixes):
        raise ValueError(f"file-name prefixes must be non-empty and different, got {prefixes}")
    images = _stem_map(folder, image_prefix, _IMAGE_EXTENSIONS)
    if not images:
        raise ValueError(
            f"no image named '{image_prefix}<id>.<ext>' in '{folder}' "
            f"(extensions {', '.join(_IMAGE_EXTENSIONS)})"
        )
    depths = _stem_map(folder, depth_prefix, _DEPTH_EXTENSIONS)
    truths = _stem_map(folder, truth_prefix, _DEPTH_EXTENSIONS) if truth_prefix else {}
    frames = []
    for key in sorted(images):
        if len(images[key]) > 1:
            image, depth = str(sorted(images[key])[0]), None  # ambiguous: reported by the batch
        else:
            image = str(images[key][0])
            depth = str(depths[key][0]) if len(depths.get(key, ())) == 1 else None
        truth = str(truths[key][0]) if len(truths.get(key, ())) == 1 else None
        frames.append(FileFrame(name=key, image=image, depth=depth, truth=truth))
    return frames


def nyu_frames(path, indices=None) -> list[NYUFrame]:
    """Frames of an NYU Depth V2 labeled ``.mat`` (checked once, read later, lazily).

    Parameters
    ----------
    path : str or os.PathLike
        ``nyu_depth_v2_labeled.mat`` or an HDF5 file with the same layout
        (see :class:`~sparsedepth.io.NYUDepthV2Labeled`).
    indices : iterable of int or slice, optional
        Frame indices (negative count from the end); default all frames.

    Returns
    -------
    list of NYUFrame

    Raises
    ------
    FileNotFoundError, ValueError
        As :class:`~sparsedepth.io.NYUDepthV2Labeled`.
    IndexError
        An index out of range.
    """
    with NYUDepthV2Labeled(path) as nyu:
        n = len(nyu)
        if indices is None:
            chosen = range(n)
        elif isinstance(indices, slice):
            chosen = range(n)[indices]
        else:
            chosen = [nyu._index(i) for i in indices]
        if len(chosen) == 0:
            raise ValueError(f"no frame selected from '{path}' ({n} frames)")
        return [NYUFrame(name=f"nyu_{i:04d}", path=str(nyu.path), index=int(i)) for i in chosen]


# --------------------------------------------------------------------------------------
# the batch
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BatchOptions:
    """What to do with every frame of a batch (picklable, sent to the workers).

    Attributes
    ----------
    task : {"complete", "fill"}
        See :func:`evaluate_frame`.  For NYU frames, ``"fill"`` fills
        ``rawDepths`` and scores against the inpainted ``depths``;
        ``"complete"`` samples ``depths`` (give ``keep_fraction`` or
        ``keep_count``).
    keep_fraction, keep_count : optional
        Simulate sparse input (``"complete"`` only).
    seed : int
        Frame ``i`` of the batch (0-based position) is sampled with
        ``numpy.random.default_rng([seed, i])``.
    fill_method : {"colorization", "complete"}
    weights, solver, tol, max_iter
        Passed to :func:`~sparsedepth.complete_depth`.
    depth_scale : float or str, optional
        Divisor of integer depth files (:data:`~sparsedepth.io.DEPTH_SCALES`).
    downsample : int
        Keep every ``downsample``-th row and column (1 = full resolution).
    out_dir : str, optional
        If given, each frame's output depth is written there as
        ``<name><out_format>`` (atomically).
    out_format : str
        ``".npy"``, ``".npz"``, ``".h5"``, ``".pfm"`` or ``".png"``
        (16-bit, stored value = depth x ``out_scale``).
    out_scale : float or str
        PNG output scale.
    """

    task: str = "complete"
    keep_fraction: float | None = None
    keep_count: int | None = None
    seed: int = 0
    fill_method: str = "colorization"
    weights: Weights = field(default_factory=lambda: DEFAULT_WEIGHTS)
    solver: str = "auto"
    tol: float | None = None
    max_iter: int | None = None
    depth_scale: float | str | None = None
    downsample: int = 1
    out_dir: str | None = None
    out_format: str = ".npy"
    out_scale: float | str = 1000.0

    def __post_init__(self):
        if self.task not in TASKS:
            raise ValueError(f"unknown task {self.task!r}; choose one of {list(TASKS)}")
        if self.fill_method not in FILL_METHODS:
            raise ValueError(f"unknown fill method {self.fill_method!r}; choose one of {list(FILL_METHODS)}")
        if not isinstance(self.downsample, int) or isinstance(self.downsample, bool) or self.downsample < 1:
            raise ValueError(f"downsample must be an integer >= 1, got {self.downsample!r}")
        if self.out_format not in (".npy", ".npz", ".h5", ".hdf5", ".pfm", ".png"):
            raise ValueError(f"unknown out_format {self.out_format!r}; use .npy, .npz, .h5, .pfm or .png")
        if self.out_dir is not None and not Path(self.out_dir).is_dir():
            raise FileNotFoundError(f"output folder '{self.out_dir}' does not exist")


@dataclass(frozen=True)
class BatchSummary:
    """Counts of a finished batch and where its CSV is."""

    total: int
    succeeded: int
    failed: int
    csv_path: str


def _read_frame(source, options: BatchOptions):
    """(image, depth, truth) of one frame, in metres."""
    if isinstance(source, NYUFrame):
        with NYUDepthV2Labeled(source.path) as nyu:
            image, depth, raw = nyu[source.index]
        if options.task == "fill":
            if raw is None:
                raise ValueError(f"'{source.path}' has no rawDepths to fill")
            return image, raw, depth
        return image, depth, None
    if source.depth is None:
        raise ValueError(f"no (unique) depth file for image '{source.image}'")
    image = read_image(source.image)
    depth = read_depth(source.depth, scale=options.depth_scale)
    truth = None if source.truth is None else read_depth(source.truth, scale=options.depth_scale)
    return image, depth, truth


def _fmt(value):
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if math.isnan(value) else f"{value:.6g}"
    return value


def _process(position: int, source, options: BatchOptions) -> dict:
    """Worker: one frame in, one CSV row out (errors become a row, never an exception)."""
    row = {"position": position, "name": source.name, "status": "ok"}
    try:
        image, depth, truth = _read_frame(source, options)
        step = options.downsample
        if step > 1:
            image, depth = image[::step, ::step], depth[::step, ::step]
            truth = None if truth is None else truth[::step, ::step]
        out = evaluate_frame(
            image, depth, truth=truth, task=options.task, keep_fraction=options.keep_fraction,
            keep_count=options.keep_count, seed=np.random.default_rng([options.seed, position]),
            fill_method=options.fill_method, weights=options.weights, solver=options.solver,
            tol=options.tol, max_iter=options.max_iter,
        )
        row.update(height=depth.shape[0], width=depth.shape[1], observed=int(out.observed.sum()),
                   method=out.method, runtime=f"{out.runtime:.3f}",
                   converged="" if out.result is None else out.result.converged)
        if out.metrics is not None:
            row.update(scored=out.metrics.count)
            for key in ("rmse", "mae", "rel", "delta1"):
                row[key] = _fmt(getattr(out.metrics, key))
                row["nn_" + key] = _fmt(getattr(out.nearest_metrics, key))
        if options.out_dir is not None:
            target = Path(options.out_dir) / f"{source.name}{options.out_format}"
            write_depth(target, out.depth, scale=options.out_scale)
            row["output"] = str(target)
    except Exception as exc:  # noqa: BLE001 - a failing frame is reported, not fatal
        row.update(status="error", error=_one_line(exc))
    return row


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return f"{type(exc).__name__}: {text}"


def run_batch(
    frames: Sequence,
    csv_path,
    *,
    options: BatchOptions | None = None,
    executor: Executor | None = None,
    max_workers: int | None = None,
    progress: Callable[[int, int, dict], None] | None = None,
) -> BatchSummary:
    """Process frames one at a time on an executor, appending one CSV row per frame.

    Parameters
    ----------
    frames : sequence of FileFrame or NYUFrame
        From :func:`find_frames`, :func:`nyu_frames` or built by hand.
    csv_path : str or os.PathLike
        CSV file to create (an existing file is replaced).  Its folder must
        exist.  Columns: :data:`CSV_COLUMNS`; one row per frame, written and
        flushed as the frame finishes (so in completion order; ``position``
        is the frame's place in ``frames``).
    options : BatchOptions, optional
        What to do with each frame; default ``BatchOptions()``.
    executor : concurrent.futures.Executor, optional
        Where frames run.  Default: a new
        :class:`~concurrent.futures.ProcessPoolExecutor` with ``max_workers``,
        shut down at the end.  A given executor is left running.
    max_workers : int, optional
        Workers of the default pool, and the bound on frames in flight
        (``2 * max_workers``) for any executor; default ``os.cpu_count()``.
    progress : callable, optional
        ``progress(done, total, row)`` in the calling process after every
        frame, ``row`` being the CSV row as a dict.

    Returns
    -------
    BatchSummary

    Raises
    ------
    FileNotFoundError
        If the CSV folder does not exist.
    ValueError
        If ``frames`` is empty or ``max_workers < 1``.

    Notes
    -----
    Memory is bounded by the frames in flight: each worker reads its own
    frame from disk and returns only a row, and at most ``2 * max_workers``
    frames are submitted at a time.  A frame that raises (unreadable file,
    size mismatch, no valid depth, ...) becomes a row with ``status=error``
    and the message in ``error``; the other frames go on.  If the executor
    itself fails (e.g. a worker process is killed), the frames concerned get
    an error row too.
    """
    frames = list(frames)
    if not frames:
        raise ValueError("no frame to process")
    if max_workers is not None and (not isinstance(max_workers, int) or max_workers < 1):
        raise ValueError(f"max_workers must be a positive integer, got {max_workers!r}")
    options = BatchOptions() if options is None else options
    csv_path = Path(csv_path)
    if not csv_path.parent.is_dir():
        raise FileNotFoundError(f"folder of the CSV file '{csv_path}' does not exist")
    in_flight = 2 * (max_workers or os.cpu_count() or 1)
    own = executor is None
    if own:
        executor = ProcessPoolExecutor(max_workers=max_workers)
    total, succeeded, done = len(frames), 0, 0
    try:
        with open(csv_path, "w", newline="", encoding="utf-8") as handle:
            writer = csv.DictWriter(handle, fieldnames=CSV_COLUMNS, restval="")
            writer.writeheader()
            handle.flush()
            queue = iter(enumerate(frames))
            pending: dict = {}

            def submit_next() -> None:
                for position, source in queue:
                    pending[executor.submit(_process, position, source, options)] = (position, source)
                    return

            for _ in range(in_flight):
                submit_next()
            while pending:
                finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in finished:
                    position, source = pending.pop(future)
                    try:
                        row = future.result()
                    except Exception as exc:  # noqa: BLE001 - executor failure for this frame
                        row = {"position": position, "name": getattr(source, "name", str(position)),
                               "status": "error", "error": _one_line(exc)}
                    writer.writerow(row)
                    handle.flush()
                    done += 1
                    succeeded += row["status"] == "ok"
                    if progress is not None:
                        progress(done, total, row)
                    submit_next()
    finally:
        if own:
            executor.shutdown(wait=True, cancel_futures=True)
    return BatchSummary(total=total, succeeded=succeeded, failed=total - succeeded, csv_path=str(csv_path))
