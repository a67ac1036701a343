"""Solvers for the completion objective; all return the same output type.

Every solver takes an :class:`~sparsedepth.objective.Objective`, a starting
point and stopping parameters, and returns a :class:`SolverOutput`; the public
entry point :func:`sparsedepth.complete_depth` turns it into a
:class:`~sparsedepth.result.CompletionResult`.  Solvers are registered by name
in :data:`SOLVERS`, their options (with defaults) in :data:`SOLVER_OPTIONS`.

:func:`solve` works in normalised units: the depth is divided by a power of
two ``s`` near its median (:func:`depth_scale`) and the objective becomes
``F / s²`` (:func:`scaled_objective`), so every solver, its defaults and its
tolerances see data of order 1 whatever the unit.  Every solver's output
carries a duality gap (:mod:`sparsedepth.solvers.certificate`), a bound on
``F(z) − F*``; ``converged`` needs the solver's own rule (below) and ``gap
<= gap_tol · max(F, 1e-7 F(0))`` (option ``gap_tol``: 1e-6 for ``direct``,
``cg``, ``amg`` and ``admm``, 1e-4 for ``irls``, 1e-2 for ``lbfgsb``, 1e-1
for ``adam``, whose smoothed objective is ~1e-4 to 1e-3 above the exact
optimum).  Every relative stopping
test on ``F`` has an absolute floor (:func:`_objective_floor`), so ``F* = 0``
converges; a solver that claims convergence at its start must pass a
projected-gradient check.

==========  ===========  ====================================================
name        objective    stopping rule (``tol``)
==========  ===========  ====================================================
direct      γ = 0        exact sparse LU solve of the normal equations
cg          γ = 0        Jacobi-PCG, ``‖b − A z‖ ≤ tol ‖b‖``
amg         γ = 0        PCG with a multigrid V-cycle (geometric GridMultigrid;
                         ``options={"preconditioner": "amg"}`` for pyamg
                         Ruge–Stüben), same rule
irls        any          ``F_{k-1} − F_k ≤ tol · F_k + floor`` at the final ε
admm        any          primal residual ``<= tol`` (relative) starts exact
                         active-set polishes, 3, 6, 12, 12, ... iterations
                         apart; stops when the best polished F changes by
                         ``<= 2e-7`` (relative, + floor) between two of them
lbfgsb      any          SciPy L-BFGS-B on the smoothed objective scaled by
                         ``1/F(x0)``; ``ftol = tol``
adam        any          projected Adam on the smoothed objective; relative
                         decrease over 50 steps ``≤ tol`` (+ floor)
==========  ===========  ====================================================
"""

from __future__ import annotations


import time
from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from .._validation import is_int, is_real
from ..objective.l1 import StackedL1, graph_components
from .certificate import Certificate, curvature_lower_bound
from ..linalg.krylov import pcg, pcg_steps
from ..linalg.preconditioners import make_preconditioner
from ..linalg.multigrid import GridMultigrid
from ..grid.stencil import index_dtype, full_pattern_offsets
from ..objective.objective import AbsTerm, Objective, QuadraticTerm
from ..result import IterationRecord, SolverState

__all__ = ["SolverOutput", "SOLVERS", "SOLVER_OPTIONS", "DEFAULT_TOL", "DEFAULT_MAX_ITER", "solve", "depth_scale",
           "scaled_objective", "check_solver_arguments"]

#: ADMM keeps the quadratic part's matrix ``A`` next to ``S = 2A + ρKᵀK`` below
#: this many pixels (its polish then merges ``A`` directly, ~0.15 s less per run
#: at 640x480); from it on only ``S`` is kept, for the peak memory of large frames.
_ADMM_KEEP_A_PIXELS = 1 << 21


@dataclass(frozen=True)
class SolverOutput:
    z: np.ndarray
    iterations: int
    converged: bool
    message: str
    history: tuple
    gap: float = float("nan")


class _Stop(Exception):
    """Raised inside a solver when the callback asked to stop; carries the iterate."""

    def __init__(self, iteration, z):
        super().__init__(iteration)
        self.iteration = iteration
        self.z = z


class _Recorder:
    """Keeps the history and calls the user callback after every iteration.

    The solver works in normalised units (depth divided by ``scale``, the
    objective by ``scale²``); the history and the callback's states are in
    the user's units (``F · scale²``, ``z · scale``).  A call returns ``F``
    in the solver's units.
    """

    def __init__(self, objective, callback, scale=1.0):
        self.objective = objective
        self.callback = callback
        self.scale = float(scale)
        self.start = time.perf_counter()
        self.history = []

    def elapsed(self):
        return time.perf_counter() - self.start

    def user_value(self, F):
        """``F`` in the user's units."""
        return float(F) * self.scale * self.scale

    def set_last_value(self, F):
        """Replace the objective of the last history entry by ``F`` (solver units)."""
        last = self.history[-1]
        self.history[-1] = IterationRecord(last.iteration, self.user_value(F), last.time, last.function_evals,
                                           last.gradient_evals, last.inner_iterations)

    def __call__(self, iteration, z, *, fevals=None, gevals=None, inner=None, value=None):
        t = self.elapsed()
        F = self.objective.value(z) if value is None else float(value)
        F_user = self.user_value(F)
        self.history.append(IterationRecord(iteration, F_user, t, fevals, gevals, inner))
        if self.callback is not None:
            depth = np.array(z, dtype=float).reshape(self.objective.shape)
            depth *= self.scale
            try:
                self.callback(SolverState(iteration, F_user, t, depth))
            except StopIteration:
                raise _Stop(iteration, np.array(z, dtype=float)) from None
        return F


def _relative(change, reference):
    """``change / |reference|`` for a message (no division by zero: ``0/0 = 0``, ``x/0 = inf``)."""
    reference = abs(float(reference))
    if reference > 0:
        return float(change) / reference
    return 0.0 if change == 0 else float(np.copysign(np.inf, change))


def _objective_floor(objective):
    """An absolute floor for changes of ``F``: rounding level of ``F`` near its scale ``F(0) = c``.

    In normalised units (depth ~1) ``c = zᵀAz − 2bᵀz + c`` at ``z = 0`` is the
    size of the quadratic terms; a change of ``F`` below ``1e-13 · c`` (about
    500 rounding units) is not a change the iteration can resolve.  ``c = 0``
    (all targets zero, e.g. an all-zero depth map) gives the floor
    ``1e-13 · N`` (``F* = 0`` there and every change is noise at depth ~1).
    """
    _, _, c = objective.normal_equations()
    return 1e-13 * (abs(c) if c > 0 else float(objective.size))


def _require_quadratic(objective, name):
    if objective.has_l1:
        raise ValueError(
            f"solver {name!r} solves the quadratic problem only (gamma = 0); use solver='irls', 'lbfgsb' or 'adam' for gamma > 0"
        )


def _output(z, iterations, converged, message, recorder, gap=float("nan")):
    return SolverOutput(np.asarray(z, dtype=float), int(iterations), bool(converged), message, tuple(recorder.history),
                        float(gap))


def _gap_threshold(objective, F, gap_tol):
    """``gap_tol · max(F, floor)``, ``floor = 1e-7 F(0)`` (``1e-7 N`` when ``F(0) = 0``), in solver units."""
    _, _, c = objective.normal_equations()
    return float(gap_tol) * max(float(F), 1e-7 * (abs(c) if c > 0 else float(objective.size)))


#: Solvers whose problem is ``min_{z >= 0} F`` (the others solve the unconstrained quadratic problem).
_NONNEGATIVE_SOLVERS = ("irls", "admm", "lbfgsb", "adam")
_QUADRATIC_SOLVERS = ("direct", "cg", "amg")


# ---------------------------------------------------------------------------
# quadratic problem (gamma = 0)
# ---------------------------------------------------------------------------
def solve_direct(objective, x0, *, tol=None, max_iter=None, recorder, options):
    """Sparse LU (SuperLU) solve of ``A z = b``; the reference for γ = 0."""
    _require_quadratic(objective, "direct")
    recorder(0, x0)
    A, b, _ = objective.normal_equations()
    z = spsolve(sp.csc_matrix(A), b)
    recorder(1, z)
    return _output(z, 1, True, "direct sparse solve", recorder)


def _solve_pcg(objective, x0, *, tol, max_iter, recorder, preconditioner):
    r"""PCG on ``A z = b`` to ``‖b − A z‖ ≤ tol ‖b‖`` (true residual), history per CG step.

    The objective recorded after each CG step is ``F(z) = c − bᵀz − rᵀz``
    (``= zᵀAz − 2bᵀz + c`` with the CG residual ``r = b − A z``), two dot
    products instead of a full evaluation of every term; the last entry is
    re-evaluated exactly term by term.
    """
    from ..linalg.krylov import dot

    A, b, c = objective.normal_equations()
    recorder(0, x0)
    M = make_preconditioner(A, preconditioner, shape=objective.shape)
    it = [0]

    def cb(xk, rk):
        it[0] += 1
        recorder(it[0], xk, inner=it[0], value=c - dot(b, xk) - dot(rk, xk))

    z, n, converged, rel = pcg(A, b, x0=x0, M=M, rtol=tol, maxiter=max_iter, callback=cb, callback_residual=True)
    if recorder.history and recorder.history[-1].iteration == n and n > 0:
        recorder.set_last_value(objective.value(z))
    msg = f"relative residual {rel:.2e} {'<=' if converged else '>'} tol {tol:.1e} after {n} CG iterations"
    return _output(z, n, converged, msg, recorder)


def solve_cg(objective, x0, *, tol, max_iter, recorder, options):
    """Conjugate gradients with the Jacobi preconditioner ``diag(A)⁻¹``."""
    _require_quadratic(objective, "cg")
    return _solve_pcg(objective, x0, tol=tol, max_iter=max_iter, recorder=recorder, preconditioner="jacobi")


def solve_amg(objective, x0, *, tol, max_iter, recorder, options):
    """Conjugate gradients preconditioned by one multigrid V-cycle.

    Options
    -------
    preconditioner : {"grid", "amg"}, default "grid"
        ``"grid"``: geometric :class:`~sparsedepth.linalg.multigrid.GridMultigrid`
        built once for ``A`` (the quadratic part of any objective is a grid
        operator of stencil radius <= 2); ``"amg"``: pyamg Ruge–Stüben.
    """
    _require_quadratic(objective, "amg")
    return _solve_pcg(
        objective, x0, tol=tol, max_iter=max_iter, recorder=recorder, preconditioner=options["preconditioner"]
    )


# ---------------------------------------------------------------------------
# L1 problem: IRLS
# ---------------------------------------------------------------------------
def solve_irls(objective, x0, *, tol, max_iter, recorder, options):
    r"""Iteratively reweighted least squares (majorise–minimise) for the L1 terms.

    Notes
    -----
    With ``t = K z`` and ``m_k = max(|t_k|, ε_k)``, each ``|t|`` is majorised by
    the quadratic ``t²/(2 m_k) + m_k/2`` (tight where ``|t_k| >= ε_k``); the
    next iterate minimises the quadratic part plus these majorisers::

        (A + ½ Kᵀ diag(γ w / m_k) K) z = b

    solved by PCG, warm-started from the current iterate, to relative residual
    ``inner_rtol``.  The preconditioner (option ``preconditioner``, default
    ``"grid"``) is one geometric multigrid hierarchy built in the first
    iteration and re-computed numerically (:meth:`GridMultigrid.update`, same
    stencil) in the others; ``"amg"`` rebuilds a pyamg hierarchy each time.  ε starts at
    ``eps_start`` and is divided by ``eps_factor`` whenever the relative
    decrease of the exact ``F`` falls below ``tol`` (``F_{k-1} − F_k <= tol ·
    F_k + F_floor``, the absolute floor ``F_floor`` of :func:`_objective_floor`),
    down to ``eps_min``; the solver has converged when that happens at
    ``eps_min``.  ``eps_start`` and ``eps_min`` default to ``1e-2`` and
    ``1e-7`` times ``scale``, the median positive starting value (about 1 in
    the normalised units :func:`solve` works in).  A step that would
    increase the exact ``F`` is halved (along the segment, ``F`` being convex)
    until it does not, so the exact ``F`` never increases.

    References
    ----------
    Daubechies, DeVore, Fornasier, Güntürk, "Iteratively reweighted least
    squares minimization for sparse recovery", CPAM 63 (2010).
    """
    A0, b, _ = objective.normal_equations()
    l1 = objective.abs_terms
    # the reweighted normal matrices Kᵀ diag(ω) K are sparse products: CSR operators, converted once
    l1_csr = [t.operator if sp.issparse(t.operator) else t.operator.tocsr() for t in l1]
    scale = options["scale"]
    if scale is None:
        positive = x0[x0 > 0]
        scale = max(float(np.median(positive)) if positive.size else 1.0, 1e-12)
    eps = 1e-2 * scale if options["eps_start"] is None else float(options["eps_start"])
    eps_min = 1e-7 * scale if options["eps_min"] is None else float(options["eps_min"])
    eps_min = min(eps_min, eps)
    eps_factor = float(options["eps_factor"])
    inner_rtol = float(options["inner_rtol"])
    preconditioner = options["preconditioner"]
    floor = _objective_floor(objective)
    hierarchy = None
    z = np.maximum(np.asarray(x0, dtype=float).copy(), 0.0)
    F = recorder(0, z, inner=0)
    inner_total = 0
    converged = False
    message = f"reached max_iter = {max_iter}"
    k = 0
    while k < max_iter:
        k += 1
        if not l1:
            system = A0
        else:
            parts = [A0]
            for term, K in zip(l1, l1_csr):
                t = K @ z
                omega = term.scaled_row_weights() / np.maximum(np.abs(t), eps)
                parts.append(0.5 * (K.T @ sp.diags(omega) @ K))
            system = sum(parts[1:], parts[0]).tocsr()
        if preconditioner == "grid":
            # one hierarchy for the whole run: numeric update for new weights
            if hierarchy is None:
                hierarchy = GridMultigrid(system, objective.shape, interpolation="auto")
            else:
                hierarchy.update(system)
            M = hierarchy.aspreconditioner()
        else:
            M = make_preconditioner(system, preconditioner, shape=objective.shape)
        z_new, n_inner, _, _ = pcg(system, b, x0=z, M=M, rtol=inner_rtol, maxiter=options["inner_max_iter"])
        inner_total += n_inner
        z_new = np.maximum(z_new, 0.0)
        F_new = objective.value(z_new)
        step = 1.0
        while F_new > F and step > 1e-6:
            step *= 0.5
            trial = z + step * (z_new - z)
            F_trial = objective.value(trial)
            if F_trial <= F:
                z_new, F_new = trial, F_trial
                break
        if F_new > F:
            z_new, F_new = z, F
        decrease = F - F_new
        z, F = z_new, F_new
        recorder(k, z, inner=inner_total, value=F)
        if decrease <= tol * abs(F) + floor:
            if eps <= eps_min * (1 + 1e-12) or not l1:
                converged = True
                message = (f"relative decrease {_relative(decrease, F):.1e} <= tol {tol:.1e} (or absolute "
                           f"{decrease:.1e} <= floor {floor:.1e}) at eps = {eps:.1e}")
                break
            eps = max(eps / eps_factor, eps_min)
    return _output(z, k, converged, message, recorder)


# ---------------------------------------------------------------------------
# L1 problem: ADMM / split Bregman with a constant system matrix
# ---------------------------------------------------------------------------
def _default_rho(objective, max_weight, depth_scale):
    """ADMM penalty ``ρ = 1.5 max(α, 300 max_k c_k / s)``.

    ``α`` is the weight of the ``data`` term (1 without one), ``c`` the L1
    row weights and ``s`` a typical depth (the median of the positive
    starting values).  ρ has the units of the quadratic weights; ``c/s`` has
    them too, and ``c_k / ρ`` is the shrinkage threshold in depth units.
    Measured with over-relaxation 1.9 and the polishes of
    :func:`solve_admm` (the polished F after k iterations, real 640x480
    frames): for γ = 0.01 on a ~3 m NYU frame ρ = 1.5α reached ~3e-7 of the
    optimum in 32 iterations, ρ = α stalls after a fast start and 2α … 4.5α
    are slower; for γ = 0.03 ρ = 1.5α stalled at ~1.5e-6 for 50 iterations
    while ρ ≈ 4.5 reached 7e-8 in 75; for γ = 0.003, ρ = 1.5α beat 0.75α and
    0.45α.  Hence ρ grows with the L1 weight relative to the depth scale, but
    not below 1.5α.
    """
    alpha = 1.0
    for term in objective.quadratic_terms:
        if term.name == "data":
            alpha = float(term.weight)
    return 1.5 * max(alpha, 300.0 * float(max_weight) / depth_scale)


def _combine(a, A, b, B):
    """``a A + b B`` for CSR matrices; one vector operation when both have the same sparsity pattern."""
    A, B = sp.csr_matrix(A), sp.csr_matrix(B)
    if (A.shape == B.shape and A.nnz == B.nnz and A.has_canonical_format and B.has_canonical_format
            and np.array_equal(A.indptr, B.indptr) and np.array_equal(A.indices, B.indices)):
        return sp.csr_matrix((a * A.data + b * B.data, A.indices, A.indptr), shape=A.shape)
    return (a * A + b * B).tocsr()


def solve_admm(objective, x0, *, tol, max_iter, recorder, options):
    r"""ADMM (split Bregman) with over-relaxation for the L1 terms, finished by exact active-set polishes.

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
    defaults ``1e-10`` and ``0.1``, which one step always met on the
    ``bench/perf.py`` frame): one V-cycle and one product with ``S`` per
    iteration, as ``S z`` is carried along with ``z``.  When ``K`` is
    the image gradient, ``K z`` and ``Kᵀ v`` are array slices
    (:meth:`StackedL1.apply`), not sparse products.  The exact objective of
    every iterate is recorded; for ``z >= 0`` it is evaluated as
    ``zᵀAz − 2bᵀz + c + Σ c_k |(Kz)_k|`` with ``zᵀAz = ½(zᵀSz − ρ‖Kz‖²)``.
    The residuals are ``r_k = ‖Kz − u‖ / max(‖Kz‖, ‖u‖)`` (primal) and
    ``s_k = ‖u − u_prev‖ / ‖λ‖`` (dual, measured on the edges).

    ADMM finds the set of edges with ``(K z*)_k = 0`` long before its iterates
    are accurate, so once ``r_k <= tol`` (default 1.5e-3) it switches to
    *active-set polishes* (:func:`_polish_active_set`): the quadratic problem
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
    (:class:`~sparsedepth.solvers.certificate.Certificate`, dual point ``ρλ`` on the
    tied rows) is at most ``gap_tol · max(F, 1e-7 F(0))`` (option
    ``gap_tol``, default 1e-6).  The agreement alone is a heuristic (two
    polishes can land on the same wrong tied set); when the certificate
    refuses it, ADMM goes on iterating and polishing until it passes or
    ``max_iter``, and the message says so.  The best polished point is returned if it is below the
    last ADMM iterate, so the reported ``F`` is exact and ``z >= 0``.  With
    ``polish=False``, or when the reduced model is singular (a component
    without any quadratic term), it is plain ADMM stopped by
    ``r_k, s_k <= tol``, converged when its duality gap (tied rows: ``u =
    0``) passes ``gap_tol`` too.  Where the gap cannot be computed (NaN:
    the quadratic part's matrix is singular) the solver's own rules decide.  The result carries the gap of the
    returned point.

    ρ (option ``rho``; default :func:`_default_rho`) may be adapted by
    residual balancing (factor 2 when one residual exceeds 10× the other,
    checked every 5 iterations) during the first ``adapt_iters`` iterations
    (default 0); the hierarchy is then re-computed numerically with
    :meth:`GridMultigrid.update`.

    Memory: from ``_ADMM_KEEP_A_PIXELS`` (2²¹) pixels on and without ρ
    adaptation the solver keeps ``S`` and not ``A`` (it calls
    :meth:`Objective.clear_cache`; ``zᵀAz`` and the polish's reduced matrix
    are computed from ``S``); on smaller frames it keeps ``A`` too, and the
    polish merges ``A`` itself, which is faster; for the grid gradient ``K`` is
    never stored, the weights ``c`` are read chunk by chunk from the L1
    term's row weights, and the ADMM vectors are ``u``, ``λ`` and one work
    vector of ``2N`` entries each (the peak of a whole 8-megapixel run is
    in ``docs/performance.md``, measured by ``bench/perf.py``).

    Options: ``rho``, ``relaxation`` (1.9), ``inner_rtol``, ``inner_factor``,
    ``inner_max_iter``, ``adapt_iters``, ``preconditioner``, ``polish``,
    ``polish_rounds``, ``check_every``, ``check_rtol``, ``polish_rtol``
    (1e-7), ``polish_preconditioner`` (``"jacobi"``; or ``"amg"``),
    ``gap_tol`` (1e-6).

    References
    ----------
    Boyd, Parikh, Chu, Peleato, Eckstein, "Distributed optimization and
    statistical learning via the alternating direction method of multipliers",
    Found. Trends Mach. Learn. 3 (2011), §3.4.  Goldstein, Osher, "The split
    Bregman method for L1-regularized problems", SIAM J. Imaging Sci. 2 (2009).
    """
    from ..linalg.krylov import dot

    A0, b, const = objective.normal_equations()
    z = np.maximum(np.asarray(x0, dtype=float).copy(), 0.0)
    recorder(0, z, inner=0)
    kind = options["preconditioner"]
    if not objective.has_l1:
        # nothing to split: one PCG solve
        M = make_preconditioner(A0, kind, shape=objective.shape)
        z, n, ok, rel = pcg(A0, b, x0=z, M=M, rtol=options["inner_rtol"])
        recorder(1, z, inner=n)
        return _output(z, 1, ok, f"quadratic problem: relative residual {rel:.1e}", recorder)
    l1 = StackedL1(objective)
    relax = float(options["relaxation"])
    inner_rtol = float(options["inner_rtol"])
    inner_factor = float(options["inner_factor"])
    inner_max = int(options["inner_max_iter"])
    adapt_iters = int(options["adapt_iters"])
    polish = bool(options["polish"]) and l1.exact_pairs
    polish_args = dict(rounds=int(options["polish_rounds"]), rtol=float(options["polish_rtol"]),
                       preconditioner=options["polish_preconditioner"])
    check_every = int(options["check_every"])
    check_rtol = float(options["check_rtol"])
    gap_tol = float(options["gap_tol"])
    certificate = None  # built at the first check: one multigrid hierarchy of A for all checks
    certified = None  # (z, gap) of the last certificate
    refused = 0  # polish agreements the certificate refused
    F_floor = _objective_floor(objective)
    # residual floors: edge vectors below 1e-9 per row (depth ~1 in normalised units) count as zero
    edge_floor_sq = (1e-9 * 1e-9) * l1.rows
    positive = z[z > 0]
    depth_scale = float(np.median(positive)) if positive.size else 1.0
    del positive
    rho = _default_rho(objective, l1.max_weight(), depth_scale) if options["rho"] is None else float(options["rho"])
    # KᵀK in A0's own pattern when A0 is a full in-grid stencil matrix: S then shares A0's index arrays
    KtK = l1.gram(full_pattern_offsets(A0, objective.shape) if l1.grid_gradient else None)
    S = _combine(2.0, A0, rho, KtK)
    if adapt_iters <= 0 and objective.size >= _ADMM_KEEP_A_PIXELS:
        # S carries all the solver needs of A0: zᵀA0z = (zᵀSz − ρ‖Kz‖²)/2, and the polish reduces S
        # (penalty=rho); without rho adaptation neither A0 nor KᵀK is needed again
        del KtK, A0
        objective.clear_cache()
        quad, penalty = S, rho
    else:  # small frames (or rho adaptation): the polish merges A0 itself, without KᵀK's entries
        if adapt_iters <= 0:
            del KtK
        quad, penalty = A0, None
    if kind == "grid":
        hierarchy = GridMultigrid(S, objective.shape, interpolation="auto")
        precondition = hierarchy.vcycle
    else:
        hierarchy = None
        precondition = make_preconditioner(S, kind, shape=objective.shape).matvec
    Sz = S @ z
    u = l1.apply(z)
    lam = np.zeros_like(u)
    spare = np.empty_like(u)  # work vector: K z, then x; holds the previous u after each update
    inner_total = 0
    r_norm = s_norm = np.inf
    polish_steps = 0
    best = None  # (F, z, components) of the best polished point
    next_polish = None
    converged = False
    message = f"reached max_iter = {max_iter}"
    k = 0
    while k < max_iter:
        k += 1
        rhs = l1.adjoint(np.subtract(u, lam, out=spare))
        rhs *= rho
        rhs += b
        rhs += b
        if k % 25 == 0:
            Sz = S @ z  # drop the rounding drift of the carried product
        inner_total += pcg_steps(S, precondition, z, Sz, rhs, rtol=inner_rtol, factor=inner_factor,
                                  max_steps=inner_max)
        x = l1.apply(z, out=spare)  # K z, overwritten by the new u below
        # between polishes the residuals decide nothing: skip them
        need_r = best is None or not polish or k <= adapt_iters
        need_s = not polish or k <= adapt_iters
        # v = u + a (Kz − u);  λ ← clip(v + λ, ±c/ρ);  u ← v + λ − λ_new: one chunked pass over the edges
        step = l1.admm_step(x, u, lam, relax=relax, scale=1.0 / rho, primal=need_r, dual=need_s)
        u, spare = x, u
        Kz_sq = step["Kz_sq"]
        feasible = z.min() >= 0
        if feasible:
            value = 0.5 * (dot(z, Sz) - rho * Kz_sq) - 2.0 * dot(b, z) + const + step["value"]
        if need_r:
            r_norm = np.sqrt(step["r_sq"] / max(Kz_sq, step["u_sq"], edge_floor_sq))
        if need_s:
            s_norm = np.sqrt(step["s_sq"] / max(step["lam_sq"], edge_floor_sq))
        if feasible:
            recorder(k, z, inner=inner_total, value=value)
        else:
            recorder(k, np.maximum(z, 0.0), inner=inner_total)
        if not polish and r_norm <= tol and s_norm <= tol:
            converged = True
            message = f"primal {r_norm:.1e} and dual {s_norm:.1e} residuals <= tol {tol:.1e} (rho = {rho:.3g})"
            z_stop = np.maximum(z, 0.0)
            certificate = Certificate(objective, nonnegative=True, fit_max_iter=0)
            gap = certificate.gap(z_stop, p=rho * lam, tied=u == 0)
            certified = (z_stop, gap)
            if not (np.isnan(gap) or gap <= _gap_threshold(objective, objective.value(z_stop), gap_tol)):
                converged = False
                message += (f"; NOT converged: duality gap {_relative(gap, objective.value(z_stop)):.1e} (relative) "
                            f"> gap_tol {gap_tol:.1e}")
            break
        if polish and (k == next_polish or (next_polish is None and r_norm <= tol)):
            F_prev = None if best is None else best[0]
            polished = _polish_active_set(quad, b, const, l1, u, z0=z if best is None else best[1],
                                          penalty=penalty, **polish_args)
            if polished is None:  # the reduced model is singular: plain ADMM
                polish = False
                continue
            z_pol, F_pol, n_comp, steps = polished
            polish_steps += steps
            if best is None or F_pol < best[0]:
                best = (F_pol, z_pol, n_comp)
            # the first check comes check_every iterations later; each failed check doubles the wait
            # (up to 4 check_every), so that slow cases are not dominated by polishes
            interval = check_every if F_prev is None else min(2 * interval, 4 * check_every)
            next_polish = k + interval
            if F_prev is not None and abs(F_prev - F_pol) <= check_rtol * abs(F_pol) + F_floor:
                # the polishes agree; the duality gap of the best polished point decides
                if certificate is None:
                    certificate = Certificate(objective, nonnegative=True, fit_max_iter=0)
                gap = certificate.gap(best[1], p=rho * lam)
                certified = (best[1], gap)
                if np.isnan(gap) or gap <= _gap_threshold(objective, best[0], gap_tol):
                    converged = True
                    message = (f"active-set polish at iteration {k} changed the best polished F by "
                               f"{_relative(F_prev - F_pol, F_pol):.1e} (relative), |.| <= check_rtol "
                               f"{check_rtol:.1e} (or by {abs(F_prev - F_pol):.1e} <= floor {F_floor:.1e}), and its "
                               f"duality gap {_relative(gap, best[0]):.1e} (relative) <= gap_tol {gap_tol:.1e} "
                               f"(rho = {rho:.3g})")
                    if refused:
                        message += f"; the certificate had refused {refused} earlier agreement(s)"
                    break
                refused += 1
                message = (f"reached max_iter = {max_iter}; the polishes agreed {refused} time(s) but the duality gap "
                           f"{_relative(gap, best[0]):.1e} (relative) stayed > gap_tol {gap_tol:.1e}")
        if k <= adapt_iters and k % 5 == 0 and (r_norm > 10 * s_norm or s_norm > 10 * r_norm):
            factor = 2.0 if r_norm > s_norm else 0.5
            rho *= factor
            lam /= factor
            S = _combine(2.0, A0, rho, KtK)
            Sz = S @ z
            if hierarchy is not None:
                hierarchy.update(S)
            else:
                precondition = make_preconditioner(S, kind, shape=objective.shape).matvec
    z = np.maximum(z, 0.0)
    if polish and best is None:
        polished = _polish_active_set(quad, b, const, l1, u, z0=z, penalty=penalty, **polish_args)
        if polished is not None:
            polish_steps += polished[3]
            best = (polished[1], polished[0], polished[2])
    if best is not None:
        F_cur = objective.value(z)
        if best[0] < F_cur:
            z = best[1]
            recorder(k + 1, z, inner=inner_total + polish_steps, value=best[0])
            message += f"; returned the best active-set polish ({best[2]} components, {polish_steps} CG steps in all)"
        else:
            message += "; no active-set polish lowered F"
    if certified is not None and (certified[0] is z or np.array_equal(certified[0], z)):
        gap = certified[1]
    else:
        if certificate is None:
            certificate = Certificate(objective, nonnegative=True, fit_max_iter=0)
        gap = certificate.gap(z, p=rho * lam)
    return _output(z, k, converged, message, recorder, gap=gap)


def _merge(M, labels, count, *, entries=None, chunk=1 << 16):
    """``Cᵀ M C`` for the indicator ``C`` of ``labels``: the entries of ``M`` summed per pair of labels.

    The pixels are taken in label order, a range of labels with about
    ``chunk`` pixels at a time: their rows of ``M`` with the columns
    relabelled are summed per label by one sparse product, and the blocks of
    rows are stacked.  The work memory is that of one block, not of a copy of
    ``M``'s indices.

    Parameters
    ----------
    M : scipy.sparse matrix, shape (N, N)
    labels : ndarray of int, shape (N,)
        Values ``0 .. count-1``.
    count : int
    entries : callable, optional
        ``entries(block, rows) -> data``: the values to merge in place of the
        block's own (``block`` is ``M[rows]``, CSR); lets the caller merge a
        matrix derived from ``M`` entry by entry without forming it.
    chunk : int
        Pixels per block.
    """
    M = sp.csr_matrix(M)
    n = M.shape[0]
    labels = np.asarray(labels)
    members = np.argsort(labels, kind="stable")
    starts = np.zeros(count + 1, dtype=np.int64)
    np.cumsum(np.bincount(labels, minlength=count), out=starts[1:])
    edges = np.unique(np.searchsorted(starts, np.arange(0, n, max(int(chunk), 1)), side="right") - 1)
    edges = np.append(edges[edges < count], count)
    blocks = []
    for c0, c1 in zip(edges[:-1], edges[1:]):
        p0, p1 = starts[c0], starts[c1]
        rows = members[p0:p1]
        block = M[rows]
        data = block.data if entries is None else entries(block, rows)
        right = sp.csr_matrix((data, labels[block.indices], block.indptr), shape=(p1 - p0, count))
        left = sp.csr_matrix((np.ones(p1 - p0), np.arange(p1 - p0), starts[c0:c1 + 1] - p0), shape=(c1 - c0, p1 - p0))
        blocks.append((left @ right).tocsr())
        del block, data, right, left
    return _stack_rows(blocks, count)


def _stack_rows(blocks, n_cols):
    """Vertical stack of CSR blocks, each freed once copied (the result is never held twice)."""
    if len(blocks) == 1:
        return blocks.pop()
    nnz = sum(b.nnz for b in blocks)
    n_rows = sum(b.shape[0] for b in blocks)
    itype = index_dtype(nnz, n_cols)
    data = np.empty(nnz)
    indices = np.empty(nnz, dtype=itype)
    indptr = np.empty(n_rows + 1, dtype=itype)
    indptr[0] = 0
    row = pos = 0
    blocks.reverse()
    while blocks:
        b = blocks.pop()
        m, k = b.shape[0], b.nnz
        data[pos:pos + k] = b.data
        indices[pos:pos + k] = b.indices
        indptr[row + 1:row + m + 1] = b.indptr[1:] + pos
        row, pos = row + m, pos + k
        del b
    return sp.csr_matrix((data, indices, indptr), shape=(n_rows, n_cols))


def _polish_active_set(A, b, const, l1, u, *, z0, rounds=2, rtol=1e-7, preconditioner="jacobi", penalty=None):
    r"""Active-set polish: the quadratic model with the edges where ``u == 0`` tied and the other signs fixed.

    Pixels joined by a tied row of ``K`` (every row must be a difference of
    two pixels, :meth:`StackedL1.pixel_pairs`) are merged into connected
    components; with ``C`` the pixel-to-component indicator, ``z = C y`` and,
    for the signs ``s = sign(u)``, the polished point solves::

        Cᵀ A C y = Cᵀ(b − ½ Kᵀ(c ⊙ s))

    ``CᵀAC`` is assembled by summing the entries of ``A`` per pair of
    components and solved by PCG (``preconditioner``: ``"jacobi"``, the
    default, or ``"amg"`` for pyamg Ruge–Stüben) to relative residual
    ``rtol``, warm-started from the component means of ``z0``.

    A pixel-difference row whose polished value ``t_k`` has ``t_k s_k <= 0``
    contradicts its fixed sign (the minimiser of the model would cross the
    kink of ``|t_k|``); such rows are tied in the next round, whose
    components are merged from the previous ones and whose reduced matrix is
    summed from the previous reduced matrix below ``_ADMM_KEEP_A_PIXELS``
    pixels, from ``A`` again above (never two reduced matrices at once), for at most
    ``rounds`` solves, stopping when no sign is wrong or ``F`` stops
    decreasing.

    With ``penalty = ρ``, ``A`` is ADMM's ``S = 2A + ρKᵀK`` instead (the
    solver then keeps no copy of the quadratic part's matrix): the reduced
    matrix is ``Cᵀ(S − ρKᵀK)C / 2``, the entries of ``KᵀK`` computed block
    by block inside :func:`_merge` (:meth:`StackedL1.gram_entries`), and
    ``zᵀAz = (zᵀSz − ρ‖Kz‖²) / 2``.

    Returns
    -------
    None, or the tuple:
    z : ndarray, shape (N,)
        The polished point with the lowest exact ``F``, clipped at 0.
    F : float
        Its objective ``zᵀAz − 2bᵀz + const + Σ c_k |(Kz)_k|``.
    components : int
        Number of components of that polish.
    cg_steps : int
        PCG steps of all rounds.
    """
    from ..linalg.krylov import dot

    signs = np.zeros(u.shape, dtype=np.int8)  # sign(u) in 1/8 of the memory
    signs[u > 0] = 1
    signs[u < 0] = -1
    labels, count = l1.tied_components(signs == 0)
    entries = None  # the entries of A merged by _merge: A's own
    if penalty is not None and l1.grid_gradient:  # A = (S − ρKᵀK)/2 entry by entry, block by block
        def entries(block, rows):
            return 0.5 * (block.data - penalty * l1.gram_entries(block, rows))
    elif penalty is not None:  # a general K: form A once
        A = ((A - penalty * l1.gram()) * 0.5).tocsr()
        penalty = None
    reduced = _merge(A, labels, count, entries=entries)
    if not np.all(reduced.diagonal() > 0):
        return None  # a component without quadratic coupling: the model is not strictly convex
    best_F, best_z, best_count, steps = np.inf, None, 0, 0
    z_start = z0
    rounds = max(int(rounds), 1)
    for round_ in range(1, rounds + 1):
        sizes = np.bincount(labels, minlength=count)
        pull = l1.adjoint(l1.weighted(signs))
        pull *= -0.5
        pull += b
        rhs = np.bincount(labels, weights=pull, minlength=count)
        del pull
        y0 = np.bincount(labels, weights=z_start, minlength=count) / sizes
        y, n_steps, _, _ = pcg(reduced, rhs, x0=y0, M=make_preconditioner(reduced, preconditioner), rtol=rtol,
                               maxiter=5000)
        steps += n_steps
        z = y[labels]
        np.maximum(z, 0.0, out=z)
        del y
        Kz = l1.apply(z)
        zAz = dot(z, A @ z) if penalty is None else 0.5 * (dot(z, A @ z) - penalty * dot(Kz, Kz))
        F = zAz - 2.0 * dot(b, z) + const + l1.value(Kz)
        if F >= best_F:
            break
        best_F, best_z, best_count = F, z, count
        if round_ == rounds:
            break
        # a fixed sign that the polished difference contradicts (rows that are not pairs have sign 0)
        wrong = ((signs > 0) & (Kz <= 0)) | ((signs < 0) & (Kz >= 0))
        del Kz
        if not wrong.any():
            break
        signs[wrong] = 0
        first, second = l1.pairs_where(wrong)
        del wrong
        merged, count = graph_components(count, labels[first], labels[second])
        labels = merged[labels]
        if A.shape[0] < _ADMM_KEEP_A_PIXELS:  # merge the previous components: a smaller matrix than A
            reduced = _merge(reduced, merged, count)
            del merged
        else:  # reduced again from A: the previous reduced matrix is not held alongside the new one (8-MP peak)
            del merged, reduced
            reduced = _merge(A, labels, count, entries=entries)
        z_start = z
    return best_z, best_F, best_count, steps


# ---------------------------------------------------------------------------
# gradient-based solvers on the smoothed objective
# ---------------------------------------------------------------------------
def solve_lbfgsb(objective, x0, *, tol, max_iter, recorder, options):
    """SciPy L-BFGS-B with bounds ``z >= 0`` on the smoothed objective.

    The objective is divided by ``F(x0)`` so that ``ftol = tol`` is a relative
    decrease; ``gtol`` defaults to 1e-12 on the scaled problem.
    """
    f0 = max(objective.smoothed_value_and_gradient(x0)[0], _objective_floor(objective))
    counts = {"f": 0}

    def fun(z):
        counts["f"] += 1
        v, g = objective.smoothed_value_and_gradient(z)
        return v / f0, g / f0

    recorder(0, x0, fevals=0, gevals=0)
    it = [0]

    def cb(xk):
        it[0] += 1
        recorder(it[0], xk, fevals=counts["f"], gevals=counts["f"])

    res = scipy.optimize.minimize(
        fun,
        x0,
        jac=True,
        method="L-BFGS-B",
        bounds=scipy.optimize.Bounds(0.0, np.inf),
        callback=cb,
        options={
            "maxiter": max_iter,
            "maxfun": 10 * max_iter + 100 if options["maxfun"] is None else options["maxfun"],
            "ftol": tol,
            "gtol": options["gtol"],
            "maxcor": options["maxcor"],
        },
    )
    return _output(res.x, res.nit, res.success, str(res.message), recorder)


def solve_adam(objective, x0, *, tol, max_iter, recorder, options):
    """Adam (bias-corrected moments) with the projection ``z ← max(z, 0)``.

    Step ``z ← max(z − η_k m̂/(sqrt(v̂) + 1e-8·scale), 0)`` with ``η_k =
    learning_rate / sqrt(1 + k/decay_steps)``; default ``learning_rate`` is
    ``1e-2`` times the median observed depth.  Converged when the smoothed
    objective decreased by less than ``tol`` (relative) over the last
    ``window`` steps.
    """
    scale = max(float(np.median(x0[x0 > 0])) if np.any(x0 > 0) else 1.0, 1e-12)
    lr = 1e-2 * scale if options["learning_rate"] is None else float(options["learning_rate"])
    decay = float(options["decay_steps"])
    b1, b2 = float(options["beta1"]), float(options["beta2"])
    window = int(options["window"])
    record_every = int(options["record_every"])
    floor = _objective_floor(objective)
    z = np.maximum(np.asarray(x0, dtype=float).copy(), 0.0)
    m = np.zeros_like(z)
    v = np.zeros_like(z)
    recorder(0, z, fevals=0, gevals=0)
    values = []
    converged = False
    message = f"reached max_iter = {max_iter}"
    k = 0
    while k < max_iter:
        k += 1
        f, g = objective.smoothed_value_and_gradient(z)
        values.append(f)
        m = b1 * m + (1 - b1) * g
        v = b2 * v + (1 - b2) * g * g
        mhat = m / (1 - b1**k)
        vhat = v / (1 - b2**k)
        step = lr / np.sqrt(1.0 + k / decay)
        z = np.maximum(z - step * mhat / (np.sqrt(vhat) + 1e-8 * scale), 0.0)
        if k % record_every == 0:
            recorder(k, z, fevals=k, gevals=k)
        if len(values) > window:
            old = values[-window - 1]
            if 0 <= (old - f) <= tol * abs(f) + floor:
                converged = True
                message = (f"relative decrease over {window} steps {_relative(old - f, f):.1e} <= tol {tol:.1e} "
                           f"(or absolute {old - f:.1e} <= floor {floor:.1e})")
                break
    if k % record_every != 0:
        recorder(k, z, fevals=k, gevals=k)
    return _output(z, k, converged, message, recorder)


SOLVERS = {
    "direct": solve_direct,
    "cg": solve_cg,
    "amg": solve_amg,
    "irls": solve_irls,
    "admm": solve_admm,
    "lbfgsb": solve_lbfgsb,
    "adam": solve_adam,
}

DEFAULT_TOL = {"direct": 0.0, "cg": 1e-8, "amg": 1e-8, "irls": 1e-7, "admm": 1.5e-3, "lbfgsb": 1e-12, "adam": 1e-7}
DEFAULT_MAX_ITER = {"direct": 1, "cg": 5000, "amg": 500, "irls": 200, "admm": 1000, "lbfgsb": 15000, "adam": 20000}

#: The valid ``options`` of every solver with their defaults (``None``: computed from the problem, see the
#: solver's docstring).  :func:`solve` rejects any other key and fills in the defaults.
SOLVER_OPTIONS = {
    "direct": {"gap_tol": 1e-6},
    "cg": {"gap_tol": 1e-6},
    "amg": {"preconditioner": "grid", "gap_tol": 1e-6},
    "irls": {"gap_tol": 1e-4, "eps_start": None, "eps_min": None, "scale": None, "eps_factor": 10.0, "inner_rtol": 1e-6,
             "inner_max_iter": 500, "preconditioner": "grid"},
    "admm": {"rho": None, "relaxation": 1.9, "inner_rtol": 1e-10, "inner_factor": 0.1, "inner_max_iter": 1,
             "adapt_iters": 0, "preconditioner": "grid", "polish": True, "polish_rounds": 2, "polish_rtol": 1e-7,
             "polish_preconditioner": "jacobi", "check_every": 3, "check_rtol": 2e-7,
             "gap_tol": 1e-6},
    "lbfgsb": {"maxfun": None, "gtol": 1e-12, "maxcor": 10, "gap_tol": 1e-2},
    "adam": {"learning_rate": None, "decay_steps": 200.0, "beta1": 0.9, "beta2": 0.999, "window": 50,
             "record_every": 1, "gap_tol": 1e-1},
}

#: Options in depth units: divided by the depth scale together with the depth (see :func:`solve`).
_DEPTH_UNIT_OPTIONS = {"eps_start", "eps_min", "scale", "learning_rate"}
#: The type of the options whose default is None.
_NONE_DEFAULT_TYPES = {"eps_start": float, "eps_min": float, "scale": float, "rho": float, "learning_rate": float,
                       "maxfun": int}
_POSITIVE_OPTIONS = {"eps_start", "eps_min", "scale", "rho", "learning_rate", "relaxation", "eps_factor", "decay_steps"}
_OPTION_CHOICES = {"preconditioner": ("grid", "amg"), "polish_preconditioner": ("jacobi", "amg")}


def _check_option(solver, key, value):
    default = SOLVER_OPTIONS[solver][key]
    kind = _NONE_DEFAULT_TYPES.get(key) if default is None else type(default)
    if default is None and value is None:
        return None
    where = f"options[{key!r}] of solver {solver!r}"
    if kind is bool:
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{where} must be True or False; got {type(value).__name__} {value!r}")
        return bool(value)
    if kind is int:
        if not is_int(value):
            raise TypeError(f"{where} must be an int; got {type(value).__name__} {value!r}: "
                            f"pass e.g. {key}={int(value) if is_real(value) and np.isfinite(value) else default}")
        if value < (0 if key == "adapt_iters" else 1):
            raise ValueError(f"{where} must be >= {0 if key == 'adapt_iters' else 1}; got {value}")
        return int(value)
    if kind is float:
        if not is_real(value):
            raise TypeError(f"{where} must be a number; got {type(value).__name__} {value!r}")
        value = float(value)
        positive = key in _POSITIVE_OPTIONS
        if not (np.isfinite(value) and (value > 0 if positive else value >= 0)):
            raise ValueError(f"{where} must be finite and {'>' if positive else '>='} 0; got {value!r}")
        return value
    if not isinstance(value, str) or value not in _OPTION_CHOICES[key]:
        raise ValueError(f"{where} must be one of {list(_OPTION_CHOICES[key])}; got {value!r}")
    return value


def check_solver_arguments(solver, tol=None, max_iter=None, options=None):
    """Check and complete the stopping parameters and options of the named solver.

    Parameters
    ----------
    solver : str
        A key of :data:`SOLVERS`.
    tol : float, optional
        Default :data:`DEFAULT_TOL`.
    max_iter : int, optional
        Default :data:`DEFAULT_MAX_ITER`; ``bool`` is not an int here.
    options : dict, optional
        Keys of :data:`SOLVER_OPTIONS` for ``solver``.

    Returns
    -------
    tol : float
    max_iter : int
    options : dict
        Every valid key of the solver, given or default (values in the user's units).

    Raises
    ------
    ValueError
        For an unknown solver or option key (the message lists the valid
        keys with their defaults), a negative or non-finite ``tol``,
        ``max_iter < 1`` or an option value out of range.
    TypeError
        For a ``tol``, ``max_iter``, ``options`` or option value of the wrong type.
    """
    if not isinstance(solver, str) or solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {sorted(SOLVERS)} or 'auto'")
    if tol is None:
        tol = DEFAULT_TOL[solver]
    elif not is_real(tol):
        raise TypeError(f"tol must be a number; got {type(tol).__name__} {tol!r}: pass e.g. tol=1e-6")
    tol = float(tol)
    if not (np.isfinite(tol) and tol >= 0):
        raise ValueError(f"tol must be finite and >= 0, got {tol!r}")
    if max_iter is None:
        max_iter = DEFAULT_MAX_ITER[solver]
    elif not is_int(max_iter):
        hint = f"max_iter={int(max_iter)}" if is_real(max_iter) and np.isfinite(max_iter) else "max_iter=100"
        raise TypeError(f"max_iter must be an int; got {type(max_iter).__name__} {max_iter!r}: pass e.g. {hint}")
    max_iter = int(max_iter)
    if max_iter < 1:
        raise ValueError(f"max_iter must be >= 1, got {max_iter}")
    if options is None:
        options = {}
    elif not isinstance(options, dict):
        raise TypeError(f"options must be a dict; got {type(options).__name__}: pass e.g. options=dict(...)")
    valid = SOLVER_OPTIONS[solver]
    unknown = [key for key in options if key not in valid]
    if unknown:
        listing = ", ".join(f"{k}={v!r}" for k, v in valid.items()) if valid else "none"
        raise ValueError(f"unknown option {unknown[0]!r} for solver {solver!r}; valid options (default): {listing}")
    return tol, max_iter, {key: _check_option(solver, key, options[key]) if key in options else default
                           for key, default in valid.items()}


def depth_scale(values) -> float:
    """The power of two nearest (in log) to the median of the positive finite ``values``; 1 without any.

    :func:`solve` divides depth by it: a power of two makes the division and
    the product back exact (no rounding), so completing ``2ᵏ · depth`` gives
    exactly ``2ᵏ`` times the result.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    with np.errstate(invalid="ignore"):
        v = v[np.isfinite(v) & (v > 0)]
    if v.size == 0:
        return 1.0
    return float(2.0 ** int(np.round(np.log2(float(np.median(v))))))


def scaled_objective(objective, scale):
    """The objective in depth units of ``scale``: ``F_s(z / s) = F(z) / s²``.

    Every quadratic term's target is divided by ``s`` (its weight is
    unchanged), every L1 weight and the smoothing ``ε`` are divided by ``s``.
    Returns ``objective`` itself for ``s = 1``.
    """
    s = float(scale)
    if s == 1.0:
        return objective
    terms = []
    for t in objective.terms:
        if isinstance(t, QuadraticTerm):
            target = None if t.target is None else np.asarray(t.target, dtype=np.float64) / s
            terms.append(QuadraticTerm(t.name, t.weight, t.operator, t.row_weights, target))
        elif isinstance(t, AbsTerm):
            terms.append(AbsTerm(t.name, t.weight / s, t.operator, t.row_weights))
        else:
            raise TypeError(f"objective term {t.name!r} has unknown type {type(t).__name__}")
    return Objective(objective.shape, terms, l1_smoothing=objective.l1_smoothing / s)


#: A solver that stops at its start with converged=True must pass this relative optimality test.
_START_KKT_RTOL = 1e-6


def _start_kkt_residual(objective, z, smoothed):
    r"""Relative projected-gradient norm at ``z`` (0 certifies optimality over ``z >= 0``).

    The gradient is that of the smoothed objective (``smoothed``) or the
    subgradient of the exact one with ``sign((Kz)_k)`` (0 where ``(Kz)_k =
    0``: one element of the subdifferential, so a small value is a
    sufficient, not a necessary, certificate).  Projected: ``g_i`` where
    ``z_i > 0``, ``min(g_i, 0)`` where ``z_i = 0``.  Relative to
    ``2‖Az‖∞ + 2‖b‖∞ + ‖Kᵀ|c|‖∞`` (the sizes of the gradient's parts).
    """
    A, b, _ = objective.normal_equations()
    if smoothed:
        g = objective.smoothed_value_and_gradient(z)[1]
    else:
        g = objective.l1_subgradient(z)
    size = 2.0 * float(np.max(np.abs(A @ z), initial=0.0)) + 2.0 * float(np.max(np.abs(b), initial=0.0))
    for t in objective.abs_terms:
        size += float(np.max(np.abs(t.operator.T @ t.scaled_row_weights()), initial=0.0))
    pg = np.where(z > 0, g, np.minimum(g, 0.0))
    return float(np.max(np.abs(pg), initial=0.0)) / max(size, np.finfo(float).tiny)


def solve(objective, x0, *, solver, tol=None, max_iter=None, callback=None, options=None):
    """Run one named solver in normalised units; returns ``(SolverOutput, runtime_seconds)``.

    The depth is divided by ``s = depth_scale(x0)`` (a power of two near the
    median positive starting value): the solver minimises
    :func:`scaled_objective` from ``x0 / s`` and sees data of order 1 whatever
    the unit, so micrometres and kilometres give the same answer.  The
    output (``z``, the history's objective values, the callback's states) is
    in the user's units.  Options in depth units (``eps_start``, ``eps_min``,
    ``scale``, ``learning_rate``) are divided by ``s`` too.  See
    :func:`check_solver_arguments` for the checks of the arguments.

    A solver that reports convergence after at most one iteration, or at its
    unchanged start, must pass a projected-gradient check
    (:func:`_start_kkt_residual` ``<= 1e-6``); otherwise the output says
    ``converged=False`` and why.
    """
    tol, max_iter, options = check_solver_arguments(solver, tol, max_iter, options)
    x0 = np.asarray(x0, dtype=np.float64).ravel()
    scale = depth_scale(x0)
    return solve_scaled(scaled_objective(objective, scale), x0 / scale, scale=scale, solver=solver, tol=tol,
                         max_iter=max_iter, callback=callback, options=options)


def solve_scaled(objective, x0, *, scale, solver, tol, max_iter, callback, options):
    """:func:`solve` for an objective and start already in units of ``scale`` (checked arguments)."""
    options = {key: (value / scale if key in _DEPTH_UNIT_OPTIONS and value is not None else value)
               for key, value in options.items()}
    recorder = _Recorder(objective, callback, scale)
    try:
        out = SOLVERS[solver](objective, x0, tol=tol, max_iter=max_iter, recorder=recorder, options=options)
    except _Stop as stop:
        out = SolverOutput(stop.z, stop.iteration, False, f"stopped by callback at iteration {stop.iteration}",
                           tuple(recorder.history))
    converged, message = out.converged, out.message
    gap = out.gap
    if np.isnan(gap):
        gap = _certify(objective, out.z, solver, options)
    own = converged
    if np.isnan(gap):
        message += "; duality gap not available (the solve with the quadratic part's matrix failed)"
    elif converged and not gap <= _gap_threshold(objective, objective.value(out.z), options["gap_tol"]):
        converged = False
        message += (f"; NOT converged: duality gap {_relative(gap, objective.value(out.z)):.1e} (relative) > "
                    f"gap_tol {options['gap_tol']:.1e}")
    if own and solver != "direct" and (out.iterations <= 1 or np.array_equal(out.z, np.maximum(x0, 0.0))):
        smoothed = solver in ("lbfgsb", "adam")
        kkt = _start_kkt_residual(objective, np.maximum(out.z, 0.0), smoothed)
        if not kkt <= _START_KKT_RTOL:
            converged = False
            message += (f"; NOT converged: stopped after {out.iterations} iteration(s) at a point whose relative "
                        f"projected gradient {kkt:.1e} > {_START_KKT_RTOL:.0e}")
    z = out.z * scale
    return (SolverOutput(z, out.iterations, converged, message, tuple(recorder.history), gap * scale * scale),
            recorder.elapsed())


def _certify(objective, z, solver, options):
    """The duality gap (:mod:`sparsedepth.solvers.certificate`) of a solver's output ``z``, in solver units.

    Rows of ``K`` with ``|(Kz)_k| <= ε`` count as tied, with ``ε`` the
    smoothing of L-BFGS-B and Adam (:attr:`Objective.l1_smoothing`, 1e-4 at
    depth ~1), the same for IRLS (whose iterates leave differences of ~1e-5
    on edges that the optimum ties, far above its final ``ε``) and exact
    ties otherwise (ADMM's polished points, the γ = 0 solvers).  For the
    γ = 0 solvers the one-product bound ``¼ ‖r‖² / λ_min(A)`` is returned
    when it already meets ``gap_tol``.
    """
    if solver in _QUADRATIC_SOLVERS and not objective.has_l1:
        # unconstrained quadratic problem: F(z) − F* = ¼ rᵀA⁻¹r <= ¼ ‖r‖² / λ_min(A), r = 2(Az − b); this costs one
        # product, and the solve below is needed only where the cheap bound is not already within gap_tol
        curvature = curvature_lower_bound(objective)
        if curvature > 0:
            A, b, _ = objective.normal_equations()
            r = 2.0 * (A @ z - b)
            cheap = 0.25 * float(r @ r) / curvature
            if cheap <= _gap_threshold(objective, objective.value(z), options["gap_tol"]):
                return cheap
    if solver in ("lbfgsb", "adam", "irls"):
        eps = float(objective.l1_smoothing)
    else:
        eps = 0.0
    nonnegative = solver in _NONNEGATIVE_SOLVERS and not (solver == "admm" and not objective.has_l1)
    return Certificate(objective, nonnegative=nonnegative).gap(z, eps=eps)
