"""The grey image and the window affinities of the NYU toolbox colorization fill.

The toolbox asks every pixel to equal a weighted average of its window
neighbours, the weights coming from the grey image.  This module computes the
grey image (:func:`rgb_to_grey`), those weights for every pixel at once
(:func:`window_weights`), and turns them into rows of the sparse matrix
(:func:`window_entries`, :func:`window_rows`, :func:`colorization_weights`).

May import NumPy, SciPy and :mod:`sparsedepth._validation`.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse

from .._validation import as_float_image, check_count

__all__ = [
    "GREY_WEIGHTS",
    "rgb_to_grey",
    "as_grey",
    "colorization_weights",
    "window_weights",
    "window_entries",
    "window_rows",
    "box_sum",
    "box_count",
]

GREY_WEIGHTS = (0.2989, 0.5870, 0.1140)
"""Weights of R, G, B in the grey image, as documented for MATLAB ``rgb2gray``.

MATLAB computes with the unrounded ``0.298936021293775, 0.587043074451121,
0.114020904255103``; the rounded, documented values differ by less than 1e-4
and are what :mod:`bench.naive_colorization` and this module both use.
"""

# The toolbox's constants: window variance factor, the floor that keeps the
# closest neighbour's weight >= 0.01, and the absolute floor of the scale.
_VARIANCE_FACTOR = 0.6
_LOG_100 = math.log(100.0)  # -log(0.01)
_MIN_CSIG = 2e-6


def as_grey(image, name="image"):
    """Check ``image`` and return its grey version, float64 (H, W) in [0, 1].

    The checks and the [0, 1] scaling are :func:`sparsedepth._validation.as_float_image`'s;
    three channels become ``GREY_WEIGHTS``-weighted grey, one channel is used as is.
    """
    out = as_float_image(image, name=name)
    if out.shape[2] == 1:
        return out[..., 0]
    r, g, b = GREY_WEIGHTS
    return r * out[..., 0] + g * out[..., 1] + b * out[..., 2]


def rgb_to_grey(image):
    """Grey image used by the colorization fill (MATLAB ``rgb2gray`` weights).

    Parameters
    ----------
    image : array_like, shape (H, W, 3) or (H, W)
        Colour or grey image: uint8 (divided by 255), uint16 (divided by
        65535) or float in [0, 1].

    Returns
    -------
    ndarray of float64, shape (H, W)
        ``0.2989 R + 0.5870 G + 0.1140 B`` (see :data:`GREY_WEIGHTS`), or the
        grey input as float64.

    Raises
    ------
    ValueError
        If the shape is not (H, W) or (H, W, C) with C in {1, 3, 4} (an alpha
        channel is dropped), the dtype is not uint8, uint16 or float, or a
        float image has NaN/inf or values outside [0, 1].
    """
    return as_grey(image)


# ----------------------------------------------------------------------------
# window sums
# ----------------------------------------------------------------------------
def box_sum(image, radius):
    """Sum of ``image`` over the (clipped) ``(2 radius + 1)²`` window of every pixel (separable, new array)."""
    rows = image.copy()
    for d in range(1, radius + 1):  # separable: over axis 0 first, then over axis 1
        rows[d:] += image[:-d]
        rows[:-d] += image[d:]
    out = rows.copy()
    for d in range(1, radius + 1):
        out[:, d:] += rows[:, :-d]
        out[:, :-d] += rows[:, d:]
    return out


def box_count(mask, radius):
    """Number of True pixels of ``mask`` in the (clipped) window of radius ``radius`` of every pixel."""
    return box_sum(mask.astype(np.int32), radius)


# ----------------------------------------------------------------------------
# the window weights
# ----------------------------------------------------------------------------
def _offsets(radius):
    """Window offsets (di, dj) in row-major order, the centre included."""
    return [(di, dj) for di in range(-radius, radius + 1) for dj in range(-radius, radius + 1)]


def _shift_slices(d, n):
    """Target and source slices along one axis for the neighbour at offset ``d``."""
    return slice(max(0, -d), n - max(0, d)), slice(max(0, d), n - max(0, -d))


def _squared_differences(grey, offsets):
    """``(planes, min_d2)``: squared grey differences to every window neighbour, and their minimum.

    ``planes[k][i, j] = (g[i + di, j + dj] - g[i, j])^2`` for the ``k``-th
    offset, 0 outside the image and at the centre, where no weight is
    computed; ``min_d2`` is their minimum over the in-image neighbours (0 for
    a 1x1 image).  The plane of offset ``-k`` is that of offset ``k`` shifted,
    so ``(g_p - g_q)^2`` is computed once per pair.
    """
    H, W = grey.shape
    centre = len(offsets) // 2
    slices = []
    for di, dj in offsets:
        ti, si = _shift_slices(di, H)
        tj, sj = _shift_slices(dj, W)
        slices.append(((ti, tj), (si, sj)))
    planes = np.zeros((len(offsets), H, W))
    min_d2 = np.full((H, W), np.inf)
    for k in range(len(offsets)):
        if k == centre:
            continue
        t, s = slices[k]
        if k < centre:
            diff = np.subtract(grey[s], grey[t], out=planes[k][t])
            diff *= diff
        else:
            diff = planes[k][t]
            diff[...] = planes[len(offsets) - 1 - k][s]
        np.minimum(min_d2[t], diff, out=min_d2[t])
    min_d2[np.isinf(min_d2)] = 0.0  # a 1x1 image has no neighbour
    return planes, min_d2


def _window_scale(grey, planes, min_d2, radius):
    """The toolbox's scale ``c_p`` of every pixel (see :func:`colorization_weights`, Notes).

    The population variance of the window is computed shifted to the centre
    value: ``n v_p = sum_q (g_q - g_p)^2 - n (mu_p - g_p)^2``.  A window
    pixel deviates from the mean by at most ``sqrt(n - 1)`` standard
    deviations, so ``(mu_p - g_p)^2 <= (n - 1) v_p``: the subtraction loses
    at most a factor ``n = (2r+1)^2`` in relative accuracy (a few ulps,
    against the toolbox's two-pass variance), unlike the textbook one-pass
    formula.
    """
    H, W = grey.shape
    rows = np.arange(H)
    cols = np.arange(W)
    n_rows = np.minimum(rows + radius, H - 1) - np.maximum(rows - radius, 0) + 1
    n_cols = np.minimum(cols + radius, W - 1) - np.maximum(cols - radius, 0) + 1
    count = np.multiply.outer(n_rows, n_cols).astype(np.float64)  # window pixels, centre included
    mean = box_sum(grey, radius) / count
    var = planes.sum(axis=0)
    var /= count
    shift = mean - grey
    shift *= shift
    var -= shift
    np.maximum(var, 0.0, out=var)
    csig = _VARIANCE_FACTOR * var
    np.maximum(csig, min_d2 / _LOG_100, out=csig)
    np.maximum(csig, _MIN_CSIG, out=csig)
    return csig


def window_weights(grey, radius):
    """Window weights of every pixel, fully vectorised.

    Returns ``(planes, steps)``: ``planes[k, i, j]`` is the normalised weight
    of the neighbour ``(i + di, j + dj)`` of pixel ``(i, j)``, with ``(di, dj)``
    the ``k``-th window offset in row-major order, and 0 where that neighbour
    lies outside the image; the centre plane ``k = K // 2`` is 0, for the
    caller to fill.  ``steps[k] = di * W + dj`` is the
    offset of the neighbour in the C-order pixel numbering.
    """
    H, W = grey.shape
    offsets = _offsets(radius)
    centre = len(offsets) // 2
    planes, min_d2 = _squared_differences(grey, offsets)
    csig = _window_scale(grey, planes, min_d2, radius)
    # unnormalised weights exp(-d^2 / c) on the two contiguous blocks of
    # neighbour planes, then 0 again outside the image
    neg_csig = np.negative(csig)  # x / (-c) is exactly -(x / c)
    for block in (planes[:centre], planes[centre + 1 :]):
        np.divide(block, neg_csig, out=block)
        np.exp(block, out=block)
    for k, (di, dj) in enumerate(offsets):
        if k == centre:
            continue
        plane = planes[k]
        plane[: max(0, -di)] = 0.0
        plane[H - max(0, di) :] = 0.0
        plane[:, : max(0, -dj)] = 0.0
        plane[:, W - max(0, dj) :] = 0.0
    total = planes.sum(axis=0)
    total[total == 0] = 1.0  # no neighbour at all (1x1 image)
    planes /= total
    steps = np.array([di * W + dj for di, dj in offsets], dtype=np.int64)
    return planes, steps


# ----------------------------------------------------------------------------
# the sparse rows
# ----------------------------------------------------------------------------
def window_entries(planes, diagonal, sign, order=None):
    """Prepare ``planes`` in place for :func:`window_rows`.

    Returns ``(flat, pixels, position)``: the ``(K, n)`` entries (``sign * w``
    off the centre, ``diagonal`` at it), the pixels in matrix order
    (``order``, or C order) and the matrix position of every pixel (None for
    C order).
    """
    K, H, W = planes.shape
    n = H * W
    if sign < 0:
        np.negative(planes, out=planes)
    planes[K // 2] = diagonal.reshape(H, W) if np.ndim(diagonal) else diagonal
    itype = np.int32 if n * K < 2**31 - 1 else np.int64
    if order is None:
        return planes.reshape(K, n), np.arange(n, dtype=itype), None
    pixels = order.astype(itype)
    position = np.empty(n, dtype=itype)
    position[pixels] = np.arange(n, dtype=itype)
    return planes.reshape(K, n), pixels, position


def window_rows(flat, steps, rows, position):
    """The rows of the pixels ``rows`` (in this order) of the window matrix, as CSR.

    ``flat``, ``position`` from :func:`window_entries`; the columns are
    numbered by ``position`` (C order if None).  The entries outside the
    image (weight exactly 0) are removed; the column indices are not sorted
    when ``position`` is given.
    """
    K, n = flat.shape
    itype = rows.dtype
    data = (np.ascontiguousarray(flat.T) if rows.size == n and position is None else flat.T[rows]).reshape(-1)
    cols = rows[:, None] + steps.astype(itype)[None, :]
    np.clip(cols, 0, n - 1, out=cols)
    if position is not None:
        cols = position[cols]
    indptr = np.arange(0, rows.size * K + 1, K, dtype=itype)
    mat = scipy.sparse.csr_matrix((data, cols.reshape(-1), indptr), shape=(rows.size, n))
    mat.eliminate_zeros()
    mat.has_sorted_indices = False
    return mat


def colorization_weights(image, *, window_radius=1):
    """Row-stochastic window affinity matrix of the NYU toolbox colorization fill.

    Parameters
    ----------
    image : array_like, shape (H, W, 3) or (H, W)
        Guide image, uint8, uint16 or float in [0, 1] (see :func:`rgb_to_grey`).
    window_radius : int, optional
        Radius ``r`` of the ``(2r+1) x (2r+1)`` window; the toolbox uses 1.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (H*W, H*W)
        ``W`` with ``W[p, q] = w_pq`` for the neighbours ``q`` of ``p`` and 0
        elsewhere (zero diagonal); every row sums to 1 (except for a 1x1
        image, whose only row is empty).  Pixels are numbered in C order,
        ``p = i * W + j``.  The toolbox matrix is ``I - W``.

    Raises
    ------
    ValueError
        For a bad image (see :func:`rgb_to_grey`) or window radius.

    Notes
    -----
    With ``g`` the grey image, ``N(p)`` the window pixels of ``p`` that lie
    inside the image (so border pixels have fewer neighbours), ``mu_p`` and
    ``v_p`` the mean and population variance of ``g`` over ``N(p)`` and ``p``
    itself::

        c_p  = max(0.6 v_p,  min_{q in N(p)} (g_q - g_p)^2 / log(100),  2e-6)
        w_pq = exp(-(g_q - g_p)^2 / c_p) / sum_{s in N(p)} exp(-(g_s - g_p)^2 / c_p)

    The second floor keeps the closest neighbour's unnormalised weight at or
    above 0.01.  Since ``v_p >= (g_q - g_p)^2 / 18`` for every window pixel
    ``q``, every exponent is at most 30 for ``r = 1``: no weight underflows,
    so the neighbour graph is always connected.

    References
    ----------
    .. [1] A. Levin, D. Lischinski, Y. Weiss, "Colorization using
       optimization", ACM SIGGRAPH 2004.
    .. [2] N. Silberman, D. Hoiem, P. Kohli, R. Fergus, "Indoor segmentation
       and support inference from RGBD images", ECCV 2012 (NYU Depth V2
       toolbox, ``fill_depth_colorization.m``).

    Examples
    --------
    >>> import numpy as np
    >>> W = colorization_weights(np.zeros((2, 3)))
    >>> W.shape, np.allclose(W.sum(axis=1), 1.0)
    ((6, 6), True)
    """
    grey = as_grey(image)
    radius = check_count(window_radius, name="window_radius")
    planes, steps = window_weights(grey, radius)
    # every row gets all K window entries, those outside the image (weight exactly 0) are then
    # removed; the offsets are in row-major order, so the column indices of every row ascend
    flat, pixels, position = window_entries(planes, 0.0, +1)
    mat = window_rows(flat, steps, pixels, position)
    mat.has_sorted_indices = True
    return mat
