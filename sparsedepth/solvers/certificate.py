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
from ..linalg.multigrid import GridMultigrid
from ..linalg.preconditioners import make_preconditioner
from ..objective.objective import QuadraticTerm

__all__ = ["Certificate", "BoundReached", "duality_gap", "curvature_lower_bound"]


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
    r"""Duality-gap bounds for one objective, reusing its multigrid hierarchy between calls (unless ``low_memory``).

    Parameters
    ----------
    objective : Objective
    nonnegative : bool
        True when the problem is ``min_{z >= 0} F`` (the L1 solvers, L-BFGS-B
        and Adam), False for the unconstrained quadratic problem of the
        γ = 0 solvers ``direct``, ``cg`` and ``amg``.  Ignored when
        ``bounds`` is given.
    bounds : (float or ndarray, float or ndarray), optional
        ``(low, high)``: the problem is ``min_{low <= z <= high} F``
        (``high`` may be ``inf``, ``low`` ``-inf``; arrays of shape (N,) are
        per-pixel bounds); the box of a range clamp.  Default: ``(0, inf)``
        when ``nonnegative``, else no bound.
    preconditioner : callable or LinearOperator, optional
        A preconditioner of ``A`` to use instead of building one; default the
        objective's kept one (:attr:`Objective.preconditioner`), if any.
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
    low_memory : bool
        False: the preconditioner of ``A`` (a multigrid hierarchy) is built at
        the first call and reused by the next ones.  True, for the memory of
        large frames where a caller such as ADMM checks rarely: ``2(Az − b)``
        is summed term by term (:meth:`Objective.quadratic_gradient`), so
        that ``A`` is assembled (:meth:`Objective.normal_equations`) only
        after the dual point, for the solve; the hierarchy is built in each
        call with a float64 fine level swept from ``A``'s own stencil (no
        float32 copy of it) and dropped at the end of the call, like ``A``
        (not left in the objective's cache).

    Attributes
    ----------
    proven : bool
        True when ``λ_min(A)`` has a positive lower bound
        (:func:`curvature_lower_bound`): the gap then includes the error term
        of the inexact solve and is a proven bound; otherwise that term is
        left out and the gap is an estimate (accurate to the PCG tolerance).
    """

    def __init__(self, objective, *, nonnegative=True, bounds=None, rtol=1e-10, fit_steps=20, fit_max_iter=100,
                 fit_correction=False, low_memory=False, preconditioner=None):
        self.objective = objective
        self.low_memory = bool(low_memory)
        self.fit_correction = bool(fit_correction)
        if bounds is None:
            bounds = (0.0, np.inf) if nonnegative else (-np.inf, np.inf)
        self.low, self.high = (b if np.ndim(b) == 0 else np.asarray(b, dtype=np.float64).ravel()
                               for b in (float(bounds[0]) if np.ndim(bounds[0]) == 0 else bounds[0],
                                         float(bounds[1]) if np.ndim(bounds[1]) == 0 else bounds[1]))
        if not np.all(self.low <= self.high):
            raise ValueError("bounds must have low <= high everywhere")
        self.nonnegative = bool(np.all(self.low >= 0.0))
        self.rtol = float(rtol)
        self.fit_steps = int(fit_steps)
        self.fit_max_iter = int(fit_max_iter)
        self.l1 = StackedL1(objective) if objective.has_l1 else None
        self.curvature = curvature_lower_bound(objective)
        self.proven = self.curvature > 0
        self._precondition = preconditioner
        self._K_norm_sq = None

    @property
    def preconditioner(self):
        """The preconditioner of ``A`` this certificate keeps for its next call (None before the first solve with
        ``A``, and with ``low_memory``): to hand to another certificate of the same objective."""
        return self._precondition

    def _preconditioner(self, A):
        """The preconditioner of ``A``: kept for the next call, or (``low_memory``) a new one each time."""
        if self._precondition is not None:
            return self._precondition
        if not self.low_memory and self.objective.preconditioner is not None:
            self._precondition = self.objective.preconditioner
            return self._precondition
        try:
            if self.low_memory:
                hierarchy = GridMultigrid(A, self.objective.shape, interpolation="auto", fine_precision="double")
                return hierarchy.aspreconditioner()
            self._precondition = make_preconditioner(A, "grid", shape=self.objective.shape)
        except (ValueError, np.linalg.LinAlgError, RuntimeError):
            self._precondition = make_preconditioner(A, "jacobi")
        return self._precondition

    def _quadratic_gradient(self, z):
        """``2(Az − b)``: with ``A`` and ``b`` (cached by the objective), or (``low_memory``) term by term."""
        if self.low_memory:
            return self.objective.quadratic_gradient(z)
        A, b, _ = self.objective.normal_equations(form="stencil")  # products and a preconditioned solve: either form
        g = A @ z
        g -= b
        g *= 2.0
        return g

    def k_norm_squared(self):
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

        Returns
        -------
        p, t, c : ndarray, shape (m,)
            The dual point, ``t = K z`` and the row weights ``c``.
        """
        return self._dual(z, g, p=p, eps=eps, tied=tied), self.l1.apply(z), self.l1.weights

    def _dual(self, z, g, *, p=None, eps=0.0, tied=None, overwrite_p=False):
        """The dual point of :meth:`dual_point` alone; of the edge vectors only it and the tied rows are kept.

        The start is formed chunk by chunk (:meth:`StackedL1.weight_chunks`),
        so that neither ``c`` nor a temporary as long as ``K z`` is formed,
        and ``K z`` is dropped before the fits.  With ``overwrite_p`` the
        start is written into ``p`` when ``p`` is a float64 array of its own
        (each chunk of ``p`` is read before it is overwritten).
        """
        l1 = self.l1
        t = l1.apply(z)
        tie = max(float(eps), 1e-12 * (1.0 + float(np.max(np.abs(z), initial=0.0))))
        floor = eps if eps > 0 else np.finfo(float).tiny
        q = None
        if p is not None:
            given = p
            p = np.asarray(p, dtype=float)
            if overwrite_p and p is given and p.shape == t.shape and p.flags.c_contiguous and p.flags.writeable:
                q = p
        if q is None:
            q = np.empty_like(t)
        if tied is not None:
            tied = np.asarray(tied, dtype=bool)
        free = np.empty(t.shape, dtype=bool)
        for rows, c in l1.weight_chunks():
            t_k, q_k, free_k = t[rows], q[rows], free[rows]
            a = np.abs(t_k)
            np.less_equal(a, tie, out=free_k)
            if tied is not None:
                free_k |= tied[rows]
            start = None if p is None else np.clip(p[rows], -c, c)  # read before q_k (maybe p's rows) is written
            np.multiply(c, t_k, out=q_k)
            q_k /= np.maximum(a, floor, out=a)
            np.clip(q_k, -c, c, out=q_k)
            if start is not None:
                np.copyto(q_k, start, where=free_k)
        del t, p, tied
        if self.fit_max_iter > 0 and free.any():
            q = self._least_squares_fit(q, free, g)
        if self.fit_steps > 0 and free.any():
            q = self._projected_gradient_fit(q, free, g)
        return q

    def _projected_gradient_fit(self, q, free, g):
        """``q`` improved on its tied rows by ``fit_steps`` FISTA steps on ``‖g + Kᵀq‖²`` over the box, if lower."""
        l1 = self.l1
        step = 1.0 / self.k_norm_squared()
        c = l1.weights
        lo, hi = -c[free], c[free]
        del c
        y = q.copy()
        prev = q[free].copy()
        s = 1.0
        for _ in range(self.fit_steps):
            grad = l1.apply(g + l1.adjoint(y))
            new = np.clip(y[free] - step * grad[free], lo, hi)
            s_new = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * s * s))
            y[free] = new + ((s - 1.0) / s_new) * (new - prev)
            prev, s = new, s_new
        del y, grad, new, lo, hi
        cand = q.copy()
        cand[free] = prev
        # keep the fit only if it lowered the residual it minimises
        if _norm_sq(g + l1.adjoint(cand)) <= _norm_sq(g + l1.adjoint(q)):
            return cand
        return q

    def _least_squares_fit(self, q, free, g):
        r"""``q`` with its tied rows ``T`` replaced by the clipped least-squares fit of ``min ‖g + Kᵀq‖²``.

        Unconstrained, ``q_T = q⁰_T + K_T w`` with ``K_Tᵀ K_T w = −(h − h̄)``,
        ``h = g + Kᵀq⁰`` and ``h̄`` its mean over each component of the pixels
        joined by tied rows (the system is consistent; CG with the Jacobi
        preconditioner, at most ``fit_max_iter`` steps); ``q⁰`` is ``q`` with
        ``q⁰_T = 0``, or ``q`` itself with ``fit_correction`` (the fit then
        corrects the start on the tied rows).  The fit is kept only if it
        lowers ``‖g + Kᵀq‖``.  Memory: besides ``q`` and the tied rows'
        mask, pixel vectors during the CG steps
        (:meth:`StackedL1.masked_normal_product`), then the candidate.
        """
        l1 = self.l1
        h = l1.adjoint(q)
        h += g  # g + Kᵀq
        start_sq = _norm_sq(h)
        if not self.fit_correction:
            h = l1.adjoint(np.where(free, 0.0, q))
            h += g
        labels, count = l1.tied_components(free)
        means = np.bincount(labels, weights=h, minlength=count)
        means /= np.bincount(labels, minlength=count)
        rhs = h - means[labels]
        np.negative(rhs, out=rhs)
        del h, labels, means
        degree = l1.squared_adjoint(free)  # rows of K_T per pixel: the diagonal of K_TᵀK_T
        inv = np.divide(1.0, degree, out=np.ones_like(degree), where=degree > 0)
        del degree
        n = rhs.size
        L = sp.linalg.LinearOperator((n, n), matvec=lambda v: l1.masked_normal_product(np.ravel(v), free),
                                     dtype=np.float64)
        w, _, _, _ = pcg(L, rhs, M=lambda v: inv * v, rtol=1e-10, maxiter=self.fit_max_iter)
        del rhs, inv, L
        cand = l1.apply(w)
        del w
        if self.fit_correction:
            cand += q
        l1.clip(cand)
        np.copyto(cand, q, where=~free)
        h = l1.adjoint(cand)
        h += g
        if _norm_sq(h) <= start_sq:
            return cand
        return q

    def gap(self, z, *, p=None, eps=0.0, tied=None, overwrite_p=False, target=None):
        """:func:`duality_gap` of ``z`` (solver units) for the problem over the box; NaN when the solve with ``A`` fails.

        ``z`` is clipped to the box first.

        ``p``, ``eps`` and ``tied``: see :meth:`dual_point`.  With
        ``overwrite_p`` the dual point is formed in ``p``'s memory (a float64
        array), whose contents are then undefined: for a caller whose ``p``
        is a work vector.  The dual point is formed first and reduced to
        ``r`` before the preconditioner of ``A`` is built or used, so that
        the edge vectors and the multigrid hierarchy are not held together.

        ``target``: for a caller that only asks whether the gap is at most
        ``target``.  When the bound is proven (:attr:`proven`), the solve with
        ``A`` stops as soon as the bound at its current iterate, error term
        included, is at most half of ``target`` (:class:`BoundReached`), and
        the bound of that iterate is returned: a proven bound at most
        ``target``, looser than the one of a solve to ``rtol``.  Where it
        is not (the recursive residual drifted from the true one), the solve
        goes on to ``rtol``.
        """
        z = np.asarray(z, dtype=np.float64).ravel()
        if np.any(z < self.low) or np.any(z > self.high):
            z = np.clip(z, self.low, self.high)
        g = self._quadratic_gradient(z)
        first = 0.0
        r = g
        if self.l1 is not None:
            q = self._dual(z, g, p=p, eps=eps, tied=tied, overwrite_p=overwrite_p)
            del p, tied
            first = self._complementarity(z, q)
            r = self.l1.adjoint(q)
            del q
            r += g
        del g
        first += self._bound_multipliers(z, r)
        del z
        if not np.all(np.isfinite(r)):
            return float("nan")
        if not np.any(r):
            return first
        A = self.objective.normal_equations(form="stencil", cache=not self.low_memory)[0]
        precondition = self._preconditioner(A)
        early = None
        if target is not None and self.proven and np.isfinite(target):
            early = BoundReached(r, first, self.curvature, 0.5 * float(target))
        y, _, ok, _ = pcg(A, r, M=precondition, rtol=self.rtol, maxiter=2000, callback=early,
                          callback_residual=True)
        bound = self._solve_bound(A, r, y, first, ok)
        if early is not None and early.reached and not bound <= target:  # the true residual disagreed: go on
            y, _, ok, _ = pcg(A, r, x0=y, M=precondition, rtol=self.rtol, maxiter=2000)
            bound = self._solve_bound(A, r, y, first, ok)
        return bound

    def _solve_bound(self, A, r, y, first, ok):
        """``first + ¼ (yᵀ(r + e) + ‖e‖² / λ)`` with ``e = r − A y`` (``λ`` the curvature bound; without one, the
        error term is left out and NaN is returned for a solve that did not converge)."""
        if not self.proven and not ok:
            return float("nan")
        quad = _inverse_form_bound(y, r, r - A @ y, self.curvature if self.proven else None)
        if not np.isfinite(quad):
            return float("nan")
        return first + 0.25 * max(quad, 0.0)

    def _bound_multipliers(self, z, r):
        """Subtract the bounds' multipliers from ``r`` in place; returns their complementarity term (0 up to rounding).

        ``μ_low = max(r, 0)`` where ``z`` is at ``low`` and ``μ_high = max(−r, 0)`` where it is at ``high``
        (0 elsewhere): ``r − μ_low + μ_high`` is the gradient of the Lagrangian, and the term is ``μ_lowᵀ(z −
        low) + μ_highᵀ(high − z)``.
        """
        term = 0.0
        if np.any(np.isfinite(self.low)):
            mu = np.where(z <= self.low, np.maximum(r, 0.0), 0.0)
            r -= mu
            term += max(dot(mu, np.where(mu > 0, z - self.low, 0.0)), 0.0)
        if np.any(np.isfinite(self.high)):
            mu = np.where(z >= self.high, np.maximum(-r, 0.0), 0.0)
            r += mu
            term += max(dot(mu, np.where(mu > 0, self.high - z, 0.0)), 0.0)
        return term

    def cheap_gap(self, z):
        """A proven bound from one product: :meth:`gap` with ``A⁻¹`` bounded by ``1 / λ_min(A)``; ``inf`` without one.

        For the quadratic objective (no L1 term): ``F(z) − F* <= (complementarity) + ¼ ‖r‖² / λ_min(A)`` with
        ``r`` the Lagrangian's gradient (:meth:`gap`, Notes of :func:`duality_gap`) and ``λ_min(A) >=``
        :func:`curvature_lower_bound`.  ``inf`` when the objective has L1 terms or no curvature bound.
        """
        if self.l1 is not None or not self.proven:
            return float("inf")
        z = np.clip(np.asarray(z, dtype=np.float64).ravel(), self.low, self.high)
        r = self._quadratic_gradient(z)
        first = self._bound_multipliers(z, r)
        return first + 0.25 * dot(r, r) / self.curvature

    def _complementarity(self, z, q):
        """``Σ_k max(c_k |t_k| − q_k t_k, 0)`` with ``t = K z``, chunk by chunk."""
        t = self.l1.apply(z)
        total = 0.0
        for rows, c in self.l1.weight_chunks():
            t_k = t[rows]
            c *= np.abs(t_k)
            c -= q[rows] * t_k
            total += float(np.sum(np.maximum(c, 0.0, out=c)))
        return total


class BoundReached:
    r"""A PCG callback that stops the certificate's solve ``A y = r`` once its bound is at most ``target``.

    Called with the iterate ``y`` and the recursive residual ``e ≈ r − A y``; raises ``StopIteration`` when
    ``first + ¼ (yᵀ(r + e) + ‖e‖² / λ) <= target``, the bound :meth:`Certificate.gap` computes (there with the true
    residual), and sets :attr:`reached`.

    Notes
    -----
    For any ``y``, ``rᵀA⁻¹r = 2yᵀr − yᵀAy + (r − Ay)ᵀA⁻¹(r − Ay) <= yᵀ(r + e) + ‖e‖² / λ_min(A)`` with
    ``e = r − A y``, so the bound holds at every iterate, not only at the end of the solve; it decreases toward
    ``rᵀA⁻¹r`` as CG converges.
    """

    def __init__(self, r, first, curvature, target):
        self.r, self.first, self.curvature, self.target = r, float(first), float(curvature), float(target)
        self.reached = False

    def __call__(self, y, e):
        quad = _inverse_form_bound(y, self.r, e, self.curvature)
        if self.first + 0.25 * max(quad, 0.0) <= self.target:
            self.reached = True
            raise StopIteration


def _inverse_form_bound(y, r, e, curvature):
    """``yᵀ(r + e) + ‖e‖² / λ`` with ``e = r − A y`` and ``λ = curvature``: a bound on ``rᵀA⁻¹r`` for any ``y``
    (:class:`BoundReached`, Notes); without ``curvature`` (None) the last term is left out and the value is an
    estimate, exact as ``e → 0``."""
    quad = dot(y, r) + dot(y, e)  # = 2yᵀr − yᵀAy
    if curvature is not None:
        quad += dot(e, e) / curvature
    return quad


def _norm_sq(v):
    return dot(v, v)


def duality_gap(objective, z, *, p=None, eps=0.0, nonnegative=True, bounds=None, rtol=1e-10, fit_steps=50):
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
    bounds : (float or ndarray, float or ndarray), optional
        ``F* = min_{low <= z <= high} F`` instead (see :class:`Certificate`).
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

    ``μ_i = max(r_i, 0)`` where ``z_i = 0`` (0 elsewhere).  Over a box
    ``low <= z <= high`` the same holds with ``μ_low = max(r, 0)`` where
    ``z`` is at ``low``, ``μ_high = max(−r, 0)`` where it is at ``high``
    (``L`` gains ``−μ_lowᵀ(z' − low) + μ_highᵀ(z' − high)``, at most 0 in
    the box) and ``r = 2(Az − b) + Kᵀp − μ_low + μ_high``.  The solve is
    inexact: with ``y`` from multigrid-preconditioned CG and ``e = r − Ay``,
    ``rᵀA⁻¹r = 2yᵀr − yᵀAy + eᵀA⁻¹e`` and ``eᵀA⁻¹e <= ‖e‖² / λ_min(A)``,
    ``λ_min(A) >=`` :func:`curvature_lower_bound` (``δ`` for the prior
    ``δ‖z − z_c‖²``).  For γ = 0 (no L1 term) and ``nonnegative=False``
    this is the quadratic's own gap ``¼ rᵀA⁻¹r``.
    """
    cert = Certificate(objective, nonnegative=nonnegative, bounds=bounds, rtol=rtol, fit_steps=fit_steps)
    return cert.gap(z, p=p, eps=eps)
