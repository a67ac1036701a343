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


def as_prior(prior, shape, *, name: str = "prior") -> np.ndarray:
    """``prior`` as a new float64 ``(H, W)`` array; ``ValueError``/``TypeError`` for a wrong shape or values.

    Raises
    ------
    TypeError
        If ``prior`` is not a numeric array.
    ValueError
        If its shape is not ``shape`` (that of ``sparse_depth``) or it holds NaN or infinite values.
    """
    array = np.asarray(prior)
    if not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise TypeError(f"{name} must be a numeric (H, W) array of depth; got dtype {array.dtype}")
    check_same_shape(array.shape, tuple(shape), name, "sparse_depth")
    out = array.astype(np.float64)
    bad = ~np.isfinite(out)
    if bad.any():
        raise ValueError(f"{name} has {int(np.count_nonzero(bad))} NaN or infinite values; a prior must be dense "
                         "and finite everywhere (fill its holes first, e.g. with sparsedepth.nearest_fill)")
    return out


def align_prior(prior, sparse_depth, mask=None, *, alignment: str = "scale_shift"):
    """Fit ``s · prior + t`` to the observed depth by least squares.

    Parameters
    ----------
    prior : ndarray, (H, W)
        Dense, finite map (metric or relative depth; any sign).
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
        For an unknown ``alignment``, a prior of another shape or with
        NaN/inf, or no observed pixel.
    TypeError
        If ``alignment`` is not a str or ``prior`` not numeric.

    Notes
    -----
    ``(s, t) = argmin Σ_i (s p_i + t − z_i)²`` over the observed pixels
    ``i``, solved by ``numpy.linalg.lstsq`` on the columns ``[p, 1]``; when the
    prior is constant on the observed pixels the system is rank-deficient and
    ``lstsq`` returns the minimum-norm solution, for which ``s p + t`` is the
    mean observed depth there.  With ``"scale"``, ``s = Σ p z / Σ p²`` (``s =
    1`` if the prior is 0 at every sample).  An inverse-depth map
    (disparity) is not an affine function of depth: invert it first.

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
    values, at = depth[observed], p[observed]
    if alignment == "none":
        scale, shift = 1.0, 0.0
    elif alignment == "scale":
        denominator = float(at @ at)
        scale, shift = (float(at @ values) / denominator if denominator > 0 else 1.0), 0.0
    else:
        columns = np.column_stack([at, np.ones_like(at)])
        (scale, shift), *_ = np.linalg.lstsq(columns, values, rcond=None)
        scale, shift = float(scale), float(shift)
    return scale * p + shift, scale, shift
