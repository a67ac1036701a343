"""Where a completion spends its time: sparsedepth.profiling's phases add up and nest as documented."""

import warnings

import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.profiling import PHASES, PhaseTimes, phase, phase_times

from conftest import make_problem


def test_nested_phases_count_exclusive_time():
    times = PhaseTimes()  # hand-made clock: a from 0 to 10 with b from 2 to 5 and c from 6 to 7 inside it
    times._enter("a", 0.0)
    times._enter("b", 2.0)
    times._leave(5.0)
    times._enter("c", 6.0)
    times._leave(7.0)
    times._leave(10.0)
    assert times == {"a": 6.0, "b": 3.0, "c": 1.0}
    times._enter("b", 11.0)
    times._leave(11.5)
    assert times["b"] == 3.5


def test_phase_outside_a_collector_records_nothing():
    with phase("iterations"):
        pass
    with phase_times() as times:
        pass
    assert dict(times) == {} and times.wall >= 0 and times.outside() == times.wall


def test_collectors_do_not_nest():
    with phase_times():
        with pytest.raises(RuntimeError, match="nested"):
            with phase_times():
                pass
    with phase_times() as times:  # the failed inner block left the state clean
        with phase("clamp"):
            pass
    assert set(times) == {"clamp"}


@pytest.mark.parametrize("kwargs, expected", [
    ({}, {"prior fill", "assembly", "hierarchy", "iterations", "certificate", "term values", "clamp"}),
    ({"uncertainty": True}, {"prior fill", "assembly", "hierarchy", "iterations", "uncertainty map"}),
])
def test_a_completion_reports_its_phases(kwargs, expected):
    image, sparse, mask, _ = make_problem(shape=(48, 64), fraction=0.1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        with phase_times() as times:
            result = sd.complete_depth(image, sparse, mask, **kwargs)
    assert expected <= set(times) <= set(PHASES)
    assert all(v >= 0 for v in times.values())
    assert sum(times.values()) <= times.wall * (1 + 1e-9) and times.outside() >= -1e-9
    # and the marks do not change the answer
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        again = sd.complete_depth(image, sparse, mask, **kwargs)
    np.testing.assert_array_equal(result.depth, again.depth)
