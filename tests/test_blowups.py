"""sparsedepth.blowups: planted spikes and mid-jump values are flagged, ramps and clean steps are not, removal and
replacement give what an independent computation gives, and bad arguments are refused naming the argument."""

import importlib

import numpy as np
import pytest

from sparsedepth.blowups import (BLOWUP_GAP, BLOWUP_MISFIT, blowup_evidence, flag_blowups, judge_blowups,
                                 remove_blowups)

SHAPE = (40, 50)


def _uniform_samples(depth, fraction=0.1, seed=0):
    mask = np.random.default_rng(seed).random(depth.shape) < fraction
    return np.where(mask, depth, 0.0), mask


def _ramp(slope_rows=0.02, slope_cols=0.01):
    rows, cols = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    return 2.0 + slope_rows * rows + slope_cols * cols


def _step(near=1.0, far=4.0, edge_col=25):
    return np.where(np.arange(SHAPE[1]) < edge_col, near, far) * np.ones((SHAPE[0], 1))


def _unobserved(mask, candidates):
    return [tuple(p) for p in candidates if not mask[tuple(p)]]


@pytest.mark.parametrize("slopes", [(0.02, 0.01), (0.2, 0.05)], ids=["gentle", "steep"])
def test_a_smooth_ramp_is_not_flagged(slopes):
    depth = _ramp(*slopes)
    sparse, mask = _uniform_samples(depth)
    assert not flag_blowups(depth, sparse, mask).any()


@pytest.mark.parametrize("pattern", ["uniform", "scan lines"])
def test_a_floor_seen_in_perspective_is_not_flagged(pattern):
    """A plane of the scene: affine in inverse depth (from 20 m at the top, 4 % a row, to 7 m), sampled uniformly or
    every 8 rows."""
    rows, cols = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    depth = 1.0 / (0.05 + 0.002 * rows + 0.0005 * cols)
    mask = np.random.default_rng(0).random(SHAPE) < 0.1 if pattern == "uniform" else rows % 8 == 3
    assert not flag_blowups(depth, np.where(mask, depth, 0.0), mask).any()


def test_a_clean_step_is_not_flagged():
    depth = _step()
    sparse, mask = _uniform_samples(depth)
    assert not flag_blowups(depth, sparse, mask).any()


def test_a_spike_planted_on_a_ramp_is_flagged_and_nothing_else():
    depth = _ramp()
    sparse, mask = _uniform_samples(depth)
    spikes = _unobserved(mask, [(10, 10), (20, 30), (30, 40)])
    completed = depth.copy()
    for (r, c), factor in zip(spikes, (1.5, 0.6, 2.0)):
        completed[r, c] *= factor
    flagged = flag_blowups(completed, sparse, mask)
    assert sorted(map(tuple, np.argwhere(flagged))) == sorted(spikes)


def test_values_in_the_middle_of_a_depth_jump_are_flagged_and_the_sides_are_not():
    """The blow-up of issue 46: a column of pixels along a depth edge halfway between the two sides (samples every
    3 pixels, so that two sample columns on each side show that the values are a step, not a ramp)."""
    depth = _step(1.0, 4.0, edge_col=26)
    mask = np.zeros(SHAPE, dtype=bool)
    mask[::3, ::3] = True
    sparse = np.where(mask, depth, 0.0)
    completed = depth.copy()
    completed[5:35, 25] = 2.5
    flagged = flag_blowups(completed, sparse, mask)
    assert flagged[5:35, 25].all()
    evidence = blowup_evidence(completed, sparse, mask)
    inside = np.zeros(SHAPE, dtype=bool)
    inside[evidence["rows"], evidence["cols"]] = evidence["inside"]
    assert inside[5:35, 25].all()    # inside the range of the nearby samples: a local min/max test passes them
    flagged[5:35, 25] = False
    assert not flagged.any()


def test_samples_and_nan_pixels_are_never_flagged():
    depth = _step()
    sparse, mask = _uniform_samples(depth)
    completed = depth.copy()
    completed[mask] = 2.5          # a completion that moved its samples: not this check's business
    completed[0, 25] = np.nan
    flagged = flag_blowups(completed, sparse, mask)
    assert not flagged[mask].any() and not flagged[0, 25]


def test_a_larger_gap_flags_fewer_pixels_and_the_evidence_judges_like_flag_blowups():
    depth = _step()
    sparse, mask = _uniform_samples(depth)
    completed = depth + np.random.default_rng(1).uniform(-1.5, 1.5, SHAPE) * ~mask
    evidence = blowup_evidence(completed, sparse, mask, gap=0.05)
    previous = None
    for gap in (0.05, 0.1, 0.3):
        flagged = flag_blowups(completed, sparse, mask, gap=gap)
        judged = np.zeros(SHAPE, dtype=bool)
        judged[evidence["rows"], evidence["cols"]] = judge_blowups(evidence, gap=gap, misfit=BLOWUP_MISFIT)
        np.testing.assert_array_equal(judged, flagged)
        if previous is not None:
            assert not (flagged & ~previous).any()
        previous = flagged


def test_the_gap_is_measured_against_each_of_the_nearest_samples():
    """A pixel whose value equals one of its 8 nearest samples' is not flagged, however far the others are."""
    sparse, mask = np.zeros((5, 5)), np.zeros((5, 5), dtype=bool)
    points = {(0, 0): 1.0, (0, 4): 1.0, (4, 0): 9.0, (4, 4): 9.0, (2, 0): 5.0, (0, 2): 1.0, (4, 2): 9.0, (2, 4): 5.0}
    for p, v in points.items():
        sparse[p], mask[p] = v, True
    completed = np.where(mask, sparse, 5.0)
    completed[2, 2] = 5.0 * (1 + 0.5 * BLOWUP_GAP)
    assert not flag_blowups(completed, sparse, mask)[2, 2]
    completed[2, 2] = 7.0
    assert flag_blowups(completed, sparse, mask)[2, 2]


def test_remove_blowups_sets_nan_or_the_nearest_samples_value_without_touching_the_input():
    depth = _step()
    sparse, mask = _uniform_samples(depth)
    completed = depth.copy()
    flagged = np.zeros(SHAPE, dtype=bool)
    flagged[3:6, 20:30] = True
    flagged &= ~mask
    before = completed.copy()
    removed = remove_blowups(completed, flagged)
    np.testing.assert_array_equal(completed, before)
    assert np.isnan(removed[flagged]).all()
    np.testing.assert_array_equal(removed[~flagged], completed[~flagged])
    replaced = remove_blowups(completed, flagged, replace="nearest", sparse_depth=sparse, mask=mask)
    sample_points = np.argwhere(mask)
    for r, c in np.argwhere(flagged):
        distances = np.hypot(*(sample_points - (r, c)).T)
        nearest_values = sparse[tuple(sample_points[distances == distances.min()].T)]
        assert replaced[r, c] in nearest_values
    np.testing.assert_array_equal(replaced[~flagged], completed[~flagged])


@pytest.mark.parametrize("call, kind, name", [
    (lambda d, s, m: flag_blowups(d[0], s, m), ValueError, "depth"),
    (lambda d, s, m: flag_blowups(d[:-1], s, m), ValueError, "sparse_depth"),
    (lambda d, s, m: flag_blowups(d, s, m[:-1]), ValueError, "mask"),
    (lambda d, s, m: flag_blowups(d.astype(str), s, m), TypeError, "depth"),
    (lambda d, s, m: flag_blowups(d, s, m, gap=-0.1), ValueError, "gap"),
    (lambda d, s, m: flag_blowups(d, s, m, gap="0.1"), TypeError, "gap"),
    (lambda d, s, m: flag_blowups(d, s, m, misfit=0.0), ValueError, "misfit"),
    (lambda d, s, m: flag_blowups(d, s, m, neighbours=2), ValueError, "neighbours"),
    (lambda d, s, m: flag_blowups(d, s, m, neighbours=4.5), ValueError, "neighbours"),
    (lambda d, s, m: blowup_evidence(d, s, m, neighbours=1), ValueError, "neighbours"),
    (lambda d, s, m: blowup_evidence(d, s, m, gap=np.inf), ValueError, "gap"),
    (lambda d, s, m: flag_blowups(d, np.where(np.arange(d.size).reshape(d.shape) < 2, 1.0, 0.0)), ValueError,
     "sparse_depth"),
    (lambda d, s, m: remove_blowups(d, m.astype(int)), ValueError, "flagged"),
    (lambda d, s, m: remove_blowups(d, m[:-1]), ValueError, "flagged"),
    (lambda d, s, m: remove_blowups(d, m, replace="zero"), ValueError, "replace"),
    (lambda d, s, m: remove_blowups(d, m, replace="nearest"), ValueError, "sparse_depth"),
    (lambda d, s, m: remove_blowups(d, m, replace="nearest", sparse_depth=s[:-1]), ValueError, "sparse_depth"),
])
def test_bad_arguments_are_refused_naming_them(call, kind, name):
    depth = _step()
    sparse, mask = _uniform_samples(depth)
    with pytest.raises(kind, match=name):
        call(depth, sparse, mask)


def test_the_bench_chooses_the_largest_error_share_beyond_the_pixel_share_among_few_false_flags():
    blowups_bench = importlib.import_module("bench.blowups")
    grid = [(g, m) for g in blowups_bench.GAPS for m in blowups_bench.MISFITS]
    scores = {key: {"flagged": 0.01, "error_share": 0.2, "false": 0.0} for key in grid}
    scores[grid[0]] = {"flagged": 0.05, "error_share": 0.9, "false": 0.5}      # most error, too many false flags
    scores[grid[1]] = {"flagged": 0.30, "error_share": 0.6, "false": 0.0}      # 30 % beyond its pixel share
    scores[grid[2]] = {"flagged": 0.02, "error_share": 0.5, "false": 0.05}     # 48 %: the choice
    scores[grid[-1]] = {"flagged": 0.01, "error_share": 0.8, "false": 0.0}     # 79 %, but too slow
    scores.update({("cost", g): 0.05 for g in blowups_bench.GAPS})
    scores["cost", grid[-1][0]] = 0.5
    chosen, rows = blowups_bench.choose_thresholds([scores])
    assert chosen == grid[2] and len(rows) == len(grid)


def test_the_bench_quick_run_writes_its_sections():
    page, results = importlib.import_module("bench.blowups").run(["--quick"])
    for title in ("## Calibration", "## The other frames", "Summary"):
        assert title in page
    assert results["chosen"] in [(g, m) for g in importlib.import_module("bench.blowups").GAPS
                                 for m in importlib.import_module("bench.blowups").MISFITS]
