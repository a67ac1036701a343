"""The worker side of a batch: one frame in, one CSV row out.

:func:`process_frame` runs in a worker (a process of the pool, a thread, or
a Dask task): it reads the frame (a COLMAP view: its image and
:func:`~sparsedepth.io.view_depth` of the model, the model read once per
process), runs :func:`~sparsedepth.batch.evaluate_frame`, writes the output
depth (and uncertainty) atomically and returns the row as a dict.  A failing frame becomes an error
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
import os
import re
import threading
import warnings
from pathlib import Path

import numpy as np

from ..io import NYUDepthV2Labeled, read_colmap_model, read_depth, read_image, read_nyu_h5, view_depth, write_depth
from ..io.colmap import MODEL_FILES
from ..io.writing import uncertainty_writer
from ..io.files import atomic_target
from ..result import ClampWarning
from ..registration import ImageShift, estimate_image_shift
from .evaluate import evaluate_frame, frame_observations
from .frames import ColmapFrame, NYUFrame, NYUH5Frame
from .options import BatchOptions

__all__ = ["process_frame", "estimate_frame_shift", "output_path", "uncertainty_path", "remove_temporaries",
           "error_text", "one_line", "colmap_model"]

_MODEL_LOCK = threading.Lock()
_MODEL_CACHE: dict = {}  # {model folder: (its files' (size, mtime) stamps, ColmapModel)}, at most one model


def _model_stamp(folder: str) -> tuple:
    """(size, mtime) of every model file in ``folder`` (None for an absent one): a changed model reads anew."""
    stamps = []
    for stem in MODEL_FILES:
        for ext in (".bin", ".txt"):
            try:
                info = os.stat(os.path.join(folder, stem + ext))
            except OSError:
                stamps.append(None)
            else:
                stamps.append((info.st_size, info.st_mtime_ns))
    return tuple(stamps)


def colmap_model(model_dir, *, max_pixels=None):
    """The COLMAP model of ``model_dir``, read once per process while its files are unchanged.

    A batch's workers complete many views of one model: each worker process
    (or thread of a Dask worker) reads the model on its first view only.
    ``max_pixels`` is passed to :func:`~sparsedepth.io.read_colmap_model`
    (it is part of the cached entry's key).
    """
    folder = os.path.abspath(model_dir)
    key = (folder, max_pixels)
    stamp = _model_stamp(folder)
    with _MODEL_LOCK:
        cached = _MODEL_CACHE.get(key)
        if cached is not None and cached[0] == stamp:
            return cached[1]
    model = read_colmap_model(folder, name="model_dir", max_pixels=max_pixels)
    with _MODEL_LOCK:
        _MODEL_CACHE.clear()
        _MODEL_CACHE[key] = (stamp, model)
    return model


def _read_colmap_view(source: ColmapFrame, options: BatchOptions):
    """(image, sparse depth in model units) of one view: the image file and the model's points it observes."""
    if options.downsample > 1:
        raise ValueError("downsample does not apply to COLMAP views (a strided sparse map would lose most of "
                         "the model's points); complete them at full resolution")
    model = colmap_model(source.model_dir, max_pixels=options.max_pixels)
    view = model.image(source.image_id)
    if not os.path.isfile(source.image_path):
        raise FileNotFoundError(f"the COLMAP model registers image {view.name!r} (IMAGE_ID {source.image_id}) but "
                                f"its file '{source.image_path}' does not exist; put it in the image folder (or "
                                "give the folder the model was made from)")
    depth, _, _ = view_depth(model, source.image_id, max_error=options.colmap_max_error,
                             min_track=options.colmap_min_track)
    image = read_image(source.image_path, max_pixels=options.max_pixels)
    if image.shape[:2] != depth.shape:
        camera = model.cameras[view.camera_id]
        raise ValueError(f"image '{source.image_path}' is {image.shape[1]}x{image.shape[0]} (W x H) but camera "
                         f"{camera.id} of the COLMAP model, which it is registered with, is "
                         f"{camera.width}x{camera.height}; give the images the model was made from (after "
                         "`colmap image_undistorter`, its undistorted images)")
    return image, depth


def _read_frame(source, options: BatchOptions):
    """(image, depth, truth) of one frame, in metres (a COLMAP view: in the model's units, no truth)."""
    if isinstance(source, ColmapFrame):
        image, depth = _read_colmap_view(source, options)
        return image, depth, None
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
    """Where the output depth of frame ``name`` goes: ``<out_dir>/<name><out_format>``.

    A COLMAP view's name keeps the sub-folders of its image name
    (``cam1/00``), which the worker creates in ``out_dir``.
    """
    return Path(options.out_dir) / f"{name}{options.out_format}"


def uncertainty_path(name: str, options: BatchOptions) -> Path:
    """Where the uncertainty of frame ``name`` goes: ``<uncertainty_dir>/<name><out_format>``."""
    return Path(options.uncertainty_dir) / f"{name}{options.out_format}"


def process_frame(position: int, source, options: BatchOptions) -> dict:
    """Worker: one frame in, one CSV row out (errors become a row, never an exception).

    Parameters
    ----------
    position : int
        The frame's 0-based place in the batch: its sampling seed is
        ``numpy.random.default_rng([options.seed, position])``.
    source : FileFrame, NYUFrame, NYUH5Frame or ColmapFrame
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
    error row naming the file and ``out_dir``.  With
    ``options.uncertainty_dir`` the uncertainty map is encoded first and
    written before the depth; if the depth then cannot be written the
    uncertainty just written is removed, so that a frame leaves both or
    neither.  :class:`~sparsedepth.ClampWarning` is not shown: the row's
    ``clamped`` column carries it.  A COLMAP view's depth is in the model's
    units and has no ground truth (no metric columns); ``observed`` counts
    the pixels holding a model point (one point per pixel, the nearest).
    """
    row = {"position": position, "name": source.name, "status": "ok"}
    try:
        image, depth, truth = _prepared(source, options)
        with _clamp_warnings_quiet():  # the row's "clamped" column carries them; a worker never prints
            out = evaluate_frame(
                image, depth, truth=truth, task=options.task, keep_fraction=options.keep_fraction,
                keep_count=options.keep_count, seed=_sampling_seed(position, options),
                fill_method=options.fill_method, weights=options.weights, solver=options.solver,
                tol=options.tol, max_iter=options.max_iter, clip_to_observed=options.clip_to_observed,
                quality=options.quality, image_shift=options.image_shift,
                uncertainty=options.uncertainty_dir is not None,
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
            _write_outputs(target, out, source.name, options)
            row["output"] = str(target)
    except Exception as exc:  # noqa: BLE001 - a failing frame is reported, not fatal
        row.update(status="error", error=error_text(exc))
    return row


_QUIET_LOCK = threading.Lock()


@contextlib.contextmanager
def _clamp_warnings_quiet():
    """:class:`~sparsedepth.ClampWarning` not shown while a frame runs, in any thread.

    ``warnings.catch_warnings`` changes the filters of the whole process and restores them on exit, so in threads
    (a thread pool, a threaded Dask worker) one frame's exit would let another's warnings through, or drop filters
    set meanwhile.  In the main thread (a worker process of the default pool) the filter is set for the frame and
    restored; in any other thread it is set once for the process and left in place (worker threads run frames only).
    """
    if threading.current_thread() is threading.main_thread():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ClampWarning)
            yield
        return
    with _QUIET_LOCK:
        if not any(f[0] == "ignore" and f[2] is ClampWarning for f in warnings.filters):
            warnings.filterwarnings("ignore", category=ClampWarning)
    yield


def _write_outputs(target: Path, out, name: str, options: BatchOptions) -> None:
    """The frame's uncertainty (with ``uncertainty_dir``), then its depth; the uncertainty is removed again if the
    depth cannot be written."""
    if options.uncertainty_dir is None:
        _write_output(target, out.depth, options)
        return
    sigma_target = uncertainty_path(name, options)
    writer = uncertainty_writer(sigma_target, out.uncertainty, scale=options.out_scale)
    _make_parent(sigma_target, options.uncertainty_dir)
    try:
        with atomic_target(sigma_target) as tmp:
            writer(tmp)
    except OSError as exc:
        raise _write_error(exc, sigma_target, "uncertainty_dir", "--uncertainty") from exc
    try:
        _write_output(target, out.depth, options)
    except BaseException:
        with contextlib.suppress(OSError):
            sigma_target.unlink()
        raise


def _make_parent(target: Path, folder) -> None:
    """Create the sub-folders of ``folder`` that ``target`` is in (a COLMAP image name's folders)."""
    if target.parent != Path(folder):
        target.parent.mkdir(parents=True, exist_ok=True)


def _write_error(exc: OSError, target: Path, option: str, flag: str) -> OSError:
    reason = exc.strerror or one_line(exc)
    error = OSError(f"could not write the output '{target}' (`{option}`, command line {flag}): {reason}; "
                    f"free space (or choose another {flag}), then run the same batch again to redo this frame")
    error.errno = exc.errno
    return error


def _write_output(target: Path, depth, options: BatchOptions) -> None:
    """:func:`~sparsedepth.io.write_depth` of a frame's output; an ``OSError`` (a full disk) names the file and
    the option (``out_dir``, ``--outdir`` on the command line), with the system's reason."""
    try:
        _make_parent(target, options.out_dir)
        write_depth(target, depth, scale=options.out_scale)
    except OSError as exc:
        raise _write_error(exc, target, "out_dir", "--outdir") from exc


def one_line(exc: BaseException) -> str:
    """The message of ``exc`` on one line (its type name if it has none)."""
    return " ".join(str(exc).split()) or type(exc).__name__


def error_text(exc: BaseException) -> str:
    """The ``error`` cell of a failed frame: ``"<exception type>: <message on one line>"``."""
    return f"{type(exc).__name__}: {one_line(exc)}"


def remove_temporaries(names, options: BatchOptions) -> list[Path]:
    """Delete the temporary files that writes of these frames' outputs left (a worker stopped or killed mid-write).

    An output is written to ``.<name><ext>.<12 hex digits>.tmp<ext>`` beside its target and then renamed onto
    ``<name><ext>`` (:func:`~sparsedepth.io.files.atomic_target`); only files of that exact form, for the depth
    and (with ``options.uncertainty_dir``) uncertainty outputs of ``names``, in each output's own folder, are
    removed.

    Parameters
    ----------
    names : iterable of str
        Frame names (a COLMAP view's name may hold sub-folders).
    options : BatchOptions

    Returns
    -------
    list of Path
        The files removed.
    """
    if options.out_dir is None:
        return []
    suffix = re.compile(r"\.[0-9a-f]{12}\.tmp" + re.escape(options.out_format) + r"$")
    removed = []
    for name in names:
        targets = [output_path(name, options)]
        if options.uncertainty_dir is not None:
            targets.append(uncertainty_path(name, options))
        for target in targets:
            if not target.parent.is_dir():
                continue
            for tmp in target.parent.glob(f".{glob.escape(target.name)}.*.tmp*"):
                if suffix.fullmatch(tmp.name[len(target.name) + 1:]) is None or not tmp.is_file():
                    continue
                with contextlib.suppress(FileNotFoundError):
                    tmp.unlink()
                    removed.append(tmp)
    return removed