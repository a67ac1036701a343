"""Solvers of the completion objective, one registry, one result type.

May import :mod:`sparsedepth.objective`, :mod:`sparsedepth.linalg` and :mod:`sparsedepth.grid`.
"""

from .certificate import Certificate, curvature_lower_bound, duality_gap
from .core import (
    DEFAULT_MAX_ITER,
    DEFAULT_TOL,
    SOLVER_OPTIONS,
    SOLVERS,
    SolverOutput,
    check_solver_arguments,
    depth_scale,
    scaled_objective,
    solve,
)

__all__ = ["SolverOutput", "SOLVERS", "SOLVER_OPTIONS", "DEFAULT_TOL", "DEFAULT_MAX_ITER", "solve", "depth_scale",
           "scaled_objective", "check_solver_arguments", "Certificate", "duality_gap", "curvature_lower_bound"]
