"""Sparse finite-difference operators on an image grid.

Pixels are flattened in C order (row-major): pixel ``(i, j)`` of an ``(H, W)``
grid has index ``i * W + j``.  Every operator is a ``scipy.sparse`` CSR matrix
built by vectorised index arithmetic and cached per grid shape, so building the
same operator twice costs nothing.

Boundary convention (Neumann): a forward difference is zero in the last column
(horizontal) or the last row (vertical); the operators keep one row per pixel so
that the row of pixel ``(i, j)`` of ``forward_diff(shape, axis=1)`` is
``z[i, j+1] - z[i, j]`` (``0`` when ``j = W - 1``).

The same operators exist matrix-free (:class:`StencilOperator`,
:func:`gradient_stencil`, :func:`hessian_stencil`), applied by array slicing.

May import NumPy, SciPy, :mod:`sparsedepth._validation` and :mod:`.rowbands`.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.sparse as sp

from .._validation import check_grid_shape
from .rowbands import row_bands, rows_per_band
from ..limits import memory_limits

__all__ = [
    "forward_diff",
    "gradient",
    "second_diff",
    "mixed_diff",
    "hessian_operator",
    "StencilOperator",
    "gradient_stencil",
    "hessian_stencil",
]



@lru_cache(maxsize=16)
def _forward_diff_1d(n: int) -> sp.csr_matrix:
    """``(n, n)`` forward difference with a zero last row."""
    main = -np.ones(n)
    main[-1] = 0.0
    upper = np.ones(n - 1)
    return sp.diags([main, upper], [0, 1], shape=(n, n), format="csr")


@lru_cache(maxsize=16)
def _forward_diff_cached(shape: tuple[int, int], axis: int) -> sp.csr_matrix:
    H, W = shape
    if axis == 1:
        op = sp.kron(sp.identity(H, format="csr"), _forward_diff_1d(W), format="csr")
    else:
        op = sp.kron(_forward_diff_1d(H), sp.identity(W, format="csr"), format="csr")
    op.eliminate_zeros()
    op.sort_indices()
    return op


def forward_diff(shape, axis: int) -> sp.csr_matrix:
    """Forward difference along one axis of an ``(H, W)`` grid.

    Parameters
    ----------
    shape : tuple of int
        Grid shape ``(H, W)``.
    axis : {0, 1}
        ``1`` for the horizontal difference ``∂x z[i, j] = z[i, j+1] - z[i, j]``,
        ``0`` for the vertical difference ``∂y z[i, j] = z[i+1, j] - z[i, j]``.

    Returns
    -------
    scipy.sparse.csr_matrix
        ``(H*W, H*W)`` operator; rows of the last column (axis 1) or last row
        (axis 0) are zero (Neumann boundary).

    Examples
    --------
    >>> z = np.arange(6.0).reshape(2, 3)
    >>> (forward_diff((2, 3), axis=1) @ z.ravel()).reshape(2, 3)
    array([[1., 1., 0.],
           [1., 1., 0.]])
    """
    shape = check_grid_shape(shape)
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 or 1, got {axis!r}")
    return _forward_diff_cached(shape, axis)


@lru_cache(maxsize=16)
def _gradient_cached(shape):
    return sp.vstack([_forward_diff_cached(shape, 1), _forward_diff_cached(shape, 0)], format="csr")


def gradient(shape) -> sp.csr_matrix:
    """Stacked gradient ``[∂x; ∂y]`` of an ``(H, W)`` grid, shape ``(2*H*W, H*W)``.

    The first ``H*W`` rows are the horizontal differences, the last ``H*W`` the
    vertical ones (see :func:`forward_diff`).
    """
    return _gradient_cached(check_grid_shape(shape))


@lru_cache(maxsize=16)
def _second_diff_1d(n: int) -> sp.csr_matrix:
    """``(n, n)`` central second difference, zero in the first and last row."""
    if n < 3:
        return sp.csr_matrix((n, n))
    lower = np.ones(n - 1)
    main = -2.0 * np.ones(n)
    upper = np.ones(n - 1)
    lower[-1] = 0.0  # row n-1 is zero
    main[[0, -1]] = 0.0
    upper[0] = 0.0  # row 0 is zero
    op = sp.diags([lower, main, upper], [-1, 0, 1], shape=(n, n), format="csr")
    op.eliminate_zeros()
    return op


@lru_cache(maxsize=16)
def _second_diff_cached(shape, axis):
    H, W = shape
    if axis == 1:
        return sp.kron(sp.identity(H, format="csr"), _second_diff_1d(W), format="csr")
    return sp.kron(_second_diff_1d(H), sp.identity(W, format="csr"), format="csr")


def second_diff(shape, axis: int) -> sp.csr_matrix:
    """Central second difference along one axis, zero on the first/last line.

    Row of pixel ``(i, j)`` for ``axis=1``: ``z[i, j-1] - 2 z[i, j] + z[i, j+1]``
    for ``0 < j < W-1`` and ``0`` on the first and last column.
    """
    shape = check_grid_shape(shape)
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 or 1, got {axis!r}")
    return _second_diff_cached(shape, axis)


@lru_cache(maxsize=16)
def _mixed_diff_cached(shape):
    op = (_forward_diff_cached(shape, 0) @ _forward_diff_cached(shape, 1)).tocsr()
    op.eliminate_zeros()
    return op


def mixed_diff(shape) -> sp.csr_matrix:
    """Mixed difference ``∂y ∂x z``: ``z[i+1,j+1] - z[i+1,j] - z[i,j+1] + z[i,j]``.

    Zero in the last row and the last column.
    """
    return _mixed_diff_cached(check_grid_shape(shape))


@lru_cache(maxsize=16)
def _hessian_cached(shape):
    return sp.vstack(
        [_second_diff_cached(shape, 1), _second_diff_cached(shape, 0), np.sqrt(2.0) * _mixed_diff_cached(shape)],
        format="csr",
    )


def hessian_operator(shape) -> sp.csr_matrix:
    """Stacked second derivatives ``[∂xx; ∂yy; √2 ∂xy]``, shape ``(3*H*W, H*W)``.

    ``‖hessian_operator(shape) @ z‖²`` is the discrete thin-plate (Frobenius
    norm of the Hessian) energy; it vanishes exactly on affine ramps
    ``z = a + b*i + c*j``.
    """
    return _hessian_cached(check_grid_shape(shape))


# --------------------------------------------------------------------------
# matrix-free stencil form of the same operators
# --------------------------------------------------------------------------


def _anchor_region(taps, shape):
    """Slices ``(ys, xs)`` of the pixels whose taps all lie inside the grid."""
    H, W = shape
    dys = [dy for (dy, _), _ in taps]
    dxs = [dx for (_, dx), _ in taps]
    y0, x0 = max(0, -min(dys)), max(0, -min(dxs))
    y1, x1 = H - max(0, max(dys)), W - max(0, max(dxs))
    if y1 <= y0 or x1 <= x0:  # no pixel has all its taps inside the grid
        return slice(0, 0), slice(0, 0)
    return slice(y0, y1), slice(x0, x1)


def _flat_images(stencil):
    """The images of ``stencil`` (shape ``(k, H, W)``) as flat views ``(k, H * W)``; the array must be C-contiguous."""
    if not (isinstance(stencil, np.ndarray) and stencil.ndim == 3 and stencil.flags.c_contiguous):
        raise ValueError("the stencil must be a C-contiguous ndarray of shape (len(offsets), H, W)")
    return stencil.reshape(stencil.shape[0], -1)


def _shifted(region, offset):
    ys, xs = region
    if ys.stop == 0:  # empty region: stays empty (no wrap-around of negative stops)
        return region
    dy, dx = offset
    return slice(ys.start + dy, ys.stop + dy), slice(xs.start + dx, xs.stop + dx)


class StencilOperator:
    r"""Matrix-free stack of pixel-anchored difference operators on an ``(H, W)`` grid.

    Block ``b`` has one row per pixel (C order).  The row of pixel ``p`` is
    :math:`\sum_t c_t\, z[p + o_t]` over the block's taps ``(o_t, c_t)`` when
    every tap lies inside the grid, and zero otherwise -- the boundary rule of
    :func:`forward_diff` (zero last column / row) and :func:`second_diff`
    (zero first and last line).  The stacked operator has shape
    ``(n_blocks * H * W, H * W)`` and equals :meth:`tocsr`, but is applied by
    array slicing, stores nothing per pixel, and yields the stencil of
    :math:`K^\top \operatorname{diag}(r) K` directly (:meth:`add_normal_stencil`),
    so the normal equations are assembled without sparse matrix products.

    Parameters
    ----------
    shape : tuple of int
        Grid shape ``(H, W)``.
    blocks : sequence of sequence of ((int, int), float)
        Per block, its taps ``((dy, dx), coefficient)``.

    See Also
    --------
    gradient_stencil, hessian_stencil : the stencil forms of :func:`gradient`
        and :func:`hessian_operator`.

    Examples
    --------
    >>> D = StencilOperator((2, 3), [[((0, 0), -1.0), ((0, 1), 1.0)]])
    >>> D @ np.arange(6.0)
    array([1., 1., 0., 1., 1., 0.])
    >>> np.array_equal(D.tocsr().toarray(), forward_diff((2, 3), 1).toarray())
    True
    """

    def __init__(self, shape, blocks):
        self.grid_shape = check_grid_shape(shape)
        self.blocks = tuple(tuple(((int(dy), int(dx)), float(c)) for (dy, dx), c in block) for block in blocks)
        if not self.blocks or any(len(block) == 0 for block in self.blocks):
            raise ValueError("a StencilOperator needs at least one block, each with at least one tap")
        self._regions = tuple(_anchor_region(block, self.grid_shape) for block in self.blocks)

    @property
    def shape(self):
        n = self.grid_shape[0] * self.grid_shape[1]
        return (len(self.blocks) * n, n)

    @property
    def T(self):
        """The adjoint ``Kᵀ`` (matrix-free; ``K.T @ v``)."""
        return _AdjointStencilOperator(self)

    def _as_image(self, z):
        z = np.asarray(z, dtype=np.float64)
        n = self.shape[1]
        if z.ndim != 1 or z.shape[0] != n:
            raise ValueError(f"expected a vector of length {n} (grid {self.grid_shape}), got shape {z.shape}")
        return z.reshape(self.grid_shape)

    def block_matvec(self, z, b, out=None):
        """Rows of block ``b`` of ``K z`` (length ``H * W``), into ``out`` if given.

        The anchored rows are summed tap by tap over bands of image rows (about 512 kB of values each), so that
        the partial sums stay in cache; the rows outside the anchor region are zero.
        """
        img = self._as_image(z)
        H, W = self.grid_shape
        out = np.empty((H, W)) if out is None else out.reshape(H, W)
        ys, xs = self._regions[b]
        out[:ys.start] = 0.0
        out[ys.stop:] = 0.0
        out[ys, :xs.start] = 0.0
        out[ys, xs.stop:] = 0.0
        (first_offset, first_coef), *taps = self.blocks[b]
        band = rows_per_band(W, memory_limits().operator_band_values)
        work = np.empty((min(band, max(ys.stop - ys.start, 0)), max(xs.stop - xs.start, 0)))
        for band_rows in row_bands(ys.start, ys.stop, band):
            rows = (band_rows, xs)
            view = out[rows]
            np.multiply(img[_shifted(rows, first_offset)], first_coef, out=view)
            term = work[:view.shape[0]]
            for offset, coef in taps:
                np.multiply(img[_shifted(rows, offset)], coef, out=term)
                view += term
        return out.reshape(-1)

    def block_rmatvec_add(self, out, b, v):
        """``out += K_bᵀ v`` for the rows ``v`` (length ``H * W``) of block ``b``; returns ``out``."""
        target = out.reshape(self.grid_shape)
        region = self._regions[b]
        src = np.asarray(v, dtype=np.float64).reshape(self.grid_shape)[region]
        for offset, coef in self.blocks[b]:
            target[_shifted(region, offset)] += coef * src
        return out

    def row_pieces(self, z):
        """``K z`` in pieces ``(rows, values)`` that cover every row once (``rows`` a slice): here one block each.

        ``values`` is a work array the next piece reuses (copy it to keep it).
        """
        n = self.shape[1]
        work = np.empty(n)
        for b in range(len(self.blocks)):
            yield slice(b * n, (b + 1) * n), self.block_matvec(z, b, out=work)

    def matvec(self, z):
        """``K z`` for a vector of length ``H * W``; returns length ``n_blocks * H * W``."""
        n = self.shape[1]
        out = np.empty(self.shape[0])
        for b in range(len(self.blocks)):
            self.block_matvec(z, b, out=out[b * n:(b + 1) * n])
        return out

    def rmatvec(self, v):
        """``Kᵀ v`` for a vector of length ``n_blocks * H * W``."""
        v = np.asarray(v, dtype=np.float64)
        if v.ndim != 1 or v.shape[0] != self.shape[0]:
            raise ValueError(f"expected a vector of length {self.shape[0]}, got shape {v.shape}")
        n = self.shape[1]
        out = np.zeros(n)
        for b in range(len(self.blocks)):
            self.block_rmatvec_add(out, b, v[b * n:(b + 1) * n])
        return out

    def __matmul__(self, z):
        return self.matvec(z)

    def offsets(self):
        """Offsets ``(dy, dx)`` of :math:`K^\\top K`, sorted (lexicographic = CSR column order)."""
        out = {(0, 0)}
        for block in self.blocks:
            for (oi, _) in block:
                for (ok, _) in block:
                    out.add((ok[0] - oi[0], ok[1] - oi[1]))
        return sorted(out)

    def add_normal_stencil(self, stencil, offsets, row_weights=None, scale=1.0, *, symmetric=False):
        r"""Accumulate ``scale · Kᵀ diag(r) K`` into stencil images, in place.

        Row ``p`` of block ``b`` contributes
        :math:`\mathrm{scale}\; r_p\, c_i c_k` to the coupling of pixels
        ``p + o_i`` and ``p + o_k``, i.e. to the image of offset
        ``o_k − o_i`` at pixel ``p + o_i``: one whole-array operation per
        pair of taps.

        Parameters
        ----------
        stencil : ndarray, shape (len(offsets), H, W)
            ``stencil[j, y, x]`` is the coupling of pixel ``(y, x)`` with
            ``(y, x) + offsets[j]``; updated in place.  C-contiguous.
        offsets : list of tuple of int
            Must contain :meth:`offsets` (with ``symmetric``: those ``>= (0, 0)``).
        row_weights : ndarray, shape (n_blocks * H * W,), optional
            ``r`` (default ones); or an object whose slices within one block are that block's weights (the
            lazily computed weights of :mod:`sparsedepth.grid.edges`), read a block at a time.
        scale : float
        symmetric : bool, default False
            Write only the couplings at offsets ``>= (0, 0)`` (the stored half
            of a :class:`~sparsedepth.grid.stencil.SymmetricStencil`); the
            others are their mirrors (the pair of taps taken the other way round).

        Raises
        ------
        ValueError
            If ``stencil`` is not a C-contiguous array.

        Notes
        -----
        The stencil is written a band of its rows at a time (about ``operator_band_values`` values, the
        :class:`~sparsedepth.limits.MemoryLimits` field).  A pair's rows of a band are added as one contiguous
        run of the flat image (whole grid rows, the columns outside the block's anchor region adding zeros),
        since NumPy adds a strided two-dimensional view several times slower than a contiguous run.  The
        weighted row :math:`(\mathrm{scale}\, c_i c_k)\, r_p` of a band (:math:`r_p = 1` without row weights)
        is formed once per distinct value of the coefficient :math:`\mathrm{scale}\, c_i c_k` of a block (a
        three-tap second difference has three such values for its nine pairs) and added at the place of every
        pair with that value.  Each stencil value receives its terms in the order of the blocks and pairs, as
        in one pass over the whole grid, so the images do not depend on the band height.
        """
        slot = {o: j for j, o in enumerate(offsets)}
        H, W = self.grid_shape
        n = H * W
        images = _flat_images(stencil)
        if row_weights is None:
            weights = [None] * len(self.blocks)
        elif isinstance(row_weights, (np.ndarray, list, tuple)):
            weights = list(np.asarray(row_weights, dtype=np.float64).reshape((len(self.blocks), H, W)))
        else:  # weights computed when read (grid.edges): one block at a time
            weights = [np.asarray(row_weights[b * n:(b + 1) * n], dtype=np.float64).reshape(H, W)
                       for b in range(len(self.blocks))]
        # per block: its anchor region, its pairs of taps (target shift, offset, coefficient) in the order of
        # the taps, and the distinct coefficients among them
        plans = []
        for b, (block, region) in enumerate(zip(self.blocks, self._regions)):
            if region[0].stop == 0:
                continue
            pairs = [(oi, (ok[0] - oi[0], ok[1] - oi[1]), scale * ci * ck)
                     for oi, ci in block for ok, ck in block
                     if not (symmetric and (ok[0] - oi[0], ok[1] - oi[1]) < (0, 0))]
            if pairs:
                # the distinct coefficients, told apart by their bits (float.hex)
                coefficients = {coefficient.hex(): coefficient for _, _, coefficient in pairs}
                plans.append((weights[b], region, pairs, coefficients))
        band = rows_per_band(W, memory_limits().operator_band_values)
        for band_rows in row_bands(0, H, band):
            y0, y1 = band_rows.start, band_rows.stop
            for weight, (ys, xs), pairs, coefficients in plans:
                shifts = [oi[0] for oi, _, _ in pairs]
                # the anchor rows a0 .. a1 - 1 whose row of some pair lands on the band's rows
                a0, a1 = max(ys.start, y0 - max(shifts)), min(ys.stop, y1 - min(shifts))
                if a1 <= a0:
                    continue
                rows = np.ones((a1 - a0, W)) if weight is None else weight[a0:a1]
                weighted = {}
                for key, coefficient in coefficients.items():
                    values = np.multiply(rows, coefficient)
                    values[:, :xs.start] = 0.0  # outside the anchor columns: a zero for the flat run
                    values[:, xs.stop:] = 0.0
                    weighted[key] = values.reshape(-1)
                for oi, offset, coefficient in pairs:
                    # anchor rows lo .. hi - 1 land on stencil rows lo + oi[0] .. hi - 1 + oi[0], inside the band
                    lo, hi = max(a0, y0 - oi[0]), min(a1, y1 - oi[0])
                    if hi <= lo:
                        continue
                    first, stop = (lo - a0) * W + xs.start, (hi - 1 - a0) * W + xs.stop
                    target = (lo + oi[0]) * W + xs.start + oi[1]
                    images[slot[offset]][target:target + stop - first] += weighted[coefficient.hex()][first:stop]
        return stencil

    def tocsr(self):
        """The same operator as a ``scipy.sparse`` CSR matrix (zero rows kept, no stored zeros)."""
        H, W = self.grid_shape
        n = H * W
        index = np.arange(n).reshape(H, W)
        rows, cols, vals = [], [], []
        for b, (block, region) in enumerate(zip(self.blocks, self._regions)):
            anchors = index[region].ravel()
            for offset, coef in block:
                if coef == 0:
                    continue
                rows.append(anchors + b * n)
                cols.append(index[_shifted(region, offset)].ravel())
                vals.append(np.full(anchors.size, coef))
        if not rows:
            return sp.csr_matrix(self.shape)
        out = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=self.shape)
        out.sum_duplicates()
        out.eliminate_zeros()
        return out

    def __repr__(self):
        return f"StencilOperator(shape={self.grid_shape}, blocks={len(self.blocks)})"


class _AdjointStencilOperator:
    """``Kᵀ`` of a :class:`StencilOperator` (only ``@`` and ``shape``)."""

    def __init__(self, op):
        self._op = op

    @property
    def shape(self):
        return self._op.shape[::-1]

    @property
    def T(self):
        return self._op

    def __matmul__(self, v):
        return self._op.rmatvec(v)


_FORWARD_X = (((0, 0), -1.0), ((0, 1), 1.0))
_FORWARD_Y = (((0, 0), -1.0), ((1, 0), 1.0))


def gradient_stencil(shape) -> StencilOperator:
    """Matrix-free :func:`gradient` (``[∂x; ∂y]``, same rows and boundary rule)."""
    return StencilOperator(shape, [_FORWARD_X, _FORWARD_Y])


def hessian_stencil(shape) -> StencilOperator:
    """Matrix-free :func:`hessian_operator` (``[∂xx; ∂yy; √2 ∂xy]``, same rows)."""
    r2 = np.sqrt(2.0)
    return StencilOperator(shape, [
        (((0, -1), 1.0), ((0, 0), -2.0), ((0, 1), 1.0)),
        (((-1, 0), 1.0), ((0, 0), -2.0), ((1, 0), 1.0)),
        (((0, 0), r2), ((0, 1), -r2), ((1, 0), -r2), ((1, 1), r2)),
    ])
