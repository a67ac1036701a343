"""The Krylov layer (sparsedepth.linalg.krylov): pcg_info/pcg, pcg_steps and gmres against independent computations."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from sparsedepth.linalg import PCGResult, gmres, pcg, pcg_info, pcg_steps, solve_spd


def spd_system(n=12, seed=0):
    """A sparse SPD matrix (a 2-D Laplacian with a random positive diagonal) on an n x n grid and a right-hand side."""
    rng = np.random.default_rng(seed)
    d = sp.diags([-np.ones(n), np.r_[np.ones(n - 1), 0.0]], [0, 1])
    L = sp.kron(sp.eye(n), d.T @ d) + sp.kron(d.T @ d, sp.eye(n))
    A = (L + sp.diags(rng.uniform(0.01, 1.0, n * n))).tocsr()
    return A, rng.standard_normal(n * n)


def jacobi(A):
    inv = 1.0 / A.diagonal()
    return lambda r: inv * r


@pytest.mark.parametrize("preconditioned", [False, True])
def test_pcg_info_history_convergence_flag_and_solution(preconditioned):
    A, b = spd_system()
    M = jacobi(A) if preconditioned else None
    x0 = np.random.default_rng(1).standard_normal(b.size)
    keep = x0.copy()
    result = pcg_info(A, b, x0=x0, M=M, rtol=1e-10)
    assert isinstance(result, PCGResult)
    np.testing.assert_array_equal(x0, keep)
    norms = result.residual_norms
    assert norms.shape == (result.iterations + 1,)
    assert norms[0] == pytest.approx(np.linalg.norm(b - A @ x0), rel=1e-12)
    true = np.linalg.norm(b - A @ result.x)
    assert norms[-1] == pytest.approx(true, rel=1e-10)
    assert result.relative_residual == pytest.approx(true / np.linalg.norm(b), rel=1e-10)
    assert result.converged and true <= 1e-10 * np.linalg.norm(b)
    assert not result.breakdown and not result.stopped and result.message == "converged"
    x_ref = spla.spsolve(A.tocsc(), b)
    # λ_min(A) >= 0.01, so ‖x − x*‖₂ <= ‖b − A x‖₂ / 0.01
    assert np.linalg.norm(result.x - x_ref) <= true / 0.01 + 1e-12 * np.linalg.norm(x_ref)
    np.testing.assert_allclose(result.x, x_ref, rtol=0, atol=1e-7 * np.abs(x_ref).max())
    # the tuple form is the same solve
    x, it, ok, rel = pcg(A, b, x0=x0, M=M, rtol=1e-10)
    np.testing.assert_array_equal(x, result.x)
    assert (it, ok, rel) == (result.iterations, result.converged, result.relative_residual)


@pytest.mark.parametrize("rtol, atol, maxiter", [(1e-3, 0.0, None), (1e-14, 0.0, 3), (0.0, 1e-2, None), (0.0, 1e-30, 5)])
def test_pcg_info_converged_iff_the_true_residual_meets_the_target(rtol, atol, maxiter):
    A, b = spd_system(seed=2)
    result = pcg_info(A, b, rtol=rtol, atol=atol, maxiter=maxiter)
    true = np.linalg.norm(b - A @ result.x)
    target = max(rtol * np.linalg.norm(b), atol)
    assert result.converged == (true <= target)
    assert result.residual_norms[-1] == pytest.approx(true, rel=1e-10)
    if maxiter is not None:
        assert not result.converged and result.iterations <= maxiter
        assert result.message == f"no convergence in {maxiter} iterations"


def test_pcg_info_reports_breakdown_on_an_indefinite_matrix():
    A = sp.diags([1.0, -1.0]).tocsr()
    b = np.array([1.0, 1.0])
    result = pcg_info(A, b)  # p = b: pᵀAp = 0 at the first step
    assert result.breakdown and not result.converged
    assert "breakdown" in result.message
    assert result.residual_norms[-1] == pytest.approx(np.linalg.norm(b - A @ result.x), rel=1e-10)
    # through solve_spd: status -2 and the breakdown message, not an iteration limit
    x, info = solve_spd(A, b, (1, 2), preconditioner="none")
    assert not info.converged and info.status == -2
    assert info.message == "CG breakdown (operator or preconditioner not SPD?)"
    assert info.residuals[-1] == pytest.approx(np.linalg.norm(b - A @ x), rel=1e-10)


def test_pcg_info_callback_may_stop():
    A, b = spd_system(seed=3)
    seen = []

    def stop_after_three(x):
        seen.append(x.copy())
        if len(seen) == 3:
            raise StopIteration

    result = pcg_info(A, b, rtol=1e-12, callback=stop_after_three)
    assert result.stopped and not result.converged and result.message == "stopped by callback"
    assert result.iterations == len(seen) == 3  # set by the callback, far below the count for 1e-12
    np.testing.assert_array_equal(result.x, seen[-1])
    assert result.residual_norms[-1] == pytest.approx(np.linalg.norm(b - A @ result.x), rel=1e-10)


def test_pcg_info_zero_rhs_is_exact():
    A, b = spd_system()
    result = pcg_info(A, np.zeros_like(b), x0=np.ones_like(b))
    assert result.converged and result.iterations == 0
    np.testing.assert_array_equal(result.x, 0.0)
    np.testing.assert_array_equal(result.residual_norms, [0.0])


def reference_pcg(S, M, z, rhs, steps):
    """``steps`` textbook PCG steps on S z = rhs from ``z`` (dense NumPy, no stopping test)."""
    z = z.copy()
    r = rhs - S @ z
    d = M @ r
    p = d.copy()
    rd = r @ d
    for _ in range(steps):
        q = S @ p
        alpha = rd / (p @ q)
        z = z + alpha * p
        r = r - alpha * q
        d = M @ r
        rd_new = r @ d
        p = d + (rd_new / rd) * p
        rd = rd_new
    return z


@pytest.mark.parametrize("steps", [1, 2, 5])
def test_pcg_steps_from_a_warm_start_are_plain_pcg_steps(steps):
    A, b = spd_system(n=8, seed=4)
    S = A.toarray()
    M = np.diag(1.0 / np.diag(S))
    z0 = np.random.default_rng(5).standard_normal(b.size)
    z = z0.copy()
    Sz = S @ z
    n = pcg_steps(A, lambda r: M @ r, z, Sz, b.copy(), rtol=0.0, factor=0.0, max_steps=steps)
    assert n == steps  # the limit itself: a zero target is never met in a few steps
    expected = reference_pcg(S, M, z0, b, steps)
    np.testing.assert_allclose(z, expected, rtol=0, atol=1e-10 * np.abs(expected).max())
    np.testing.assert_allclose(Sz, S @ z, rtol=0, atol=1e-10 * np.abs(S @ z).max())  # Sz kept equal to S z
    assert np.linalg.norm(b - S @ z) < np.linalg.norm(b - S @ z0)


def test_pcg_steps_stop_at_the_relative_reduction():
    """With an identity preconditioner that returns its argument itself (the residual buffer, updated in place)."""
    A, b = spd_system(n=8, seed=6)
    z = np.zeros(b.size)
    Sz = np.zeros(b.size)
    r0 = np.linalg.norm(b)
    n = pcg_steps(A, lambda r: r, z, Sz, b.copy(), rtol=0.0, factor=0.1, max_steps=500)
    assert 0 < n < 500
    assert np.linalg.norm(b - A @ z) <= 0.1 * r0 * (1 + 1e-8)
    # the same number of plain CG steps from zero reaches the same point
    expected = reference_pcg(A.toarray(), np.eye(b.size), np.zeros(b.size), b, n)
    np.testing.assert_allclose(z, expected, rtol=0, atol=1e-8 * np.abs(expected).max())


@pytest.mark.parametrize("restart", [3, 30])
def test_gmres_matches_a_dense_solve(restart):
    rng = np.random.default_rng(7)
    n = 40
    A = np.eye(n) * 4.0 + rng.standard_normal((n, n)) * 0.3  # non-symmetric, well conditioned
    b = rng.standard_normal(n)
    x0 = rng.standard_normal(n)
    inv_diag = 1.0 / np.diag(A)
    x, lift_x, history, res_inf, ok = gmres(lambda v, _: A @ v, None, b, x0, lambda v: inv_diag * v, 1e-11, 500,
                                            restart=restart)
    assert ok and lift_x is None
    assert history[0] == pytest.approx(np.linalg.norm(b - A @ x0), rel=1e-12)
    assert res_inf == pytest.approx(np.abs(b - A @ x).max(), rel=1e-6, abs=1e-14)
    assert res_inf <= 1e-11
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=0, atol=1e-9)


def test_gmres_with_a_lift_solves_the_composed_operator():
    """A x = B x + C (L x): the lift L is applied to the Krylov directions, the iterate's lift is kept."""
    rng = np.random.default_rng(8)
    n, m = 25, 15
    B = np.eye(n) * 3.0 + 0.2 * rng.standard_normal((n, n))
    C = 0.2 * rng.standard_normal((n, m))
    L = rng.standard_normal((m, n))
    b = rng.standard_normal(n)
    x, lift_x, _, res_inf, ok = gmres(lambda v, lv: B @ v + C @ lv, lambda v: L @ v, b, np.zeros(n), lambda v: v,
                                      1e-11, 500)
    assert ok
    np.testing.assert_allclose(lift_x, L @ x, rtol=0, atol=1e-10)
    np.testing.assert_allclose(x, np.linalg.solve(B + C @ L, b), rtol=0, atol=1e-9)


def test_pcg_info_in_float32_meets_its_tolerance_against_a_direct_solve():
    A, b = spd_system(n=20, seed=3)
    exact = spla.spsolve(A.tocsc(), b)
    single = A.astype(np.float32)
    inverse_diagonal = (1.0 / A.diagonal()).astype(np.float32)
    out = pcg_info(single, b, M=lambda r: inverse_diagonal * r, rtol=1e-4, dtype=np.float32)
    assert out.x.dtype == np.float32 and out.converged
    assert np.linalg.norm(b - A @ out.x.astype(np.float64)) <= 2e-4 * np.linalg.norm(b)  # float32 rounding: < 1e-4
    error = np.linalg.norm(out.x - exact) / np.linalg.norm(exact)
    assert error <= 1e-4 * np.linalg.cond(A.toarray())
    with pytest.raises(ValueError, match="float64 or float32"):
        pcg_info(A, b, dtype=np.float16)
