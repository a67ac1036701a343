r"""A duality-gap certificate: a proven upper bound on ``F(z) − F*`` for the completion objective.

The objective is ``F(z) = Q(z) + Σ_k c_k |(K z)_k|`` with the quadratic part
``Q(z) = zᵀAz − 2bᵀz + const`` (:meth:`~sparsedepth.objective.Objective.normal_equations`,
``A`` symmetric positive definite) and the stacked L1 operator ``K`` with row
weights ``c >= 0`` (:class:`~sparsedepth.objective.l1.StackedL1`).  See
:func:`duality_gap`.

May import :mod:`sparsedepth.objective` and :mod:`sparsedepth.linalg`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg  # noqa: F401  (sp.linalg)

from ..objective.l1 import StackedL1
from ..linalg.krylov import dot, pcg
from ..linalg.preconditioners import make_preconditioner
from ..objective.objective import QuadraticTerm

__all__ = ["Certificate", "duality_gap", "curvature_lower_bound"]


def curvature_lower_bound(objective) -> float:
    """A lower bound on ``λ_min(A)``: ``Σ weight · min(r)`` over the quadratic terms whose operator is the identity.

    ``A`` is the sum of these diagonal terms ``weight · diag(r)`` (the prior
    ``δ I``, and the data term ``α M``, whose minimum row weight is 0 unless
    every pixel is observed) and positive semidefinite terms; 0 when there is
    no such term.
    """
    bound = 0.0
    for t in objective.quadratic_terms:
        if isinstance(t, QuadraticTerm) and t.operator is None and t.weight > 0:
            r = 1.0 if t.row_weights is None else float(np.min(t.row_weights, initial=1.0))
            bound += float(t.weight) * r
    return bound


class Certificate:
    r"""Duality-gap bounds for one objective, reusing its multigrid hierarchy between calls.

    Parameters
    ----------
    objective : Objective
    nonnegative : bool
        True when the problem is ``min_{z >= 0} F`` (the L1 solvers, L-BFGS-B
        and Adam), False for the unconstrained quadratic problem of the
        γ = 0 solvers ``direct``, ``cg`` and ``amg``.
    rtol : float
        Relative residual of the PCG solve with ``A``.
    fit_steps : int
        Accelerated projected-gradient steps that fit the dual point on the
        tied rows of ``K`` (see Notes of :func:`duality_gap`).
    fit_max_iter : int
        CG steps of the least-squares fit on the tied rows at most
        (:meth:`_least_squares_fit`; 0 skips it).
    fit_correction : bool
        False: the least-squares fit replaces the start's tied rows; True: it
        corrects them (for a start that is close already, such as ADMM's
        multiplier).

    Attributes
    ----------
    proven : bool
        True when ``λ_min(A)`` has a positive lower bound
        (:func:`curvature_lower_bound`): the gap then includes the error term
        of the inexact solve and is a proven bound; otherwise that term is
        left out and the gap is an estimate (accurate to the PCG tolerance).
    """

    def __init__(self, objective, *, nonnegative=True, rtol=1e-10, fit_steps=20, fit_max_iter=100,
                 fit_correction=False):
        self.objective = objective
        self.fit_correction = bool(fit_correction)
        self.nonnegative = bool(nonnegative)
        self.rtol = float(rtol)
        self.fit_steps = int(fit_steps)
        self.fit_max_iter = int(fit_max_iter)
        self.l1 = StackedL1(objective) if objective.has_l1 else None
        self.curvature = curvature_lower_bound(objective)
        self.proven = self.curvature > 0
        self._precondition = None
        self._K_norm_sq = None

    def _preconditioner(self, A):
        if self._precondition is None:
            try:
                self._precondition = make_preconditioner(A, "grid", shape=self.objective.shape)
            except (ValueError, np.linalg.LinAlgError, RuntimeError):
                self._precondition = make_preconditioner(A, "jacobi")
        return self._precondition

    def _k_norm_sq(self):
        """An upper bound on ``‖K‖₂²``: max absolute row sum times max absolute column sum."""
        if self._K_norm_sq is None:
            if self.l1.grid_gradient:
                self._K_norm_sq = 8.0
            else:
                K = abs(sp.csr_matrix(self.l1.matrix))
                rows = float(np.max(np.asarray(K.sum(axis=1)), initial=0.0))
                cols = float(np.max(np.asarray(K.sum(axis=0)), initial=0.0))
                self._K_norm_sq = max(rows * cols, np.finfo(float).tiny)
        return self._K_norm_sq

    def dual_point(self, z, g, *, p=None, eps=0.0, tied=None):
        r"""The dual point ``p`` (``|p| <= c``) used for ``z``, and ``K z``.

        Rows with ``|(Kz)_k| > tie`` get ``c_k t_k / max(|t_k|, eps)``
        (``c_k sign(t_k)`` for ``eps = 0``); ``tie = max(eps, 1e-12 (1 +
        max|z|))``.  On the others and on the rows where ``tied`` is True
        (the tied rows) the start is ``p`` clipped to ``[−c, c]`` (without
        ``p``: the same formula), replaced (``fit_correction``: corrected) by the
        clipped least-squares fit of :meth:`_least_squares_fit` where that
        lowers ``‖g + Kᵀp‖`` (at most
        ``fit_max_iter`` CG steps, 0 skips it), then improved by
        ``fit_steps`` accelerated projected-gradient (FISTA) steps on ``‖g +
        Kᵀp‖²`` over the box.
        """
        l1 = self.l1
        t = l1.apply(z)
        c = l1.weights
        tie = max(float(eps), 1e-12 * (1.0 + float(np.max(np.abs(z), initial=0.0))))
        free = np.abs(t) <= tie
        if tied is not None:
            free |= np.asarray(tied, dtype=bool)
        q = c * t / np.maximum(np.abs(t), eps if eps > 0 else np.finfo(float).tiny)
        np.clip(q, -c, c, out=q)
        if p is not None:
            q[free] = np.clip(np.asarray(p, dtype=float)[free], -c[free], c[free])
        if self.fit_max_iter > 0 and free.any():
            q = self._least_squares_fit(q, free, g)
        if self.fit_steps > 0 and free.any():
            step = 1.0 / self._k_norm_sq()
            lo, hi = -c[free], c[free]
            y = q.copy()
            prev = q[free].copy()
            s = 1.0
            for _ in range(self.fit_steps):
                grad = l1.apply(g + l1.adjoint(y))
                new = np.clip(y[free] - step * grad[free], lo, hi)
                s_new = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * s * s))
                y[free] = new + ((s - 1.0) / s_new) * (new - prev)
                prev, s = new, s_new
            cand = q.copy()
            cand[free] = prev
            # keep the fit only if it lowered the residual it minimises
            if _norm_sq(g + l1.adjoint(cand)) <= _norm_sq(g + l1.adjoint(q)):
                q = cand
        return q, t, c

    def _least_squares_fit(self, q, free, g):
        r"""``q`` with its tied rows ``T`` replaced by the clipped least-squares fit of ``min ‖g + Kᵀq‖²``.

        Unconstrained, ``q_T = q⁰_T + K_T w`` with ``K_Tᵀ K_T w = −(h − h̄)``,
        ``h = g + Kᵀq⁰`` and ``h̄`` its mean over each component of the pixels
        joined by tied rows (the system is consistent; CG with the Jacobi
        preconditioner, at most ``fit_max_iter`` steps); ``q⁰`` is ``q`` with
        ``q⁰_T = 0``, or ``q`` itself with ``fit_correction`` (the fit then
        corrects the start on the tied rows).  The fit is kept only if it
        lowers ``‖g + Kᵀq‖``.
        """
        l1 = self.l1
        c_free = l1.weights[free]
        base = q.copy()
        if not self.fit_correction:
            base[free] = 0.0
        h = g + l1.adjoint(base)
        labels, count = l1.tied_components(free)
        sizes = np.bincount(labels, minlength=count)
        rhs = -(h - (np.bincount(labels, weights=h, minlength=count) / sizes)[labels])
        mask = free.astype(np.float64)
        if l1.grid_gradient:
            first, second = l1.pairs_where(free)
            degree = np.bincount(first, minlength=h.size) + np.bincount(second, minlength=h.size)
        else:
            K = sp.csr_matrix(l1.matrix)
            degree = np.asarray(K.multiply(K).T @ mask).ravel()
        inv = np.where(degree > 0, 1.0 / np.maximum(degree, np.finfo(float).tiny), 1.0)
        n = h.size
        L = sp.linalg.LinearOperator((n, n), matvec=lambda v: l1.adjoint(mask * l1.apply(np.ravel(v))),
                                     dtype=np.float64)
        w, _, _, _ = pcg(L, rhs, M=lambda v: inv * v, rtol=1e-10, maxiter=self.fit_max_iter)
        cand = q.copy()
        cand[free] = np.clip(base[free] + l1.apply(w)[free], -c_free, c_free)
        if _norm_sq(g + l1.adjoint(cand)) <= _norm_sq(g + l1.adjoint(q)):
            return cand
        return q

    def gap(self, z, *, p=None, eps=0.0, tied=None):
        """:func:`duality_gap` of ``z`` (solver units); NaN when the solve with ``A`` fails."""
        objective = self.objective
        A, b, _ = objective.normal_equations(form="stencil")  # products and a preconditioned solve: either form
        z = np.asarray(z, dtype=np.float64).ravel()
        if self.nonnegative:
            z = np.maximum(z, 0.0)
        g = A @ z
        g -= b
        g *= 2.0
        first = 0.0
        r = g
        if self.l1 is not None:
            q, t, c = self.dual_point(z, g, p=p, eps=eps, tied=tied)
            first = float(np.sum(np.maximum(c * np.abs(t) - q * t, 0.0)))
            r = g + self.l1.adjoint(q)
        if self.nonnegative:
            mu = np.where(z <= 0.0, np.maximum(r, 0.0), 0.0)
            r = r - mu
            first += max(dot(mu, z), 0.0)  # 0 up to rounding: mu is nonzero where z = 0 only
        if not np.all(np.isfinite(r)):
            return float("nan")
        if not np.any(r):
            return first
        y, _, ok, _ = pcg(A, r, M=self._preconditioner(A), rtol=self.rtol, maxiter=2000)
        e = r - A @ y
        quad = dot(y, r + e)  # = 2yᵀr − yᵀAy
        if self.proven:
            quad += dot(e, e) / self.curvature
        elif not ok:
            return float("nan")
        if not np.isfinite(quad):
            return float("nan")
        return first + 0.25 * max(quad, 0.0)


def _norm_sq(v):
    return dot(v, v)


def duality_gap(objective, z, *, p=None, eps=0.0, nonnegative=True, rtol=1e-10, fit_steps=50):
    r"""A proven upper bound on ``F(z) − F*`` by weak duality.

    Parameters
    ----------
    objective : Objective
    z : ndarray, shape (N,)
        The point (in the objective's units).
    p : ndarray, shape (m,), optional
        A dual estimate for the L1 rows (e.g. ADMM's ``ρλ``); used on the
        tied rows only, clipped to ``[−c, c]``.
    eps : float
        Rows with ``|(Kz)_k| <= eps`` count as tied; elsewhere ``p_k = c_k
        t_k / max(|t_k|, eps)`` (the smoothed solvers' gradient).
    nonnegative : bool
        ``F* = min_{z >= 0} F`` (True) or the unconstrained minimum (False).
    rtol : float
        Relative residual of the PCG solve with ``A``.
    fit_steps : int
        Projected-gradient steps of the dual fit on the tied rows.

    Returns
    -------
    float
        The bound (>= 0), in the objective's units; NaN when the solve with
        ``A`` fails (``A`` singular, e.g. ``δ = 0`` and no quadratic
        smoothness).  Proven when :func:`curvature_lower_bound` is positive;
        otherwise the residual term of the inexact solve is left out (an
        estimate accurate to ``rtol``).

    Notes
    -----
    For any ``p`` with ``|p_k| <= c_k`` and ``μ >= 0`` (the multiplier of
    ``z >= 0``), ``c_k|t_k| >= p_k t_k`` and ``μᵀz' >= 0`` for ``z' >= 0``,
    so ``F* >= min_{z'} L(z')`` with ``L(z') = Q(z') + pᵀKz' − μᵀz'``.  ``L``
    is quadratic with Hessian ``2A``; with ``r = ∇L(z) = 2(Az − b) + Kᵀp −
    μ`` its minimum is ``L(z) − ¼ rᵀA⁻¹r``, hence::

        F(z) − F* <= Σ_k (c_k |t_k| − p_k t_k) + μᵀz + ¼ rᵀA⁻¹r.

    ``μ_i = max(r_i, 0)`` where ``z_i = 0`` (0 elsewhere).  The solve is
    inexact: with ``y`` from multigrid-preconditioned CG and ``e = r − Ay``,
    ``rᵀA⁻¹r = 2yᵀr − yᵀAy + eᵀA⁻¹e`` and ``eᵀA⁻¹e <= ‖e‖² / λ_min(A)``,
    ``λ_min(A) >=`` :func:`curvature_lower_bound` (``δ`` for the prior
    ``δ‖z − z_c‖²``).  For γ = 0 (no L1 term) and ``nonnegative=False``
    this is the quadratic's own gap ``¼ rᵀA⁻¹r``.
    """
    cert = Certificate(objective, nonnegative=nonnegative, rtol=rtol, fit_steps=fit_steps)
    return cert.gap(z, p=p, eps=eps)
