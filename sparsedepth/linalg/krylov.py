"""Sparse SPD linear solves: preconditioners and preconditioned conjugate gradients."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator

__all__ = ["make_preconditioner", "pcg", "PRECONDITIONERS"]

PRECONDITIONERS = ("grid", "jacobi", "amg", "none")


def make_preconditioner(A, kind: str = "amg", *, shape=None):
    """A preconditioner for the SPD matrix ``A`` as a ``LinearOperator``.

    Parameters
    ----------
    A : scipy.sparse matrix, (N, N), symmetric positive definite
    kind : {"grid", "amg", "jacobi", "none"} or GridMultigrid
        ``"grid"``: one symmetric V-cycle of a geometric
        :class:`~sparsedepth.linalg.multigrid.GridMultigrid` (``interpolation="auto"``) built here (needs
        ``shape``; ``A`` must be a grid operator of stencil radius <= 2, which
        the quadratic part of every completion objective is);
        ``"amg"``: one V-cycle of a pyamg Ruge–Stüben hierarchy (set up here);
        ``"jacobi"``: ``diag(A)⁻¹``; ``"none"``: identity.  An already built
        ``GridMultigrid`` (e.g. after :meth:`~GridMultigrid.update`) is used
        as is.
    shape : tuple of int, optional
        Grid shape ``(H, W)`` with ``H * W = N``; required for ``"grid"``.

    Returns
    -------
    LinearOperator or None
        ``None`` for ``"none"``.

    Raises
    ------
    ValueError
        For an unknown kind, ``"grid"`` without ``shape``, or a non-positive
        diagonal with ``"jacobi"``.
    """
    from .multigrid import GridMultigrid

    n = A.shape[0]
    if isinstance(kind, GridMultigrid):
        return kind.aspreconditioner()
    if kind == "none":
        return None
    if kind == "jacobi":
        d = A.diagonal()
        if np.any(d <= 0):
            raise ValueError("Jacobi preconditioner needs a positive diagonal")
        inv = 1.0 / d
        return LinearOperator((n, n), matvec=lambda x: inv * np.ravel(x), dtype=np.float64)
    if kind == "grid":
        if shape is None:
            raise ValueError("preconditioner 'grid' needs the grid shape: pass shape=(H, W)")
        return GridMultigrid(A, shape, interpolation="auto").aspreconditioner()
    if kind == "amg":
        import pyamg

        ml = pyamg.ruge_stuben_solver(sp.csr_matrix(A), max_coarse=300, coarse_solver="splu")
        return ml.aspreconditioner(cycle="V")
    raise ValueError(f"unknown preconditioner {kind!r}; one of {PRECONDITIONERS}")


def dot(x, y):
    # einsum runs its own loop instead of BLAS ddot: multithreaded OpenBLAS on
    # a busy 2-core machine made one 600k-long dot product cost ~8 ms instead
    # of 0.1 ms (measured), i.e. more than a V-cycle.
    return float(np.einsum("i,i->", x, y))


def _as_apply(M):
    if M is None:
        return None
    if hasattr(M, "matvec"):
        return M.matvec
    if callable(M):
        return M
    return lambda r: M @ r


def pcg(A, b, *, x0=None, M=None, rtol=1e-8, atol=0.0, maxiter=None, callback=None, callback_residual=False):
    r"""Preconditioned CG for ``A x = b`` stopping at ``‖b − A x‖ ≤ max(rtol·‖b‖, atol)``.

    Parameters
    ----------
    A : scipy.sparse matrix or LinearOperator, (N, N), SPD
    b : ndarray, (N,)
    x0 : ndarray, (N,), optional
        Starting point (zero by default); not modified.
    M : LinearOperator, callable or None
        Applies the preconditioner ``M⁻¹ r`` (must be SPD).
    rtol, atol : float
        Relative and absolute tolerances on the *true* residual.
    maxiter : int, optional
        Maximum number of CG iterations; default ``10 N``.
    callback : callable, optional
        ``callback(x)`` after every iteration (``x`` is the live iterate: copy
        it to keep it); ``callback(x, r)`` with the recursively updated
        residual ``r ≈ b − A x`` when ``callback_residual`` is true.

    Returns
    -------
    x : ndarray
    iterations : int
    converged : bool
        ``‖b − A x‖ ≤ max(rtol ‖b‖, atol)`` at the returned ``x``.
    relative_residual : float
        ``‖b − A x‖ / ‖b‖`` recomputed at the returned ``x``.

    Notes
    -----
    Standard preconditioned CG (Hestenes–Stiefel with ``z = M⁻¹ r``).  When
    the recursively updated residual meets the tolerance the true residual
    ``b − A x`` is recomputed; if it does not meet it (rounding drift), CG
    restarts from the true residual, so ``converged`` is never claimed on the
    recursive residual alone.  Dot products avoid BLAS (see ``dot``).
    """
    b = np.asarray(b, dtype=np.float64).ravel()
    n = b.shape[0]
    bnorm = np.sqrt(dot(b, b))
    if bnorm == 0:
        return np.zeros_like(b), 0, True, 0.0
    maxiter = 10 * n if maxiter is None else int(maxiter)
    prec = _as_apply(M)
    x = np.zeros(n) if x0 is None else np.array(x0, dtype=np.float64).ravel()
    r = b - A @ x if x0 is not None else b.copy()
    target2 = max(rtol * bnorm, float(atol)) ** 2
    rr = dot(r, r)
    it = 0
    converged = rr <= target2
    restarts = 0
    while not converged and it < maxiter:
        z = r if prec is None else prec(r)
        rz = dot(r, z)
        p = z.copy()
        del z  # (here and below) drop work vectors early: peak memory of 8-MP frames
        while it < maxiter:
            q = A @ p
            pq = dot(p, q)
            if not pq > 0:
                break  # breakdown: A or M not SPD (or exact solution reached)
            step = rz / pq
            x += step * p
            q *= step
            r -= q
            del q
            it += 1
            if callback is not None:
                if callback_residual:
                    callback(x, r)
                else:
                    callback(x)
            rr = dot(r, r)
            if rr <= target2:
                break
            z = r if prec is None else prec(r)
            rz_new = dot(r, z)
            p *= rz_new / rz
            p += z
            del z
            rz = rz_new
        r = b - A @ x
        rr = dot(r, r)
        converged = rr <= target2
        restarts += 1
        if not converged and (restarts > 5 or not pq > 0):
            break
    return x, it, bool(converged), float(np.sqrt(rr) / bnorm)
