"""expected_error: a completion's and nearest fill's RMSE estimated from the samples alone, on scenes whose true
error is known by construction; complete_depth(expected_error=True), its warning, and the command line's line."""

import json
import re
import warnings

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

import sparsedepth as sd
from sparsedepth.complete import main
from sparsedepth.expected_error import (DEFAULT_FACTOR, MIN_TILE, ExpectedError, distance_model, expected_error,
                                        tile_folds)


@pytest.fixture
def image():
    return np.random.default_rng(0).random((96, 120, 3))


def _quiet(function, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        return function(*args, **kwargs)


def test_a_constant_scene_has_no_expected_error(image):
    truth = np.full(image.shape[:2], 2.0)
    sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=0)
    estimate = expected_error(image, sparse, mask)
    assert isinstance(estimate, ExpectedError)
    assert estimate.rmse == pytest.approx(0.0, abs=1e-9) and estimate.nearest_rmse == pytest.approx(0.0, abs=1e-9)
    assert estimate.held_out == mask.sum() and estimate.folds == 3


def test_a_tilted_plane_nearest_fill_error_is_predicted(image):
    """Nearest fill of a plane errs by the gradient times the offset to the nearest sample: the estimate, fitted on
    held-out samples at other distances, matches the true RMSE; the completion's is expected smaller."""
    rows, cols = np.mgrid[0:96, 0:120]
    plane = 1.0 + 0.01 * cols + 0.005 * rows
    sparse, mask = sd.sample_depth(plane, fraction=0.05, seed=0)
    estimate = expected_error(image, sparse, mask)
    true_nearest = np.sqrt(np.mean((sd.nearest_fill(sparse, mask) - plane)[~mask] ** 2))
    assert estimate.nearest_rmse == pytest.approx(true_nearest, rel=0.3)
    assert estimate.rmse < estimate.nearest_rmse and estimate.beats_nearest


def test_sample_noise_is_measured_against_a_new_measurement(image):
    """Constant depth 2 with relative noise s at the samples (sigma = 2 s): nearest fill's held-out error is the
    difference of two independent noisy samples, sigma * sqrt(2), whatever the distance."""
    truth = np.full(image.shape[:2], 2.0)
    relative = 0.025
    sparse, mask = sd.sample_depth(truth, fraction=0.1, seed=0, noise=relative)
    sigma = 2.0 * relative
    estimate = expected_error(image, sparse, mask)
    assert estimate.nearest_rmse == pytest.approx(np.sqrt(2.0) * sigma, rel=0.15)
    assert estimate.rmse == pytest.approx(DEFAULT_FACTOR * sigma, rel=0.3)  # the completion averages the noise


def _cells(image):
    """Constant cells of 12x12 pixels, each observed on its inner 10x10 block: nearest fill is exact."""
    depth = np.kron(np.random.default_rng(1).uniform(1, 3, (8, 10)), np.ones((12, 12)))
    mask = np.zeros(depth.shape, bool)
    for row in range(1, 11):
        for col in range(1, 11):
            mask[row::12, col::12] = True
    return np.where(mask, depth, np.nan), mask, depth


def test_where_nearest_fill_is_exact_the_warning_fires(image):
    sparse, mask, depth = _cells(image)
    assert np.array_equal(sd.nearest_fill(sparse, mask), depth)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = sd.complete_depth(image, sparse, mask, expected_error=True)
    assert [w for w in caught if issubclass(w.category, sd.NoGainWarning)]
    assert result.expected_rmse >= result.expected_nearest_rmse
    true_rmse = np.sqrt(np.mean((result.depth - depth)[~mask] ** 2))
    assert true_rmse > 0.05  # the completion really is worse than the exact nearest fill


def test_complete_depth_stores_what_expected_error_returns(image):
    rows, cols = np.mgrid[0:96, 0:120]
    truth = 1.0 + np.sin(cols / 15.0) * 0.3 + rows / 100.0
    sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=0)
    plain = _quiet(sd.complete_depth, image, sparse, mask)
    assert np.isnan(plain.expected_rmse) and np.isnan(plain.expected_nearest_rmse)
    for quality in ("default", "fast"):
        with warnings.catch_warnings():
            warnings.simplefilter("error", sd.NoGainWarning)
            warnings.simplefilter("ignore", sd.ClampWarning)
            result = sd.complete_depth(image, sparse, mask, quality=quality, expected_error=True)
        estimate = expected_error(image, sparse, mask, quality=quality,
                                  completed=result.depth if quality == "default" else None)
        assert result.expected_rmse == estimate.rmse and result.expected_nearest_rmse == estimate.nearest_rmse
    assert np.array_equal(result.depth, _quiet(sd.complete_depth, image, sparse, mask, quality="fast").depth)
    assert expected_error(image, sparse, mask).rmse == pytest.approx(
        DEFAULT_FACTOR * expected_error(image, sparse, mask, quality="fast").rmse)


def test_the_default_completions_own_factor(image):
    """Given the default completion, the factor is sqrt(1 - mean (z_d - z_f)^2 / fast MSE), within [0.5, 1]: 1 when
    the completion is the fast one itself, 0.5 when it departs from it by more than the fast error."""
    rows, cols = np.mgrid[0:96, 0:120]
    truth = 1.0 + np.sin(cols / 15.0) * 0.3 + rows / 100.0
    sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=0)
    fast = _quiet(sd.complete_depth, image, sparse, mask, quality="fast").depth
    fast_estimate = expected_error(image, sparse, mask, quality="fast")
    same = expected_error(image, sparse, mask, completed=fast)
    assert same.factor == 1.0 and same.rmse == pytest.approx(fast_estimate.rmse)
    shift = 0.5 * fast_estimate.rmse
    shifted = expected_error(image, sparse, mask, completed=fast + shift)
    assert shifted.factor == pytest.approx(np.sqrt(1 - shift ** 2 / fast_estimate.rmse ** 2))
    far = expected_error(image, sparse, mask, completed=fast + 10 * fast_estimate.rmse)
    assert far.factor == 0.5 and far.rmse == pytest.approx(0.5 * fast_estimate.rmse)
    assert expected_error(image, sparse, mask).factor == DEFAULT_FACTOR


def test_the_estimate_is_a_function_of_the_seed(image):
    rows, cols = np.mgrid[0:96, 0:120]
    truth = 1.0 + np.cos(rows / 9.0) * 0.2 + cols / 200.0
    sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=3)
    assert expected_error(image, sparse, mask, seed=4) == expected_error(image, sparse, mask, seed=4)


def test_region_restricts_the_pixels_averaged_over(image):
    rows, cols = np.mgrid[0:96, 0:120]
    truth = 1.0 + 0.01 * cols
    sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=0)
    left = cols < 60
    estimate = expected_error(image, sparse, mask, region=left)
    assert estimate.pixels == np.count_nonzero(left & ~mask)


def test_distance_model_recovers_a_power_law():
    distance = np.repeat(np.arange(1.0, 33.0), 50)
    model, exponent, largest = distance_model(distance, 0.01 * distance)
    assert exponent == pytest.approx(1.0, abs=1e-6)
    assert model(np.array([2 * largest]))[0] == pytest.approx(0.01 * 2 * largest, rel=0.05)
    _, steep, _ = distance_model(distance, distance ** 4)
    assert steep == 2.0  # bounded


def test_arguments_are_checked(image):
    truth = np.full(image.shape[:2], 2.0)
    sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=0)
    with pytest.raises(ValueError, match="folds"):
        expected_error(image, sparse, mask, folds=1)
    with pytest.raises(ValueError, match="quality"):
        expected_error(image, sparse, mask, quality="slow")
    with pytest.raises(ValueError, match="region has shape"):
        expected_error(image, sparse, mask, region=np.ones((3, 3), bool))
    with pytest.raises(ValueError, match="completed has shape"):
        expected_error(image, sparse, mask, completed=np.ones((3, 3)))
    few = np.zeros_like(mask)
    few[0, :10] = True
    with pytest.raises(ValueError, match="at least 16"):
        expected_error(image, np.where(few, 2.0, np.nan), few)
    with pytest.raises(TypeError, match="expected_error must be True or False"):
        sd.complete_depth(image, sparse, mask, expected_error="yes")
    with pytest.raises(ValueError, match="cannot be combined with prior"):
        sd.complete_depth(image, sparse, mask, expected_error=True, prior=truth)


def test_the_command_line_prints_one_line_and_reports_both(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["--downsample", "8", "--expected-error", "--json", "r.json", "-q", "--outdir", "."]) == 0
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if line.startswith("expected RMSE")]
    assert len(lines) == 1
    match = re.fullmatch(r"expected RMSE ~ (\S+) m \(nearest fill ~ (\S+) m\)", lines[0])
    report = json.loads((tmp_path / "r.json").read_text())
    assert float(match.group(1)) == pytest.approx(report["expected_rmse"], rel=5e-3)
    assert float(match.group(2)) == pytest.approx(report["expected_nearest_rmse"], rel=5e-3)
    assert main(["--downsample", "8", "--json", "plain.json", "-q", "--outdir", "."]) == 0
    assert "expected RMSE" not in capsys.readouterr().out
    assert "expected_rmse" not in json.loads((tmp_path / "plain.json").read_text())


def test_the_command_line_refuses_it_with_a_prior(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["--image", "rgb.png", "--depth", "d.png", "--prior", "p.npy", "--expected-error"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--expected-error" in err[0] and "--prior" in err[0]


def test_the_command_line_warns_in_one_line_where_nearest_fill_is_exact(image, tmp_path, capsys, monkeypatch):
    import imageio.v3 as iio

    monkeypatch.chdir(tmp_path)
    sparse, mask, _ = _cells(image)
    iio.imwrite("rgb.png", (image * 255).astype(np.uint8))
    np.save("depth.npy", np.where(mask, sparse, 0.0))
    assert main(["--image", "rgb.png", "--depth", "depth.npy", "--out", "dense.npy", "--expected-error", "-q"]) == 0
    captured = capsys.readouterr()
    warned = [line for line in captured.err.splitlines() if "not expected to beat nearest fill" in line]
    assert len(warned) == 1 and warned[0].startswith("warning: ")
    line = next(line for line in captured.out.splitlines() if line.startswith("expected RMSE"))
    expected, nearest = map(float, re.findall(r"~ (\S+) m", line))
    assert expected >= nearest


@pytest.mark.parametrize("source", [["--batch", "frames"], ["--colmap", "sparse", "--images", "images"]])
def test_the_command_line_refuses_it_for_a_batch(source, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for folder in ("frames", "sparse", "images", "out"):
        (tmp_path / folder).mkdir()
    assert main([*source, "--outdir", "out", "--csv", "out/rows.csv", "--expected-error"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--expected-error is for one frame" in err[0]


def test_the_samples_of_one_tile_share_a_fold():
    """tile_folds (the folds of expected_error and of quality='best'): a tile's samples are held out together, the
    tile side follows the target pixels' distances, and the folds come from the seed alone."""
    mask = np.random.default_rng(3).random((90, 120)) < 0.02
    split = tile_folds(mask, ~mask, 3, 0)
    rows, cols = np.nonzero(mask)
    assert split.tile >= MIN_TILE and split.fold_of.shape == rows.shape and set(split.fold_of) == {0, 1, 2}
    tiles = (rows // split.tile) * 1000 + cols // split.tile
    for tile in np.unique(tiles):
        assert np.unique(split.fold_of[tiles == tile]).size == 1
    assert np.array_equal(split.fold_of, tile_folds(mask, ~mask, 3, 0).fold_of)
    np.testing.assert_array_equal(split.target_distance, distance_transform_edt(~mask)[~mask])
