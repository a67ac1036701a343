"""Per-pixel uncertainty of a completed depth map, calibrated on the observations.

:func:`estimate_uncertainty` turns a completion and two completions from the
two halves of the samples into a map of standard-deviation-like errors;
:func:`error_cues`, :func:`fit_calibration` and :func:`split_samples` are its
steps.  :func:`sparsedepth.complete_depth` calls it for ``uncertainty=True``.

May import NumPy, SciPy, :mod:`sparsedepth.result` and
:mod:`sparsedepth._validation`; it never solves (the caller passes the
completions).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage, spatial

from ._validation import as_float_image, check_nonnegative_real
from .result import UncertaintyCalibration

__all__ = ["MIN_OBSERVED", "MIN_SHAPE", "TARGET_COVERAGE", "NOVELTY_WEIGHT", "NOVELTY_NEIGHBOURS", "split_samples",
           "error_cues", "colour_novelty", "fit_calibration", "estimate_uncertainty", "check_uncertainty_shape"]

#: Fewest observed pixels for which the uncertainty is estimated (each half keeps at least 8).
MIN_OBSERVED = 16

#: Coverage the calibration aims at on the held-out samples: |error| <= 1 sigma and <= 2 sigma.  Below a
#: Gaussian's 0.68 at 1 sigma because the map of the full completion covers more at 1 sigma than the held-out
#: fit (the extrapolation term, the mapping of the full cue); chosen on the tuning frames (``bench/frames.py``
#: ``TUNE_FRAMES``; ``python -m bench.uncertainty`` reports the coverage on the report frames: docs/uncertainty.md).
TARGET_COVERAGE = (0.62, 0.95)
#: How far each coverage may stray from its target before the other is preferred (the loss weights).
_COVERAGE_TOLERANCE = (0.08, 0.04)
#: A calibration loss this small is good enough to prefer a smaller offset (see :func:`fit_calibration`).
_GOOD_LOSS = 0.5
#: Depth fraction per unit of RGB distance (channels in [0, 1]) of the colour-novelty cue, and how many nearest
#: samples it compares with; chosen on the tuning frames (docs/uncertainty.md scores them on the report frames).
NOVELTY_WEIGHT = 0.8
NOVELTY_NEIGHBOURS = 8
_NOVELTY_CHUNK = 1 << 16


#: Smallest frame (rows, columns) with an uncertainty map: its cues take the depth gradient along both axes.
MIN_SHAPE = (2, 2)


def check_uncertainty_shape(shape, *, name: str = "uncertainty") -> None:
    """``ValueError`` unless a frame of ``shape`` ``(H, W, ...)`` has at least :data:`MIN_SHAPE` pixels.

    ``name`` labels the option in the message (``"uncertainty"`` for
    :func:`sparsedepth.complete_depth`, ``"--uncertainty"`` on the command
    line).  Call it before any solve: the map needs the gradient of the
    completed depth along both axes, which a 1 x N or N x 1 frame lacks.
    """
    H, W = (int(n) for n in tuple(shape)[:2])
    if H < MIN_SHAPE[0] or W < MIN_SHAPE[1]:
        raise ValueError(f"{name} needs a frame of at least {MIN_SHAPE[0]}x{MIN_SHAPE[1]} pixels (the map uses the "
                         f"depth gradient along both axes); this frame is {H}x{W} (H x W)")


def split_samples(observed, seed=0):
    """Two disjoint random halves ``(half_a, half_b)`` of the observed pixels (boolean (H, W) masks)."""
    index = np.flatnonzero(observed)
    order = np.random.default_rng(seed).permutation(index)
    half_a = np.zeros(observed.size, dtype=bool)
    half_a[order[: index.size // 2]] = True
    half_a = half_a.reshape(observed.shape)
    return half_a, observed & ~half_a


@dataclass(frozen=True)
class _SampleLayout:
    """Where the samples of a mask are: each pixel's nearest sample, its distance, and the mean spacing ``h``."""

    rows: np.ndarray
    cols: np.ndarray
    distance: np.ndarray
    spacing: float

    def nearest(self, values):
        """The nearest-sample fill of ``values`` (read at the samples)."""
        return values[self.rows, self.cols]


def _layout(observed) -> _SampleLayout:
    """One distance transform of ``~observed`` gives every pixel's nearest sample and its distance."""
    distance, (rows, cols) = ndimage.distance_transform_edt(~observed, return_indices=True)
    spacing = 1.0 / np.sqrt(np.count_nonzero(observed) / observed.size)
    return _SampleLayout(rows, cols, distance, spacing)


def _local_range(image, radius):
    """max - min of ``image`` over a (2 ceil(radius) + 1)² window around each pixel."""
    size = 2 * int(np.ceil(radius)) + 1
    return ndimage.maximum_filter(image, size) - ndimage.minimum_filter(image, size)


def error_cues(depth, sparse, observed):
    """The single-completion error cue of :func:`estimate_uncertainty` (same units as ``depth``).

    Parameters
    ----------
    depth : ndarray, (H, W)
        A completion from the samples ``observed``.
    sparse : ndarray, (H, W)
        Observed depth (read only where ``observed``).
    observed : ndarray of bool, (H, W)

    Returns
    -------
    ndarray, (H, W)
        ``|depth - z_nn| + |grad depth| d + R d / h`` (see Notes).

    Notes
    -----
    With ``z_nn`` the nearest-sample fill, ``d`` the distance to the nearest
    sample in pixels, ``h = (observed fraction)^(-1/2)`` the mean sample
    spacing and ``R`` the range (max - min) of ``z_nn`` over a window of
    half-width ``h``:

    * ``|depth - z_nn|`` is large where two interpolants disagree;
    * ``|grad depth| d`` is the change of depth between the pixel and its
      nearest sample if the slope holds;
    * ``R d / h`` is the depth step near the pixel (a depth edge among the
      nearby samples), weighted by how far the pixel is from a sample.
    """
    return _error_cues(depth, sparse, observed, _layout(observed))


def _error_cues(depth, sparse, observed, layout):
    """:func:`error_cues` with the sample layout of ``observed`` already computed."""
    nearest = layout.nearest(np.where(observed, sparse, 0.0))
    distance, spacing = layout.distance, layout.spacing
    grad_rows, grad_cols = np.gradient(depth)
    cue = np.abs(depth - nearest)
    cue += np.hypot(grad_rows, grad_cols) * distance
    cue += _local_range(nearest, spacing) * (distance / spacing)
    return cue


def fit_calibration(errors, cue):
    """``(slope, offset)`` of ``sigma = slope * cue + offset`` fitted to held-out ``|errors|``.

    Parameters
    ----------
    errors : array_like
        Held-out errors (signed or absolute).
    cue : array_like
        The cue at the same pixels (``>= 0``).

    Returns
    -------
    slope, offset : float

    Notes
    -----
    With ``c1`` and ``c2`` the fractions of ``|errors| <= sigma`` and
    ``<= 2 sigma`` and ``(t1, t2)`` = :data:`TARGET_COVERAGE`, the loss is
    ``max(|c1 - t1| / 0.08, |c2 - t2| / 0.04)``.  For each offset on a grid (0 and quantiles of ``|errors|``) the slope minimising
    the loss is found on a grid; the smallest offset whose loss is at most
    1/2 wins (the plain scale ``sigma = slope * cue`` when it covers well),
    else the pair of least loss.  The errors are heavy-tailed: the scale
    that covers 68 % at 1 sigma covers too little at 2 sigma, and the
    offset (a floor) lets both hold.
    """
    errors = np.abs(np.asarray(errors, dtype=np.float64))
    cue = np.asarray(cue, dtype=np.float64)
    cue = np.maximum(cue, 1e-12 * max(float(cue.max(initial=0.0)), float(errors.max(initial=0.0)), 1e-300))
    (c1, c2), (w1, w2) = TARGET_COVERAGE, _COVERAGE_TOLERANCE
    fits = []
    for offset in np.concatenate([[0.0], np.quantile(errors, np.linspace(0.02, 0.8, 40))]):
        ratio_1 = np.sort((errors - offset) / cue)        # sigma covers e  <=>  slope >= ratio_1
        ratio_2 = np.sort((errors / 2 - offset) / cue)    # 2 sigma covers e  <=>  slope >= ratio_2
        low = max(np.quantile(ratio_1, 0.3), 1e-12)
        high = max(np.quantile(ratio_2, 0.999), 1.01 * low)
        slopes = np.geomspace(low, high, 200)
        cover_1 = np.searchsorted(ratio_1, slopes, side="right") / ratio_1.size
        cover_2 = np.searchsorted(ratio_2, slopes, side="right") / ratio_2.size
        loss = np.maximum(np.abs(cover_1 - c1) / w1, np.abs(cover_2 - c2) / w2)
        k = int(np.argmin(loss))
        fits.append((float(loss[k]), float(offset), float(slopes[k])))
    good = [fit for fit in fits if fit[0] <= _GOOD_LOSS]
    loss, offset, slope = min(good, key=lambda fit: fit[1]) if good else min(fits)
    return slope, offset


def _held_out_error_map(held_out_a, held_out_b, half_a, half_b, layout):
    """The held-out errors, nearest-filled from the observed pixels and averaged over a window of half-width h."""
    errors = np.zeros(half_a.shape)
    errors[half_b] = held_out_a
    errors[half_a] = held_out_b
    return ndimage.uniform_filter(layout.nearest(errors), 2 * int(np.ceil(layout.spacing)) + 1)


def _quantile_map(values, reference, where):
    """``values`` mapped monotonically onto the distribution of ``reference`` (both sampled at ``where``)."""
    return np.interp(values, np.sort(values[where]), np.sort(reference[where]))


def colour_novelty(depth, image, observed, *, neighbours=NOVELTY_NEIGHBOURS):
    """``NOVELTY_WEIGHT * depth * min_k |I(p) - I(s_k)|`` over the ``neighbours`` nearest samples ``s_k`` of ``p``.

    A pixel whose colour none of its nearby samples shares may lie on a
    surface no sample touched (the background seen through a gap), at
    another depth than all of them.  Same units as ``depth``; colours in
    [0, 1] (:func:`sparsedepth._validation.as_float_image`), distances in RGB.
    """
    colours = as_float_image(image)
    samples = np.argwhere(observed)
    k = min(int(neighbours), samples.shape[0])
    tree = spatial.KDTree(samples)
    sample_colours = colours[samples[:, 0], samples[:, 1]]
    flat = colours.reshape(-1, colours.shape[-1])
    novelty = np.empty(flat.shape[0])
    width = observed.shape[1]
    for start in range(0, flat.shape[0], _NOVELTY_CHUNK):  # bounded memory: chunk x k x channels floats
        stop = min(start + _NOVELTY_CHUNK, flat.shape[0])
        pixels = np.arange(start, stop)
        _, nearest = tree.query(np.column_stack([pixels // width, pixels % width]), k=k)
        nearest = nearest.reshape(stop - start, k)
        novelty[start:stop] = np.linalg.norm(flat[start:stop, None, :] - sample_colours[nearest], axis=-1).min(axis=1)
    return NOVELTY_WEIGHT * depth * novelty.reshape(observed.shape)


def estimate_uncertainty(depth, depth_a, depth_b, sparse, half_a, half_b, image=None, *, precision=0.0):
    """Per-pixel uncertainty of ``depth`` from two completions of disjoint halves of its samples.

    Parameters
    ----------
    depth : ndarray, (H, W)
        The completion from all samples ``half_a | half_b``.
    depth_a, depth_b : ndarray, (H, W)
        Completions (same method and weights) from ``half_a`` and ``half_b`` only.
    sparse : ndarray, (H, W)
        Observed depth (read where observed).
    half_a, half_b : ndarray of bool, (H, W)
        Disjoint halves of the observed pixels (:func:`split_samples`).
    image : ndarray, (H, W, 3) or (H, W), optional
        The guide image; adds :func:`colour_novelty` to the cue.
    precision : float, default 0
        The precision to which ``depth`` was computed (depth units, ``>= 0``):
        the least ``sigma`` of an unobserved pixel.

    Returns
    -------
    sigma : ndarray, (H, W)
        Standard-deviation-like error estimate in the units of ``depth``;
        at an observed pixel, ``|depth - observation|``.
    calibration : UncertaintyCalibration

    Raises
    ------
    ValueError
        If the frame is smaller than :data:`MIN_SHAPE` (see
        :func:`check_uncertainty_shape`) or ``precision`` is negative.

    Notes
    -----
    The cue ranks the unobserved pixels by expected error; the calibration
    gives it units.

    *Cue.*  ``u = c(depth) + |depth_a - depth_b| + max(|depth - depth_a|,
    |depth - depth_b|) + E``, with ``c`` of :func:`error_cues`: the single-
    completion cue, how much the completion moves when half of the samples
    are left out (the split-sample jackknife spread), and ``E`` the local
    held-out error: each observation's error in the completion of the other
    half, nearest-filled and averaged over a window of half-width ``h`` (the
    mean sample spacing); with ``image``, also :func:`colour_novelty`.  Every
    part uses the depth values, not only where the samples are.

    *Calibration (on observations only).*  ``depth_a`` predicts each
    observation of ``half_b`` without having seen it, and ``depth_b`` each
    one of ``half_a``; these held-out errors ``e`` and the cue
    ``c(depth_a)`` (``c(depth_b)``) at the same pixels give
    ``sigma = slope * c + offset`` by :func:`fit_calibration`.  The
    single-completion cue transfers from half the samples to all of them
    (it scales with the sample spacing), the spread terms do not exist for
    a half; so ``u`` is first mapped monotonically onto the distribution of
    ``c(depth)`` over the unobserved pixels (same order as ``u``, the scale
    of ``c``), then calibrated: ``sigma = slope * map(u) + offset``.

    *Extrapolation.*  Held-out observations are never much farther than the
    mean spacing ``h`` from the others, so the calibration says nothing about
    pixels far from every sample (a sensor's border, the sky above a LiDAR).
    Beyond ``h`` the map grows by ``s90 * (d - h)``, with ``d`` the distance
    to the nearest sample and ``s90`` the 90th percentile of ``|grad depth|``
    over the unobserved pixels within ``h`` of a sample: the depth change a
    steep slope of this scene would make where nothing was seen.  This term
    is a prior, not calibrated; :func:`sparsedepth.complete_depth`'s
    ``max_uncertainty`` uses it to leave such regions missing.

    *Floor.*  Where every cue vanishes (a plane the samples fit exactly, with
    no fitted offset) the line gives ``sigma`` near 0, below the error the
    solver leaves; ``sigma`` is at least ``precision`` there.
    """
    precision = check_nonnegative_real(precision, name="precision")
    check_uncertainty_shape(np.shape(depth))
    observed = half_a | half_b
    unobserved = ~observed
    held_out_a = np.abs(depth_a - sparse)[half_b]  # half a's errors where half b observed
    held_out_b = np.abs(depth_b - sparse)[half_a]
    layout = _layout(observed)
    cue_full = _error_cues(depth, sparse, observed, layout)
    cue = (cue_full + np.abs(depth_a - depth_b) + np.maximum(np.abs(depth - depth_a), np.abs(depth - depth_b))
           + _held_out_error_map(held_out_a, held_out_b, half_a, half_b, layout))
    if image is not None:
        cue += colour_novelty(depth, image, observed)

    cue_a, cue_b = error_cues(depth_a, sparse, half_a), error_cues(depth_b, sparse, half_b)
    held_out_errors = np.concatenate([held_out_a, held_out_b])
    held_out_cue = np.concatenate([cue_a[half_b], cue_b[half_a]])
    slope, offset = fit_calibration(held_out_errors, held_out_cue)
    held_out_sigma = slope * held_out_cue + offset
    calibration = UncertaintyCalibration(
        slope=slope, offset=offset, held_out=int(held_out_errors.size),
        coverage_1sigma=float(np.mean(held_out_errors <= held_out_sigma)),
        coverage_2sigma=float(np.mean(held_out_errors <= 2 * held_out_sigma)),
    )

    sigma = np.abs(depth - np.where(observed, sparse, depth))
    if unobserved.any():
        sigma[unobserved] = np.maximum(slope * _quantile_map(cue, cue_full, unobserved) + offset
                                       + _extrapolation_term(depth, observed, layout), precision)[unobserved]
    return sigma, calibration


def _extrapolation_term(depth, observed, layout):
    """``s90 * max(d - h, 0)``: the depth change a steep slope would make beyond one sample spacing."""
    distance, spacing = layout.distance, layout.spacing
    grad_rows, grad_cols = np.gradient(depth)
    slope = np.hypot(grad_rows, grad_cols)
    interpolated = (distance <= spacing) & ~observed
    if not interpolated.any():
        return np.zeros(depth.shape)
    steep = float(np.percentile(slope[interpolated], 90))
    return steep * np.maximum(distance - spacing, 0.0)
