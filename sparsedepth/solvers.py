"""Solvers for the completion objective; all return the same output type.

Every solver takes an :class:`~sparsedepth.objective.Objective`, a starting
point and stopping parameters, and returns a :class:`SolverOutput`; the public
entry point :func:`sparsedepth.complete_depth` turns it into a
:class:`~sparsedepth.result.CompletionResult`.  Solvers are registered by name
in :data:`SOLVERS`.

==========  ===========  ====================================================
name        objective    stopping rule (``tol``)
==========  ===========  ====================================================
direct      γ = 0        exact sparse LU solve of the normal equations
cg          γ = 0        Jacobi-PCG, ``‖b − A z‖ ≤ tol ‖b‖``
amg         γ = 0        PCG with a multigrid V-cycle (geometric GridMultigrid;
                         ``options={"preconditioner": "amg"}`` for pyamg
                         Ruge–Stüben), same rule
irls        any          ``F_{k-1} − F_k ≤ tol · F_k`` at the final ε
admm        any          primal and dual residuals ``<= tol`` (relative),
                         then an exact active-set polish
lbfgsb      any          SciPy L-BFGS-B on the smoothed objective scaled by
                         ``1/F(x0)``; ``ftol = tol``
adam        any          projected Adam on the smoothed objective; relative
                         decrease over 50 steps ``≤ tol``
==========  ===========  ====================================================
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from .linear import make_preconditioner, pcg
from .multigrid import GridMultigrid
from .result import IterationRecord, SolverState

__all__ = ["SolverOutput", "SOLVERS", "DEFAULT_TOL", "solve"]


@dataclass(frozen=True)
class SolverOutput:
    z: np.ndarray
    iterations: int
    converged: bool
    message: str
    history: tuple


class _Stop(Exception):
    """Raised inside a solver when the callback asked to stop; carries the iterate."""

    def __init__(self, iteration, z):
        super().__init__(iteration)
        self.iteration = iteration
        self.z = z


class _Recorder:
    """Keeps the history and calls the user callback after every iteration."""

    def __init__(self, objective, callback):
        self.objective = objective
        self.callback = callback
        self.start = time.perf_counter()
        self.history = []

    def elapsed(self):
        return time.perf_counter() - self.start

    def __call__(self, iteration, z, *, fevals=None, gevals=None, inner=None, value=None):
        t = self.elapsed()
        F = self.objective.value(z) if value is None else float(value)
        self.history.append(IterationRecord(iteration, F, t, fevals, gevals, inner))
        if self.callback is not None:
            try:
                self.callback(SolverState(iteration, F, t, np.array(z, dtype=float).reshape(self.objective.shape)))
            except StopIteration:
                raise _Stop(iteration, np.array(z, dtype=float)) from None
        return F


def _require_quadratic(objective, name):
    if objective.has_l1:
        raise ValueError(
            f"solver {name!r} solves the quadratic problem only (gamma = 0); use solver='irls', 'lbfgsb' or 'adam' for gamma > 0"
        )


def _output(z, iterations, converged, message, recorder):
    return SolverOutput(np.asarray(z, dtype=float), int(iterations), bool(converged), message, tuple(recorder.history))


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
    from .linear import _dot

    A, b, c = objective.normal_equations()
    recorder(0, x0)
    M = make_preconditioner(A, preconditioner, shape=objective.shape)
    it = [0]

    def cb(xk, rk):
        it[0] += 1
        recorder(it[0], xk, inner=it[0], value=c - _dot(b, xk) - _dot(rk, xk))

    z, n, converged, rel = pcg(A, b, x0=x0, M=M, rtol=tol, maxiter=max_iter, callback=cb, callback_residual=True)
    if recorder.history and recorder.history[-1].iteration == n and n > 0:
        last = recorder.history[-1]
        recorder.history[-1] = IterationRecord(last.iteration, objective.value(z), last.time, last.function_evals,
                                               last.gradient_evals, last.inner_iterations)
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
        ``"grid"``: geometric :class:`~sparsedepth.multigrid.GridMultigrid`
        built once for ``A`` (the quadratic part of any objective is a grid
        operator of stencil radius <= 2); ``"amg"``: pyamg Ruge–Stüben.
    """
    _require_quadratic(objective, "amg")
    return _solve_pcg(
        objective, x0, tol=tol, max_iter=max_iter, recorder=recorder, preconditioner=options.get("preconditioner", "grid")
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
    decrease of the exact ``F`` falls below ``tol``, down to ``eps_min``; the
    solver has converged when that happens at ``eps_min``.  A step that would
    increase the exact ``F`` is halved (along the segment, ``F`` being convex)
    until it does not, so the exact ``F`` never increases.

    References
    ----------
    Daubechies, DeVore, Fornasier, Güntürk, "Iteratively reweighted least
    squares minimization for sparse recovery", CPAM 63 (2010).
    """
    A0, b, _ = objective.normal_equations()
    l1 = objective.abs_terms
    scale = options.get("scale") or max(float(np.median(np.abs(x0[x0 > 0]))) if np.any(x0 > 0) else 1.0, 1e-12)
    eps = float(options.get("eps_start", 1e-2 * scale))
    eps_min = float(options.get("eps_min", 1e-7 * scale))
    eps_factor = float(options.get("eps_factor", 10.0))
    inner_rtol = float(options.get("inner_rtol", 1e-6))
    preconditioner = options.get("preconditioner", "grid")
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
            for term in l1:
                t = term.operator @ z
                omega = term.scaled_row_weights() / np.maximum(np.abs(t), eps)
                parts.append(0.5 * (term.operator.T @ sp.diags(omega) @ term.operator))
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
        z_new, n_inner, _, _ = pcg(system, b, x0=z, M=M, rtol=inner_rtol, maxiter=options.get("inner_max_iter", 500))
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
        decrease = (F - F_new) / max(abs(F_new), np.finfo(float).tiny)
        z, F = z_new, F_new
        recorder(k, z, inner=inner_total, value=F)
        if decrease <= tol:
            if eps <= eps_min * (1 + 1e-12) or not l1:
                converged = True
                message = f"relative decrease {decrease:.1e} <= tol {tol:.1e} at eps = {eps:.1e}"
                break
            eps = max(eps / eps_factor, eps_min)
    return _output(z, k, converged, message, recorder)


# ---------------------------------------------------------------------------
# L1 problem: ADMM / split Bregman with a constant system matrix
# ---------------------------------------------------------------------------
def _stack_l1(objective):
    terms = objective.abs_terms
    K = sp.vstack([t.operator for t in terms], format="csr")
    c = np.concatenate([t.scaled_row_weights() for t in terms])
    return K, c


def _default_rho(objective):
    """ADMM penalty: twice the data weight α (weight of the ``data`` term), else 2.

    ρ has the units of the quadratic weights.  With tol = 1e-3 plus the
    active-set polish, ρ = 2α reached the exact objective within ~1e-7 of a
    long reference run on two real 640x480 NYU frames (γ = 0.01), where
    ρ = α stopped ~1e-6 short at the same tolerance (bench/perf.py).
    """
    for term in objective.quadratic_terms:
        if term.name == "data":
            return 2.0 * float(term.weight)
    return 2.0


def _shrink(v, threshold):
    return np.sign(v) * np.maximum(np.abs(v) - threshold, 0.0)


def solve_admm(objective, x0, *, tol, max_iter, recorder, options):
    r"""ADMM (split Bregman) with over-relaxation for the L1 terms.

    Notes
    -----
    With ``u = K z`` (``K`` the stacked L1 operators, ``c`` their weights), the
    scaled-form iteration is::

        z ← (2A + ρ KᵀK)⁻¹ (2b + ρ Kᵀ(u − λ))      # PCG, warm-started, inexact
        v ← a K z + (1 − a) u                       # over-relaxation, a = 1.6
        u ← shrink(v + λ, c/ρ)
        λ ← λ + v − u

    The system matrix ``2A + ρKᵀK`` does not depend on the iterate and is a
    grid operator of stencil radius <= 2, so ONE geometric multigrid hierarchy
    (:class:`~sparsedepth.multigrid.GridMultigrid`, option ``preconditioner``,
    default ``"grid"``; ``"amg"`` for pyamg) preconditions every inner PCG
    solve, warm-started from the previous ``z``, stops when its residual is
    ``<= max(inner_rtol ‖rhs‖, inner_factor ‖rhs − S z_prev‖)`` (defaults
    ``inner_rtol = 1e-10``, ``inner_factor = 0.1``): a fixed reduction of the
    residual the new right-hand side creates, i.e. one or two V-cycles, with
    an error that shrinks as the iterates (and so the right-hand sides)
    settle.  ρ (option ``rho``; default
    :func:`_default_rho`) is adapted by residual balancing (factor 2 when one
    residual exceeds 10× the other, checked every 5 iterations) during the
    first ``adapt_iters`` iterations (default 0); the hierarchy is then
    re-computed numerically with :meth:`GridMultigrid.update`.  Stops when
    the primal and dual residuals ``r_k = ‖Kz − u‖ / max(‖Kz‖, ‖u‖)`` and
    ``s_k = ρ‖Kᵀ(u − u_prev)‖ / ‖ρKᵀλ‖`` are both ``<= tol``.  Finally an
    *active-set polish* (:func:`_active_set_polish`) solves the quadratic
    problem with the edges where ``u = 0`` tied (pixels merged) and the signs
    of the others fixed, and keeps it only if it lowers the exact F.

    References
    ----------
    Boyd, Parikh, Chu, Peleato, Eckstein, "Distributed optimization and
    statistical learning via the alternating direction method of multipliers",
    Found. Trends Mach. Learn. 3 (2011), §3.4.  Goldstein, Osher, "The split
    Bregman method for L1-regularized problems", SIAM J. Imaging Sci. 2 (2009).
    """
    from .linear import _dot

    A0, b, _ = objective.normal_equations()
    z = np.maximum(np.asarray(x0, dtype=float).copy(), 0.0)
    F = recorder(0, z, inner=0)
    kind = options.get("preconditioner", "grid")
    if not objective.has_l1:
        # nothing to split: one PCG solve
        M = make_preconditioner(A0, kind, shape=objective.shape)
        z, n, ok, rel = pcg(A0, b, x0=z, M=M, rtol=options.get("inner_rtol", 1e-10))
        recorder(1, z, inner=n)
        return _output(z, 1, ok, f"quadratic problem: relative residual {rel:.1e}", recorder)
    K, c = _stack_l1(objective)
    KT = K.T  # a CSC view, no copy
    relax = float(options.get("relaxation", 1.6))
    inner_rtol = float(options.get("inner_rtol", 1e-10))
    inner_factor = float(options.get("inner_factor", 0.1))
    adapt_iters = int(options.get("adapt_iters", 0))
    polish = bool(options.get("polish", True))
    Kz = K @ z
    rho = float(options["rho"]) if "rho" in options else _default_rho(objective)
    KtK = (KT @ K).tocsr()
    u = Kz.copy()
    lam = np.zeros_like(u)
    S = (2.0 * A0 + rho * KtK).tocsr()
    if adapt_iters <= 0:
        del KtK  # only needed to rebuild S for a new rho
    if kind == "grid":
        hierarchy = GridMultigrid(S, objective.shape, interpolation="auto")
        M = hierarchy.aspreconditioner()
    else:
        hierarchy = None
        M = make_preconditioner(S, kind, shape=objective.shape)
    inner_total = 0
    converged = False
    message = f"reached max_iter = {max_iter}"
    k = 0
    while k < max_iter:
        k += 1
        rhs = 2.0 * b + rho * (KT @ (u - lam))
        res0 = rhs - S @ z
        atol_k = inner_factor * np.sqrt(_dot(res0, res0))
        z, n_inner, _, _ = pcg(S, rhs, x0=z, M=M, rtol=inner_rtol, atol=atol_k,
                               maxiter=options.get("inner_max_iter", 200))
        inner_total += n_inner
        Kz = K @ z
        v = relax * Kz + (1.0 - relax) * u
        u_prev = u
        u = _shrink(v + lam, c / rho)
        lam += v - u
        d = Kz - u
        r_norm = np.sqrt(_dot(d, d)) / max(np.sqrt(_dot(Kz, Kz)), np.sqrt(_dot(u, u)), 1e-300)
        du = KT @ (u - u_prev)
        KTl = KT @ lam
        s_norm = np.sqrt(_dot(du, du)) / max(np.sqrt(_dot(KTl, KTl)), 1e-300)
        recorder(k, np.maximum(z, 0.0), inner=inner_total)
        if r_norm <= tol and s_norm <= tol:
            converged = True
            message = f"primal {r_norm:.1e} and dual {s_norm:.1e} residuals <= tol {tol:.1e} (rho = {rho:.3g})"
            break
        if k <= adapt_iters and k % 5 == 0 and (r_norm > 10 * s_norm or s_norm > 10 * r_norm):
            factor = 2.0 if r_norm > s_norm else 0.5
            rho *= factor
            lam /= factor
            S = (2.0 * A0 + rho * KtK).tocsr()
            if hierarchy is not None:
                hierarchy.update(S)
            else:
                M = make_preconditioner(S, kind, shape=objective.shape)
    z = np.maximum(z, 0.0)
    if polish:
        z_pol = _active_set_polish(objective, A0, b, K, c, u, kind, z0=z)
        if z_pol is not None:
            z_pol = np.maximum(z_pol, 0.0)
            F_pol, F_cur = objective.value(z_pol), objective.value(z)
            if F_pol < F_cur:
                z = z_pol
                recorder(k + 1, z, inner=inner_total, value=F_pol)
                message += "; active-set polish lowered F"
    return _output(z, k, converged, message, recorder)


def _active_set_polish(objective, A, b, K, c, u, kind, z0=None, rtol=1e-11):
    r"""Minimise the quadratic model with edges where ``u == 0`` tied and other signs fixed.

    Pixels joined by a tied edge are merged (connected components); with
    ``C`` the pixel-to-component indicator, ``z = C y`` and::

        Cᵀ A C y = Cᵀ(b − ½ Kᵀ(c ⊙ sign u))

    is solved by PCG with a pyamg Ruge–Stüben preconditioner (the reduced
    system is no longer a grid operator) to relative residual ``rtol``,
    warm-started from the component means of ``z0``.  Returns None where
    ``K`` has rows that are not pixel differences.
    """
    from scipy.sparse.csgraph import connected_components

    n = A.shape[0]
    counts = np.diff(K.indptr)
    pair_rows = np.flatnonzero(counts == 2)
    if np.any(counts > 2):
        return None
    first = K.indices[K.indptr[pair_rows]]
    second = K.indices[K.indptr[pair_rows] + 1]
    tied = u[pair_rows] == 0
    graph = sp.coo_matrix((np.ones(int(tied.sum())), (first[tied], second[tied])), shape=(n, n))
    n_comp, labels = connected_components(graph, directed=False)
    C = sp.csr_matrix((np.ones(n), (np.arange(n), labels)), shape=(n, n_comp))
    CT = C.T.tocsr()
    reduced = (CT @ A @ C).tocsr()
    rhs = CT @ (b - 0.5 * (K.T @ (c * np.sign(u))))
    y0 = None
    if z0 is not None:
        y0 = (CT @ z0) / np.bincount(labels, minlength=n_comp)
    pkind = "amg" if kind == "grid" else kind
    try:
        y, _, ok, _ = pcg(reduced, rhs, x0=y0, M=make_preconditioner(reduced, pkind), rtol=rtol, maxiter=2000)
    except ValueError:
        return None
    return C @ y


# ---------------------------------------------------------------------------
# gradient-based solvers on the smoothed objective
# ---------------------------------------------------------------------------
def solve_lbfgsb(objective, x0, *, tol, max_iter, recorder, options):
    """SciPy L-BFGS-B with bounds ``z >= 0`` on the smoothed objective.

    The objective is divided by ``F(x0)`` so that ``ftol = tol`` is a relative
    decrease; ``gtol`` defaults to 1e-12 on the scaled problem.
    """
    f0 = max(objective.smoothed_value_and_gradient(x0)[0], np.finfo(float).tiny)
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
            "maxfun": options.get("maxfun", 10 * max_iter + 100),
            "ftol": tol,
            "gtol": options.get("gtol", 1e-12),
            "maxcor": options.get("maxcor", 10),
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
    lr = float(options.get("learning_rate", 1e-2 * scale))
    decay = float(options.get("decay_steps", 200.0))
    b1, b2 = float(options.get("beta1", 0.9)), float(options.get("beta2", 0.999))
    window = int(options.get("window", 50))
    record_every = int(options.get("record_every", 1))
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
            if 0 <= (old - f) <= tol * abs(f):
                converged = True
                message = f"relative decrease over {window} steps {(old - f) / abs(f):.1e} <= tol {tol:.1e}"
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

DEFAULT_TOL = {"direct": 0.0, "cg": 1e-8, "amg": 1e-8, "irls": 1e-7, "admm": 1e-3, "lbfgsb": 1e-12, "adam": 1e-7}
DEFAULT_MAX_ITER = {"direct": 1, "cg": 5000, "amg": 500, "irls": 200, "admm": 1000, "lbfgsb": 15000, "adam": 20000}


def solve(objective, x0, *, solver, tol=None, max_iter=None, callback=None, options=None):
    """Run one named solver; returns ``(SolverOutput, runtime_seconds)``."""
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {sorted(SOLVERS)} or 'auto'")
    tol = DEFAULT_TOL[solver] if tol is None else float(tol)
    if not (np.isfinite(tol) and tol >= 0):
        raise ValueError(f"tol must be finite and >= 0, got {tol!r}")
    max_iter = DEFAULT_MAX_ITER[solver] if max_iter is None else int(max_iter)
    if max_iter < 1:
        raise ValueError(f"max_iter must be >= 1, got {max_iter}")
    recorder = _Recorder(objective, callback)
    try:
        out = SOLVERS[solver](objective, x0, tol=tol, max_iter=max_iter, recorder=recorder, options=dict(options or {}))
    except _Stop as stop:
        out = SolverOutput(stop.z, stop.iteration, False, f"stopped by callback at iteration {stop.iteration}", tuple(recorder.history))
    return out, recorder.elapsed()
