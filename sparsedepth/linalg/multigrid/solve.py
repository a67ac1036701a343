"""Whole SPD solves on a grid: :func:`solve_spd`, preconditioned CG with the preconditioner chosen by name.

The iteration is :func:`.iteration.preconditioned_cg`
(:func:`sparsedepth.linalg.krylov.pcg_info` with the true residual recorded
after every iteration).  May import the hierarchy (:mod:`.hierarchy`),
:mod:`.iteration`, :mod:`sparsedepth._validation`, NumPy, SciPy and pyamg.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..._validation import as_grid_operator, check_option_names
from .hierarchy import GridMultigrid
from .iteration import SolveInfo, preconditioned_cg, prepare_rhs

__all__ = ["SolveInfo", "solve_spd"]

_PRECONDITIONERS = ("grid", "amg", "sa", "jacobi", "none")
#: The options of :class:`GridMultigrid` that ``solve_spd(..., preconditioner="grid", **options)`` passes on.
GRID_OPTIONS = ("interpolation", "smoother", "sweeps", "max_coarse", "max_levels", "coarse_precision",
                "fine_precision", "line_anisotropy")


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
            check_option_names(options, GRID_OPTIONS, where="preconditioner='grid'")
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


# long only by its numpydoc docstring (with an example); the code is 7 lines
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
    b_arr, x_init, bnorm = prepare_rhs(b, x0, A.shape[0])
    t0 = time.perf_counter()
    M, name = _solve_preconditioner(A, shape, preconditioner, options)
    return preconditioned_cg(A, b_arr, x_init, bnorm, M=M, name=name, rtol=rtol, atol=atol, maxiter=maxiter,
                             callback=callback, setup_time=time.perf_counter() - t0, out_shape=np.shape(b))
