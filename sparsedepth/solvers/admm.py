r"""ADMM (split Bregman) with over-relaxation for the L1 problem, finished by exact active-set polishes.

:func:`solve_admm` drives the iteration; one run's state and its steps
(setup, one iteration, the polish check, the finish) live in a private
class.  The polish itself is :mod:`sparsedepth.solvers.active_set`.

May import :mod:`sparsedepth.linalg`, :mod:`sparsedepth.grid`,
:mod:`sparsedepth.objective.l1` and the other modules of :mod:`sparsedepth.solvers`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from ..grid.resample import block_mean, upsample_bilinear, upsample_edges
from ..grid.stencil import full_pattern_offsets
from ..limits import memory_limits
from ..linalg.krylov import dot, pcg, pcg_steps
from ..linalg.multigrid import GridMultigrid
from ..linalg.preconditioners import make_preconditioner
from ..objective.coarsen import COARSENING, coarsen_objective
from ..objective.l1 import StackedL1
from .active_set import polish_active_set
from .certificate import Certificate
from .common import Recorder, gap_threshold, objective_floor, output, refuse_robust, relative

__all__ = ["solve_admm", "finish_from", "default_rho", "combine", "RHO_REFERENCE_PIXELS", "ADMM_TOL", "ADMM_MAX_ITER"]


#: Rows with ``|(Kz)_k|`` at most this (solver units: the depth divided by its scale, about 1) count as tied in
#: the duality gap of a polished point (:class:`~sparsedepth.solvers.certificate.Certificate`, ``eps``).
TIE_BAND = 1e-4
#: CG steps of the least-squares correction of ``ρλ`` on the tied rows in the duality gap of a polished point.
DUAL_FIT_STEPS = 30

#: The reference pixel count of :func:`default_rho` (a 640x480 frame); ρ grows with the side length above it.
RHO_REFERENCE_PIXELS = 640 * 480

#: ``tol`` and ``max_iter`` of ``solver="admm"`` when not given (its entry of the solver registry).
ADMM_TOL, ADMM_MAX_ITER = 1.5e-3, 1000


def target_gap(options) -> float:
    """The relative duality gap the solver works to: the smaller of ``target_gap`` and ``gap_tol``."""
    return min(options.target_gap, options.gap_tol)

def default_rho(objective, max_weight, depth_unit):
    """ADMM penalty ``ρ = 1.5 max(α, 300 max_k c_k / s) · max(1, √(N / N₀))``.

    ``α`` is the weight of the ``data`` term (1 without one), ``c`` the L1
    row weights, ``s`` a typical depth (the median of the positive
    starting values), ``N`` the pixels and ``N₀`` =
    :data:`RHO_REFERENCE_PIXELS`.  ρ has the units of the quadratic weights;
    ``c/s`` has them too, and ``c_k / ρ`` is the shrinkage threshold in depth
    units.  With over-relaxation 1.9 and the polishes of :func:`solve_admm`,
    ``ρ = 1.5α`` is the choice for small L1 weights (a smaller ρ stalls
    after a fast start, a larger one is slower), while a large L1 weight
    relative to the depth scale needs ρ to grow with it: hence ρ grows with
    ``c/s``, but not below ``1.5α`` (``python -m bench.admm_scale``,
    ``docs/admm_scale.md``, times it).  The same scene sampled on a finer grid has depth differences
    between neighbours smaller in proportion to the pixel spacing, ``1/√N``,
    so the shrinkage threshold ``c/ρ`` shrinks with them: ρ grows as the side
    length from ``N₀`` pixels on (iterations and times on frames resized 2x
    and 4x per side: ``docs/admm_scale.md``, from ``bench/admm_scale.py``).
    """
    alpha = 1.0
    for term in objective.quadratic_terms:
        if term.name == "data":
            alpha = float(term.weight)
    grid = max(1.0, float(np.sqrt(objective.size / RHO_REFERENCE_PIXELS)))
    return 1.5 * max(alpha, 300.0 * float(max_weight) / depth_unit) * grid


def _penalty(objective, l1, z, options):
    """ρ of a run from ``z``: option ``rho``, or :func:`default_rho` with the median positive value of ``z``."""
    if options.rho is not None:
        return options.rho
    positive = z[z > 0]
    return default_rho(objective, l1.max_weight(), float(np.median(positive)) if positive.size else 1.0)


def combine(a, A, b, B):
    """``a A + b B`` for CSR matrices; one vector operation when both have the same sparsity pattern."""
    A, B = sp.csr_matrix(A), sp.csr_matrix(B)
    if (A.shape == B.shape and A.nnz == B.nnz and A.has_canonical_format and B.has_canonical_format
            and np.array_equal(A.indptr, B.indptr) and np.array_equal(A.indices, B.indices)):
        return sp.csr_matrix((a * A.data + b * B.data, A.indices, A.indptr), shape=A.shape)
    return (a * A + b * B).tocsr()


# over 80 lines only through its docstring (the method in full); the code is a 20-line loop over _AdmmRun's steps
def solve_admm(objective, x0, *, tol, max_iter, recorder, options):
    r"""ADMM (split Bregman) with over-relaxation for the L1 terms, finished by exact active-set polishes.

    Parameters
    ----------
    objective : Objective
    x0 : ndarray, shape (N,)
    tol : float
        Primal residual at which the polishes start (plain ADMM: primal and
        dual residual at which it stops).
    max_iter : int
    recorder : Recorder
    options : AdmmOptions

    Returns
    -------
    SolverOutput

    Notes
    -----
    With ``u = K z`` (``K`` the stacked L1 operators, ``c`` their weights,
    see :class:`~sparsedepth.objective.l1.StackedL1`), the scaled-form iteration is::

        z ← (2A + ρ KᵀK)⁻¹ (2b + ρ Kᵀ(u − λ))      # PCG, warm-started, inexact
        v ← a K z + (1 − a) u                       # over-relaxation, a = 1.9
        u ← shrink(v + λ, c/ρ)                      # = v + λ − clip(v + λ, ±c/ρ)
        λ ← λ + v − u                               # = clip(v + λ, ±c/ρ)

    The system matrix ``S = 2A + ρKᵀK`` does not depend on the iterate and is
    a grid operator of stencil radius <= 2, so ONE geometric multigrid
    hierarchy (:class:`~sparsedepth.linalg.multigrid.GridMultigrid`, option
    ``preconditioner``, default ``"grid"``; ``"amg"`` for pyamg)
    preconditions every inner solve.  The inner solve is one V-cycle
    preconditioned step with exact line search from the previous ``z``
    (option ``inner_max_iter``, default 1; with more, PCG steps until
    ``‖rhs − S z‖ <= max(inner_rtol ‖rhs‖, inner_factor ‖rhs − S z_prev‖)``,
    defaults ``1e-10`` and ``0.1``, which one step meets on typical
    frames): one V-cycle and one product with ``S`` per
    iteration, as ``S z`` is carried along with ``z``.  When ``K`` is
    the image gradient, ``K z`` and ``Kᵀ v`` are array slices
    (:meth:`StackedL1.apply`), not sparse products.  The exact objective of
    every iterate is recorded; for ``z >= 0`` it is evaluated as
    ``zᵀAz − 2bᵀz + c + Σ c_k |(Kz)_k|`` with ``zᵀAz = ½(zᵀSz − ρ‖Kz‖²)``.
    The residuals are ``r_k = ‖Kz − u‖ / max(‖Kz‖, ‖u‖)`` (primal) and
    ``s_k = ‖u − u_prev‖ / ‖λ‖`` (dual, measured on the edges).

    ADMM finds the set of edges with ``(K z*)_k = 0`` long before its iterates
    are accurate, so once ``r_k <= tol`` (default 1.5e-3) it switches to
    *active-set polishes* (:func:`~sparsedepth.solvers.active_set.polish_active_set`):
    the quadratic problem
    with the edges where ``u = 0`` tied (pixels merged into connected
    components) and the signs of the other ``u_k`` fixed, solved exactly; an
    edge whose polished difference has the wrong sign is then tied too and the
    polish repeated (up to ``polish_rounds = 2`` solves).  With the optimal
    tied set and signs the polished point is the exact minimiser.  ADMM goes
    on and is polished again ``check_every = 3`` iterations later (each
    further wait twice the previous one, at most ``4 check_every``, so that
    a slowly converging run is not dominated by polishes); the solver stops
    when a polish changes the best polished ``F`` by at most ``check_rtol ·
    F`` (default 2e-7) AND the duality gap of the best polished point
    (:class:`~sparsedepth.solvers.certificate.Certificate`; its dual point on
    the rows with ``|(Kz)_k| <=`` :data:`TIE_BAND` is ``ρλ`` corrected by
    :data:`DUAL_FIT_STEPS` CG steps of a least-squares fit on those rows) is
    at most ``target · max(F, 1e-7 F(0))``, ``target`` the smaller of the
    options ``target_gap`` (default 1e-6) and ``gap_tol``.  The agreement
    alone is a heuristic (two polishes can land on the
    same wrong tied set); when the certificate
    refuses it, ADMM goes on iterating and polishing until it passes or
    ``max_iter``, and the message says so.  The best polished point is returned if it is below the
    last ADMM iterate, so the reported ``F`` is exact and ``z >= 0``.  With
    ``polish=False``, or when the reduced model is singular (a component
    without any quadratic term), it is plain ADMM stopped by
    ``r_k, s_k <= tol``, converged when its duality gap (tied rows: ``u =
    0``) passes the target too.  Where the gap cannot be computed (NaN:
    the quadratic part's matrix is singular) the solver's own rules decide.  The result carries the gap of the
    returned point.

    Nested iteration (option ``warm_start="coarse"``; default ``"none"``):
    on a grid of more than ``coarse_above`` pixels (default 600000) whose L1
    operator is the image gradient, the same problem rediscretised on blocks
    of 2x2 pixels (:func:`~sparsedepth.objective.coarsen.coarsen_objective`:
    same terms and weights, row weights summed over the blocks and scaled by
    ``2^(−pm)`` for differences of order ``m`` in a term of power ``p``) is
    solved first, by this solver from the block means of the start,
    recursively, with ``ρ_c = ρ / 2`` (:func:`default_rho` grows with the side
    length), ``check_rtol`` loosened by ``coarse_gap_tol / target`` (default
    ``coarse_gap_tol`` 1e-4) and no certificate: a coarse run stops when two
    polishes agree.  This grid's run
    then starts from ``z = P z_c`` (bilinear,
    :func:`~sparsedepth.grid.resample.upsample_bilinear`), ``u = K z`` and
    ``λ = c ⊙ σ / ρ``, where ``σ = clip(ρ_c λ_c / c_c, −1, 1)``, the coarse
    multiplier relative to its bound, is interpolated onto the fine edges by
    :func:`~sparsedepth.grid.resample.upsample_edges`: ``ρλ`` is then inside
    the bound ``[−c, c]`` and, where the coarse solution has a jump or a
    slope, at the bound with its sign, as the fine optimum's multiplier.  The
    fine run's stopping rules, polishes and certificate are those above, so
    the result is certified as without it; the message names the coarse
    grids and their iterations.

    With ``restart_from_polish=True`` (default False) a polish that lowers
    the best polished ``F`` also moves the iteration: ADMM goes on from
    ``z`` = the polished point and ``u = K z`` (its tied edges exactly 0),
    with its ``λ``.  The stopping rules are unchanged.

    ρ (option ``rho``; default :func:`default_rho`) may be adapted by
    residual balancing (factor 2 when one residual exceeds 10× the other,
    checked every 5 iterations) during the first ``adapt_iters`` iterations
    (default 0); the hierarchy is then re-computed numerically with
    :meth:`GridMultigrid.update`.

    Memory: from :attr:`~sparsedepth.limits.MemoryLimits.reduced_matrix_pixels` (2²¹)
    pixels on and without ρ adaptation the solver keeps ``S`` and not ``A``
    (it calls :meth:`Objective.clear_cache`; ``zᵀAz`` and the polish's
    reduced matrix are computed from ``S``); on smaller frames it keeps ``A``
    too, and the polish merges ``A`` itself, which is faster; for the grid
    gradient ``K`` is never stored, the weights ``c`` are read chunk by chunk
    from the L1 term's row weights, and the ADMM vectors are ``u``, ``λ`` and
    one work vector of ``2N`` entries each.  On these frames the certificate
    keeps nothing between checks (``low_memory``: its hierarchy of ``A`` and
    ``A`` itself exist only during its solve) and forms its dual point in the
    work vector (the peak of a whole 8-megapixel run is in
    ``docs/performance.md``, from ``bench/perf.py``).

    Options: :class:`~sparsedepth.solvers.options.AdmmOptions`.

    References
    ----------
    Boyd, Parikh, Chu, Peleato, Eckstein, "Distributed optimization and
    statistical learning via the alternating direction method of multipliers",
    Found. Trends Mach. Learn. 3 (2011), §3.4.  Goldstein, Osher, "The split
    Bregman method for L1-regularized problems", SIAM J. Imaging Sci. 2 (2009).
    """
    refuse_robust(objective, "admm")
    z = np.maximum(np.asarray(x0, dtype=float).copy(), 0.0)
    recorder(0, z, inner=0)
    if not objective.has_l1:
        return _solve_quadratic(objective, z, recorder, options)
    return _run(_new_run(objective, z, options, max_iter, tol), tol, max_iter, recorder)


def _new_run(objective, z, options, max_iter, tol):
    """The run of :func:`solve_admm` from ``z``, or with ``warm_start="coarse"`` from the coarse grid's solution."""
    start = _coarse_start(objective, z, options, max_iter, tol)
    if start is None:
        return _AdmmRun(objective, z, options, max_iter)
    z, sigma, note = start
    run = _AdmmRun(objective, z, options, max_iter)
    run.lam = run.l1.weighted(sigma)
    run.lam /= run.rho
    run.warm_note = note
    return run


def _coarse_start(objective, z, options, max_iter, tol):
    """``(z, σ, note)``: the coarse grid's solution and normalised dual ``ρλ / c`` on this grid, or None.

    None unless ``warm_start="coarse"``, the grid has more than
    ``coarse_above`` pixels and the L1 operator is the grid gradient (the
    coarse problem: :func:`~sparsedepth.objective.coarsen.coarsen_objective`).
    The coarse problem is solved by :func:`solve_admm`'s run (itself started
    from a coarser grid when it is large enough) from the block means of
    ``z``, with ``target_gap = coarse_gap_tol``, ``check_rtol`` loosened in
    the same ratio and half this grid's ``ρ``; its solution is interpolated bilinearly
    (:func:`~sparsedepth.grid.resample.upsample_bilinear`) and its dual
    edge field ``σ = clip(ρλ / c, −1, 1)`` by
    :func:`~sparsedepth.grid.resample.upsample_edges`.
    """
    if options.warm_start != "coarse" or objective.size <= options.coarse_above:
        return None
    l1 = StackedL1(objective)
    if not l1.grid_gradient:
        return None
    coarse = coarsen_objective(objective)
    if coarse is None or min(coarse.shape) < 2 or not coarse.has_l1:
        return None
    shape, cshape = objective.shape, coarse.shape
    z_coarse = block_mean(np.maximum(z, 0.0).reshape(shape), COARSENING).ravel()
    loosen = max(1.0, options.coarse_gap_tol / target_gap(options))
    sub_options = replace(options, target_gap=options.coarse_gap_tol,
                          gap_tol=max(options.gap_tol, options.coarse_gap_tol), check_rtol=options.check_rtol * loosen)
    sub_options = replace(sub_options, rho=_penalty(objective, l1, z, options) / COARSENING)
    del l1
    run = _new_run(coarse, z_coarse, sub_options, max_iter, tol)
    run.certify = False
    out = _run(run, tol, max_iter, Recorder(coarse, None, values=False))
    c = run.l1.weights
    sigma = np.divide(run.rho * run.lam, c, out=np.zeros_like(c), where=c > 0)
    np.clip(sigma, -1.0, 1.0, out=sigma)
    del c
    n = coarse.size
    sigma = np.concatenate([upsample_edges(sigma[:n].reshape(cshape), shape, COARSENING, axis=1).ravel(),
                            upsample_edges(sigma[n:].reshape(cshape), shape, COARSENING, axis=0).ravel()])
    z = upsample_bilinear(out.z.reshape(cshape), shape, COARSENING).ravel()
    note = (f"started from the solution on the {cshape[0]}x{cshape[1]} grid ({out.iterations} ADMM iterations, "
            f"{'its polishes agreed' if out.converged else 'its polishes did not agree'}"
            + (f"; {run.warm_note}" if run.warm_note else "") + ")")
    return z, sigma, note


def finish_from(objective, z, p, *, tol, max_iter, recorder, options, first_iteration):
    """ADMM with its active-set polishes from a point ``z`` and dual ``p`` of another solver; a :class:`SolverOutput`.

    The exact finishing phase of :func:`~sparsedepth.solvers.irls.solve_irls`:
    ``u = K z`` and the scaled multiplier ``λ = clip(p, −c, c) / ρ``, then
    the iteration and stopping rules of :func:`solve_admm`, its iterations
    recorded as ``first_iteration + 1, ...`` (``max_iter`` of them at most).
    """
    run = _AdmmRun(objective, np.maximum(np.asarray(z, dtype=float), 0.0), options, max_iter)
    c = run.l1.weights
    run.lam = np.clip(p, -c, c) / run.rho
    return _run(run, tol, max_iter, recorder, first=first_iteration)


def _run(run, tol, max_iter, recorder, first=0):
    """Iterate ``run`` until its stopping rules or ``max_iter`` iterations (numbered from ``first + 1``)."""
    k, last = first, first + max_iter
    while k < last:
        k += 1
        run.iterate(k, recorder)
        if not run.polish and run.r_norm <= tol and run.s_norm <= tol:
            run.stop_on_residuals(tol)
            break
        if run.polish and (k == run.next_polish or (run.next_polish is None and run.r_norm <= tol)):
            verdict = run.polish_and_check(k)
            if verdict is None:  # the reduced model is singular: plain ADMM from now on
                continue
            if verdict:
                break
        run.adapt_rho(k - first)
    return run.finish(k, recorder)


def _solve_quadratic(objective, z, recorder, options):
    """Nothing to split (no L1 term): one PCG solve of ``A z = b``."""
    A0, b, _ = objective.normal_equations()
    M = make_preconditioner(A0, options.preconditioner, shape=objective.shape)
    z, n, ok, rel = pcg(A0, b, x0=z, M=M, rtol=options.inner_rtol)
    recorder(1, z, inner=n)
    return output(z, 1, ok, f"quadratic problem: relative residual {rel:.1e}", recorder)


class _AdmmRun:
    """The state of one ADMM run and its steps (see :func:`solve_admm`)."""

    def __init__(self, objective, z, options, max_iter):
        _, self.b, self.const = objective.normal_equations()
        self.objective = objective
        self.options = options
        self.z = z
        l1 = self.l1 = StackedL1(objective)
        self.polish = options.polish and l1.exact_pairs
        self.polish_args = dict(rounds=options.polish_rounds, rtol=options.polish_rtol,
                                preconditioner=options.polish_preconditioner)
        self.certificate = None  # built at the first check (see _new_certificate)
        self.certified = None  # (z, gap) of the last certificate
        self.refused = 0  # polish agreements the certificate refused
        self.F_floor = objective_floor(objective)
        # residual floors: edge vectors below 1e-9 per row (depth ~1 in normalised units) count as zero
        self.edge_floor_sq = (1e-9 * 1e-9) * l1.rows
        self.rho = _penalty(objective, l1, z, options)
        self._build_system()
        self.Sz = self.S @ z
        self.u = l1.apply(z)
        self.lam = np.zeros_like(self.u)
        self.spare = np.empty_like(self.u)  # work vector: K z, then x; holds the previous u after each update
        self.inner_total = 0
        self.r_norm = self.s_norm = np.inf
        self.polish_steps = 0
        self.best = None  # (F, z, components) of the best polished point
        self.next_polish = None
        self.interval = None
        self.converged = False
        self.message = f"reached max_iter = {max_iter}"
        self.max_iter = max_iter
        self.warm_note = None  # how a coarse grid started the run (warm_start="coarse")
        self.certify = True  # False: a coarse grid's run, stopped by the polishes' agreement alone

    def _build_system(self):
        """``S = 2A + ρKᵀK``, the matrices the polish and the ρ adaptation need, the preconditioner of ``S``."""
        objective, l1, rho = self.objective, self.l1, self.rho
        A0 = objective.normal_equations()[0]
        # KᵀK in A0's own pattern when A0 is a full in-grid stencil matrix: S then shares A0's index arrays
        KtK = l1.gram(full_pattern_offsets(A0, objective.shape) if l1.grid_gradient else None)
        self.S = combine(2.0, A0, rho, KtK)
        adapt = self.options.adapt_iters > 0
        self.A0 = self.KtK = None
        self.lean = not adapt and objective.size >= memory_limits().reduced_matrix_pixels
        if self.lean:
            # S carries all the solver needs of A0: zᵀA0z = (zᵀSz − ρ‖Kz‖²)/2, and the polish reduces S
            # (penalty=rho); without rho adaptation neither A0 nor KᵀK is needed again
            del KtK, A0
            objective.clear_cache()
            self.quad, self.penalty = self.S, rho
        else:  # small frames (or rho adaptation): the polish merges A0 itself, without KᵀK's entries
            if adapt:
                self.A0, self.KtK = A0, KtK
            del KtK
            self.quad, self.penalty = A0, None
        kind = self.options.preconditioner
        if kind == "grid":
            self.hierarchy = GridMultigrid(self.S, objective.shape, interpolation="auto")
            self.precondition = self.hierarchy.vcycle
        else:
            self.hierarchy = None
            self.precondition = make_preconditioner(self.S, kind, shape=objective.shape).matvec

    def iterate(self, k, recorder):
        """ADMM iteration ``k``: the inexact ``z`` solve, the edge update, the residuals, the record."""
        l1, rho, z, options = self.l1, self.rho, self.z, self.options
        rhs = l1.adjoint(np.subtract(self.u, self.lam, out=self.spare))
        rhs *= rho
        rhs += self.b
        rhs += self.b
        if k % 25 == 0:
            self.Sz = self.S @ z  # drop the rounding drift of the carried product
        self.inner_total += pcg_steps(self.S, self.precondition, z, self.Sz, rhs, rtol=options.inner_rtol,
                                      factor=options.inner_factor, max_steps=options.inner_max_iter)
        x = l1.apply(z, out=self.spare)  # K z, overwritten by the new u below
        # between polishes the residuals decide nothing: skip them
        need_r = self.best is None or not self.polish or k <= options.adapt_iters
        need_s = not self.polish or k <= options.adapt_iters
        # v = u + a (Kz − u);  λ ← clip(v + λ, ±c/ρ);  u ← v + λ − λ_new: one chunked pass over the edges
        step = l1.admm_step(x, self.u, self.lam, relax=options.relaxation, scale=1.0 / rho, primal=need_r,
                            dual=need_s)
        self.u, self.spare = x, self.u
        Kz_sq = step["Kz_sq"]
        feasible = z.min() >= 0
        if feasible:
            value = 0.5 * (dot(z, self.Sz) - rho * Kz_sq) - 2.0 * dot(self.b, z) + self.const + step["value"]
        if need_r:
            self.r_norm = np.sqrt(step["r_sq"] / max(Kz_sq, step["u_sq"], self.edge_floor_sq))
        if need_s:
            self.s_norm = np.sqrt(step["s_sq"] / max(step["lam_sq"], self.edge_floor_sq))
        if feasible:
            recorder(k, z, inner=self.inner_total, value=value)
        else:
            recorder(k, np.maximum(z, 0.0), inner=self.inner_total)

    def _new_certificate(self):
        """The duality-gap certificate of this run.

        On frames where the run keeps ``A`` (below
        :attr:`~sparsedepth.limits.MemoryLimits.reduced_matrix_pixels` pixels) one
        multigrid hierarchy of ``A`` serves all its checks; on larger ones the
        certificate keeps nothing between checks (``low_memory``; see :meth:`_gap`).

        The dual point on the tied rows is ``ρλ`` clipped to ``[−c, c]``.  For
        a polished point the tied rows are those with ``|(Kz)_k| <=``
        :data:`TIE_BAND` and the start is corrected by the certificate's
        least-squares fit (:data:`DUAL_FIT_STEPS` CG steps, ``fit_correction``;
        no projected-gradient steps); an unpolished iterate's is improved by
        the certificate's default projected-gradient fit.
        """
        if self.polish:
            return Certificate(self.objective, nonnegative=True, fit_steps=0, fit_max_iter=DUAL_FIT_STEPS,
                               fit_correction=True, low_memory=self.lean)
        return Certificate(self.objective, nonnegative=True, fit_max_iter=0, low_memory=self.lean)

    def _gap(self, z, **kwargs):
        """The certificate's duality gap of ``z`` with the dual start ``ρλ`` (keyword arguments: ``eps``, ``tied``).

        ``ρλ`` is written into the work vector, whose contents the next
        iteration does not read, and the certificate forms its dual point there
        (``overwrite_p``).
        """
        if self.certificate is None:
            self.certificate = self._new_certificate()
        return self.certificate.gap(z, p=np.multiply(self.lam, self.rho, out=self.spare), overwrite_p=True, **kwargs)

    def stop_on_residuals(self, tol):
        """Plain ADMM's stop: converged when the duality gap (tied rows: ``u = 0``) passes the target too."""
        objective, gap_tol = self.objective, target_gap(self.options)
        self.converged = True
        self.message = (f"primal {self.r_norm:.1e} and dual {self.s_norm:.1e} residuals <= tol {tol:.1e} "
                        f"(rho = {self.rho:.3g})")
        z_stop = np.maximum(self.z, 0.0)
        self.certificate = self._new_certificate()
        gap = self._gap(z_stop, tied=self.u == 0)
        self.certified = (z_stop, gap)
        if not (np.isnan(gap) or gap <= gap_threshold(objective, objective.value(z_stop), gap_tol)):
            self.converged = False
            self.message += (f"; NOT converged: duality gap {relative(gap, objective.value(z_stop)):.1e} "
                             f"(relative) > target {gap_tol:.1e}")

    def polish_and_check(self, k):
        """Polish at iteration ``k`` and schedule the next polish.

        Returns None when the reduced model is singular (polishing is then
        switched off), True when the polishes agree and the certificate
        accepts the best polished point (a coarse grid's run of the nested
        iteration: when they agree), False otherwise.
        """
        options = self.options
        F_prev = None if self.best is None else self.best[0]
        polished = polish_active_set(self.quad, self.b, self.const, self.l1, self.u,
                                     z0=self.z if self.best is None else self.best[1], penalty=self.penalty,
                                     **self.polish_args)
        if polished is None:
            self.polish = False
            return None
        z_pol, F_pol, n_comp, steps = polished
        self.polish_steps += steps
        if self.best is None or F_pol < self.best[0]:
            self.best = (F_pol, z_pol, n_comp)
            if options.restart_from_polish:  # ADMM goes on from the polished point, with its λ
                self.z = z_pol.copy()
                self.Sz = self.S @ self.z
                self.l1.apply(self.z, out=self.u)
        # the first check comes check_every iterations later; each failed check doubles the wait
        # (up to 4 check_every), so that slow cases are not dominated by polishes
        check_every = options.check_every
        self.interval = check_every if F_prev is None else min(2 * self.interval, 4 * check_every)
        self.next_polish = k + self.interval
        if F_prev is not None and abs(F_prev - F_pol) <= options.check_rtol * abs(F_pol) + self.F_floor:
            if not self.certify:  # a coarse grid's run: the agreement alone stops it
                self.converged = True
                self.message = (f"active-set polish at iteration {k} changed the best polished F by "
                                f"{relative(F_prev - F_pol, F_pol):.1e} (relative), no certificate")
                return True
            return self._certify_agreement(k, F_prev, F_pol)
        return False

    def _certify_agreement(self, k, F_prev, F_pol):
        """The polishes agree: the duality gap of the best polished point decides (True: converged)."""
        objective, options, best = self.objective, self.options, self.best
        gap_tol = target_gap(options)
        gap = self._gap(best[1], eps=TIE_BAND)
        self.certified = (best[1], gap)
        if np.isnan(gap) or gap <= gap_threshold(objective, best[0], gap_tol):
            self.converged = True
            self.message = (f"active-set polish at iteration {k} changed the best polished F by "
                            f"{relative(F_prev - F_pol, F_pol):.1e} (relative), |.| <= check_rtol "
                            f"{options.check_rtol:.1e} (or by {abs(F_prev - F_pol):.1e} <= floor {self.F_floor:.1e}), "
                            f"and its duality gap {relative(gap, best[0]):.1e} (relative) <= target {gap_tol:.1e} "
                            f"(rho = {self.rho:.3g})")
            if self.refused:
                self.message += f"; the certificate had refused {self.refused} earlier agreement(s)"
            return True
        self.refused += 1
        self.message = (f"reached max_iter = {self.max_iter}; the polishes agreed {self.refused} time(s) but the "
                        f"duality gap {relative(gap, best[0]):.1e} (relative) stayed > target {gap_tol:.1e}")
        return False

    def adapt_rho(self, k):
        """Residual balancing during the first ``adapt_iters`` iterations: ρ times or divided by 2."""
        r_norm, s_norm = self.r_norm, self.s_norm
        if k <= self.options.adapt_iters and k % 5 == 0 and (r_norm > 10 * s_norm or s_norm > 10 * r_norm):
            factor = 2.0 if r_norm > s_norm else 0.5
            self.rho *= factor
            self.lam /= factor
            self.S = combine(2.0, self.A0, self.rho, self.KtK)
            self.Sz = self.S @ self.z
            if self.hierarchy is not None:
                self.hierarchy.update(self.S)
            else:
                self.precondition = make_preconditioner(self.S, self.options.preconditioner,
                                                        shape=self.objective.shape).matvec

    def finish(self, k, recorder):
        """The output: the best polished point if it is below the last iterate, with its duality gap."""
        objective = self.objective
        z = np.maximum(self.z, 0.0)
        if self.polish and self.best is None:
            polished = polish_active_set(self.quad, self.b, self.const, self.l1, self.u, z0=z, penalty=self.penalty,
                                         **self.polish_args)
            if polished is not None:
                self.polish_steps += polished[3]
                self.best = (polished[1], polished[0], polished[2])
        if self.best is not None:
            F_cur = objective.value(z)
            if self.best[0] < F_cur:
                z = self.best[1]
                recorder(k + 1, z, inner=self.inner_total + self.polish_steps, value=self.best[0])
                self.message += (f"; returned the best active-set polish ({self.best[2]} components, "
                                 f"{self.polish_steps} CG steps in all)")
            else:
                self.message += "; no active-set polish lowered F"
        if self.certified is not None and (self.certified[0] is z or np.array_equal(self.certified[0], z)):
            gap = self.certified[1]
        elif not self.certify:
            gap = float("nan")
        else:
            gap = self._gap(z, eps=TIE_BAND if self.polish else 0.0)
        if self.warm_note:
            self.message += f"; {self.warm_note}"
        return output(z, k, self.converged, self.message, recorder, gap=gap)
