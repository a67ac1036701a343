"""ADMM's nested iteration (``warm_start="coarse"``): the coarse problem, the transfers, and the same optimum."""

import numpy as np
import pytest
import scipy.sparse as sp

from sparsedepth import Weights, build_objective, complete_depth
from sparsedepth.grid.operators import gradient_stencil, hessian_stencil
from sparsedepth.grid.resample import block_sum, coarse_shape, upsample_edges
from sparsedepth.objective.coarsen import coarsen_objective, difference_order
from sparsedepth.objective.objective import Objective
from sparsedepth.objective.terms import AbsTerm, QuadraticTerm
from sparsedepth.solvers import check_solver_arguments

from conftest import make_problem

L1 = Weights.paper(alpha=1.0, beta=0.2, gamma=0.05, delta=0.01, kappa=5.0)
#: Forces the nesting on small test grids: every grid above 500 pixels starts from the coarser one.
NESTED = {"warm_start": "coarse", "coarse_above": 500}


@pytest.mark.parametrize("shape", [(6, 8), (7, 9), (5, 5)])
def test_block_sum_equals_a_loop_over_the_blocks_with_partial_ones(shape):
    values = np.random.default_rng(1).random(shape)
    h, w = coarse_shape(shape, 2)
    expected = np.array([[values[2 * i:2 * i + 2, 2 * j:2 * j + 2].sum() for j in range(w)] for i in range(h)])
    np.testing.assert_allclose(block_sum(values, 2), expected, rtol=1e-14)


@pytest.mark.parametrize("axis", [0, 1])
def test_upsample_edges_puts_coarse_edges_between_the_blocks_and_averages_inside(axis):
    """Along the axis: fine edge 2j+1 (between blocks j and j+1) is coarse edge j, fine edge 2j the mean of j-1, j."""
    rng = np.random.default_rng(2)
    coarse = rng.random((5, 6)) if axis == 1 else rng.random((6, 5))
    shape = (10, 12) if axis == 1 else (12, 10)
    fine = upsample_edges(coarse, shape, 2, axis)
    # across the axis, fine line 5 lies 1/4 of the way from block centre 2 (fine 4.5) to block centre 3 (fine 6.5)
    line = 0.75 * np.moveaxis(coarse, axis, -1)[2] + 0.25 * np.moveaxis(coarse, axis, -1)[3]
    got = np.moveaxis(fine, axis, -1)[5]
    for j in range(line.size - 1):
        assert got[2 * j + 1] == pytest.approx(line[j], rel=1e-14)
        assert got[2 * j + 2] == pytest.approx(0.5 * (line[j] + line[j + 1]), rel=1e-14)
    assert got[0] == pytest.approx(line[0], rel=1e-14)  # before the first coarse edge: its value


def test_upsample_edges_rejects_a_wrong_shape():
    with pytest.raises(ValueError, match="needs"):
        upsample_edges(np.zeros((3, 3)), (8, 8), 2, 1)


def test_upsample_edges_rejects_a_wrong_axis():
    with pytest.raises(ValueError, match="axis"):
        upsample_edges(np.zeros((4, 4)), (8, 8), 2, 2)


def test_difference_order_of_the_grid_operators():
    assert [difference_order(b) for b in gradient_stencil((4, 4)).blocks] == [1, 1]
    assert [difference_order(b) for b in hessian_stencil((4, 4)).blocks] == [2, 2, 2]
    assert difference_order((((0, 0), 2.0),)) == 0


def test_coarse_data_term_differs_from_the_fine_one_by_a_constant_on_block_constant_maps():
    """Σ_B r (z − d)² = r_B (z_B − d_B)² + const for z constant on each block: order 0 is exact."""
    rng = np.random.default_rng(3)
    shape = (7, 10)  # partial blocks in the last row
    mask = rng.random(shape) < 0.4
    depth = rng.random(shape) + 1.0
    fine = Objective(shape, [QuadraticTerm("data", 1.5, None, mask.ravel(), depth.ravel()),
                             QuadraticTerm("prior", 0.1, None, None, depth.ravel()),
                             AbsTerm("edge", 0.1, gradient_stencil(shape))])
    coarse = coarsen_objective(fine)
    assert coarse.shape == coarse_shape(shape, 2)
    differences = []
    for seed in range(3):
        z_coarse = np.random.default_rng(10 + seed).random(coarse.shape) * 3.0
        z_fine = np.repeat(np.repeat(z_coarse, 2, axis=0), 2, axis=1)[:shape[0], :shape[1]]
        fine_values = [fine.term(name).value(z_fine.ravel()) for name in ("data", "prior")]
        coarse_values = [coarse.term(name).value(z_coarse.ravel()) for name in ("data", "prior")]
        differences.append(np.subtract(fine_values, coarse_values))
    np.testing.assert_allclose(differences[1], differences[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(differences[2], differences[0], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", ["smooth", "edge", "second_order"])
def test_coarse_terms_of_a_smooth_map_converge_to_the_fine_ones(name):
    """For a smooth map, coarse(block means) / fine → 1 as the grid is refined (error about halves per doubling)."""

    def relative_error(n):
        shape = (n, n + n // 2)
        ii, jj = np.mgrid[0:shape[0], 0:shape[1]] / n
        z = 1.0 + np.sin(2.0 * ii) + 0.5 * jj ** 2  # in units where the grid spans [0, 1]
        weights = 1.0 + 0.5 * np.cos(3.0 * ii + jj)  # smooth, positive row weights
        op = hessian_stencil(shape) if name == "second_order" else gradient_stencil(shape)
        if name == "edge":
            term = AbsTerm(name, 0.3, op, weights.ravel())
        else:
            term = QuadraticTerm(name, 0.3, op, np.tile(weights.ravel(), len(op.blocks)))
        fine = Objective(shape, [QuadraticTerm("data", 1.0, None, None, z.ravel()), term])
        coarse = coarsen_objective(fine)
        z_coarse = block_sum(z, 2) / block_sum(np.ones(shape), 2)
        return abs(coarse.term(name).value(z_coarse.ravel()) / fine.term(name).value(z.ravel()) - 1.0)

    errors = [relative_error(n) for n in (32, 64, 128)]
    assert errors[2] < 0.05, errors
    assert errors[2] < 0.7 * errors[0], errors


def test_coarsen_leaves_out_a_general_quadratic_term_and_refuses_a_general_l1_one():
    shape = (6, 8)
    n = shape[0] * shape[1]
    general = sp.identity(n, format="csr")
    base = [QuadraticTerm("data", 1.0, None, None, np.ones(n)), AbsTerm("edge", 0.1, gradient_stencil(shape))]
    coarse = coarsen_objective(Objective(shape, base + [QuadraticTerm("other", 1.0, general)]))
    assert [t.name for t in coarse.terms] == ["data", "edge"]
    assert coarsen_objective(Objective(shape, [base[0], AbsTerm("edge", 0.1, general)])) is None


def test_warm_start_options_are_checked():
    assert check_solver_arguments("admm", options={"warm_start": "coarse"})[2]["warm_start"] == "coarse"
    with pytest.raises(ValueError, match="warm_start"):
        check_solver_arguments("admm", options={"warm_start": "coarser"})


@pytest.mark.parametrize("shape", [(48, 64), (45, 61)])
def test_nested_admm_reaches_the_optimum_of_a_tight_cold_solve(shape):
    """Started from two coarser grids, ADMM stops at the optimum a 100x tighter cold run certifies."""
    image, sparse, mask, _ = make_problem(shape, fraction=0.08)
    nested = complete_depth(image, sparse, mask, weights=L1, solver="admm", options=NESTED, clip_to_observed=False)
    tight = complete_depth(image, sparse, mask, weights=L1, solver="admm", clip_to_observed=False,
                           options={"gap_tol": 1e-8, "check_rtol": 2e-9})
    assert nested.converged and tight.converged, (nested.message, tight.message)
    assert "started from the solution on the" in nested.message
    assert nested.message.count("started from the solution") == 2  # 48x64 -> 24x32 -> 12x16
    # F* lies in [F_tight − gap_tight, F_tight]; the nested F is above F* by at most its own gap
    assert nested.objective - tight.objective <= nested.gap + 1e-12 * tight.objective
    assert tight.objective - nested.objective <= tight.gap + 1e-12 * tight.objective
    assert nested.gap <= 1e-6 * nested.objective


def test_nested_admm_on_a_real_frame_matches_the_cold_solve_within_the_certified_gaps(shared_data):
    from sparsedepth import load_shared_frame, sample_depth

    frame = load_shared_frame("nyu_mmseg_pseudo/bookstore_0001d_00001")
    sparse, mask = sample_depth(np.array(frame.depth), fraction=0.05, seed=0)
    runs = [complete_depth(frame.image, sparse, mask, weights=L1, solver="admm", clip_to_observed=False,
                           options=options) for options in ({}, NESTED)]
    cold, nested = runs
    assert cold.converged and nested.converged, (cold.message, nested.message)
    assert "started from the solution on the" in nested.message
    assert abs(nested.objective - cold.objective) <= cold.gap + nested.gap


@pytest.mark.parametrize("options", [{"restart_from_polish": True}, dict(NESTED, restart_from_polish=True)])
def test_admm_restarted_from_its_polishes_reaches_the_optimum_of_a_tight_cold_solve(options):
    image, sparse, mask, _ = make_problem((48, 64), fraction=0.08)
    weights = Weights.paper(alpha=1.0, beta=0.2, gamma=0.2, delta=0.01, kappa=5.0)  # many ties
    run = complete_depth(image, sparse, mask, weights=weights, solver="admm", options=options,
                         clip_to_observed=False)
    tight = complete_depth(image, sparse, mask, weights=weights, solver="admm", clip_to_observed=False,
                           options={"gap_tol": 1e-8, "check_rtol": 2e-9})
    assert run.converged and tight.converged, (run.message, tight.message)
    assert run.objective - tight.objective <= run.gap + 1e-12 * tight.objective
    assert tight.objective - run.objective <= tight.gap + 1e-12 * tight.objective
