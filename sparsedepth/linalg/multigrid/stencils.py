"""Stencils of grid operators: one coefficient image per neighbour offset, read from and written to CSR matrices.

The multigrid set-up works on stencils, never on general sparse products;
this module reads them from an operator (:func:`grid_stencil`; a CSR matrix
in the full in-grid pattern is checked by :func:`verify_full_pattern` and read
by position, :class:`PatternRows`), hands a level's stencil to the set-up one
parity class or one band of rows at a time (:class:`StencilSource`) and
writes the coarse levels' CSR forms (:func:`assemble_csr`).  May import
:mod:`sparsedepth.grid` and :mod:`sparsedepth._validation`, NumPy and SciPy.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..._validation import as_grid_operator
from ...grid.stencil import SymmetricStencil, csr_to_stencil, full_pattern_offsets, index_dtype

__all__ = ["grid_stencil", "extract_stencil", "StencilSource", "CollapsedSource", "fine_stencil_source",
           "mirrored_image", "read_full_pattern", "verify_full_pattern", "PatternRows", "assemble_csr",
           "centre_row_holds"]


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
    ty, tx = slice(max(0, dy), min(h, h + dy)), slice(max(0, dx), min(w, w + dx))
    if ty.start >= ty.stop or tx.start >= tx.stop:
        if out is None:
            return np.zeros((h, w))
        out[...] = 0.0
        return out
    if out is None:
        out = np.zeros((h, w))
    else:  # zero the strips outside the copied block only
        out[:ty.start] = 0.0
        out[ty.stop:] = 0.0
        out[ty, :tx.start] = 0.0
        out[ty, tx.stop:] = 0.0
    out[ty, tx] = image[ty.start - dy:ty.stop - dy, tx.start - dx:tx.stop - dx]
    return out


class StencilSource:
    """A level's stencil for the numeric set-up, handed out one parity class or one band of rows at a time.

    Either an array ``(K, H, W)`` (coarse levels, or a fine operator whose
    stencil had to be extracted diagonal by diagonal), a symmetric stencil, or a CSR matrix in the
    full in-grid pattern of :func:`~sparsedepth.grid.stencil.stencil_to_csr`, read
    class by class (:meth:`parity_class`) or band by band (:meth:`row_reader`) so that the fine stencil is
    never held whole.  For the class-by-class products, grids below
    ``keep_stencil_pixels`` (:class:`~sparsedepth.limits.MemoryLimits`) read it whole once (:meth:`read_whole`).
    """

    def __init__(self, offsets, shape, *, array=None, csr=None, csr_offsets=None, symmetric=None, layout=None):
        self.layout = layout  # a CSR source's pattern layout, when already computed (verify_full_pattern)
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

    def row_reader(self):
        """``rows_of(y0, y1)``: the stencil on the image rows ``y0:y1``, ``(len(offsets), y1 − y0, W)`` float64.

        An array source hands out views of its rows (copies when not float64), a symmetric one
        :meth:`~sparsedepth.grid.stencil.SymmetricStencil.full_rows`, a CSR one (in the full in-grid pattern of
        ``csr_offsets``, as the set-up makes or checks it) reads them by position (:class:`PatternRows`); the
        offsets it lacks read as zero.
        """
        if self.array is not None:
            read = lambda y0, y1: np.asarray(self.array[:, y0:y1], dtype=np.float64)  # noqa: E731
        elif self.symmetric is not None:
            read = lambda y0, y1: self.symmetric.full_rows(y0, y1).astype(np.float64, copy=False)  # noqa: E731
        else:
            read = PatternRows(self.csr, self.csr_offsets, self.shape, self.layout)
        if self.array is not None or self.csr_offsets == self.offsets:
            rows_of = read
        else:
            slots = [self.offsets.index(o) for o in self.csr_offsets]

            def rows_of(y0, y1):
                out = np.zeros((len(self.offsets), y1 - y0, self.shape[1]))
                out[slots] = read(y0, y1)
                return out
        kept = getattr(self, "_kept", None)
        if kept is None:
            return rows_of
        slots = [self.offsets.index(o) for o in kept.images]

        def rows_kept(y0, y1):
            rows = rows_of(y0, y1)
            kept.add([rows[k] for k in slots], y0, y1)
            return rows

        return rows_kept

    def keep_images(self, offsets):
        """Copy the images of ``offsets`` (those the source has) as :meth:`row_reader` hands out their rows.

        Returns a :class:`KeptImages`: its ``images`` (``{offset: (H, W) array}``) are complete once every
        row was read (``complete``).
        """
        self._kept = KeptImages([o for o in offsets if o in self.offsets], self.shape)
        return self._kept

    def read_whole(self):
        """Read a CSR source into one array now (the set-up asks for most classes twice)."""
        if self.array is None:
            self.array = (self.row_reader()(0, self.shape[0]) if self.symmetric is None
                          else self.parity_class(None, None))
            self.csr = self.symmetric = None
        return self


class KeptImages:
    """Whole images of some offsets, filled band by band as a :class:`StencilSource`'s rows are read.

    Attributes
    ----------
    images : dict
        ``{offset: (H, W) float64 array}``.
    complete : bool
        True once every row has been read.
    """

    def __init__(self, offsets, shape):
        self.images = {tuple(o): np.empty(shape) for o in offsets}  # every row is written before it is used
        self._read = np.zeros(shape[0], dtype=bool)

    def add(self, rows, y0, y1):
        """Copy ``rows`` (one ``(y1 − y0, W)`` array per image, in the order of ``images``) into the images."""
        for image, part in zip(self.images.values(), rows):
            image[y0:y1] = part
        self._read[y0:y1] = True

    @property
    def complete(self):
        return bool(self._read.all())


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


def _pattern_layout(offsets, shape):
    """The full in-grid pattern's row lengths and its inner block (the pixels whose every neighbour is inside).

    Returns ``(counts, (y0, y1, x0, x1))``: entries per pixel, an ``(H, W)`` int64 array, and the inner
    block's rows and columns.
    """
    h, w = shape
    dys = np.array([dy for dy, _ in offsets])
    dxs = np.array([dx for _, dx in offsets])
    rows_in = ((np.arange(h)[:, None] + dys >= 0) & (np.arange(h)[:, None] + dys < h)).astype(np.float64)
    columns_in = ((np.arange(w)[:, None] + dxs >= 0) & (np.arange(w)[:, None] + dxs < w)).astype(np.float64)
    counts = (rows_in @ columns_in.T).astype(np.int64)  # offsets inside at (y, x): a sum of at most K ones
    y0, y1 = max(0, -int(dys.min())), h - max(0, int(dys.max()))
    x0, x1 = max(0, -int(dxs.min())), w - max(0, int(dxs.max()))
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
    if y1 > y0 and x1 > x0:  # the rows above, the side columns of the inner rows, the rows below: in order
        sides = np.concatenate([np.arange(x0), np.arange(x1, w)])
        border = np.concatenate([np.arange(y0 * w), (np.arange(y0, y1)[:, None] * w + sides).reshape(-1),
                                 np.arange(y1 * w, h * w)])
    else:
        border = np.arange(h * w)
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
    of the CSR arrays: the values are the stencil's images copied into it one by one, and the column indices
    :math:`(y + d_y) W + x + d_x` are written a band of rows at a time; the few border pixels are written by
    scatters.
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
        for k in range(K):  # one image at a time: contiguous reads (faster than a transposed copy here)
            values[:, :, k] = stencil[k, y0:y1, x0:x1]
        own = np.arange(x0, x1, dtype=itype)[None, :, None] + delta.astype(itype)
        band = _band_rows((x1 - x0) * K)
        for r0 in range(0, y1 - y0, band):
            r1 = min(y1 - y0, r0 + band)
            np.add(own, (np.arange(y0 + r0, y0 + r1, dtype=itype) * itype(w))[:, None, None], out=columns[r0:r1])
    position, k, pixel = _border_entries(offsets, (h, w), indptr, inner)
    data[position] = stencil[k, pixel // w, pixel % w]
    indices[position] = pixel + delta[k]
    out = sp.csr_array((data, indices, indptr), shape=(n, n))
    out.has_sorted_indices = True
    out.has_canonical_format = True
    return out


def verify_full_pattern(A, shape, radius=None):
    r"""Offsets of a CSR matrix stored in the full in-grid pattern (every index compared), else None.

    Parameters
    ----------
    A : scipy.sparse CSR matrix or array, shape (H*W, H*W)
    shape : tuple of int
        ``(H, W)``.
    radius : int, optional
        Largest stencil radius accepted (default 2).

    Returns
    -------
    list of tuple of int, or None
        As :func:`~sparsedepth.grid.stencil.full_pattern_offsets` (the offsets read from the row of the grid's
        centre, when ``A.indptr`` and ``A.indices`` are exactly the pattern of
        :func:`~sparsedepth.grid.stencil.stencil_to_csr` for them), and None as well for offsets beyond
        `radius`.

    Notes
    -----
    The pixels whose every neighbour is inside the grid hold the ``K`` offsets in order, so their column
    indices are a ``(rows, columns, K)`` view of ``A.indices`` (the row pointers checked first); a band of
    rows at a time, less its first row's start, it must equal the band of the pattern's first rows.  The few
    border pixels are compared by gathers.
    """
    checked = _verified_layout(A, shape, radius)
    return None if checked is None else checked[0]


def _verified_layout(A, shape, radius=None):
    """:func:`verify_full_pattern`'s offsets and the pattern's layout (:func:`_pattern_layout`), or None."""
    h, w = shape
    n = h * w
    if A.format != "csr" or A.shape != (n, n) or A.nnz == 0:
        return None
    indptr, indices = A.indptr, A.indices
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
    y0, y1, x0, x1 = inner
    if y1 > y0 and x1 > x0:
        (columns,) = _inner_views((indices,), indptr, counts, inner, K)
        band = min(y1 - y0, _band_rows((x1 - x0) * K))
        # the columns of the first band's entries, in the index type (they are columns of the matrix: below N)
        itype = indices.dtype.type
        pattern = (np.arange(y0, y0 + band, dtype=np.int64)[:, None, None] * w
                   + np.arange(x0, x1, dtype=np.int64)[None, :, None] + delta).astype(indices.dtype)
        shifted = np.empty_like(pattern)
        for r0 in range(0, y1 - y0, band):
            r1 = min(y1 - y0, r0 + band)
            part = shifted[:r1 - r0]
            np.subtract(columns[r0:r1], itype(r0 * w), out=part)  # a later band less its rows' offset from the first
            if not np.array_equal(part, pattern[:r1 - r0]):
                return None
    position, k, pixel = _border_entries(offsets, shape, indptr, inner)
    if not np.array_equal(indices[position], pixel + delta[k]):
        return None
    return offsets, (counts, inner)


class PatternRows:
    """The stencil images of a CSR matrix in the full in-grid pattern, read a band of image rows at a time.

    Parameters
    ----------
    A : scipy.sparse CSR matrix or array, shape (H*W, H*W)
        Stored in the full in-grid pattern of `offsets` (as checked by :func:`verify_full_pattern`, or as made
        by :func:`assemble_csr`): the values are read by position, the indices are not looked at.
    offsets : list of tuple of int
    shape : tuple of int
        ``(H, W)``.
    layout : tuple, optional
        The pattern's layout if already computed (as when checked).

    Notes
    -----
    ``rows(y0, y1)`` gives ``(len(offsets), y1 − y0, W)`` float64 images, zero where the neighbour is outside
    the grid: the inner pixels' values are a ``(rows, columns, K)`` view of ``A.data``, transposed into the
    images a few hundred kilobytes at a time; the border pixels' are scattered.
    """

    def __init__(self, A, offsets, shape, layout=None):
        self.offsets = [tuple(o) for o in offsets]
        self.shape = tuple(shape)
        h, w = self.shape
        self._data = A.data
        counts, self._inner = _pattern_layout(self.offsets, self.shape) if layout is None else layout
        y0, y1, x0, x1 = self._inner
        self._values = (_inner_views((A.data,), A.indptr, counts, self._inner, len(self.offsets))[0]
                        if y1 > y0 and x1 > x0 else None)
        self._position, self._k, self._pixel = _border_entries(self.offsets, self.shape, A.indptr, self._inner)

    def __call__(self, y0, y1):
        """The images on rows ``y0:y1``, a new ``(K, y1 − y0, W)`` float64 array."""
        h, w = self.shape
        K = len(self.offsets)
        out = np.empty((K, y1 - y0, w))
        iy0, iy1, x0, x1 = self._inner
        a, b = max(y0, iy0), min(y1, iy1)
        # zero outside the inner block (the border pixels' entries outside the grid stay so)
        out[:, :max(0, a - y0)] = 0.0
        out[:, max(0, b - y0):] = 0.0
        out[:, max(0, a - y0):max(0, b - y0), :x0] = 0.0
        out[:, max(0, a - y0):max(0, b - y0), x1:] = 0.0
        if self._values is not None and b > a:
            band = _band_rows((x1 - x0) * K)
            for r0 in range(a, b, band):
                r1 = min(b, r0 + band)
                out[:, r0 - y0:r1 - y0, x0:x1] = self._values[r0 - iy0:r1 - iy0].transpose(2, 0, 1)
        lo, hi = np.searchsorted(self._pixel, (y0 * w, y1 * w))  # border entries in CSR order: by pixel
        pixel, k = self._pixel[lo:hi], self._k[lo:hi]
        out[k, pixel // w - y0, pixel % w] = self._data[self._position[lo:hi]]
        return out


def read_full_pattern(A, shape, radius=None):
    """Offsets and stencil images ``(len(offsets), H, W)`` of a CSR matrix in the full in-grid pattern, else None.

    :func:`verify_full_pattern`, then :class:`PatternRows` for all rows: the results of
    :func:`~sparsedepth.grid.stencil.full_pattern_offsets` and :func:`~sparsedepth.grid.stencil.csr_to_stencil`.
    """
    checked = _verified_layout(A, shape, radius)
    if checked is None:
        return None
    offsets, layout = checked
    return offsets, PatternRows(A, offsets, shape, layout)(0, shape[0])


def fine_stencil_source(A, shape, radius=None):
    """Offsets and :class:`StencilSource` of a fine operator (a symmetric stencil, pattern read, else extraction)."""
    if isinstance(A, SymmetricStencil):
        largest = 2 if radius is None else int(radius)
        if any(max(abs(dy), abs(dx)) > largest for dy, dx in A.offsets):
            raise ValueError(f"`A` couples pixels farther apart than a stencil of radius {largest}: offsets "
                             f"{A.offsets}")
        return list(A.offsets), StencilSource(A.offsets, shape, symmetric=A)
    checked = _verified_layout(A, shape, radius)
    if checked is not None:
        offsets, layout = checked
        return offsets, StencilSource(offsets, shape, csr=A, csr_offsets=offsets, layout=layout)
    offsets, S = _stencil_of(A, shape, radius)
    return offsets, StencilSource(offsets, shape, array=S)
