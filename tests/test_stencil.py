"""Stencil images <-> CSR in the full in-grid pattern (sparsedepth.grid.stencil)."""

import numpy as np
import pytest
import scipy.sparse as sp

from sparsedepth.linalg.multigrid import GridMultigrid, grid_stencil
from sparsedepth.grid import stencil as stencil_module
from sparsedepth.grid.stencil import FullPattern, csr_to_stencil, full_pattern_offsets, stencil_to_csr

FIVE = [(-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)]
NINE = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
OFFSETS_13 = sorted({(0, 0), (0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (-1, -1), (1, -1), (-1, 1),
                     (0, 2), (0, -2), (2, 0), (-2, 0)})
TWENTY_ONE = [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3) if abs(dy) + abs(dx) < 4]
TWENTY_FIVE = [(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3)]
OFFSET_SETS = {"1": [(0, 0)], "5": FIVE, "9": NINE, "13": OFFSETS_13, "21": TWENTY_ONE, "25": TWENTY_FIVE}
SHAPES = [(1, 1), (1, 6), (5, 1), (2, 3), (3, 3), (4, 4), (4, 5), (5, 4), (6, 7), (6, 9), (9, 8), (11, 7)]


def _inside(offsets, shape):
    """``(K, H, W)`` booleans: the neighbour of pixel ``(y, x)`` at offset ``k`` lies inside the grid."""
    H, W = shape
    dy, dx = np.array(offsets).T[:, :, None, None]
    y, x = np.arange(H)[:, None], np.arange(W)[None, :]
    return (y + dy >= 0) & (y + dy < H) & (x + dx >= 0) & (x + dx < W)


def _dense_from_definition(offsets, S):
    """``A[(y, x), (y + dy_k, x + dx_k)] = S[k, y, x]`` for every neighbour inside the grid (one dense scatter)."""
    K, H, W = S.shape
    k, y, x = np.indices(S.shape)
    dy, dx = np.moveaxis(np.array(offsets).reshape(K, 2)[k], -1, 0)
    inside = _inside(offsets, (H, W))
    A = np.zeros((H * W, H * W), dtype=S.dtype)
    A[(y * W + x)[inside], ((y + dy) * W + x + dx)[inside]] = S[inside]
    return A


def _centre_holds(offsets, shape):
    """The grid's centre pixel has every offset inside, ``2 |dx| < W``: its row names the offsets unambiguously."""
    H, W = shape
    return all(0 <= H // 2 + dy < H and 2 * abs(dx) < W for dy, dx in offsets)


@pytest.mark.parametrize("offsets", OFFSET_SETS.values(), ids=OFFSET_SETS.keys())
@pytest.mark.parametrize("shape", SHAPES)
def test_stencil_to_csr_matches_the_definition_and_is_canonical(offsets, shape):
    rng = np.random.default_rng(len(offsets) + 7 * shape[0] + shape[1])
    S = rng.standard_normal((len(offsets),) + shape)
    S[rng.random(S.shape) < 0.2] = 0.0  # in-grid zeros are stored too
    inside = _inside(offsets, shape)
    for dtype in (np.float64, np.float32):
        A = stencil_to_csr(offsets, S, dtype=dtype)
        assert A.dtype == dtype and A.has_canonical_format and A.has_sorted_indices
        assert A.indices.dtype == A.indptr.dtype == np.int32
        np.testing.assert_array_equal(A.toarray(), _dense_from_definition(offsets, S).astype(dtype))
        # every in-grid coupling is stored, zeros included, in strictly increasing columns
        np.testing.assert_array_equal(np.diff(A.indptr), inside.sum(axis=0).reshape(-1))
        for i in range(A.shape[0]):
            assert np.all(np.diff(A.indices[A.indptr[i]:A.indptr[i + 1]]) > 0)
    # float32 images are stored as they are, integer ones through float64
    S32 = S.astype(np.float32)
    np.testing.assert_array_equal(stencil_to_csr(offsets, S32).toarray(), _dense_from_definition(offsets, S32))
    whole = np.round(S * 1000).astype(np.int64)
    np.testing.assert_array_equal(stencil_to_csr(offsets, whole, dtype=np.float32).toarray(),
                                  _dense_from_definition(offsets, whole.astype(np.float32)))


def test_stencil_to_csr_checks_its_arguments():
    S = np.ones((5, 4, 4))
    with pytest.raises(ValueError, match="sorted"):
        stencil_to_csr(FIVE[::-1], S)
    with pytest.raises(ValueError, match="shape"):
        stencil_to_csr(FIVE, S[:4])


@pytest.mark.parametrize("offsets", OFFSET_SETS.values(), ids=OFFSET_SETS.keys())
@pytest.mark.parametrize("shape", SHAPES + [(30, 41)])
def test_full_pattern_is_recognised_and_read_by_position(offsets, shape):
    rng = np.random.default_rng(len(offsets) + 5 * shape[0] + shape[1])
    S = rng.uniform(0.5, 1.5, (len(offsets),) + shape)
    expected = np.where(_inside(offsets, shape), S, 0.0)  # the stencil as read: 0 where the neighbour is outside
    A = stencil_to_csr(offsets, S)
    wide = sp.csr_array((A.data, A.indices.astype(np.int64), A.indptr.astype(np.int64)), shape=A.shape)
    assert wide.indices.dtype == np.int64
    pattern = FullPattern(offsets, shape)
    # recognised, with the offsets it was made of, exactly when the centre row holds them all
    assert pattern.recognisable == _centre_holds(offsets, shape)
    for M in (A, sp.csr_matrix(A), wide):
        found = full_pattern_offsets(M, shape)
        assert (found == offsets) == pattern.recognisable
        read = csr_to_stencil(M, shape)
        if found is None:
            assert read is None
        else:  # on small grids, maybe as the pattern of the offsets the centre row holds
            assert read[0] == found
            np.testing.assert_array_equal(_dense_from_definition(*read), A.toarray())
        # read by position with the offsets given: whole, by bands of rows, by parity classes
        np.testing.assert_array_equal(csr_to_stencil(M, shape, offsets=offsets)[1], expected)
        H = shape[0]
        for y0, y1 in [(0, 1), (H - 1, H), (H // 3, 2 * H // 3 + 1), (1, min(H, 4))]:
            if y1 > y0:
                np.testing.assert_array_equal(pattern.read_rows(M, y0, y1), expected[:, y0:y1])
        for py in range(min(2, shape[0])):
            for px in range(min(2, shape[1])):
                np.testing.assert_array_equal(csr_to_stencil(M, shape, offsets=offsets, parity=(py, px))[1],
                                              expected[:, py::2, px::2])


@pytest.mark.parametrize("offsets", [FIVE, OFFSETS_13, TWENTY_FIVE], ids=["5", "13", "25"])
@pytest.mark.parametrize("shape", [(1, 9), (9, 1), (3, 7), (8, 9), (13, 6)])
def test_pattern_in_bands_of_one_row(monkeypatch, offsets, shape):
    """With one image row per band, the assembly, the check and the reads give what one band gives."""
    rng = np.random.default_rng(3)
    S = rng.standard_normal((len(offsets),) + shape)
    expected = np.where(_inside(offsets, shape), S, 0.0)
    whole = stencil_to_csr(offsets, S, dtype=np.float32)
    A = stencil_to_csr(offsets, S)
    found = full_pattern_offsets(A, shape)
    assert (found == offsets) == FullPattern(offsets, shape).recognisable
    monkeypatch.setattr(stencil_module, "_CHUNK_ENTRIES", 1)
    monkeypatch.setattr(stencil_module, "_CACHE_ENTRIES", 1)
    banded = stencil_to_csr(offsets, S, dtype=np.float32)
    for name in ("indptr", "indices", "data"):
        np.testing.assert_array_equal(getattr(banded, name), getattr(whole, name))
    pattern = FullPattern(offsets, shape)
    for rows in (2, 3):
        by_rows = pattern.to_csr(lambda y0, y1: S[:, y0:y1], np.float64, rows_per_read=rows)
        np.testing.assert_array_equal(by_rows.toarray(), _dense_from_definition(offsets, S))
    assert full_pattern_offsets(A, shape) == found
    np.testing.assert_array_equal(pattern.read_rows(A, 0, shape[0]), expected)
    np.testing.assert_array_equal(pattern.read_class(A, 0, 0), expected[:, ::2, ::2])
    if A.nnz > 1 and found is not None:
        B = A.copy()
        B.indices[-1] -= 1
        assert full_pattern_offsets(B, shape) is None


@pytest.mark.parametrize("position", ["first", "inner", "last"])
def test_full_pattern_offsets_rejects_a_moved_column(position):
    shape = (9, 11)
    S = np.random.default_rng(0).uniform(0.5, 1.5, (len(OFFSETS_13),) + shape)
    A = stencil_to_csr(OFFSETS_13, S)
    assert full_pattern_offsets(A, shape) == OFFSETS_13
    entry = {"first": 0, "inner": A.nnz // 2, "last": A.nnz - 1}[position]
    B = A.copy()
    B.indices[entry] += 1 if position == "first" else -1  # still sorted, no longer the pattern
    assert full_pattern_offsets(B, shape) is None
    assert csr_to_stencil(B, shape) is None
    # row pointers of another pattern
    D = A.copy()
    D.indptr[1:-1] += 1
    assert full_pattern_offsets(D, shape) is None
    # another layout of the same matrix (the entries of a row not in column order) is not read by position
    C = sp.csr_array(A.toarray())
    C.indices[:] = C.indices[::-1].copy()  # unsorted: columns no longer those of the pattern
    assert full_pattern_offsets(C, shape) is None


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
    assert full_pattern_offsets(A.tocsc(), shape) is None


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
    # the stencil read from either equals the one assembled
    for A in (A_full, A_general):
        got_offsets, got = grid_stencil(A, shape)
        np.testing.assert_array_equal(_dense_from_definition(got_offsets, got), A_full.toarray())
