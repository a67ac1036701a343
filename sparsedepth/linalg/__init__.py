"""Sparse symmetric positive definite solves: one Krylov layer and its preconditioners.

May import :mod:`sparsedepth.grid`; nothing above it.
"""

from .krylov import dot, gmres, pcg, pcg_steps
from .preconditioners import PRECONDITIONERS, make_preconditioner
from .multigrid import GridMultigrid, SolveInfo, grid_multigrid, grid_stencil, solve_spd

__all__ = ["pcg", "pcg_steps", "gmres", "dot", "make_preconditioner", "PRECONDITIONERS", "GridMultigrid", "SolveInfo", "grid_multigrid",
           "grid_stencil", "solve_spd"]
