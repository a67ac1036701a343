"""What to do with every frame of a batch (:class:`BatchOptions`) and what a finished batch reports (:class:`BatchSummary`).

Every option is checked when :class:`BatchOptions` is made, so that a bad
option is one error before any frame runs; the exception's ``option``
attribute names the field, so that the command line can name its flag.

Imports the standard library, :mod:`sparsedepth._validation`,
:mod:`sparsedepth.io` (scales, pixel limit), the solver and fill-method
names, the completion qualities, :class:`~sparsedepth.Weights` and the shift
check of :mod:`sparsedepth.registration`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from .._validation import is_int, is_real
from ..holes import FILL_METHODS
from ..io import MAX_PIXELS
from ..io import resolve_scale
from ..io.formats import OUT_EXTENSIONS
from ..objective import DensitySchedule, Weights
from ..completion import QUALITIES, argument_conflict
from ..registration import check_image_shift
from ..solvers import SOLVERS
from .evaluate import TASKS

__all__ = ["BatchOptions", "BatchSummary"]


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
    weights : Weights, DensitySchedule or None
        ``None`` (default): the library's defaults (the density schedule
        evaluated per frame; see :func:`~sparsedepth.batch.evaluate.evaluate_frame`).
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
        An extension of :data:`sparsedepth.io.formats.OUT_EXTENSIONS`:
        ``".npy"``, ``".npz"``, ``".h5"``, ``".hdf5"``, ``".pfm"``, ``".tif"``,
        ``".tiff"`` or ``".png"`` (16-bit, stored value = depth x ``out_scale``).
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
    quality : {"default", "fast", "best"}
        Passed to :func:`~sparsedepth.complete_depth`: ``"fast"`` is the
        real-time mode, ``"best"`` the per-input choice by cross-validation
        on the samples (both with ``solver="auto"``, no ``tol`` or
        ``max_iter``; not with the colorization fill).
    image_shift : None, "auto" or pair of int
        Passed to :func:`~sparsedepth.batch.evaluate.evaluate_frame`: move
        each frame's image ``(dy, dx)`` pixels (after ``downsample``) to
        register it to the depth.  ``"auto"``: the batch measures one shift
        on up to 8 of its frames, spread evenly over the batch (each read and
        sampled as it is completed, done frames included, so that a rerun
        measures the same shift), pools their estimates
        (:func:`~sparsedepth.pool_image_shifts`) and uses it for every frame;
        (0, 0) when no frame gives an estimate (too few samples).  ``None``
        (default): no shift.  A pair is stored as a tuple of ints.
    uncertainty_dir : str, optional
        An existing folder other than ``out_dir``: each frame's per-pixel
        uncertainty (:func:`~sparsedepth.complete_depth`'s ``uncertainty``,
        two more solves) is written there as ``<name><out_format>``, a PNG
        at ``out_scale`` (saturating, see
        :func:`~sparsedepth.io.write_uncertainty`).  Not with the
        colorization fill or ``quality="fast"``.
    colmap_max_error : float >= 0, optional
    colmap_min_track : int >= 1, optional
        For :class:`~sparsedepth.batch.ColmapFrame` frames: passed to
        :func:`~sparsedepth.io.view_depth` as ``max_error`` (drop points
        whose mean reprojection error in pixels is above it) and
        ``min_track`` (drop points seen by fewer images).

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
    weights: Weights | DensitySchedule | None = None
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
    quality: str = "default"
    image_shift: tuple[int, int] | str | None = None
    uncertainty_dir: str | None = None
    colmap_max_error: float | None = None
    colmap_min_track: int | None = None

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
        if self.weights is not None and not isinstance(self.weights, (Weights, DensitySchedule)):
            raise _option_error("weights", f"weights must be a sparsedepth.Weights, a sparsedepth.DensitySchedule or "
                                f"None (the library's defaults), got {type(self.weights).__name__}; e.g. "
                                "Weights(gamma=0.0)", TypeError)
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
        if self.out_format not in OUT_EXTENSIONS:
            raise _option_error("out_format", f"unknown out_format {self.out_format!r}; "
                                f"use {', '.join(OUT_EXTENSIONS[:-1])} or {OUT_EXTENSIONS[-1]}")
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
        if self.colmap_max_error is not None and not (is_real(self.colmap_max_error)
                                                      and math.isfinite(self.colmap_max_error)
                                                      and self.colmap_max_error >= 0):
            raise _option_error("colmap_max_error", f"colmap_max_error must be a finite number >= 0 (pixels) or "
                                f"None, got {self.colmap_max_error!r}")
        if self.colmap_min_track is not None and (not is_int(self.colmap_min_track) or self.colmap_min_track < 1):
            raise _option_error("colmap_min_track", f"colmap_min_track must be an integer >= 1 or None, got "
                                f"{self.colmap_min_track!r}")
        self._check_quality()
        self._check_image_shift()
        for name, what in (("out_dir", "output folder"), ("uncertainty_dir", "uncertainty folder")):
            folder = getattr(self, name)
            if folder is None:
                continue
            if not isinstance(folder, (str, os.PathLike)):
                raise _option_error(name, f"{name} must be a str or os.PathLike, got {type(folder).__name__}",
                                    TypeError)
            if not Path(folder).is_dir():
                raise _option_error(name, f"{what} '{folder}' does not exist; create it first", FileNotFoundError)
        if self.uncertainty_dir is not None:
            if self.out_dir is None:
                raise _option_error("uncertainty_dir", "uncertainty_dir needs out_dir (the depth maps' folder)")
            if os.path.realpath(self.uncertainty_dir) == os.path.realpath(self.out_dir):
                raise _option_error("uncertainty_dir", f"the uncertainty folder '{self.uncertainty_dir}' is the "
                                    "output folder; the maps would have the depth maps' names: give another folder")

    def _check_image_shift(self):
        """``image_shift`` is None, ``"auto"`` or a pair of integers, stored as a tuple of ints."""
        try:
            shift = check_image_shift(self.image_shift)
        except (TypeError, ValueError) as exc:
            raise _option_error("image_shift", str(exc), type(exc)) from None
        object.__setattr__(self, "image_shift", shift)  # frozen: a list or NumPy pair is kept as a tuple of ints

    def _check_quality(self):
        """``quality`` is a known mode, and the options go together by the library's one table of rules."""
        if not isinstance(self.quality, str) or self.quality not in QUALITIES:
            raise _option_error("quality", f"quality must be one of {list(QUALITIES)}, got {self.quality!r}")
        colorization = self.task == "fill" and self.fill_method == "colorization"
        given = [name for name, value in (("colorization", colorization), ("quality", self.quality == "fast"),
                                          ("best", self.quality == "best"),
                                          ("weights", self.weights is not None), ("solver", self.solver != "auto"),
                                          ("tol", self.tol is not None), ("max_iter", self.max_iter is not None),
                                          ("uncertainty", self.uncertainty_dir is not None))
                 if value]
        conflict = argument_conflict(given)
        if conflict is not None:
            argument, why, excluded = conflict
            named = {"colorization": "the colorization fill (task='fill', fill_method='colorization')",
                     "quality": "quality='fast'", "best": "quality='best'",
                     "uncertainty": "uncertainty (uncertainty_dir)"}
            option = excluded[0] if argument == "colorization" else argument
            option = "quality" if option == "best" else option
            raise _option_error("uncertainty_dir" if option == "uncertainty" else option,
                                f"{named.get(argument, argument)} {why} "
                                f"{', '.join(named.get(name, name) for name in excluded)}")


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
    image_shift : tuple of int or None
        The ``(dy, dx)`` every frame's image is moved by: the option's pair,
        or with ``image_shift="auto"`` the shift measured for the batch
        ((0, 0) when no frame gave an estimate); None without the option.
    image_shift_frames : int or None
        With ``image_shift="auto"``: the frames the shift is measured on
        (those that gave an estimate); None otherwise.
    """

    total: int
    succeeded: int
    failed: int
    csv_path: str
    skipped: int = 0
    rmse_ratio: float | None = None
    scored: int = 0
    image_shift: tuple[int, int] | None = None
    image_shift_frames: int | None = None
