"""Errors that name what the user typed: huge --image-shift, a full disk in a batch, intrinsics that overflow the
point cloud, frames too small for the uncertainty; and uncertainty maps written as they are (sigma = 0 kept)."""

import csv
import errno
import warnings
from concurrent.futures import ThreadPoolExecutor

import imageio.v3 as iio
import numpy as np
import pytest
import tifffile

import sparsedepth as sd
import sparsedepth.batch.csvlog
import sparsedepth.batch.worker
from conftest import make_scene
from sparsedepth.batch import BatchOptions, find_frames, run_batch
from sparsedepth.cli.checks import check_frame, check_options
from sparsedepth.cli.messages import UsageError
from sparsedepth.cli.parser import build_parser
from sparsedepth.cli.report import uncertainty_png
from sparsedepth.complete import main
from sparsedepth.io.pfm import read_pfm
from sparsedepth.io.writing import png_saturated, uncertainty_writer, write_uncertainty
from sparsedepth.uncertainty import check_uncertainty_shape, estimate_uncertainty

FAST = ["--gamma", "0", "--solver", "direct"]
HUGE = 99999999999999999999  # beyond int64


@pytest.fixture
def files(tmp_path):
    image, depth = make_scene((20, 30))
    iio.imwrite(tmp_path / "rgb.png", image)
    sd.write_depth(tmp_path / "dense.png", depth, scale=1000)
    return tmp_path


def _base(files):
    return ["--image", str(files / "rgb.png"), "--depth", str(files / "dense.png"), "--depth-scale", "mm",
            "--keep-fraction", "0.3", "-q", *FAST]


def _refused(argv, capsys, *expected):
    """main(argv) exits 2 with one error line holding every ``expected`` text, no traceback, no Python warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        rc = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2, err
    errors = [line for line in err.splitlines() if line.startswith("python -m sparsedepth.complete: error:")]
    assert len(errors) == 1, err
    assert "Traceback" not in err and "RuntimeWarning" not in err
    for text in expected:
        assert text in errors[0], err
    return errors[0]


def _args(argv):
    args = build_parser().parse_args([str(a) for a in argv])
    return args, check_options(args)


# ----------------------------------------------------------------------------- --image-shift
@pytest.mark.parametrize("shift", [(HUGE, 0), (0, -HUGE), (3, 0), (0, 4), (-3, 0)])
def test_shift_image_refuses_a_shift_that_leaves_the_frame(shift):
    image = np.arange(12).reshape(3, 4)
    with pytest.raises(ValueError, match=r"out of its 3x4 \(H x W\) frame"):
        sd.shift_image(image, shift)
    np.testing.assert_array_equal(sd.shift_image(image, (-2, 3)), [[8, 8, 8, 8]] * 3)  # the largest that fits


def test_huge_image_shift_on_the_command_line_is_one_line(files, capsys):
    _refused([*_base(files), f"--image-shift={HUGE},0"], capsys, f"--image-shift {HUGE},0", "--max-pixels")


def test_image_shift_beyond_the_frame_names_the_option_and_the_frame_size(files):
    args, mode = _args([*_base(files), "--image-shift", "0,30"])
    image, depth = sd.read_image(files / "rgb.png"), sd.read_depth(files / "dense.png", scale=1000)
    with pytest.raises(UsageError, match=r"--image-shift \(0, 30\) moves the image out of its 20x30"):
        check_frame(args, mode, image, depth)
    args, mode = _args([*_base(files), "--image-shift", "0,29"])
    check_frame(args, mode, image, depth)


# ----------------------------------------------------------------------------- a full disk in a batch
def _batch(tmp_path):
    for key in ("a", "b"):
        image, depth = make_scene((16, 20), seed=len(key))
        iio.imwrite(tmp_path / f"rgb_{key}.png", image)
        sd.write_depth(tmp_path / f"depth_{key}.png", depth, scale=1000)
    out = tmp_path / "out"
    out.mkdir()
    options = BatchOptions(keep_fraction=0.3, seed=7, weights=sd.Weights(gamma=0.0), solver="direct",
                           depth_scale="mm", out_dir=str(out))
    return find_frames(tmp_path), options, out


def test_full_disk_for_an_output_names_the_file_and_outdir(tmp_path, monkeypatch):
    frames, options, out = _batch(tmp_path)

    def too_large(path, *a, **k):
        raise OSError(errno.EFBIG, "File too large")

    monkeypatch.setattr(sparsedepth.batch.worker, "write_depth", too_large)
    with ThreadPoolExecutor(1) as executor:
        summary = run_batch(frames, tmp_path / "m.csv", options=options, executor=executor)
    with open(tmp_path / "m.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert summary.failed == 2 and sorted(r["name"] for r in rows) == ["a", "b"]  # one row per frame
    for row in rows:
        assert f"'{out / (row['name'] + '.npy')}'" in row["error"]
        assert "--outdir" in row["error"] and "File too large" in row["error"]


def test_full_disk_for_the_csv_names_the_file_and_csv_and_keeps_the_rows(tmp_path, monkeypatch, capsys):
    frames, options, out = _batch(tmp_path)
    real, written = sparsedepth.batch.csvlog.csv_line, []

    def full_after_one(row):
        if written:
            raise OSError(errno.EFBIG, "File too large")
        written.append(row["name"])
        return real(row)

    monkeypatch.setattr(sparsedepth.batch.csvlog, "csv_line", full_after_one)
    csv_path = tmp_path / "m.csv"
    line = _refused(["--batch", tmp_path, "--csv", csv_path, "--outdir", out, "--out-format", "npy",
                     "--depth-scale", "mm", "--keep-fraction", "0.3", "--workers", "1", *FAST, "-q"], capsys,
                    f"'{csv_path}'", "--csv", "File too large")
    assert "the row of frame" in line
    with open(csv_path, newline="") as fh:
        assert [r["name"] for r in csv.DictReader(fh)] == written  # the row written before is kept


def test_full_disk_for_the_settings_file_names_it(tmp_path, monkeypatch):
    frames, options, _ = _batch(tmp_path)

    def no_space(path, text):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(sparsedepth.batch.csvlog, "write_text_atomic", no_space)
    with pytest.raises(OSError, match=r"settings of the batch .*--csv.*No space left on device") as caught:
        run_batch(frames, tmp_path / "m.csv", options=options, executor=ThreadPoolExecutor(1))
    assert caught.value.errno == errno.ENOSPC


# ----------------------------------------------------------------------------- intrinsics and the point cloud
def test_depth_to_points_refuses_intrinsics_that_overflow_float32_without_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=r"`intrinsics` .*1e-40.* beyond the float32 range"):
            sd.depth_to_points(np.full((3, 4), 2.0), (1e-40, 1.0, 0.0, 0.0))
        with pytest.raises(ValueError, match=r"--intrinsics .*\|y\| up to inf"):
            sd.depth_to_points(np.full((3, 4), 2.0), (1.0, 1e-320, 0.0, 0.0), name="--intrinsics")
        points, _ = sd.depth_to_points(np.full((3, 4), 2.0), (1e-30, 1.0, 0.0, 0.0))  # 6e30 m fits float32
    assert points[:, 0].max() == np.float32(3 * 2.0 / 1e-30)


def test_intrinsics_that_overflow_the_ply_are_one_line_without_runtime_warnings(files, capsys):
    _refused([*_base(files), "--intrinsics", "1e-40,1e-40,0,0", "--ply", files / "c.ply"], capsys, "intrinsics",
             "float32")
    assert not (files / "c.ply").exists()


def test_check_frame_names_intrinsics_and_ply(files):
    args, mode = _args([*_base(files), "--intrinsics", "1e-40,1,0,0", "--ply", files / "c.ply"])
    image, depth = sd.read_image(files / "rgb.png"), sd.read_depth(files / "dense.png", scale=1000)
    with pytest.raises(UsageError, match=r"--intrinsics 1e-40,1,0,0: the --ply point cloud of this 20x30"):
        check_frame(args, mode, image, depth, intrinsics=args.intrinsics)
    check_frame(args, mode, image, depth, intrinsics=(1e-30, 1.0, 0.0, 0.0))  # fits


# ----------------------------------------------------------------------------- the uncertainty's frame size
@pytest.mark.parametrize("shape", [(1, 50), (50, 1), (1, 1)])
def test_uncertainty_needs_two_rows_and_two_columns(shape):
    with pytest.raises(ValueError, match=rf"uncertainty needs a frame of at least 2x2 pixels .* {shape[0]}x{shape[1]}"):
        check_uncertainty_shape(shape)
    depth = np.ones(shape)
    half_a = np.zeros(shape, bool)
    half_a.flat[0] = True
    with pytest.raises(ValueError, match="at least 2x2 pixels"):
        estimate_uncertainty(depth, depth, depth, depth, half_a, ~half_a)
    check_uncertainty_shape((2, 2))


def test_uncertainty_of_a_one_row_frame_on_the_command_line(tmp_path, capsys):
    image, depth = make_scene((20, 30))
    iio.imwrite(tmp_path / "rgb.png", image[:1])
    sd.write_depth(tmp_path / "dense.png", depth[:1], scale=1000)
    _refused([*_base(tmp_path), "--keep-fraction", "0.6", "--uncertainty", tmp_path / "s.npy"], capsys,
             "uncertainty needs a frame of at least 2x2 pixels", "1x30")
    args, mode = _args([*_base(tmp_path), "--max-uncertainty", "1"])
    with pytest.raises(UsageError, match=r"--max-uncertainty needs a frame of at least 2x2 pixels.* 1x30"):
        check_frame(args, mode, image[:1], depth[:1])


# ----------------------------------------------------------------------------- writing the uncertainty
@pytest.mark.parametrize("ext", ["npy", "npz", "h5", "tif", "pfm"])
def test_float_formats_keep_sigma_zero_and_only_nan_is_missing(tmp_path, ext):
    sigma = np.array([[0.0, 0.25, np.nan], [3.5, 0.0, 1e-6]])
    path = tmp_path / f"s.{ext}"
    write_uncertainty(path, sigma)
    if ext == "npy":
        stored = np.load(path)
    elif ext == "npz":
        stored = np.load(path)["depth"]
    elif ext == "h5":
        import h5py
        with h5py.File(path) as handle:
            stored = handle["depth"][()]
    elif ext == "tif":
        stored = tifffile.imread(path)
    else:
        stored = np.where(np.isinf(read_pfm(path)), np.nan, read_pfm(path))
    np.testing.assert_array_equal(np.isnan(stored), np.isnan(sigma))
    np.testing.assert_allclose(stored[~np.isnan(sigma)], sigma[~np.isnan(sigma)], rtol=1e-7)


def test_png_sigma_saturates_instead_of_failing(tmp_path):
    sigma = np.array([[0.0, 0.001, np.nan], [358.0, 255.99, 2.0]])  # KITTI's sky reaches 358 m
    write_uncertainty(tmp_path / "s.png", sigma, scale="kitti")
    stored = iio.imread(tmp_path / "s.png")
    np.testing.assert_array_equal(stored, [[1, 1, 0], [65535, 65533, 512]])
    assert png_saturated(sigma, 256) == 1 and png_saturated(sigma, 1) == 0
    with pytest.raises(ValueError, match="negative"):
        uncertainty_writer(tmp_path / "t.png", -sigma)
    assert not (tmp_path / "t.png").exists()


def test_report_counts_the_saturated_png_pixels():
    class Outcome:
        result = type("Result", (), {"uncertainty": np.array([[1.0, 300.0], [np.nan, 400.0]])})()

    args = type("Args", (), {"uncertainty": "sigma.PNG"})()
    assert uncertainty_png(args, Outcome, 256.0) == {"scale": 256.0, "largest": 65535 / 256, "saturated": 2}
    args.uncertainty = "sigma.npy"
    assert uncertainty_png(args, Outcome, 256.0) is None
