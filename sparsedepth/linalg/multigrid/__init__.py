r"""Geometric multigrid for SPD operators on pixel grids: the hierarchy, its parts, and whole solves.

The solvers of this package repeatedly solve sparse symmetric positive definite
(SPD) systems that live on an :math:`H \times W` pixel grid (pixels flattened in
C order, :math:`N = HW`), typically

.. math::

    A = \operatorname{diag}(a) + D_x^\top \operatorname{diag}(w_x) D_x
        + D_y^\top \operatorname{diag}(w_y) D_y ,

with forward differences :math:`D_x, D_y` (Neumann boundary), a reaction term
:math:`a \ge 0` and edge weights :math:`w_x, w_y > 0` (constant, or jumping by
orders of magnitude for IRLS / split-Bregman variants), possibly plus a
second-order term that widens the stencil to 13 points.

This module exploits the grid: the hierarchy is built from *stencils*, i.e. one
coefficient image per neighbour offset, so that

* the prolongation :math:`P` comes from 1-D interpolation along each axis
  (``interpolation="bilinear"``, fixed per grid shape) or from the matrix
  entries themselves (``interpolation="operator"``, Dendy's black-box
  multigrid, for jumping coefficients); either is stored as weight arrays
  (1-D, or two images per parity class) and applied by array slicing, never
  as an :math:`N`-row sparse matrix;
* the Galerkin operators :math:`A^c = P^\top A P` are computed by vectorised
  stencil arithmetic, never by a general sparse matrix product: for the
  bilinear :math:`P` the rows, then the columns are coarsened (half the
  offsets of each symmetric step, a band of rows at a time), for the
  operator-dependent one the four parity classes of fine pixels are summed;
  they land in a sparsity pattern that is fixed per grid shape;
* :meth:`GridMultigrid.update` therefore redoes only the numeric part for a new
  operator with the same stencil (new weights between IRLS iterations).

The cycle is a symmetric V-cycle (forward Gauss--Seidel before, backward
Gauss--Seidel after the coarse-grid correction, using pyamg's compiled
kernels), so it is a valid preconditioner for conjugate gradients.  Unless
the operator is very large it runs in float32 (on a float32 copy of the fine
operator's values), which moves fewer bytes per sweep; the callers'
residuals stay float64, so a solve's accuracy does not depend on it.
:func:`solve_spd` runs preconditioned CG (:mod:`sparsedepth.linalg.krylov`)
with a choice of preconditioners and returns an honest residual history.

The fine operator may also be a :class:`~sparsedepth.grid.stencil.SymmetricStencil`
(half the stencil images, no CSR: ``Objective.normal_equations(form="stencil")``);
on large frames its float64 sweeps and the float32 coarse levels then run
band by band through the same kernel (:mod:`.bands`), bit for bit as on
the CSR forms, without holding them.

Modules, from the bottom up: :mod:`.stencils` (reading stencils from CSR),
:mod:`.interpolation` (prolongation weights), :mod:`.transfer` (prolongation
operators), :mod:`.galerkin` (coarse operators), :mod:`.bands` (band-wise
sweeps and products of symmetric stencils), :mod:`.smoothers`, :mod:`.iteration` (PCG
and V-cycle iterations with their residual history),
:mod:`.hierarchy` (:class:`GridMultigrid`), :mod:`.solve` (:func:`solve_spd`).
The subpackage may import :mod:`sparsedepth.linalg.krylov`,
:mod:`sparsedepth.grid`, :mod:`sparsedepth._validation`, NumPy, SciPy and
pyamg; never :mod:`sparsedepth.objective`, :mod:`sparsedepth.solvers` or
anything above.
"""

from .hierarchy import GridMultigrid, grid_multigrid
from .solve import SolveInfo, solve_spd
from .stencils import grid_stencil

__all__ = ["GridMultigrid", "SolveInfo", "grid_multigrid", "grid_stencil", "solve_spd"]
