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


def local_linear_operator(image, eps: float) -> "LocalLinearOperator":
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
    >>> round(float(np.sum((K @ np.array([2.0, 2, 5, 2, 2, 5, 2, 2, 5])) ** 2)), 4)  # z = 2 + 3 I fits
    0.0089
    """
    eps = check_nonnegative_real(eps, name="local_linear_eps")
    return LocalLinearOperator(as_float_image(image), eps)


def _window_sum(array, H, W):
    """Σ over the 3x3 window of every interior pixel of the last two axes: shape ``array.shape[:-2] + (H-2, W-2)``."""
    out = np.zeros(array.shape[:-2] + (H - 2, W - 2))
    for dy, dx in WINDOW_OFFSETS:
        out += array[..., 1 + dy:H - 1 + dy, 1 + dx:W - 1 + dx]
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
        det = S[0, 0] * c00 + S[0, 1] * c01 + S[0, 2] * c02
        return np.stack([np.stack([c00, c01, c02]), np.stack([c01, c11, c12]), np.stack([c02, c12, c22])]) / det
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
        self._fit_cache = None
        if not self._windows:
            return
        mean = _window_sum(self._image, H, W) / 9.0
        cov = np.empty((C, C) + mean.shape[1:])
        for c in range(C):
            for d in range(c, C):
                cov[c, d] = _window_sum(self._image[c] * self._image[d], H, W) / 9.0 - mean[c] * mean[d]
                cov[d, c] = cov[c, d]
        self._mean = mean
        self._inverse = self._regularised_inverse(cov)

    def _regularised_inverse(self, cov):
        """``P = (Σ + ε/9 · 1)^{-1}`` per window (the pseudo-inverse for ``ε = 0``), shape ``(C, C, H-2, W-2)``.

        ``M = P / 9`` is the ``(G + ε)^{-1}`` of the class notes.
        """
        C = self.channels
        if self.eps > 0:
            for c in range(C):
                cov[c, c] += self.eps / 9.0
            return _symmetric_inverse(cov)
        values, vectors = np.linalg.eigh(np.moveaxis(cov, (0, 1), (-2, -1)))
        keep = values > PINV_CUTOFF
        inv_values = np.where(keep, 1.0 / np.where(keep, values, 1.0), 0.0)
        return np.einsum("...ik,...k,...jk->ij...", vectors, inv_values, vectors)

    # -- the fit of every window ---------------------------------------------
    def _shifted(self, array, o):
        """The ``(..., H-2, W-2)`` view of ``array`` at the window pixel ``o`` of every interior centre."""
        H, W = self.grid_shape
        return array[..., 1 + o[0]:H - 1 + o[0], 1 + o[1]:W - 1 + o[1]]

    def _rows(self, z):
        """Every block of ``K z`` on the interior pixels, shape ``(9 + C, H-2, W-2)`` (cached for the last ``z``)."""
        if self._fit_cache is not None and np.array_equal(self._fit_cache[0], z):
            return self._fit_cache[1]
        img = self._as_image(z)
        C = self.channels
        zbar = _window_sum(img, *self.grid_shape) / 9.0
        cross = np.zeros(self._mean.shape)
        product = np.empty(self._mean.shape)
        for o in WINDOW_OFFSETS:
            np.multiply(self._shifted(self._image, o), self._shifted(img, o), out=product)
            cross += product
        cross /= 9.0
        cross -= self._mean * zbar  # the covariance of image and depth in each window
        a = _apply(self._inverse, cross)
        intercept = zbar - _dot(a, self._mean)
        rows = np.empty((9 + C,) + zbar.shape)
        for j, o in enumerate(WINDOW_OFFSETS):
            row = rows[j]
            np.subtract(self._shifted(img, o), intercept, out=row)
            for c in range(C):
                np.multiply(a[c], self._shifted(self._image[c], o), out=product[0])
                row -= product[0]
        np.multiply(a, np.sqrt(self.eps), out=rows[9:])
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
        target = out.reshape(self.grid_shape)
        interior = self._interior
        shape = self._mean.shape[1:]
        v = [np.zeros(shape) if r is None else r[interior] for r in rows[:9]]
        u = np.stack([np.zeros(shape) if r is None else r[interior] for r in rows[9:]])
        vsum = np.zeros(shape)
        xv = np.zeros(self._mean.shape)
        for o, vj in zip(WINDOW_OFFSETS, v):
            vsum += vj
            xv += self._shifted(self._image, o) * vj
        xv -= self._mean * vsum  # Xᵀ v
        g = _apply(self._inverse, np.sqrt(self.eps) * u - xv) / 9.0  # M (√ε u − Xᵀ v)
        vbar = vsum / 9.0
        offset = _dot(self._mean, g)
        for o, vj in zip(WINDOW_OFFSETS, v):
            self._shifted(target, o)[...] += vj - vbar - offset + _dot(self._shifted(self._image, o), g)
        return out

    def offsets(self):
        """The 25 offsets ``|dy|, |dx| <= 2`` of ``Kᵀ K``, sorted."""
        return [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3)]

    def add_normal_stencil(self, stencil, offsets, row_weights=None, scale=1.0):
        r"""Accumulate ``scale · L`` (``L = Kᵀ K``, the matting Laplacian) into stencil images, in place.

        Window ``p``'s entry ``L_w[i, j] = δ_ij − (1 + (I_i − μ)ᵀ P (I_j − μ)) / 9`` (``P = (Σ + ε/9)^{-1}``)
        is the coupling of pixel ``p + o_i`` with ``p + o_j``: it goes to the image of offset ``o_j − o_i`` at
        pixel ``p + o_i``, one whole-array operation per pair ``(i, j)``.

        Raises
        ------
        ValueError
            If ``row_weights`` is given (the term has no per-row weights).
        """
        if row_weights is not None:
            raise ValueError("the local-linear term takes no row_weights (its rows are the windows' fit residuals)")
        if not self._windows:
            return stencil
        slot = {o: k for k, o in enumerate(offsets)}
        C = self.channels
        constant = -scale / 9.0
        # I_j − μ is recomputed for each pair instead of kept for all nine j: C planes instead of 9 C (an 8-MP
        # colour frame: 190 MB instead of 1.7 GB), the same operations in the same order
        centred = np.empty((C,) + self._mean.shape[1:])
        coupling = np.empty(self._mean.shape[1:])
        product = np.empty(self._mean.shape[1:])
        for i, oi in enumerate(WINDOW_OFFSETS):
            np.subtract(self._shifted(self._image, oi), self._mean, out=centred)
            projected = _apply(self._inverse, centred)
            projected *= constant  # -(scale / 9) P (I_i - mu)
            for j in range(i, 9):
                oj = WINDOW_OFFSETS[j]
                np.subtract(self._shifted(self._image, oj), self._mean, out=centred)
                np.multiply(projected[0], centred[0], out=coupling)
                for c in range(1, C):
                    np.multiply(projected[c], centred[c], out=product)
                    coupling += product
                coupling += constant + scale if i == j else constant
                if i == j:
                    self._shifted(stencil[slot[(0, 0)]], oi)[...] += coupling
                    continue
                # L is symmetric: the pair (i, j) is the coupling of p + o_i with p + o_j and of p + o_j with p + o_i
                self._shifted(stencil[slot[(oj[0] - oi[0], oj[1] - oi[1])]], oi)[...] += coupling
                self._shifted(stencil[slot[(oi[0] - oj[0], oi[1] - oj[1])]], oj)[...] += coupling
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
