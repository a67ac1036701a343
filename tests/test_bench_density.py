"""bench.density's coordinate descent on a score made by hand (no completion): it finds the minimiser, stays within
its span and weighs datasets alike."""

import importlib
import math
from types import SimpleNamespace

import pytest

import sparsedepth as sd


def _density():
    return importlib.import_module("bench.density")


def _sample(name, density, index):
    return SimpleNamespace(frame=SimpleNamespace(name=name), density=density, key=(name, density, index))


def _score_of(targets):
    """A score whose minimum over delta is at ``targets[frame]``: |log2(delta / target)| + 1."""
    def ratios(self, sample, weights):
        value = abs(math.log2(weights.delta / targets[sample.frame.name])) + 1.0
        return value, value
    return ratios


def _scored_by(monkeypatch, targets):
    """bench.density with :func:`_score_of` ``targets`` in place of completions."""
    density = _density()
    monkeypatch.setattr(density.Scorer, "ratios", _score_of(targets))
    return density


def test_descent_reaches_each_anchors_minimiser(monkeypatch):
    base = sd.DEFAULT_WEIGHTS.delta
    density = _scored_by(monkeypatch, {"nyu_a/0": base * 4, "kitti/0": base / 2})
    samples = [_sample("nyu_a/0", 0.10, 0), _sample("kitti/0", 0.01, 0)]
    schedule, trace = density.descend(samples, rounds=3, span=64.0)
    assert schedule.weights(0.10).delta == pytest.approx(base * 4, rel=1e-12)
    assert schedule.weights(0.01).delta == pytest.approx(base / 2, rel=1e-12)
    assert trace[-1] == pytest.approx(1.0) and trace == sorted(trace, reverse=True)


def test_descent_stays_within_its_span(monkeypatch):
    base = sd.DEFAULT_WEIGHTS.delta
    density = _scored_by(monkeypatch, {"nyu_a/0": base * 1000})
    schedule, _ = density.descend([_sample("nyu_a/0", 0.05, 0)], rounds=3, span=8.0)
    assert schedule.weights(0.05).delta == pytest.approx(base * 8, rel=1e-12)


def test_balanced_score_counts_each_dataset_once(monkeypatch):
    base = sd.DEFAULT_WEIGHTS.delta
    # three NYU inputs want 4x, one KITTI input wants 1/4x, all at the same density (one anchor decides)
    targets = {"nyu_a/0": base * 4, "nyu_b/1": base * 4, "nyu_c/2": base * 4, "kitti/0": base / 4}
    density = _scored_by(monkeypatch, targets)
    samples = [_sample(name, 0.05, 0) for name in targets]
    scorer = density.Scorer()
    schedule = sd.DensitySchedule.from_weights(((0.05, sd.DEFAULT_WEIGHTS.replace(delta=base * 4)),))
    assert scorer.mean(schedule, samples) == pytest.approx((3 * 1 + 5) / 4)
    assert scorer.mean(schedule, samples, balanced=True) == pytest.approx((1 + 5) / 2)


def test_added_anchor_descends_alone_from_the_lowest_anchors_values(monkeypatch):
    base = sd.DEFAULT_WEIGHTS.delta
    # the sparse input wants 4x the default delta, the 1 % input 1/2x; the 1 % anchor is fixed at 1x
    density = _scored_by(monkeypatch, {"nyu_a/0": base * 4, "kitti/0": base / 2})
    samples = [_sample("nyu_a/0", 0.002, 0), _sample("kitti/0", 0.01, 0)]
    schedule = sd.DensitySchedule.from_weights(((0.01, sd.DEFAULT_WEIGHTS), (0.1, sd.DEFAULT_WEIGHTS)))
    extended, trace = density.extend(schedule, 0.003, samples, rounds=3, span=64.0)
    assert [f for f, _ in extended.anchors] == [0.003, 0.01, 0.1]
    assert extended.anchors[1:] == schedule.anchors  # the other anchors are not tuned
    assert extended.weights(0.002).delta == pytest.approx(base * 4, rel=1e-12)
    assert extended.weights(0.01).delta == pytest.approx(base, rel=1e-12)
    # the first score is the unextended schedule's: both inputs at 1x (|log2 4| + 1 and |log2 1/2| + 1)
    assert trace[0] == pytest.approx(((2 + 1) + (1 + 1)) / 2)
    assert trace[-1] == pytest.approx((1 + 2) / 2)


def test_added_anchor_must_lie_below_the_lowest():
    density = _density()
    schedule = sd.DensitySchedule.from_weights(((0.01, sd.DEFAULT_WEIGHTS),))
    with pytest.raises(ValueError, match="below the lowest"):
        density.extend(schedule, 0.02, [], rounds=1)


def test_schedule_differences_name_each_changed_field_and_anchor():
    density = _density()
    tuned = sd.DensitySchedule.from_weights(((0.01, sd.DEFAULT_WEIGHTS), (0.1, sd.DEFAULT_WEIGHTS)))
    assert density._schedule_differences(tuned, tuned) == []
    library = sd.DensitySchedule.from_weights(((0.003, sd.DEFAULT_WEIGHTS), (0.01, sd.DEFAULT_WEIGHTS.replace(kappa=50)),
                                               (0.1, sd.DEFAULT_WEIGHTS)))
    assert density._schedule_differences(tuned, library) == [
        "an anchor at 0.3 % only in the library", f"1 % kappa = 50 (tuned here {sd.DEFAULT_WEIGHTS.kappa:g})"]


def test_windows_descent_moves_the_window_weights_and_keeps_the_3x3_term_off(monkeypatch):
    density = _density()
    start = density.WINDOWS_START
    assert (start.beta_local_linear, start.beta_local_linear_cross, start.beta_local_linear_2x2) == (
        0.0, sd.DEFAULT_WEIGHTS.beta_local_linear, sd.DEFAULT_WEIGHTS.beta_local_linear)
    assert "beta_local_linear" not in density.WINDOWS_FIELDS
    assert {"beta_local_linear_cross", "beta_local_linear_2x2"} <= set(density.WINDOWS_FIELDS)
    cross, two = start.beta_local_linear_cross / 4, start.beta_local_linear_2x2 * 2

    def ratios(self, sample, weights):  # minimum at (cross, two), whatever the other fields
        value = (abs(math.log2(weights.beta_local_linear_cross / cross))
                 + abs(math.log2(weights.beta_local_linear_2x2 / two)) + 1.0 + 10 * weights.beta_local_linear)
        return value, value
    monkeypatch.setattr(density.Scorer, "ratios", ratios)
    schedule, trace = density.descend([_sample("nyu_a/0", 0.05, 0)], rounds=3, span=8.0, start_weights=start,
                                      fields=density.WINDOWS_FIELDS)
    w = schedule.weights(0.05)
    assert w.beta_local_linear_cross == pytest.approx(cross, rel=1e-12)
    assert w.beta_local_linear_2x2 == pytest.approx(two, rel=1e-12)
    assert w.beta_local_linear == 0.0 and trace[-1] == pytest.approx(1.0)


def test_schedule_differences_name_a_window_weight_one_schedule_does_not_set():
    density = _density()
    library = sd.DensitySchedule.from_weights(((0.01, sd.DEFAULT_WEIGHTS),))
    tuned = sd.DensitySchedule.from_weights(((0.01, sd.DEFAULT_WEIGHTS.replace(beta_local_linear_cross=0.02)),))
    assert density._schedule_differences(tuned, library) == ["1 % beta_local_linear_cross = 0 (tuned here 0.02)"]


def test_quick_windows_run_reports_the_window_weights_and_keeps_the_3x3_term_off(tmp_path):
    """``--local-linear-windows`` end to end on the tiny quick frames: the anchor table lists both window weights
    beside the starting weights, and the 3x3 weight is 0 at every anchor."""
    density = _density()
    out = tmp_path / "density.md"
    # --span 2: one step of 2x either way per weight, so the descent still moves the window weights
    assert density.main(["--quick", "--local-linear-windows", "--span", "2", "--out", str(out)]) == 0
    rows = {cells[0]: cells[1:] for cells in ([c.strip() for c in line.split("|")[1:-1]]
                                              for line in out.read_text().splitlines() if line.startswith("| beta_"))}
    start = density.WINDOWS_START
    assert rows["beta_local_linear"] == ["0"] * 5
    for name in ("beta_local_linear_cross", "beta_local_linear_2x2"):
        assert len(rows[name]) == 5 and float(rows[name][-1]) == getattr(start, name)  # 4 anchors, then the start
        assert all(float(v) > 0 for v in rows[name])
    assert "constant `sd.DEFAULT_WEIGHTS` on cross and 2x2 windows" in out.read_text()
