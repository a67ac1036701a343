"""--uncertainty, --max-uncertainty and --max-relative-uncertainty on the command line: files, the removed pixels,
the statistics on stdout and in the JSON report, and bad input."""

import json

import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd

from conftest import make_scene
from sparsedepth.complete import main

FAST = ["--gamma", "0", "--solver", "direct"]


@pytest.fixture
def files(tmp_path):
    image, depth = make_scene((48, 64))
    iio.imwrite(tmp_path / "rgb.png", image)
    sd.write_depth(tmp_path / "dense.png", depth, scale=1000)
    return tmp_path


def _base(files):
    return ["--image", str(files / "rgb.png"), "--depth", str(files / "dense.png"), "--depth-scale", "mm",
            "--keep-fraction", "0.08", *FAST]


def _library_result(files, **kwargs):
    image = sd.read_image(files / "rgb.png")
    dense = sd.read_depth(files / "dense.png", scale=1000)
    sparse, mask = sd.sample_depth(dense, fraction=0.08, seed=0)
    return sd.complete_depth(image, sparse, mask, weights=sd.DEFAULT_SCHEDULE.replace(gamma=0.0), solver="direct", **kwargs)


def test_uncertainty_file_is_the_library_map(files, capsys):
    rc = main([*_base(files), "--out", str(files / "d.npy"), "--uncertainty", str(files / "u.npy")])
    assert rc == 0
    expected = _library_result(files, uncertainty=True)
    np.testing.assert_allclose(np.load(files / "u.npy"), expected.uncertainty, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.load(files / "d.npy"), expected.depth, rtol=1e-9, atol=1e-12)
    assert "uncertainty over the" in capsys.readouterr().out


def test_stdout_and_json_report_the_same_statistics_over_the_unobserved_pixels(files, capsys):
    """median, 90th and 99th percentiles over the pixels not given as samples, computed here from the map."""
    rc = main([*_base(files), "--uncertainty", str(files / "u.npy"), "--json", str(files / "r.json")])
    assert rc == 0
    sigma = np.load(files / "u.npy")
    _, mask = sd.sample_depth(sd.read_depth(files / "dense.png", scale=1000), fraction=0.08, seed=0)
    median, p90, p99 = np.percentile(sigma[~mask], [50, 90, 99])
    assert np.percentile(sigma, 50) != median  # the observed pixels would change it
    out = capsys.readouterr().out
    assert (f"uncertainty over the {(~mask).sum()} unobserved pixels: median {median:.3g} m, 90th percentile "
            f"{p90:.3g} m, 99th percentile {p99:.3g} m") in out
    report = json.loads((files / "r.json").read_text())["uncertainty"]
    assert report["pixels"] == "unobserved" and report["count"] == (~mask).sum()
    np.testing.assert_allclose([report["median"], report["p90"], report["p99"]], [median, p90, p99], rtol=1e-12)


def test_max_uncertainty_leaves_the_pixels_above_it_missing(files, capsys):
    reference = _library_result(files, uncertainty=True)
    threshold = float(np.percentile(reference.uncertainty, 80))
    rc = main([*_base(files), "--out", str(files / "d.npy"), "--uncertainty", str(files / "u.npy"),
               "--max-uncertainty", repr(threshold), "--json", str(files / "r.json")])
    assert rc == 0
    depth, sigma = np.load(files / "d.npy"), np.load(files / "u.npy")
    removed = sigma > threshold
    assert removed.any()
    np.testing.assert_array_equal(np.isnan(depth), removed)
    out = capsys.readouterr().out
    assert f"--max-uncertainty {threshold:g}: {removed.sum()} pixels" in out
    report = json.loads((files / "r.json").read_text())
    assert report["uncertainty"]["removed"] == removed.sum()
    assert report["uncertainty"]["limits"] == {"max_uncertainty": threshold}
    # scored on the kept hidden pixels only, against the dense input as truth
    truth = sd.read_depth(files / "dense.png", scale=1000)
    _, mask = sd.sample_depth(truth, fraction=0.08, seed=0)
    kept = ~mask & ~removed
    assert report["metrics"]["scored"] == kept.sum()
    assert report["metrics"]["completed"]["rmse"] == pytest.approx(
        sd.depth_metrics(depth, truth, mask=kept).rmse, rel=1e-12)


@pytest.mark.parametrize("absolute", [False, True])
def test_max_relative_uncertainty_leaves_out_sigma_above_r_times_depth(files, capsys, absolute):
    """Left out: sigma > R x depth, computed here from the library's map and depth (and sigma > M with
    --max-uncertainty M too); the scores are on the kept hidden pixels only."""
    reference = _library_result(files, uncertainty=True)
    sigma, full = reference.uncertainty, reference.depth
    fraction = float(np.percentile(sigma / full, 85))
    expected = sigma > fraction * full
    limits = ["--max-relative-uncertainty", repr(fraction)]
    if absolute:
        threshold = float(np.percentile(sigma[~expected], 90))
        expected |= sigma > threshold
        limits += ["--max-uncertainty", repr(threshold)]
    assert expected.any() and not expected.all()
    rc = main([*_base(files), "--out", str(files / "d.npy"), "--uncertainty", str(files / "u.npy"), *limits,
               "--json", str(files / "r.json")])
    assert rc == 0
    depth = np.load(files / "d.npy")
    np.testing.assert_array_equal(np.isnan(depth), expected)
    np.testing.assert_allclose(depth[~expected], full[~expected], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.load(files / "u.npy"), sigma, rtol=1e-9, atol=1e-12)  # the whole map is kept
    out = capsys.readouterr().out
    assert f": {expected.sum()} pixels ({expected.sum() / expected.size:.1%}) left missing" in out
    assert f"--max-relative-uncertainty {fraction:g}" in out
    report = json.loads((files / "r.json").read_text())
    assert report["uncertainty"]["removed"] == expected.sum()
    assert report["uncertainty"]["limits"]["max_relative_uncertainty"] == fraction
    truth = sd.read_depth(files / "dense.png", scale=1000)
    _, mask = sd.sample_depth(truth, fraction=0.08, seed=0)
    kept = ~mask & ~expected
    assert report["metrics"]["scored"] == kept.sum()
    assert report["metrics"]["completed"]["rmse"] == pytest.approx(
        sd.depth_metrics(depth, truth, mask=kept).rmse, rel=1e-12)
    assert report["metrics"]["nearest"]["rmse"] == pytest.approx(
        sd.depth_metrics(sd.nearest_fill(np.where(mask, truth, np.nan), mask), truth, mask=kept).rmse, rel=1e-12)


def test_png_outputs_zero_where_missing_and_at_least_one_unit_of_uncertainty(files):
    reference = _library_result(files, uncertainty=True)
    threshold = float(np.percentile(reference.uncertainty, 80))
    rc = main([*_base(files), "--out", str(files / "d.png"), "--uncertainty", str(files / "u.png"),
               "--max-uncertainty", repr(threshold)])
    assert rc == 0
    stored_depth = iio.imread(files / "d.png")
    stored_sigma = iio.imread(files / "u.png")
    removed = reference.uncertainty > threshold
    np.testing.assert_array_equal(stored_depth == 0, removed)
    assert stored_sigma.dtype == np.uint16 and stored_sigma.min() >= 1
    np.testing.assert_array_equal(stored_sigma, np.maximum(np.rint(reference.uncertainty * 1000), 1))


def test_outdir_writes_the_uncertainty_map(files):
    outdir = files / "out"
    outdir.mkdir()
    assert main([*_base(files), "--outdir", str(outdir), "--max-uncertainty", "100"]) == 0
    sigma = np.load(outdir / "uncertainty.npy")
    assert sigma.shape == (48, 64) and np.all(np.isfinite(sigma))
    assert not np.any(np.isnan(np.load(outdir / "depth.npy")))  # 100 m removes nothing here


def _listing(folder):
    return sorted(p.name for p in folder.rglob("*"))


@pytest.mark.parametrize("extra, expect", [
    (["--max-uncertainty", "-1"], "--max-uncertainty"),
    (["--max-uncertainty", "nan"], "--max-uncertainty"),
    (["--max-relative-uncertainty", "0"], "--max-relative-uncertainty"),
    (["--max-relative-uncertainty", "-0.1"], "--max-relative-uncertainty"),
    (["--max-relative-uncertainty", "inf"], "--max-relative-uncertainty"),
    (["--max-relative-uncertainty", "ten"], "--max-relative-uncertainty"),
    (["--max-relative-uncertainty", "0.1", "--fill-holes"], "--max-relative-uncertainty"),
    (["--uncertainty", "u.txt"], "--uncertainty"),
    (["--uncertainty", "u.npy", "--fill-holes"], "--uncertainty"),
])
def test_bad_uncertainty_flags_are_one_line_and_exit_2(files, capsys, extra, expect):
    extra = [str(files / e) if e == "u.txt" or e == "u.npy" else e for e in extra]
    argv = ["--image", str(files / "rgb.png"), "--depth", str(files / "dense.png"), "--depth-scale", "mm",
            "--out", str(files / "d.npy"), *extra]
    before = _listing(files)
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2
    assert err.count("\n") == 1 and expect in err, err
    assert _listing(files) == before


@pytest.mark.parametrize("flag", ["--max-uncertainty", "--max-relative-uncertainty"])
def test_uncertainty_refused_in_a_batch(files, capsys, flag):
    rc = main(["--batch", str(files), "--csv", str(files / "m.csv"), "--keep-fraction", "0.1", flag, "1"])
    err = capsys.readouterr().err
    assert rc == 2 and "not a batch" in err and err.count("\n") == 1


def test_unwritable_uncertainty_writes_nothing(files, capsys):
    rc = main([*_base(files), "--out", str(files / "d.npy"), "--uncertainty", str(files / "missing" / "u.npy")])
    assert rc == 2
    assert "--uncertainty" in capsys.readouterr().err
    assert not (files / "d.npy").exists()


def test_too_uncertain_by_hand():
    from sparsedepth.uncertainty import too_uncertain

    sigma = np.array([[0.05, 0.5, 3.0, 0.2], [1.0, np.nan, 0.01, 0.3]])
    depth = np.array([[1.0, 2.0, 40.0, np.nan], [5.0, 2.0, 0.0, 3.0]])
    # sigma > 0.1 depth: 0.05 > 0.1 no; 0.5 > 0.2 yes; 3 > 4 no; NaN depth: out; 1 > 0.5 yes; NaN sigma: kept;
    # depth 0 (no depth): out; 0.3 > 0.3 no
    relative = [[False, True, False, True], [True, False, True, False]]
    np.testing.assert_array_equal(too_uncertain(sigma, depth, max_relative_uncertainty=0.1), relative)
    np.testing.assert_array_equal(too_uncertain(sigma, depth, max_uncertainty=0.4),
                                  [[False, True, True, False], [True, False, False, False]])
    np.testing.assert_array_equal(too_uncertain(sigma, depth, max_uncertainty=0.4, max_relative_uncertainty=0.1),
                                  np.array(relative) | (np.nan_to_num(sigma) > 0.4))
    assert not too_uncertain(sigma, depth).any()
    for bad in (0.0, -0.1, np.inf):
        with pytest.raises(ValueError, match="max_relative_uncertainty"):
            too_uncertain(sigma, depth, max_relative_uncertainty=bad)
    with pytest.raises(ValueError, match="one shape"):
        too_uncertain(sigma, depth[:, :3], max_uncertainty=1.0)


@pytest.mark.filterwarnings("ignore::sparsedepth.ClampWarning")
def test_complete_depth_leaves_out_what_either_limit_refuses():
    """complete_depth(max_relative_uncertainty=R) is the plain uncertainty run with the pixels whose sigma exceeds
    R times their depth set to NaN; with max_uncertainty too, the pixels either limit refuses."""
    image, depth = make_scene(shape=(40, 60))
    sparse, mask = sd.sample_depth(depth, fraction=0.1, seed=3)
    plain = sd.complete_depth(image, sparse, mask, uncertainty=True)
    sigma, dense = plain.uncertainty, plain.depth
    for limits, refused in (({"max_relative_uncertainty": 0.01}, sigma > 0.01 * dense),
                            ({"max_relative_uncertainty": 0.01, "max_uncertainty": 0.005},
                             (sigma > 0.01 * dense) | (sigma > 0.005))):
        limited = sd.complete_depth(image, sparse, mask, **limits)
        assert 0 < refused.sum() < refused.size
        np.testing.assert_array_equal(np.isnan(limited.depth), refused)
        np.testing.assert_array_equal(limited.depth[~refused], dense[~refused])
        assert limited.removed == int(refused.sum())
    for bad in (0.0, -1.0, np.nan):
        with pytest.raises(ValueError, match="max_relative_uncertainty"):
            sd.complete_depth(image, sparse, mask, max_relative_uncertainty=bad)
    with pytest.raises(ValueError, match="prior"):
        sd.complete_depth(image, sparse, mask, max_relative_uncertainty=0.1, prior=np.ones(depth.shape))
