"""The solvers of the quadratic problem (γ = 0): ``direct``, ``cg`` and ``amg``.

Each minimises ``F(z) = zᵀAz − 2bᵀz + c`` without bounds, i.e. solves the
normal equations ``A z = b``.

May import :mod:`sparsedepth.linalg`, :mod:`sparsedepth.grid`, :mod:`sparsedepth.limits`,
:mod:`sparsedepth.profiling` and the other modules of :mod:`sparsedepth.solvers`.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from ..grid.diagonals import stencil_to_dia
from ..grid.operators import StencilOperator
from ..linalg.krylov import dot, pcg, pcg_info
from ..linalg.multigrid import GridMultigrid
from ..linalg.preconditioners import make_preconditioner
from ..limits import memory_limits
from ..profiling import phase
from .common import output, quick_value, require_quadratic

__all__ = ["solve_direct", "solve_cg", "solve_amg", "single_precision_cg", "RemainingChange", "DEFAULT_DEPTH_RTOL",
           "default_hierarchy"]

#: ``depth_rtol`` of the ``amg`` solve of :func:`sparsedepth.complete_depth` when neither ``tol`` nor a depth
#: tolerance is given: an RMS remaining change of 3e-4 of the depth scale.
DEFAULT_DEPTH_RTOL = 3e-4


def solve_direct(objective, x0, *, tol=None, max_iter=None, recorder, options):
    """Sparse LU (SuperLU) solve of ``A z = b``; the reference for γ = 0."""
    require_quadratic(objective, "direct")
    recorder(0, x0)
    A, b, _ = objective.normal_equations()
    z = spsolve(sp.csc_matrix(A), b)
    recorder(1, z)
    return output(z, 1, True, "direct sparse solve", recorder)


class RemainingChange:
    r"""Estimate of the remaining change ``‖z_k − z*‖_RMS`` of a CG solve from its steps; a stopping rule.

    Called as ``stop(step, direction)`` by :func:`~sparsedepth.linalg.krylov.pcg`
    after every iteration; returns True once :attr:`estimate` ``<= tol``.

    Parameters
    ----------
    size : int
        Number of unknowns ``N``.
    tol : float
        The tolerance on the estimate (units of the unknowns).
    window : int, default 3
        Steps whose ratios estimate the contraction rate.
    max_rate : float, default 0.95
        A larger estimated rate gives no estimate (``inf``): the iteration
        is not contracting steadily.

    Attributes
    ----------
    estimate : float
        The estimate after the last step (``inf`` before ``window + 1`` steps).
    steps : list of float
        ``s_j = ‖z_{j+1} − z_j‖_RMS = |α_j| ‖p_j‖₂ / √N`` of every step.

    Notes
    -----
    With the steps contracting at a rate ``ρ`` (``s_{j+1} ≈ ρ s_j``), the
    remaining change after step ``k`` is ``z* − z_{k+1} = Σ_{j>k} α_j p_j``,
    of RMS norm at most ``Σ_{j>k} s_j ≈ s_k ρ / (1 − ρ)``.  ``ρ`` is the
    largest ratio ``s_j / s_{j−1}`` over the last ``window`` steps (the
    largest, so a transient fast step does not end the solve).  It is an
    estimate, not a bound: a later phase of slower convergence is not
    foreseen.  ``python -m bench.speed`` (``docs/speed.md``) compares it
    with the true remaining change at the default stop.  Each call costs
    one dot product.
    """

    def __init__(self, size, tol, *, window=3, max_rate=0.95):
        self.size = int(size)
        self.tol = float(tol)
        self.window = int(window)
        self.max_rate = float(max_rate)
        self.estimate = math.inf
        self.steps = []

    def __call__(self, step, direction):
        s = abs(float(step)) * math.sqrt(dot(direction, direction) / self.size)
        self.steps.append(s)
        self.estimate = self._estimate()
        return self.estimate <= self.tol

    def _estimate(self):
        steps = self.steps
        if steps[-1] == 0.0:
            return 0.0  # CG stepped by zero: the iterate is the solution
        if len(steps) <= self.window:
            return math.inf
        rate = max(b / a if a > 0 else math.inf for a, b in zip(steps[-self.window - 1:-1], steps[-self.window:]))
        if not rate < self.max_rate:
            return math.inf
        return steps[-1] * rate / (1.0 - rate)


def system_form(objective):
    """``"stencil"`` (a :class:`~sparsedepth.grid.stencil.SymmetricStencil`) from ``stencil_form_pixels`` on, else CSR.

    ``stencil_form_pixels`` is :attr:`~sparsedepth.limits.MemoryLimits.stencil_form_pixels` (2²², about 4.2
    megapixels).

    The symmetric stencil keeps half the coefficient images and no index
    arrays (56 bytes per pixel instead of 160 for the 13-point system), but
    its product is slower than the CSR product (``python -m bench.scaling``,
    ``docs/scaling.md``, measures both).
    """
    return "stencil" if objective.size >= memory_limits().stencil_form_pixels else "csr"


def default_hierarchy(A, shape):
    """The multigrid hierarchy the ``amg`` solve with ``preconditioner="grid"`` builds for ``A z = b``.

    Parameters
    ----------
    A : scipy.sparse matrix or SymmetricStencil, shape (N, N)
        The system in the form :func:`system_form` gives it.
    shape : tuple of int
        Grid shape ``(H, W)``.

    Returns
    -------
    GridMultigrid
        ``interpolation="auto"``, ``smoother="line_gauss_seidel"`` (default ``line_anisotropy``) in either
        form; on a stencil form (the frames of at least ``stencil_form_pixels``, :func:`system_form`) the line steps
        gather the fine operator's rows from its images, so no CSR copy of it is made.

    Notes
    -----
    The image-edge weights of the completion operator couple pixels along an edge much more strongly than
    across it; line relaxation along those pixels removes the error modes point Gauss--Seidel leaves
    (:class:`~sparsedepth.linalg.multigrid.smoothers.LineGaussSeidel`).  ``python -m bench.speed`` times the
    V-cycles of this hierarchy.
    """
    return GridMultigrid(A, shape, interpolation="auto", smoother="line_gauss_seidel")


def _depth_tolerance(options):
    """The tolerance on the RMS remaining change in solver units (None: no depth rule); options already scaled."""
    rtol, atol = options.depth_rtol, options.depth_atol
    if rtol is None and atol is None:
        return None
    return max(0.0 if rtol is None else rtol, 0.0 if atol is None else atol)


def _solve_pcg(objective, x0, *, tol, max_iter, recorder, preconditioner, depth_tol=None):
    r"""PCG on ``A z = b`` to ``‖b − A z‖ ≤ tol ‖b‖`` (true residual), history per CG step.

    With ``depth_tol`` (solver units) it also stops when the estimated RMS
    remaining change (:class:`RemainingChange`) is at most ``depth_tol``.

    The objective recorded at the start is ``zᵀAz − 2bᵀz + c`` and after each
    CG step ``F(z) = c − bᵀz − rᵀz`` (the same with the CG residual
    ``r = b − A z``): a product and dot products instead of a full evaluation
    of every term; the last entry is re-evaluated with the true residual
    (:meth:`~sparsedepth.objective.objective.Objective.system_value`).
    """
    A, b, c = objective.normal_equations(form=system_form(objective))
    values = recorder.values
    recorder(0, x0, value=quick_value(objective, x0) if values else math.nan)
    with phase("hierarchy"):
        if preconditioner == "grid":
            M = default_hierarchy(A, objective.shape).aspreconditioner()
        else:
            M = make_preconditioner(A, preconditioner, shape=objective.shape)
    it = [0]

    def cb(xk, rk):
        it[0] += 1
        recorder(it[0], xk, inner=it[0], value=c - dot(b, xk) - dot(rk, xk) if values else math.nan)

    rule = None if depth_tol is None else RemainingChange(b.size, depth_tol)
    z, n, converged, rel = pcg(A, b, x0=x0, M=M, rtol=tol, maxiter=max_iter, callback=cb, callback_residual=True,
                               stop=rule)
    if preconditioner in ("grid", "amg"):
        objective.preconditioner = M  # for the certificate's solve with A (solvers.core.solve_scaled drops it)
    del M
    if values and recorder.history and recorder.history[-1].iteration == n and n > 0:
        recorder.set_last_value(quick_value(objective, z))  # with the true residual, not the recurrence's
    residual = f"relative residual {rel:.2e} {'<=' if converged else '>'} tol {tol:.1e}"
    if rule is not None and rule.estimate <= depth_tol:
        s = recorder.scale
        msg = (f"estimated remaining change {rule.estimate * s:.1e} (RMS, depth units) <= depth tolerance "
               f"{depth_tol * s:.1e} after {n} CG iterations ({residual})")
        return output(z, n, True, msg, recorder)
    msg = f"{residual} after {n} CG iterations"
    if rule is not None:
        msg += f"; estimated remaining change {rule.estimate * recorder.scale:.1e} (RMS, depth units)"
    return output(z, n, converged, msg, recorder)


def solve_cg(objective, x0, *, tol, max_iter, recorder, options):
    """Conjugate gradients with the Jacobi preconditioner ``diag(A)⁻¹``; the stopping rules of :func:`solve_amg`."""
    require_quadratic(objective, "cg")
    return _solve_pcg(objective, x0, tol=tol, max_iter=max_iter, recorder=recorder, preconditioner="jacobi",
                      depth_tol=_depth_tolerance(options))


def solve_amg(objective, x0, *, tol, max_iter, recorder, options):
    """Conjugate gradients preconditioned by one multigrid V-cycle.

    ``options.preconditioner`` (:class:`~sparsedepth.solvers.options.AmgOptions`):
    ``"grid"``, the geometric :class:`~sparsedepth.linalg.multigrid.GridMultigrid`
    built once for ``A`` (the quadratic part of any objective is a grid
    operator of stencil radius <= 2), or ``"amg"``, pyamg Ruge–Stüben.

    Stops at ``‖b − A z‖ ≤ tol ‖b‖`` or, with ``options.depth_rtol`` or
    ``options.depth_atol``, when the estimated RMS remaining change of the
    depth (:class:`RemainingChange`) is within the larger of ``depth_rtol``
    (in units of the depth scale) and ``depth_atol``; the message gives the
    estimate in depth units.
    """
    require_quadratic(objective, "amg")
    return _solve_pcg(objective, x0, tol=tol, max_iter=max_iter, recorder=recorder,
                      preconditioner=options.preconditioner, depth_tol=_depth_tolerance(options))


def single_precision_cg(objective, x0, *, tol, max_iter, recorder):
    """Jacobi-preconditioned CG on ``A z = b`` from ``x0``, in single precision.

    The loop (:func:`~sparsedepth.linalg.krylov.pcg_info`), preconditioner, start and stop (``‖b − A z‖ <= tol
    ‖b‖``) of :func:`solve_cg`, in float32: ``A`` held as a float32 DIA array made from the objective's normal
    stencil (:func:`~sparsedepth.grid.diagonals.stencil_to_dia`: no index arrays to build), the iterate, the
    residual, the work vectors and ``diag(A)⁻¹`` in float32 too (half the bytes to stream per step).  Each step then
    carries float32 rounding (relative 1e-7) instead of float64's, far below a stopping residual of 1e-4; the answer
    is returned in float64.  An objective with a term that is not a stencil operator keeps its float64 CSR matrix
    and float64 vectors.  No objective values are recorded (NaN) and no certificate is computed: the coarse solve of
    the fast mode (:func:`sparsedepth.modes.fast.complete_fast`), whose answer is an intermediate.  Returns a
    :class:`~sparsedepth.solvers.common.SolverOutput` in the units of ``x0``.
    """
    require_quadratic(objective, "cg")
    dtype = np.float64
    if all(t.operator is None or isinstance(t.operator, StencilOperator) for t in objective.quadratic_terms):
        offsets, stencil = objective.normal_stencil()
        diagonal = stencil[offsets.index((0, 0))].ravel()
        A = stencil_to_dia(offsets, stencil, dtype=np.float32)
        b = objective.normal_rhs()
        dtype = np.float32
    else:
        A, b, _ = objective.normal_equations()
        diagonal = A.diagonal()
    if not np.all(diagonal > 0):
        raise ValueError("the coarse system has a diagonal entry <= 0; Jacobi preconditioning needs a positive one")
    inverse_diagonal = (1.0 / diagonal).astype(dtype)
    recorder(0, x0, value=math.nan)
    steps = itertools.count(1)

    def record(z, _residual):
        step = next(steps)
        recorder(step, z, inner=step, value=math.nan)

    with phase("iterations"):
        result = pcg_info(A, b, x0=x0, M=lambda r: np.multiply(inverse_diagonal, r), rtol=tol, maxiter=max_iter,
                          callback=record, callback_residual=True, dtype=dtype)
    result = dataclasses.replace(result, x=result.x.astype(np.float64))
    message = (f"relative residual {result.relative_residual:.2e} {'<=' if result.converged else '>'} tol {tol:.1e} "
               f"after {result.iterations} CG iterations")
    return output(result.x, result.iterations, result.converged, message, recorder)
