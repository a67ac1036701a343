"""make_preconditioner (sparsedepth.linalg.preconditioners): each kind against what it should apply."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from sparsedepth.linalg import PRECONDITIONERS, GridMultigrid, make_preconditioner, pcg


def grid_system(shape, seed=0):
    """5-point SPD system on a grid: Neumann Laplacian plus a random positive diagonal."""
    h, w = shape
    rng = np.random.default_rng(seed)

    def d(n):
        return sp.diags([-np.ones(n), np.r_[np.ones(n - 1), 0.0]], [0, 1])

    Dx, Dy = sp.kron(sp.eye(h), d(w)), sp.kron(d(h), sp.eye(w))
    A = (Dx.T @ Dx + Dy.T @ Dy + sp.diags(rng.uniform(0.01, 1.0, h * w))).tocsr()
    return A, rng.standard_normal(h * w)


def test_jacobi_applies_the_inverse_diagonal():
    A, r = grid_system((6, 7))
    M = make_preconditioner(A, "jacobi")
    np.testing.assert_allclose(M @ r, r / A.diagonal(), rtol=1e-15)


def test_none_is_the_identity():
    A, _ = grid_system((4, 4))
    assert make_preconditioner(A, "none") is None


def test_a_built_hierarchy_is_used_as_is():
    shape = (12, 10)
    A, r = grid_system(shape, seed=1)
    mg = GridMultigrid(A, shape)
    np.testing.assert_array_equal(make_preconditioner(A, mg) @ r, mg.vcycle(r))


@pytest.mark.parametrize("kind", ["grid", "amg", "jacobi", "none"])
def test_every_kind_preconditions_cg_to_the_direct_solution(kind):
    shape = (20, 24)
    A, b = grid_system(shape, seed=2)
    assert kind in PRECONDITIONERS
    x, _, ok, rel = pcg(A, b, M=make_preconditioner(A, kind, shape=shape), rtol=1e-10)
    assert ok and rel <= 1e-10
    x_ref = spla.spsolve(A.tocsc(), b)
    # λ_min(A) >= 0.01, so ‖x − x*‖₂ <= ‖b − A x‖₂ / 0.01
    assert np.linalg.norm(x - x_ref) <= np.linalg.norm(b - A @ x) / 0.01 + 1e-12 * np.linalg.norm(x_ref)


def test_errors_name_the_problem():
    A, _ = grid_system((4, 5))
    with pytest.raises(ValueError, match=r"pass shape=\(H, W\)"):
        make_preconditioner(A, "grid")
    with pytest.raises(ValueError, match="unknown preconditioner 'ilu'"):
        make_preconditioner(A, "ilu")
    with pytest.raises(ValueError, match="positive diagonal"):
        make_preconditioner(-A, "jacobi")
