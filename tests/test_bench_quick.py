"""Smoke tests of the benchmark scripts in --quick mode (tiny frames, one seed; seconds)."""

import importlib
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

import sparsedepth as sd

REPO = Path(__file__).resolve().parents[1]


def load(name):
    """The benchmark module ``bench.<name>`` (run from the repository root as ``python -m bench.<name>``)."""
    return importlib.import_module(f"bench.{name}")


def first_table(markdown):
    """Header and rows of the first markdown table of ``markdown``."""
    lines = markdown.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| "))
    block = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        block.append([c.strip() for c in line.strip("|").split("|")])
    return block[0], block[2:]


def finite(row_value):
    return all(math.isfinite(v) for v in (row_value if isinstance(row_value, tuple) else (row_value,)))


def test_sparsity_quick_table_and_completion_beats_nearest_on_planes():
    sparsity = load("sparsity")
    text, rows = sparsity.run(["--quick"])
    header, body = first_table(text)
    assert header[:3] == ["observed", "method", "RMSE"] and len(header) == 9
    assert [(r[0], r[1]) for r in body] == [(f, m) for f in ("1%", "5%", "10%") for m in ("nearest", "ours")]
    assert len(rows) == 6 and all(finite(r[k]) for r in rows for k in ("rmse", "mae", "rel", "delta1", "runtime"))
    H = sparsity.H
    planes = H.synthetic_frame()
    for seed in (0, 1):
        ours = H.evaluate(H.ours(), planes, fraction=0.05, seed=seed).metrics.rmse
        nearest = H.evaluate(H.NEAREST, planes, fraction=0.05, seed=seed).metrics.rmse
        assert ours < 0.95 * nearest


def test_baselines_quick_has_every_method_and_linear_exact_on_a_plane():
    baselines = load("baselines")
    text, rows = baselines.run(["--quick"])
    header, body = first_table(text)
    methods = ["nearest", "linear (griddata)", "biharmonic (skimage)", "colorization (Levin/NYU)", "ours"]
    assert [r[1] for r in body] == methods * 3
    assert all(finite(r["rmse"]) and finite(r["rmse_ratio"]) for r in rows)
    assert all(r["rmse_ratio"] == (1.0, 0.0) for r in rows if r["method"] == "nearest")
    # the harness scores hidden pixels only: an affine plane is reproduced by the linear fill inside the hull,
    # so its RMSE there is far below the nearest fill's
    H = baselines.H
    ii, jj = np.mgrid[0:40, 0:50]
    plane = H.FrameData("plane", np.zeros((40, 50, 3), np.uint8), 2.0 + 0.03 * ii + 0.02 * jj)
    lin = H.evaluate(H.LINEAR, plane, fraction=0.2, seed=0).metrics.rmse
    nn = H.evaluate(H.NEAREST, plane, fraction=0.2, seed=0).metrics.rmse
    assert lin < 0.2 * nn


def test_ablation_quick_variants_and_data_only_equals_nearest():
    ablation = load("ablation")
    text, rows = ablation.run(["--quick"])
    header, body = first_table(text)
    labels = [r[0] for r in body]
    assert labels[0] == "data only (α, δ)" and any(lbl.startswith("full objective") for lbl in labels)
    assert any("beta_second =" in lbl for lbl in labels) and any("beta_image =" in lbl for lbl in labels)
    assert all(finite(r["rmse"]) for r in rows)
    # data + nearest prior and no smoothness: the minimiser at hidden pixels is the nearest fill
    H = ablation.H
    w = dict(ablation.variants())["data only (α, δ)"]
    for frame in H.quick_frames():
        a = H.evaluate(H.ours("data", weights=w), frame, fraction=0.05, seed=0).metrics.rmse
        b = H.evaluate(H.NEAREST, frame, fraction=0.05, seed=0).metrics.rmse
        assert a == pytest.approx(b, rel=1e-6)


def test_ablation_rows_of_the_local_linear_windows_carry_a_ridge():
    """Each window term is ablated at a used weight with the eps that goes with it (the constant defaults leave
    the cross and 2x2 terms at 0: their rows take the density schedule's weight and eps at the ablation's 5 %)."""
    ablation = load("ablation")
    from sparsedepth.objective.weights import DEFAULT_SCHEDULE, LOCAL_LINEAR_FIELDS, resolve_weights
    scheduled = resolve_weights(DEFAULT_SCHEDULE, ablation.FRACTION)
    rows = dict(ablation.variants())
    for field in LOCAL_LINEAR_FIELDS:
        (label, w), = [(lbl, w) for lbl, w in rows.items() if lbl.startswith("paper + ") and getattr(w, field) > 0]
        source = sd.DEFAULT_WEIGHTS if getattr(sd.DEFAULT_WEIGHTS, field) > 0 else scheduled
        assert getattr(w, field) == getattr(source, field) > 0
        assert w.local_linear_eps == source.local_linear_eps > 0
        assert f"local_linear_eps = {source.local_linear_eps:g}" in label


def test_solvers_quick_gaps_and_plots(tmp_path):
    pytest.importorskip("matplotlib")
    solvers = load("solvers")
    text, rows = solvers.run(["--quick"], plot_dir=tmp_path)
    header, body = first_table(text)
    assert "gap to best" in header and "time × L-BFGS-B" in header
    got = {(r["group"], r["solver"]) for r in rows}
    expected = {(g, s) for g, _, ss in solvers.groups() for s in ss}
    assert got == expected
    for r in rows:
        assert r["gap"][0] >= 0 and finite(r["objective"]) and finite(r["rmse"])
        if r["solver"] == "lbfgsb":
            assert r["time_ratio"] == pytest.approx(1.0)
        if r["solver"] == "direct":
            assert r["gap_max"] < 1e-8  # exact on the quadratic problem
        if r["solver"] == "amg":
            # its default stop is an RMS remaining depth change of 3e-4 of the depth scale, not a residual of 1e-8:
            # F − F* = ‖z − z*‖²_A, measured 1.1e-4 of F here with the default local-linear term (its stiffer
            # directions weigh the same depth change more), 7.6e-5 without it
            assert r["gap_max"] < 3e-4
    assert (tmp_path / "solver_objective_vs_iter.png").stat().st_size > 1000
    assert (tmp_path / "solver_objective_vs_time.png").stat().st_size > 1000


def test_protocol_quick_crop_and_counts():
    protocol = load("protocol")
    text, rows = protocol.run(["--quick"])
    header, body = first_table(text)
    assert header[2:5] == ["RMSE (m)", "REL", "δ<1.25"]
    assert {int(r[0]) for r in body} == set(protocol.QUICK_COUNTS) and len(body) == 10
    assert all(finite(r["rmse"]) and 0 <= r["delta1"][0] <= 1 for r in rows)
    f = protocol.protocol_frame(protocol.H.synthetic_frame(), (60, 80), (57, 76))
    assert f.depth.shape == (57, 76) and f.image.shape == (57, 76, 3) and f.image.dtype == np.uint8
    # nearest-neighbour resize never invents a depth value
    assert set(np.unique(f.depth[np.isfinite(f.depth)])) <= set(np.unique(protocol.H.synthetic_frame().depth))


def test_run_all_quick_writes_every_section(tmp_path):
    run_all = load("run_all")
    out = tmp_path / "results.md"
    have_matplotlib = importlib.util.find_spec("matplotlib") is not None
    extra = [] if have_matplotlib else ["--no-plot"]
    assert run_all.main(["--quick", "--jobs", "1", "--out", str(out), *extra]) == 0
    text = out.read_text()
    assert text.count("\n## ") == 6 and text.count("\nHeadline") == 5 and "Command: `python -m bench.sparsity --quick`" in text
    assert (tmp_path / "solver_objective_vs_iter.png").exists() == have_matplotlib


def test_run_all_without_matplotlib_stops_before_running_anything(monkeypatch, tmp_path, capsys):
    run_all = load("run_all")
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "matplotlib" else real(name, *a))
    out = tmp_path / "results.md"
    assert run_all.main(["--quick", "--jobs", "1", "--out", str(out)]) == 2
    assert not out.exists()
    assert "--no-plot" in capsys.readouterr().err


def test_committed_results_were_made_with_the_current_defaults():
    """docs/results.md records the default weights of its run: they must be today's defaults.

    A run started before a change of the defaults and committed after it would leave the README's figures
    without a source; this catches that (regenerate with ``python -m bench.run_all``).
    """
    import re

    import sparsedepth as sd

    harness = load("harness")  # the formatting run_all writes with
    text = (REPO / "docs" / "results.md").read_text()
    recorded = re.findall(r"[Dd]efault weights at run time: (.*?)\.\n", text)
    recorded += re.findall(r"defaults at run time: (.*?)\):", text)
    assert len(recorded) >= 2, "docs/results.md no longer records its default weights"
    assert set(recorded) == {harness.weights_markdown(sd.DEFAULT_SCHEDULE)}


def test_uncertainty_quick_ratios_against_a_direct_computation():
    uncertainty = load("uncertainty")
    text, records = uncertainty.run(["--quick"])
    assert "## Measured on the report frames" in text and "$" not in text.split("## Measured")[0]
    assert len(records) == 6
    for r in records:
        assert 0 < r["ranking"]["true error"] <= r["ranking"]["ours"] <= 1.5
        assert 0 <= r["cover1"] <= r["cover2"] <= 1 and r["cost"] > 0
    # the ranking ratio by hand: errors 1..8, the score puts 1, 2, 7, 8 in the better half
    errors = np.arange(1.0, 9.0)
    score = np.array([0, 1, 9, 9, 9, 9, 2, 3])
    expected = np.sqrt(np.mean(np.array([1, 2, 7, 8.0]) ** 2)) / np.sqrt(np.mean(errors ** 2))
    assert uncertainty.ranking_ratio(errors, score) == pytest.approx(expected)


def test_committed_uncertainty_doc_is_a_full_run():
    text = (REPO / "docs" / "uncertainty.md").read_text()
    assert "Command: `python -m bench.uncertainty`" in text or "Command: `python -m bench.uncertainty --out" in text
    assert "Quick mode" not in text


def test_registration_calibration_sums_the_densest_inputs_errors_by_sample_count():
    """The calibrated shift: each densest input's error map weighted by its sample count; sparser inputs ignored."""
    registration = load("registration")
    import sparsedepth as sd

    class Fake:
        def __init__(self, fraction, errors, samples):
            self.fraction = fraction
            self.estimate = sd.ImageShift(shift=(0, 0), errors=np.asarray(errors, float), gain=1.0, samples=samples)

    centre_wins = np.array([[5.0, 5, 5], [5, 1, 5], [5, 5, 5]])
    corner_wins = np.array([[0.5, 5, 5], [5, 2, 5], [5, 5, 5]])
    # a sparse input that prefers the corner strongly is ignored; the two dense ones weigh 30 and 10 samples
    inputs = [Fake(0.01, np.full((3, 3), 9.0) - 8.9 * (np.arange(9) == 0).reshape(3, 3), 100),
              Fake(0.1, centre_wins, 30), Fake(0.1, corner_wins, 10)]
    estimate = registration.calibrated_estimate(inputs)
    np.testing.assert_allclose(estimate.errors, (30 * centre_wins + 10 * corner_wins) / 40)
    assert estimate.samples == 40 and estimate.best == (0, 0) and estimate.gain == pytest.approx(1.0)
    inputs[1] = Fake(0.1, centre_wins, 1)
    estimate = registration.calibrated_estimate(inputs)
    assert estimate.best == (-1, -1) and estimate.gain == pytest.approx((1 + 20) / (5 + 5))
    assert estimate.shift_at(2.0) == (-1, -1) and estimate.shift_at(2.2) == (0, 0)


def quick_report(bench, tmp_path, *extra):
    """The report a bench module's ``--quick`` run on the Teddy frame writes (skips without ``../shared``)."""
    if not importlib.import_module("bench.frames").available(["middlebury2003/teddy"]):
        pytest.skip("../shared/data is not beside the repository")
    out = tmp_path / "report.md"
    assert bench.main(["--quick", *extra, "--out", str(out)]) == 0
    return out.read_text()


def test_default_runtime_quick_writes_the_ratio_of_the_summed_times(tmp_path):
    """Σ defaults / Σ baseline, per frame and over two passes: a weighted mean of each pass's own ratio."""
    bench = load("default_runtime")
    text = quick_report(bench, tmp_path, "--repeats", "2")
    rows = [[c.strip().strip("*`") for c in line.split("|")[1:-1]] for line in text.splitlines()
            if line.startswith("| `") or line.startswith("| all")]
    assert [r[0] for r in rows] == ["middlebury2003/teddy", "all"]
    assert rows[0][1:] == rows[1][1:]  # one frame: the total is that frame
    baseline, defaults, ratio, without, without_ratio = (float(c) for c in rows[0][1:])
    assert baseline > 0 and defaults > 0 and without > 0
    for seconds, shown in ((defaults, ratio), (without, without_ratio)):
        # every cell is rounded to 0.01: the ratio of the unrounded times lies within the rounded cells' bounds
        assert (seconds - 0.005) / (baseline + 0.005) - 0.005 <= shown <= (seconds + 0.005) / (baseline - 0.005) + 0.005
    per_pass = next(line for line in text.splitlines() if line.startswith("Per pass (2)"))
    walls = [float(pair.split("/")[0]) for pair in per_pass.split(": ", 1)[1].rstrip(".").split(", ")]
    assert len(walls) == 2
    assert min(walls) - 0.01 <= ratio <= max(walls) + 0.01
    with pytest.raises(SystemExit):
        bench.main(["--quick", "--repeats", "0"])


def test_default_runtime_without_local_linear_is_the_defaults_with_that_term_off():
    """At any observed fraction, every field as in the library's defaults but the local-linear weights 0."""
    bench = load("default_runtime")
    sd = importlib.import_module("sparsedepth")
    off = dict(beta_local_linear=0, beta_local_linear_cross=0, beta_local_linear_2x2=0)
    for fraction in (0.001, 0.003, 0.007, 0.01, 0.03, 0.05, 0.1, 0.5):
        assert bench.WITHOUT_LOCAL_LINEAR.weights(fraction) == sd.default_weights(fraction).replace(**off)
    assert [label for label, _ in bench.SETTINGS][-1] == "baseline"


def test_interpolation_quick_compares_both_on_both_objectives(tmp_path):
    """Each objective's total row sums its frame rows; the two depth-rule solutions agree within the rule's scale."""
    rows = [[c.strip().strip("*`") for c in line.split("|")[1:-1]]
            for line in quick_report(load("interpolation"), tmp_path).splitlines()
            if line.startswith("| `") or line.startswith("| all")]
    sd = importlib.import_module("sparsedepth")
    frame = importlib.import_module("bench.harness").load_frame("middlebury2003/teddy", 4)
    sparse, mask = sd.sample_depth(frame.depth, fraction=0.05, seed=0)
    points = len(sd.build_objective(frame.image, sparse, mask)[0].normal_stencil()[0])  # the defaults' stencil
    assert [r[1] for r in rows] == [f"defaults ({points}-point)", "baseline (13-point)"] * 2
    for frame_row, total_row in zip(rows[:2], rows[2:]):
        assert frame_row[2:7] == total_row[2:7]  # one frame: the totals are that frame
        for cell in frame_row[2:4]:
            depth_rule, residual = (int(c) for c in cell.split(" / "))
            assert 0 < depth_rule <= residual  # the depth rule stops no later than the residual rule
        assert float(frame_row[7]) < 10 * 3e-4  # DEFAULT_DEPTH_RTOL: both solutions are the same answer


def test_registration_quick_tables_hold_what_their_headers_say(tmp_path):
    registration = load("registration")
    frames = importlib.import_module("bench.frames")
    if len(frames.available(["middlebury2001/tsukuba", "tum/0"])) < 2:
        pytest.skip("../shared/data is not beside the repository")
    out = tmp_path / "registration.md"
    # --max-shift 1: 9 candidate shifts per input instead of 25, the same tables
    assert registration.main(["--quick", "--max-shift", "1", "--out", str(out)]) == 0
    text = out.read_text()

    def table_after(title):
        lines = text.split(title, 1)[1].splitlines()
        lines = lines[next(k for k, line in enumerate(lines) if line.startswith("|")):]  # the first table after it
        table = lines[:next((k for k, line in enumerate(lines) if not line.startswith("|")), len(lines))]
        return [[c.strip() for c in line.strip("|").split("|")] for line in table][2:]

    per_dataset = table_after("Per dataset of the report frames:")
    assert [row[0] for row in per_dataset] == ["TUM"] and len(per_dataset[0]) == 5
    per_tuning_frame = table_after("Per tuning frame")
    assert [row[0] for row in per_tuning_frame] == ["`middlebury2001/tsukuba`"] and len(per_tuning_frame[0]) == 4
