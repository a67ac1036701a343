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
