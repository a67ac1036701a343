"""The windowed local-linear term (matting Laplacian, Weights.beta_local_linear / local_linear_eps)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import sparsedepth as sd
from sparsedepth.grid.affinity import PINV_CUTOFF, WINDOW_OFFSETS, WINDOWS, local_linear_operator
from sparsedepth.grid.stencil import SymmetricStencil, stencil_to_csr
from sparsedepth.linalg.multigrid import GridMultigrid
from sparsedepth.objective.objective import build_objective
from sparsedepth.objective.weights import LOCAL_LINEAR_FIELDS, MODEL_FIELDS

from conftest import DOUBLE

pytestmark = pytest.mark.filterwarnings("ignore::sparsedepth.ClampWarning")


#: The pixels of each window shape, written out (an independent statement of sparsedepth's WINDOWS).
SHAPES = {
    "3x3": [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)],
    "cross": [(-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)],
    "2x2": [(0, 0), (0, 1), (1, 0), (1, 1)],
}


def _window_indices(H, W, window="3x3"):
    """Flat indices of the pixels of every placement of a window inside an (H, W) grid (loop, C order)."""
    offsets = SHAPES[window]
    for y in range(H):
        for x in range(W):
            if all(0 <= y + dy < H and 0 <= x + dx < W for dy, dx in offsets):
                yield [(y + dy) * W + x + dx for dy, dx in offsets]


def _laplacian_by_loop(image, eps, window="3x3"):
    """Levin et al.'s matting Laplacian, one window at a time with dense linear algebra (independent reference)."""
    H, W = image.shape[:2]
    colours = image.reshape(H * W, -1)
    C = colours.shape[1]
    L = np.zeros((H * W, H * W))
    for idx in _window_indices(H, W, window):
        n = len(idx)
        X = colours[idx]
        mu = X.mean(axis=0)
        cov = (X - mu).T @ (X - mu) / n
        if eps > 0:
            P = np.linalg.inv(cov + eps / n * np.eye(C))
        else:  # the pseudo-inverse, eigenvalues <= PINV_CUTOFF dropped
            values, vectors = np.linalg.eigh(cov)
            keep = values > PINV_CUTOFF
            P = (vectors[:, keep] / values[keep]) @ vectors[:, keep].T
        L[np.ix_(idx, idx)] += np.eye(n) - (1.0 + (X - mu) @ P @ (X - mu).T) / n
    return L


def _largest_inverse_norm(image, eps, window):
    """The largest ‖(Σ_w + ε/n)^{-1}‖₂ over the windows: what the rounding of a window's covariance is scaled by."""
    H, W = image.shape[:2]
    colours = image.reshape(H * W, -1)
    largest = 0.0
    for idx in _window_indices(H, W, window):
        X = colours[idx] - colours[idx].mean(axis=0)
        smallest = np.linalg.eigvalsh(X.T @ X / len(idx))[0] + eps / len(idx)
        if smallest > PINV_CUTOFF:
            largest = max(largest, 1.0 / smallest)
    return largest


def _ridge_cost_by_loop(image, z, eps, window="3x3"):
    """Σ over windows of min_(a, b) Σ (z_i − aᵀ I_i − b)² + eps ‖a‖², by a least-squares solve per window."""
    H, W = image.shape[:2]
    colours = image.reshape(H * W, -1)
    C = colours.shape[1]
    total = 0.0
    for idx in _window_indices(H, W, window):
        design = np.vstack([np.hstack([colours[idx], np.ones((len(idx), 1))]),
                            np.hstack([np.sqrt(eps) * np.eye(C), np.zeros((C, 1))])])
        target = np.concatenate([z[idx], np.zeros(C)])
        coef, *_ = np.linalg.lstsq(design, target, rcond=None)
        total += float(np.sum((design @ coef - target) ** 2))
    return total


def _stencil_matrix(K):
    offsets = K.offsets()
    stencil = np.zeros((len(offsets),) + K.grid_shape)
    K.add_normal_stencil(stencil, offsets)
    return stencil_to_csr(offsets, stencil).toarray()


CASES = [(1, 1e-3), (3, 1e-2), (3, 1e-5), (1, 0.0), (3, 0.0)]
WINDOW_NAMES = ["3x3", "cross", "2x2"]


def test_window_shapes_are_the_written_out_ones():
    assert {name: list(offsets) for name, offsets in WINDOWS.items()} == SHAPES
    assert list(WINDOW_OFFSETS) == SHAPES["3x3"]


@pytest.mark.parametrize("window", WINDOW_NAMES)
@pytest.mark.parametrize("channels, eps", CASES)
def test_normal_stencil_equals_a_loop_over_windows(channels, eps, window):
    rng = np.random.default_rng(channels)
    image = rng.random((5, 7, channels))
    image[:3, :3] = 0.4  # a flat window: its covariance is 0 (pseudo-inverse 0 for eps = 0)
    K = local_linear_operator(image if channels > 1 else image[..., 0], eps, window=window)
    L = _laplacian_by_loop(image, eps, window)
    # the operator forms a window's covariance as E[I Iᵀ] − μ μᵀ: its rounding (~1e-16) is amplified by the inverse
    # (a cross or 2x2 window's 4-5 colours in 3 channels with a small ridge: ‖P‖ up to ~1e5)
    atol = 1e-11 + 1e-14 * _largest_inverse_norm(image, eps, window)
    np.testing.assert_allclose(_stencil_matrix(K), L, rtol=0, atol=atol)
    Kd = K.tocsr().toarray()
    np.testing.assert_allclose(Kd.T @ Kd, L, rtol=0, atol=atol)


@pytest.mark.parametrize("window, points", [("3x3", 25), ("cross", 13), ("2x2", 9)])
def test_the_stencil_has_the_couplings_of_the_window_and_no_other(window, points):
    """Every offset of the stencil couples two pixels of one window somewhere, and every such pair is coupled."""
    rng = np.random.default_rng(40)
    K = local_linear_operator(rng.random((6, 7, 3)), 1e-3, window=window)
    L = _laplacian_by_loop(rng.random((6, 7, 3)), 1e-3, window)  # any image: the pattern is the windows'
    W = 7
    rows, cols = np.nonzero(L)
    pattern = {(c // W - r // W, c % W - r % W) for r, c in zip(rows, cols)}
    assert sorted(pattern) == K.offsets() and len(K.offsets()) == points


@pytest.mark.parametrize("window", WINDOW_NAMES)
@pytest.mark.parametrize("channels, eps", [(1, 1e-3), (3, 1e-2), (3, 0.0)])
def test_squared_rows_are_the_ridge_fit_cost_of_every_window(channels, eps, window):
    rng = np.random.default_rng(10 + channels)
    image = rng.random((4, 6, channels))
    z = rng.standard_normal(24)
    K = local_linear_operator(image, eps, window=window)
    reference = (_ridge_cost_by_loop(image, z, eps, window) if eps > 0
                 else z @ _laplacian_by_loop(image, 0.0, window) @ z)
    rounding = 1e-14 * _largest_inverse_norm(image, eps, window) * (z @ z)  # see the normal-stencil test
    assert float(np.sum((K @ z) ** 2)) == pytest.approx(reference, rel=1e-11, abs=rounding)


@pytest.mark.parametrize("window", WINDOW_NAMES)
@pytest.mark.parametrize("channels, eps", [(1, 1e-3), (3, 1e-4), (3, 0.0)])
def test_adjoint_and_block_products(channels, eps, window):
    rng = np.random.default_rng(20 + channels)
    image = rng.random((6, 8, channels))
    K = local_linear_operator(image, eps, window=window)
    z, v = rng.standard_normal(K.shape[1]), rng.standard_normal(K.shape[0])
    Kz, KTv = K @ z, K.T @ v
    atol = 1e-12 + 1e-13 * _largest_inverse_norm(image, eps, window)  # see the normal-stencil test
    assert v @ Kz == pytest.approx(z @ KTv, rel=1e-12, abs=atol)
    n = K.shape[1]
    Kd = K.tocsr().toarray()
    np.testing.assert_allclose(Kz, Kd @ z, rtol=0, atol=atol)
    total = np.zeros(n)
    for b in range(len(K.blocks)):  # the block products QuadraticTerm uses
        np.testing.assert_allclose(K.block_matvec(z, b), Kd[b * n:(b + 1) * n] @ z, rtol=0, atol=atol)
        K.block_rmatvec_add(total, b, v[b * n:(b + 1) * n])
    np.testing.assert_allclose(total, KTv, rtol=0, atol=atol)


@pytest.mark.parametrize("window", WINDOW_NAMES)
@pytest.mark.parametrize("channels, eps", [(1, 1e-3), (3, 1e-5), (3, 0.0)])
@pytest.mark.parametrize("band_pixels", [1, 16, 1 << 16], ids=["row bands", "two-row bands", "one band"])
def test_symmetric_half_and_row_pieces_band_by_band(set_limits, channels, eps, band_pixels, window):
    """The stored half equals those images of the full stencil and of Kᵀ K; the pieces are K z, any band."""
    from sparsedepth.grid import affinity

    set_limits(affinity_band_pixels=band_pixels)
    rng = np.random.default_rng(30 + channels)
    image = rng.random((9, 8, channels))
    image[2:6, 1:5] = 0.3  # flat windows
    K = local_linear_operator(image if channels > 1 else image[..., 0], eps, window=window)
    offsets = K.offsets()
    full = np.zeros((len(offsets),) + K.grid_shape)
    K.add_normal_stencil(full, offsets, scale=0.7)
    upper = [o for o in offsets if o >= (0, 0)]
    half = np.zeros((len(upper),) + K.grid_shape)
    K.add_normal_stencil(half, upper, scale=0.7, symmetric=True)
    np.testing.assert_array_equal(half, full[[offsets.index(o) for o in upper]])
    Kd = K.tocsr().toarray()
    dense = SymmetricStencil(offsets, half).toarray()
    rounding = _largest_inverse_norm(image, eps, window)  # see the normal-stencil test
    np.testing.assert_allclose(dense, 0.7 * Kd.T @ Kd, rtol=0, atol=1e-11 + 1e-14 * rounding)
    z = rng.standard_normal(K.shape[1])
    pieced = np.full(K.shape[0], np.nan)
    for rows, values in K.row_pieces(z):
        assert np.all(np.isnan(pieced[rows]))  # every row once
        pieced[rows] = values
    np.testing.assert_allclose(pieced, Kd @ z, rtol=0, atol=1e-12 + 1e-13 * rounding)


def test_affine_functions_of_the_image_cost_nothing_without_ridge_and_constants_never():
    rng = np.random.default_rng(3)
    grey = rng.random((6, 7))
    depth = 2.0 + 3.0 * grey
    for eps in (0.0, 1e-3, 1.0):
        K = local_linear_operator(grey, eps)
        assert np.sum((K @ np.full(42, 1.7)) ** 2) < 1e-24
    assert np.sum((local_linear_operator(grey, 0.0) @ depth.ravel()) ** 2) < 1e-20
    # with a ridge the slope 3 costs eps * 9 per window at most (a = 3 is feasible): strictly less, but > 0
    cost = np.sum((local_linear_operator(grey, 1e-3) @ depth.ravel()) ** 2)
    assert 0 < cost < 1e-3 * 9 * 20


def test_term_value_and_gradient_match_finite_differences_and_the_stencil():
    rng = np.random.default_rng(4)
    image = rng.random((7, 9, 3))
    sparse = np.zeros((7, 9))
    mask = rng.random((7, 9)) < 0.3
    sparse[mask] = 1.0 + rng.random(mask.sum())
    w = sd.Weights(beta_local_linear=0.7, local_linear_eps=1e-3, edge_sigma=0.0)
    objective, _, _ = build_objective(image, sparse, mask, weights=w)
    term = objective.term("local_linear")
    z = rng.standard_normal(63)
    grad = term.gradient(z)
    # the term is quadratic, so the central difference is exact for any h; h = 1e-6 would divide the values'
    # rounding (|value| ~ 1e2, so ~1e-14) by 2e-6, as large as the tolerance below
    h = 1e-3
    for k in rng.choice(63, size=8, replace=False):
        e = np.zeros(63)
        e[k] = h
        fd = (term.value(z + e) - term.value(z - e)) / (2 * h)
        assert fd == pytest.approx(grad[k], rel=1e-6, abs=1e-8)
    L = _laplacian_by_loop(image, 1e-3)
    np.testing.assert_allclose(grad, 2 * 0.7 * L @ z, rtol=0, atol=1e-10)
    assert term.value(z) == pytest.approx(0.7 * z @ L @ z, rel=1e-12)
    A, b, _ = objective.normal_equations()
    without, _, _ = build_objective(image, sparse, mask, weights=w.replace(beta_local_linear=0.0))
    A0 = without.normal_equations()[0]
    np.testing.assert_allclose((A - A0).toarray(), 0.7 * L, rtol=0, atol=1e-12)


def test_the_term_uses_the_image_blurred_by_edge_sigma():
    rng = np.random.default_rng(5)
    image = rng.random((8, 8, 3))
    sparse = np.where(rng.random((8, 8)) < 0.4, 2.0, 0.0)
    w = sd.Weights(beta_local_linear=0.1, edge_sigma=1.5)
    objective, _, _ = build_objective(image, sparse, weights=w)
    K = objective.term("local_linear").operator
    expected = local_linear_operator(sd.grid.smoothed_image(image, 1.5), w.local_linear_eps)
    z = rng.standard_normal(64)
    np.testing.assert_array_equal(K @ z, expected @ z)


def test_weight_zero_reproduces_the_objective_and_completion_bit_for_bit():
    rng = np.random.default_rng(6)
    image = rng.random((20, 24, 3))
    truth = 1.0 + np.add.outer(np.linspace(0, 1, 20), np.linspace(0, 2, 24))
    sparse, mask = sd.sample_depth(truth, fraction=0.1, seed=0)
    off = sd.Weights(beta_local_linear=0.0)
    before = sd.complete_depth(image, sparse, mask, weights=off)
    after = sd.complete_depth(image, sparse, mask, weights=off.replace(local_linear_eps=0.5))
    np.testing.assert_array_equal(before.depth, after.depth)
    assert before.terms == after.terms and "local_linear" not in after.terms
    names = [t.name for t in build_objective(image, sparse, mask, weights=off)[0].terms]
    assert names == ["data", "smooth", "edge", "prior", "smooth_image", "second_order", "second_order_image"]
    defaults = sd.complete_depth(image, sparse, mask).terms  # the defaults use the cross and 2x2 windows
    assert {"local_linear_cross", "local_linear_2x2"} <= set(defaults) and "local_linear" not in defaults


def _step_scene(shape, seed):
    """A noisy image with a vertical step at column 21, depth stepping there (and a ramp down), 5 % sampled."""
    rng = np.random.default_rng(seed)
    H, W = shape
    image = np.clip(rng.random(shape + (3,)) * 0.2 + (np.arange(W) > 20)[None, :, None] * 0.7, 0, 1)
    truth = 2.0 + np.where(np.arange(W) > 20, 1.0, 0.0)[None, :] + 0.01 * np.arange(H)[:, None]
    return (image, *sd.sample_depth(truth, fraction=0.05, seed=1))


def test_the_25_point_system_is_solved_by_the_multigrid_and_amg():
    shape = (33, 47)
    image, sparse, mask = _step_scene(shape, 7)
    w = sd.Weights(beta_local_linear=0.05, local_linear_eps=1e-4)
    objective, _, _ = build_objective(image, sparse, mask, weights=w)
    A, b, _ = objective.normal_equations()
    offsets, _ = objective.normal_stencil()
    assert max(max(abs(dy), abs(dx)) for dy, dx in offsets) == 2 and len(offsets) == 25
    mg = GridMultigrid(A, shape, max_coarse=1, **DOUBLE)
    for fine, coarse in zip(mg.levels[:-1], mg.levels[1:]):  # Galerkin coarse operators of the 25-point system
        P = sp.csr_array(fine.P if sp.issparse(fine.P) else fine.P.tocsr())
        expected = (P.T @ fine.A @ P).toarray()
        scale = (abs(P.T) @ abs(fine.A) @ abs(P)).toarray()
        assert np.all(np.abs(coarse.A.toarray() - expected) <= 1e-12 * (scale + 1e-300))
    direct = spla.spsolve(sp.csc_matrix(A), b)
    result = sd.complete_depth(image, sparse, mask, weights=w, solver="amg", tol=1e-10, clip_to_observed=False)
    assert result.converged
    np.testing.assert_allclose(result.depth.ravel(), direct, rtol=0, atol=1e-6 * np.max(np.abs(direct)))


def test_cross_and_2x2_terms_add_their_laplacians_and_keep_a_13_point_system():
    rng = np.random.default_rng(11)
    image = rng.random((9, 11, 3))
    sparse = np.where(rng.random((9, 11)) < 0.3, 1.0 + rng.random((9, 11)), 0.0)
    w = sd.Weights(beta_local_linear=0.0, beta_local_linear_cross=0.4, beta_local_linear_2x2=0.3,
                   local_linear_eps=1e-3, edge_sigma=0.0)
    objective, _, _ = build_objective(image, sparse, weights=w)
    names = [t.name for t in objective.terms]
    assert names[-2:] == ["local_linear_cross", "local_linear_2x2"] and "local_linear" not in names
    L = {window: _laplacian_by_loop(image, 1e-3, window) for window in ("cross", "2x2")}
    z = rng.standard_normal(99)
    assert objective.term("local_linear_cross").value(z) == pytest.approx(0.4 * z @ L["cross"] @ z, rel=1e-12)
    assert objective.term("local_linear_2x2").value(z) == pytest.approx(0.3 * z @ L["2x2"] @ z, rel=1e-12)
    A = objective.normal_equations()[0]
    A0 = build_objective(image, sparse, weights=w.replace(beta_local_linear_cross=0.0,
                                                          beta_local_linear_2x2=0.0))[0].normal_equations()[0]
    np.testing.assert_allclose((A - A0).toarray(), 0.4 * L["cross"] + 0.3 * L["2x2"], rtol=0, atol=1e-12)
    offsets, _ = objective.normal_stencil()
    assert len(offsets) == 13 and all(abs(dy) + abs(dx) <= 2 for dy, dx in offsets)
    with_3x3, _, _ = build_objective(image, sparse, weights=w.replace(beta_local_linear=0.1))
    assert len(with_3x3.normal_stencil()[0]) == 25


def test_the_13_point_system_of_the_cross_and_2x2_terms_is_solved_by_the_multigrid():
    image, sparse, mask = _step_scene((31, 45), 12)
    w = sd.Weights(beta_local_linear=0.0, beta_local_linear_cross=0.05, beta_local_linear_2x2=0.1,
                   local_linear_eps=1e-4)
    objective, _, _ = build_objective(image, sparse, mask, weights=w)
    A, b, _ = objective.normal_equations()
    direct = spla.spsolve(sp.csc_matrix(A), b)
    result = sd.complete_depth(image, sparse, mask, weights=w, solver="amg", tol=1e-10, clip_to_observed=False)
    assert result.converged and {"local_linear_cross", "local_linear_2x2"} <= set(result.terms)
    np.testing.assert_allclose(result.depth.ravel(), direct, rtol=0, atol=1e-6 * np.max(np.abs(direct)))


def test_local_linear_term_moves_the_completion_towards_an_image_aligned_step():
    """Depth steps where the image steps: the term must not lower the accuracy on such a scene, and it acts."""
    rng = np.random.default_rng(8)
    H, W = 30, 40
    step = (np.arange(W) >= 17)[None, :].repeat(H, axis=0)
    image = np.dstack([np.where(step, 0.8, 0.2)] * 3) + 0.01 * rng.standard_normal((H, W, 3))
    truth = np.where(step, 4.0, 2.0)
    sparse, mask = sd.sample_depth(truth, fraction=0.03, seed=2)
    plain = sd.complete_depth(image, sparse, mask, weights=sd.Weights(edge_sigma=0.0, fill_contrast=0.0))
    local = sd.complete_depth(image, sparse, mask,
                              weights=sd.Weights(edge_sigma=0.0, fill_contrast=0.0, beta_local_linear=0.05,
                                                 local_linear_eps=1e-4))
    hidden = ~mask
    err_plain = np.sqrt(np.mean((plain.depth - truth)[hidden] ** 2))
    err_local = np.sqrt(np.mean((local.depth - truth)[hidden] ** 2))
    assert err_local < err_plain
    assert local.terms["local_linear"] > 0


# -- validation ----------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("value", [-1e-3, float("nan"), float("inf")])
def test_bad_eps_is_refused_naming_the_field(value):
    with pytest.raises(ValueError, match="local_linear_eps"):
        sd.Weights(local_linear_eps=value)
    with pytest.raises(ValueError, match="local_linear_eps"):
        local_linear_operator(np.zeros((4, 4)), value)


@pytest.mark.parametrize("field", LOCAL_LINEAR_FIELDS)
@pytest.mark.parametrize("value", [-0.1, float("nan")])
def test_bad_weight_is_refused_naming_the_field(value, field):
    with pytest.raises(ValueError, match=field):
        sd.Weights(**{field: value})


@pytest.mark.parametrize("window", ["5x5", "", None, 3])
def test_unknown_window_is_refused(window):
    with pytest.raises(ValueError, match="window must be one of"):
        local_linear_operator(np.zeros((4, 4)), 1e-3, window=window)


def test_eps_that_is_not_a_number_and_row_weights_are_refused():
    with pytest.raises(TypeError, match="local_linear_eps must be a real number"):
        sd.Weights(local_linear_eps="small")
    K = local_linear_operator(np.zeros((4, 4)), 1e-3)
    with pytest.raises(ValueError, match="row_weights"):
        K.add_normal_stencil(np.zeros((25, 4, 4)), K.offsets(), row_weights=np.ones(K.shape[0]))


def test_grids_without_a_full_window_give_the_zero_operator():
    K = local_linear_operator(np.random.default_rng(0).random((2, 5, 3)), 1e-3)
    z = np.arange(10.0)
    assert np.array_equal(K @ z, np.zeros(K.shape[0]))
    assert np.array_equal(K.T @ np.ones(K.shape[0]), np.zeros(10))
    assert not _stencil_matrix(K).any()


def test_eps_is_a_model_field_reported_only_when_its_term_is_used():
    assert "local_linear_eps" in MODEL_FIELDS
    off = sd.Weights(beta_local_linear=0.0).as_dict(used_only=True)
    assert not {"beta_local_linear", "local_linear_eps"} & set(off)
    used = sd.Weights(beta_local_linear=0.1).as_dict(used_only=True)
    assert used["beta_local_linear"] == 0.1 and used["local_linear_eps"] == sd.Weights().local_linear_eps == 1e-5
    assert "local_linear_eps" not in sd.Weights(beta_local_linear=0.1, local_linear_eps=0.0).as_dict(used_only=True)
    assert sd.Weights.paper().beta_local_linear == 0.0
    names = [f.name for f in dataclasses.fields(sd.Weights)]
    # positional order of the older fields kept, the window shapes' weights after them
    assert names[-4:] == ["beta_local_linear", "local_linear_eps", "beta_local_linear_cross", "beta_local_linear_2x2"]
    assert LOCAL_LINEAR_FIELDS == ("beta_local_linear", "beta_local_linear_cross", "beta_local_linear_2x2")
    # the shapes' weights are reported when used, and eps with any of them
    assert not {"beta_local_linear_cross", "beta_local_linear_2x2"} & set(sd.Weights().as_dict(used_only=True))
    cross = sd.Weights(beta_local_linear=0.0, beta_local_linear_cross=0.2).as_dict(used_only=True)
    assert cross["beta_local_linear_cross"] == 0.2 and cross["local_linear_eps"] == 1e-5
    assert not {"beta_local_linear", "beta_local_linear_2x2"} & set(cross)
    assert sd.Weights(beta_local_linear_2x2=0.3).as_dict()["beta_local_linear_2x2"] == 0.3


def test_cli_flags_set_the_new_fields():
    from sparsedepth.cli.parser import build_parser, weights_of

    args = build_parser().parse_args(["--beta-local-linear", "0.02", "--local-linear-eps", "1e-5"])
    schedule, given = weights_of(args)
    for fraction in (0.001, 0.05, 0.5):  # fixed at every density
        weights = schedule.weights(fraction)
        assert (weights.beta_local_linear, weights.local_linear_eps) == (0.02, 1e-5)
    assert given == {"beta_local_linear": 0.02, "local_linear_eps": 1e-5}
    args = build_parser().parse_args(["--beta-local-linear", "0", "--beta-local-linear-cross", "0.03",
                                      "--beta-local-linear-2x2", "0.06"])
    weights = weights_of(args)[0].weights(0.05)
    assert (weights.beta_local_linear, weights.beta_local_linear_cross, weights.beta_local_linear_2x2) == (0, 0.03,
                                                                                                         0.06)


def test_fast_mode_solves_the_objective_with_the_term_on_its_coarse_grid():
    rng = np.random.default_rng(9)
    H, W = 48, 64
    step = (np.arange(W) >= 30)[None, :].repeat(H, axis=0)
    image = np.clip(np.dstack([np.where(step, 0.8, 0.2)] * 3) + 0.02 * rng.standard_normal((H, W, 3)), 0, 1)
    truth = np.where(step, 4.0, 2.0) + 0.01 * np.arange(H)[:, None]
    sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=3)
    w = sd.Weights(beta_local_linear=0.01, local_linear_eps=1e-5)
    fast = sd.complete_depth(image, sparse, mask, weights=w, quality="fast")
    assert fast.depth.shape == (H, W) and np.all(np.isfinite(fast.depth))
    nearest = sd.nearest_fill(sparse, mask)
    hidden = ~mask
    assert np.sqrt(np.mean((fast.depth - truth)[hidden] ** 2)) < np.sqrt(np.mean((nearest - truth)[hidden] ** 2))
