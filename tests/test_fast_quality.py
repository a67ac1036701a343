"""complete_depth(quality="fast"): a coarse solve, upsampled; checked against hand-made scenes and the default solve."""

import warnings

import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.completion import _block_counts, _block_sums, _fast_factor, _upsample

from conftest import make_problem


def _rmse(a, b, where):
    return float(np.sqrt(np.mean((a[where] - b[where]) ** 2)))


def test_block_sums_and_counts_against_loops():
    rng = np.random.default_rng(0)
    values = rng.standard_normal((7, 10))
    sums = _block_sums(values, 4)
    counts = _block_counts(values.shape, 4)
    assert sums.shape == counts.shape == (2, 3)
    for i in range(2):
        for j in range(3):
            block = values[4 * i:4 * i + 4, 4 * j:4 * j + 4]
            assert sums[i, j] == pytest.approx(block.sum(), abs=1e-12)
            assert counts[i, j] == block.size
    image = rng.random((7, 10, 3)).astype(np.float32)
    np.testing.assert_allclose(_block_sums(image, 2)[1, 2], image[2:4, 4:6].sum(axis=(0, 1)), rtol=1e-6)


def test_upsample_is_bilinear_between_block_centres():
    f = 4
    coarse = np.add.outer(np.arange(5.0) * 2.0, np.arange(6.0) * 3.0)  # a plane in block units
    fine = _upsample(coarse, f, (20, 24))
    ii, jj = np.mgrid[0:20, 0:24]
    u, v = (ii - 1.5) / f, (jj - 1.5) / f  # pixel position in block-centre units
    inside = (u >= 0) & (u <= 4) & (v >= 0) & (v <= 5)
    np.testing.assert_allclose(fine[inside], (2.0 * u + 3.0 * v)[inside], rtol=0, atol=1e-12)
    # outside the outermost centres the value is held (clamped coordinates)
    np.testing.assert_allclose(fine[0, 10], fine[1, 10])


def test_fast_factor():
    assert _fast_factor((480, 640)) == 4 and _fast_factor((100, 640)) == 2 and _fast_factor((20, 30)) == 1


def test_a_constant_scene_stays_constant():
    rng = np.random.default_rng(2)
    image = rng.integers(0, 256, (130, 150, 3), dtype=np.uint8)
    mask = rng.random((130, 150)) < 0.05
    res = sd.complete_depth(image, np.where(mask, 2.25, np.nan), mask, quality="fast")
    np.testing.assert_allclose(res.depth, 2.25, rtol=1e-9)
    assert res.clamped == 0 and np.isnan(res.objective) and res.terms == {}
    assert "quality='fast': solved on 4x4 blocks" in res.message


@pytest.mark.parametrize("shape", [(64, 80), (160, 200)])
def test_fast_is_close_to_the_default_and_better_than_nearest(shape):
    image, sparse, mask, truth = make_problem(shape, fraction=0.05, seed=4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        fast = sd.complete_depth(image, sparse, mask, quality="fast")
        default = sd.complete_depth(image, sparse, mask)
    hidden = ~mask
    e_fast = _rmse(fast.depth, truth, hidden)
    e_default = _rmse(default.depth, truth, hidden)
    e_nearest = _rmse(sd.nearest_fill(sparse, mask), truth, hidden)
    assert e_fast < 0.8 * e_nearest
    assert e_fast < 1.5 * e_default
    lo, hi = fast.depth_range
    assert lo == np.nanmin(sparse) and hi == np.nanmax(sparse)
    assert np.all((fast.depth >= lo) & (fast.depth <= hi))
    assert fast.converged and fast.solver == "amg"


def test_units_do_not_matter_and_inputs_are_not_modified():
    image, sparse, mask, _ = make_problem((96, 128), fraction=0.05, seed=5)
    keep_image, keep_sparse, keep_mask = image.copy(), sparse.copy(), mask.copy()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        metres = sd.complete_depth(image, sparse, mask, quality="fast")
        millimetres = sd.complete_depth(image, sparse * 1000.0, mask, quality="fast")
    np.testing.assert_array_equal(image, keep_image)
    np.testing.assert_array_equal(sparse, keep_sparse)
    np.testing.assert_array_equal(mask, keep_mask)
    np.testing.assert_allclose(millimetres.depth, metres.depth * 1000.0, rtol=1e-5)


def test_bad_quality_and_what_fast_refuses():
    image, sparse, mask, _ = make_problem((40, 50))
    with pytest.raises(ValueError, match=r"quality must be one of \['default', 'fast'\]; got 'quick'"):
        sd.complete_depth(image, sparse, mask, quality="quick")
    with pytest.raises(ValueError, match="quality must be one of"):
        sd.complete_depth(image, sparse, mask, quality=None)
    with pytest.raises(ValueError, match=r"quality='fast' .* without gamma > 0; got gamma > 0: use quality='default'"):
        sd.complete_depth(image, sparse, mask, quality="fast", weights=sd.Weights(gamma=0.01))
    with pytest.raises(ValueError, match="without x0, uncertainty"):
        sd.complete_depth(image, sparse, mask, quality="fast", x0=np.ones((40, 50)), uncertainty=True)
    with pytest.raises(ValueError, match="without callback"):
        sd.complete_depth(image, sparse, mask, quality="fast", callback=lambda state: None)
    with pytest.raises(ValueError, match="image has shape"):
        sd.complete_depth(image[:30], sparse, mask, quality="fast")


def test_a_uint8_image_and_the_same_image_as_floats_give_the_same_depth():
    rng = np.random.default_rng(6)
    _, sparse, mask, _ = make_problem((130, 140), fraction=0.05, seed=6)
    image = rng.integers(0, 256, (130, 140, 3), dtype=np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        a = sd.complete_depth(image, sparse, mask, quality="fast")
        b = sd.complete_depth(image / 255.0, sparse, mask, quality="fast")
    np.testing.assert_allclose(a.depth, b.depth, rtol=1e-5)


def test_the_coarse_solve_stops_at_its_own_depth_tolerance_unless_told_otherwise():
    image, sparse, mask, _ = make_problem((130, 140), fraction=0.05, seed=8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        default = sd.complete_depth(image, sparse, mask, quality="fast")
        told = sd.complete_depth(image, sparse, mask, quality="fast", options={"depth_rtol": 1e-6})
        tight = sd.complete_depth(image, sparse, mask, quality="fast", tol=1e-10)
    scale = sd.solvers.depth_scale(sparse[mask])
    assert "depth tolerance %.1e" % (1e-3 * scale) in default.message
    assert "depth tolerance %.1e" % (1e-6 * scale) in told.message
    assert "remaining change" not in tight.message
    # the coarse solution moves by at most a few times its tolerance: the results agree to that
    assert np.sqrt(np.mean((default.depth - tight.depth) ** 2)) <= 3 * 1e-3 * scale
