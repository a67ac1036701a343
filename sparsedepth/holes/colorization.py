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
sparse LU of the whole system.  The pieces live beside it: the grey image and
the window affinities in :mod:`~sparsedepth.holes.affinity`, the elimination
order in :mod:`~sparsedepth.holes.ordering`, the block solve in
:mod:`~sparsedepth.holes.schur`; this module checks the inputs, decides what
runs in two threads and assembles the fill.

May import NumPy, :mod:`sparsedepth._validation` and the modules above.

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

import numpy as np

from .._system import available_cpus
from .._validation import as_depth_and_mask, check_bool_mask, check_count, check_positive_real, check_same_shape
from .affinity import GREY_WEIGHTS, as_grey, colorization_weights, rgb_to_grey, window_entries, window_rows, window_weights
from .ordering import nested_dissection_order
from .schur import eliminated_sets, solve_schur

__all__ = [
    "GREY_WEIGHTS",
    "rgb_to_grey",
    "colorization_weights",
    "colorization_fill",
    "window_weights_two_threads",
]


def window_weights_two_threads(grey, radius):
    """:func:`~sparsedepth.holes.affinity.window_weights` computed for the top and the bottom half in two threads.

    Each half is given ``radius`` rows of the other as a halo, so every
    pixel sees the same window as in one pass: the planes are identical
    (they are per-pixel results).  NumPy releases the GIL in its loops, so on
    a multi-core machine the two halves are computed in parallel.  Small
    images and single-CPU processes use one pass.
    """
    H = grey.shape[0]
    if H < 16 * (radius + 1) or available_cpus() < 2:
        return window_weights(grey, radius)
    half = H // 2
    with concurrent.futures.ThreadPoolExecutor(max_workers=1) as worker:
        top = worker.submit(window_weights, grey[: half + radius], radius)
        bottom, steps = window_weights(grey[half - radius :], radius)
        top = top.result()[0]
    planes = np.empty((top.shape[0],) + grey.shape)
    planes[:, :half] = top[:, :half]
    planes[:, half:] = bottom[:, radius:]
    return planes, steps


def _check_fill_inputs(image, depth, mask, alpha, rtol, window_radius, maxiter):
    """The checked inputs of :func:`colorization_fill`: grey image, depth (0 where unknown), mask and options."""
    grey = as_grey(image)
    radius = check_count(window_radius, name="window_radius")
    if mask is not None:
        check_bool_mask(mask, np.shape(depth), shape_name="depth")
    d, m = as_depth_and_mask(depth, mask, name="depth")
    check_same_shape(d.shape, grey.shape, "depth", "image")
    alpha = check_positive_real(alpha, name="alpha")
    rtol = check_positive_real(rtol, name="rtol")
    maxiter = check_count(maxiter, name="maxiter")
    return grey, d, m, radius, alpha, rtol, maxiter


# the docstring carries the maths and the solver design (Notes); the code below it is short
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
        Known pixels.  Default: ``isfinite(depth) & (depth > 0)`` (a negative
        depth is then an error, as under the mask).  The NYU
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
        Maximum number of Krylov (GMRES) iterations; the iteration stops
        earlier once ``rtol`` is met (see Notes).

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
        mask, negative depth (under the mask, or anywhere without one), no
        known pixel, ``alpha``/``rtol`` not finite and > 0, or
        ``window_radius``/``maxiter`` not an integer >= 1.
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

    In flat, JPEG-quantised image regions the weights split the unknown
    pixels into clusters joined by very weak links, on which algebraic and
    geometric multigrid preconditioners converge slowly.  The exact elimination
    removes that difficulty, leaving a known block whose Jacobi iteration
    contracts by ``1/(1 + alpha)`` per step; eliminating the coupled known
    pixels too and preconditioning with the strip's Schur complement bring
    GMRES down to a few iterations for ``rtol = 1e-8``.  Most of the time is
    spent in the two factorisations.

    *Two threads.*  ``A_EE`` (and the lift of the starting guess) is
    factorised in a worker thread as soon as the rows of ``E`` exist;
    SuperLU releases the GIL, so meanwhile this thread assembles the rows
    of ``K``, the strip's blocks and factorises ``A_ss``.  The window
    weights are computed for the two halves of the image in two threads as
    well.  The result is the same bit for bit as with one thread.

    *Not used: mixed precision.*  With ``A_EE`` factored in float32 the
    Schur complement is no longer applied exactly: the error caused by the
    residual ``r_E`` of the eliminated rows must then be bounded by
    ``||A_EE^{-1}||_inf ||r_E||_inf`` (``||A_EE^{-1}||_inf`` can be large,
    and certifying it costs one more solve), which costs more
    iterations than the cheaper factorisation saves.

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
    grey, d, m, radius, alpha, rtol, maxiter = _check_fill_inputs(image, depth, mask, alpha, rtol, window_radius,
                                                                  maxiter)
    scale = float(np.max(np.abs(d[m])))
    if scale == 0.0:
        return np.zeros(grey.shape)
    known_flat = m.ravel()
    elim, strip, rim = eliminated_sets(m, radius)
    nd_order = nested_dissection_order(*grey.shape)
    unknown = nd_order[elim.ravel()[nd_order]]  # in a fill-reducing order
    known = np.flatnonzero(~elim)
    order = np.concatenate((unknown, known))

    planes, steps = window_weights_two_threads(grey, radius)
    flat, pixels, position = window_entries(planes, 1.0 + alpha * known_flat, -1, order)
    n_e = unknown.size
    b = d.ravel()[order]  # 0 at the holes
    b *= alpha / scale
    x0 = d.ravel()[known] / scale
    # the rows of K are built while A_EE is factorised (in a worker thread)
    x, _ = solve_schur(window_rows(flat, steps, pixels[:n_e], position),
                       lambda: window_rows(flat, steps, pixels[n_e:], position), b, x0=x0,
                       atol=alpha * rtol, maxiter=maxiter, diag_K=1.0 + alpha,
                       strip=np.flatnonzero(strip.ravel()[unknown]), rim=np.flatnonzero(rim.ravel()[known]))
    out = np.empty(grey.size)
    out[order] = x * scale
    return out.reshape(grey.shape)
