import numpy as np
import pytest

from sparsedepth import depth_metrics, sample_depth, sample_mask


def test_metrics_hand_computed():
    gt = np.array([[1.0, 2.0], [4.0, 0.0]])  # 0 = invalid, not scored
    pred = np.array([[1.5, 2.0], [2.0, 7.0]])
    m = depth_metrics(pred, gt)
    err = np.array([0.5, 0.0, -2.0])
    assert m.count == 3
    assert m.rmse == pytest.approx(np.sqrt(np.mean(err**2)))
    assert m.mae == pytest.approx(2.5 / 3)
    assert m.rel == pytest.approx((0.5 / 1 + 0 + 2 / 4) / 3)
    # ratios 1.5, 1.0, 2.0 -> delta1: 1/3, delta2 (1.5625): 2/3, delta3 (1.953): 2/3
    assert m.delta1 == pytest.approx(1 / 3)
    assert m.delta2 == pytest.approx(2 / 3)
    assert m.delta3 == pytest.approx(2 / 3)


def test_metrics_mask_restricts():
    gt = np.array([[1.0, 2.0], [4.0, np.nan]])
    pred = np.array([[1.5, 2.0], [2.0, 7.0]])
    m = depth_metrics(pred, gt, mask=np.array([[False, True], [True, True]]))
    assert m.count == 2 and m.mae == pytest.approx(1.0)


def test_metrics_zero_prediction_is_not_accurate():
    m = depth_metrics(np.zeros((1, 2)), np.ones((1, 2)))
    assert m.delta3 == 0.0 and m.rel == 1.0


def test_metrics_errors():
    with pytest.raises(ValueError, match="no pixel to score"):
        depth_metrics(np.ones((2, 2)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="shape"):
        depth_metrics(np.ones((2, 2)), np.ones((2, 3)))


def test_sampling_fraction_and_count_are_seeded():
    depth = np.random.default_rng(0).random((50, 60)) + 0.5
    depth[:10] = 0  # invalid rows
    m1 = sample_mask(depth, fraction=0.05, seed=7)
    m2 = sample_mask(depth, fraction=0.05, seed=7)
    m3 = sample_mask(depth, fraction=0.05, seed=8)
    np.testing.assert_array_equal(m1, m2)
    assert not np.array_equal(m1, m3)
    assert m1.sum() == round(0.05 * 40 * 60)
    assert not m1[:10].any()  # only valid pixels
    assert sample_mask(depth, count=200, seed=1).sum() == 200
    sparse, mask = sample_depth(depth, count=500, seed=1)
    assert np.array_equal(np.isfinite(sparse), mask)
    np.testing.assert_array_equal(sparse[mask], depth[mask])


def test_sampling_errors():
    depth = np.ones((5, 5))
    with pytest.raises(ValueError, match="exactly one"):
        sample_mask(depth)
    with pytest.raises(ValueError, match="exactly one"):
        sample_mask(depth, fraction=0.1, count=3)
    with pytest.raises(ValueError, match="fraction"):
        sample_mask(depth, fraction=1.5)
    with pytest.raises(ValueError, match="exceeds"):
        sample_mask(depth, count=26)
    with pytest.raises(ValueError, match="no valid pixel"):
        sample_mask(np.zeros((5, 5)), fraction=0.5)


@pytest.mark.parametrize("count", [0, -3, 2.0, True, "5"])
def test_sample_count_must_be_an_integer_of_at_least_one(count):
    # the shared count rule: a float (even 2.0) or a bool is not a pixel count
    depth = np.ones((10, 12))
    with pytest.raises(ValueError, match="count must be an integer >= 1"):
        sample_mask(depth, count=count, seed=0)


def test_sample_count_accepts_numpy_integers():
    depth = np.ones((10, 12))
    assert sample_mask(depth, count=np.int64(7), seed=0).sum() == 7


@pytest.mark.parametrize("kwargs, kind, words", [
    (dict(fraction=0.5, seed=-1), ValueError, "seed must be an integer >= 0"),  # NumPy's own: no argument named
    (dict(fraction=0.5, seed=1.5), TypeError, "seed must be an integer >= 0"),
    (dict(fraction=0.5, seed="7"), TypeError, "seed must be an integer >= 0"),
    (dict(fraction="0.5"), TypeError, "fraction must be a number"),  # was float()'s "could not convert string"
    (dict(fraction=[0.5]), TypeError, "fraction must be a number"),
    (dict(fraction=True), TypeError, "fraction must be a number"),  # was read as 1.0: every pixel kept
])
def test_sampling_errors_name_the_argument(kwargs, kind, words):
    depth = np.ones((5, 5))
    with pytest.raises(kind, match=words):
        sample_mask(depth, **kwargs)


def test_sampling_accepts_numpy_scalars_and_generators():
    depth = np.ones((5, 5))
    a = sample_mask(depth, fraction=np.float32(0.4), seed=np.int64(3))
    b = sample_mask(depth, fraction=0.4, seed=np.random.default_rng(3))
    assert a.sum() == b.sum() == 10 and np.array_equal(a, b)
