"""Per-pixel uncertainty of a completed depth map, calibrated on the observations.

:func:`estimate_uncertainty` turns a completion and two completions from the
two halves of the samples into a map of standard-deviation-like errors;
:func:`error_cues`, :func:`fit_calibration` and :func:`split_samples` are its
steps.  :func:`sparsedepth.complete_depth` calls it for ``uncertainty=True``.
:func:`too_uncertain` marks the pixels whose uncertainty exceeds a limit in
metres or a fraction of their depth.

May import NumPy, SciPy, :mod:`sparsedepth.result` and
:mod:`sparsedepth._validation`; it never solves (the caller passes the
completions).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage, spatial

from ._validation import as_float_image, check_nonnegative_real, check_positive_finite
from .result import UncertaintyCalibration

__all__ = ["MIN_OBSERVED", "MIN_SHAPE", "TARGET_COVERAGE", "NOVELTY_WEIGHT", "NOVELTY_NEIGHBOURS", "split_samples",
           "error_cues", "colour_novelty", "fit_calibration", "estimate_uncertainty", "check_uncertainty_shape",
           "check_relative_limit", "too_uncertain"]

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
#: Pixels per step of :func:`colour_novelty` (bounded memory: step x candidates floats per array).
_NOVELTY_CHUNK = 1 << 13
#: Side of the pixel blocks of :func:`colour_novelty` and the nearest samples of a block's centre searched for the
#: neighbours of its pixels (see its Notes).
_NOVELTY_BLOCK = 6
_NOVELTY_CANDIDATES = 28


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
    """Where the samples of a mask are: each pixel's nearest sample (flat index), its distance, and the spacing ``h``.

    ``distance`` is ``None`` for a layout made with ``distance=False``
    (:meth:`distance_at` gives it at chosen pixels).
    """

    index: np.ndarray
    distance: np.ndarray | None
    spacing: float

    def nearest(self, values):
        """The nearest-sample fill of ``values`` (read at the samples)."""
        return values.ravel()[self.index]

    def distance_at(self, pixels):
        """The distance from each of ``pixels`` (flat indices) to its nearest sample."""
        width = self.index.shape[1]
        rows, cols = np.divmod(pixels, width)
        sample_rows, sample_cols = np.divmod(self.index.ravel()[pixels], width)
        return np.sqrt(((sample_rows - rows) ** 2 + (sample_cols - cols) ** 2).astype(np.float64))


def _layout(observed, *, distance=True) -> _SampleLayout:
    """One distance transform of ``~observed`` gives every pixel's nearest sample and its distance."""
    rows, cols = ndimage.distance_transform_edt(~observed, return_distances=False, return_indices=True)
    height, width = observed.shape
    index = rows.astype(np.intp) * width + cols
    spacing = 1.0 / np.sqrt(np.count_nonzero(observed) / observed.size)
    if not distance:
        return _SampleLayout(index, None, spacing)
    rows -= np.arange(height, dtype=rows.dtype)[:, None]
    cols -= np.arange(width, dtype=cols.dtype)[None, :]
    rows *= rows
    cols *= cols
    rows += cols
    return _SampleLayout(index, np.sqrt(rows.astype(np.float64)), spacing)


def _local_range(image, radius):
    """max - min of ``image`` over a (2 ceil(radius) + 1)² window around each pixel."""
    size = 2 * int(np.ceil(radius)) + 1
    return ndimage.maximum_filter(image, size) - ndimage.minimum_filter(image, size)


def _local_range_at(image, radius, rows, cols):
    """:func:`_local_range` at pixels ``(rows, cols)`` only.

    The filters' ``reflect`` border repeats pixels of the window, so the
    window's extremes are those of the window clipped to the image: the
    extremes along the rows are filtered over the whole image, those of
    their columns read at the pixels.
    """
    half = int(np.ceil(radius))
    row_max = ndimage.maximum_filter1d(image, 2 * half + 1, axis=1)
    row_min = ndimage.minimum_filter1d(image, 2 * half + 1, axis=1)
    window = np.clip(rows[:, None] + np.arange(-half, half + 1), 0, image.shape[0] - 1)
    return row_max[window, cols[:, None]].max(axis=1) - row_min[window, cols[:, None]].min(axis=1)


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
    return _error_cues(depth, sparse, observed, _layout(observed))[0]


def _error_cues(depth, sparse, observed, layout):
    """:func:`error_cues` with the sample layout of ``observed`` already computed, and ``|grad depth|``."""
    nearest = layout.nearest(np.where(observed, sparse, 0.0))
    distance, spacing = layout.distance, layout.spacing
    grad_rows, grad_cols = np.gradient(depth)
    slope = np.hypot(grad_rows, grad_cols)
    cue = np.abs(depth - nearest)
    cue += slope * distance
    cue += _local_range(nearest, spacing) * (distance / spacing)
    return cue, slope


def _error_cues_at(depth, sparse, observed, pixels):
    """:func:`error_cues` at ``pixels`` only (flat indices), as the whole map would give them there."""
    layout = _layout(observed, distance=False)
    nearest = layout.nearest(np.where(observed, sparse, 0.0))
    spacing = layout.spacing
    height, width = depth.shape
    rows, cols = np.divmod(pixels, width)
    flat = depth.ravel()
    distance = layout.distance_at(pixels)
    slope = np.hypot(_central_difference(flat, rows, cols, 0, height, width),
                     _central_difference(flat, rows, cols, 1, height, width))
    cue = np.abs(flat[pixels] - nearest.ravel()[pixels])
    cue += slope * distance
    cue += _local_range_at(nearest, spacing, rows, cols) * (distance / spacing)
    return cue


def _central_difference(flat, rows, cols, axis, height, width):
    """:func:`numpy.gradient` of the (height, width) image ``flat`` along ``axis`` at pixels ``(rows, cols)``."""
    place, size, stride = (rows, height, width) if axis == 0 else (cols, width, 1)
    before, after = np.maximum(place - 1, 0), np.minimum(place + 1, size - 1)
    here = rows * width + cols
    return (flat[here + (after - place) * stride] - flat[here + (before - place) * stride]) / (after - before)


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
        ratio_1 = (errors - offset) / cue        # sigma covers e  <=>  slope >= ratio_1
        ratio_2 = (errors / 2 - offset) / cue    # 2 sigma covers e  <=>  slope >= ratio_2
        low = max(np.quantile(ratio_1, 0.3), 1e-12)
        high = max(np.quantile(ratio_2, 0.999), 1.01 * low)
        slopes = np.geomspace(low, high, 200)
        cover_1, cover_2 = _covered(ratio_1, slopes), _covered(ratio_2, slopes)
        loss = np.maximum(np.abs(cover_1 - c1) / w1, np.abs(cover_2 - c2) / w2)
        k = int(np.argmin(loss))
        fits.append((float(loss[k]), float(offset), float(slopes[k])))
    good = [fit for fit in fits if fit[0] <= _GOOD_LOSS]
    loss, offset, slope = min(good, key=lambda fit: fit[1]) if good else min(fits)
    return slope, offset


def _covered(ratios, slopes):
    """The fraction of ``ratios`` at most each of the increasing ``slopes`` (one binary search per ratio)."""
    below = np.bincount(np.searchsorted(slopes, ratios), minlength=slopes.size + 1)[:-1]
    return np.cumsum(below) / ratios.size


def _held_out_error_map(held_out_a, held_out_b, half_a, half_b, layout):
    """The held-out errors, nearest-filled from the observed pixels and averaged over a window of half-width h."""
    errors = np.zeros(half_a.shape)
    errors[half_b] = held_out_a
    errors[half_a] = held_out_b
    return ndimage.uniform_filter(layout.nearest(errors), 2 * int(np.ceil(layout.spacing)) + 1)


def _quantile_map(values, reference, where):
    """``values[where]`` mapped monotonically onto the distribution of ``reference[where]``.

    Each value takes the reference value of its rank: with ``v`` the sorted
    ``values[where]`` and ``r`` the sorted ``reference[where]``, ``v_i``
    maps onto ``r_j``, ``j`` the last rank of the values equal to ``v_i``
    (what ``numpy.interp(values, v, r)`` gives at the points of ``v``).
    """
    source, target = values[where], np.sort(reference[where])
    order = np.argsort(source)
    ranked = source[order]
    if not (np.isfinite(ranked[0]) and np.isfinite(ranked[-1])):  # NaN sorts last
        return np.interp(source, ranked, target)
    last = np.empty(ranked.size, dtype=bool)                        # the last of a run of equal values
    np.not_equal(ranked[1:], ranked[:-1], out=last[:-1])
    last[-1] = True
    run = np.cumsum(last) - last                                    # the run of each rank
    mapped = np.empty_like(source)
    mapped[order] = target[np.flatnonzero(last)[run]]
    return mapped


def colour_novelty(depth, image, observed, *, neighbours=NOVELTY_NEIGHBOURS):
    """``NOVELTY_WEIGHT * depth * min_k |I(p) - I(s_k)|`` over the ``neighbours`` nearest samples ``s_k`` of ``p``.

    A pixel whose colour none of its nearby samples shares may lie on a
    surface no sample touched (the background seen through a gap), at
    another depth than all of them.  Same units as ``depth``; colours in
    [0, 1] (:func:`sparsedepth._validation.as_float_image`), distances in RGB.

    Notes
    -----
    The pixels are taken in blocks of :data:`_NOVELTY_BLOCK` x
    :data:`_NOVELTY_BLOCK`; one KD-tree query gives the
    :data:`_NOVELTY_CANDIDATES` nearest samples of a block's centre ``q``,
    the ``K``-th of them at distance ``R``.  Every sample within ``r`` of a
    pixel ``p`` of the block is within ``r + |p - q|`` of ``q``, so it is a
    candidate whenever ``r + |p - q| < R``: with ``r = d_k``, the distance
    of ``p``'s ``k``-th nearest candidate, the candidates hold every sample
    at most ``d_k`` from ``p`` and the ``k`` nearest are found among them.
    Where several samples lie at distance ``d_k`` and only some of them
    count, the KD-tree's choice decides; if that choice can change the
    minimum (a tied sample's colour is nearer than every closer sample's), or
    the test fails (the block's candidates do not reach far enough, as in a
    large gap), the pixel is queried on its own.  The result is that of one
    KD-tree query per pixel.
    """
    colours = as_float_image(image)
    observed = np.asarray(observed, dtype=bool)
    samples = np.argwhere(observed)
    tree = spatial.KDTree(samples)
    k = min(int(neighbours), samples.shape[0])
    distance = _nearest_sample_colour_distance(image, colours, samples, tree, k)
    distance[observed] = 0.0  # a sample is its own nearest sample
    queried = np.flatnonzero(np.isnan(distance) & ~observed)
    if queried.size:
        distance.ravel()[queried] = _queried_colour_distance(colours, samples, tree, k, queried)
    return NOVELTY_WEIGHT * depth * distance


def _queried_colour_distance(colours, samples, tree, k, pixels):
    """The least RGB distance from each of ``pixels`` (flat indices) to its ``k`` nearest samples by a KD-tree query."""
    width, channels = colours.shape[1], colours.shape[-1]
    flat = colours.reshape(-1, channels)
    sample_colours = colours[samples[:, 0], samples[:, 1]]
    distance = np.empty(pixels.size)
    for start in range(0, pixels.size, _NOVELTY_CHUNK):  # bounded memory: chunk x k x channels floats
        chunk = pixels[start: start + _NOVELTY_CHUNK]
        _, nearest = tree.query(np.column_stack([chunk // width, chunk % width]), k=k)
        nearest = nearest.reshape(chunk.size, k)
        distance[start: start + chunk.size] = np.linalg.norm(flat[chunk, None, :] - sample_colours[nearest],
                                                             axis=-1).min(axis=1)
    return distance


def _nearest_sample_colour_distance(image, colours, samples, tree, k):
    """:func:`colour_novelty`'s colour distance where a block's candidates decide it, NaN elsewhere (see its Notes).

    Squared distances are inner products of augmented vectors, ``|a - b|**2 =
    (a, |a|**2, 1) . (-2 b, 1, |b|**2)``, one matrix product per block: exact
    for pixel coordinates (integers; float32 while every partial sum stays
    below 2**23) and for a uint8 ``image``'s codes (integers below 2**20 in
    float32; the distance is then divided by 255).  Other images are
    compared channel by channel in float64.  The arrays hold a block's
    candidates along the middle axis and its pixels along the last, so the
    reductions over the candidates run along long rows.
    """
    height, width, channels = colours.shape
    block = _NOVELTY_BLOCK
    block_rows, block_cols = -(-height // block), -(-width // block)
    candidates = min(_NOVELTY_CANDIDATES, samples.shape[0])
    centre = (block - 1) / 2
    corners = np.stack(np.meshgrid(np.arange(block_rows) * block, np.arange(block_cols) * block, indexing="ij"),
                       axis=-1).reshape(-1, 2)
    reach, nearest = tree.query(corners + centre, k=candidates)
    nearest = nearest.reshape(-1, candidates)
    if candidates < samples.shape[0]:
        reach = reach.reshape(-1, candidates)[:, -1] * (1 - 1e-12)  # a margin over rounding for the test below
        farthest = float(reach.max())
    else:
        reach, farthest = np.full(len(corners), np.inf), float(height + width)  # every sample is a candidate
    place_type = np.float32 if (farthest + 3 * block) ** 2 < 2 ** 23 else np.float64
    places = np.stack(np.divmod(np.arange(block * block), block), axis=-1)        # (block**2, 2) place in a block
    off_centre = np.hypot(places[:, 0] - centre, places[:, 1] - centre)
    pixel_places = _augmented(places.astype(place_type), 1)                       # (block**2, 4)
    pixel_places_t = np.ascontiguousarray(pixel_places.T)                         # (4, block**2)
    corners = corners.astype(np.int32)[:, None, :]
    samples = samples.astype(np.int32)

    codes_uint8 = np.asarray(image).dtype == np.uint8
    if codes_uint8:
        codes, unit = np.asarray(image).reshape(height, width, -1)[..., :channels].astype(np.float32), 255.0
    else:
        codes, unit = colours, 1.0
    sample_codes = codes[samples[:, 0], samples[:, 1]]                            # (samples, channels)
    padded = np.zeros((block_rows * block, block_cols * block, channels), dtype=codes.dtype)
    padded[:height, :width] = codes
    padded = padded.reshape(block_rows, block, block_cols, block, channels)

    distance = np.empty((len(corners), block * block))
    beyond = np.asarray(4.0 * channels * unit ** 2, dtype=codes.dtype)  # added to the squared colour distance of a
    step = block_cols * max(1, _NOVELTY_CHUNK // (block_cols * block * block))  # candidate that does not count
    for start in range(0, len(corners), step):
        blocks = slice(start, start + step)
        found = nearest[blocks]
        sample_places = _augmented((samples[found] - corners[blocks]).astype(place_type), -1)  # (blocks, K, 4)
        kth = np.partition(np.matmul(pixel_places, sample_places.swapaxes(1, 2)), k - 1, axis=-1)[..., k - 1]
        squared = np.matmul(sample_places, pixel_places_t)                       # (blocks, K, pixels)
        outside = squared > kth[:, None, :]
        pixel_codes = padded[start // block_cols: (start + step) // block_cols].transpose(0, 2, 4, 1, 3).reshape(
            -1, channels, block * block)                                          # (blocks, channels, pixels)
        if codes_uint8:
            colour = np.matmul(_augmented(sample_codes[found], -1), _augmented(pixel_codes, 1, axis=1))
        else:
            colour = np.zeros(squared.shape)
            for channel in range(channels):
                difference = sample_codes[found, channel, None] - pixel_codes[:, None, channel, :]
                colour += difference * difference
        penalised = outside * beyond
        penalised += colour
        least = penalised.min(axis=1)
        decided = np.sqrt(kth.astype(np.float64)) + off_centre < reach[blocks, None]
        tied = np.nonzero(squared.shape[1] - np.add.reduce(outside.view(np.uint8), axis=1, dtype=np.uint8) > k)
        if tied[0].size:  # samples tied at the k-th distance: does the KD-tree's choice among them change the minimum?
            farther = squared[tied[0], :, tied[1]] >= kth[tied][:, None]
            closer = (colour[tied[0], :, tied[1]] + farther * beyond).min(axis=-1)
            decided[tied] &= least[tied] >= closer
        distance[blocks] = np.where(decided, np.sqrt(least.astype(np.float64)) / unit, np.nan)
    return distance.reshape(block_rows, block_cols, block, block).swapaxes(1, 2).reshape(
        block_rows * block, block_cols * block)[:height, :width].copy()


def _augmented(vectors, side, axis=-1):
    """``(v, |v|**2, 1)`` (``side=1``) or ``(-2 v, 1, |v|**2)`` (``side=-1``) of the ``vectors`` along ``axis``.

    The inner product of a ``side=1`` and a ``side=-1`` augmented vector is
    the squared distance of the two vectors.
    """
    n = vectors.shape[axis]
    shape = list(vectors.shape)
    shape[axis] = n + 2
    out = np.empty(shape, dtype=vectors.dtype)
    parts = np.moveaxis(out, axis, 0)
    components = np.moveaxis(vectors, axis, 0)
    norm, one = (n, n + 1) if side > 0 else (n + 1, n)
    np.multiply(components[0], components[0], out=parts[norm])
    for component in components[1:]:
        parts[norm] += component * component
    np.multiply(components, 1 if side > 0 else -2, out=parts[:n])
    parts[one] = 1
    return out


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
    cue_full, slope_full = _error_cues(depth, sparse, observed, layout)
    cue = (cue_full + np.abs(depth_a - depth_b) + np.maximum(np.abs(depth - depth_a), np.abs(depth - depth_b))
           + _held_out_error_map(held_out_a, held_out_b, half_a, half_b, layout))
    if image is not None:
        cue += colour_novelty(depth, image, observed)

    held_out_errors = np.concatenate([held_out_a, held_out_b])
    held_out_cue = np.concatenate([_error_cues_at(depth_a, sparse, half_a, np.flatnonzero(half_b)),
                                   _error_cues_at(depth_b, sparse, half_b, np.flatnonzero(half_a))])
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
                                       + _extrapolation_term(slope_full, observed, layout, unobserved), precision)
    return sigma, calibration


def _extrapolation_term(slope, observed, layout, where):
    """``s90 * max(d - h, 0)`` at ``where``: the depth change a steep slope would make beyond one sample spacing.

    ``slope`` is ``|grad depth|`` (:func:`_error_cues`).
    """
    distance, spacing = layout.distance, layout.spacing
    interpolated = (distance <= spacing) & ~observed
    if not interpolated.any():
        return np.zeros(np.count_nonzero(where))
    steep = float(np.percentile(slope[interpolated], 90))
    return steep * np.maximum(distance[where] - spacing, 0.0)


def check_relative_limit(max_relative_uncertainty) -> float:
    """``max_relative_uncertainty`` as a float, refused unless a finite number ``> 0`` (a fraction of the depth)."""
    return check_positive_finite(max_relative_uncertainty, label="max_relative_uncertainty",
                                 expected="a fraction of the depth (0.1 = 10 %)")


def too_uncertain(uncertainty, depth, *, max_uncertainty=None, max_relative_uncertainty=None) -> np.ndarray:
    """The pixels whose uncertainty exceeds an absolute limit or a fraction of their depth.

    Parameters
    ----------
    uncertainty : ndarray, (H, W)
        Per-pixel uncertainty ``sigma`` (:func:`estimate_uncertainty`), in
        the units of ``depth``.
    depth : ndarray, (H, W)
        The completed depth.
    max_uncertainty : float, optional
        Absolute limit, in the units of ``depth`` (``>= 0``).
    max_relative_uncertainty : float, optional
        Limit as a fraction of each pixel's depth (``> 0``; 0.1 = 10 %).

    Returns
    -------
    ndarray of bool, (H, W)
        True where a limit given is exceeded (none given: no pixel).

    Raises
    ------
    TypeError
        A limit is not a real number.
    ValueError
        The shapes differ, ``max_uncertainty`` is negative or not finite,
        or ``max_relative_uncertainty`` is not a finite number ``> 0``.

    Notes
    -----
    A pixel is marked when ``sigma > max_uncertainty`` or
    ``sigma > max_relative_uncertainty * depth``.  A pixel with a depth
    that is not finite and positive fails the relative limit, and a pixel
    with a NaN ``sigma`` fails neither.

    Examples
    --------
    >>> import numpy as np
    >>> sigma, depth = np.array([[0.05, 0.5, 3.0]]), np.array([[1.0, 2.0, 40.0]])
    >>> too_uncertain(sigma, depth, max_relative_uncertainty=0.1).tolist()
    [[False, True, False]]
    >>> too_uncertain(sigma, depth, max_uncertainty=2.0, max_relative_uncertainty=0.1).tolist()
    [[False, True, True]]
    """
    sigma = np.asarray(uncertainty, dtype=np.float64)
    values = np.asarray(depth, dtype=np.float64)
    if sigma.shape != values.shape:
        raise ValueError(f"uncertainty and depth must have one shape, got {sigma.shape} and {values.shape}")
    marked = np.zeros(sigma.shape, dtype=bool)
    if max_uncertainty is not None:
        limit = check_nonnegative_real(max_uncertainty, name="max_uncertainty")
        with np.errstate(invalid="ignore"):
            marked |= sigma > limit
    if max_relative_uncertainty is not None:
        fraction = check_relative_limit(max_relative_uncertainty)
        with np.errstate(invalid="ignore"):
            usable = np.isfinite(values) & (values > 0)
            marked |= (sigma > fraction * np.where(usable, values, 0.0)) | (~usable & ~np.isnan(sigma))
    return marked
