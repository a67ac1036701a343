import warnings

import numpy as np
import pytest

from sparsedepth import Weights, build_objective, edge_weights, nearest_fill
from sparsedepth.objective import image_gradient_magnitude

from conftest import make_problem

ALL_TERMS = Weights(
    alpha=1.3, beta=0.4, gamma=0.2, delta=0.05, kappa=3.0, beta_image=0.3, beta_second=0.1, beta_second_image=0.2
)


def _central_difference(f, z, h=1e-6):
    g = np.empty_like(z)
    for k in range(z.size):
        e = np.zeros_like(z)
        e[k] = h
        g[k] = (f(z + e) - f(z - e)) / (2 * h)
    return g


@pytest.mark.parametrize(
    "weights",
    [
        Weights.paper(alpha=1, beta=0, gamma=0, delta=0.1),  # data + prior
        Weights.paper(alpha=0, beta=0.7, gamma=0, delta=0.1),  # smooth
        Weights.paper(alpha=0, beta=0, gamma=0.3, delta=0.1, kappa=2),  # edge L1 (smoothed)
        Weights.paper(alpha=0, beta=0, gamma=0, delta=0.2),  # prior
        Weights.paper(alpha=0, beta=0, gamma=0, delta=0.1, kappa=2).replace(beta_image=0.5),
        Weights.paper(alpha=0, beta=0, gamma=0, delta=0.1).replace(beta_second=0.5),
        Weights.paper(alpha=0, beta=0, gamma=0, delta=0.1, kappa=4).replace(beta_second_image=0.5),
        ALL_TERMS,
    ],
)
def test_gradient_against_finite_differences(weights):
    image, sparse, mask, _ = make_problem((6, 7))
    obj, _, _ = build_objective(image, sparse, mask, weights=weights, l1_smoothing=0.05)
    z = 1 + np.random.default_rng(0).random(obj.size)
    value, grad = obj.smoothed_value_and_gradient(z)
    fd = _central_difference(lambda x: obj.smoothed_value_and_gradient(x)[0], z)
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-7)


def test_exact_terms_against_hand_computation():
    image, sparse, mask, _ = make_problem((5, 6))
    # weights of the raw image, z_c the nearest fill, the terms computed by hand below (the local-linear term has its
    # own hand computations in test_local_linear.py)
    w = ALL_TERMS.replace(edge_sigma=0.0, fill_contrast=0.0, beta_local_linear=0.0)
    obj, coarse, observed = build_objective(image, sparse, mask, weights=w)
    z = np.random.default_rng(4).random((5, 6)) + 1
    img = image
    grad_i = np.zeros((5, 6))
    gx = np.zeros_like(img)
    gy = np.zeros_like(img)
    gx[:, :-1] = np.diff(img, axis=1)
    gy[:-1] = np.diff(img, axis=0)
    grad_i = np.sqrt((gx**2 + gy**2).sum(axis=2))
    ew = np.exp(-w.kappa * grad_i)
    # per-pair weights: colour distance between the two pixels of each difference
    wx = np.ones((5, 6))
    wy = np.ones((5, 6))
    wx[:, :-1] = np.exp(-w.kappa * np.linalg.norm(np.diff(img, axis=1), axis=2))
    wy[:-1] = np.exp(-w.kappa * np.linalg.norm(np.diff(img, axis=0), axis=2))
    zx = np.zeros_like(z)
    zy = np.zeros_like(z)
    zx[:, :-1] = np.diff(z, axis=1)
    zy[:-1] = np.diff(z, axis=0)
    zxx = np.zeros_like(z)
    zyy = np.zeros_like(z)
    zxy = np.zeros_like(z)
    zxx[:, 1:-1] = z[:, :-2] - 2 * z[:, 1:-1] + z[:, 2:]
    zyy[1:-1] = z[:-2] - 2 * z[1:-1] + z[2:]
    zxy[:-1, :-1] = z[1:, 1:] - z[1:, :-1] - z[:-1, 1:] + z[:-1, :-1]
    # second differences weighted by the smallest pair weight they span (loops: independent of the library)
    second_image = 0.0
    for i in range(5):
        for j in range(6):
            if 0 < j < 5:
                second_image += min(wx[i, j - 1], wx[i, j]) * zxx[i, j] ** 2
            if 0 < i < 4:
                second_image += min(wy[i - 1, j], wy[i, j]) * zyy[i, j] ** 2
            if i < 4 and j < 5:
                second_image += 2 * min(wx[i, j], wx[i + 1, j], wy[i, j], wy[i, j + 1]) * zxy[i, j] ** 2
    expected = {
        "data": w.alpha * np.sum(mask * (z - np.nan_to_num(sparse)) ** 2),
        "smooth": w.beta * np.sum(zx**2 + zy**2),
        "edge": w.gamma * np.sum(ew * (np.abs(zx) + np.abs(zy))),
        "prior": w.delta * np.sum((z - coarse) ** 2),
        "smooth_image": w.beta_image * np.sum(wx * zx**2 + wy * zy**2),
        "second_order": w.beta_second * np.sum(zxx**2 + zyy**2 + 2 * zxy**2),
        "second_order_image": w.beta_second_image * second_image,
    }
    got = obj.term_values(z)
    assert set(got) == set(expected)
    for name in expected:
        assert got[name] == pytest.approx(expected[name], rel=1e-12), name
    assert obj.value(z) == pytest.approx(sum(expected.values()), rel=1e-12)


def test_normal_equations_reproduce_quadratic_part():
    image, sparse, mask, _ = make_problem((6, 5))
    obj, _, _ = build_objective(image, sparse, mask, weights=ALL_TERMS.replace(gamma=0))
    A, b, c = obj.normal_equations()
    z = np.random.default_rng(5).random(obj.size)
    assert z @ (A @ z) - 2 * b @ z + c == pytest.approx(obj.value(z), rel=1e-10)
    assert abs(A - A.T).max() < 1e-12


def test_paper_weights_switch_the_extension_terms_off():
    w = Weights.paper(gamma=0.0)
    assert (w.beta_image, w.beta_second, w.beta_second_image) == (0.0, 0.0, 0.0)
    image, sparse, mask, _ = make_problem((6, 5))
    obj, _, _ = build_objective(image, sparse, mask, weights=w)
    assert {t.name for t in obj.quadratic_terms} == {"data", "smooth", "prior"}
    assert not obj.has_l1


def test_edge_weight_definition():
    img = np.zeros((3, 3, 3))
    img[:, 2] = 1.0  # vertical edge between columns 1 and 2
    g = image_gradient_magnitude(img)
    np.testing.assert_allclose(g[:, 1], np.sqrt(3.0))
    np.testing.assert_allclose(g[:, [0, 2]], 0.0)
    np.testing.assert_allclose(edge_weights(img, 2.0)[:, 1], np.exp(-2 * np.sqrt(3.0)))
    # uint8 is scaled by 1/255
    np.testing.assert_allclose(image_gradient_magnitude((img * 255).astype(np.uint8)), g)


def test_nearest_fill_hand_made():
    d = np.full((3, 4), np.nan)
    d[0, 0] = 1.0
    d[2, 3] = 5.0
    out = nearest_fill(d)
    expected = np.array([[1, 1, 1, 5], [1, 1, 5, 5], [1, 5, 5, 5]], float)
    # e.g. (0, 2): distance 2 to (0, 0) vs sqrt(5) to (2, 3); (2, 1): sqrt(5) vs 2
    np.testing.assert_array_equal(out, expected)


def test_nearest_fill_keeps_observations():
    image, sparse, mask, _ = make_problem((30, 20))
    out = nearest_fill(sparse, mask)
    np.testing.assert_array_equal(out[mask], sparse[mask])
    assert np.all(np.isfinite(out))


def test_second_order_edge_weights_read_block_by_block_equal_the_array():
    from sparsedepth.grid.edges import SecondOrderEdgeWeights, pair_edge_weights, second_order_edge_weights

    rng = np.random.default_rng(8)
    shape = (5, 7)
    pair = pair_edge_weights(rng.random(shape + (3,)), 3.0)
    full = second_order_edge_weights(pair, shape)
    lazy = SecondOrderEdgeWeights(pair, shape)
    assert lazy.shape == full.shape and len(lazy) == full.size and lazy.dtype == full.dtype
    np.testing.assert_array_equal(np.asarray(lazy), full)
    n = shape[0] * shape[1]
    for key in (slice(0, n), slice(n, 2 * n), slice(2 * n, 3 * n), slice(n + 3, 2 * n - 1), slice(n - 2, n + 2),
                slice(None, None, 2), np.array([0, 40, 104])):
        np.testing.assert_array_equal(lazy[key], full[key])
    with pytest.raises(ValueError, match="pair_weights must have shape"):
        SecondOrderEdgeWeights(pair[:-1], shape)


@pytest.mark.parametrize("channels", [1, 3])
def test_pair_edge_weights_of_channel_planes_read_block_by_block_equal_the_array(channels):
    from sparsedepth.grid.edges import PairEdgeWeights, SecondOrderEdgeWeights, pair_edge_weights, \
        second_order_edge_weights

    rng = np.random.default_rng(11)
    shape = (6, 5)
    image = rng.random(shape + (channels,))
    planes = np.ascontiguousarray(np.moveaxis(image, -1, 0))
    full = pair_edge_weights(image, 7.0)
    factor = rng.random(full.shape)
    n = shape[0] * shape[1]
    for lazy, ref in ((PairEdgeWeights(planes, 7.0), full), (PairEdgeWeights(planes, 7.0, factor), full * factor)):
        assert lazy.shape == ref.shape and len(lazy) == ref.size
        np.testing.assert_array_equal(np.asarray(lazy), ref)
        for key in (slice(0, n), slice(n, 2 * n), slice(3, n - 1), slice(n - 2, n + 2), np.array([0, 31, 59])):
            np.testing.assert_array_equal(lazy[key], ref[key])
        # the second-order weights read the pair weights a block at a time
        np.testing.assert_array_equal(np.asarray(SecondOrderEdgeWeights(lazy, shape)),
                                      second_order_edge_weights(ref, shape))
    with pytest.raises(ValueError, match="factor must have shape"):
        PairEdgeWeights(planes, 7.0, factor[:-1])
    with pytest.raises(ValueError, match="planes must have shape"):
        PairEdgeWeights(image[..., 0], 7.0)
    with pytest.raises(ValueError, match="kappa"):
        PairEdgeWeights(planes, -1.0)


def test_objective_with_the_local_linear_term_keeps_one_image_for_it_and_the_pair_weights():
    from sparsedepth.grid.edges import PairEdgeWeights, pair_edge_weights, smoothed_image

    rng = np.random.default_rng(12)
    image = rng.integers(0, 256, (9, 11, 3)).astype(np.uint8)
    sparse = np.where(rng.random((9, 11)) < 0.2, 1.0 + rng.random((9, 11)), 0.0)
    w = Weights().replace(gamma=0)
    obj, _, _ = build_objective(image, sparse, weights=w)
    pair = obj.term("smooth_image").row_weights
    assert isinstance(pair, PairEdgeWeights)
    assert np.shares_memory(pair.planes, obj.term("local_linear").operator._image)  # one copy of the blurred image
    np.testing.assert_array_equal(pair, pair_edge_weights(smoothed_image(image, w.edge_sigma), w.kappa))
    z = rng.random(99)
    without = build_objective(image, sparse, weights=w.replace(beta_local_linear=0.0))[0]
    for name in ("smooth_image", "second_order_image"):
        assert obj.term(name).value(z) == without.term(name).value(z)


def test_term_values_at_a_changed_point_are_recomputed():
    """The kept values of the last point never answer for another point, even one changed in place."""
    image, sparse, mask, _ = make_problem((6, 5))
    obj, _, _ = build_objective(image, sparse, mask, weights=ALL_TERMS)
    z = np.random.default_rng(2).random(obj.size)
    first = obj.term_values(z)
    first["data"] = -1.0  # the caller's dict is its own
    again = obj.term_values(z.copy())
    assert again["data"] >= 0
    z[3] += 0.5  # in place: same array object, new values
    fresh = build_objective(image, sparse, mask, weights=ALL_TERMS)[0].term_values(z)
    assert obj.term_values(z) == fresh
    assert obj.value(z.reshape(obj.shape)) == pytest.approx(sum(fresh.values()), rel=1e-15)


def test_the_first_history_entry_is_the_objective_at_the_start():
    import sparsedepth as sd

    image, sparse, mask, _ = make_problem((20, 16))
    x0 = np.where(mask, sparse, np.nanmean(np.where(mask, sparse, np.nan)))
    result = sd.complete_depth(image, sparse, mask, solver="amg", x0=x0, clip_to_observed=False)
    obj, _, _ = build_objective(image, sparse, mask, weights=result.weights)
    assert result.history[0].iteration == 0
    assert result.history[0].objective == pytest.approx(obj.value(x0), rel=1e-9)
    assert result.objective == pytest.approx(obj.value(result.depth), rel=1e-12)


def test_system_value_is_the_terms_sum_once_the_normal_equations_are_kept():
    """zᵀAz − 2bᵀz + c equals the term-by-term value; it is None before assembly and with an L1 term."""
    import sparsedepth as sd

    image, sparse, mask, _ = make_problem((12, 9))
    obj, _, _ = build_objective(image, sparse, mask, weights=sd.DEFAULT_WEIGHTS)  # quadratic, 25-point
    z = 1.0 + np.random.default_rng(7).random(obj.size)
    assert obj.system_value(z) is None  # nothing assembled yet
    obj.normal_equations()
    assert obj.system_value(z) == pytest.approx(obj.value(z), rel=1e-10)
    assert obj.system_value(z.reshape(obj.shape)) == obj.system_value(z)
    kept = obj.system_value(z)
    z[5] += 0.25  # in place: the kept value must not answer for the new point
    assert obj.system_value(z) != kept
    assert obj.system_value(z) == pytest.approx(obj.value(z), rel=1e-10)
    obj.clear_cache()
    assert obj.system_value(z) is None  # no assembled system, no kept value either
    with_l1, _, _ = build_objective(image, sparse, mask, weights=ALL_TERMS)
    with_l1.normal_equations()
    assert with_l1.system_value(z) is None  # F has |Kz| terms the system does not hold


def test_the_last_history_entry_of_a_clamped_completion_is_the_solver_output_value():
    """The PCG records F at its final iterate (before the clamp); the result's terms are those at the clamped depth."""
    import sparsedepth as sd

    image, sparse, mask, _ = make_problem((24, 20))
    unclamped = sd.complete_depth(image, sparse, mask, solver="amg", clip_to_observed=False)
    obj, _, _ = build_objective(image, sparse, mask, weights=unclamped.weights)
    # the history's F is zᵀAz − 2bᵀz + c, a small difference of numbers of the size below: its rounding scales with them
    A, b, c = obj.normal_equations()
    z = unclamped.depth.ravel()
    rounding = 1e-13 * (abs(z @ (A @ z)) + 2 * abs(b @ z) + abs(c))
    assert unclamped.history[-1].objective == pytest.approx(obj.value(unclamped.depth), rel=1e-9, abs=rounding)
    assert unclamped.history[-1].objective == pytest.approx(unclamped.objective, rel=1e-9, abs=rounding)
    low, high = sparse[mask].min(), sparse[mask].max()
    assert np.any((unclamped.depth < low) | (unclamped.depth > high))  # this problem overshoots its samples
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        clamped = sd.complete_depth(image, sparse, mask, solver="amg")
    assert clamped.clamped > 0
    assert clamped.objective == pytest.approx(obj.value(np.clip(unclamped.depth, low, high)), rel=1e-9)
    assert clamped.objective > unclamped.objective  # the clamp moves off the minimiser
    assert clamped.history[-1].objective == pytest.approx(unclamped.history[-1].objective, rel=1e-12)
