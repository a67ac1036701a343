"""Many frames, one at a time: evaluation of one frame and a batch runner with a CSV log.

:func:`evaluate_frame` is the per-frame pipeline shared by the command line
(one frame) and :func:`run_batch` (many frames): optionally simulate sparse
input from a dense map, complete it (or fill the holes of raw depth), compute
the nearest-neighbour baseline and score both against ground truth on the
pixels the method did not see.

:func:`run_batch` runs :func:`evaluate_frame` over frames read lazily from
disk - a folder of image/depth pairs (:func:`find_frames`), an image folder
and a depth folder with the same file names (:func:`find_frame_pairs`, the
KITTI layout), a folder of preprocessed NYU ``.h5`` files
(:func:`nyu_h5_frames`) or an index range of the NYU Depth V2 labeled
``.mat`` (:func:`nyu_frames`) - on any :class:`concurrent.futures.Executor`
(a process pool by default).  Each frame is read inside the worker, which
writes its output atomically and returns only a small row of metrics; the
driver alone writes the CSV, one row per frame, flushed as the frame
finishes.  A rerun with the same settings resumes: frames already done are
skipped and the others run (see :func:`run_batch`).  The library never
prints: progress goes to an optional callback.
"""

from __future__ import annotations

import contextlib
import ctypes
import csv
import dataclasses
import glob
import io as _io
import json
import math
import os
import signal
import time
import warnings
from collections import deque
from concurrent.futures import FIRST_COMPLETED, BrokenExecutor, CancelledError, Executor, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from .._validation import check_same_shape, is_int, is_real
from ..baselines import nearest_fill
from ..completion import complete_depth
from ..holes.fill import FILL_METHODS, fill_holes
from ..io.formats import MAX_PIXELS, NYUDepthV2Labeled, atomic_target, resolve_scale, read_depth, read_image, read_nyu_h5, write_depth
from ..metrics import DepthMetrics, depth_metrics
from ..result import ClampWarning, CompletionResult
from ..sampling import sample_mask, valid_depth_mask
from ..solvers.core import SOLVERS
from ..objective.weights import DEFAULT_WEIGHTS, Weights

__all__ = [
    "TASKS",
    "CSV_COLUMNS",
    "FrameOutcome",
    "evaluate_frame",
    "FileFrame",
    "NYUFrame",
    "NYUH5Frame",
    "find_frames",
    "find_frame_pairs",
    "nyu_frames",
    "nyu_h5_frames",
    "BatchOptions",
    "BatchSummary",
    "default_workers",
    "settings_path",
    "run_batch",
]

#: ``"complete"``: depth completion from (possibly simulated) sparse input;
#: ``"fill"``: hole filling of raw depth (every valid pixel observed).
TASKS = ("complete", "fill")

#: Columns of the batch CSV, in order.
CSV_COLUMNS = (
    "position", "name", "status", "height", "width", "observed", "scored", "method",
    "rmse", "mae", "rel", "delta1", "nn_rmse", "nn_mae", "nn_rel", "nn_delta1",
    "runtime", "converged", "clamped", "output", "error",
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
    clip_to_observed: bool = True,
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
    weights, solver, tol, max_iter, callback, clip_to_observed
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
            image, sparse, observed, weights=weights, solver=solver, tol=tol, max_iter=max_iter, callback=callback,
            clip_to_observed=clip_to_observed,
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


@dataclass(frozen=True)
class NYUH5Frame:
    """One preprocessed NYU Depth V2 ``.h5`` file (``rgb`` + ``depth``, see :func:`~sparsedepth.io.read_nyu_h5`)."""

    name: str
    path: str


_SHOWN = 5  # file names quoted in a "found nothing" error


def _some_names(paths) -> str:
    names = sorted(p.name for p in paths)
    if not names:
        return "no file"
    more = f" and {len(names) - _SHOWN} more" if len(names) > _SHOWN else ""
    return ", ".join(names[:_SHOWN]) + more


def _stem_map(folder: Path, prefix: str, extensions) -> dict[str, list[Path]]:
    found: dict[str, list[Path]] = {}
    for path in folder.iterdir():
        if path.is_file() and path.name.startswith(prefix) and path.suffix.lower() in extensions:
            found.setdefault(path.stem[len(prefix):], []).append(path)
    return found


def _files(folder: Path, extensions) -> list[Path]:
    return [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in extensions]


def _check_folder(folder, name: str) -> Path:
    if not isinstance(folder, (str, os.PathLike)):
        raise TypeError(f"{name} must be a str or os.PathLike, got {type(folder).__name__}")
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"{name} '{folder}' does not exist or is not a directory")
    return folder


def find_frames(folder, *, image_prefix: str = "rgb_", depth_prefix: str = "depth_",
                truth_prefix: str | None = None) -> list[FileFrame]:
    """Pair the images and depth maps of a folder by name.

    The convention is ``<image_prefix><id>.<image ext>`` with
    ``<depth_prefix><id>.<depth ext>`` (and, optionally,
    ``<truth_prefix><id>.<depth ext>``): by default ``rgb_0001.png`` goes
    with ``depth_0001.png`` (the KITTI/Metric3D demo layout; use
    ``depth_prefix="sync_depth_"`` for the BTS NYU layout).  Image extensions:
    png, jpg, jpeg, ppm, pgm, pnm, bmp, tif, tiff; depth: png, pgm, pnm, pfm,
    npy, npz, h5, hdf5.  Frames are sorted by id.  For an image folder and a
    depth folder holding the same file names see :func:`find_frame_pairs`;
    for a folder of NYU ``.h5`` files see :func:`nyu_h5_frames`.

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
        If the prefixes are empty or equal, no image matches
        ``image_prefix``, or no image has a depth partner (the message lists
        a few of the files found, so that the right prefix can be given).
    """
    folder = _check_folder(folder, "batch folder")
    prefixes = [p for p in (image_prefix, depth_prefix, truth_prefix) if p is not None]
    if any(not p for p in prefixes) or len(set(prefixes)) != len(prefixes):
        raise ValueError(f"file-name prefixes must be non-empty and different, got {prefixes}")
    images = _stem_map(folder, image_prefix, _IMAGE_EXTENSIONS)
    if not images:
        raise ValueError(
            f"no image named '{image_prefix}<id>.<ext>' in '{folder}' "
            f"(extensions {', '.join(_IMAGE_EXTENSIONS)}); found {_some_names(_files(folder, _IMAGE_EXTENSIONS))}: "
            "give the prefix the images share as image_prefix (command line: --image-prefix)"
        )
    depths = _stem_map(folder, depth_prefix, _DEPTH_EXTENSIONS)
    if not set(images) & set(depths):
        candidates = [p for p in _files(folder, _DEPTH_EXTENSIONS) if not p.name.startswith(image_prefix)]
        raise ValueError(
            f"no depth file named '{depth_prefix}<id>.<ext>' matches an image '{image_prefix}<id>' in '{folder}'; "
            f"found {_some_names(candidates)}: give the prefix the depth files share as depth_prefix "
            "(command line: --depth-prefix)"
        )
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


def find_frame_pairs(image_folder, depth_folder, *, truth_folder=None) -> list[FileFrame]:
    """Pair an image folder with a depth folder holding the same file names (the KITTI layout).

    KITTI depth keeps ``image_02/data/0000000005.png`` beside
    ``proj_depth/groundtruth/image_02/0000000005.png``: an image and its depth
    have the same name (the extensions may differ).  Frames are named by that
    stem and sorted.

    Parameters
    ----------
    image_folder, depth_folder : str or os.PathLike
        Folders of images and of depth files (extensions as :func:`find_frames`).
    truth_folder : str or os.PathLike, optional
        Folder of ground-truth depth files with the same names.

    Returns
    -------
    list of FileFrame
        One per image; ``depth`` (or ``truth``) is None where the folder has
        no unique file of that stem (the batch reports such a frame as failed).

    Raises
    ------
    FileNotFoundError
        If a folder does not exist.
    ValueError
        If ``image_folder`` holds no image, or no image has a depth file of
        the same name (the message lists a few names of each folder).
    """
    image_folder = _check_folder(image_folder, "image folder")
    depth_folder = _check_folder(depth_folder, "depth folder")
    images = _stem_map(image_folder, "", _IMAGE_EXTENSIONS)
    if not images:
        raise ValueError(f"no image ({', '.join(_IMAGE_EXTENSIONS)}) in image folder '{image_folder}'")
    depths = _stem_map(depth_folder, "", _DEPTH_EXTENSIONS)
    if not set(images) & set(depths):
        raise ValueError(
            f"no depth file in '{depth_folder}' has the name of an image in '{image_folder}': images "
            f"{_some_names(_files(image_folder, _IMAGE_EXTENSIONS))}; depth files "
            f"{_some_names(_files(depth_folder, _DEPTH_EXTENSIONS))}"
        )
    truths = {}
    if truth_folder is not None:
        truths = _stem_map(_check_folder(truth_folder, "truth folder"), "", _DEPTH_EXTENSIONS)
    frames = []
    for key in sorted(images):
        image = str(sorted(images[key])[0])
        depth = str(depths[key][0]) if len(depths.get(key, ())) == 1 and len(images[key]) == 1 else None
        truth = str(truths[key][0]) if len(truths.get(key, ())) == 1 else None
        frames.append(FileFrame(name=key, image=image, depth=depth, truth=truth))
    return frames


def nyu_h5_frames(folder) -> list[NYUH5Frame]:
    """The ``.h5`` / ``.hdf5`` files under ``folder`` (searched recursively), one frame each.

    This is the preprocessed NYU Depth V2 layout of most depth-completion code
    (``nyudepthv2/val/official/00001.h5``: ``rgb`` (3, H, W) uint8 and
    ``depth`` (H, W) metres, read by :func:`~sparsedepth.io.read_nyu_h5`).
    A frame is named by its path relative to ``folder`` without the
    extension, folders joined by ``_``.

    Raises
    ------
    FileNotFoundError
        If ``folder`` is not a directory.
    ValueError
        If it holds no ``.h5`` file, or two files get the same name.
    """
    folder = _check_folder(folder, "h5 folder")
    paths = sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix.lower() in (".h5", ".hdf5"))
    if not paths:
        raise ValueError(f"no .h5 or .hdf5 file under '{folder}'; found {_some_names(p for p in folder.iterdir() if p.is_file())}")
    frames, seen = [], {}
    for path in paths:
        name = "_".join(path.relative_to(folder).with_suffix("").parts)
        if name in seen:
            raise ValueError(f"'{seen[name]}' and '{path}' both give the frame name '{name}'")
        seen[name] = path
        frames.append(NYUH5Frame(name=name, path=str(path)))
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


def absolute_frame(source):
    """The frame with absolute paths (a worker may run in another working directory)."""
    if isinstance(source, FileFrame):
        return dataclasses.replace(
            source, image=os.path.abspath(source.image),
            depth=None if source.depth is None else os.path.abspath(source.depth),
            truth=None if source.truth is None else os.path.abspath(source.truth),
        )
    if isinstance(source, (NYUFrame, NYUH5Frame)):
        return dataclasses.replace(source, path=os.path.abspath(source.path))
    raise TypeError(
        f"frames must be FileFrame, NYUFrame or NYUH5Frame objects, got {type(source).__name__}; "
        "build them with find_frames, find_frame_pairs, nyu_frames or nyu_h5_frames"
    )


# --------------------------------------------------------------------------------------
# options
# --------------------------------------------------------------------------------------
def _option_error(option: str, message: str, kind=ValueError) -> Exception:
    """An error about one BatchOptions field; ``option`` lets the command line name its flag."""
    exc = kind(message)
    exc.option = option
    return exc


@dataclass(frozen=True)
class BatchOptions:
    """What to do with every frame of a batch (picklable, sent to the workers).

    Every field is checked when the object is made, so that a bad option is
    one error before any frame runs.

    Attributes
    ----------
    task : {"complete", "fill"}
        See :func:`evaluate_frame`.  For NYU frames, ``"fill"`` fills
        ``rawDepths`` and scores against the inpainted ``depths``;
        ``"complete"`` samples ``depths`` (give ``keep_fraction`` or
        ``keep_count``).
    keep_fraction : float in (0, 1], optional
    keep_count : int >= 1, optional
        Simulate sparse input (``"complete"`` only; at most one of the two).
    seed : int >= 0
        Frame ``i`` of the batch (0-based position) is sampled with
        ``numpy.random.default_rng([seed, i])``.
    fill_method : {"colorization", "complete"}
    weights : Weights
    solver : str
        ``"auto"`` or a name in :data:`~sparsedepth.SOLVERS`.
    tol : float >= 0, optional
    max_iter : int >= 1, optional
        Passed to :func:`~sparsedepth.complete_depth`.
    depth_scale : float > 0 or str, optional
        Divisor of integer depth files (:data:`~sparsedepth.io.DEPTH_SCALES`).
    downsample : int >= 1
        Keep every ``downsample``-th row and column (1 = full resolution).
    out_dir : str, optional
        An existing folder: each frame's output depth is written there as
        ``<name><out_format>`` (atomically).
    out_format : str
        ``".npy"``, ``".npz"``, ``".h5"``, ``".hdf5"``, ``".pfm"`` or
        ``".png"`` (16-bit, stored value = depth x ``out_scale``).
    out_scale : float > 0 or str
        PNG output scale.
    byteorder, invalid_values, min_depth, max_depth, max_pixels
        Passed to :func:`~sparsedepth.io.read_depth` for every depth and
        truth file (and ``max_pixels`` to :func:`~sparsedepth.io.read_image`):
        byte order of 16-bit binary Netpbm, stored values that mean "no
        measurement" (e.g. Kinect 2047, RealSense 65535), the metric range
        outside which depth counts as missing, and the largest image a header
        may declare.
    clip_to_observed : bool
        Passed to :func:`~sparsedepth.complete_depth`: keep each completed
        map within the range of its observed depths (the CSV's ``clamped``
        column counts the pixels this moved).

    Raises
    ------
    ValueError, TypeError
        A field out of range or of the wrong type; the exception's
        ``option`` attribute is the field name.
    FileNotFoundError
        ``out_dir`` does not exist.
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
    byteorder: str | None = None
    invalid_values: tuple = ()
    min_depth: float | None = None
    max_depth: float | None = None
    max_pixels: int | None = MAX_PIXELS
    clip_to_observed: bool = True

    def __post_init__(self):
        if self.task not in TASKS:
            raise _option_error("task", f"unknown task {self.task!r}; choose one of {list(TASKS)}")
        if self.keep_fraction is not None:
            if not is_real(self.keep_fraction):
                raise _option_error("keep_fraction", "keep_fraction must be a number in (0, 1] or None, got "
                                    f"{type(self.keep_fraction).__name__}", TypeError)
            if not 0 < self.keep_fraction <= 1:
                raise _option_error("keep_fraction", f"keep_fraction must be in (0, 1], got {self.keep_fraction!r}; "
                                    "e.g. 0.05 keeps 5 % of the valid depth pixels")
        if self.keep_count is not None and (not is_int(self.keep_count) or self.keep_count < 1):
            raise _option_error("keep_count", f"keep_count must be an integer >= 1 or None, got {self.keep_count!r}")
        if self.keep_fraction is not None and self.keep_count is not None:
            raise _option_error("keep_count", "give keep_fraction or keep_count, not both")
        if self.task == "fill" and (self.keep_fraction is not None or self.keep_count is not None):
            raise _option_error("keep_fraction", "keep_fraction/keep_count simulate sparse input; they do not apply "
                                "to task='fill'")
        if not is_int(self.seed) or self.seed < 0:
            raise _option_error("seed", f"seed must be an integer >= 0, got {self.seed!r}")
        if self.fill_method not in FILL_METHODS:
            raise _option_error("fill_method", f"unknown fill method {self.fill_method!r}; "
                                f"choose one of {list(FILL_METHODS)}")
        if not isinstance(self.weights, Weights):
            raise _option_error("weights", f"weights must be a sparsedepth.Weights, got {type(self.weights).__name__}; "
                                "e.g. Weights(gamma=0.0)", TypeError)
        if self.solver != "auto" and self.solver not in SOLVERS:
            raise _option_error("solver", f"unknown solver {self.solver!r}; choose one of "
                                f"{['auto', *sorted(SOLVERS)]}")
        if self.tol is not None and (not is_real(self.tol) or not math.isfinite(self.tol) or self.tol < 0):
            raise _option_error("tol", f"tol must be a finite number >= 0 or None (the solver's default), "
                                f"got {self.tol!r}")
        if self.max_iter is not None and (not is_int(self.max_iter) or self.max_iter < 1):
            raise _option_error("max_iter", f"max_iter must be an integer >= 1 or None, got {self.max_iter!r}")
        if self.depth_scale is not None:
            try:
                resolve_scale(self.depth_scale, "depth_scale")
            except (TypeError, ValueError) as exc:
                raise _option_error("depth_scale", str(exc), type(exc)) from None
        if not is_int(self.downsample) or self.downsample < 1:
            raise _option_error("downsample", f"downsample must be an integer >= 1, got {self.downsample!r}")
        if self.out_format not in (".npy", ".npz", ".h5", ".hdf5", ".pfm", ".png"):
            raise _option_error("out_format", f"unknown out_format {self.out_format!r}; "
                                "use .npy, .npz, .h5, .hdf5, .pfm or .png")
        try:
            resolve_scale(self.out_scale, "out_scale")
        except (TypeError, ValueError) as exc:
            raise _option_error("out_scale", str(exc), type(exc)) from None
        if self.byteorder not in (None, "big", "little"):
            raise _option_error("byteorder", f"byteorder must be 'big', 'little' or None, got {self.byteorder!r}")
        if not isinstance(self.invalid_values, tuple) or not all(is_real(v) for v in self.invalid_values):
            raise _option_error("invalid_values", f"invalid_values must be a tuple of numbers, got "
                                f"{self.invalid_values!r}", TypeError)
        for name in ("min_depth", "max_depth"):
            value = getattr(self, name)
            if value is not None and not (is_real(value) and math.isfinite(value) and value >= 0):
                raise _option_error(name, f"{name} must be a finite number >= 0 (metres) or None, got {value!r}")
        if self.min_depth is not None and self.max_depth is not None and self.min_depth > self.max_depth:
            raise _option_error("min_depth", f"min_depth {self.min_depth:g} is larger than max_depth "
                                f"{self.max_depth:g}")
        if self.max_pixels is not None and not (is_int(self.max_pixels) and self.max_pixels >= 1):
            raise _option_error("max_pixels", f"max_pixels must be an integer >= 1 or None, got {self.max_pixels!r}")
        if not isinstance(self.clip_to_observed, bool):
            raise _option_error("clip_to_observed", f"clip_to_observed must be True or False, got "
                                f"{self.clip_to_observed!r}", TypeError)
        if self.out_dir is not None:
            if not isinstance(self.out_dir, (str, os.PathLike)):
                raise _option_error("out_dir", f"out_dir must be a str or os.PathLike, got "
                                    f"{type(self.out_dir).__name__}", TypeError)
            if not Path(self.out_dir).is_dir():
                raise _option_error("out_dir", f"output folder '{self.out_dir}' does not exist; create it first",
                                    FileNotFoundError)


@dataclass(frozen=True)
class BatchSummary:
    """Counts of a finished batch and where its CSV is.

    Attributes
    ----------
    total : int
        Frames of the batch.
    succeeded, failed : int
        Frames whose row in the CSV is ``ok`` / an error, at the end.
    csv_path : str
    skipped : int
        Frames already done by an earlier run (kept, not recomputed);
        counted in ``succeeded``.
    rmse_ratio : float or None
        Mean over the scored ``ok`` rows of ``rmse / nn_rmse`` (the method's
        RMSE relative to nearest-neighbour fill; below 1 is better), None if
        no row is scored.
    scored : int
        Rows in that mean.
    """

    total: int
    succeeded: int
    failed: int
    csv_path: str
    skipped: int = 0
    rmse_ratio: float | None = None
    scored: int = 0


# --------------------------------------------------------------------------------------
# the worker
# --------------------------------------------------------------------------------------
_BLAS_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
_thread_limit = None  # kept alive in each worker process


def _init_worker() -> None:
    """Initializer of the default pool's worker processes.

    SIGINT is ignored (the driver decides what an interrupt does and ends
    the workers), SIGTERM gets its default action back (a forked worker
    inherits the driver's handler), and BLAS thread pools are pinned to one
    thread: the environment variables for libraries loaded from now on, and
    for those already loaded (a forked worker has the driver's) ``threadpoolctl``
    if installed, else the thread-count function of every loaded OpenBLAS.
    """
    global _thread_limit
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    for name in _BLAS_THREAD_VARIABLES:
        os.environ[name] = "1"
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        _set_openblas_threads(1)
        return
    _thread_limit = threadpool_limits(limits=1)


#: The thread-count functions of the OpenBLAS builds numpy and scipy wheels ship (symbol prefixes and suffixes vary).
_OPENBLAS_PREFIXES = ("openblas", "scipy_openblas")
_OPENBLAS_SUFFIXES = ("", "64_")


def _loaded_openblas():
    """The OpenBLAS libraries mapped into this process (from /proc/self/maps; empty elsewhere)."""
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            paths = {line.split()[-1] for line in maps if "openblas" in line.lower() and "/" in line}
    except OSError:
        return []
    libraries = []
    for path in sorted(paths):
        try:
            libraries.append(ctypes.CDLL(path))
        except OSError:
            continue
    return libraries


def _openblas_function(library, action):
    for prefix in _OPENBLAS_PREFIXES:
        for suffix in _OPENBLAS_SUFFIXES:
            function = getattr(library, f"{prefix}_{action}_num_threads{suffix}", None)
            if function is not None:
                return function
    return None


def _set_openblas_threads(count: int) -> None:
    """Set the thread count of every loaded OpenBLAS (what threadpoolctl does for it, without the dependency)."""
    for library in _loaded_openblas():
        function = _openblas_function(library, "set")
        if function is not None:
            function(ctypes.c_int(count))


def _openblas_threads() -> list[int]:
    """The thread count of every loaded OpenBLAS that reports one."""
    counts = []
    for library in _loaded_openblas():
        function = _openblas_function(library, "get")
        if function is not None:
            function.restype = ctypes.c_int
            counts.append(int(function()))
    return counts


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
    if isinstance(source, NYUH5Frame):
        image, depth = read_nyu_h5(source.path)
        return image, depth, None
    if source.depth is None:
        raise ValueError(f"no (unique) depth file for image '{source.image}'")
    image = read_image(source.image, max_pixels=options.max_pixels)
    reader = dict(scale=options.depth_scale, byteorder=options.byteorder, invalid_values=options.invalid_values,
                  min_depth=options.min_depth, max_depth=options.max_depth, max_pixels=options.max_pixels)
    depth = read_depth(source.depth, **reader)
    truth = None if source.truth is None else read_depth(source.truth, **reader)
    return image, depth, truth


def _fmt(value):
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if math.isnan(value) else f"{value:.6g}"
    return value


def _output_path(name: str, options: BatchOptions) -> Path:
    return Path(options.out_dir) / f"{name}{options.out_format}"


def _process(position: int, source, options: BatchOptions) -> dict:
    """Worker: one frame in, one CSV row out (errors become a row, never an exception).

    The output depth (with ``options.out_dir``) is written atomically: it
    appears complete, or not at all.
    """
    row = {"position": position, "name": source.name, "status": "ok"}
    try:
        image, depth, truth = _read_frame(source, options)
        step = options.downsample
        if step > 1:
            image, depth = image[::step, ::step], depth[::step, ::step]
            truth = None if truth is None else truth[::step, ::step]
        with warnings.catch_warnings():
            # the row's "clamped" column carries it; a worker never prints
            warnings.simplefilter("ignore", ClampWarning)
            out = evaluate_frame(
                image, depth, truth=truth, task=options.task, keep_fraction=options.keep_fraction,
                keep_count=options.keep_count, seed=np.random.default_rng([options.seed, position]),
                fill_method=options.fill_method, weights=options.weights, solver=options.solver,
                tol=options.tol, max_iter=options.max_iter, clip_to_observed=options.clip_to_observed,
            )
        row.update(height=depth.shape[0], width=depth.shape[1], observed=int(out.observed.sum()),
                   method=out.method, runtime=f"{out.runtime:.3f}",
                   converged="" if out.result is None else out.result.converged,
                   clamped="" if out.result is None else out.result.clamped)
        if out.metrics is not None:
            row.update(scored=out.metrics.count)
            for key in ("rmse", "mae", "rel", "delta1"):
                row[key] = _fmt(getattr(out.metrics, key))
                row["nn_" + key] = _fmt(getattr(out.nearest_metrics, key))
        if options.out_dir is not None:
            target = _output_path(source.name, options)
            write_depth(target, out.depth, scale=options.out_scale)
            row["output"] = str(target)
    except Exception as exc:  # noqa: BLE001 - a failing frame is reported, not fatal
        row.update(status="error", error=_one_line(exc))
    return row


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return f"{type(exc).__name__}: {text}"


# --------------------------------------------------------------------------------------
# the CSV, its settings, and resuming
# --------------------------------------------------------------------------------------
_LINE_END = "\r\n"  # the csv module's line terminator
_HEADER = ",".join(CSV_COLUMNS)
_SETTINGS_FORMAT = 1


def settings_path(csv_path) -> Path:
    """Where :func:`run_batch` keeps the settings fingerprint of ``csv_path``: ``<csv>.settings.json``."""
    csv_path = Path(csv_path)
    return csv_path.with_name(csv_path.name + ".settings.json")


def _fingerprint(frames, options: BatchOptions) -> dict:
    """The settings of a batch as plain JSON data: the options and the frame list (absolute paths)."""
    data = {
        "format": _SETTINGS_FORMAT,
        "options": dataclasses.asdict(options),
        "frames": [[type(f).__name__, *dataclasses.astuple(f)] for f in frames],
    }
    return json.loads(json.dumps(data, allow_nan=False))


def _settings_difference(stored, current) -> str:
    if not isinstance(stored, dict) or stored.get("format") != _SETTINGS_FORMAT:
        return "the settings file is not one this version writes"
    parts = []
    old, new = stored.get("options", {}), current["options"]
    changed = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
    if changed:
        parts.append("options " + ", ".join(changed))
    if stored.get("frames") != current["frames"]:
        before, after = stored.get("frames") or [], current["frames"]
        parts.append(f"the frame list ({len(before)} frames before, {len(after)} now)")
    return " and ".join(parts)


def _csv_line(row: dict) -> str:
    buffer = _io.StringIO()
    csv.DictWriter(buffer, fieldnames=CSV_COLUMNS, restval="", lineterminator=_LINE_END).writerow(row)
    return buffer.getvalue()


def _parse_line(line: str) -> dict:
    values = next(csv.reader([line]), [])
    return dict(zip(CSV_COLUMNS, values))


def _read_log(csv_path: Path) -> tuple[str, list[tuple[str, dict, str]]]:
    """(file text, [(name, row, line with its line end)]) of an existing batch CSV.

    A last line without its line end (a run killed while writing it) is
    dropped.
    """
    with open(csv_path, newline="", encoding="utf-8") as handle:
        text = handle.read()
    parts = text.split(_LINE_END)
    if parts[0] != _HEADER and not (len(parts) == 1 and _HEADER.startswith(parts[0])):
        raise ValueError(
            f"'{csv_path}' is not a batch CSV of this version (its first line is not the header "
            f"{_HEADER!r}); give another CSV path or overwrite=True (command line: --overwrite)"
        )
    entries = []
    for line in parts[1:-1]:
        row = _parse_line(line)
        entries.append((row.get("name", ""), row, line + _LINE_END))
    return text, entries


def _compact(entries, names) -> list[tuple[str, dict, str]]:
    """The last row of each frame of ``names``, in the order of those rows."""
    last = {name: i for i, (name, _, _) in enumerate(entries) if name in names}
    return [entries[i] for i in sorted(last.values())]


def _write_text_atomic(path: Path, text: str) -> None:
    with atomic_target(path) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as handle:
            handle.write(text)


def _is_done(row: dict, options: BatchOptions) -> bool:
    if row.get("status") != "ok":
        return False
    if options.out_dir is None:
        return True
    output = row.get("output", "")
    return bool(output) and Path(output).is_file()


def _remove_temporaries(names, options: BatchOptions) -> None:
    """Remove the temporary output files of these frames (left by a worker that was stopped)."""
    if options.out_dir is None:
        return
    folder = Path(options.out_dir)
    for name in names:
        target = _output_path(name, options)
        for tmp in folder.glob(f".{glob.escape(target.name)}.*.tmp*"):
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()


# --------------------------------------------------------------------------------------
# the driver
# --------------------------------------------------------------------------------------
def default_workers() -> int:
    """Worker processes of the default pool: half the CPUs this process may use, at least 1, at most 8.

    On a machine shared with other work (or with hyper-threading) one worker
    per core oversubscribes it: on a 2-core machine 1 worker is chosen.
    """
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # not on every platform
        cpus = os.cpu_count() or 1
    return max(1, min(cpus // 2, 8))


def _stop_pool(executor: ProcessPoolExecutor, *, terminate: bool) -> None:
    """Shut the default pool down; with ``terminate`` end its worker processes first."""
    if terminate:
        processes = list((getattr(executor, "_processes", None) or {}).values())
        for process in processes:
            with contextlib.suppress(Exception):
                process.terminate()
        for process in processes:
            with contextlib.suppress(Exception):
                process.join(5.0)
                if process.is_alive():
                    process.kill()
                    process.join(5.0)
    executor.shutdown(wait=True)


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
        ``overwrite`` is False.
    TypeError
        If a frame is not one of the frame types.
    OSError
        If the CSV cannot be written (e.g. a full disk); the rows written
        so far are kept.

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

    Memory is bounded by the frames in flight: each worker reads its own
    frame from disk and returns only a row.
    """
    frames = [absolute_frame(f) for f in frames]
    if not frames:
        raise ValueError("no frame to process")
    names = [f.name for f in frames]
    if len(set(names)) != len(names):
        duplicate = next(n for n in names if names.count(n) > 1)
        raise ValueError(f"frame names must be unique (they name the CSV rows and outputs); {duplicate!r} repeats")
    for value, name in ((max_workers, "max_workers"), (max_in_flight, "max_in_flight")):
        if value is not None and (not is_int(value) or value < 1):
            raise ValueError(f"{name} must be a positive integer or None, got {value!r}")
    options = BatchOptions() if options is None else options
    if not isinstance(options, BatchOptions):
        raise TypeError(f"options must be a BatchOptions, got {type(options).__name__}")
    if options.out_dir is not None:
        options = dataclasses.replace(options, out_dir=os.path.abspath(options.out_dir))
    csv_path = Path(os.path.abspath(csv_path))
    if not csv_path.parent.is_dir():
        raise FileNotFoundError(f"folder of the CSV file '{csv_path}' does not exist")
    settings = settings_path(csv_path)
    fingerprint = _fingerprint(frames, options)
    name_set = set(names)

    kept: list = []
    if csv_path.exists() and not overwrite:
        if not resume:
            raise ValueError(f"'{csv_path}' exists; pass resume=True to continue it or overwrite=True to start afresh")
        text, entries = _read_log(csv_path)
        try:
            stored = json.loads(settings.read_text(encoding="utf-8"))
        except FileNotFoundError:
            stored = None
        except ValueError:
            stored = {}
        if stored is None:
            if entries:
                raise ValueError(
                    f"'{csv_path}' has rows but no settings file '{settings.name}', so a resumed run cannot be "
                    "checked against it; give another CSV path or overwrite=True (command line: --overwrite)"
                )
            _write_text_atomic(settings, json.dumps(fingerprint, indent=1) + "\n")
        else:
            difference = _settings_difference(stored, fingerprint)
            if difference:
                raise ValueError(
                    f"'{csv_path}' was written with other settings ({difference} differ); to start it afresh pass "
                    "overwrite=True (command line: --overwrite), or give another CSV path"
                )
        kept = _compact(entries, name_set)
        compacted = _HEADER + _LINE_END + "".join(line for _, _, line in kept)
        if compacted != text:
            _write_text_atomic(csv_path, compacted)
    else:
        _write_text_atomic(settings, json.dumps(fingerprint, indent=1) + "\n")
        _write_text_atomic(csv_path, _HEADER + _LINE_END)

    latest = {name: row for name, row, _ in kept}
    done_before = {name for name, row in latest.items() if _is_done(row, options)}
    todo = [position for position, name in enumerate(names) if name not in done_before]
    skipped = len(frames) - len(todo)
    _remove_temporaries([names[p] for p in todo], options)

    appended = 0
    if todo:
        workers = max_workers or default_workers()
        in_flight = max_in_flight or 2 * workers
        own = executor is None
        if own:
            executor = ProcessPoolExecutor(max_workers=workers, initializer=_init_worker)
        pending: dict = {}
        stopped = False
        todo_left, retry, retried = deque(todo), deque(), set()
        try:
            with open(csv_path, "a", newline="", encoding="utf-8") as handle:

                def record(row: dict) -> None:
                    nonlocal appended
                    handle.write(_csv_line(row))
                    handle.flush()
                    appended += 1
                    latest[row["name"]] = row
                    if progress is not None:
                        progress(appended, len(todo), row)

                def submit_next() -> None:
                    nonlocal executor
                    while retry or todo_left:
                        position = retry.popleft() if retry else todo_left.popleft()
                        try:
                            future = executor.submit(_process, position, frames[position], options)
                        except BrokenExecutor as exc:
                            if not own:  # a given executor that takes no more work: the frame fails
                                record({"position": position, "name": names[position], "status": "error",
                                        "error": _one_line(exc)})
                                continue
                            _stop_pool(executor, terminate=True)
                            executor = ProcessPoolExecutor(max_workers=workers, initializer=_init_worker)
                            future = executor.submit(_process, position, frames[position], options)
                        pending[future] = position
                        return

                for _ in range(in_flight):
                    submit_next()
                while pending:
                    finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                    for future in finished:
                        position = pending.pop(future)
                        try:
                            row = future.result()
                        except (Exception, CancelledError) as exc:  # noqa: BLE001 - the executor failed
                            if own and isinstance(exc, BrokenExecutor) and position not in retried:
                                retried.add(position)  # a worker died (killed, out of memory): once more
                                retry.append(position)
                                submit_next()
                                continue
                            row = {"position": position, "name": names[position], "status": "error",
                                   "error": _one_line(exc)}
                        record(row)
                        submit_next()
        except BaseException:
            stopped = True
            raise
        finally:
            if own:  # the stopped pool fails its pending futures itself (cancelling them first upsets it)
                _stop_pool(executor, terminate=stopped)
            else:
                for future in pending:
                    future.cancel()
            _remove_temporaries([names[p] for p in pending.values()], options)
            if appended:
                with contextlib.suppress(OSError):  # a full disk: the appended log stays, compacted next run
                    _, entries = _read_log(csv_path)
                    kept = _compact(entries, name_set)
                    if len(kept) != len(entries):
                        _write_text_atomic(csv_path, _HEADER + _LINE_END + "".join(line for _, _, line in kept))

    rows = [latest[name] for name in names if name in latest]
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
