r"""Grid operators as stencil images, and their CSR form.

A *stencil* of an operator :math:`A` on an ``(H, W)`` pixel grid (pixels
flattened in C order) is a list of neighbour offsets ``(dy, dx)`` and one
coefficient image per offset::

    S[k, y, x] = A[y*W + x, (y + dy_k)*W + (x + dx_k)]      (0 outside the grid)

The normal equations of the completion objective are assembled in this form
(:meth:`~sparsedepth.grid.operators.StencilOperator.add_normal_stencil`: one
whole-array operation per pair of taps, no sparse products), converted once to
CSR for the smoothers and Krylov solvers (:func:`stencil_to_csr`), and read
back by the multigrid set-up (:func:`csr_to_stencil`) in one pass over the
non-zeros instead of one sparse diagonal extraction per offset.

The CSR layout is the *full in-grid pattern*: row ``y*W + x`` stores every
offset whose neighbour lies inside the grid, in lexicographic offset order
(= increasing column), zero coefficients included.  A matrix in that layout is
recognised exactly (its ``indptr`` and ``indices`` are compared with the
pattern), so :func:`csr_to_stencil` never guesses.

May import NumPy, SciPy, :mod:`sparsedepth._validation` and :mod:`.rowbands`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._validation import check_grid_shape
from .rowbands import row_bands, rows_per_band

__all__ = ["stencil_to_csr", "csr_to_stencil", "full_pattern_offsets", "index_dtype", "SymmetricStencil"]

#: entries per chunk of the conversions (their temporaries stay ~16 MB)
_CHUNK_ENTRIES = 1 << 21


def index_dtype(*sizes):
    """int32 when every size fits, else int64 (CSR index arrays)."""
    return np.int32 if max(sizes) < np.iinfo(np.int32).max else np.int64


def _check_offsets(offsets):
    offsets = [(int(dy), int(dx)) for dy, dx in offsets]
    if offsets != sorted(set(offsets)):
        raise ValueError(f"offsets must be distinct and sorted lexicographically, got {offsets}")
    return offsets


def _inside(offset, shape):
    """Slices of the pixels whose neighbour at ``offset`` lies inside the grid."""
    H, W = shape
    dy, dx = offset
    return slice(max(0, -dy), max(0, min(H, H - dy))), slice(max(0, -dx), max(0, min(W, W - dx)))


def _row_starts(offsets, shape, index_dtype):
    """``indptr`` of the full in-grid pattern (entries per row = offsets inside the grid)."""
    H, W = shape
    counts = np.zeros((H, W), dtype=index_dtype)
    for offset in offsets:
        counts[_inside(offset, shape)] += 1
    indptr = np.zeros(H * W + 1, dtype=index_dtype)
    np.cumsum(counts.reshape(-1), out=indptr[1:])
    return indptr


def _blocks(offsets, shape, indptr):
    """The CSR storage of the full in-grid pattern as ``(rows, columns, offsets)`` blocks.

    Image rows with the same set of in-grid vertical offsets (at most
    ``2 r + 1`` groups for a stencil of radius ``r``) have the same number
    ``L`` of entries, so their part of ``data`` is an ``(rows, L)`` array.
    Within it, the columns ``x`` whose every such offset is in the grid hold
    the same ``K_g`` offsets (a contiguous range of the sorted list), so
    their entries form one ``(rows, columns, K_g)`` block; each of the few
    border columns is a block of its own.  Yields ``(y0, y1, L, xs, ks,
    start)``: image rows ``y0:y1``, columns ``xs`` (a slice), offset indices
    ``ks`` (a slice or an index array) and the first position of the block in
    the group's rows, so that ``rows[:, start:start + nx * nk]`` reshaped to
    ``(rows, nx, nk)`` is the block.  Groups are cut into chunks of about
    ``_CHUNK_ENTRIES`` entries so that the callers' temporaries stay small.
    """
    H, W = shape
    dy = np.array([o[0] for o in offsets])
    dx = np.array([o[1] for o in offsets])
    ys = np.arange(H)[:, None] + dy[None, :]
    ok = (ys >= 0) & (ys < H)  # (H, K): vertical offsets inside the grid, per image row
    starts = np.concatenate([[0], 1 + np.flatnonzero(np.any(ok[1:] != ok[:-1], axis=1)), [H]])
    for y, y1 in zip(starts[:-1].tolist(), starts[1:].tolist()):
        rows_ok = ok[y]
        columns = np.arange(W)[:, None] + dx[None, :]
        present = rows_ok[None, :] & (columns >= 0) & (columns < W)  # (W, K)
        counts = present.sum(axis=1)
        before = np.concatenate([[0], np.cumsum(counts)[:-1]])  # first entry of column x in the row
        L = int(counts.sum())
        in_rows = np.flatnonzero(rows_ok)  # contiguous: offsets are sorted by dy first
        full = np.flatnonzero(counts == in_rows.size) if in_rows.size else np.array([], dtype=int)
        if full.size and full.size == full[-1] - full[0] + 1:
            x_lo, x_hi = int(full[0]), int(full[-1]) + 1
        else:
            x_lo = x_hi = 0
        step = max(1, _CHUNK_ENTRIES // max(L, 1))  # rows per chunk: bounded temporaries
        for c0 in range(y, y1, step):
            c1 = min(y1, c0 + step)
            if x_hi > x_lo:
                yield c0, c1, L, slice(x_lo, x_hi), slice(int(in_rows[0]), int(in_rows[-1]) + 1), int(before[x_lo])
            for x in range(W):
                if (x_lo <= x < x_hi) or counts[x] == 0:
                    continue
                yield c0, c1, L, slice(x, x + 1), np.flatnonzero(present[x]), int(before[x])


def _block_view(array, indptr, W, y0, y1, L, xs, ks, start):
    """The ``(rows, nx, nk)`` view of one block of :func:`_blocks` into ``data`` or ``indices``."""
    base = int(indptr[y0 * W])
    rows = array[base:base + (y1 - y0) * L].reshape(y1 - y0, L)
    nx = xs.stop - xs.start
    nk = len(range(*ks.indices(1 << 30))) if isinstance(ks, slice) else len(ks)
    return rows[:, start:start + nx * nk].reshape(y1 - y0, nx, nk)


def _block_columns(offsets, W, y0, y1, xs, ks, dtype):
    """Column indices of one block: ``(y + dy_k) W + x + dx_k``."""
    delta = np.array([dy * W + dx for dy, dx in offsets], dtype=dtype)[ks]
    return (np.arange(y0, y1, dtype=dtype)[:, None, None] * dtype.type(W)
            + np.arange(xs.start, xs.stop, dtype=dtype)[None, :, None] + delta[None, None, :])


def stencil_to_csr(offsets, stencil, *, dtype=np.float64):
    """CSR matrix of a stencil, in the full in-grid pattern.

    Parameters
    ----------
    offsets : list of tuple of int
        Distinct offsets ``(dy, dx)``, sorted lexicographically.
    stencil : ndarray, shape (len(offsets), H, W)
        Coefficient images; entries whose neighbour lies outside the grid are
        ignored.

    dtype : numpy dtype, default float64
        Type of the stored values (float32 for single-precision coarse levels).

    Returns
    -------
    scipy.sparse.csr_array, shape (H*W, H*W)
        Canonical (sorted, no duplicates); in-grid zero coefficients are stored.

    Examples
    --------
    >>> S = np.array([[[1.0, 1.0]], [[2.0, 2.0]], [[3.0, 3.0]]])  # 1x2 grid
    >>> stencil_to_csr([(0, -1), (0, 0), (0, 1)], S).toarray()
    array([[2., 3.],
           [1., 2.]])
    """
    offsets = _check_offsets(offsets)
    stencil = np.asarray(stencil, dtype=np.float64)
    if stencil.ndim != 3 or stencil.shape[0] != len(offsets):
        raise ValueError(f"stencil must have shape (len(offsets), H, W) = ({len(offsets)}, H, W), got {stencil.shape}")
    return _csr_from_rows(offsets, stencil.shape[1:], lambda y0, y1: stencil[:, y0:y1], np.dtype(dtype))


def _offsets_of_row(A, row, W):
    cols = A.indices[A.indptr[row]:A.indptr[row + 1]].astype(np.int64)
    delta = cols - row
    dy = (delta + W // 2) // W
    return [(int(a), int(b)) for a, b in zip(dy, delta - dy * W)]


def full_pattern_offsets(A, shape):
    """Offsets of a CSR matrix stored in the full in-grid pattern, else None.

    Parameters
    ----------
    A : scipy.sparse CSR matrix or array, shape (H*W, H*W)
    shape : tuple of int
        ``(H, W)``.

    Returns
    -------
    list of tuple of int, or None
        The offsets read from a row at the grid's centre, when ``A.indptr``
        and ``A.indices`` equal exactly the pattern :func:`stencil_to_csr`
        makes for them (checked chunk by chunk, no large temporaries);
        ``None`` otherwise (small grids whose centre row misses an offset
        included).
    """
    H, W = shape = check_grid_shape(shape)
    n = H * W
    if A.format != "csr" or A.shape != (n, n) or A.nnz == 0:
        return None
    centre = (H // 2) * W + W // 2
    offsets = _offsets_of_row(A, centre, W)
    if offsets != sorted(set(offsets)) or any(2 * abs(dx) >= W for _, dx in offsets):
        return None
    indptr = _row_starts(offsets, (H, W), np.int64)
    if not np.array_equal(A.indptr, indptr):
        return None
    for block in _blocks(offsets, (H, W), indptr):
        y0, y1, _, xs, ks, _ = block
        if not np.array_equal(_block_view(A.indices, indptr, W, *block),
                              _block_columns(offsets, W, y0, y1, xs, ks, A.indices.dtype)):
            return None
    return offsets


def csr_to_stencil(A, shape, *, offsets=None, parity=None):
    """Offsets and stencil images of a CSR matrix stored in the full in-grid pattern.

    Parameters
    ----------
    A : scipy.sparse CSR matrix or array, shape (H*W, H*W)
    shape : tuple of int
        ``(H, W)``.
    offsets : list of tuple of int, optional
        The result of :func:`full_pattern_offsets` when already checked.
    parity : tuple of int, optional
        ``(py, px)``: read only the pixels ``(py::2, px::2)`` (one parity
        class, a quarter of the memory).

    Returns
    -------
    (offsets, stencil) or None
        ``stencil`` has shape ``(len(offsets), H, W)`` (or the class's
        shape); ``None`` when ``A`` is not in the layout of
        :func:`stencil_to_csr` (see :func:`full_pattern_offsets`), in which
        case the caller extracts the stencil by other means.
    """
    H, W = shape = check_grid_shape(shape)
    if offsets is None:
        offsets = full_pattern_offsets(A, shape)
        if offsets is None:
            return None
    indptr = A.indptr
    py, px = (0, 0) if parity is None else parity
    step = 1 if parity is None else 2
    stencil = np.zeros((len(offsets), len(range(py, H, step)), len(range(px, W, step))))
    for block in _blocks(offsets, (H, W), indptr):
        y0, y1, _, xs, ks, _ = block
        view = _block_view(A.data, indptr, W, *block)
        ly = (py - y0) % step
        lx = (px - xs.start) % step
        part = view[ly::step, lx::step]
        if part.size == 0:
            continue
        r0 = (y0 + ly - py) // step
        c0 = (xs.start + lx - px) // step
        stencil[ks, r0:r0 + part.shape[0], c0:c0 + part.shape[1]] = np.moveaxis(part, -1, 0)
    return offsets, stencil


def _upper(offset):
    """True for the centre and the offsets after it in lexicographic order (the stored half)."""
    return tuple(offset) >= (0, 0)


def _pair_slices(offset, shape, rows=None):
    """Slices ``(target, source)`` of the pixels ``p`` (rows ``rows`` only) whose neighbour ``p + offset`` is inside.

    ``target`` indexes ``p``, ``source`` indexes ``p + offset`` in an ``(H, W)`` image.
    """
    H, W = shape
    dy, dx = offset
    y0, y1 = (0, H) if rows is None else rows
    ty0, ty1 = max(y0, -dy), min(y1, H - dy)
    tx0, tx1 = max(0, -dx), min(W, W - dx)
    if ty1 <= ty0 or tx1 <= tx0:
        return None
    return (slice(ty0, ty1), slice(tx0, tx1)), (slice(ty0 + dy, ty1 + dy), slice(tx0 + dx, tx1 + dx))


class SymmetricStencil:
    r"""A symmetric matrix on an ``(H, W)`` pixel grid, stored as the stencil images of half its offsets.

    For a symmetric ``A`` with stencil offsets ``O`` (closed under
    ``o → −o``), the coefficient of a lower offset ``o < (0, 0)`` at pixel
    ``p`` is that of ``−o`` at the neighbour ``p + o``:
    ``A[p, p+o] = A[p+o, p]``.  Only the centre and the offsets after it
    (lexicographically) are stored: 7 images instead of 13 for the
    13-point normal equations of the completion objective (56 bytes per
    pixel instead of 160 in float64 CSR).

    Parameters
    ----------
    offsets : list of tuple of int
        The full offset list ``O``, distinct, sorted, closed under negation,
        containing ``(0, 0)``.
    images : ndarray (len(upper), H, W) or sequence of (H, W) arrays, float32 or float64
        The images of ``upper = [o for o in O if o >= (0, 0)]``; entries
        whose neighbour lies outside the grid must be 0.  A C-contiguous
        array is kept as it is, a sequence is stacked into one.

    Attributes
    ----------
    offsets, upper : list of tuple of int
    data : ndarray, (len(upper), H, W)
        The stored images.
    images : list of ndarray
        Views of ``data``, one per offset of ``upper``.
    grid_shape : tuple of int
    shape : tuple of int
        ``(H W, H W)``.
    dtype : numpy.dtype
    nnz : int
        Entries of the full in-grid pattern (what :meth:`tocsr` stores).

    Notes
    -----
    ``A @ x`` runs over bands of image rows (a few hundred kilobytes each,
    so the partial sums stay in cache); within a band each offset is one
    multiply and one add of image slices, in the order of ``O``.  That is the
    order in which a CSR product sums a row of :meth:`tocsr`, so the two
    products agree to the last bit (no fused multiply-add in either).
    """

    format = "stencil"
    ndim = 2

    def __init__(self, offsets, images):
        offsets = _check_offsets(offsets)
        if (0, 0) not in offsets or sorted((-dy, -dx) for dy, dx in offsets) != offsets:
            raise ValueError(f"offsets must contain (0, 0) and be closed under negation, got {offsets}")
        upper = [o for o in offsets if _upper(o)]
        if not isinstance(images, np.ndarray):
            images = [np.asarray(image) for image in images]
            if len({(im.shape, im.dtype) for im in images}) > 1:
                raise ValueError(f"images must be (H, W) arrays of one shape and type, got "
                                 f"{[(im.shape, str(im.dtype)) for im in images]}")
            images = np.stack(images) if images else np.zeros((0, 0, 0))
        if images.ndim != 3 or images.shape[0] != len(upper):
            raise ValueError(f"images must be {len(upper)} (H, W) arrays (one per offset >= (0, 0)), got shape "
                             f"{images.shape}")
        if images.dtype not in (np.float32, np.float64):
            raise TypeError(f"images must be float32 or float64, got {images.dtype}")
        self.offsets = offsets
        self.upper = upper
        self.data = np.ascontiguousarray(images)
        self.images = list(self.data)
        self.grid_shape = tuple(images.shape[1:])
        n = self.grid_shape[0] * self.grid_shape[1]
        self.shape = (n, n)
        self.dtype = images.dtype
        self._slot = {o: k for k, o in enumerate(upper)}
        self._band = rows_per_band(self.grid_shape[1], 1 << 16)  # rows per band of the product

    @classmethod
    def from_stencil(cls, offsets, stencil, *, dtype=np.float64, copy=True):
        """The symmetric form of a full stencil, or None when it is not exactly symmetric.

        Parameters
        ----------
        offsets : list of tuple of int
            Distinct, sorted offsets.
        stencil : ndarray (len(offsets), H, W) or list of (H, W) arrays
            One image per offset (see :func:`stencil_to_csr`).
        dtype : numpy dtype, default float64
        copy : bool, default True
            False: ``stencil`` is a list of images that this call consumes:
            each entry is set to None once read, so that the list's images
            are freed one by one while the stored ones are written (the
            peak stays that of the full stencil).

        Returns
        -------
        SymmetricStencil or None
            None when an offset's negation is missing or a lower coefficient
            differs (in any bit, once cast to ``dtype``) from the mirrored
            upper one, i.e. the matrix is not exactly symmetric in ``dtype``;
            then only the CSR form represents it.
        """
        offsets = _check_offsets(offsets)
        shape = tuple(np.shape(stencil[0]))
        if any((-dy, -dx) not in offsets for dy, dx in offsets) or (0, 0) not in offsets:
            return None
        for k, o in enumerate(offsets):
            if _upper(o):
                continue
            pair = _pair_slices(o, shape)
            mirror = stencil[offsets.index((-o[0], -o[1]))]
            if pair is not None and not np.array_equal(stencil[k][pair[0]].astype(dtype, copy=False),
                                                       mirror[pair[1]].astype(dtype, copy=False)):
                return None
        consume = not copy and isinstance(stencil, list)
        if consume:
            for k, o in enumerate(offsets):
                if not _upper(o):
                    stencil[k] = None
        upper = [o for o in offsets if _upper(o)]
        images = np.empty((len(upper),) + shape, dtype=dtype)  # pages are touched as the images are written
        for j, o in enumerate(upper):
            k = offsets.index(o)
            pair = _pair_slices(o, shape)
            images[j] = 0
            if pair is not None:
                images[j][pair[0]] = stencil[k][pair[0]]
            if consume:
                stencil[k] = None
        return cls(offsets, images)

    @property
    def nnz(self):
        H, W = self.grid_shape
        return sum(max(0, H - abs(dy)) * max(0, W - abs(dx)) for dy, dx in self.offsets)

    @property
    def T(self):
        """The matrix itself (it is symmetric)."""
        return self

    def coefficients(self, offset, target):
        """Coefficients of ``offset`` on the pixels of ``target`` (a ``(rows, columns)`` slice pair, all inside)."""
        if _upper(offset):
            return self.images[self._slot[offset]][target]
        dy, dx = offset
        ys, xs = target
        return self.images[self._slot[(-dy, -dx)]][ys.start + dy:ys.stop + dy, xs.start + dx:xs.stop + dx]

    def full_rows(self, y0, y1, out=None):
        """The full stencil on image rows ``y0:y1``, shape ``(len(offsets), y1 − y0, W)`` (0 outside the grid)."""
        W = self.grid_shape[1]
        if out is None:
            out = np.zeros((len(self.offsets), y1 - y0, W), dtype=self.dtype)
        else:
            out[...] = 0
        for k, o in enumerate(self.offsets):
            pair = _pair_slices(o, self.grid_shape, (y0, y1))
            if pair is not None:
                (ys, xs), _ = pair
                out[k, ys.start - y0:ys.stop - y0, xs] = self.coefficients(o, (ys, xs))
        return out

    def parity_class(self, py, px):
        """The full stencil on the pixels ``(py::2, px::2)``, shape ``(len(offsets), ny, nx)``; all pixels for None."""
        if py is None:
            return self.full_rows(0, self.grid_shape[0])
        H, W = self.grid_shape
        ny, nx = len(range(py, H, 2)), len(range(px, W, 2))
        out = np.zeros((len(self.offsets), ny, nx), dtype=self.dtype)
        for k, offset in enumerate(self.offsets):
            self.class_image(offset, py, px, out=out[k])
        return out

    def class_image(self, offset, py, px, out=None):
        """Coefficients of ``offset`` on the pixels ``(py::2, px::2)`` (0 where the neighbour is outside).

        Without ``out``, a view of the stored image for an offset ``>= (0, 0)`` (no copy: its entries outside
        the grid are 0), else a new array.
        """
        H, W = self.grid_shape
        dy, dx = offset
        if out is None and _upper(offset):
            return self.images[self._slot[offset]][py::2, px::2]
        if out is None:
            out = np.zeros((len(range(py, H, 2)), len(range(px, W, 2))), dtype=self.dtype)
        iy = _class_range(py, H, dy)
        ix = _class_range(px, W, dx)
        if iy is None or ix is None:
            return out
        ys = slice(py + 2 * iy.start, py + 2 * (iy.stop - 1) + 1, 2)
        xs = slice(px + 2 * ix.start, px + 2 * (ix.stop - 1) + 1, 2)
        if _upper(offset):
            out[iy, ix] = self.images[self._slot[offset]][ys, xs]
        else:
            src = self.images[self._slot[(-dy, -dx)]]
            out[iy, ix] = src[ys.start + dy:ys.stop + dy:2, xs.start + dx:xs.stop + dx:2]
        return out

    def diagonal(self):
        """The main diagonal as a new ``(H W,)`` array."""
        return self.images[self._slot[(0, 0)]].reshape(-1).copy()

    def matvec(self, x, out=None):
        """``A x`` for a vector of ``H W`` values (in the precision of ``x`` and the images combined)."""
        img = self._as_image(x)
        H, W = self.grid_shape
        dtype = np.result_type(self.dtype, img.dtype)
        y = np.zeros(H * W, dtype=dtype) if out is None else out
        res = y.reshape(H, W)
        if out is not None:
            res[...] = 0
        tmp = np.empty((min(self._band, H), W), dtype=dtype)
        for rows in row_bands(0, H, self._band):
            self._add_rows_product(img, rows.start, rows.stop, res[rows], tmp)
        return y

    def matvec_rows(self, x, y0, y1):
        """Image rows ``y0:y1`` of ``A x``, shape ``(y1 − y0, W)`` (the same numbers as those rows of :meth:`matvec`)."""
        img = self._as_image(x)
        W = self.grid_shape[1]
        dtype = np.result_type(self.dtype, img.dtype)
        out = np.zeros((y1 - y0, W), dtype=dtype)
        tmp = np.empty((min(self._band, y1 - y0), W), dtype=dtype)
        for rows in row_bands(y0, y1, self._band):
            self._add_rows_product(img, rows.start, rows.stop, out[rows.start - y0:rows.stop - y0], tmp)
        return out

    def _as_image(self, x):
        x = np.asarray(x)
        if x.ndim != 1 or x.shape[0] != self.shape[1]:
            raise ValueError(f"expected a vector of length {self.shape[1]} (grid {self.grid_shape}), got shape "
                             f"{x.shape}")
        return x.reshape(self.grid_shape)

    def _add_rows_product(self, img, y0, y1, rows, tmp):
        """``rows += (A x)[y0:y1]`` (``rows`` the ``(y1 − y0, W)`` result rows), one offset after the other."""
        for o in self.offsets:
            pair = _pair_slices(o, self.grid_shape, (y0, y1))
            if pair is None:
                continue
            target, source = pair
            t = tmp[:target[0].stop - target[0].start, :target[1].stop - target[1].start]
            np.multiply(self.coefficients(o, target), img[source], out=t)
            rows[target[0].start - y0:target[0].stop - y0, target[1]] += t

    def __matmul__(self, x):
        if np.ndim(x) == 2 and np.shape(x)[1] == 1:
            return self.matvec(np.ravel(x)).reshape(-1, 1)
        return self.matvec(x)

    @property
    def nbytes(self):
        """Bytes of the stored images."""
        return self.data.nbytes

    def astype(self, dtype, copy=True):
        """The same matrix with images of ``dtype``."""
        if np.dtype(dtype) == self.dtype and not copy:
            return self
        return SymmetricStencil(self.offsets, self.data.astype(dtype))

    def tocsr(self, dtype=None):
        """The CSR form in the full in-grid pattern of :func:`stencil_to_csr` (built a band of rows at a time)."""
        return _csr_from_rows(self.offsets, self.grid_shape, self.full_rows,
                              np.dtype(self.dtype if dtype is None else dtype))

    def toarray(self):
        return self.tocsr().toarray()

    def __repr__(self):
        return (f"SymmetricStencil(grid_shape={self.grid_shape}, offsets={len(self.offsets)} "
                f"({len(self.upper)} stored), dtype={self.dtype})")


def _class_range(p, n, d):
    """Indices ``i`` of the parity class ``p, p+2, …`` of an ``n``-long axis with ``0 <= p + 2 i + d < n``."""
    lo = max(0, (1 - p - d) // 2)
    hi = min(len(range(p, n, 2)), (n - 1 - p - d) // 2 + 1)
    return slice(lo, hi) if hi > lo else None


def _csr_from_rows(offsets, shape, rows_of, dtype):
    """CSR (full in-grid pattern) of a stencil given as ``rows_of(y0, y1) -> (K, y1 − y0, W)`` chunks."""
    H, W = shape
    n = H * W
    K = len(offsets)
    indptr = _row_starts(offsets, (H, W), index_dtype(n * K))
    nnz = int(indptr[-1])
    data = np.empty(nnz, dtype=dtype)
    indices = np.empty(nnz, dtype=indptr.dtype)
    cached = (None, None)
    for block in _blocks(offsets, (H, W), indptr):
        y0, y1, _, xs, ks, _ = block
        if cached[0] != (y0, y1):
            cached = ((y0, y1), rows_of(y0, y1))
        _block_view(data, indptr, W, *block)[...] = np.moveaxis(cached[1][ks, :, xs], 0, -1)
        _block_view(indices, indptr, W, *block)[...] = _block_columns(offsets, W, y0, y1, xs, ks, indices.dtype)
    out = sp.csr_array((data, indices, indptr), shape=(n, n))
    out.has_sorted_indices = True
    out.has_canonical_format = True
    return out
