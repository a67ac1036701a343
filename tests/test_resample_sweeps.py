"""edge_aware_sweeps against a pixel-by-pixel red-black Gauss-Seidel loop, and its ways of taking the start, the
observations and the image; block means of integers and the fast mode's coarse image of a uint8/uint16 image."""
import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth._validation import as_float_image
from sparsedepth.grid.resample import block_mean, coarse_shape, edge_aware_sweeps, upsample_bilinear
from sparsedepth.modes.fast import _coarse_image


def _loop_sweeps(start, image, depth, observed, smoothness, kappa, sweeps):
    """Red-black Gauss-Seidel on the sweeps' model, one pixel at a time in float64 (pixels with y + x even first)."""
    H, W = start.shape
    image = np.asarray(image, dtype=np.float64).reshape(H, W, -1)
    z = np.where(observed, depth, start).astype(np.float64)

    def weight(a, b):
        return smoothness * np.exp(-kappa * np.linalg.norm(image[a] - image[b]))

    for _ in range(sweeps):
        for parity in (0, 1):
            for y in range(H):
                for x in range(W):
                    if (y + x) % 2 != parity or observed[y, x]:
                        continue
                    total, diagonal = float(start[y, x]), 1.0
                    for ny, nx in ((y, x - 1), (y, x + 1), (y - 1, x), (y + 1, x)):
                        if 0 <= ny < H and 0 <= nx < W:
                            w = weight((y, x), (ny, nx))
                            total += w * z[ny, nx]
                            diagonal += w
                    z[y, x] = total / diagonal
    return z


def _scene(shape, seed):
    rng = np.random.default_rng(seed)
    image = rng.random(shape + (3,))
    start = rng.random(shape) + 1.0
    depth = rng.random(shape) + 2.0
    observed = rng.random(shape) < 0.25
    return image, start, depth, observed


@pytest.mark.parametrize("band", [1, 4, 30, None])
@pytest.mark.parametrize("shape", [(1, 1), (1, 6), (7, 1), (2, 2), (5, 8), (8, 5), (6, 9), (9, 11), (10, 12)])
def test_edge_aware_sweeps_equal_a_pixel_loop_on_odd_and_even_grids(set_limits, shape, band):
    if band is not None:  # the half sweeps and the pair weights over chunks of `band` entries / rows
        set_limits(sweep_band_values=band)
    image, start, depth, observed = _scene(shape, seed=shape[0] * 31 + shape[1])
    got = edge_aware_sweeps(start, image, depth, observed, smoothness=4.0, kappa=1.5, sweeps=3)
    expected = _loop_sweeps(start, image, depth, observed, 4.0, 1.5, 3)
    assert got.dtype == np.float32 and got.shape == shape
    np.testing.assert_allclose(got, expected, rtol=1e-5)
    np.testing.assert_array_equal(got[observed], depth[observed].astype(np.float32))


def test_edge_aware_sweeps_move_the_free_pixels():
    image, start, depth, observed = _scene((6, 7), seed=3)
    got = edge_aware_sweeps(start, image, depth, observed, smoothness=4.0, kappa=1.5, sweeps=1)
    free = ~observed
    assert np.all(np.abs(got[free] - start[free]) > 1e-4)  # the comparisons with the loop can fail


@pytest.mark.parametrize("shape, factor", [((9, 11), 2), ((12, 10), 3), ((13, 17), 4), ((5, 7), 1)])
def test_edge_aware_sweeps_from_a_coarse_start_equal_the_sweeps_from_its_interpolation(set_limits, shape, factor):
    set_limits(sweep_band_values=8)  # the interpolation over bands of 2 rows
    image, _, depth, observed = _scene(shape, seed=5)
    coarse = np.random.default_rng(6).random(coarse_shape(shape, factor)) + 1.0
    fine = upsample_bilinear(coarse, shape, factor)
    expected = _loop_sweeps(fine, image, depth, observed, 2.0, 3.0, 2)
    got = edge_aware_sweeps(coarse, image, depth, observed, smoothness=2.0, kappa=3.0, sweeps=2, start_factor=factor)
    np.testing.assert_allclose(got, expected, rtol=1e-5)
    none = edge_aware_sweeps(coarse, image, depth, observed, smoothness=2.0, kappa=3.0, sweeps=0, start_factor=factor)
    np.testing.assert_allclose(none, np.where(observed, depth, fine), rtol=1e-6)
    with pytest.raises(ValueError, match="start has shape"):
        edge_aware_sweeps(fine, image, depth, observed, smoothness=2.0, kappa=3.0, sweeps=2, start_factor=factor + 1)


def test_edge_aware_sweeps_take_the_observed_values_alone_a_uint8_image_and_return_float64():
    image, start, depth, observed = _scene((9, 10), seed=7)
    image8 = (image * 255).round().astype(np.uint8)
    expected = _loop_sweeps(start, image8 / 255.0, depth, observed, 4.0, 1.5, 3)
    got = edge_aware_sweeps(start, image8, depth[observed], observed, smoothness=4.0, kappa=1.5, sweeps=3,
                            dtype=np.float64)
    assert got.dtype == np.float64
    np.testing.assert_allclose(got, expected, rtol=1e-5)
    with pytest.raises(ValueError, match="one per observed pixel"):
        edge_aware_sweeps(start, image8, depth[observed][1:], observed, smoothness=4.0, kappa=1.5, sweeps=3)
    with pytest.raises(ValueError, match="dtype"):
        edge_aware_sweeps(start, image8, depth, observed, smoothness=4.0, kappa=1.5, sweeps=3, dtype=np.int32)


@pytest.mark.parametrize("channels", [None, 1, 3, 4])
@pytest.mark.parametrize("dtype, top", [(np.uint8, 255), (np.uint16, 65535)])
def test_fast_coarse_image_of_integers_is_the_block_mean_of_the_scaled_image(channels, dtype, top):
    rng = np.random.default_rng(8)
    shape = (23, 17) if channels is None else (23, 17, channels)
    image = rng.integers(0, top + 1, size=shape).astype(dtype)
    for factor in (2, 3, 4):
        scaled = image[..., :3].astype(np.float64) / top if channels else image[..., None] / top
        loops = np.array([[scaled[y:y + factor, x:x + factor].reshape(-1, scaled.shape[2]).mean(axis=0)
                           for x in range(0, 17, factor)] for y in range(0, 23, factor)])
        got = _coarse_image(image, factor)
        np.testing.assert_allclose(got, loops, rtol=1e-6)
        np.testing.assert_allclose(got, np.clip(block_mean(as_float_image(image, dtype=np.float32), factor), 0, 1),
                                   rtol=1e-6)


def test_fast_mode_of_a_uint8_image_and_of_its_float_scaling_agree():
    rng = np.random.default_rng(9)
    image = rng.integers(0, 256, size=(40, 52, 3)).astype(np.uint8)
    truth = np.add.outer(np.linspace(1.0, 2.0, 40), np.linspace(0.0, 1.0, 52))
    sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=0)
    from_uint8 = sd.complete_depth(image, sparse, mask, quality="fast").depth
    from_float = sd.complete_depth(image / 255.0, sparse, mask, quality="fast").depth
    np.testing.assert_allclose(from_uint8, from_float, rtol=1e-4)
    with pytest.raises(ValueError, match="must lie in"):
        sd.complete_depth(image / 128.0, sparse, mask, quality="fast")


@pytest.mark.parametrize("dtype, low, high", [(np.uint8, 0, 256), (bool, 0, 2), (np.uint16, 0, 65536),
                                              (np.int16, -32768, 32768), (np.int32, -2**31, 2**31)])
@pytest.mark.parametrize("factor", [1, 3, 16, 17])
def test_block_mean_of_integers_is_exact(dtype, low, high, factor):
    rng = np.random.default_rng(10)
    values = rng.integers(low, high, size=(37, 35, 2), dtype=np.int64).astype(dtype)
    if dtype in (np.uint8, bool):
        values[:17, :17] = high - 1  # full 17 x 17 blocks of the largest value: past a uint16 sum at f = 17
    got = block_mean(values, factor)
    h, w = coarse_shape((37, 35), factor)
    for y in range(h):
        for x in range(w):
            block = values[y * factor:(y + 1) * factor, x * factor:(x + 1) * factor].astype(np.int64)
            for c in range(2):
                assert got[y, x, c] == int(block[..., c].sum()) / block[..., c].size  # exact sum, one rounding
