"""Whole SPD solves on a grid: :func:`solve_spd` (preconditioned CG) and the stationary V-cycle iteration, with :class:`SolveInfo`.

The CG iteration is :func:`sparsedepth.linalg.krylov.pcg_info`; this module
picks the preconditioner by name and records the true residual after every
iteration.  May import :mod:`sparsedepth.linalg.krylov`, the hierarchy
(:mod:`.hierarchy`), :mod:`sparsedepth._validation`, NumPy, SciPy and pyamg.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..._validation import as_grid_operator
from ..krylov import pcg_info
from .hierarchy import GridMultigrid

__all__ = ["SolveInfo", "solve_spd", "vcycle_iteration"]

_PRECONDITIONERS = ("grid", "amg", "sa", "jacobi", "none")


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


def _prepare_rhs(b, x0, n):
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


def _solve_preconditioner(A, shape, preconditioner, options):
    if isinstance(preconditioner, str):
        if preconditioner not in _PRECONDITIONERS:
            raise ValueError(
                f"unknown preconditioner {preconditioner!r}; use one of "
                f"{_PRECONDITIONERS}, a GridMultigrid or a LinearOperator."
            )
        if preconditioner != "grid" and preconditioner != "amg" and \
                preconditioner != "sa" and options:
            raise TypeError(
                f"preconditioner={preconditioner!r} takes no options, got "
                f"{sorted(options)}."
            )
        if preconditioner == "grid":
            return GridMultigrid(A, shape, **options).aspreconditioner(), "grid"
        if preconditioner in ("amg", "sa"):
            import pyamg

            build = (pyamg.ruge_stuben_solver if preconditioner == "amg"
                     else pyamg.smoothed_aggregation_solver)
            return build(A, **options).aspreconditioner(cycle="V"), preconditioner
        if preconditioner == "jacobi":
            d = A.diagonal()
            if np.any(d <= 0):
                raise ValueError("the Jacobi preconditioner needs a positive diagonal.")
            dinv = 1.0 / d
            n = A.shape[0]
            return spla.LinearOperator((n, n), matvec=lambda r: dinv * r.ravel(),
                                       dtype=np.float64), "jacobi"
        return None, "none"
    if options:
        raise TypeError(
            f"options {sorted(options)} are only used when `preconditioner` is a name."
        )
    if hasattr(preconditioner, "aspreconditioner"):
        return preconditioner.aspreconditioner(), type(preconditioner).__name__
    if isinstance(preconditioner, spla.LinearOperator) or sp.issparse(preconditioner):
        return preconditioner, type(preconditioner).__name__
    raise TypeError(
        "`preconditioner` must be a name, an object with .aspreconditioner() or a "
        f"LinearOperator, got {type(preconditioner).__name__}."
    )


# long only by its numpydoc docstring (with an example); the code is about 25 lines
def solve_spd(A, b, shape, *, x0=None, rtol=1e-8, atol=0.0, maxiter=None,
              preconditioner="grid", callback=None, **options):
    r"""Solve an SPD grid system :math:`A x = b` by preconditioned CG.

    Parameters
    ----------
    A : scipy.sparse matrix, shape (N, N)
        Symmetric positive definite operator on a ``shape`` grid (C order).
    b : array_like, shape (N,) or (H, W)
        Right-hand side.
    shape : tuple of int
        Grid shape ``(H, W)``, ``H * W == N``.
    x0 : array_like, optional
        Initial guess (zero by default); never modified.
    rtol, atol : float
        Stop when :math:`\|b - A x_k\|_2 \le \max(\mathrm{rtol}\,\|b\|_2,
        \mathrm{atol})`, the rule of :func:`scipy.sparse.linalg.cg` checked
        on the recursively updated residual and then confirmed on the true
        one (see :func:`~sparsedepth.linalg.krylov.pcg_info`).
    maxiter : int, optional
        Maximum number of CG iterations; default ``10 * N`` as in SciPy.
    preconditioner : str, GridMultigrid, pyamg solver or LinearOperator
        ``"grid"`` (default): a :class:`GridMultigrid` V-cycle built from
        `A` with ``**options``; ``"amg"``: pyamg Ruge--Stueben;
        ``"sa"``: pyamg smoothed aggregation (``**options`` passed on);
        ``"jacobi"``: diagonal scaling; ``"none"``.  An already built
        hierarchy (e.g. after :meth:`GridMultigrid.update`) is used as is.
    callback : callable, optional
        ``callback(xk)`` with a copy of the iterate after each iteration; may
        raise ``StopIteration`` to stop, which the result then reports.
    **options
        Keyword options for the named multigrid preconditioner, e.g.
        ``interpolation="operator"``.

    Returns
    -------
    x : ndarray, same shape as `b`
        Approximate solution.
    info : SolveInfo
        Convergence flag and status, iteration count, true residual history
        :math:`\|b - A x_k\|_2` for :math:`k = 0, \dots, \text{iterations}`,
        setup and solve times.

    Raises
    ------
    ValueError
        Unknown preconditioner name, or `A`, `b`, `shape` that do not fit.
    TypeError
        Options given for a preconditioner that takes none.

    Notes
    -----
    The residual history is recomputed from the iterate after every CG step
    (one extra product with `A` per iteration), so it reports the true
    residual, not CG's recursively updated one.  ``info.status`` is 0 when
    converged, -1 when the callback stopped the solve, -2 on a CG breakdown
    (:math:`p^\top A p \le 0`: `A` or the preconditioner not SPD) and the
    number of iterations (> 0) otherwise.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> H, W = 20, 30
    >>> d = lambda n: sp.diags([-np.ones(n), np.r_[np.ones(n - 1), 0]], [0, 1])
    >>> Dx = sp.kron(sp.eye(H), d(W)); Dy = sp.kron(d(H), sp.eye(W))
    >>> A = (0.1 * sp.eye(H * W) + Dx.T @ Dx + Dy.T @ Dy).tocsr()
    >>> x, info = solve_spd(A, np.ones((H, W)), (H, W), rtol=1e-10)
    >>> info.converged, x.shape, bool(info.relative_residual < 1e-10)
    (True, (20, 30), True)
    """
    A, shape = as_grid_operator(A, shape)
    n = A.shape[0]
    b_arr, x_init, bnorm = _prepare_rhs(b, x0, n)
    if maxiter is None:
        maxiter = 10 * n
    t0 = time.perf_counter()
    M, name = _solve_preconditioner(A, shape, preconditioner, options)
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
                     setup_time=t1 - t0, solve_time=t2 - t1)
    return result.x.reshape(np.shape(b)), info


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
    b_arr, x, bnorm = _prepare_rhs(b, x0, A.shape[0])
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
