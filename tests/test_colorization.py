"""colorization_fill: against the naive per-pixel port of the NYU toolbox, and its analytic properties."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.linalg

from sparsedepth.holes.colorization import colorization_fill, colorization_weights

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def naive():
    """bench/naive_colorization.py, imported by path (bench/ is not a package)."""
    spec = importlib.util.spec_from_file_location("naive_colorization", REPO / "bench" / "naive_colorization.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _random_frame(shape=(23, 31), hole_fraction=0.4, seed=0):
    rng = np.random.default_rng(seed)
    image = rng.random(shape + (3,))
    depth = 1.0 + 3.0 * rng.random(shape)
    depth[rng.random(shape) < hole_fraction] = 0.0
    return image, depth


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("alpha", [1.0, 5.0])
def test_matches_naive_port(naive, seed, alpha):
    image, depth = _random_frame(seed=seed)
    expected = naive.fill_depth_colorization(image, depth, alpha)
    got = colorization_fill(image, depth, alpha=alpha)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6)


def test_matches_naive_port_uint8_and_large_hole(naive):
    rng = np.random.default_rng(3)
    image8 = rng.integers(0, 256, size=(20, 26, 3), dtype=np.uint8)
    depth = 2.0 + rng.random((20, 26))
    depth[4:16, 5:20] = 0.0  # one big hole, no known pixel inside
    expected = naive.fill_depth_colorization(image8 / 255.0, depth)
    np.testing.assert_allclose(colorization_fill(image8, depth), expected, rtol=0, atol=1e-6)


def _direct_solution(naive, grey, depth, known, alpha=1.0, win_rad=1):
    """The toolbox system built by the naive port, solved by sparse LU (no iteration)."""
    A = naive.naive_colorization_matrix(grey, win_rad)
    m = known.ravel().astype(float)
    scale = depth[known].max()
    system = (A + scipy.sparse.diags(alpha * m)).tocsc()
    x = scipy.sparse.linalg.spsolve(system, alpha * m * np.where(known, depth, 0.0).ravel() / scale)
    return x.reshape(depth.shape) * scale


def _hand_made_frame():
    # two flat grey regions with a JPEG-like quantised ramp, a big hole that crosses the region edge,
    # a hole touching the image border, and an island of two known pixels inside the big hole
    ii, jj = np.mgrid[0:26, 0:34]
    grey = np.where(jj < 15, 0.25, 0.7) + np.round(0.02 * ii * 8) / 255.0
    depth = 1.0 + 0.1 * ii + np.where(jj < 15, 0.0, 1.5)
    known = np.ones(grey.shape, dtype=bool)
    known[6:20, 8:25] = False
    known[12, 16:18] = True
    known[:3, 28:] = False
    known[(ii * 7 + jj * 3) % 11 == 0] = False
    return grey, depth, known


@pytest.mark.parametrize("window_radius", [1, 2])
@pytest.mark.parametrize("alpha", [1.0, 0.3])
def test_matches_direct_solve_at_tight_tolerance(naive, window_radius, alpha):
    grey, depth, known = _hand_made_frame()
    expected = _direct_solution(naive, grey, depth, known, alpha, window_radius)
    got = colorization_fill(grey, np.where(known, depth, 0.0), alpha=alpha, rtol=1e-13,
                            window_radius=window_radius)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10)


@pytest.mark.parametrize("rtol", [1e-3, 1e-6])
def test_error_bound_of_rtol(naive, rtol):
    # documented: |out - exact| <= rtol * max |depth[mask]| at every pixel
    grey, depth, known = _hand_made_frame()
    expected = _direct_solution(naive, grey, depth, known)
    got = colorization_fill(grey, np.where(known, depth, 0.0), rtol=rtol)
    assert np.abs(got - expected).max() <= rtol * depth[known].max()


@pytest.mark.parametrize("case", ["all known", "one known", "one unknown"])
def test_extreme_masks_match_direct_solve(naive, case):
    grey, depth, _ = _hand_made_frame()
    known = np.full(grey.shape, case == "all known")
    if case == "one known":
        known[3, 4] = True
    elif case == "one unknown":
        known[:] = True
        known[3, 4] = False
    expected = _direct_solution(naive, grey, depth, known)
    got = colorization_fill(grey, depth, mask=known, rtol=1e-13)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10)


def _flat_bright_grey():
    # near-white flat image with one-level (1/255) steps and two isolated outliers: tiny window
    # variances under a large mean, where a one-pass variance would cancel catastrophically
    rng = np.random.default_rng(1)
    grey = 0.96 + np.round(rng.random((24, 30)) * 0.6 - 0.3) / 255.0
    grey[5, 7] -= 40 / 255.0
    grey[12, 20] -= 3 / 255.0
    return grey


@pytest.mark.parametrize("frame", ["hand made", "flat bright"])
@pytest.mark.parametrize("window_radius", [1, 2])
def test_weights_are_the_naive_matrix(naive, window_radius, frame):
    grey = _hand_made_frame()[0] if frame == "hand made" else _flat_bright_grey()
    W = colorization_weights(grey, window_radius=window_radius)
    A = naive.naive_colorization_matrix(grey, window_radius)
    np.testing.assert_allclose(W.toarray(), np.eye(grey.size) - A.toarray(), rtol=0, atol=1e-15)
    assert W.has_sorted_indices and np.all(np.diff(W.indptr) > 0)


def test_maximum_principle():
    image, depth = _random_frame(seed=5, hole_fraction=0.7)
    known = depth > 0
    out = colorization_fill(image, depth)
    lo, hi = depth[known].min(), depth[known].max()
    assert out.min() >= lo - 1e-9 and out.max() <= hi + 1e-9
    # the bound is attained nowhere strictly outside and is not trivially satisfied by a constant
    assert out.max() - out.min() > 0.5 * (hi - lo)


def test_constant_depth_is_reproduced_everywhere():
    # every row of the system is "x_p = convex combination of neighbours (and d_p)": a constant solves it
    rng = np.random.default_rng(2)
    image = rng.random((30, 40, 3))
    depth = np.full((30, 40), 2.5)
    depth[rng.random(depth.shape) < 0.5] = 0.0
    depth[5:20, 10:30] = 0.0
    np.testing.assert_allclose(colorization_fill(image, depth), 2.5, rtol=0, atol=1e-7)


def test_known_pixels_kept_where_neighbours_agree():
    # a depth step that coincides with an image edge: the window weights across the edge are
    # exp(-0.36 / (0.6 var)) ~ 5e-4, so each side keeps its own known value to ~1e-3 of the step,
    # holes included, and exactly far from the edge
    rng = np.random.default_rng(2)
    cols = np.arange(40)[None, :] * np.ones((30, 1))
    image = np.where(cols < 20, 0.2, 0.8)
    truth = np.where(cols < 20, 1.5, 3.0)
    depth = truth.copy()
    holes = rng.random(truth.shape) < 0.3
    depth[holes] = 0.0
    out = colorization_fill(image, depth)
    np.testing.assert_allclose(out, truth, rtol=0, atol=2e-3)
    far = np.abs(cols - 19.5) > 8
    np.testing.assert_allclose(out[far], truth[far], rtol=0, atol=1e-6)
    # without the image edge the step is smoothed out: the test above is not vacuous
    blurred = colorization_fill(np.full((30, 40), 0.5), depth)
    assert np.abs(blurred - truth).max() > 0.1


def test_input_not_modified():
    image, depth = _random_frame(seed=4)
    image0, depth0 = image.copy(), depth.copy()
    colorization_fill(image, depth)
    np.testing.assert_array_equal(image, image0)
    np.testing.assert_array_equal(depth, depth0)


def test_every_public_name_exists():
    # ``from sparsedepth.holes.colorization import *`` must not fail on a stale ``__all__`` entry
    import sparsedepth.holes.colorization as module

    missing = [name for name in module.__all__ if not hasattr(module, name)]
    assert missing == []


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (2, 2), (5, 7), (33, 20)])
def test_nested_dissection_order_is_a_permutation(shape):
    from sparsedepth.holes.ordering import nested_dissection_keys, nested_dissection_order

    keys = nested_dissection_keys(*shape)
    np.testing.assert_array_equal(np.sort(keys), np.arange(shape[0] * shape[1]))
    np.testing.assert_array_equal(nested_dissection_order(*shape), np.argsort(keys))


def test_large_alpha_matches_direct_solve(naive):
    # with alpha = 1e4 the preconditioned Schur complement is the identity to 1e-4, so Gram-Schmidt
    # cancels catastrophically and is repeated (the rarely taken branch of the GMRES)
    grey, depth, known = _hand_made_frame()
    expected = _direct_solution(naive, grey, depth, known, alpha=1e4)
    got = colorization_fill(grey, np.where(known, depth, 0.0), alpha=1e4, rtol=1e-13)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10)


def _window_count(mask, radius):
    """Brute force: number of True pixels of ``mask`` in every pixel's (clipped) window."""
    padded = np.pad(mask.astype(int), radius)
    H, W = mask.shape
    return sum(padded[radius + di : radius + di + H, radius + dj : radius + dj + W]
               for di in range(-radius, radius + 1) for dj in range(-radius, radius + 1))


@pytest.mark.parametrize("window_radius", [1, 2])
def test_eliminated_sets_definition(window_radius):
    from sparsedepth.holes.schur import LAYER_MIN_UNKNOWN as _LAYER_MIN_UNKNOWN
    from sparsedepth.holes.schur import STRIP_WIDTH as _STRIP_WIDTH
    from sparsedepth.holes.schur import eliminated_sets as _eliminated_sets

    _, _, known = _hand_made_frame()
    elim, strip, rim = _eliminated_sets(known, window_radius)
    hole = ~known
    expected_elim = hole | (known & (_window_count(hole, window_radius) >= _LAYER_MIN_UNKNOWN))
    np.testing.assert_array_equal(elim, expected_elim)
    assert (elim & known).any()  # the hand-made frame has known pixels between holes
    np.testing.assert_array_equal(strip, elim & (_window_count(~elim, _STRIP_WIDTH * window_radius) > 0))
    np.testing.assert_array_equal(rim, ~elim & (_window_count(elim, window_radius) > 0))


@pytest.mark.parametrize("use_strip", [True, False])
@pytest.mark.parametrize("window_radius", [1, 2])
def test_schur_solve_matches_spsolve(use_strip, window_radius):
    # the elimination of E = holes + coupled known pixels, with and without the strip
    # preconditioner, against a sparse LU of the same system built from colorization_weights
    from sparsedepth.holes.ordering import nested_dissection_order as _nested_dissection_order
    from sparsedepth.holes.schur import eliminated_sets as _eliminated_sets
    from sparsedepth.holes.schur import solve_schur as _solve_schur

    grey, depth, known = _hand_made_frame()
    alpha = 0.7
    n = grey.size
    system = (scipy.sparse.identity(n) - colorization_weights(grey, window_radius=window_radius)
              + scipy.sparse.diags(alpha * known.ravel().astype(float))).tocsr()
    rhs = alpha * np.where(known, depth, 0.0).ravel()
    expected = scipy.sparse.linalg.spsolve(system.tocsc(), rhs)

    elim, strip, rim = _eliminated_sets(known, window_radius)
    nd = _nested_dissection_order(*grey.shape)
    unknown = nd[elim.ravel()[nd]]
    rest = np.flatnonzero(~elim.ravel())
    order = np.concatenate((unknown, rest))
    A = system[order][:, order].tocsr()
    x, history = _solve_schur(
        A[: unknown.size], A[unknown.size :], rhs[order], x0=depth.ravel()[rest], atol=1e-13, maxiter=200, diag_K=1.0 + alpha,
        strip=np.flatnonzero(strip.ravel()[unknown]) if use_strip else None,
        rim=np.flatnonzero(rim.ravel()[rest]) if use_strip else None,
    )
    got = np.empty(n)
    got[order] = x
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-11)
    assert len(history) > 1  # GMRES ran


@pytest.mark.parametrize("window_radius", [1, 2])
@pytest.mark.parametrize("height", [48, 61])
def test_weights_in_two_threads_equal_one_pass(window_radius, height, monkeypatch):
    # the halves carry a halo of window_radius rows: every plane equals the one-pass result exactly
    from sparsedepth.holes import affinity, colorization

    monkeypatch.setattr(colorization, "available_cpus", lambda: 2)
    grey = np.random.default_rng(3).random((height, 37))
    one, steps_one = affinity.window_weights(grey, window_radius)
    two, steps_two = colorization.window_weights_two_threads(grey, window_radius)
    np.testing.assert_array_equal(two, one)
    np.testing.assert_array_equal(steps_two, steps_one)


def test_negative_depth_is_rejected_like_complete_depth():
    # the depth rule shared with complete_depth and the baselines: without a mask a negative value is an
    # error (not silently a hole), and under a mask a negative known value is an error
    grey, depth, known = _hand_made_frame()
    sparse = np.where(known, depth, 0.0)
    pixel = tuple(np.argwhere(known)[0])
    sparse[pixel] = -1.0
    with pytest.raises(ValueError, match="negative"):
        colorization_fill(grey, sparse)
    with pytest.raises(ValueError, match="negative"):
        colorization_fill(grey, sparse, mask=known)
    ok = known.copy()
    ok[pixel] = False  # the negative value is not a known pixel: ignored, as any value outside the mask
    expected = colorization_fill(grey, np.where(ok, depth, 0.0), mask=ok)
    np.testing.assert_array_equal(colorization_fill(grey, sparse, mask=ok), expected)


@pytest.mark.parametrize("options, error, message", [
    ({"mask": "known_as_int"}, ValueError, "mask must be a boolean array"),
    ({"alpha": 0.0}, ValueError, "alpha must be finite and > 0"),
    ({"rtol": "tight"}, TypeError, "rtol must be a real number"),
    ({"window_radius": 0}, ValueError, "window_radius must be an integer >= 1"),
    ({"window_radius": True}, ValueError, "window_radius must be an integer >= 1"),
    ({"maxiter": 2.0}, ValueError, "maxiter must be an integer >= 1"),
])
def test_fill_option_checks(options, error, message):
    grey, depth, known = _hand_made_frame()
    if options.get("mask") == "known_as_int":
        options = {"mask": known.astype(int)}
    with pytest.raises(error, match=message):
        colorization_fill(grey, np.where(known, depth, 0.0), **options)


def test_depth_of_another_size_than_the_image():
    grey, depth, known = _hand_made_frame()
    with pytest.raises(ValueError, match="depth has shape .* but image has shape"):
        colorization_fill(grey[:, :-1], np.where(known, depth, 0.0))
