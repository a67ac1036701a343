"""The public entry point: :func:`complete_depth` (checks, scaling, solve, clamp).

May import every subpackage below the front door: :mod:`~sparsedepth.objective`,
:mod:`~sparsedepth.solvers`, :mod:`~sparsedepth.linalg`, :mod:`~sparsedepth.grid`, :mod:`~sparsedepth.result`,
:mod:`~sparsedepth.uncertainty` and :mod:`sparsedepth._validation`.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
import warnings

import numpy as np
from scipy.sparse.linalg import LinearOperator

from ._validation import as_depth_and_mask, as_float_image, check_nonnegative_real, check_same_shape
from .grid.diagonals import stencil_to_dia
from .grid.resample import block_mean, block_sample_mean, coarse_shape, edge_aware_sweeps, upsample_bilinear
from .grid.operators import StencilOperator
from .linalg.krylov import pcg_info
from .priors import align_prior
from .objective.objective import DEFAULT_L1_SMOOTHING, build_objective
from .result import ClampWarning, CompletionResult, RangeOutlierWarning
from .solvers import SOLVERS, solve_scaled, check_solver_arguments, depth_scale
from .solvers.common import Recorder, output
from .solvers.quadratic import DEFAULT_DEPTH_RTOL
from .objective.weights import (DEFAULT_WEIGHTS, DensitySchedule, Weights, check_weights, observed_fraction,
                               resolve_weights)
from .uncertainty import MIN_OBSERVED, check_uncertainty_shape, estimate_uncertainty, split_samples

__all__ = ["complete_depth", "choose_solver", "depth_jump_factor", "range_outliers", "QUALITIES", "fast_factor",
           "CLAMP_WARNING_SHARE"]

#: The values of ``complete_depth``'s ``quality``.
QUALITIES = ("default", "fast")
#: The fast mode's coarse solve of a quadratic objective: Jacobi-preconditioned CG (no multigrid set-up on a grid
#: of a few ten thousand pixels) stopped at this relative residual.
FAST_COARSE_RTOL = 1e-4
#: The fast mode's edge-aware sweeps on the full grid: ``λ``, ``κ`` and the number of sweeps
#: (:func:`~sparsedepth.grid.resample.edge_aware_sweeps`), chosen on the tuning frames (``bench/fast_mode.py``).
FAST_SMOOTHNESS, FAST_KAPPA, FAST_SWEEPS = 16.0, 30.0, 3
#: The weights ``quality="fast"`` solves with when given the default weights: the image-weighted first- and
#: second-order terms of the 13-point model without the local-linear term, which does not carry over to a grid 2-4x
#: coarser (its 3x3 windows then span 6-12 pixels), and the Euclidean nearest fill as ``z_c``; chosen on the tuning
#: frames, where each is more accurate than the alternative: ``python -m bench.fast_mode`` (docs/fast_mode.md, "The
#: fast mode's weights").
FAST_WEIGHTS = DEFAULT_WEIGHTS.replace(beta_local_linear=0.0, beta_image=0.00673, beta_second_image=0.039,
                                       fill_contrast=0.0)
#: Relative moves the fast mode's clamp does not count: the rounding of its float32 sweeps.
FLOAT32_ROUNDING = 1e-6
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
    prior=None,
    prior_alignment: str = "scale_shift",
    quality: str = "default",
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
    quality : {"default", "fast"}
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

    Returns
    -------
    CompletionResult
        ``clamped`` pixels were moved into ``depth_range`` by the clamp.

    Raises
    ------
    ValueError
        Inconsistent shapes, no observed pixel, NaN/inf in the image, negative
        depth (observed, or anywhere without a mask), wrong number of
        dimensions, a negative weight, an unknown solver or option key, or a
        quadratic-only solver with γ > 0.
        Fewer than 16 observed pixels with ``uncertainty``; a negative or
        non-finite ``max_uncertainty``; an unknown ``quality``, or
        ``"fast"`` with γ > 0, ``x0``, ``callback`` or uncertainty.
    TypeError
        ``weights`` not a :class:`Weights`, :class:`DensitySchedule` or
        ``None``, ``max_iter`` not an int, ``tol``
        not a number, ``options`` not a dict, an option of the wrong type, or
        ``uncertainty`` not a bool.

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
    median observed depth (:func:`sparsedepth.solvers.depth_scale`); the
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
    :data:`FAST_COARSE_RTOL`), interpolates the
    solution bilinearly between the block centres and refines it by
    :data:`FAST_SWEEPS` red-black sweeps of
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
    if _check_quality(quality, solver=solver, tol=tol, max_iter=max_iter, callback=callback, options=options,
                      uncertainty=uncertainty, max_uncertainty=max_uncertainty, prior=prior):
        return _complete_fast(image, sparse_depth, mask, weights=FAST_WEIGHTS if weights is None else
                              _weights_for(weights, sparse_depth, mask), l1_smoothing=l1_smoothing,
                              clip_to_observed=clip_to_observed, x0=x0)
    weights = _weights_for(weights, sparse_depth, mask)
    name, tol, max_iter, options = _check_arguments(weights, solver, tol, max_iter, options, clip_to_observed)
    want_uncertainty = _check_uncertainty_arguments(uncertainty, max_uncertainty)
    if want_uncertainty:
        check_uncertainty_shape(np.shape(sparse_depth), name="max_uncertainty" if max_uncertainty is not None
                                else "uncertainty")
    settings = dict(weights=weights, solver=name, tol=tol, max_iter=max_iter, options=options,
                    l1_smoothing=l1_smoothing, clip_to_observed=clip_to_observed)
    if prior is not None:
        if want_uncertainty:
            raise ValueError("prior= cannot be combined with uncertainty= or max_uncertainty= (the half-sample "
                             "estimate does not model the prior); leave one of them out")
        return _complete_with_prior(image, sparse_depth, mask, prior, prior_alignment, x0=x0, callback=callback,
                                    settings=settings)
    result = _complete(image, sparse_depth, mask, x0=x0, callback=callback, **settings)
    if not want_uncertainty:
        return result
    return _with_uncertainty(result, image, sparse_depth, mask, settings, max_uncertainty)


def _weights_for(weights, sparse_depth, mask) -> Weights:
    """The :class:`Weights` of ``weights`` (``None``, a schedule or weights) for the observed fraction of the input."""
    if isinstance(weights, Weights):
        return weights
    _, observed = as_depth_and_mask(sparse_depth, mask)
    return resolve_weights(weights, observed_fraction(observed))


def _complete(image, sparse_depth, mask, *, weights, solver, tol, max_iter, callback, x0, l1_smoothing,
              options, clip_to_observed, bounds=None, certify_result=True) -> CompletionResult:
    """One completion with checked arguments (``solver`` a name of :data:`SOLVERS`).

    The depth is clamped to ``bounds`` (user units; floats or per-pixel arrays) when given, else to the range of
    the observations (:func:`_depth_range`); the result's ``gap`` and ``converged`` are those of the clamped depth
    (:func:`~sparsedepth.solvers.core.solve_scaled` with the bounds).  ``certify_result=False`` skips the
    certificate (an intermediate completion: the uncertainty's halves).

    With ``weights.depth_jump > 0`` (and an image-weighted smoothness term) it solves twice: the second objective's
    pair weights are relaxed where the first solution jumps (:func:`depth_jump_factor`) and its solve starts from
    the first solution; iterations and runtime are those of both solves, the history that of the second.
    """
    objective, coarse, scale, depth_range = _scaled_objective(image, sparse_depth, mask, weights, l1_smoothing,
                                                              clip_to_observed)
    box = depth_range if bounds is None else tuple(np.ravel(b) if np.ndim(b) else b for b in bounds)
    start = _starting_point(x0, coarse, objective.shape, scale)
    jump = weights.depth_jump > 0 and (weights.beta_image > 0 or weights.beta_second_image > 0)
    solve = dict(solver=solver, tol=tol, max_iter=max_iter, callback=callback, options=options)
    out, runtime = solve_scaled(objective, start, scale=scale, certify_result=certify_result and not jump,
                                bounds=None if jump else _in_units(box, scale), **solve)
    iterations = out.iterations
    if jump:
        first = np.clip(out.z, *box)
        factor = depth_jump_factor(first.reshape(objective.shape), weights.depth_jump)
        objective, _, scale, _ = _scaled_objective(image, sparse_depth, mask, weights, l1_smoothing,
                                                   clip_to_observed, pair_factor=factor)
        out, second = solve_scaled(objective, np.maximum(out.z, 0.0) / scale, scale=scale,
                                   certify_result=certify_result, bounds=_in_units(box, scale), **solve)
        runtime += second
        iterations += out.iterations
    z, clamped = _clamp(out.z, box, clip_to_observed or bounds is not None)  # in the user's units
    scale2 = scale * scale
    terms = {key: value * scale2 for key, value in objective.term_values(z / scale).items()}
    return CompletionResult(
        depth=z.reshape(objective.shape),
        objective=float(sum(terms.values())),
        terms=terms,
        iterations=iterations,
        converged=out.converged,
        message=out.message,
        clamped=clamped,
        history=out.history,
        solver=solver,
        weights=weights,
        runtime=runtime,
        depth_range=depth_range,
        gap=out.gap,
        solver_gap=out.solver_gap,
        gap_proven=out.gap_proven,
    )


def _in_units(box, scale):
    """``box`` (user units, floats or per-pixel arrays) divided by ``scale``, flattened."""
    return tuple(b / scale if np.ndim(b) == 0 else np.ravel(b) / scale for b in box)


def _complete_with_prior(image, sparse_depth, mask, prior, alignment, *, x0, callback, settings):
    """:func:`complete_depth` with ``prior``: complete the shifted residual ``z − P + c``, add ``P − c`` back.

    The residual is clamped to ``[low − P + c, high − P + c]`` per pixel, so that the depth ``z = P − c + r``
    lies in the range ``[low, high]`` of the observations: the objective, terms and gap are those of the
    residual of the depth returned.
    """
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    aligned, _, _ = align_prior(prior, depth, observed, alignment=alignment)
    residual = depth[observed] - aligned[observed]
    values = depth[observed]
    clip_to_observed = settings["clip_to_observed"]
    depth_range = _depth_range(values, clip_to_observed)
    # c keeps every residual sample >= the median depth: positive, and of the depth's magnitude for the scaling
    shift = float(np.median(values)) + max(0.0, -float(residual.min()))
    shifted = np.zeros_like(depth)
    shifted[observed] = residual + shift
    start = None if x0 is None else _prior_start(x0, aligned, shift)
    offset = shift - aligned  # r = z + offset
    bounds = (depth_range[0] + offset, depth_range[1] + offset)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClampWarning)  # the residual's clamp is the user's: warned about below
        result = _complete(image, shifted, observed, x0=start, callback=callback, bounds=bounds, **settings)
    z = np.clip(result.depth - offset, *depth_range)  # moves rounding only: the residual is in its bounds
    _warn_clamped(result.clamped, z.size, depth_range, clip_to_observed)
    return dataclasses.replace(result, depth=z, depth_range=depth_range)


def _prior_start(x0, aligned, shift):
    """The residual problem's start ``x0 − P + c`` (``x0`` checked like a depth start)."""
    start = np.asarray(x0, dtype=np.float64)
    if start.shape != aligned.shape:
        raise ValueError(f"x0 has shape {start.shape}, expected {aligned.shape}")
    if not np.all(np.isfinite(start)):
        raise ValueError("x0 contains NaN or infinite values")
    return np.maximum(start - aligned + shift, 0.0)


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


def _check_uncertainty_arguments(uncertainty, max_uncertainty) -> bool:
    """Whether the uncertainty is wanted; ``TypeError``/``ValueError`` for a bad flag or threshold."""
    if not isinstance(uncertainty, (bool, np.bool_)):
        raise TypeError(f"uncertainty must be True or False; got {type(uncertainty).__name__}")
    if max_uncertainty is None:
        return bool(uncertainty)
    check_nonnegative_real(max_uncertainty, name="max_uncertainty")
    return True


def _with_uncertainty(result, image, sparse_depth, mask, settings, max_uncertainty) -> CompletionResult:
    """``result`` with the uncertainty map (two half-sample completions) and, past ``max_uncertainty``, NaN.

    The halves start from ``result.depth``: a start near their answer saves iterations, and every solver
    stops on its own criterion for the half's objective, so the start does not decide where they end.
    No unobserved pixel's uncertainty is below the precision of the solve (:func:`_solve_precision`).
    """
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    if np.count_nonzero(observed) < MIN_OBSERVED:
        raise ValueError(f"uncertainty needs at least {MIN_OBSERVED} observed pixels (two halves of at least "
                         f"{MIN_OBSERVED // 2}); got {np.count_nonzero(observed)}")
    half_a, half_b = split_samples(observed, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClampWarning)  # the halves' clamps are not the user's result
        halves = [_complete(image, np.where(half, depth, np.nan), half, x0=result.depth, callback=None,
                            certify_result=False, **settings).depth for half in (half_a, half_b)]
    sigma, calibration = estimate_uncertainty(result.depth, *halves, depth, half_a, half_b, image=image,
                                              precision=_solve_precision(settings["options"], depth[observed]))
    dense, removed = result.depth, 0
    if max_uncertainty is not None:
        too_uncertain = sigma > max_uncertainty
        removed = int(np.count_nonzero(too_uncertain))
        dense = np.where(too_uncertain, np.nan, dense)
    return dataclasses.replace(result, depth=dense, uncertainty=sigma, uncertainty_calibration=calibration,
                               removed=removed)


def _solve_precision(options, observed_depth) -> float:
    """The RMS depth precision a solve stops at: the larger of ``depth_atol`` and ``depth_rtol`` × the depth scale.

    Solves without a depth rule (other solvers, an explicit ``tol``) are taken at the default's
    :data:`~sparsedepth.solvers.quadratic.DEFAULT_DEPTH_RTOL`.
    """
    rtol, atol = options.get("depth_rtol"), options.get("depth_atol")
    if rtol is None and atol is None:
        rtol = DEFAULT_DEPTH_RTOL
    return max(0.0 if rtol is None else rtol * depth_scale(observed_depth), 0.0 if atol is None else atol)


def _check_arguments(weights, solver, tol, max_iter, options, clip_to_observed):
    """The solver name ``"auto"`` resolves to, and the checked ``tol``, ``max_iter``, ``options``.

    Without ``tol`` and a depth tolerance, ``options["depth_rtol"]`` of ``"amg"`` is set to :data:`DEFAULT_DEPTH_RTOL`.
    """
    check_weights(weights)
    name = choose_solver(weights) if solver == "auto" else solver
    if name not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {['auto', *sorted(SOLVERS)]}")
    explicit_tol = tol is not None
    tol, max_iter, options = check_solver_arguments(name, tol, max_iter, options)
    if name == "amg" and not explicit_tol and options["depth_rtol"] is None and options["depth_atol"] is None:
        options["depth_rtol"] = DEFAULT_DEPTH_RTOL
    if not isinstance(clip_to_observed, (bool, np.bool_)):
        raise TypeError(f"clip_to_observed must be True or False; got {type(clip_to_observed).__name__}")
    return name, tol, max_iter, options


def _scaled_objective(image, sparse_depth, mask, weights, l1_smoothing, clip_to_observed, pair_factor=None):
    """``(objective, coarse, scale, depth_range)``: the objective in units of the depth scale ``s``.

    Depth, ``gamma``, ``edge_scale`` and ``l1_smoothing`` are divided by
    ``s``, so the objective is ``F / s²`` (see :func:`complete_depth`, Notes); ``coarse`` is
    the nearest fill in those units, ``depth_range`` the clamp range in the
    user's units.
    """
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    observed_values = depth[observed]
    depth_range = _depth_range(observed_values, clip_to_observed)
    scale = depth_scale(observed_values)
    del observed_values
    depth /= scale
    objective, coarse, _ = build_objective(
        image, depth, observed,
        weights=weights.replace(gamma=weights.gamma / scale, edge_scale=weights.edge_scale / scale),
        l1_smoothing=l1_smoothing / scale, pair_factor=pair_factor)
    return objective, coarse, scale, depth_range


def _starting_point(x0, coarse, shape, scale):
    """The flat starting point in units of ``scale``: ``coarse`` without a copy, or ``max(x0, 0) / scale``."""
    if x0 is None:
        start = coarse.reshape(-1).view()  # no copy (8-MP memory); every solver copies its start
        start.flags.writeable = False  # ... and the prior's target must stay intact
        return start
    return np.maximum(_checked_x0(x0, shape).ravel(), 0.0) / scale


def _checked_x0(x0, shape):
    """``x0`` as float64; ``ValueError`` unless it has ``shape`` and finite values."""
    start = np.asarray(x0, dtype=np.float64)
    if start.shape != tuple(shape):
        raise ValueError(f"x0 has shape {start.shape}, expected {tuple(shape)}")
    if not np.all(np.isfinite(start)):
        raise ValueError("x0 contains NaN or infinite values")
    return start


def _depth_range(observed_values, clip_to_observed):
    """The clamp range in the user's units: ``[min, max]`` of the observations, or ``[0, inf)`` without the clamp.

    With the clamp, observations that widen it as outliers would are warned about (:func:`range_outliers`).
    """
    if clip_to_observed:
        low, high = float(observed_values.min()), float(observed_values.max())
        outliers = range_outliers(observed_values)
        if outliers:
            warnings.warn(
                f"complete_depth: {outliers} observed depth value(s) lie far outside the other observations "
                f"(the range [{low:g}, {high:g}] the depth is clamped to includes them); an outlier pulls its "
                "neighbourhood toward it: remove it from mask if it is not a real measurement", RangeOutlierWarning,
                stacklevel=_user_stacklevel())
        return low, high
    return 0.0, np.inf


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


def _user_stacklevel() -> int:
    """The ``stacklevel`` of a warning that points at the first frame outside the package (the user's call)."""
    import sys

    frame, level = sys._getframe(1), 1
    package = __name__.rsplit(".", 1)[0]
    while frame is not None and frame.f_globals.get("__name__", "").startswith(package):
        frame, level = frame.f_back, level + 1
    return level


def _clamp(z, depth_range, clip_to_observed, rounding=1e-9):
    """``(clip(z, *depth_range), clamped)``, warning with a :class:`ClampWarning` when many pixels moved.

    ``depth_range`` holds floats or per-pixel arrays.  With
    ``clip_to_observed``, moves of rounding size (up to ``rounding`` times
    the upper end: a flat input whose solution is the observed value to
    1e-15; 1e-6 for the float32 sweeps of the fast mode) are not counted;
    without it the range is ``[0, inf)`` and the pixels at 0 are counted.
    The warning (:func:`_warn_clamped`) needs :data:`CLAMP_WARNING_SHARE`
    of the pixels.
    """
    low, high = depth_range
    if clip_to_observed:
        slack = rounding * np.max(np.abs(high))
        clamped = int(np.count_nonzero((z < low - slack) | (z > high + slack)))
    else:
        clamped = int(np.count_nonzero(z <= 0))
    z = np.clip(z, low, high)
    _warn_clamped(clamped, z.size, depth_range, clip_to_observed)
    return z, clamped


def _warn_clamped(clamped, size, depth_range, clip_to_observed):
    """A :class:`ClampWarning` when ``clamped`` is at least :data:`CLAMP_WARNING_SHARE` of ``size`` pixels."""
    if clamped < CLAMP_WARNING_SHARE * size:
        return
    low, high = (float(np.min(b)) if np.ndim(b) else float(b) for b in depth_range)
    warnings.warn(
        f"complete_depth: {clamped} of {size} pixels ({clamped / size:.1%}) were outside the depth range "
        f"[{low:g}, {high:g}] and were clamped to it (result.clamped, result.depth_range)"
        + ("" if clip_to_observed else "; clip_to_observed=False: they are held at the bound 0"),
        ClampWarning, stacklevel=_user_stacklevel())


def fast_factor(observed_fraction: float) -> int:
    """The fast mode's coarsening ``f``: the largest of 4, 3 with ``f² ×`` the observed fraction at most 1, else 2.

    A coarse block of ``f x f`` pixels then holds about one observation or
    fewer, so averaging over it loses little; at higher densities a coarser
    grid blurs the detail the samples carry.
    """
    for factor in (4, 3):
        if factor * factor * float(observed_fraction) <= 1.0:
            return factor
    return 2


def _check_quality(quality, **arguments) -> bool:
    """True for ``quality="fast"`` (with its checks); ``ValueError`` for an unknown quality or an unsupported argument."""
    if not isinstance(quality, str) or quality not in QUALITIES:
        raise ValueError(f"quality must be one of {list(QUALITIES)}; got {quality!r}")
    if quality != "fast":
        return False
    given = [name for name, value in arguments.items()
             if not (value is None or (name == "solver" and value == "auto") or (name == "uncertainty" and value is False))]
    if given:
        raise ValueError(f"quality='fast' picks its own solve and takes no {', '.join(given)}; leave "
                         f"{'it' if len(given) == 1 else 'them'} at the default or use quality='default'")
    return True


def _complete_fast(image, sparse_depth, mask, *, weights, l1_smoothing, clip_to_observed, x0) -> CompletionResult:
    """The real-time mode (:func:`complete_depth`, Notes): coarse solve, bilinear upsampling, edge-aware sweeps."""
    start_time = time.perf_counter()
    name = "cg" if weights.gamma == 0 else choose_solver(weights)
    _, tol, max_iter, options = _check_arguments(weights, name, FAST_COARSE_RTOL if name == "cg" else None, None,
                                                 None, clip_to_observed)
    fine_image = as_float_image(image, dtype=np.float32)
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    check_same_shape(fine_image.shape[:2], depth.shape, "image", "sparse_depth")
    shape = depth.shape
    if x0 is not None:
        x0 = _checked_x0(x0, shape)
    factor = fast_factor(np.count_nonzero(observed) / observed.size)
    if min(coarse_shape(shape, factor)) < 2:
        factor = 1
    coarse_depth, coarse_observed = block_sample_mean(depth, observed, factor)
    coarse_image = np.clip(block_mean(fine_image, factor), 0.0, 1.0)  # float32 means may round past 1
    # lengths in the user's pixels: a blur of edge_sigma pixels is edge_sigma / f coarse pixels, and a coarse step
    # is f pixels long, so the geodesic fill's cost per unit of image contrast is fill_contrast / f in its steps
    coarse_weights = weights.replace(edge_sigma=weights.edge_sigma / factor,
                                     fill_contrast=weights.fill_contrast / factor)
    objective, coarse, scale, _ = _scaled_objective(coarse_image, coarse_depth, coarse_observed, coarse_weights,
                                                    l1_smoothing, False)
    if x0 is not None:
        x0 = block_mean(np.maximum(x0, 0.0), factor)
    start = _starting_point(x0, coarse, objective.shape, scale)
    if name == "cg":
        out = _coarse_cg(objective, start, scale=scale, tol=tol, max_iter=max_iter)
    else:
        out, _ = solve_scaled(objective, start, scale=scale, solver=name, tol=tol, max_iter=max_iter, callback=None,
                              options=options, certify_result=False, objective_values=False)
    z = upsample_bilinear(out.z.reshape(objective.shape).astype(np.float32), shape, factor)
    z = edge_aware_sweeps(z, fine_image, depth, observed, smoothness=FAST_SMOOTHNESS, kappa=FAST_KAPPA,
                          sweeps=FAST_SWEEPS).astype(np.float64)
    depth_range = _depth_range(depth[observed], clip_to_observed)
    z, clamped = _clamp(z, depth_range, clip_to_observed, rounding=FLOAT32_ROUNDING)
    return CompletionResult(
        depth=z,
        objective=float("nan"),
        terms={},
        iterations=out.iterations,
        converged=out.converged,
        message=(f"fast mode: {factor}x coarser grid {objective.shape[0]}x{objective.shape[1]} ({name}: "
                 f"{out.message}), bilinear upsampling, {FAST_SWEEPS} edge-aware sweeps"),
        clamped=clamped,
        history=out.history,
        solver=name,
        weights=weights,
        runtime=time.perf_counter() - start_time,
        depth_range=depth_range,
        gap=float("nan"),
    )


def _coarse_cg(objective, start, *, scale, tol, max_iter):
    """The fast mode's coarse solve of a quadratic objective: Jacobi-preconditioned CG on ``A z = b`` from ``start``.

    The loop, preconditioner, start and stop (``‖b − A z‖ <= tol ‖b‖``) of ``solver="cg"``
    (:func:`~sparsedepth.solvers.quadratic.solve_cg`), with the products by ``A`` in single precision: ``A`` is
    held as a float32 DIA array made from the objective's normal stencil
    (:func:`~sparsedepth.grid.diagonals.stencil_to_dia`; no index arrays to build, half the bytes to stream per
    product), the vectors and the preconditioner ``diag(A)⁻¹`` stay in float64.  Each product then carries
    float32 rounding (relative 1e-7) instead of float64's, far below the stopping residual.  An objective with a
    term that is not a stencil operator keeps its float64 CSR matrix.  No objective values are recorded and no
    certificate is computed (the answer is an intermediate of the fast mode).  Returns a
    :class:`~sparsedepth.solvers.common.SolverOutput` in the user's units.
    """
    if all(t.operator is None or isinstance(t.operator, StencilOperator) for t in objective.quadratic_terms):
        offsets, stencil = objective.normal_stencil()
        diagonal = stencil[offsets.index((0, 0))].ravel()
        single = stencil_to_dia(offsets, stencil, dtype=np.float32)
        A = LinearOperator(single.shape, matvec=lambda z: (single @ z.astype(np.float32)).astype(np.float64),
                           dtype=np.float64)
        b = sum(t.normal_rhs(objective.size) for t in objective.quadratic_terms)  # as normal_equations sums it
    else:
        A, b, _ = objective.normal_equations()
        diagonal = A.diagonal()
    if not np.all(diagonal > 0):
        raise ValueError("the coarse system has a diagonal entry <= 0; Jacobi preconditioning needs a positive one")
    inverse_diagonal = 1.0 / diagonal
    recorder = Recorder(objective, None, scale, values=False)
    recorder(0, start)
    steps = itertools.count(1)

    def record(z, _residual):
        step = next(steps)
        recorder(step, z, inner=step, value=math.nan)

    result = pcg_info(A, b, x0=start, M=lambda r: inverse_diagonal * r, rtol=tol, maxiter=max_iter, callback=record,
                      callback_residual=True)
    message = (f"relative residual {result.relative_residual:.2e} {'<=' if result.converged else '>'} tol {tol:.1e} "
               f"after {result.iterations} CG iterations")
    return output(result.x * scale, result.iterations, result.converged, message, recorder)
