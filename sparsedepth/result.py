"""The one result type every solver returns, with a per-iteration history.

May import NumPy and :mod:`sparsedepth.objective.weights`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .objective.weights import Weights

__all__ = ["IterationRecord", "SolverState", "UncertaintyCalibration", "CompletionResult", "ClampWarning",
           "RangeOutlierWarning", "NoGainWarning"]


class ClampWarning(UserWarning):
    """Warned by :func:`sparsedepth.complete_depth` when pixels were moved into the depth range.

    ``CompletionResult.clamped`` holds the count and ``CompletionResult.depth_range``
    the range; filter it with ``warnings.filterwarnings("ignore", category=sparsedepth.ClampWarning)``.
    """


class RangeOutlierWarning(ClampWarning):
    """A :class:`ClampWarning` about observed depths so far outside the others that they widen the clamp range.

    See :func:`sparsedepth.completion.range_outliers` for the rule.
    """


class NoGainWarning(UserWarning):
    """Warned by :func:`sparsedepth.complete_depth` with ``expected_error=True`` when the completion is not
    expected to beat nearest fill: ``result.expected_rmse >= result.expected_nearest_rmse``.

    Both are estimates from the samples alone (:func:`sparsedepth.expected_error.expected_error`); filter it with
    ``warnings.filterwarnings("ignore", category=sparsedepth.NoGainWarning)``.
    """


@dataclass(frozen=True)
class IterationRecord:
    """One entry of a solver's history.

    Attributes
    ----------
    iteration : int
        0 is the starting point; then one entry per solver iteration (an outer
        iteration for IRLS/ADMM, a CG step for ``cg``/``amg``, an L-BFGS-B or
        Adam step).
    objective : float
        Exact objective ``F`` at the iterate.
    time : float
        Wall time in seconds since the solver started (set-up included).
    function_evals, gradient_evals : int or None
        Cumulative evaluations of the (smoothed) objective and its gradient,
        where the solver uses them.
    inner_iterations : int or None
        Cumulative inner CG iterations, where the solver has them.
    """

    iteration: int
    objective: float
    time: float
    function_evals: Optional[int] = None
    gradient_evals: Optional[int] = None
    inner_iterations: Optional[int] = None


@dataclass(frozen=True)
class SolverState:
    """What a ``callback`` receives after every iteration.

    ``depth`` is a copy; a callback may raise ``StopIteration`` to stop the
    solver, and the result's message then says so.
    """

    iteration: int
    objective: float
    time: float
    depth: np.ndarray


@dataclass(frozen=True)
class UncertaintyCalibration:
    """How :attr:`CompletionResult.uncertainty` was calibrated.

    Attributes
    ----------
    slope, offset : float
        ``sigma = slope * cue + offset`` (``offset`` in the depth's units).
    held_out : int
        Observations the calibration was fitted on (every observed pixel,
        each predicted by the completion from the other half).
    coverage_1sigma, coverage_2sigma : float
        Fraction of those held-out observations with ``|error| <= sigma``
        and ``<= 2 sigma``.
    """

    slope: float
    offset: float
    held_out: int
    coverage_1sigma: float
    coverage_2sigma: float


@dataclass(frozen=True)
class CompletionResult:
    """Result of :func:`sparsedepth.complete_depth`.

    Attributes
    ----------
    depth : ndarray, (H, W)
        Completed depth, inside :attr:`depth_range` everywhere except the
        :attr:`removed` pixels, which are NaN.
    objective : float
        Exact objective ``F(depth)``.
    terms : dict of str to float
        Exact value of each named term at ``depth`` (they sum to ``objective``).
    iterations : int
    converged : bool
        True when the solver's stopping rule was met (named in
        :attr:`message`) and :attr:`gap` is at most ``gap_tol · max(F,
        floor)`` (solver option ``gap_tol``, default 1e-2 for every solver;
        ``floor = 1e-7 F(0)``, the objective of the all-zero depth).  It is
        about :attr:`depth` as returned, after the range clamp.  Where the
        gap cannot be computed (NaN; robust edge penalties, a singular
        quadratic part, the fast mode) it is the solver's rule alone, and
        :attr:`message` says so.
    message : str
    clamped : int
        Number of pixels the range clamp moved: the solver's value was outside
        :attr:`depth_range` by more than ``1e-9`` times its upper end and was
        replaced by the nearer end (values outside by less, rounding, are
        clamped too but not counted).  With
        ``clip_to_observed=False`` the range is ``[0, inf)`` and the count is
        the pixels at the lower bound 0 (held there by the constraint
        ``z >= 0`` or projected onto it).
    history : tuple of IterationRecord
    solver : str
    weights : Weights
    runtime : float
        Seconds from the start of the solver (set-up included) to the end.
    depth_range : tuple of float
        ``(low, high)`` the depth was clamped to: the smallest and largest
        observed depth with ``clip_to_observed=True``, else ``(0, inf)``.
    gap : float
        Duality gap of the returned :attr:`depth`: an upper bound on
        ``F(depth) − F*`` in the units of :attr:`objective`, with ``F*`` the
        smallest ``F`` of any depth inside :attr:`depth_range` (with
        ``clip_to_observed=False``: of any depth ``>= 0``).  Weak duality
        (:func:`sparsedepth.solvers.certificate.duality_gap`); proven when
        :attr:`gap_proven`.  NaN when it cannot be computed (the quadratic
        part's matrix is singular: ``delta = 0`` with no quadratic
        smoothness; robust edge penalties; the fast mode).
    solver_gap : float
        The same bound for the solver's own point before the range clamp, over
        the solver's own problem (``z >= 0``; any ``z`` for the γ = 0 solvers
        ``direct``, ``cg``, ``amg``).  Equal to :attr:`gap` when the clamp
        moved no pixel.  When it moved some, the two tell apart what the
        solver left and what the clamp added; for the γ = 0 solvers it is then
        the one-product bound ``¼ ‖r‖² / λ_min`` (proven, often loose) unless
        :attr:`gap` fails ``gap_tol``, when it is computed in full.
    gap_proven : bool
        True when :attr:`gap` is a proven bound: the quadratic part has a
        positive lower bound on its curvature (``delta > 0``, or every pixel
        observed).  False (``delta = 0``): the error term of the inexact
        linear solve is left out and the gap is an estimate, accurate to that
        solve's tolerance; :attr:`message` says so too.
    uncertainty : ndarray, (H, W), or None
        With ``uncertainty=True``: a standard-deviation-like estimate of each
        pixel's error, in the units of :attr:`depth`
        (:func:`sparsedepth.uncertainty.estimate_uncertainty`).
    uncertainty_calibration : UncertaintyCalibration or None
        How :attr:`uncertainty` was calibrated on held-out observations.
    removed : int
        Pixels set to NaN in :attr:`depth` because their uncertainty exceeds
        ``max_uncertainty``, or because ``blowups="remove"`` judged them blown
        up (0 without either).
    expected_rmse, expected_nearest_rmse : float
        With ``expected_error=True``: the RMSE over the unobserved pixels
        expected of :attr:`depth` and of nearest fill, estimated from the
        samples alone (:func:`sparsedepth.expected_error.expected_error`),
        in the units of :attr:`depth`; NaN without it.
    blowups : ndarray of bool, (H, W), or None
        With ``blowups="flag"`` or ``"remove"``: the completed pixels that
        :func:`sparsedepth.blowups.flag_blowups` judges blown up (no nearby
        sample supports their depth); with ``"remove"`` they are NaN in
        :attr:`depth` and counted in :attr:`removed`.  None without it.
    """

    depth: np.ndarray
    objective: float
    terms: dict
    iterations: int
    converged: bool
    message: str
    clamped: int
    history: tuple = field(repr=False)
    solver: str = ""
    weights: Optional[Weights] = None
    runtime: float = 0.0
    depth_range: tuple = (0.0, float("inf"))
    gap: float = float("nan")
    solver_gap: float = float("nan")
    gap_proven: bool = True
    uncertainty: Optional[np.ndarray] = field(default=None, repr=False)
    uncertainty_calibration: Optional[UncertaintyCalibration] = None
    removed: int = 0
    expected_rmse: float = float("nan")
    expected_nearest_rmse: float = float("nan")
    blowups: Optional[np.ndarray] = field(default=None, repr=False)

    def history_array(self, name: str) -> np.ndarray:
        """One field of :attr:`history` as an array (``None`` becomes NaN)."""
        if name not in IterationRecord.__dataclass_fields__:
            raise ValueError(f"unknown history field {name!r}; one of {list(IterationRecord.__dataclass_fields__)}")
        return np.array([np.nan if getattr(r, name) is None else getattr(r, name) for r in self.history], dtype=float)
