"""Preconditioners for the SPD systems of the package by name: Jacobi, grid multigrid, pyamg.

May import :mod:`.multigrid`, :mod:`sparsedepth.grid`, NumPy, SciPy and pyamg.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator

from ..grid.stencil import SymmetricStencil
from .multigrid import GridMultigrid

__all__ = ["make_preconditioner", "PRECONDITIONERS"]

PRECONDITIONERS = ("grid", "jacobi", "amg", "none")


def make_preconditioner(A, kind: str = "amg", *, shape=None):
    """A preconditioner for the SPD matrix ``A`` as a ``LinearOperator``.

    Parameters
    ----------
    A : scipy.sparse matrix or SymmetricStencil, (N, N), symmetric positive definite
        A :class:`~sparsedepth.grid.stencil.SymmetricStencil` (e.g.
        ``objective.normal_equations(form="stencil")``) gives the same
        preconditioner as its CSR form (``"amg"`` converts it).
    kind : {"grid", "amg", "jacobi", "none"} or GridMultigrid
        ``"grid"``: one symmetric V-cycle of a geometric
        :class:`~sparsedepth.linalg.multigrid.GridMultigrid` (``interpolation="auto"``) built here (needs
        ``shape``; ``A`` must be a grid operator of stencil radius <= 2, which
        the quadratic part of every completion objective is);
        ``"amg"``: one V-cycle of a pyamg Ruge–Stüben hierarchy (set up here);
        ``"jacobi"``: ``diag(A)⁻¹``; ``"none"``: identity.  An already built
        ``GridMultigrid`` (e.g. after :meth:`~GridMultigrid.update`) is used
        as is.
    shape : tuple of int, optional
        Grid shape ``(H, W)`` with ``H * W = N``; required for ``"grid"``
        (a stencil's own grid by default).

    Returns
    -------
    LinearOperator or None
        ``None`` for ``"none"``.

    Raises
    ------
    ValueError
        For an unknown kind, ``"grid"`` without ``shape``, or a non-positive
        diagonal with ``"jacobi"``.
    """
    n = A.shape[0]
    if shape is None and isinstance(A, SymmetricStencil):
        shape = A.grid_shape
    if isinstance(kind, GridMultigrid):
        return kind.aspreconditioner()
    if kind == "none":
        return None
    if kind == "jacobi":
        d = A.diagonal()
        if np.any(d <= 0):
            raise ValueError("Jacobi preconditioner needs a positive diagonal")
        inv = 1.0 / d
        return LinearOperator((n, n), matvec=lambda x: inv * np.ravel(x), dtype=np.float64)
    if kind == "grid":
        if shape is None:
            raise ValueError("preconditioner 'grid' needs the grid shape: pass shape=(H, W)")
        return GridMultigrid(A, shape, interpolation="auto").aspreconditioner()
    if kind == "amg":
        import pyamg

        csr = A.tocsr() if isinstance(A, SymmetricStencil) else A
        ml = pyamg.ruge_stuben_solver(sp.csr_matrix(csr), max_coarse=300, coarse_solver="splu")
        return ml.aspreconditioner(cycle="V")
    raise ValueError(f"unknown preconditioner {kind!r}; one of {PRECONDITIONERS}")
