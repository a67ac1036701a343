"""The public entry point: :func:`complete_depth` (checks, scaling, solve, clamp).

May import every subpackage below the front door: :mod:`~sparsedepth.objective`,
:mod:`~sparsedepth.solvers`, :mod:`~sparsedepth.result`, :mod:`~sparsedepth.uncertainty` and
:mod:`sparsedepth._validation`.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings

import numpy as np
from scipy.ndimage import gaussian_filter

from ._validation import as_depth_and_mask, as_float_image, check_nonnegative_real
from .objective.objective import DEFAULT_L1_SMOOTHING, build_objective
from .result import ClampWarning, CompletionResult
from .solvers import SOLVERS, solve_scaled, check_solver_arguments, depth_scale
from .solvers.quadratic import DEFAULT_DEPTH_RTOL
from .objective.weights import DEFAULT_WEIGHTS, Weights, check_weights
from .uncertainty import MIN_OBSERVED, estimate_uncertainty, split_samples

__all__ = ["complete_depth", "choose_solver"]


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
    weights: Weights = DEFAULT_WEIGHTS,
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
    quality: str = "default",
) -> CompletionResult:
    """Complete a sparse depth map into a dense one, guided by an image.

    Minimises over ``z >= 0``::

        F(z) = α Σ M (z − z_obs)² + β Σ (∂x z)² + (∂y z)²
             + γ Σ w (|∂x z| + |∂y z|) + δ Σ (z − z_c)²   (+ optional terms)

    with ``w = exp(−κ ‖∇I‖)`` and ``z_c`` the nearest-neighbour fill of the
    observations (see :class:`~sparsedepth.objective.weights.Weights`).

    Parameters
    ----------
    image : ndarray, (H, W, 3) or (H, W)
        uint8 (÷255), uint16 (÷65535) or float in [0, 1].
    sparse_depth : ndarray, (H, W)
        Depth in metres at the observed pixels.
    mask : ndarray of bool, (H, W), optional
        True where depth is observed.  Default: finite and ``> 0`` (0 and NaN
        mean "no measurement"; a negative value is then an error).
    weights : Weights
        Term weights; default :data:`~sparsedepth.objective.weights.DEFAULT_WEIGHTS`.
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
    quality : {"default", "fast"}
        ``"fast"``: solve on a grid of ``f x f`` pixel blocks (``f = 4`` when
        both sides have at least 128 pixels, 2 from 32, else 1), then
        upsample (see Notes); for γ = 0 only, without ``x0``,
        ``callback`` or uncertainty; without ``tol`` and a depth tolerance
        the coarse solve stops at an RMS remaining change of 1e-3 of the
        depth scale.  ``result.objective`` is then NaN (the
        full-resolution objective is not built), ``result.terms`` empty and
        ``iterations``, ``history`` and ``converged`` those of the coarse solve.

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
        ``weights`` not a :class:`Weights`, ``max_iter`` not an int, ``tol``
        not a number, ``options`` not a dict, an option of the wrong type, or
        ``uncertainty`` not a bool.

    Warns
    -----
    ClampWarning
        When the clamp moved any pixel (the count is ``result.clamped``).

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
    observations; the number of moved pixels is ``result.clamped`` and a
    :class:`~sparsedepth.ClampWarning` is issued when it is not 0.

    With ``quality="fast"`` the image is averaged over ``f x f`` blocks and
    each block with samples gets their mean; the coarse problem (same
    weights) is solved as above, interpolated bilinearly between block
    centres, and corrected by the residuals at the samples,
    ``c = G(m r) / max(G(m), m̄)`` (``G`` a Gaussian of ``σ = f / 2``
    pixels, ``m`` the mask, ``m̄`` its mean, ``r`` the sample minus the
    interpolated value), before the clamp.  On the report frames it keeps
    most of the gain over the nearest fill at a fraction of the time
    (``docs/speed.md``).

    An outlier sample (say 65.5 m in a 1-4 m room) is kept as an
    observation: the data term pulls its neighbourhood toward it, so a
    blob of too-large depth surrounds it and the smoothness terms ring
    around it, undershooting below the other observations.  The clamp
    cannot remove the blob (the outlier widens the range to 65.5 m) but it
    holds the undershoot at the smallest observation, and the warning
    counts those pixels.  Remove outliers (or leave them out of ``mask``)
    before completing.

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
    name, tol, max_iter, options = _check_arguments(weights, solver, tol, max_iter, options, clip_to_observed,
                                                    FAST_DEPTH_RTOL if quality == "fast" else DEFAULT_DEPTH_RTOL)
    want_uncertainty = _check_uncertainty_arguments(uncertainty, max_uncertainty)
    settings = dict(weights=weights, solver=name, tol=tol, max_iter=max_iter, options=options,
                    l1_smoothing=l1_smoothing, clip_to_observed=clip_to_observed)
    if _check_quality(quality, weights, x0, callback, want_uncertainty) == "fast":
        return _complete_fast(image, sparse_depth, mask, settings)
    result = _complete(image, sparse_depth, mask, x0=x0, callback=callback, **settings)
    if not want_uncertainty:
        return result
    return _with_uncertainty(result, image, sparse_depth, mask, settings, max_uncertainty)


def _complete(image, sparse_depth, mask, *, weights, solver, tol, max_iter, callback, x0, l1_smoothing,
              options, clip_to_observed) -> CompletionResult:
    """One completion with checked arguments (``solver`` a name of :data:`SOLVERS`)."""
    objective, coarse, scale, depth_range = _scaled_objective(image, sparse_depth, mask, weights, l1_smoothing,
                                                              clip_to_observed)
    start = _starting_point(x0, coarse, objective.shape, scale)
    out, runtime = solve_scaled(objective, start, scale=scale, solver=solver, tol=tol, max_iter=max_iter,
                                 callback=callback, options=options)
    z, clamped = _clamp(out.z, depth_range, clip_to_observed)  # in the user's units
    scale2 = scale * scale
    terms = {key: value * scale2 for key, value in objective.term_values(z / scale).items()}
    return CompletionResult(
        depth=z.reshape(objective.shape),
        objective=float(sum(terms.values())),
        terms=terms,
        iterations=out.iterations,
        converged=out.converged,
        message=out.message,
        clamped=clamped,
        history=out.history,
        solver=solver,
        weights=weights,
        runtime=runtime,
        depth_range=depth_range,
        gap=out.gap,
    )


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
    """
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    if np.count_nonzero(observed) < MIN_OBSERVED:
        raise ValueError(f"uncertainty needs at least {MIN_OBSERVED} observed pixels (two halves of at least "
                         f"{MIN_OBSERVED // 2}); got {np.count_nonzero(observed)}")
    half_a, half_b = split_samples(observed, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClampWarning)  # the halves' clamps are not the user's result
        halves = [_complete(image, np.where(half, depth, np.nan), half, x0=result.depth, callback=None,
                            **settings).depth for half in (half_a, half_b)]
    sigma, calibration = estimate_uncertainty(result.depth, *halves, depth, half_a, half_b, image=image)
    dense, removed = result.depth, 0
    if max_uncertainty is not None:
        too_uncertain = sigma > max_uncertainty
        removed = int(np.count_nonzero(too_uncertain))
        dense = np.where(too_uncertain, np.nan, dense)
    return dataclasses.replace(result, depth=dense, uncertainty=sigma, uncertainty_calibration=calibration,
                               removed=removed)


def _check_arguments(weights, solver, tol, max_iter, options, clip_to_observed, depth_rtol=DEFAULT_DEPTH_RTOL):
    """The solver name ``"auto"`` resolves to, and the checked ``tol``, ``max_iter``, ``options``.

    Without ``tol`` and a depth tolerance, ``options["depth_rtol"]`` of ``"amg"`` is set to ``depth_rtol``.
    """
    check_weights(weights)
    name = choose_solver(weights) if solver == "auto" else solver
    if name not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {['auto', *sorted(SOLVERS)]}")
    explicit_tol = tol is not None
    tol, max_iter, options = check_solver_arguments(name, tol, max_iter, options)
    if name == "amg" and not explicit_tol and options["depth_rtol"] is None and options["depth_atol"] is None:
        options["depth_rtol"] = depth_rtol
    if not isinstance(clip_to_observed, (bool, np.bool_)):
        raise TypeError(f"clip_to_observed must be True or False; got {type(clip_to_observed).__name__}")
    return name, tol, max_iter, options


def _scaled_objective(image, sparse_depth, mask, weights, l1_smoothing, clip_to_observed):
    """``(objective, coarse, scale, depth_range)``: the objective in units of the depth scale ``s``.

    Depth, ``gamma``, ``edge_scale`` and ``l1_smoothing`` are divided by
    ``s``, so the objective is ``F / s²`` (see :func:`complete_depth`, Notes); ``coarse`` is
    the nearest fill in those units, ``depth_range`` the clamp range in the
    user's units.
    """
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    observed_values = depth[observed]
    depth_range = (float(observed_values.min()), float(observed_values.max())) if clip_to_observed else (0.0, np.inf)
    scale = depth_scale(observed_values)
    del observed_values
    depth /= scale
    objective, coarse, _ = build_objective(
        image, depth, observed,
        weights=weights.replace(gamma=weights.gamma / scale, edge_scale=weights.edge_scale / scale),
        l1_smoothing=l1_smoothing / scale)
    return objective, coarse, scale, depth_range


def _starting_point(x0, coarse, shape, scale):
    """The flat starting point in units of ``scale``: ``coarse`` without a copy, or ``max(x0, 0) / scale``."""
    if x0 is None:
        start = coarse.reshape(-1).view()  # no copy (8-MP memory); every solver copies its start
        start.flags.writeable = False  # ... and the prior's target must stay intact
        return start
    start = np.asarray(x0, dtype=np.float64)
    if start.shape != shape:
        raise ValueError(f"x0 has shape {start.shape}, expected {shape}")
    if not np.all(np.isfinite(start)):
        raise ValueError("x0 contains NaN or infinite values")
    return np.maximum(start.ravel(), 0.0) / scale


def _clamp(z, depth_range, clip_to_observed):
    """``(clip(z, *depth_range), clamped)``, warning with a :class:`ClampWarning` when ``clamped`` is not 0.

    With ``clip_to_observed``, moves of rounding size (a flat input whose
    solution is the observed value to 1e-15) are not counted; without it the
    range is ``[0, inf)`` and the pixels at 0 are counted.
    """
    low, high = depth_range
    if clip_to_observed:
        slack = 1e-9 * high
        clamped = int(np.count_nonzero((z < low - slack) | (z > high + slack)))
    else:
        clamped = int(np.count_nonzero(z <= 0))
    z = np.clip(z, low, high)
    if clamped:
        warnings.warn(
            f"complete_depth: {clamped} of {z.size} pixels were outside the depth range "
            f"[{low:g}, {high:g}] and were clamped to it (result.clamped, result.depth_range)"
            + ("" if clip_to_observed else "; clip_to_observed=False: they are held at the bound 0"),
            ClampWarning, stacklevel=4)
    return z, clamped


#: The values of ``complete_depth(quality=...)``.
QUALITIES = ("default", "fast")
#: ``depth_rtol`` of the coarse solve of ``quality="fast"`` (without ``tol`` and a depth tolerance): on the report
#: frames at 640x480 the same RMSE as 3e-4 to 1e-3 relative, 8 % less time (``bench/speed.py``).
FAST_DEPTH_RTOL = 1e-3


def _check_quality(quality, weights, x0, callback, want_uncertainty) -> str:
    """``quality`` checked; ``ValueError`` for an unknown one or what ``"fast"`` cannot do."""
    if not isinstance(quality, str) or quality not in QUALITIES:
        raise ValueError(f"quality must be one of {list(QUALITIES)}; got {quality!r}")
    if quality == "fast":
        refused = [what for what, given in (("gamma > 0", weights.gamma != 0), ("x0", x0 is not None),
                                            ("callback", callback is not None),
                                            ("uncertainty", want_uncertainty)) if given]
        if refused:
            raise ValueError(f"quality='fast' solves the quadratic objective (gamma = 0) on a coarse grid, without "
                             f"{', '.join(refused)}; got {', '.join(refused)}: use quality='default' for them")
    return quality


def _fast_factor(shape) -> int:
    """The block size ``f`` of ``quality="fast"``: 4 when both sides are >= 128 pixels, 2 from 32, else 1."""
    side = min(shape)
    return 4 if side >= 128 else 2 if side >= 32 else 1


def _block_sums(values, f):
    """Sums of ``values`` (H, W[, C]) over ``f x f`` blocks (zero-padded at the far edges), in float64.

    The ``f`` phases are added slice by slice (uint8 in uint16 along the rows): several times faster than
    NumPy's reduction over the strided block axes.
    """
    H, W = values.shape[:2]
    h, w = -(-H // f), -(-W // f)
    rest = values.shape[2:]
    if (h * f, w * f) != (H, W):
        padded = np.zeros((h * f, w * f) + rest, dtype=values.dtype)
        padded[:H, :W] = values
        values = padded
    x = values.reshape((h * f, w, f) + rest)
    rows = x[:, :, 0].astype(np.uint16 if values.dtype == np.uint8 and f <= 16 else np.float64)
    for k in range(1, f):
        rows += x[:, :, k]
    rows = rows.reshape((h, f, w) + rest)
    out = rows[:, 0].astype(np.float64)
    for k in range(1, f):
        out += rows[:, k]
    return out


def _block_counts(shape, f):
    """Pixels per ``f x f`` block of a ``shape`` grid (fewer in the last row and column of blocks)."""
    rows, cols = (np.minimum(f, n - np.arange(0, n, f)).astype(np.float64) for n in shape)
    return np.multiply.outer(rows, cols)


def _upsample(coarse, f, shape):
    """Bilinear interpolation of block values (one per ``f x f`` block, at its centre) at every pixel."""
    out = coarse
    for axis, n in enumerate(shape):
        u = (np.arange(n) - (f - 1) / 2.0) / f  # pixel position in block-centre units
        i0 = np.clip(np.floor(u).astype(np.intp), 0, coarse.shape[axis] - 1)
        i1 = np.minimum(i0 + 1, coarse.shape[axis] - 1)
        t = np.clip(u - i0, 0.0, 1.0)
        t = t[:, None] if axis == 0 else t[None, :]
        a, b = np.take(out, i0, axis=axis), np.take(out, i1, axis=axis)
        out = a + t * (b - a)
    return out


def _complete_fast(image, sparse_depth, mask, settings) -> CompletionResult:
    """``quality="fast"``: the default completion on ``f x f`` blocks, upsampled and corrected (see complete_depth)."""
    start = time.perf_counter()
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    raw = np.asarray(image)
    # a uint8 RGB image is averaged as it is (÷255 after the sums); any other goes through the checks first
    img, unit = (raw, 255.0) if raw.dtype == np.uint8 and raw.ndim == 3 and raw.shape[2] == 3 else \
        (as_float_image(image).astype(np.float32), 1.0)
    if img.shape[:2] != depth.shape:
        raise ValueError(f"image has shape {img.shape[:2]} but sparse_depth has shape {depth.shape}")
    f = _fast_factor(depth.shape)
    coarse_image = _block_sums(img, f) / (unit * _block_counts(depth.shape, f)[..., None])
    del img
    hits = _block_sums(observed.view(np.uint8), f)
    coarse_mask = hits > 0
    coarse_depth = np.where(coarse_mask, _block_sums(depth, f) / np.maximum(hits, 1.0), np.nan)
    objective, nearest, scale, _ = _scaled_objective(coarse_image, coarse_depth, coarse_mask, settings["weights"],
                                                     settings["l1_smoothing"], settings["clip_to_observed"])
    out, _ = solve_scaled(objective, _starting_point(None, nearest, objective.shape, scale), scale=scale,
                          solver=settings["solver"], tol=settings["tol"], max_iter=settings["max_iter"],
                          callback=None, options=settings["options"])
    z = _upsample(out.z.reshape(objective.shape), f, depth.shape)
    sigma = f / 2.0
    spread = gaussian_filter(np.where(observed, depth - z, 0.0).astype(np.float32), sigma, mode="nearest",
                             truncate=3.0)
    density = gaussian_filter(observed.astype(np.float32), sigma, mode="nearest", truncate=3.0)
    z += spread / np.maximum(density, np.float32(np.count_nonzero(observed) / observed.size))
    values = depth[observed]
    depth_range = (float(values.min()), float(values.max())) if settings["clip_to_observed"] else (0.0, math.inf)
    z, clamped = _clamp(z.ravel(), depth_range, settings["clip_to_observed"])
    message = (f"quality='fast': solved on {f}x{f} blocks ({objective.shape[1]}x{objective.shape[0]}), "
               f"upsampled and corrected at the samples; coarse solve: {out.message}")
    return CompletionResult(
        depth=z.reshape(depth.shape), objective=float("nan"), terms={}, iterations=out.iterations,
        converged=out.converged, message=message, clamped=clamped, history=out.history,
        solver=settings["solver"], weights=settings["weights"], runtime=time.perf_counter() - start,
        depth_range=depth_range)
