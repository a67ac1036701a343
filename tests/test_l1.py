"""The L1 machinery of the ADMM solver: slicing operator, active-set polish, optimality of the result."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import lsq_linear

from sparsedepth import Weights, build_objective, complete_depth
from sparsedepth.objective.l1 import StackedL1, is_grid_gradient
from sparsedepth.objective import AbsTerm, Objective, QuadraticTerm
from sparsedepth.grid.operators import forward_diff, gradient, hessian_operator
from sparsedepth.solvers import solve
from sparsedepth.solvers.active_set import polish_active_set

from conftest import make_problem

L1 = Weights.paper(alpha=1.0, beta=0.2, gamma=0.05, delta=0.01, kappa=5.0)


def _objective_with(shape, operator, rng):
    n = shape[0] * shape[1]
    terms = [
        QuadraticTerm("prior", 1.0, None, None, rng.random(n)),
        AbsTerm("edge", 0.5, operator, rng.random(operator.shape[0])),
    ]
    return Objective(shape, terms)


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (6, 1), (5, 8), (9, 4)])
def test_gradient_by_slicing_equals_the_sparse_product(shape):
    rng = np.random.default_rng(1)
    G = gradient(shape)
    l1 = StackedL1(_objective_with(shape, G, rng))
    assert l1.grid_gradient
    z = rng.standard_normal(G.shape[1])
    v = rng.standard_normal(G.shape[0])
    np.testing.assert_allclose(l1.apply(z), G @ z, rtol=0, atol=1e-14)
    np.testing.assert_allclose(l1.adjoint(v), G.T @ v, rtol=0, atol=1e-14)
    # adjoint (dot) test
    assert np.dot(l1.apply(z), v) == pytest.approx(np.dot(z, l1.adjoint(v)), rel=1e-12, abs=1e-12)


def test_matrix_free_operators_are_accepted():
    from sparsedepth.grid.operators import gradient_stencil

    rng = np.random.default_rng(3)
    shape = (4, 6)
    l1 = StackedL1(_objective_with(shape, gradient_stencil(shape), rng))
    assert l1.grid_gradient
    z = rng.standard_normal(shape[0] * shape[1])
    np.testing.assert_allclose(l1.apply(z), gradient(shape) @ z, atol=1e-14)



@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (6, 1), (5, 8)])
def test_grid_gradient_pairs_gram_and_value_match_the_matrix(shape):
    """The grid fast paths (no CSR matrix) against quantities read from the CSR gradient itself."""
    from sparsedepth.grid.operators import gradient_stencil
    from sparsedepth.grid.stencil import stencil_to_csr

    rng = np.random.default_rng(4)
    l1 = StackedL1(_objective_with(shape, gradient_stencil(shape), rng))
    assert l1.grid_gradient and l1._matrix is None
    G = gradient(shape).tocsr()
    rows, first, second, exact = l1.pixel_pairs()
    assert exact and l1.exact_pairs
    counts = np.diff(G.indptr)
    expected_rows = np.flatnonzero(counts == 2)
    np.testing.assert_array_equal(np.sort(rows), expected_rows)
    order = np.argsort(rows)
    np.testing.assert_array_equal(first[order], G.indices[G.indptr[expected_rows]])
    np.testing.assert_array_equal(second[order], G.indices[G.indptr[expected_rows] + 1])
    assert l1._matrix is None  # none of the above built the matrix
    np.testing.assert_allclose(l1.gram().toarray(), (G.T @ G).toarray(), atol=0)
    z = rng.standard_normal(G.shape[1])
    assert l1.value(l1.apply(z)) == pytest.approx(np.sum(l1.weights * np.abs(G @ z)), rel=1e-13)
    # in another matrix's full in-grid pattern: the same indptr / indices
    offsets = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    pattern = stencil_to_csr(offsets, np.ones((9,) + shape))
    L = l1.gram(offsets)
    np.testing.assert_array_equal(L.indptr, pattern.indptr)
    np.testing.assert_array_equal(L.indices, pattern.indices)
    np.testing.assert_allclose(L.toarray(), (G.T @ G).toarray(), atol=0)
    np.testing.assert_allclose(l1.gram([(0, 0), (0, 1)]).toarray(), (G.T @ G).toarray(), atol=0)  # joined
    out = np.full(2 * G.shape[1], np.nan)
    assert l1.apply(z, out=out) is out
    np.testing.assert_allclose(out, G @ z, atol=1e-14)
    np.testing.assert_allclose(l1.matrix.toarray(), G.toarray())


def test_grid_gradient_recognised_only_when_equal():
    shape = (4, 5)
    G = gradient(shape)
    assert is_grid_gradient(G, shape)
    assert is_grid_gradient(G.copy(), shape)
    assert not is_grid_gradient(2.0 * G, shape)
    assert not is_grid_gradient(sp.vstack([forward_diff(shape, 0), forward_diff(shape, 1)]).tocsr(), shape)
    assert not is_grid_gradient(hessian_operator(shape), shape)
    assert not is_grid_gradient(G, (5, 4))


def test_other_operators_use_sparse_products():
    rng = np.random.default_rng(2)
    shape = (5, 6)
    H = hessian_operator(shape)
    l1 = StackedL1(_objective_with(shape, H, rng))
    assert not l1.grid_gradient
    z = rng.standard_normal(H.shape[1])
    v = rng.standard_normal(H.shape[0])
    np.testing.assert_allclose(l1.apply(z), H @ z)
    np.testing.assert_allclose(l1.adjoint(v), H.T @ v)
    rows, first, second, exact = l1.pixel_pairs()
    assert not exact  # second differences are not pixel pairs: no polish
    assert not l1.exact_pairs
    assert StackedL1(_objective_with(shape, gradient(shape), rng)).pixel_pairs()[3]


def _kkt_gap_bound(obj, z):
    """Upper bound on F(z) − min F from the optimality conditions, by an independent bounded least squares.

    For any p with |p| <= c, F(z') >= L(z') = Q(z') + pᵀKz' >= L(z) − ¼ rᵀA⁻¹r with r = ∇L(z), so
    F(z) − F* <= Σ (c|Kz| − p·Kz) + ‖r‖² / (4 λ_min(A)); λ_min(A) >= δ (the prior weight).
    p is fixed to c·sign(Kz) where |Kz| is not tiny and fitted by lsq_linear in the box elsewhere.
    """
    A, b, const = obj.normal_equations()
    term = obj.term("edge")
    K = sp.csr_matrix(term.operator if sp.issparse(term.operator) else term.operator.tocsr())
    c = term.scaled_row_weights()
    t = K @ z
    free = np.abs(t) <= 1e-9 * max(1.0, np.abs(z).max())
    g = 2.0 * (A @ z - b)
    fixed = np.where(free, 0.0, c * np.sign(t))
    target = -(g + K.T @ fixed)
    Kf = K[free].T.tocsc()
    fit = lsq_linear(Kf, target, bounds=(-c[free], c[free]), tol=1e-14, lsmr_tol="auto", max_iter=5000)
    p = fixed.copy()
    p[free] = fit.x
    r = g + K.T @ p
    delta = obj.term("prior").weight
    return float(np.sum(c * np.abs(t) - p * t) + r @ r / (4.0 * delta))


def test_admm_result_is_certified_optimal_on_a_small_problem():
    image, sparse, mask, _ = make_problem((24, 30))
    res = complete_depth(image, sparse, mask, weights=L1, solver="admm")
    obj, _, _ = build_objective(image, sparse, mask, weights=L1)
    assert res.depth.min() > 0  # the bound below ignores z >= 0, valid as no bound is active
    bound = _kkt_gap_bound(obj, res.depth.ravel())
    assert bound <= 1e-8 * res.objective, (bound, res.message)
    # and plain ADMM iterates at the same count are far from it: the polish did the work
    plain = complete_depth(image, sparse, mask, weights=L1, solver="admm", max_iter=res.iterations,
                           options={"polish": False})
    assert plain.objective - res.objective > 1e3 * bound


def test_admm_matches_a_long_reference_run():
    image, sparse, mask, _ = make_problem((40, 50))
    ref = complete_depth(image, sparse, mask, weights=L1, solver="admm", tol=1e-9, max_iter=5000,
                         options={"polish": False})
    res = complete_depth(image, sparse, mask, weights=L1, solver="admm")
    assert res.converged, res.message
    assert res.objective <= ref.objective * (1 + 1e-6)
    np.testing.assert_allclose(res.depth, ref.depth, atol=1e-3)
    # the history starts at the starting point and ends at the returned point
    assert res.history[0].iteration == 0
    assert res.history[-1].objective == pytest.approx(res.objective, rel=1e-9)
    inner = res.history_array("inner_iterations")
    assert np.all(np.diff(inner) >= 0)


@pytest.fixture(scope="module")
def optimal_signs():
    """A small L1 problem, a long plain-ADMM run and the tied set / signs read off it."""
    image, sparse, mask, _ = make_problem((20, 25))
    obj, coarse, _ = build_objective(image, sparse, mask, weights=L1)
    ref, _ = solve(obj, coarse.ravel(), solver="admm", tol=1e-10, max_iter=20000, options={"polish": False})
    A, b, const = obj.normal_equations()
    l1 = StackedL1(obj)
    t = l1.apply(ref.z)
    u = np.where(np.abs(t) <= 1e-7, 0.0, t)  # the optimal tied set and signs, read off a long run
    return obj, coarse, ref, (A, b, const), l1, u


def test_polish_from_the_optimal_signs_is_the_optimum(optimal_signs):
    obj, coarse, ref, (A, b, const), l1, u = optimal_signs
    z, F, count, _ = polish_active_set(A, b, const, l1, u, z0=coarse.ravel(), rtol=1e-12)
    assert F == pytest.approx(obj.value(z), rel=1e-10)
    assert F <= obj.value(ref.z) * (1 + 1e-12)
    assert count < obj.size  # pixels were merged
    assert _kkt_gap_bound(obj, z) <= 1e-9 * F
    # the tied pixels are exactly equal
    tied = l1.pixel_pairs()[0][u[l1.pixel_pairs()[0]] == 0]
    assert np.all(l1.apply(z)[tied] == 0)


def test_polish_ties_edges_whose_sign_comes_out_wrong(optimal_signs):
    obj, coarse, ref, (A, b, const), l1, u = optimal_signs
    rows = l1.pixel_pairs()[0]
    # untie some optimal ties with an arbitrary sign: the first round has wrong signs there
    tied_rows = rows[u[rows] == 0]
    spoiled = u.copy()
    spoiled[tied_rows[::3]] = 1.0
    _, F_one, _, _ = polish_active_set(A, b, const, l1, spoiled, z0=coarse.ravel(), rounds=1, rtol=1e-12)
    _, F_two, _, _ = polish_active_set(A, b, const, l1, spoiled, z0=coarse.ravel(), rounds=2, rtol=1e-12)
    _, F_opt, _, _ = polish_active_set(A, b, const, l1, u, z0=coarse.ravel(), rtol=1e-12)
    assert F_opt < F_two < F_one
    assert F_two - F_opt < 0.1 * (F_one - F_opt)  # measured ~0.03: most spoiled edges are re-tied


def test_admm_without_polish_stops_on_its_residuals():
    image, sparse, mask, _ = make_problem((20, 25))
    res = complete_depth(image, sparse, mask, weights=L1, solver="admm", tol=1e-4, options={"polish": False})
    assert res.converged and "residuals" in res.message
    assert "polish" not in res.message


def test_polish_declines_a_singular_reduced_model():
    # no prior and no quadratic smoothness: an unobserved pixel on its own has no quadratic term
    weights = Weights.paper(alpha=1.0, beta=0.0, gamma=0.05, delta=0.0, kappa=5.0)
    image, sparse, mask, _ = make_problem((20, 25))
    obj, coarse, _ = build_objective(image, sparse, mask, weights=weights)
    A, b, const = obj.normal_equations()
    l1 = StackedL1(obj)
    untied = np.ones(l1.rows)
    assert polish_active_set(A, b, const, l1, untied, z0=coarse.ravel()) is None
    # the solver still runs (plain ADMM where the polish is declined) and returns a valid point
    res = complete_depth(image, sparse, mask, weights=weights, solver="admm", max_iter=200)
    assert np.all(np.isfinite(res.depth)) and res.depth.min() >= 0
    assert res.objective == pytest.approx(obj.value(res.depth), rel=1e-12)


def test_merge_sums_entries_per_pair_of_components():
    from sparsedepth.solvers.active_set import merge_by_label

    rng = np.random.default_rng(4)
    M = sp.random(30, 30, density=0.2, random_state=5, format="csr")
    labels = rng.integers(0, 7, 30)
    labels[:7] = np.arange(7)  # every label used
    C = sp.csr_matrix((np.ones(30), (np.arange(30), labels)), shape=(30, 7))
    np.testing.assert_allclose(merge_by_label(M, labels, 7).toarray(), (C.T @ M @ C).toarray(), atol=1e-14)
    # in blocks of a few pixels (stacked), and with entries replaced by a function of the block
    expected = (C.T @ M @ C).toarray()
    for chunk in (1, 4, 13):
        np.testing.assert_allclose(merge_by_label(M, labels, 7, chunk=chunk).toarray(), expected, atol=1e-14)
    doubled = merge_by_label(M, labels, 7, chunk=5, entries=lambda block, rows: 2.0 * block.data + rows[0] * 0)
    np.testing.assert_allclose(doubled.toarray(), 2.0 * expected, atol=1e-14)


@pytest.mark.parametrize("shape", [(1, 6), (5, 1), (2, 2), (3, 3), (6, 7)])
def test_gram_entries_are_the_laplacian_on_a_wider_pattern(shape):
    from sparsedepth.grid.operators import gradient_stencil
    from sparsedepth.grid.stencil import stencil_to_csr

    rng = np.random.default_rng(5)
    l1 = StackedL1(_objective_with(shape, gradient_stencil(shape), rng))
    offsets = sorted({(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3) if abs(dy) + abs(dx) <= 2})
    pattern = sp.csr_matrix(stencil_to_csr(offsets, rng.random((len(offsets),) + shape)))  # 13-point, all stored
    G = gradient(shape)
    laplacian = (G.T @ G).toarray()
    rows = np.array([0, shape[0] * shape[1] - 1, (shape[0] * shape[1]) // 2])
    block = pattern[rows]
    got = np.zeros((rows.size, pattern.shape[1]))
    for i in range(rows.size):
        cols = block.indices[block.indptr[i]:block.indptr[i + 1]]
        got[i, cols] = l1.gram_entries(block, rows)[block.indptr[i]:block.indptr[i + 1]]
    np.testing.assert_array_equal(got, laplacian[rows])


@pytest.mark.parametrize("shape", [(1, 5), (4, 1), (2, 2), (3, 4)])
def test_gram_entries_on_a_dense_block(shape):
    # every column stored, including the pixels one index away across an image row's end
    rng = np.random.default_rng(6)
    l1 = StackedL1(_objective_with(shape, gradient(shape), rng))
    n = shape[0] * shape[1]
    dense = sp.csr_matrix(np.ones((n, n)))
    rows = rng.permutation(n)[: max(n - 1, 1)]
    G = gradient(shape)
    laplacian = (G.T @ G).toarray()
    got = l1.gram_entries(dense[rows], rows).reshape(rows.size, n)
    np.testing.assert_array_equal(got, laplacian[rows])


def test_weight_chunks_and_stack_rows():
    from sparsedepth.objective import l1 as _l1
    from sparsedepth.solvers.active_set import stack_rows

    rng = np.random.default_rng(6)
    shape = (7, 9)
    l1 = StackedL1(_objective_with(shape, gradient(shape), rng))
    old_chunk, _l1.CHUNK_ROWS = _l1.CHUNK_ROWS, 10  # several chunks
    try:
        assert l1.max_weight() == pytest.approx(np.max(l1.weights), rel=1e-15)
        Kz = l1.apply(rng.standard_normal(shape[0] * shape[1]))
        assert l1.value(Kz) == pytest.approx(np.sum(l1.weights * np.abs(Kz)), rel=1e-13)
    finally:
        _l1.CHUNK_ROWS = old_chunk
    blocks = [sp.random(m, 11, density=0.3, random_state=m, format="csr") for m in (3, 1, 4)]
    expected = sp.vstack(blocks).toarray()
    np.testing.assert_array_equal(stack_rows(list(blocks), 11).toarray(), expected)


def test_polish_with_the_admm_matrix_equals_the_polish_with_A(optimal_signs):
    """penalty=ρ: the polish reduces S = 2A + ρKᵀK block by block and must find the same point."""
    from sparsedepth.solvers.admm import combine

    obj, coarse, ref, (A, b, const), l1, u = optimal_signs
    rho = 2.5
    S = combine(2.0, A, rho, (gradient(obj.shape).T @ gradient(obj.shape)).tocsr())
    spoiled = u.copy()
    rows = l1.pixel_pairs()[0]
    spoiled[rows[u[rows] == 0][::3]] = 1.0  # two rounds
    for sign_source in (u, spoiled):
        z_a, F_a, n_a, _ = polish_active_set(A, b, const, l1, sign_source, z0=coarse.ravel(), rtol=1e-12)
        z_s, F_s, n_s, _ = polish_active_set(S, b, const, l1, sign_source, z0=coarse.ravel(), rtol=1e-12,
                                              penalty=rho)
        assert n_a == n_s
        assert F_s == pytest.approx(F_a, rel=1e-11)
        np.testing.assert_allclose(z_s, z_a, atol=1e-8)


def test_combine_same_and_different_patterns():
    from sparsedepth.solvers.admm import combine

    A = sp.random(20, 20, density=0.3, random_state=1, format="csr")
    same = sp.csr_matrix((np.arange(1.0, A.nnz + 1), A.indices, A.indptr), shape=A.shape)
    other = sp.random(20, 20, density=0.3, random_state=2, format="csr")
    for B in (same, other):
        np.testing.assert_allclose(combine(2.0, A, 1.5, B).toarray(), (2.0 * A + 1.5 * B).toarray(), atol=1e-14)


@pytest.mark.parametrize("options", [{"inner_max_iter": 3}, {"adapt_iters": 20}, {"preconditioner": "amg"},
                                     {"polish_preconditioner": "amg"}])
def test_admm_options_reach_the_same_optimum(options):
    image, sparse, mask, _ = make_problem((24, 30))
    obj, _, _ = build_objective(image, sparse, mask, weights=L1)
    res = complete_depth(image, sparse, mask, weights=L1, solver="admm", options=options)
    assert res.depth.min() > 0
    assert _kkt_gap_bound(obj, res.depth.ravel()) <= 1e-7 * res.objective, res.message


def test_admm_keeping_only_s_reaches_the_same_point(set_limits):
    """Large frames keep S = 2A + ρKᵀK only (the polish reduces S); forced here on a small frame."""
    from sparsedepth.solvers import active_set

    image, sparse, mask, _ = make_problem((24, 30))
    obj, _, _ = build_objective(image, sparse, mask, weights=L1)
    with_a = complete_depth(image, sparse, mask, weights=L1, solver="admm")
    set_limits(reduced_matrix_pixels=0)
    s_only = complete_depth(image, sparse, mask, weights=L1, solver="admm")
    assert s_only.converged and with_a.converged
    # the same ADMM iterates, not only the same end point (compared by value: counts are not, as rounding
    # can move the stopping iteration)
    F_s, F_a = s_only.history_array("objective"), with_a.history_array("objective")
    k = min(len(F_s), len(F_a))
    assert k >= 2
    np.testing.assert_allclose(F_s[:k], F_a[:k], rtol=1e-6)
    assert s_only.objective == pytest.approx(with_a.objective, rel=1e-10)
    np.testing.assert_allclose(s_only.depth, with_a.depth, atol=1e-8)
    assert _kkt_gap_bound(obj, s_only.depth.ravel()) <= 1e-7 * s_only.objective


def test_weights_shared_by_the_gradient_blocks_equal_the_stacked_ones():
    """AbsTerm row weights of shape (N,) stand for the same weights on the x and the y edges."""
    from sparsedepth.objective import l1 as _l1
    from sparsedepth.grid.operators import gradient_stencil

    rng = np.random.default_rng(7)
    shape = (6, 5)
    n = shape[0] * shape[1]
    G = gradient_stencil(shape)
    w = rng.random(n)
    prior = QuadraticTerm("prior", 1.0, None, None, rng.random(n))
    shared = Objective(shape, [prior, AbsTerm("edge", 0.7, G, w)])
    stacked = Objective(shape, [prior, AbsTerm("edge", 0.7, G, np.concatenate([w, w]))])
    np.testing.assert_array_equal(shared.term("edge").scaled_row_weights(), 0.7 * np.concatenate([w, w]))
    z = rng.standard_normal(n)
    assert shared.value(z) == pytest.approx(stacked.value(z), rel=1e-14)
    a, b = StackedL1(shared), StackedL1(stacked)
    np.testing.assert_array_equal(a.weights, b.weights)
    v = rng.standard_normal(2 * n)
    old_chunk, _l1.CHUNK_ROWS = _l1.CHUNK_ROWS, 7  # chunks that do not divide a block
    try:
        np.testing.assert_allclose(a.weighted(v), b.weights * v, rtol=1e-15)
        assert a.value(v) == pytest.approx(np.sum(b.weights * np.abs(v)), rel=1e-14)
        assert a.max_weight() == pytest.approx(0.7 * w.max(), rel=1e-15)
    finally:
        _l1.CHUNK_ROWS = old_chunk
    with pytest.raises(ValueError, match="row_weights"):
        AbsTerm("edge", 0.7, G, rng.random(n + 1))


def _admm_step_by_formula(Kz, u, lam, c, relax, scale):
    """The ADMM edge update of ``StackedL1.admm_step`` written out on whole vectors, with ``c`` formed."""
    x = relax * Kz + (1 - relax) * u + lam
    lam_new = np.sign(x) * np.minimum(np.abs(x), scale * c)
    u_new = x - lam_new
    sums = dict(Kz_sq=Kz @ Kz, value=np.sum(c * np.abs(Kz)), r_sq=np.sum((Kz - u_new) ** 2), u_sq=u_new @ u_new,
                s_sq=np.sum((u - u_new) ** 2), lam_sq=lam_new @ lam_new)
    return u_new, lam_new, sums


@pytest.mark.parametrize("chunk", [5, 7, 1 << 13])
@pytest.mark.parametrize("weights", ["shared", "stacked", "none"])
def test_admm_step_equals_the_update_written_out(monkeypatch, chunk, weights):
    """The fused chunked edge step against the textbook update (shrinkage, clipped multiplier, sums)."""
    from sparsedepth.objective import l1 as _l1
    from sparsedepth.grid.operators import gradient_stencil

    monkeypatch.setattr(_l1, "STEP_CHUNK_ROWS", chunk)  # 5 and 7 do not divide the blocks of 2 * 30 rows
    rng = np.random.default_rng(8)
    shape = (6, 5)
    n = shape[0] * shape[1]
    G = gradient_stencil(shape)
    row_weights = {"shared": rng.random(n), "stacked": rng.random(2 * n), "none": None}[weights]
    if weights == "shared":
        row_weights[3] = 0.0  # a zero weight: that edge's multiplier is clipped to 0
    obj = Objective(shape, [QuadraticTerm("prior", 1.0, None, None, rng.random(n)),
                            AbsTerm("edge", 0.7, G, row_weights)])
    l1 = StackedL1(obj)
    c = l1.weights
    Kz = l1.apply(rng.standard_normal(n))
    u = rng.standard_normal(2 * n) * 0.5
    lam = rng.standard_normal(2 * n) * 0.3
    u_exp, lam_exp, sums_exp = _admm_step_by_formula(Kz, u, lam, c, 1.9, 0.4)
    out, lam_out = Kz.copy(), lam.copy()
    sums = l1.admm_step(out, u, lam_out, relax=1.9, scale=0.4, primal=True, dual=True)
    np.testing.assert_allclose(out, u_exp, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(lam_out, lam_exp, rtol=1e-13, atol=1e-15)
    assert np.all(np.abs(lam_out) <= 0.4 * c * (1 + 1e-15))
    assert sums.keys() == sums_exp.keys()
    for key, expected in sums_exp.items():
        assert sums[key] == pytest.approx(expected, rel=1e-12, abs=1e-15), key
    # without the residual sums: the same update, only the two sums the objective needs
    out2, lam2 = Kz.copy(), lam.copy()
    assert set(l1.admm_step(out2, u, lam2, relax=1.9, scale=0.4)) == {"Kz_sq", "value"}
    np.testing.assert_array_equal(out2, out)
    np.testing.assert_array_equal(lam2, lam_out)


@pytest.mark.parametrize("operator", ["gradient", "hessian"])
@pytest.mark.parametrize("shape", [(1, 6), (5, 1), (6, 7)])
def test_row_weight_passes_and_masked_products_equal_the_matrix_forms(shape, operator, monkeypatch):
    """weight_chunks, clip, squared_adjoint and masked_normal_product against the CSR matrix of K and c."""
    from sparsedepth.objective import l1 as _l1

    monkeypatch.setattr(_l1, "CHUNK_ROWS", 5)  # several chunks
    rng = np.random.default_rng(8)
    K = sp.csr_matrix(gradient(shape) if operator == "gradient" else hessian_operator(shape))
    l1 = StackedL1(_objective_with(shape, K, rng))
    assert l1.grid_gradient == (operator == "gradient")
    c = l1.weights
    n = shape[0] * shape[1]
    pieces = list(l1.weight_chunks())
    assert len(pieces) > 1
    np.testing.assert_array_equal(np.concatenate([w for _, w in pieces]), c)
    assert [rows.start for rows, _ in pieces] == [0] + [rows.stop for rows, _ in pieces[:-1]]
    v = 3.0 * rng.standard_normal(K.shape[0]) * np.maximum(c, 1e-3)
    np.testing.assert_array_equal(l1.clip(v.copy()), np.clip(v, -c, c))
    mask = rng.random(K.shape[0]) < 0.5
    dense = K.toarray()
    np.testing.assert_allclose(l1.squared_adjoint(mask), (dense**2).T @ mask, rtol=1e-14)
    z = rng.standard_normal(n)
    expected = dense.T @ (mask * (dense @ z))
    np.testing.assert_allclose(l1.masked_normal_product(z, mask), expected, rtol=1e-12, atol=1e-12)
    # bit for bit the product the certificate's fit used before: K^T (mask * K z)
    np.testing.assert_array_equal(l1.masked_normal_product(z, mask), l1.adjoint(mask * l1.apply(z)))
