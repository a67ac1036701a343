"""What every solver shares: its output type, the iteration recorder, the stopping floors.

Every solver takes an :class:`~sparsedepth.objective.Objective`, a starting
point, stopping parameters, a :class:`Recorder` and its options, and returns
a :class:`SolverOutput`.  The stopping tests of all solvers use the same
absolute floor (:func:`objective_floor`) and the same gap threshold
(:func:`gap_threshold`).

May import :mod:`sparsedepth.result`; nothing else of the package.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..result import IterationRecord, SolverState

__all__ = ["SolverOutput", "CallbackStop", "Recorder", "relative", "objective_floor", "gap_threshold", "quick_value",
           "require_quadratic", "refuse_robust", "output"]


@dataclass(frozen=True)
class SolverOutput:
    """What a solver returns.

    Parameters
    ----------
    z : ndarray, shape (N,)
        The final iterate (flattened depth).
    iterations : int
        Iterations of the solver's outer loop.
    converged : bool
        The solver's stopping rule and the duality-gap test both passed.
    message : str
        Why the solver stopped.
    history : tuple of IterationRecord
        One record per recorded iteration, the start first.
    gap : float
        The duality gap of ``z`` (NaN when not computed); after
        :func:`~sparsedepth.solvers.core.solve_scaled` with ``bounds``, the
        gap of ``z`` clipped to the bounds, over the box.
    solver_gap : float
        The gap of the solver's own point for the solver's own problem (the
        same as ``gap`` when the bounds moved nothing).
    gap_proven : bool
        False when the gap is an estimate: the quadratic part has no positive
        curvature bound (``delta = 0`` and not every pixel observed).
    """

    z: np.ndarray
    iterations: int
    converged: bool
    message: str
    history: tuple
    gap: float = float("nan")
    solver_gap: float = float("nan")
    gap_proven: bool = True


class CallbackStop(Exception):
    """Raised inside a solver when the callback asked to stop; carries the iterate."""

    def __init__(self, iteration, z):
        super().__init__(iteration)
        self.iteration = iteration
        self.z = z


class Recorder:
    """Keeps the history and calls the user callback after every iteration.

    The solver works in normalised units (depth divided by ``scale``, the
    objective by ``scale²``); the history and the callback's states are in
    the user's units (``F · scale²``, ``z · scale``).  A call returns ``F``
    in the solver's units.

    Parameters
    ----------
    objective : Objective
        In the solver's units; evaluated when a call gives no ``value``.
    callback : callable or None
        ``callback(SolverState)``; raising ``StopIteration`` stops the solver
        (the recorder raises :class:`CallbackStop`).
    scale : float
        The depth unit of the solver's units.
    values : bool, default True
        Record ``F`` at every iteration.  False records NaN where a call gives
        no ``value`` (no evaluation of the terms), and solvers that compute
        ``F`` only for the history skip it (:attr:`values`): for a solve
        whose objective values nobody reads.
    """

    def __init__(self, objective, callback, scale=1.0, *, values=True):
        self.objective = objective
        self.callback = callback
        self.scale = float(scale)
        self.values = bool(values)
        self.start = time.perf_counter()
        self.history = []

    def elapsed(self):
        """Seconds since the recorder was made."""
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
        if value is not None:
            F = float(value)
        else:
            F = self.objective.value(z) if self.values else float("nan")
        F_user = self.user_value(F)
        self.history.append(IterationRecord(iteration, F_user, t, fevals, gevals, inner))
        if self.callback is not None:
            depth = np.array(z, dtype=float).reshape(self.objective.shape)
            depth *= self.scale
            try:
                self.callback(SolverState(iteration, F_user, t, depth))
            except StopIteration:
                raise CallbackStop(iteration, np.array(z, dtype=float)) from None
        return F


def relative(change, reference):
    """``change / |reference|`` for a message (no division by zero: ``0/0 = 0``, ``x/0 = inf``)."""
    reference = abs(float(reference))
    if reference > 0:
        return float(change) / reference
    return 0.0 if change == 0 else float(np.copysign(np.inf, change))


def objective_floor(objective):
    """An absolute floor for changes of ``F``: rounding level of ``F`` near its scale ``F(0) = c``.

    In normalised units (depth ~1) ``c = zᵀAz − 2bᵀz + c`` at ``z = 0`` is the
    size of the quadratic terms; a change of ``F`` below ``1e-13 · c`` (about
    500 rounding units) is not a change the iteration can resolve.  ``c = 0``
    (all targets zero, e.g. an all-zero depth map) gives the floor
    ``1e-13 · N`` (``F* = 0`` there and every change is noise at depth ~1).
    """
    c = objective.constant()
    return 1e-13 * (abs(c) if c > 0 else float(objective.size))


def quick_value(objective, z):
    """``F(z)``: :meth:`~Objective.system_value` (one product) when it is available, else the terms' sum.

    For the quadratic solvers' records and the scale of a tolerance, not for the reported terms.
    """
    F = objective.system_value(z)
    return objective.value(z) if F is None else F


def gap_threshold(objective, F, gap_tol):
    """``gap_tol · max(F, floor)``, ``floor = 1e-7 F(0)`` (``1e-7 N`` when ``F(0) = 0``), in solver units."""
    c = objective.constant()
    return float(gap_tol) * max(float(F), 1e-7 * (abs(c) if c > 0 else float(objective.size)))


def refuse_robust(objective, name):
    """Raise ``ValueError`` when solver ``name`` (convex problems only) gets an objective with robust terms."""
    robust = [t.name for t in objective.robust_terms]
    if robust:
        raise ValueError(
            f"solver {name!r} cannot minimise the robust term(s) {robust} (penalty "
            f"{objective.robust_terms[0].penalty.name!r}, not the convex L1 or quadratic it handles); use "
            "solver='irls' (or 'lbfgsb', 'adam'), or edge_penalty='l1'"
        )


def require_quadratic(objective, name):
    """Raise ``ValueError`` when solver ``name`` (quadratic problem only) gets an objective with L1 or robust terms."""
    refuse_robust(objective, name)
    if objective.has_l1:
        raise ValueError(
            f"solver {name!r} solves the quadratic problem only (gamma = 0); use solver='irls', 'lbfgsb' or 'adam' for gamma > 0"
        )


def output(z, iterations, converged, message, recorder, gap=float("nan")):
    """A :class:`SolverOutput` with the recorder's history."""
    return SolverOutput(np.asarray(z, dtype=float), int(iterations), bool(converged), message, tuple(recorder.history),
                        float(gap))
