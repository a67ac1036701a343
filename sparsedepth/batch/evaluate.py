"""One frame: complete (or hole-fill) it and score it against the nearest-neighbour baseline.

:func:`evaluate_frame` is the per-frame pipeline shared by the command line
(one frame) and :func:`~sparsedepth.batch.run_batch` (many frames):
optionally simulate sparse input from a dense map, complete it (or fill the
holes of raw depth), compute the nearest-neighbour baseline and score both
against ground truth on the pixels the method did not see.

Imports NumPy and the library below :mod:`sparsedepth.batch` (completion,
hole filling, baselines, metrics, registration, sampling, validation); no
file is read or written here.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .._validation import check_same_shape
from ..baselines import nearest_fill
from ..completion import argument_conflict, complete_depth
from ..holes import FILL_METHODS, fill_holes
from ..holes.fill import hole_fill_weights
from ..metrics import DepthMetrics, depth_metrics
from ..objective import DensitySchedule, Weights
from ..registration import check_image_shift, estimate_image_shift, shift_image
from ..result import CompletionResult
from ..sampling import sample_mask, valid_depth_mask

__all__ = ["TASKS", "FrameOutcome", "evaluate_frame", "frame_observations"]

#: ``"complete"``: depth completion from (possibly simulated) sparse input;
#: ``"fill"``: hole filling of raw depth (every valid pixel observed).
TASKS = ("complete", "fill")


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
        Pixels scored: valid ``truth``, not ``observed``, and not left
        missing in ``depth`` (by a limit of the uncertainty or ``blowups="remove"``).
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
    uncertainty : ndarray, (H, W), or None
        ``result.uncertainty`` when it was asked for.
    image_shift : tuple of int
        ``(dy, dx)`` by which the image was moved (:func:`~sparsedepth.shift_image`)
        before the method ran; ``(0, 0)`` when it was not moved.
    image_shift_fallback : str or None
        With ``image_shift="auto"``: why no shift could be estimated (the
        message of :func:`~sparsedepth.estimate_image_shift`'s ``ValueError``;
        ``image_shift`` is then ``(0, 0)``); None otherwise.
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
    uncertainty: np.ndarray | None = None
    image_shift: tuple[int, int] = (0, 0)
    image_shift_fallback: str | None = None


def _depth_2d(depth, name):
    arr = np.asarray(depth)
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a 2-D (H, W) array, got shape {arr.shape}")
    return arr.astype(np.float64)  # a copy: inputs are never modified


def _check_task(task, fill_method, keep_fraction, keep_count) -> None:
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; choose one of {list(TASKS)}")
    if task == "fill" and fill_method not in FILL_METHODS:
        raise ValueError(f"unknown fill method {fill_method!r}; choose one of {list(FILL_METHODS)}")
    if task == "fill" and (keep_fraction is not None or keep_count is not None):
        raise ValueError("keep_fraction/keep_count simulate sparse input; they do not apply to task='fill'")


def _registered(image, sparse, observed, image_shift):
    """(image moved by the shift, (dy, dx), why ``"auto"`` fell back to no shift or None)."""
    fallback = None
    if image_shift is None:
        shift = (0, 0)
    elif image_shift == "auto":
        try:
            shift = estimate_image_shift(image, sparse, observed).shift
        except ValueError as exc:  # too few samples to estimate from: the frame is completed unshifted
            shift, fallback = (0, 0), " ".join(str(exc).split())
    else:
        shift = image_shift
    return (image if shift == (0, 0) else shift_image(image, shift)), shift, fallback


def _valid_pixels(image, values, mask) -> np.ndarray:
    """Valid pixels of ``values`` (finite and > 0), restricted to ``mask``; at least one."""
    check_same_shape(np.shape(image)[:2], values.shape, "image", "depth")
    valid = valid_depth_mask(values)
    if mask is not None:
        mask = np.asarray(mask)
        if mask.dtype != bool:
            raise ValueError(f"mask must be a boolean array, got dtype {mask.dtype}")
        check_same_shape(mask.shape, values.shape, "mask", "depth")
        valid &= mask
    if not valid.any():
        raise ValueError("depth has no valid pixel (all 0, NaN or inf, or outside the mask); nothing to complete from")
    return valid


def frame_observations(image, depth, *, mask=None, keep_fraction=None, keep_count=None, seed=0):
    """The observations :func:`evaluate_frame` gives the method: ``(values, valid, observed, sparse)``.

    ``values`` is ``depth`` as float64, ``valid`` its valid pixels (within
    ``mask``), ``observed`` those kept by the sampling (all of ``valid``
    without ``keep_fraction``/``keep_count``) and ``sparse`` the depth at
    ``observed``, NaN elsewhere.  ``ValueError`` for inconsistent shapes or
    no valid pixel.
    """
    values = _depth_2d(depth, "depth")
    valid = _valid_pixels(image, values, mask)
    if keep_fraction is not None or keep_count is not None:
        observed = sample_mask(np.where(valid, values, np.nan), fraction=keep_fraction, count=keep_count, seed=seed)
    else:
        observed = valid
    return values, valid, observed, np.where(observed, values, np.nan)


def _run_method(image, sparse, observed, task, fill_method, solve_options):
    """(dense depth, method name, CompletionResult or None, seconds) of the task on the observations."""
    result = None
    start = time.perf_counter()
    if task == "fill" and fill_method == "colorization":
        dense = fill_holes(image, sparse, mask=observed, method="colorization")
        method = "fill colorization"
    else:
        # fill_holes(method="complete") is exactly this call; calling it here keeps the solver result
        if task == "fill" and solve_options.get("quality") != "fast":
            solve_options = {**solve_options, "weights": hole_fill_weights(solve_options.get("weights"))}
        result = complete_depth(image, sparse, observed, **solve_options)
        dense = result.depth
        quality = solve_options.get("quality")
        mode = (", fast" if quality == "fast" else f", best: {result.selection.chosen}" if quality == "best"
                else "")
        method = f"{'fill complete' if task == 'fill' else 'complete'} ({result.solver}{mode})"
    return dense, method, result, time.perf_counter() - start


def _score(dense, nearest, truth, observed):
    """(scored pixels, metrics of ``dense``, metrics of ``nearest``) on valid ``truth`` not observed; Nones without."""
    scored = metrics = nearest_metrics = None
    if truth is not None:
        scored = valid_depth_mask(truth) & ~observed & ~np.isnan(dense)
        if scored.any():
            metrics = depth_metrics(dense, truth, mask=scored)
            nearest_metrics = depth_metrics(nearest, truth, mask=scored)
    return scored, metrics, nearest_metrics


# the numpydoc docstring is most of this function's length; its code is about 30 lines of named steps
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
    weights: Weights | DensitySchedule | None = None,
    solver: str = "auto",
    tol: float | None = None,
    max_iter: int | None = None,
    callback=None,
    clip_to_observed: bool = True,
    uncertainty: bool = False,
    max_uncertainty: float | None = None,
    max_relative_uncertainty: float | None = None,
    quality: str = "default",
    prior=None,
    prior_alignment: str = "scale_shift",
    image_shift=None,
    blowups: str | None = None,
    expected_error: bool = False,
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
    weights, solver, tol, max_iter, callback, clip_to_observed, uncertainty, max_uncertainty, quality
        Passed to :func:`~sparsedepth.complete_depth` (not used by the
        colorization fill, which refuses ``uncertainty``,
        ``max_uncertainty`` and ``quality``).  ``weights=None`` is the library's default:
        the density schedule for ``"complete"``, ``DEFAULT_WEIGHTS`` for the
        ``"fill"`` task's default solve (as :func:`~sparsedepth.fill_holes`).
    prior, prior_alignment
        Passed to :func:`~sparsedepth.complete_depth`: a dense depth map the
        user brings, aligned to the observations and completed around (not
        with the colorization fill, which refuses it).
    image_shift : None, "auto" or pair of int
        Register the image to the depth before the method runs: ``(dy, dx)``
        moves the image content ``dy`` rows down and ``dx`` columns right
        (:func:`~sparsedepth.shift_image`, border repeated); ``"auto"``
        estimates the shift from the observations the method is given
        (after ``mask`` and the sampling) with
        :func:`~sparsedepth.estimate_image_shift` at its defaults, and uses no
        shift, silently, when there are too few of them to estimate from
        (``FrameOutcome.image_shift_fallback`` says why).  ``None``: the image
        as it is.  The nearest-neighbour baseline does not use the image.
    max_relative_uncertainty, blowups, expected_error
        Passed to :func:`~sparsedepth.complete_depth` (the colorization fill
        refuses the first two); the pixels a limit or ``blowups="remove"``
        leaves missing are not scored.

    Returns
    -------
    FrameOutcome
        Scores are on ``scored = valid(truth) & ~observed``: the pixels the
        method did not see.

    Raises
    ------
    ValueError
        Unknown task or fill method, inconsistent shapes, no valid depth, a
        sampling option with ``task="fill"``, a string ``image_shift`` other
        than ``"auto"``, and the errors of the functions called.
    TypeError
        An ``image_shift`` that is not None, a string or a pair of integers.
    """
    _check_task(task, fill_method, keep_fraction, keep_count)
    image_shift = check_image_shift(image_shift)
    if task == "fill" and fill_method == "colorization":
        given = ["colorization"] + [name for name, value in (
            ("uncertainty", bool(uncertainty)),
            ("max_uncertainty", max_uncertainty is not None or max_relative_uncertainty is not None),
            ("prior", prior is not None), ("quality", quality == "fast"), ("best", quality == "best"),
            ("blowups", blowups is not None)) if value]
        conflict = argument_conflict(given)
        if conflict is not None:
            raise ValueError(f"the colorization fill {conflict[1]} {', '.join(conflict[2])}: use "
                             "fill_method='complete'")
    values, valid, observed, sparse = frame_observations(image, depth, mask=mask, keep_fraction=keep_fraction,
                                                         keep_count=keep_count, seed=seed)
    if truth is not None:
        truth = _depth_2d(truth, "truth")
        check_same_shape(truth.shape, values.shape, "truth", "depth")
    elif keep_fraction is not None or keep_count is not None:
        truth = np.where(valid, values, np.nan)
    image, shift, fallback = _registered(image, sparse, observed, image_shift)

    dense, method, result, runtime = _run_method(
        image, sparse, observed, task, fill_method,
        dict(weights=weights, solver=solver, tol=tol, max_iter=max_iter, callback=callback,
             clip_to_observed=clip_to_observed, uncertainty=uncertainty, max_uncertainty=max_uncertainty,
             max_relative_uncertainty=max_relative_uncertainty,
             quality=quality, prior=prior, prior_alignment=prior_alignment, blowups=blowups,
             expected_error=expected_error),
    )
    start = time.perf_counter()
    nearest = nearest_fill(sparse, observed)
    nearest_runtime = time.perf_counter() - start

    scored, metrics, nearest_metrics = _score(dense, nearest, truth, observed)
    return FrameOutcome(
        depth=dense, observed=observed, sparse=sparse, nearest=nearest, truth=truth, scored=scored, metrics=metrics,
        nearest_metrics=nearest_metrics, method=method, runtime=runtime, nearest_runtime=nearest_runtime,
        result=result, uncertainty=None if result is None else result.uncertainty, image_shift=shift,
        image_shift_fallback=fallback,
    )
