"""Simulating sparse input: which valid depth pixels a sensor or a reconstruction would give, and how wrong they are.

Four patterns of observed pixels (:data:`PATTERNS`), each fixed by a seed:

* ``"uniform"`` - a random subset of the valid pixels (the benchmark's classic input);
* ``"keypoints"`` - the strongest FAST corners of the image, as structure-from-motion gives points where the image
  has texture (clustered on edges and corners, none on plain walls);
* ``"scan_lines"`` - every ``spacing``-th image row, as a LiDAR's rings cross a camera image;
* ``"holes"`` - a depth sensor's missing pixels: dark and saturated surfaces, bands along depth edges (shadows and
  flying pixels) and random blobs, until a given share of the valid pixels is left.

:func:`sample_depth` also corrupts the kept values as a reconstruction would (``noise``: relative Gaussian error;
``outliers``: a share of the samples multiplied by a factor in ``outlier_range``).

May import NumPy, SciPy, scikit-image and :mod:`sparsedepth._validation`.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ._validation import as_float_image, check_count, check_same_shape, is_int, is_real

__all__ = ["valid_depth_mask", "sample_mask", "sample_depth", "corrupt_samples", "PATTERNS"]

#: The observation patterns of :func:`sample_mask`, and whether each needs the image.
PATTERNS = {"uniform": False, "keypoints": True, "scan_lines": False, "holes": True}
#: ``holes``: image luminance quantiles below and above which a depth sensor returns nothing (dark, absorbing
#: surfaces; saturated, specular ones).
HOLE_LUMINANCE_QUANTILES = (0.03, 0.98)
#: ``holes``: a pixel is on a depth edge when the depth range of its 3x3 neighbourhood exceeds this share of its depth;
#: such pixels, widened by one pixel, are missing (the shadow and flying pixels of a structured-light or stereo sensor).
HOLE_EDGE_JUMP = 0.05
#: ``holes``: the radius of the random blobs, as a share of the smaller image side (drawn uniformly in this range).
HOLE_BLOB_RADIUS = (0.02, 0.08)


def valid_depth_mask(depth) -> np.ndarray:
    """True where ``depth`` is finite and ``> 0`` (0 and NaN mean "invalid")."""
    depth = np.asarray(depth, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.isfinite(depth) & (depth > 0)


def sample_mask(depth, *, fraction=None, count=None, seed=0, pattern="uniform", image=None, spacing=8,
                min_distance=2) -> np.ndarray:
    """Boolean mask of the valid pixels of ``depth`` that a sensor or a reconstruction of ``pattern`` would observe.

    Parameters
    ----------
    depth : ndarray, (H, W)
        Ground truth; valid where finite and ``> 0`` (:func:`valid_depth_mask`).  Only valid pixels are kept.
    fraction, count : float or int
        How many pixels (``"uniform"``, ``"keypoints"``, ``"holes"``; exactly one of the two): ``fraction`` of the
        valid pixels, in (0, 1] (``round(fraction · n_valid)``, at least one), or ``count`` pixels.  For
        ``"holes"`` the share of the valid pixels the sensor returns (e.g. 0.7), at most.  Not used by
        ``"scan_lines"`` (give neither).
    seed : int or numpy.random.Generator
        The same seed gives the same mask.
    pattern : str
        One of :data:`PATTERNS` (see the module notes).
    image : ndarray, (H, W, 3) or (H, W), optional
        The image of ``depth``; needed by ``"keypoints"`` and ``"holes"``.
    spacing : int
        ``"scan_lines"``: rows between two scan lines (the first line is at a seeded row below ``spacing``).
    min_distance : int
        ``"keypoints"``: the least distance in pixels between two keypoints.

    Raises
    ------
    ValueError
        An unknown ``pattern``; both or neither of ``fraction``/``count`` where they are needed, or either where
        they are not; out-of-range values (a negative ``seed`` included); a depth map without a valid pixel; more
        samples requested than valid pixels; a pattern that needs ``image`` without one, or of another size.
    TypeError
        A ``fraction`` that is not a number, or a ``seed`` NumPy cannot seed a generator with (e.g. a float).

    Notes
    -----
    ``"keypoints"``: the FAST-9 corner response (:func:`skimage.feature.corner_fast`: 9 contiguous pixels of the
    16 on a circle brighter or darker by 0.05) of the image's luminance, its local maxima at least
    ``min_distance`` apart (:func:`skimage.feature.corner_peaks`) on valid pixels, the strongest ``n`` of them;
    where there are fewer maxima than ``n``, the remaining keypoints are the valid pixels of largest response
    (ties broken by the seed).  ``"holes"``: the pixels whose luminance lies below or above the
    :data:`HOLE_LUMINANCE_QUANTILES` of the image's, and the depth-edge band (:data:`HOLE_EDGE_JUMP`), are removed,
    then disks of radius :data:`HOLE_BLOB_RADIUS` at random valid pixels until at most ``n`` valid pixels are left.
    """
    depth = np.asarray(depth)
    if depth.ndim != 2:
        raise ValueError(f"depth must be a 2-D (H, W) array, got shape {depth.shape}")
    if not isinstance(pattern, str) or pattern not in PATTERNS:
        raise ValueError(f"unknown sampling pattern {pattern!r}; choose one of {list(PATTERNS)}")
    valid = valid_depth_mask(depth)
    idx = np.flatnonzero(valid)
    if idx.size == 0:
        raise ValueError("depth has no valid pixel (finite and > 0) to sample from")
    if PATTERNS[pattern]:
        if image is None:
            raise ValueError(f"pattern {pattern!r} needs the image= of the depth map")
        image = as_float_image(image)
        check_same_shape(image.shape[:2], depth.shape, "image", "depth")
    rng = seed if isinstance(seed, np.random.Generator) else _generator(seed)
    if pattern == "scan_lines":
        if fraction is not None or count is not None:
            raise ValueError("pattern 'scan_lines' takes spacing=, not fraction= or count=")
        spacing = check_count(spacing, name="spacing")
        rows = np.zeros(depth.shape, dtype=bool)
        rows[int(rng.integers(spacing))::spacing] = True
        return rows & valid
    n = _sample_size(fraction, count, idx.size)
    if pattern == "uniform":
        mask = np.zeros(depth.shape, dtype=bool)
        mask.flat[rng.choice(idx, size=n, replace=False)] = True
        return mask
    if pattern == "keypoints":
        return _keypoint_mask(_luminance(image), valid, n, rng, check_count(min_distance, name="min_distance"))
    return _hole_mask(_luminance(image), np.asarray(depth, dtype=np.float64), valid, n, rng)


def _sample_size(fraction, count, n_valid) -> int:
    """The number of pixels asked for by ``fraction`` of ``n_valid`` or by ``count`` (exactly one given)."""
    if (fraction is None) == (count is None):
        raise ValueError("give exactly one of fraction= or count=")
    if fraction is not None:
        if not is_real(fraction):
            raise TypeError(f"fraction must be a number in (0, 1]; got {type(fraction).__name__} {fraction!r}")
        fraction = float(fraction)
        if not (0 < fraction <= 1):
            raise ValueError(f"fraction must be in (0, 1], got {fraction}")
        return max(1, int(round(fraction * n_valid)))
    n = check_count(count, name="count")
    if n > n_valid:
        raise ValueError(f"count={n} exceeds the {n_valid} valid pixels of depth")
    return n


def _luminance(image) -> np.ndarray:
    """Rec. 601 luma of a [0, 1] image (the image itself when grey)."""
    if image.ndim == 2:
        return image
    return image[..., :3] @ np.array([0.299, 0.587, 0.114]) if image.shape[-1] >= 3 else image[..., 0]


def _keypoint_mask(luma, valid, n, rng, min_distance) -> np.ndarray:
    """The ``n`` strongest FAST corners on valid pixels (then the valid pixels of largest response)."""
    from skimage.feature import corner_fast, corner_peaks

    response = corner_fast(luma, n=9, threshold=0.05)
    response = np.where(valid, response, 0.0)
    peaks = corner_peaks(response, min_distance=min_distance, threshold_abs=1e-12, exclude_border=False)
    flat = np.ravel_multi_index(peaks.T, luma.shape) if len(peaks) else np.zeros(0, dtype=np.intp)
    flat = flat[valid.flat[flat]]
    order = np.argsort(-response.flat[flat], kind="stable")
    chosen = flat[order[:n]]
    if chosen.size < n:  # too few corners: the valid pixels of largest response, random among equals
        rest = np.flatnonzero(valid)
        rest = rest[~np.isin(rest, chosen)]
        rest = rest[rng.permutation(rest.size)]
        rest = rest[np.argsort(-response.flat[rest], kind="stable")]
        chosen = np.concatenate([chosen, rest[:n - chosen.size]])
    mask = np.zeros(luma.shape, dtype=bool)
    mask.flat[chosen] = True
    return mask


def _hole_mask(luma, depth, valid, n, rng) -> np.ndarray:
    """A depth sensor's returns: valid pixels minus dark/bright ones, depth-edge bands and random blobs."""
    low, high = np.quantile(luma, HOLE_LUMINANCE_QUANTILES)
    kept = valid & (luma > low) & (luma < high)
    filled = np.where(valid, depth, np.nan)
    with np.errstate(invalid="ignore"):
        local_max = ndimage.maximum_filter(np.nan_to_num(filled, nan=-np.inf), size=3, mode="nearest")
        local_min = ndimage.minimum_filter(np.nan_to_num(filled, nan=np.inf), size=3, mode="nearest")
        edge = valid & (local_max - local_min > HOLE_EDGE_JUMP * depth)
    kept &= ~ndimage.binary_dilation(edge)
    h, w = depth.shape
    yy, xx = np.ogrid[:h, :w]
    side = min(h, w)
    while np.count_nonzero(kept) > n:
        centre = rng.choice(np.flatnonzero(kept))
        cy, cx = divmod(int(centre), w)
        radius = max(1.0, rng.uniform(*HOLE_BLOB_RADIUS) * side)
        y0, y1 = max(cy - int(radius), 0), min(cy + int(radius) + 1, h)
        x0, x1 = max(cx - int(radius), 0), min(cx + int(radius) + 1, w)
        disk = (yy[y0:y1] - cy) ** 2 + (xx[:, x0:x1] - cx) ** 2 <= radius * radius
        kept[y0:y1, x0:x1] &= ~disk
    return kept


def _generator(seed) -> np.random.Generator:
    """``np.random.default_rng(seed)``, its errors naming ``seed``."""
    if is_int(seed) and seed < 0:
        raise ValueError(f"seed must be an integer >= 0 or a numpy.random.Generator, got {seed!r}")
    try:
        return np.random.default_rng(seed)
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"seed must be an integer >= 0 or a numpy.random.Generator, got {seed!r} ({exc})") from None


def sample_depth(depth, *, fraction=None, count=None, seed=0, pattern="uniform", image=None, spacing=8,
                 min_distance=2, noise=0.0, outliers=0.0, outlier_range=(0.7, 1.3)):
    """Sparse depth (NaN where hidden) and its mask: :func:`sample_mask`, then :func:`corrupt_samples`.

    Parameters
    ----------
    depth, fraction, count, seed, pattern, image, spacing, min_distance
        As :func:`sample_mask`'s.
    noise, outliers, outlier_range
        As :func:`corrupt_samples`'s (by default the samples are the exact depth).

    Returns
    -------
    sparse : ndarray, (H, W), float64
        ``depth`` at kept pixels (corrupted as asked), NaN elsewhere.
    mask : ndarray of bool, (H, W)

    Examples
    --------
    >>> import numpy as np
    >>> depth = np.full((4, 6), 2.0)
    >>> sparse, mask = sample_depth(depth, pattern="scan_lines", spacing=2, seed=0)
    >>> mask.sum(axis=1)
    array([0, 6, 0, 6])
    """
    rng = seed if isinstance(seed, np.random.Generator) else _generator(seed)
    mask = sample_mask(depth, fraction=fraction, count=count, seed=rng, pattern=pattern, image=image,
                       spacing=spacing, min_distance=min_distance)
    sparse = np.full(mask.shape, np.nan)
    sparse[mask] = np.asarray(depth, dtype=np.float64)[mask]
    if noise or outliers:
        sparse = corrupt_samples(sparse, mask, noise=noise, outliers=outliers, outlier_range=outlier_range, seed=rng)
    return sparse, mask


def corrupt_samples(sparse, mask, *, noise=0.0, outliers=0.0, outlier_range=(0.7, 1.3), seed=0):
    """The samples as a reconstruction measures them: relative Gaussian noise and a share of gross outliers.

    Parameters
    ----------
    sparse : ndarray, (H, W)
        Depth at the observed pixels.
    mask : ndarray of bool, (H, W)
        The observed pixels.
    noise : float
        ``σ >= 0``: each sample is multiplied by ``1 + σ ε``, ``ε`` standard normal (clipped so that the factor
        stays above 0.1).
    outliers : float
        The share of the samples, in [0, 1], multiplied by a factor drawn uniformly in ``outlier_range`` instead
        (``round(outliers · n)`` of them).
    outlier_range : (float, float)
        ``0 < low <= high``.
    seed : int or numpy.random.Generator

    Returns
    -------
    ndarray, (H, W), float64
        A copy of ``sparse`` with the observed values corrupted (the others unchanged).
    """
    mask = np.asarray(mask, dtype=bool)
    out = np.array(sparse, dtype=np.float64)
    check_same_shape(out.shape, mask.shape, "sparse", "mask")
    if not (is_real(noise) and noise >= 0 and np.isfinite(noise)):
        raise ValueError(f"noise must be a finite number >= 0, got {noise!r}")
    if not (is_real(outliers) and 0 <= outliers <= 1):
        raise ValueError(f"outliers must be a share in [0, 1], got {outliers!r}")
    low, high = (float(v) for v in outlier_range)
    if not (0 < low <= high < np.inf):
        raise ValueError(f"outlier_range must be (low, high) with 0 < low <= high, got {outlier_range!r}")
    rng = seed if isinstance(seed, np.random.Generator) else _generator(seed)
    idx = np.flatnonzero(mask)
    factor = np.maximum(1.0 + float(noise) * rng.standard_normal(idx.size), 0.1)
    wrong = rng.choice(idx.size, size=int(round(float(outliers) * idx.size)), replace=False)
    factor[wrong] = rng.uniform(low, high, wrong.size)
    out.flat[idx] *= factor
    return out
