"""Sparse SPD linear solves: preconditioners and preconditioned conjugate gradients."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, cg

__all__ = ["make_preconditioner", "pcg", "PRECONDITIONERS"]

PRECONDITIONERS = ("jacobi", "amg", "none")


def make_preconditioner(A, kind: str = "amg", *, shape=None):
    """A preconditioner for the SPD matrix ``A`` as a ``LinearOperator``.

    Parameters
    ----------
    A : scipy.sparse matrix, (N, N), symmetric positive definite
    kind : {"amg", "jacobi", "none"}
        ``"amg"``: one V-cycle of a pyamg Ruge–Stüben hierarchy (set up here);
        ``"jacobi"``: ``diag(A)⁻¹``; ``"none"``: identity.
    shape : tuple of int, optional
        Grid shape (unused by these kinds; kept for structured preconditioners).
    """
    n = A.shape[0]
    if kind == "none":
        return None
    if kind == "jacobi":
        d = A.diagonal()
        if np.any(d <= 0):
            raise ValueError("Jacobi preconditioner needs a positive diagonal")
        inv = 1.0 / d
        return LinearOperator((n, n), matvec=lambda x: inv * np.ravel(x), dtype=np.float64)
    if kind == "amg":
        import pyamg

        ml = pyamg.ruge_stuben_solver(sp.csr_matrix(A), max_coarse=300, coarse_solver="splu")
        return ml.aspreconditioner(cycle="V")
    raise ValueError(f"unknown preconditioner {kind!r}; one of {PRECONDITIONERS}")


def pcg(A, b, *, x0=None, M=None, rtol=1e-8, maxiter=None, callback=None):
    """Preconditioned CG for ``A x = b`` stopping at ``‖b − A x‖ ≤ rtol·‖b‖``.

    Returns
    -------
    x : ndarray
    iterations : int
    converged : bool
    relative_residual : float
        ``‖b − A x‖ / ‖b‖`` recomputed at the returned ``x``.
    """
    count = [0]

    def _cb(xk):
        count[0] += 1
        if callback is not None:
            callback(xk)

    bnorm = np.linalg.norm(b)
    if bnorm == 0:
        return np.zeros_like(b), 0, True, 0.0
    x, info = cg(A, b, x0=x0, rtol=rtol, atol=0.0, maxiter=maxiter, M=M, callback=_cb)
    rel = float(np.linalg.norm(b - A @ x) / bnorm)
    return x, count[0], info == 0, rel
