"""Stencil images <-> CSR in the full in-grid pattern (sparsedepth.grid.stencil)."""

import numpy as np
import pytest
import scipy.sparse as sp

from sparsedepth.linalg.multigrid import GridMultigrid, grid_stencil
from sparsedepth.grid.stencil import csr_to_stencil, stencil_to_csr

OFFSETS_13 = sorted({(0, 0), (0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (-1, -1), (1, -1), (-1, 1),
                     (0, 2), (0, -2), (2, 0), (-2, 0)})


def _dense_from_definition(offsets, S):
    K, H, W = S.shape
    out = np.zeros((H * W, H * W))
    for k, (dy, dx) in enumerate(offsets):
        for y in range(H):
            for x in range(W):
                if 0 <= y + dy < H and 0 <= x + dx < W:
                    out[y * W + x, (y + dy) * W + x + dx] += S[k, y, x]
    return out


@pytest.mark.parametrize("shape", [(1, 1), (1, 6), (5, 1), (2, 3), (4, 4), (6, 9), (11, 7)])
def test_stencil_to_csr_matches_the_definition_and_is_canonical(shape):
    rng = np.random.default_rng(0)
    S = rng.standard_normal((len(OFFSETS_13),) + shape)
    A = stencil_to_csr(OFFSETS_13, S)
    np.testing.assert_array_equal(A.toarray(), _dense_from_definition(OFFSETS_13, S))
    for i in range(A.shape[0]):  # strictly increasing columns in every row
        assert np.all(np.diff(A.indices[A.indptr[i]:A.indptr[i + 1]]) > 0)
    # every in-grid coupling is stored, zeros included
    H, W = shape
    inside = sum(max(0, H - abs(dy)) * max(0, W - abs(dx)) for dy, dx in OFFSETS_13)
    assert A.nnz == inside


@pytest.mark.parametrize("shape", [(6, 9), (11, 7), (30, 41)])
def test_csr_to_stencil_round_trip(shape):
    rng = np.random.default_rng(1)
    S = rng.standard_normal((len(OFFSETS_13),) + shape)
    offsets, back = csr_to_stencil(stencil_to_csr(OFFSETS_13, S), shape)
    assert offsets == OFFSETS_13
    # outside the grid the read stencil is zero, inside it equals S
    _, ref = grid_stencil(sp.csr_array(_dense_from_definition(OFFSETS_13, S)), shape)
    np.testing.assert_array_equal(back, ref)


def test_csr_to_stencil_declines_other_layouts():
    shape = (8, 9)
    rng = np.random.default_rng(2)
    S = rng.standard_normal((len(OFFSETS_13),) + shape)
    A = stencil_to_csr(OFFSETS_13, S)
    B = A.copy()
    B.data[5] = 0.0
    B.eliminate_zeros()  # one stored coupling missing: not the full pattern
    assert csr_to_stencil(B, shape) is None
    assert csr_to_stencil(A, (9, 8)) is None  # wrong grid shape
    assert csr_to_stencil(sp.random(72, 72, density=0.1, format="csr", random_state=0), shape) is None


def test_multigrid_reads_the_full_pattern_like_a_general_matrix():
    shape = (33, 47)
    rng = np.random.default_rng(3)
    # SPD 13-point operator: sum of the identity and a Hessian-type normal matrix
    from sparsedepth.grid.operators import hessian_stencil

    K = hessian_stencil(shape)
    offsets = K.offsets()
    S = np.zeros((len(offsets),) + shape)
    K.add_normal_stencil(S, offsets, rng.random(K.shape[0]), 1.0)
    S[offsets.index((0, 0))] += 0.1
    # one symmetric pair of couplings set to zero, so the scipy-built copy lacks them
    S[offsets.index((0, 1)), 10, 10] = S[offsets.index((0, -1)), 10, 11] = 0.0
    A_full = stencil_to_csr(offsets, S)
    A_general = sp.csr_array(A_full.toarray())  # same matrix, zeros not stored
    assert csr_to_stencil(A_general, shape) is None  # so the multigrid takes the diagonal extraction
    mg_full = GridMultigrid(A_full, shape)
    mg_general = GridMultigrid(A_general, shape)
    for a, b in zip(mg_full.levels, mg_general.levels):
        np.testing.assert_allclose(a.A.toarray(), b.A.toarray(), rtol=1e-13, atol=1e-15)
    r = rng.standard_normal(A_full.shape[0])
    np.testing.assert_allclose(mg_full.vcycle(r), mg_general.vcycle(r), rtol=1e-11, atol=1e-13)
