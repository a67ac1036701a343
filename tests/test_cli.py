"""python -m sparsedepth.complete: main([...]) on hand-made files, round trips, bad input, batch, demo."""

import csv
import dataclasses
import json
import sys

import h5py
import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd

from conftest import make_scene as _scene
from sparsedepth.complete import main
from sparsedepth.io import write_pfm

FAST = ["--gamma", "0", "--solver", "direct"]  # quadratic objective, exact direct solve
# what FAST selects: the default density schedule with gamma fixed at 0 (hole filling: the constant defaults)
FAST_WEIGHTS = sd.DEFAULT_SCHEDULE.replace(gamma=0.0)


@pytest.fixture
def files(tmp_path):
    """rgb.png, dense.png (mm), sparse.png (10 % of dense, mm) and raw.png (dense with holes, mm)."""
    image, depth = _scene()
    iio.imwrite(tmp_path / "rgb.png", image)
    sd.write_depth(tmp_path / "dense.png", depth, scale=1000)
    sparse, _ = sd.sample_depth(depth, fraction=0.1, seed=1)
    sd.write_depth(tmp_path / "sparse.png", sparse, scale=1000)
    raw = depth.copy()
    raw[5:15, 10:30] = np.nan
    raw[np.random.default_rng(2).random(depth.shape) < 0.15] = np.nan
    sd.write_depth(tmp_path / "raw.png", raw, scale=1000)
    return tmp_path


def _listing(folder):
    return sorted(p.name for p in folder.rglob("*"))


def _expected_completion(folder, name="sparse.png", scale=1000):
    image = sd.read_image(folder / "rgb.png")
    sparse = sd.read_depth(folder / name, scale=scale)
    return sd.complete_depth(image, sparse, weights=FAST_WEIGHTS, solver="direct").depth


# ----------------------------------------------------------------------------- help
def test_help_lists_every_option_and_an_example(capsys):
    assert main(["--help-all"]) == 0
    out = capsys.readouterr().out
    assert "examples:" in out and "python -m sparsedepth.complete --image" in out
    for f in dataclasses.fields(sd.Weights):  # weight options follow the Weights dataclass
        assert f"--{f.name.replace('_', '-')}" in out
    for option in ("--depth-scale", "--keep-fraction", "--keep-count", "--fill-holes", "--fill-method", "--out",
                   "--json", "--figure", "--batch", "--nyu-mat", "--indices", "--csv", "--workers", "--calib"):
        assert option in out
    for solver in sd.SOLVERS:
        assert solver in out


def test_help_makes_no_speed_claims_and_says_what_an_uncertainty_limit_is(capsys):
    """Measured numbers live on the pages the benches write, which the help names; a limit on the uncertainty is
    an expected error in metres, not a depth."""
    import re

    for flag in ("--help", "--help-all"):
        assert main([flag]) == 0
        text = " ".join(capsys.readouterr().out.split())
        assert not re.search(r"\d\s*x faster|about \d|\d+(\.\d+)?-\d+(\.\d+)? of a", text), flag
    assert main(["--help-all"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "expected error of their depth, in metres; not a depth" in text
    assert "R times their depth" in text and "docs/figures/uncertainty_limits.csv" in text
    assert "docs/fast_mode.md" in text and "docs/expected_error.md" in text


def test_every_weight_field_is_an_option(files, capsys):
    # a non-default value of every weight ends up in the solver's Weights (json "weights")
    args = []
    for i, f in enumerate(dataclasses.fields(sd.Weights)):
        args += [f"--{f.name.replace('_', '-')}", str(0.125 * (i + 1))]
    args[args.index("--gamma") + 1] = "0"
    args[args.index("--edge-penalty"):args.index("--edge-penalty") + 2] = []  # a name, not a number: below
    args[args.index("--edge-scale"):args.index("--edge-scale") + 2] = []  # the scale of a robust penalty only
    rc = main(["--image", str(files / "rgb.png"), "--depth", str(files / "sparse.png"), "--depth-scale", "mm",
               "--solver", "direct", "--json", str(files / "m.json"), "-q", *args])
    assert rc == 0, capsys.readouterr().err
    report = json.loads((files / "m.json").read_text())
    for i, f in enumerate(dataclasses.fields(sd.Weights)):
        if f.name in ("edge_penalty", "edge_scale"):
            assert report["weights"][f.name] == getattr(sd.DEFAULT_WEIGHTS, f.name)
        else:
            assert report["weights"][f.name] == (0.0 if f.name == "gamma" else 0.125 * (i + 1))


def test_edge_penalty_options_reach_the_weights_and_pick_irls(files, capsys):
    rc = main(["--image", str(files / "rgb.png"), "--depth", str(files / "sparse.png"), "--depth-scale", "mm",
               "--gamma", "0.01", "--edge-penalty", "cauchy", "--edge-scale", "0.02",
               "--json", str(files / "m.json"), "--out", str(files / "out.npy"), "-q"])
    assert rc == 0, capsys.readouterr().err
    report = json.loads((files / "m.json").read_text())
    assert report["weights"]["edge_penalty"] == "cauchy" and report["weights"]["edge_scale"] == 0.02
    assert report["solver"] == "irls"
    image = sd.read_image(files / "rgb.png")
    sparse = sd.read_depth(files / "sparse.png", scale=1000)
    expected = sd.complete_depth(image, sparse, weights=sd.DEFAULT_SCHEDULE.replace(
        gamma=0.01, edge_penalty="cauchy", edge_scale=0.02)).depth
    np.testing.assert_allclose(sd.read_depth(files / "out.npy"), expected, rtol=1e-12)


@pytest.mark.parametrize("argv, words", [
    (["--edge-penalty", "huber", "--gamma", "0.01"], "invalid choice"),
    (["--edge-penalty", "cauchy"], "--gamma > 0"),
    (["--edge-penalty", "cauchy", "--gamma", "0.01", "--solver", "admm"], "--solver irls"),
    (["--edge-scale", "0.1", "--gamma", "0.01"], "robust --edge-penalty"),
    (["--edge-penalty", "cauchy", "--gamma", "0.01", "--edge-scale", "0"], "metres > 0"),
])
def test_edge_penalty_options_are_checked(files, capsys, argv, words):
    rc = main(["--image", str(files / "rgb.png"), "--depth", str(files / "sparse.png"), "--depth-scale", "mm",
               "-q", *argv])
    assert rc == 2
    assert words in capsys.readouterr().err


@pytest.mark.parametrize("method", ["complete", "colorization"])
def test_fill_method_without_fill_holes_is_refused(files, capsys, method):
    rc = main(["--image", str(files / "rgb.png"), "--depth", str(files / "sparse.png"), "--depth-scale", "mm",
               "--out", str(files / "out.npy"), "-q", "--fill-method", method])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and f"--fill-method {method}" in err and "--fill-holes" in err, err
    assert not (files / "out.npy").exists()


@pytest.mark.parametrize("argv, flag", [
    (["--keep-fraction", "0.1", "--seed", "-1"], "--seed"),  # was NumPy's "expected non-negative integer"
    (["--keep-fraction", "0.1", "--seed", "1.5"], "--seed"),
    (["--tol", "-1"], "--tol"),  # was "tol must be finite and >= 0", not the flag
    (["--tol", "nan"], "--tol"),
])
def test_one_frame_bad_seed_or_tol_is_one_line_naming_the_flag(files, capsys, argv, flag):
    rc = main(["--image", str(files / "rgb.png"), "--depth", str(files / "dense.png"), "--depth-scale", "mm",
               "--out", str(files / "out.npy"), "-q", *argv])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and f"argument {flag}:" in err, err
    assert not (files / "out.npy").exists()


def test_too_few_valid_pixels_name_the_flags(files, capsys):
    """--keep-count above the valid count, an all-zero --mask and a --downsample that leaves nothing name the flag."""
    depth = sd.read_depth(files / "sparse.png", scale=1000)
    valid = int(np.count_nonzero(np.isfinite(depth) & (depth > 0)))
    np.save(files / "none.npy", np.zeros(depth.shape, dtype=bool))
    cases = [(["--depth", str(files / "sparse.png"), "--keep-count", str(valid + 1)], f"--keep-count {valid + 1}"),
             (["--depth", str(files / "sparse.png"), "--mask", str(files / "none.npy")], "--mask"),
             (["--depth", str(files / "sparse.png"), "--downsample", "1000"], "--downsample 1000")]
    for argv, words in cases:
        rc = main(["--image", str(files / "rgb.png"), "--depth-scale", "mm", "--out", str(files / "out.npy"), "-q",
                   *argv])
        err = capsys.readouterr().err
        assert rc == 2 and err.count("\n") == 1 and words in err, err
        assert not (files / "out.npy").exists()
    rc = main(["--image", str(files / "rgb.png"), "--depth", str(files / "sparse.png"), "--depth-scale", "mm",
               "--keep-count", str(valid), "--out", str(files / "out.npy"), "-q"])
    assert rc == 0  # every valid pixel is a count the sampling can keep


# ----------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("ext, atol", [(".npy", 1e-12), (".npz", 1e-12), (".h5", 1e-12), (".pfm", 1e-6)])
def test_round_trip_float_formats(files, capsys, ext, atol):
    out = files / f"out{ext}"
    rc = main(["--image", str(files / "rgb.png"), "--depth", str(files / "sparse.png"), "--depth-scale", "mm",
               "--out", str(out), "-q", *FAST])
    assert rc == 0, capsys.readouterr().err
    np.testing.assert_allclose(sd.read_depth(out), _expected_completion(files), rtol=atol, atol=atol)


@pytest.mark.parametrize("preset, scale", [("mm", 1000.0), ("kitti", 256.0)])
def test_round_trip_png_in_the_input_scale(tmp_path, capsys, preset, scale):
    image, depth = _scene()
    iio.imwrite(tmp_path / "rgb.png", image)
    sparse, _ = sd.sample_depth(depth, fraction=0.1, seed=1)
    sd.write_depth(tmp_path / "sparse.png", sparse, scale=scale)
    rc = main(["--image", str(tmp_path / "rgb.png"), "--depth", str(tmp_path / "sparse.png"),
               "--depth-scale", preset, "--out", str(tmp_path / "out.png"), "-q", *FAST])
    assert rc == 0, capsys.readouterr().err
    expected = _expected_completion(tmp_path, scale=scale)
    stored = iio.imread(tmp_path / "out.png")
    assert stored.dtype == np.uint16
    np.testing.assert_array_equal(stored, np.rint(expected * scale).astype(np.uint16))
    np.testing.assert_allclose(sd.read_depth(tmp_path / "out.png", scale=scale), expected, atol=0.5 / scale)


def test_out_scale_overrides(files, capsys):
    rc = main(["--image", str(files / "rgb.png"), "--depth", str(files / "sparse.png"), "--depth-scale", "mm",
               "--out", str(files / "out.png"), "--out-scale", "5000", "-q", *FAST])
    assert rc == 0, capsys.readouterr().err
    np.testing.assert_array_equal(iio.imread(files / "out.png"),
                                  np.rint(_expected_completion(files) * 5000).astype(np.uint16))


def test_keep_fraction_scores_against_the_dense_map(files, capsys):
    rc = main(["--image", str(files / "rgb.png"), "--depth", str(files / "dense.png"), "--depth-scale", "nyu",
               "--keep-fraction", "0.1", "--seed", "3", "--json", str(files / "m.json"), *FAST])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    image, dense = sd.read_image(files / "rgb.png"), sd.read_depth(files / "dense.png", scale=1000)
    sparse, mask = sd.sample_depth(dense, fraction=0.1, seed=3)
    completed = sd.complete_depth(image, sparse, mask, weights=FAST_WEIGHTS, solver="direct").depth
    expected = sd.depth_metrics(completed, dense, mask=~mask)
    nearest = sd.depth_metrics(sd.nearest_fill(sparse, mask), dense, mask=~mask)
    report = json.loads((files / "m.json").read_text())
    assert report["observed"] == mask.sum()
    assert report["metrics"]["completed"]["rmse"] == pytest.approx(expected.rmse, rel=1e-12)
    assert report["metrics"]["nearest"]["mae"] == pytest.approx(nearest.mae, rel=1e-12)
    assert report["solver"] == "direct" and report["history"][0]["iteration"] == 0
    assert f"{expected.rmse:9.4f}" in captured.out and "nearest neighbour" in captured.out


def test_keep_count_and_mask(files, capsys):
    image, dense = sd.read_image(files / "rgb.png"), sd.read_depth(files / "dense.png", scale=1000)
    mask = np.zeros(dense.shape, bool)
    mask[:, :30] = True  # only the left half may be observed
    np.save(files / "mask.npy", mask)
    rc = main(["--image", str(files / "rgb.png"), "--depth", str(files / "dense.png"), "--depth-scale", "mm",
               "--mask", str(files / "mask.npy"), "--keep-count", "50", "--json", str(files / "m.json"), "-q",
               *FAST])
    assert rc == 0, capsys.readouterr().err
    observed = sd.sample_mask(np.where(mask, dense, np.nan), count=50, seed=0)
    report = json.loads((files / "m.json").read_text())
    assert report["observed"] == 50 == observed.sum()
    assert report["metrics"]["scored"] == (mask & ~observed).sum()  # truth = the masked dense map


def test_pfm_disparity_with_calib(tmp_path, capsys):
    image, depth = _scene()
    f_px, baseline_mm = 500.0, 100.0
    disparity = f_px * baseline_mm / 1000.0 / depth
    disparity[np.random.default_rng(0).random(depth.shape) > 0.1] = np.inf  # sparse
    iio.imwrite(tmp_path / "rgb.png", image)
    write_pfm(tmp_path / "disp.pfm", disparity)
    (tmp_path / "calib.txt").write_text(
        f"cam0=[{f_px} 0 30; 0 {f_px} 20; 0 0 1]\ncam1=[{f_px} 0 30; 0 {f_px} 20; 0 0 1]\n"
        f"doffs=0\nbaseline={baseline_mm}\nwidth=60\nheight=40\n")
    rc = main(["--image", str(tmp_path / "rgb.png"), "--depth", str(tmp_path / "disp.pfm"),
               "--calib", str(tmp_path / "calib.txt"), "--out", str(tmp_path / "out.npy"), "-q", *FAST])
    assert rc == 0, capsys.readouterr().err
    metric = sd.read_depth(tmp_path / "disp.pfm", calib=tmp_path / "calib.txt")
    np.testing.assert_allclose(np.nanmax(np.abs(metric - depth)), 0, atol=1e-5)  # calib applied
    expected = sd.complete_depth(image, metric, weights=FAST_WEIGHTS, solver="direct").depth
    np.testing.assert_allclose(np.load(tmp_path / "out.npy"), expected, atol=1e-12)


def test_fill_holes_mode(files, capsys):
    rc = main(["--fill-holes", "--image", str(files / "rgb.png"), "--depth", str(files / "raw.png"),
               "--depth-scale", "mm", "--truth", str(files / "dense.png"), "--out", str(files / "filled.npy"),
               "--json", str(files / "m.json"), "-q"])
    assert rc == 0, capsys.readouterr().err
    image, raw = sd.read_image(files / "rgb.png"), sd.read_depth(files / "raw.png", scale=1000)
    truth = sd.read_depth(files / "dense.png", scale=1000)
    expected = sd.fill_holes(image, raw)
    np.testing.assert_array_equal(np.load(files / "filled.npy"), expected)
    holes = np.isnan(raw)
    report = json.loads((files / "m.json").read_text())
    assert report["metrics"]["scored"] == holes.sum()
    assert report["metrics"]["completed"]["mae"] == pytest.approx(
        sd.depth_metrics(expected, truth, mask=holes).mae, rel=1e-12)


def test_fill_holes_complete_method(files, capsys):
    rc = main(["--fill-holes", "--fill-method", "complete", "--image", str(files / "rgb.png"), "--depth",
               str(files / "raw.png"), "--depth-scale", "mm", "--out", str(files / "filled.npy"), "-q", *FAST])
    assert rc == 0, capsys.readouterr().err
    image, raw = sd.read_image(files / "rgb.png"), sd.read_depth(files / "raw.png", scale=1000)
    expected = sd.fill_holes(image, raw, method="complete", weights=sd.Weights(gamma=0.0), solver="direct")
    np.testing.assert_allclose(np.load(files / "filled.npy"), expected, atol=1e-12)


def test_figure(files, capsys):
    pytest.importorskip("matplotlib")
    rc = main(["--image", str(files / "rgb.png"), "--depth", str(files / "dense.png"), "--depth-scale", "mm",
               "--keep-fraction", "0.1", "--figure", str(files / "fig.png"), "-q", *FAST])
    assert rc == 0, capsys.readouterr().err
    picture = iio.imread(files / "fig.png")
    # seven panels (image, input, nearest, output / truth, two errors) in two rows of four, each at least 320 px
    assert picture.ndim == 3 and picture.shape[1] >= 4 * 320 and picture.shape[0] >= 2 * 320 * 40 / 60


def test_demo_writes_its_folder(tmp_path, capsys):
    outdir = tmp_path / "demo"
    rc = main(["--outdir", str(outdir), "--downsample", "8", "-q", *FAST])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    frame = sd.load_motorcycle()
    image, depth = frame.image[::8, ::8], frame.depth[::8, ::8]
    sparse, mask = sd.sample_depth(depth, fraction=0.05, seed=0)
    completed = sd.complete_depth(image, sparse, mask, weights=FAST_WEIGHTS, solver="direct").depth
    np.testing.assert_allclose(np.load(outdir / "depth.npy"), completed, atol=1e-12)
    report = json.loads((outdir / "metrics.json").read_text())
    assert report["metrics"]["completed"]["rmse"] == pytest.approx(
        sd.depth_metrics(completed, depth, mask=~mask).rmse, rel=1e-12)
    assert (outdir / "depth.png").is_file()
    assert "Motorcycle" in captured.out and "nearest neighbour" in captured.out


# ----------------------------------------------------------------------------- bad input
def _run_bad(argv, capsys, folder, expect):
    before = _listing(folder)
    rc = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.endswith("\n") and err.count("\n") == 1, err  # exactly one line
    assert expect.lower() in err.lower(), err
    assert _listing(folder) == before  # nothing written, not even a temporary file


def _base(files, depth="sparse.png"):
    return ["--image", files / "rgb.png", "--depth", files / depth, "--depth-scale", "mm", "--out", files / "o.npy"]


def test_missing_image(files, capsys):
    _run_bad(["--image", files / "nope.png", "--depth", files / "sparse.png", "--depth-scale", "mm", "--out",
              files / "o.npy"], capsys, files, "no such file")


def test_missing_depth(files, capsys):
    _run_bad(["--image", files / "rgb.png", "--depth", files / "nope.png", "--depth-scale", "mm", "--out",
              files / "o.npy"], capsys, files, "no such file")


def test_unreadable_image(files, capsys):
    (files / "bad.png").write_bytes(b"\x89PNG\r\n\x1a\nnot really")
    _run_bad(["--image", files / "bad.png", "--depth", files / "sparse.png", "--depth-scale", "mm", "--out",
              files / "o.npy"], capsys, files, "could not decode")


def test_size_mismatch(files, capsys):
    image, _ = _scene(shape=(30, 60))
    iio.imwrite(files / "small.png", image)
    _run_bad(["--image", files / "small.png", "--depth", files / "sparse.png", "--depth-scale", "mm", "--out",
              files / "o.npy"], capsys, files, "same size")


def test_depth_without_valid_pixel(files, capsys):
    iio.imwrite(files / "zeros.png", np.zeros((40, 60), np.uint16))
    _run_bad(_base(files, "zeros.png"), capsys, files, "no valid pixel")


def test_unknown_depth_format(files, capsys):
    (files / "depth.txt").write_text("1 2 3")
    _run_bad(_base(files, "depth.txt"), capsys, files, "unsupported extension")


def test_unknown_output_format(files, capsys):
    argv = _base(files)
    argv[-1] = files / "o.jpg"
    _run_bad(argv, capsys, files, "unsupported extension")


def test_output_folder_missing(files, capsys):
    argv = _base(files)
    argv[-1] = files / "absent" / "o.npy"
    _run_bad(argv, capsys, files, "does not exist")


def test_png_depth_needs_a_scale(files, capsys):
    _run_bad(["--image", files / "rgb.png", "--depth", files / "sparse.png", "--out", files / "o.npy"],
             capsys, files, "scale")


def test_unknown_option(files, capsys):
    _run_bad([*_base(files), "--frobnicate"], capsys, files, "unrecognized arguments")


def test_unknown_solver(files, capsys):
    _run_bad([*_base(files), "--solver", "magic"], capsys, files, "invalid choice")


def test_unknown_scale_preset(files, capsys):
    _run_bad(["--image", files / "rgb.png", "--depth", files / "sparse.png", "--depth-scale", "furlong"],
             capsys, files, "--depth-scale")


def test_negative_weight(files, capsys):
    _run_bad([*_base(files), "--beta", "-1"], capsys, files, "--beta")


def test_keep_count_too_large(files, capsys):
    _run_bad([*_base(files), "--keep-count", "100000"], capsys, files, "exceeds")


def test_image_without_depth(files, capsys):
    _run_bad(["--image", files / "rgb.png"], capsys, files, "go together")


def test_fill_holes_with_keep_fraction(files, capsys):
    _run_bad(["--fill-holes", *_base(files, "raw.png"), "--keep-fraction", "0.1"], capsys, files, "do not apply")


def test_colorization_with_solver_options(files, capsys):
    _run_bad(["--fill-holes", *_base(files, "raw.png"), "--gamma", "0"], capsys, files, "colorization")


def test_png_overflow_leaves_no_file(files, capsys):
    # 1-2 m depth stored at scale 50000 overflows uint16: the error comes when writing, atomically
    _run_bad([*_base(files)[:-1], files / "o.png", "--out-scale", "50000", "-q", *FAST], capsys, files,
             "overflows")


def test_figure_without_matplotlib(files, capsys, monkeypatch):
    for name in ("matplotlib", "matplotlib.figure", "matplotlib.backends.backend_agg"):
        monkeypatch.setitem(sys.modules, name, None)  # import raises ImportError
    _run_bad([*_base(files), "--figure", files / "fig.png", "--json", files / "m.json"], capsys, files,
             "matplotlib")


def test_absurd_scale_warns(files, capsys):
    # millimetre PNG read as metres: median ~1500 m
    rc = main(["--image", str(files / "rgb.png"), "--depth", str(files / "sparse.png"), "--depth-scale", "m",
               "--out", str(files / "o.npy"), "-q", *FAST])
    err = _without_clamp_warning(capsys.readouterr().err)
    assert rc == 0
    assert err.count("\n") == 1 and err.startswith("warning:") and "median depth" in err
    assert (files / "o.npy").is_file()


def test_sensible_scale_does_not_warn(files, capsys):
    rc = main([*map(str, _base(files)), "-q", *FAST])
    assert rc == 0 and _without_clamp_warning(capsys.readouterr().err) == ""


def _without_clamp_warning(err):
    """stderr less the range clamp's warning line (the default weights overshoot this scene's depth step)."""
    return "".join(line for line in err.splitlines(keepends=True)
                   if not (line.startswith("warning: ") and "--no-clip" in line))


# ----------------------------------------------------------------------------- batch
def test_batch_folder_with_a_corrupt_frame(tmp_path, capsys):
    for i, key in enumerate(["0001", "0002", "0003"]):
        image, depth = _scene(seed=i)
        iio.imwrite(tmp_path / f"rgb_{key}.png", image)
        sd.write_depth(tmp_path / f"depth_{key}.png", depth, scale=1000)
    (tmp_path / "depth_0002.png").write_bytes(b"corrupt")
    rc = main(["--batch", str(tmp_path), "--depth-scale", "mm", "--keep-fraction", "0.1", "--csv",
               str(tmp_path / "m.csv"), "--workers", "2", *FAST])
    captured = capsys.readouterr()
    assert rc == 1  # finished, with a failed frame
    with open(tmp_path / "m.csv", newline="") as fh:
        rows = {row["name"]: row for row in csv.DictReader(fh)}
    assert rows["0002"]["status"] == "error" and rows["0002"]["error"]
    assert rows["0001"]["status"] == rows["0003"]["status"] == "ok"
    assert float(rows["0001"]["rmse"]) > 0
    progress = [line for line in captured.err.splitlines() if line.startswith("[")]
    assert len(progress) == 3 and "FAILED" in captured.err  # one progress line per frame
    assert "2 of 3 frames done, 1 failed" in captured.out


def test_batch_nyu_mat_index_range(tmp_path, capsys):
    frames = [_scene(seed=s) for s in range(3)]
    with h5py.File(tmp_path / "nyu.mat", "w") as fh:
        fh.create_dataset("images", data=np.stack([im.transpose(2, 1, 0) for im, _ in frames]))
        fh.create_dataset("depths", data=np.stack([d.T for _, d in frames]).astype(np.float32))
    rc = main(["--nyu-mat", str(tmp_path / "nyu.mat"), "--indices", "1:3", "--keep-fraction", "0.1",
               "--csv", str(tmp_path / "m.csv"), "--workers", "1", "-q", *FAST])
    assert rc == 0, capsys.readouterr().err
    with open(tmp_path / "m.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert sorted(r["name"] for r in rows) == ["nyu_0001", "nyu_0002"]
    assert all(r["status"] == "ok" for r in rows)


def test_batch_needs_csv(tmp_path, capsys):
    _run_bad(["--batch", tmp_path], capsys, tmp_path, "--csv")


def test_nyu_mat_missing(tmp_path, capsys):
    _run_bad(["--nyu-mat", tmp_path / "absent.mat", "--fill-holes", "--csv", tmp_path / "m.csv"], capsys,
             tmp_path, "no such file")


# ----------------------------------------------------------------------------- range clamp
def test_clamp_warns_only_when_worth_it_and_no_clip_keeps_the_unclamped_map(files, capsys):
    """The default second-order weights overshoot the observed range at the scene's depth step (under 1 % of it)."""
    image = sd.read_image(files / "rgb.png")
    sparse = sd.read_depth(files / "sparse.png", scale=1000)
    argv = ["--image", str(files / "rgb.png"), "--depth", str(files / "sparse.png"), "--depth-scale", "mm",
            "--solver", "direct"]
    clamped = sd.complete_depth(image, sparse, solver="direct", clip_to_observed=False)
    lo, hi = np.nanmin(sparse), np.nanmax(sparse)
    outside = int(np.count_nonzero((clamped.depth < lo) | (clamped.depth > hi)))
    assert 0 < outside < sd.completion.CLAMP_WARNING_SHARE * sparse.size  # ordinary overshoot

    assert main([*argv, "--out", str(files / "a.npy"), "--json", str(files / "a.json")]) == 0
    assert "warning:" not in capsys.readouterr().err
    a = np.load(files / "a.npy")
    np.testing.assert_allclose(a, np.clip(clamped.depth, lo, hi), rtol=0, atol=1e-9)
    report = json.loads((files / "a.json").read_text())
    assert 0 < report["clamped"] <= outside

    assert main([*argv, "--no-clip", "--out", str(files / "b.npy")]) == 0
    assert "warning:" not in capsys.readouterr().err
    np.testing.assert_allclose(np.load(files / "b.npy"), clamped.depth, rtol=0, atol=1e-9)

    # an outlier sample (40 m in a 1-3 m scene) widens the range: one line, without the --no-clip hint
    sparse_mm = np.nan_to_num(sparse * 1000).astype(np.uint16)
    rows, cols = np.nonzero(sparse_mm)
    sparse_mm[rows[5], cols[5]] = 40000
    iio.imwrite(files / "outlier.png", sparse_mm)
    assert main([*argv[:2], "--depth", str(files / "outlier.png"), "--depth-scale", "mm", "--solver", "direct",
                 "--out", str(files / "c.npy")]) == 0
    warnings_printed = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning:")]
    outlier_lines = [line for line in warnings_printed if "far outside the other observations" in line]
    assert len(outlier_lines) == 1 and "--no-clip" not in outlier_lines[0]


@pytest.mark.parametrize("truth_given", [False, True])
def test_table_without_metrics_says_why(truth_given):
    """No score: without ground truth the table asks for --truth; with one that has nothing to score it says so."""
    import io
    from types import SimpleNamespace

    from sparsedepth.cli.report import print_table

    depth = np.ones((4, 5))
    truth = np.where(np.eye(4, 5, dtype=bool), 1.0, 0.0) if truth_given else None
    outcome = SimpleNamespace(depth=depth, observed=np.eye(4, 5, dtype=bool), result=None, metrics=None,
                              method="complete (amg)", runtime=0.5, truth=truth)
    stream = io.StringIO()
    print_table(outcome, "frame", stream)
    text = stream.getvalue()
    assert ("give --truth" in text) is not truth_given
    assert ("no valid pixel that was not observed" in text) is truth_given
