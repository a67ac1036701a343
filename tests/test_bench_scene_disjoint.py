"""bench.scene_disjoint and the scene split of bench.frames: the leave-one-scene-out choice, the README block, a
quick end-to-end run."""

import json

import numpy as np
import pytest

import sparsedepth as sd
from bench import frames as frame_list
from bench import scene_disjoint as sdj


def _scene(name):
    return name.split("/")[0]


def test_loso_choice_by_hand():
    # scene A (two frames) loves candidate x, scenes B and C prefer y
    scores = {("A/1", 0, "x"): 0.1, ("A/1", 0, "y"): 0.9, ("A/2", 0, "x"): 0.2, ("A/2", 0, "y"): 0.8,
              ("B/1", 0, "x"): 0.9, ("B/1", 0, "y"): 0.5,
              ("C/1", 0, "x"): 0.6, ("C/1", 0, "y"): 0.5}
    choice = sdj.loso_choice(scores, ["x", "y"], _scene)
    # held out A: B and C give x 0.75, y 0.5 -> y
    # held out B: A/1, A/2, C/1 give x (0.1+0.2+0.6)/3 = 0.3, y (0.9+0.8+0.5)/3 = 0.733 -> x
    # held out C: A/1, A/2, B/1 give x 0.4, y 0.733 -> x
    assert choice == {"A": "y", "B": "x", "C": "x"}


def test_loso_choice_never_reads_the_held_out_scene():
    rng = np.random.default_rng(3)
    frames = ["A/1", "A/2", "B/1", "C/1", "C/2", "D/1"]
    candidates = ["p", "q", "r"]
    scores = {(f, i, c): float(rng.uniform(0.5, 1.0)) for f in frames for i in range(3) for c in candidates}
    choice = sdj.loso_choice(scores, candidates, _scene)
    for scene in "ABCD":
        for candidate in candidates:  # make the held-out scene adore each candidate in turn
            changed = {k: (0.0 if k[2] == candidate else 10.0) if _scene(k[0]) == scene else v
                       for k, v in scores.items()}
            assert sdj.loso_choice(changed, candidates, _scene)[scene] == choice[scene]


def test_loso_choice_skips_inputs_a_candidate_lacks():
    scores = {("A/1", 0, "x"): 0.5, ("A/1", 0, "y"): 0.6, ("B/1", 0, "x"): 0.9, ("B/1", 0, "y"): 0.2,
              ("B/1", 1, "x"): 0.1}  # y has no score on (B/1, 1): that input is left out of every mean
    assert sdj.loso_choice(scores, ["x", "y"], _scene)["A"] == "y"


def test_loso_folds_keep_each_scene_on_one_side():
    names = ["kitti/0000000005", "tum/0", "kitti/0000000050", "kitti_raw_0023/0000000000", "nyu_metric3d/00000",
             "nyu_metric3d/00050", "nyu_rcnn_depth/demo"]
    folds = frame_list.loso_folds(names)
    assert len(folds) == len({frame_list.scene_of(n) for n in names}) == 5
    for scene, held, others in folds:
        assert held and sorted(held + others) == sorted(names)
        assert {frame_list.scene_of(n) for n in held} == {scene}
        assert scene not in {frame_list.scene_of(n) for n in others}


def test_tune_and_report_frames_share_no_scene():
    tune = {frame_list.scene_of(n) for n in frame_list.TUNE_FRAMES}
    report = {frame_list.scene_of(n) for n in frame_list.REPORT_FRAMES}
    assert tune and report and not tune & report


def test_scan_line_like_masks():
    mask = np.zeros((64, 80), bool)
    mask[3::8] = True
    assert sdj.scan_line_like(mask)
    mask[:, ::2] = False  # half of each line left: still lines
    assert sdj.scan_line_like(mask)
    rng = np.random.default_rng(0)
    uniform = rng.random((64, 80)) < 0.05
    assert not sdj.scan_line_like(uniform)
    few = np.zeros((64, 80), bool)
    few[[5, 30], [7, 60]] = True  # two samples on two rows: not scan lines
    assert not sdj.scan_line_like(few)
    assert not sdj.scan_line_like(np.zeros((4, 4), bool))


def test_dense_end_scales_beta_second_from_its_fraction_up():
    schedule = sd.DensitySchedule.from_weights(((0.01, sd.DEFAULT_WEIGHTS.replace(beta_second=1e-4)),
                                                (0.1, sd.DEFAULT_WEIGHTS.replace(beta_second=2e-4))))
    dense = sdj.dense_end(schedule, 0.5, 10.0)
    assert [f for f, _ in dense.anchors] == [0.01, 0.1, 0.5]
    for fraction in (0.005, 0.01, 0.05, 0.1):
        assert dense.weights(fraction) == schedule.weights(fraction)
    assert dense.weights(0.5).beta_second == pytest.approx(2e-3, rel=1e-12)
    assert dense.weights(0.9).beta_second == pytest.approx(2e-3, rel=1e-12)
    assert 2e-4 < dense.weights(0.2).beta_second < 2e-3
    again = sdj.dense_end(dense, 0.5, 10.0)  # an anchor at the fraction already: replaced, times 10 again
    assert [f for f, _ in again.anchors] == [0.01, 0.1, 0.5]
    assert again.weights(0.5).beta_second == pytest.approx(2e-2, rel=1e-12)
    assert again.weights(0.5).replace(beta_second=0.0) == dense.weights(0.5).replace(beta_second=0.0)


def test_configurations_start_with_the_defaults():
    mask = np.zeros((40, 50), bool)
    mask[::7, ::3] = True
    label, weights_for = sdj.configurations()[0]
    assert weights_for(mask) == sd.default_weights(mask.mean())
    assert len(sdj.configurations()) <= 6


def test_replace_block_replaces_exactly_the_block(tmp_path):
    text = "# Title\n\nbefore\n<!-- scene-disjoint:start -->\nold 1\nold 2\n<!-- scene-disjoint:end -->\nafter\n"
    path = tmp_path / "README.md"
    path.write_text(text)
    new = sdj.replace_block(path.read_text(), ["new a", "", "new b"])
    assert new == ("# Title\n\nbefore\n<!-- scene-disjoint:start -->\nnew a\n\nnew b\n<!-- scene-disjoint:end -->\n"
                   "after\n")
    assert sdj.replace_block(new, ["x"]) == sdj.replace_block(text, ["x"])  # idempotent on the block
    with pytest.raises(ValueError):
        sdj.replace_block("no markers\n", ["x"])
    with pytest.raises(ValueError):
        sdj.replace_block("<!-- scene-disjoint:end -->\n<!-- scene-disjoint:start -->\n", ["x"])


@pytest.mark.skipif(sd.shared_data_dir() is None, reason="the shared frames (../shared/data) are absent")
def test_quick_run_end_to_end(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("top\n<!-- scene-disjoint:start -->\nstale\n<!-- scene-disjoint:end -->\nbottom\n")
    cache, page = tmp_path / "cache.json", tmp_path / "page.md"
    assert sdj.main(["--quick", "--cache", str(cache), "--out", str(page), "--readme", str(readme)]) == 0
    text = page.read_text()
    for scene in ("nyu/bookstore_0001d", "middlebury/tsukuba"):
        assert f"`{scene}`" in text
    lines = readme.read_text().split("\n")
    start, end = lines.index(sdj.MARK_START), lines.index(sdj.MARK_END)
    assert lines[0] == "top" and lines[end + 1] == "bottom" and "stale" not in lines
    assert 0 < end - start - 1 <= 12
    # the cached nearest-fill score is the direct computation's
    name, (label, keywords) = sdj.QUICK_FRAMES[0], next(p for p in sdj.PATTERNS if p[0] == sdj.QUICK_PATTERNS[0])
    image, depth = frame_list.load(name, step=sdj.STEP)
    sparse, mask = sd.sample_depth(depth, image=image, seed=0, **keywords)
    hidden = np.isfinite(depth) & (depth > 0) & ~mask
    direct = np.sqrt(np.mean((sd.nearest_fill(sparse, mask)[hidden] - depth[hidden]) ** 2))
    scores = json.loads(cache.read_text())["scores"]
    assert scores[f"{sdj.input_key(name, label, 0, sdj.STEP)}|nearest"]["rmse"] == pytest.approx(direct, rel=1e-12)
