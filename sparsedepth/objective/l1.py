"""The stacked L1 operator of an objective, with array-slicing products for the image gradient.

The L1 ("edge") term of the completion objective is ``Σ_k c_k |(K z)_k|``
with ``K`` the forward-difference gradient ``[∂x; ∂y]`` of
:func:`sparsedepth.grid.operators.gradient`.  :class:`StackedL1` stacks the
operators of all L1 terms of an :class:`~sparsedepth.objective.Objective` and
applies ``K`` and ``Kᵀ``; when ``K`` is exactly the grid gradient it does so
by NumPy slicing of the ``(H, W)`` image (a few passes over the array instead
of a sparse product with index look-ups), otherwise by sparse products.
:func:`graph_components` labels the pixels joined by pixel-pair rows.

May import :mod:`sparsedepth.grid`; nothing else of the package.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy import ndimage
from scipy.sparse.csgraph import connected_components

from ..grid.operators import StencilOperator, gradient, gradient_stencil
from ..grid.stencil import index_dtype, stencil_to_csr

__all__ = ["StackedL1", "is_grid_gradient", "graph_components", "CHUNK_ROWS", "STEP_CHUNK_ROWS"]


def is_grid_gradient(K, shape) -> bool:
    """True when the sparse ``K`` equals :func:`~sparsedepth.grid.operators.gradient` of ``shape`` entry by entry.

    Parameters
    ----------
    K : scipy.sparse matrix, shape (m, N)
    shape : tuple of int
        Grid shape ``(H, W)``.
    """
    H, W = shape
    n = H * W
    if K.shape != (2 * n, n):
        return False
    G = gradient(shape)
    if K is G:
        return True
    K = sp.csr_matrix(K)
    if K.nnz != G.nnz:
        return False
    K = K.copy()
    K.sort_indices()
    return bool(
        np.array_equal(K.indptr, G.indptr) and np.array_equal(K.indices, G.indices) and np.array_equal(K.data, G.data)
    )


_LAPLACIAN_OFFSETS = {(-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)}
#: Rows per chunk of the passes over the L1 row weights (:meth:`StackedL1.value`, :meth:`StackedL1.weighted`).
CHUNK_ROWS = 1 << 20
#: Rows per chunk of the fused ADMM edge step: its temporaries (a few float64 chunks) stay in the L2
#: cache, and its dot products stay below the length (10000) from which OpenBLAS's ddot starts threads
#: (a threaded dot product is many times slower than a single-threaded one on a busy machine).
STEP_CHUNK_ROWS = 8192


def _is_gradient_operator(operator, shape) -> bool:
    """True for :func:`~sparsedepth.grid.operators.gradient_stencil` of ``shape`` or a sparse matrix equal to it."""
    if isinstance(operator, StencilOperator):
        return operator.grid_shape == tuple(shape) and operator.blocks == gradient_stencil(shape).blocks
    return sp.issparse(operator) and is_grid_gradient(operator, shape)


def _grid_gradient_pairs(shape):
    """:meth:`StackedL1.pixel_pairs` of the grid gradient, by index arithmetic (int32 when it fits)."""
    H, W = shape
    n = H * W
    dtype = index_dtype(2 * n)
    pixels = np.arange(n, dtype=dtype).reshape(H, W)
    x_first = pixels[:, :-1].reshape(-1)  # rows 0 .. n-1: pixel p and p + 1 (not in the last column)
    y_first = pixels[:-1].reshape(-1)     # rows n .. 2n-1: pixel p and p + W (not in the last row)
    rows = np.concatenate([x_first, y_first + dtype(n)])
    first = np.concatenate([x_first, y_first])
    second = np.concatenate([x_first + dtype(1), y_first + dtype(W)])
    return rows, first, second, True


def graph_components(n, first, second):
    """Connected components of the graph on ``n`` nodes with edges ``first[i]–second[i]``: ``(labels, count)``."""
    graph = sp.csr_matrix((np.ones(first.size), (first, second)), shape=(n, n))
    count, labels = connected_components(graph, directed=False)
    return labels, int(count)


class StackedL1:
    r"""The L1 terms of an objective as one operator ``K`` with row weights ``c``.

    ``Σ_terms weight · Σ_k r_k |(K_term z)_k| = Σ_k c_k |(K z)_k|`` with ``K``
    the vertical stack of the terms' operators and ``c`` the stack of their
    ``weight · r``.

    Parameters
    ----------
    objective : Objective
        With at least one L1 term of positive weight; its operators are
        ``scipy.sparse`` matrices or have a ``tocsr()`` method
        (:class:`~sparsedepth.grid.operators.StencilOperator`).

    Attributes
    ----------
    matrix : scipy.sparse.csr_matrix, shape (m, N)
        ``K`` (built on first access; the grid-gradient fast paths never
        need it).
    weights : ndarray, shape (m,)
        ``c >= 0`` (formed on access; :meth:`value` and :meth:`weighted`
        use the terms' row weights without forming it).
    grid_gradient : bool
        True when ``K`` is the forward-difference gradient of the grid
        (``m = 2N``; products by slicing).
    """

    def __init__(self, objective):
        terms = objective.abs_terms
        if not terms:
            raise ValueError("the objective has no L1 term with a positive weight")
        self.shape = tuple(objective.shape)
        # c is not stored (2N floats): per term its weight and the term's own row weights
        self._row_weights = [(float(t.weight), t.row_weights, t.operator.shape[0]) for t in terms]
        # (weight, r, m): r of shape (m,), or (m / k,) repeated k times (AbsTerm's shared block weights)
        self.grid_gradient = len(terms) == 1 and _is_gradient_operator(terms[0].operator, self.shape)
        # the grid gradient is applied by slicing: its CSR matrix (~88 bytes per pixel) is built only on request
        self._operators = [t.operator for t in terms]
        self._matrix = None
        self._transpose = None
        self._pairs = None

    @property
    def weights(self):
        """``c >= 0``, shape (m,): a new array on every access (kept by nobody between calls)."""
        return np.concatenate([w * (np.ones(m) if r is None else np.tile(r, m // r.shape[0]))
                               for w, r, m in self._row_weights])

    def _weight_chunks(self, chunk=None):
        """``(rows, weight, r[rows])`` in chunks of at most ``chunk`` rows (``r`` None for ones).

        ``chunk`` defaults to :data:`CHUNK_ROWS`, read at the call.
        """
        if chunk is None:
            chunk = CHUNK_ROWS
        start = 0
        for w, r, m in self._row_weights:
            period = m if r is None else r.shape[0]  # r repeats every `period` rows
            for block in range(0, m, max(period, 1)):
                for lo in range(0, min(period, m - block), chunk):
                    hi = min(lo + chunk, period, m - block)
                    yield slice(start + block + lo, start + block + hi), w, (None if r is None else r[lo:hi])
            start += m

    def weight_chunks(self, chunk=None):
        """``(rows, c[rows])`` over all rows, in chunks of at most ``chunk`` rows (default :data:`CHUNK_ROWS`).

        For passes over the rows that need ``c`` without forming it: each
        chunk's weights are a new array of the chunk's length, with the same
        values as :attr:`weights`.
        """
        for rows, w, r in self._weight_chunks(chunk):
            yield rows, (np.full(rows.stop - rows.start, w) if r is None else w * r)

    def max_weight(self) -> float:
        """``max_k c_k`` (0 for an empty ``K``)."""
        return max((w * (1.0 if r is None else float(np.max(r, initial=0.0))) for w, r, m in self._row_weights if m),
                   default=0.0)

    def admm_step(self, Kz, u, lam, *, relax, scale, primal=False, dual=False):
        r"""One ADMM update of the edge variables, in place and in one chunked pass.

        With ``a = relax`` and bounds ``±scale · c`` (``scale = 1/ρ``)::

            x = a Kz + (1 − a) u + λ          (as ((Kz − u) a + u) + λ)
            λ ← clip(x, −scale c, scale c)
            u_new = x − λ                      (the shrinkage of x), written into Kz

        chunk by chunk (``STEP_CHUNK_ROWS`` rows), so that each vector is read or
        written once and ``c`` is never formed.  The same pass sums what the
        solver needs of ``Kz`` before it is overwritten.

        Parameters
        ----------
        Kz : ndarray, shape (m,)
            ``K z``; overwritten with the new ``u``.
        u, lam : ndarray, shape (m,)
            Current ``u`` (read only) and ``λ`` (updated in place).
        relax, scale : float
        primal, dual : bool
            Also return the squared norms the primal residual ``‖Kz − u_new‖``
            and the dual residual ``‖u − u_new‖ / ‖λ_new‖`` need.

        Returns
        -------
        dict
            ``Kz_sq = ‖Kz‖²`` and ``value = Σ c |Kz|`` always; with ``primal``
            ``r_sq = ‖Kz − u_new‖²`` and ``u_sq = ‖u_new‖²``; with ``dual``
            ``s_sq = ‖u − u_new‖²`` and ``lam_sq = ‖λ_new‖²``.
        """
        n = min(STEP_CHUNK_ROWS, Kz.shape[0])
        x, bound, low, work = (np.empty(n) for _ in range(4))
        sums = dict(Kz_sq=0.0, value=0.0)
        if primal:
            sums.update(r_sq=0.0, u_sq=0.0)
        if dual:
            sums.update(s_sq=0.0, lam_sq=0.0)
        for rows, w, r in self._weight_chunks(STEP_CHUNK_ROWS):
            k, u_k, lam_k = Kz[rows], u[rows], lam[rows]
            size = k.shape[0]
            xk, bk, lk, wk = x[:size], bound[:size], low[:size], work[:size]
            sums["Kz_sq"] += float(np.dot(k, k))
            np.abs(k, out=wk)
            if r is None:
                sums["value"] += w * float(np.sum(wk))
                bk.fill(scale * w)
            else:
                sums["value"] += w * float(np.dot(r, wk))
                np.multiply(r, scale * w, out=bk)
            np.subtract(k, u_k, out=xk)
            xk *= relax
            xk += u_k
            xk += lam_k
            np.negative(bk, out=lk)
            np.minimum(xk, bk, out=lam_k)  # clip to [−b, b] by two ufuncs (np.clip's wrapper costs more here)
            np.maximum(lam_k, lk, out=lam_k)
            xk -= lam_k  # u_new
            if primal:
                np.subtract(k, xk, out=wk)
                sums["r_sq"] += float(np.dot(wk, wk))
                sums["u_sq"] += float(np.dot(xk, xk))
            if dual:
                np.subtract(u_k, xk, out=wk)
                sums["s_sq"] += float(np.dot(wk, wk))
                sums["lam_sq"] += float(np.dot(lam_k, lam_k))
            k[...] = xk
        return sums

    def weighted(self, v):
        """``c ⊙ v`` as a new float64 array (without forming ``c``)."""
        out = np.empty(v.shape[0])
        for rows, w, r in self._weight_chunks():
            np.multiply(v[rows], w, out=out[rows])
            if r is not None:
                out[rows] *= r
        return out

    @property
    def matrix(self):
        """``K`` as a CSR matrix, shape (m, N) (built on first access)."""
        if self._matrix is None:
            ops = [op if sp.issparse(op) else op.tocsr() for op in self._operators]
            self._matrix = sp.csr_matrix(ops[0]) if len(ops) == 1 else sp.vstack(ops, format="csr")
        return self._matrix

    @property
    def rows(self) -> int:
        n = self.shape[0] * self.shape[1]
        return 2 * n if self.grid_gradient else self.matrix.shape[0]

    def apply(self, z, out=None):
        """``K z`` for ``z`` of shape (N,); returns shape (m,), written into ``out`` if given."""
        if not self.grid_gradient:
            if out is None:
                return self.matrix @ z
            out[...] = self.matrix @ z
            return out
        H, W = self.shape
        n = H * W
        z2 = np.asarray(z, dtype=np.float64).reshape(H, W)
        t = np.empty(2 * n) if out is None else out
        tx = t[:n].reshape(H, W)
        ty = t[n:].reshape(H, W)
        np.subtract(z2[:, 1:], z2[:, :-1], out=tx[:, :-1])
        tx[:, -1] = 0.0
        np.subtract(z2[1:], z2[:-1], out=ty[:-1])
        ty[-1] = 0.0
        return t

    def adjoint(self, v):
        """``Kᵀ v`` for ``v`` of shape (m,); returns shape (N,)."""
        if not self.grid_gradient:
            if self._transpose is None:
                self._transpose = self.matrix.T.tocsr()
            return self._transpose @ v
        H, W = self.shape
        n = H * W
        vx = v[:n].reshape(H, W)[:, :-1]  # the rows of the last column / row are zero
        vy = v[n:].reshape(H, W)[:-1]
        out = np.empty((H, W))
        np.negative(vx, out=out[:, :-1])
        out[:, -1] = 0.0
        out[:, 1:] += vx
        out[:-1] -= vy
        out[1:] += vy
        return out.reshape(-1)

    def masked_normal_product(self, v, mask):
        """``Kᵀ (mask ⊙ K v)`` for ``v`` of shape (N,) and ``mask`` (bool) of shape (m,); returns shape (N,).

        The product with ``K_Tᵀ K_T`` for the rows ``T`` where ``mask`` is
        True.  For the grid gradient one axis at a time by slicing (no
        temporary as long as ``K v``), bit for bit equal to
        ``adjoint(mask * apply(v))``.
        """
        if not self.grid_gradient:
            t = self.apply(v)
            t *= mask
            return self.adjoint(t)
        H, W = self.shape
        n = H * W
        v2 = np.asarray(v, dtype=np.float64).reshape(H, W)
        out = np.zeros((H, W))
        d = np.subtract(v2[:, 1:], v2[:, :-1])
        d *= mask[:n].reshape(H, W)[:, :-1]
        out[:, :-1] -= d
        out[:, 1:] += d
        d = np.subtract(v2[1:], v2[:-1])
        d *= mask[n:].reshape(H, W)[:-1]
        out[:-1] -= d
        out[1:] += d
        return out.reshape(-1)

    def squared_adjoint(self, v):
        """``(K ∘ K)ᵀ v`` (``K ∘ K`` the entrywise square of ``K``) for ``v`` of shape (m,); returns shape (N,).

        For a 0/1 ``v`` marking rows of pixel differences ``±1`` this is, per
        pixel, the number of marked rows it is in (the diagonal of
        ``Kᵀ diag(v) K``).  For the grid gradient by slicing, as :meth:`adjoint`.
        """
        if not self.grid_gradient:
            K = self.matrix
            return np.asarray(K.multiply(K).T @ np.asarray(v, dtype=np.float64)).ravel()
        H, W = self.shape
        n = H * W
        v = np.asarray(v)  # a boolean v is read as 0/1 without a float copy
        vx = v[:n].reshape(H, W)[:, :-1]  # the rows of the last column / row are zero
        vy = v[n:].reshape(H, W)[:-1]
        out = np.zeros((H, W))
        out[:, :-1] += vx
        out[:, 1:] += vx
        out[:-1] += vy
        out[1:] += vy
        return out.reshape(-1)

    def clip(self, v):
        """``v`` clipped to ``[−c, c]`` in place (chunk by chunk, without forming ``c``); returns ``v``."""
        for rows, c in self.weight_chunks():
            part = v[rows]
            np.minimum(part, c, out=part)
            np.negative(c, out=c)
            np.maximum(part, c, out=part)
        return v

    def gram(self, offsets=None):
        """``KᵀK`` as a CSR matrix (the 5-point Neumann Laplacian for the grid gradient).

        Parameters
        ----------
        offsets : list of tuple of int, optional
            For the grid gradient: the result is stored in the full in-grid
            pattern (:func:`~sparsedepth.grid.stencil.stencil_to_csr`) of these
            offsets joined with the 5-point ones; pass those of a matrix ``A``
            in that pattern that has the 5-point offsets and ``KᵀK`` has
            exactly ``A``'s ``indptr`` and ``indices``, so ``a A + b KᵀK`` is
            one vector operation.  Default: the 5 offsets.  Ignored for a
            general ``K`` (sparse product).
        """
        if not self.grid_gradient:
            K = self.matrix
            return (K.T @ K).tocsr()
        offsets = sorted(_LAPLACIAN_OFFSETS.union(() if offsets is None else offsets))
        stencil = np.zeros((len(offsets),) + self.shape)
        gradient_stencil(self.shape).add_normal_stencil(stencil, offsets)
        return stencil_to_csr(offsets, stencil)

    def value(self, Kz) -> float:
        """``Σ_k c_k |(K z)_k|`` from ``K z`` (in chunks: no temporary as long as ``K z``)."""
        total = 0.0
        for rows, w, r in self._weight_chunks():
            a = np.abs(Kz[rows])
            total += w * float(np.sum(a) if r is None else np.dot(r, a))
        return total

    def tied_components(self, tied):
        """Connected components of the pixels joined by the pixel-pair rows where ``tied`` is True.

        Parameters
        ----------
        tied : ndarray of bool, shape (m,)
            Rows of ``K``; rows that are not pixel differences are ignored.

        Returns
        -------
        labels : ndarray of int, shape (N,)
            Component of every pixel, ``0 .. count-1``.
        count : int

        Notes
        -----
        For the grid gradient the pixels and the tied edges are drawn on a
        ``(2H-1, 2W-1)`` boolean image (pixel ``(y, x)`` at ``(2y, 2x)``, the
        edge to its right neighbour at ``(2y, 2x+1)``, to the one below at
        ``(2y+1, 2x)``) and labelled by :func:`scipy.ndimage.label` with
        4-connectivity: about 20 bytes per pixel, where a graph of up to
        ``2N`` edges for :func:`scipy.sparse.csgraph.connected_components`
        takes several times that.
        """
        tied = np.asarray(tied, dtype=bool)
        if not self.grid_gradient:
            rows, first, second, _ = self.pixel_pairs()
            sel = tied[rows]
            return graph_components(self.shape[0] * self.shape[1], first[sel], second[sel])
        H, W = self.shape
        n = H * W
        sites = np.zeros((2 * H - 1, 2 * W - 1), dtype=bool)
        sites[::2, ::2] = True
        sites[::2, 1::2] = tied[:n].reshape(H, W)[:, :-1]
        sites[1::2, ::2] = tied[n:].reshape(H, W)[:-1]
        image, count = ndimage.label(sites)
        del sites
        labels = image[::2, ::2].reshape(-1)
        labels -= 1
        return labels, int(count)

    def gram_entries(self, block, rows):
        """Values of ``KᵀK`` (the grid gradient's 5-point Laplacian) at the stored entries of ``block``.

        Parameters
        ----------
        block : scipy.sparse CSR matrix, shape (len(rows), N)
            Rows ``rows`` of a matrix on the grid (e.g. ``S[rows]``).
        rows : ndarray of int
            Their pixel indices.

        Returns
        -------
        ndarray, shape (block.nnz,)
            ``−1`` where the column is a 4-neighbour of the row's pixel, the
            pixel's number of in-grid neighbours on the diagonal, 0 elsewhere
            (decided from grid coordinates, for any stencil radius and width).
        """
        if not self.grid_gradient:
            raise ValueError("gram_entries needs the grid gradient")
        H, W = self.shape
        counts = np.diff(block.indptr)
        row_y, row_x = np.divmod(np.repeat(np.asarray(rows, dtype=np.int64), counts), W)
        col_y, col_x = np.divmod(block.indices.astype(np.int64), W)
        distance = np.abs(row_y - col_y) + np.abs(row_x - col_x)
        out = -(distance == 1).astype(np.float64)
        diagonal = distance == 0
        y, x = row_y[diagonal], row_x[diagonal]
        out[diagonal] = (x > 0).astype(np.float64) + (x < W - 1) + (y > 0) + (y < H - 1)
        return out

    def pairs_where(self, mask):
        """The two pixels of each pixel-pair row where ``mask`` (bool, shape (m,)) is True: ``(first, second)``."""
        mask = np.asarray(mask, dtype=bool)
        if not self.grid_gradient:
            rows, first, second, _ = self.pixel_pairs()
            sel = mask[rows]
            return first[sel], second[sel]
        H, W = self.shape
        n = H * W
        x_rows = mask[:n].reshape(H, W).copy()
        x_rows[:, -1] = False  # the last column's rows are empty
        x_first = np.flatnonzero(x_rows)
        y_first = np.flatnonzero(mask[n:n + (H - 1) * W])  # the last row's rows are empty
        return np.concatenate([x_first, y_first]), np.concatenate([x_first + 1, y_first + W])

    @property
    def exact_pairs(self) -> bool:
        """:meth:`pixel_pairs`' ``exact`` flag, without forming the pairs for the grid gradient."""
        return True if self.grid_gradient else self.pixel_pairs()[3]

    def pixel_pairs(self):
        """Rows of ``K`` that are differences of two pixels.

        For the grid gradient by index arithmetic (int32 indices when they
        fit, nothing kept between calls); otherwise read from the rows of
        :attr:`matrix` once and cached.

        Returns
        -------
        rows : ndarray of int
            Rows with exactly two entries ``(−a, a)``, ``a ≠ 0``.
        first, second : ndarray of int
            Their two pixels.
        exact : bool
            True when every non-empty row of ``K`` is such a difference, i.e.
            ``(K z)_k = 0`` means ``z_first = z_second`` for every row.
        """
        if self.grid_gradient:
            return _grid_gradient_pairs(self.shape)
        if self._pairs is not None:
            return self._pairs
        K = self.matrix
        counts = np.diff(K.indptr)
        rows = np.flatnonzero(counts == 2)
        start = K.indptr[rows]
        a, b = K.data[start], K.data[start + 1]
        is_difference = (a == -b) & (a != 0)
        exact = bool(np.all(is_difference)) and not np.any(counts > 2) and not np.any(counts == 1)
        rows = rows[is_difference]
        start = start[is_difference]
        self._pairs = (rows, K.indices[start], K.indices[start + 1], exact)
        return self._pairs
