"""The same objective on a grid twice as coarse per side: the coarse problem of a nested iteration.

:func:`coarsen_objective` rediscretises every term of an
:class:`~sparsedepth.objective.objective.Objective` whose operator is the
identity or a plain :class:`~sparsedepth.grid.operators.StencilOperator`
(the gradient, the Hessian) on the grid of
:func:`~sparsedepth.grid.resample.coarse_shape` (blocks of 2x2 pixels), with
row weights summed over the blocks and scaled by the order of the operator's
differences, so that a smooth depth map and its block means cost about the
same on both grids.  The ADMM solver's ``warm_start="coarse"`` solves it
first and starts from its solution (:mod:`sparsedepth.solvers.admm`).

May import NumPy, :mod:`sparsedepth.grid` and the other modules of :mod:`sparsedepth.objective`.
"""

from __future__ import annotations

import numpy as np

from ..grid.operators import StencilOperator
from ..grid.resample import block_sum, coarse_shape
from .objective import Objective
from .terms import AbsTerm, QuadraticTerm

__all__ = ["coarsen_objective", "difference_order", "COARSENING"]

#: Pixels per side of a coarse block.
COARSENING = 2


def difference_order(taps) -> int:
    """The order ``m`` of a stencil's differences: the first ``k`` with a non-zero moment ``Σ c_t o_t^k``.

    0 for a stencil whose taps do not sum to 0, 1 for a first difference
    (``(0, 0): −1, (0, 1): 1``), 2 for a second or a mixed difference; at
    most 4 (a stencil whose moments up to order 4 all vanish counts as 4).

    Parameters
    ----------
    taps : sequence of ((int, int), float)
        One block of :attr:`StencilOperator.blocks`.
    """
    size = sum(abs(c) for _, c in taps)
    for k in range(4):
        # the moments of order k: Σ c dy^i dx^(k−i), i = 0..k
        if any(abs(sum(c * dy ** i * dx ** (k - i) for (dy, dx), c in taps)) > 1e-12 * size for i in range(k + 1)):
            return k
    return 4


def _coarse_rows(row_weights, target, blocks, shape, power):
    """Per block of rows: the coarse row weights ``Σ_block r / 2^(power·m)`` and the weighted mean target.

    ``blocks`` holds the difference order ``m`` of each block of the operator
    (one block of ``N`` rows for the identity); ``power`` is 2 for a squared
    term, 1 for an absolute one.  The target of a difference of order ``m``
    is ``2^m`` times the mean of the fine targets (the same slope over twice
    the spacing).
    """
    n = shape[0] * shape[1]
    weights, targets = [], []
    for b, order in enumerate(blocks):
        rows = slice(b * n, (b + 1) * n)
        r = np.ones(shape) if row_weights is None else np.asarray(row_weights[rows], dtype=np.float64).reshape(shape)
        total = block_sum(r, COARSENING)
        weights.append(total.ravel() / float(COARSENING) ** (power * order))
        if target is not None:
            d = np.asarray(target[rows], dtype=np.float64).reshape(shape)
            mean = np.divide(block_sum(r * d, COARSENING), total, out=np.zeros_like(total), where=total > 0)
            targets.append(mean.ravel() * float(COARSENING) ** order)
    return np.concatenate(weights), (None if target is None else np.concatenate(targets))


def _plain_stencil(operator):
    """True for a :class:`StencilOperator` itself (fixed taps), not a subclass with per-pixel coefficients."""
    return type(operator) is StencilOperator


def coarsen_objective(objective):
    r"""The objective rediscretised on the grid of 2x2-pixel blocks, or None when its L1 part cannot be.

    Parameters
    ----------
    objective : Objective
        On an ``(H, W)`` grid.

    Returns
    -------
    Objective or None
        On ``coarse_shape((H, W), 2)``, with the same term names and
        weights and ``l1_smoothing``; None when an L1 term's operator is not
        the identity or a plain :class:`StencilOperator`.  Quadratic terms
        with another operator (e.g. the local-linear term) are left out:
        the coarse problem only has to be a good start.

    Notes
    -----
    A term ``weight · Σ_k r_k ρ((K z)_k − d_k)`` with ``ρ(t) = t²`` or
    ``|t|`` keeps its weight and operator (the same taps on the coarse grid)
    and gets per block ``B`` of 2x2 pixels and per block of rows of ``K``
    of difference order ``m`` (:func:`difference_order`)

    .. math::

        r^c_B = 2^{-p m} \sum_{k \in B} r_k, \qquad
        d^c_B = 2^m \frac{\sum_{k \in B} r_k d_k}{\sum_{k \in B} r_k}

    with ``p = 2`` for a squared term and ``p = 1`` for an absolute one
    (the data and prior terms, ``m = 0``: the count of the block's
    observations and their mean).  For a depth map ``z`` smooth on the
    scale of a block, the differences of order ``m`` of its block means on
    the coarse grid (spacing 2) are ``2^m`` times those of ``z``, and each
    coarse row stands for the ``Σ_B`` of its fine rows: the two grids'
    values of the term agree to first order; a jump along a line of ``L``
    pixels costs ``Σ c |jump|`` over ``L`` fine edges and over ``L / 2``
    coarse edges of twice the weight (``p = 1``, ``m = 1``).  The coarse
    row weights are the fine ones summed over the pixels of the block, so
    a low edge weight (an image edge) anywhere in a block lowers the
    coarse edge weight in proportion.
    """
    shape = objective.shape
    cshape = coarse_shape(shape, COARSENING)
    terms = []
    for t in objective.terms:
        if t.weight <= 0:
            continue
        op = t.operator
        if op is not None and not _plain_stencil(op):
            if isinstance(t, AbsTerm):
                return None
            continue
        orders = [0] if op is None else [difference_order(block) for block in op.blocks]
        cop = None if op is None else StencilOperator(cshape, op.blocks)
        if isinstance(t, QuadraticTerm):
            r, d = _coarse_rows(t.row_weights, t.target, orders, shape, 2)
            terms.append(QuadraticTerm(t.name, t.weight, cop, r, d))
        elif isinstance(t, AbsTerm):
            row_weights = t.row_weights
            if row_weights is not None and t.row_weight_blocks() > 1:  # shared by the blocks
                if len(set(orders)) == 1:  # ... of one order: coarsened once, shared on the coarse grid too
                    r, _ = _coarse_rows(row_weights, None, orders[:1], shape, 1)
                    terms.append(AbsTerm(t.name, t.weight, cop, r))
                    continue
                row_weights = np.tile(np.asarray(row_weights, dtype=np.float64), t.row_weight_blocks())
            r, _ = _coarse_rows(row_weights, None, orders, shape, 1)
            terms.append(AbsTerm(t.name, t.weight, cop, r))
        else:
            return None
    return Objective(cshape, terms, l1_smoothing=objective.l1_smoothing)
