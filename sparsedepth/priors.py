"""External dense depth priors: checking a user's map and aligning it to the depth samples.

A prior is a dense ``(H, W)`` map the user brings, for instance the output of a monocular depth network: metric
depth, or depth known only up to scale and shift ("relative" depth).  :func:`align_prior` fits it to the
observations by least squares; :func:`~sparsedepth.complete_depth` (``prior=``) then completes the residual
between the samples and the aligned prior and adds the prior back.  No network code lives here: the library
takes the map as an array.

May import NumPy and :mod:`sparsedepth._validation`.
"""

from __future__ import annotations

import numpy as np

from ._validation import as_depth_and_mask, check_same_shape

__all__ = ["PRIOR_ALIGNMENTS", "as_prior", "align_prior"]

#: How :func:`align_prior` maps the prior onto the samples.
PRIOR_ALIGNMENTS = ("scale_shift", "scale", "none")


def as_prior(prior, shape, *, name: str = "prior", shape_name: str = "sparse_depth") -> np.ndarray:
    """``prior`` as a new float64 ``(H, W)`` array: the one rule for a prior, the library's and the command line's.

    A prior is dense and finite.  Zeros and negative values are values, not
    missing depth: a relative prior (depth up to scale and shift, e.g. a
    monocular network's output normalised to [0, 1], or a zero-mean map) holds
    them legitimately.

    Parameters
    ----------
    prior : array_like, (H, W)
        Integer or float map.
    shape : tuple of int
        ``(H, W)`` of the depth it goes with.
    name, shape_name : str, optional
        How the prior and the depth are named in messages (the command line
        passes its flags and files).

    Returns
    -------
    ndarray of float64, (H, W)
        A copy; the caller's array is never modified.

    Raises
    ------
    TypeError
        If ``prior`` is not a numeric array.
    ValueError
        If its shape is not ``shape``, it holds NaN or infinite values (pixels
        without a value), or it is 0 at every pixel (no depth at all).
    """
    array = np.asarray(prior)
    if not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise TypeError(f"{name} must be a numeric (H, W) array of depth; got dtype {array.dtype}")
    check_same_shape(array.shape, tuple(shape), name, shape_name)
    out = array.astype(np.float64)
    bad = int(np.count_nonzero(~np.isfinite(out)))
    if bad:
        raise ValueError(f"{name} has {bad} NaN or infinite values ({bad} pixels without a value); a prior must be "
                         "dense and finite everywhere: fill its holes first (e.g. with sparsedepth.nearest_fill)")
    if not out.any():
        raise ValueError(f"{name} is 0 at every pixel: it holds no depth to align or complete around; check how it "
                         "was computed, read or scaled")
    return out


def align_prior(prior, sparse_depth, mask=None, *, alignment: str = "scale_shift"):
    """Fit ``s · prior + t`` to the observed depth by least squares.

    Parameters
    ----------
    prior : ndarray, (H, W)
        Dense, finite map (metric or relative depth; any sign, any scale),
        see :func:`as_prior`.
    sparse_depth : ndarray, (H, W)
        Depth at the observed pixels.
    mask : ndarray of bool, (H, W), optional
        True where depth is observed; default: finite and ``> 0``.
    alignment : {"scale_shift", "scale", "none"}
        Fit both ``s`` and ``t`` (relative depth), ``s`` only with ``t = 0``,
        or neither (``s = 1, t = 0``: a metric prior used as it is).

    Returns
    -------
    aligned : ndarray, (H, W)
        ``s · prior + t``.
    scale, shift : float
        ``s`` and ``t``.

    Raises
    ------
    ValueError
        For an unknown ``alignment``, a prior :func:`as_prior` refuses, no
        observed pixel, or a prior that cannot be aligned: with
        ``"scale_shift"``, one that takes a single value at every observed
        pixel but varies elsewhere (its scale is undetermined); with
        ``"scale"``, one that is 0 at every observed pixel; a fitted ``s``
        or an aligned map that is not finite in float64.
    TypeError
        If ``alignment`` is not a str or ``prior`` not numeric.

    Notes
    -----
    ``(s, t) = argmin Σ_i (s p_i + t − z_i)²`` over the observed pixels
    ``i``: ``s = Σ (p_i − p̄)(z_i − z̄) / Σ (p_i − p̄)²`` and ``t = z̄ − s p̄``
    (means over the observed pixels).  With ``"scale"``, ``s = Σ p z / Σ
    p²``.  The fit runs in normalised units, ``p / 2^a`` and ``z / 2^b``
    with ``2^a`` and ``2^b`` the powers of two just above ``max |p|`` and
    ``max z`` (exact divisions), and ``s`` and ``t`` are scaled back: the
    alignment is invariant to the scale of the prior up to rounding, from a
    prior in 1e-160 units to one in 1e+160.  A prior constant everywhere
    carries no shape: with ``"scale_shift"`` its fit is ``s = 0``, ``t = z̄``.
    An inverse-depth map (disparity) is not an affine function of depth:
    invert it first.

    Examples
    --------
    >>> import numpy as np
    >>> truth = np.add.outer(np.linspace(1, 2, 4), np.linspace(0, 1, 5))
    >>> mask = np.zeros(truth.shape, bool); mask[::2, ::2] = True
    >>> _, s, t = align_prior((truth - 0.5) / 3, truth, mask)
    >>> round(s, 12), round(t, 12)
    (3.0, 0.5)
    """
    if not isinstance(alignment, str):
        raise TypeError(f"prior_alignment must be a str, one of {list(PRIOR_ALIGNMENTS)}; got "
                        f"{type(alignment).__name__}")
    if alignment not in PRIOR_ALIGNMENTS:
        raise ValueError(f"unknown prior_alignment {alignment!r}; choose one of {list(PRIOR_ALIGNMENTS)}")
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    p = as_prior(prior, depth.shape)
    if alignment == "none":
        return p, 1.0, 0.0
    p_exponent = int(np.frexp(np.max(np.abs(p)))[1])
    z_exponent = int(np.frexp(np.max(depth[observed]))[1])
    unit_prior = np.ldexp(p, -p_exponent)  # |values| <= 1
    at, values = unit_prior[observed], np.ldexp(depth[observed], -z_exponent)  # values in (0, 1]
    count = at.size
    if alignment == "scale":
        denominator = float(at @ at)
        if denominator == 0:
            raise ValueError(f"prior is 0 at all {count} observed pixels, so no scale fits it to the samples: "
                             "observe pixels where the prior is not 0, or check that it is the map of this frame")
        unit_scale, unit_shift = float(at @ values) / denominator, 0.0
    else:
        mean = float(at.mean())
        centred = at - mean
        if np.ptp(at) <= 4 * np.finfo(np.float64).eps * np.max(np.abs(at)):
            if np.ptp(unit_prior) > 0:
                value = float(p[observed][0])
                other = "prior_alignment='scale' or " if value != 0 else ""
                raise ValueError(
                    f"prior takes the one value {value:g} at all {count} observed pixels but varies elsewhere, so "
                    f"its scale is undetermined: use {other}prior_alignment='none' (metric depth), or observe "
                    "pixels where the prior differs")
            unit_scale, unit_shift = 0.0, float(values.mean())  # a constant prior carries no shape
        else:
            unit_scale = float(centred @ (values - values.mean())) / float(centred @ centred)
            unit_shift = float(values.mean()) - unit_scale * mean
    with np.errstate(over="ignore"):
        scale = float(np.ldexp(unit_scale, z_exponent - p_exponent))
    if not np.isfinite(scale):
        raise ValueError(f"prior: the fitted scale is not finite in float64 (the prior reaches {np.max(np.abs(p)):g} "
                         f"and the depth {np.max(depth[observed]):g}); give the prior in units nearer the depth's")
    with np.errstate(over="ignore"):
        aligned = np.ldexp(unit_scale * unit_prior + unit_shift, z_exponent)
    if not np.all(np.isfinite(aligned)):
        raise ValueError("prior: the aligned prior s * prior + t overflows float64; give a prior whose values are "
                         "closer to an affine copy of the depth")
    return aligned, scale, float(np.ldexp(unit_shift, z_exponent))
