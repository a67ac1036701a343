r"""Smoothers of the V-cycle: Gauss--Seidel sweeps (pyamg's compiled kernel) and damped Jacobi.

Forward Gauss--Seidel before and backward after the coarse-grid correction
are adjoint in the :math:`A` inner product, and damped Jacobi is symmetric,
so either keeps the V-cycle a symmetric preconditioner.  May import NumPy
and pyamg.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from pyamg import amg_core

__all__ = ["gauss_seidel_forward", "gauss_seidel_backward", "jacobi_damping", "jacobi_sweeps", "LineGaussSeidel"]


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


class LineGaussSeidel:
    r"""Alternating line Gauss--Seidel for a grid operator of stencil radius at most 2 (CSR).

    The unknowns are split into six blocks: the rows :math:`y \equiv c \pmod 3` (``x``-lines) and then the
    columns :math:`x \equiv c \pmod 3` (``y``-lines), :math:`c = 0, 1, 2`.  Lines of one block lie at least
    three pixels apart, so with couplings at most two pixels apart a block's matrix :math:`A_{BB}` is
    block diagonal with one pentadiagonal SPD matrix per line, factored once (banded Cholesky, LAPACK
    ``pbtrf``).  :meth:`forward` visits the blocks in that order, :meth:`backward` in the reverse one.

    Parameters
    ----------
    A : scipy.sparse CSR matrix, shape (N, N)
        Symmetric positive definite operator on the grid, float32 or float64 (the sweeps' precision).
    shape : tuple of int
        Grid shape ``(H, W)``.

    Notes
    -----
    A block step is :math:`x_B \leftarrow x_B + A_{BB}^{-1} (b - A x)_B`, with :math:`(A x)_B` from the
    block's rows of :math:`A` (kept as a CSR slice: the six slices hold twice the non-zeros of :math:`A`).
    A forward sweep :math:`S` and the backward sweep :math:`S^\ast`, the same block steps in reverse order,
    are adjoint in the :math:`A` inner product, as for point Gauss--Seidel, so a V-cycle with :math:`S`
    before and :math:`S^\ast` after the coarse-grid correction stays symmetric positive definite.  Along
    an image edge the operator couples pixels strongly along the edge and weakly across it; errors that
    are smooth along such a line and oscillate across it are not reduced by point relaxation nor seen by
    the coarse grid, but one line solve removes them.
    """

    def __init__(self, A, shape, select=None):
        h, w = shape
        n = h * w
        dtype = A.dtype
        self.pbtrf, self.pbtrs = scipy.linalg.get_lapack_funcs(("pbtrf", "pbtrs"), dtype=dtype)
        diag = A.diagonal()
        self.blocks = []
        grid = np.arange(n).reshape(h, w)
        for axis, (step, lines) in enumerate(((1, grid), (w, grid.T))):
            near, far = (np.concatenate([A.diagonal(k * step), np.zeros(k * step, dtype=dtype)]) for k in (1, 2))
            chosen = None if select is None else (select[axis] if axis == 0 else select[axis].T)
            for c in range(3):
                idx = lines[c::3]
                if chosen is not None:
                    idx = idx[chosen[c::3]]
                idx = np.ascontiguousarray(idx).reshape(-1)
                if idx.size == 0:
                    continue
                gap1 = np.diff(idx, append=-1)
                gap2 = np.zeros_like(gap1)
                gap2[:-2] = idx[2:] - idx[:-2]
                ab = np.zeros((3, idx.size), dtype=dtype)
                ab[0] = diag[idx]
                ab[1] = np.where(gap1 == step, near[idx], np.where(gap1 == 2 * step, far[idx], 0))
                ab[2] = np.where(gap2 == 2 * step, far[idx], 0)
                factor, info = self.pbtrf(ab, lower=1)
                if info != 0:
                    raise ValueError("the line smoother needs a symmetric positive definite operator.")
                self.blocks.append((idx, A[idx], factor))

    def _step(self, block, x, b):
        idx, rows, factor = block
        r = b[idx] - rows @ x
        dx, _ = self.pbtrs(factor, r, lower=1)
        x[idx] += dx

    def forward(self, x, b):
        """One forward sweep (x-lines, then y-lines) on ``A x = b``, updating ``x`` in place."""
        for block in self.blocks:
            self._step(block, x, b)

    def backward(self, x, b):
        """The adjoint sweep: the block steps of :meth:`forward` in reverse order, updating ``x`` in place."""
        for block in self.blocks[::-1]:
            self._step(block, x, b)
