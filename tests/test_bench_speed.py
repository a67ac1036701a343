"""bench.speed and bench.fast_peers: the quick run, and the two filters against hand-made inputs."""

import importlib
import importlib.util

import numpy as np
import pytest

speed = importlib.import_module("bench.speed")
fast_peers = importlib.import_module("bench.fast_peers")

needs_cv2 = pytest.mark.skipif(not fast_peers.available(), reason="opencv-contrib-python-headless (bench extra) missing")


def test_speed_quick_run(tmp_path):
    text, rows = speed.run(["--quick"], figure=tmp_path / "speed.png")
    assert "## Stopping rule of the default solve" in text and "## Fast filters beside ours" in text
    assert "## Iterations by the terms of the objective" in text
    assert "## Where the time goes" in text and "## The default against a direct solve" in text
    for r in rows:
        assert r["rule_met"] and r["its"][0] <= r["its"][1]
        assert r["true_rms"] <= 3 * r["tol"]  # the stated factor of tests/test_depth_stop.py
        assert abs(r["rmse_change"]) < 1e-2
    if fast_peers.available():
        assert "FGS (" in text and "IP-Basic (" in text and "sparsedepth (fast)" in text
        assert "python -m bench.fast_mode" in text  # the fast mode frame by frame is bench.fast_mode's report
        if importlib.util.find_spec("matplotlib") is None:  # the figure is optional (plot extra): said, not drawn
            assert "(matplotlib missing: no figure.)" in text and not (tmp_path / "speed.png").exists()
        else:
            assert (tmp_path / "speed.png").stat().st_size > 1000
    else:
        assert "is not installed" in text


@needs_cv2
def test_fgs_normalized_convolution_keeps_a_constant_and_stays_in_range():
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (30, 40, 3), dtype=np.uint8)
    mask = rng.random((30, 40)) < 0.1
    sparse = np.where(mask, 2.5, np.nan)
    out = fast_peers.fgs_fill(image, sparse, mask, lam=10.0, sigma_color=20.0)
    np.testing.assert_allclose(out, 2.5, rtol=1e-5)  # a weighted mean of equal values
    sparse = np.where(mask, rng.uniform(1, 3, (30, 40)), np.nan)
    out = fast_peers.fgs_fill(image, sparse, mask, lam=10.0, sigma_color=20.0)
    lo, hi = np.nanmin(sparse), np.nanmax(sparse)
    assert np.all((out >= lo - 1e-4) & (out <= hi + 1e-4))  # a convex combination of the samples


@needs_cv2
@pytest.mark.parametrize("kernel", ["full3", "cross5", "diamond7"])
def test_ipbasic_fills_every_pixel_and_keeps_a_constant(kernel):
    rng = np.random.default_rng(1)
    mask = rng.random((30, 40)) < 0.05
    image = np.zeros((30, 40, 3), np.uint8)
    out = fast_peers.ipbasic_fill(image, np.where(mask, 4.0, np.nan), mask, kernel=kernel, blur="gaussian")
    assert np.all(np.isfinite(out)) and out.shape == (30, 40)
    np.testing.assert_allclose(out, 4.0, rtol=1e-5)
    # the dilation of the inverted depth keeps the nearer of two surfaces where they meet
    depth = np.where(np.arange(40) < 20, 1.0, 5.0)[None, :].repeat(30, axis=0)
    out = fast_peers.ipbasic_fill(image, np.where(mask, depth, np.nan), mask, kernel=kernel, blur="none")
    assert np.all((out >= 1.0 - 1e-5) & (out <= 5.0 + 1e-5))


def test_kernels_are_the_named_shapes():
    assert fast_peers._kernel("full5").sum() == 25
    assert fast_peers._kernel("cross5").sum() == 9
    assert fast_peers._kernel("diamond5").sum() == 13  # |i| + |j| <= 2
    assert fast_peers._kernel("diamond7").sum() == 25


def test_fast_mode_quick_run(capsys):
    fast_mode = importlib.import_module("bench.fast_mode")
    assert fast_mode.main(["--quick"]) == 0
    text = capsys.readouterr().out
    assert "| quick | 5% |" in text and "fast / default time" in text
    if fast_peers.available():
        assert "FGS setting picked on the tuning frames" in text



def test_time_breakdown_columns_add_up_to_the_phases():
    time_breakdown = importlib.import_module("bench.time_breakdown")
    from sparsedepth.profiling import PhaseTimes

    times = PhaseTimes()  # hand-made: 1 s of iterations inside 3 s of assembly, 4 s in all
    times._enter("assembly", 0.0)
    times._enter("iterations", 1.0)
    times._leave(2.0)
    times._leave(3.0)
    times.wall = 4.0
    table = time_breakdown.breakdown_table([dict(mode="default", shape=(2, 3), times=times)])
    row = table.splitlines()[-1].split("|")[1:-1]
    header = table.splitlines()[0].split("|")[1:-1]
    cell = dict(zip((h.strip() for h in header), (c.strip() for c in row)))
    assert cell["assembly"] == "2.000" and cell["iterations"] == "1.000" and cell["other"] == "1.000"
    assert cell["not iterations / iterations"] == "3.00" and cell["size"] == "3x2"
