"""The public entry point: :func:`complete_depth`, which checks which arguments go together and calls a mode.

The work is done by :class:`~sparsedepth.problem.CompletionProblem` (set up once, solved), the modes of
:mod:`sparsedepth.modes` (fast, prior, uncertainty) and :mod:`sparsedepth.selection` (best); this module decides
which of them a call asks for (:func:`check_modes`).

May import :mod:`sparsedepth.problem`, :mod:`sparsedepth.modes`, :mod:`sparsedepth.selection` and what they
import.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

from ._validation import check_nonnegative_real
from .modes.fast import FAST_COARSE_RTOL, FAST_WEIGHTS, complete_fast, fast_factor
from .modes.prior import complete_with_prior
from .modes.uncertainty import complete_with_uncertainty
from .objective.objective import DEFAULT_L1_SMOOTHING
from .objective.weights import DensitySchedule, Weights
from .problem import CLAMP_WARNING_SHARE, CompletionProblem, choose_solver, depth_jump_factor, range_outliers
from .expected_error import expected_error as estimate_expected_error
from .result import CompletionResult, NoGainWarning
from .uncertainty import check_relative_limit
from .blowups import flag_blowups, remove_blowups
from .selection import complete_best

__all__ = ["complete_depth", "check_modes", "argument_conflict", "ARGUMENT_RULES", "choose_solver", "depth_jump_factor",
           "range_outliers", "QUALITIES", "fast_factor", "FAST_WEIGHTS", "FAST_COARSE_RTOL", "CLAMP_WARNING_SHARE",
           "with_expected_error", "warn_if_no_gain"]

#: The values of ``complete_depth``'s ``quality``.
QUALITIES = ("default", "fast", "best")


# the numpydoc docstring (the objective, scaling and clamp in Notes) is long; the code is short
def complete_depth(
    image,
    sparse_depth,
    mask=None,
    *,
    weights: Weights | DensitySchedule | None = None,
    solver: str = "auto",
    tol: float | None = None,
    max_iter: int | None = None,
    callback=None,
    x0=None,
    l1_smoothing: float = DEFAULT_L1_SMOOTHING,
    options: dict | None = None,
    clip_to_observed: bool = True,
    uncertainty: bool = False,
    max_uncertainty: float | None = None,
    max_relative_uncertainty: float | None = None,
    prior=None,
    prior_alignment: str = "scale_shift",
    quality: str = "default",
    expected_error: bool = False,
    blowups: str | None = None,
) -> CompletionResult:
    """Complete a sparse depth map into a dense one, guided by an image.

    Minimises over ``z >= 0``::

        F(z) = α Σ M (z − z_obs)² + β Σ (∂x z)² + (∂y z)²
             + γ Σ w (|∂x z| + |∂y z|) + δ Σ (z − z_c)²   (+ optional terms)

    with ``w = exp(−κ ‖∇I‖)`` (of the image blurred by ``weights.edge_sigma``)
    and ``z_c`` the image-aware (geodesic) nearest-sample fill of the
    observations, or with ``weights.fill_contrast = 0`` the Euclidean one
    (see :class:`~sparsedepth.objective.weights.Weights`).

    Parameters
    ----------
    image : ndarray, (H, W, 3) or (H, W)
        uint8 (÷255), uint16 (÷65535) or float in [0, 1].
    sparse_depth : ndarray, (H, W)
        Depth in metres at the observed pixels.
    mask : ndarray of bool, (H, W), optional
        True where depth is observed.  Default: finite and ``> 0`` (0 and NaN
        mean "no measurement"; a negative value is then an error).
    weights : Weights, DensitySchedule or None
        Term weights.  ``None`` (default): the weights of
        :data:`~sparsedepth.objective.weights.DEFAULT_SCHEDULE` for the
        observed fraction of the pixels (``mask.mean()``;
        :func:`~sparsedepth.default_weights`); with ``quality="fast"``,
        :data:`FAST_WEIGHTS`.  A :class:`DensitySchedule` is evaluated at the
        observed fraction; :class:`Weights` are used as given.  The weights
        solved with are ``result.weights``.
    solver : {"auto", "direct", "cg", "amg", "irls", "admm", "lbfgsb", "adam"}
        ``"auto"`` is ``"amg"`` for γ = 0, ``"irls"`` for γ > 0 with a robust
        ``weights.edge_penalty`` and ``"admm"`` otherwise.  The stopping
        rule of each is in :mod:`sparsedepth.solvers`.
    tol : float, optional
        Solver tolerance (meaning per solver; default per solver).  Without
        it (and without a depth tolerance in ``options``) the default
        ``"amg"`` solve stops when its estimated RMS remaining change of the
        depth is at most ``options["depth_rtol"] = 3e-4`` of the depth scale
        (see :class:`~sparsedepth.solvers.options.AmgOptions`); with it
        alone, at the relative residual ``tol``; a depth tolerance given in
        ``options`` stops the solve too, whichever rule is met first.
    max_iter : int, optional
        Maximum number of (outer) iterations.
    callback : callable, optional
        ``callback(state)`` with a :class:`~sparsedepth.result.SolverState`
        after every iteration; raise ``StopIteration`` to stop.
    x0 : ndarray, (H, W), optional
        Starting point; default ``z_c``.
    l1_smoothing : float
        ``ε`` of the smoothed L1 used by the gradient-based solvers.
    options : dict, optional
        Solver-specific options: the keys of
        :data:`sparsedepth.SOLVER_OPTIONS` for the solver (see each solver's
        docstring); any other key is an error.
    clip_to_observed : bool
        Clamp the completed depth to ``[min, max]`` of the observed depth
        (default); ``False`` keeps the solver's values (``>= 0``).
    uncertainty : bool
        Also estimate each pixel's error (``result.uncertainty``, in the
        units of ``sparse_depth``); costs two more solves, each from half of
        the samples.  Needs at least 16 observed pixels.
    max_uncertainty : float, optional
        Leave the pixels whose uncertainty exceeds this (units of
        ``sparse_depth``) missing: NaN in ``result.depth``, counted in
        ``result.removed``.  Implies ``uncertainty=True``.
    max_relative_uncertainty : float, optional
        The same for the pixels whose uncertainty exceeds this fraction of
        their depth (0.1: 10 %); with ``max_uncertainty`` too, a pixel goes
        when it breaks either limit
        (:func:`sparsedepth.uncertainty.too_uncertain`).  Implies
        ``uncertainty=True``.
    prior : ndarray, (H, W), optional
        A dense, finite depth map the caller brings (e.g. a monocular
        network's prediction; metric or relative).  It is aligned to the
        samples (``prior_alignment``), the residual ``z_obs − prior`` is
        completed by the objective, and the aligned prior is added back
        (Notes).  Not combined with ``uncertainty``.
    prior_alignment : {"scale_shift", "scale", "none"}
        Least-squares fit of ``s · prior + t`` to the samples
        (:func:`sparsedepth.priors.align_prior`): both (relative depth, the
        default), ``s`` only, or neither (a metric prior used as it is).
    quality : {"default", "fast", "best"}
        ``"best"``: per input, the completion chosen among a few fixed
        candidates (the defaults, the image trusted a quarter as much, the
        image ignored, half the defaults and half nearest fill, nearest
        fill) by cross-validation on the samples
        (:func:`sparsedepth.selection.complete_best`); the defaults unless
        another candidate is expected clearly more accurate.  The choice and
        every candidate's score are ``result.selection``.  It takes
        ``weights`` (the candidates transform them), ``clip_to_observed``,
        ``x0``, ``l1_smoothing`` and ``expected_error`` (from the same
        folds); the solver settings, ``prior`` and the uncertainty are not
        available (an error).  Needs at least 16 observed pixels.  Its
        accuracy and time: ``python -m bench.best_quality``.
        ``"fast"``: the real-time mode (see Notes): a solve on a grid 2, 3
        or 4 times coarser per side, interpolated back and refined by a few
        edge-aware sweeps.  Without ``weights`` it solves with
        :data:`FAST_WEIGHTS` (the defaults made for the coarse grid); given
        ``weights`` are used as given.  It takes ``weights``, ``clip_to_observed``,
        ``x0`` (its block means start the coarse solve: pass the previous
        frame's depth to reuse it along a video) and the inputs; ``solver``
        must be ``"auto"`` and ``tol``, ``max_iter``, ``callback``,
        ``options``, ``prior`` and the uncertainty are not available (an
        error).  Its
        result has no full-resolution objective: ``objective`` and ``gap``
        are NaN and ``terms`` is empty; the iterations and history are
        those of the coarse solve, whose objective values are not computed
        (NaN: the coarse objective is not the user's).
    expected_error : bool
        Also estimate, from the samples alone, the RMSE over the unobserved
        pixels of the result and of nearest fill
        (:func:`sparsedepth.expected_error.expected_error`: cross-validation
        on the samples with fast completions, 0.14-0.28 of a default
        completion's time); stored in ``result.expected_rmse`` and
        ``result.expected_nearest_rmse``, with a
        :class:`~sparsedepth.result.NoGainWarning` when the first is not
        below the second.  Works with the default, fast and uncertainty
        modes (with ``max_uncertainty`` it is about every unobserved pixel,
        the removed ones included); not with ``prior``, whose completion
        the fast completions do not model (an error).
    blowups : {None, "flag", "remove"}
        Check the completed depth for local blow-ups
        (:func:`sparsedepth.blowups.flag_blowups`: pixels that no nearby
        sample supports, typically a value in the middle of a depth jump):
        ``"flag"`` marks them in ``result.blowups``; ``"remove"`` also sets
        them to NaN in ``result.depth`` and counts them in
        ``result.removed``.  Works in every mode; what it catches and what
        it flags wrongly: ``python -m bench.blowups``.

    Returns
    -------
    CompletionResult
        ``clamped`` pixels were moved into ``depth_range`` by the clamp.
        With ``quality="best"`` a
        :class:`~sparsedepth.selection.BestCompletionResult` (its
        ``selection`` holds the choice and the scores).

    Raises
    ------
    ValueError
        Inconsistent shapes, no observed pixel, NaN/inf in the image, negative
        depth (observed, or anywhere without a mask), wrong number of
        dimensions, a negative weight, an unknown solver or option key, or a
        quadratic-only solver with γ > 0.
        Fewer than 16 observed pixels with ``uncertainty`` or
        ``quality="best"``; a negative or
        non-finite ``max_uncertainty``; a ``max_relative_uncertainty`` that is
        not a finite number > 0; an unknown ``quality``, or
        ``"fast"`` with γ > 0, ``x0``, ``callback`` or uncertainty;
        ``"best"`` with a solver setting, ``prior`` or uncertainty;
        ``expected_error`` with ``prior`` or fewer than 16 observed pixels;
        a ``blowups`` other than None, ``"flag"`` and ``"remove"``.
    TypeError
        ``weights`` not a :class:`Weights`, :class:`DensitySchedule` or
        ``None``, ``max_iter`` not an int, ``tol``
        not a number, ``options`` not a dict, an option of the wrong type, or
        ``uncertainty`` not a bool, ``blowups`` not a string or None.

    Warns
    -----
    ClampWarning
        When the clamp moved at least :data:`CLAMP_WARNING_SHARE` (1 %) of
        the pixels (the count is ``result.clamped``), or when observed depths
        lie so far outside the others that they widen the clamp range
        (:func:`range_outliers`).

    Notes
    -----
    The solve runs in normalised units: depth, ``x0``, ``γ``, ``edge_scale``
    and ``l1_smoothing`` are divided by ``s``, the power of two nearest the
    median observed depth (:func:`sparsedepth.solvers.depth_unit`); the
    quadratic weights are unchanged, so the objective is ``F / s²``.  The
    result (depth, objective, terms, history, callback states) is in the
    units of ``sparse_depth``, and the answer does not depend on the unit
    (micrometres to kilometres).

    The quadratic terms (the second-order smoothness of the default weights
    in particular) can overshoot: a completed value may leave the range of
    the observations, down to 0 (the bound ``z >= 0``) near a steep change.
    With ``clip_to_observed=True`` every value is clamped to ``[min, max]``
    of the observed depth, which never produces 0 m pixels from positive
    observations; the number of moved pixels is ``result.clamped``, and a
    :class:`~sparsedepth.ClampWarning` is issued when it reaches
    :data:`CLAMP_WARNING_SHARE` of the pixels (a few dozen pixels of
    overshoot near steep changes are ordinary and not warned about).

    The result is certified after the clamp: ``result.gap`` bounds ``F(depth)
    − F*`` with ``F*`` the smallest ``F`` of a depth inside
    ``result.depth_range``, ``result.solver_gap`` is the solver's own bound
    before the clamp, and ``converged`` needs the solver's stopping rule and
    ``gap <= gap_tol · max(F, 1e-7 F(0))`` (``gap_tol`` 1e-2 by default,
    for every solver; see :class:`~sparsedepth.result.CompletionResult`).

    An outlier sample (say 65.5 m in a 1-4 m room) is kept as an
    observation: the data term pulls its neighbourhood toward it, so a
    blob of too-large depth surrounds it and the smoothness terms ring
    around it, undershooting below the other observations.  The clamp
    cannot remove the blob (the outlier widens the range to 65.5 m) but it
    holds the undershoot at the smallest observation.  Such a sample is
    warned about (:func:`range_outliers`).  Remove outliers (or leave them
    out of ``mask``) before completing.

    With ``prior``, let ``P = s · prior + t`` be the aligned prior.  The
    objective completes the residual ``r = z − P`` from ``r_obs = z_obs −
    P`` (shifted by a constant ``c`` so that every residual sample is
    positive, for the bound ``>= 0``), so between the samples the result
    follows the prior's shape and the smoothness terms act on its error:
    ``z = P + r``.  The range clamp then applies to ``z``.  ``objective``,
    ``terms`` and ``history`` are those of the residual problem; ``x0`` is
    a starting depth ``z`` as usual.  A prior equal to the truth up to scale
    and shift gives back the truth (a zero residual).

    ``quality="fast"`` averages the image and the observations over blocks
    of ``f x f`` pixels (:func:`fast_factor`: ``f = 4`` up to one
    observation per 16 pixels, 3 up to one per 9, 2 above), solves the
    objective of ``weights`` (:data:`FAST_WEIGHTS` without them) on the ``f`` times coarser grid (no duality gap is
    computed; for γ = 0 Jacobi-preconditioned CG, its products by the
    normal matrix in float32, to a relative residual of
    :data:`~sparsedepth.modes.fast.FAST_COARSE_RTOL`), interpolates the
    solution bilinearly between the block centres and refines it by
    :data:`~sparsedepth.modes.fast.FAST_SWEEPS` red-black sweeps of
    :func:`~sparsedepth.grid.resample.edge_aware_sweeps` with the
    observations held.  Its accuracy and time beside the default's and the
    fast filters': ``python -m bench.fast_mode``.

    Examples
    --------
    >>> import numpy as np, sparsedepth
    >>> rng = np.random.default_rng(0)
    >>> image = rng.random((40, 50, 3))
    >>> truth = np.add.outer(np.linspace(1, 2, 40), np.linspace(0, 1, 50))
    >>> sparse, mask = sparsedepth.sample_depth(truth, fraction=0.05, seed=0)
    >>> result = sparsedepth.complete_depth(image, sparse, mask)
    >>> result.depth.shape
    (40, 50)
    """
    mode = check_modes(quality=quality, solver=solver, tol=tol, max_iter=max_iter, callback=callback,
                       options=options, uncertainty=uncertainty, max_uncertainty=max_uncertainty,
                       max_relative_uncertainty=max_relative_uncertainty, prior=prior, expected_error=expected_error)
    check_blowups(blowups)
    if mode == "best":
        result = complete_best(image, sparse_depth, mask, weights=weights, l1_smoothing=l1_smoothing,
                               clip_to_observed=clip_to_observed, x0=x0, expected_error=expected_error)
        if expected_error and result.selection.chosen != "nearest":
            warn_if_no_gain(result.expected_rmse, result.expected_nearest_rmse, stacklevel=3)
    elif mode == "prior":
        result = complete_with_prior(image, sparse_depth, mask, prior, alignment=prior_alignment, weights=weights,
                                     l1_smoothing=l1_smoothing, clip_to_observed=clip_to_observed, solver=solver,
                                     tol=tol, max_iter=max_iter, options=options, callback=callback, x0=x0)
    else:
        if mode == "fast":
            result = complete_fast(image, sparse_depth, mask, weights=weights, l1_smoothing=l1_smoothing,
                                   clip_to_observed=clip_to_observed, x0=x0)
        else:
            settings = dict(solver=solver, tol=tol, max_iter=max_iter, options=options, callback=callback, x0=x0)
            problem = CompletionProblem(image, sparse_depth, mask, weights=weights, l1_smoothing=l1_smoothing,
                                        clip_to_observed=clip_to_observed)
            if mode == "uncertainty":
                result = complete_with_uncertainty(problem, max_uncertainty=max_uncertainty,
                                                   max_relative_uncertainty=max_relative_uncertainty, **settings)
            else:
                result = problem.solve(**settings)
        if expected_error:
            result = with_expected_error(result, image, sparse_depth, mask, quality, weights)
    return result if blowups is None else with_blowups(result, sparse_depth, mask, blowups)


#: The values of ``complete_depth``'s ``blowups`` besides None.
BLOWUP_ACTIONS = ("flag", "remove")


def check_blowups(blowups) -> None:
    """Refuse a ``blowups`` that is not None, ``"flag"`` or ``"remove"`` (TypeError for a non-string)."""
    if blowups is None:
        return
    if not isinstance(blowups, str):
        raise TypeError(f"blowups must be None or one of {list(BLOWUP_ACTIONS)}; got {type(blowups).__name__}")
    if blowups not in BLOWUP_ACTIONS:
        raise ValueError(f"blowups must be None or one of {list(BLOWUP_ACTIONS)}; got {blowups!r}")


def with_blowups(result, sparse_depth, mask, blowups) -> CompletionResult:
    """``result`` with the pixels :func:`~sparsedepth.blowups.flag_blowups` judges blown up in ``result.blowups``;
    with ``blowups="remove"`` they are also NaN in the depth and counted in ``result.removed``."""
    flagged = flag_blowups(result.depth, sparse_depth, mask)
    if blowups == "flag":
        return replace(result, blowups=flagged)
    return replace(result, depth=remove_blowups(result.depth, flagged), blowups=flagged,
                   removed=result.removed + int(np.count_nonzero(flagged)))


def with_expected_error(result, image, sparse_depth, mask, quality, weights) -> CompletionResult:
    """``result`` with its expected RMSE and nearest fill's (:func:`~sparsedepth.expected_error.expected_error`),
    warning :class:`~sparsedepth.result.NoGainWarning` when the completion is not expected to beat nearest fill."""
    estimate = estimate_expected_error(image, sparse_depth, mask, quality=quality,
                                       weights=weights if quality == "fast" else None,
                                       completed=result.depth if quality == "default" else None)
    warn_if_no_gain(estimate.rmse, estimate.nearest_rmse, stacklevel=4)
    return replace(result, expected_rmse=estimate.rmse, expected_nearest_rmse=estimate.nearest_rmse)


def warn_if_no_gain(expected_rmse, expected_nearest_rmse, *, stacklevel=3) -> None:
    """Warn :class:`~sparsedepth.result.NoGainWarning` when ``expected_rmse >= expected_nearest_rmse``."""
    if not expected_rmse < expected_nearest_rmse:
        warnings.warn(f"the completion is not expected to beat nearest fill: expected RMSE {expected_rmse:.4g} vs "
                      f"{expected_nearest_rmse:.4g} for nearest fill (estimated from the samples; "
                      "sparsedepth.nearest_fill gives it)", NoGainWarning, stacklevel=stacklevel)


#: Which arguments go together, the one table every front end reads: ``(argument, why, the arguments it
#: excludes)``, the first rule that a call breaks deciding the message.  ``"quality"`` stands for
#: ``quality="fast"``, ``"best"`` for ``quality="best"``, ``"colorization"`` for the colorization hole fill
#: (:func:`sparsedepth.fill_holes`), and an argument counts as given when it is not at its default.
ARGUMENT_RULES = (
    ("colorization", "is not the completion solver and takes no",
     ("weights", "solver", "tol", "max_iter", "options", "quality", "best", "uncertainty", "max_uncertainty",
      "prior", "blowups")),
    ("prior", "cannot be combined with", ("quality", "uncertainty", "max_uncertainty")),
    ("quality", "picks its own solve and takes no",
     ("solver", "tol", "max_iter", "callback", "options", "uncertainty", "max_uncertainty")),
    ("best", "chooses its completion by cross-validation and takes no",
     ("solver", "tol", "max_iter", "callback", "options", "uncertainty", "max_uncertainty", "prior")),
    ("expected_error", "estimates the completion's error from fast completions and cannot be combined with",
     ("colorization", "prior")),
)


def argument_conflict(given) -> tuple[str, str, list[str]] | None:
    """The first rule of :data:`ARGUMENT_RULES` that the set ``given`` of argument names breaks, or None.

    Returns ``(argument, why, excluded)``, ``excluded`` the given arguments the rule refuses, in its order; a
    front end words it with its own names (``--fast picks its own solve and takes no --tol``).
    """
    given = set(given)
    for argument, why, excludes in ARGUMENT_RULES:
        if argument in given:
            excluded = [name for name in excludes if name in given]
            if excluded:
                return argument, why, excluded
    return None


def check_modes(*, quality="default", solver="auto", tol=None, max_iter=None, callback=None, options=None,
                uncertainty=False, max_uncertainty=None, max_relative_uncertainty=None, prior=None,
                expected_error=False) -> str:
    """Which mode a call of :func:`complete_depth` asks for: ``"fast"``, ``"best"``, ``"prior"``, ``"uncertainty"`` or
    ``"default"``.

    Which arguments go together is :data:`ARGUMENT_RULES` (:func:`argument_conflict`: ``max_relative_uncertainty``
    counts as ``max_uncertainty`` there); either limit
    implies the uncertainty.

    Raises
    ------
    ValueError
        An unknown ``quality``, arguments :data:`ARGUMENT_RULES` refuses together, a negative or non-finite
        ``max_uncertainty``, or a ``max_relative_uncertainty`` that is not a finite number > 0.
    TypeError
        ``uncertainty`` or ``expected_error`` not a bool.
    """
    if not isinstance(quality, str) or quality not in QUALITIES:
        raise ValueError(f"quality must be one of {list(QUALITIES)}; got {quality!r}")
    for name, value in (("uncertainty", uncertainty), ("expected_error", expected_error)):
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{name} must be True or False; got {type(value).__name__}")
    if max_uncertainty is not None:
        check_nonnegative_real(max_uncertainty, name="max_uncertainty")
    if max_relative_uncertainty is not None:
        check_relative_limit(max_relative_uncertainty)
    limited = max_uncertainty is not None or max_relative_uncertainty is not None
    given = [name for name, value in (("quality", quality == "fast"), ("best", quality == "best"),
                                      ("solver", solver != "auto"),
                                      ("tol", tol is not None), ("max_iter", max_iter is not None),
                                      ("callback", callback is not None), ("options", options is not None),
                                      ("uncertainty", bool(uncertainty)),
                                      ("max_uncertainty", limited),
                                      ("prior", prior is not None),
                                      ("expected_error", bool(expected_error))) if value]
    conflict = argument_conflict(given)
    if conflict is not None:
        argument, why, excluded = conflict
        label, names = _named(argument), [_named(name) for name in excluded]
        raise ValueError(f"{label} {why} {', '.join(names)}: leave {'it' if len(names) == 1 else 'them'} at the "
                         "default" + (" or use quality='default'" if argument in ("quality", "best") else ""))
    if quality in ("fast", "best"):
        return quality
    if prior is not None:
        return "prior"
    return "uncertainty" if bool(uncertainty) or limited else "default"


def _named(argument) -> str:
    """An argument of :data:`ARGUMENT_RULES` as :func:`complete_depth` spells it."""
    return {"quality": "quality='fast'", "best": "quality='best'"}.get(argument, argument)
