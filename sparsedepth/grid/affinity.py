r"""Windowed local-linear image affinities: the matting Laplacian of Levin, Lischinski and Weiss as a grid operator.

In every 3x3 window ``w`` of the image, depth is modelled as an affine function of the image's channels,
``z_i ≈ aᵀ I_i + b`` for the nine pixels ``i`` of the window, with a ridge penalty ``ε ‖a‖²`` on the slope.
The cost of the best fit, summed over the windows,

.. math::

    J(z) = \sum_w \min_{a, b} \Bigl[\sum_{i \in w} (z_i - a^\top I_i - b)^2 + \varepsilon \|a\|^2\Bigr]
         = z^\top L z,

is a quadratic form whose matrix is the matting Laplacian

.. math::

    L_{ij} = \sum_{w \ni i, j} \Bigl(\delta_{ij} - \tfrac19 \bigl(1 + (I_i - \mu_w)^\top
             (\Sigma_w + \tfrac{\varepsilon}{9} \mathbf 1)^{-1} (I_j - \mu_w)\bigr)\Bigr),

``μ_w`` and ``Σ_w`` the mean and (biased) covariance of the colours in the window.  Two pixels of one window are
coupled, so ``L`` has the 25-point stencil of radius 2.  Depth may follow any affine function of the colour inside
a window (so it can jump where the colour jumps) but not vary where the colour does not.  The same sum over the
windows of another shape (:data:`WINDOWS`: a pixel with its four neighbours, or 2x2 pixels; ``9`` becomes the
window's number of pixels ``n``) couples fewer pixels: a 13- or 9-point ``L``.

:func:`local_linear_operator` returns an operator ``K`` (a :class:`~sparsedepth.grid.operators.StencilOperator`)
with ``Kᵀ K = L``: per window, the nine residuals of the best fit and ``√ε a`` (one row per channel), so that
``‖K z‖² = J(z)``.  Its :meth:`~LocalLinearOperator.add_normal_stencil` writes ``L`` directly (one whole-array
operation per pair of window pixels), which is what the normal equations use.

References
----------
A. Levin, D. Lischinski, Y. Weiss, "A closed-form solution to natural image matting", CVPR 2006 and IEEE TPAMI
30(2), 2008 (equations 12-13).

May import NumPy, :mod:`.operators` and :mod:`sparsedepth._validation`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._validation import as_float_image, check_nonnegative_real
from .operators import StencilOperator, _flat_images
from ..limits import memory_limits

__all__ = ["LocalLinearOperator", "local_linear_operator", "WINDOWS", "WINDOW_OFFSETS", "PINV_CUTOFF"]

#: The window shapes of the term: the offsets of a window's pixels from its anchor pixel, in C order.  ``"3x3"``
#: couples pixels up to 2 apart in each direction (a 25-point ``L``); ``"cross"`` (a pixel and its four
#: neighbours) and ``"2x2"`` couple pixels at most 2 apart in city-block distance, a 13- and a 9-point ``L``.
WINDOWS = {
    "3x3": tuple((dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)),
    "cross": ((-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)),
    "2x2": ((0, 0), (0, 1), (1, 0), (1, 1)),
}
#: The nine offsets of a 3x3 window from its centre, in C order.
WINDOW_OFFSETS = WINDOWS["3x3"]
#: With ``ε = 0``, eigenvalues of a window's colour covariance at or below this (in [0, 1]² units) count as 0.
PINV_CUTOFF = 1e-10


def local_linear_operator(image, eps: float, *, window: str = "3x3", copy: bool = True) -> "LocalLinearOperator":
    """The operator ``K`` with ``Kᵀ K`` the matting Laplacian of ``image`` over the windows of one shape.

    Parameters
    ----------
    image : ndarray, (H, W) or (H, W, C)
        uint8, uint16 or float in [0, 1] (see :func:`sparsedepth._validation.as_float_image`); every channel is
        a regressor of the local affine model.
    eps : float
        ``ε >= 0``, the ridge weight of the slope ``a`` (in squared image units: [0, 1]²).  Large ``ε`` makes
        every window fit a constant (``L`` becomes the sum of the windows' centring matrices); ``ε = 0`` uses
        the pseudo-inverse of the window covariance (eigenvalues at or below :data:`PINV_CUTOFF` dropped).
    window : {"3x3", "cross", "2x2"}, default "3x3"
        The shape of the windows (:data:`WINDOWS`); every placement of it inside the grid is a window.
    copy : bool, default True
        False: a float64 ``(H, W, C)`` image already scaled to [0, 1] is kept as it is (a view of contiguous
        channel planes, ``np.moveaxis(planes, 0, -1)``, without a copy); any other image is converted as with
        True.

    Returns
    -------
    LocalLinearOperator

    Raises
    ------
    ValueError
        If ``eps`` is not a finite number ``>= 0``, ``window`` is not a name of :data:`WINDOWS`, or for a bad
        image.

    Examples
    --------
    >>> K = local_linear_operator(np.array([[0.0, 0, 1], [0, 0, 1], [0, 0, 1]]), 1e-3)
    >>> z = np.array([2.0, 2, 5, 2, 2, 5, 2, 2, 5])  # z = 2 + 3 I: affine in the image
    >>> round(float(np.sum((K @ z) ** 2)), 4)  # small, not 0: the ridge ε shrinks the slope 3
    0.009
    """
    eps = check_nonnegative_real(eps, name="local_linear_eps")
    if not isinstance(window, str) or window not in WINDOWS:
        raise ValueError(f"window must be one of {sorted(WINDOWS)}, got {window!r}")
    array = np.asarray(image)
    keep = not copy and array.dtype == np.float64 and array.ndim == 3
    return LocalLinearOperator(array if keep else as_float_image(image), eps, window)


def _symmetric_inverse(S):
    """Inverses of symmetric positive definite matrices given as planes ``S[c][d]`` (only ``c <= d`` is read).

    Returns the inverse as a nested list of planes, ``P[c][d]`` and ``P[d][c]`` the same array.  1x1 and 3x3
    (grey and colour images) by the closed form (the adjugate over the determinant), one whole-array operation
    per product.
    """
    C = len(S)
    if C == 1:
        return [[np.divide(1.0, S[0][0])]]
    if C == 3:
        shape = np.shape(S[0][0])
        cofactors = np.empty((6,) + shape)
        c00, c01, c02, c11, c12, c22 = cofactors
        work = np.empty(shape)
        for cofactor, (a, b), (c, d) in ((c00, (S[1][1], S[2][2]), (S[1][2], S[1][2])),
                                         (c01, (S[0][2], S[1][2]), (S[0][1], S[2][2])),
                                         (c02, (S[0][1], S[1][2]), (S[0][2], S[1][1])),
                                         (c11, (S[0][0], S[2][2]), (S[0][2], S[0][2])),
                                         (c12, (S[0][1], S[0][2]), (S[0][0], S[1][2])),
                                         (c22, (S[0][0], S[1][1]), (S[0][1], S[0][1]))):
            np.multiply(a, b, out=cofactor)  # a b − c d
            np.multiply(c, d, out=work)
            cofactor -= work
        determinant = np.multiply(S[0][0], c00)
        np.multiply(S[0][1], c01, out=work)
        determinant += work
        np.multiply(S[0][2], c02, out=work)
        determinant += work
        np.divide(1.0, determinant, out=determinant)
        cofactors *= determinant
        return [[c00, c01, c02], [c01, c11, c12], [c02, c12, c22]]
    full = np.moveaxis(np.array([[S[min(c, d)][max(c, d)] for d in range(C)] for c in range(C)]), (0, 1), (-2, -1))
    inverse = np.moveaxis(np.linalg.inv(full), (-2, -1), (0, 1))
    return [[inverse[c, d] for d in range(C)] for c in range(C)]


def _apply(P, x, out=None, work=None):
    """``P x`` per pixel: ``P`` a nested list of ``C x C`` planes, ``x`` of shape ``(C, ...)`` (broadcast with the planes).

    ``out`` (shape of ``x``) and ``work`` (shape ``x.shape[1:]``) are optional buffers.
    """
    out = np.empty(x.shape) if out is None else out
    work = np.empty(x.shape[1:]) if work is None else work
    for c, row in enumerate(P):
        np.multiply(row[0], x[0], out=out[c])
        for d in range(1, x.shape[0]):
            np.multiply(row[d], x[d], out=work)
            out[c] += work
    return out


def _divide(array, count):
    """``array /= count`` in place; by a power of two as the product with its reciprocal (exact: the same rounding)."""
    if count & (count - 1) == 0:
        array *= 1.0 / count
    else:
        array /= count
    return array


def _dot(x, y):
    """``xᵀ y`` per pixel for ``(C, ...)`` arrays."""
    out = x[0] * y[0]
    for c in range(1, x.shape[0]):
        out += x[c] * y[c]
    return out


class LocalLinearOperator(StencilOperator):
    r"""``K`` of the local-linear (matting Laplacian) term on an ``(H, W)`` grid; build it with :func:`local_linear_operator`.

    Row blocks (each one row per pixel, C order, non-zero only at the anchor pixels ``p`` of the windows, those
    whose window ``p + o`` (``o`` in ``window``, a tuple of :data:`WINDOWS`) lies inside the grid; for a 3x3 window
    the interior pixels ``1 <= y <= H-2``, ``1 <= x <= W-2``): with ``n`` the window's pixels, block ``j < n`` is the
    residual ``z[p + o_j] − a_pᵀ I[p + o_j] − b_p`` of the window anchored at ``p`` (``o_j`` the ``j``-th offset),
    block ``n + c`` is ``√ε a_{p,c}``, with ``(a_p, b_p)`` the ridge fit of that window.

    Notes
    -----
    With ``X`` the window's centred colours (n x C), ``G = XᵀX = n Σ`` and ``M = (G + ε 1)^{-1}``, the fit is
    ``a = M Xᵀ z_w``, ``b = z̄ − aᵀ μ``, and the rows are ``r = C z_w − X a`` (``C = 1 − 11ᵀ/n``) and ``√ε a``.
    Since ``M (G + ε) M = M``, ``‖r‖² + ε ‖a‖² = z_wᵀ (C − X M Xᵀ) z_w = z_wᵀ L_w z_w``: ``Kᵀ K = Σ_w L_w = L``.
    The adjoint of one window's rows ``(v, u)`` is ``C v + X M (√ε u − Xᵀ v)``.  All sums over a window are ``n``
    shifted whole-array operations.

    The windows of anchor rows ``k0 .. k1 − 1`` are computed as one flat run of length ``(k1 − k0) W − s``
    (``s`` the columns a window spans, minus 1): position ``f`` of the run is the window anchored ``f // W``
    rows and ``f % W`` columns after the first window of row ``k0``, so pixel ``o`` of every window of the run
    is one contiguous run of the flat image, which NumPy processes several times faster than a strided
    two-dimensional view.  The positions with ``f % W >= W − s`` (the wrap from a row's last window to the
    next row's first) are no windows: they are computed like the others and set to 0 before anything is
    written to the grid.  Every value of a real window is computed by the same operations in the same order
    as on the two-dimensional grid.
    """

    def __init__(self, image, eps, window="3x3"):
        img = np.asarray(image, dtype=np.float64)
        H, W, C = img.shape
        self.grid_shape = (H, W)
        self.eps = float(eps)
        self.channels = C
        self.window = window
        self.offsets_in_window = WINDOWS[window]
        self.size = len(self.offsets_in_window)
        self._image = np.ascontiguousarray(np.moveaxis(img, -1, 0))  # (C, H, W): whole-image planes
        self._flat = self._image.reshape(C, H * W)  # the same planes, flat
        taps = tuple((o, float("nan")) for o in self.offsets_in_window)  # taps of every block; coefficients per pixel
        self.blocks = (taps,) * (self.size + C)
        dys, dxs = [o[0] for o in self.offsets_in_window], [o[1] for o in self.offsets_in_window]
        self._low = (-min(dys), -min(dxs))  # the first anchor row and column
        self._span = (max(dys) - min(dys), max(dxs) - min(dxs))  # rows and columns a window covers, minus 1
        self._anchor_rows = max(0, H - self._span[0])  # the anchor rows: grid rows low .. low + anchor_rows - 1
        self._windows = H > self._span[0] and W > self._span[1]
        self._planes = None
        self._fit_cache = None

    # -- the fit of every window ---------------------------------------------
    def _band_rows(self):
        """Window rows per band of the band-wise computations (about ``affinity_band_pixels`` pixels).

        ``affinity_band_pixels`` is the :class:`~sparsedepth.limits.MemoryLimits` field.
        """
        return max(1, memory_limits().affinity_band_pixels // self.grid_shape[1])

    def _run_length(self, k0, k1):
        """Length of the flat run of the windows of anchor rows ``k0 .. k1 − 1``."""
        return (k1 - k0) * self.grid_shape[1] - self._span[1]

    def _run(self, flat, o, k0, length, origin=0):
        """The run of window pixel ``o`` of the windows from anchor row ``k0``: a view of ``flat[..., :]``.

        ``flat`` holds the flat grid from grid index ``origin`` on.
        """
        start = (k0 + self._low[0] + o[0]) * self.grid_shape[1] + self._low[1] + o[1] - origin
        return flat[..., start:start + length]

    def _run_sum(self, flat, k0, length, origin=0):
        """Σ over the window of every window of the run (:meth:`_run` summed in the order of the window's pixels)."""
        first, second, *others = self.offsets_in_window
        out = np.add(self._run(flat, first, k0, length, origin), self._run(flat, second, k0, length, origin))
        for o in others:
            out += self._run(flat, o, k0, length, origin)
        return out

    def _outside(self, k0, k1):
        """The positions of the run of anchor rows ``k0 .. k1 − 1`` that are no window (an index array)."""
        W, span = self.grid_shape[1], self._span[1]
        return (np.arange(k1 - k0 - 1)[:, None] * W + np.arange(W - span, W)).reshape(-1)

    def _window_planes(self, k0, k1):
        """``(μ, P)`` of the windows of anchor rows ``k0 .. k1 − 1`` as flat runs: shapes ``(C, L)`` and ``C x C``.

        ``L`` is :meth:`_run_length`; ``P`` is a nested list of planes of shape ``(L,)`` (``P[c][d]`` and
        ``P[d][c]`` the same array).  ``P = (Σ + ε/n · 1)^{-1}`` (the pseudo-inverse for ``ε = 0``); ``M = P / n``
        is the ``(G + ε)^{-1}`` of the class notes.  Every entry depends on its own window only, so a band
        gives the same numbers as the whole grid.
        """
        C, W = self.channels, self.grid_shape[1]
        length = self._run_length(k0, k1)
        mean = self._run_sum(self._flat, k0, length)
        _divide(mean, self.size)
        first, stop = k0 * W, (k1 + self._span[0]) * W  # the grid rows the windows cover
        product = np.empty(stop - first)
        work = np.empty(length)
        cov = [[None] * C for _ in range(C)]
        for c in range(C):
            for d in range(c, C):
                np.multiply(self._flat[c, first:stop], self._flat[d, first:stop], out=product)
                entry = self._run_sum(product, k0, length, origin=first)
                _divide(entry, self.size)
                np.multiply(mean[c], mean[d], out=work)
                entry -= work
                cov[c][d] = cov[d][c] = entry
        return mean, self._regularised_inverse(cov)

    def _whole_planes(self):
        """:meth:`_window_planes` of every window, kept for the products with ``K`` and ``Kᵀ`` (9 planes).

        Only :meth:`block_matvec` and the adjoint use them; the normal stencil and the term's value
        (:meth:`row_pieces`) work band by band and keep nothing.
        """
        if self._planes is None:
            self._planes = self._window_planes(0, self._anchor_rows)
        return self._planes

    def _regularised_inverse(self, cov):
        """``P = (Σ + ε/n · 1)^{-1}`` per window (the pseudo-inverse for ``ε = 0``) of the nested planes ``cov``."""
        C = self.channels
        if self.eps > 0:
            for c in range(C):
                cov[c][c] += self.eps / float(self.size)
            return _symmetric_inverse(cov)
        values, vectors = np.linalg.eigh(np.moveaxis(np.array(cov), (0, 1), (-2, -1)))
        keep = values > PINV_CUTOFF
        inv_values = np.where(keep, 1.0 / np.where(keep, values, 1.0), 0.0)
        inverse = np.einsum("...ik,...k,...jk->ij...", vectors, inv_values, vectors)
        return [[inverse[c, d] for d in range(C)] for c in range(C)]

    def _fit_rows(self, z, k0, k1, planes):
        """Every block of ``K z`` on the windows of anchor rows ``k0 .. k1 − 1`` as flat runs, shape ``(n + C, L)``.

        ``z`` is the flat depth (length ``H * W``), ``planes`` the :meth:`_window_planes` of those windows; the
        positions of the run that are no window (:meth:`_outside`) are 0.
        """
        mean, inverse = planes
        C = self.channels
        length = mean.shape[1]
        zbar = self._run_sum(z, k0, length)
        _divide(zbar, self.size)
        cross = np.zeros(mean.shape)
        product = np.empty(mean.shape)
        for o in self.offsets_in_window:
            np.multiply(self._run(self._flat, o, k0, length), self._run(z, o, k0, length), out=product)
            cross += product
        _divide(cross, self.size)
        cross -= mean * zbar  # the covariance of image and depth in each window
        a = _apply(inverse, cross)
        intercept = zbar - _dot(a, mean)
        out = np.empty((self.size + C, length))
        for j, o in enumerate(self.offsets_in_window):
            row = out[j]
            np.subtract(self._run(z, o, k0, length), intercept, out=row)
            for c in range(C):
                np.multiply(a[c], self._run(self._flat[c], o, k0, length), out=product[0])
                row -= product[0]
        np.multiply(a, np.sqrt(self.eps), out=out[self.size:])
        out[:, self._outside(k0, k1)] = 0.0
        return out

    def _rows(self, z):
        """Every block of ``K z`` on the windows as one flat run, shape ``(n + C, L)`` (cached for the last ``z``)."""
        if self._fit_cache is not None and np.array_equal(self._fit_cache[0], z):
            return self._fit_cache[1]
        rows = self._fit_rows(self._as_image(z).reshape(-1), 0, self._anchor_rows, self._whole_planes())
        self._fit_cache = (np.array(z, dtype=np.float64, copy=True), rows)
        return rows

    def _first_anchor(self):
        """The flat grid index of the first window's anchor pixel (where a run of all windows starts)."""
        return self._low[0] * self.grid_shape[1] + self._low[1]

    # -- StencilOperator interface ---------------------------------------------
    def block_matvec(self, z, b, out=None):
        """Rows of block ``b`` of ``K z`` (length ``H * W``), into ``out`` if given."""
        z = self._as_image(z).reshape(-1)
        out = np.zeros(z.shape[0]) if out is None else out.reshape(-1)
        out[...] = 0.0
        if self._windows:
            values = self._rows(z)[b]
            start = self._first_anchor()
            out[start:start + values.shape[0]] = values
        return out

    def row_pieces(self, z):
        """``K z`` a band of grid rows at a time: ``(rows, values)``, each block's rows of the band.

        The fit of a band's windows is computed for the band only (no per-pixel plane is kept), so a pass
        over ``K z`` (the term's value) needs a few band-sized arrays.
        """
        z = self._as_image(z).reshape(-1)
        H, W = self.grid_shape
        n = H * W
        step = self._band_rows()
        low_y, low_x = self._low
        for y0 in range(0, H, step):
            y1 = min(H, y0 + step)
            # the windows anchored on grid rows y0 .. y1 - 1
            k0, k1 = max(y0 - low_y, 0), min(y1 - low_y, self._anchor_rows)
            band = np.zeros((len(self.blocks), (y1 - y0) * W))
            if self._windows and k1 > k0:
                values = self._fit_rows(z, k0, k1, self._window_planes(k0, k1))
                start = (k0 + low_y - y0) * W + low_x
                band[:, start:start + values.shape[1]] = values
            for b in range(len(self.blocks)):
                yield slice(b * n + y0 * W, b * n + y1 * W), band[b]

    def block_rmatvec_add(self, out, b, v):
        """``out += K_bᵀ v`` for the rows ``v`` (length ``H * W``) of block ``b``; returns ``out``."""
        v = np.asarray(v, dtype=np.float64).reshape(-1)
        rows = [None] * len(self.blocks)
        rows[b] = v
        return self._adjoint_add(out, rows)

    def rmatvec(self, v):
        """``Kᵀ v`` for a vector of length ``(n + C) * H * W``."""
        v = np.asarray(v, dtype=np.float64)
        if v.ndim != 1 or v.shape[0] != self.shape[0]:
            raise ValueError(f"expected a vector of length {self.shape[0]}, got shape {v.shape}")
        n = self.shape[1]
        rows = [v[k * n:(k + 1) * n] for k in range(len(self.blocks))]
        return self._adjoint_add(np.zeros(n), rows)

    def _adjoint_add(self, out, rows):
        """``out += Kᵀ [v_0; ...; v_(n-1); u_0; ...]`` with ``rows`` the ``n + C`` flat row vectors (None for zero rows)."""
        if not self._windows:
            return out
        mean, inverse = self._whole_planes()
        target = out.reshape(-1)
        length = mean.shape[1]
        start = self._first_anchor()
        n = self.size
        v = [np.zeros(length) if r is None else r[start:start + length] for r in rows[:n]]
        u = np.stack([np.zeros(length) if r is None else r[start:start + length] for r in rows[n:]])
        vsum = np.zeros(length)
        xv = np.zeros(mean.shape)
        for o, vj in zip(self.offsets_in_window, v):
            vsum += vj
            xv += self._run(self._flat, o, 0, length) * vj
        xv -= mean * vsum  # Xᵀ v
        g = _apply(inverse, np.sqrt(self.eps) * u - xv) / float(n)  # M (√ε u − Xᵀ v)
        vbar = vsum / float(n)
        offset = _dot(mean, g)
        outside = self._outside(0, self._anchor_rows)
        for o, vj in zip(self.offsets_in_window, v):
            values = vj - vbar - offset + _dot(self._run(self._flat, o, 0, length), g)
            values[outside] = 0.0  # no window: its rows are not rows of K
            self._run(target, o, 0, length)[...] += values
        return out

    def offsets(self):
        """The offsets of ``Kᵀ K``, sorted: the differences of two pixels of a window (25 for a 3x3 window)."""
        window = self.offsets_in_window
        return sorted({(a[0] - b[0], a[1] - b[1]) for a in window for b in window})

    def add_normal_stencil(self, stencil, offsets, row_weights=None, scale=1.0, *, symmetric=False):
        r"""Accumulate ``scale · L`` (``L = Kᵀ K``, the matting Laplacian) into stencil images, in place.

        Window ``p``'s entry ``L_w[i, j] = δ_ij − (1 + (I_i − μ)ᵀ P (I_j − μ)) / n`` (``P = (Σ + ε/n)^{-1}``,
        ``n`` the window's pixels)
        is the coupling of pixel ``p + o_i`` with ``p + o_j``: it goes to the image of offset ``o_j − o_i`` at
        pixel ``p + o_i`` and, for ``i ≠ j``, to the image of ``o_i − o_j`` at ``p + o_j``.

        Parameters
        ----------
        stencil : ndarray, shape (len(offsets), H, W)
            Updated in place; C-contiguous.
        offsets : list of tuple of int
            The offsets of the images of ``stencil``; all of :meth:`offsets`, or with ``symmetric`` those
            ``>= (0, 0)``.
        row_weights : None
            The term has no per-row weights.
        scale : float
        symmetric : bool, default False
            Write only the couplings at offsets ``>= (0, 0)`` (the stored half of a
            :class:`~sparsedepth.grid.stencil.SymmetricStencil`); the others are their mirrors.

        Raises
        ------
        ValueError
            If ``row_weights`` is given (the term has no per-row weights), or ``stencil`` is not C-contiguous.

        Notes
        -----
        The grid is processed a band of stencil rows at a time: the windows that touch the band get their
        ``μ`` and ``P`` (:meth:`_window_planes`), the centred colours ``I_j − μ`` of all their pixels and the
        projections ``−(scale/n) P (I_i − μ)`` (the windows of the rows the previous band also touched keep
        theirs), then every pixel ``i`` its couplings with the pixels ``j >= i``, one whole-band operation per
        channel.  Every window quantity is a flat run of the band (see the class notes) and every coupling is
        added to the stencil as one contiguous run, its positions that are no window adding 0.  Each stencil
        entry receives its terms in the order of the pairs, as in one pass over the whole grid, so the images
        do not depend on the band height; nothing per pixel is kept.
        """
        if row_weights is not None:
            raise ValueError("the local-linear term takes no row_weights (its rows are the windows' fit residuals)")
        if not self._windows:
            return stencil
        H, W = self.grid_shape
        images = _flat_images(stencil)
        slot = {o: k for k, o in enumerate(offsets)}
        C = self.channels
        window, n = self.offsets_in_window, self.size
        constant = -scale / float(n)
        # per pair, where its coupling goes: (image, window pixel it is written at)
        writes = {}
        for i, oi in enumerate(window):
            for j in range(i, n):
                oj = window[j]
                if i == j:
                    places = [((0, 0), oi)]
                else:
                    places = [((oj[0] - oi[0], oj[1] - oi[1]), oi), ((oi[0] - oj[0], oi[1] - oj[1]), oj)]
                writes[i, j] = [(images[slot[o]], a) for o, a in places if not symmetric or o >= (0, 0)]
        step = self._band_rows()
        (low_y, low_x), span_y = self._low, self._span[0]
        span_x = self._span[1]
        longest = min(step + span_y, self._anchor_rows) * W  # the longest run of a band, and its row's tail
        centred_all, projected_all = np.empty((2, C, n, longest))
        couplings_all, product_all = np.empty((2, n, longest))
        done = (0, 0)  # the anchor rows whose centred colours and projections the buffers hold (from position 0)
        for y0 in range(0, H, step):
            y1 = min(H, y0 + step)
            # the windows with a pixel on grid rows y0 .. y1 - 1 (anchor row k covers grid rows k .. k + span_y)
            k0, k1 = max(y0 - span_y, 0), min(y1, self._anchor_rows)
            if k1 <= k0:
                continue
            length = self._run_length(k0, k1)
            fresh = k0  # the first anchor row not computed for the previous band
            if done[0] <= k0 < done[1]:
                fresh = done[1]
                source, count = (k0 - done[0]) * W, (fresh - k0) * W - span_x
                for buffer in (centred_all, projected_all):
                    buffer[:, :, :count] = buffer[:, :, source:source + count]
                    buffer[:, :, count:count + span_x] = 0.0  # the wrap to row `fresh`: no window
            if fresh < k1:
                mean, inverse = self._window_planes(fresh, k1)
                part = slice((fresh - k0) * W, length)
                centred = centred_all[:, :, part]  # centred[c, j]: channel c of I_j − μ
                for j, o in enumerate(window):
                    np.subtract(self._run(self._flat, o, fresh, mean.shape[1]), mean, out=centred[:, j])
                projected = _apply(inverse, centred, out=projected_all[:, :, part],
                                   work=product_all[:, :mean.shape[1]])
                projected *= constant  # projected[:, i]: −(scale / n) P (I_i − μ)
            done = (k0, k1)
            centred, projected = centred_all[:, :, :length], projected_all[:, :, :length]
            outside = self._outside(k0, k1)
            for i in range(n):
                # the couplings of i with j = i .. n − 1
                coupling, work = couplings_all[:n - i, :length], product_all[:n - i, :length]
                np.multiply(projected[0, i], centred[0, i:], out=coupling)
                for c in range(1, C):
                    np.multiply(projected[c, i], centred[c, i:], out=work)
                    coupling += work
                coupling[0] += constant + scale
                coupling[1:] += constant
                coupling[:, outside] = 0.0
                for j in range(i, n):
                    for image, a in writes[i, j]:
                        # windows whose pixel p + a lies on the band's rows: anchor rows lo .. hi − 1
                        lo, hi = max(k0, y0 - low_y - a[0]), min(k1, y1 - low_y - a[0])
                        if hi > lo:
                            first, stop = (lo - k0) * W, (hi - k0) * W - self._span[1]
                            start = (lo + low_y + a[0]) * W + low_x + a[1]
                            image[start:start + stop - first] += coupling[j - i, first:stop]
        return stencil

    def tocsr(self):
        """``K`` as a ``scipy.sparse`` CSR matrix (built column by column from :meth:`matvec`; for tests and small grids)."""
        n = self.shape[1]
        columns = []
        for k in range(n):
            e = np.zeros(n)
            e[k] = 1.0
            columns.append(sp.csr_matrix(self.matvec(e)).T)
        out = sp.hstack(columns, format="csr") if columns else sp.csr_matrix(self.shape)
        out.eliminate_zeros()
        return out

    def __repr__(self):
        return (f"LocalLinearOperator(shape={self.grid_shape}, channels={self.channels}, eps={self.eps:g}, "
                f"window={self.window!r})")
