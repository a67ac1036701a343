"""The stacked L1 operator of an objective, with array-slicing products for the image gradient.

The L1 ("edge") term of the completion objective is ``Σ_k c_k |(K z)_k|``
with ``K`` the forward-difference gradient ``[∂x; ∂y]`` of
:func:`sparsedepth.operators.gradient`.  :class:`StackedL1` stacks the
operators of all L1 terms of an :class:`~sparsedepth.objective.Objective` and
applies ``K`` and ``Kᵀ``; when ``K`` is exactly the grid gradient it does so
by NumPy slicing of the ``(H, W)`` image (a few passes over the array instead
of a sparse product with index look-ups), otherwise by sparse products.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .operators import gradient

__all__ = ["StackedL1", "is_grid_gradient"]


def is_grid_gradient(K, shape) -> bool:
    """True when the sparse ``K`` equals :func:`~sparsedepth.operators.gradient` of ``shape`` entry by entry.

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
        (:class:`~sparsedepth.operators.StencilOperator`).

    Attributes
    ----------
    matrix : scipy.sparse.csr_matrix, shape (m, N)
        ``K``.
    weights : ndarray, shape (m,)
        ``c >= 0``.
    grid_gradient : bool
        True when ``K`` is the forward-difference gradient of the grid
        (``m = 2N``; products by slicing).
    """

    def __init__(self, objective):
        terms = objective.abs_terms
        if not terms:
            raise ValueError("the objective has no L1 term with a positive weight")
        operators = [t.operator if sp.issparse(t.operator) else t.operator.tocsr() for t in terms]
        K = sp.csr_matrix(operators[0]) if len(operators) == 1 else sp.vstack(operators, format="csr")
        self.matrix = K
        self.weights = np.concatenate([t.scaled_row_weights() for t in terms])
        self.shape = tuple(objective.shape)
        self.grid_gradient = is_grid_gradient(K, self.shape)
        self._transpose = None
        self._pairs = None

    @property
    def rows(self) -> int:
        return self.matrix.shape[0]

    def apply(self, z):
        """``K z`` for ``z`` of shape (N,); returns shape (m,)."""
        if not self.grid_gradient:
            return self.matrix @ z
        H, W = self.shape
        n = H * W
        z2 = np.asarray(z, dtype=np.float64).reshape(H, W)
        t = np.empty(2 * n)
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

    def gram(self):
        """``KᵀK`` as a CSR matrix (the 5-point Neumann Laplacian for the grid gradient)."""
        K = self.matrix
        return (K.T @ K).tocsr()

    def value(self, Kz) -> float:
        """``Σ_k c_k |(K z)_k|`` from ``K z``."""
        return float(np.einsum("i,i->", self.weights, np.abs(Kz)))

    def pixel_pairs(self):
        """Rows of ``K`` that are differences of two pixels (computed once).

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
