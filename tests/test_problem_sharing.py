"""CompletionProblem.with_samples: the new problem shares the assembled matrix, with the data term's diagonal changed."""

import warnings

import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.uncertainty import split_samples

from conftest import make_problem


def _halves(shape=(40, 56), fraction=0.1):
    image, sparse, mask, _ = make_problem(shape=shape, fraction=fraction)
    problem = sd.CompletionProblem(image, sparse, mask)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        problem.solve()  # assembles the normal equations
    half, _ = split_samples(mask, seed=0)
    half_depth = np.where(half, sparse, np.nan)
    return problem, image, half_depth, half


def test_shared_matrix_equals_a_fresh_assembly():
    problem, image, half_depth, half = _halves()
    shared = problem.with_samples(half_depth, half)
    fresh = sd.CompletionProblem(image, half_depth, half, weights=problem.weights)
    A1, b1, c1 = shared.objective.normal_equations()
    A2, b2, c2 = fresh.objective.normal_equations()
    assert A1 is not problem.objective.normal_equations()[0]  # a copy: the parent's matrix is left as it was
    scale = abs(A2).max()
    assert abs(A1 - A2).max() <= 1e-13 * scale
    np.testing.assert_allclose(b1, b2, rtol=0, atol=1e-13 * np.abs(b2).max())
    assert c1 == pytest.approx(c2, rel=1e-13)
    # the data term's diagonal: alpha on the half's samples only, checked against the mask by hand
    alpha = problem.weights.alpha
    other = problem.objective.normal_equations()[0].diagonal() - A1.diagonal()
    np.testing.assert_allclose(other, alpha * (problem.observed & ~half).ravel(), atol=1e-13 * scale)


def test_shared_matrix_gives_the_same_completion():
    problem, image, half_depth, half = _halves()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        shared = problem.with_samples(half_depth, half).solve(tol=1e-10)
        fresh = sd.CompletionProblem(image, half_depth, half, weights=problem.weights).solve(tol=1e-10)
    np.testing.assert_allclose(shared.depth, fresh.depth, rtol=0, atol=1e-7 * np.nanmax(fresh.depth))


def test_share_matrix_stencil_form_and_refusals():
    from sparsedepth.objective.objective import _plus_diagonal
    from sparsedepth.grid.stencil import SymmetricStencil

    problem, *_ = _halves(shape=(12, 15))
    A = problem.objective.normal_equations()[0]
    symmetric = problem.objective._stencil_parts(symmetric=True)
    stencil = SymmetricStencil(symmetric[0], symmetric[1])
    d = np.linspace(-0.5, 0.5, A.shape[0])
    expected = (A + np.diag(d)) if isinstance(A, np.ndarray) else (A.toarray() + np.diag(d))
    np.testing.assert_allclose(_plus_diagonal(stencil, d).tocsr().toarray(), expected, rtol=0, atol=1e-14)
    np.testing.assert_allclose(_plus_diagonal(A, d).toarray(), expected, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(A.toarray(), problem.objective.normal_equations()[0].toarray())
    import scipy.sparse as sp

    with pytest.raises(ValueError, match="diagonal"):
        _plus_diagonal(sp.csr_array(np.array([[0.0, 1.0], [1.0, 0.0]])), np.ones(2))
