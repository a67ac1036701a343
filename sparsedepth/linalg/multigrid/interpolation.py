r"""Interpolation weights of the prolongation: bilinear (fixed per grid shape) and Dendy's black-box (from the operator).

Weights are images ``W[ey, ex][y, x] = P[(y, x), (y//2 + ey, x//2 + ex)]``
(fine pixel, parent offset); :mod:`.transfer` turns them into operators and
:mod:`.galerkin` multiplies them into the coarse stencils.  May import NumPy
only (stencils arrive as a :class:`~.stencils.StencilSource`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["InterpolationWeights", "linear_weights_1d", "bilinear_weights", "operator_weights"]


class InterpolationWeights:
    """Prolongation weights ``W[ey, ex][y, x] = P[(y, x), (y//2+ey, x//2+ex)]``.

    Stored either separably (``wy``: (2, H), ``wx``: (2, W)) or as full images
    (``full``: (2, 2, H, W)).
    """

    def __init__(self, wy=None, wx=None, full=None):
        self.wy, self.wx, self.full = wy, wx, full

    def cls(self, ey, ex, py, px):
        """Weights of parent (ey, ex) on the fine parity class (py, px)."""
        if self.full is not None:
            return self.full[ey, ex, py::2, px::2]
        return self.wy[ey, py::2][:, None] * self.wx[ex, px::2][None, :]

    def padded_cls(self, ry, rx, pad, separable=False):
        """All parent weights on class (ry, rx), zero-padded (pad, pad+1) per axis.

        ``separable=True`` (bilinear only) returns the two 1-D factors
        ``(wy, wx)`` of shapes ``(2, ny)`` and ``(2, nx)`` instead of their
        ``(2, 2, ny, nx)`` product.
        """
        if self.full is not None:
            sub = self.full[:, :, ry::2, rx::2]
            return np.pad(sub, ((0, 0), (0, 0), (pad, pad + 1), (pad, pad + 1)))
        wy = np.pad(self.wy[:, ry::2], ((0, 0), (pad, pad + 1)))
        wx = np.pad(self.wx[:, rx::2], ((0, 0), (pad, pad + 1)))
        if separable:
            return wy, wx
        return wy[:, None, :, None] * wx[None, :, None, :]


def linear_weights_1d(n):
    """1-D linear interpolation from points ``0, 2, 4, ...`` (Neumann end)."""
    wts = np.zeros((2, n))
    i = np.arange(n)
    odd = i % 2 == 1
    wts[0, ~odd] = 1.0
    wts[0, odd] = 0.5
    wts[1, odd] = 0.5
    if n % 2 == 0:  # last fine point has no right-hand coarse point
        wts[0, n - 1], wts[1, n - 1] = 1.0, 0.0
    return wts


def bilinear_weights(shape):
    """Bilinear weights of a grid: the 1-D weights of :func:`linear_weights_1d` along each axis, kept separable."""
    h, w = shape
    return InterpolationWeights(wy=linear_weights_1d(h), wx=linear_weights_1d(w))


def _safe_ratio(num, den, default):
    out = np.full(np.broadcast(num, den).shape, default, dtype=float)
    ok = den > 0
    np.divide(num, den, out=out, where=ok)
    return out


def _window(arr, oy, ox, ny, nx):
    """``arr[oy:oy+ny, ox:ox+nx]``, zero-padded where it runs past the end of ``arr``."""
    out = np.zeros((ny, nx))
    sub = arr[oy:oy + ny, ox:ox + nx]
    out[: sub.shape[0], : sub.shape[1]] = sub
    return out


def operator_weights(offsets, source, shape):
    """Dendy's black-box interpolation from a radius-1 (up to 9-point) stencil.

    Works on the parity classes that need each quantity (the collapsed
    stencils only on the pixels between two coarse points), so the
    temporaries stay a fraction of ``H W``: besides the ``(2, 2, H, W)``
    weights, about one ``H W`` image (8 MP: ~70 MB instead of ~1.5 GB).
    """
    h, w = shape
    full = np.zeros((2, 2, h, w))

    def collapsed(part, axis, value):
        """Sum of the stencil images whose offset has ``offset[axis] == value``, on one parity class."""
        out = np.zeros(part.shape[1:])
        for k, off in enumerate(offsets):
            if off[axis] == value:
                out += part[k]
        return out

    # pixels between two coarse points horizontally: (even y, odd x)
    part = source.parity_class(0, 1)
    c_mid = collapsed(part, 1, 0)
    wxW = _safe_ratio(-collapsed(part, 1, -1), c_mid, 0.5)
    wxE = _safe_ratio(-collapsed(part, 1, 1), c_mid, 0.5)
    # ... and vertically: (odd y, even x)
    part = source.parity_class(1, 0)
    c_mid = collapsed(part, 0, 0)
    wyN = _safe_ratio(-collapsed(part, 0, -1), c_mid, 0.5)
    wyS = _safe_ratio(-collapsed(part, 0, 1), c_mid, 0.5)
    del c_mid, part
    full[0, 0, 0::2, 0::2] = 1.0
    full[0, 0, 0::2, 1::2] = wxW
    full[0, 1, 0::2, 1::2] = wxE
    full[0, 0, 1::2, 0::2] = wyN
    full[1, 0, 1::2, 0::2] = wyS
    # cell centres (odd y, odd x): harmonic combination of the neighbours' rows
    ny, nx = h // 2, w // 2
    if ny and nx:
        part = source.parity_class(1, 1)
        c = {(dy, dx): part[k] for k, (dy, dx) in enumerate(offsets)}
        zero = np.zeros((ny, nx))

        def cc(dy, dx):
            return c.get((dy, dx), zero)

        # neighbour N (y-1, x) is an (even, odd) pixel (row i of wxW); S (y+1, x) is row i+1;
        # neighbour W (y, x-1) is an (odd, even) pixel (column j of wyN); E (y, x+1) is column j+1
        xW_N, xE_N = _window(wxW, 0, 0, ny, nx), _window(wxE, 0, 0, ny, nx)
        xW_S, xE_S = _window(wxW, 1, 0, ny, nx), _window(wxE, 1, 0, ny, nx)
        yN_W, yS_W = _window(wyN, 0, 0, ny, nx), _window(wyS, 0, 0, ny, nx)
        yN_E, yS_E = _window(wyN, 0, 1, ny, nx), _window(wyS, 0, 1, ny, nx)
        centre = cc(0, 0)
        parts = {
            (0, 0): cc(-1, -1) + cc(-1, 0) * xW_N + cc(0, -1) * yN_W,
            (0, 1): cc(-1, 1) + cc(-1, 0) * xE_N + cc(0, 1) * yN_E,
            (1, 0): cc(1, -1) + cc(1, 0) * xW_S + cc(0, -1) * yS_W,
            (1, 1): cc(1, 1) + cc(1, 0) * xE_S + cc(0, 1) * yS_E,
        }
        for (ey, ex), e in parts.items():
            full[ey, ex, 1::2, 1::2] = _safe_ratio(-e, centre, 0.25)
    # parents outside the coarse grid (even H or W) carry no weight
    if h % 2 == 0:
        full[1, :, h - 1, :] = 0.0
    if w % 2 == 0:
        full[:, 1, :, w - 1] = 0.0
    return InterpolationWeights(full=full)
