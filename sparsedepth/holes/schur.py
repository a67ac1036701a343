"""The linear solve of the colorization fill: exact elimination plus GMRES on the Schur complement.

:func:`eliminated_sets` chooses the pixels eliminated exactly (the holes and
the known pixels most coupled to them); :func:`solve_schur` factors their
block once with SuperLU and runs GMRES (:func:`sparsedepth.linalg.krylov.gmres`)
on the Schur complement of the other, known, pixels.  The mathematics is in
:func:`sparsedepth.holes.colorization.colorization_fill`, Notes.

May import NumPy, SciPy, :mod:`sparsedepth.linalg` and the other modules of
:mod:`sparsedepth.holes` below :mod:`~sparsedepth.holes.colorization`.
"""

from __future__ import annotations

import concurrent.futures

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from ..linalg.krylov import gmres
from .affinity import box_count
from .ordering import segments

__all__ = [
    "LAYER_MIN_UNKNOWN",
    "STRIP_WIDTH",
    "NEUMANN_TERMS",
    "eliminated_sets",
    "solve_schur",
]

#: Known pixels with at least this many holes in their window are eliminated with the holes.
LAYER_MIN_UNKNOWN = 2
#: The preconditioner sees the eliminated pixels within this many window steps of the iterated ones.
STRIP_WIDTH = 2
#: Terms of the Neumann series of the preconditioner.
NEUMANN_TERMS = 4


def eliminated_sets(known, radius):
    """The pixels eliminated exactly, and the strip of them seen by the preconditioner.

    Returns three boolean (H, W) masks.  ``elim`` holds the holes and the
    known pixels with at least :data:`LAYER_MIN_UNKNOWN` holes in their window
    (the known pixels most strongly coupled to the holes, notably those
    between thin holes); the others form the iterated set ``K``.  ``strip``
    holds the pixels of ``elim`` within :data:`STRIP_WIDTH` window steps of
    ``K``, and ``rim`` the pixels of ``K`` with a pixel of ``elim`` in their
    window.
    """
    hole = ~known
    elim = hole | (known & (box_count(hole, radius) >= LAYER_MIN_UNKNOWN))
    strip = elim & (box_count(~elim, STRIP_WIDTH * radius) > 0)
    rim = ~elim & (box_count(elim, radius) > 0)
    return elim, strip, rim


# ----------------------------------------------------------------------------
# sparse blocks
# ----------------------------------------------------------------------------
def _csr_split_columns(A, split):
    """``(A[:, :split], A[:, split:])`` of a CSR matrix, in one pass over its entries."""
    left = A.indices < split
    counts = np.concatenate(([0], np.cumsum(left, dtype=A.indptr.dtype)))
    indptr_left = counts[A.indptr]
    indptr_right = A.indptr - indptr_left
    right = ~left
    return (
        scipy.sparse.csr_matrix((A.data[left], A.indices[left], indptr_left), shape=(A.shape[0], split)),
        scipy.sparse.csr_matrix((A.data[right], A.indices[right] - split, indptr_right),
                                shape=(A.shape[0], A.shape[1] - split)),
    )


def _csr_submatrix(A, rows, column_map, n_columns):
    """Rows ``rows`` of the CSR matrix ``A``, keeping column ``j`` as ``column_map[j]`` if it is >= 0."""
    start = A.indptr[rows]
    seg, t = segments(A.indptr[rows + 1] - start)
    entries = start[seg] + t
    columns = column_map[A.indices[entries]]
    keep = columns >= 0
    indptr = np.zeros(rows.size + 1, dtype=A.indptr.dtype)
    np.cumsum(np.bincount(seg[keep], minlength=rows.size), out=indptr[1:])
    return scipy.sparse.csr_matrix((A.data[entries[keep]], columns[keep], indptr),
                                   shape=(rows.size, n_columns))


def _factor_rows(B):
    """SuperLU factorisation of the CSR matrix ``B``; ``lu.solve(v, trans="T")`` solves ``B y = v``.

    The CSR arrays of ``B`` (sorted here) are the CSC arrays of ``B^T``.
    ``B`` is a principal submatrix of the system, row diagonally dominant, so
    ``B^T`` is column diagonally dominant: it is factored in the given order,
    without pivoting.
    """
    B.sort_indices()
    Bt = scipy.sparse.csc_matrix((B.data, B.indices, B.indptr), shape=B.shape)
    # No relaxed supernodes and panels of one column: the supernodes of a
    # nested-dissection order of a 2-D grid are small, and SuperLU's defaults
    # (relax 10, panel 20) factor them more slowly; the transposed solve is
    # faster than a solve with a factorisation of B.  Large values are unsafe:
    # relax=100, panel_size=40 crashes SciPy 1.17's SuperLU.
    return scipy.sparse.linalg.splu(
        Bt, permc_spec="NATURAL", diag_pivot_thresh=0.0, relax=1, panel_size=1,
        options={"SymmetricMode": True},
    )


# ----------------------------------------------------------------------------
# the solve
# ----------------------------------------------------------------------------
def _factor_in_worker(A_EE, A_EK, b_E, x0):
    """Start factorising ``A_EE`` and lifting ``x0`` in a worker thread; returns the future.

    The future's result is ``(lu, A_EE^{-1} (b_E - A_EK x0))``, the lift of
    the initial guess (which is affine).  SuperLU releases the GIL, so the
    calling thread can meanwhile assemble the other blocks.
    """
    A_EE.sort_indices()  # here, not in the worker: the calling thread reads A_EE meanwhile

    def factor_and_lift_x0():
        lu = _factor_rows(A_EE)
        return lu, lu.solve(b_E - A_EK @ x0, trans="T")

    worker = concurrent.futures.ThreadPoolExecutor(max_workers=1)
    factorisation = worker.submit(factor_and_lift_x0)
    worker.shutdown(wait=False)
    return factorisation


def _strip_correction(A_EE, A_EK, A_K, strip, rim, apply_KK):
    """``z -> (A_KK - A_Ks A_ss^{-1} A_sK) z``, the Schur complement of the strip ``s`` only."""
    n_k = A_EK.shape[1]
    itype = A_K.indices.dtype
    strip_map = np.full(A_K.shape[1], -1, dtype=itype)
    strip_map[strip] = np.arange(strip.size, dtype=itype)
    A_sK = _csr_submatrix(A_EK, strip, np.arange(n_k, dtype=itype), n_k)
    A_Ks = _csr_submatrix(A_K, rim, strip_map, strip.size)
    lu_s = _factor_rows(_csr_submatrix(A_EE, strip, strip_map, strip.size))

    def apply_M(z):
        t = apply_KK(z)
        t[rim] -= A_Ks @ lu_s.solve(A_sK @ z, trans="T")
        return t

    return apply_M


def _neumann_preconditioner(apply_M, diag_K):
    """``NEUMANN_TERMS`` terms of the Neumann series of ``M^{-1}``, ``M = D - P`` with ``P >= 0``, ``D = diag_K``.

    ``z_{j+1} = z_j + (v - M z_j) / D`` from ``z_1 = v / D``.
    """
    def apply_precond(v):
        z0 = v / diag_K
        z = z0.copy()
        for _ in range(NEUMANN_TERMS - 1):
            t = apply_M(z)
            t /= diag_K
            z -= t
            z += z0
        return z

    return apply_precond


def solve_schur(A_E, A_K, b, *, x0, atol, maxiter, diag_K, strip=None, rim=None):
    """Solve ``A x = b`` by exact elimination of the unknowns ``E`` (the first rows and columns).

    ``A_E`` and ``A_K`` (CSR) are the rows of ``A`` of the eliminated pixels
    ``E``, numbered first in a fill-reducing order, and of the others ``K``
    (all known), numbered last; ``A_K`` may instead be a function returning
    them, called while ``A_EE`` is factorised in a worker thread (SuperLU
    releases the GIL, so the two overlap on a multi-core machine).
    ``diag_K`` is the (constant) diagonal of the rows of ``K``; ``x0`` the
    initial guess of ``x_K``.  GMRES runs on the Schur complement of
    ``A_EE`` (see :func:`~sparsedepth.holes.colorization.colorization_fill`),
    preconditioned by :data:`NEUMANN_TERMS` terms of the Neumann series of
    the inverse of ``A_KK - A_Ks A_ss^{-1} A_sK``, the Schur complement of the
    pixels ``strip`` of ``E`` only (indices into ``E``; None or empty:
    ``A_KK`` alone).  ``rim`` (indices into ``K``) must hold every row of
    ``K`` with an entry in the columns of ``strip``.  Returns ``(x,
    residual_history)`` with ``x`` in the order of ``A``.
    """
    n_e, n = A_E.shape
    if n == n_e:  # everything eliminated: a direct solve
        return _factor_rows(A_E).solve(b, trans="T"), np.zeros(0)
    if n_e:
        A_EE, A_EK = _csr_split_columns(A_E, n_e)
        factorisation = _factor_in_worker(A_EE, A_EK, b[:n_e], x0)
    if callable(A_K):
        A_K = A_K()
    b_K = b[n_e:]

    def apply(x_K, x_E):
        # S x_K = A_KK x_K + A_KE x_E with x_E = lift(x_K)
        return A_K @ (x_K if x_E is None else np.concatenate((x_E, x_K)))

    # A_KK z computed as A_K [0; z] (as fast as a separate A_KK, whose
    # extraction would cost more than it saves)
    y = np.zeros(n)
    y_K = y[n_e:]

    def apply_KK(z):
        y_K[:] = z
        return A_K @ y

    lift = lift_x0 = None
    apply_M = apply_KK
    if n_e:
        if strip is not None and strip.size:
            apply_M = _strip_correction(A_EE, A_EK, A_K, strip, rim, apply_KK)
        lu, lift_x0 = factorisation.result()

        def lift(x_K):
            # x_E = -A_EE^{-1} A_EK x_K, the linear part of the lift
            x_E = lu.solve(A_EK @ x_K, trans="T")
            return np.negative(x_E, out=x_E)

    x_K, x_E, history, res_inf, converged = gmres(apply, lift, b_K, x0, _neumann_preconditioner(apply_M, diag_K),
                                                   atol, maxiter, lift_x0=lift_x0)
    if not converged:
        raise RuntimeError(
            f"colorization_fill: GMRES did not reach the tolerance {atol:.3g} in {maxiter} "
            f"iterations (max-norm residual {res_inf:.3g}); increase maxiter or rtol"
        )
    return (x_K if x_E is None else np.concatenate((x_E, x_K))), history
