"""Sparse symmetric positive definite solves: one Krylov layer and its preconditioners.

:mod:`.krylov` holds every Krylov loop of the package (``pcg``/``pcg_info``,
the warm-started ``pcg_steps``, restarted ``gmres``), :mod:`.preconditioners`
the preconditioners by name, :mod:`.multigrid` the geometric multigrid
hierarchy and whole grid solves (``solve_spd``).  May import
:mod:`sparsedepth.grid` and :mod:`sparsedepth._validation`, NumPy, SciPy and
pyamg; never :mod:`sparsedepth.objective`, :mod:`sparsedepth.solvers` or
anything above.
"""

from .krylov import PCGResult, dot, gmres, pcg, pcg_info, pcg_steps
from .preconditioners import PRECONDITIONERS, make_preconditioner
from .multigrid import GridMultigrid, SolveInfo, grid_multigrid, grid_stencil, solve_spd

__all__ = ["pcg", "pcg_info", "PCGResult", "pcg_steps", "gmres", "dot", "make_preconditioner", "PRECONDITIONERS",
           "GridMultigrid", "SolveInfo", "grid_multigrid", "grid_stencil", "solve_spd"]
