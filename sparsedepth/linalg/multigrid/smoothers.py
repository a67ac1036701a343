r"""Smoothers of the V-cycle: Gauss--Seidel sweeps (pyamg's compiled kernel) and damped Jacobi.

Forward Gauss--Seidel before and backward after the coarse-grid correction
are adjoint in the :math:`A` inner product, and damped Jacobi is symmetric,
so either keeps the V-cycle a symmetric preconditioner.  May import NumPy
and pyamg.
"""

from __future__ import annotations

import numpy as np
from pyamg import amg_core

__all__ = ["gauss_seidel_forward", "gauss_seidel_backward", "jacobi_damping", "jacobi_sweeps"]


def gauss_seidel_forward(A, x, b, sweeps):
    """``sweeps`` forward Gauss--Seidel sweeps on the CSR system ``A x = b``, updating ``x`` in place.

    ``A`` may also be a :class:`~sparsedepth.linalg.multigrid.bands.BandedStencil` (its own band-wise sweeps).
    """
    if hasattr(A, "gauss_seidel"):
        A.gauss_seidel(x, b, sweeps)
        return
    n = x.shape[0]
    for _ in range(sweeps):
        amg_core.gauss_seidel(A.indptr, A.indices, A.data, x, b, 0, n, 1)


def gauss_seidel_backward(A, x, b, sweeps):
    """``sweeps`` backward Gauss--Seidel sweeps (last row first), updating ``x`` in place."""
    if hasattr(A, "gauss_seidel"):
        A.gauss_seidel(x, b, sweeps, backward=True)
        return
    n = x.shape[0]
    for _ in range(sweeps):
        amg_core.gauss_seidel(A.indptr, A.indices, A.data, x, b, n - 1, -1, -1)


def jacobi_damping(A):
    r"""``(diag_inv, omega)`` of damped Jacobi for ``A``: :math:`D^{-1}` and :math:`\omega = 4 / (3 \rho)`.

    :math:`\rho = \max_i \sum_j |a_{ij}| / a_{ii}` is the Gershgorin bound of
    :math:`D^{-1} A`.  ``ValueError`` unless the diagonal is positive.
    """
    if not hasattr(A, "indptr"):  # a stencil form: its CSR form, for the row sums
        A = A.tocsr()
    diag = A.diagonal()
    if np.any(diag <= 0):
        raise ValueError("the Jacobi smoother needs a positive diagonal.")
    absrow = np.abs(A) @ np.ones(A.shape[0])
    rho = float(np.max(absrow / diag))
    return 1.0 / diag, 4.0 / (3.0 * rho)


def jacobi_sweeps(A, x, b, diag_inv, omega, sweeps):
    r"""``sweeps`` damped Jacobi sweeps :math:`x \leftarrow x + \omega D^{-1} (b - A x)`, updating ``x`` in place."""
    for _ in range(sweeps):
        x += omega * diag_inv * (b - A @ x)
