import numpy as np
import pytest

from sparsedepth import Weights, complete_depth, depth_metrics, sample_depth

from conftest import make_problem


@pytest.fixture
def inputs():
    image, sparse, mask, _ = make_problem((12, 15))
    return image, sparse, mask


def test_shapes_differ(inputs):
    image, sparse, mask = inputs
    with pytest.raises(ValueError, match="image has shape .* but sparse_depth"):
        complete_depth(image[:-1], sparse, mask)
    with pytest.raises(ValueError, match="mask has shape"):
        complete_depth(image, sparse, mask[:, :-1])


def test_no_observed_pixel(inputs):
    image, sparse, _ = inputs
    with pytest.raises(ValueError, match="no observed pixel"):
        complete_depth(image, np.full(sparse.shape, np.nan))
    with pytest.raises(ValueError, match="no observed pixel"):
        complete_depth(image, np.zeros(sparse.shape))


def test_nan_in_image(inputs):
    image, sparse, mask = inputs
    bad = image.copy()
    bad[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match="image contains NaN"):
        complete_depth(bad, sparse, mask)
    bad[3, 4, 1] = np.inf
    with pytest.raises(ValueError, match="image contains NaN or infinite"):
        complete_depth(bad, sparse, mask)


def test_float_image_out_of_range(inputs):
    image, sparse, mask = inputs
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        complete_depth(image * 255, sparse, mask)


def test_negative_observed_depth(inputs):
    image, sparse, mask = inputs
    bad = sparse.copy()
    bad[mask.nonzero()[0][0], mask.nonzero()[1][0]] = -1.0
    with pytest.raises(ValueError, match="negative observed"):
        complete_depth(image, bad, mask)


def test_nan_under_mask(inputs):
    image, sparse, mask = inputs
    m = mask.copy()
    m[~mask] = False
    m[np.argwhere(~mask)[0][0], np.argwhere(~mask)[0][1]] = True
    with pytest.raises(ValueError, match="NaN or infinite values at 1 observed"):
        complete_depth(image, sparse, m)


@pytest.mark.parametrize("shape", [(12,), (12, 15, 3, 1)])
def test_wrong_dimensions_image(inputs, shape):
    image, sparse, mask = inputs
    with pytest.raises(ValueError, match="dimensions"):
        complete_depth(np.zeros(shape), sparse, mask)


def test_wrong_dimensions_depth(inputs):
    image, sparse, mask = inputs
    with pytest.raises(ValueError, match="2-D"):
        complete_depth(image, sparse[None], mask)


def test_bad_channels(inputs):
    image, sparse, mask = inputs
    with pytest.raises(ValueError, match="channels"):
        complete_depth(np.zeros((12, 15, 2)), sparse, mask)


@pytest.mark.parametrize("field", ["alpha", "beta", "gamma", "delta", "kappa", "beta_image", "beta_second", "beta_second_image"])
def test_negative_weight(field):
    with pytest.raises(ValueError, match=f"weight {field} must be finite and >= 0"):
        Weights(**{field: -0.1})
    with pytest.raises(ValueError, match=field):
        Weights(**{field: float("nan")})


def test_ill_posed_weights(inputs):
    image, sparse, mask = inputs
    with pytest.raises(ValueError, match="unique solution"):
        complete_depth(image, sparse, mask, weights=Weights.paper(alpha=1, beta=0, gamma=0, delta=0))


def test_weights_are_immutable():
    w = Weights()
    with pytest.raises(Exception):
        w.alpha = 3.0
    assert w.replace(alpha=3.0).alpha == 3.0 and w.alpha != 3.0 or w.alpha == 3.0


def test_inputs_not_modified(inputs):
    image, sparse, mask = inputs
    copies = [a.copy() for a in inputs]
    complete_depth(image, sparse, mask, solver="irls")
    for a, b in zip(inputs, copies):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("dtype,scale", [(np.uint8, 255), (np.uint16, 65535)])
def test_integer_images_equal_scaled_float(inputs, dtype, scale):
    image, sparse, mask = inputs
    q = np.round(image * scale).astype(dtype)
    a = complete_depth(q, sparse, mask, weights=Weights(gamma=0), solver="direct")
    b = complete_depth(q.astype(float) / scale, sparse, mask, weights=Weights(gamma=0), solver="direct")
    np.testing.assert_allclose(a.depth, b.depth, atol=1e-12)


def test_grey_image_accepted(inputs):
    image, sparse, mask = inputs
    res = complete_depth(image[..., 0], sparse, mask, weights=Weights(gamma=0), solver="direct")
    assert res.depth.shape == sparse.shape


# --- the shared number and mask rules (one rule per concept, used by the colorization fill, the
# edge weights, the objective and the weights)
@pytest.mark.parametrize("value", [1, 2.5, np.float32(0.1), np.int64(3), np.array(0.25)])
def test_check_positive_real_accepts_and_converts(value):
    from sparsedepth._validation import check_positive_real

    number = check_positive_real(value, name="alpha")
    assert type(number) is float and number == float(value)


@pytest.mark.parametrize("value, error, message", [
    (0.0, ValueError, "alpha must be finite and > 0, got 0.0"),
    (-1, ValueError, r"alpha must be finite and > 0, got -1.0"),
    (np.inf, ValueError, "alpha must be finite and > 0"),
    (np.nan, ValueError, "alpha must be finite and > 0"),
    ("abc", TypeError, "alpha must be a real number, got str 'abc'"),
    ("3", TypeError, "alpha must be a real number, got str '3'"),
    (True, TypeError, "alpha must be a real number, got bool True"),
    (None, TypeError, "alpha must be a real number, got NoneType None"),
])
def test_check_positive_real_rejects(value, error, message):
    from sparsedepth._validation import check_positive_real

    with pytest.raises(error, match=message):
        check_positive_real(value, name="alpha")


def test_check_nonnegative_real():
    from sparsedepth._validation import check_nonnegative_real

    assert check_nonnegative_real(0, name="kappa") == 0.0
    assert check_nonnegative_real(np.float64(2.5), name="kappa") == 2.5
    with pytest.raises(ValueError, match=r"kappa must be finite and >= 0, got -0.5"):
        check_nonnegative_real(-0.5, name="kappa")
    with pytest.raises(ValueError, match="kappa must be finite and >= 0"):
        check_nonnegative_real(np.nan, name="kappa")
    assert check_nonnegative_real(np.array(1.5), name="kappa") == 1.5
    for bad in ("x", "1", True, None, [1.0], np.array([1.0])):
        with pytest.raises(TypeError, match="kappa must be a real number"):
            check_nonnegative_real(bad, name="kappa")


@pytest.mark.parametrize("value", [1, 7, np.int64(3)])
def test_check_count_accepts(value):
    from sparsedepth._validation import check_count

    got = check_count(value, name="maxiter")
    assert got == int(value) and type(got) is int


@pytest.mark.parametrize("value", [0, -2, 1.0, True, np.bool_(True), "2", None])
def test_check_count_rejects(value):
    from sparsedepth._validation import check_count

    with pytest.raises(ValueError, match="maxiter must be an integer >= 1"):
        check_count(value, name="maxiter")


def test_check_bool_mask():
    from sparsedepth._validation import check_bool_mask

    mask = np.zeros((3, 4), dtype=bool)
    assert check_bool_mask(mask, (3, 4)) is mask or np.array_equal(check_bool_mask(mask, (3, 4)), mask)
    with pytest.raises(ValueError, match="mask must be a boolean array, got dtype int64"):
        check_bool_mask(mask.astype(np.int64), (3, 4))
    with pytest.raises(ValueError, match=r"mask has shape \(3, 4\) but raw_depth has shape \(4, 3\)"):
        check_bool_mask(mask, (4, 3), shape_name="raw_depth")


@pytest.mark.parametrize("kappa", ["strong", "10", None, [1.0]])
def test_edge_weights_reject_a_non_number_kappa_with_a_type_error_naming_it(kappa):
    # the shared non-negative-number rule: a TypeError naming kappa (a numeric string is not converted)
    from sparsedepth.objective import edge_weights, pair_edge_weights

    image = np.zeros((4, 5))
    with pytest.raises(TypeError, match="kappa must be a real number"):
        edge_weights(image, kappa)
    with pytest.raises(TypeError, match="kappa must be a real number"):
        pair_edge_weights(image, kappa)


def test_objective_rejects_a_non_number_l1_smoothing_with_a_type_error():
    from sparsedepth.objective import Objective

    with pytest.raises(TypeError, match="l1_smoothing must be a real number"):
        Objective((2, 3), [], l1_smoothing="small")
    with pytest.raises(ValueError, match="l1_smoothing must be finite and > 0"):
        Objective((2, 3), [], l1_smoothing=0.0)


def test_clamp_warning_points_at_the_caller():
    # complete_depth's clamp is a named step; its ClampWarning must still name the caller's line
    import warnings

    from sparsedepth import ClampWarning

    image = np.zeros((6, 20))
    depth = np.zeros((6, 20))
    depth[:, 0], depth[:, 9], depth[:, 10], depth[:, 19] = 1.0, 1.0, 5.0, 5.0  # a step: the smoothness overshoots
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = complete_depth(image, depth, weights=Weights(alpha=1.0, delta=1e-6, beta_second=1.0), solver="direct")
    clamp = [w for w in caught if issubclass(w.category, ClampWarning)]
    assert result.clamped > 0 and len(clamp) == 1
    assert clamp[0].filename == __file__
    assert f"{result.clamped} of 120 pixels" in str(clamp[0].message)
    assert np.all((result.depth >= 1.0) & (result.depth <= 5.0))


@pytest.mark.parametrize("value", [0, 5, np.int64(2)])
def test_check_nonnegative_count_accepts(value):
    from sparsedepth._validation import check_nonnegative_count

    got = check_nonnegative_count(value, name="sweeps")
    assert got == int(value) and type(got) is int


@pytest.mark.parametrize("value", [-1, 1.0, True, np.bool_(False), "2", None])
def test_check_nonnegative_count_rejects(value):
    from sparsedepth._validation import check_nonnegative_count

    with pytest.raises(ValueError, match="sweeps must be an integer >= 0"):
        check_nonnegative_count(value, name="sweeps")
