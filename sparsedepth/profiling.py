"""Where a completion spends its time: named phases, timed only while someone is listening.

The library marks the parts of a completion with :func:`phase` (building the image terms, the prior fill, the
assembly of the normal equations, the multigrid set-up, the solver's iterations, the certificate, the term values,
the clamp, the uncertainty map).  Outside :func:`phase_times` a mark costs one context-variable lookup and nothing is
recorded.  Inside it, every phase's *exclusive* wall time is added up: time spent in a phase nested inside another
counts for the inner one only, so the phases add up to the time the marked code ran.

>>> import numpy as np, sparsedepth as sd
>>> frame = sd.load_motorcycle()
>>> sparse, mask = sd.sample_depth(frame.depth[::4, ::4], fraction=0.05, seed=0)
>>> with sd.profiling.phase_times() as times:
...     result = sd.complete_depth(frame.image[::4, ::4], sparse, mask)
>>> sorted(times) == sorted(set(times) & set(sd.profiling.PHASES))
True

``python -m bench.speed`` writes the breakdown of the default, fast and uncertainty completions to
``docs/speed.md`` with it.

May import the standard library only.
"""

from __future__ import annotations

import contextlib
import contextvars
import time

__all__ = ["PHASES", "PhaseTimes", "phase", "phase_times"]

#: The phases the library marks, in the order a completion meets them.
PHASES = (
    "image terms",  # edge weights, local-linear affinities, the objective's terms
    "prior fill",  # the nearest-sample (geodesic) fill z_c
    "assembly",  # the normal equations A, b, c
    "hierarchy",  # the multigrid (or other) preconditioner's set-up
    "iterations",  # the solver's loop
    "certificate",  # the duality gap of the returned depth
    "term values",  # the value of each term at the returned depth
    "upsampling and sweeps",  # the fast mode's interpolation to the full grid and its edge-aware sweeps
    "clamp",  # the range clamp of the returned depth
    "uncertainty map",  # the calibration of the half-sample differences into sigma
)

_ACTIVE = contextvars.ContextVar("sparsedepth_phase_times", default=None)


class PhaseTimes(dict):
    """Exclusive wall seconds per phase name (a dict), filled while its :func:`phase_times` block runs.

    Attributes
    ----------
    wall : float
        Wall seconds of the whole block (set when it ends); ``wall − sum(values)`` is the time outside every phase.
    """

    def __init__(self):
        super().__init__()
        self.wall = float("nan")
        self._open = []  # [name, start of its current stretch]

    def _enter(self, name, now):
        if self._open:
            outer = self._open[-1]
            self[outer[0]] = self.get(outer[0], 0.0) + now - outer[1]
        self._open.append([name, now])

    def _leave(self, now):
        name, start = self._open.pop()
        self[name] = self.get(name, 0.0) + now - start
        if self._open:
            self._open[-1][1] = now

    def outside(self) -> float:
        """Wall seconds of the block spent in no phase."""
        return self.wall - sum(self.values())


@contextlib.contextmanager
def phase(name: str):
    """Mark the code of the ``with`` block as the phase ``name`` (timed only inside :func:`phase_times`)."""
    times = _ACTIVE.get()
    if times is None:
        yield
        return
    times._enter(name, time.perf_counter())
    try:
        yield
    finally:
        times._leave(time.perf_counter())


@contextlib.contextmanager
def phase_times():
    """Collect the exclusive time of every :func:`phase` run inside the block; yields a :class:`PhaseTimes`.

    Blocks may not be nested in one thread of control (the inner one would take the phases from the outer one);
    other threads and tasks have their own (a context variable).
    """
    if _ACTIVE.get() is not None:
        raise RuntimeError("phase_times blocks cannot be nested")
    times = PhaseTimes()
    token = _ACTIVE.set(times)
    start = time.perf_counter()
    try:
        yield times
    finally:
        times.wall = time.perf_counter() - start
        _ACTIVE.reset(token)
