r"""Smoothers of the V-cycle: Gauss--Seidel sweeps (pyamg's compiled kernel) and damped Jacobi.

Forward Gauss--Seidel before and backward after the coarse-grid correction
are adjoint in the :math:`A` inner product, and damped Jacobi is symmetric,
so either keeps the V-cycle a symmetric preconditioner.  May import NumPy,
SciPy, pyamg and :mod:`sparsedepth.grid`.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from pyamg import amg_core

from ...grid.stencil import SymmetricStencil, index_dtype
from ...limits import memory_limits

__all__ = ["LINE_OFFSETS", "gauss_seidel_forward", "gauss_seidel_backward", "jacobi_damping", "jacobi_sweeps", "LineGaussSeidel",
           "anisotropic_pixels", "stencil_rows_product"]



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


#: The offsets of a stencil that :class:`LineGaussSeidel` reads (the couplings along rows and columns).
LINE_OFFSETS = ((0, 0), (0, 1), (0, 2), (1, 0), (2, 0))


def _line_bands(A, shape, images):
    """``{offset: image}`` of the couplings ``(0, 0)``, ``(0, 1)``, ``(0, 2)``, ``(1, 0)``, ``(2, 0)`` of ``A``.

    The images of a :class:`~sparsedepth.grid.stencil.SymmetricStencil` ``A``; for a CSR ``A`` taken from
    ``images`` (a ``{offset: (H, W) image}`` mapping of the stencil) where it has them, else read as diagonals
    of ``A`` (zero where the neighbour is outside the grid).
    """
    h, w = shape
    n = h * w
    if isinstance(A, SymmetricStencil):  # every offset >= (0, 0) is stored: its images, no copy
        images = dict(zip(A.upper, A.images))
        return {o: images[o] if o in images else np.zeros(shape, dtype=A.dtype) for o in LINE_OFFSETS}
    out = {}
    for dy, dx in LINE_OFFSETS:
        if images is not None and (dy, dx) in images:
            out[dy, dx] = np.asarray(images[dy, dx])
            continue
        k = dy * w + dx
        band = np.zeros(n, dtype=A.dtype)
        if k < n:
            band[:n - k] = A.diagonal(k)
        band = band.reshape(h, w)
        if dx:
            band[:, w - dx:] = 0.0
        out[dy, dx] = band
    return out


def stencil_rows_product(A, idx, x, out):
    r"""The rows ``idx`` of ``A @ x`` for a :class:`~sparsedepth.grid.stencil.SymmetricStencil` ``A``.

    Parameters
    ----------
    A : SymmetricStencil, shape (N, N)
    idx : ndarray of int, shape (m,)
        Flat (C-order) pixel indices.
    x : ndarray, shape (N,)
        Finite values.
    out : ndarray, shape (m,)
        Receives :math:`(A x)_i`, ``i`` in ``idx``.

    Returns
    -------
    out : ndarray, shape (m,)

    Notes
    -----
    Gathered from the stored images at the pixels' indices, with no rows of ``A`` built:

    .. math::

        (A x)_p = a_0[p] x_p + \sum_{u > 0} \left( a_u[p] x_{p + u} + a_u[p - u] x_{p - u} \right),

    ``u`` over the stored offsets after ``(0, 0)`` as flat index steps, :math:`a_{-u}[p] = a_u[p - u]` by
    symmetry.  A neighbour outside the grid has a zero coefficient; its flat index (``p + u`` past the end,
    ``p - u`` before the start, or a pixel of the next or previous image row) reads that zero: ``x`` is
    read with clipped indices, the coefficient ``a_u[p - u]`` with ``p - u < 0`` at ``p - u + N``, a pixel
    whose neighbour at ``u`` lies past the grid's last row.  Pixels go ``gather_pixels``
    (:class:`~sparsedepth.limits.MemoryLimits`) at a time, so the temporaries stay small.
    """
    h, w = A.grid_shape
    # an offset reaching past the grid from every pixel has a zero image; the others step 0 < dy W + dx < N
    terms = [(dy * w + dx, image.reshape(-1)) for (dy, dx), image in zip(A.upper, A.images)
             if dy < h and abs(dx) < w]
    chunk = max(1, memory_limits().gather_pixels)
    for start in range(0, idx.shape[0], chunk):
        p = idx[start:start + chunk]
        acc = out[start:start + chunk]
        acc[:] = 0.0
        for step, a in terms:
            if step == 0:
                acc += a[p] * x[p]
                continue
            q = p + step
            acc += a[p] * np.take(x, q, mode="clip")
            np.subtract(p, step, out=q)
            acc += a[q] * np.take(x, q, mode="clip")  # a[q], q < 0: a[q + n] (NumPy's negative indices)
    return out


def _line_pixels(pick, axis, c):
    """Flat indices of the ``True`` pixels of ``pick`` on the rows (``axis`` 0) or columns (1) ``≡ c (mod 3)``.

    Ordered line by line, and along each line by position (row-major for rows, column-major for columns).
    """
    h, w = pick.shape
    if axis == 0:
        line, pos = np.divmod(np.flatnonzero(pick[c::3]), w)
        return (c + 3 * line) * w + pos
    line, pos = np.divmod(np.flatnonzero(pick[:, c::3].T), h)
    return pos * w + c + 3 * line


def anisotropic_pixels(bands, anisotropy):
    r"""The pixels whose couplings along one axis outweigh those along the other by more than `anisotropy`.

    Parameters
    ----------
    bands : dict
        ``{(dy, dx): (H, W) image}`` of the couplings at the offsets ``(0, 1)``, ``(0, 2)``, ``(1, 0)``,
        ``(2, 0)`` of a symmetric grid operator (zero where the neighbour is outside the grid).
    anisotropy : float
        The ratio, at least 1.

    Returns
    -------
    along_x, along_y : ndarray of bool, shape (H, W)
        :math:`s_x > \theta s_y` and :math:`s_y > \theta s_x`.

    Notes
    -----
    :math:`s_x(y, x) = \sum_{d = \pm 1, \pm 2} |a_{(y, x), (y, x + d)}|` and :math:`s_y` likewise along
    :math:`y`; the couplings at negative offsets are those of the neighbour at the positive one (symmetry).
    """
    h, w = bands[0, 0].shape
    a = np.empty((h, w))
    strength = []
    for offsets in (((0, 1), (0, 2)), ((1, 0), (2, 0))):
        total = None
        for dy, dx in offsets:
            np.abs(bands[dy, dx], out=a)
            if total is None:
                total = a.copy()  # the sum starts from 0: 0 + |a| is |a|
            else:
                total += a
            total[dy:, dx:] += a[:h - dy, :w - dx]
        strength.append(total)
    sx, sy = strength
    np.multiply(sy, anisotropy, out=a)
    along_x = sx > a
    np.multiply(sx, anisotropy, out=a)
    return along_x, sy > a


class LineGaussSeidel:
    r"""Alternating line Gauss--Seidel for a grid operator of stencil radius at most 2 (CSR or symmetric stencil).

    Parameters
    ----------
    A : scipy.sparse CSR matrix or SymmetricStencil, shape (N, N)
        Symmetric positive definite operator on the grid, float32 or float64 (the sweeps' precision).
    shape : tuple of int
        Grid shape ``(H, W)``.
    images : dict, optional
        ``{(dy, dx): (H, W) image}`` of ``A``'s stencil (zero outside the grid); the couplings along the
        lines are read from it where it has them, else from the diagonals of ``A`` (a
        :class:`~sparsedepth.grid.stencil.SymmetricStencil`: from its own images).
    anisotropy : float, optional
        Relax along the lines only the pixels of :func:`anisotropic_pixels` with this ratio (``x``-lines:
        those coupled more strongly along ``x``, ``y``-lines: along ``y``); None: every pixel on both.

    Notes
    -----
    The relaxed pixels are split into six blocks: those on the rows :math:`y \equiv c \pmod 3` (``x``-lines),
    then those on the columns :math:`x \equiv c \pmod 3` (``y``-lines), :math:`c = 0, 1, 2`.  Lines of one
    block lie at least three pixels apart, so with couplings at most two pixels apart the block's matrix
    :math:`A_{BB}` is block diagonal, one pentadiagonal SPD matrix per line (or per run of chosen pixels of a
    line), factored once (banded Cholesky :math:`A_{BB} = L L^\top`, LAPACK ``pbtrf``; :math:`L` kept as its
    three bands).
    A block step is

    .. math::

        x_B \leftarrow x_B + A_{BB}^{-1} (b - A x)_B ,

    with :math:`(A x)_B` from the block's rows of :math:`A`, kept as a CSR slice for a CSR ``A`` and gathered
    from the images at each step for a :class:`~sparsedepth.grid.stencil.SymmetricStencil`
    (:func:`stencil_rows_product`: no copy of its coefficients, only the block's pixel indices), and
    :math:`A_{BB}^{-1}` applied by forward and back substitution with :math:`L` and :math:`L^\top` (LAPACK
    ``pbtrs``).  Besides the CSR slice of a CSR ``A``, the smoother keeps 4 or 8 bytes of index and three
    coefficients of :math:`L` per relaxed pixel and line direction.
    :meth:`forward` takes the blocks in that order, :meth:`backward` in the reverse one: as for point
    Gauss--Seidel the two sweeps' error propagators :math:`I - B^{-1} A` and :math:`I - B^{-\top} A` are
    adjoint in the :math:`A` inner product, so a V-cycle with one before and the other after the coarse-grid
    correction stays symmetric positive definite.

    Along an image edge the operator couples pixels strongly along the edge and weakly across it.  Errors
    smooth along such a line and oscillating across it are barely reduced by point relaxation, and the
    coarse grids (every other row and column) do not represent them; one line solve removes them [1]_.

    References
    ----------
    .. [1] U. Trottenberg, C. Oosterlee, A. Schueller, *Multigrid*, Academic Press, 2001, section 5.1.
    """

    def __init__(self, A, shape, *, images=None, anisotropy=None):
        w = shape[1]
        dtype = A.dtype
        self.stencil = A if isinstance(A, SymmetricStencil) else None
        self.pbtrf, self.pbtrs = scipy.linalg.get_lapack_funcs(("pbtrf", "pbtrs"), dtype=dtype)
        index = index_dtype(2 * shape[0] * shape[1])  # p + u < 2 N in stencil_rows_product
        bands = _line_bands(A, shape, images)
        chosen = (None, None) if anisotropy is None else anisotropic_pixels(bands, anisotropy)
        flat = {offset: band.reshape(-1) for offset, band in bands.items()}
        self.blocks = []
        self.size = 0
        for axis, step, near, far in ((0, 1, flat[0, 1], flat[0, 2]), (1, w, flat[1, 0], flat[2, 0])):
            pick = np.ones(shape, dtype=bool) if anisotropy is None else chosen[axis]
            for c in range(3):
                idx = _line_pixels(pick, axis, c).astype(index)
                if idx.size == 0:
                    continue
                a1, a2 = near[idx], far[idx]
                # the next chosen pixel of the line 1 or 2 steps on, the one after next 2 steps on
                gap1 = np.diff(idx, append=-1)
                gap2 = np.full_like(gap1, -1)
                gap2[:-2] = idx[2:] - idx[:-2]
                ab = np.zeros((3, idx.size), dtype=dtype)
                ab[0] = flat[0, 0][idx]
                ab[1] = np.where(gap1 == step, a1, np.where(gap1 == 2 * step, a2, 0))
                ab[2] = np.where(gap2 == 2 * step, a2, 0)
                factor, info = self.pbtrf(ab, lower=1)
                if info != 0:
                    raise ValueError("the line smoother needs a symmetric positive definite operator.")
                rows = None if self.stencil is not None else A[idx]
                self.blocks.append((idx, rows, factor))
                self.size += idx.size

    def _step(self, block, x, b):
        idx, rows, factor = block
        if rows is None:
            r = stencil_rows_product(self.stencil, idx, x, np.empty(idx.shape[0], dtype=x.dtype))
            np.subtract(b[idx], r, out=r)
        else:
            r = b[idx] - rows @ x
        dx, _ = self.pbtrs(factor, r, lower=1, overwrite_b=1)  # L L^T dx = r (info < 0 only for bad arguments)
        x[idx] += dx

    def forward(self, x, b):
        """One sweep (the x-line blocks, then the y-line blocks) on ``A x = b``, updating ``x`` in place."""
        for block in self.blocks:
            self._step(block, x, b)

    def backward(self, x, b):
        """The adjoint sweep: the block steps of :meth:`forward` in reverse order, updating ``x`` in place."""
        for block in self.blocks[::-1]:
            self._step(block, x, b)
