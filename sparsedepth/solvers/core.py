"""The front door of the solvers: argument checks, depth scaling, one solve, its certificate.

:func:`check_solver_arguments` checks and completes ``tol``, ``max_iter`` and
``options``; :func:`solve` divides the depth by :func:`depth_unit`, runs the
named solver of :data:`~sparsedepth.solvers.registry.REGISTRY` on
:func:`scaled_objective` and checks its claim of convergence against the
duality gap (:func:`certify`; not for objectives with robust terms, which
may be non-convex) and, for a solver that stopped at its start, a
projected-gradient test.  :data:`SOLVERS` and :data:`SOLVER_OPTIONS` are
the registry's, importable from here too.

May import :mod:`sparsedepth.objective`, :mod:`sparsedepth._validation` and
the other modules of :mod:`sparsedepth.solvers`.
"""

from __future__ import annotations

import numpy as np

from .._validation import is_int, is_real
from ..profiling import phase
from ..objective.objective import AbsTerm, Objective, QuadraticTerm, RobustTerm
from .certificate import Certificate, curvature_lower_bound
from .common import CallbackStop, Recorder, SolverOutput, gap_threshold, refuse_robust, relative, quick_value
from .registry import DEFAULT_MAX_ITER, DEFAULT_TOL, REGISTRY, SOLVER_OPTIONS, SOLVERS

__all__ = ["solve", "solve_scaled", "check_solver_arguments", "depth_unit", "scaled_objective", "certify",
           "start_kkt_residual", "SOLVERS", "SOLVER_OPTIONS", "QUADRATIC_CERTIFICATE_RTOL"]

#: A solver that stops at its start with converged=True must pass this relative optimality test.
START_KKT_RTOL = 1e-6


def check_solver_arguments(solver, tol=None, max_iter=None, options=None):
    """Check and complete the stopping parameters and options of the named solver.

    Parameters
    ----------
    solver : str
        A name in :data:`SOLVERS`.
    tol : float, optional
        Default :data:`~sparsedepth.solvers.registry.DEFAULT_TOL`.
    max_iter : int, optional
        Default :data:`~sparsedepth.solvers.registry.DEFAULT_MAX_ITER`;
        ``bool`` is not an int here.
    options : dict or SolverOptions, optional
        Keys of :data:`SOLVER_OPTIONS` for ``solver``, or an instance of the
        solver's options class (e.g. :class:`~sparsedepth.solvers.options.AdmmOptions`).

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
        For a ``tol``, ``max_iter``, ``options`` or option value of the wrong
        type, or the options class of another solver.
    """
    if not isinstance(solver, str) or solver not in REGISTRY:
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
    return tol, max_iter, REGISTRY[solver].options.from_mapping(options).as_dict()


def depth_unit(values) -> float:
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


#: The former name of :func:`depth_unit`, kept for code that imports it (``--depth-scale`` is the file's unit).
depth_scale = depth_unit

def scaled_objective(objective, scale, *, overwrite=False):
    """The objective in depth units of ``scale``: ``F_s(z / s) = F(z) / s²``.

    Every quadratic term's target is divided by ``s`` (its weight is
    unchanged), every L1 weight and the smoothing ``ε`` are divided by ``s``,
    and so are every robust term's weight and scale (``φ_σ(s t) = s φ_{σ/s}(t)``).
    Returns ``objective`` itself for ``s = 1``.  With ``overwrite`` the
    targets (float64 arrays) are divided in place, without a copy: for a
    caller that built ``objective`` and gives it up (a frame's targets are
    two arrays of its size).
    """
    s = float(scale)
    if s == 1.0:
        return objective
    targets = [t.target for t in objective.terms if isinstance(t, QuadraticTerm) and t.target is not None]
    # in place only when every target is a writeable float64 array of its own (no two share memory)
    overwrite = overwrite and all(isinstance(a, np.ndarray) and a.dtype == np.float64 and a.flags.writeable
                                  for a in targets) and not any(
        np.shares_memory(a, b) for i, a in enumerate(targets) for b in targets[i + 1:])
    terms = []
    for t in objective.terms:
        if isinstance(t, QuadraticTerm):
            if t.target is None:
                target = None
            elif overwrite:
                target = t.target
                target /= s
            else:
                target = np.asarray(t.target, dtype=np.float64) / s
            terms.append(QuadraticTerm(t.name, t.weight, t.operator, t.row_weights, target))
        elif isinstance(t, AbsTerm):
            terms.append(AbsTerm(t.name, t.weight / s, t.operator, t.row_weights))
        elif isinstance(t, RobustTerm):
            terms.append(RobustTerm(t.name, t.weight / s, t.operator, t.row_weights, t.penalty, t.scale / s))
        else:
            raise TypeError(f"objective term {t.name!r} has unknown type {type(t).__name__}")
    return Objective(objective.shape, terms, l1_smoothing=objective.l1_smoothing / s)


def start_kkt_residual(objective, z, smoothed):
    r"""Relative projected-gradient norm at ``z`` (0 certifies optimality over ``z >= 0``).

    The gradient is that of the smoothed objective (``smoothed``) or the
    subgradient of the exact one with ``sign((Kz)_k)`` (0 where ``(Kz)_k =
    0``: one element of the subdifferential, so a small value is a
    sufficient, not a necessary, certificate).  Projected: ``g_i`` where
    ``z_i > 0``, ``min(g_i, 0)`` where ``z_i = 0``.  Relative to
    ``2‖Az‖∞ + 2‖b‖∞ + ‖Kᵀ|c|‖∞`` (the sizes of the gradient's parts; ``c``
    the L1 and robust terms' ``weight · r``, robust gradients entering exactly).
    """
    A, b, _ = objective.normal_equations(form="stencil")  # products only: the cached form, no conversion
    if smoothed:
        g = objective.smoothed_value_and_gradient(z)[1]
    else:
        g = objective.l1_subgradient(z)
    size = 2.0 * float(np.max(np.abs(A @ z), initial=0.0)) + 2.0 * float(np.max(np.abs(b), initial=0.0))
    for t in objective.abs_terms + objective.robust_terms:
        size += float(np.max(np.abs(t.operator.T @ t.scaled_row_weights()), initial=0.0))
    pg = np.where(z > 0, g, np.minimum(g, 0.0))
    return float(np.max(np.abs(pg), initial=0.0)) / max(size, np.finfo(float).tiny)


def solve(objective, x0, *, solver, tol=None, max_iter=None, callback=None, options=None):
    """Run one named solver in normalised units; returns ``(SolverOutput, runtime_seconds)``.

    The depth is divided by ``s = depth_unit(x0)`` (a power of two near the
    median positive starting value): the solver minimises
    :func:`scaled_objective` from ``x0 / s`` and sees data of order 1 whatever
    the unit, so micrometres and kilometres give the same answer.  The
    output (``z``, the history's objective values, the callback's states) is
    in the user's units.  Options in depth units (``eps_start``, ``eps_min``,
    ``scale``, ``learning_rate``) are divided by ``s`` too.  See
    :func:`check_solver_arguments` for the checks of the arguments.

    A solver that reports convergence after at most one iteration, or at its
    unchanged start, must pass a projected-gradient check
    (:func:`start_kkt_residual` ``<= 1e-6``); otherwise the output says
    ``converged=False`` and why.

    An objective with robust terms (:class:`~sparsedepth.objective.terms.RobustTerm`)
    is accepted by the solvers registered ``robust`` only (IRLS, L-BFGS-B,
    Adam; the others raise ``ValueError``).  It may be non-convex, so there is
    no duality gap (NaN): ``converged`` is the solver's own stopping rule,
    which finds a stationary point, not a certified minimum.
    """
    tol, max_iter, options = check_solver_arguments(solver, tol, max_iter, options)
    x0 = np.asarray(x0, dtype=np.float64).ravel()
    scale = depth_unit(x0)
    return solve_scaled(scaled_objective(objective, scale), x0 / scale, scale=scale, solver=solver, tol=tol,
                        max_iter=max_iter, callback=callback, options=options)


def solve_scaled(objective, x0, *, scale, solver, tol, max_iter, callback, options, certify_result=True,
                 objective_values=True, bounds=None):
    """:func:`solve` for an objective and start already in units of ``scale`` (checked ``tol`` and ``max_iter``).

    ``options`` is a dict of the solver's options or an instance of its
    options class, in the user's units.  With ``certify_result=False`` no
    duality gap is computed where the solver did not produce one (the gap is
    NaN and ``converged`` is the solver's own rule): the real-time mode's
    coarse solve, whose answer is an intermediate of a larger computation.
    With ``objective_values=False`` the history's objective values are NaN
    where the solver would evaluate ``F`` only to record it (the quadratic
    solvers' CG steps and last iterate).

    ``bounds = (low, high)`` (solver units; floats or per-pixel arrays) is
    the box the caller clips the answer to: the output's ``gap`` is then a
    bound on ``F(clip(z)) − min_{low <= z' <= high} F`` (see
    :func:`certify`), ``solver_gap`` the solver's own, and ``converged``
    needs the solver's stopping rule and ``gap <= gap_tol · max(F, floor)``
    with ``F`` of the clipped point: it is about the depth the caller
    returns.  ``z`` itself is the solver's point, unclipped.
    """
    entry = REGISTRY[solver]
    if not entry.robust:
        refuse_robust(objective, solver)
    options = entry.options.from_mapping(options).in_depth_units(scale)
    recorder = Recorder(objective, callback, scale, values=objective_values)
    try:
        with phase("iterations"):
            out = entry.solve(objective, x0, tol=tol, max_iter=max_iter, recorder=recorder, options=options)
    except CallbackStop as stop:
        out = SolverOutput(stop.z, stop.iteration, False, f"stopped by callback at iteration {stop.iteration}",
                           tuple(recorder.history))
    robust = [t.name for t in objective.robust_terms]
    certified = certify_result and not robust
    z_returned = out.z if bounds is None else np.clip(out.z, bounds[0], bounds[1])
    moved = int(np.count_nonzero(z_returned != out.z))
    with phase("certificate"):
        # F at the returned point and at the solver's point, each evaluated once for every test and message below
        F_returned = quick_value(objective, z_returned) if certified else float("nan")
        F_solver = quick_value(objective, out.z) if certified and moved else F_returned
        solver_gap = out.gap
        if moved and certified:
            gap = certify(objective, z_returned, solver, options, bounds=bounds, value=F_returned)
            if np.isnan(solver_gap):
                # the solver's own point is certified in full only where it tells why the returned depth failed
                failed = not gap <= gap_threshold(objective, F_returned, options.gap_tol)
                solver_gap = certify(objective, out.z, solver, options, cheap=not failed, value=F_solver)
        else:
            if np.isnan(solver_gap) and certified:
                solver_gap = certify(objective, out.z, solver, options, value=F_solver)
            gap = solver_gap
    objective.preconditioner = None  # the hierarchy a solve left for the certificate: not held past it
    proven = curvature_lower_bound(objective) > 0
    converged, message = out.converged, out.message
    own = converged
    if robust:
        gap = solver_gap = float("nan")
        message += (f"; no duality gap for the robust term(s) {robust} (F may be non-convex): converged is the "
                    "solver's own rule, a stationary point")
    elif not certify_result:
        message += "; duality gap not computed"
    elif np.isnan(gap):
        message += "; duality gap not available (the solve with the quadratic part's matrix failed)"
    else:
        converged, message = _gap_verdict(objective, out, (F_returned, F_solver), gap, solver_gap, moved, bounds,
                                          scale, options.gap_tol, proven)
    if own and solver != "direct" and (out.iterations <= 1 or np.array_equal(out.z, np.maximum(x0, 0.0))):
        kkt = start_kkt_residual(objective, np.maximum(out.z, 0.0), entry.smoothed)
        if not kkt <= START_KKT_RTOL:
            converged = False
            message += (f"; NOT converged: stopped after {out.iterations} iteration(s) at a point whose relative "
                        f"projected gradient {kkt:.1e} > {START_KKT_RTOL:.0e}")
    z = out.z * scale
    s2 = scale * scale
    return (SolverOutput(z, out.iterations, converged, message, tuple(recorder.history), gap * s2,
                         solver_gap * s2, proven), recorder.elapsed())


def _gap_verdict(objective, out, values, gap, solver_gap, moved, bounds, scale, gap_tol, proven):
    """``(converged, message)``: the solver's rule and the gap test of the returned point, said in the message.

    ``values`` are ``F`` at the returned point and at the solver's point.
    """
    F, F_solver = values
    threshold = gap_threshold(objective, F, gap_tol)
    message = out.message
    if moved:
        low, high = (float(np.min(b)) * scale if np.ndim(b) else float(b) * scale for b in bounds)
        message += (f"; clipping to [{low:g}, {high:g}] moved {moved} pixel(s): duality gap of the returned depth "
                    f"{relative(gap, F):.1e} (relative, over that range), of the solver's point "
                    f"{relative(solver_gap, F_solver):.1e}")
    else:
        message += f"; duality gap {relative(gap, F):.1e} (relative)"
    if not proven:
        message += " (an estimate, not a proven bound: no positive curvature bound, delta = 0)"
    if not gap <= threshold:
        cause = ""
        if moved and solver_gap <= gap_threshold(objective, F_solver, gap_tol):
            cause = " (the clipping, not the solver: clip_to_observed=False returns the solver's point)"
        return False, message + f"; NOT converged: > gap_tol {gap_tol:.1e}{cause}"
    return out.converged, message + (f" <= gap_tol {gap_tol:.1e}" if out.converged else "")


#: Relative residual of the certificate's solve with ``A`` for an objective without L1 terms whose curvature bound
#: makes the gap proven: the bound then includes the solve's error term ``‖e‖² / λ_min``, at most 1e-4 of the
#: one-product bound ``¼ ‖r‖² / λ_min``.
QUADRATIC_CERTIFICATE_RTOL = 1e-2


def certify(objective, z, solver, options, *, bounds=None, cheap=False, value=None):
    """The duality gap (:mod:`sparsedepth.solvers.certificate`) of a solver's output ``z``, in solver units.

    Without ``bounds``: a bound on ``F(z) − F*`` with ``F*`` the minimum of
    the solver's problem (over all ``z`` for the γ = 0 solvers, over ``z >=
    0`` for the others).  With ``bounds = (low, high)`` (``z`` inside
    them): a bound on ``F(z) − min_{low <= z' <= high} F``, the smaller of
    the certificate over the solver's problem (valid too where the box lies
    inside its feasible set, whose minimum is no larger) and the one over the
    box (:class:`~sparsedepth.solvers.certificate.Certificate` with
    ``bounds``; computed only when the first one does not pass ``gap_tol``).

    Rows of ``K`` with ``|(Kz)_k| <= ε`` count as tied, with ``ε`` the
    smoothing :attr:`Objective.l1_smoothing` for the solvers registered with
    ``smoothing_ties`` (L-BFGS-B, Adam, IRLS) and exact ties otherwise.
    Without L1 terms the one-product bound ``¼ ‖r‖² / λ_min(A)``
    (:meth:`Certificate.cheap_gap`) is returned when it already meets
    ``gap_tol``, else the solve with ``A`` runs to
    :data:`QUADRATIC_CERTIFICATE_RTOL`, preconditioned by the hierarchy the
    solve left (:attr:`Objective.preconditioner`, dropped by :func:`solve_scaled` after the certificate).  With ``cheap`` that
    one-product bound is returned as it is (``inf`` with L1 terms).  ``value``
    is ``F(z)`` when the caller has it (the scale of ``gap_tol``).  NaN for
    an objective with robust terms: the certificate covers quadratic and L1
    terms only (and a robust objective may be non-convex).
    """
    if objective.robust_terms:
        return float("nan")
    entry = REGISTRY[solver]
    eps = float(objective.l1_smoothing) if entry.smoothing_ties else 0.0
    # ADMM without L1 terms returns one unconstrained PCG solve
    nonnegative = not entry.quadratic and not (solver == "admm" and not objective.has_l1)
    quadratic = not objective.has_l1
    rtol = QUADRATIC_CERTIFICATE_RTOL if quadratic and curvature_lower_bound(objective) > 0 else 1e-10
    threshold = gap_threshold(objective, quick_value(objective, z) if value is None else value, options.gap_tol)
    problem_low = 0.0 if nonnegative else -np.inf
    boxes = []  # the solver's problem (when the box lies inside it), then the box itself
    if bounds is None or np.all(np.asarray(bounds[0]) >= problem_low):
        boxes.append((problem_low, np.inf))
    if bounds is not None:
        boxes.append((np.maximum(bounds[0], problem_low), bounds[1]))
    gap, shared = float("nan"), None
    for box in boxes:
        certificate = Certificate(objective, bounds=box, rtol=rtol, preconditioner=shared)  # one hierarchy of A
        bound = certificate.cheap_gap(z)
        bound = bound if cheap or bound <= threshold else certificate.gap(z, eps=eps, target=threshold)
        gap = bound if np.isnan(gap) else min(gap, bound)
        shared = certificate.preconditioner
        if gap <= threshold:
            break
    return gap
