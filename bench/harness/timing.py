"""Wall-clock timing: one call, and the best (or every) time of repeated calls, with ``time.perf_counter``.

The machine the benchmarks run on is shared, so the reports compare times measured in the same run (ratios) and
take the best of repeats where a single call is short.

May import the standard library only.
"""

from __future__ import annotations

import time

__all__ = ["timed", "best_of"]


def timed(fn, *args, **kwargs):
    """``(fn(*args, **kwargs), seconds)``: the result and the wall-clock time of one call."""
    start = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - start


def best_of(repeat, fn, *args, **kwargs) -> float:
    """The shortest wall-clock time of ``repeat`` calls of ``fn(*args, **kwargs)``, in seconds."""
    return min(timed(fn, *args, **kwargs)[1] for _ in range(repeat))
