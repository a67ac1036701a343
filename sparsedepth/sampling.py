"""Simulating sparse input: keep a random subset (fixed by a seed) of the valid depth pixels.

May import NumPy and :mod:`sparsedepth._validation`.
"""

from __future__ import annotations

import numpy as np

from ._validation import check_count, is_int, is_real

__all__ = ["valid_depth_mask", "sample_mask", "sample_depth"]


def valid_depth_mask(depth) -> np.ndarray:
    """True where ``depth`` is finite and ``> 0`` (0 and NaN mean "invalid")."""
    depth = np.asarray(depth, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.isfinite(depth) & (depth > 0)


def sample_mask(depth, *, fraction=None, count=None, seed=0) -> np.ndarray:
    """Boolean mask of a random subset of the valid pixels of ``depth``.

    Exactly one of ``fraction`` (of the *valid* pixels, in (0, 1]) or ``count``
    (a number of pixels, >= 1) is given.  ``round(fraction · n_valid)`` pixels
    are kept (at least one).  The same ``seed`` (int or
    ``numpy.random.Generator``) gives the same mask.

    Raises
    ------
    ValueError
        Both or neither of ``fraction``/``count``; out-of-range values
        (a negative ``seed`` included); a depth map without a valid pixel;
        more samples requested than valid pixels.
    TypeError
        A ``fraction`` that is not a number, or a ``seed`` NumPy cannot seed
        a generator with (e.g. a float).
    """
    depth = np.asarray(depth)
    if depth.ndim != 2:
        raise ValueError(f"depth must be a 2-D (H, W) array, got shape {depth.shape}")
    if (fraction is None) == (count is None):
        raise ValueError("give exactly one of fraction= or count=")
    valid = valid_depth_mask(depth)
    idx = np.flatnonzero(valid)
    if idx.size == 0:
        raise ValueError("depth has no valid pixel (finite and > 0) to sample from")
    if fraction is not None:
        if not is_real(fraction):
            raise TypeError(f"fraction must be a number in (0, 1]; got {type(fraction).__name__} {fraction!r}")
        fraction = float(fraction)
        if not (0 < fraction <= 1):
            raise ValueError(f"fraction must be in (0, 1], got {fraction}")
        n = max(1, int(round(fraction * idx.size)))
    else:
        n = check_count(count, name="count")
        if n > idx.size:
            raise ValueError(f"count={n} exceeds the {idx.size} valid pixels of depth")
    rng = seed if isinstance(seed, np.random.Generator) else _generator(seed)
    keep = rng.choice(idx, size=n, replace=False)
    mask = np.zeros(depth.shape, dtype=bool)
    mask.flat[keep] = True
    return mask


def _generator(seed) -> np.random.Generator:
    """``np.random.default_rng(seed)``, its errors naming ``seed``."""
    if is_int(seed) and seed < 0:
        raise ValueError(f"seed must be an integer >= 0 or a numpy.random.Generator, got {seed!r}")
    try:
        return np.random.default_rng(seed)
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"seed must be an integer >= 0 or a numpy.random.Generator, got {seed!r} ({exc})") from None


def sample_depth(depth, *, fraction=None, count=None, seed=0):
    """Sparse depth (NaN where hidden) and its mask, see :func:`sample_mask`.

    Returns
    -------
    sparse : ndarray, (H, W), float64
        ``depth`` at kept pixels, NaN elsewhere.
    mask : ndarray of bool, (H, W)
    """
    mask = sample_mask(depth, fraction=fraction, count=count, seed=seed)
    sparse = np.full(mask.shape, np.nan)
    sparse[mask] = np.asarray(depth, dtype=np.float64)[mask]
    return sparse, mask
