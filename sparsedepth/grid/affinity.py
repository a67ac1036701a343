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
from .operators import StencilOperator
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
    """Inverses of symmetric positive definite matrices stored as ``S[c, d]`` images: shape ``(C, C, h, w)``.

    1x1 and 3x3 (grey and colour images) by the closed form (the adjugate over the determinant).
    """
    C = S.shape[0]
    if C == 1:
        return 1.0 / S
    if C == 3:
        c00 = S[1, 1] * S[2, 2] - S[1, 2] * S[1, 2]
        c01 = S[0, 2] * S[1, 2] - S[0, 1] * S[2, 2]
        c02 = S[0, 1] * S[1, 2] - S[0, 2] * S[1, 1]
        c11 = S[0, 0] * S[2, 2] - S[0, 2] * S[0, 2]
        c12 = S[0, 1] * S[0, 2] - S[0, 0] * S[1, 2]
        c22 = S[0, 0] * S[1, 1] - S[0, 1] * S[0, 1]
        scale = 1.0 / (S[0, 0] * c00 + S[0, 1] * c01 + S[0, 2] * c02)  # 1 / det
        out = np.empty(S.shape)
        for (c, d), cofactor in zip(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)), (c00, c01, c02, c11, c12, c22)):
            np.multiply(cofactor, scale, out=out[c, d])
            out[d, c] = out[c, d]
        return out
    return np.moveaxis(np.linalg.inv(np.moveaxis(S, (0, 1), (-2, -1))), (-2, -1), (0, 1))


def _apply(P, x):
    """``P x`` per pixel: ``P`` of shape ``(C, C, h, w)``, ``x`` of shape ``(C, h, w)``."""
    out = P[:, 0] * x[0]
    for d in range(1, x.shape[0]):
        out += P[:, d] * x[d]
    return out


def _dot(x, y):
    """``xᵀ y`` per pixel for ``(C, h, w)`` arrays."""
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
        taps = tuple((o, float("nan")) for o in self.offsets_in_window)  # taps of every block; coefficients per pixel
        self.blocks = (taps,) * (self.size + C)
        dys, dxs = [o[0] for o in self.offsets_in_window], [o[1] for o in self.offsets_in_window]
        self._low = (-min(dys), -min(dxs))  # the first anchor row and column
        self._span = (max(dys) - min(dys), max(dxs) - min(dxs))  # rows and columns a window covers, minus 1
        self._anchor_rows = max(0, H - self._span[0])  # the anchor rows: grid rows low .. low + anchor_rows - 1
        self._windows = H > self._span[0] and W > self._span[1]
        self._interior = ((slice(self._low[0], self._low[0] + H - self._span[0]),
                           slice(self._low[1], self._low[1] + W - self._span[1])) if self._windows
                          else (slice(0, 0), slice(0, 0)))
        self._planes = None
        self._fit_cache = None

    # -- the fit of every window ---------------------------------------------
    def _band_rows(self):
        """Window rows per band of the band-wise computations (about ``affinity_band_pixels`` pixels).

        ``affinity_band_pixels`` is the :class:`~sparsedepth.limits.MemoryLimits` field.
        """
        return max(1, memory_limits().affinity_band_pixels // self.grid_shape[1])

    def _window_planes(self, k0, k1):
        """``(μ, P)`` of the windows of anchor rows ``k0 .. k1 − 1``: shapes ``(C, k1-k0, columns)``, ``(C, C, ...)``.

        Anchor row ``k`` is grid row ``k + low`` (for a 3x3 window its centre row ``k + 1``).  ``P = (Σ + ε/n ·
        1)^{-1}`` (the pseudo-inverse for ``ε = 0``); ``M = P / n`` is the ``(G + ε)^{-1}`` of the class notes.
        Every entry depends on its own window only, so a band gives the same numbers as the whole grid.
        """
        C = self.channels
        rows = (k0, k1)
        n = float(self.size)
        mean = self._window_sum(self._image, rows) / n
        band = self._image[:, k0:k1 + self._span[0]]  # the grid rows the windows cover
        cov = np.empty((C, C) + mean.shape[1:])
        for c in range(C):
            for d in range(c, C):
                cov[c, d] = self._window_sum(band[c] * band[d], (0, k1 - k0)) / n - mean[c] * mean[d]
                cov[d, c] = cov[c, d]
        return mean, self._regularised_inverse(cov)

    def _whole_planes(self):
        """:meth:`_window_planes` of every window, kept for the products with ``K`` and ``Kᵀ`` (15 planes).

        Only :meth:`block_matvec` and the adjoint use them; the normal stencil and the term's value
        (:meth:`row_pieces`) work band by band and keep nothing.
        """
        if self._planes is None:
            self._planes = self._window_planes(0, self._anchor_rows)
        return self._planes

    def _regularised_inverse(self, cov):
        """``P = (Σ + ε/n · 1)^{-1}`` per window (the pseudo-inverse for ``ε = 0``), shape ``(C, C, h, w)``."""
        C = self.channels
        if self.eps > 0:
            for c in range(C):
                cov[c, c] += self.eps / float(self.size)
            return _symmetric_inverse(cov)
        values, vectors = np.linalg.eigh(np.moveaxis(cov, (0, 1), (-2, -1)))
        keep = values > PINV_CUTOFF
        inv_values = np.where(keep, 1.0 / np.where(keep, values, 1.0), 0.0)
        return np.einsum("...ik,...k,...jk->ij...", vectors, inv_values, vectors)

    def _shifted(self, array, o, rows=None):
        """The view of ``array`` at the window pixel ``o`` of the windows of anchor rows ``rows`` (default all)."""
        W = self.grid_shape[1]
        k0, k1 = (0, self._anchor_rows) if rows is None else rows
        y, x = self._low
        return array[..., k0 + y + o[0]:k1 + y + o[0], x + o[1]:x + W - self._span[1] + o[1]]

    def _window_sum(self, array, rows):
        """Σ over the window of every window of anchor rows ``rows = (k0, k1)``: :meth:`_shifted` summed over the
        window's pixels, shape ``array.shape[:-2] + (k1 - k0, columns)``."""
        first, *others = self.offsets_in_window
        out = self._shifted(array, first, rows).copy()
        for o in others:
            out += self._shifted(array, o, rows)
        return out

    def _fit_rows(self, img, rows, planes):
        """Every block of ``K z`` on the windows of anchor rows ``rows``, shape ``(n + C, k1 - k0, columns)``.

        ``img`` is ``z`` as an ``(H, W)`` image, ``planes`` the :meth:`_window_planes` of those windows.
        """
        mean, inverse = planes
        C = self.channels
        n = float(self.size)
        zbar = self._window_sum(img, rows) / n
        cross = np.zeros(mean.shape)
        product = np.empty(mean.shape)
        for o in self.offsets_in_window:
            np.multiply(self._shifted(self._image, o, rows), self._shifted(img, o, rows), out=product)
            cross += product
        cross /= n
        cross -= mean * zbar  # the covariance of image and depth in each window
        a = _apply(inverse, cross)
        intercept = zbar - _dot(a, mean)
        out = np.empty((self.size + C,) + zbar.shape)
        for j, o in enumerate(self.offsets_in_window):
            row = out[j]
            np.subtract(self._shifted(img, o, rows), intercept, out=row)
            for c in range(C):
                np.multiply(a[c], self._shifted(self._image[c], o, rows), out=product[0])
                row -= product[0]
        np.multiply(a, np.sqrt(self.eps), out=out[self.size:])
        return out

    def _rows(self, z):
        """Every block of ``K z`` on the anchor pixels, shape ``(n + C, rows, columns)`` (cached for the last ``z``)."""
        if self._fit_cache is not None and np.array_equal(self._fit_cache[0], z):
            return self._fit_cache[1]
        rows = self._fit_rows(self._as_image(z), (0, self._anchor_rows), self._whole_planes())
        self._fit_cache = (np.array(z, dtype=np.float64, copy=True), rows)
        return rows

    # -- StencilOperator interface ---------------------------------------------
    def block_matvec(self, z, b, out=None):
        """Rows of block ``b`` of ``K z`` (length ``H * W``), into ``out`` if given."""
        img = self._as_image(z)
        out = np.zeros(self.grid_shape) if out is None else out.reshape(self.grid_shape)
        out[...] = 0.0
        if self._windows:
            out[self._interior] = self._rows(img.reshape(-1))[b]
        return out.reshape(-1)

    def row_pieces(self, z):
        """``K z`` a band of grid rows at a time: ``(rows, values)``, each block's rows of the band.

        The fit of a band's windows is computed for the band only (no per-pixel plane is kept), so a pass
        over ``K z`` (the term's value) needs a few band-sized arrays.
        """
        img = self._as_image(z)
        H, W = self.grid_shape
        n = H * W
        step = self._band_rows()
        low_y, low_x = self._low
        for y0 in range(0, H, step):
            y1 = min(H, y0 + step)
            # the windows anchored on grid rows y0 .. y1 - 1
            k0, k1 = max(y0 - low_y, 0), min(y1 - low_y, self._anchor_rows)
            band = np.zeros((len(self.blocks), y1 - y0, W))
            if self._windows and k1 > k0:
                rows = (k0, k1)
                band[:, k0 + low_y - y0:k1 + low_y - y0, low_x:low_x + W - self._span[1]] = \
                    self._fit_rows(img, rows, self._window_planes(*rows))
            for b in range(len(self.blocks)):
                yield slice(b * n + y0 * W, b * n + y1 * W), band[b].reshape(-1)

    def block_rmatvec_add(self, out, b, v):
        """``out += K_bᵀ v`` for the rows ``v`` (length ``H * W``) of block ``b``; returns ``out``."""
        v = np.asarray(v, dtype=np.float64).reshape(self.grid_shape)
        rows = [None] * len(self.blocks)
        rows[b] = v
        return self._adjoint_add(out, rows)

    def rmatvec(self, v):
        """``Kᵀ v`` for a vector of length ``(n + C) * H * W``."""
        v = np.asarray(v, dtype=np.float64)
        if v.ndim != 1 or v.shape[0] != self.shape[0]:
            raise ValueError(f"expected a vector of length {self.shape[0]}, got shape {v.shape}")
        n = self.shape[1]
        rows = [v[k * n:(k + 1) * n].reshape(self.grid_shape) for k in range(len(self.blocks))]
        return self._adjoint_add(np.zeros(n), rows)

    def _adjoint_add(self, out, rows):
        """``out += Kᵀ [v_0; ...; v_(n-1); u_0; ...]`` with ``rows`` the ``n + C`` row images (None for zero rows)."""
        if not self._windows:
            return out
        mean, inverse = self._whole_planes()
        target = out.reshape(self.grid_shape)
        interior = self._interior
        shape = mean.shape[1:]
        n = self.size
        v = [np.zeros(shape) if r is None else r[interior] for r in rows[:n]]
        u = np.stack([np.zeros(shape) if r is None else r[interior] for r in rows[n:]])
        vsum = np.zeros(shape)
        xv = np.zeros(mean.shape)
        for o, vj in zip(self.offsets_in_window, v):
            vsum += vj
            xv += self._shifted(self._image, o) * vj
        xv -= mean * vsum  # Xᵀ v
        g = _apply(inverse, np.sqrt(self.eps) * u - xv) / float(n)  # M (√ε u − Xᵀ v)
        vbar = vsum / float(n)
        offset = _dot(mean, g)
        for o, vj in zip(self.offsets_in_window, v):
            self._shifted(target, o)[...] += vj - vbar - offset + _dot(self._shifted(self._image, o), g)
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
            Updated in place.
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
            If ``row_weights`` is given (the term has no per-row weights).

        Notes
        -----
        The grid is processed a band of stencil rows at a time: the windows that touch the band get their
        ``μ`` and ``P`` (:meth:`_window_planes`), then every pair ``(i, j)``
        its coupling, one whole-band operation per pair.  Each stencil entry receives its terms in the order
        of the pairs, as in one pass over the whole grid, so the images do not depend on the band height;
        nothing per pixel is kept.
        """
        if row_weights is not None:
            raise ValueError("the local-linear term takes no row_weights (its rows are the windows' fit residuals)")
        if not self._windows:
            return stencil
        H, W = self.grid_shape
        slot = {o: k for k, o in enumerate(offsets)}
        C = self.channels
        window, n = self.offsets_in_window, self.size
        constant = -scale / float(n)
        # per pair, where its coupling goes: (offset, window pixel it is written at)
        writes = {}
        for i, oi in enumerate(window):
            for j in range(i, n):
                oj = window[j]
                if i == j:
                    places = [((0, 0), oi)]
                else:
                    places = [((oj[0] - oi[0], oj[1] - oi[1]), oi), ((oi[0] - oj[0], oi[1] - oj[1]), oj)]
                writes[i, j] = [(o, a) for o, a in places if not symmetric or o >= (0, 0)]
        step = self._band_rows()
        (low_y, low_x), (span_y, span_x) = self._low, self._span
        for y0 in range(0, H, step):
            y1 = min(H, y0 + step)
            # the windows with a pixel on grid rows y0 .. y1 - 1 (anchor row k covers grid rows k .. k + span_y)
            k0, k1 = max(y0 - span_y, 0), min(y1, self._anchor_rows)
            if k1 <= k0:
                continue
            rows = (k0, k1)
            mean, inverse = self._window_planes(*rows)
            centred = np.empty((C,) + mean.shape[1:])
            coupling = np.empty(mean.shape[1:])
            product = np.empty(mean.shape[1:])
            for i, oi in enumerate(window):
                np.subtract(self._shifted(self._image, oi, rows), mean, out=centred)
                projected = _apply(inverse, centred)
                projected *= constant  # -(scale / n) P (I_i - mu)
                for j in range(i, n):
                    np.subtract(self._shifted(self._image, window[j], rows), mean, out=centred)
                    np.multiply(projected[0], centred[0], out=coupling)
                    for c in range(1, C):
                        np.multiply(projected[c], centred[c], out=product)
                        coupling += product
                    coupling += constant + scale if i == j else constant
                    for o, a in writes[i, j]:
                        # windows whose pixel p + a lies on the band's rows
                        lo, hi = max(k0, y0 - low_y - a[0]), min(k1, y1 - low_y - a[0])
                        if hi > lo:
                            x = low_x + a[1]
                            stencil[slot[o]][lo + low_y + a[0]:hi + low_y + a[0], x:x + W - span_x] += \
                                coupling[lo - k0:hi - k0]
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
