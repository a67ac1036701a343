"""Levin-style colorization fill of depth holes (NYU Depth V2 toolbox), fast and exact.

The NYU Depth V2 toolbox fills the holes of raw Kinect depth with
``fill_depth_colorization.m``, an adaptation of Levin, Lischinski & Weiss,
"Colorization using optimization" (SIGGRAPH 2004): every pixel is asked to
equal a weighted average of its 3x3 neighbours, the weights coming from the
grey image, and known pixels are pulled towards their measured depth.  This
module builds exactly the same linear system, but vectorised (no per-pixel
Python loop), and solves it with an exact block elimination of the unknown
pixels (and of the known pixels most coupled to them) plus a short, provably
convergent Krylov iteration on the other known ones, instead of a general
sparse LU of the whole system.

Public functions
----------------
rgb_to_grey
    The grey image the toolbox uses (MATLAB ``rgb2gray`` weights).
colorization_weights
    The row-stochastic window affinity matrix ``W`` of the toolbox.
colorization_fill
    The toolbox fill, ``(I - W + alpha M) x = alpha M d``.
"""

from __future__ import annotations

import concurrent.futures
import functools
import math
import numbers
import os

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg

from .._validation import as_float_image
from ..linalg.krylov import gmres

__all__ = [
    "GREY_WEIGHTS",
    "rgb_to_grey",
    "colorization_weights",
    "colorization_fill",
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

# The solver's set-up (see colorization_fill, Notes): known pixels with at
# least this many holes in their window are eliminated with the holes; the
# preconditioner sees the eliminated pixels within this many window steps of
# the iterated ones; and it has this many terms of a Neumann series.
_LAYER_MIN_UNKNOWN = 2
_STRIP_WIDTH = 2
_NEUMANN_TERMS = 4


# ----------------------------------------------------------------------------
# input checks
# ----------------------------------------------------------------------------
def _as_grey(image, name="image"):
    """Check ``image`` and return its grey version, float64 (H, W) in [0, 1].

    The checks and the [0, 1] scaling are :func:`sparsedepth._validation.as_float_image`'s;
    three channels become ``GREY_WEIGHTS``-weighted grey, one channel is used as is.
    """
    out = as_float_image(image, name=name)
    if out.shape[2] == 1:
        return out[..., 0]
    r, g, b = GREY_WEIGHTS
    return r * out[..., 0] + g * out[..., 1] + b * out[..., 2]


def _check_radius(window_radius):
    if (
        not isinstance(window_radius, numbers.Integral)
        or isinstance(window_radius, bool)
        or window_radius < 1
    ):
        raise ValueError(f"window_radius must be an integer >= 1, got {window_radius!r}")
    return int(window_radius)


def _check_positive(value, name):
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, got {value!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return value


def _depth_and_mask(depth, mask, shape):
    """Return float64 depth (H, W) with 0 where unobserved, and the bool mask."""
    d = np.asarray(depth)
    if d.ndim != 2:
        raise ValueError(f"depth must have shape (H, W), got shape {d.shape}")
    if d.shape != shape:
        raise ValueError(f"depth has shape {d.shape} but image has shape {shape}; they must match")
    if not (np.issubdtype(d.dtype, np.floating) or np.issubdtype(d.dtype, np.integer)):
        raise ValueError(f"depth dtype must be real numeric, got {d.dtype}")
    d = d.astype(np.float64)
    if mask is None:
        with np.errstate(invalid="ignore"):
            m = np.isfinite(d) & (d > 0)
    else:
        m = np.asarray(mask)
        if m.dtype != np.bool_:
            raise ValueError(f"mask must be a boolean array, got dtype {m.dtype}")
        if m.shape != shape:
            raise ValueError(f"mask has shape {m.shape} but depth has shape {shape}; they must match")
        if not np.all(np.isfinite(d[m])):
            raise ValueError("depth is NaN or infinite at some pixels where mask is True")
    if not m.any():
        raise ValueError("mask (or depth > 0 when mask is None) selects no known pixel; "
                         "at least one known depth is needed")
    return np.where(m, d, 0.0), m


# ----------------------------------------------------------------------------
# the window affinities
# ----------------------------------------------------------------------------
def _offsets(radius):
    """Window offsets (di, dj) in row-major order, the centre included."""
    return [(di, dj) for di in range(-radius, radius + 1) for dj in range(-radius, radius + 1)]


def _shift_slices(d, n):
    """Target and source slices along one axis for the neighbour at offset ``d``."""
    return slice(max(0, -d), n - max(0, d)), slice(max(0, d), n - max(0, -d))


def _window_weights(grey, radius):
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
    # pixels in the (clipped) window, centre included
    rows = np.arange(H)
    cols = np.arange(W)
    n_rows = np.minimum(rows + radius, H - 1) - np.maximum(rows - radius, 0) + 1
    n_cols = np.minimum(cols + radius, W - 1) - np.maximum(cols - radius, 0) + 1
    count = np.multiply.outer(n_rows, n_cols).astype(np.float64)

    slices = []
    for di, dj in offsets:
        ti, si = _shift_slices(di, H)
        tj, sj = _shift_slices(dj, W)
        slices.append(((ti, tj), (si, sj)))
    neighbours = [k for k in range(len(offsets)) if k != centre]

    # squared grey differences to the centre (0 outside the image and at the
    # centre, where no weight is computed) and their minimum over the window;
    # the plane of offset -k is that of offset k shifted: (g_p - g_q)^2 is
    # computed once per pair
    planes = np.zeros((len(offsets), H, W))
    min_d2 = np.full((H, W), np.inf)
    for k in neighbours:
        t, s = slices[k]
        if k < centre:
            diff = np.subtract(grey[s], grey[t], out=planes[k][t])
            diff *= diff
        else:
            diff = planes[k][t]
            diff[...] = planes[len(offsets) - 1 - k][s]
        np.minimum(min_d2[t], diff, out=min_d2[t])
    min_d2[np.isinf(min_d2)] = 0.0  # a 1x1 image has no neighbour

    # mean of the window (a separable box sum) and its population variance,
    # shifted to the centre value: n v_p = sum_q (g_q - g_p)^2 - n (mu_p - g_p)^2.
    # A window pixel deviates from the mean by at most sqrt(n - 1) standard
    # deviations, so (mu_p - g_p)^2 <= (n - 1) v_p: the subtraction loses at
    # most a factor n = (2r+1)^2 in relative accuracy (a few ulps, against
    # the toolbox's two-pass variance), unlike the textbook one-pass formula.
    total = _box_sum(grey, radius)
    mean = total / count
    var = planes.sum(axis=0)
    var /= count
    shift = mean - grey
    shift *= shift
    var -= shift
    np.maximum(var, 0.0, out=var)

    csig = _VARIANCE_FACTOR * var
    np.maximum(csig, min_d2 / _LOG_100, out=csig)
    np.maximum(csig, _MIN_CSIG, out=csig)

    # unnormalised weights exp(-d^2 / c) on the two contiguous blocks of
    # neighbour planes, then 0 again outside the image
    neg_csig = np.negative(csig)  # x / (-c) is exactly -(x / c)
    for block in (planes[:centre], planes[centre + 1 :]):
        np.divide(block, neg_csig, out=block)
        np.exp(block, out=block)
    for k in neighbours:
        di, dj = offsets[k]
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


def _window_weights_two_threads(grey, radius):
    """:func:`_window_weights` computed for the top and the bottom half in two threads.

    Each half is given ``radius`` rows of the other as a halo, so every
    pixel sees the same window as in one pass: the planes are identical
    (they are per-pixel results).  NumPy releases the GIL in its loops, so on
    a multi-core machine this takes about 60 % of one pass (measured on a
    640x480 frame: 49 ms instead of 77 ms, with the copy into one array).
    Small images and single-CPU processes use one pass.
    """
    H = grey.shape[0]
    if H < 16 * (radius + 1) or _available_cpus() < 2:
        return _window_weights(grey, radius)
    half = H // 2
    with concurrent.futures.ThreadPoolExecutor(max_workers=1) as worker:
        top = worker.submit(_window_weights, grey[: half + radius], radius)
        bottom, steps = _window_weights(grey[half - radius :], radius)
        top = top.result()[0]
    planes = np.empty((top.shape[0],) + grey.shape)
    planes[:, :half] = top[:, :half]
    planes[:, half:] = bottom[:, radius:]
    return planes, steps


def _available_cpus():
    """CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _window_csr(planes, steps, diagonal, sign):
    """CSR matrix with ``sign * w`` off the diagonal and ``diagonal`` on it, pixels in C order.

    Every row is first given all ``K`` window entries; the entries outside
    the image, whose weight is exactly 0, are then removed.  The column
    indices of every row are ascending (the offsets are in row-major order).
    ``planes`` is overwritten.  (:func:`colorization_fill` builds its
    permuted rows block by block with :func:`_window_entries` and
    :func:`_window_rows` instead.)
    """
    flat, pixels, position = _window_entries(planes, diagonal, sign)
    mat = _window_rows(flat, steps, pixels, position)
    mat.has_sorted_indices = True
    return mat


def _window_entries(planes, diagonal, sign, order=None):
    """Prepare ``planes`` in place for :func:`_window_rows`.

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


def _window_rows(flat, steps, rows, position):
    """The rows of the pixels ``rows`` (in this order) of the window matrix, as CSR.

    ``flat``, ``position`` from :func:`_window_entries`; the columns are
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
    return _as_grey(image)


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
    grey = _as_grey(image)
    radius = _check_radius(window_radius)
    planes, steps = _window_weights(grey, radius)
    return _window_csr(planes, steps, 0.0, +1)


# ----------------------------------------------------------------------------
# the fill
# ----------------------------------------------------------------------------
def _segments(lengths):
    """Segment number and index within the segment for consecutive segments."""
    seg = np.repeat(np.arange(lengths.size), lengths)
    starts = np.cumsum(lengths) - lengths
    return seg, np.arange(seg.size) - starts[seg]


@functools.lru_cache(maxsize=8)
def _nested_dissection_keys(H, W, leaf=4):
    """Elimination position of every pixel of an H x W grid in a nested-dissection order.

    Rectangles are split recursively across their longer side by a
    one-pixel-wide line (which separates the 8-neighbour grid), the two halves
    numbered first and the separator last; rectangles of at most ``leaf``
    pixels are numbered row by row.  The order depends only on ``(H, W)``, so
    it is computed level by level over all rectangles at once and cached.
    Restricted to any subset of the pixels (the unknown ones), it is a good
    fill-reducing order for a sparse LU: on NYU frames it factors about twice
    as fast as SuperLU's own minimum-degree orders, at the same fill.
    """
    key = np.empty(H * W, dtype=np.int64)
    r0, r1 = np.array([0]), np.array([H])
    c0, c1 = np.array([0]), np.array([W])
    base = np.array([0])
    while r0.size:
        h, w = r1 - r0, c1 - c0
        area = h * w
        is_leaf = (area <= leaf) | ((h < 3) & (w < 3))
        if is_leaf.any():
            seg, t = _segments(area[is_leaf])
            lw = w[is_leaf][seg]
            rows = r0[is_leaf][seg] + t // lw
            cols = c0[is_leaf][seg] + t % lw
            key[rows * W + cols] = base[is_leaf][seg] + t
        split = ~is_leaf
        r0, r1, c0, c1, base, h, w = (a[split] for a in (r0, r1, c0, c1, base, h, w))
        if not r0.size:
            break
        by_row = h >= w  # cut across the longer side
        mid = np.where(by_row, r0 + h // 2, c0 + w // 2)
        a_r1, a_c1 = np.where(by_row, mid, r1), np.where(by_row, c1, mid)
        b_r0, b_c0 = np.where(by_row, mid + 1, r0), np.where(by_row, c0, mid + 1)
        area_a = (a_r1 - r0) * (a_c1 - c0)
        area_b = (r1 - b_r0) * (c1 - b_c0)
        seg, t = _segments(np.where(by_row, w, h))
        rows = np.where(by_row[seg], mid[seg], r0[seg] + t)
        cols = np.where(by_row[seg], c0[seg] + t, mid[seg])
        key[rows * W + cols] = (base + area_a + area_b)[seg] + t
        keep_a, keep_b = area_a > 0, area_b > 0
        r0, r1, c0, c1, base = (
            np.concatenate((r0[keep_a], b_r0[keep_b])),
            np.concatenate((a_r1[keep_a], r1[keep_b])),
            np.concatenate((c0[keep_a], b_c0[keep_b])),
            np.concatenate((a_c1[keep_a], c1[keep_b])),
            np.concatenate((base[keep_a], (base + area_a)[keep_b])),
        )
    key.flags.writeable = False
    return key


@functools.lru_cache(maxsize=8)
def _nested_dissection_order(H, W):
    """The pixels of an H x W grid in nested-dissection elimination order (cached)."""
    key = _nested_dissection_keys(H, W)
    order = np.empty_like(key)
    order[key] = np.arange(key.size)
    order.flags.writeable = False
    return order


# Vector kernels of the GMRES below.  ``einsum`` runs single-threaded C loops:
# the multi-threaded BLAS behind ``@``/``norm`` spends more time waking and
# synchronising its threads than computing on vectors of this length when the
# cores are shared, which made the iteration twice as slow in measurements.
def colorization_fill(image, depth, *, mask=None, alpha=1.0, rtol=1e-8, window_radius=1,
                      maxiter=1000):
    """Fill depth holes with the NYU toolbox colorization method, fast and exact.

    Solves exactly the linear system of ``fill_depth_colorization.m`` (NYU
    Depth V2 toolbox) for every pixel at once: unknown pixels become a
    grey-image-weighted average of their 3x3 neighbours, known pixels a blend
    of their measurement and that average.

    Parameters
    ----------
    image : array_like, shape (H, W, 3) or (H, W)
        Guide image, uint8, uint16 or float in [0, 1]; converted to grey with
        :data:`GREY_WEIGHTS`.
    depth : array_like, shape (H, W)
        Depth (metres, or any unit).  Values where ``mask`` is False are
        ignored and may be 0, NaN or anything else.
    mask : array_like of bool, shape (H, W), optional
        Known pixels.  Default: ``isfinite(depth) & (depth > 0)``.  The NYU
        toolbox also treats ``depth == 10`` (the clipped Kinect maximum) as
        missing; pass ``mask=(depth > 0) & (depth != 10)`` to do the same.
    alpha : float, optional
        Weight (> 0) of the known depth values; the toolbox uses 1.
    rtol : float, optional
        Accuracy of the iterative part, relative to ``max |depth[mask]|``: the
        returned depth differs from the exact solution of the system by at
        most ``rtol * max |depth[mask]|`` at every pixel (up to rounding in
        the sparse LU).  The default 1e-8 is 0.1 micrometre at 10 m.
    window_radius : int, optional
        Window radius; the toolbox uses 1 (3x3 window).
    maxiter : int, optional
        Maximum number of Krylov iterations (typically 4-10 are needed).

    Returns
    -------
    ndarray of float64, shape (H, W)
        Dense depth, in the unit of ``depth``.  It lies within
        ``[min depth[mask], max depth[mask]]``.  Known pixels are smoothed
        too: with finite ``alpha`` they are *not* reproduced exactly (see
        Notes).

    Raises
    ------
    ValueError
        For a bad image (see :func:`rgb_to_grey`), a depth/mask of another
        shape than the image, a non-boolean mask, NaN/inf depth under the
        mask, no known pixel, or ``alpha``/``rtol`` not finite and > 0.
    RuntimeError
        If the Krylov iteration does not reach ``rtol`` within ``maxiter``
        iterations (it converges at least geometrically; this should not
        happen).

    Notes
    -----
    With ``W`` from :func:`colorization_weights`, ``M = diag(mask)`` and ``s =
    max |depth[mask]|`` the toolbox solves, for ``x`` in units of ``s``::

        (I - W + alpha M) x = alpha M d / s,           depth_out = s x.

    Row ``p`` says ``(1 + alpha m_p) x_p = (W x)_p + alpha m_p d_p / s``: each
    output is a convex combination of its neighbours' outputs and (if known)
    its measurement, hence the maximum principle above, and a known pixel
    equals ``(alpha d_p + (W x)_p) / (1 + alpha)`` -- its measurement only
    where the neighbourhood average agrees with it, or as ``alpha -> inf``.
    The system is a non-symmetric, non-singular M-matrix.

    *Solution.*  Let ``E`` be the unknown pixels together with the known
    pixels that have at least two unknown pixels in their window (the known
    pixels most strongly coupled to the holes, e.g. between thin holes), and
    ``K`` the other known pixels.  Ordering ``E`` first::

        [A_EE  A_EK] [x_E]   [b_E]
        [A_KE  A_KK] [x_K] = [b_K],        b = alpha M d,

    ``A_EE`` is factored exactly once (SuperLU, in a cached nested-dissection
    order of the pixel grid; ``A_EE`` is row diagonally dominant, so its
    transpose is factored without pivoting), and the Schur complement
    system::

        S x_K = b_K - A_KE A_EE^{-1} b_E,      S = A_KK - A_KE A_EE^{-1} A_EK,

    is solved by right-preconditioned GMRES from ``x_K = d_K``.  Every
    product with ``S`` computes ``x_E = -A_EE^{-1} A_EK x_K`` for its Krylov
    direction (one pair of triangular solves); those are kept, so the final
    ``x_E`` is their combination plus the (affine) lift of the starting
    guess, and costs no further solve.  The preconditioner is the Neumann
    series, four terms, of the inverse of the Schur complement of the *strip*
    ``s`` of ``E`` within two window steps of ``K`` only, ``A_KK - A_Ks
    A_ss^{-1} A_sK`` (``A_ss`` is small and thin, cheap to factor and solve):
    it captures the strong coupling of ``K`` to itself through the near
    holes, which a preconditioner built from ``A_KK`` alone misses.
    ``A_EE^{-1}`` and ``-A_EE^{-1} A_EK`` are non-negative, the latter with
    row sums at most 1, so ``S`` is an M-matrix with every row sum at least
    ``alpha``: ``||S^{-1}||_inf <= 1/alpha``, and the error of ``x_E`` is at
    most the largest error of ``x_K``.  Hence stopping when the residual
    satisfies ``||r||_inf <= alpha * rtol`` guarantees ``max |x - x_exact|
    <= rtol``.

    The difficulty of this system for iterative methods lies in the unknown
    block: in flat, JPEG-quantised image regions the weights split the pixels
    into clusters joined by links of relative weight ~1e-4, and algebraic
    multigrid (smoothed aggregation, Ruge-Stuben, AIR) needs 40-150 GMRES
    iterations; geometric black-box multigrid
    (:class:`sparsedepth.linalg.multigrid.GridMultigrid` with operator-dependent
    interpolation) as GMRES preconditioner of the whole system is still 2.5
    cm off after 100 iterations on a 640x480 NYU frame.  The exact
    elimination removes that difficulty, leaving a known block whose Jacobi
    iteration contracts by ``1/(1 + alpha)`` per step.  With the two-term
    Neumann series of ``A_KK^{-1}`` and only the unknown pixels eliminated,
    GMRES needs 9 iterations for ``rtol = 1e-8`` on a 640x480 NYU frame with
    27 % holes (rate 0.15, set by the known pixels next to the holes); with
    the preconditioner above it needs 4 (rate 0.016).  There (cProfile,
    5 calls on nyu_metric3d/00000, 0.70 s per call on a loaded 2-core
    machine, about 0.55 s unloaded, all in one thread), the two
    factorisations take 35 % of the time, the 17 triangular solves (5 with
    ``A_EE``, 12 with ``A_ss``) 15 %, the sparse products 12 %, the window
    weights 12 %, the assembly and splitting of the matrix 11 % and the rest
    of GMRES the remainder.

    *Two threads.*  ``A_EE`` (and the lift of the starting guess) is
    factorised in a worker thread as soon as the rows of ``E`` exist;
    SuperLU releases the GIL, so meanwhile this thread assembles the rows
    of ``K``, the strip's blocks and factorises ``A_ss``.  On that frame
    this hid about 50 ms of the 0.2-0.3 s factorisation: 0.493 s instead of
    0.521 s best of 15 interleaved calls, 0.565 s instead of 0.654 s
    median.  The window weights are computed for the two halves of the
    image in two threads as well (:func:`_window_weights_two_threads`):
    with both, 0.454 s instead of 0.503 s best of 15, 0.593 s instead of
    0.647 s median.  The result is the same bit for bit.

    *Not used: mixed precision.*  Factoring ``A_EE`` in float32 (SuperLU)
    saves only 18 % of its factorisation (0.26 s -> 0.22 s; with one-column
    panels the factorisation is not bound by the bytes of the values) and
    6 ms per solve, but the Schur complement is then no longer applied
    exactly: FGMRES on the whole system (float64 residuals, block
    upper-triangular preconditioner with the float32 factors) must bound
    the error caused by the residual ``r_E`` of the eliminated rows by
    ``||A_EE^{-1}||_inf ||r_E||_inf``, with ``||A_EE^{-1}||_inf ~ 2e5`` on
    that frame (one more solve to certify it), which takes 5 iterations
    instead of 4: it was 13 % slower overall.

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
    >>> rng = np.random.default_rng(0)
    >>> image = rng.random((20, 30))
    >>> depth = np.full((20, 30), 2.0)
    >>> depth[5:10, 5:20] = 0.0                      # a hole
    >>> out = colorization_fill(image, depth)
    >>> bool(np.allclose(out, 2.0))
    True
    """
    grey = _as_grey(image)
    radius = _check_radius(window_radius)
    d, m = _depth_and_mask(depth, mask, grey.shape)
    alpha = _check_positive(alpha, "alpha")
    rtol = _check_positive(rtol, "rtol")
    if (not isinstance(maxiter, numbers.Integral)) or isinstance(maxiter, bool) or maxiter < 1:
        raise ValueError(f"maxiter must be an integer >= 1, got {maxiter!r}")

    scale = float(np.max(np.abs(d[m])))
    if scale == 0.0:
        return np.zeros(grey.shape)
    known_flat = m.ravel()
    elim, strip, rim = _eliminated_sets(m, radius)
    nd_order = _nested_dissection_order(*grey.shape)
    unknown = nd_order[elim.ravel()[nd_order]]  # in a fill-reducing order
    known = np.flatnonzero(~elim)
    order = np.concatenate((unknown, known))

    planes, steps = _window_weights_two_threads(grey, radius)
    flat, pixels, position = _window_entries(planes, 1.0 + alpha * known_flat, -1, order)
    n_e = unknown.size
    b = d.ravel()[order]  # 0 at the holes
    b *= alpha / scale
    x0 = d.ravel()[known] / scale
    # the rows of K are built while A_EE is factorised (in a worker thread)
    x, _ = _solve_schur(_window_rows(flat, steps, pixels[:n_e], position),
                        lambda: _window_rows(flat, steps, pixels[n_e:], position), b, x0=x0,
                        atol=alpha * rtol, maxiter=maxiter, diag_K=1.0 + alpha,
                        strip=np.flatnonzero(strip.ravel()[unknown]), rim=np.flatnonzero(rim.ravel()[known]))
    out = np.empty(grey.size)
    out[order] = x * scale
    return out.reshape(grey.shape)


def _csr_split_columns(A, split):
    """``(A[:, :split], A[:, split:])`` of a CSR matrix, in one pass over its entries."""
    left = A.indices < split
    counts = np.concatenate(([0], np.cumsum(left, dtype=A.indptr.dtype)))
    indptr_left = counts[A.indptr]
    indptr_right = A.indptr - indptr_left
    right = ~left
    return (
        scipy.sparse.csr_matrix((A.data[left], A.indices[left], indptr_left), shape=(A.shape[0], split)),
        scipy.sparse.csr_matrix((A.data[right], A.indices[right] - split, indptr_right),
                                shape=(A.shape[0], A.shape[1] - split)),
    )


def _box_count(mask, radius):
    """Number of True pixels of ``mask`` in the (clipped) window of radius ``radius`` of every pixel."""
    return _box_sum(mask.astype(np.int32), radius)


def _box_sum(image, radius):
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


def _eliminated_sets(known, radius):
    """The pixels eliminated exactly, and the strip of them seen by the preconditioner.

    Returns three boolean (H, W) masks.  ``elim`` holds the holes and the
    known pixels with at least ``_LAYER_MIN_UNKNOWN`` holes in their window
    (the known pixels most strongly coupled to the holes, notably those
    between thin holes); the others form the iterated set ``K``.  ``strip``
    holds the pixels of ``elim`` within ``_STRIP_WIDTH`` window steps of
    ``K``, and ``rim`` the pixels of ``K`` with a pixel of ``elim`` in their
    window.
    """
    hole = ~known
    elim = hole | (known & (_box_count(hole, radius) >= _LAYER_MIN_UNKNOWN))
    strip = elim & (_box_count(~elim, _STRIP_WIDTH * radius) > 0)
    rim = ~elim & (_box_count(elim, radius) > 0)
    return elim, strip, rim


def _csr_submatrix(A, rows, column_map, n_columns):
    """Rows ``rows`` of the CSR matrix ``A``, keeping column ``j`` as ``column_map[j]`` if it is >= 0."""
    start = A.indptr[rows]
    seg, t = _segments(A.indptr[rows + 1] - start)
    entries = start[seg] + t
    columns = column_map[A.indices[entries]]
    keep = columns >= 0
    indptr = np.zeros(rows.size + 1, dtype=A.indptr.dtype)
    np.cumsum(np.bincount(seg[keep], minlength=rows.size), out=indptr[1:])
    return scipy.sparse.csr_matrix((A.data[entries[keep]], columns[keep], indptr),
                                   shape=(rows.size, n_columns))


def _factor_rows(B):
    """SuperLU factorisation of the CSR matrix ``B``; ``lu.solve(v, trans="T")`` solves ``B y = v``.

    The CSR arrays of ``B`` (sorted here) are the CSC arrays of ``B^T``.
    ``B`` is a principal submatrix of the system, row diagonally dominant, so
    ``B^T`` is column diagonally dominant: it is factored in the given order,
    without pivoting.
    """
    B.sort_indices()
    Bt = scipy.sparse.csc_matrix((B.data, B.indices, B.indptr), shape=B.shape)
    # no relaxed supernodes and panels of one column: 15-20 % faster than
    # SuperLU's defaults (relax 10, panel 20) on the small supernodes of a
    # nested-dissection order of a 2-D grid, and the transposed solve is 1.5
    # times faster than the solve with a factorisation of B (measured on NYU
    # frames).  Large values are unsafe: relax=100, panel_size=40 segfaults
    # (SciPy 1.17).
    return scipy.sparse.linalg.splu(
        Bt, permc_spec="NATURAL", diag_pivot_thresh=0.0, relax=1, panel_size=1,
        options={"SymmetricMode": True},
    )


def _solve_schur(A_E, A_K, b, *, x0, atol, maxiter, diag_K, strip=None, rim=None):
    """Solve ``A x = b`` by exact elimination of the unknowns ``E`` (the first rows and columns).

    ``A_E`` and ``A_K`` (CSR) are the rows of ``A`` of the eliminated pixels
    ``E``, numbered first in a fill-reducing order, and of the others ``K``
    (all known), numbered last; ``A_K`` may instead be a function returning
    them, called while ``A_EE`` is factorised in a worker thread (SuperLU
    releases the GIL, so the two overlap on a multi-core machine).
    ``diag_K`` is the (constant) diagonal of the rows of ``K``; ``x0`` the
    initial guess of ``x_K``.  GMRES runs on the Schur complement of
    ``A_EE`` (see :func:`colorization_fill`), preconditioned by
    ``_NEUMANN_TERMS`` terms of the Neumann series of the inverse of ``A_KK -
    A_Ks A_ss^{-1} A_sK``, the Schur complement of the pixels ``strip`` of
    ``E`` only (indices into ``E``; None or empty: ``A_KK`` alone).  ``rim``
    (indices into ``K``) must hold every row of ``K`` with an entry in the
    columns of ``strip``.  Returns ``(x, residual_history)`` with ``x`` in
    the order of ``A``.
    """
    n_e, n = A_E.shape
    n_k = n - n_e
    if n_k == 0:  # everything eliminated: a direct solve
        return _factor_rows(A_E).solve(b, trans="T"), np.zeros(0)
    if n_e:
        A_EE, A_EK = _csr_split_columns(A_E, n_e)
        A_EE.sort_indices()  # here, not in the worker: this thread reads A_EE meanwhile

        def factor_and_lift_x0():
            lu = _factor_rows(A_EE)
            # the lift of the initial guess is affine: A_EE^{-1} (b_E - A_EK x0)
            return lu, lu.solve(b[:n_e] - A_EK @ x0, trans="T")

        worker = concurrent.futures.ThreadPoolExecutor(max_workers=1)
        factorisation = worker.submit(factor_and_lift_x0)
        worker.shutdown(wait=False)
    if callable(A_K):
        A_K = A_K()
    b_K = b[n_e:]

    def apply(x_K, x_E):
        # S x_K = A_KK x_K + A_KE x_E with x_E = lift(x_K)
        return A_K @ (x_K if x_E is None else np.concatenate((x_E, x_K)))

    # A_KK z computed as A_K [0; z] (as fast as a separate A_KK, whose
    # extraction would cost more than it saves)
    y = np.zeros(n)
    y_K = y[n_e:]

    def apply_KK(z):
        y_K[:] = z
        return A_K @ y

    lift = lift_x0 = None
    apply_M = apply_KK
    if n_e:
        if strip is not None and strip.size:
            itype = A_K.indices.dtype
            strip_map = np.full(n, -1, dtype=itype)
            strip_map[strip] = np.arange(strip.size, dtype=itype)
            A_sK = _csr_submatrix(A_EK, strip, np.arange(n_k, dtype=itype), n_k)
            A_Ks = _csr_submatrix(A_K, rim, strip_map, strip.size)
            lu_s = _factor_rows(_csr_submatrix(A_EE, strip, strip_map, strip.size))

            def apply_M(z):
                t = apply_KK(z)
                t[rim] -= A_Ks @ lu_s.solve(A_sK @ z, trans="T")
                return t

        lu, lift_x0 = factorisation.result()

        def lift(x_K):
            # x_E = -A_EE^{-1} A_EK x_K, the linear part of the lift
            x_E = lu.solve(A_EK @ x_K, trans="T")
            return np.negative(x_E, out=x_E)

    # Neumann series of the approximate Schur complement M = D - P with P >= 0
    # (D = diag_K): z_{j+1} = z_j + (v - M z_j) / D from z_1 = v / D
    def apply_precond(v):
        z0 = v / diag_K
        z = z0.copy()
        for _ in range(_NEUMANN_TERMS - 1):
            t = apply_M(z)
            t /= diag_K
            z -= t
            z += z0
        return z

    x_K, x_E, history, res_inf, converged = gmres(apply, lift, b_K, x0, apply_precond, atol, maxiter,
                                                   lift_x0=lift_x0)
    if not converged:
        raise RuntimeError(
            f"colorization_fill: GMRES did not reach the tolerance {atol:.3g} in {maxiter} "
            f"iterations (max-norm residual {res_inf:.3g}); increase maxiter or rtol"
        )
    return (x_K if x_E is None else np.concatenate((x_E, x_K))), history
