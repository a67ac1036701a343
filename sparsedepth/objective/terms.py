"""The terms of the completion objective: data, each a weight, a sparse operator and row weights.

* :class:`QuadraticTerm`  ``weight · Σ_k r_k ((K z)_k − d_k)²``
* :class:`AbsTerm`        ``weight · Σ_k r_k |(K z)_k|``
* :class:`RobustTerm`     ``weight · Σ_k r_k φ((K z)_k)``, ``φ`` a robust penalty (:mod:`.robust`)

A term knows its value, its (smoothed) gradient and, for a quadratic term,
its contribution ``weight · Kᵀ diag(r) K`` to the normal equations; the sum of
terms is :class:`~sparsedepth.objective.objective.Objective`.

May import NumPy, SciPy, :mod:`sparsedepth.grid`, :mod:`sparsedepth._validation` and :mod:`.robust`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
import scipy.sparse as sp

from ..grid.operators import StencilOperator
from ..grid.stencil import stencil_to_csr
from .._validation import check_positive_real
from .robust import robust_penalty

__all__ = ["QuadraticTerm", "AbsTerm", "RobustTerm"]


def _apply(operator, z):
    return z if operator is None else operator @ z


def _apply_adjoint(operator, v):
    return v if operator is None else operator.T @ v


@dataclass(frozen=True, eq=False)
class QuadraticTerm:
    """``weight · Σ_k r_k ((K z)_k − d_k)²``.

    Parameters
    ----------
    name : str
        Name used in per-term reports.
    weight : float
        Non-negative scalar weight.
    operator : scipy.sparse matrix or StencilOperator of shape (m, N), or None
        ``K``; ``None`` means the identity (``m = N``).  A
        :class:`~sparsedepth.grid.operators.StencilOperator` is applied matrix-free
        and lets :meth:`Objective.normal_equations` assemble ``KᵀK`` as a
        stencil.
    row_weights : ndarray of shape (m,), or None
        ``r >= 0`` (float, or bool for a 0/1 selection such as the data
        term's observation mask); ``None`` means all ones.  An object with
        ``shape``, slicing and ``__array__`` (e.g.
        :class:`~sparsedepth.grid.edges.PairEdgeWeights`, computed when read)
        serves as well: the term reads it a block of rows at a time.
    target : ndarray of shape (m,), or None
        ``d``; ``None`` means zeros.
    """

    name: str
    weight: float
    operator: Optional[object] = None
    row_weights: Optional[np.ndarray] = None
    target: Optional[np.ndarray] = None

    def residual(self, z):
        t = _apply(self.operator, z)
        return t if self.target is None else t - self.target

    def _block_residuals(self, z):
        """``(rows, K_b z − d_b)`` per block: one ``H*W`` work vector for a StencilOperator."""
        K = self.operator
        if not isinstance(K, StencilOperator):
            yield slice(None), self.residual(z)
            return
        n = K.shape[1]
        work = np.empty(n)
        for b in range(len(K.blocks)):
            rows = slice(b * n, (b + 1) * n)
            K.block_matvec(z, b, out=work)
            if self.target is not None:
                work -= self.target[rows]
            yield rows, work

    def _residual_pieces(self, z):
        """``(rows, K_rows z − d_rows)`` in the pieces of the operator's ``row_pieces`` (a StencilOperator).

        Every piece is an array the caller may overwrite.
        """
        K = self.operator
        if not isinstance(K, StencilOperator):
            residual = self.residual(z)
            yield slice(None), (residual.copy() if np.shares_memory(residual, z) else residual)
            return
        for rows, values in K.row_pieces(z):
            if self.target is not None:
                values -= self.target[rows]
            yield rows, values

    def value(self, z) -> float:
        if self.weight == 0:
            return 0.0
        total = 0.0
        for rows, res in self._residual_pieces(z):
            sq = np.multiply(res, res, out=res)  # each piece is a work array of its own: squared in place
            if self.row_weights is not None:
                sq *= self.row_weights[rows]
            total += float(np.sum(sq))
        return float(self.weight * total)

    def gradient(self, z):
        """``2 · weight · Kᵀ (r ⊙ (K z − d))``."""
        if self.weight == 0:
            return np.zeros_like(z)
        if not isinstance(self.operator, StencilOperator):
            res = self.residual(z)
            if self.row_weights is not None:
                res = res * np.asarray(self.row_weights)
            return 2.0 * self.weight * _apply_adjoint(self.operator, res)
        grad = np.zeros(self.operator.shape[1])
        for b, (rows, res) in enumerate(self._block_residuals(z)):
            if self.row_weights is not None:
                res *= self.row_weights[rows]
            self.operator.block_rmatvec_add(grad, b, res)
        grad *= 2.0 * self.weight
        return grad

    def normal_matrix(self, n: int) -> sp.csr_matrix:
        """Half the Hessian: ``weight · Kᵀ diag(r) K`` (sparse, ``(n, n)``)."""
        r = (np.ones(n if self.operator is None else self.operator.shape[0]) if self.row_weights is None
             else np.asarray(self.row_weights))
        if self.operator is None:
            return sp.diags(self.weight * r, format="csr")
        K = self.operator
        if isinstance(K, StencilOperator):
            offsets = K.offsets()
            stencil = np.zeros((len(offsets),) + K.grid_shape)
            K.add_normal_stencil(stencil, offsets, self.row_weights, self.weight)
            return sp.csr_matrix(stencil_to_csr(offsets, stencil))
        return (K.T @ sp.diags(self.weight * r) @ K).tocsr()

    def normal_rhs(self, n: int):
        """``weight · Kᵀ (r ⊙ d)``: the right-hand side contribution."""
        if self.target is None or self.weight == 0:
            return np.zeros(n)
        d = self.target if self.row_weights is None else np.asarray(self.row_weights) * self.target
        return self.weight * _apply_adjoint(self.operator, d)

    def constant(self) -> float:
        """``weight · Σ r d²``: the value at ``K z = 0``."""
        if self.target is None:
            return 0.0
        d2 = self.target**2
        if self.row_weights is not None:
            d2 = d2 * np.asarray(self.row_weights)
        return float(self.weight * np.sum(d2))


class _SharedRowWeights:
    """The row weights of a non-quadratic term: ``r`` of shape ``(m,)``, or ``(N,)`` shared by the ``m / N`` blocks."""

    def _check_row_weights(self):
        """``ValueError`` unless ``row_weights`` have shape (m,), or (N,) shared by the blocks."""
        if self.row_weights is not None:
            m, n = self.operator.shape
            size = np.shape(self.row_weights)[0] if np.ndim(self.row_weights) == 1 else -1
            if size != m and not (size == n and n > 0 and m % n == 0):
                raise ValueError(f"row_weights of term {self.name!r} must have shape ({m},) or ({n},) "
                                 f"(shared by the {m // max(n, 1)} blocks), got {np.shape(self.row_weights)}")

    def row_weight_blocks(self) -> int:
        """How many times the stored ``row_weights`` repeat along the rows (1 when of shape (m,))."""
        if self.row_weights is None:
            return 1
        return self.operator.shape[0] // np.shape(self.row_weights)[0]

    def scaled_row_weights(self):
        """``weight · r`` as an array of shape (m,)."""
        m = self.operator.shape[0]
        if self.row_weights is None:
            return np.full(m, float(self.weight))
        return self.weight * np.tile(np.asarray(self.row_weights, dtype=np.float64), self.row_weight_blocks())


@dataclass(frozen=True, eq=False)
class AbsTerm(_SharedRowWeights):
    """``weight · Σ_k r_k |(K z)_k|`` (weighted L1 of a linear map of ``z``).

    Parameters
    ----------
    name : str
    weight : float
    operator : scipy.sparse matrix or StencilOperator of shape (m, N)
        ``build_objective`` passes the matrix-free
        :func:`~sparsedepth.grid.operators.gradient_stencil`; the L1 solvers
        recognise it (:class:`~sparsedepth.objective.l1.StackedL1`) and apply it by
        slicing.
    row_weights : ndarray of shape (m,) or (N,), or None
        ``r``; shape ``(N,)`` (with ``m`` a multiple of ``N``, e.g. the two
        blocks of the gradient) means the same weights for every block of
        ``N`` rows, stored once (``build_objective`` passes the edge weights
        of the pixels so: half the memory of the stacked ``r``).
    """

    name: str
    weight: float
    operator: object
    row_weights: Optional[np.ndarray] = None

    def __post_init__(self):
        self._check_row_weights()

    def value(self, z) -> float:
        if self.weight == 0:
            return 0.0
        return float(np.sum(self.scaled_row_weights() * np.abs(self.operator @ z)))

    def smoothed_value(self, z, eps: float) -> float:
        """``weight · Σ r sqrt((K z)² + ε²)``."""
        if self.weight == 0:
            return 0.0
        t = self.operator @ z
        return float(np.sum(self.scaled_row_weights() * np.sqrt(t * t + eps * eps)))

    def smoothed_gradient(self, z, eps: float):
        """``weight · Kᵀ (r ⊙ t / sqrt(t² + ε²))`` with ``t = K z``."""
        if self.weight == 0:
            return np.zeros_like(z)
        t = self.operator @ z
        return self.operator.T @ (self.scaled_row_weights() * t / np.sqrt(t * t + eps * eps))


@dataclass(frozen=True, eq=False)
class RobustTerm(_SharedRowWeights):
    r"""``weight · Σ_k r_k φ((K z)_k)`` with ``φ`` a robust penalty of scale ``s``.

    Parameters
    ----------
    name : str
    weight : float
    operator : scipy.sparse matrix or StencilOperator of shape (m, N)
        ``K`` (``build_objective`` passes the gradient, as for the L1 edge term).
    row_weights : ndarray of shape (m,) or (N,), or None
        ``r``, stored as for :class:`AbsTerm` (shape ``(N,)``: shared by every
        block of ``N`` rows).
    penalty : str, float or RobustPenalty
        A name in :data:`~sparsedepth.objective.robust.PENALTIES` or Barron's
        shape ``a <= 2`` (see :class:`~sparsedepth.objective.robust.RobustPenalty`);
        stored as a :class:`~sparsedepth.objective.robust.RobustPenalty`.
    scale : float
        ``s > 0``, in the units of ``K z`` (depth): differences much smaller
        than ``s`` cost ``t² / (2s)``, larger ones far less than their square.

    Notes
    -----
    The term is smooth.  Its gradient is ``weight · Kᵀ (r ⊙ φ'(K z))``, and at
    ``z₀`` (``t₀ = K z₀``) it is majorised by the quadratic

    .. math::

        \sum_k c_k \left[\varphi(t_{0k}) + \tfrac12 \omega(t_{0k})
        \bigl((Kz)_k^2 - t_{0k}^2\bigr)\right], \qquad c = \mathrm{weight} \cdot r,

    equal to it at ``z₀`` (:meth:`majorizer_weights` returns ``c ⊙ ω(t₀)``).
    """

    name: str
    weight: float
    operator: object
    row_weights: Optional[np.ndarray] = None
    penalty: object = "charbonnier"
    scale: float = 0.05

    def __post_init__(self):
        self._check_row_weights()
        object.__setattr__(self, "penalty", robust_penalty(self.penalty))
        object.__setattr__(self, "scale", check_positive_real(self.scale, name=f"scale of term {self.name!r}"))

    def value(self, z) -> float:
        """``weight · Σ r φ(K z)``."""
        if self.weight == 0:
            return 0.0
        t = self.operator @ z
        return float(np.sum(self.scaled_row_weights() * self.penalty.value(t, self.scale)))

    def gradient(self, z):
        """``weight · Kᵀ (r ⊙ φ'(K z))``."""
        if self.weight == 0:
            return np.zeros_like(z)
        t = self.operator @ z
        return self.operator.T @ (self.scaled_row_weights() * self.penalty.derivative(t, self.scale))

    def majorizer_weights(self, z):
        """``weight · r ⊙ ω(K z)``, shape (m,).

        The quadratic majoriser of the term at ``z`` is ``½ Σ_k (this)_k (K z')_k² + const`` in ``z'``.
        """
        return self.scaled_row_weights() * self.penalty.weight(self.operator @ z, self.scale)
