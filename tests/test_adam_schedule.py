"""Adam's learning-rate schedules: the cosine decay by hand, its horizon, and the result against ADMM's optimum."""

import math

import numpy as np
import pytest

from sparsedepth import Weights, complete_depth
from sparsedepth.solvers.adam import _step_size
from sparsedepth.solvers.options import AdamOptions

from conftest import make_problem

L1 = Weights.paper(alpha=1.0, beta=0.2, gamma=0.05, delta=0.01, kappa=5.0)


@pytest.fixture(scope="module")
def problem():
    return make_problem((40, 50))


@pytest.fixture(scope="module")
def optimum(problem):
    image, sparse, mask, _ = problem
    return complete_depth(image, sparse, mask, weights=L1, solver="admm", tol=1e-10, clip_to_observed=False).objective


def test_cosine_steps_by_hand():
    options = AdamOptions()
    assert options.schedule == "cosine"
    steps = [_step_size(options, 2.0, k, 4) for k in range(1, 5)]
    expected = [2.0 * 0.5 * (1 + math.cos(math.pi * j / 4)) for j in range(4)]  # 2, 1.707, 1, 0.293
    np.testing.assert_allclose(steps, expected, rtol=1e-15)
    legacy = AdamOptions(schedule="inverse_sqrt", decay_steps=3.0)
    assert _step_size(legacy, 2.0, 6, 4) == pytest.approx(2.0 / math.sqrt(3.0))


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
