r"""Grid operators as stencil images, and their CSR form.

A *stencil* of an operator :math:`A` on an ``(H, W)`` pixel grid (pixels
flattened in C order) is a list of neighbour offsets ``(dy, dx)`` and one
coefficient image per offset::

    S[k, y, x] = A[y*W + x, (y + dy_k)*W + (x + dx_k)]      (0 outside the grid)

The normal equations of the completion objective are assembled in this form
(:meth:`~sparsedepth.grid.operators.StencilOperator.add_normal_stencil`: one
whole-array operation per pair of taps, no sparse products), converted once to
CSR for the smoothers and Krylov solvers (:func:`stencil_to_csr`), and read
back by the multigrid set-up (:func:`csr_to_stencil`, or a band of rows at a
time with :meth:`FullPattern.read_rows`) by position, without one sparse
diagonal extraction per offset.

The CSR layout is the *full in-grid pattern* (:class:`FullPattern`): row
``y*W + x`` stores every offset whose neighbour lies inside the grid, in
lexicographic offset order (= increasing column), zero coefficients included.
A matrix in that layout is recognised exactly (its ``indptr`` and ``indices``
are compared with the pattern, :func:`full_pattern_offsets`), so
:func:`csr_to_stencil` never guesses.

May import NumPy, SciPy, :mod:`sparsedepth._validation` and :mod:`.rowbands`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._validation import check_grid_shape
from .rowbands import row_bands, rows_per_band

__all__ = ["stencil_to_csr", "csr_to_stencil", "full_pattern_offsets", "FullPattern", "index_dtype",
           "SymmetricStencil"]

#: entries per band of rows of the pattern's scatters and checks (their temporaries stay ~16 MB)
_CHUNK_ENTRIES = 1 << 21
#: entries per band of the inner block's copies and column indices (a few hundred kilobytes: they stay in cache)
_CACHE_ENTRIES = 1 << 16


def index_dtype(*sizes):
    """int32 when every size fits, else int64 (CSR index arrays)."""
    return np.int32 if max(sizes) < np.iinfo(np.int32).max else np.int64


def _check_offsets(offsets):
    offsets = [(int(dy), int(dx)) for dy, dx in offsets]
    if offsets != sorted(set(offsets)):
        raise ValueError(f"offsets must be distinct and sorted lexicographically, got {offsets}")
    return offsets


def _indices_between(axis, lo, hi):
    """``(a, b)``: the positions ``i`` of ``axis`` (a range) with ``lo <= axis[i] < hi`` are ``a:b``."""
    start, step = axis.start, axis.step
    a = max(0, -(-(lo - start) // step))
    b = min(len(axis), -(-(hi - start) // step))
    return a, max(a, b)


class FullPattern:
    r"""The full in-grid pattern of a stencil's offsets on a grid: where its CSR form stores each entry.

    Parameters
    ----------
    offsets : list of tuple of int
        Distinct offsets ``(dy, dx)``, sorted lexicographically.
    shape : tuple of int
        The grid ``(H, W)``.

    Attributes
    ----------
    offsets : list of tuple of int
    shape : tuple of int
    inner : tuple of int
        ``(y0, y1, x0, x1)``: the pixels ``y0 <= y < y1``, ``x0 <= x < x1``
        have every offset inside the grid (none when ``y1 <= y0`` or
        ``x1 <= x0``).

    Notes
    -----
    Row :math:`p = yW + x` of the pattern stores, for each offset
    :math:`k` whose neighbour is inside the grid, the column
    :math:`(y + d_{y,k}) W + x + d_{x,k}`, in the order of `offsets`.  Two
    in-grid neighbours of one pixel differ by less than :math:`W` in
    :math:`x`, so that order is the order of the columns (canonical CSR).

    The inner pixels hold all :math:`K` offsets, and every inner row of the
    image holds the same number :math:`L` of entries with the inner block at
    the same place, so the inner block's entries are a
    ``(y1 − y0, x1 − x0, K)`` view of the CSR arrays (rows of :math:`L`
    entries, less the ``first`` ones of the border columns ``x < x0``).  The
    few border pixels (the rows above and below, the columns on either
    side) are handled by scatters and gathers, a band of image rows at a
    time; each of their entries sits at ``indptr[p]`` plus the number of
    in-grid offsets before it.
    """

    def __init__(self, offsets, shape):
        self.offsets = _check_offsets(offsets)
        H, W = self.shape = (int(shape[0]), int(shape[1]))
        dys = np.array([dy for dy, _ in self.offsets], dtype=np.int64)
        dxs = np.array([dx for _, dx in self.offsets], dtype=np.int64)
        self._delta = dys * W + dxs  # column minus row of each offset's entries
        ys, xs = np.arange(H)[:, None] + dys, np.arange(W)[:, None] + dxs
        self._rows_in = (ys >= 0) & (ys < H)  # (H, K): the offsets' rows inside the grid, per image row
        self._columns_in = (xs >= 0) & (xs < W)  # (W, K)
        if self.offsets:
            self.inner = (max(0, -int(dys.min())), H - max(0, int(dys.max())),
                          max(0, -int(dxs.min())), W - max(0, int(dxs.max())))
        else:
            self.inner = (0, 0, 0, 0)
        self._inner_row_length = int(self._columns_in.sum())  # entries of an image row with every dy inside
        self._inner_first = int(self._columns_in[:self.inner[2]].sum())  # of them, before the inner block

    @classmethod
    def of_matrix(cls, A, shape):
        """The full in-grid pattern a CSR matrix ``A`` on an ``(H, W)`` grid is stored in, else None.

        The check of :func:`full_pattern_offsets`, returning the pattern
        itself: that of the offsets read from the row of the grid's centre,
        when ``A.indptr`` and ``A.indices`` are exactly that pattern's (every
        index compared, a band of rows at a time); None otherwise (small
        grids whose centre row misses an offset included, see
        :attr:`recognisable`).
        """
        H, W = shape = check_grid_shape(shape)
        n = H * W
        if A.format != "csr" or A.shape != (n, n) or A.nnz == 0:
            return None
        indptr, indices = A.indptr, A.indices
        centre = (H // 2) * W + W // 2
        delta = indices[indptr[centre]:indptr[centre + 1]].astype(np.int64) - centre
        dys = (delta + W // 2) // W
        dxs = delta - dys * W
        offsets = list(zip(dys.tolist(), dxs.tolist()))
        if not offsets or offsets != sorted(set(offsets)) or np.any(2 * np.abs(dxs) >= W):
            return None
        pattern = cls(offsets, shape)
        if not np.array_equal(indptr, pattern.indptr(np.int64)):
            return None
        y0, y1, x0, x1 = pattern.inner
        if y1 > y0 and x1 > x0:
            columns = pattern._inner_view(indices, indptr)
            band = min(y1 - y0, pattern._inner_band_rows())
            # the first band's columns, in the index type (they are columns of the matrix: below N)
            first = pattern._inner_columns(y0, y0 + band, out=np.empty((band, x1 - x0, len(offsets)), indices.dtype))
            shifted = np.empty_like(first)
            for r0 in range(0, y1 - y0, band):
                r1 = min(y1 - y0, r0 + band)
                part = shifted[:r1 - r0]
                np.subtract(columns[r0:r1], indices.dtype.type(r0 * W), out=part)  # a band less its shift
                if not np.array_equal(part, first[:r1 - r0]):
                    return None
        for rows in row_bands(0, H, pattern._chunk_rows()):
            position, k, pixel = pattern._border_entries(indptr, rows.start, rows.stop)
            if not np.array_equal(indices[position], pixel + pattern._delta[k]):
                return None
        return pattern

    @property
    def recognisable(self):
        """True when :meth:`of_matrix` recognises a matrix in this pattern as such.

        That is when the grid's centre pixel has every offset inside the grid
        with ``2 |dx| < W``: the offsets are read from its row.
        """
        H, W = self.shape
        cy, cx = H // 2, W // 2
        return all(0 <= cy + dy < H and 0 <= cx + dx < W and 2 * abs(dx) < W for dy, dx in self.offsets)

    def indptr(self, dtype):
        """The row pointers, an ``(H W + 1,)`` array of ``dtype``."""
        H, W = self.shape
        # entries of pixel (y, x): the offsets inside in both directions, a sum of at most K ones
        counts = (self._rows_in.astype(np.float64) @ self._columns_in.T.astype(np.float64)).astype(dtype)
        indptr = np.zeros(H * W + 1, dtype=dtype)
        np.cumsum(counts.reshape(-1), out=indptr[1:])
        return indptr

    def to_csr(self, rows_of, dtype, rows_per_read=None):
        """The CSR matrix of a stencil handed out a band of rows at a time.

        Parameters
        ----------
        rows_of : callable
            ``rows_of(y0, y1)`` returns the stencil on the image rows
            ``y0:y1``, a ``(K, y1 − y0, W)`` array (entries whose neighbour is
            outside the grid are not read).
        dtype : numpy dtype
            Type of the stored values (each value is cast once, from the
            type ``rows_of`` hands out).
        rows_per_read : int, optional
            Rows per call of ``rows_of``; by default about ``2**21`` entries'
            worth (the border scatters' temporaries stay ~16 MB).

        Returns
        -------
        scipy.sparse.csr_array, shape (H*W, H*W)
            Canonical; index arrays int32 unless ``H W K`` needs int64.
        """
        H, W = self.shape
        n, K = H * W, len(self.offsets)
        indptr = self.indptr(index_dtype(n * K))
        nnz = int(indptr[-1])
        data = np.empty(nnz, dtype=dtype)
        indices = np.empty(nnz, dtype=indptr.dtype)
        iy0, iy1, ix0, ix1 = self.inner
        values = None
        if iy1 > iy0 and ix1 > ix0:
            values, columns = self._inner_view(data, indptr), self._inner_view(indices, indptr)
            band = self._inner_band_rows()
            for r0 in range(iy0, iy1, band):
                r1 = min(iy1, r0 + band)
                self._inner_columns(r0, r1, out=columns[r0 - iy0:r1 - iy0])
        for rows in row_bands(0, H, self._chunk_rows() if rows_per_read is None else rows_per_read):
            y0, y1 = rows.start, rows.stop
            stencil = rows_of(y0, y1)
            a, b = max(y0, iy0), min(y1, iy1)
            if values is not None and b > a:
                values[a - iy0:b - iy0] = np.moveaxis(stencil[:, a - y0:b - y0, ix0:ix1], 0, -1)
            position, k, pixel = self._border_entries(indptr, y0, y1)
            data[position] = stencil[k, pixel // W - y0, pixel % W]
            indices[position] = pixel + self._delta[k]
        out = sp.csr_array((data, indices, indptr), shape=(n, n))
        out.has_sorted_indices = True
        out.has_canonical_format = True
        return out

    def read_rows(self, A, y0, y1):
        """The stencil images of a matrix in this pattern on the image rows ``y0:y1``.

        Parameters
        ----------
        A : scipy.sparse CSR matrix or array
            Stored in this pattern (as :meth:`of_matrix` checks it or
            :meth:`to_csr` makes it): the values are read by position, the
            indices are not looked at.
        y0, y1 : int
            First image row and one past the last.

        Returns
        -------
        ndarray, shape (K, y1 − y0, W), float64
            Zero where the neighbour is outside the grid.
        """
        return self._read(A, range(y0, y1), range(0, self.shape[1]))

    def read_class(self, A, py, px):
        """:meth:`read_rows` for the pixels ``(py::2, px::2)`` only: shape ``(K, ny, nx)``."""
        H, W = self.shape
        return self._read(A, range(py, H, 2), range(px, W, 2))

    def _read(self, A, ys, xs):
        """The images on the pixels ``ys × xs`` (two ranges of one step), float64."""
        H, W = self.shape
        K = len(self.offsets)
        out = np.empty((K, len(ys), len(xs)))
        iy0, iy1, ix0, ix1 = self.inner
        ra, rb = _indices_between(ys, iy0, iy1)
        ca, cb = _indices_between(xs, ix0, ix1)
        # zero outside the inner block (the border pixels' entries outside the grid stay so)
        out[:, :ra] = 0.0
        out[:, rb:] = 0.0
        out[:, ra:rb, :ca] = 0.0
        out[:, ra:rb, cb:] = 0.0
        if rb > ra and cb > ca:
            step = ys.step
            values = self._inner_view(A.data, A.indptr)[ys[ra] - iy0:ys[rb - 1] - iy0 + 1:step,
                                                         xs[ca] - ix0:xs[cb - 1] - ix0 + 1:step]
            band = max(1, _CACHE_ENTRIES // ((cb - ca) * K))
            for r0 in range(0, rb - ra, band):  # transposed a few hundred kilobytes at a time
                r1 = min(rb - ra, r0 + band)
                out[:, ra + r0:ra + r1, ca:cb] = values[r0:r1].transpose(2, 0, 1)
        for rows in row_bands(ys.start, ys.stop, self._chunk_rows()):
            position, k, pixel = self._border_entries(A.indptr, rows.start, rows.stop)
            y, x = np.divmod(pixel, W)
            if ys.step > 1:
                mine = ((y - ys.start) % ys.step == 0) & ((x - xs.start) % xs.step == 0)
                position, k, y, x = position[mine], k[mine], y[mine], x[mine]
            out[k, (y - ys.start) // ys.step, (x - xs.start) // xs.step] = A.data[position]
        return out

    def _inner_view(self, array, indptr):
        """The ``(y1 − y0, x1 − x0, K)`` view of the inner block's entries in ``array`` (CSR values or indices)."""
        y0, y1, x0, x1 = self.inner
        W = self.shape[1]
        begin = int(indptr[y0 * W])
        length, first = self._inner_row_length, self._inner_first
        K = len(self.offsets)
        return (array[begin:begin + (y1 - y0) * length].reshape(y1 - y0, length)[:, first:first + (x1 - x0) * K]
                .reshape(y1 - y0, x1 - x0, K))

    def _inner_band_rows(self):
        """Image rows per band of the inner block's copies (about ``_CACHE_ENTRIES`` entries)."""
        return rows_per_band((self.inner[3] - self.inner[2]) * len(self.offsets), _CACHE_ENTRIES)

    def _chunk_rows(self):
        """Image rows per band of the border scatters and gathers (about ``_CHUNK_ENTRIES`` entries)."""
        return rows_per_band(self.shape[1] * max(1, len(self.offsets)), _CHUNK_ENTRIES)

    def _inner_columns(self, y0, y1, out):
        """``out[...] =`` the column indices ``(y + dy_k) W + x + dx_k`` of the inner pixels of rows ``y0:y1``.

        ``out`` is a ``(y1 − y0, x1 − x0, K)`` integer array; returns it.
        """
        _, _, x0, x1 = self.inner
        dtype = out.dtype
        own = np.arange(x0, x1, dtype=dtype)[None, :, None] + self._delta.astype(dtype)
        return np.add(own, (np.arange(y0, y1, dtype=dtype) * dtype.type(self.shape[1]))[:, None, None], out=out)

    def _border_entries(self, indptr, y0, y1):
        """The entries of the pixels of rows ``y0:y1`` outside the inner block: ``(position, k, pixel)`` of each."""
        H, W = self.shape
        iy0, iy1, ix0, ix1 = self.inner
        if iy1 > iy0 and ix1 > ix0:  # the rows above, the side columns of the inner rows, the rows below
            a, b = max(y0, iy0), min(y1, iy1)
            sides = np.concatenate([np.arange(ix0), np.arange(ix1, W)])
            border = np.concatenate([np.arange(y0 * W, max(y0, min(y1, iy0)) * W),
                                     (np.arange(a, max(a, b))[:, None] * W + sides).reshape(-1),
                                     np.arange(max(y0, iy1) * W, y1 * W)])
        else:
            border = np.arange(y0 * W, y1 * W)
        by, bx = np.divmod(border, W)
        inside = self._rows_in[by] & self._columns_in[bx]
        position = indptr[border].astype(np.int64)[:, None] + np.cumsum(inside, axis=1) - 1
        which, k = np.nonzero(inside)
        return position[which, k], k, border[which]


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

    Notes
    -----
    The layout is that of :class:`FullPattern` (:meth:`FullPattern.to_csr`):
    the inner pixels' values are the images copied one by one into a
    ``(rows, columns, K)`` view of ``data``, their column indices
    :math:`(y + d_y) W + x + d_x` are written a band of rows at a time, and
    the border pixels' entries are scattered.  Floating-point images are
    cast to `dtype` directly, others through float64.

    Examples
    --------
    >>> S = np.array([[[1.0, 1.0]], [[2.0, 2.0]], [[3.0, 3.0]]])  # 1x2 grid
    >>> stencil_to_csr([(0, -1), (0, 0), (0, 1)], S).toarray()
    array([[2., 3.],
           [1., 2.]])
    """
    offsets = _check_offsets(offsets)
    stencil = np.asarray(stencil)
    if stencil.dtype not in (np.float16, np.float32, np.float64):  # these widen to float64 exactly
        stencil = stencil.astype(np.float64)
    if stencil.ndim != 3 or stencil.shape[0] != len(offsets):
        raise ValueError(f"stencil must have shape (len(offsets), H, W) = ({len(offsets)}, H, W), got {stencil.shape}")
    return FullPattern(offsets, stencil.shape[1:]).to_csr(lambda y0, y1: stencil[:, y0:y1], np.dtype(dtype))


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
        makes for them (checked a band of rows at a time, no large
        temporaries: :meth:`FullPattern.of_matrix`); ``None`` otherwise
        (small grids whose centre row misses an offset included).
    """
    pattern = FullPattern.of_matrix(A, shape)
    return None if pattern is None else pattern.offsets


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
        shape), float64; ``None`` when ``A`` is not in the layout of
        :func:`stencil_to_csr` (see :func:`full_pattern_offsets`), in which
        case the caller extracts the stencil by other means.
    """
    shape = check_grid_shape(shape)
    pattern = FullPattern.of_matrix(A, shape) if offsets is None else FullPattern(offsets, shape)
    if pattern is None:
        return None
    stencil = pattern.read_rows(A, 0, shape[0]) if parity is None else pattern.read_class(A, *parity)
    return pattern.offsets, stencil


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
        return FullPattern(self.offsets, self.grid_shape).to_csr(self.full_rows,
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
