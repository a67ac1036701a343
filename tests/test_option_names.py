"""A misspelt option is a ValueError naming the key, wherever options are passed on as keywords."""

import inspect

import numpy as np
import pytest
import scipy.sparse as sp

import sparsedepth as sd
from sparsedepth._validation import check_option_names
from sparsedepth.linalg import GridMultigrid, solve_spd
from sparsedepth.linalg.multigrid.solve import GRID_OPTIONS


def small_frame():
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, (12, 14, 3), dtype=np.uint8)
    depth = 1.0 + rng.random((12, 14))
    mask = rng.random((12, 14)) < 0.3
    return image, np.where(mask, depth, 0.0), mask


def test_check_option_names_names_the_key_and_lists_the_valid_ones():
    check_option_names({"a": 1}, ("a", "b"), where="f")
    with pytest.raises(ValueError, match=r"^unknown option 'c' for f; valid options: a, b$"):
        check_option_names({"a": 1, "c": 2}, ("b", "a"), where="f")


def test_colorization_baseline_refuses_a_misspelt_option_and_takes_the_right_one():
    image, sparse, mask = small_frame()
    with pytest.raises(ValueError, match="unknown option 'alpah' for colorization_baseline; valid options: alpha, "):
        sd.colorization_baseline(image, sparse, mask, alpah=2.0)
    filled = sd.colorization_baseline(image, sparse, mask, alpha=2.0)
    expected = sd.holes.colorization_fill(image, sparse, mask=mask, alpha=2.0)
    np.testing.assert_array_equal(filled, expected)


def test_solve_spd_refuses_a_misspelt_grid_option():
    A = sp.diags([4.0] * 16).tocsr()
    with pytest.raises(ValueError, match="unknown option 'sweepz' for preconditioner='grid'"):
        solve_spd(A, np.ones(16), (4, 4), sweepz=2)
    x, info = solve_spd(A, np.ones(16), (4, 4), sweeps=2)
    assert info.converged
    np.testing.assert_allclose(x, 0.25, rtol=1e-8)


def test_grid_options_are_exactly_the_keyword_options_of_the_hierarchy():
    keyword_only = {name for name, p in inspect.signature(GridMultigrid).parameters.items()
                    if p.kind is inspect.Parameter.KEYWORD_ONLY}
    assert set(GRID_OPTIONS) == keyword_only


@pytest.mark.parametrize("solver", sorted(sd.SOLVERS))
def test_complete_depth_refuses_a_misspelt_solver_option(solver):
    image, sparse, mask = small_frame()
    with pytest.raises(ValueError, match=f"unknown option 'toll' for solver '{solver}'"):
        sd.complete_depth(image, sparse, mask, solver=solver, options={"toll": 1e-3})
