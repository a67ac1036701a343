r"""Transfer operators between grid levels: the prolongation :math:`P` and its transpose, applied by array slicing.

Neither form stores an :math:`N`-row sparse matrix: the bilinear
:math:`P = P_y \otimes P_x` is applied one axis at a time
(:class:`SeparableProlongation`), the operator-dependent one keeps its
weights as images per parity class (:class:`ClassProlongation`).  Both offer
``P @ x``, ``P.T @ r``, the V-cycle's in-place ``out += P x``
(``add_prolonged``) and a CSR form (``tocsr``, for pyamg and checks).  May
import :mod:`sparsedepth.grid`, NumPy and SciPy.
"""

from __future__ import annotations

import functools

import numpy as np
import scipy.sparse as sp

from ...grid.stencil import index_dtype
from .interpolation import linear_weights_1d
from ...limits import memory_limits

__all__ = ["SeparableProlongation", "ClassProlongation"]



def _interp_matrix_1d(weights):
    """``(n, nc)`` CSR matrix of 1-D interpolation weights ``(2, n)`` (parents ``i//2`` and ``i//2 + 1``)."""
    n = weights.shape[1]
    nc = (n + 1) // 2
    i = np.arange(n)
    rows = np.concatenate([i, i])
    cols = np.concatenate([i // 2, i // 2 + 1])
    vals = np.concatenate([weights[0], weights[1]])
    keep = (vals != 0) & (cols < nc)
    return sp.csr_array((vals[keep], (rows[keep], cols[keep])), shape=(n, nc))


@functools.lru_cache(maxsize=64)
def _axis_matrices(n):
    """``(P, Pᵀ, Pᵀ in float32)`` of 1-D linear interpolation to ``n`` points, CSR; made once per length.

    Shared by every :class:`SeparableProlongation` with an axis of that length: nothing writes to them.
    """
    P = _interp_matrix_1d(linear_weights_1d(n))
    PT = P.T.tocsr()
    return P, PT, PT.astype(np.float32)


def _interpolate_linear_rows(X, h):
    """Rows of ``X`` (``hc`` rows) interpolated to ``h`` rows by :func:`linear_weights_1d`, a new array."""
    hc = X.shape[0]
    T = np.empty((h,) + X.shape[1:], dtype=X.dtype)
    T[0::2] = X
    mid = hc - 1
    if mid:
        np.add(X[:-1], X[1:], out=T[1:2 * mid:2])
        T[1:2 * mid:2] *= 0.5
    if h % 2 == 0:
        T[h - 1] = X[hc - 1]
    return T

class SeparableProlongation:
    r"""Bilinear prolongation :math:`P = P_y \otimes P_x`, applied one axis at a time.

    ``P @ x`` is :math:`\operatorname{vec}(P_y X P_x^\top)` and ``P.T @ r`` is
    :math:`\operatorname{vec}(P_y^\top R P_x)`: no ``N``-row matrix is stored
    (no CSR ``P`` with its index arrays).  ``P @ x`` (and the V-cycle's
    ``out += P @ x``) interpolates rows, then columns, by array slicing (a
    sparse product would need a transposed intermediate); ``P.T @ r`` uses
    the 1-D interpolation matrices of :func:`linear_weights_1d` (a few
    hundred rows).
    """

    def __init__(self, shape):
        h, w = shape
        (self.Py, self.PyT, PyT32), (self.Px, self.PxT, PxT32) = _axis_matrices(h), _axis_matrices(w)
        # the same (weights 1 and 1/2: exact in float32) for restricting float32 residuals in float32
        self._single = (PyT32, PxT32)
        hc, wc = self.Py.shape[1], self.Px.shape[1]
        self.fine_shape, self.coarse_shape = (h, w), (hc, wc)
        self.shape = (h * w, hc * wc)

    def __matmul__(self, x):
        return self.add_prolonged(np.zeros(self.shape[0]), x)

    def _rows_per_band(self, even=False):
        """Rows per band of the band-wise transfers (about ``transfer_band_pixels`` fine pixels; even if asked).

        ``transfer_band_pixels`` is the :class:`~sparsedepth.limits.MemoryLimits` field.
        """
        rows = max(2, memory_limits().transfer_band_pixels // self.fine_shape[1])
        return rows - rows % 2 if even else rows

    def add_prolonged(self, out, x):
        """``out += P @ x`` without an ``N``-long temporary (``out`` is C-contiguous), in ``out``'s precision.

        A band of fine rows at a time: its rows interpolated from the coarse rows, then its columns.
        """
        X = np.asarray(x, dtype=out.dtype).reshape(self.coarse_shape)
        O = out.reshape(self.fine_shape)
        (h, w), (hc, wc) = self.fine_shape, self.coarse_shape
        step = self._rows_per_band(even=True)
        for y0 in range(0, h, step):  # y0 even: fine row y0 is coarse row y0 / 2
            y1 = min(h, y0 + step)
            # the band's rows of the whole interpolation: the last band ends the grid, the others are interior
            T = (_interpolate_linear_rows(X[y0 // 2:], h - y0) if y1 == h
                 else _interpolate_linear_rows(X[y0 // 2:y1 // 2 + 1], y1 - y0 + 1)[:y1 - y0])
            band = O[y0:y1]
            band[:, 0::2] += T  # columns at coarse points
            mid = wc - 1  # columns between two coarse points: 1, 3, ..., 2 wc - 3
            if mid:
                between = T[:, :-1] + T[:, 1:]
                between *= 0.5
                band[:, 1:2 * mid:2] += between
            if w % 2 == 0:  # the last column has one coarse point to its left only
                band[:, w - 1] += T[:, wc - 1]
        return out

    def rmatvec(self, r):
        """``Pᵀ r`` as a new array, float32 for a float32 ``r``, else float64.

        A band of coarse rows at a time (the same sums: each coarse row is its own sparse product).
        """
        R = np.asarray(r)
        if R.dtype == np.float32:
            PyT, PxT = self._single
        else:
            PyT, PxT = self.PyT, self.PxT
            R = R.astype(np.float64, copy=False)
        R = R.reshape(self.fine_shape)
        (h, w), (hc, wc) = self.fine_shape, self.coarse_shape
        out = np.empty((hc, wc), dtype=R.dtype)
        step = max(1, self._rows_per_band() // 2)
        for Y0 in range(0, hc, step):
            Y1 = min(hc, Y0 + step)
            T = (PyT[Y0:Y1] @ R).T  # (w, Y1 - Y0)
            out[Y0:Y1] = (PxT @ T).T
        return out.reshape(-1)

    def restrict_rows(self, rows_of, dtype):
        """``Pᵀ r`` (float64 or float32 ``dtype``) for an ``r`` handed out a few rows at a time: never held whole.

        ``rows_of(y0, y1)`` returns the fine rows ``y0:y1`` of ``r`` as a ``(y1 − y0, W)`` array in ``dtype``.
        Each band of coarse rows reads the fine rows its weights reach (one more on each side) and sums them
        as :meth:`rmatvec` does (the same numbers).
        """
        single = np.dtype(dtype) == np.float32
        PyT, PxT = self._single if single else (self.PyT, self.PxT)
        (h, w), (hc, wc) = self.fine_shape, self.coarse_shape
        out = np.empty((hc, wc), dtype=np.float32 if single else np.float64)
        step = max(1, self._rows_per_band() // 2)
        for Y0 in range(0, hc, step):
            Y1 = min(hc, Y0 + step)
            f0, f1 = max(0, 2 * Y0 - 1), min(h, 2 * Y1)  # the fine rows of coarse rows Y0 .. Y1 - 1
            T = (PyT[Y0:Y1, f0:f1] @ rows_of(f0, f1)).T  # (w, Y1 - Y0)
            out[Y0:Y1] = (PxT @ T).T
        return out.reshape(-1)

    @property
    def T(self):
        return _Transposed(self)

    def tocsr(self):
        """The same ``P`` as a CSR matrix (``kron(P_y, P_x)``)."""
        return sp.kron(self.Py, self.Px, format="csr")

    def toarray(self):
        return self.tocsr().toarray()


class ClassProlongation:
    r"""Operator-dependent prolongation stored as weight images per parity class, applied by slicing.

    A fine pixel :math:`(2Y+p_y, 2X+p_x)` has the parents :math:`(Y+e_y,
    X+e_x)`, :math:`e \le p`; class ``(0, 0)`` copies its parent (weight 1),
    the others keep their 2 or 4 weights as images of the class's shape
    (``w01``: (2, ny0, nx1), ``w10``: (2, ny1, nx0), ``w11``: (2, 2, ny1,
    nx1)), a parent outside the coarse grid with weight 0.  That is 2
    numbers per pixel in the coarse levels' precision and no index array,
    where a CSR ``P`` holds 2.25 values, 2.25 column indices and a row
    pointer per pixel; ``P x`` and ``Pᵀ r`` are a few array operations per
    class instead of sparse products.
    """

    def __init__(self, weights, shape, dtype):
        h, w = shape
        self.fine_shape, self.coarse_shape = (h, w), ((h + 1) // 2, (w + 1) // 2)
        self.shape = (h * w, self.coarse_shape[0] * self.coarse_shape[1])
        self.dtype = np.dtype(dtype)
        # the weights W[ey, ex][y, x] of operator_weights (an InterpolationWeights), class by class
        def part(py, px):  # an empty class (a grid of one row or column) as an empty array of its shape
            if py < h and px < w:
                return weights.class_weights(py, px)
            return np.zeros((2, 2, len(range(py, h, 2)), len(range(px, w, 2))))

        self.w01 = np.ascontiguousarray(part(0, 1)[0, :], dtype=self.dtype)
        self.w10 = np.ascontiguousarray(part(1, 0)[:, 0], dtype=self.dtype)
        self.w11 = np.ascontiguousarray(part(1, 1), dtype=self.dtype)

    def _padded(self, x):
        hc, wc = self.coarse_shape
        X = np.zeros((hc + 1, wc + 1), dtype=np.result_type(x, self.dtype))
        X[:hc, :wc] = np.asarray(x).reshape(hc, wc)
        return X

    def add_prolonged(self, out, x):
        """``out += P @ x`` (``out`` C-contiguous, float32 or float64)."""
        (h, w), (hc, wc) = self.fine_shape, self.coarse_shape
        ny, nx = h // 2, w // 2  # odd rows / columns
        X = self._padded(x)
        O = out.reshape(h, w)
        O[0::2, 0::2] += X[:hc, :wc]
        if nx:
            O[0::2, 1::2] += self.w01[0] * X[:hc, :nx] + self.w01[1] * X[:hc, 1:nx + 1]
        if ny:
            O[1::2, 0::2] += self.w10[0] * X[:ny, :wc] + self.w10[1] * X[1:ny + 1, :wc]
        if nx and ny:
            w11 = self.w11
            O[1::2, 1::2] += (w11[0, 0] * X[:ny, :nx] + w11[0, 1] * X[:ny, 1:nx + 1]
                              + w11[1, 0] * X[1:ny + 1, :nx] + w11[1, 1] * X[1:ny + 1, 1:nx + 1])
        return out

    def __matmul__(self, x):
        return self.add_prolonged(np.zeros(self.shape[0]), x)

    def rmatvec(self, r):
        """``Pᵀ r`` as a new array, float32 for a float32 ``r``, else float64."""
        (h, w), (hc, wc) = self.fine_shape, self.coarse_shape
        ny, nx = h // 2, w // 2
        R = np.asarray(r)
        dtype = np.float32 if R.dtype == np.float32 else np.float64
        R = R.astype(dtype, copy=False).reshape(h, w)
        C = np.zeros((hc + 1, wc + 1), dtype=dtype)
        C[:hc, :wc] = R[0::2, 0::2]
        if nx:
            part = R[0::2, 1::2]
            C[:hc, :nx] += self.w01[0] * part
            C[:hc, 1:nx + 1] += self.w01[1] * part
        if ny:
            part = R[1::2, 0::2]
            C[:ny, :wc] += self.w10[0] * part
            C[1:ny + 1, :wc] += self.w10[1] * part
        if nx and ny:
            part = R[1::2, 1::2]
            for ey in (0, 1):
                for ex in (0, 1):
                    C[ey:ey + ny, ex:ex + nx] += self.w11[ey, ex] * part
        return np.ascontiguousarray(C[:hc, :wc]).reshape(-1)

    @property
    def T(self):
        return _Transposed(self)

    def dense_weights(self):
        """The weights as ``(2, 2, H, W)`` images (float64), as :func:`operator_weights` gave them."""
        h, w = self.fine_shape
        full = np.zeros((2, 2, h, w))
        full[0, 0, 0::2, 0::2] = 1.0
        full[0, :, 0::2, 1::2] = self.w01
        full[:, 0, 1::2, 0::2] = self.w10
        full[:, :, 1::2, 1::2] = self.w11
        return full

    def tocsr(self):
        """The same ``P`` as a CSR matrix (values in the stored precision)."""
        indptr, indices, gather = _prolongation_pattern(self.fine_shape)
        data = np.take(self.dense_weights().reshape(-1), gather).astype(self.dtype)
        return sp.csr_array((data, indices, indptr), shape=self.shape)

    def toarray(self):
        return self.tocsr().toarray()


class _Transposed:
    """``P.T`` of a prolongation: ``P.T @ r`` is ``P.rmatvec(r)``."""

    def __init__(self, op):
        self._op = op
        self.shape = op.shape[::-1]

    def __matmul__(self, r):
        return self._op.rmatvec(r)


def _prolongation_pattern(shape):
    """CSR structure of P (fine x coarse) and the gather index from weights to data.

    ``P.data = W.reshape(-1)[gather]`` for weights ``W`` of shape (2, 2, H, W).
    """
    h, w = shape
    hc, wc = (h + 1) // 2, (w + 1) // 2
    itype = index_dtype(4 * h * w)
    cy = (np.arange(h) // 2).astype(itype)
    cx = (np.arange(w) // 2).astype(itype)
    # second parent exists for odd indices whose right/lower coarse point exists
    second_y = slice(1, 2 * (hc - 1), 2)
    second_x = slice(1, 2 * (wc - 1), 2)
    all_y, all_x = slice(0, h), slice(0, w)

    def slots():
        for ey, ys in ((0, all_y), (1, second_y)):
            for ex, xs in ((0, all_x), (1, second_x)):
                if ys.start >= ys.stop or xs.start >= xs.stop:
                    continue
                cols = (cy[ys] + ey)[:, None] * itype(wc) + (cx[xs] + ex)[None, :]
                yield 2 * ey + ex, ys, xs, cols

    return _pattern_from_slots(shape, 4, slots(), itype)


def _pattern_from_slots(shape, n_slots, slots, itype):
    """CSR structure assembled slot by slot, without per-entry masks.

    ``slots`` yields ``(k, ys, xs, cols)``: slot ``k`` is present for the fine
    pixels ``[ys, xs]`` (slices) and has column indices ``cols`` there.  Slots
    must come in increasing column order within every row.  Returns ``indptr``,
    ``indices`` and ``gather`` with ``gather = k * N + row`` for each entry.
    """
    h, w = shape
    n = h * w
    slots = list(slots)
    counts = np.zeros((h, w), dtype=itype)
    for _, ys, xs, _ in slots:
        counts[ys, xs] += 1
    indptr = np.zeros(n + 1, dtype=itype)
    np.cumsum(counts.reshape(-1), out=indptr[1:])
    nnz = int(indptr[-1])
    indices = np.empty(nnz, dtype=itype)
    gather = np.empty(nnz, dtype=itype)
    pos = indptr[:-1].reshape(h, w).copy()
    rows = np.arange(n, dtype=itype).reshape(h, w)
    for k, ys, xs, cols in slots:
        where = pos[ys, xs]
        indices[where] = cols
        gather[where] = rows[ys, xs] + itype(k * n)
        pos[ys, xs] += 1
    return indptr, indices, gather
