"""The symmetric stencil form of grid operators: products, sweeps, multigrid and solves against CSR and dense."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

import sparsedepth as sd
from sparsedepth.grid.stencil import SymmetricStencil, stencil_to_csr
from sparsedepth.linalg import make_preconditioner, pcg
from sparsedepth.linalg.multigrid import GridMultigrid
from sparsedepth.linalg.multigrid import bands
from sparsedepth.linalg.multigrid.bands import BandedStencil
from sparsedepth.linalg.multigrid.smoothers import gauss_seidel_backward, gauss_seidel_forward

from conftest import stencil_images

FIVE = [(-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)]
THIRTEEN = sorted({(0, 0), (0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (-1, -1), (1, -1), (-1, 1), (0, 2), (0, -2),
                   (2, 0), (-2, 0)})
TWENTY_FIVE = [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3)]
SHAPES = [(1, 1), (1, 2), (2, 1), (1, 7), (7, 1), (2, 2), (2, 9), (5, 5), (13, 8), (30, 21)]


def _inside(offset, shape):
    H, W = shape
    dy, dx = offset
    m = np.zeros(shape, dtype=bool)
    m[max(0, -dy):min(H, H - dy), max(0, -dx):min(W, W - dx)] = True
    return m


def random_spd(offsets, shape, seed):
    """A random diagonally dominant symmetric stencil and its dense matrix, built entry by entry."""
    rng = np.random.default_rng(seed)
    H, W = shape
    n = H * W
    dense = np.zeros((n, n))
    upper = [o for o in offsets if o >= (0, 0)]
    images = []
    for dy, dx in upper:
        image = rng.uniform(-1.0, 1.0, shape) * _inside((dy, dx), shape)
        if (dy, dx) == (0, 0):
            image = 2.0 * len(offsets) + rng.random(shape)
        images.append(image)
        for y in range(H):
            for x in range(W):
                if 0 <= y + dy < H and 0 <= x + dx < W:
                    p, q = y * W + x, (y + dy) * W + x + dx
                    dense[p, q] = dense[q, p] = image[y, x]
    return SymmetricStencil(offsets, images), dense


@pytest.mark.parametrize("offsets", [FIVE, THIRTEEN, TWENTY_FIVE], ids=["5", "13", "25"])
@pytest.mark.parametrize("shape", SHAPES)
def test_product_equals_csr_and_dense(offsets, shape):
    A, dense = random_spd(offsets, shape, seed=shape[0] * 31 + shape[1])
    csr = stencil_to_csr(offsets, stencil_images(dense, offsets, shape))
    np.testing.assert_array_equal(A.tocsr().toarray(), dense)
    for dtype in (np.float64, np.float32):  # the CSR form of stencil_to_csr, entry for entry
        mine, full = A.tocsr(dtype=dtype), stencil_to_csr(offsets, stencil_images(dense, offsets, shape), dtype=dtype)
        assert mine.dtype == dtype and mine.has_canonical_format
        for name in ("indptr", "indices", "data"):
            np.testing.assert_array_equal(getattr(mine, name), getattr(full, name))
    rng = np.random.default_rng(1)
    for _ in range(3):
        x = rng.standard_normal(A.shape[0])
        np.testing.assert_array_equal(A @ x, csr @ x)  # same sums in the same order
        np.testing.assert_allclose(A @ x, dense @ x, rtol=1e-12, atol=1e-12)
        x32 = x.astype(np.float32)
        A32 = A.astype(np.float32)
        np.testing.assert_array_equal(A32 @ x32, A32.tocsr() @ x32)
        H = shape[0]
        for y0, y1 in [(0, H), (0, (H + 1) // 2), (H // 3, H)]:  # rows of the product: those of the whole
            np.testing.assert_array_equal(A.matvec_rows(x, y0, y1), (A @ x).reshape(shape)[y0:y1])
    np.testing.assert_array_equal(A.diagonal(), np.diag(dense))


@pytest.mark.parametrize("shape", [(1, 1), (1, 5), (6, 1), (7, 9)])
def test_from_stencil_round_trip_and_parity_classes(shape):
    A, dense = random_spd(THIRTEEN, shape, seed=3)
    full = stencil_images(dense, THIRTEEN, shape)
    B = SymmetricStencil.from_stencil(THIRTEEN, full)
    for a, b in zip(A.images, B.images):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(A.full_rows(0, shape[0]), full)
    for py in (0, 1):
        for px in (0, 1):
            np.testing.assert_array_equal(A.parity_class(py, px), full[:, py::2, px::2])
    assert A.nnz == A.tocsr().nnz


def test_from_stencil_refuses_an_asymmetric_stencil():
    _, dense = random_spd(FIVE, (6, 7), seed=4)
    full = stencil_images(dense, FIVE, (6, 7))
    full[0, 3, 2] = np.nextafter(full[0, 3, 2], 10.0)  # one lower coefficient off by one unit in the last place
    assert SymmetricStencil.from_stencil(FIVE, full) is None
    assert SymmetricStencil.from_stencil(FIVE[1:], full[1:]) is None  # (1, 0) without (-1, 0)


def test_stencil_checks_its_arguments():
    with pytest.raises(ValueError, match="closed under negation"):
        SymmetricStencil([(0, 0), (0, 1)], [np.ones((2, 2)), np.zeros((2, 2))])
    with pytest.raises(ValueError, match="one per offset"):
        SymmetricStencil(FIVE, [np.ones((2, 2))])
    with pytest.raises(TypeError, match="float32 or float64"):
        SymmetricStencil(FIVE, [np.ones((2, 2), dtype=int)] * 3)
    with pytest.raises(ValueError, match="vector of length"):
        SymmetricStencil(FIVE, [np.ones((2, 2))] * 3) @ np.ones(5)


@pytest.mark.parametrize("rows", [None, 1, 3])
@pytest.mark.parametrize("offsets", [FIVE, THIRTEEN, TWENTY_FIVE], ids=["5", "13", "25"])
@pytest.mark.parametrize("shape", SHAPES)
def test_banded_sweeps_and_products_equal_the_csr_kernel(set_limits, rows, offsets, shape):
    if rows is not None:  # small bands: several per grid, and a shorter last one
        set_limits(stencil_band_values=rows * shape[1] * len(offsets))
    A, _ = random_spd(offsets, shape, seed=5)
    rng = np.random.default_rng(2)
    for dtype in (np.float64, np.float32):
        banded, csr = BandedStencil(A, dtype), A.tocsr(dtype=dtype)
        x = rng.standard_normal(A.shape[0]).astype(dtype)
        b = rng.standard_normal(A.shape[0]).astype(dtype)
        np.testing.assert_array_equal(banded @ x, csr @ x)
        _assert_sweeps_equal(banded, csr, x, b)


@pytest.mark.parametrize("rows", [None, 1, 3])
@pytest.mark.parametrize("offsets", [THIRTEEN, TWENTY_FIVE], ids=["13", "25"])
@pytest.mark.parametrize("shape", [(1, 7), (2, 9), (13, 8), (30, 21)])
def test_full_stencil_sweeps_and_products_equal_the_csr_kernel(set_limits, rows, offsets, shape):
    """A FullStencil (every image, not symmetric) cycles like its CSR form, bit for bit."""
    if rows is not None:
        set_limits(stencil_band_values=rows * shape[1] * len(offsets))
    rng = np.random.default_rng(7)
    S = rng.uniform(-1.0, 1.0, (len(offsets),) + shape)
    S[offsets.index((0, 0))] = 2.0 * len(offsets) + rng.random(shape)
    for dtype in (np.float64, np.float32):
        full, csr = bands.FullStencil(offsets, S, dtype), stencil_to_csr(offsets, S, dtype=dtype)
        assert full.nnz == csr.nnz and (full.tocsr() != csr).nnz == 0
        np.testing.assert_array_equal(full.diagonal(), csr.diagonal())
        x = rng.standard_normal(csr.shape[0]).astype(dtype)
        b = rng.standard_normal(csr.shape[0]).astype(dtype)
        np.testing.assert_array_equal(full @ x, csr @ x)
        _assert_sweeps_equal(BandedStencil(full, dtype), csr, x, b)


@pytest.mark.parametrize("fine_precision", ["double", "single"])
@pytest.mark.parametrize("shape", [(3, 4), (17, 23), (40, 31)])
def test_multigrid_of_the_stencil_equals_that_of_its_csr(fine_precision, shape):
    A, dense = random_spd(THIRTEEN, shape, seed=6)
    ours = GridMultigrid(A, shape, max_coarse=16, fine_precision=fine_precision)
    ref = GridMultigrid(A.tocsr(), shape, max_coarse=16, fine_precision=fine_precision)
    assert len(ours.levels) == len(ref.levels)
    r = np.random.default_rng(3).standard_normal(A.shape[0])
    np.testing.assert_array_equal(ours.vcycle(r), ref.vcycle(r))
    b = dense @ np.linspace(1.0, 2.0, A.shape[0])
    x, info = ours.solve(b, rtol=1e-12)
    assert info.converged
    np.testing.assert_allclose(x, np.linalg.solve(dense, b), rtol=1e-10)


def test_multigrid_update_and_checks():
    A, _ = random_spd(THIRTEEN, (20, 18), seed=7)
    B, _ = random_spd(THIRTEEN, (20, 18), seed=8)
    mg = GridMultigrid(A, (20, 18), max_coarse=16, fine_precision="double").update(B)
    ref = GridMultigrid(B.tocsr(), (20, 18), max_coarse=16, fine_precision="double")
    r = np.ones(A.shape[0])
    np.testing.assert_array_equal(mg.vcycle(r), ref.vcycle(r))
    with pytest.raises(ValueError, match="grid of shape"):
        GridMultigrid(A, (18, 20))
    assert "pyamg" in type(mg.to_pyamg()).__module__


def _problem(shape=(36, 44), seed=0):
    rng = np.random.default_rng(seed)
    image = rng.integers(0, 256, shape + (3,)).astype(np.uint8)
    depth = 1.0 + 4.0 * rng.random(shape)
    mask = rng.random(shape) < 0.1
    return image, np.where(mask, depth, 0.0), mask


@pytest.mark.parametrize("weights", [sd.DEFAULT_WEIGHTS.replace(gamma=0),
                                     sd.Weights.paper(alpha=1.0, beta=0.1, gamma=0.0, delta=1e-3, kappa=10.0)],
                         ids=["13-point", "5-point"])
def test_normal_equations_stencil_form(weights):
    image, sparse, mask = _problem()
    obj, coarse, _ = sd.build_objective(image, sparse, mask, weights=weights)
    A, b, c = sd.build_objective(image, sparse, mask, weights=weights)[0].normal_equations()
    S, b2, c2 = obj.normal_equations(form="stencil")
    assert isinstance(S, SymmetricStencil)
    np.testing.assert_array_equal(b, b2)
    assert c == c2
    x = coarse.ravel()
    np.testing.assert_array_equal(S @ x, A @ x)
    assert obj.normal_equations(form="stencil")[0] is S  # cached
    A2 = obj.normal_equations()[0]  # the CSR form replaces the cached stencil
    assert sp.issparse(A2) and (A2 != A).nnz == 0
    assert obj.normal_equations(form="stencil")[0] is A2  # a cached CSR serves the stencil form
    with pytest.raises(ValueError, match="form must be"):
        obj.normal_equations(form="dense")


@pytest.mark.parametrize("grey", [False, True], ids=["colour", "grey"])
def test_stencil_form_is_the_upper_half_of_the_full_assembly_with_and_without_row_weights(grey):
    """Every stencil term (identity, row-weighted differences, local-linear) written once into the stored half."""
    image, sparse, mask = _problem((11, 13), seed=3)
    if grey:
        image = image.mean(axis=2).astype(np.uint8)
    obj, _, _ = sd.build_objective(image, sparse, mask, weights=sd.DEFAULT_WEIGHTS.replace(gamma=0))
    assert {t.name for t in obj.quadratic_terms} >= {"smooth_image", "second_order_image", "local_linear"}
    offsets, full = obj.normal_stencil()
    S, _, _ = obj.normal_equations(form="stencil")
    assert S.offsets == offsets and len(offsets) == 25
    np.testing.assert_array_equal(S.data, full[[offsets.index(o) for o in S.upper]])
    dense = np.zeros((obj.size, obj.size))
    for t in obj.quadratic_terms:  # Σ weight · Kᵀ diag(r) K from the explicit matrices
        K = sp.identity(obj.size) if t.operator is None else t.operator.tocsr()
        r = np.ones(K.shape[0]) if t.row_weights is None else np.asarray(t.row_weights, dtype=float)
        dense += t.weight * (K.T @ sp.diags(r) @ K).toarray()
    np.testing.assert_allclose(S.toarray(), dense, rtol=0, atol=1e-12 * np.abs(dense).max())


def test_normal_equations_stencil_form_falls_back_to_csr_for_general_operators():
    image, sparse, mask = _problem((12, 10))
    obj, _, _ = sd.build_objective(image, sparse, mask, weights=sd.DEFAULT_WEIGHTS.replace(gamma=0))
    terms = [t if t.name != "smooth_image" else type(t)(t.name, t.weight, t.operator.tocsr(), t.row_weights)
             for t in obj.terms]
    general = type(obj)(obj.shape, terms)
    A, _, _ = general.normal_equations(form="stencil")
    assert sp.issparse(A)
    np.testing.assert_allclose(A.toarray(), obj.normal_equations()[0].toarray(), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("kind", ["grid", "jacobi", "amg", "none"])
def test_solve_through_the_stencil_form_equals_spsolve(kind):
    """``‖z − z*‖ <= ‖b − A z‖ / λ_min(A)``, ``λ_min(A) >= δ`` (A = δI + semidefinite terms)."""
    image, sparse, mask = _problem((40, 52), seed=1)
    weights = sd.DEFAULT_WEIGHTS.replace(gamma=0)
    obj, coarse, _ = sd.build_objective(image, sparse, mask, weights=weights)
    S, b, _ = obj.normal_equations(form="stencil")
    ref = spsolve(sp.csc_matrix(S.tocsr()), b)
    z, _, converged, rel = pcg(S, b, x0=coarse.ravel(), M=make_preconditioner(S, kind), rtol=1e-12, maxiter=20000)
    assert converged and rel <= 1e-12
    residual = np.linalg.norm(b - S.tocsr() @ z)
    assert np.linalg.norm(z - ref) <= residual / weights.delta * (1 + 1e-6) + 1e-12 * np.linalg.norm(ref)


@pytest.mark.parametrize("layout", ["symmetric", "full", "full, read class by class"])
@pytest.mark.parametrize("shape", [(33, 47), (64, 50)])
def test_banded_coarse_levels_equal_the_csr_hierarchy(monkeypatch, set_limits, shape, layout):
    """The large-frame layout (fine float64 bands, float32 stencil coarse levels) cycles like the CSR one."""
    from sparsedepth.linalg.multigrid import hierarchy

    from sparsedepth.linalg.multigrid import transfer

    set_limits(single_fine_values=0)  # every fine operator counts as large
    set_limits(banded_coarse_pixels=64)
    set_limits(transfer_band_pixels=100)  # the fine residual restricted a few rows at a time
    if layout.startswith("full"):  # as if no coarse level were exactly symmetric in float32
        monkeypatch.setattr(SymmetricStencil, "from_stencil", classmethod(lambda cls, *args, **kwargs: None))
    if layout.endswith("by class"):  # the 8-MP set-up: every level read one parity class at a time
        set_limits(keep_stencil_pixels=0)
    image, sparse, mask = _problem(shape, seed=2)
    obj, coarse, _ = sd.build_objective(image, sparse, mask, weights=sd.DEFAULT_WEIGHTS.replace(gamma=0))
    S, b, _ = obj.normal_equations(form="stencil")
    ours = GridMultigrid(S, shape, coarse_precision="single")
    ref = GridMultigrid(S.tocsr(), shape, coarse_precision="single")
    kind = SymmetricStencil if layout == "symmetric" else bands.FullStencil
    assert isinstance(ours.levels[1].A, kind) and ours.levels[1].A.dtype == np.float32
    assert ours.fine_dtype == ref.fine_dtype == np.float64
    for seed in range(3):
        r = np.random.default_rng(seed).standard_normal(b.size)
        np.testing.assert_array_equal(ours.vcycle(r), ref.vcycle(r))
    z, _, converged, _ = pcg(S, b, x0=coarse.ravel(), M=ours.aspreconditioner(), rtol=1e-11)
    assert converged
    np.testing.assert_allclose(S @ z, b, rtol=0, atol=1e-10 * np.linalg.norm(b))


def test_large_frames_solve_in_stencil_form_with_the_csr_solution(set_limits):
    """From STENCIL_FORM_PIXELS on, the γ = 0 solve keeps A as a SymmetricStencil; same depth as the CSR solve.

    Both are solved to a relative residual of 1e-12 and compared at that accuracy.
    """
    import warnings

    import sparsedepth as sd
    from conftest import make_scene
    from sparsedepth.grid.stencil import SymmetricStencil
    from sparsedepth.solvers import quadratic

    image, depth = make_scene(shape=(40, 52))
    sparse, mask = sd.sample_depth(depth, fraction=0.05, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        csr = sd.complete_depth(image, sparse, mask, tol=1e-12)
        set_limits(stencil_form_pixels=1)
        objective, _, _ = sd.build_objective(image, sparse, mask)
        assert quadratic.system_form(objective) == "stencil"
        stencil = sd.complete_depth(image, sparse, mask, tol=1e-12)
    np.testing.assert_allclose(stencil.depth, csr.depth, rtol=1e-9, atol=0)
    assert stencil.converged == csr.converged and np.isfinite(stencil.gap)
    A, _, _ = objective.normal_equations(form=quadratic.system_form(objective))
    assert isinstance(A, SymmetricStencil)


def _assert_sweeps_equal(banded, csr, x, b):
    """Two forward and one backward Gauss-Seidel sweeps from ``x`` give the same iterates on both forms, bit for bit."""
    ours, ref = x.copy(), x.copy()
    gauss_seidel_forward(banded, ours, b, 2)
    gauss_seidel_forward(csr, ref, b, 2)
    np.testing.assert_array_equal(ours, ref)
    gauss_seidel_backward(banded, ours, b, 1)
    gauss_seidel_backward(csr, ref, b, 1)
    np.testing.assert_array_equal(ours, ref)
