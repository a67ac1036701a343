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
amg         γ = 0        PCG with an algebraic-multigrid V-cycle, same rule
irls        any          ``F_{k-1} − F_k ≤ tol · F_k`` at the final ε
admm        any          primal and dual residuals ``<= tol`` (relative)
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
    A, b, _ = objective.normal_equations()
    recorder(0, x0)
    M = make_preconditioner(A, preconditioner, shape=objective.shape)
    it = [0]

    def cb(xk):
        it[0] += 1
        recorder(it[0], xk, inner=it[0])

    z, n, converged, rel = pcg(A, b, x0=x0, M=M, rtol=tol, maxiter=max_iter, callback=cb)
    msg = f"relative residual {rel:.2e} {'<=' if converged else '>'} tol {tol:.1e} after {n} CG iterations"
    return _output(z, n, converged, msg, recorder)


def solve_cg(objective, x0, *, tol, max_iter, recorder, options):
    """Conjugate gradients with the Jacobi preconditioner ``diag(A)⁻¹``."""
    _require_quadratic(objective, "cg")
    return _solve_pcg(objective, x0, tol=tol, max_iter=max_iter, recorder=recorder, preconditioner="jacobi")


def solve_amg(objective, x0, *, tol, max_iter, recorder, options):
    """Conjugate gradients preconditioned by one algebraic-multigrid V-cycle."""
    _require_quadratic(objective, "amg")
    return _solve_pcg(
        objective, x0, tol=tol, max_iter=max_iter, recorder=recorder, preconditioner=options.get("preconditioner", "amg")
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

    solved by PCG (multigrid V-cycle preconditioner), warm-started from the
    current iterate, to relative residual ``inner_rtol``.  ε starts at
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
    preconditioner = options.get("preconditioner", "amg")
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
    """ADMM penalty: the data weight α (weight of the ``data`` term), else 1."""
    for term in objective.quadratic_terms:
        if term.name == "data":
            return float(term.weight)
    return 1.0


def _shrink(v, threshold):
    return np.sign(v) * np.maximum(np.abs(v) - threshold, 0.0)


def solve_admm(objective, x0, *, tol, max_iter, recorder, options):
    r"""ADMM (split Bregman) with over-relaxation for the L1 terms.

    Notes
    -----
    With ``u = K z`` (``K`` the stacked L1 operators, ``c`` their weights), the
    scaled-form iteration is::

        z ← (2A + ρ KᵀK)⁻¹ (2b + ρ Kᵀ(u − λ))      # PCG, warm-started
        v ← a K z + (1 − a) u                       # over-relaxation, a = 1.6
        u ← shrink(v + λ, c/ρ)
        λ ← λ + v − u

    The system matrix ``2A + ρKᵀK`` does not depend on the iterate, so one
    preconditioner (multigrid hierarchy) serves every iteration; ρ is adapted
    by residual balancing only during the first ``adapt_iters`` iterations
    (each change rebuilds the preconditioner once).  Stops when the primal and
    dual residuals ``‖Kz − u‖ / max(‖Kz‖, ‖u‖)`` and ``ρ‖Kᵀ(u − u_prev)‖ /
    ‖ρKᵀλ‖`` are both ``<= tol``.  Finally an *active-set polish* solves the
    quadratic problem with the edges where ``u = 0`` tied (pixels merged) and
    the signs of the others fixed, and keeps it only if it lowers the exact F.

    References
    ----------
    Boyd, Parikh, Chu, Peleato, Eckstein, "Distributed optimization and
    statistical learning via the alternating direction method of multipliers",
    Found. Trends Mach. Learn. 3 (2011), §3.4.  Goldstein, Osher, "The split
    Bregman method for L1-regularized problems", SIAM J. Imaging Sci. 2 (2009).
    """
    A0, b, _ = objective.normal_equations()
    z = np.maximum(np.asarray(x0, dtype=float).copy(), 0.0)
    F = recorder(0, z, inner=0)
    if not objective.has_l1:
        # nothing to split: one PCG solve
        M = make_preconditioner(A0, options.get("preconditioner", "amg"), shape=objective.shape)
        z, n, ok, rel = pcg(A0, b, x0=z, M=M, rtol=options.get("inner_rtol", 1e-10))
        recorder(1, z, inner=n)
        return _output(z, 1, ok, f"quadratic problem: relative residual {rel:.1e}", recorder)
    K, c = _stack_l1(objective)
    relax = float(options.get("relaxation", 1.6))
    inner_rtol = float(options.get("inner_rtol", 1e-8))
    adapt_iters = int(options.get("adapt_iters", 0))
    polish = bool(options.get("polish", True))
    kind = options.get("preconditioner", "amg")
    Kz = K @ z
    # ρ has the units of the quadratic weights; the data weight α was the best
    # fixed choice within a factor of ~3 on real frames (bench/perf.py)
    rho = float(options["rho"]) if "rho" in options else _default_rho(objective)
    KtK = (K.T @ K).tocsr()
    u = Kz.copy()
    lam = np.zeros_like(u)

    def system(rho):
        S = (2.0 * A0 + rho * KtK).tocsr()
        return S, make_preconditioner(S, kind, shape=objective.shape)

    S, M = system(rho)
    inner_total = 0
    converged = False
    message = f"reached max_iter = {max_iter}"
    k = 0
    while k < max_iter:
        k += 1
        rhs = 2.0 * b + rho * (K.T @ (u - lam))
        z, n_inner, _, _ = pcg(S, rhs, x0=z, M=M, rtol=inner_rtol, maxiter=options.get("inner_max_iter", 200))
        inner_total += n_inner
        Kz = K @ z
        v = relax * Kz + (1.0 - relax) * u
        u_prev = u
        u = _shrink(v + lam, c / rho)
        lam += v - u
        r_norm = np.linalg.norm(Kz - u) / max(np.linalg.norm(Kz), np.linalg.norm(u), 1e-300)
        s_norm = np.linalg.norm(K.T @ (u - u_prev)) / max(np.linalg.norm(K.T @ lam), 1e-300)
        recorder(k, np.maximum(z, 0.0), inner=inner_total)
        if r_norm <= tol and s_norm <= tol:
            converged = True
            message = f"primal {r_norm:.1e} and dual {s_norm:.1e} residuals <= tol {tol:.1e} (rho = {rho:.3g})"
            break
        if k <= adapt_iters and k % 5 == 0 and (r_norm > 10 * s_norm or s_norm > 10 * r_norm):
            factor = 2.0 if r_norm > s_norm else 0.5
            rho *= factor
            lam /= factor
            S, M = system(rho)
    z = np.maximum(z, 0.0)
    if polish:
        z_pol = _active_set_polish(objective, A0, b, K, c, u, kind)
        if z_pol is not None:
            z_pol = np.maximum(z_pol, 0.0)
            F_pol, F_cur = objective.value(z_pol), objective.value(z)
            if F_pol < F_cur:
                z = z_pol
                recorder(k + 1, z, inner=inner_total, value=F_pol)
                message += "; active-set polish lowered F"
    return _output(z, k, converged, message, recorder)


def _active_set_polish(objective, A, b, K, c, u, kind):
    """Minimise the quadratic model with edges where ``u == 0`` tied and other signs fixed.

    Pixels joined by a tied edge are merged (connected components); ``z = C y``
    with ``C`` the pixel-to-component indicator, and ``Cᵀ A C y = Cᵀ(b − ½Kᵀ(c·sign u))``.
    Returns None where ``K`` has rows that are not pixel differences.
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
    reduced = (C.T @ A @ C).tocsr()
    rhs = C.T @ (b - 0.5 * (K.T @ (c * np.sign(u))))
    try:
        y, _, ok, _ = pcg(reduced, rhs, M=make_preconditioner(reduced, "amg" if kind == "grid" else kind), rtol=1e-12, maxiter=2000)
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

DEFAULT_TOL = {"direct": 0.0, "cg": 1e-8, "amg": 1e-8, "irls": 1e-7, "admm": 1e-4, "lbfgsb": 1e-12, "adam": 1e-7}
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
