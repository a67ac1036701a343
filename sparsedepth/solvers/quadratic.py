"""The solvers of the quadratic problem (γ = 0): ``direct``, ``cg`` and ``amg``.

Each minimises ``F(z) = zᵀAz − 2bᵀz + c`` without bounds, i.e. solves the
normal equations ``A z = b``.

May import :mod:`sparsedepth.linalg` and the other modules of :mod:`sparsedepth.solvers`.
"""

from __future__ import annotations

import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from ..linalg.krylov import dot, pcg
from ..linalg.preconditioners import make_preconditioner
from .common import output, require_quadratic

__all__ = ["solve_direct", "solve_cg", "solve_amg"]


def solve_direct(objective, x0, *, tol=None, max_iter=None, recorder, options):
    """Sparse LU (SuperLU) solve of ``A z = b``; the reference for γ = 0."""
    require_quadratic(objective, "direct")
    recorder(0, x0)
    A, b, _ = objective.normal_equations()
    z = spsolve(sp.csc_matrix(A), b)
    recorder(1, z)
    return output(z, 1, True, "direct sparse solve", recorder)


def _solve_pcg(objective, x0, *, tol, max_iter, recorder, preconditioner):
    r"""PCG on ``A z = b`` to ``‖b − A z‖ ≤ tol ‖b‖`` (true residual), history per CG step.

    The objective recorded after each CG step is ``F(z) = c − bᵀz − rᵀz``
    (``= zᵀAz − 2bᵀz + c`` with the CG residual ``r = b − A z``), two dot
    products instead of a full evaluation of every term; the last entry is
    re-evaluated exactly term by term.
    """
    A, b, c = objective.normal_equations()
    recorder(0, x0)
    M = make_preconditioner(A, preconditioner, shape=objective.shape)
    it = [0]

    def cb(xk, rk):
        it[0] += 1
        recorder(it[0], xk, inner=it[0], value=c - dot(b, xk) - dot(rk, xk))

    z, n, converged, rel = pcg(A, b, x0=x0, M=M, rtol=tol, maxiter=max_iter, callback=cb, callback_residual=True)
    if recorder.history and recorder.history[-1].iteration == n and n > 0:
        recorder.set_last_value(objective.value(z))
    msg = f"relative residual {rel:.2e} {'<=' if converged else '>'} tol {tol:.1e} after {n} CG iterations"
    return output(z, n, converged, msg, recorder)


def solve_cg(objective, x0, *, tol, max_iter, recorder, options):
    """Conjugate gradients with the Jacobi preconditioner ``diag(A)⁻¹``."""
    require_quadratic(objective, "cg")
    return _solve_pcg(objective, x0, tol=tol, max_iter=max_iter, recorder=recorder, preconditioner="jacobi")


def solve_amg(objective, x0, *, tol, max_iter, recorder, options):
    """Conjugate gradients preconditioned by one multigrid V-cycle.

    ``options.preconditioner`` (:class:`~sparsedepth.solvers.options.AmgOptions`):
    ``"grid"``, the geometric :class:`~sparsedepth.linalg.multigrid.GridMultigrid`
    built once for ``A`` (the quadratic part of any objective is a grid
    operator of stencil radius <= 2), or ``"amg"``, pyamg Ruge–Stüben.
    """
    require_quadratic(objective, "amg")
    return _solve_pcg(objective, x0, tol=tol, max_iter=max_iter, recorder=recorder,
                      preconditioner=options.preconditioner)
