"""The one registry of solvers: name → solve function, options class, defaults, problem.

:data:`REGISTRY` is the only place a solver is listed; :data:`SOLVERS`,
:data:`SOLVER_OPTIONS`, :data:`DEFAULT_TOL` and :data:`DEFAULT_MAX_ITER` are
derived from it.  A new solver is a module of :mod:`sparsedepth.solvers` with
a ``solve_<name>(objective, x0, *, tol, max_iter, recorder, options)``
function, an options class in :mod:`~sparsedepth.solvers.options` and one
entry here.

May import the other modules of :mod:`sparsedepth.solvers`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from .adam import solve_adam
from .admm import ADMM_MAX_ITER, ADMM_TOL, solve_admm
from .irls import solve_irls
from .lbfgsb import solve_lbfgsb
from .options import (AdamOptions, AdmmOptions, AmgOptions, CgOptions, DirectOptions, IrlsOptions, LbfgsbOptions,
                      SolverOptions)
from .quadratic import solve_amg, solve_cg, solve_direct

__all__ = ["SolverEntry", "REGISTRY", "SOLVERS", "SOLVER_OPTIONS", "DEFAULT_TOL", "DEFAULT_MAX_ITER"]


@dataclass(frozen=True)
class SolverEntry:
    """One registered solver.

    Parameters
    ----------
    solve : callable
        ``solve(objective, x0, *, tol, max_iter, recorder, options) -> SolverOutput``.
    options : type
        Its :class:`~sparsedepth.solvers.options.SolverOptions` subclass.
    tol : float
        Default ``tol``.
    max_iter : int
        Default ``max_iter``.
    quadratic : bool
        True for the solvers of the unconstrained quadratic problem (γ = 0);
        the others solve ``min_{z >= 0} F``.
    smoothed : bool
        True when the solver minimises the smoothed objective
        (:meth:`Objective.smoothed_value_and_gradient`).
    smoothing_ties : bool
        True when the certificate counts the rows with ``|(Kz)_k| <= ε``
        (:attr:`Objective.l1_smoothing`) as tied: the smoothed solvers, and
        IRLS, whose iterates leave differences of ~1e-5 on edges that the
        optimum ties, far above its final ``ε``.  Otherwise only exact ties
        count (ADMM's polished points, the γ = 0 solvers).
    robust : bool
        True when the solver handles robust (non-convex, smooth) terms
        (:class:`~sparsedepth.objective.terms.RobustTerm`): IRLS by
        majorise–minimise, L-BFGS-B and Adam through the exact gradient.
        The others refuse an objective with one.
    """

    solve: Callable
    options: type[SolverOptions]
    tol: float
    max_iter: int
    quadratic: bool = False
    smoothed: bool = False
    smoothing_ties: bool = False
    robust: bool = False


REGISTRY = {
    "direct": SolverEntry(solve_direct, DirectOptions, 0.0, 1, quadratic=True),
    "cg": SolverEntry(solve_cg, CgOptions, 1e-8, 5000, quadratic=True),
    "amg": SolverEntry(solve_amg, AmgOptions, 1e-8, 500, quadratic=True),
    "irls": SolverEntry(solve_irls, IrlsOptions, 1e-7, 200, smoothing_ties=True, robust=True),
    "admm": SolverEntry(solve_admm, AdmmOptions, ADMM_TOL, ADMM_MAX_ITER),
    "lbfgsb": SolverEntry(solve_lbfgsb, LbfgsbOptions, 1e-12, 15000, smoothed=True, smoothing_ties=True,
                          robust=True),
    "adam": SolverEntry(solve_adam, AdamOptions, 1e-7, 20000, smoothed=True, smoothing_ties=True,
                        robust=True),
}

#: Solver name → solve function, in the order of :data:`REGISTRY` (the public ``sd.SOLVERS``).
SOLVERS = {name: entry.solve for name, entry in REGISTRY.items()}
#: The valid ``options`` of every solver with their defaults (``None``: computed from the problem, see the
#: solver's docstring).  :func:`~sparsedepth.solvers.solve` rejects any other key and fills in the defaults.
SOLVER_OPTIONS = {name: entry.options.defaults() for name, entry in REGISTRY.items()}
DEFAULT_TOL = {name: entry.tol for name, entry in REGISTRY.items()}
DEFAULT_MAX_ITER = {name: entry.max_iter for name, entry in REGISTRY.items()}
