r"""Gauss--Seidel sweeps and products of a symmetric stencil, a band of image rows at a time.

pyamg's Gauss--Seidel kernel needs a CSR matrix.  Instead of holding the
whole CSR form of a level (12 bytes per non-zero in float64),
:class:`BandedStencil` writes the CSR values of
a few image rows at a time into a small buffer (one slice per offset of the stencil's
images) and runs the kernel on that band.  The vectors are copied into a grid padded by the stencil radius
``R`` on every side, so that every band has the same column indices
(computed once) and every pixel the same ``K`` entries, the neighbours
outside the grid pointing into the zero padding (whatever finite
coefficient such an entry holds, it multiplies an exact zero).  Rows
are visited in the order of the whole-matrix kernel, each row sums its
entries in the same order, and the extra entries add exact zeros, so a sweep
or a product equals the one on :meth:`~sparsedepth.grid.stencil.SymmetricStencil.tocsr`
in the same precision, bit for bit.

May import NumPy, SciPy, pyamg and :mod:`sparsedepth.grid`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from pyamg import amg_core

from ...grid.rowbands import row_bands, rows_per_band
from ...grid.stencil import SymmetricStencil, stencil_to_csr
from ...limits import memory_limits

__all__ = ["BandedStencil", "FullStencil"]



class FullStencil:
    """A grid operator stored as the coefficient images of all its offsets (see :mod:`sparsedepth.grid.stencil`).

    The form of a large coarse level whose coefficients are not exactly
    symmetric once rounded to its precision (so that
    :class:`~sparsedepth.grid.stencil.SymmetricStencil` cannot hold it): the
    values of its CSR form without the index arrays (in float32, half the
    bytes of the CSR form), swept and multiplied band by
    band by :class:`BandedStencil`.

    Parameters
    ----------
    offsets : list of tuple of int
        Distinct offsets, sorted.
    stencil : ndarray (len(offsets), H, W) or list of (H, W) arrays
        One image per offset; entries whose neighbour lies outside the grid
        are ignored (stored as 0).  A list is consumed: each entry is set to
        None once stored, so that its image can be freed.
    dtype : numpy dtype
        Precision of the stored images.

    Attributes
    ----------
    offsets : list of tuple of int
    data : ndarray (len(offsets), H, W)
    grid_shape, shape : tuple of int
    dtype : numpy.dtype
    nnz : int
        Entries of the full in-grid pattern (what :meth:`tocsr` stores).
    """

    format = "stencil"

    def __init__(self, offsets, stencil, dtype):
        self.offsets = [(int(dy), int(dx)) for dy, dx in offsets]
        H, W = self.grid_shape = tuple(np.shape(stencil[0]))
        self.data = np.empty((len(self.offsets), H, W), dtype=dtype)
        for k, (dy, dx) in enumerate(self.offsets):
            inside = np.zeros((H, W), dtype=bool)
            inside[max(0, -dy):max(0, H - dy), max(0, -dx):max(0, W - dx)] = True
            np.copyto(self.data[k], stencil[k], casting="unsafe")
            self.data[k][~inside] = 0
            if isinstance(stencil, list):
                stencil[k] = None
        self.dtype = self.data.dtype
        self.shape = (H * W, H * W)

    @property
    def nnz(self):
        H, W = self.grid_shape
        return sum(max(0, H - abs(dy)) * max(0, W - abs(dx)) for dy, dx in self.offsets)

    def diagonal(self):
        """The main diagonal as a new ``(H W,)`` array."""
        return self.data[self.offsets.index((0, 0))].reshape(-1).copy()

    def tocsr(self, dtype=None):
        """The CSR form in the full in-grid pattern of :func:`~sparsedepth.grid.stencil.stencil_to_csr`."""
        return stencil_to_csr(self.offsets, self.data, dtype=self.dtype if dtype is None else dtype)

    def __matmul__(self, x):
        return BandedStencil(self, self.dtype) @ x

    def __repr__(self):
        return f"FullStencil(grid_shape={self.grid_shape}, offsets={len(self.offsets)}, dtype={self.dtype})"


class BandedStencil:
    """A :class:`~sparsedepth.grid.stencil.SymmetricStencil` or :class:`FullStencil` applied through band-wise CSR.

    Parameters
    ----------
    A : SymmetricStencil or FullStencil
        The operator; its images are read (and cast) band by band, never copied whole.
    dtype : numpy dtype
        Precision of the sweeps and products (float32 or float64).

    Attributes
    ----------
    shape : tuple of int
        ``(N, N)``.
    dtype : numpy.dtype
    stencil : SymmetricStencil
    """

    def __init__(self, A, dtype):
        if not isinstance(A, (SymmetricStencil, FullStencil)):
            raise TypeError(f"`A` must be a SymmetricStencil or a FullStencil, got {type(A).__name__}")
        self.stencil = A
        self.dtype = np.dtype(dtype)
        self.shape = A.shape
        H, W = self.grid_shape = A.grid_shape
        self.radius = R = max(max(abs(dy), abs(dx)) for dy, dx in A.offsets)
        self._wp = W + 2 * R
        K = len(A.offsets)
        self._rows = min(H, rows_per_band(W * K, memory_limits().stencil_band_values))
        self._delta = np.array([dy * self._wp + dx for dy, dx in A.offsets])
        self._patterns = {}
        # flat start in A.data of each offset's coefficients for pixel 0 (may be negative): entry (p, k) of a band
        # reads offset k's coefficient at pixel p, i.e. the stored image of k there or, for a lower offset o, the
        # image of -o at the neighbour p + o, so each offset reads one contiguous run of data.ravel(); entries
        # whose neighbour lies outside the grid read some other finite coefficient, which multiplies the padding
        if isinstance(A, SymmetricStencil):
            self._starts = [A._slot[o] * H * W if o >= (0, 0) else A._slot[(-o[0], -o[1])] * H * W + o[0] * W + o[1]
                            for o in A.offsets]
        else:  # every offset has its own image
            self._starts = [k * H * W for k in range(K)]

    # ---- band structure -----------------------------------------------------
    def _pattern(self, rows):
        """``(indptr, indices, matrix)`` of a band of ``rows`` image rows, in the coordinates of its padded view."""
        if rows not in self._patterns:
            R, W, wp = self.radius, self.grid_shape[1], self._wp
            K = len(self.stencil.offsets)
            view_rows = rows + 2 * R
            counts = np.zeros((view_rows, wp), dtype=np.int32)
            counts[R:R + rows, R:R + W] = K
            indptr = np.zeros(view_rows * wp + 1, dtype=np.int32)
            np.cumsum(counts.reshape(-1), out=indptr[1:])
            centre = (np.arange(R, R + rows)[:, None] * wp + np.arange(R, R + W)[None, :]).astype(np.int32)
            indices = (centre[:, :, None] + self._delta[None, None, :].astype(np.int32)).reshape(-1)
            values = np.zeros(indices.size, dtype=self.dtype)
            matrix = sp.csr_array((values, indices, indptr), shape=(view_rows * wp, view_rows * wp))
            # the kernels read the arrays the matrix holds (SciPy may have copied or cast them)
            self._patterns[rows] = (matrix.indptr, matrix.indices, matrix)
        return self._patterns[rows]

    def _bands(self, reverse=False):
        bands = [(rows.start, rows.stop) for rows in row_bands(0, self.grid_shape[0], self._rows)]
        return bands[::-1] if reverse else bands

    def _fill(self, y0, y1):
        """Write the CSR values of image rows ``y0:y1`` into their band matrix; returns its flat values.

        One slice copy per offset (contiguous reads of the stencil's images); a run that would start before
        the first image (lower offsets in the first rows) reads its first value there instead.
        """
        _, _, matrix = self._pattern(y1 - y0)
        W = self.grid_shape[1]
        n = (y1 - y0) * W
        flat = self.stencil.data.reshape(-1)
        values = matrix.data.reshape(n, -1)
        for k, first in enumerate(self._starts):
            lo = first + y0 * W
            if lo >= 0:
                values[:, k] = flat[lo:lo + n]
            else:
                values[:-lo, k] = flat[0]
                values[-lo:, k] = flat[:lo + n]
        return matrix.data

    def _padded(self, v):
        H, W = self.grid_shape
        R = self.radius
        out = np.zeros((H + 2 * R, self._wp), dtype=self.dtype)
        out[R:R + H, R:R + W] = v.reshape(H, W)
        return out

    def _view(self, padded, y0, y1):
        """The flat view of padded rows ``y0 .. y1 + 2R`` (image rows ``y0 − R .. y1 + R``)."""
        return padded.reshape(-1)[y0 * self._wp:(y1 + 2 * self.radius) * self._wp]

    # ---- operations ---------------------------------------------------------
    def gauss_seidel(self, x, b, sweeps=1, *, backward=False):
        """``sweeps`` Gauss--Seidel sweeps on ``A x = b`` (forward, or last row first), updating ``x`` in place.

        Each band copies its rows of ``b`` and its rows of ``x`` with ``R`` more on each side into a small
        zero-padded buffer, is swept there and copied back before the next band reads ``x``: the same
        operations as a sweep over whole padded copies, without them.
        """
        H, W = self.grid_shape
        R, wp = self.radius, self._wp
        xg, bg = x.reshape(H, W), b.reshape(H, W)
        xp = np.zeros((self._rows + 2 * R, wp), dtype=self.dtype)
        bp = np.zeros_like(xp)
        for _ in range(sweeps):
            for y0, y1 in self._bands(reverse=backward):
                indptr, indices, _ = self._pattern(y1 - y0)
                data = self._fill(y0, y1)
                rows = y1 - y0 + 2 * R
                lo, hi = max(0, y0 - R), min(H, y1 + R)  # the grid rows of x the band reads
                xb, bb = xp[:rows], bp[:rows]
                xb[...] = 0
                xb[lo - y0 + R:hi - y0 + R, R:R + W] = xg[lo:hi]
                bb[R:R + y1 - y0, R:R + W] = bg[y0:y1]
                first, stop = R * wp, (R + y1 - y0) * wp
                xv, bv = xb.reshape(-1), bb.reshape(-1)
                if backward:
                    amg_core.gauss_seidel(indptr, indices, data, xv, bv, stop - 1, first - 1, -1)
                else:
                    amg_core.gauss_seidel(indptr, indices, data, xv, bv, first, stop, 1)
                xg[y0:y1] = xb[R:R + y1 - y0, R:R + W]
        return x

    def matvec(self, x):
        """``A x`` in precision :attr:`dtype` (``x`` is cast to it).

        In the stencil's own precision this is the stencil's product by image
        slices (:meth:`SymmetricStencil.matvec`, the same bits and no
        gathering); otherwise the band-wise CSR product.
        """
        H, W = self.grid_shape
        R = self.radius
        x = np.asarray(x).reshape(-1)
        if x.shape[0] != self.shape[1]:
            raise ValueError(f"expected a vector of length {self.shape[1]} (grid {self.grid_shape}), got "
                             f"{x.shape[0]}")
        if x.dtype == self.dtype == self.stencil.dtype and isinstance(self.stencil, SymmetricStencil):
            return self.stencil.matvec(x)
        xp = self._padded(x)
        out = np.empty((H, W), dtype=self.dtype)
        for y0, y1 in self._bands():
            _, _, matrix = self._pattern(y1 - y0)
            self._fill(y0, y1)
            y = matrix @ self._view(xp, y0, y1)
            out[y0:y1] = y.reshape(-1, self._wp)[R:R + y1 - y0, R:R + W]
        return out.reshape(-1)

    def __matmul__(self, x):
        return self.matvec(x)

    def diagonal(self):
        return self.stencil.diagonal().astype(self.dtype)

    def __repr__(self):
        return f"BandedStencil({self.stencil!r}, dtype={self.dtype}, rows per band={self._rows})"
