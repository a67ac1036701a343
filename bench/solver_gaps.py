"""Every L1 solver on issue 20's problem: certified gap and time relative to ADMM, on three real frames.

Run, from the repository root (about 15 minutes on 2 cores)::

    python -m bench.solver_gaps            # writes docs/solver_gaps.md
    python -m bench.solver_gaps --quick    # the first frame only, prints

The problem: a whole shared frame (no crop) with its depth in metres, 5 %
of its valid pixels observed (``mask = valid & (default_rng(5).random(shape)
< 0.05)``), the reference paper's four terms with α = 1, β = 0.5, γ = 0.2,
δ = 0.01, κ = 10, solved without the range clamp (``clip_to_observed=False``:
the table compares minimisers of the objective).  Frames: :data:`FRAMES`
(the first is issue 20's; all three are report frames).

Per frame, in this one process (one BLAS thread), ADMM runs first with its
defaults; its time ``t_ADMM`` is the unit.  Then:

* ``irls`` with its defaults (``target_gap = 1e-4``) and with ``target_gap = 1e-6``;
* ``adam`` with its defaults (a cosine schedule over 1000 steps);
* ``lbfgsb`` stopped by a callback at ``BUDGET`` × ``t_ADMM``, the time the
  issue allows Adam;
* ADMM again (its second run gives the spread of the timing).

``F*`` is the lowest exact objective any run reached on the frame.  The
table gives each run's time / ``t_ADMM``, ``(F − F*) / F*``, the certified
relative duality gap ``result.gap / F`` (an upper bound on ``(F − F_opt) /
F``), ``converged``, and the time (in ``t_ADMM``) at which its history first
came within ``1e-2``, ``1e-4`` and ``1e-6`` of ``F*``.  For the first frame
it draws ``(F_k − F*) / F*`` (log axis) of every run against time (in
``t_ADMM``) and against iterations: :data:`FIGURE` (needs matplotlib).

May import :mod:`sparsedepth`, :mod:`bench.blas`, :mod:`bench.harness`, numpy and (for the figure) matplotlib.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import sparsedepth as sd  # noqa: E402

from .harness.machine import machine_markdown  # noqa: E402
from .harness.report import write_text  # noqa: E402

FRAMES = ("nyu_metric3d/00050", "nyu_rcnn_depth/demo", "kitti/0000000050")
WEIGHTS = sd.Weights.paper(alpha=1.0, beta=0.5, gamma=0.2, delta=0.01, kappa=10.0)
FRACTION = 0.05
SEED = 5
#: L-BFGS-B is stopped at this many ADMM times (the time issue 20 allows Adam).
BUDGET = 10.0
LEVELS = (1e-2, 1e-4, 1e-6)
OUT = Path("docs/solver_gaps.md")
FIGURE = Path("docs/figures/solver_gaps.png")


def problem(name):
    """``(image, sparse, mask)`` of issue 20's protocol on one shared frame."""
    frame = sd.load_shared_frame(name)
    depth = np.array(frame.depth, dtype=float)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(depth) & (depth > 0)
    mask = valid & (np.random.default_rng(SEED).random(depth.shape) < FRACTION)
    return np.asarray(frame.image), np.where(mask, depth, np.nan), mask


class _Budget:
    """A callback that stops the solver once ``seconds`` have passed since the solver's start."""

    def __init__(self, seconds):
        self.seconds = seconds

    def __call__(self, state):
        if state.time > self.seconds:
            raise StopIteration


def runs(t_admm):
    """``[(label, solver, options, max_iter, callback)]`` after the first ADMM run."""
    budget = BUDGET * t_admm
    return [
        ("irls", "irls", None, None, None),
        ("irls, target_gap 1e-6", "irls", {"target_gap": 1e-6}, None, None),
        ("adam", "adam", None, None, None),
        (f"lbfgsb, stopped at {BUDGET:g}× ADMM", "lbfgsb", None, 100000, _Budget(budget)),
        ("admm (second run)", "admm", None, None, None),
    ]


def solve(image, sparse, mask, solver, options, max_iter, callback):
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = sd.complete_depth(image, sparse, mask, weights=WEIGHTS, solver=solver, options=options,
                                   max_iter=max_iter, callback=callback, clip_to_observed=False)
    return result, time.perf_counter() - start


def frame_rows(name, *, log=print):
    image, sparse, mask = problem(name)
    admm, t_admm = solve(image, sparse, mask, "admm", None, None, None)
    log(f"{name}: {image.shape[1]}x{image.shape[0]}, admm {t_admm:.2f} s, F {admm.objective:.10g}")
    results = [("admm", admm, t_admm)]
    for label, solver, options, max_iter, callback in runs(t_admm):
        result, seconds = solve(image, sparse, mask, solver, options, max_iter, callback)
        log(f"  {label}: {seconds:.2f} s, F {result.objective:.10g}, converged {result.converged}")
        results.append((label, result, seconds))
    best = min(r.objective for _, r, _ in results)
    rows = []
    for label, result, seconds in results:
        F = result.objective
        history = [(h.time, h.objective) for h in result.history]
        reached = []
        for level in LEVELS:
            times = [t for t, value in history if value - best <= level * best]
            reached.append(min(times) / t_admm if times else None)
        rows.append(dict(frame=name, label=label, ratio=seconds / t_admm, seconds=seconds, above=(F - best) / best,
                         gap=result.gap / F if np.isfinite(result.gap) else float("nan"),
                         converged=result.converged, reached=reached, iterations=result.iterations,
                         curve=[(h.iteration, h.time / t_admm, (h.objective - best) / best) for h in result.history]))
    return rows


def plot(rows, path):
    """``(F_k − F*) / F*`` against time (in ADMM runs) and against iterations, one curve per run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (by_time, by_iter) = plt.subplots(1, 2, figsize=(11, 4.2))
    floor = 1e-12
    for r in rows:
        it, t, above = np.array(r["curve"]).T
        above = np.maximum(above, floor)
        by_time.plot(t, above, label=r["label"])
        by_iter.plot(np.maximum(it, 1), above, label=r["label"])
    by_time.set(xscale="log", yscale="log", xlabel="time / ADMM's time", ylabel="(F − F*) / F*",
                title=rows[0]["frame"])
    by_iter.set(xscale="log", yscale="log", xlabel="iteration", ylabel="(F − F*) / F*")
    by_iter.legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _cell(value, fmt):
    return "—" if value is None or (isinstance(value, float) and not np.isfinite(value)) else format(value, fmt)


def table(rows):
    head = ("| frame | solver | time / ADMM | s | (F − F*)/F* | gap / F | converged | iterations | "
            "≤ 1e-2 at | ≤ 1e-4 at | ≤ 1e-6 at |\n|---|---|---|---|---|---|---|---|---|---|---|\n")
    lines = []
    for r in rows:
        reached = " | ".join(_cell(x, ".2f") for x in r["reached"])
        lines.append(f"| {r['frame']} | {r['label']} | {r['ratio']:.2f} | {r['seconds']:.1f} | "
                     f"{_cell(max(r['above'], 0.0), '.1e')} | {_cell(r['gap'], '.1e')} | "
                     f"{'yes' if r['converged'] else 'no'} | {r['iterations']} | {reached} |")
    return head + "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the first frame only; print, write nothing")
    args = parser.parse_args(argv)
    frames = [n for n in FRAMES if sd.shared_data_dir() is not None and n in set(sd.list_shared_frames())]
    if not frames:
        print("no shared frames found (../shared/data): nothing to measure", file=sys.stderr)
        return 1
    if args.quick:
        frames = frames[:1]
    start = time.perf_counter()
    rows = []
    for name in frames:
        rows += frame_rows(name, log=lambda s: print(s, flush=True))
    text = table(rows)
    print(text)
    if not args.quick:
        doc = (f"# Every L1 solver on issue 20's problem\n\nMade by `python -m bench.solver_gaps` "
               f"({(time.perf_counter() - start) / 60:.0f} min); see its docstring for the protocol.  Times are "
               f"ratios to the first ADMM run on the same frame in the same process; \"≤ 1e-4 at\" is the time "
               f"(in ADMM runs) at which the run's history first came within 1e-4 × F* of the lowest F any run "
               f"reached; \"gap / F\" is the certified bound `result.gap / result.objective` (— where the solver's "
               f"run was stopped before the certificate).\n\n{text}\n![every solver on {frames[0]}](figures/solver_gaps.png)\n\n{machine_markdown()}\n")
        write_text(OUT, doc)
        try:
            plot([r for r in rows if r["frame"] == frames[0]], FIGURE)
        except ImportError:
            print("matplotlib is not installed: no figure", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
