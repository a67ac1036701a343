import os
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("SPARSEDEPTH_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture
def shared_data():
    """Path of ../shared/data; skips the test where it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real-data folder {SHARED_DATA} not present (CI has it beside the clone)")
    return SHARED_DATA


def make_problem(shape=(40, 50), fraction=0.08, seed=0):
    """A small synthetic problem: a tilted plane with a step, a matching image."""
    rng = np.random.default_rng(seed)
    H, W = shape
    ii, jj = np.mgrid[0:H, 0:W]
    truth = 1.0 + 0.02 * ii + 0.01 * jj + 0.5 * (jj > W // 2)
    image = np.clip(0.2 + 0.5 * (jj > W // 2)[..., None] + 0.05 * rng.standard_normal((H, W, 3)), 0, 1)
    mask = rng.random(shape) < fraction
    mask[0, 0] = True
    sparse = np.where(mask, truth, np.nan)
    return image, sparse, mask, truth


def make_scene(shape=(40, 60), seed=0):
    """A tilted plane with a 0.5 m step, and a uint8 image whose edge is the step (for CLI and batch tests)."""
    rng = np.random.default_rng(seed)
    ii, jj = np.mgrid[0 : shape[0], 0 : shape[1]]
    depth = 1.0 + 0.02 * ii + 0.01 * jj + 0.5 * (jj > shape[1] // 2)
    image = np.clip(60 + 120 * (jj > shape[1] // 2)[..., None] + rng.integers(0, 30, shape + (3,)), 0, 255)
    return image.astype(np.uint8), depth


@pytest.fixture
def scene_files(tmp_path):
    """``rgb.png`` and ``sparse.png`` (10 % of :func:`make_scene`'s depth, mm) in ``tmp_path``, for CLI tests."""
    import imageio.v3 as iio

    import sparsedepth as sd

    image, depth = make_scene()
    iio.imwrite(tmp_path / "rgb.png", image)
    sparse, _ = sd.sample_depth(depth, fraction=0.1, seed=1)
    sd.write_depth(tmp_path / "sparse.png", sparse, scale=1000)
    return tmp_path


#: Multigrid options that keep the whole V-cycle in float64, for tests of its exact algebra (by default the V-cycle
#: runs in float32 unless the operator is very large).
DOUBLE = dict(fine_precision="double", coarse_precision="double")


def forward_difference_1d(n):
    """The 1-D forward difference on ``n`` points as an ``(n, n)`` CSR matrix, its last row zero (Neumann)."""
    main = -np.ones(n)
    main[-1] = 0.0
    return sp.diags([main, np.ones(n - 1)], [0, 1], shape=(n, n), format="csr")


@pytest.fixture
def set_limits():
    """``set_limits(**changes)``: :func:`sparsedepth.limits.limited` for the rest of the test (cumulative)."""
    import contextlib

    from sparsedepth.limits import limited

    with contextlib.ExitStack() as stack:
        yield lambda **changes: stack.enter_context(limited(**changes))


def linear_interpolation_1d(n):
    """``(n, (n + 1) // 2)`` dense 1-D linear interpolation from the even points, written out entry by entry (the
    last point of an even-length axis takes its one coarse neighbour)."""
    nc = (n + 1) // 2
    P = np.zeros((n, nc))
    for i in range(n):
        if i % 2 == 0:
            P[i, i // 2] = 1.0
        elif i // 2 + 1 < nc:
            P[i, i // 2] = P[i, i // 2 + 1] = 0.5
        else:
            P[i, i // 2] = 1.0
    return P


def stencil_images(dense, offsets, shape):
    """``(len(offsets), H, W)`` images ``S[k, y, x] = A[(y, x), (y, x) + offsets[k]]`` of a dense matrix (0 outside
    the grid), read entry by entry."""
    H, W = shape
    S = np.zeros((len(offsets), H, W))
    for k, (dy, dx) in enumerate(offsets):
        for y in range(H):
            for x in range(W):
                if 0 <= y + dy < H and 0 <= x + dx < W:
                    S[k, y, x] = dense[y * W + x, (y + dy) * W + x + dx]
    return S
