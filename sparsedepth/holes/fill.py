"""Filling the holes of raw sensor depth (Kinect, RealSense): every valid pixel is observed.

Two methods behind one function, :func:`fill_holes`:

* ``"colorization"`` - the NYU Depth V2 toolbox fill (``fill_depth_colorization.m``),
  computed exactly by :func:`sparsedepth.holes.colorization.colorization_fill`;
* ``"complete"`` - this package's objective, :func:`sparsedepth.complete_depth`
  with every valid raw pixel observed.
"""

from __future__ import annotations

import numpy as np

from .._validation import check_bool_mask, check_same_shape
from .colorization import colorization_fill
from ..completion import complete_depth
from ..sampling import valid_depth_mask
from ..objective.weights import DEFAULT_WEIGHTS

__all__ = ["FILL_METHODS", "fill_holes", "hole_fill_weights"]

#: The methods :func:`fill_holes` accepts.
FILL_METHODS = ("colorization", "complete")

_COMPLETE_ONLY = ("weights", "solver", "tol", "max_iter", "callback")


def _check_method_options(method, alpha, **complete_options):
    """``ValueError`` for an unknown ``method`` or an option of the other method."""
    if method not in FILL_METHODS:
        raise ValueError(f"unknown hole-filling method {method!r}; choose one of {list(FILL_METHODS)}")
    if method == "colorization":
        wrong = [name for name in _COMPLETE_ONLY if complete_options[name] is not None]
        if wrong:
            raise ValueError(f"{', '.join(wrong)} only apply to method='complete', not 'colorization'")
    elif alpha is not None:
        raise ValueError("alpha only applies to method='colorization'; use weights=Weights(alpha=...)")


def _raw_depth_and_mask(image, raw_depth, mask):
    """``(raw, mask)`` as arrays: raw 2-D and of the image's size, mask boolean, with a valid and no negative pixel."""
    raw = np.asarray(raw_depth)
    if raw.ndim != 2:
        raise ValueError(f"raw_depth must be a 2-D (H, W) array, got shape {raw.shape}")
    check_same_shape(np.shape(image)[:2], raw.shape, "image", "raw_depth")
    if mask is None:
        mask = valid_depth_mask(raw)
    else:
        mask = check_bool_mask(mask, raw.shape, shape_name="raw_depth")
    if not mask.any():
        raise ValueError("raw_depth has no valid pixel (finite and > 0, or in mask); nothing to fill from")
    with np.errstate(invalid="ignore"):
        negative = int(np.count_nonzero(raw[mask] < 0))
    if negative:
        raise ValueError(f"raw_depth has {negative} negative value(s) at valid pixels; depth must be >= 0")
    return raw, mask


# the numpydoc docstring is long (options of two methods, Notes); the code is short
def fill_holes(
    image,
    raw_depth,
    *,
    mask=None,
    method: str = "colorization",
    alpha: float | None = None,
    weights=None,
    solver: str | None = None,
    tol: float | None = None,
    max_iter: int | None = None,
    callback=None,
) -> np.ndarray:
    """Fill the holes of a raw depth map, guided by the image.

    Every valid raw pixel is an observation; the output is dense.

    Parameters
    ----------
    image : ndarray, (H, W, 3) or (H, W)
        Guide image: uint8, uint16 or float in [0, 1].
    raw_depth : ndarray, (H, W)
        Raw depth (metres, or any unit: both methods are linear in the depth).
        Holes are 0, NaN or inf unless ``mask`` is given.
    mask : ndarray of bool, (H, W), optional
        True where ``raw_depth`` is valid.  Default: finite and ``> 0``.  The
        NYU toolbox also treats the clipped Kinect maximum (10 m) as a hole:
        pass ``mask=(raw > 0) & (raw != 10)`` for that.
    method : {"colorization", "complete"}
        ``"colorization"``: the NYU Depth V2 toolbox's ``fill_depth_colorization``
        (Levin et al. colorization), solved exactly and fast by
        :func:`~sparsedepth.holes.colorization.colorization_fill`.
        ``"complete"``: :func:`~sparsedepth.complete_depth` with observed =
        ``mask``.
    alpha : float, optional
        ``"colorization"`` only: weight of the known depth (toolbox default 1).
    weights : Weights, optional
        ``"complete"`` only: term weights (default
        :data:`~sparsedepth.objective.weights.DEFAULT_WEIGHTS`).
    solver : str, optional
        ``"complete"`` only: solver name (default ``"auto"``).
    tol, max_iter : optional
        ``"complete"`` only: passed to :func:`~sparsedepth.complete_depth`.
    callback : callable, optional
        ``"complete"`` only: ``callback(state)`` after every solver iteration.

    Returns
    -------
    ndarray of float64, (H, W)
        Dense depth, in the unit of ``raw_depth``.  Neither method reproduces
        the valid raw pixels exactly (both smooth them slightly, with finite
        data weights); copy them back with ``np.where(mask, raw, out)`` if
        needed.

    Raises
    ------
    ValueError
        Unknown ``method``; an option of the other method given; image and
        depth of different sizes; no valid pixel; negative depth; and the
        errors of the underlying function.

    Notes
    -----
    ``"colorization"`` solves ``(I - W + alpha M) x = alpha M d`` with ``W`` the
    row-stochastic 3x3 window affinity of the grey image and ``M`` the mask
    (see :func:`~sparsedepth.holes.colorization.colorization_fill`).  ``"complete"``
    minimises ``F(z)`` of :func:`~sparsedepth.complete_depth` with
    ``M = mask``; it is exactly ``complete_depth(image, raw_depth, mask).depth``.

    References
    ----------
    .. [1] N. Silberman, D. Hoiem, P. Kohli, R. Fergus, "Indoor segmentation
       and support inference from RGBD images", ECCV 2012 (NYU Depth V2
       toolbox, ``fill_depth_colorization.m``).
    .. [2] A. Levin, D. Lischinski, Y. Weiss, "Colorization using
       optimization", ACM SIGGRAPH 2004.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> image = rng.random((20, 30))
    >>> raw = np.full((20, 30), 2.0)
    >>> raw[5:10, 5:20] = 0.0                        # a hole
    >>> dense = fill_holes(image, raw)
    >>> bool(np.allclose(dense, 2.0))
    True
    """
    _check_method_options(method, alpha, weights=weights, solver=solver, tol=tol, max_iter=max_iter,
                          callback=callback)
    raw, mask = _raw_depth_and_mask(image, raw_depth, mask)
    if method == "colorization":
        return colorization_fill(image, raw, mask=mask, alpha=1.0 if alpha is None else alpha)
    result = complete_depth(
        image,
        raw,
        mask,
        weights=hole_fill_weights(weights),
        solver="auto" if solver is None else solver,
        tol=tol,
        max_iter=max_iter,
        callback=callback,
    )
    return result.depth


def hole_fill_weights(weights):
    """The weights of the ``"complete"`` hole fill: ``weights``, or :data:`~sparsedepth.DEFAULT_WEIGHTS` for None.

    Raw sensor depth is observed almost everywhere, far denser than the anchors of the density schedule
    ``complete_depth`` uses without weights, so hole filling keeps the constant defaults.
    """
    return DEFAULT_WEIGHTS if weights is None else weights
