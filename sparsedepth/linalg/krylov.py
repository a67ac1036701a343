"""Every Krylov loop of the package: preconditioned CG (whole solves and warm-started inner steps) and restarted GMRES."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg

__all__ = ["dot", "pcg", "pcg_info", "PCGResult", "pcg_steps", "gmres"]


def dot(x, y):
    """``xᵀ y`` of two float vectors as a Python float.

    Notes
    -----
    ``einsum`` runs its own single-threaded loop instead of BLAS ``ddot``:
    a multithreaded OpenBLAS on a busy machine can make one dot product of a
    frame's length cost more than a V-cycle, by an amount that depends on
    the other users' load.
    """
    return float(np.einsum("i,i->", x, y))


def _as_apply(M):
    if M is None:
        return None
    if hasattr(M, "matvec"):
        return M.matvec
    if callable(M):
        return M
    return lambda r: M @ r


@dataclass(frozen=True)
class PCGResult:
    """Outcome of :func:`pcg_info`.

    Attributes
    ----------
    x : ndarray, (N,)
        The returned iterate.
    iterations : int
        Number of CG iterations performed (over all restarts).
    converged : bool
        ``‖b − A x‖ ≤ max(rtol ‖b‖, atol)`` at the returned ``x`` (true residual).
    relative_residual : float
        ``‖b − A x‖ / ‖b‖`` recomputed at the returned ``x``.
    residual_norms : ndarray, (iterations + 1,)
        Residual norm at every iterate, starting with ``‖b − A x0‖``: the
        recursively updated residual of CG, except at the end of every CG
        cycle (a restart, a breakdown, a stop, the last iterate), where the
        true residual ``b − A x`` is recomputed and recorded instead.
    breakdown : bool
        ``pᵀ A p ≤ 0`` met before convergence: ``A`` or the preconditioner is
        not symmetric positive definite.
    stopped : bool
        The callback raised ``StopIteration``.
    message : str
        Why the iteration ended.
    rule_met : bool
        The caller's stopping rule (``stop=`` of :func:`pcg_info`) ended the solve.
    """

    x: np.ndarray
    iterations: int
    converged: bool
    relative_residual: float
    residual_norms: np.ndarray
    breakdown: bool
    stopped: bool
    message: str
    rule_met: bool = False


#: CG cycles (each restarted from the recomputed true residual) before rounding drift ends the solve
_MAX_CYCLES = 6


class _RuleMet(Exception):
    """Raised inside a CG cycle when the caller's stopping rule is met."""


def pcg_info(A, b, *, x0=None, M=None, rtol=1e-8, atol=0.0, maxiter=None, callback=None, callback_residual=False,
             stop=None, dtype=np.float64):
    r"""Preconditioned CG for ``A x = b`` stopping at ``‖b − A x‖ ≤ max(rtol·‖b‖, atol)``, with its history.

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
        residual ``r ≈ b − A x`` when ``callback_residual`` is true.  It may
        raise ``StopIteration`` to stop: the result then has ``stopped`` set
        and holds the iterate it was called with.
    stop : callable, optional
        A stopping rule of the caller: ``stop(step, direction)`` after every
        iteration (after ``callback``), where the iterate has just moved by
        ``step * direction`` (``direction`` is live: read it, do not keep
        it).  Returning True ends the solve at that iterate with
        ``rule_met`` set; ``converged`` still reports the residual test.
    dtype : {numpy.float64, numpy.float32}
        The type of the iterate, the residual and the work vectors (``b``
        and ``x0`` are cast to it); ``A`` and ``M`` must return it.
        float32 halves the memory traffic of a solve whose tolerance is far
        above float32 rounding (a relative residual of 1e-4, say); its dot
        products are accumulated in float32 too.

    Returns
    -------
    PCGResult
        The iterate, the iteration count, convergence on the true residual,
        the residual history, breakdown, stop and rule flags and a message.

    Notes
    -----
    Standard preconditioned CG (Hestenes–Stiefel with ``z = M⁻¹ r``).  When
    the recursively updated residual meets the tolerance the true residual
    ``b − A x`` is recomputed; if it does not meet it (rounding drift), CG
    restarts from the true residual (at most 6 cycles in all), so
    ``converged`` is never claimed on the recursive residual alone.  A step
    with ``pᵀ A p ≤ 0`` ends the solve (breakdown, unless the recomputed
    residual meets the target: ``p = 0`` at the exact solution).  For
    ``b = 0`` the exact ``x = 0`` is returned without iterating.  Dot
    products avoid BLAS (see ``dot``).
    """
    dtype = np.dtype(dtype)
    if dtype not in (np.float64, np.float32):
        raise ValueError(f"dtype must be float64 or float32, got {dtype}")
    b = np.asarray(b, dtype=dtype).ravel()
    n = b.shape[0]
    bnorm = np.sqrt(dot(b, b))
    if bnorm == 0:
        return PCGResult(np.zeros_like(b), 0, True, 0.0, np.zeros(1), False, False, "b = 0: x = 0 is exact")
    maxiter = 10 * n if maxiter is None else int(maxiter)
    prec = _as_apply(M)
    x = np.zeros(n, dtype=dtype) if x0 is None else np.array(x0, dtype=dtype).ravel()
    r = b - A @ x if x0 is not None else b.copy()
    target2 = max(rtol * bnorm, float(atol)) ** 2
    rr = dot(r, r)
    norms = [math.sqrt(rr)]
    if callback is None or callback_residual:
        notify = callback
    else:
        def notify(x, r):
            callback(x)
    converged = rr <= target2
    breakdown = stopped = rule_met = False
    cycles = 0
    while not converged and len(norms) - 1 < maxiter:
        try:
            ok = _cg_cycle(A, x, r, prec, target2, maxiter, norms, notify, stop)
        except StopIteration:
            ok, stopped = True, True
        except _RuleMet:
            ok, rule_met = True, True
        r = b - A @ x
        rr = dot(r, r)
        norms[-1] = math.sqrt(rr)
        converged = rr <= target2
        breakdown = not ok and not converged
        cycles += 1
        if stopped or rule_met or breakdown or (not converged and cycles >= _MAX_CYCLES):
            break
    iterations = len(norms) - 1
    message = _pcg_message(converged, stopped, rule_met, breakdown, iterations, maxiter)
    return PCGResult(x, iterations, bool(converged), float(np.sqrt(rr) / bnorm), np.asarray(norms),
                     breakdown, stopped, message, rule_met)


def _pcg_message(converged, stopped, rule_met, breakdown, iterations, maxiter):
    if stopped:
        return "stopped by callback"
    if rule_met:
        return "stopping rule met"
    if converged:
        return "converged"
    if breakdown:
        return "breakdown: pᵀAp <= 0 (A or the preconditioner is not symmetric positive definite)"
    if iterations >= maxiter:
        return f"no convergence in {maxiter} iterations"
    return f"no convergence: the true residual stayed above the target after {_MAX_CYCLES} restarted CG cycles"


def _cg_cycle(A, x, r, prec, target2, maxiter, norms, notify, stop=None):
    """CG steps from ``x`` with residual ``r`` (both updated in place) until ``‖r‖² ≤ target2`` or the budget is spent.

    Appends ``‖r‖`` after every step to ``norms`` (whose length counts the
    iterations) and returns False on breakdown (``pᵀ A p ≤ 0``), else True;
    raises ``_RuleMet`` when ``stop(step, p)`` returns True.
    """
    z = r if prec is None else prec(r)
    rz = dot(r, z)
    p = z.copy()
    del z  # (here and below) drop work vectors early: peak memory of 8-MP frames
    while len(norms) - 1 < maxiter:
        q = A @ p
        pq = dot(p, q)
        if not pq > 0:
            return False
        step = rz / pq
        q *= step
        r -= q
        x += np.multiply(p, step, out=q)  # q's buffer holds step p: no work vector of its own
        del q
        rr = dot(r, r)
        norms.append(math.sqrt(rr))
        if notify is not None:
            notify(x, r)
        if stop is not None and stop(step, p):
            raise _RuleMet
        if rr <= target2:
            return True
        z = r if prec is None else prec(r)
        rz_new = dot(r, z)
        p *= rz_new / rz
        p += z
        del z
        rz = rz_new
    return True


def pcg(A, b, *, x0=None, M=None, rtol=1e-8, atol=0.0, maxiter=None, callback=None, callback_residual=False,
        stop=None):
    r"""Preconditioned CG for ``A x = b`` stopping at ``‖b − A x‖ ≤ max(rtol·‖b‖, atol)``; the tuple form of :func:`pcg_info`.

    Parameters
    ----------
    A, b, x0, M, rtol, atol, maxiter, callback, callback_residual, stop
        As for :func:`pcg_info`.

    Returns
    -------
    x : ndarray
    iterations : int
    converged : bool
        ``‖b − A x‖ ≤ max(rtol ‖b‖, atol)`` at the returned ``x``.
    relative_residual : float
        ``‖b − A x‖ / ‖b‖`` recomputed at the returned ``x``.
    """
    result = pcg_info(A, b, x0=x0, M=M, rtol=rtol, atol=atol, maxiter=maxiter, callback=callback,
                      callback_residual=callback_residual, stop=stop)
    return result.x, result.iterations, result.converged, result.relative_residual


def pcg_steps(S, precondition, z, Sz, rhs, *, rtol, factor, max_steps):
    r"""PCG steps on ``S z = rhs`` from the current ``z``, updating ``z`` and ``Sz = S z`` in place.

    With ``max_steps = 1``: one preconditioned step with exact line search
    along ``d = M⁻¹(rhs − Sz)``.  With more: CG steps until ``‖rhs − S z‖ <=
    max(rtol ‖rhs‖, factor ‖rhs − S z_start‖)`` or ``max_steps``.  The
    residual is ``rhs − Sz`` with ``Sz`` updated alongside ``z`` (one product
    with ``S`` per step).  ``rhs`` is overwritten (its buffer holds the
    residual).  ``precondition`` may return its argument itself (identity).
    Returns the number of steps.
    """
    rhs_sq = dot(rhs, rhs) if max_steps > 1 else None
    r = np.subtract(rhs, Sz, out=rhs)
    if max_steps > 1:
        rr = dot(r, r)
        target = max(rtol * rtol * rhs_sq, factor * factor * rr)
        if rr <= target:
            return 0
    d = precondition(r)
    rd = dot(r, d)
    p = d.copy() if d is r else d  # r is updated in place below: p must not share its buffer
    for step in range(1, max_steps + 1):
        q = S @ p
        pq = dot(p, q)
        if not pq > 0:
            return step - 1
        alpha = rd / pq
        if step == max_steps:  # p and q are not needed again: scale them in place
            p *= alpha
            z += p
            q *= alpha
            Sz += q
            return step
        z += alpha * p
        Sz += alpha * q
        r -= alpha * q
        if dot(r, r) <= target:
            return step
        d = precondition(r)
        rd_new = dot(r, d)
        p = d + (rd_new / rd) * p
        rd = rd_new
    return max_steps


def _norm(v):
    return math.sqrt(float(np.einsum("i,i->", v, v)))


def _dots(V, v):
    return np.einsum("ij,j->i", V, v)


def _combine(c, V):
    return np.einsum("i,ij->j", c, V)


# Gram-Schmidt is repeated only when ||v - V h|| < _REORTHOGONALISE ||v||.
# One classical pass loses about eps / ratio of orthogonality.  The
# preconditioned Schur complement of the colorization fill is close to the
# identity, so the ratio is small: the usual 0.7
# (Daniel-Gragg-Kaufman-Stewart) would repeat nearly every pass, doubling the
# vector work, to avoid a loss of order eps / ratio.  The residual is
# recomputed from x at the end of every cycle anyway.
_REORTHOGONALISE = 0.01


def gmres(apply, lift, b, x0, precond, atol, maxiter, restart=30, lift_x0=None):
    """Right-preconditioned restarted GMRES, stopping on ``||b - A x||_inf <= atol``.

    The operator is ``A x = apply(x, lift(x))``: ``lift`` is the expensive
    linear part (for the colorization fill ``x_K -> x_U``, one sparse
    triangular solve pair) and ``apply`` the cheap rest.  The lifted images
    of the Krylov directions are kept, so the lift of the iterate is their
    combination and the residual ``b - apply(x, lift(x))`` at the end of a
    cycle costs no extra solve.  ``lift`` may be None (then ``apply(x,
    None)`` is the whole operator).  ``lift_x0``, if given, replaces
    ``lift(x0)`` for the initial guess: the caller's lift may be affine,
    ``x -> lift(x) + c``, with ``lift`` applied to the Krylov directions
    being its linear part.

    The preconditioned images of the Krylov vectors are kept too (as in
    flexible GMRES), so the update of ``x`` at the end of a cycle costs no
    further application of ``precond``.  The max-norm of the residual is
    evaluated from the Arnoldi relation ``r_k = V_{k+1} (beta e_1 - H_k y_k)``
    once the 2-norm estimate makes it possible, and confirmed at the end of
    every cycle with the residual ``b - A x`` recomputed from ``x`` and its
    lift.

    Returns ``(x, lift_x, residual_norms, true_residual_inf, converged)``;
    ``residual_norms`` holds the 2-norm of the initial residual and then the
    GMRES estimate after every iteration.
    """
    x = x0.copy()
    if lift is None:
        lift_x = None
    else:
        lift_x = lift(x) if lift_x0 is None else lift_x0.copy()
    r = b - apply(x, lift_x)
    res_inf = float(np.max(np.abs(r)))
    beta = _norm(r)
    history = [beta]
    n_iter = 0
    n = b.size
    sqrt_n = math.sqrt(n)
    restart = max(1, min(restart, n, maxiter))
    while res_inf > atol and n_iter < maxiter:
        V = np.empty((restart + 1, n))
        Z = np.empty((restart, n))  # preconditioned V
        lifted = None if lift is None else np.empty((restart, lift_x.size))
        rotations = _Givens(restart, beta)
        np.divide(r, beta, out=V[0])
        k = 0
        while k < restart and n_iter < maxiter:
            w = Z[k] = precond(V[k])
            if lift is None:
                v = apply(w, None)
            else:
                lifted[k] = lift(w)
                v = apply(w, lifted[k])
            h_next = rotations.add_column(_orthogonalise(V[: k + 1], v), k)
            k += 1
            n_iter += 1
            g_k = rotations.g[k]
            history.append(abs(g_k))
            if h_next == 0.0:  # the Krylov space is invariant: exact solution
                break
            np.divide(v, h_next, out=V[k])
            if abs(g_k) <= atol * sqrt_n and rotations.residual_inf(V, k) <= atol:
                break
        y = scipy.linalg.solve_triangular(rotations.H[:k, :k], rotations.g[:k])
        x += _combine(y, Z[:k])
        if lift is not None:
            lift_x += _combine(y, lifted[:k])
        r = b - apply(x, lift_x)
        res_inf = float(np.max(np.abs(r)))
        beta = _norm(r)
    return x, lift_x, np.asarray(history), res_inf, res_inf <= atol


def _orthogonalise(V, v):
    """Orthogonalise ``v`` against the rows of ``V`` in place; returns the new Hessenberg column ``(h, ‖v‖)``.

    Classical Gram-Schmidt (BLAS-2), repeated once when it cancels
    catastrophically (see ``_REORTHOGONALISE``).
    """
    norm_v = _norm(v)
    h = _dots(V, v)
    v -= _combine(h, V)
    h_next = _norm(v)
    if h_next < _REORTHOGONALISE * norm_v:
        h2 = _dots(V, v)
        v -= _combine(h2, V)
        h += h2
        h_next = _norm(v)
    return np.append(h, h_next)


class _Givens:
    """The Givens QR of one GMRES cycle's Hessenberg matrix: rotations, triangular ``H`` and rotated ``g = Qᵀ beta e_1``."""

    def __init__(self, restart, beta):
        self.H = np.zeros((restart + 1, restart))
        self.cs = np.zeros(restart)
        self.sn = np.zeros(restart)
        self.g = np.zeros(restart + 1)
        self.g[0] = beta

    def add_column(self, col, k):
        """Rotate the Hessenberg column ``k`` into ``H``, update ``g``; returns the column's last entry before rotation."""
        cs, sn = self.cs, self.sn
        h_next = col[k + 1]
        for i in range(k):  # apply the previous Givens rotations
            col[i], col[i + 1] = (cs[i] * col[i] + sn[i] * col[i + 1],
                                  -sn[i] * col[i] + cs[i] * col[i + 1])
        rho = math.hypot(col[k], col[k + 1])
        cs[k], sn[k] = col[k] / rho, col[k + 1] / rho
        col[k], col[k + 1] = rho, 0.0
        self.H[: k + 2, k] = col
        g = self.g
        g[k + 1] = -sn[k] * g[k]
        g[k] = cs[k] * g[k]
        return h_next

    def residual_inf(self, V, k):
        """``‖r_k‖_inf`` of the residual vector ``r_k = g_k V_{k+1} Q_kᵀ e_{k+1}`` after ``k`` steps."""
        cs, sn = self.cs, self.sn
        u = np.zeros(k + 1)
        u[k] = 1.0
        for i in range(k - 1, -1, -1):
            u[i], u[i + 1] = cs[i] * u[i] - sn[i] * u[i + 1], sn[i] * u[i] + cs[i] * u[i + 1]
        return abs(self.g[k]) * float(np.max(np.abs(_combine(u, V[: k + 1]))))
