"""The density-scheduled defaults reach every entry point: complete_depth, build_objective, the batch, the CLI.

Each check compares against the same call with the schedule's weights for the input's observed fraction, computed
by hand from the mask, as explicit :class:`~sparsedepth.Weights`.
"""

import json
import warnings

import numpy as np
import pytest

import sparsedepth as sd
import sparsedepth.objective.weights as weights_module
from conftest import make_scene
from sparsedepth.batch import BatchOptions
from sparsedepth.batch.csvlog import fingerprint
from sparsedepth.batch.evaluate import evaluate_frame
from sparsedepth.complete import main

# anchors far apart, so that the weights of 2 % and of 8 % observed differ in every scheduled field
LOW = sd.DEFAULT_WEIGHTS.replace(delta=1e-4, kappa=10.0, beta_image=1e-3, beta_second=1e-4,
                                 beta_second_image=0.005, beta_local_linear=0.004, local_linear_eps=2e-5)
HIGH = sd.DEFAULT_WEIGHTS.replace(delta=4e-3, kappa=40.0, beta_image=4e-3, beta_second=8e-4,
                                  beta_second_image=0.02, beta_local_linear=0.02, local_linear_eps=5e-6)
SCHEDULE = sd.DensitySchedule.from_weights(((0.01, LOW), (0.1, HIGH)))


@pytest.fixture
def default_schedule(monkeypatch):
    """The library's default schedule replaced by :data:`SCHEDULE` for one test."""
    monkeypatch.setattr(weights_module, "DEFAULT_SCHEDULE", SCHEDULE)
    return SCHEDULE


def _input(fraction=0.05, seed=0, shape=(40, 60)):
    image, depth = make_scene(shape, seed=seed)
    sparse, mask = sd.sample_depth(depth, fraction=fraction, seed=seed)
    return image, sparse, mask


def _complete(*args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        return sd.complete_depth(*args, **kwargs)


def test_observed_fraction_counts_the_mask():
    mask = np.zeros((4, 5), dtype=bool)
    mask[0, :3] = True
    assert sd.observed_fraction(mask) == 3 / 20
    assert sd.observed_fraction(np.zeros((0, 3), dtype=bool)) == 0.0


def test_resolve_weights_of_each_kind():
    assert sd.resolve_weights(None, 0.01) == sd.default_weights(0.01)
    assert sd.resolve_weights(SCHEDULE, 0.1) == HIGH
    assert sd.resolve_weights(SCHEDULE, 0.0) == LOW  # no observation: the caller's error, not the schedule's
    given = sd.Weights(gamma=0.0, delta=0.5)
    assert sd.resolve_weights(given, 0.05) is given
    with pytest.raises(TypeError, match="DensitySchedule"):
        sd.resolve_weights({"delta": 1.0}, 0.05)


def test_schedule_replace_fixes_fields_at_every_density():
    fixed = SCHEDULE.replace(delta=0.25, gamma=0.5)
    for fraction in (0.005, 0.03, 0.2):
        w, before = fixed.weights(fraction), SCHEDULE.weights(fraction)
        assert (w.delta, w.gamma) == (0.25, 0.5)
        assert w.kappa == before.kappa and w.beta_image == before.beta_image
    with pytest.raises(TypeError):
        SCHEDULE.replace(not_a_field=1.0)
    with pytest.raises(ValueError):
        SCHEDULE.replace(delta=-1.0)


def test_schedules_with_the_same_anchors_hash_alike():
    again = sd.DensitySchedule.from_weights(((0.01, LOW), (0.1, HIGH)))
    assert again == SCHEDULE and hash(again) == hash(SCHEDULE)
    assert SCHEDULE.replace(delta=1.0) != SCHEDULE
    assert len({SCHEDULE, again, SCHEDULE.replace(delta=1.0)}) == 2


@pytest.mark.parametrize("fraction", [0.02, 0.08])
def test_complete_depth_without_weights_solves_with_the_schedule_at_the_observed_fraction(default_schedule, fraction):
    image, sparse, mask = _input(fraction)
    expected = SCHEDULE.weights(mask.sum() / mask.size)
    assert expected != LOW and expected != HIGH
    result = _complete(image, sparse, mask)
    explicit = _complete(image, sparse, mask, weights=expected)
    assert result.weights == expected
    np.testing.assert_array_equal(result.depth, explicit.depth)


def test_a_given_schedule_and_given_weights(monkeypatch):
    image, sparse, mask = _input(0.05)
    fraction = mask.sum() / mask.size
    assert _complete(image, sparse, mask, weights=SCHEDULE).weights == SCHEDULE.weights(fraction)
    given = sd.Weights(gamma=0.0, delta=0.02)
    assert _complete(image, sparse, mask, weights=given).weights == given
    with pytest.raises(TypeError, match="weights"):
        _complete(image, sparse, mask, weights={"delta": 0.02})


def test_the_weights_are_chosen_once_from_all_samples_with_uncertainty(default_schedule):
    image, sparse, mask = _input(0.08)
    result = _complete(image, sparse, mask, uncertainty=True)
    assert result.weights == SCHEDULE.weights(mask.sum() / mask.size)
    assert result.uncertainty is not None


def test_the_fast_mode_without_weights_uses_fast_weights_and_given_weights_as_given(default_schedule):
    image, sparse, mask = _input(0.05, shape=(48, 64))
    assert _complete(image, sparse, mask, quality="fast").weights == sd.FAST_WEIGHTS
    given = sd.DEFAULT_WEIGHTS.replace(delta=0.01)
    assert _complete(image, sparse, mask, quality="fast", weights=given).weights == given


def test_build_objective_without_weights_matches_the_scheduled_weights(default_schedule):
    image, sparse, mask = _input(0.08)
    objective, coarse, _ = sd.build_objective(image, sparse, mask)
    explicit, coarse_explicit, _ = sd.build_objective(image, sparse, mask,
                                                      weights=SCHEDULE.weights(mask.sum() / mask.size))
    z = np.random.default_rng(3).random(mask.shape) + 1.0
    assert objective.value(z) == explicit.value(z)
    np.testing.assert_array_equal(coarse, coarse_explicit)


def test_evaluate_frame_schedules_completion_and_keeps_hole_filling_on_the_constant_defaults(default_schedule):
    image, depth = make_scene((40, 60))
    outcome = evaluate_frame(image, depth, keep_fraction=0.08, seed=1)
    assert outcome.result.weights == SCHEDULE.weights(outcome.observed.mean())
    raw = depth.copy()
    raw[5:15, 10:30] = np.nan
    filled = evaluate_frame(image, raw, task="fill", fill_method="complete")
    assert filled.result.weights == sd.DEFAULT_WEIGHTS


def test_batch_options_take_none_a_schedule_or_weights_and_fingerprint_them():
    assert BatchOptions().weights is None
    assert BatchOptions(weights=SCHEDULE).weights == SCHEDULE
    with pytest.raises(TypeError, match="DensitySchedule"):
        BatchOptions(weights={"delta": 1.0})
    prints = [json.dumps(fingerprint([], BatchOptions(weights=w)), sort_keys=True)
              for w in (None, SCHEDULE, sd.DEFAULT_WEIGHTS)]
    assert len(set(prints)) == 3
    stored = fingerprint([], BatchOptions())["options"]["weights"]
    assert stored["density_schedule"] == {f"{f:g}": dict(v) for f, v in sd.DEFAULT_SCHEDULE.anchors}


@pytest.fixture
def scene(tmp_path):
    import imageio.v3 as iio

    image, depth = make_scene((40, 60))
    iio.imwrite(tmp_path / "rgb.png", image)
    sparse, _ = sd.sample_depth(depth, fraction=0.08, seed=1)
    sd.write_depth(tmp_path / "sparse.png", sparse, scale=1000)
    return tmp_path


def _report(folder, capsys, *extra):
    rc = main(["--image", str(folder / "rgb.png"), "--depth", str(folder / "sparse.png"), "--depth-scale", "mm",
               "--json", str(folder / "m.json"), "-q", *extra])
    assert rc == 0, capsys.readouterr().err
    return json.loads((folder / "m.json").read_text())


def test_cli_reports_the_observed_fraction_and_the_scheduled_weights(scene, capsys, default_schedule):
    report = _report(scene, capsys)
    expected = SCHEDULE.weights(report["observed_fraction"])
    assert report["observed"] / (40 * 60) == pytest.approx(report["observed_fraction"], rel=1e-12)
    assert report["weights_source"].startswith("DEFAULT_SCHEDULE")
    for name in ("delta", "kappa", "beta_image", "beta_local_linear"):
        assert report["weights"][name] == pytest.approx(getattr(expected, name), rel=1e-12)
    assert set(report["weights_settings"]["density_schedule"]) == {"0.01", "0.1"}
    assert report["weights_settings"] == weights_module.weights_settings(SCHEDULE)


def test_cli_weight_options_fix_their_field_and_keep_the_schedule_elsewhere(scene, capsys, default_schedule):
    report = _report(scene, capsys, "--delta", "0.03")
    expected = SCHEDULE.replace(delta=0.03).weights(report["observed_fraction"])
    assert report["weights"]["delta"] == 0.03
    assert report["weights"]["kappa"] == pytest.approx(expected.kappa, rel=1e-12)
    assert report["weights_given"] == {"delta": 0.03}
    fast = _report(scene, capsys, "--fast", "--delta", "0.03")
    assert fast["weights"]["delta"] == 0.03 and fast["weights"]["kappa"] == sd.FAST_WEIGHTS.kappa
    assert fast["weights_source"] == "FAST_WEIGHTS with the weight options"
