"""--image-shift DY,DX|auto: the parser, one frame (completion, hole filling, the demo), the batch options and
evaluate_frame(image_shift=...), each against the library's shift_image / estimate_image_shift called directly."""

import csv
import json
import warnings

import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd

from conftest import make_scene
from sparsedepth.batch import BatchOptions, evaluate_frame
from sparsedepth.batch import csvlog
from sparsedepth.cli.parser import build_parser
from sparsedepth.complete import main

FAST = ["--gamma", "0", "--solver", "direct"]  # quadratic objective, exact direct solve
FAST_WEIGHTS = sd.DEFAULT_SCHEDULE.replace(gamma=0.0)  # what FAST selects
OFFSET = (0, 2)  # the image of the files is this far from the depth: (0, -2) registers it

pytestmark = pytest.mark.filterwarnings("ignore::sparsedepth.ClampWarning")  # the clamping is not what is tested


@pytest.fixture
def frame(tmp_path):
    """rgb.png (the scene's image moved by OFFSET), dense.npy (metres), raw.npy (holes) and few.npy (3 samples)."""
    image, depth = make_scene()
    iio.imwrite(tmp_path / "rgb.png", sd.shift_image(image, OFFSET))
    np.save(tmp_path / "dense.npy", depth)
    raw = depth.copy()
    raw[5:15, 10:40] = np.nan
    raw[np.random.default_rng(2).random(depth.shape) < 0.2] = np.nan
    np.save(tmp_path / "raw.npy", raw)
    few = np.zeros_like(depth)
    few[5, 5], few[30, 50], few[20, 10] = 1.2, 2.4, 1.6
    np.save(tmp_path / "few.npy", few)
    return tmp_path


def _run(frame, capsys, *argv):
    rc = main([str(a) for a in argv])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    return captured


def _completed(image, sparse, mask):
    return sd.complete_depth(image, sparse, mask, weights=FAST_WEIGHTS, solver="direct").depth


# ----------------------------------------------------------------------------- parser
@pytest.mark.parametrize("argv, value", [
    (["--image-shift", "0,-2"], (0, -2)),
    (["--image-shift", "-1,1"], (-1, 1)),  # a value starting with a minus sign, as a separate argument
    (["--image-shift=-1,-3"], (-1, -3)),
    (["--image-shift", "auto"], "auto"),
    ([], None),
])
def test_parser_reads_a_pair_or_auto(argv, value):
    assert build_parser().parse_args(argv).image_shift == value


@pytest.mark.parametrize("value", ["1", "1,2,3", "a,b", "1.5,0", "", "-1", "-1,2,3", "auto,1"])
def test_malformed_shift_is_one_line_naming_the_flag(tmp_path, capsys, value):
    rc = main(["--image-shift", value, "--outdir", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "argument --image-shift:" in err, err
    assert list(tmp_path.iterdir()) == []


def test_help_describes_the_option(capsys):
    assert main(["--help-all"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "--image-shift DY,DX|auto" in text and "after --downsample" in text and "estimate_image_shift" in text


# ----------------------------------------------------------------------------- one frame
def test_given_shift_moves_the_image_before_completion(frame, capsys):
    out = _run(frame, capsys, "--image", frame / "rgb.png", "--depth", frame / "dense.npy", "--keep-fraction", "0.1",
               "--seed", "3", "--image-shift", "0,-2", "--out", frame / "out.npy", "--json", frame / "m.json", *FAST)
    image, dense = sd.read_image(frame / "rgb.png"), np.load(frame / "dense.npy")
    sparse, mask = sd.sample_depth(dense, fraction=0.1, seed=3)
    expected = _completed(sd.shift_image(image, (0, -2)), sparse, mask)
    np.testing.assert_allclose(np.load(frame / "out.npy"), expected, rtol=0, atol=1e-12)
    assert np.abs(expected - _completed(image, sparse, mask)).max() > 1e-3  # the shift changes the output
    report = json.loads((frame / "m.json").read_text())
    assert report["image_shift"] == [0, -2]
    assert report["metrics"]["completed"]["rmse"] == pytest.approx(
        sd.depth_metrics(expected, dense, mask=~mask).rmse, rel=1e-12)
    assert "image moved by dy = 0 rows, dx = -2 columns (--image-shift 0,-2)" in out.out


def test_without_the_option_the_report_says_no_shift(frame, capsys):
    out = _run(frame, capsys, "--image", frame / "rgb.png", "--depth", frame / "dense.npy", "--keep-fraction", "0.1",
               "--json", frame / "m.json", "-q", *FAST)
    assert json.loads((frame / "m.json").read_text())["image_shift"] == [0, 0]
    assert "image moved" not in out.out


def test_auto_estimates_from_the_sampled_and_masked_input(frame, capsys):
    mask_file = np.ones((40, 60), bool)
    mask_file[:, 50:] = False
    np.save(frame / "mask.npy", mask_file)
    out = _run(frame, capsys, "--image", frame / "rgb.png", "--depth", frame / "dense.npy", "--mask",
               frame / "mask.npy", "--keep-fraction", "0.3", "--seed", "4", "--image-shift", "auto",
               "--out", frame / "out.npy", "--json", frame / "m.json", *FAST)
    image, dense = sd.read_image(frame / "rgb.png"), np.load(frame / "dense.npy")
    observed = sd.sample_mask(np.where(mask_file, dense, np.nan), fraction=0.3, seed=4)
    sparse = np.where(observed, dense, np.nan)
    estimate = sd.estimate_image_shift(image, sparse, observed).shift
    assert estimate != (0, 0)  # the files' image is OFFSET away from the depth
    report = json.loads((frame / "m.json").read_text())
    assert report["image_shift"] == list(estimate) and report["observed"] == observed.sum()
    np.testing.assert_allclose(np.load(frame / "out.npy"), _completed(sd.shift_image(image, estimate), sparse,
                                                                      observed), rtol=0, atol=1e-12)
    assert f"dy = {estimate[0]} rows, dx = {estimate[1]} columns (estimated by --image-shift auto)" in out.out
    assert "image-shift" not in out.err


def test_auto_with_too_few_samples_warns_and_does_not_move_the_image(frame, capsys):
    out = _run(frame, capsys, "--image", frame / "rgb.png", "--depth", frame / "few.npy", "--image-shift", "auto",
               "--out", frame / "out.npy", "--json", frame / "m.json", "--no-clip", *FAST)
    lines = [line for line in out.err.splitlines() if "--image-shift" in line]
    assert len(lines) == 1 and lines[0].startswith("warning: --image-shift auto:") and "at least 8" in lines[0]
    image, few = sd.read_image(frame / "rgb.png"), np.load(frame / "few.npy")
    with pytest.raises(ValueError):
        sd.estimate_image_shift(image, few)
    expected = sd.complete_depth(image, few, weights=FAST_WEIGHTS, solver="direct", clip_to_observed=False).depth
    np.testing.assert_allclose(np.load(frame / "out.npy"), expected, rtol=0, atol=1e-12)
    assert json.loads((frame / "m.json").read_text())["image_shift"] == [0, 0]


def test_fill_holes_fills_with_the_moved_image(frame, capsys):
    _run(frame, capsys, "--fill-holes", "--image", frame / "rgb.png", "--depth", frame / "raw.npy",
         "--image-shift", "1,-2", "--out", frame / "filled.npy", "-q")
    image, raw = sd.read_image(frame / "rgb.png"), np.load(frame / "raw.npy")
    expected = sd.fill_holes(sd.shift_image(image, (1, -2)), raw)
    np.testing.assert_array_equal(np.load(frame / "filled.npy"), expected)
    assert not np.array_equal(expected, sd.fill_holes(image, raw))


def test_shift_applies_after_downsample(frame, capsys):
    _run(frame, capsys, "--image", frame / "rgb.png", "--depth", frame / "dense.npy", "--downsample", "2",
         "--keep-fraction", "0.2", "--image-shift", "0,-1", "--out", frame / "out.npy", "-q", *FAST)
    image, dense = sd.read_image(frame / "rgb.png")[::2, ::2], np.load(frame / "dense.npy")[::2, ::2]
    sparse, mask = sd.sample_depth(dense, fraction=0.2, seed=0)
    np.testing.assert_allclose(np.load(frame / "out.npy"), _completed(sd.shift_image(image, (0, -1)), sparse, mask),
                               rtol=0, atol=1e-12)


def test_the_point_cloud_takes_its_colours_from_the_moved_image(frame, capsys):
    _run(frame, capsys, "--image", frame / "rgb.png", "--depth", frame / "dense.npy", "--keep-fraction", "0.1",
         "--image-shift", "0,-2", "--intrinsics", "50,50,30,20", "--ply", frame / "c.ply", "-q", *FAST)
    _, colours = sd.read_ply(frame / "c.ply")
    moved = sd.shift_image(sd.read_image(frame / "rgb.png"), (0, -2))
    np.testing.assert_array_equal(colours, moved.reshape(-1, 3))


def test_demo_takes_the_option(tmp_path, capsys):
    outdir = tmp_path / "demo"
    _run(tmp_path, capsys, "--outdir", outdir, "--downsample", "8", "--image-shift", "1,0", "-q", *FAST)
    demo = sd.load_motorcycle()
    image, depth = demo.image[::8, ::8], demo.depth[::8, ::8]
    sparse, mask = sd.sample_depth(depth, fraction=0.05, seed=0)
    np.testing.assert_allclose(np.load(outdir / "depth.npy"), _completed(sd.shift_image(image, (1, 0)), sparse, mask),
                               rtol=0, atol=1e-12)
    assert json.loads((outdir / "metrics.json").read_text())["image_shift"] == [1, 0]


# ----------------------------------------------------------------------------- batch
def test_batch_options_take_none_a_pair_or_auto():
    assert BatchOptions().image_shift is None
    assert BatchOptions(image_shift="auto").image_shift == "auto"
    stored = BatchOptions(image_shift=[np.int64(-1), 2]).image_shift
    assert stored == (-1, 2) and type(stored) is tuple and all(type(v) is int for v in stored)
    with pytest.raises(ValueError, match="image_shift") as info:
        BatchOptions(image_shift="AUTO")
    assert info.value.option == "image_shift"
    with pytest.raises(TypeError, match="image_shift") as info:
        BatchOptions(image_shift=(True, 0))
    assert info.value.option == "image_shift"


def test_batch_fingerprint_names_the_shift_only_when_given():
    assert "image_shift" not in csvlog.fingerprint([], BatchOptions())["options"]
    assert csvlog.fingerprint([], BatchOptions(image_shift=(1, -2)))["options"]["image_shift"] == [1, -2]
    assert csvlog.fingerprint([], BatchOptions(image_shift="auto"))["options"]["image_shift"] == "auto"


def test_evaluate_frame_moves_the_image():
    image, depth = make_scene()
    out = evaluate_frame(image, depth, keep_fraction=0.1, seed=3, weights=FAST_WEIGHTS, solver="direct",
                         image_shift=(1, 0))
    sparse, mask = sd.sample_depth(depth, fraction=0.1, seed=3)
    np.testing.assert_allclose(out.depth, _completed(sd.shift_image(image, (1, 0)), sparse, mask), rtol=0, atol=1e-12)
    assert out.image_shift == (1, 0) and out.image_shift_fallback is None


def test_evaluate_frame_auto_and_its_silent_fallback():
    image, depth = make_scene()
    image = sd.shift_image(image, OFFSET)
    out = evaluate_frame(image, depth, keep_fraction=0.3, seed=5, weights=FAST_WEIGHTS, solver="direct",
                         image_shift="auto")
    sparse, mask = sd.sample_depth(depth, fraction=0.3, seed=5)
    estimate = sd.estimate_image_shift(image, sparse, mask).shift
    assert out.image_shift == estimate != (0, 0) and out.image_shift_fallback is None
    np.testing.assert_allclose(out.depth, _completed(sd.shift_image(image, estimate), sparse, mask), rtol=0, atol=1e-12)

    few = np.zeros_like(depth)
    few[5, 5], few[30, 50], few[20, 10] = 1.2, 2.4, 1.6
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning, no exception
        out = evaluate_frame(image, few, weights=FAST_WEIGHTS, solver="direct", image_shift="auto",
                             clip_to_observed=False)
    assert out.image_shift == (0, 0) and "at least 8" in out.image_shift_fallback
    expected = sd.complete_depth(image, few, weights=FAST_WEIGHTS, solver="direct", clip_to_observed=False).depth
    np.testing.assert_allclose(out.depth, expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("value, kind", [("left", ValueError), (1.5, TypeError), ((0, 0.5), TypeError)])
def test_evaluate_frame_refuses_a_bad_shift(value, kind):
    image, depth = make_scene()
    with pytest.raises(kind, match="image_shift"):
        evaluate_frame(image, depth, keep_fraction=0.1, image_shift=value)


def test_cli_batch_moves_every_frame_and_keeps_the_csv_columns(tmp_path, capsys):
    image, depth = make_scene()
    for key, seed in (("a", 0), ("b", 1)):
        iio.imwrite(tmp_path / f"rgb_{key}.png", image)
        sd.write_depth(tmp_path / f"depth_{key}.png", depth + 0.1 * seed, scale=1000)
    out = tmp_path / "out"
    out.mkdir()
    rc = main(["--batch", str(tmp_path), "--depth-scale", "mm", "--keep-fraction", "0.1", "--seed", "2",
               "--image-shift", "-1,2", "--csv", str(tmp_path / "m.csv"), "--outdir", str(out), "--workers", "1",
               "-q", *FAST])
    assert rc == 0, capsys.readouterr().err
    with open(tmp_path / "m.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert list(rows[0]) == list(sd.batch.CSV_COLUMNS) and len(rows) == 2
    for position, key in enumerate(("a", "b")):
        truth = sd.read_depth(tmp_path / f"depth_{key}.png", scale=1000)
        observed = sd.sample_mask(truth, fraction=0.1, seed=np.random.default_rng([2, position]))
        expected = _completed(sd.shift_image(image, (-1, 2)), np.where(observed, truth, np.nan), observed)
        np.testing.assert_allclose(np.load(out / f"{key}.npy"), expected, rtol=0, atol=1e-12)
    settings = json.loads((tmp_path / "m.csv.settings.json").read_text())
    assert settings["options"]["image_shift"] == [-1, 2]
