r"""Iteratively reweighted least squares (IRLS) for the L1 problem ``min_{z >= 0} F``.

May import :mod:`sparsedepth.linalg` and the other modules of :mod:`sparsedepth.solvers`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..grid.stencil import stencil_to_csr
from ..linalg.krylov import dot, pcg
from ..linalg.multigrid import GridMultigrid
from ..linalg.preconditioners import make_preconditioner
from ..objective.l1 import StackedL1
from .admm import ADMM_MAX_ITER, ADMM_TOL, finish_from
from .certificate import Certificate, curvature_lower_bound
from .common import gap_threshold, objective_floor, output, relative
from .options import AdmmOptions

__all__ = ["solve_irls"]


def solve_irls(objective, x0, *, tol, max_iter, recorder, options):
    r"""Iteratively reweighted least squares for the L1 terms: primal-dual Newton or plain reweighting.

    Option ``method="newton"`` (the default, for L1 terms on the pixel grid,
    a quadratic part in stencil form and a positive lower bound on its
    curvature, so that the duality gap is proven) runs :func:`_solve_newton`;
    the other cases, and ``method="reweighting"``, the majorise–minimise
    iteration described below.

    Parameters
    ----------
    objective : Objective
    x0 : ndarray, shape (N,)
    tol : float
    max_iter : int
    recorder : Recorder
    options : IrlsOptions

    Returns
    -------
    SolverOutput

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
    F_k + F_floor``, the absolute floor ``F_floor`` of
    :func:`~sparsedepth.solvers.common.objective_floor`), down to ``eps_min``;
    the solver has converged when that happens at ``eps_min``.  ``eps_start``
    and ``eps_min`` default to ``1e-2`` and ``1e-7`` times ``scale``, the
    median positive starting value (about 1 in the normalised units
    :func:`~sparsedepth.solvers.solve` works in).  A step that would
    increase the exact ``F`` is halved (along the segment, ``F`` being convex)
    until it does not, so the exact ``F`` never increases.

    A robust term ``c_k φ((Kz)_k)``
    (:class:`~sparsedepth.objective.terms.RobustTerm`) adds ``½ Kᵀ diag(c ⊙
    ω(K z)) K`` to the system, ``ω = φ'(t)/t`` its majoriser weight
    (majorise–minimise: ``φ`` is concave in ``t²``); without L1 terms the
    solver has converged at the first relative decrease ``<= tol``, a
    stationary point of a possibly non-convex ``F``.  The step guard keeps
    ``F`` from increasing there too.

    References
    ----------
    Daubechies, DeVore, Fornasier, Güntürk, "Iteratively reweighted least
    squares minimization for sparse recovery", CPAM 63 (2010).
    """
    system = _newton_system(objective) if options.method == "newton" else None
    if system is not None:
        return _solve_newton(objective, system, x0, max_iter=max_iter, recorder=recorder, options=options)
    A0, b, _ = objective.normal_equations()
    l1 = objective.abs_terms
    # the reweighted normal matrices Kᵀ diag(ω) K are sparse products: CSR operators, converted once
    l1_csr = [t.operator if sp.issparse(t.operator) else t.operator.tocsr() for t in l1]
    robust = objective.robust_terms
    robust_csr = [t.operator if sp.issparse(t.operator) else t.operator.tocsr() for t in robust]
    eps, eps_min = _smoothing_range(x0, options)
    preconditioner = _ReweightedPreconditioner(options.preconditioner, objective.shape)
    floor = objective_floor(objective)
    z = np.maximum(np.asarray(x0, dtype=float).copy(), 0.0)
    F = recorder(0, z, inner=0)
    inner_total = 0
    converged = False
    message = f"reached max_iter = {max_iter}"
    k = 0
    while k < max_iter:
        k += 1
        system = _reweighted_system(A0, l1, l1_csr, z, eps, robust, robust_csr)
        z_new, n_inner, _, _ = pcg(system, b, x0=z, M=preconditioner(system), rtol=options.inner_rtol,
                                   maxiter=options.inner_max_iter)
        inner_total += n_inner
        z_new, F_new = _monotone_step(objective, z, F, np.maximum(z_new, 0.0))
        decrease = F - F_new
        z, F = z_new, F_new
        recorder(k, z, inner=inner_total, value=F)
        if decrease <= tol * abs(F) + floor:
            if eps <= eps_min * (1 + 1e-12) or not l1:
                converged = True
                message = (f"relative decrease {relative(decrease, F):.1e} <= tol {tol:.1e} (or absolute "
                           f"{decrease:.1e} <= floor {floor:.1e}) at eps = {eps:.1e}")
                break
            eps = max(eps / options.eps_factor, eps_min)
    return output(z, k, converged, message, recorder)


def _smoothing_range(x0, options):
    """``(eps_start, eps_min)`` of the options, or ``1e-2`` and ``1e-7`` times the typical depth."""
    scale = _smoothing_scale(x0, options)
    eps = 1e-2 * scale if options.eps_start is None else float(options.eps_start)
    eps_min = 1e-7 * scale if options.eps_min is None else float(options.eps_min)
    return eps, min(eps_min, eps)


def _reweighted_system(A0, l1, l1_csr, z, eps, robust=(), robust_csr=()):
    """``A + ½ Σ Kᵀ diag(c / max(|Kz|, ε)) K`` over the L1 terms, plus ``½ Kᵀ diag(ω) K`` per robust term
    (``ω`` its :meth:`~sparsedepth.objective.terms.RobustTerm.majorizer_weights`), as CSR (``A`` itself without
    either)."""
    if not l1 and not robust:
        return A0
    parts = [A0]
    for term, K in zip(l1, l1_csr):
        t = K @ z
        omega = term.scaled_row_weights() / np.maximum(np.abs(t), eps)
        parts.append(0.5 * (K.T @ sp.diags(omega) @ K))
    for term, K in zip(robust, robust_csr):
        parts.append(0.5 * (K.T @ sp.diags(term.majorizer_weights(z)) @ K))
    return sum(parts[1:], parts[0]).tocsr()


class _ReweightedPreconditioner:
    """The preconditioner of each reweighted system.

    ``"grid"``: one hierarchy for the whole run, updated numerically for the
    new weights; otherwise a new preconditioner for every system.
    """

    def __init__(self, kind, shape):
        self.kind = kind
        self.shape = shape
        self.hierarchy = None

    def __call__(self, system):
        if self.kind != "grid":
            return make_preconditioner(system, self.kind, shape=self.shape)
        # one hierarchy for the whole run: numeric update for new weights
        if self.hierarchy is None:
            self.hierarchy = GridMultigrid(system, self.shape, interpolation="auto")
        else:
            self.hierarchy.update(system)
        return self.hierarchy.aspreconditioner()


def _monotone_step(objective, z, F, z_new):
    """``(z_new, F(z_new))``, the step halved along the segment until ``F`` does not increase.

    ``(z, F)`` itself when no step down to ``1e-6`` of the full one decreases ``F``.
    """
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
    return z_new, F_new


def _newton_system(objective):
    """The :class:`_GradientSystem` of the Newton steps, or None where they do not apply.

    They apply when the objective has L1 terms and no robust term, the L1
    operator is the grid gradient, ``A`` has a stencil form and a positive
    curvature bound (without it the duality gap is not proven, and the
    reweighting's own stopping rule decides).
    """
    if not objective.has_l1 or objective.robust_terms or curvature_lower_bound(objective) <= 0:
        return None
    if not StackedL1(objective).grid_gradient:
        return None
    try:
        return _GradientSystem(objective)
    except ValueError:  # a quadratic term with a general sparse operator: no stencil form
        return None


class _GradientSystem:
    """``A + ½ Kᵀ diag(d) K`` for the grid gradient ``K``, filled as a stencil and converted to CSR.

    The quadratic part's stencil is read once; each call adds the 5-point
    stencil of the weighted Laplacian ``½ Kᵀ diag(d) K`` (``d`` of shape
    ``(2N,)``: the x rows, then the y rows) to a copy.
    """

    def __init__(self, objective):
        self.shape = objective.shape
        own, stencil = objective.normal_stencil()
        offsets = sorted(set(own) | {(-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)})
        if offsets != own:
            full = np.zeros((len(offsets),) + self.shape)
            full[[offsets.index(o) for o in own]] = stencil
            stencil = full
        self.offsets = offsets
        self.stencil = stencil
        self.index = {o: k for k, o in enumerate(offsets)}

    def __call__(self, d):
        H, W = self.shape
        n = H * W
        st = self.stencil.copy()
        wx = 0.5 * d[:n].reshape(H, W)[:, :-1]
        wy = 0.5 * d[n:].reshape(H, W)[:-1]
        i = self.index
        st[i[(0, 1)], :, :-1] -= wx
        st[i[(0, -1)], :, 1:] -= wx
        st[i[(1, 0)], :-1] -= wy
        st[i[(-1, 0)], 1:] -= wy
        centre = st[i[(0, 0)]]
        centre[:, :-1] += wx
        centre[:, 1:] += wx
        centre[:-1] += wy
        centre[1:] += wy
        return stencil_to_csr(self.offsets, st)


def _huber_value(A, b, const, l1, c, z, eps):
    """The smoothed objective the Newton steps decrease: ``|t|`` replaced by Huber's ``t²/(2ε)`` for ``|t| <= ε``."""
    t = l1.apply(z)
    a = np.abs(t)
    h = np.where(a <= eps, t * t / (2.0 * eps), a - 0.5 * eps)
    return dot(z, A @ z) - 2.0 * dot(b, z) + const + dot(c, h)


def _solve_newton(objective, system, x0, *, max_iter, recorder, options):
    r"""Primal-dual Newton steps on the reweighted systems, with continuation in ``ε``.

    Notes
    -----
    The L1 terms are smoothed by Huber's function (``|t|`` for ``|t| > ε``,
    ``t²/(2ε) + ε/2`` below), whose gradient is the reweighting's dual point
    ``p = c t / max(|t|, ε)``.  With ``t = Kz``, ``m = max(|t|, ε)``, the
    smoothed problem's optimality conditions are::

        R₁ = 2(Az − b) + Kᵀp = 0,      R₂ = m ⊙ p − c ⊙ t = 0

    and with ``p`` kept as an unknown of its own (Chan, Golub and Mulet), one
    Newton step solves the reweighted system::

        (A + ½ Kᵀ diag(d) K) Δz = −½ R₁ + ½ Kᵀ(R₂ / m),
        d = (c − p̃ ⊙ sign t) / m where |t| > ε,   c / ε elsewhere,

    with ``p̃ = clip(p, −c, c)`` (Hintermüller and Stadler: ``d >= 0``, so
    the system is positive definite), then ``Δp = d ⊙ KΔz − R₂ / m``.  The
    system is filled as a stencil and solved by PCG (option
    ``newton_rtol``, at most ``newton_max_inner`` steps) preconditioned by a
    geometric multigrid hierarchy built for it; the step length halves
    until the smoothed objective does not increase, ``z`` is projected on
    ``z >= 0`` and ``p`` on ``|p| <= c``.  ``ε`` starts at ``eps_start`` and
    is divided by ``eps_factor`` when the smoothed problem's relative
    gradient ``‖2(Az − b) + Kᵀ(c t / m)‖ / ‖2b‖`` is below ``newton_tol``
    or after ``level_steps`` steps, down to ``eps_min``, where the solver
    stops (not converged) when a level of steps leaves the best ``F``
    unchanged.  At the end of each
    level with ``ε <= certify_below`` the duality gap of the best point so
    far (:class:`~sparsedepth.solvers.certificate.Certificate`, rows with
    ``|t| <= tie_band`` fitted as tied, ``p`` as their start) decides
    convergence: ``gap <= target · max(F, floor)``, ``target`` the smaller
    of the options ``target_gap`` (1e-4) and ``gap_tol``.  The exact ``F`` of
    the iterates may rise when ``ε`` shrinks; the point returned is the one
    with the lowest exact ``F``.

    The Newton steps lower ``F`` fast while ``ε`` is large but slow down
    and stall near a gap of 1e-5 ``F`` as ``ε`` shrinks: the reweighted
    systems grow ill-conditioned and the iterates never tie edges exactly.
    With option ``finish="admm"`` (the default) they therefore stop at the
    gap ``max(target, newton_gap)`` (``newton_gap`` 1e-2 by default), and
    when the target is smaller (or the Newton phase stalled) an exact
    finishing phase takes over (the gap that decides this hand-over uses the
    dual point ``p`` as it is on the tied rows, without the certificate's
    least-squares fit and projected-gradient steps): ADMM with its
    active-set polishes and certificate
    (:func:`~sparsedepth.solvers.admm.finish_from`), started from the best
    Newton point with ``p`` as its dual, whose iterations continue the
    history and count in ``iterations``.  ``python -m bench.solver_gaps``
    measures both phases against ADMM from the start.

    References
    ----------
    Chan, Golub, Mulet, "A nonlinear primal-dual method for total
    variation-based image restoration", SIAM J. Sci. Comput. 20 (1999).
    Hintermüller, Stadler, "An infeasible primal-dual algorithm for total
    bounded variation-based inf-convolution-type image restoration", SIAM J.
    Sci. Comput. 28 (2006).
    """
    A, b, const = objective.normal_equations()
    l1 = StackedL1(objective)
    c = l1.weights
    H, W = objective.shape
    n = H * W
    c[:n].reshape(H, W)[:, -1] = 0.0  # rows of the last column / row of the grid gradient are zero
    c[n:].reshape(H, W)[-1] = 0.0
    eps, eps_min = _smoothing_range(x0, options)
    scale = _smoothing_scale(x0, options)
    tie_band = 1e-3 * scale if options.tie_band is None else options.tie_band
    certify_below = 1e-5 * scale if options.certify_below is None else options.certify_below
    floor = objective_floor(objective)
    finish = options.finish == "admm"
    target = min(options.target_gap, options.gap_tol)
    newton_gap_tol = max(target, options.newton_gap) if finish else target
    # a gap that only decides the hand-over to the exact finish needs no fitted dual point on the tied rows
    hand_over = finish and newton_gap_tol > target
    unfitted = {"fit_max_iter": 0, "fit_steps": 0} if hand_over else {}
    certificate = Certificate(objective, nonnegative=True, **unfitted)
    b_norm = max(2.0 * float(np.linalg.norm(b)), np.finfo(float).tiny)
    z = np.maximum(np.asarray(x0, dtype=float).copy(), 0.0)
    F = recorder(0, z, inner=0)
    best_F, best_z = F, z.copy()
    t = l1.apply(z)
    Az = A @ z
    p = c * t / np.maximum(np.abs(t), eps)
    inner_total, level, level_start_F = 0, 0, np.inf
    converged, gap = False, float("nan")
    message = f"reached max_iter = {max_iter}"
    k = 0
    while k < max_iter:
        k += 1
        level += 1
        a = np.abs(t)
        m = np.maximum(a, eps)
        clipped = np.clip(p, -c, c)
        d = np.where(a > eps, (c - clipped * np.sign(t)) / m, c / eps)
        grad = 2.0 * (Az - b) + l1.adjoint(p)
        R2_m = p - c * t / m
        S = system(d)
        M = _newton_preconditioner(S, options.preconditioner, objective.shape)
        rhs = -0.5 * grad + 0.5 * l1.adjoint(R2_m)
        dz, n_inner, _, _ = pcg(S, rhs, M=M, rtol=options.newton_rtol, maxiter=options.newton_max_inner)
        inner_total += n_inner
        dp = d * l1.apply(dz) - R2_m
        z, p, step = _newton_step(A, b, const, l1, c, z, p, dz, dp, eps)
        F = objective.value(z)
        recorder(k, z, inner=inner_total, value=F)
        if F < best_F:
            best_F, best_z = F, z.copy()
        t = l1.apply(z)
        Az = A @ z
        smoothed_grad = 2.0 * (Az - b) + l1.adjoint(c * t / np.maximum(np.abs(t), eps))
        residual = float(np.linalg.norm(smoothed_grad)) / b_norm
        if residual > options.newton_tol and level < options.level_steps and step > 0:
            continue
        threshold = gap_threshold(objective, best_F, newton_gap_tol)
        # a level whose steps still lowered the best F by more than the tolerance is not certified (the gap is at
        # least what later steps take off)
        if eps <= certify_below * (1 + 1e-12) and level_start_F - best_F <= threshold:
            gap = certificate.gap(best_z, p=p, eps=tie_band)
            if gap <= threshold:
                converged = True
                message = (f"duality gap {relative(gap, best_F):.1e} (relative) <= "
                           f"{'newton_gap' if newton_gap_tol > target else 'target'} {newton_gap_tol:.1e} "
                           f"at eps = {eps:.1e} after {k} Newton steps")
                break
        if eps <= eps_min * (1 + 1e-12) and level_start_F - best_F <= floor:
            message = (f"stalled: {options.level_steps} Newton steps at eps_min = {eps_min:.1e} did not lower F "
                       f"(after {k} steps)")
            break
        eps = max(eps / options.eps_factor, eps_min)
        level, level_start_F = 0, best_F
    if not converged and not np.isnan(gap):
        message += f"; duality gap {relative(gap, best_F):.1e} (relative) > {newton_gap_tol:.1e}"
    recorded = k
    if best_F < F:
        recorded = k + 1
        recorder(recorded, best_z, inner=inner_total, value=best_F)
    if finish and not (converged and newton_gap_tol <= target):
        out = finish_from(objective, best_z, p, tol=ADMM_TOL, max_iter=ADMM_MAX_ITER, recorder=recorder,
                          options=AdmmOptions(gap_tol=options.gap_tol, target_gap=target), first_iteration=recorded)
        message = (f"Newton phase: {message}; finished by {out.iterations - recorded} ADMM iterations with "
                   f"active-set polishes from its point: {out.message}")
        return output(out.z, out.iterations, out.converged, message, recorder, gap=out.gap)
    return output(best_z, k, converged, message, recorder, gap=gap if converged else float("nan"))


def _newton_preconditioner(S, kind, shape):
    if kind == "grid":
        return GridMultigrid(S, shape, interpolation="auto").aspreconditioner()
    return make_preconditioner(S, kind, shape=shape)


def _newton_step(A, b, const, l1, c, z, p, dz, dp, eps):
    """``(z, p, step)`` after the longest step in 1, ½, ¼, ... that does not raise the smoothed objective."""
    value = _huber_value(A, b, const, l1, c, z, eps)
    step = 1.0
    while step >= 2.0 ** -12:
        trial = np.maximum(z + step * dz, 0.0)
        if _huber_value(A, b, const, l1, c, trial, eps) <= value:
            return trial, np.clip(p + step * dp, -c, c), step
        step *= 0.5
    return z, p, 0.0


def _smoothing_scale(x0, options):
    """The typical depth: option ``scale`` or the median positive starting value."""
    if options.scale is not None:
        return options.scale
    positive = x0[x0 > 0]
    return max(float(np.median(positive)) if positive.size else 1.0, 1e-12)
