"""DensitySchedule: log-density interpolation of weights, checked against hand computations."""

import math

import pytest

import sparsedepth as sd
from sparsedepth.objective.weights import DENSITY_FIELDS, OPTIONAL_DENSITY_FIELDS


def _schedule():
    low = sd.DEFAULT_WEIGHTS.replace(delta=1e-4, kappa=10.0, beta_local_linear=0.0)
    high = sd.DEFAULT_WEIGHTS.replace(delta=1e-2, kappa=40.0, beta_local_linear=0.02)
    return sd.DensitySchedule.from_weights(((0.01, low), (0.1, high)))


def test_anchor_values_are_returned_at_and_beyond_the_anchors():
    schedule = _schedule()
    assert schedule.weights(0.01).delta == 1e-4
    assert schedule.weights(0.001).delta == 1e-4
    assert schedule.weights(0.1).kappa == 40.0
    assert schedule.weights(1.0).kappa == 40.0


def test_interpolation_is_geometric_in_log_density_and_linear_through_zero():
    schedule = _schedule()
    f = 0.01 * 10 ** 0.25  # a quarter of the way in log-density
    w = schedule.weights(f)
    assert w.delta == pytest.approx(1e-4 * (1e-2 / 1e-4) ** 0.25, rel=1e-12)
    assert w.kappa == pytest.approx(math.exp(0.75 * math.log(10.0) + 0.25 * math.log(40.0)), rel=1e-12)
    assert w.beta_local_linear == pytest.approx(0.25 * 0.02, rel=1e-12)


def test_fields_outside_the_schedule_come_from_the_base():
    base = sd.DEFAULT_WEIGHTS.replace(gamma=0.3, edge_sigma=2.0)
    schedule = sd.DensitySchedule(_schedule().anchors, base)
    w = schedule.weights(0.03)
    assert (w.gamma, w.edge_sigma, w.alpha) == (0.3, 2.0, base.alpha)


def test_the_default_schedule_gives_every_density_field():
    for fraction in (0.002, 0.01, 0.03, 0.07, 0.5):
        w = sd.default_weights(fraction)
        assert isinstance(w, sd.Weights)
        for name in DENSITY_FIELDS:
            values = [values[name] for _, values in sd.DEFAULT_SCHEDULE.anchors]
            assert min(values) <= getattr(w, name) <= max(values)


@pytest.mark.parametrize("fraction, error", [(0.0, ValueError), (1.5, ValueError), (-0.1, ValueError),
                                             (float("nan"), ValueError), ("0.1", TypeError)])
def test_bad_fractions_are_rejected(fraction, error):
    with pytest.raises(error):
        sd.default_weights(fraction)


def test_bad_anchors_are_rejected():
    values = {name: getattr(sd.DEFAULT_WEIGHTS, name) for name in DENSITY_FIELDS}
    with pytest.raises(ValueError, match="at least one"):
        sd.DensitySchedule(())
    with pytest.raises(ValueError, match="increase"):
        sd.DensitySchedule(((0.1, values), (0.05, values)))
    with pytest.raises(ValueError, match="fields"):
        sd.DensitySchedule(((0.1, dict(values, gamma=1.0)),))
    with pytest.raises(ValueError):
        sd.DensitySchedule(((0.1, dict(values, delta=-1.0)),))
    with pytest.raises(TypeError):
        sd.DensitySchedule(((0.1, values),), base={"alpha": 1.0})


def test_an_interior_anchor_gives_its_own_values_exactly():
    low = sd.DEFAULT_WEIGHTS.replace(kappa=50.0, delta=1e-4)
    mid = sd.DEFAULT_WEIGHTS.replace(kappa=50.0, delta=3e-4)
    high = sd.DEFAULT_WEIGHTS.replace(kappa=100.0, delta=1e-3)
    schedule = sd.DensitySchedule.from_weights(((0.003, low), (0.01, mid), (0.05, high)))
    w = schedule.weights(0.01)
    assert (w.kappa, w.delta) == (50.0, 3e-4)
    for fraction, values in schedule.anchors:
        assert {name: getattr(schedule.weights(fraction), name) for name in DENSITY_FIELDS} == values


def test_the_window_weights_are_scheduled_at_every_anchor_or_come_from_the_base():
    values = {name: getattr(sd.DEFAULT_WEIGHTS, name) for name in DENSITY_FIELDS}
    scheduled = sd.DensitySchedule(((0.01, dict(values, beta_local_linear_cross=0.004, beta_local_linear_2x2=0.0)),
                                    (0.1, dict(values, beta_local_linear_cross=0.001, beta_local_linear_2x2=0.002))))
    assert scheduled.scheduled == DENSITY_FIELDS + OPTIONAL_DENSITY_FIELDS
    w = scheduled.weights(0.01 * 10 ** 0.5)  # half way in log-density
    assert w.beta_local_linear_cross == pytest.approx(math.sqrt(0.004 * 0.001), rel=1e-12)
    assert w.beta_local_linear_2x2 == pytest.approx(0.5 * 0.002, rel=1e-12)  # linear through 0
    # replace sets a scheduled field at every anchor, the others in the base
    fixed = scheduled.replace(beta_local_linear_cross=0.5)
    assert all(v["beta_local_linear_cross"] == 0.5 for _, v in fixed.anchors) and fixed.base == scheduled.base
    plain = sd.DensitySchedule(((0.01, values), (0.1, values)), sd.DEFAULT_WEIGHTS.replace(beta_local_linear_2x2=0.3))
    assert plain.scheduled == DENSITY_FIELDS
    assert plain.weights(0.05).beta_local_linear_2x2 == 0.3
    moved = plain.replace(beta_local_linear_cross=0.2)
    assert moved.base.beta_local_linear_cross == 0.2 and moved.anchors == plain.anchors
    with pytest.raises(ValueError, match="at every anchor or at none"):
        sd.DensitySchedule(((0.01, dict(values, beta_local_linear_cross=0.1)), (0.1, values)))


def test_from_weights_schedules_a_window_weight_only_where_some_anchor_uses_it():
    low, high = sd.DEFAULT_WEIGHTS, sd.DEFAULT_WEIGHTS.replace(delta=1e-3)
    assert sd.DensitySchedule.from_weights(((0.01, low), (0.1, high))).scheduled == DENSITY_FIELDS
    crossed = sd.DensitySchedule.from_weights(((0.01, low), (0.1, high.replace(beta_local_linear_cross=0.01))))
    assert crossed.scheduled == DENSITY_FIELDS + ("beta_local_linear_cross",)
    assert crossed.weights(0.01).beta_local_linear_cross == 0.0 and crossed.weights(0.1).beta_local_linear_cross == 0.01
    # the library's schedule sets both window weights at every anchor (and the 3x3 weight to 0)
    assert all(set(OPTIONAL_DENSITY_FIELDS) <= set(v) and v["beta_local_linear"] == 0
               for v in sd.DEFAULT_SCHEDULE.as_dict().values())
