"""The multigrid hierarchy :class:`GridMultigrid`: set-up from stencils, :meth:`~GridMultigrid.update`, the V-cycle.

The set-up reads the fine stencil (:mod:`.stencils`), builds the prolongation
(:mod:`.interpolation`, :mod:`.transfer`) and the Galerkin coarse operators
(:mod:`.galerkin`) level by level, sets up the smoothers (:mod:`.smoothers`)
and factors the coarsest operator.  May import the sibling modules,
:mod:`sparsedepth.grid`, :mod:`sparsedepth._validation`, NumPy, SciPy and
pyamg; :mod:`.solve` only inside :meth:`GridMultigrid.solve`.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..._validation import as_grid_operator, check_grid_shape
from ...grid.stencil import FullPattern, SymmetricStencil, stencil_to_csr
from .bands import BandedStencil, FullStencil
from .galerkin import galerkin_offsets, galerkin_stencil
from .iteration import preconditioned_cg, prepare_rhs, vcycle_iteration
from .interpolation import bilinear_weights, operator_weights
from .smoothers import (LINE_OFFSETS, LineGaussSeidel, gauss_seidel_backward, gauss_seidel_forward, jacobi_damping,
                        jacobi_sweeps)
from .stencils import CollapsedSource, StencilSource, extract_stencil, fine_stencil_source, full_pattern_within
from .transfer import ClassProlongation, SeparableProlongation
from ...limits import memory_limits

__all__ = ["GridMultigrid", "grid_multigrid"]

_INTERPOLATIONS = ("bilinear", "operator", "auto")
_SMOOTHERS = ("gauss_seidel", "jacobi", "line_gauss_seidel")
# The sizes at which the hierarchy stores a level more leanly are sparsedepth.limits.MemoryLimits':
# single_coarse_pixels (fine grids from it keep their coarse levels in float32, coarse_precision="auto"),
# single_fine_values (fine operators with at most that many non-zeros are smoothed on a float32 copy,
# fine_precision="auto"; larger ones in float64, as the copy would weigh on the peak memory),
# keep_stencil_pixels (below it every CSR coarse level's stencil is kept as one (K, H, W) array during the set-up
# instead of being read back from its CSR form, the operator-dependent interpolation reads the fine operator into
# one such array once, and the line smoother's images of a fine CSR operator are copied as the bilinear product
# reads its rows; the bilinear product reads any level a band of rows at a time, the operator-dependent one a
# parity class at a time) and banded_coarse_pixels (with a fine SymmetricStencil
# smoothed in float64, coarse levels of at least that many pixels are float32 stencils swept band by band,
# :mod:`.bands`; smaller ones stay CSR).


class _Level:
    """One level of the hierarchy: operator, prolongation to it from below, smoother."""

    __slots__ = ("shape", "A", "offsets", "P", "diag_inv", "omega")

    def __init__(self, shape):
        self.shape = shape
        self.A = None
        self.offsets = None
        self.P = None  # prolongation from the next coarser level
        self.diag_inv = None
        self.omega = None


def _wide(offsets) -> bool:
    """True when the stencil of ``offsets`` reaches beyond radius 1 (13- and 25-point stencils)."""
    return any(max(abs(dy), abs(dx)) > 1 for dy, dx in offsets)


class GridMultigrid:
    r"""Geometric multigrid hierarchy for an SPD operator on a pixel grid.

    Build once, then use as a preconditioner many times; after the weights of
    the operator change (same grid, same stencil) call :meth:`update`, which
    recomputes only the numbers.

    Parameters
    ----------
    A : scipy.sparse matrix or SymmetricStencil, shape (N, N)
        Symmetric positive definite operator on a ``shape`` grid with pixels
        flattened in C order, coupling pixels at most 2 apart in each direction
        (5-, 9- or 13-point stencils).  Used as is when it is float64 CSR or a
        float64 :class:`~sparsedepth.grid.stencil.SymmetricStencil`; never
        modified.  A stencil gives the hierarchy of its CSR form, cycled bit
        for bit alike; when its fine level is smoothed in float64 (see
        `fine_precision`) the fine sweeps read the stencil band by band and
        the coarse levels of at least ``2**18`` pixels are kept as float32
        stencils: symmetric ones, or all the images of a level whose float32
        coefficients are not exactly symmetric
        (:class:`~sparsedepth.linalg.multigrid.bands.FullStencil`), swept
        band by band like the fine level, without the CSR forms' index arrays.
    shape : tuple of int
        Grid shape ``(H, W)`` with ``H * W == N``.
    interpolation : {"bilinear", "operator", "auto"}, default "bilinear"
        ``"bilinear"``: tensor product of 1-D linear interpolation, fixed per
        grid shape.  ``"operator"``: Dendy's black-box interpolation whose
        weights are read from the (collapsed) stencil; more robust when the
        weights jump across image edges.  A stencil of radius 2 (13- or
        25-point) is read as one of radius 1, each coupling moved to the
        neighbour in its direction
        (:class:`~sparsedepth.linalg.multigrid.stencils.CollapsedSource`);
        the Galerkin products use the stencil itself.  ``"auto"``:
        ``"operator"`` for radius-1 (5-/9-point) stencils, ``"bilinear"``
        otherwise; :attr:`interpolation` then holds the choice
        (``python -m bench.interpolation`` compares the two on the
        completion systems of radius 2).
    smoother : {"gauss_seidel", "jacobi", "line_gauss_seidel"}, default "gauss_seidel"
        Gauss--Seidel uses a forward sweep before and a backward sweep after
        the coarse-grid correction; Jacobi is damped with
        :math:`\omega = 4 / (3 \rho)`, :math:`\rho` the Gershgorin bound of
        :math:`D^{-1} A`.  ``"line_gauss_seidel"``: Gauss--Seidel, and on the
        fine level after the forward sweep a sweep of line Gauss--Seidel
        (:class:`~sparsedepth.linalg.multigrid.smoothers.LineGaussSeidel`:
        the pixels of `line_anisotropy` relaxed along rows, then along
        columns), its adjoint before the backward sweep; for operators
        whose weights drop across image edges, which couple the pixels
        along an edge much more strongly than across it.  All three keep
        the V-cycle symmetric.
    sweeps : int, default 1
        Smoothing sweeps (point sweeps) before and after the coarse-grid
        correction.
    line_anisotropy : float or None, default 4.0
        For ``smoother="line_gauss_seidel"``: the pixels relaxed along rows
        (columns) are those whose couplings along the row (column) outweigh
        those along the other axis by more than this ratio
        (:func:`~sparsedepth.linalg.multigrid.smoothers.anisotropic_pixels`);
        None: every pixel along both.  At least 1.
    max_coarse : int, default 1024
        Coarsening stops once a level has at most this many unknowns; that
        level is solved directly (sparse LU).
    max_levels : int, optional
        Upper bound on the number of levels.
    coarse_precision : {"auto", "double", "single"}, default "auto"
        Storage and smoothing precision of the coarse levels (level 1 on).
        ``"single"`` halves the bytes of the coarse operators' values and
        perturbs the preconditioner by float32 rounding only;
        ``"auto"`` takes it when the fine level is smoothed in single
        precision or the fine grid has at least ``2**21`` pixels.
    fine_precision : {"auto", "double", "single"}, default "auto"
        Precision of the V-cycle's work on the fine level (smoothing, the
        residual, the transfers).  ``"single"`` keeps a float32 copy of the
        fine operator's values (sharing its index arrays: 4 bytes per
        non-zero), so each sweep moves fewer bytes; the operator `A` itself
        is kept as given, so the residuals of :meth:`solve` and of PCG stay
        float64 and the accuracy of a solve is unchanged (the V-cycle is
        only a preconditioner).  ``"auto"`` takes it when `A` has at most
        ``2**26`` non-zeros (a copy of at most 256 MB: a 13-point system of
        up to about 5 megapixels).

    Attributes
    ----------
    levels : list
        Per level, fine to coarse: ``shape``, operator ``A`` (CSR) and
        prolongation ``P`` to it from the next coarser level (None at the
        coarsest).
    shape : tuple of int
        Fine grid shape.
    fine_dtype, coarse_dtype : numpy.dtype
        Precision of the V-cycle on the fine level and on the coarse levels
        (see `fine_precision` and `coarse_precision`).

    Raises
    ------
    ValueError
        For an unknown option, a `shape` that does not match `A`, or an `A`
        that is not a grid operator of stencil radius at most 2.

    See Also
    --------
    solve_spd : preconditioned conjugate gradients with this preconditioner.

    Notes
    -----
    Grid :math:`l+1` keeps the pixels of grid :math:`l` with even row and
    column indices, so an :math:`n`-pixel axis becomes :math:`\lceil n/2
    \rceil` (odd and even sizes alike).  With 1-D weights :math:`W^{(1)}`
    (weight 1 at coincident points, :math:`\tfrac12, \tfrac12` between two
    coarse points, 1 for a trailing point of an even-length axis) the bilinear
    prolongation is :math:`P = W^{(1)}_y \otimes W^{(1)}_x`; it reproduces
    constants, matching the Neumann boundary.

    For ``interpolation="operator"`` the stencil is collapsed across the
    interpolation direction: a pixel between two coarse points along :math:`x`
    gets weights :math:`-\bar a_W / \bar a_C` and :math:`-\bar a_E / \bar a_C`
    with :math:`\bar a_\ast` the column sums of its 3x3 stencil
    (same along :math:`y`), and a cell-centre pixel :math:`c` gets
    :math:`P_{c,:} = -a_{cc}^{-1} \sum_{n \ne c} a_{cn} P_{n,:}` from its eight
    neighbours [1]_.

    Coarse operators are Galerkin products :math:`A_{l+1} = P_l^\top A_l P_l`
    (the 5-point stencil becomes 9-point, a 13-point one 25-point, then stay
    so).  The V-cycle applied to a residual :math:`b` is

    .. math::

        x \leftarrow S_f^{\nu}(0, b),\quad
        x \leftarrow x + P\, V_{l+1}(P^\top (b - A x)),\quad
        x \leftarrow S_b^{\nu}(x, b)

    with :math:`S_f` / :math:`S_b` forward / backward Gauss--Seidel, which are
    adjoint in the :math:`A` inner product, and an exact solve on the coarsest
    grid; hence :math:`M^{-1} = V_0` is symmetric positive definite and can
    precondition CG.

    References
    ----------
    .. [1] J. E. Dendy, "Black box multigrid", J. Comput. Phys. 48 (1982)
       366-386.
    .. [2] U. Trottenberg, C. Oosterlee, A. Schueller, *Multigrid*, Academic
       Press, 2001.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> from scipy.sparse.linalg import cg
    >>> H, W = 30, 40
    >>> d = lambda n: sp.diags([-np.ones(n), np.r_[np.ones(n - 1), 0]], [0, 1])
    >>> Dx = sp.kron(sp.eye(H), d(W)); Dy = sp.kron(d(H), sp.eye(W))
    >>> A = (1e-2 * sp.eye(H * W) + Dx.T @ Dx + Dy.T @ Dy).tocsr()
    >>> mg = GridMultigrid(A, (H, W))
    >>> x, info = cg(A, np.ones(H * W), rtol=1e-10, M=mg.aspreconditioner())
    >>> info
    0
    """

    def __init__(self, A, shape, *, interpolation="bilinear",
                 smoother="gauss_seidel", sweeps=1, max_coarse=1024,
                 max_levels=None, coarse_precision="auto", fine_precision="auto", line_anisotropy=4.0):
        for name, value in (("coarse_precision", coarse_precision), ("fine_precision", fine_precision)):
            if value not in ("auto", "double", "single"):
                raise ValueError(f"`{name}` must be 'auto', 'double' or 'single', got {value!r}.")
        if interpolation not in _INTERPOLATIONS:
            raise ValueError(
                f"unknown interpolation {interpolation!r}; "
                f"use one of {_INTERPOLATIONS}."
            )
        if smoother not in _SMOOTHERS:
            raise ValueError(
                f"unknown smoother {smoother!r}; use one of {_SMOOTHERS}."
            )
        if line_anisotropy is not None and not float(line_anisotropy) >= 1.0:
            raise ValueError(f"`line_anisotropy` must be a ratio of at least 1, or None; got {line_anisotropy!r}.")
        if int(sweeps) < 1:
            raise ValueError(f"`sweeps` must be a positive integer, got {sweeps!r}.")
        if int(max_coarse) < 1:
            raise ValueError(
                f"`max_coarse` must be a positive integer, got {max_coarse!r}."
            )
        if max_levels is not None and int(max_levels) < 1:
            raise ValueError(
                f"`max_levels` must be a positive integer or None, got {max_levels!r}."
            )
        self.requested_interpolation = interpolation
        self.interpolation = interpolation
        self.smoother = smoother
        self.sweeps = int(sweeps)
        self.line_anisotropy = None if line_anisotropy is None else float(line_anisotropy)
        self.max_coarse = int(max_coarse)
        self.max_levels = None if max_levels is None else int(max_levels)
        A, shape = _as_fine_operator(A, shape)
        self.shape = shape
        limits = memory_limits()
        large = shape[0] * shape[1] >= limits.single_coarse_pixels
        fine_single = fine_precision == "single" or (fine_precision == "auto" and A.nnz <= limits.single_fine_values)
        coarse_single = coarse_precision == "single" or (coarse_precision == "auto" and (large or fine_single))
        self.fine_dtype = np.dtype(np.float32 if fine_single else np.float64)
        self.coarse_dtype = np.dtype(np.float32 if coarse_single else np.float64)
        self._banded = isinstance(A, SymmetricStencil) and not fine_single
        self._build(A)

    # ---- construction -------------------------------------------------------
    def _shapes(self):
        shapes = [self.shape]
        while True:
            h, w = shapes[-1]
            if h * w <= self.max_coarse or (h == 1 and w == 1):
                break
            if self.max_levels is not None and len(shapes) >= self.max_levels:
                break
            shapes.append(((h + 1) // 2, (w + 1) // 2))
        return shapes

    def _keeps_stencils(self):
        """True when the set-up holds each level's stencil as one array (grids below ``keep_stencil_pixels``)."""
        return self.shape[0] * self.shape[1] < memory_limits().keep_stencil_pixels

    def _build(self, A):
        offsets, source = fine_stencil_source(A, self.shape)
        if self.requested_interpolation == "auto":
            self.interpolation = "bilinear" if _wide(offsets) else "operator"
        shapes = self._shapes()
        levels = []
        for li, shp in enumerate(shapes):
            lvl = _Level(shp)
            if li == 0:
                lvl.A = A
            levels.append(lvl)
        # structure: offsets of the coarse operators (their CSR form is made by
        # stencil_to_csr in _numeric); P is made there too
        levels[0].offsets = offsets
        for li in range(1, len(levels)):
            levels[li].offsets = galerkin_offsets(levels[li - 1].offsets)
        self.levels = levels
        box = [source]
        del source  # _numeric drops the fine stencil as soon as the first Galerkin product is done
        self._numeric(box)

    def _numeric(self, box, refill_p=True):
        """Numeric setup: interpolation weights, Galerkin products, smoothers, LU.

        ``box`` is a one-element list holding the fine :class:`StencilSource`,
        emptied here so that the fine stencil is freed after the first
        Galerkin product.
        """
        source = box.pop()
        keep = self._keeps_stencils()
        if keep and self.interpolation == "operator":  # the weights and the products read it class by class
            source.read_whole()
        levels = self.levels
        line_images = None
        if self.smoother == "line_gauss_seidel" and source.array is not None:
            line_images = dict(zip(source.offsets, source.array))
        elif self.smoother == "line_gauss_seidel" and source.csr is not None and keep:
            # the bilinear product reads the stencil a band of rows at a time: the line smoother's images are
            # copied as they pass (used only if every row was read); larger grids read them from the matrix
            line_images = source.keep_images(LINE_OFFSETS)
        for li in range(len(levels) - 1):
            fine, coarse = levels[li], levels[li + 1]
            if self.interpolation == "operator":
                seen = CollapsedSource(source) if _wide(fine.offsets) else source  # weights read radius 1
                interp = operator_weights(seen.offsets, seen, fine.shape)
                del seen
                fine.P = ClassProlongation(interp, fine.shape, self.coarse_dtype)
            else:
                interp = bilinear_weights(fine.shape)
                if refill_p:
                    fine.P = SeparableProlongation(fine.shape)
            banded = self._banded and coarse.shape[0] * coarse.shape[1] >= memory_limits().banded_coarse_pixels
            # a banded level is stored image by image from a list, each float64 image freed once stored
            S = galerkin_stencil(fine.offsets, source, interp, fine.shape, coarse.offsets, as_list=banded)
            del source, interp  # the fine level's weights are kept by its prolongation (float32 for operator ones)
            symmetric = (SymmetricStencil.from_stencil(coarse.offsets, S, dtype=self.coarse_dtype, copy=False)
                         if banded else None)
            if symmetric is not None:
                # symmetric once stored: half the images, no index arrays
                coarse.A = symmetric
                source = StencilSource(coarse.offsets, coarse.shape, symmetric=symmetric)
                del S
                continue
            if banded:
                # not exactly symmetric in its precision: every image, still no index arrays (half the CSR form)
                coarse.A = FullStencil(coarse.offsets, S, self.coarse_dtype)
                source = StencilSource(coarse.offsets, coarse.shape, array=coarse.A.data)
                del S
                continue
            coarse.A = stencil_to_csr(coarse.offsets, S, dtype=self.coarse_dtype)
            if keep:
                source = StencilSource(coarse.offsets, coarse.shape, array=S)
            elif (pattern := FullPattern(coarse.offsets, coarse.shape)).recognisable:  # smaller grids keep S
                # read back by position, class by class or band by band: the coarse stencil array can go
                source = StencilSource(coarse.offsets, coarse.shape, csr=coarse.A, pattern=pattern)
            else:
                source = StencilSource(coarse.offsets, coarse.shape, array=S)
            del S
        del source
        A = levels[0].A
        if isinstance(A, SymmetricStencil):
            # float64: swept band by band from the stencil itself (no copy); float32: a CSR copy of its own
            self._fine_cycle_A = (BandedStencil(A, A.dtype) if self.fine_dtype == A.dtype
                                  else A.tocsr(dtype=self.fine_dtype))
        else:
            # the fine level's operator in the cycle's precision: a float32 copy of the values, same index arrays
            self._fine_cycle_A = A if self.fine_dtype == A.dtype else sp.csr_matrix(
                (A.data.astype(self.fine_dtype), A.indices, A.indptr), shape=A.shape)
        # the operator each smoothed level is cycled with: the fine one in the cycle's precision, stencils band-wise
        self._cycle_ops = [self._fine_cycle_A] + [
            BandedStencil(lvl.A, lvl.A.dtype) if isinstance(lvl.A, (SymmetricStencil, FullStencil)) else lvl.A
            for lvl in levels[1:-1]]
        for lvl in levels[:-1]:
            self._setup_smoother(lvl)
        self._line = None
        if self.smoother == "line_gauss_seidel" and len(levels) > 1:
            # a stencil swept band by band: the line steps gather its rows from the stencil itself
            fine = self._fine_cycle_A if sp.issparse(self._fine_cycle_A) else A
            if line_images is not None and not isinstance(line_images, dict):
                line_images = line_images.images if line_images.complete else None
            self._line = LineGaussSeidel(fine, self.shape, images=line_images, anisotropy=self.line_anisotropy)
        del line_images
        self._factor_coarsest()

    def _setup_smoother(self, lvl):
        if self.smoother == "jacobi":
            lvl.diag_inv, lvl.omega = jacobi_damping(lvl.A)

    def _factor_coarsest(self):
        Ac = self.levels[-1].A
        if isinstance(Ac, (SymmetricStencil, FullStencil)):  # a one-level hierarchy of a stencil, or a large level
            Ac = Ac.tocsr()
        self._pinv = None
        self._lu = None
        try:
            lu = spla.splu(sp.csc_matrix(Ac, dtype=np.float64))
            pivots = np.abs(lu.U.diagonal())
            if not pivots.min() > 1e3 * Ac.shape[0] * np.finfo(float).eps * pivots.max():
                raise RuntimeError("numerically singular")
            self._lu = lu
        except RuntimeError:
            # singular coarsest operator (e.g. pure Neumann problem): pseudo-inverse
            self._lu = None
            self._pinv = scipy.linalg.pinvh(Ac.toarray().astype(np.float64))

    def _coarse_solve(self, b):
        if self._lu is not None:
            return self._lu.solve(b)
        return self._pinv @ b

    # ---- public API ---------------------------------------------------------
    def update(self, A):
        """Recompute the hierarchy numerically for a new operator on the same grid.

        Parameters
        ----------
        A : scipy.sparse matrix, shape (N, N)
            New SPD operator on the same grid whose stencil is contained in the
            stencil of the operator this hierarchy was built for (typically the
            same sparsity pattern with new weights).

        Returns
        -------
        self : GridMultigrid

        Raises
        ------
        ValueError
            If `A` does not fit the grid.

        Notes
        -----
        Interpolation weights (for ``interpolation="operator"``), Galerkin
        coarse operators, smoother data and the coarsest factorisation are
        recomputed into the existing sparsity patterns; the grid hierarchy,
        the coarse operators' patterns and the bilinear prolongation are reused.  If the stencil
        gained offsets, the structure is rebuilt.
        """
        A, _ = _as_fine_operator(A, self.shape)
        offsets = self.levels[0].offsets
        if isinstance(A, SymmetricStencil):
            if not set(A.offsets) <= set(offsets):
                self._build(A)
                return self
            source = StencilSource(offsets, self.shape, symmetric=A)
        elif (pattern := full_pattern_within(A, self.shape)) is not None and set(pattern.offsets) <= set(offsets):
            source = StencilSource(offsets, self.shape, csr=A, pattern=pattern)
        else:
            S = extract_stencil(A, self.shape, offsets)
            if int(np.count_nonzero(S)) != int(np.count_nonzero(A.data)):
                # the stencil grew (a pixel and a diagonal determine at most one
                # in-grid offset, so equal non-zero counts mean nothing is missing)
                del S
                self._build(A)
                return self
            source = StencilSource(offsets, self.shape, array=S)
            del S
        self.levels[0].A = A
        box = [source]
        del source
        self._numeric(box, refill_p=False)
        return self

    def vcycle(self, b):
        """Apply one V-cycle with zero initial guess, i.e. :math:`M^{-1} b`.

        Parameters
        ----------
        b : array_like, shape (N,)
            Right-hand side (a residual, when used as a preconditioner).

        Returns
        -------
        x : ndarray, shape (N,)
        """
        b = np.ascontiguousarray(b, dtype=self.fine_dtype).reshape(-1)
        levels = self.levels
        nu = self.sweeps
        cycle_ops = self._cycle_ops
        xs, bs = [], []
        for lvl, A in zip(levels[:-1], cycle_ops):
            x = np.zeros_like(b)
            if lvl.diag_inv is None:
                gauss_seidel_forward(A, x, b, nu)
                if self._line is not None and lvl is levels[0]:
                    self._line.forward(x, b)
            else:
                self._jacobi(lvl, x, b, A)
            xs.append(x)
            bs.append(b)
            b = _restricted_residual(A, lvl.P, x, b).astype(self.coarse_dtype, copy=False)
        x = self._coarse_solve(b.astype(np.float64, copy=False)).astype(self.coarse_dtype, copy=False)
        for lvl, A, xf, bf in zip(levels[-2::-1], cycle_ops[::-1], xs[::-1], bs[::-1]):
            lvl.P.add_prolonged(xf, x)
            if self._line is not None and lvl is levels[0]:
                self._line.backward(xf, bf)
            if lvl.diag_inv is None:
                gauss_seidel_backward(A, xf, bf, nu)
            else:
                self._jacobi(lvl, xf, bf, A)
            x = xf
        return x.astype(np.float64, copy=False)

    def _jacobi(self, lvl, x, b, A):
        """``sweeps`` damped Jacobi sweeps on ``A x = b`` (``A``: ``lvl``'s operator in the cycle's precision)."""
        jacobi_sweeps(A, x, b, lvl.diag_inv, lvl.omega, self.sweeps)

    def aspreconditioner(self):
        """The V-cycle as a :class:`scipy.sparse.linalg.LinearOperator`.

        Returns
        -------
        M : LinearOperator, shape (N, N)
            ``M @ r`` applies one V-cycle (symmetric positive definite), for
            the ``M=`` argument of :func:`scipy.sparse.linalg.cg`.
        """
        n = self.levels[0].A.shape[0]
        return spla.LinearOperator((n, n), matvec=self.vcycle, dtype=np.float64)

    def solve(self, b, *, x0=None, rtol=1e-8, atol=0.0, maxiter=None,
              accel="cg", callback=None):
        r"""Solve :math:`A x = b` with this hierarchy.

        Parameters
        ----------
        b : array_like, shape (N,) or (H, W)
            Right-hand side.
        x0 : array_like, optional
            Initial guess (zero by default).
        rtol, atol : float
            Stop when :math:`\|b - A x_k\|_2 \le \max(\mathrm{rtol}\,\|b\|_2,
            \mathrm{atol})`.
        maxiter : int, optional
            Maximum number of iterations (CG iterations or V-cycles); default
            ``10 * N`` for CG and 100 for plain cycling.
        accel : {"cg", None}, default "cg"
            ``"cg"``: V-cycle-preconditioned conjugate gradients; ``None``:
            stationary V-cycle iteration
            :math:`x_{k+1} = x_k + M^{-1}(b - A x_k)`.
        callback : callable, optional
            Called as ``callback(xk)`` with a copy of the iterate after each
            iteration; may raise ``StopIteration`` to stop early.

        Returns
        -------
        x : ndarray, same shape as `b`
        info : SolveInfo
            Convergence flag, iteration count, residual history.
        """
        if accel == "cg":
            A = self.levels[0].A
            b_arr, x_init, bnorm = prepare_rhs(b, x0, A.shape[0])
            t0 = time.perf_counter()
            M = self.aspreconditioner()
            return preconditioned_cg(A, b_arr, x_init, bnorm, M=M, name=type(self).__name__, rtol=rtol, atol=atol,
                                     maxiter=maxiter, callback=callback, setup_time=time.perf_counter() - t0,
                                     out_shape=np.shape(b))
        if accel is not None:
            raise ValueError(f"unknown accel {accel!r}; use 'cg' or None.")
        return vcycle_iteration(self, b, x0=x0, rtol=rtol, atol=atol, maxiter=maxiter, callback=callback)

    def to_pyamg(self):
        """The same hierarchy as a :class:`pyamg.multilevel.MultilevelSolver`.

        Returns
        -------
        ml : pyamg.multilevel.MultilevelSolver
            Shares the float64 operators (no copies); float32 coarse levels
            are converted to float64, as pyamg cycles in the precision of the
            fine level, and the prolongations to CSR matrices.  Its cycle
            is therefore the float64 form of :meth:`vcycle` (equal to it for
            ``fine_precision = coarse_precision = "double"``).  Use its
            ``solve(b, accel='cg')``, ``aspreconditioner()``, ``cycle_complexity``.
        """
        from pyamg.multilevel import MultilevelSolver

        pyamg_levels = []
        for lvl in self.levels:
            L = MultilevelSolver.Level()
            L.A = (lvl.A.tocsr(dtype=np.float64) if isinstance(lvl.A, (SymmetricStencil, FullStencil))
                   else lvl.A.astype(np.float64, copy=False))
            if lvl.P is not None:
                L.P = (lvl.P if sp.issparse(lvl.P) else lvl.P.tocsr()).astype(np.float64, copy=False)
                L.R = L.P.T.tocsr()
                if lvl.diag_inv is None and self._line is not None and lvl is self.levels[0]:
                    nu, line = self.sweeps, self._line
                    L.presmoother = lambda A, x, b, nu=nu: (gauss_seidel_forward(A, x, b, nu), line.forward(x, b))
                    L.postsmoother = lambda A, x, b, nu=nu: (line.backward(x, b), gauss_seidel_backward(A, x, b, nu))
                elif lvl.diag_inv is None:
                    nu = self.sweeps
                    L.presmoother = lambda A, x, b, nu=nu: gauss_seidel_forward(A, x, b, nu)
                    L.postsmoother = lambda A, x, b, nu=nu: gauss_seidel_backward(A, x, b, nu)
                else:
                    L.presmoother = L.postsmoother = (
                        lambda A, x, b, lvl=lvl: self._jacobi(lvl, x, b, A))
            pyamg_levels.append(L)
        ml = MultilevelSolver(pyamg_levels, coarse_solver=_CoarseSolve(self))
        ml.symmetric_smoothing = True  # forward GS before, backward GS after
        return ml

    # ---- reporting ----------------------------------------------------------
    def operator_complexity(self):
        """Sum over levels of non-zeros divided by the fine-level non-zeros."""
        return sum(lvl.A.nnz for lvl in self.levels) / self.levels[0].A.nnz

    def grid_complexity(self):
        """Sum over levels of unknowns divided by the fine-level unknowns."""
        n0 = self.levels[0].A.shape[0]
        return sum(lvl.A.shape[0] for lvl in self.levels) / n0

    def __repr__(self):
        total = sum(lvl.A.nnz for lvl in self.levels)
        coarse = "splu" if self._lu is not None else "pinv"
        lines = [
            f"GridMultigrid(shape={self.shape}, interpolation={self.interpolation!r}, "
            f"smoother={self.smoother!r}, sweeps={self.sweeps})",
            f"Number of Levels:     {len(self.levels)}",
            f"Operator Complexity:  {self.operator_complexity():6.3f}",
            f"Grid Complexity:      {self.grid_complexity():6.3f}",
            f"Coarse Solver:        {coarse}",
            "  level      grid     unknowns     nonzeros  stencil",
        ]
        for i, lvl in enumerate(self.levels):
            h, w = lvl.shape
            lines.append(
                f"{i:>7} {f'{h}x{w}':>9} {h * w:>12} {lvl.A.nnz:>12}  "
                f"{len(lvl.offsets):>2}-point [{100 * lvl.A.nnz / total:5.2f}%]"
            )
        return "\n".join(lines)


class _CoarseSolve:
    """Callable coarsest-grid solve for pyamg (reuses our factorisation)."""

    def __init__(self, mg):
        self._mg = mg

    def __call__(self, A, b):
        return self._mg._coarse_solve(np.asarray(b, dtype=np.float64).ravel())

    def __repr__(self):
        return "splu" if self._mg._lu is not None else "pinv"


def _restricted_residual(A, P, x, b):
    """``Pᵀ (b − A x)``, the right-hand side of the next coarser level.

    For the bilinear ``P`` and a symmetric stencil in its own precision (the fine level of large frames) it is
    summed a band of rows at a time, without the fine residual (the same numbers); else through the whole
    residual.
    """
    if (isinstance(P, SeparableProlongation) and isinstance(A, BandedStencil)
            and isinstance(A.stencil, SymmetricStencil) and x.dtype == b.dtype == A.stencil.dtype):
        rhs = b.reshape(A.grid_shape)

        def residual_rows(y0, y1):
            r = A.stencil.matvec_rows(x, y0, y1)
            return np.subtract(rhs[y0:y1], r, out=r)

        return P.restrict_rows(residual_rows, x.dtype)
    r = A @ x
    np.subtract(b, r, out=r)
    return P.T @ r


def _as_fine_operator(A, shape):
    """``(A, shape)``: a float64 :class:`SymmetricStencil` as it is (checked against ``shape``), else canonical CSR."""
    if isinstance(A, SymmetricStencil):
        shape = check_grid_shape(shape)
        if A.grid_shape != shape:
            raise ValueError(f"`A` is a stencil on a grid of shape {A.grid_shape}, but shape={shape} was passed; pass "
                             "the grid the stencil was built on.")
        return A.astype(np.float64, copy=False), shape
    return as_grid_operator(A, shape)


def grid_multigrid(A, shape, **options):
    """Build a :class:`GridMultigrid` (functional spelling; same parameters)."""
    return GridMultigrid(A, shape, **options)
