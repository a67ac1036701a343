"""Robust edge penalties: the penalty family, the robust term, IRLS descent and exactness, refusals."""

import dataclasses
import math
import warnings

import numpy as np
import pytest
import scipy.sparse as sp

import sparsedepth as sd
from sparsedepth import Weights, build_objective, complete_depth
from sparsedepth.objective import Objective, QuadraticTerm, RobustPenalty, RobustTerm, robust_penalty
from sparsedepth.grid.operators import gradient_stencil
from sparsedepth.objective.weights import LOCAL_LINEAR_FIELDS, MODEL_FIELDS
from sparsedepth.solvers import scaled_objective, solve

from conftest import make_problem

NAMES = ["charbonnier", "cauchy", "geman_mcclure", "welsch"]
SHAPES = [2.0, 1.5, 1.0, 0.5, 0.0, -0.5, -2.0, -5.0, -np.inf]


def _penalties():
    return [robust_penalty(n) for n in NAMES] + [RobustPenalty(a) for a in SHAPES]


# ----------------------------------------------------------------------------- the penalty family
@pytest.mark.parametrize("penalty", _penalties(), ids=lambda p: p.name)
@pytest.mark.parametrize("scale", [0.05, 1.0, 7.0])
def test_derivative_and_weight_match_finite_differences(penalty, scale):
    rng = np.random.default_rng(0)
    t = scale * rng.uniform(-6, 6, 200)
    h = 1e-6 * scale
    fd = (penalty.value(t + h, scale) - penalty.value(t - h, scale)) / (2 * h)
    d = penalty.derivative(t, scale)
    np.testing.assert_allclose(d, fd, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(penalty.weight(t, scale) * t, d, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("penalty", _penalties(), ids=lambda p: p.name)
def test_value_is_quadratic_near_zero_with_weight_one_over_scale(penalty):
    s = 0.3
    t = np.array([1e-4, -3e-4, 5e-5])
    np.testing.assert_allclose(penalty.value(t, s), t * t / (2 * s), rtol=1e-5)
    assert penalty.value(0.0, s) == 0.0
    assert penalty.weight(0.0, s) == pytest.approx(1 / s, rel=1e-15)  # the finite limit, no 0/0


@pytest.mark.parametrize("penalty", _penalties(), ids=lambda p: p.name)
def test_majoriser_lies_above_the_penalty_and_touches_it(penalty):
    rng = np.random.default_rng(1)
    s = 0.05
    t = s * rng.standard_normal(4000) * rng.choice([0.1, 1, 10, 100], 4000)
    t0 = s * rng.standard_normal(4000) * rng.choice([0.1, 1, 10, 100], 4000)
    t0[:500] = 0.0  # the tangent at 0 (weight 1/s) too
    phi, phi0, w0 = penalty.value(t, s), penalty.value(t0, s), penalty.weight(t0, s)
    bound = phi0 + 0.5 * w0 * (t * t - t0 * t0)
    slack = 1e-12 * (phi + phi0 + 0.5 * w0 * (t * t + t0 * t0) + s)  # rounding of the sum
    assert np.all(phi <= bound + slack)
    # equality at t = ±t0
    np.testing.assert_allclose(penalty.value(-t0, s), phi0, rtol=1e-14, atol=0)


def test_barron_special_cases_match_their_closed_forms():
    x = np.linspace(-30, 30, 601)
    general = lambda a: RobustPenalty(a).rho(x)  # noqa: E731
    # the named members by their own formulas (Barron 2019, eqs. 3-10)
    np.testing.assert_allclose(robust_penalty("charbonnier").rho(x), np.sqrt(x**2 + 1) - 1, rtol=1e-14)
    np.testing.assert_allclose(robust_penalty("cauchy").rho(x), np.log(0.5 * x**2 + 1), rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(robust_penalty("geman_mcclure").rho(x), 2 * x**2 / (x**2 + 4), rtol=1e-14)
    np.testing.assert_allclose(robust_penalty("welsch").rho(x), 1 - np.exp(-0.5 * x**2), rtol=1e-14, atol=1e-300)
    np.testing.assert_allclose(general(2.0), 0.5 * x**2, rtol=1e-14)
    # the general formula near each special shape approaches it (limits a -> 0, a -> -inf, a -> 2, a = 1, -2)
    np.testing.assert_allclose(general(1e-7), np.log(0.5 * x**2 + 1), rtol=1e-5, atol=1e-12)
    np.testing.assert_allclose(general(-1e7), 1 - np.exp(-0.5 * x**2), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(general(2 - 1e-7), 0.5 * x**2, rtol=1e-4, atol=1e-12)
    np.testing.assert_allclose(general(1 + 1e-9), np.sqrt(x**2 + 1) - 1, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(general(-2 - 1e-9), 2 * x**2 / (x**2 + 4), rtol=1e-6, atol=1e-12)


def test_charbonnier_is_like_l1_far_from_zero_and_the_bounded_ones_saturate():
    s = 0.05
    t = np.array([5.0, -20.0])
    np.testing.assert_allclose(robust_penalty("charbonnier").value(t, s), np.abs(t) - s, rtol=1e-4)
    assert robust_penalty("welsch").value(1e3, s) == pytest.approx(s)  # s · ρ(∞) = s
    assert robust_penalty("geman_mcclure").value(1e3, s) == pytest.approx(2 * s)


@pytest.mark.parametrize("bad, error", [(2.5, ValueError), (np.nan, ValueError), ("huber", ValueError),
                                        (None, TypeError), (True, TypeError)])
def test_robust_penalty_rejects_bad_shapes_and_names(bad, error):
    with pytest.raises(error, match="penalty|shape"):
        robust_penalty(bad)


# ----------------------------------------------------------------------------- the term
def _robust_objective(shape=(6, 7), penalty="cauchy", seed=0):
    rng = np.random.default_rng(seed)
    n = shape[0] * shape[1]
    G = gradient_stencil(shape)
    r = rng.uniform(0.1, 1.0, n)  # shared by the two blocks
    term = RobustTerm("edge", 0.7, G, r, penalty, 0.2)
    data = QuadraticTerm("data", 1.0, None, rng.random(n) < 0.3, rng.uniform(1, 3, n))
    return Objective(shape, [data, term]), term, rng


@pytest.mark.parametrize("penalty", NAMES)
def test_robust_term_value_gradient_and_majoriser_against_direct_formulas(penalty):
    obj, term, rng = _robust_objective(penalty=penalty)
    z = rng.uniform(1, 3, obj.size)
    Gx = sp.csr_matrix(gradient_stencil(obj.shape).tocsr())
    t = Gx @ z
    c = 0.7 * np.tile(term.row_weights, 2)
    p = robust_penalty(penalty)
    assert term.value(z) == pytest.approx(float(np.sum(c * 0.2 * p.rho(t / 0.2))), rel=1e-13)
    np.testing.assert_allclose(term.majorizer_weights(z), c * p.weight(t, 0.2), rtol=1e-13)
    # gradient against central differences of the value
    h = 1e-6
    fd = np.array([(term.value(z + h * e) - term.value(z - h * e)) / (2 * h) for e in np.eye(obj.size)])
    np.testing.assert_allclose(term.gradient(z), fd, rtol=1e-6, atol=1e-8)
    # the objective: exact value in value / term_values, and in the smoothed value and gradient (it is smooth)
    v, g = obj.smoothed_value_and_gradient(z)
    assert obj.term_values(z)["edge"] == pytest.approx(term.value(z), rel=1e-14)
    assert v == pytest.approx(obj.value(z), rel=1e-13)
    np.testing.assert_allclose(g, obj.quadratic_gradient(z) + term.gradient(z), rtol=1e-13)
    assert obj.robust_terms == (term,) and not obj.has_l1


def test_robust_term_rejects_bad_scale_and_row_weights():
    G = gradient_stencil((4, 5))
    with pytest.raises(ValueError, match="scale"):
        RobustTerm("edge", 1.0, G, None, "cauchy", 0.0)
    with pytest.raises(ValueError, match="row_weights"):
        RobustTerm("edge", 1.0, G, np.ones(7), "cauchy", 0.1)


def test_scaled_objective_divides_robust_weight_and_scale():
    obj, _, rng = _robust_objective()
    z = rng.uniform(1, 3, obj.size)
    s = 4.0
    # F_s(z / s) = F(z) / s² (same identity as for the L1 and quadratic terms)
    assert scaled_objective(obj, s).value(z / s) == pytest.approx(obj.value(z) / s**2, rel=1e-12)


# ----------------------------------------------------------------------------- weights
def test_weights_build_an_abs_or_a_robust_edge_term():
    image, sparse, mask, _ = make_problem((20, 25))
    base = Weights.paper(gamma=0.05)
    obj_l1, _, _ = build_objective(image, sparse, mask, weights=base)
    obj_r, _, _ = build_objective(image, sparse, mask, weights=base.replace(edge_penalty="welsch", edge_scale=0.1))
    l1, robust = obj_l1.term("edge"), obj_r.term("edge")
    assert isinstance(l1, sd.AbsTerm) and isinstance(robust, RobustTerm)
    assert robust.penalty.shape == -np.inf and robust.scale == 0.1 and robust.weight == 0.05
    np.testing.assert_array_equal(robust.row_weights, l1.row_weights)  # the same image-edge weights


@pytest.mark.parametrize("changes, error, match", [
    (dict(edge_penalty="huber"), ValueError, "charbonnier"),
    (dict(edge_penalty="L1"), ValueError, "l1"),
    (dict(edge_penalty=1.0), TypeError, "edge_penalty"),
    (dict(edge_penalty=None), TypeError, "edge_penalty"),
    (dict(edge_scale=0.0), ValueError, "edge_scale"),
    (dict(edge_scale=-0.1), ValueError, "edge_scale"),
    (dict(edge_scale=np.nan), ValueError, "edge_scale"),
    (dict(edge_scale=np.inf), ValueError, "edge_scale"),
])
def test_bad_edge_penalty_weights_are_refused(changes, error, match):
    with pytest.raises(error, match=match):
        Weights(**changes)


def test_weights_with_a_penalty_round_trip_through_as_dict():
    w = Weights(gamma=0.02, edge_penalty="cauchy", edge_scale=0.1)
    assert Weights(**w.as_dict()) == w
    assert w.replace(edge_penalty="l1") == Weights(gamma=0.02, edge_scale=0.1)
    assert sd.DEFAULT_WEIGHTS.edge_penalty == "l1"  # the defaults keep the L1 edge term


# ----------------------------------------------------------------------------- solving
def _step_scene(shape=(40, 50)):
    """Two flat regions (2 m and 3 m, a rectangle) whose depth steps exactly at the image edge."""
    H, W = shape
    inside = np.zeros(shape, bool)
    inside[10:30, 18:38] = True
    image = np.where(inside[..., None], 0.8, 0.2) * np.ones(3)
    truth = np.where(inside, 3.0, 2.0)
    sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=0)
    return image, sparse, mask, truth


EDGE_ONLY = Weights.paper(alpha=1.0, beta=0.0, gamma=0.1, delta=0.0, kappa=10.0)


@pytest.mark.parametrize("penalty", NAMES)
def test_piecewise_constant_scene_is_recovered_exactly_without_staircase(penalty):
    image, sparse, mask, truth = _step_scene()
    x0 = None
    if penalty == "welsch":
        # bounded penalty: from the nearest fill, Voronoi cells of the wrong region are (numerically) stationary;
        # start from the convex Charbonnier solution instead
        x0 = complete_depth(image, sparse, mask, weights=EDGE_ONLY.replace(edge_penalty="charbonnier")).depth
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        res = complete_depth(image, sparse, mask, weights=EDGE_ONLY.replace(edge_penalty=penalty), x0=x0)
    assert res.solver == "irls"
    np.testing.assert_allclose(res.depth, truth, rtol=1e-3)
    # the jump is one pixel wide: no value strictly between the two levels
    assert not np.any((res.depth > 2.01) & (res.depth < 2.99))


def test_l2_smoothing_misses_the_piecewise_constant_scene():
    # the same scene and samples with quadratic smoothness instead: the exactness test above can fail
    image, sparse, mask, truth = _step_scene()
    res = complete_depth(image, sparse, mask, weights=Weights.paper(alpha=1.0, beta=0.1, gamma=0.0, delta=0.0))
    assert np.max(np.abs(res.depth - truth)) > 0.1
    assert np.count_nonzero((res.depth > 2.01) & (res.depth < 2.99)) > 50  # a ramp, not a step


@pytest.fixture(scope="module")
def motorcycle_crop():
    frame = sd.load_motorcycle()
    image = np.asarray(frame.image)[200:240, 300:350]
    depth = np.asarray(frame.depth)[200:240, 300:350]
    sparse, mask = sd.sample_depth(depth, fraction=0.05, seed=3)
    return image, sparse, mask


@pytest.mark.parametrize("penalty", NAMES)
def test_irls_never_increases_the_objective_on_a_real_image(motorcycle_crop, penalty):
    image, sparse, mask = motorcycle_crop
    w = sd.DEFAULT_WEIGHTS.replace(gamma=0.05, edge_penalty=penalty, edge_scale=0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        res = complete_depth(image, sparse, mask, weights=w, clip_to_observed=False)
    F = np.array([h.objective for h in res.history])
    assert len(F) >= 4  # several majorise-minimise steps, so the test can see an increase
    assert np.all(np.diff(F) <= 0), np.diff(F).max()
    assert F[-1] < F[0]
    # the recorded values are the exact objective of the iterates: the last one is the result's
    assert res.objective == pytest.approx(F[-1], rel=1e-9)
    assert res.converged and math.isnan(res.gap)
    assert "no duality gap" in res.message and "NOT" not in res.message and "failed" not in res.message


@pytest.mark.parametrize("penalty", NAMES)
def test_irls_and_lbfgsb_reach_the_same_objective_from_the_l2_solution(penalty):
    image, sparse, mask, _ = make_problem((40, 50))
    base = Weights.paper(alpha=1.0, beta=0.05, gamma=0.0, delta=0.01, kappa=5.0)
    start = complete_depth(image, sparse, mask, weights=base, solver="direct").depth
    w = base.replace(gamma=0.05, edge_penalty=penalty, edge_scale=0.1)
    F = {}
    for solver in ("irls", "lbfgsb"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sd.ClampWarning)
            res = complete_depth(image, sparse, mask, weights=w, solver=solver, x0=start, clip_to_observed=False)
        F[solver] = res.objective
        assert res.objective < build_objective(image, sparse, mask, weights=w)[0].value(start)
    # measured 6e-9 to 3e-8 relative; the bound leaves a factor 30
    assert abs(F["irls"] - F["lbfgsb"]) <= 1e-6 * F["lbfgsb"], F


def test_auto_picks_irls_for_a_robust_edge_penalty():
    assert sd.choose_solver(Weights(gamma=0.1, edge_penalty="cauchy")) == "irls"
    assert sd.choose_solver(Weights(gamma=0.1)) == "admm"
    assert sd.choose_solver(Weights(gamma=0.0, edge_penalty="cauchy")) == "amg"  # no edge term at all


@pytest.mark.parametrize("solver", ["admm", "direct", "cg", "amg"])
def test_convex_only_solvers_refuse_a_robust_term(solver):
    image, sparse, mask, _ = make_problem((20, 25))
    w = Weights.paper(gamma=0.05).replace(edge_penalty="cauchy")
    with pytest.raises(ValueError, match=r"robust.*'edge'.*solver='irls'"):
        complete_depth(image, sparse, mask, weights=w, solver=solver)
    obj, coarse, _ = build_objective(image, sparse, mask, weights=w)
    with pytest.raises(ValueError, match="solver='irls'"):
        solve(obj, coarse.ravel(), solver=solver)


def test_solver_entry_points_refuse_a_robust_term_when_called_directly():
    from sparsedepth.solvers.admm import solve_admm
    from sparsedepth.solvers.common import Recorder
    from sparsedepth.solvers.options import AdmmOptions, DirectOptions
    from sparsedepth.solvers.quadratic import solve_direct

    image, sparse, mask, _ = make_problem((20, 25))
    w = Weights.paper(gamma=0.05).replace(edge_penalty="welsch")
    obj, coarse, _ = build_objective(image, sparse, mask, weights=w)
    for fn, options in ((solve_admm, AdmmOptions()), (solve_direct, DirectOptions())):
        with pytest.raises(ValueError, match="'edge'"):
            fn(obj, coarse.ravel(), tol=1e-6, max_iter=10, recorder=Recorder(obj, None), options=options)


def test_robust_completion_does_not_depend_on_the_depth_unit():
    image, sparse, mask, _ = make_problem((30, 40))
    w = Weights.paper(alpha=1.0, beta=0.05, gamma=0.05, delta=0.01).replace(edge_penalty="cauchy", edge_scale=0.1)
    metres = complete_depth(image, sparse, mask, weights=w)
    # a unit 1024 times smaller: gamma and edge_scale are in depth units and scale with it (the quadratic weights
    # do not); a power of two gives the same normalised problem, so the same answer to rounding
    small = complete_depth(image, sparse * 1024, mask, weights=w.replace(gamma=0.05 * 1024, edge_scale=0.1 * 1024))
    np.testing.assert_allclose(small.depth, 1024 * metres.depth, rtol=1e-12)
    assert small.objective == pytest.approx(1024**2 * metres.objective, rel=1e-12)


# ----------------------------------------------------------------------------- where Weights is serialised
def test_batch_settings_fingerprint_keeps_the_edge_penalty():
    from sparsedepth.batch import BatchOptions
    from sparsedepth.batch.csvlog import fingerprint, settings_difference

    robust = BatchOptions(keep_fraction=0.05, weights=Weights(gamma=0.01, edge_penalty="cauchy", edge_scale=0.1))
    stored = fingerprint([], robust)
    assert stored["options"]["weights"]["edge_penalty"] == "cauchy"
    assert Weights(**stored["options"]["weights"]) == robust.weights  # the JSON gives the weights back
    other = BatchOptions(keep_fraction=0.05, weights=robust.weights.replace(edge_penalty="welsch"))
    assert settings_difference(stored, fingerprint([], other)) == "options weights"
    assert settings_difference(stored, fingerprint([], robust)) == ""


def test_batch_settings_of_an_l1_batch_match_files_without_the_edge_penalty_fields():
    """An L1 batch's fingerprint leaves out edge_penalty / edge_scale: a settings file without them still resumes."""
    from sparsedepth.batch import BatchOptions
    from sparsedepth.batch.csvlog import fingerprint, settings_difference

    # the objective of the files written before the modelling fields and the local-linear terms
    off = dict.fromkeys((*MODEL_FIELDS, *LOCAL_LINEAR_FIELDS), 0.0)
    current = fingerprint([], BatchOptions(keep_fraction=0.05, weights=Weights(gamma=0.01, **off)))
    assert "edge_penalty" not in current["options"]["weights"] and "edge_scale" not in current["options"]["weights"]
    stored = {**current, "options": {**current["options"], "weights": {
        k: v for k, v in dataclasses.asdict(Weights(gamma=0.01)).items()
        if k not in ("edge_penalty", "edge_scale", *LOCAL_LINEAR_FIELDS, *MODEL_FIELDS)}}}
    assert settings_difference(stored, current) == ""
    changed = fingerprint([], BatchOptions(keep_fraction=0.05, weights=Weights(gamma=0.02, **off)))
    assert settings_difference(stored, changed) == "options weights"


def test_bench_reports_and_ablation_accept_a_robust_edge_penalty():
    from bench import ablation
    from bench.harness import weights_markdown

    robust = Weights(gamma=0.01, edge_penalty="welsch", edge_scale=0.1)
    text = weights_markdown(robust)
    assert "edge_penalty = welsch" in text and "edge_scale = 0.1" in text and "gamma = 0.01" in text
    default_text = weights_markdown(sd.DEFAULT_WEIGHTS)  # the l1 default reads as before
    assert "edge_penalty" not in default_text and "edge_scale" not in default_text
    labels = [label for label, _ in ablation.variants(D=robust)]
    assert labels[-1] == "defaults (sd.DEFAULT_WEIGHTS)"
    assert dict(ablation.variants(D=robust))["defaults (sd.DEFAULT_WEIGHTS)"] == robust


def test_bench_edge_method_is_complete_depth_with_weights_relative_to_the_median():
    from bench import robust_penalties as bench

    image, sparse, mask, _ = make_problem((20, 25))
    m = float(np.median(sparse[mask]))
    got = bench.edge_method("cauchy", 0.03).run(image, sparse, mask)
    w = sd.DEFAULT_WEIGHTS.replace(gamma=bench.GAMMA_REL * m, edge_penalty="cauchy", edge_scale=0.03 * m)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        expected = complete_depth(image, sparse, mask, weights=w)
    assert got.weights == w and got.solver == "irls"
    np.testing.assert_array_equal(got.depth, expected.depth)
