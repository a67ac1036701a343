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

May import NumPy, SciPy and :mod:`sparsedepth._validation`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._validation import check_grid_shape

__all__ = ["stencil_to_csr", "csr_to_stencil", "full_pattern_offsets", "index_dtype"]

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
    K, H, W = stencil.shape
    n = H * W
    indptr = _row_starts(offsets, (H, W), index_dtype(n * K))
    nnz = int(indptr[-1])
    data = np.empty(nnz, dtype=dtype)
    indices = np.empty(nnz, dtype=indptr.dtype)
    for block in _blocks(offsets, (H, W), indptr):
        y0, y1, _, xs, ks, _ = block
        _block_view(data, indptr, W, *block)[...] = np.moveaxis(stencil[ks, y0:y1, xs], 0, -1)
        _block_view(indices, indptr, W, *block)[...] = _block_columns(offsets, W, y0, y1, xs, ks, indices.dtype)
    out = sp.csr_array((data, indices, indptr), shape=(n, n))
    out.has_sorted_indices = True
    out.has_canonical_format = True
    return out


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
