r"""Geometric multigrid preconditioners for SPD operators on pixel grids.

The solvers of this package repeatedly solve sparse symmetric positive definite
(SPD) systems that live on an :math:`H \times W` pixel grid (pixels flattened in
C order, :math:`N = HW`), typically

.. math::

    A = \operatorname{diag}(a) + D_x^\top \operatorname{diag}(w_x) D_x
        + D_y^\top \operatorname{diag}(w_y) D_y ,

with forward differences :math:`D_x, D_y` (Neumann boundary), a reaction term
:math:`a \ge 0` and edge weights :math:`w_x, w_y > 0` (constant, or jumping by
orders of magnitude for IRLS / split-Bregman variants), possibly plus a
second-order term that widens the stencil to 13 points.

This module exploits the grid: the hierarchy is built from *stencils*, i.e. one
coefficient image per neighbour offset, so that

* the prolongation :math:`P` comes from 1-D interpolation along each axis
  (``interpolation="bilinear"``, fixed per grid shape) or from the matrix
  entries themselves (``interpolation="operator"``, Dendy's black-box
  multigrid, for jumping coefficients); either is stored as weight arrays
  (1-D, or two images per parity class) and applied by array slicing, never
  as an :math:`N`-row sparse matrix;
* the Galerkin operators :math:`A^c = P^\top A P` are computed by vectorised
  stencil arithmetic on the four parity classes of fine pixels, never by a
  general sparse matrix product, and land in a sparsity pattern that is fixed
  per grid shape;
* :meth:`GridMultigrid.update` therefore redoes only the numeric part for a new
  operator with the same stencil (new weights between IRLS iterations).

The cycle is a symmetric V-cycle (forward Gauss--Seidel before, backward
Gauss--Seidel after the coarse-grid correction, using pyamg's compiled
kernels), so it is a valid preconditioner for conjugate gradients.  Unless
the operator is very large it runs in float32 (on a float32 copy of the fine
operator's values), which moves fewer bytes per sweep; the callers'
residuals stay float64, so a solve's accuracy does not depend on it.
:func:`solve_spd` runs preconditioned CG with a choice of preconditioners and
returns an honest residual history.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from pyamg import amg_core

from .._validation import check_grid_shape
from ..grid.stencil import index_dtype, csr_to_stencil, full_pattern_offsets, stencil_to_csr

__all__ = [
    "GridMultigrid",
    "SolveInfo",
    "grid_multigrid",
    "grid_stencil",
    "solve_spd",
]

_INTERPOLATIONS = ("bilinear", "operator", "auto")
_SMOOTHERS = ("gauss_seidel", "jacobi")
_PRECONDITIONERS = ("grid", "amg", "sa", "jacobi", "none")
#: fine grids from this many pixels keep their coarse levels in float32 (coarse_precision="auto")
_SINGLE_COARSE_PIXELS = 1 << 21
#: fine operators with at most this many non-zeros are smoothed in float32 (fine_precision="auto"), on
#: a float32 copy of their values (at most 256 MB); larger ones (an 8-megapixel 13-point system has
#: 1.04e8) are smoothed in float64, as the copy would then weigh on the peak memory
_SINGLE_FINE_VALUES = 1 << 26
# Below this many fine pixels every level's stencil is kept as one (K, H, W)
# array during the set-up (fine: read from the CSR once; coarse: the Galerkin
# result itself) instead of being read back from the CSR one parity class at a
# time, which keeps the 8-MP set-up's memory low but reads most classes twice.
_KEEP_STENCIL_PIXELS = 1 << 21


# --------------------------------------------------------------------------
# input checks
# --------------------------------------------------------------------------


def _check_matrix(A, shape):
    """Return `A` as a canonical float64 CSR matrix (no copy when it already is)."""
    if not sp.issparse(A):
        raise TypeError(
            f"`A` must be a scipy.sparse matrix or array, got {type(A).__name__}."
        )
    h, w = check_grid_shape(shape)
    if A.shape != (h * w, h * w):
        raise ValueError(
            f"`A` has shape {A.shape} but a grid of shape {(h, w)} needs "
            f"({h * w}, {h * w}); pass the (H, W) the pixels were flattened from."
        )
    if np.iscomplexobj(A.data):
        raise TypeError("`A` must be real; complex operators are not supported.")
    if A.format != "csr" or A.dtype != np.float64:
        A = sp.csr_array(A, dtype=np.float64)
    if not A.has_canonical_format:
        A = A.copy()
        A.sum_duplicates()
    return A, (h, w)


# --------------------------------------------------------------------------
# stencils
# --------------------------------------------------------------------------
def _square_offsets(radius):
    r = range(-radius, radius + 1)
    return [(dy, dx) for dy in r for dx in r]


def _mask_outside(S, offsets, shape):
    """Zero stencil coefficients whose neighbour lies outside the grid (in place)."""
    h, w = shape
    for k, (dy, dx) in enumerate(offsets):
        if dy > 0:
            S[k, max(h - dy, 0):, :] = 0.0
        elif dy < 0:
            S[k, : min(-dy, h), :] = 0.0
        if dx > 0:
            S[k, :, max(w - dx, 0):] = 0.0
        elif dx < 0:
            S[k, :, : min(-dx, w)] = 0.0


def _extract_stencil(A, shape, offsets):
    """Stencil images of a canonical CSR matrix for the given offsets."""
    h, w = shape
    n = h * w
    S = np.zeros((len(offsets), h, w))
    flat = S.reshape(len(offsets), n)
    for k, (dy, dx) in enumerate(offsets):
        delta = dy * w + dx
        if abs(delta) >= n:
            continue
        d = A.diagonal(delta)
        if delta >= 0:
            flat[k, : n - delta] = d
        else:
            flat[k, -delta:] = d
    _mask_outside(S, offsets, shape)
    return S


def grid_stencil(A, shape, *, radius=None):
    r"""Stencil (one coefficient image per neighbour offset) of a grid operator.

    Parameters
    ----------
    A : scipy.sparse matrix, shape (N, N)
        Operator on an ``shape = (H, W)`` grid, pixels flattened in C order,
        ``N = H * W``.
    shape : tuple of int
        Grid shape ``(H, W)``.
    radius : int, optional
        Stencil radius :math:`r`: couplings :math:`|dy|, |dx| \le r` are read.
        By default 1 is tried, then 2.

    Returns
    -------
    offsets : list of tuple of int
        Neighbour offsets ``(dy, dx)`` in lexicographic order, restricted to
        those with a non-zero coefficient somewhere (the centre is always kept).
    S : ndarray, shape (len(offsets), H, W)
        ``S[k, y, x] = A[y*W + x, (y+dy_k)*W + (x+dx_k)]``; zero where the
        neighbour lies outside the grid.

    Raises
    ------
    ValueError
        If `A` has couplings outside the stencil radius (for instance when
        `shape` is not the grid `A` was built on).

    Notes
    -----
    The coefficients are read diagonal by diagonal (``A.diagonal(dy*W + dx)``)
    and masked at the grid boundary.  A pixel and a diagonal determine at
    most one in-grid offset, so every non-zero entry of `A` lands in `S` at
    most once, and the extraction is complete iff the numbers of non-zeros
    agree -- an exact integer check (an earlier floating-point comparison of
    Frobenius norms failed on 640x480 grids through rounding alone).

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> A = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(4, 4))
    >>> offsets, S = grid_stencil(A, (1, 4))
    >>> offsets
    [(0, -1), (0, 0), (0, 1)]
    """
    A, shape = _check_matrix(A, shape)
    offsets = _pattern_offsets(A, shape, radius)  # one pass when A is in the full in-grid pattern
    if offsets is None:
        return _stencil_of(A, shape, radius)
    _, S = csr_to_stencil(A, shape, offsets=offsets)
    return _without_empty_offsets(offsets, S)


def _without_empty_offsets(offsets, S):
    """``offsets`` and ``S`` without the offsets whose image is all zero (the centre is always kept)."""
    keep = [k for k, o in enumerate(offsets) if o == (0, 0) or np.any(S[k])]
    return [offsets[k] for k in keep], (S if len(keep) == len(offsets) else S[keep])


def _offset_image(A, shape, dy, dx, out):
    """``out[y, x] = A[y*W + x, (y+dy)*W + (x+dx)]`` (0 outside the grid); returns ``out``."""
    h, w = shape
    n = h * w
    flat = out.reshape(n)
    flat[:] = 0.0
    delta = dy * w + dx
    if abs(delta) < n:
        d = A.diagonal(delta)
        if delta >= 0:
            flat[: n - delta] = d
        else:
            flat[-delta:] = d
    _mask_outside(out[None], [(dy, dx)], shape)
    return out


def _stencil_of(A, shape, radius=None):
    """Offsets present in ``A`` (radius <= 2, or ``radius``) and their stencil images.

    (Matrices in the full in-grid pattern of :func:`~sparsedepth.grid.stencil.stencil_to_csr`
    are read by the callers, see :func:`_pattern_offsets`, before this is tried.)
    Two passes over the candidate offsets: the first only counts the non-zeros
    of each offset (one ``(H, W)`` work image; the 5-point, then the 3x3, then
    the 5x5 offsets, stopping as soon as every non-zero is accounted for), the
    second fills ``S`` for the offsets present, so memory is ``(#present + 1) H W`` floats, never the
    full ``(2r+1)² H W`` (1.6 GB for a 13-point operator on 8 MP).
    Completeness is exact: a pixel and a diagonal determine at most one
    in-grid offset, so the operator is captured iff the non-zero counts add
    up to the number of stored non-zeros of ``A``.
    """
    largest = 2 if radius is None else int(radius)
    if radius is None:  # 5-point first, then 3x3, then 5x5: stop once all is found
        rings = [[(-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)], _square_offsets(1), _square_offsets(2)]
    else:
        rings = [_square_offsets(largest)]
    total = int(np.count_nonzero(A.data))
    if radius is None:
        # common case first: a 5-point operator is extracted in a single pass
        five = rings[0]
        S = np.empty((5,) + tuple(shape))
        if sum(int(np.count_nonzero(_offset_image(A, shape, dy, dx, S[k])))
               for k, (dy, dx) in enumerate(five)) == total:
            return _without_empty_offsets(five, S)
        del S
    work = np.empty(shape)
    present, seen, counted = [], set(), 0
    for ring in rings:
        for dy, dx in ring:
            if (dy, dx) in seen:
                continue
            seen.add((dy, dx))
            count = int(np.count_nonzero(_offset_image(A, shape, dy, dx, work)))
            if count or (dy, dx) == (0, 0):
                present.append((dy, dx))
                counted += count
        if counted == total:
            break
    del work
    present.sort()
    if counted != total:
        raise ValueError(
            f"`A` couples pixels farther apart than a stencil of radius {largest} "
            f"on a grid of shape {shape}: check that `shape` is the (H, W) the pixels "
            "were flattened from (C order), or pass `radius=` for wider stencils."
        )
    S = np.empty((len(present),) + tuple(shape))
    for k, (dy, dx) in enumerate(present):
        _offset_image(A, shape, dy, dx, S[k])
    return present, S


class _StencilSource:
    """A level's stencil for the numeric set-up, handed out one parity class at a time.

    Either an array ``(K, H, W)`` (coarse levels, or a fine operator whose
    stencil had to be extracted diagonal by diagonal) or a CSR matrix in the
    full in-grid pattern of :func:`~sparsedepth.grid.stencil.stencil_to_csr`, read
    class by class so that the fine stencil is never held whole (8 MP,
    13-point: 210 MB per class instead of 830 MB).  Grids below
    ``_KEEP_STENCIL_PIXELS`` read it whole once (:meth:`read_whole`).
    """

    def __init__(self, offsets, shape, *, array=None, csr=None, csr_offsets=None):
        self.offsets = list(offsets)
        self.shape = tuple(shape)
        self.array = array
        self.csr = csr
        self.csr_offsets = None if csr_offsets is None else list(csr_offsets)

    def parity_class(self, py, px):
        """Stencil images on the pixels ``(py::2, px::2)``, shape ``(K, ny, nx)`` (``py = None``: all pixels)."""
        if self.array is not None:
            return np.ascontiguousarray(self.array[:, py::2, px::2])
        parity = None if py is None else (py, px)  # None: the whole grid
        _, part = csr_to_stencil(self.csr, self.shape, offsets=self.csr_offsets, parity=parity)
        if self.csr_offsets == self.offsets:
            return part
        out = np.zeros((len(self.offsets),) + part.shape[1:])
        slot = {o: k for k, o in enumerate(self.offsets)}
        for k, o in enumerate(self.csr_offsets):
            out[slot[o]] = part[k]
        return out

    def read_whole(self):
        """Read a CSR source into one array now (the set-up asks for most classes twice)."""
        if self.array is None:
            self.array = self.parity_class(None, None)
            self.csr = None
        return self


def _pattern_offsets(A, shape, radius=None):
    """Offsets of ``A`` when it is in the full in-grid pattern within the radius (default 2), else None."""
    largest = 2 if radius is None else int(radius)
    offsets = full_pattern_offsets(A, shape)
    if offsets is not None and all(max(abs(dy), abs(dx)) <= largest for dy, dx in offsets):
        return offsets
    return None


def _fine_source(A, shape, radius=None):
    """Offsets and :class:`_StencilSource` of a fine operator (pattern read, else extraction)."""
    offsets = _pattern_offsets(A, shape, radius)
    if offsets is not None:
        return offsets, _StencilSource(offsets, shape, csr=A, csr_offsets=offsets)
    offsets, S = _stencil_of(A, shape, radius)
    return offsets, _StencilSource(offsets, shape, array=S)


def _pattern_from_slots(shape, n_slots, slots, index_dtype):
    """CSR structure assembled slot by slot, without per-entry masks.

    ``slots`` yields ``(k, ys, xs, cols)``: slot ``k`` is present for the fine
    pixels ``[ys, xs]`` (slices) and has column indices ``cols`` there.  Slots
    must come in increasing column order within every row.  Returns ``indptr``,
    ``indices`` and ``gather`` with ``gather = k * N + row`` for each entry.
    """
    h, w = shape
    n = h * w
    slots = list(slots)
    counts = np.zeros((h, w), dtype=index_dtype)
    for _, ys, xs, _ in slots:
        counts[ys, xs] += 1
    indptr = np.zeros(n + 1, dtype=index_dtype)
    np.cumsum(counts.reshape(-1), out=indptr[1:])
    nnz = int(indptr[-1])
    indices = np.empty(nnz, dtype=index_dtype)
    gather = np.empty(nnz, dtype=index_dtype)
    pos = indptr[:-1].reshape(h, w).copy()
    rows = np.arange(n, dtype=index_dtype).reshape(h, w)
    for k, ys, xs, cols in slots:
        where = pos[ys, xs]
        indices[where] = cols
        gather[where] = rows[ys, xs] + index_dtype(k * n)
        pos[ys, xs] += 1
    return indptr, indices, gather


# --------------------------------------------------------------------------
# interpolation
# --------------------------------------------------------------------------
class _Interp:
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


def _linear_weights_1d(n):
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


def _bilinear_interp(shape):
    h, w = shape
    return _Interp(wy=_linear_weights_1d(h), wx=_linear_weights_1d(w))


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


def _interpolate_linear_rows(X, h):
    """Rows of ``X`` (``hc`` rows) interpolated to ``h`` rows by :func:`_linear_weights_1d`, a new array."""
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


class _SeparableProlongation:
    r"""Bilinear prolongation :math:`P = P_y \otimes P_x`, applied one axis at a time.

    ``P @ x`` is :math:`\operatorname{vec}(P_y X P_x^\top)` and ``P.T @ r`` is
    :math:`\operatorname{vec}(P_y^\top R P_x)`: no ``N``-row matrix is stored
    (8 MP: ~300 MB saved over a CSR ``P``).  ``P @ x`` (and the V-cycle's
    ``out += P @ x``) interpolates rows, then columns, by array slicing (a
    sparse product with a transposed intermediate was measured 8x slower on
    a 640x480 grid); ``P.T @ r`` uses the 1-D interpolation matrices of
    :func:`_linear_weights_1d` (a few hundred rows).
    """

    def __init__(self, shape):
        h, w = shape
        self.Py = _interp_matrix_1d(_linear_weights_1d(h))
        self.Px = _interp_matrix_1d(_linear_weights_1d(w))
        self.PyT = self.Py.T.tocsr()
        self.PxT = self.Px.T.tocsr()
        # the same (weights 1 and 1/2: exact in float32) for restricting float32 residuals in float32
        self._single = (self.PyT.astype(np.float32), self.PxT.astype(np.float32))
        hc, wc = self.Py.shape[1], self.Px.shape[1]
        self.fine_shape, self.coarse_shape = (h, w), (hc, wc)
        self.shape = (h * w, hc * wc)

    def __matmul__(self, x):
        return self.add_prolonged(np.zeros(self.shape[0]), x)

    def add_prolonged(self, out, x):
        """``out += P @ x`` without an ``N``-long temporary (``out`` is C-contiguous), in ``out``'s precision."""
        X = np.asarray(x, dtype=out.dtype).reshape(self.coarse_shape)
        O = out.reshape(self.fine_shape)
        (h, w), (hc, wc) = self.fine_shape, self.coarse_shape
        T = _interpolate_linear_rows(X, h)  # (h, wc)
        O[:, 0::2] += T  # columns at coarse points
        mid = wc - 1  # columns between two coarse points: 1, 3, ..., 2 wc - 3
        if mid:
            between = T[:, :-1] + T[:, 1:]
            between *= 0.5
            O[:, 1:2 * mid:2] += between
        if w % 2 == 0:  # the last column has one coarse point to its left only
            O[:, w - 1] += T[:, wc - 1]
        return out

    def rmatvec(self, r):
        """``Pᵀ r`` as a new array, float32 for a float32 ``r``, else float64."""
        R = np.asarray(r)
        if R.dtype == np.float32:
            PyT, PxT = self._single
        else:
            PyT, PxT = self.PyT, self.PxT
            R = R.astype(np.float64, copy=False)
        T = (PyT @ R.reshape(self.fine_shape)).T  # (w, hc)
        return np.ascontiguousarray((PxT @ T).T).reshape(-1)

    @property
    def T(self):
        return _Transposed(self)

    def tocsr(self):
        """The same ``P`` as a CSR matrix (``kron(P_y, P_x)``)."""
        return sp.kron(self.Py, self.Px, format="csr")

    def toarray(self):
        return self.tocsr().toarray()


class _ClassProlongation:
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

    def __init__(self, full, dtype):
        h, w = full.shape[2:]
        self.fine_shape, self.coarse_shape = (h, w), ((h + 1) // 2, (w + 1) // 2)
        self.shape = (h * w, self.coarse_shape[0] * self.coarse_shape[1])
        self.dtype = np.dtype(dtype)
        # the weights full[ey, ex, y, x] (shape (2, 2, H, W)) of _operator_interp, class by class
        self.w01 = np.ascontiguousarray(full[0, :, 0::2, 1::2], dtype=self.dtype)
        self.w10 = np.ascontiguousarray(full[:, 0, 1::2, 0::2], dtype=self.dtype)
        self.w11 = np.ascontiguousarray(full[:, :, 1::2, 1::2], dtype=self.dtype)

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
        """The weights as ``(2, 2, H, W)`` images (float64), as :func:`_operator_interp` gave them."""
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
    def __init__(self, op):
        self._op = op
        self.shape = op.shape[::-1]

    def __matmul__(self, r):
        return self._op.rmatvec(r)

    def tocsr(self):
        return self._op.tocsr().T.tocsr()


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


def _operator_interp(offsets, source, shape):
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
    return _Interp(full=full)


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


# --------------------------------------------------------------------------
# Galerkin product on stencils
# --------------------------------------------------------------------------
def _galerkin_offsets(offsets):
    """Offsets of P^T A P for the given fine offsets (structural)."""
    out = set()
    for py in (0, 1):
        for px in (0, 1):
            for dy, dx in offsets:
                qy, ry = divmod(py + dy, 2)
                qx, rx = divmod(px + dx, 2)
                for ey in range(py + 1):
                    for ex in range(px + 1):
                        for fy in range(ry + 1):
                            for fx in range(rx + 1):
                                out.add((qy + fy - ey, qx + fx - ex))
    return sorted(out)


def _galerkin(offsets, source, interp, shape, coarse_offsets):
    r"""Coarse stencil of :math:`P^\top A P` by parity-class stencil arithmetic.

    For a fine pixel :math:`i = (2Y+p_y, 2X+p_x)`, neighbour offset
    :math:`o = (d_y, d_x)` and parents :math:`e, f \in \{0,1\}^2`,

    .. math::

        A^c_{D}[Y+e_y, X+e_x] \mathrel{+}= W_e(i)\, S_o(i)\, W_f(i+o),
        \qquad D = \lfloor (p+d)/2 \rfloor + f - e ,

    where the floor and the parity :math:`(p+d) \bmod 2` select the class and
    shift of the neighbour :math:`j = i + o`.  All pixels of one parity class
    are processed at once.  The sum is taken in two steps: first, per offset
    :math:`E = \lfloor (p+d)/2 \rfloor + f` of a parent of :math:`j`
    relative to :math:`(Y, X)`, the row of :math:`AP`,
    :math:`(AP)_E(i) = \sum_{o, f} S_o(i) W_f(i+o)`; then
    :math:`A^c_{E-e}[Y+e_y, X+e_x] \mathrel{+}= W_e(i) (AP)_E(i)` for every
    parent :math:`e` of :math:`i`.  That is one product per (offset, parent
    of the neighbour) and one per (E, own parent), instead of one per
    (offset, both parents), and one work image per class at a time.
    """
    h, w = shape
    hc, wc = (h + 1) // 2, (w + 1) // 2
    radius = max(max(abs(dy), abs(dx)) for dy, dx in offsets)
    pad = (radius + 1) // 2
    slot = {d: i for i, d in enumerate(coarse_offsets)}
    separable = interp.full is None
    acc = np.zeros((len(coarse_offsets), hc + 1, wc + 1))
    padded = {}
    for ry in (0, 1):
        for rx in (0, 1):
            if ry < h and rx < w:
                padded[ry, rx] = interp.padded_cls(ry, rx, pad, separable=separable)
    for py in (0, 1):
        for px in (0, 1):
            if py >= h or px >= w:
                continue
            # the (offset, parent of the neighbour) pairs of each parent offset E of this class's rows of AP
            terms = {}
            for k, (dy, dx) in enumerate(offsets):
                qy, ry = divmod(py + dy, 2)
                qx, rx = divmod(px + dx, 2)
                if (ry, rx) not in padded:
                    continue  # the neighbour class is empty: S_k is zero here
                for fy in range(ry + 1):
                    for fx in range(rx + 1):
                        terms.setdefault((qy + fy, qx + fx), []).append((k, ry, rx, qy, qx, fy, fx))
            Ssub = source.parity_class(py, px)
            ny, nx = Ssub.shape[1:]
            ap = np.empty((ny, nx))
            tmp = np.empty((ny, nx))
            # parent (0, 0) of a class-(0, 0) pixel is the pixel itself: weight 1
            own = {(ey, ex): (None if py == px == 0 else interp.cls(ey, ex, py, px))
                   for ey in range(py + 1) for ex in range(px + 1)}
            for (Ey, Ex), pairs in terms.items():
                for n_term, (k, ry, rx, qy, qx, fy, fx) in enumerate(pairs):
                    out = ap if n_term == 0 else tmp
                    if separable:  # (ny, 1) and (1, nx) factors: no dense weight images
                        wfy, wfx = padded[ry, rx]
                        np.multiply(Ssub[k], wfy[fy, pad + qy: pad + qy + ny, None], out=out)
                        out *= wfx[fx, None, pad + qx: pad + qx + nx]
                    else:
                        wf = padded[ry, rx][fy, fx, pad + qy: pad + qy + ny, pad + qx: pad + qx + nx]
                        np.multiply(Ssub[k], wf, out=out)
                    if n_term:
                        ap += tmp
                for (ey, ex), we in own.items():
                    view = acc[slot[(Ey - ey, Ex - ex)], ey: ey + ny, ex: ex + nx]
                    if we is None:
                        view += ap
                    else:
                        np.multiply(we, ap, out=tmp)
                        view += tmp
    return acc[:, :hc, :wc]


# --------------------------------------------------------------------------
# smoothers
# --------------------------------------------------------------------------
def _gs_forward(A, x, b, sweeps):
    n = x.shape[0]
    for _ in range(sweeps):
        amg_core.gauss_seidel(A.indptr, A.indices, A.data, x, b, 0, n, 1)


def _gs_backward(A, x, b, sweeps):
    n = x.shape[0]
    for _ in range(sweeps):
        amg_core.gauss_seidel(A.indptr, A.indices, A.data, x, b, n - 1, -1, -1)


class _Level:
    """One level of the hierarchy: operator, prolongation to it from below, smoother."""

    __slots__ = ("shape", "A", "offsets", "P", "diag_inv", "omega")

    def __init__(self, shape):
        self.shape = shape
        self.A = None
        self.offsets = None
        self.P = None  # prolongation from the next coarser level
        self.diag_inv = None
        self.omega = None


# --------------------------------------------------------------------------
# the multigrid hierarchy
# --------------------------------------------------------------------------
class GridMultigrid:
    r"""Geometric multigrid hierarchy for an SPD operator on a pixel grid.

    Build once, then use as a preconditioner many times; after the weights of
    the operator change (same grid, same stencil) call :meth:`update`, which
    recomputes only the numbers.

    Parameters
    ----------
    A : scipy.sparse matrix, shape (N, N)
        Symmetric positive definite operator on a ``shape`` grid with pixels
        flattened in C order, coupling pixels at most 2 apart in each direction
        (5-, 9- or 13-point stencils).  Used as is when it is float64 CSR;
        never modified.
    shape : tuple of int
        Grid shape ``(H, W)`` with ``H * W == N``.
    interpolation : {"bilinear", "operator", "auto"}, default "bilinear"
        ``"bilinear"``: tensor product of 1-D linear interpolation, fixed per
        grid shape.  ``"operator"``: Dendy's black-box interpolation whose
        weights are read from the (collapsed) stencil; more robust when the
        weights jump across image edges.  Requires a stencil of radius 1.
        ``"auto"``: ``"operator"`` for radius-1 (5-/9-point) stencils,
        ``"bilinear"`` otherwise (6 instead of 9 PCG iterations on a 640x480
        depth-completion system, measured); :attr:`interpolation` then holds
        the choice.
    smoother : {"gauss_seidel", "jacobi"}, default "gauss_seidel"
        Gauss--Seidel uses a forward sweep before and a backward sweep after
        the coarse-grid correction; Jacobi is damped with
        :math:`\omega = 4 / (3 \rho)`, :math:`\rho` the Gershgorin bound of
        :math:`D^{-1} A`.  Both keep the V-cycle symmetric.
    sweeps : int, default 1
        Smoothing sweeps before and after the coarse-grid correction.
    max_coarse : int, default 1024
        Coarsening stops once a level has at most this many unknowns; that
        level is solved directly (sparse LU).
    max_levels : int, optional
        Upper bound on the number of levels.
    coarse_precision : {"auto", "double", "single"}, default "auto"
        Storage and smoothing precision of the coarse levels (level 1 on).
        ``"single"`` halves the coarse operators' values (8 MP, 13-point:
        ~200 MB) and perturbs the preconditioner by float32 rounding only;
        ``"auto"`` takes it when the fine level is smoothed in single
        precision or the fine grid has at least ``2**21`` pixels.
    fine_precision : {"auto", "double", "single"}, default "auto"
        Precision of the V-cycle's work on the fine level (smoothing, the
        residual, the transfers).  ``"single"`` keeps a float32 copy of the
        fine operator's values (sharing its index arrays: 4 bytes per
        non-zero), so each sweep moves fewer bytes; the operator `A` itself
        is kept as given, so the residuals of :meth:`solve` and of PCG stay
        float64 and the accuracy of a solve is unchanged (the V-cycle is
        only a preconditioner).  ``"auto"`` takes it when `A` has at most
        ``2**26`` non-zeros (a copy of at most 256 MB: a 13-point system of
        up to about 5 megapixels).

    Attributes
    ----------
    levels : list
        Per level, fine to coarse: ``shape``, operator ``A`` (CSR) and
        prolongation ``P`` to it from the next coarser level (None at the
        coarsest).
    shape : tuple of int
        Fine grid shape.
    fine_dtype, coarse_dtype : numpy.dtype
        Precision of the V-cycle on the fine level and on the coarse levels
        (see `fine_precision` and `coarse_precision`).

    Raises
    ------
    ValueError
        For an unknown option, a `shape` that does not match `A`, or an `A`
        that is not a grid operator of stencil radius at most 2.

    See Also
    --------
    solve_spd : preconditioned conjugate gradients with this preconditioner.

    Notes
    -----
    Grid :math:`l+1` keeps the pixels of grid :math:`l` with even row and
    column indices, so an :math:`n`-pixel axis becomes :math:`\lceil n/2
    \rceil` (odd and even sizes alike).  With 1-D weights :math:`W^{(1)}`
    (weight 1 at coincident points, :math:`\tfrac12, \tfrac12` between two
    coarse points, 1 for a trailing point of an even-length axis) the bilinear
    prolongation is :math:`P = W^{(1)}_y \otimes W^{(1)}_x`; it reproduces
    constants, matching the Neumann boundary.

    For ``interpolation="operator"`` the stencil is collapsed across the
    interpolation direction: a pixel between two coarse points along :math:`x`
    gets weights :math:`-\bar a_W / \bar a_C` and :math:`-\bar a_E / \bar a_C`
    with :math:`\bar a_\ast` the column sums of its 3x3 stencil
    (same along :math:`y`), and a cell-centre pixel :math:`c` gets
    :math:`P_{c,:} = -a_{cc}^{-1} \sum_{n \ne c} a_{cn} P_{n,:}` from its eight
    neighbours [1]_.

    Coarse operators are Galerkin products :math:`A_{l+1} = P_l^\top A_l P_l`
    (the 5-point stencil becomes 9-point, a 13-point one 25-point, then stay
    so).  The V-cycle applied to a residual :math:`b` is

    .. math::

        x \leftarrow S_f^{\nu}(0, b),\quad
        x \leftarrow x + P\, V_{l+1}(P^\top (b - A x)),\quad
        x \leftarrow S_b^{\nu}(x, b)

    with :math:`S_f` / :math:`S_b` forward / backward Gauss--Seidel, which are
    adjoint in the :math:`A` inner product, and an exact solve on the coarsest
    grid; hence :math:`M^{-1} = V_0` is symmetric positive definite and can
    precondition CG.

    References
    ----------
    .. [1] J. E. Dendy, "Black box multigrid", J. Comput. Phys. 48 (1982)
       366-386.
    .. [2] U. Trottenberg, C. Oosterlee, A. Schueller, *Multigrid*, Academic
       Press, 2001.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> from scipy.sparse.linalg import cg
    >>> H, W = 30, 40
    >>> d = lambda n: sp.diags([-np.ones(n), np.r_[np.ones(n - 1), 0]], [0, 1])
    >>> Dx = sp.kron(sp.eye(H), d(W)); Dy = sp.kron(d(H), sp.eye(W))
    >>> A = (1e-2 * sp.eye(H * W) + Dx.T @ Dx + Dy.T @ Dy).tocsr()
    >>> mg = GridMultigrid(A, (H, W))
    >>> x, info = cg(A, np.ones(H * W), rtol=1e-10, M=mg.aspreconditioner())
    >>> info
    0
    """

    def __init__(self, A, shape, *, interpolation="bilinear",
                 smoother="gauss_seidel", sweeps=1, max_coarse=1024,
                 max_levels=None, coarse_precision="auto", fine_precision="auto"):
        for name, value in (("coarse_precision", coarse_precision), ("fine_precision", fine_precision)):
            if value not in ("auto", "double", "single"):
                raise ValueError(f"`{name}` must be 'auto', 'double' or 'single', got {value!r}.")
        if interpolation not in _INTERPOLATIONS:
            raise ValueError(
                f"unknown interpolation {interpolation!r}; "
                f"use one of {_INTERPOLATIONS}."
            )
        if smoother not in _SMOOTHERS:
            raise ValueError(
                f"unknown smoother {smoother!r}; use one of {_SMOOTHERS}."
            )
        if int(sweeps) < 1:
            raise ValueError(f"`sweeps` must be a positive integer, got {sweeps!r}.")
        if int(max_coarse) < 1:
            raise ValueError(
                f"`max_coarse` must be a positive integer, got {max_coarse!r}."
            )
        if max_levels is not None and int(max_levels) < 1:
            raise ValueError(
                f"`max_levels` must be a positive integer or None, got {max_levels!r}."
            )
        self.requested_interpolation = interpolation
        self.interpolation = interpolation
        self.smoother = smoother
        self.sweeps = int(sweeps)
        self.max_coarse = int(max_coarse)
        self.max_levels = None if max_levels is None else int(max_levels)
        A, shape = _check_matrix(A, shape)
        self.shape = shape
        large = shape[0] * shape[1] >= _SINGLE_COARSE_PIXELS
        fine_single = fine_precision == "single" or (fine_precision == "auto" and A.nnz <= _SINGLE_FINE_VALUES)
        coarse_single = coarse_precision == "single" or (coarse_precision == "auto" and (large or fine_single))
        self.fine_dtype = np.dtype(np.float32 if fine_single else np.float64)
        self.coarse_dtype = np.dtype(np.float32 if coarse_single else np.float64)
        self._build(A)

    # ---- construction -------------------------------------------------------
    def _shapes(self):
        shapes = [self.shape]
        while True:
            h, w = shapes[-1]
            if h * w <= self.max_coarse or (h == 1 and w == 1):
                break
            if self.max_levels is not None and len(shapes) >= self.max_levels:
                break
            shapes.append(((h + 1) // 2, (w + 1) // 2))
        return shapes

    def _build(self, A):
        offsets, source = _fine_source(A, self.shape)
        wide = any(max(abs(dy), abs(dx)) > 1 for dy, dx in offsets)
        if self.requested_interpolation == "auto":
            self.interpolation = "bilinear" if wide else "operator"
        if self.interpolation == "operator" and wide:
            raise ValueError(
                "interpolation='operator' needs a stencil of radius 1 (5- or "
                "9-point); use interpolation='bilinear' for wider stencils."
            )
        shapes = self._shapes()
        levels = []
        for li, shp in enumerate(shapes):
            lvl = _Level(shp)
            if li == 0:
                lvl.A = A
            levels.append(lvl)
        # structure: offsets of the coarse operators (their CSR form is made by
        # stencil_to_csr in _numeric); P is made there too
        levels[0].offsets = offsets
        for li in range(1, len(levels)):
            levels[li].offsets = _galerkin_offsets(levels[li - 1].offsets)
        self.levels = levels
        box = [source]
        del source  # _numeric drops the fine stencil as soon as the first Galerkin product is done
        self._numeric(box)

    def _numeric(self, box, refill_p=True):
        """Numeric setup: interpolation weights, Galerkin products, smoothers, LU.

        ``box`` is a one-element list holding the fine :class:`_StencilSource`,
        emptied here so that the fine stencil is freed after the first
        Galerkin product.
        """
        source = box.pop()
        keep = self.shape[0] * self.shape[1] < _KEEP_STENCIL_PIXELS
        if keep:
            source.read_whole()
        levels = self.levels
        for li in range(len(levels) - 1):
            fine, coarse = levels[li], levels[li + 1]
            if self.interpolation == "operator":
                interp = _operator_interp(fine.offsets, source, fine.shape)
                fine.P = _ClassProlongation(interp.full, self.coarse_dtype)
            else:
                interp = _bilinear_interp(fine.shape)
                if refill_p:
                    fine.P = _SeparableProlongation(fine.shape)
            S = _galerkin(fine.offsets, source, interp, fine.shape, coarse.offsets)
            del source
            coarse.A = stencil_to_csr(coarse.offsets, S, dtype=self.coarse_dtype)
            if keep:
                source = _StencilSource(coarse.offsets, coarse.shape, array=S)
            elif full_pattern_offsets(coarse.A, coarse.shape) == coarse.offsets:
                # read back class by class: the coarse stencil array can go
                source = _StencilSource(coarse.offsets, coarse.shape, csr=coarse.A, csr_offsets=coarse.offsets)
            else:
                source = _StencilSource(coarse.offsets, coarse.shape, array=S)
            del S
        del source
        A = levels[0].A
        # the fine level's operator in the cycle's precision: a float32 copy of the values, same index arrays
        self._fine_cycle_A = A if self.fine_dtype == A.dtype else sp.csr_matrix(
            (A.data.astype(self.fine_dtype), A.indices, A.indptr), shape=A.shape)
        for lvl in levels[:-1]:
            self._setup_smoother(lvl)
        self._factor_coarsest()

    def _setup_smoother(self, lvl):
        if self.smoother != "jacobi":
            return
        A = lvl.A
        diag = A.diagonal()
        if np.any(diag <= 0):
            raise ValueError("the Jacobi smoother needs a positive diagonal.")
        absrow = np.abs(A) @ np.ones(A.shape[0])
        rho = float(np.max(absrow / diag))
        lvl.diag_inv = 1.0 / diag
        lvl.omega = 4.0 / (3.0 * rho)

    def _factor_coarsest(self):
        Ac = self.levels[-1].A
        self._pinv = None
        self._lu = None
        try:
            lu = spla.splu(sp.csc_matrix(Ac, dtype=np.float64))
            pivots = np.abs(lu.U.diagonal())
            if not pivots.min() > 1e3 * Ac.shape[0] * np.finfo(float).eps * pivots.max():
                raise RuntimeError("numerically singular")
            self._lu = lu
        except RuntimeError:
            # singular coarsest operator (e.g. pure Neumann problem): pseudo-inverse
            self._lu = None
            self._pinv = scipy.linalg.pinvh(Ac.toarray().astype(np.float64))

    def _coarse_solve(self, b):
        if self._lu is not None:
            return self._lu.solve(b)
        return self._pinv @ b

    # ---- public API ---------------------------------------------------------
    def update(self, A):
        """Recompute the hierarchy numerically for a new operator on the same grid.

        Parameters
        ----------
        A : scipy.sparse matrix, shape (N, N)
            New SPD operator on the same grid whose stencil is contained in the
            stencil of the operator this hierarchy was built for (typically the
            same sparsity pattern with new weights).

        Returns
        -------
        self : GridMultigrid

        Raises
        ------
        ValueError
            If `A` does not fit the grid.

        Notes
        -----
        Interpolation weights (for ``interpolation="operator"``), Galerkin
        coarse operators, smoother data and the coarsest factorisation are
        recomputed into the existing sparsity patterns; the grid hierarchy,
        the coarse operators' patterns and the bilinear prolongation are reused.  If the stencil
        gained offsets, the structure is rebuilt.
        """
        A, _ = _check_matrix(A, self.shape)
        offsets = self.levels[0].offsets
        pattern = full_pattern_offsets(A, self.shape)
        if pattern is not None and set(pattern) <= set(offsets):
            source = _StencilSource(offsets, self.shape, csr=A, csr_offsets=pattern)
        else:
            S = _extract_stencil(A, self.shape, offsets)
            if int(np.count_nonzero(S)) != int(np.count_nonzero(A.data)):
                # the stencil grew (a pixel and a diagonal determine at most one
                # in-grid offset, so equal non-zero counts mean nothing is missing)
                del S
                self._build(A)
                return self
            source = _StencilSource(offsets, self.shape, array=S)
            del S
        self.levels[0].A = A
        box = [source]
        del source
        self._numeric(box, refill_p=False)
        return self

    def vcycle(self, b):
        """Apply one V-cycle with zero initial guess, i.e. :math:`M^{-1} b`.

        Parameters
        ----------
        b : array_like, shape (N,)
            Right-hand side (a residual, when used as a preconditioner).

        Returns
        -------
        x : ndarray, shape (N,)
        """
        b = np.ascontiguousarray(b, dtype=self.fine_dtype).reshape(-1)
        levels = self.levels
        nu = self.sweeps
        # the operator each smoothed level is cycled with: the fine one in the cycle's precision
        cycle_ops = [self._fine_cycle_A] + [lvl.A for lvl in levels[1:-1]]
        xs, bs = [], []
        for lvl, A in zip(levels[:-1], cycle_ops):
            x = np.zeros_like(b)
            if lvl.diag_inv is None:
                _gs_forward(A, x, b, nu)
            else:
                self._jacobi(lvl, x, b, A)
            r = A @ x
            np.subtract(b, r, out=r)
            xs.append(x)
            bs.append(b)
            b = (lvl.P.T @ r).astype(self.coarse_dtype, copy=False)
            del r  # work vectors go as soon as possible: peak memory of 8-MP frames
        x = self._coarse_solve(b.astype(np.float64, copy=False)).astype(self.coarse_dtype, copy=False)
        for lvl, A, xf, bf in zip(levels[-2::-1], cycle_ops[::-1], xs[::-1], bs[::-1]):
            lvl.P.add_prolonged(xf, x)
            if lvl.diag_inv is None:
                _gs_backward(A, xf, bf, nu)
            else:
                self._jacobi(lvl, xf, bf, A)
            x = xf
        return x.astype(np.float64, copy=False)

    def _jacobi(self, lvl, x, b, A):
        """``sweeps`` damped Jacobi sweeps on ``A x = b`` (``A``: ``lvl``'s operator in the cycle's precision)."""
        for _ in range(self.sweeps):
            x += lvl.omega * lvl.diag_inv * (b - A @ x)

    def aspreconditioner(self):
        """The V-cycle as a :class:`scipy.sparse.linalg.LinearOperator`.

        Returns
        -------
        M : LinearOperator, shape (N, N)
            ``M @ r`` applies one V-cycle (symmetric positive definite), for
            the ``M=`` argument of :func:`scipy.sparse.linalg.cg`.
        """
        n = self.levels[0].A.shape[0]
        return spla.LinearOperator((n, n), matvec=self.vcycle, dtype=np.float64)

    def solve(self, b, *, x0=None, rtol=1e-8, atol=0.0, maxiter=None,
              accel="cg", callback=None):
        r"""Solve :math:`A x = b` with this hierarchy.

        Parameters
        ----------
        b : array_like, shape (N,) or (H, W)
            Right-hand side.
        x0 : array_like, optional
            Initial guess (zero by default).
        rtol, atol : float
            Stop when :math:`\|b - A x_k\|_2 \le \max(\mathrm{rtol}\,\|b\|_2,
            \mathrm{atol})`.
        maxiter : int, optional
            Maximum number of iterations (CG iterations or V-cycles); default
            ``10 * N`` for CG and 100 for plain cycling.
        accel : {"cg", None}, default "cg"
            ``"cg"``: V-cycle-preconditioned conjugate gradients; ``None``:
            stationary V-cycle iteration
            :math:`x_{k+1} = x_k + M^{-1}(b - A x_k)`.
        callback : callable, optional
            Called as ``callback(xk)`` with a copy of the iterate after each
            iteration; may raise ``StopIteration`` to stop early.

        Returns
        -------
        x : ndarray, same shape as `b`
        info : SolveInfo
            Convergence flag, iteration count, residual history.
        """
        if accel == "cg":
            return solve_spd(self.levels[0].A, b, self.shape, x0=x0, rtol=rtol,
                             atol=atol, maxiter=maxiter, preconditioner=self,
                             callback=callback)
        if accel is not None:
            raise ValueError(f"unknown accel {accel!r}; use 'cg' or None.")
        A = self.levels[0].A
        b_arr, x, bnorm = _prepare_rhs(b, x0, A.shape[0])
        maxiter = 100 if maxiter is None else int(maxiter)
        t0 = time.perf_counter()
        r = b_arr - A @ x
        res = [float(np.linalg.norm(r))]
        target = max(rtol * bnorm, atol)
        stopped = False
        while res[-1] > target and len(res) <= maxiter:
            x += self.vcycle(r)
            r = b_arr - A @ x
            res.append(float(np.linalg.norm(r)))
            if callback is not None:
                try:
                    callback(x.copy())
                except StopIteration:
                    stopped = True
                    break
        if res[-1] <= target:
            status, message = 0, "converged"
        elif stopped:
            status, message = -1, "stopped by callback"
        else:
            status, message = 1, f"no convergence in {maxiter} V-cycles"
        info = SolveInfo(converged=status == 0, status=status, message=message,
                         iterations=len(res) - 1, residuals=np.asarray(res),
                         b_norm=bnorm, rtol=rtol, atol=atol,
                         preconditioner="GridMultigrid (V-cycle iteration)",
                         setup_time=0.0, solve_time=time.perf_counter() - t0)
        return x.reshape(np.shape(b)), info

    def to_pyamg(self):
        """The same hierarchy as a :class:`pyamg.multilevel.MultilevelSolver`.

        Returns
        -------
        ml : pyamg.multilevel.MultilevelSolver
            Shares the float64 operators (no copies); float32 coarse levels
            are converted to float64, as pyamg cycles in the precision of the
            fine level, and the prolongations to CSR matrices.  Its cycle
            is therefore the float64 form of :meth:`vcycle` (equal to it for
            ``fine_precision = coarse_precision = "double"``).  Use its
            ``solve(b, accel='cg')``, ``aspreconditioner()``, ``cycle_complexity``.
        """
        from pyamg.multilevel import MultilevelSolver

        pyamg_levels = []
        for lvl in self.levels:
            L = MultilevelSolver.Level()
            L.A = lvl.A.astype(np.float64, copy=False)
            if lvl.P is not None:
                L.P = (lvl.P if sp.issparse(lvl.P) else lvl.P.tocsr()).astype(np.float64, copy=False)
                L.R = L.P.T.tocsr()
                if lvl.diag_inv is None:
                    nu = self.sweeps
                    L.presmoother = lambda A, x, b, nu=nu: _gs_forward(A, x, b, nu)
                    L.postsmoother = lambda A, x, b, nu=nu: _gs_backward(A, x, b, nu)
                else:
                    L.presmoother = L.postsmoother = (
                        lambda A, x, b, lvl=lvl: self._jacobi(lvl, x, b, A))
            pyamg_levels.append(L)
        ml = MultilevelSolver(pyamg_levels, coarse_solver=_CoarseSolve(self))
        ml.symmetric_smoothing = True  # forward GS before, backward GS after
        return ml

    # ---- reporting ----------------------------------------------------------
    def operator_complexity(self):
        """Sum over levels of non-zeros divided by the fine-level non-zeros."""
        return sum(lvl.A.nnz for lvl in self.levels) / self.levels[0].A.nnz

    def grid_complexity(self):
        """Sum over levels of unknowns divided by the fine-level unknowns."""
        n0 = self.levels[0].A.shape[0]
        return sum(lvl.A.shape[0] for lvl in self.levels) / n0

    def __repr__(self):
        total = sum(lvl.A.nnz for lvl in self.levels)
        coarse = "splu" if self._lu is not None else "pinv"
        lines = [
            f"GridMultigrid(shape={self.shape}, interpolation={self.interpolation!r}, "
            f"smoother={self.smoother!r}, sweeps={self.sweeps})",
            f"Number of Levels:     {len(self.levels)}",
            f"Operator Complexity:  {self.operator_complexity():6.3f}",
            f"Grid Complexity:      {self.grid_complexity():6.3f}",
            f"Coarse Solver:        {coarse}",
            "  level      grid     unknowns     nonzeros  stencil",
        ]
        for i, lvl in enumerate(self.levels):
            h, w = lvl.shape
            lines.append(
                f"{i:>7} {f'{h}x{w}':>9} {h * w:>12} {lvl.A.nnz:>12}  "
                f"{len(lvl.offsets):>2}-point [{100 * lvl.A.nnz / total:5.2f}%]"
            )
        return "\n".join(lines)


class _CoarseSolve:
    """Callable coarsest-grid solve for pyamg (reuses our factorisation)."""

    def __init__(self, mg):
        self._mg = mg

    def __call__(self, A, b):
        return self._mg._coarse_solve(np.asarray(b, dtype=np.float64).ravel())

    def __repr__(self):
        return "splu" if self._mg._lu is not None else "pinv"


def grid_multigrid(A, shape, **options):
    """Build a :class:`GridMultigrid` (functional spelling; same parameters)."""
    return GridMultigrid(A, shape, **options)


# --------------------------------------------------------------------------
# preconditioned conjugate gradients
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class SolveInfo:
    """Outcome of :func:`solve_spd` / :meth:`GridMultigrid.solve`.

    Attributes
    ----------
    converged : bool
        Whether the stopping rule was met.
    status : int
        0 converged, >0 iteration limit reached, <0 stopped (breakdown or by
        the callback).
    message : str
        Human-readable status.
    iterations : int
        Number of iterations performed.
    residuals : ndarray, shape (iterations + 1,)
        True residual norms :math:`\\|b - A x_k\\|_2`, starting with the initial
        residual :math:`k = 0`.
    b_norm : float
        :math:`\\|b\\|_2`.
    rtol, atol : float
        Tolerances used.
    preconditioner : str
        Which preconditioner was used.
    setup_time, solve_time : float
        Wall-clock seconds for building the preconditioner and for iterating.
    """

    converged: bool
    status: int
    message: str
    iterations: int
    residuals: np.ndarray
    b_norm: float
    rtol: float
    atol: float
    preconditioner: str
    setup_time: float
    solve_time: float

    @property
    def relative_residual(self):
        """Final :math:`\\|b - A x\\|_2 / \\|b\\|_2` (0 when :math:`b = 0`)."""
        if self.b_norm == 0:
            return float(self.residuals[-1])
        return float(self.residuals[-1] / self.b_norm)


def _prepare_rhs(b, x0, n):
    b_arr = np.asarray(b, dtype=np.float64)
    if b_arr.size != n:
        raise ValueError(
            f"`b` has {b_arr.size} entries ({b_arr.shape}) but the operator has "
            f"{n} unknowns."
        )
    b_arr = np.ascontiguousarray(b_arr.reshape(-1))
    if x0 is None:
        x = np.zeros(n)
    else:
        x = np.array(x0, dtype=np.float64).reshape(-1)
        if x.size != n:
            raise ValueError(
                f"`x0` has {x.size} entries but the operator has {n} unknowns."
            )
    return b_arr, x, float(np.linalg.norm(b_arr))


def _make_preconditioner(A, shape, preconditioner, options):
    if isinstance(preconditioner, str):
        if preconditioner not in _PRECONDITIONERS:
            raise ValueError(
                f"unknown preconditioner {preconditioner!r}; use one of "
                f"{_PRECONDITIONERS}, a GridMultigrid or a LinearOperator."
            )
        if preconditioner != "grid" and preconditioner != "amg" and \
                preconditioner != "sa" and options:
            raise TypeError(
                f"preconditioner={preconditioner!r} takes no options, got "
                f"{sorted(options)}."
            )
        if preconditioner == "grid":
            return GridMultigrid(A, shape, **options).aspreconditioner(), "grid"
        if preconditioner in ("amg", "sa"):
            import pyamg

            build = (pyamg.ruge_stuben_solver if preconditioner == "amg"
                     else pyamg.smoothed_aggregation_solver)
            return build(A, **options).aspreconditioner(cycle="V"), preconditioner
        if preconditioner == "jacobi":
            d = A.diagonal()
            if np.any(d <= 0):
                raise ValueError("the Jacobi preconditioner needs a positive diagonal.")
            dinv = 1.0 / d
            n = A.shape[0]
            return spla.LinearOperator((n, n), matvec=lambda r: dinv * r.ravel(),
                                       dtype=np.float64), "jacobi"
        return None, "none"
    if options:
        raise TypeError(
            f"options {sorted(options)} are only used when `preconditioner` is a name."
        )
    if hasattr(preconditioner, "aspreconditioner"):
        return preconditioner.aspreconditioner(), type(preconditioner).__name__
    if isinstance(preconditioner, spla.LinearOperator) or sp.issparse(preconditioner):
        return preconditioner, type(preconditioner).__name__
    raise TypeError(
        "`preconditioner` must be a name, an object with .aspreconditioner() or a "
        f"LinearOperator, got {type(preconditioner).__name__}."
    )


def solve_spd(A, b, shape, *, x0=None, rtol=1e-8, atol=0.0, maxiter=None,
              preconditioner="grid", callback=None, **options):
    r"""Solve an SPD grid system :math:`A x = b` by preconditioned CG.

    Parameters
    ----------
    A : scipy.sparse matrix, shape (N, N)
        Symmetric positive definite operator on a ``shape`` grid (C order).
    b : array_like, shape (N,) or (H, W)
        Right-hand side.
    shape : tuple of int
        Grid shape ``(H, W)``, ``H * W == N``.
    x0 : array_like, optional
        Initial guess (zero by default); never modified.
    rtol, atol : float
        Stopping rule of :func:`scipy.sparse.linalg.cg`: stop when the
        recursively updated residual satisfies
        :math:`\|r_k\|_2 \le \max(\mathrm{rtol}\,\|b\|_2, \mathrm{atol})`.
    maxiter : int, optional
        Maximum number of CG iterations; default ``10 * N`` as in SciPy.
    preconditioner : str, GridMultigrid, pyamg solver or LinearOperator
        ``"grid"`` (default): a :class:`GridMultigrid` V-cycle built from
        `A` with ``**options``; ``"amg"``: pyamg Ruge--Stueben;
        ``"sa"``: pyamg smoothed aggregation (``**options`` passed on);
        ``"jacobi"``: diagonal scaling; ``"none"``.  An already built
        hierarchy (e.g. after :meth:`GridMultigrid.update`) is used as is.
    callback : callable, optional
        ``callback(xk)`` with a copy of the iterate after each iteration; may
        raise ``StopIteration`` to stop, which the result then reports.
    **options
        Keyword options for the named multigrid preconditioner, e.g.
        ``interpolation="operator"``.

    Returns
    -------
    x : ndarray, same shape as `b`
        Approximate solution.
    info : SolveInfo
        Convergence flag and status, iteration count, true residual history
        :math:`\|b - A x_k\|_2` for :math:`k = 0, \dots, \text{iterations}`,
        setup and solve times.

    Raises
    ------
    ValueError
        Unknown preconditioner name, or `A`, `b`, `shape` that do not fit.
    TypeError
        Options given for a preconditioner that takes none.

    Notes
    -----
    The residual history is recomputed from the iterate after every CG step
    (one extra product with `A` per iteration), so it reports the true
    residual, not CG's recursively updated one.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> H, W = 20, 30
    >>> d = lambda n: sp.diags([-np.ones(n), np.r_[np.ones(n - 1), 0]], [0, 1])
    >>> Dx = sp.kron(sp.eye(H), d(W)); Dy = sp.kron(d(H), sp.eye(W))
    >>> A = (0.1 * sp.eye(H * W) + Dx.T @ Dx + Dy.T @ Dy).tocsr()
    >>> x, info = solve_spd(A, np.ones((H, W)), (H, W), rtol=1e-10)
    >>> info.converged, x.shape, bool(info.relative_residual < 1e-10)
    (True, (20, 30), True)
    """
    A, shape = _check_matrix(A, shape)
    n = A.shape[0]
    b_arr, x_init, bnorm = _prepare_rhs(b, x0, n)
    if maxiter is None:
        maxiter = 10 * n
    t0 = time.perf_counter()
    M, name = _make_preconditioner(A, shape, preconditioner, options)
    t1 = time.perf_counter()
    residuals = [float(np.linalg.norm(b_arr - A @ x_init))]
    last = {"x": None}

    def _cb(xk):
        residuals.append(float(np.linalg.norm(b_arr - A @ xk)))
        if callback is not None:
            last["x"] = xk
            callback(xk.copy())

    stopped = False
    try:
        x, status = spla.cg(A, b_arr, x0=x_init, rtol=rtol, atol=atol,
                            maxiter=maxiter, M=M, callback=_cb)
    except StopIteration:
        stopped = True
        x, status = last["x"].copy(), -1
    t2 = time.perf_counter()
    iterations = len(residuals) - 1
    if stopped:
        message = "stopped by callback"
    elif status == 0:
        message = "converged"
    elif status > 0:
        message = f"no convergence in {maxiter} iterations"
    else:
        message = "CG breakdown (operator or preconditioner not SPD?)"
    info = SolveInfo(converged=(status == 0 and not stopped), status=int(status),
                     message=message, iterations=iterations,
                     residuals=np.asarray(residuals), b_norm=bnorm, rtol=rtol,
                     atol=atol, preconditioner=name, setup_time=t1 - t0,
                     solve_time=t2 - t1)
    return x.reshape(np.shape(b)), info
