"""Per-input choice among fixed candidates by cross-validation on the samples: ``complete_depth(quality="best")``.

:func:`select` scores every candidate of :data:`CANDIDATES` (the defaults, the image trusted less or not at all, a
blend with nearest fill, nearest fill) by the distance-matched cross-validation of
:mod:`sparsedepth.expected_error` (the same tile folds, :func:`~sparsedepth.expected_error.tile_folds`), and keeps
the defaults unless another candidate's expected RMSE is lower by :data:`MARGIN`; :func:`complete_best` completes
with the chosen one at full resolution.  Its accuracy and time beside the default's and nearest fill's:
``python -m bench.best_quality`` (``docs/best_quality.md``).

May import :mod:`sparsedepth.expected_error`, :mod:`sparsedepth.problem`, :mod:`sparsedepth.modes`,
:mod:`sparsedepth.baselines` and what they import; never :mod:`sparsedepth.completion` (which calls it).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field, fields, replace

import numpy as np

from ._validation import as_depth_and_mask
from .baselines import nearest_fill
from .expected_error import MIN_SAMPLES, departure_factor, expected_mse, held_out_errors, tile_folds
from .modes.fast import FAST_WEIGHTS, complete_fast
from .objective.objective import DEFAULT_L1_SMOOTHING
from .objective.weights import DEFAULT_SCHEDULE, DensitySchedule, check_weights
from .problem import CompletionProblem
from .result import ClampWarning, CompletionResult

__all__ = ["Candidate", "CANDIDATES", "IMAGE_TRUST_FIELDS", "MARGIN", "FOLD_QUALITY", "FOLD_QUALITIES",
           "Selection", "BestCompletionResult", "image_trust", "candidate_weights", "cross_validation_scores",
           "choose", "select", "complete_best"]


@dataclass(frozen=True)
class Candidate:
    """One completion :func:`select` may choose: ``(1 − nearest_share) · z + nearest_share · n``.

    ``z`` is the completion with the weights' image trust scaled by ``image_trust`` (:func:`image_trust`) and
    ``n`` the nearest fill of the samples (:func:`~sparsedepth.nearest_fill`); ``nearest_share = 1`` is nearest
    fill alone (no solve).

    Attributes
    ----------
    name : str
    image_trust : float
        Factor in [0, 1] on the image-dependent fields of the weights (:data:`IMAGE_TRUST_FIELDS`).
    nearest_share : float
        Weight in [0, 1] of nearest fill in the blend.
    """

    name: str
    image_trust: float = 1.0
    nearest_share: float = 0.0


#: The candidates of ``quality="best"``: the defaults; the image trusted a quarter as much; the image ignored;
#: half the defaults and half nearest fill; nearest fill.  The first is the one kept without a clear gain.
CANDIDATES = (
    Candidate("default"),
    Candidate("image_trust_0.25", image_trust=0.25),
    Candidate("image_ignored", image_trust=0.0),
    Candidate("half_nearest", nearest_share=0.5),
    Candidate("nearest", nearest_share=1.0),
)
#: The fields of :class:`~sparsedepth.Weights` through which the image acts, scaled by the image trust: the edge
#: sensitivity ``kappa`` of every image weight, the contrast cost ``fill_contrast`` of the geodesic fill, and the
#: weights of the local-linear terms (depth an affine function of the colour).
IMAGE_TRUST_FIELDS = ("kappa", "fill_contrast", "beta_local_linear", "beta_local_linear_cross",
                      "beta_local_linear_2x2")
#: Another candidate replaces the defaults only when its cross-validated RMSE is below ``(1 − MARGIN)`` times the
#: defaults'.  Chosen on the calibration scenes of :mod:`bench.expected_error` (middlebury2001/tsukuba,
#: nyu_mmseg_pseudo/bookstore_0001d_00001, realsense_d435 80 and 130; every pattern, seeds 0-2, half
#: resolution): the smallest mean RMSE over nearest fill's, ``python -m bench.best_quality`` (its calibration
#: table, docs/best_quality.md).
MARGIN = 0.1
#: The completions of the folds: ``"fast"`` (:func:`~sparsedepth.modes.fast.complete_fast`) or ``"default"`` (one
#: full solve per fold and candidate); chosen on the same scenes by the same table.
FOLD_QUALITY = "fast"
#: The values of ``fold_quality``.
FOLD_QUALITIES = ("fast", "default")


@dataclass(frozen=True)
class Selection:
    """What :func:`select` returns: the chosen candidate and every candidate's cross-validated score.

    Attributes
    ----------
    chosen : str
        The chosen candidate's name (:data:`CANDIDATES`).
    scores : dict of str to float
        Each candidate's expected RMSE over the unobserved pixels from the cross-validation (Notes of
        :func:`select`), in the depth's units.
    margin : float
    fold_quality : str
    folds : int
    tile : int
        Side in pixels of the tiles held out together.
    held_out : int
        Samples each score was fitted on.
    """

    chosen: str
    scores: dict
    margin: float
    fold_quality: str
    folds: int
    tile: int
    held_out: int


@dataclass(frozen=True)
class BestCompletionResult(CompletionResult):
    """A :class:`~sparsedepth.result.CompletionResult` of ``quality="best"`` with its :attr:`selection`.

    With a blend or nearest fill chosen, :attr:`depth` is not the minimiser of an objective: ``objective``,
    ``gap`` and ``solver_gap`` are NaN and ``terms`` is empty (the iterations and history are those of the solve
    in the blend; none for nearest fill).

    Attributes
    ----------
    selection : Selection
        The chosen candidate and every candidate's score.
    """

    selection: Selection | None = field(default=None)


def image_trust(weights, trust):
    """``weights`` with the image trusted ``trust`` times as much: every :data:`IMAGE_TRUST_FIELDS` entry scaled.

    Parameters
    ----------
    weights : Weights, DensitySchedule or None
        ``None`` is :data:`~sparsedepth.objective.weights.DEFAULT_SCHEDULE`; a schedule is scaled at every anchor
        (and in its base), so it still follows the density.
    trust : float
        The factor, >= 0: 1 gives equal weights, 0 ignores the image (edge weights 1, Euclidean nearest fill as
        the prior's target, no local-linear term).

    Returns
    -------
    Weights or DensitySchedule

    Notes
    -----
    The image enters the objective through the edge weights ``w = exp(−κ ‖ΔI‖)``, the geodesic fill's step cost
    ``1 + λ ‖ΔI‖`` and the local-linear terms' weights ``β_LL``; with trust ``t`` they become
    ``exp(−t κ ‖ΔI‖)``, ``1 + t λ ‖ΔI‖`` and ``t β_LL``, so that an image edge must be ``1/t`` times as strong to
    cut the smoothness as much.
    """
    weights = DEFAULT_SCHEDULE if weights is None else weights

    def scaled(values):
        return {name: value * trust if name in IMAGE_TRUST_FIELDS else value for name, value in values.items()}

    base = weights.base if isinstance(weights, DensitySchedule) else weights
    check_weights(base)
    base = base.replace(**scaled({name: getattr(base, name) for name in IMAGE_TRUST_FIELDS}))
    if isinstance(weights, DensitySchedule):
        return DensitySchedule(tuple((fraction, scaled(values)) for fraction, values in weights.anchors), base)
    return base


def candidate_weights(weights, candidate: Candidate, quality="default"):
    """The weights a candidate's completion solves with, in the default or the fast mode.

    ``weights`` (``None``: the mode's own defaults, :data:`~sparsedepth.objective.weights.DEFAULT_SCHEDULE` or
    :data:`~sparsedepth.modes.fast.FAST_WEIGHTS`) as given for trust 1, else through :func:`image_trust`.
    """
    if candidate.image_trust == 1:
        return weights
    if weights is None and quality == "fast":
        weights = FAST_WEIGHTS
    return image_trust(weights, candidate.image_trust)


def _solved(image, sparse_depth, mask, weights, quality, l1_smoothing, clip_to_observed):
    """One completion in the fold's mode, the clamp's warnings silenced (they are about a fold, not the input)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClampWarning)
        if quality == "fast":
            return complete_fast(image, sparse_depth, mask, weights=weights, l1_smoothing=l1_smoothing,
                                 clip_to_observed=clip_to_observed)
        return CompletionProblem(image, sparse_depth, mask, weights=weights, l1_smoothing=l1_smoothing,
                                 clip_to_observed=clip_to_observed).solve()


def _blend(candidate, completion, nearest):
    """``(1 − s) · completion + s · nearest`` for the candidate's share ``s`` (the completion alone at 0)."""
    share = candidate.nearest_share
    if share == 0:
        return completion
    if share == 1:
        return nearest
    return (1.0 - share) * completion + share * nearest


def _check_candidates(candidates, fold_quality):
    if fold_quality not in FOLD_QUALITIES:
        raise ValueError(f"fold_quality must be one of {list(FOLD_QUALITIES)}; got {fold_quality!r}")
    names = [c.name for c in candidates]
    if not names or names[0] != "default" or len(set(names)) != len(names):
        raise ValueError(f"candidates need distinct names, the first 'default'; got {names}")
    for c in candidates:
        if not (0 <= c.image_trust and 0 <= c.nearest_share <= 1):
            raise ValueError(f"candidate {c.name!r}: image_trust >= 0 and nearest_share in [0, 1]; got "
                             f"{c.image_trust!r}, {c.nearest_share!r}")


def cross_validation_scores(image, sparse_depth, mask=None, *, candidates=CANDIDATES, weights=None, folds=3, seed=0,
                            fold_quality=FOLD_QUALITY, l1_smoothing=DEFAULT_L1_SMOOTHING,
                            clip_to_observed=True) -> tuple[dict, object, int]:
    """Every candidate's expected RMSE over the unobserved pixels, by distance-matched cross-validation.

    Parameters
    ----------
    image, sparse_depth, mask
        As :func:`sparsedepth.complete_depth`'s.
    candidates : sequence of Candidate
        The first named ``"default"``.
    weights : Weights, DensitySchedule or None
        The weights the candidates transform (``None``: the fold mode's defaults).
    folds, seed
        As :func:`~sparsedepth.expected_error.expected_error`'s.
    fold_quality : {"fast", "default"}
        The mode of the fold completions.
    l1_smoothing, clip_to_observed
        As :func:`sparsedepth.complete_depth`'s.

    Returns
    -------
    scores : dict of str to float
        ``{name: expected RMSE}`` in the order of ``candidates``.
    split : TileFolds
        The folds (:func:`~sparsedepth.expected_error.tile_folds`).
    held_out : int
        Held-out samples (each predicted once).

    Raises
    ------
    ValueError
        Fewer than :data:`~sparsedepth.expected_error.MIN_SAMPLES` observed pixels or no unobserved one; an
        unknown ``fold_quality``; candidates without ``"default"`` first or with repeated names.

    Notes
    -----
    The folds are those of :func:`~sparsedepth.expected_error.expected_error` (:func:`tile_folds` with the
    unobserved pixels as targets).  In each fold the kept samples are completed once per distinct image trust of
    the candidates (``fold_quality`` mode) and nearest-filled; candidate ``c`` predicts each held-out sample
    ``i`` by ``ẑ_c = (1 − s_c) z_(t_c) + s_c n``.  With ``d_i`` the held-out sample's distance to the nearest kept
    one and ``m_c`` the :func:`~sparsedepth.expected_error.distance_model` of the ``(d_i, (ẑ_c,i − z_i)²)``, the
    score is

    .. math:: S_c = \\sqrt{\\tfrac{1}{|T|} \\sum_{x \\in T} m_c(D(x))}

    over the unobserved pixels ``T`` at their distances ``D(x)`` to the nearest sample: the expected RMSE of the
    fold-mode completion, distance-matched like :func:`~sparsedepth.expected_error.expected_error`'s.
    """
    candidates = tuple(candidates)
    _check_candidates(candidates, fold_quality)
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    count = int(observed.sum())
    if count < MIN_SAMPLES:
        raise ValueError(f"quality='best' needs at least {MIN_SAMPLES} observed pixels for its cross-validation; "
                         f"got {count}")
    target = ~observed
    if not target.any():
        raise ValueError("quality='best' has no unobserved pixel to choose a completion for")
    split = tile_folds(observed, target, int(folds), seed)
    trusts = list(dict.fromkeys(c.image_trust for c in candidates if c.nearest_share < 1))
    by_trust = {t: candidate_weights(weights, Candidate("", image_trust=t), fold_quality) for t in trusts}

    def predict(keep, kept_depth, nearest):
        completions = {t: _solved(image, kept_depth, keep, by_trust[t], fold_quality, l1_smoothing,
                                  clip_to_observed).depth for t in trusts}
        return {c.name: _blend(c, completions.get(c.image_trust), nearest) for c in candidates if c.name != "nearest"}

    distances, errors = held_out_errors(depth, observed, split, predict)
    scores = {c.name: float(np.sqrt(expected_mse(distances, errors[c.name], split.target_distance)[0]))
              for c in candidates}
    return scores, split, int(distances.size)


def choose(scores, margin=MARGIN) -> str:
    """The candidate to complete with: the lowest score if below ``(1 − margin)`` times ``scores["default"]``,
    else ``"default"`` (ties to the first in ``scores``' order)."""
    best = min(scores, key=scores.get)
    return best if scores[best] < (1.0 - margin) * scores["default"] else "default"


def select(image, sparse_depth, mask=None, *, candidates=CANDIDATES, weights=None, folds=3, seed=0,
           fold_quality=FOLD_QUALITY, margin=MARGIN, l1_smoothing=DEFAULT_L1_SMOOTHING,
           clip_to_observed=True) -> Selection:
    """Choose a candidate completion for this input by cross-validation on its samples.

    Parameters
    ----------
    image, sparse_depth, mask, candidates, weights, folds, seed, fold_quality, l1_smoothing, clip_to_observed
        As :func:`cross_validation_scores`'.
    margin : float
        The relative gain over the defaults' score another candidate needs (:func:`choose`).

    Returns
    -------
    Selection

    Raises
    ------
    ValueError
        As :func:`cross_validation_scores`.

    Notes
    -----
    With ``S_c`` the cross-validated scores (:func:`cross_validation_scores`) the choice is

    .. math:: c^* = \\begin{cases} \\arg\\min_c S_c & \\text{if } \\min_c S_c < (1 - \\mu) S_{default} \\\\
              \\text{default} & \\text{otherwise} \\end{cases}

    with ``μ = margin``: the estimates scatter by tens of percent (``docs/expected_error.md``), so a small
    difference of scores is no evidence against the defaults.
    """
    scores, split, held_out = cross_validation_scores(
        image, sparse_depth, mask, candidates=candidates, weights=weights, folds=folds, seed=seed,
        fold_quality=fold_quality, l1_smoothing=l1_smoothing, clip_to_observed=clip_to_observed)
    return Selection(chosen=choose(scores, margin), scores=scores, margin=float(margin), fold_quality=fold_quality,
                     folds=split.folds, tile=split.tile, held_out=held_out)


def complete_best(image, sparse_depth, mask=None, *, weights=None, l1_smoothing=DEFAULT_L1_SMOOTHING,
                  clip_to_observed=True, x0=None, expected_error=False, candidates=CANDIDATES, folds=3, seed=0,
                  fold_quality=FOLD_QUALITY, margin=MARGIN) -> BestCompletionResult:
    """Complete with the candidate :func:`select` chooses for this input (``complete_depth(quality="best")``).

    Parameters
    ----------
    image, sparse_depth, mask, weights, l1_smoothing, clip_to_observed, x0
        As :func:`sparsedepth.complete_depth`'s (``x0`` starts the full-resolution solve).
    expected_error : bool
        Also set ``expected_rmse`` and ``expected_nearest_rmse`` from the same folds (Notes).
    candidates, folds, seed, fold_quality, margin
        As :func:`select`'s.

    Returns
    -------
    BestCompletionResult
        The chosen candidate's completion at full resolution (default mode), with :attr:`selection`.

    Raises
    ------
    ValueError
        As :func:`cross_validation_scores`.

    Notes
    -----
    The chosen candidate ``c`` is completed as in its definition, ``(1 − s_c) z_(t_c) + s_c n`` with ``z_(t_c)``
    the default mode's completion of all the samples with :func:`image_trust` ``t_c`` of ``weights``.

    With ``expected_error``, ``expected_nearest_rmse`` is the nearest candidate's score and ``expected_rmse`` is
    ``f S_c``: ``f = 1`` for nearest fill and for default-mode folds; with fast folds, ``f`` is the factor of
    :func:`~sparsedepth.expected_error.departure_factor` between the result and the same candidate built from a
    fast completion of all the samples (one more fast completion; the cross-validation is not run again).

    Examples
    --------
    >>> import numpy as np
    >>> import sparsedepth as sd
    >>> truth = np.add.outer(np.linspace(1, 2, 60), np.linspace(0, 1, 80))   # a tilted plane, metres
    >>> image = np.repeat(truth[..., None] / 3, 3, axis=2)
    >>> sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=0)
    >>> result = sd.complete_depth(image, sparse, mask, quality="best")   # calls complete_best
    >>> result.selection.chosen in result.selection.scores
    True
    """
    start = time.perf_counter()
    candidates = tuple(candidates)
    selection = select(image, sparse_depth, mask, candidates=candidates, weights=weights, folds=folds, seed=seed,
                       fold_quality=fold_quality, margin=margin, l1_smoothing=l1_smoothing,
                       clip_to_observed=clip_to_observed)
    candidate = next(c for c in candidates if c.name == selection.chosen)
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    nearest = nearest_fill(depth, observed) if candidate.nearest_share > 0 else None
    if candidate.nearest_share < 1:
        result = CompletionProblem(image, sparse_depth, mask, weights=candidate_weights(weights, candidate),
                                   l1_smoothing=l1_smoothing, clip_to_observed=clip_to_observed).solve(x0=x0)
        if candidate.nearest_share > 0:
            result = replace(result, depth=_blend(candidate, result.depth, nearest), objective=float("nan"), terms={},
                             gap=float("nan"), solver_gap=float("nan"),
                             message=f"{result.message}; depth = {1 - candidate.nearest_share:g} x this completion + "
                                     f"{candidate.nearest_share:g} x nearest fill (quality='best')")
    else:
        values = depth[observed]
        result = CompletionResult(
            depth=nearest, objective=float("nan"), terms={}, iterations=0, converged=True,
            message="nearest fill chosen by cross-validation (quality='best')", clamped=0, history=(),
            solver="nearest", weights=None,
            depth_range=(float(values.min()), float(values.max())) if clip_to_observed else (0.0, float("inf")))
    if expected_error:
        score, nearest_score = selection.scores[candidate.name], selection.scores["nearest"]
        factor = 1.0
        if fold_quality == "fast" and candidate.nearest_share < 1:
            fast = _solved(image, np.where(observed, depth, np.nan), observed,
                           candidate_weights(weights, candidate, "fast"), "fast", l1_smoothing, clip_to_observed).depth
            fast = _blend(candidate, fast, nearest) if nearest is not None else fast
            factor = departure_factor(result.depth, fast, ~observed, score ** 2)
        result = replace(result, expected_rmse=factor * score, expected_nearest_rmse=nearest_score)
    values = {f.name: getattr(result, f.name) for f in fields(CompletionResult)}
    values["runtime"] = time.perf_counter() - start
    return BestCompletionResult(**values, selection=selection)
