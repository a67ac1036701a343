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

    Stored either separably (``wy``: (2, H), ``wx``: (2, W)), as full images
    (``full``: (2, 2, H, W)), or per parity class ``(py, px)`` of the fine
    pixels (``classes[py, px]``: (2, 2, ny + 2 pad + 1, nx + 2 pad + 1), the
    class's weights zero-padded by ``pad`` before and ``pad + 1`` after on
    each axis: the form the Galerkin product reads, so that it needs no
    padded copy).
    """

    def __init__(self, wy=None, wx=None, full=None, classes=None, pad=0):
        self.wy, self.wx, self.full = wy, wx, full
        self.classes, self.pad = classes, int(pad)

    @property
    def separable(self) -> bool:
        """True when stored as the 1-D factors ``wy``, ``wx``."""
        return self.full is None and self.classes is None

    def class_weights(self, py, px):
        """All parent weights on the fine parity class (py, px), shape (2, 2, ny, nx) (a view where stored so)."""
        if self.classes is not None:
            padded = self.classes[py, px]
            ny, nx = (n - 2 * self.pad - 1 for n in padded.shape[2:])
            return padded[:, :, self.pad:self.pad + ny, self.pad:self.pad + nx]
        if self.full is not None:
            return self.full[:, :, py::2, px::2]
        return self.wy[:, None, py::2, None] * self.wx[None, :, None, px::2]

    def cls(self, ey, ex, py, px):
        """Weights of parent (ey, ex) on the fine parity class (py, px)."""
        if self.full is not None or self.classes is not None:
            return self.class_weights(py, px)[ey, ex]
        return self.wy[ey, py::2][:, None] * self.wx[ex, px::2][None, :]

    def padded_cls(self, ry, rx, pad, separable=False):
        """All parent weights on class (ry, rx), zero-padded (pad, pad+1) per axis.

        ``separable=True`` (bilinear only) returns the two 1-D factors
        ``(wy, wx)`` of shapes ``(2, ny)`` and ``(2, nx)`` instead of their
        ``(2, 2, ny, nx)`` product.  Weights stored per class with at least
        this padding are returned as a view.
        """
        if self.classes is not None and pad <= self.pad:
            trim = self.pad - pad
            padded = self.classes[ry, rx]
            return padded[:, :, trim:padded.shape[2] - trim, trim:padded.shape[3] - trim]
        if self.full is not None or self.classes is not None:
            sub = self.class_weights(ry, rx)
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


def operator_weights(offsets, source, shape, pad=1):
    """Dendy's black-box interpolation from a radius-1 (up to 9-point) stencil.

    Works on the parity classes that need each quantity (the collapsed
    stencils only on the pixels between two coarse points), so the
    temporaries stay a fraction of ``H W``: besides the weights (4 per
    pixel), about one ``H W`` image.  The
    weights are stored per parity class, zero-padded by ``pad`` (the
    padding the Galerkin product of a radius-1 stencil reads), so that
    they are held once during the set-up.
    """
    h, w = shape
    classes = {(py, px): np.zeros((2, 2, len(range(py, h, 2)) + 2 * pad + 1, len(range(px, w, 2)) + 2 * pad + 1))
               for py in (0, 1) for px in (0, 1) if py < h and px < w}
    weights = InterpolationWeights(classes=classes, pad=pad)

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
    weights.class_weights(0, 0)[0, 0] = 1.0
    if w > 1:
        weights.class_weights(0, 1)[0, 0] = wxW
        weights.class_weights(0, 1)[0, 1] = wxE
    if h > 1:
        weights.class_weights(1, 0)[0, 0] = wyN
        weights.class_weights(1, 0)[1, 0] = wyS
    # cell centres (odd y, odd x): harmonic combination of the neighbours' rows
    ny, nx = h // 2, w // 2
    if ny and nx:
        part = source.parity_class(1, 1)
        c = {(dy, dx): part[k] for k, (dy, dx) in enumerate(offsets)}
        zero = np.zeros((ny, nx))

        def cc(dy, dx):
            return c.get((dy, dx), zero)

        # neighbour N (y-1, x) is an (even, odd) pixel (row i of wxW); S (y+1, x) is row i+1;
        # neighbour W (y, x-1) is an (odd, even) pixel (column j of wyN); E (y, x+1) is column j+1.
        # Parent (ey, ex): its vertical neighbour's weight (row ey of wxW or wxE, by ex) and its
        # horizontal neighbour's (column ex of wyN or wyS, by ey); one parent at a time, so that
        # only two shifted windows exist at once
        centre = cc(0, 0)
        for ey in (0, 1):
            for ex in (0, 1):
                vertical = _window(wxE if ex else wxW, ey, 0, ny, nx)
                horizontal = _window(wyS if ey else wyN, 0, ex, ny, nx)
                e = cc(2 * ey - 1, 2 * ex - 1) + cc(2 * ey - 1, 0) * vertical + cc(0, 2 * ex - 1) * horizontal
                del vertical, horizontal
                weights.class_weights(1, 1)[ey, ex] = _safe_ratio(-e, centre, 0.25)
                del e
    # parents outside the coarse grid (even H or W) carry no weight: the last row (column) is of class 1
    if h % 2 == 0:
        for px in range(min(w, 2)):
            weights.class_weights(1, px)[1, :, -1, :] = 0.0
    if w % 2 == 0:
        for py in range(min(h, 2)):
            weights.class_weights(py, 1)[:, 1, :, -1] = 0.0
    return weights
