"""The worker side of a batch: one frame in, one CSV row out.

:func:`process_frame` runs in a worker (a process of the pool, a thread, or
a Dask task): it reads the frame, runs
:func:`~sparsedepth.batch.evaluate_frame`, writes the output depth
atomically and returns the row as a dict.  A failing frame becomes an error
row, never an exception.  :func:`estimate_frame_shift` reads and samples a
frame the same way and estimates its image shift (for a batch's
``image_shift="auto"``).

Imports NumPy, :mod:`sparsedepth.io`, :mod:`sparsedepth.registration`,
:mod:`sparsedepth.result` and the frame, option and evaluation modules of
:mod:`sparsedepth.batch`.
"""

from __future__ import annotations

import contextlib
import glob
import math
import warnings
from pathlib import Path

import numpy as np

from ..io import NYUDepthV2Labeled, read_depth, read_image, read_nyu_h5, write_depth
from ..result import ClampWarning
from ..registration import ImageShift, estimate_image_shift
from .evaluate import evaluate_frame, frame_observations
from .frames import NYUFrame, NYUH5Frame
from .options import BatchOptions

__all__ = ["process_frame", "estimate_frame_shift", "output_path", "remove_temporaries", "error_text", "one_line"]


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
    if source.problem is not None:
        raise ValueError(source.problem)
    if source.depth is None:
        raise ValueError(f"no depth file for image '{source.image}'")
    image = read_image(source.image, max_pixels=options.max_pixels)
    reader = dict(scale=options.depth_scale, byteorder=options.byteorder, invalid_values=options.invalid_values,
                  min_depth=options.min_depth, max_depth=options.max_depth, max_pixels=options.max_pixels)
    depth = read_depth(source.depth, **reader)
    truth = None if source.truth is None else read_depth(source.truth, **reader)
    return image, depth, truth


def _prepared(source, options: BatchOptions):
    """(image, depth, truth) of one frame as the batch completes it: read, then ``options.downsample``."""
    image, depth, truth = _read_frame(source, options)
    step = options.downsample
    if step > 1:
        image, depth = image[::step, ::step], depth[::step, ::step]
        truth = None if truth is None else truth[::step, ::step]
    return image, depth, truth


def _sampling_seed(position: int, options: BatchOptions) -> np.random.Generator:
    """The sampling seed of the frame at ``position``: ``default_rng([options.seed, position])``."""
    return np.random.default_rng([options.seed, position])


def estimate_frame_shift(position: int, source, options: BatchOptions) -> ImageShift | None:
    """Worker: the image shift estimated from one frame's observations, None if the frame gives none.

    The frame is read, downsampled and sampled exactly as :func:`process_frame`
    does (same seed), and :func:`~sparsedepth.estimate_image_shift` runs at its
    defaults on the observations the method would be given.  A frame that
    fails to read, or has too few observations to estimate from, gives None
    (its own row reports a read error when it runs).
    """
    try:
        image, depth, _ = _prepared(source, options)
        _, _, observed, sparse = frame_observations(image, depth, keep_fraction=options.keep_fraction,
                                                    keep_count=options.keep_count,
                                                    seed=_sampling_seed(position, options))
        return estimate_image_shift(image, sparse, observed)
    except Exception:  # noqa: BLE001 - a frame without an estimate is left out of the measurement
        return None


def _fmt(value):
    """A CSV cell: "" for None and NaN, 6 significant digits for a float."""
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if math.isnan(value) else f"{value:.6g}"
    return value


def output_path(name: str, options: BatchOptions) -> Path:
    """Where the output depth of frame ``name`` goes: ``<out_dir>/<name><out_format>``."""
    return Path(options.out_dir) / f"{name}{options.out_format}"


def process_frame(position: int, source, options: BatchOptions) -> dict:
    """Worker: one frame in, one CSV row out (errors become a row, never an exception).

    Parameters
    ----------
    position : int
        The frame's 0-based place in the batch: its sampling seed is
        ``numpy.random.default_rng([options.seed, position])``.
    source : FileFrame, NYUFrame or NYUH5Frame
        Read here, in the worker.
    options : BatchOptions

    Returns
    -------
    dict
        The CSV row: columns of :data:`~sparsedepth.batch.CSV_COLUMNS`;
        ``status`` is ``"ok"``, or ``"error"`` with the message in ``error``.

    Notes
    -----
    The output depth (with ``options.out_dir``) is written atomically: it
    appears complete, or not at all; a failed write (a full disk) is an
    error row naming the file and ``out_dir``.  :class:`~sparsedepth.ClampWarning` is
    not shown: the row's ``clamped`` column carries it.
    """
    row = {"position": position, "name": source.name, "status": "ok"}
    try:
        image, depth, truth = _prepared(source, options)
        with warnings.catch_warnings():
            # the row's "clamped" column carries it; a worker never prints
            warnings.simplefilter("ignore", ClampWarning)
            out = evaluate_frame(
                image, depth, truth=truth, task=options.task, keep_fraction=options.keep_fraction,
                keep_count=options.keep_count, seed=_sampling_seed(position, options),
                fill_method=options.fill_method, weights=options.weights, solver=options.solver,
                tol=options.tol, max_iter=options.max_iter, clip_to_observed=options.clip_to_observed,
                quality=options.quality, image_shift=options.image_shift,
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
            target = output_path(source.name, options)
            _write_output(target, out.depth, options)
            row["output"] = str(target)
    except Exception as exc:  # noqa: BLE001 - a failing frame is reported, not fatal
        row.update(status="error", error=error_text(exc))
    return row


def _write_output(target: Path, depth, options: BatchOptions) -> None:
    """:func:`~sparsedepth.io.write_depth` of a frame's output; an ``OSError`` (a full disk) names the file and
    the option (``out_dir``, ``--outdir`` on the command line), with the system's reason."""
    try:
        write_depth(target, depth, scale=options.out_scale)
    except OSError as exc:
        reason = exc.strerror or one_line(exc)
        error = OSError(f"could not write the output '{target}' (`out_dir`, command line --outdir): {reason}; "
                        "free space (or choose another --outdir), then run the same batch again to redo this frame")
        error.errno = exc.errno
        raise error from exc


def one_line(exc: BaseException) -> str:
    """The message of ``exc`` on one line (its type name if it has none)."""
    return " ".join(str(exc).split()) or type(exc).__name__


def error_text(exc: BaseException) -> str:
    """The ``error`` cell of a failed frame: ``"<exception type>: <message on one line>"``."""
    return f"{type(exc).__name__}: {one_line(exc)}"


def remove_temporaries(names, options: BatchOptions) -> None:
    """Remove the temporary output files of these frames (left by a worker that was stopped)."""
    if options.out_dir is None:
        return
    folder = Path(options.out_dir)
    for name in names:
        target = output_path(name, options)
        for tmp in folder.glob(f".{glob.escape(target.name)}.*.tmp*"):
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
