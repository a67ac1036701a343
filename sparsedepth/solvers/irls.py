r"""Iteratively reweighted least squares (IRLS) for the L1 problem ``min_{z >= 0} F``.

May import :mod:`sparsedepth.linalg` and the other modules of :mod:`sparsedepth.solvers`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..linalg.krylov import pcg
from ..linalg.multigrid import GridMultigrid
from ..linalg.preconditioners import make_preconditioner
from .common import objective_floor, output, relative

__all__ = ["solve_irls"]


def solve_irls(objective, x0, *, tol, max_iter, recorder, options):
    r"""Iteratively reweighted least squares (majorise–minimise) for the L1 terms.

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
    scale = options.scale
    if scale is None:
        positive = x0[x0 > 0]
        scale = max(float(np.median(positive)) if positive.size else 1.0, 1e-12)
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
