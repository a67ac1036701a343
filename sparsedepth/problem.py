"""A completion problem set up once and solved many times: :class:`CompletionProblem`.

The problem owns everything of a completion that does not depend on the solver: the checked inputs, the weights
resolved for the observed fraction, the depth unit the solve runs in, the assembled objective, the nearest-sample
fill ``z_c`` and the range the answer is clamped to.  :meth:`CompletionProblem.solve` runs any registered solver on
it and returns a :class:`~sparsedepth.result.CompletionResult`; :meth:`CompletionProblem.with_samples` is the same
problem with another set of observations (the uncertainty's half-sample solves), sharing every term that depends on
the image alone.  :func:`sparsedepth.complete_depth` is: build the problem, solve it.

May import :mod:`sparsedepth.objective`, :mod:`sparsedepth.solvers`, :mod:`sparsedepth.result`,
:mod:`sparsedepth.profiling` and :mod:`sparsedepth._validation`.
"""

from __future__ import annotations

import math
import sys
import warnings

import numpy as np

from ._validation import as_depth_and_mask, check_nonnegative_real
from .objective.objective import (DEFAULT_L1_SMOOTHING, AbsTerm, Objective, QuadraticTerm, RobustTerm,
                                  build_objective, sample_fill)
from .objective.weights import Weights, check_weights, observed_fraction, resolve_weights
from .profiling import phase
from .result import ClampWarning, CompletionResult, RangeOutlierWarning
from .solvers import SOLVERS, check_solver_arguments, depth_unit, scaled_objective, solve_scaled
from .solvers.quadratic import DEFAULT_DEPTH_RTOL

__all__ = ["CompletionProblem", "choose_solver", "observed_range", "range_outliers", "depth_jump_factor",
           "CLAMP_WARNING_SHARE", "OUTLIER_FACTOR"]

#: The share of the pixels the range clamp must move for a :class:`~sparsedepth.ClampWarning`: fewer moved pixels
#: are the ordinary overshoot of the smoothness terms near steep depth changes, counted in ``result.clamped`` only.
CLAMP_WARNING_SHARE = 0.01
#: The least factor beyond the observations' 1st-99th percentile range at which a sample is an outlier
#: (:func:`range_outliers`).
OUTLIER_FACTOR = 2.0


def choose_solver(weights: Weights) -> str:
    """The solver ``solver="auto"`` picks: ``"amg"`` for γ = 0, ``"irls"`` for a robust edge penalty, else ``"admm"``.
    """
    if weights.gamma == 0:
        return "amg"
    return "irls" if weights.robust_edge else "admm"


class CompletionProblem:
    r"""One completion problem, set up once: inputs, weights, depth unit, objective, fill and clamp range.

    Parameters
    ----------
    image : ndarray, (H, W, 3) or (H, W)
        uint8 (÷255), uint16 (÷65535) or float in [0, 1].
    sparse_depth : ndarray, (H, W)
        Depth at the observed pixels (any unit).
    mask : ndarray of bool, (H, W), optional
        True where depth is observed; default finite and ``> 0``.
    weights : Weights, DensitySchedule or None
        As :func:`sparsedepth.complete_depth`'s: ``None`` is
        :data:`~sparsedepth.objective.weights.DEFAULT_SCHEDULE` at the
        observed fraction of the pixels, a schedule is evaluated there,
        :class:`Weights` are used as given.
    l1_smoothing : float
        ``ε`` of the smoothed L1 used by the gradient-based solvers (depth units).
    clip_to_observed : bool
        Clamp the answer to ``[min, max]`` of the observed depth (default),
        else to ``[0, inf)``.
    bounds : (float or ndarray, float or ndarray), optional
        The clamp range instead (depth units; per-pixel arrays of shape
        ``(H, W)`` allowed): the residual problem of a prior
        (:func:`sparsedepth.modes.prior.complete_with_prior`).

    Attributes
    ----------
    shape : tuple of int
    weights : Weights
        The weights solved with.
    scale : float
        The depth unit of the solve, :func:`~sparsedepth.solvers.depth_unit`
        of the observations (a power of two).
    objective : Objective
        The objective in that unit: ``F_s(z / s) = F(z) / s²``.
    fill : ndarray, (H, W)
        ``z_c`` in that unit: the nearest-sample fill the prior term pulls toward.
    depth_range : (float, float)
        ``[min, max]`` of the observations (``[0, inf)`` without the clamp), in depth units.
    observed : ndarray of bool, (H, W)

    Notes
    -----
    The objective is built in depth units and put in the unit ``s`` by
    :func:`~sparsedepth.solvers.scaled_objective`, the one place a depth unit
    is applied to an objective: depth targets, L1 and robust weights, robust
    scales and ``l1_smoothing`` are divided by ``s``, the quadratic weights
    are unchanged, so the objective is ``F / s²`` and every solver sees data
    of order 1 whatever the unit.  A
    power of two makes the division exact: completing ``2ᵏ · depth`` gives
    exactly ``2ᵏ`` times the result.  Results are in the user's units.
    """

    def __init__(self, image, sparse_depth, mask=None, *, weights=None, l1_smoothing=DEFAULT_L1_SMOOTHING,
                 clip_to_observed=True, bounds=None, _pair_factor=None, _reuse=None):
        if not isinstance(clip_to_observed, (bool, np.bool_)):
            raise TypeError(f"clip_to_observed must be True or False; got {type(clip_to_observed).__name__}")
        depth, observed = as_depth_and_mask(sparse_depth, mask)
        if not isinstance(weights, Weights):
            weights = resolve_weights(weights, observed_fraction(observed))
        check_weights(weights)
        self.image = image
        self.weights = weights
        self.l1_smoothing = l1_smoothing
        self.clip_to_observed = bool(clip_to_observed)
        self.observed = observed
        self.shape = depth.shape
        values = depth[observed]
        self.depth_range = observed_range(values, self.clip_to_observed)
        self.scale = depth_unit(values)
        self.bounds = self.depth_range if bounds is None else tuple(b if np.ndim(b) == 0 else np.ravel(b)
                                                                     for b in bounds)
        self._has_bounds = bounds is not None
        del values
        if _reuse is None:
            objective, fill, _ = build_objective(image, depth, observed, weights=weights, l1_smoothing=l1_smoothing,
                                                 pair_factor=_pair_factor)
        else:
            objective, fill = _with_new_data(_reuse, depth, observed, weights, l1_smoothing)
        del depth
        # the one place a depth unit is applied; in place: the data and prior targets are depth's and fill's memory
        with phase("image terms"):
            self.objective = scaled_objective(objective, self.scale, overwrite=True)
        del objective
        if _reuse is not None:  # the quadratic part differs from _reuse's by the data term's diagonal alone
            self.objective.share_matrix(_reuse.objective, weights.alpha * (observed.reshape(-1).astype(np.float64)
                                                                          - _reuse.observed.reshape(-1)))
        self.fill = fill  # the prior term's target, now in the solve's unit

    # -- variants of the problem ------------------------------------------------
    def with_samples(self, sparse_depth, mask=None) -> "CompletionProblem":
        """The problem with other observations: the same image, weights and options, a new data term and fill.

        Every term that depends on the image alone is shared with this problem (the same objects); the data term,
        the nearest-sample fill of the prior term and the depth unit are those of the new samples.  The weights
        are used as they are (not re-evaluated at the new observed fraction).  When this problem's normal equations
        are assembled (after a γ = 0 solve), the new problem's matrix is a copy of them with the data term's
        diagonal changed (:meth:`~sparsedepth.objective.objective.Objective.share_matrix`), not assembled again.
        """
        return CompletionProblem(self.image, sparse_depth, mask, weights=self.weights, l1_smoothing=self.l1_smoothing,
                                 clip_to_observed=self.clip_to_observed, _reuse=self)

    def relaxed(self, pair_factor) -> "CompletionProblem":
        """The problem whose image pair weights are multiplied by ``pair_factor`` (the second solve of depth_jump)."""
        problem = CompletionProblem(self.image, self.samples(), self.observed, weights=self.weights,
                                    l1_smoothing=self.l1_smoothing, clip_to_observed=self.clip_to_observed,
                                    bounds=self.bounds if self._has_bounds else None, _pair_factor=pair_factor)
        return problem

    def samples(self) -> np.ndarray:
        """The observed depth (depth units), 0 at the pixels not observed: the data term's target, scaled back."""
        return self.objective.term("data").target.reshape(self.shape) * self.scale  # exact: a power of two

    # -- solving -----------------------------------------------------------------
    def start(self, x0=None) -> np.ndarray:
        """The flat starting point in the solve's unit: the fill (no copy), or ``max(x0, 0) / scale``."""
        if x0 is None:
            start = self.fill.reshape(-1).view()  # no copy (8-MP memory); every solver copies its start
            start.flags.writeable = False  # ... and the prior term's target must stay intact
            return start
        return np.maximum(checked_start(x0, self.shape).ravel(), 0.0) / self.scale

    def run(self, *, solver="auto", tol=None, max_iter=None, callback=None, options=None, start=None,
            certify=True, objective_values=True, clip=True):
        """One solve: ``(SolverOutput, runtime)`` of :func:`~sparsedepth.solvers.core.solve_scaled` in depth units.

        ``start`` is in the solve's unit (:meth:`start`); ``clip=True`` certifies the point clipped to the clamp
        range (see :func:`~sparsedepth.solvers.core.solve_scaled`).  ``solver``, ``tol``, ``max_iter`` and
        ``options`` are checked as :func:`solver_settings` does.
        """
        name, tol, max_iter, options = solver_settings(self.weights, solver, tol, max_iter, options)
        return solve_scaled(self.objective, self.start() if start is None else start, scale=self.scale,
                            solver=name, tol=tol, max_iter=max_iter, callback=callback, options=options,
                            certify_result=certify, objective_values=objective_values,
                            bounds=_in_units(self.bounds, self.scale) if clip else None)

    def solve(self, *, solver="auto", tol=None, max_iter=None, callback=None, options=None, x0=None,
              certify=True, evaluate=True) -> CompletionResult:
        """Solve and clamp: the :class:`~sparsedepth.result.CompletionResult` of :func:`sparsedepth.complete_depth`.

        With ``weights.depth_jump > 0`` (and an image-weighted smoothness term) it solves twice: the second
        problem's pair weights are relaxed where the first solution jumps (:func:`depth_jump_factor`) and its solve
        starts from the first solution; iterations and runtime are those of both solves, the history that of the
        second.  ``certify=False`` computes no duality gap (NaN; ``converged`` is the solver's rule);
        ``evaluate=False`` no term values (``objective`` NaN, ``terms`` empty): for an intermediate completion
        whose depth alone is used (the uncertainty's halves).
        """
        name = solver_settings(self.weights, solver, tol, max_iter, options)[0]
        weights = self.weights
        jump = weights.depth_jump > 0 and (weights.beta_image > 0 or weights.beta_second_image > 0)
        settings = dict(solver=name, tol=tol, max_iter=max_iter, callback=callback, options=options)
        problem = self
        out, runtime = self.run(start=self.start(x0), certify=certify and not jump, clip=not jump, **settings)
        iterations = out.iterations
        if jump:
            first = np.clip(out.z, *self.bounds)
            problem = self.relaxed(depth_jump_factor(first.reshape(self.shape), weights.depth_jump))
            out, second = problem.run(start=np.maximum(out.z, 0.0) / problem.scale, certify=certify, **settings)
            runtime += second
            iterations += out.iterations
        with phase("clamp"):
            z, clamped = clamp(out.z, self.bounds, self.clip_to_observed or self._has_bounds)
        scale2 = problem.scale * problem.scale
        terms = {}
        if evaluate:
            with phase("term values"):
                terms = {key: value * scale2
                         for key, value in problem.objective.term_values(z / problem.scale).items()}
        return CompletionResult(
            depth=z.reshape(self.shape),
            objective=float(sum(terms.values())) if evaluate else float("nan"),
            terms=terms,
            iterations=iterations,
            converged=out.converged,
            message=out.message,
            clamped=clamped,
            history=out.history,
            solver=name,
            weights=weights,
            runtime=runtime,
            depth_range=self.depth_range,
            gap=out.gap,
            solver_gap=out.solver_gap,
            gap_proven=out.gap_proven,
        )

    def precision(self, options) -> float:
        """The RMS depth precision a solve with ``options`` stops at: the larger of ``depth_atol`` and
        ``depth_rtol`` × the depth scale (:data:`~sparsedepth.solvers.quadratic.DEFAULT_DEPTH_RTOL` without either).
        """
        options = options or {}
        rtol, atol = options.get("depth_rtol"), options.get("depth_atol")
        if rtol is None and atol is None:
            rtol = DEFAULT_DEPTH_RTOL
        return max(0.0 if rtol is None else rtol * self.scale, 0.0 if atol is None else atol)


def solver_settings(weights, solver, tol, max_iter, options):
    """``(name, tol, max_iter, options)``: the solver ``"auto"`` resolves to and its checked stopping parameters.

    Without ``tol`` and a depth tolerance, ``options["depth_rtol"]`` of ``"amg"`` is set to
    :data:`~sparsedepth.solvers.quadratic.DEFAULT_DEPTH_RTOL`.
    """
    name = choose_solver(weights) if solver == "auto" else solver
    if not isinstance(name, str) or name not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {['auto', *sorted(SOLVERS)]}")
    explicit_tol = tol is not None
    tol, max_iter, options = check_solver_arguments(name, tol, max_iter, options)
    if name == "amg" and not explicit_tol and options["depth_rtol"] is None and options["depth_atol"] is None:
        options["depth_rtol"] = DEFAULT_DEPTH_RTOL
    return name, tol, max_iter, options


def _with_new_data(problem, depth, observed, weights, l1_smoothing):
    """``(objective, fill)`` in depth units: ``problem``'s objective with the data and prior terms of new samples.

    The quadratic terms that depend on the image alone are ``problem``'s own objects (they hold no depth); the
    edge term keeps its operator and row weights with the weight (and robust scale) of ``weights``, in depth
    units.  The fill is the one :func:`build_objective` computes for these samples.
    """
    fill = sample_fill(problem.image, depth, observed, weights)
    terms = []
    for t in problem.objective.terms:
        if t.name == "data":
            t = QuadraticTerm("data", weights.alpha, None, observed.reshape(-1), depth.ravel())
        elif t.name == "prior":
            t = QuadraticTerm("prior", weights.delta, None, None, fill.ravel())
        elif isinstance(t, AbsTerm):
            t = AbsTerm(t.name, weights.gamma, t.operator, t.row_weights)
        elif isinstance(t, RobustTerm):
            t = RobustTerm(t.name, weights.gamma, t.operator, t.row_weights, t.penalty, weights.edge_scale)
        terms.append(t)
    return Objective(problem.objective.shape, terms, l1_smoothing=l1_smoothing), fill


def _in_units(box, scale):
    """``box`` (depth units, floats or flat per-pixel arrays) divided by ``scale``."""
    return tuple(b / scale for b in box)


def checked_start(x0, shape):
    """``x0`` as float64; ``ValueError`` unless it has ``shape`` and finite values."""
    start = np.asarray(x0, dtype=np.float64)
    if start.shape != tuple(shape):
        raise ValueError(f"x0 has shape {start.shape}, expected {tuple(shape)}")
    if not np.all(np.isfinite(start)):
        raise ValueError("x0 contains NaN or infinite values")
    return start


def observed_range(observed_values, clip_to_observed):
    """The clamp range in depth units: ``[min, max]`` of the observations, or ``[0, inf)`` without the clamp.

    With the clamp, observations that widen it as outliers would are warned about (:func:`range_outliers`).
    """
    if not clip_to_observed:
        return 0.0, np.inf
    low, high = float(observed_values.min()), float(observed_values.max())
    outliers = range_outliers(observed_values)
    if outliers:
        warnings.warn(
            f"complete_depth: {outliers} observed depth value(s) lie far outside the other observations "
            f"(the range [{low:g}, {high:g}] the depth is clamped to includes them); an outlier pulls its "
            "neighbourhood toward it: remove it from mask if it is not a real measurement", RangeOutlierWarning,
            stacklevel=user_stacklevel())
    return low, high


def range_outliers(values) -> int:
    """The number of observed depths that widen the range as outliers.

    A value is an outlier when it lies beyond the 1st-99th percentile range
    ``[q1, q99]`` of ``values`` by more, in log-depth, than the log-width of
    that range and than a factor of :data:`OUTLIER_FACTOR`:
    ``log(v / q99) > max(log(q99 / q1), log 2)`` above, the same below.
    A 65.5 m reading among 1-4 m ones is one; 100 m among 5-85 m LiDAR
    returns is not.
    """
    values = np.asarray(values, dtype=np.float64)
    values = values[values > 0]
    if values.size < 2:
        return 0
    q1, q99 = np.percentile(values, [1.0, 99.0])
    margin = max(math.log(q99 / q1), math.log(OUTLIER_FACTOR))
    return int(np.count_nonzero((values > q99 * math.exp(margin)) | (values < q1 * math.exp(-margin))))


def user_stacklevel() -> int:
    """The ``stacklevel`` of a warning that points at the first frame outside the package (the user's call)."""
    frame, level = sys._getframe(1), 1
    package = __name__.rsplit(".", 1)[0]
    while frame is not None and frame.f_globals.get("__name__", "").startswith(package):
        frame, level = frame.f_back, level + 1
    return level


def clamp(z, depth_range, clip_to_observed, rounding=1e-9):
    """``(clip(z, *depth_range), clamped)``, warning with a :class:`ClampWarning` when many pixels moved.

    ``depth_range`` holds floats or per-pixel arrays.  With
    ``clip_to_observed``, moves of rounding size (up to ``rounding`` times
    the upper end: a flat input whose solution is the observed value to
    1e-15; 1e-6 for the float32 sweeps of the fast mode) are not counted;
    without it the range is ``[0, inf)`` and the pixels at 0 are counted.
    The warning (:func:`warn_clamped`) needs :data:`CLAMP_WARNING_SHARE`
    of the pixels.
    """
    low, high = depth_range
    if clip_to_observed:
        slack = rounding * np.max(np.abs(high))
        clamped = int(np.count_nonzero((z < low - slack) | (z > high + slack)))
    else:
        clamped = int(np.count_nonzero(z <= 0))
    z = np.clip(z, low, high)
    warn_clamped(clamped, z.size, depth_range, clip_to_observed)
    return z, clamped


def warn_clamped(clamped, size, depth_range, clip_to_observed):
    """A :class:`ClampWarning` when ``clamped`` is at least :data:`CLAMP_WARNING_SHARE` of ``size`` pixels."""
    if clamped < CLAMP_WARNING_SHARE * size:
        return
    low, high = (float(np.min(b)) if np.ndim(b) else float(b) for b in depth_range)
    warnings.warn(
        f"complete_depth: {clamped} of {size} pixels ({clamped / size:.1%}) were outside the depth range "
        f"[{low:g}, {high:g}] and were clamped to it (result.clamped, result.depth_range)"
        + ("" if clip_to_observed else "; clip_to_observed=False: they are held at the bound 0"),
        ClampWarning, stacklevel=user_stacklevel())


def depth_jump_factor(depth, tau: float) -> np.ndarray:
    """Per-pair factors ``1 / (1 + (Δz / (τ z̄))²)`` in the row order of :func:`~sparsedepth.grid.pair_edge_weights`.

    Parameters
    ----------
    depth : ndarray, (H, W)
        A completed depth map (> 0 where used; the pair mean is floored at
        the smallest positive value of ``depth`` times 1e-6).
    tau : float
        ``τ > 0``, the relative depth change at which the factor is 1/2.

    Returns
    -------
    ndarray, (2*H*W,)
        Horizontal pairs ``(i, j)–(i, j+1)`` first, then vertical pairs
        ``(i, j)–(i+1, j)``; the rows of the last column / row (no pair) are 1.

    Notes
    -----
    ``Δz / z̄`` is the pair's depth difference relative to its mean depth, so
    the factor does not depend on the depth unit; it is the Cauchy
    (Lorentzian) IRLS weight of the relative difference with scale ``τ``.
    """
    z = np.asarray(depth, dtype=np.float64)
    tau = check_nonnegative_real(tau, name="depth_jump")
    if tau == 0:
        return np.ones(2 * z.size)
    positive = z[z > 0]
    floor = 1e-6 * float(positive.min()) if positive.size else 1e-300
    fx = np.ones_like(z)
    fy = np.ones_like(z)
    mean_x = np.maximum(0.5 * (z[:, 1:] + z[:, :-1]), floor)
    mean_y = np.maximum(0.5 * (z[1:, :] + z[:-1, :]), floor)
    fx[:, :-1] = 1.0 / (1.0 + ((z[:, 1:] - z[:, :-1]) / (tau * mean_x)) ** 2)
    fy[:-1, :] = 1.0 / (1.0 + ((z[1:, :] - z[:-1, :]) / (tau * mean_y)) ** 2)
    return np.concatenate([fx.ravel(), fy.ravel()])
