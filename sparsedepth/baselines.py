"""Baselines a user would otherwise reach for: nearest, linear, biharmonic and colorization fills.

Each takes a sparse depth map and the mask of its observed pixels, and returns
a dense map of the same shape; none of them uses the objective of
:func:`sparsedepth.complete_depth`.  They are what :mod:`bench` compares the
completion against.

- :func:`nearest_fill`: the value of the nearest observed pixel;
- :func:`linear_fill`: piecewise-linear on the Delaunay triangulation of the
  observed pixels (``scipy.interpolate.griddata``), nearest outside their hull;
- :func:`biharmonic_fill`: biharmonic inpainting
  (``skimage.restoration.inpaint_biharmonic``);
- :func:`colorization_baseline`: the Levin / NYU-toolbox colorization fill,
  the only one that uses the image.

May import NumPy, SciPy, scikit-image, :mod:`sparsedepth._validation` and, inside
:func:`colorization_baseline`, :mod:`sparsedepth.holes.colorization` (imported
there because :mod:`sparsedepth.holes` imports :mod:`sparsedepth.completion`,
whose objective imports this module's nearest fill).
"""

from __future__ import annotations

import inspect

import numpy as np
from scipy import ndimage

from ._validation import as_depth_and_mask, check_option_names, check_same_shape

__all__ = ["nearest_fill", "linear_fill", "biharmonic_fill", "colorization_baseline"]


def nearest_fill(sparse_depth, mask=None) -> np.ndarray:
    """Nearest-neighbour fill: each pixel takes the value of the nearest observed pixel.

    Distance is Euclidean in pixel units (``scipy.ndimage.distance_transform_edt``
    with ``return_indices``); ties are broken as that function does.

    Parameters
    ----------
    sparse_depth : ndarray, (H, W)
    mask : ndarray of bool, (H, W), optional
        True where depth is observed; default: finite and ``> 0``.

    Returns
    -------
    ndarray, (H, W), float64
        Equal to the observation at every observed pixel.
    """
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    ii, jj = ndimage.distance_transform_edt(~observed, return_distances=False, return_indices=True)
    return depth[ii, jj]


def linear_fill(sparse_depth, mask=None) -> np.ndarray:
    """Piecewise-linear interpolation of the observations, nearest-neighbour outside their hull.

    This is ``scipy.interpolate.griddata(points, values, pixels,
    method="linear")`` on the (row, column) coordinates of the observed
    pixels, the interpolation most users reach for first.

    Parameters
    ----------
    sparse_depth : ndarray, (H, W)
        Depth at the observed pixels (any values elsewhere).
    mask : ndarray of bool, (H, W), optional
        True where depth is observed; default: finite and ``> 0``.

    Returns
    -------
    ndarray, (H, W), float64
        Equal to the observation at every observed pixel (up to rounding).

    Raises
    ------
    ValueError
        For a non-2-D depth, a mask of another shape, NaN/inf or negative
        values at observed pixels, or no observed pixel.

    Notes
    -----
    Inside the convex hull of the observed pixels the value is the
    barycentric interpolation on the Delaunay triangle (Qhull) that contains
    the pixel; outside it (near the image border) it is the nearest-neighbour
    fill, :func:`nearest_fill`.  With fewer than three observed pixels, or all
    of them on one line, there is no triangle and the whole result is the
    nearest-neighbour fill.  The cost is dominated by locating every pixel in
    the triangulation, and Qhull's point location on integer-grid points is
    erratic (``python -m bench.baselines`` times it beside the other fills:
    ``docs/results.md``).

    Examples
    --------
    >>> import numpy as np
    >>> ii, jj = np.mgrid[0:20, 0:30]
    >>> plane = 1.0 + 0.1 * ii + 0.05 * jj
    >>> mask = np.zeros(plane.shape, bool); mask[::4, ::5] = True; mask[-1, -1] = True
    >>> bool(np.allclose(linear_fill(np.where(mask, plane, 0), mask)[:17, :26], plane[:17, :26]))
    True
    """
    from scipy.interpolate import griddata
    from scipy.spatial import QhullError

    depth, observed = as_depth_and_mask(sparse_depth, mask)
    nearest = nearest_fill(depth, observed)
    points = np.argwhere(observed)
    if points.shape[0] < 3:
        return nearest
    try:
        linear = griddata(points, depth[observed], tuple(np.indices(depth.shape)), method="linear")
    except QhullError:  # all observed pixels on one line: no triangle
        return nearest
    return np.where(np.isfinite(linear), linear, nearest)


def biharmonic_fill(sparse_depth, mask=None) -> np.ndarray:
    """Biharmonic inpainting of the unobserved pixels (``skimage.restoration.inpaint_biharmonic``).

    Parameters
    ----------
    sparse_depth : ndarray, (H, W)
        Depth at the observed pixels (any values elsewhere).
    mask : ndarray of bool, (H, W), optional
        True where depth is observed; default: finite and ``> 0``.

    Returns
    -------
    ndarray, (H, W), float64
        Equal to the observation at every observed pixel.  Not clipped: the
        biharmonic interpolant can overshoot, and may go below 0 near steep
        depth edges.

    Raises
    ------
    ValueError
        As :func:`linear_fill`.

    Notes
    -----
    Solves the biharmonic equation ``Δ² z = 0`` at the unobserved pixels
    with ``z`` fixed at the observed ones, with scikit-image's
    discretisation: its stencil is truncated at the image border, so an
    affine plane is reproduced exactly where the two outermost rows and
    columns are observed, and is bent otherwise.
    One sparse system over all the unobserved pixels is assembled and solved
    directly, whose time grows faster than the pixel count
    (``python -m bench.baselines`` times it: ``docs/results.md``); subsample
    the frame where that matters.

    References
    ----------
    .. [1] S. B. Damelin, N. S. Hoang, "On surface completion and image
       inpainting by biharmonic functions: numerical aspects", 2018.
    """
    from skimage.restoration import inpaint_biharmonic

    depth, observed = as_depth_and_mask(sparse_depth, mask)
    if observed.all():
        return depth
    out = inpaint_biharmonic(depth, ~observed)
    out[observed] = depth[observed]  # exact already; guard against rounding
    return out


def colorization_baseline(image, sparse_depth, mask=None, **options) -> np.ndarray:
    """Levin/NYU-toolbox colorization fill of the sparse observations.

    A thin wrapper over :func:`sparsedepth.holes.colorization.colorization_fill`
    with the sparse depth as the known pixels, so that it is called like the
    other baselines.

    Parameters
    ----------
    image : ndarray, (H, W, 3) or (H, W)
        Guide image, uint8, uint16 or float in [0, 1].
    sparse_depth : ndarray, (H, W)
        Depth at the observed pixels (any values elsewhere).
    mask : ndarray of bool, (H, W), optional
        True where depth is observed; default: finite and ``> 0``.
    **options
        Passed on to ``colorization_fill`` (``alpha``, ``rtol``,
        ``window_radius``, ``maxiter``).

    Returns
    -------
    ndarray, (H, W), float64
        Dense depth.  With the toolbox's ``alpha = 1`` observed pixels are
        smoothed towards their neighbourhood, not reproduced exactly.

    Raises
    ------
    ValueError
        As :func:`linear_fill`, or an image whose height and width differ
        from the depth's.
    """
    from .holes.colorization import colorization_fill

    depth, observed = as_depth_and_mask(sparse_depth, mask)
    check_same_shape(np.shape(image)[:2], depth.shape, "image", "sparse_depth")
    check_option_names(options, set(_keyword_only_parameters(colorization_fill)) - {"mask"}, where="colorization_baseline")
    return colorization_fill(image, depth, mask=observed, **options)


def _keyword_only_parameters(function) -> tuple[str, ...]:
    """The keyword-only parameter names of ``function`` (the options it accepts)."""
    return tuple(name for name, parameter in inspect.signature(function).parameters.items()
                 if parameter.kind is inspect.Parameter.KEYWORD_ONLY)
