r"""ADMM's active-set polish: the quadratic model with the tied edges merged, solved exactly.

:func:`polish_active_set` merges the pixels joined by tied rows of ``K``
into components and solves the reduced quadratic model; :func:`merge_by_label`
sums a sparse matrix's entries per pair of components and
:func:`stack_rows` stacks its blocks without holding the result twice.

May import :mod:`sparsedepth.linalg`, :mod:`sparsedepth.grid` and
:mod:`sparsedepth.objective.l1`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..grid.stencil import index_dtype
from ..linalg.krylov import dot, pcg
from ..linalg.preconditioners import make_preconditioner
from ..objective.l1 import graph_components
from ..limits import memory_limits

__all__ = ["polish_active_set", "merge_by_label", "stack_rows"]


def merge_by_label(M, labels, count, *, entries=None, chunk=1 << 16):
    """``Cᵀ M C`` for the indicator ``C`` of ``labels``: the entries of ``M`` summed per pair of labels.

    The pixels are taken in label order, a range of labels with about
    ``chunk`` pixels at a time: their rows of ``M`` with the columns
    relabelled are summed per label by one sparse product, and the blocks of
    rows are stacked.  The work memory is that of one block, not of a copy of
    ``M``'s indices.

    Parameters
    ----------
    M : scipy.sparse matrix, shape (N, N)
    labels : ndarray of int, shape (N,)
        Values ``0 .. count-1``.
    count : int
    entries : callable, optional
        ``entries(block, rows) -> data``: the values to merge in place of the
        block's own (``block`` is ``M[rows]``, CSR); lets the caller merge a
        matrix derived from ``M`` entry by entry without forming it.
    chunk : int
        Pixels per block.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (count, count)
    """
    M = sp.csr_matrix(M)
    n = M.shape[0]
    labels = np.asarray(labels)
    members = np.argsort(labels, kind="stable")
    starts = np.zeros(count + 1, dtype=np.int64)
    np.cumsum(np.bincount(labels, minlength=count), out=starts[1:])
    edges = np.unique(np.searchsorted(starts, np.arange(0, n, max(int(chunk), 1)), side="right") - 1)
    edges = np.append(edges[edges < count], count)
    blocks = []
    for c0, c1 in zip(edges[:-1], edges[1:]):
        p0, p1 = starts[c0], starts[c1]
        rows = members[p0:p1]
        block = M[rows]
        data = block.data if entries is None else entries(block, rows)
        right = sp.csr_matrix((data, labels[block.indices], block.indptr), shape=(p1 - p0, count))
        left = sp.csr_matrix((np.ones(p1 - p0), np.arange(p1 - p0), starts[c0:c1 + 1] - p0), shape=(c1 - c0, p1 - p0))
        blocks.append((left @ right).tocsr())
        del block, data, right, left
    return stack_rows(blocks, count)


def stack_rows(blocks, n_cols):
    """Vertical stack of CSR blocks, each freed once copied (the result is never held twice).

    ``blocks`` (a list) is emptied.
    """
    if len(blocks) == 1:
        return blocks.pop()
    nnz = sum(b.nnz for b in blocks)
    n_rows = sum(b.shape[0] for b in blocks)
    itype = index_dtype(nnz, n_cols)
    data = np.empty(nnz)
    indices = np.empty(nnz, dtype=itype)
    indptr = np.empty(n_rows + 1, dtype=itype)
    indptr[0] = 0
    row = pos = 0
    blocks.reverse()
    while blocks:
        b = blocks.pop()
        m, k = b.shape[0], b.nnz
        data[pos:pos + k] = b.data
        indices[pos:pos + k] = b.indices
        indptr[row + 1:row + m + 1] = b.indptr[1:] + pos
        row, pos = row + m, pos + k
        del b
    return sp.csr_matrix((data, indices, indptr), shape=(n_rows, n_cols))


# over 80 lines only through its docstring (parameters and the maths); the code is ~30 lines
def polish_active_set(A, b, const, l1, u, *, z0, rounds=2, rtol=1e-7, preconditioner="jacobi", penalty=None):
    r"""Active-set polish: the quadratic model with the edges where ``u == 0`` tied and the other signs fixed.

    Parameters
    ----------
    A : scipy.sparse matrix, shape (N, N)
        The quadratic part's matrix, or ADMM's ``S = 2A + ρKᵀK`` with ``penalty = ρ``.
    b : ndarray, shape (N,)
    const : float
        ``F = zᵀAz − 2bᵀz + const + Σ c_k |(Kz)_k|``.
    l1 : StackedL1
        ``K`` and ``c``; every row must be a difference of two pixels.
    u : ndarray, shape (m,)
        Its zeros are the tied rows, its signs the fixed signs of the others.
    z0 : ndarray, shape (N,)
        The PCG start (its component means).
    rounds : int
        Solves at most.
    rtol : float
        Relative residual of each PCG solve.
    preconditioner : {"jacobi", "amg"}
    penalty : float, optional
        ``ρ`` when ``A`` is ``S``.

    Returns
    -------
    None, or the tuple:
    z : ndarray, shape (N,)
        The polished point with the lowest exact ``F``, clipped at 0.
    F : float
        Its objective ``zᵀAz − 2bᵀz + const + Σ c_k |(Kz)_k|``.
    components : int
        Number of components of that polish.
    cg_steps : int
        PCG steps of all rounds.

    Notes
    -----
    Pixels joined by a tied row of ``K`` (:meth:`StackedL1.pixel_pairs`) are
    merged into connected components; with ``C`` the pixel-to-component
    indicator, ``z = C y`` and, for the signs ``s = sign(u)``, the polished
    point solves::

        Cᵀ A C y = Cᵀ(b − ½ Kᵀ(c ⊙ s))

    ``CᵀAC`` is assembled by summing the entries of ``A`` per pair of
    components (:func:`merge_by_label`) and solved by PCG
    (``preconditioner``: ``"jacobi"``, the default, or ``"amg"`` for pyamg
    Ruge–Stüben) to relative residual ``rtol``, warm-started from the
    component means of ``z0``.  ``None`` when ``CᵀAC`` has a diagonal entry
    ``<= 0`` (a component without quadratic coupling: the model is not
    strictly convex).

    A pixel-difference row whose polished value ``t_k`` has ``t_k s_k <= 0``
    contradicts its fixed sign (the minimiser of the model would cross the
    kink of ``|t_k|``); such rows are tied in the next round, whose
    components are merged from the previous ones and whose reduced matrix is
    summed from the previous reduced matrix below
    :attr:`~sparsedepth.limits.MemoryLimits.reduced_matrix_pixels` pixels, from ``A`` again above (never two
    reduced matrices at once), for at most ``rounds`` solves, stopping when no sign is wrong or ``F`` stops
    decreasing.

    With ``penalty = ρ`` the reduced matrix is ``Cᵀ(S − ρKᵀK)C / 2``, the
    entries of ``KᵀK`` computed block by block inside :func:`merge_by_label`
    (:meth:`StackedL1.gram_entries`), and ``zᵀAz = (zᵀSz − ρ‖Kz‖²) / 2``.
    """
    signs = np.zeros(u.shape, dtype=np.int8)  # sign(u) in 1/8 of the memory
    signs[u > 0] = 1
    signs[u < 0] = -1
    labels, count = l1.tied_components(signs == 0)
    A, entries, penalty = _matrix_to_merge(A, l1, penalty)
    reduced = merge_by_label(A, labels, count, entries=entries)
    if not np.all(reduced.diagonal() > 0):
        return None  # a component without quadratic coupling: the model is not strictly convex
    best_F, best_z, best_count, steps = np.inf, None, 0, 0
    z_start = z0
    rounds = max(int(rounds), 1)
    for round_ in range(1, rounds + 1):
        z, F, Kz, n_steps = _solve_reduced(A, b, const, l1, signs, labels, count, reduced, z_start, rtol=rtol,
                                           preconditioner=preconditioner, penalty=penalty)
        steps += n_steps
        if F >= best_F:
            break
        best_F, best_z, best_count = F, z, count
        if round_ == rounds:
            break
        # a fixed sign that the polished difference contradicts (rows that are not pairs have sign 0)
        wrong = ((signs > 0) & (Kz <= 0)) | ((signs < 0) & (Kz >= 0))
        del Kz
        if not wrong.any():
            break
        merged, count = _tie(l1, signs, wrong, labels, count)
        del wrong
        labels = merged[labels]
        if A.shape[0] < memory_limits().reduced_matrix_pixels:  # merge the previous components: smaller than A
            reduced = merge_by_label(reduced, merged, count)
            del merged
        else:  # reduced again from A: the previous reduced matrix is not held alongside the new one (8-MP peak)
            del merged, reduced
            reduced = merge_by_label(A, labels, count, entries=entries)
        z_start = z
    return best_z, best_F, best_count, steps


def _matrix_to_merge(A, l1, penalty):
    """``(M, entries, penalty)`` for :func:`merge_by_label`: the entries of the quadratic part's matrix.

    For ``A = S`` (``penalty = ρ``) and the grid gradient the entries of
    ``(S − ρKᵀK)/2`` are computed block by block; for a general ``K`` that
    matrix is formed once (and ``penalty`` becomes None).
    """
    if penalty is not None and l1.grid_gradient:
        def entries(block, rows):
            return 0.5 * (block.data - penalty * l1.gram_entries(block, rows))

        return A, entries, penalty
    if penalty is not None:
        return ((A - penalty * l1.gram()) * 0.5).tocsr(), None, None
    return A, None, None


def _solve_reduced(A, b, const, l1, signs, labels, count, reduced, z_start, *, rtol, preconditioner, penalty):
    """One polish round: ``(z, F, Kz, cg_steps)`` of the reduced model's PCG solution, ``z`` clipped at 0."""
    sizes = np.bincount(labels, minlength=count)
    pull = l1.adjoint(l1.weighted(signs))
    pull *= -0.5
    pull += b
    rhs = np.bincount(labels, weights=pull, minlength=count)
    del pull
    y0 = np.bincount(labels, weights=z_start, minlength=count) / sizes
    y, n_steps, _, _ = pcg(reduced, rhs, x0=y0, M=make_preconditioner(reduced, preconditioner), rtol=rtol,
                           maxiter=5000)
    z = y[labels]
    np.maximum(z, 0.0, out=z)
    del y
    Kz = l1.apply(z)
    zAz = dot(z, A @ z) if penalty is None else 0.5 * (dot(z, A @ z) - penalty * dot(Kz, Kz))
    F = zAz - 2.0 * dot(b, z) + const + l1.value(Kz)
    return z, F, Kz, n_steps


def _tie(l1, signs, wrong, labels, count):
    """Tie the rows where ``wrong`` is True (``signs`` set to 0 there, in place).

    Returns ``(merged, count)``: the new component of every old component
    (of ``labels``) and their number.
    """
    signs[wrong] = 0
    first, second = l1.pairs_where(wrong)
    return graph_components(count, labels[first], labels[second])
