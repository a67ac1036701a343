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
a window (so it can jump where the colour jumps) but not vary where the colour does not.

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

__all__ = ["LocalLinearOperator", "local_linear_operator", "WINDOW_OFFSETS", "PINV_CUTOFF"]

#: The nine offsets of a 3x3 window from its centre, in C order.
WINDOW_OFFSETS = tuple((dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1))
#: With ``ε = 0``, eigenvalues of a window's colour covariance at or below this (in [0, 1]² units) count as 0.
PINV_CUTOFF = 1e-10
#: pixels per band of the band-wise computations (the normal stencil, the term's value): their work arrays
#: stay a few megabytes whatever the frame size
_BAND_PIXELS = 1 << 15


def local_linear_operator(image, eps: float, *, copy: bool = True) -> "LocalLinearOperator":
    """The operator ``K`` with ``Kᵀ K`` the 3x3-window matting Laplacian of ``image``.

    Parameters
    ----------
    image : ndarray, (H, W) or (H, W, C)
        uint8, uint16 or float in [0, 1] (see :func:`sparsedepth._validation.as_float_image`); every channel is
        a regressor of the local affine model.
    eps : float
        ``ε >= 0``, the ridge weight of the slope ``a`` (in squared image units: [0, 1]²).  Large ``ε`` makes
        every window fit a constant (``L`` becomes the sum of the windows' centring matrices); ``ε = 0`` uses
        the pseudo-inverse of the window covariance (eigenvalues at or below :data:`PINV_CUTOFF` dropped).
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
        If ``eps`` is not a finite number ``>= 0``, or for a bad image.

    Examples
    --------
    >>> K = local_linear_operator(np.array([[0.0, 0, 1], [0, 0, 1], [0, 0, 1]]), 1e-3)
    >>> z = np.array([2.0, 2, 5, 2, 2, 5, 2, 2, 5])  # z = 2 + 3 I: affine in the image
    >>> round(float(np.sum((K @ z) ** 2)), 4)  # small, not 0: the ridge ε shrinks the slope 3
    0.009
    """
    eps = check_nonnegative_real(eps, name="local_linear_eps")
    array = np.asarray(image)
    keep = not copy and array.dtype == np.float64 and array.ndim == 3
    return LocalLinearOperator(array if keep else as_float_image(image), eps)


def _window_sum(array, rows):
    """Σ over the 3x3 window of the interior pixels of window rows ``rows = (k0, k1)`` (grid rows ``k0+1 .. k1``).

    ``array`` has the grid on its last two axes; the result has shape ``array.shape[:-2] + (k1 - k0, W - 2)``.
    """
    k0, k1 = rows
    W = array.shape[-1]
    (dy, dx), *others = WINDOW_OFFSETS
    out = array[..., k0 + 1 + dy:k1 + 1 + dy, 1 + dx:W - 1 + dx].copy()
    for dy, dx in others:
        out += array[..., k0 + 1 + dy:k1 + 1 + dy, 1 + dx:W - 1 + dx]
    return out


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

    Row blocks (each one row per pixel, C order, non-zero only at the interior pixels ``1 <= y <= H-2``,
    ``1 <= x <= W-2``, the centres of the windows): block ``j < 9`` is the residual
    ``z[p + o_j] − a_pᵀ I[p + o_j] − b_p`` of the window centred at ``p`` (``o_j`` the ``j``-th of
    :data:`WINDOW_OFFSETS`), block ``9 + c`` is ``√ε a_{p,c}``, with ``(a_p, b_p)`` the ridge fit of that window.

    Notes
    -----
    With ``X`` the window's centred colours (9 x C), ``G = XᵀX = 9 Σ`` and ``M = (G + ε 1)^{-1}``, the fit is
    ``a = M Xᵀ z_w``, ``b = z̄ − aᵀ μ``, and the rows are ``r = C z_w − X a`` (``C = 1 − 11ᵀ/9``) and ``√ε a``.
    Since ``M (G + ε) M = M``, ``‖r‖² + ε ‖a‖² = z_wᵀ (C − X M Xᵀ) z_w = z_wᵀ L_w z_w``: ``Kᵀ K = Σ_w L_w = L``.
    The adjoint of one window's rows ``(v, u)`` is ``C v + X M (√ε u − Xᵀ v)``.  All sums over a window are nine
    shifted whole-array operations.
    """

    def __init__(self, image, eps):
        img = np.asarray(image, dtype=np.float64)
        H, W, C = img.shape
        self.grid_shape = (H, W)
        self.eps = float(eps)
        self.channels = C
        self._image = np.ascontiguousarray(np.moveaxis(img, -1, 0))  # (C, H, W): whole-image planes
        window = tuple((o, float("nan")) for o in WINDOW_OFFSETS)  # taps of every block; coefficients per pixel
        self.blocks = (window,) * (9 + C)
        self._windows = H >= 3 and W >= 3
        self._interior = (slice(1, H - 1), slice(1, W - 1)) if self._windows else (slice(0, 0), slice(0, 0))
        self._planes = None
        self._fit_cache = None

    # -- the fit of every window ---------------------------------------------
    def _band_rows(self):
        """Window rows per band of the band-wise computations (about :data:`_BAND_PIXELS` pixels)."""
        return max(1, _BAND_PIXELS // self.grid_shape[1])

    def _window_planes(self, k0, k1):
        """``(μ, P)`` of the windows centred on grid rows ``k0+1 .. k1``: shapes ``(C, k1-k0, W-2)``, ``(C, C, ...)``.

        ``P = (Σ + ε/9 · 1)^{-1}`` (the pseudo-inverse for ``ε = 0``); ``M = P / 9`` is the ``(G + ε)^{-1}`` of
        the class notes.  Every entry depends on its own window only, so a band gives the same numbers as the
        whole grid.
        """
        C = self.channels
        rows = (k0, k1)
        mean = _window_sum(self._image, rows) / 9.0
        band = self._image[:, k0:k1 + 2]  # the grid rows the windows cover
        cov = np.empty((C, C) + mean.shape[1:])
        for c in range(C):
            for d in range(c, C):
                cov[c, d] = _window_sum(band[c] * band[d], (0, k1 - k0)) / 9.0 - mean[c] * mean[d]
                cov[d, c] = cov[c, d]
        return mean, self._regularised_inverse(cov)

    def _whole_planes(self):
        """:meth:`_window_planes` of every window, kept for the products with ``K`` and ``Kᵀ`` (15 planes).

        Only :meth:`block_matvec` and the adjoint use them; the normal stencil and the term's value
        (:meth:`row_pieces`) work band by band and keep nothing.
        """
        if self._planes is None:
            self._planes = self._window_planes(0, self.grid_shape[0] - 2)
        return self._planes

    def _regularised_inverse(self, cov):
        """``P = (Σ + ε/9 · 1)^{-1}`` per window (the pseudo-inverse for ``ε = 0``), shape ``(C, C, h, w)``."""
        C = self.channels
        if self.eps > 0:
            for c in range(C):
                cov[c, c] += self.eps / 9.0
            return _symmetric_inverse(cov)
        values, vectors = np.linalg.eigh(np.moveaxis(cov, (0, 1), (-2, -1)))
        keep = values > PINV_CUTOFF
        inv_values = np.where(keep, 1.0 / np.where(keep, values, 1.0), 0.0)
        return np.einsum("...ik,...k,...jk->ij...", vectors, inv_values, vectors)

    def _shifted(self, array, o, rows=None):
        """The view of ``array`` at the window pixel ``o`` of the windows of rows ``rows`` (default all)."""
        H, W = self.grid_shape
        k0, k1 = (0, H - 2) if rows is None else rows
        return array[..., k0 + 1 + o[0]:k1 + 1 + o[0], 1 + o[1]:W - 1 + o[1]]

    def _fit_rows(self, img, rows, planes):
        """Every block of ``K z`` on the windows of ``rows``, shape ``(9 + C, k1 - k0, W - 2)``.

        ``img`` is ``z`` as an ``(H, W)`` image, ``planes`` the :meth:`_window_planes` of those windows.
        """
        mean, inverse = planes
        C = self.channels
        zbar = _window_sum(img, rows) / 9.0
        cross = np.zeros(mean.shape)
        product = np.empty(mean.shape)
        for o in WINDOW_OFFSETS:
            np.multiply(self._shifted(self._image, o, rows), self._shifted(img, o, rows), out=product)
            cross += product
        cross /= 9.0
        cross -= mean * zbar  # the covariance of image and depth in each window
        a = _apply(inverse, cross)
        intercept = zbar - _dot(a, mean)
        out = np.empty((9 + C,) + zbar.shape)
        for j, o in enumerate(WINDOW_OFFSETS):
            row = out[j]
            np.subtract(self._shifted(img, o, rows), intercept, out=row)
            for c in range(C):
                np.multiply(a[c], self._shifted(self._image[c], o, rows), out=product[0])
                row -= product[0]
        np.multiply(a, np.sqrt(self.eps), out=out[9:])
        return out

    def _rows(self, z):
        """Every block of ``K z`` on the interior pixels, shape ``(9 + C, H-2, W-2)`` (cached for the last ``z``)."""
        if self._fit_cache is not None and np.array_equal(self._fit_cache[0], z):
            return self._fit_cache[1]
        rows = self._fit_rows(self._as_image(z), (0, self.grid_shape[0] - 2), self._whole_planes())
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
        for y0 in range(0, H, step):
            y1 = min(H, y0 + step)
            k0, k1 = max(y0 - 1, 0), min(y1 - 1, H - 2)  # the windows centred on grid rows y0 .. y1 - 1
            band = np.zeros((len(self.blocks), y1 - y0, W))
            if self._windows and k1 > k0:
                rows = (k0, k1)
                band[:, k0 + 1 - y0:k1 + 1 - y0, 1:W - 1] = self._fit_rows(img, rows, self._window_planes(*rows))
            for b in range(len(self.blocks)):
                yield slice(b * n + y0 * W, b * n + y1 * W), band[b].reshape(-1)

    def block_rmatvec_add(self, out, b, v):
        """``out += K_bᵀ v`` for the rows ``v`` (length ``H * W``) of block ``b``; returns ``out``."""
        v = np.asarray(v, dtype=np.float64).reshape(self.grid_shape)
        rows = [None] * len(self.blocks)
        rows[b] = v
        return self._adjoint_add(out, rows)

    def rmatvec(self, v):
        """``Kᵀ v`` for a vector of length ``(9 + C) * H * W``."""
        v = np.asarray(v, dtype=np.float64)
        if v.ndim != 1 or v.shape[0] != self.shape[0]:
            raise ValueError(f"expected a vector of length {self.shape[0]}, got shape {v.shape}")
        n = self.shape[1]
        rows = [v[k * n:(k + 1) * n].reshape(self.grid_shape) for k in range(len(self.blocks))]
        return self._adjoint_add(np.zeros(n), rows)

    def _adjoint_add(self, out, rows):
        """``out += Kᵀ [v_0; ...; v_8; u_0; ...]`` with ``rows`` the ``9 + C`` row images (None for zero rows)."""
        if not self._windows:
            return out
        mean, inverse = self._whole_planes()
        target = out.reshape(self.grid_shape)
        interior = self._interior
        shape = mean.shape[1:]
        v = [np.zeros(shape) if r is None else r[interior] for r in rows[:9]]
        u = np.stack([np.zeros(shape) if r is None else r[interior] for r in rows[9:]])
        vsum = np.zeros(shape)
        xv = np.zeros(mean.shape)
        for o, vj in zip(WINDOW_OFFSETS, v):
            vsum += vj
            xv += self._shifted(self._image, o) * vj
        xv -= mean * vsum  # Xᵀ v
        g = _apply(inverse, np.sqrt(self.eps) * u - xv) / 9.0  # M (√ε u − Xᵀ v)
        vbar = vsum / 9.0
        offset = _dot(mean, g)
        for o, vj in zip(WINDOW_OFFSETS, v):
            self._shifted(target, o)[...] += vj - vbar - offset + _dot(self._shifted(self._image, o), g)
        return out

    def offsets(self):
        """The 25 offsets ``|dy|, |dx| <= 2`` of ``Kᵀ K``, sorted."""
        return [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3)]

    def add_normal_stencil(self, stencil, offsets, row_weights=None, scale=1.0, *, symmetric=False):
        r"""Accumulate ``scale · L`` (``L = Kᵀ K``, the matting Laplacian) into stencil images, in place.

        Window ``p``'s entry ``L_w[i, j] = δ_ij − (1 + (I_i − μ)ᵀ P (I_j − μ)) / 9`` (``P = (Σ + ε/9)^{-1}``)
        is the coupling of pixel ``p + o_i`` with ``p + o_j``: it goes to the image of offset ``o_j − o_i`` at
        pixel ``p + o_i`` and, for ``i ≠ j``, to the image of ``o_i − o_j`` at ``p + o_j``.

        Parameters
        ----------
        stencil : ndarray, shape (len(offsets), H, W)
            Updated in place.
        offsets : list of tuple of int
            The offsets of the images of ``stencil``; all 25 of :meth:`offsets`, or with ``symmetric`` the 13
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
        The grid is processed a band of stencil rows at a time: the windows that touch the band (its rows and
        one more on each side) get their ``μ`` and ``P`` (:meth:`_window_planes`), then every pair ``(i, j)``
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
        constant = -scale / 9.0
        # per pair, where its coupling goes: (offset, window pixel it is written at)
        writes = {}
        for i, oi in enumerate(WINDOW_OFFSETS):
            for j in range(i, 9):
                oj = WINDOW_OFFSETS[j]
                if i == j:
                    places = [((0, 0), oi)]
                else:
                    places = [((oj[0] - oi[0], oj[1] - oi[1]), oi), ((oi[0] - oj[0], oi[1] - oj[1]), oj)]
                writes[i, j] = [(o, a) for o, a in places if not symmetric or o >= (0, 0)]
        step = self._band_rows()
        for y0 in range(0, H, step):
            y1 = min(H, y0 + step)
            k0, k1 = max(y0 - 2, 0), min(y1, H - 2)  # the windows with a pixel on grid rows y0 .. y1 - 1
            if k1 <= k0:
                continue
            rows = (k0, k1)
            mean, inverse = self._window_planes(*rows)
            centred = np.empty((C,) + mean.shape[1:])
            coupling = np.empty(mean.shape[1:])
            product = np.empty(mean.shape[1:])
            for i, oi in enumerate(WINDOW_OFFSETS):
                np.subtract(self._shifted(self._image, oi, rows), mean, out=centred)
                projected = _apply(inverse, centred)
                projected *= constant  # -(scale / 9) P (I_i - mu)
                for j in range(i, 9):
                    np.subtract(self._shifted(self._image, WINDOW_OFFSETS[j], rows), mean, out=centred)
                    np.multiply(projected[0], centred[0], out=coupling)
                    for c in range(1, C):
                        np.multiply(projected[c], centred[c], out=product)
                        coupling += product
                    coupling += constant + scale if i == j else constant
                    for o, a in writes[i, j]:
                        # windows whose pixel p + a lies on the band's rows
                        lo, hi = max(k0, y0 - 1 - a[0]), min(k1, y1 - 1 - a[0])
                        if hi > lo:
                            stencil[slot[o]][lo + 1 + a[0]:hi + 1 + a[0], 1 + a[1]:W - 1 + a[1]] += \
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
        return f"LocalLinearOperator(shape={self.grid_shape}, channels={self.channels}, eps={self.eps:g})"
