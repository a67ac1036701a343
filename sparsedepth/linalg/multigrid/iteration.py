"""The iterations behind the multigrid solves: preconditioned CG with a true-residual history, and the V-cycle iteration.

:class:`SolveInfo` is what both return.  Used by :mod:`.hierarchy`
(:meth:`GridMultigrid.solve`) and :mod:`.solve` (:func:`solve_spd`); may
import :mod:`sparsedepth.linalg.krylov`, NumPy and SciPy, never the hierarchy.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..krylov import pcg_info

__all__ = ["SolveInfo", "prepare_rhs", "preconditioned_cg", "vcycle_iteration"]


@dataclass(frozen=True)
class SolveInfo:
    """Outcome of :func:`solve_spd` / :meth:`GridMultigrid.solve`.

    Attributes
    ----------
    converged : bool
        Whether the stopping rule was met.
    status : int
        0 converged, >0 iteration limit reached, <0 stopped (breakdown or by
        the callback).
    message : str
        Human-readable status.
    iterations : int
        Number of iterations performed.
    residuals : ndarray, shape (iterations + 1,)
        True residual norms :math:`\\|b - A x_k\\|_2`, starting with the initial
        residual :math:`k = 0`.
    b_norm : float
        :math:`\\|b\\|_2`.
    rtol, atol : float
        Tolerances used.
    preconditioner : str
        Which preconditioner was used.
    setup_time, solve_time : float
        Wall-clock seconds for building the preconditioner and for iterating.
    """

    converged: bool
    status: int
    message: str
    iterations: int
    residuals: np.ndarray
    b_norm: float
    rtol: float
    atol: float
    preconditioner: str
    setup_time: float
    solve_time: float

    @property
    def relative_residual(self):
        """Final :math:`\\|b - A x\\|_2 / \\|b\\|_2` (0 when :math:`b = 0`)."""
        if self.b_norm == 0:
            return float(self.residuals[-1])
        return float(self.residuals[-1] / self.b_norm)


def prepare_rhs(b, x0, n):
    """``b`` and the starting point as flat float64 vectors of ``n`` entries, and ``‖b‖``; ``ValueError`` on a size mismatch."""
    b_arr = np.asarray(b, dtype=np.float64)
    if b_arr.size != n:
        raise ValueError(
            f"`b` has {b_arr.size} entries ({b_arr.shape}) but the operator has "
            f"{n} unknowns."
        )
    b_arr = np.ascontiguousarray(b_arr.reshape(-1))
    if x0 is None:
        x = np.zeros(n)
    else:
        x = np.array(x0, dtype=np.float64).reshape(-1)
        if x.size != n:
            raise ValueError(
                f"`x0` has {x.size} entries but the operator has {n} unknowns."
            )
    return b_arr, x, float(np.linalg.norm(b_arr))


def preconditioned_cg(A, b_arr, x_init, bnorm, *, M, name, rtol, atol, maxiter, callback, setup_time, out_shape):
    """PCG (:func:`~sparsedepth.linalg.krylov.pcg_info`) from prepared vectors, recording the true residual.

    ``b_arr``, ``x_init`` and ``bnorm`` come from :func:`prepare_rhs`; ``M``
    is the preconditioner (or None) and ``name`` its label in the
    :class:`SolveInfo`.  Returns ``(x, info)`` with ``x`` shaped ``out_shape``.
    """
    if maxiter is None:
        maxiter = 10 * A.shape[0]
    t1 = time.perf_counter()
    residuals = [float(np.linalg.norm(b_arr - A @ x_init))]

    def _record(xk):
        residuals.append(float(np.linalg.norm(b_arr - A @ xk)))
        if callback is not None:
            callback(xk.copy())

    result = pcg_info(A, b_arr, x0=x_init, M=M, rtol=rtol, atol=atol, maxiter=maxiter, callback=_record)
    t2 = time.perf_counter()
    if result.stopped:
        status, message = -1, "stopped by callback"
    elif result.converged:
        status, message = 0, "converged"
    elif result.breakdown:
        status, message = -2, "CG breakdown (operator or preconditioner not SPD?)"
    else:
        status, message = max(result.iterations, 1), result.message
    info = SolveInfo(converged=status == 0, status=status, message=message, iterations=result.iterations,
                     residuals=np.asarray(residuals), b_norm=bnorm, rtol=rtol, atol=atol, preconditioner=name,
                     setup_time=setup_time, solve_time=t2 - t1)
    return result.x.reshape(out_shape), info


def vcycle_iteration(mg, b, *, x0=None, rtol=1e-8, atol=0.0, maxiter=None, callback=None):
    r"""Solve :math:`A x = b` by the stationary V-cycle iteration of the hierarchy ``mg``.

    Parameters
    ----------
    mg : GridMultigrid
        The hierarchy; ``A`` is its fine operator.
    b, x0, rtol, atol, callback
        As for :meth:`GridMultigrid.solve`.
    maxiter : int, optional
        Maximum number of V-cycles; default 100.

    Returns
    -------
    x : ndarray, same shape as `b`
    info : SolveInfo

    Notes
    -----
    :math:`x_{k+1} = x_k + M^{-1}(b - A x_k)` with :math:`M^{-1}` one
    V-cycle, until :math:`\|b - A x_k\|_2 \le \max(\mathrm{rtol}\,\|b\|_2,
    \mathrm{atol})` (the true residual, recomputed every cycle).
    """
    A = mg.levels[0].A
    b_arr, x, bnorm = prepare_rhs(b, x0, A.shape[0])
    maxiter = 100 if maxiter is None else int(maxiter)
    t0 = time.perf_counter()
    r = b_arr - A @ x
    res = [float(np.linalg.norm(r))]
    target = max(rtol * bnorm, atol)
    stopped = False
    while res[-1] > target and len(res) <= maxiter:
        x += mg.vcycle(r)
        r = b_arr - A @ x
        res.append(float(np.linalg.norm(r)))
        if callback is not None:
            try:
                callback(x.copy())
            except StopIteration:
                stopped = True
                break
    if res[-1] <= target:
        status, message = 0, "converged"
    elif stopped:
        status, message = -1, "stopped by callback"
    else:
        status, message = 1, f"no convergence in {maxiter} V-cycles"
    info = SolveInfo(converged=status == 0, status=status, message=message,
                     iterations=len(res) - 1, residuals=np.asarray(res),
                     b_norm=bnorm, rtol=rtol, atol=atol,
                     preconditioner="GridMultigrid (V-cycle iteration)",
                     setup_time=0.0, solve_time=time.perf_counter() - t0)
    return x.reshape(np.shape(b)), info
