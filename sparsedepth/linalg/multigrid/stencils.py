"""Stencils of grid operators: one coefficient image per neighbour offset, read from a CSR matrix.

The multigrid set-up works on stencils, never on general sparse products;
this module reads them from an operator (:func:`grid_stencil`) and hands a
level's stencil to the set-up one parity class at a time
(:class:`StencilSource`).  May import :mod:`sparsedepth.grid` and
:mod:`sparsedepth._validation`, NumPy and SciPy.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..._validation import as_grid_operator
from ...grid.stencil import SymmetricStencil, csr_to_stencil, full_pattern_offsets, index_dtype

__all__ = ["grid_stencil", "extract_stencil", "StencilSource", "CollapsedSource", "fine_stencil_source",
           "mirrored_image", "read_full_pattern", "assemble_csr", "centre_row_holds"]


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


def extract_stencil(A, shape, offsets):
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
    agree -- an exact integer check, which rounding cannot upset (a
    floating-point comparison of norms can, on grids as small as 640x480).

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> A = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(4, 4))
    >>> offsets, S = grid_stencil(A, (1, 4))
    >>> offsets
    [(0, -1), (0, 0), (0, 1)]
    """
    A, shape = as_grid_operator(A, shape)
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
    full ``(2r+1)² H W``.
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


def mirrored_image(image, offset, out=None):
    r"""The image of the offset :math:`-o` of a symmetric operator from the image of :math:`o`.

    Parameters
    ----------
    image : ndarray, shape (H, W)
        Coefficients :math:`a_o(p) = A_{p, p+o}`, zero where :math:`p + o` is outside the grid.
    offset : tuple of int
        :math:`o = (d_y, d_x)`.
    out : ndarray, shape (H, W), optional
        Receives the result (float64 unless given).

    Returns
    -------
    ndarray, shape (H, W)
        :math:`a_{-o}(p) = A_{p, p-o} = A_{p-o, p} = a_o(p - o)` where :math:`p - o` is inside the grid, else 0.
    """
    dy, dx = offset
    h, w = image.shape
    if out is None:
        out = np.zeros((h, w))
    else:
        out[...] = 0.0
    ty, tx = slice(max(0, dy), min(h, h + dy)), slice(max(0, dx), min(w, w + dx))
    if ty.start < ty.stop and tx.start < tx.stop:
        out[ty, tx] = image[ty.start - dy:ty.stop - dy, tx.start - dx:tx.stop - dx]
    return out


class StencilSource:
    """A level's stencil for the numeric set-up, handed out one parity class at a time.

    Either an array ``(K, H, W)`` (coarse levels, or a fine operator whose
    stencil had to be extracted diagonal by diagonal) or a CSR matrix in the
    full in-grid pattern of :func:`~sparsedepth.grid.stencil.stencil_to_csr`, read
    class by class so that the fine stencil is never held whole (a quarter
    of its pixels at a time).  Grids below
    ``keep_stencil_pixels`` (:class:`~sparsedepth.limits.MemoryLimits`) read it whole once (:meth:`read_whole`).
    """

    def __init__(self, offsets, shape, *, array=None, csr=None, csr_offsets=None, symmetric=None):
        self.offsets = list(offsets)
        self.shape = tuple(shape)
        self.array = array
        self.csr = csr
        self.csr_offsets = None if csr_offsets is None else list(csr_offsets)
        self.symmetric = symmetric  # a SymmetricStencil, read class by class like a CSR source
        if symmetric is not None:
            self.csr_offsets = list(symmetric.offsets)

    def parity_class(self, py, px):
        """Stencil images on the pixels ``(py::2, px::2)``, shape ``(K, ny, nx)`` (``py = None``: all pixels)."""
        if self.array is not None:
            return np.ascontiguousarray(self.array[:, py::2, px::2])
        if self.symmetric is not None:
            part = self.symmetric.parity_class(py, px).astype(np.float64, copy=False)
        else:
            parity = None if py is None else (py, px)  # None: the whole grid
            _, part = csr_to_stencil(self.csr, self.shape, offsets=self.csr_offsets, parity=parity)
        if self.csr_offsets == self.offsets:
            return part
        out = np.zeros((len(self.offsets),) + part.shape[1:])
        slot = {o: k for k, o in enumerate(self.offsets)}
        for k, o in enumerate(self.csr_offsets):
            out[slot[o]] = part[k]
        return out

    def class_images(self, py, px):
        """:meth:`parity_class` for reading offset by offset: ``S[k]`` and ``S.shape`` as of that array.

        A symmetric source hands out each image on request (:meth:`SymmetricStencil.class_image`: a view of
        the stored images for the offsets ``>= (0, 0)``), so the class is never held whole (one offset's image
        at a time instead of all of them); other sources give the array.
        """
        if self.array is None and self.symmetric is not None and self.csr_offsets == self.offsets:
            return _ClassImages(self.symmetric, py, px)
        return self.parity_class(py, px)

    def whole_images(self):
        """``image_of(offset)``: the whole ``(H, W)`` float64 image of an offset, or None for a CSR source.

        An array source hands out its images (views when float64); a symmetric one the stored images of the
        offsets ``>= (0, 0)`` and mirrored copies of the others
        (:func:`mirrored_image`).  A CSR source (read class by class to
        keep the memory low) has none: None.
        """
        if self.array is not None:
            slot = {o: k for k, o in enumerate(self.offsets)}
            return lambda offset: np.asarray(self.array[slot[offset]], dtype=np.float64)
        if self.symmetric is not None and self.csr_offsets == self.offsets:
            stored = dict(zip(self.symmetric.upper, self.symmetric.images))

            def image_of(offset):
                if offset in stored:
                    return stored[offset].astype(np.float64, copy=False)
                dy, dx = offset
                return mirrored_image(stored[-dy, -dx], (-dy, -dx))

            return image_of
        return None

    def read_whole(self):
        """Read a CSR source into one array now (the set-up asks for most classes twice)."""
        if self.array is None:
            self.array = self.parity_class(None, None)
            self.csr = self.symmetric = None
        return self


def _towards(offset):
    """The radius-1 offset in the direction of ``offset``: ``(sign dy, sign dx)``."""
    return tuple(int(np.sign(d)) for d in offset)


class CollapsedSource:
    """A stencil of radius 2 seen as one of radius 1: every coupling moved to the neighbour in its direction.

    ``(±2, 0)`` goes to ``(±1, 0)``, ``(±1, ±2)`` and ``(±2, ±2)`` to ``(±1, ±1)``, and so on, so each pixel's
    row keeps its sum.  Only :meth:`parity_class` is offered (what
    :func:`~sparsedepth.linalg.multigrid.interpolation.operator_weights` reads), collapsed one class at a time
    from the wrapped :class:`StencilSource`.
    """

    def __init__(self, source):
        self.source = source
        self.shape = source.shape
        self.offsets = sorted({_towards(o) for o in source.offsets})

    def parity_class(self, py, px):
        """The collapsed images on the pixels ``(py::2, px::2)``, shape ``(len(offsets), ny, nx)``."""
        part = self.source.parity_class(py, px)
        slot = {o: k for k, o in enumerate(self.offsets)}
        out = np.zeros((len(self.offsets),) + part.shape[1:])
        for k, o in enumerate(self.source.offsets):
            out[slot[_towards(o)]] += part[k]
        return out


class _ClassImages:
    """The images of one parity class of a :class:`SymmetricStencil`, each made when it is indexed (float64)."""

    def __init__(self, stencil, py, px):
        H, W = stencil.grid_shape
        self._stencil, self._py, self._px = stencil, py, px
        self.shape = (len(stencil.offsets), len(range(py, H, 2)), len(range(px, W, 2)))

    def __getitem__(self, k):
        image = self._stencil.class_image(self._stencil.offsets[k], self._py, self._px)
        return image.astype(np.float64, copy=False)


def _pattern_offsets(A, shape, radius=None):
    """Offsets of ``A`` when it is in the full in-grid pattern within the radius (default 2), else None."""
    largest = 2 if radius is None else int(radius)
    offsets = full_pattern_offsets(A, shape)
    if offsets is not None and all(max(abs(dy), abs(dx)) <= largest for dy, dx in offsets):
        return offsets
    return None


def _rows_inside(offset, shape):
    """Slices of the pixels whose neighbour at ``offset`` lies inside the grid."""
    h, w = shape
    dy, dx = offset
    return slice(max(0, -dy), max(0, min(h, h - dy))), slice(max(0, -dx), max(0, min(w, w - dx)))


def read_full_pattern(A, shape, radius=None):
    r"""Offsets and stencil images of a CSR matrix in the full in-grid pattern, checked while read; else None.

    Parameters
    ----------
    A : scipy.sparse CSR matrix or array, shape (H*W, H*W)
    shape : tuple of int
        ``(H, W)``.
    radius : int, optional
        Largest stencil radius accepted (default 2).

    Returns
    -------
    (offsets, S) or None
        As :func:`~sparsedepth.grid.stencil.full_pattern_offsets` and
        :func:`~sparsedepth.grid.stencil.csr_to_stencil` together: ``S`` of shape ``(len(offsets), H, W)``,
        zero where the neighbour is outside the grid; None when ``A`` is not stored in the pattern of
        :func:`~sparsedepth.grid.stencil.stencil_to_csr` (its ``indptr`` and ``indices`` are compared with that
        pattern entry by entry) or reaches beyond `radius`.

    Notes
    -----
    The offsets are read from the row of the grid's centre.  The pixels whose every neighbour is inside the
    grid hold the ``K`` offsets in order, so their entries are a ``(rows, columns, K)`` view of ``A.data``
    and ``A.indices`` (the row pointers checked first); they are compared and copied a band of rows at a time
    (a few hundred kilobytes, so the transposed copy works in cache), and the few border pixels by gathers.
    """
    h, w = shape
    n = h * w
    if A.format != "csr" or A.shape != (n, n) or A.nnz == 0:
        return None
    indptr, indices, data = A.indptr, A.indices, A.data
    centre = (h // 2) * w + w // 2
    delta = indices[indptr[centre]:indptr[centre + 1]].astype(np.int64) - centre
    dys = (delta + w // 2) // w
    dxs = delta - dys * w
    offsets = list(zip(dys.tolist(), dxs.tolist()))
    largest = 2 if radius is None else int(radius)
    if (not offsets or offsets != sorted(set(offsets)) or np.any(2 * np.abs(dxs) >= w)
            or max(max(abs(dy), abs(dx)) for dy, dx in offsets) > largest):
        return None
    counts, inner = _pattern_layout(offsets, shape)
    if int(indptr[0]) != 0 or not np.array_equal(indptr[1:], np.cumsum(counts.reshape(-1))):
        return None
    K = len(offsets)
    S = np.zeros((K, h, w))
    y0, y1, x0, x1 = inner
    if y1 > y0 and x1 > x0:
        values, columns = _inner_views((data, indices), indptr, counts, inner, K)
        own = np.arange(x0, x1, dtype=np.int64)[None, :, None] + delta  # each entry's column, less its row's start
        band = _band_rows((x1 - x0) * K)
        for r0 in range(0, y1 - y0, band):
            r1 = min(y1 - y0, r0 + band)
            starts = np.arange(y0 + r0, y0 + r1, dtype=np.int64)[:, None, None] * w
            if not np.array_equal(columns[r0:r1] - starts, np.broadcast_to(own, (r1 - r0,) + own.shape[1:])):
                return None
            S[:, y0 + r0:y0 + r1, x0:x1] = values[r0:r1].transpose(2, 0, 1)
    position, k, pixel = _border_entries(offsets, shape, indptr, inner)
    if not np.array_equal(indices[position], pixel + delta[k]):
        return None
    S[k, pixel // w, pixel % w] = data[position]
    return offsets, S


def _pattern_layout(offsets, shape):
    """The full in-grid pattern's row lengths and its inner block (the pixels whose every neighbour is inside).

    Returns ``(counts, (y0, y1, x0, x1))``: entries per pixel, an ``(H, W)`` int64 array, and the inner
    block's rows and columns.
    """
    h, w = shape
    counts = np.zeros((h, w), dtype=np.int64)
    for offset in offsets:
        counts[_rows_inside(offset, shape)] += 1
    dys = [dy for dy, _ in offsets]
    dxs = [dx for _, dx in offsets]
    y0, y1 = max(0, -min(dys)), h - max(0, max(dys))
    x0, x1 = max(0, -min(dxs)), w - max(0, max(dxs))
    return counts, (y0, y1, x0, x1)


def _inner_views(arrays, indptr, counts, inner, K):
    """``(rows, columns, K)`` views of the inner block's entries in each of ``arrays`` (CSR values or indices)."""
    y0, y1, x0, x1 = inner
    w = counts.shape[1]
    row_length = int(counts[y0].sum())
    first = int(counts[y0, :x0].sum())
    begin = int(indptr[y0 * w])
    return [array[begin:begin + (y1 - y0) * row_length].reshape(y1 - y0, row_length)[:, first:first + (x1 - x0) * K]
            .reshape(y1 - y0, x1 - x0, K) for array in arrays]


def _border_entries(offsets, shape, indptr, inner):
    """The entries of the pixels outside the inner block: ``(position, k, pixel)`` of each, in CSR order."""
    h, w = shape
    y0, y1, x0, x1 = inner
    outside = np.ones((h, w), dtype=bool)
    outside[y0:y1, x0:x1] = False
    border = np.flatnonzero(outside.reshape(-1))
    by, bx = np.divmod(border, w)
    dys = np.array([dy for dy, _ in offsets])
    dxs = np.array([dx for _, dx in offsets])
    ny, nx = by[:, None] + dys[None, :], bx[:, None] + dxs[None, :]
    valid = (ny >= 0) & (ny < h) & (nx >= 0) & (nx < w)
    position = indptr[border].astype(np.int64)[:, None] + np.cumsum(valid, axis=1) - 1
    which, k = np.nonzero(valid)
    return position[which, k], k, border[which]


def centre_row_holds(offsets, shape):
    """True when the grid's centre pixel has every offset inside the grid, with ``2 |dx| < W``.

    Then a matrix in the full in-grid pattern of these offsets (:func:`assemble_csr`) is recognised as such
    by :func:`~sparsedepth.grid.stencil.full_pattern_offsets`, which reads the offsets from that row.
    """
    h, w = shape
    cy, cx = h // 2, w // 2
    return all(0 <= cy + dy < h and 0 <= cx + dx < w and 2 * abs(dx) < w for dy, dx in offsets)


def _band_rows(entries_per_row):
    """Image rows per band of the inner block's copies (about 2**16 entries, a few hundred kilobytes)."""
    return max(1, (1 << 16) // max(1, entries_per_row))


def assemble_csr(offsets, stencil, dtype=np.float64):
    r"""CSR matrix of a stencil in the full in-grid pattern: :func:`~sparsedepth.grid.stencil.stencil_to_csr`'s.

    Parameters
    ----------
    offsets : list of tuple of int
        Distinct offsets, sorted lexicographically.
    stencil : ndarray, shape (len(offsets), H, W)
        Coefficient images (entries whose neighbour is outside the grid are not stored).
    dtype : numpy dtype, default float64
        Type of the stored values.

    Returns
    -------
    scipy.sparse.csr_array, shape (H*W, H*W)
        The same ``indptr``, ``indices`` and values as ``stencil_to_csr(offsets, stencil, dtype=dtype)``.

    Notes
    -----
    The inner block's entries (``K`` per pixel, in the order of `offsets`) are a ``(rows, columns, K)`` view
    of the CSR arrays: the values are the stencil's images transposed into it, and the column indices
    :math:`(y + d_y) W + x + d_x`, a band of rows at a time so that the transposed copy works in cache; the
    few border pixels are written by scatters.
    """
    offsets = [tuple(o) for o in offsets]
    K, h, w = stencil.shape
    n = h * w
    counts, inner = _pattern_layout(offsets, (h, w))
    itype = index_dtype(n * K)
    indptr = np.zeros(n + 1, dtype=itype)
    np.cumsum(counts.reshape(-1), out=indptr[1:])
    nnz = int(indptr[-1])
    data = np.empty(nnz, dtype=dtype)
    indices = np.empty(nnz, dtype=itype)
    delta = np.array([dy * w + dx for dy, dx in offsets])
    y0, y1, x0, x1 = inner
    if y1 > y0 and x1 > x0:
        values, columns = _inner_views((data, indices), indptr, counts, inner, K)
        own = np.arange(x0, x1, dtype=itype)[None, :, None] + delta.astype(itype)
        band = _band_rows((x1 - x0) * K)
        for r0 in range(0, y1 - y0, band):
            r1 = min(y1 - y0, r0 + band)
            values[r0:r1] = stencil[:, y0 + r0:y0 + r1, x0:x1].transpose(1, 2, 0)
            np.add(own, (np.arange(y0 + r0, y0 + r1, dtype=itype) * itype(w))[:, None, None], out=columns[r0:r1])
    position, k, pixel = _border_entries(offsets, (h, w), indptr, inner)
    data[position] = stencil[k, pixel // w, pixel % w]
    indices[position] = pixel + delta[k]
    out = sp.csr_array((data, indices, indptr), shape=(n, n))
    out.has_sorted_indices = True
    out.has_canonical_format = True
    return out


def fine_stencil_source(A, shape, radius=None, *, whole=False):
    """Offsets and :class:`StencilSource` of a fine operator (a symmetric stencil, pattern read, else extraction).

    ``whole=True``: a CSR operator in the full in-grid pattern is read into one array at once
    (:func:`read_full_pattern`) instead of being kept as a CSR source read class by class.
    """
    if whole and not isinstance(A, SymmetricStencil):
        read = read_full_pattern(A, shape, radius)
        if read is not None:
            offsets, S = read
            return offsets, StencilSource(offsets, shape, array=S)
    if isinstance(A, SymmetricStencil):
        largest = 2 if radius is None else int(radius)
        if any(max(abs(dy), abs(dx)) > largest for dy, dx in A.offsets):
            raise ValueError(f"`A` couples pixels farther apart than a stencil of radius {largest}: offsets "
                             f"{A.offsets}")
        return list(A.offsets), StencilSource(A.offsets, shape, symmetric=A)
    offsets = _pattern_offsets(A, shape, radius)
    if offsets is not None:
        return offsets, StencilSource(offsets, shape, csr=A, csr_offsets=offsets)
    offsets, S = _stencil_of(A, shape, radius)
    return offsets, StencilSource(offsets, shape, array=S)
