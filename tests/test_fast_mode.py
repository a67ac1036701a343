"""The real-time mode: the grid resampling helpers against loops and direct solves, complete_depth(quality="fast"), --fast."""
import json
import warnings

import imageio.v3 as iio
import numpy as np
import pytest
import scipy.ndimage as ndi
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

import sparsedepth as sd
from conftest import make_scene, stencil_images
from sparsedepth.modes.fast import fast_factor
from sparsedepth.complete import main
from sparsedepth.grid.diagonals import stencil_to_dia
from sparsedepth.grid.resample import (block_mean, block_sample_mean, coarse_shape, edge_aware_sweeps,
                                       upsample_bilinear)
from sparsedepth.grid.stencil import stencil_to_csr
from test_symmetric_stencil import FIVE, THIRTEEN, random_spd


# ----------------------------------------------------------------------------- resampling helpers
@pytest.mark.parametrize("shape, factor", [((7, 10), 3), ((8, 8), 2), ((5, 9), 4), ((6, 4), 1), ((40, 37), 16)])
def test_block_mean_and_sample_mean_equal_loops_over_the_blocks(shape, factor):
    rng = np.random.default_rng(0)
    values = rng.random(shape + (3,))
    depth = rng.random(shape) + 1.0
    observed = rng.random(shape) < 0.3
    h, w = coarse_shape(shape, factor)
    means = np.zeros((h, w, 3))
    sample_means = np.zeros((h, w))
    any_observed = np.zeros((h, w), bool)
    for i in range(h):
        for j in range(w):
            block = (slice(i * factor, (i + 1) * factor), slice(j * factor, (j + 1) * factor))
            means[i, j] = values[block].reshape(-1, 3).mean(axis=0)
            seen = observed[block]
            any_observed[i, j] = seen.any()
            if seen.any():
                sample_means[i, j] = depth[block][seen].mean()
    np.testing.assert_allclose(block_mean(values, factor), means, rtol=1e-13)
    np.testing.assert_allclose(block_mean(values[..., 0], factor), means[..., 0], rtol=1e-13)
    got_depth, got_observed = block_sample_mean(depth, observed, factor)
    np.testing.assert_array_equal(got_observed, any_observed)
    np.testing.assert_allclose(got_depth, sample_means, rtol=1e-13)


@pytest.mark.parametrize("shape, factor", [((12, 17), 4), ((9, 10), 2), ((5, 5), 3)])
def test_upsample_bilinear_matches_map_coordinates_at_the_block_centres(shape, factor):
    coarse = np.random.default_rng(1).random(coarse_shape(shape, factor))
    rows = np.clip((np.arange(shape[0]) + 0.5) / factor - 0.5, 0, coarse.shape[0] - 1)
    cols = np.clip((np.arange(shape[1]) + 0.5) / factor - 0.5, 0, coarse.shape[1] - 1)
    expected = ndi.map_coordinates(coarse, np.meshgrid(rows, cols, indexing="ij"), order=1, mode="nearest")
    np.testing.assert_allclose(upsample_bilinear(coarse, shape, factor), expected, rtol=1e-12, atol=1e-15)


def test_upsample_bilinear_reproduces_a_plane_between_the_centres_and_checks_the_shape():
    factor, shape = 4, (16, 24)
    centres_y = (np.arange(4) + 0.5) * factor - 0.5
    centres_x = (np.arange(6) + 0.5) * factor - 0.5
    coarse = 5.0 + 0.3 * centres_y[:, None] - 0.2 * centres_x[None, :]
    fine = upsample_bilinear(coarse, shape, factor)
    y, x = np.mgrid[:16, :24]
    inside = (y >= centres_y[0]) & (y <= centres_y[-1]) & (x >= centres_x[0]) & (x <= centres_x[-1])
    np.testing.assert_allclose(fine[inside], (5.0 + 0.3 * y - 0.2 * x)[inside], rtol=1e-12)
    with pytest.raises(ValueError, match="coarse has shape"):
        upsample_bilinear(coarse, (17, 24), factor)


@pytest.mark.parametrize("band_rows", [1, 2, None])
@pytest.mark.parametrize("channels, dtype, rtol", [(3, np.float64, 1e-13), (3, np.float32, 1e-6), (1, np.float64, 1e-15)])
def test_pair_distances_are_the_channel_norms_of_neighbour_differences(set_limits, channels, dtype, rtol, band_rows):
    import sparsedepth.grid.edges as edges
    from sparsedepth.grid.edges import pair_distances

    if band_rows is not None:  # the norms over bands of 1 or 2 rows (7 values per row at most)
        set_limits(norm_band_values=band_rows * 7)
    image = np.random.default_rng(6).random((5, 7, channels)).astype(dtype)
    across, down = pair_distances(image)
    assert across.dtype == down.dtype == dtype and across.shape == (5, 6) and down.shape == (4, 7)
    wide = image.astype(np.float64)
    np.testing.assert_allclose(across, np.linalg.norm(wide[:, 1:] - wide[:, :-1], axis=2), rtol=rtol)
    np.testing.assert_allclose(down, np.linalg.norm(wide[1:] - wide[:-1], axis=2), rtol=rtol)


def _sweep_model(start, image, depth, observed, smoothness, kappa):
    """The minimiser of the sweeps' model by a sparse direct solve (observed pixels eliminated)."""
    H, W = start.shape
    index = np.arange(H * W).reshape(H, W)
    image = image.astype(float)
    rows, cols, vals = [], [], []
    diag = np.ones(H * W)
    rhs = start.astype(float).ravel().copy()
    for a, b in ((index[:, :-1], index[:, 1:]), (index[:-1], index[1:])):
        a, b = a.ravel(), b.ravel()
        w = smoothness * np.exp(-kappa * np.linalg.norm(image.reshape(-1, image.shape[-1])[a]
                                                        - image.reshape(-1, image.shape[-1])[b], axis=1))
        np.add.at(diag, a, w)
        np.add.at(diag, b, w)
        rows += [a, b]
        cols += [b, a]
        vals += [-w, -w]
    L = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(H * W,) * 2)
    L = L + sp.diags(diag)
    fixed = observed.ravel()
    free = ~fixed
    z = np.where(fixed, depth.ravel(), 0.0)
    z[free] = spsolve(L[free][:, free].tocsc(), rhs[free] - L[free][:, fixed] @ z[fixed])
    return z.reshape(H, W)


@pytest.mark.parametrize("band_rows", [2, 4, None])
def test_edge_aware_sweeps_converge_to_the_direct_solve_of_their_model(set_limits, band_rows):
    import sparsedepth.grid.resample as resample

    if band_rows is not None:  # half sweeps over bands of rows of the (9, 6) parity arrays
        set_limits(sweep_band_values=band_rows * 6)
    rng = np.random.default_rng(2)
    image = rng.random((9, 11, 3))
    start = rng.random((9, 11)) + 1.0
    depth = rng.random((9, 11)) + 2.0
    observed = rng.random((9, 11)) < 0.2
    expected = _sweep_model(start, image, depth, observed, 3.0, 2.0)
    got = edge_aware_sweeps(start, image, depth, observed, smoothness=3.0, kappa=2.0, sweeps=400)
    np.testing.assert_allclose(got, expected, rtol=2e-5)
    few = edge_aware_sweeps(start, image, depth, observed, smoothness=3.0, kappa=2.0, sweeps=2)
    assert np.abs(few - expected).max() > 1e-3  # two sweeps are not the answer: the comparison above can fail
    np.testing.assert_array_equal(few[observed], depth[observed].astype(np.float32))
    none = edge_aware_sweeps(start, image, depth, observed, smoothness=3.0, kappa=2.0, sweeps=0)
    np.testing.assert_array_equal(none, np.where(observed, depth, start).astype(np.float32))


@pytest.mark.parametrize("kwargs, words", [
    (dict(smoothness=-1.0, kappa=1.0, sweeps=1), "smoothness"),
    (dict(smoothness=1.0, kappa=np.nan, sweeps=1), "kappa"),
    (dict(smoothness=1.0, kappa=1.0, sweeps=1.5), "sweeps"),
    (dict(smoothness=1.0, kappa=1.0, sweeps=-1), "sweeps"),
])
def test_edge_aware_sweeps_reject_bad_parameters(kwargs, words):
    with pytest.raises(ValueError, match=words):
        edge_aware_sweeps(np.ones((3, 3)), np.zeros((3, 3, 3)), np.ones((3, 3)), np.eye(3, dtype=bool), **kwargs)


@pytest.mark.parametrize("offsets", [FIVE, THIRTEEN], ids=["5", "13"])
@pytest.mark.parametrize("shape", [(1, 1), (1, 6), (6, 1), (3, 2), (4, 4), (7, 9), (12, 10)])
def test_stencil_to_dia_is_the_matrix_and_multiplies_as_csr_does(offsets, shape):
    _, dense = random_spd(offsets, shape, seed=shape[0] * 7 + shape[1])
    dense[np.nonzero(dense)] += np.random.default_rng(3).random(np.count_nonzero(dense))  # not symmetric
    stencil = stencil_images(dense, offsets, shape)
    D = stencil_to_dia(offsets, stencil)
    assert isinstance(D, sp.dia_array)
    np.testing.assert_array_equal(D.toarray(), dense)
    x = np.random.default_rng(5).standard_normal(dense.shape[0])
    if shape[1] > 4:  # (narrower grids share flat offsets between stencil offsets: the sum order differs)
        np.testing.assert_array_equal(D @ x, stencil_to_csr(offsets, stencil) @ x)  # the same sums in the same order
    np.testing.assert_allclose(D @ x, dense @ x, rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="stencil must have shape"):
        stencil_to_dia(offsets, stencil[1:])


@pytest.mark.parametrize("weights", ["FAST_WEIGHTS", "DEFAULT_WEIGHTS"])  # (the second: a local-linear term, CSR)
def test_the_fast_coarse_solve_meets_its_residual_in_double_precision_and_ends_near_the_cg_solver(weights):
    from sparsedepth.modes.fast import FAST_COARSE_RTOL
    from sparsedepth.solvers import depth_unit, scaled_objective
    from sparsedepth.solvers.common import Recorder
    from sparsedepth.solvers.core import solve_scaled
    from sparsedepth.solvers.quadratic import single_precision_cg
    image, depth = make_scene(shape=(30, 36))
    sparse, mask = sd.sample_depth(depth, fraction=0.05, seed=2)
    objective, coarse, _ = sd.build_objective(image, sparse, mask, weights=getattr(sd, weights))
    scale = depth_unit(sparse[mask])
    scaled = scaled_objective(objective, scale)
    start = coarse.ravel() / scale
    ours = single_precision_cg(scaled, start, tol=FAST_COARSE_RTOL, max_iter=500,
                           recorder=Recorder(scaled, None, scale, values=False))
    A, b, _ = scaled_objective(objective, scale).normal_equations()  # float64 CSR, assembled independently
    relative_residual = np.linalg.norm(b - A @ ours.z) / np.linalg.norm(b)
    assert ours.converged and relative_residual <= 1.01 * FAST_COARSE_RTOL
    assert ours.iterations >= 2 and len(ours.history) == ours.iterations + 1
    cg, _ = solve_scaled(scaled_objective(objective, scale), start, scale=scale, solver="cg", tol=FAST_COARSE_RTOL,
                         max_iter=500, callback=None, options=None, certify_result=False, objective_values=False)
    np.testing.assert_allclose(ours.z * scale, cg.z, rtol=1e-3)  # float32 products: the same path to about 1e-5 here


# ----------------------------------------------------------------------------- complete_depth(quality="fast")
def test_fast_factor_keeps_about_one_sample_per_coarse_block():
    assert fast_factor(0.01) == 4 and fast_factor(1 / 16) == 4
    assert fast_factor(0.07) == 3 and fast_factor(1 / 9) == 3
    assert fast_factor(0.12) == 2 and fast_factor(0.5) == 2


@pytest.mark.parametrize("fraction", [0.02, 0.1])
def test_fast_mode_is_exact_on_a_constant_scene_and_keeps_the_observations(fraction):
    image, _ = make_scene()
    depth = np.full(image.shape[:2], 2.5)
    sparse, mask = sd.sample_depth(depth, fraction=fraction, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", sd.ClampWarning)  # float32 rounding of the sweeps is not a clamp
        result = sd.complete_depth(image, sparse, mask, quality="fast")
    np.testing.assert_allclose(result.depth, 2.5, rtol=1e-9)
    assert np.isnan(result.objective) and np.isnan(result.gap) and result.terms == {}
    assert "fast mode" in result.message


def test_fast_mode_keeps_observations_and_beats_nearest_fill_on_a_real_frame():
    frame = sd.load_motorcycle()
    depth = np.array(frame.depth, dtype=float)[::2, ::2]
    image = frame.image[::2, ::2]
    sparse, mask = sd.sample_depth(depth, fraction=0.05, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        fast = sd.complete_depth(image, sparse, mask, quality="fast")
    hidden = np.isfinite(depth) & (depth > 0) & ~mask
    nearest = sd.nearest_fill(sparse, mask)
    rmse = lambda z: np.sqrt(np.mean((z[hidden] - depth[hidden]) ** 2))  # noqa: E731
    assert rmse(fast.depth) < 0.9 * rmse(nearest)
    np.testing.assert_allclose(fast.depth[mask], sparse[mask], rtol=1e-6)  # float32 sweeps hold the samples
    assert fast.depth.dtype == np.float64 and fast.depth.shape == depth.shape
    assert fast.iterations >= 1 and len(fast.history) >= 1


def test_fast_mode_started_from_its_own_answer_ends_near_it():
    image, depth = make_scene(shape=(64, 80))
    sparse, mask = sd.sample_depth(depth, fraction=0.05, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        cold = sd.complete_depth(image, sparse, mask, quality="fast")
        warm = sd.complete_depth(image, sparse, mask, quality="fast", x0=cold.depth)
        far = sd.complete_depth(image, sparse, mask, quality="fast", x0=np.full(depth.shape, 100.0))
    # the coarse solves stop at a relative residual of 1e-4: starts differ by that much, not by the step (0.5 m)
    assert np.abs(warm.depth - cold.depth).max() < 0.05
    assert np.abs(far.depth - cold.depth).max() < 0.05


def test_fast_mode_on_a_grid_smaller_than_two_blocks_solves_at_full_resolution():
    image = np.random.default_rng(3).random((2, 9, 3))
    truth = np.add.outer(np.linspace(1, 2, 2), np.linspace(0, 1, 9))
    mask = np.zeros((2, 9), bool)
    mask[:, ::3] = True
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        result = sd.complete_depth(image, np.where(mask, truth, 0.0), mask, quality="fast")
    assert "1x coarser" in result.message
    assert np.all(np.isfinite(result.depth))


@pytest.mark.parametrize("kwargs, words", [
    (dict(quality="slow"), "quality must be one of"),
    (dict(quality="fast", solver="admm"), "takes no solver"),
    (dict(quality="fast", tol=1e-3), "takes no tol"),
    (dict(quality="fast", x0=np.ones((40, 50))), "x0 has shape"),
    (dict(quality="fast", x0=np.full((40, 60), np.nan)), "x0 contains NaN"),
    (dict(quality="fast", uncertainty=True), "takes no uncertainty"),
    (dict(quality="fast", prior=np.ones((40, 60))), "prior cannot be combined with quality='fast'"),
    (dict(quality="fast", max_iter=3, callback=print), "takes no max_iter, callback"),
])
def test_fast_mode_rejects_what_it_does_not_take(kwargs, words):
    image, depth = make_scene()
    sparse, mask = sd.sample_depth(depth, fraction=0.1, seed=0)
    with pytest.raises(ValueError, match=words):
        sd.complete_depth(image, sparse, mask, **kwargs)


def test_solve_scaled_without_certificate_leaves_the_gap_out():
    from sparsedepth.solvers import solve_scaled
    image, depth = make_scene()
    sparse, mask = sd.sample_depth(depth, fraction=0.1, seed=0)
    objective, start, _ = sd.build_objective(image, np.where(mask, sparse, 0.0), mask)
    kwargs = dict(scale=1.0, solver="amg", tol=1e-8, max_iter=500, callback=None, options=None)
    certified, _ = solve_scaled(objective, start.ravel(), **kwargs)
    plain, _ = solve_scaled(objective, start.ravel(), certify_result=False, **kwargs)
    assert np.isfinite(certified.gap) and np.isnan(plain.gap)
    np.testing.assert_array_equal(plain.z, certified.z)
    assert "duality gap not computed" in plain.message


# ----------------------------------------------------------------------------- --fast


def test_cli_fast_writes_the_fast_completion(scene_files, capsys):
    rc = main(["--image", str(scene_files / "rgb.png"), "--depth", str(scene_files / "sparse.png"), "--depth-scale", "mm",
               "--fast", "--out", str(scene_files / "out.npy"), "--json", str(scene_files / "m.json"), "-q"])
    assert rc == 0, capsys.readouterr().err
    image = sd.read_image(scene_files / "rgb.png")
    sparse = sd.read_depth(scene_files / "sparse.png", scale=1000)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        expected = sd.complete_depth(image, sparse, quality="fast").depth
    np.testing.assert_allclose(sd.read_depth(scene_files / "out.npy"), expected, rtol=1e-12)
    report = json.loads((scene_files / "m.json").read_text())
    assert "fast" in report["method"]
    assert report["weights"] == sd.FAST_WEIGHTS.as_dict()  # the weights the fast mode solved with


@pytest.mark.parametrize("argv, words", [
    (["--tol", "1e-3"], "--fast picks its own solve and takes no --tol"),
    (["--solver", "cg"], "takes no --solver"),
    (["--uncertainty", "u.npy"], "takes no --uncertainty"),
])
def test_cli_fast_refuses_solver_options_with_one_line_and_exit_2(scene_files, capsys, argv, words):
    rc = main(["--image", str(scene_files / "rgb.png"), "--depth", str(scene_files / "sparse.png"), "--depth-scale", "mm",
               "--fast", "-q", *[str(scene_files / a) if a.endswith(".npy") else a for a in argv]])
    assert rc == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1


# ----------------------------------------------------------------------------- batches
def test_batch_fast_rows_equal_the_library_fast_mode(tmp_path):
    from concurrent.futures import ThreadPoolExecutor

    from sparsedepth.batch import BatchOptions, find_frames, run_batch

    for key, seed in (("a", 0), ("b", 1)):
        image, depth = make_scene(seed=seed)
        iio.imwrite(tmp_path / f"rgb_{key}.png", image)
        sd.write_depth(tmp_path / f"depth_{key}.png", depth, scale=1000)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    options = BatchOptions(keep_fraction=0.05, seed=3, depth_scale="mm", out_dir=str(out_dir), quality="fast")
    with ThreadPoolExecutor(max_workers=1) as pool:
        summary = run_batch(find_frames(tmp_path), tmp_path / "m.csv", options=options, executor=pool,
                            max_workers=1)
    assert summary.succeeded == 2
    for position, key in ((0, "a"), (1, "b")):
        image = sd.read_image(tmp_path / f"rgb_{key}.png")
        depth = sd.read_depth(tmp_path / f"depth_{key}.png", scale=1000)
        mask = sd.sample_mask(depth, fraction=0.05, seed=np.random.default_rng([3, position]))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sd.ClampWarning)
            expected = sd.complete_depth(image, np.where(mask, depth, np.nan), mask, quality="fast").depth
        np.testing.assert_allclose(np.load(out_dir / f"{key}.npy"), expected, rtol=1e-12)
    settings = json.loads((tmp_path / "m.csv.settings.json").read_text())
    assert settings["options"]["quality"] == "fast"


def test_batch_fingerprint_of_the_default_solve_has_no_quality_field():
    from sparsedepth.batch import BatchOptions, csvlog

    assert "quality" not in csvlog.fingerprint([], BatchOptions())["options"]
    assert csvlog.fingerprint([], BatchOptions(quality="fast"))["options"]["quality"] == "fast"


@pytest.mark.parametrize("kwargs, words", [
    (dict(quality="draft"), "quality must be one of"),
    (dict(quality="fast", tol=1e-3), "takes no tol"),
    (dict(quality="fast", solver="cg", max_iter=3), "takes no solver, max_iter"),
    (dict(quality="fast", task="fill"), "the colorization fill .* takes no quality='fast'"),
])
def test_batch_options_check_the_quality(kwargs, words):
    from sparsedepth.batch import BatchOptions

    with pytest.raises(ValueError, match=words) as info:
        BatchOptions(**kwargs)
    assert info.value.option == "quality"


def test_cli_batch_fast_refuses_tol_naming_the_flag(tmp_path, capsys):
    image, depth = make_scene()
    iio.imwrite(tmp_path / "rgb_a.png", image)
    sd.write_depth(tmp_path / "depth_a.png", depth, scale=1000)
    rc = main(["--batch", str(tmp_path), "--keep-fraction", "0.05", "--depth-scale", "mm", "--csv",
               str(tmp_path / "m.csv"), "--fast", "--tol", "1e-3", "-q"])
    assert rc == 2
    assert "--fast picks its own solve and takes no --tol" in capsys.readouterr().err


@pytest.mark.parametrize("solver", ["cg", "amg"])
def test_solve_without_objective_values_takes_the_same_steps_and_records_nan(solver):
    from sparsedepth.solvers import depth_unit, scaled_objective
    from sparsedepth.solvers.core import solve_scaled
    image, depth = make_scene(shape=(30, 36))
    sparse, mask = sd.sample_depth(depth, fraction=0.1, seed=1)
    objective, coarse, _ = sd.build_objective(image, sparse, mask)
    scale = depth_unit(sparse[mask])
    scaled = scaled_objective(objective, scale)
    runs = [solve_scaled(scaled, coarse.ravel() / scale, scale=scale, solver=solver, tol=1e-6, max_iter=None,
                         callback=None, options=None, certify_result=False, objective_values=values)[0]
            for values in (True, False)]
    with_values, without = runs
    np.testing.assert_array_equal(without.z, with_values.z)
    assert len(without.history) == len(with_values.history) >= 2
    assert np.isnan([h.objective for h in without.history]).all()
    F = [h.objective for h in with_values.history]
    assert np.isfinite(F).all()
    # the last record is zᵀAz − 2bᵀz + c (Objective.system_value): F up to the rounding that the cancellation
    # against c = F(0) magnifies, not the term-by-term sum
    np.testing.assert_allclose(F[-1], objective.value(with_values.z.reshape(objective.shape)), rtol=1e-8)


def test_fast_mode_takes_its_own_weights_for_the_defaults_and_yours_as_given():
    image, depth = make_scene(shape=(48, 60))
    sparse, mask = sd.sample_depth(depth, fraction=0.05, seed=4)
    assert sd.FAST_WEIGHTS != sd.DEFAULT_WEIGHTS and sd.FAST_WEIGHTS.beta_local_linear == 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        default = sd.complete_depth(image, sparse, mask, quality="fast")
        explicit = sd.complete_depth(image, sparse, mask, quality="fast", weights=sd.FAST_WEIGHTS)
        mine = sd.Weights(beta_local_linear=0.0, fill_contrast=5.0)
        given = sd.complete_depth(image, sparse, mask, quality="fast", weights=mine)
    np.testing.assert_array_equal(default.depth, explicit.depth)
    assert default.weights == sd.FAST_WEIGHTS and given.weights == mine
    assert not np.array_equal(given.depth, default.depth)
