"""Sparse symmetric positive definite solves: one Krylov layer and its preconditioners.

May import :mod:`sparsedepth.grid`; nothing above it.
"""

from .krylov import PRECONDITIONERS, make_preconditioner, pcg
from .multigrid import GridMultigrid, SolveInfo, grid_multigrid, grid_stencil, solve_spd

__all__ = ["pcg", "make_preconditioner", "PRECONDITIONERS", "GridMultigrid", "SolveInfo", "grid_multigrid",
           "grid_stencil", "solve_spd"]
