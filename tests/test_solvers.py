import math

import numpy as np
import pytest
import scipy.sparse.linalg as spla

import sparsedepth as sd
from sparsedepth import Weights, build_objective, complete_depth

from sparsedepth.solvers.adam import window_means_stalled, step_size
from sparsedepth.solvers.options import AdamOptions

from conftest import make_problem

# the reference paper's four terms only (the default extension terms are off)
QUAD = Weights.paper(alpha=1.0, beta=0.5, gamma=0.0, delta=0.01, kappa=5.0)
L1 = Weights.paper(alpha=1.0, beta=0.2, gamma=0.05, delta=0.01, kappa=5.0)


@pytest.fixture(scope="module")
def problem():
    return make_problem((40, 50))


@pytest.fixture(scope="module")
def direct_reference(problem):
    image, sparse, mask, _ = problem
    obj, _, _ = build_objective(image, sparse, mask, weights=QUAD)
    A, b, _ = obj.normal_equations()
    z = spla.spsolve(A.tocsc(), b)  # independent of the solver code path
    return z.reshape(obj.shape), obj.value(z)


def test_direct_solves_normal_equations(problem, direct_reference):
    image, sparse, mask, _ = problem
    res = complete_depth(image, sparse, mask, weights=QUAD, solver="direct")
    z_ref, F_ref = direct_reference
    np.testing.assert_allclose(res.depth, z_ref, atol=1e-10)
    assert res.objective == pytest.approx(F_ref, rel=1e-12)
    # stationarity: gradient of F vanishes
    obj, _, _ = build_objective(image, sparse, mask, weights=QUAD)
    assert np.abs(obj.quadratic_gradient(res.depth)).max() < 1e-9


@pytest.mark.parametrize(
    "solver,rel", [("cg", 1e-6), ("amg", 1e-6), ("irls", 1e-6), ("admm", 1e-6), ("lbfgsb", 1e-3), ("adam", 1e-3)]
)
def test_solvers_agree_on_quadratic_problem(problem, direct_reference, solver, rel):
    image, sparse, mask, _ = problem
    res = complete_depth(image, sparse, mask, weights=QUAD, solver=solver)
    _, F_ref = direct_reference
    assert res.objective >= F_ref * (1 - 1e-12)
    assert (res.objective - F_ref) / F_ref <= rel, res.message
    assert res.depth.min() >= 0
    assert res.clamped == 0  # M-matrix with non-negative data: no clamping needed
    assert len(res.history) >= 2 and res.history[0].iteration == 0
    assert res.history[-1].objective == pytest.approx(res.objective, rel=1e-9)


def test_irls_and_lbfgsb_agree_with_l1(problem):
    image, sparse, mask, _ = problem
    irls = complete_depth(image, sparse, mask, weights=L1, solver="irls", tol=1e-8)
    # L-BFGS-B at tol 1e-8 ends within 4e-5 of the optimum here, well inside the 1e-4 compared
    lbfgsb = complete_depth(image, sparse, mask, weights=L1, solver="lbfgsb", l1_smoothing=1e-5, tol=1e-8)
    assert abs(irls.objective - lbfgsb.objective) / lbfgsb.objective < 1e-4
    admm = complete_depth(image, sparse, mask, weights=L1, solver="admm")
    assert abs(admm.objective - lbfgsb.objective) / lbfgsb.objective < 1e-4
    # ADMM (exact shrinkage + polish) is at least as good as IRLS's smoothed fixed point
    assert admm.objective <= irls.objective * (1 + 1e-7)
    # Newton's exact F may rise when eps shrinks: the point returned is the best one recorded
    F = irls.history_array("objective")
    assert irls.objective == pytest.approx(F.min(), rel=1e-12)
    # plain reweighting never raises the exact F and ends near the same optimum
    mm = complete_depth(image, sparse, mask, weights=L1, solver="irls", tol=1e-8, options={"method": "reweighting"})
    F = mm.history_array("objective")
    assert np.all(np.diff(F) <= 1e-12 * F[0]), "IRLS exact objective increased"
    assert abs(mm.objective - lbfgsb.objective) / lbfgsb.objective < 1e-4
    # the L1 term changes the solution: it differs from the gamma = 0 one
    quad = complete_depth(image, sparse, mask, weights=L1.replace(gamma=0), solver="direct")
    assert np.abs(quad.depth - irls.depth).max() > 1e-3
    # and IRLS beats the quadratic solution on the full objective
    obj, _, _ = build_objective(image, sparse, mask, weights=L1)
    assert irls.objective < obj.value(quad.depth)


def test_adam_with_l1_close_to_irls(problem):
    image, sparse, mask, _ = problem
    irls = complete_depth(image, sparse, mask, weights=L1, solver="irls")
    adam = complete_depth(image, sparse, mask, weights=L1, solver="adam", max_iter=5000, l1_smoothing=1e-4)
    assert (adam.objective - irls.objective) / irls.objective < 1e-2
    assert adam.depth.min() >= 0


def test_maximum_principle(problem):
    image, sparse, mask, _ = problem
    res = complete_depth(image, sparse, mask, weights=QUAD, solver="direct")
    coarse = sd.nearest_fill(sparse, mask)
    lo = min(np.nanmin(sparse), coarse.min())
    hi = max(np.nanmax(sparse), coarse.max())
    assert lo - 1e-12 <= res.depth.min() and res.depth.max() <= hi + 1e-12


def test_result_terms_sum_to_objective(problem):
    image, sparse, mask, _ = problem
    res = complete_depth(image, sparse, mask, weights=L1, solver="irls")
    assert sum(res.terms.values()) == pytest.approx(res.objective, rel=1e-12)
    assert set(res.terms) == {"data", "smooth", "edge", "prior", "smooth_image", "second_order", "second_order_image"}
    assert res.terms["edge"] > 0 and res.terms["smooth_image"] == 0


def test_default_weights_and_auto_solver(problem):
    image, sparse, mask, truth = problem
    res = complete_depth(image, sparse, mask)
    assert res.solver == sd.choose_solver(sd.DEFAULT_WEIGHTS)
    hidden = ~mask
    nn = sd.depth_metrics(sd.nearest_fill(sparse, mask), truth, mask=hidden)
    ours = sd.depth_metrics(res.depth, truth, mask=hidden)
    assert ours.rmse < nn.rmse


def test_callback_can_stop(problem):
    image, sparse, mask, _ = problem
    seen = []

    def cb(state):
        seen.append(state.iteration)
        assert state.depth.shape == (40, 50)
        if state.iteration == 3:
            raise StopIteration

    res = complete_depth(image, sparse, mask, weights=QUAD, solver="cg", callback=cb)
    assert not res.converged and "callback" in res.message
    assert seen == [0, 1, 2, 3] and res.iterations == 3  # set by the callback (CG needs far more here)


def test_history_times_increase(problem):
    image, sparse, mask, _ = problem
    res = complete_depth(image, sparse, mask, weights=QUAD, solver="lbfgsb")
    t = res.history_array("time")
    assert np.all(np.diff(t) >= 0)
    assert np.all(np.diff(res.history_array("function_evals")) >= 0)


def test_quadratic_only_solver_rejects_l1(problem):
    image, sparse, mask, _ = problem
    for solver in ("direct", "cg", "amg"):
        with pytest.raises(ValueError, match="gamma"):
            complete_depth(image, sparse, mask, weights=L1, solver=solver)


def test_unknown_solver(problem):
    image, sparse, mask, _ = problem
    with pytest.raises(ValueError, match="unknown solver"):
        complete_depth(image, sparse, mask, solver="newton")


def test_x0_changes_nothing_at_the_optimum(problem, direct_reference):
    image, sparse, mask, _ = problem
    res = complete_depth(image, sparse, mask, weights=QUAD, solver="amg", x0=np.ones((40, 50)), tol=1e-8)
    np.testing.assert_allclose(res.depth, direct_reference[0], atol=1e-6)


# ----------------------------------------------------------------------------- Adam's learning-rate schedules
@pytest.fixture(scope="module")
def optimum(problem):
    image, sparse, mask, _ = problem
    return complete_depth(image, sparse, mask, weights=L1, solver="admm", tol=1e-10, clip_to_observed=False).objective


def test_cosine_steps_by_hand():
    options = AdamOptions()
    assert options.schedule == "cosine"
    steps = [step_size(options, 2.0, k, 4) for k in range(1, 5)]
    expected = [2.0 * 0.5 * (1 + math.cos(math.pi * j / 4)) for j in range(4)]  # 2, 1.707, 1, 0.293
    np.testing.assert_allclose(steps, expected, rtol=1e-15)
    legacy = AdamOptions(schedule="inverse_sqrt", decay_steps=3.0)
    assert step_size(legacy, 2.0, 6, 4) == pytest.approx(2.0 / math.sqrt(3.0))


def test_adam_stop_compares_window_means_not_single_values():
    """An oscillation whose low points repeat is not a plateau; a flat or slowly falling tail is; a rise is not."""
    k = np.arange(200)
    falling = 100.0 - 1e-3 * k + np.where(k % 2 == 0, 1.0, -1.0)  # the mean falls 1e-3 per step
    means = (np.mean(falling[100:150]), np.mean(falling[150:]))
    assert means[0] - means[1] == pytest.approx(0.05)  # 5e-4 of the value
    assert window_means_stalled(list(falling), 50, tol=4e-4, floor=0.0) is None
    assert window_means_stalled(list(falling), 50, tol=6e-4, floor=0.0) == pytest.approx(means)
    assert window_means_stalled(list(falling), 50, tol=0.0, floor=0.06) == pytest.approx(means)  # the absolute floor
    bouncing = np.where(k % 50 == 49, 95.0, 100.0 - 1e-2 * k)  # falling, with equal low points 50 steps apart
    single = bouncing[-51] - bouncing[-1]
    assert 0 <= single <= 1e-7 * bouncing[-1]  # the single-value rule would read a plateau here ...
    assert window_means_stalled(list(bouncing), 50, tol=1e-7, floor=0.0) is None  # ... the window means do not
    flat = [7.0] * 100
    assert window_means_stalled(flat, 50, tol=0.0, floor=0.0) == (7.0, 7.0)
    assert window_means_stalled(flat[:99], 50, tol=1.0, floor=1.0) is None  # fewer than two windows
    rising = list(1.0 + 1e-9 * k)
    assert window_means_stalled(rising, 50, tol=1.0, floor=1.0) is None  # the objective went up: not converged


def test_cosine_adam_reaches_the_optimum_within_its_horizon(problem, optimum):
    image, sparse, mask, _ = problem
    result = complete_depth(image, sparse, mask, weights=L1, solver="adam", clip_to_observed=False,
                            options={"horizon": 300})
    assert result.iterations <= 300
    assert (result.objective - optimum) / optimum < 1e-3
    assert result.gap >= result.objective - optimum - 1e-9 * optimum  # the gap bounds the distance to F*
    assert result.depth.min() >= 0


def test_max_iter_shortens_the_cosine_horizon(problem):
    image, sparse, mask, _ = problem
    short = complete_depth(image, sparse, mask, weights=L1, solver="adam", max_iter=20, clip_to_observed=False)
    assert short.iterations <= 20
    start = complete_depth(image, sparse, mask, weights=L1, solver="adam", max_iter=1, clip_to_observed=False)
    assert short.objective < start.objective


def test_inverse_sqrt_schedule_still_descends(problem, optimum):
    image, sparse, mask, _ = problem
    result = complete_depth(image, sparse, mask, weights=L1, solver="adam", max_iter=400, clip_to_observed=False,
                            options={"schedule": "inverse_sqrt"})
    assert result.history[-1].objective < result.history[0].objective
    assert result.objective >= optimum * (1 - 1e-9)


@pytest.mark.parametrize("options, error", [
    ({"schedule": "linear"}, ValueError),
    ({"horizon": 0}, ValueError),
    ({"horizon": 2.5}, TypeError),
])
def test_bad_schedule_options(problem, options, error):
    image, sparse, mask, _ = problem
    with pytest.raises(error, match="adam"):
        complete_depth(image, sparse, mask, weights=L1, solver="adam", options=options)


def test_newton_system_matches_sparse_products(problem):
    """IRLS's stencil-filled Newton matrix equals A + ½ Kᵀ diag(d) K formed by sparse products."""
    import scipy.sparse as sp

    from sparsedepth.objective.l1 import StackedL1
    from sparsedepth.solvers.irls import _GradientSystem

    image, sparse, mask, _ = problem
    for weights in (L1, L1.replace(beta_second=0.01, beta_second_image=0.02)):
        obj, _, _ = build_objective(image, sparse, mask, weights=weights)
        l1 = StackedL1(obj)
        d = np.random.default_rng(3).uniform(0.0, 5.0, l1.rows)
        A, _, _ = obj.normal_equations()
        K = sp.csr_matrix(l1.matrix)
        expected = (A + 0.5 * (K.T @ sp.diags(d) @ K)).toarray()
        np.testing.assert_allclose(_GradientSystem(obj)(d).toarray(), expected, rtol=1e-12, atol=1e-12)
