"""Stencils of grid operators: one coefficient image per neighbour offset, read from the operators.

The multigrid set-up works on stencils, never on general sparse products;
this module reads them from an operator (:func:`grid_stencil`; a CSR matrix
in the full in-grid pattern of :mod:`sparsedepth.grid.stencil` is recognised
by :func:`full_pattern_within` and read by position, others diagonal by
diagonal) and hands a level's stencil to the set-up one parity class or one
band of rows at a time (:class:`StencilSource`).  The coarse levels' CSR
forms are :func:`~sparsedepth.grid.stencil.stencil_to_csr`'s.  May import
:mod:`sparsedepth.grid` and :mod:`sparsedepth._validation`, NumPy and SciPy.
"""

from __future__ import annotations

import numpy as np

from ..._validation import as_grid_operator
from ...grid.stencil import FullPattern, SymmetricStencil

__all__ = ["grid_stencil", "extract_stencil", "StencilSource", "CollapsedSource", "fine_stencil_source",
           "mirrored_image", "full_pattern_within"]


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
    """Stencil images of a canonical CSR matrix for the given offsets, ``(len(offsets), H, W)`` (diagonal by diagonal)."""
    S = np.empty((len(offsets),) + tuple(shape))
    for k, (dy, dx) in enumerate(offsets):
        _offset_image(A, shape, dy, dx, S[k])
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
    pattern = full_pattern_within(A, shape, radius)  # one pass when A is in the full in-grid pattern
    if pattern is None:
        return _stencil_of(A, shape, radius)
    return _without_empty_offsets(pattern.offsets, pattern.read_rows(A, 0, shape[0]))


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
    are read by the callers, see :func:`full_pattern_within`, before this is tried.)
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
    full in-grid pattern of ``csr_offsets`` (:class:`~sparsedepth.grid.stencil.FullPattern`: ``pattern`` when
    already made), read by position class by class (:meth:`parity_class`) or band by band (:meth:`row_reader`)
    so that the fine stencil is never held whole.  For the class-by-class products, grids below
    ``keep_stencil_pixels`` (:class:`~sparsedepth.limits.MemoryLimits`) read it whole once (:meth:`read_whole`).
    """

    def __init__(self, offsets, shape, *, array=None, csr=None, csr_offsets=None, symmetric=None, pattern=None):
        self.offsets = list(offsets)
        self.shape = tuple(shape)
        self.array = array
        self.csr = csr
        self.pattern = None  # a CSR source's FullPattern
        if csr is not None:
            self.pattern = FullPattern(csr_offsets, self.shape) if pattern is None else pattern
            csr_offsets = self.pattern.offsets
        self.csr_offsets = None if csr_offsets is None else list(csr_offsets)
        self.symmetric = symmetric  # a SymmetricStencil, read class by class like a CSR source
        if symmetric is not None:
            self.csr_offsets = list(symmetric.offsets)

    def parity_class(self, py, px):
        """Stencil images on the pixels ``(py::2, px::2)``, shape ``(K, ny, nx)`` (``py = None``: all pixels)."""
        if self.array is not None:
            return self.array if py is None else np.ascontiguousarray(self.array[:, py::2, px::2])
        if self.symmetric is not None:
            part = self.symmetric.parity_class(py, px).astype(np.float64, copy=False)
        elif py is None:  # the whole grid
            part = self.pattern.read_rows(self.csr, 0, self.shape[0])
        else:
            part = self.pattern.read_class(self.csr, py, px)
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
        ``csr_offsets``, as the set-up makes or checks it) reads them by position
        (:meth:`~sparsedepth.grid.stencil.FullPattern.read_rows`); the offsets it lacks read as zero.
        """
        if self.array is not None:
            read = lambda y0, y1: np.asarray(self.array[:, y0:y1], dtype=np.float64)  # noqa: E731
        elif self.symmetric is not None:
            read = lambda y0, y1: self.symmetric.full_rows(y0, y1).astype(np.float64, copy=False)  # noqa: E731
        else:
            read = lambda y0, y1: self.pattern.read_rows(self.csr, y0, y1)  # noqa: E731
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
            self.csr = self.symmetric = self.pattern = None
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


def full_pattern_within(A, shape, radius=None):
    """The full in-grid pattern ``A`` is stored in, when its offsets lie within the radius (default 2), else None.

    :meth:`~sparsedepth.grid.stencil.FullPattern.of_matrix` (every index compared), limited to the stencils
    the hierarchy coarsens; ``A`` is then read by position.
    """
    largest = 2 if radius is None else int(radius)
    pattern = FullPattern.of_matrix(A, shape)
    if pattern is not None and all(max(abs(dy), abs(dx)) <= largest for dy, dx in pattern.offsets):
        return pattern
    return None


def fine_stencil_source(A, shape, radius=None):
    """Offsets and :class:`StencilSource` of a fine operator (a symmetric stencil, pattern read, else extraction)."""
    if isinstance(A, SymmetricStencil):
        largest = 2 if radius is None else int(radius)
        if any(max(abs(dy), abs(dx)) > largest for dy, dx in A.offsets):
            raise ValueError(f"`A` couples pixels farther apart than a stencil of radius {largest}: offsets "
                             f"{A.offsets}")
        return list(A.offsets), StencilSource(A.offsets, shape, symmetric=A)
    pattern = full_pattern_within(A, shape, radius)
    if pattern is not None:
        return list(pattern.offsets), StencilSource(pattern.offsets, shape, csr=A, pattern=pattern)
    offsets, S = _stencil_of(A, shape, radius)
    return offsets, StencilSource(offsets, shape, array=S)
