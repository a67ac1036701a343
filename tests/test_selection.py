"""quality="best": the candidates' cross-validated scores against a computation by hand, the chosen completion
against a direct one, the ranking on scenes where it is known, and the arguments it refuses."""

import warnings

import numpy as np
import pytest
from scipy.spatial.distance import cdist

import sparsedepth as sd
from sparsedepth import selection
from sparsedepth.expected_error import distance_model, expected_error, tile_folds
from sparsedepth.modes.fast import complete_fast
from sparsedepth.selection import CANDIDATES, Candidate, complete_best, cross_validation_scores, image_trust

SHAPE = (48, 64)


def _quiet(function, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        return function(*args, **kwargs)


@pytest.fixture
def step_scene():
    """Depth 1 m left of column 30, 3 m right of it, with an image that has the same step (plus a little noise):
    the image tells where the depth jumps."""
    rng = np.random.default_rng(0)
    cols = np.arange(SHAPE[1])[None, :].repeat(SHAPE[0], 0)
    depth = np.where(cols < 30, 1.0, 3.0) + 0.002 * cols
    image = np.where(cols < 30, 0.2, 0.8)[..., None].repeat(3, 2) + 0.01 * rng.random(SHAPE + (3,))
    sparse, mask = sd.sample_depth(depth, fraction=0.05, seed=0)
    return image, sparse, mask, depth


@pytest.fixture
def plane_scene():
    """A tilted plane and a random image (no edge to follow): between the samples a smooth completion is close to
    the plane and nearest fill errs by the gradient times the distance."""
    rows, cols = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    depth = 1.0 + 0.02 * cols + 0.01 * rows
    image = np.random.default_rng(1).random(SHAPE + (3,))
    sparse, mask = sd.sample_depth(depth, fraction=0.05, seed=0)
    return image, sparse, mask, depth


def test_scores_match_a_computation_by_hand(step_scene):
    """The folds held out, the kept samples completed (fast mode) and nearest-filled, the held-out distances by
    brute force, each candidate's blend formed by hand, the distance model averaged over the unobserved pixels'
    brute-force distances."""
    image, sparse, mask, _ = step_scene
    candidates = (Candidate("default"), Candidate("half_nearest", nearest_share=0.5),
                  Candidate("nearest", nearest_share=1.0))
    scores, split, held_out = _quiet(cross_validation_scores, image, sparse, mask, candidates=candidates, seed=3)
    observed_points = np.argwhere(mask)
    target_points = np.argwhere(~mask)
    fold_of = tile_folds(mask, ~mask, 3, 3).fold_of
    distances, errors = [], {c.name: [] for c in candidates}
    for fold in range(3):
        held = fold_of == fold
        keep = mask.copy()
        keep[tuple(observed_points[held].T)] = False
        kept = np.where(keep, sparse, np.nan)
        completion = _quiet(complete_fast, image, kept, keep).depth
        nearest = sd.nearest_fill(kept, keep)
        held_points = observed_points[held]
        truth = sparse[tuple(held_points.T)]
        distances.append(cdist(held_points, np.argwhere(keep)).min(axis=1))
        for c in candidates:
            prediction = (1 - c.nearest_share) * completion + c.nearest_share * nearest
            errors[c.name].append((prediction[tuple(held_points.T)] - truth) ** 2)
    distances = np.concatenate(distances)
    target_distance = cdist(target_points, observed_points).min(axis=1)
    assert held_out == mask.sum()
    for c in candidates:
        model = distance_model(distances, np.concatenate(errors[c.name]))[0]
        assert scores[c.name] == pytest.approx(np.sqrt(np.mean(model(target_distance))), rel=1e-9)


def test_a_constant_scene_scores_zero_for_every_candidate():
    image = np.random.default_rng(2).random(SHAPE + (3,))
    sparse, mask = sd.sample_depth(np.full(SHAPE, 2.5), fraction=0.05, seed=0)
    scores = _quiet(cross_validation_scores, image, sparse, mask)[0]
    assert list(scores) == [c.name for c in CANDIDATES]
    assert all(value == pytest.approx(0.0, abs=1e-9) for value in scores.values())


def test_the_defaults_score_is_expected_errors_fast_estimate(plane_scene):
    """One implementation of the folds: the default candidate's score and nearest fill's are expected_error's."""
    image, sparse, mask, _ = plane_scene
    scores = _quiet(cross_validation_scores, image, sparse, mask, seed=1)[0]
    estimate = _quiet(expected_error, image, sparse, mask, seed=1, quality="fast")
    assert scores["default"] == pytest.approx(estimate.rmse, rel=1e-12)
    assert scores["nearest"] == pytest.approx(estimate.nearest_rmse, rel=1e-12)


def test_the_ranking_is_the_known_one(step_scene, plane_scene):
    """Across an image-marked step, ignoring the image blurs the step; on a plane with a random image, nearest
    fill's staircase is worse than the completion: the scores rank the two as their true RMSEs do."""
    for (image, sparse, mask, depth), worse in ((step_scene, "image_ignored"), (plane_scene, "nearest")):
        scores = _quiet(cross_validation_scores, image, sparse, mask)[0]
        default = _quiet(sd.complete_depth, image, sparse, mask).depth
        other = (sd.nearest_fill(sparse, mask) if worse == "nearest" else
                 _quiet(sd.complete_depth, image, sparse, mask, weights=image_trust(None, 0.0)).depth)
        true_default, true_other = (np.sqrt(np.mean((z - depth)[~mask] ** 2)) for z in (default, other))
        assert true_other > true_default
        assert scores[worse] > scores["default"]
        chosen = _quiet(complete_best, image, sparse, mask, candidates=(
            CANDIDATES[0], *(c for c in CANDIDATES if c.name == worse)), margin=-np.inf).selection.chosen
        assert chosen == "default"  # the lower score, even with any margin allowed


def _hand_weights(fraction, trust):
    """The density-scheduled defaults at ``fraction`` with every field the image acts through scaled by hand."""
    w = sd.objective.weights.default_weights(fraction)
    return w.replace(kappa=trust * w.kappa, fill_contrast=trust * w.fill_contrast,
                     beta_local_linear=trust * w.beta_local_linear,
                     beta_local_linear_cross=trust * w.beta_local_linear_cross,
                     beta_local_linear_2x2=trust * w.beta_local_linear_2x2)


@pytest.mark.parametrize("name", [c.name for c in CANDIDATES])
def test_the_chosen_completion_is_that_candidates_own(step_scene, monkeypatch, name):
    image, sparse, mask, _ = step_scene
    monkeypatch.setattr(selection, "choose", lambda scores, margin: name)
    result = _quiet(sd.complete_depth, image, sparse, mask, quality="best")
    assert result.selection.chosen == name and set(result.selection.scores) == {c.name for c in CANDIDATES}
    default = _quiet(sd.complete_depth, image, sparse, mask).depth
    nearest = sd.nearest_fill(sparse, mask)
    fraction = mask.mean()
    expected = {"default": default, "half_nearest": 0.5 * default + 0.5 * nearest, "nearest": nearest}
    if name in expected:
        np.testing.assert_allclose(result.depth, expected[name], rtol=1e-12, atol=0)
    else:
        trust = next(c.image_trust for c in CANDIDATES if c.name == name)
        direct = _quiet(sd.complete_depth, image, sparse, mask, weights=_hand_weights(fraction, trust)).depth
        np.testing.assert_allclose(result.depth, direct, rtol=0, atol=1e-6)
    if name in ("half_nearest", "nearest"):
        assert np.isnan(result.objective) and result.terms == {}


def test_image_trust_scales_only_the_image_fields():
    weights = sd.Weights(beta_local_linear_cross=0.2, beta_local_linear_2x2=0.4)
    half = image_trust(weights, 0.5)
    assert (half.kappa, half.fill_contrast, half.beta_local_linear, half.beta_local_linear_cross,
            half.beta_local_linear_2x2) == (12.5, 10.0, 0.005, 0.1, 0.2)
    assert half.replace(kappa=25.0, fill_contrast=20.0, beta_local_linear=0.01, beta_local_linear_cross=0.2,
                        beta_local_linear_2x2=0.4) == weights
    for fraction in (0.002, 0.02, 0.05, 0.3):
        scheduled = image_trust(None, 0.25).weights(fraction)
        hand = _hand_weights(fraction, 0.25)
        for field in ("kappa", "fill_contrast", "beta_local_linear_cross", "beta_local_linear_2x2", "delta",
                      "beta_second_image"):
            assert getattr(scheduled, field) == pytest.approx(getattr(hand, field), rel=1e-12)


def test_expected_error_comes_from_the_same_folds(plane_scene, monkeypatch):
    """With the defaults chosen, the expected RMSEs are expected_error's for the default completion."""
    image, sparse, mask, _ = plane_scene
    monkeypatch.setattr(selection, "choose", lambda scores, margin: "default")
    result = _quiet(sd.complete_depth, image, sparse, mask, quality="best", expected_error=True)
    estimate = _quiet(expected_error, image, sparse, mask, completed=result.depth)
    assert result.expected_rmse == pytest.approx(estimate.rmse, rel=1e-12)
    assert result.expected_nearest_rmse == pytest.approx(estimate.nearest_rmse, rel=1e-12)
    assert result.expected_nearest_rmse == result.selection.scores["nearest"]


def test_bad_inputs_are_refused(plane_scene):
    image, sparse, mask, _ = plane_scene
    with pytest.raises(ValueError, match=r"quality must be one of \['default', 'fast', 'best'\]"):
        sd.complete_depth(image, sparse, mask, quality="finest")
    few = np.zeros(SHAPE, bool)
    few[5, 3:63:6] = True  # 10 samples
    with pytest.raises(ValueError, match="at least 16 observed pixels"):
        sd.complete_depth(image, np.where(few, 2.0, np.nan), few, quality="best")
    for kwargs in (dict(uncertainty=True), dict(solver="cg"), dict(tol=1e-3), dict(prior=np.ones(SHAPE))):
        with pytest.raises(ValueError, match="quality='best'"):
            sd.complete_depth(image, sparse, mask, quality="best", **kwargs)
    with pytest.raises(ValueError, match="fold_quality"):
        cross_validation_scores(image, sparse, mask, fold_quality="slow")
