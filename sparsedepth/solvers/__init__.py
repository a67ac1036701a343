"""Solvers of the completion objective: one registry, one output type, one certificate.

Every solver takes an :class:`~sparsedepth.objective.Objective`, a starting
point and stopping parameters, and returns a
:class:`~sparsedepth.solvers.common.SolverOutput`; the public entry point
:func:`sparsedepth.complete_depth` turns it into a
:class:`~sparsedepth.result.CompletionResult`.  Solvers are registered by name
in :data:`~sparsedepth.solvers.registry.REGISTRY` (names: :data:`SOLVERS`),
their options are one frozen dataclass per solver
(:mod:`~sparsedepth.solvers.options`; defaults: :data:`SOLVER_OPTIONS`).

:func:`solve` works in normalised units: the depth is divided by a power of
two ``s`` near its median (:func:`depth_unit`) and the objective becomes
``F / s²`` (:func:`scaled_objective`), so every solver, its defaults and its
tolerances see data of order 1 whatever the unit.  Every solver's output
carries a duality gap (:mod:`sparsedepth.solvers.certificate`), a bound on
``F(z) − F*``; ``converged`` needs the solver's own rule (below) and ``gap
<= gap_tol · max(F, 1e-7 F(0))`` (option ``gap_tol``, 1e-2 for every solver:
:data:`~sparsedepth.solvers.options.DEFAULT_GAP_TOL`).  With ``bounds``
(:func:`solve_scaled`; the range clamp of :func:`sparsedepth.complete_depth`)
the gap and the test are those of the clipped point over the box, and the
solver's own gap is kept beside them.  ADMM and IRLS work to a tighter gap of
their own (option ``target_gap``: 1e-6 and 1e-4).  Every relative stopping test on ``F`` has an absolute floor
(:func:`~sparsedepth.solvers.common.objective_floor`), so ``F* = 0``
converges; a solver that claims convergence at its start must pass a
projected-gradient check.

==========  ===========  ====================================================
name        objective    stopping rule (``tol``)
==========  ===========  ====================================================
direct      γ = 0        exact sparse LU solve of the normal equations
cg          γ = 0        Jacobi-PCG, ``‖b − A z‖ ≤ tol ‖b‖``, or (options
                         ``depth_rtol``/``depth_atol``) an estimated RMS
                         remaining change of the depth below that tolerance
amg         γ = 0        PCG with a multigrid V-cycle (geometric GridMultigrid;
                         ``options={"preconditioner": "amg"}`` for pyamg
                         Ruge–Stüben), same rules; ``complete_depth``
                         without ``tol`` uses ``depth_rtol = 3e-4``
irls        any          ``F_{k-1} − F_k ≤ tol · F_k + floor`` at the final ε
admm        any          primal residual ``<= tol`` (relative) starts exact
                         active-set polishes, 3, 6, 12, 12, ... iterations
                         apart; stops when the best polished F changes by
                         ``<= 2e-7`` (relative, + floor) between two of them
lbfgsb      any          SciPy L-BFGS-B on the smoothed objective scaled by
                         ``1/F(x0)``; ``ftol = tol``
adam        any          projected Adam on the smoothed objective; the mean
                         over the last 50 steps is ``≤ tol`` (relative, +
                         floor) below the mean over the 50 before them
==========  ===========  ====================================================

Modules: ``core`` (the front door: checks, scaling, :func:`solve`, the
certificate of a run), ``registry``, ``options``, ``common`` (output type,
recorder, floors), ``quadratic`` (direct, cg, amg), ``irls``, ``admm`` with
``active_set`` (its polish), ``lbfgsb``, ``adam``, ``certificate`` (the
duality gap).

May import :mod:`sparsedepth.objective`, :mod:`sparsedepth.linalg`,
:mod:`sparsedepth.grid`, :mod:`sparsedepth.result` and
:mod:`sparsedepth._validation`; never :mod:`sparsedepth.io`,
:mod:`sparsedepth.batch`, :mod:`sparsedepth.cli`, :mod:`sparsedepth.holes`
or :mod:`sparsedepth.completion`.
"""

from .certificate import Certificate, curvature_lower_bound, duality_gap
from .common import SolverOutput
from .core import check_solver_arguments, depth_unit, scaled_objective, solve, solve_scaled
from .options import (AdamOptions, AdmmOptions, AmgOptions, CgOptions, DirectOptions, IrlsOptions, LbfgsbOptions,
                      SolverOptions)
from .registry import DEFAULT_MAX_ITER, DEFAULT_TOL, REGISTRY, SOLVER_OPTIONS, SOLVERS

__all__ = ["SolverOutput", "SOLVERS", "SOLVER_OPTIONS", "DEFAULT_TOL", "DEFAULT_MAX_ITER", "REGISTRY", "solve",
           "solve_scaled", "depth_unit", "scaled_objective", "check_solver_arguments", "Certificate",
           "duality_gap", "curvature_lower_bound", "SolverOptions", "DirectOptions", "CgOptions", "AmgOptions",
           "IrlsOptions", "AdmmOptions", "LbfgsbOptions", "AdamOptions"]
