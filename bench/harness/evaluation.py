"""One evaluation of a method on a frame, and the aggregation of many.

:func:`evaluate` runs one :class:`~bench.harness.methods.Method` on one frame at one sparsity and seed, and
scores it on the valid ground-truth pixels hidden from it.  Results are cached in-process, so modules run by
``python -m bench.run_all`` share identical runs (e.g. ours at 5 % in the sparsity and baseline tables).
:func:`summarise` gives mean ± std over frames × seeds, and same-run time ratios to a reference method
(Σ t / Σ t_ref over the same frames and seeds).

May import :mod:`sparsedepth`, numpy, :mod:`.inputs`, :mod:`.methods` and :mod:`.timing`.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

import numpy as np

import sparsedepth as sd

from .inputs import FrameData, sample
from .methods import Method
from .timing import timed

__all__ = ["Record", "evaluate", "evaluate_all", "show_progress", "mean_std", "metric", "summarise"]


@dataclass(frozen=True)
class Record:
    """One method on one frame at one sparsity and seed."""

    method: str
    frame: str
    sampling: object  # fraction (float) or count (int)
    seed: int
    metrics: sd.DepthMetrics
    runtime: float
    objective: float | None = None
    result: object = field(default=None, repr=False, compare=False)


_CACHE: dict = {}
_PROGRESS = [False]


def show_progress(on: bool = True) -> None:
    """Print one line per evaluation to stderr (the modules' ``main`` turn it on; tests leave it off)."""
    _PROGRESS[0] = bool(on)


def evaluate(method: Method, frame: FrameData, *, fraction=None, count=None, seed=0, keep_result=False) -> Record:
    """Run ``method`` on ``frame`` with seeded sparse input; score on the hidden valid pixels.

    ``runtime`` is wall-clock seconds around the method call (for ours it
    includes building the objective).  Identical calls are served from an
    in-process cache.
    """
    key = (method.key, frame.name, frame.step, frame.shape, fraction, count, seed, keep_result)
    if method.key and key in _CACHE:
        rec = _CACHE[key]
        return Record(method.name, *[getattr(rec, f) for f in ("frame", "sampling", "seed", "metrics", "runtime",
                                                                "objective", "result")])
    sparse, mask = sample(frame, fraction=fraction, count=count, seed=seed)
    out, runtime = timed(method.run, frame.image, sparse, mask)
    objective = None
    if isinstance(out, sd.CompletionResult):
        objective = out.objective
        depth = out.depth
    else:
        depth = out
    metrics = sd.depth_metrics(depth, frame.depth, mask=~mask)
    rec = Record(method.name, frame.name, fraction if fraction is not None else count, seed, metrics, runtime,
                 objective, out if keep_result else None)
    if method.key:
        _CACHE[key] = rec
    if _PROGRESS[0]:
        print(f"  {method.name:>40s} {frame.name:>40s} {rec.sampling!s:>5s} seed {seed}: RMSE {metrics.rmse:.4g} "
              f"{runtime:.2f} s", file=sys.stderr, flush=True)
    return rec


def evaluate_all(methods, frames, seeds, *, fractions=None, counts=None, keep_result=False) -> list[Record]:
    """:func:`evaluate` of every method on every frame, seed and sampling (samplings outermost, methods innermost).

    Give the samplings as observed ``fractions`` or as sample ``counts``, not both.
    """
    if (fractions is None) == (counts is None):
        raise ValueError("give fractions or counts")
    key = "fraction" if counts is None else "count"
    return [evaluate(m, f, **{key: sampling}, seed=s, keep_result=keep_result)
            for sampling in (fractions if counts is None else counts) for f in frames for s in seeds for m in methods]


def mean_std(values) -> tuple[float, float]:
    """Mean and (population) standard deviation of ``values``."""
    v = np.asarray(list(values), dtype=float)
    return float(np.mean(v)), float(np.std(v))


def metric(rec: Record, name: str) -> float:
    """One metric of a record (``"runtime"`` or a field of :class:`sparsedepth.DepthMetrics`)."""
    return rec.runtime if name == "runtime" else float(getattr(rec.metrics, name))


def summarise(records, *, reference: str, metrics=("rmse", "mae", "rel", "delta1")) -> list[dict]:
    """Mean ± std per (method, sampling) over frames × seeds, plus ratios to ``reference``.

    ``rmse_ratio`` is the mean over frames × seeds of RMSE / RMSE of the
    reference on the same frame and input; ``time_ratio`` is Σ t / Σ t_ref
    over the same runs.
    """
    ref = {(r.frame, r.sampling, r.seed): r for r in records if r.method == reference}
    groups: dict = {}
    for r in records:
        groups.setdefault((r.method, r.sampling), []).append(r)
    rows = []
    for (method, sampling), recs in groups.items():
        row = {"method": method, "sampling": sampling, "n": len(recs)}
        for m in (*metrics, "runtime"):
            row[m] = mean_std(metric(r, m) for r in recs)
        pairs = [(r, ref[(r.frame, r.sampling, r.seed)]) for r in recs if (r.frame, r.sampling, r.seed) in ref]
        if pairs:
            row["rmse_ratio"] = mean_std(a.metrics.rmse / b.metrics.rmse for a, b in pairs)
            row["time_ratio"] = sum(a.runtime for a, _ in pairs) / max(sum(b.runtime for _, b in pairs), 1e-12)
        rows.append(row)
    return rows
