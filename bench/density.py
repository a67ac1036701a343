"""Density-scheduled weights: tuned per sample density on the tuning frames, reported on unseen frames and datasets.

The weights that complete best depend on how many pixels are observed: with denser samples the prior ``z_c`` (the
geodesic fill between close samples) deserves more weight and the image less.  A
:class:`sparsedepth.DensitySchedule` gives :data:`sparsedepth.objective.weights.DENSITY_FIELDS` a value at each
anchor density (1, 5 and 10 % of the pixels) and interpolates them in log-density for the observed fraction of a
frame (observed pixels / all pixels, clamped to the anchors).

The anchors are tuned by coordinate descent on :data:`bench.frames.TUNE_FRAMES` only: starting from
``sd.DEFAULT_WEIGHTS`` at every anchor, each field of each anchor in turn is multiplied by 1/2 and by 2 (and again
in the same direction while that helps), a change kept when it lowers the score, until a round changes nothing or
``--rounds`` is reached.  That descent scores the inputs at 1 / 5 / 10 % of the valid pixels; below the lowest
anchor a schedule keeps that anchor's values, and most of the 1 % inputs already lie there (a frame's valid pixels
are fewer than its pixels).  So an anchor at :data:`LOW_ANCHOR` of all pixels is added afterwards
(:func:`extend`): it starts from the 1 % anchor's values and descends alone, the others fixed, on every tuning input
including those that keep :data:`LOW_ANCHOR` of the valid pixels (LiDAR-like sparsity, and the 200 samples of the
literature's NYU protocol).  Score: the mean over the datasets of each dataset's mean over its frames × 1/5/10 % of the
valid pixels × seeds (every dataset counts alike; ``--unbalanced``: the plain mean) of the mean of the RMSE and MAE
on the hidden valid pixels divided by those of the nearest-neighbour fill on the same input
(:func:`bench.tune.score`'s score).  Each field stays within a factor ``--span`` (default :data:`SPAN`) of its
default value.  Every input is completed with the weights the schedule gives for *its* observed fraction, so a
frame with sparse ground truth (KITTI's LiDAR covers ~20 % of the pixels) is completed with the weights of its real
density.

The tables report the RMSE ratio to nearest neighbour on :data:`bench.frames.REPORT_FRAMES` for the constant
weights ``sd.DEFAULT_WEIGHTS``, the schedule tuned here and the library's defaults at run time
(``sd.default_weights``), and a leave-one-dataset-out table: for each dataset with tuning frames the descent is
repeated without that dataset's tuning frames and the result scored on its report frames (datasets with no tuning
frame use the schedule tuned on all of them).

Run from the repository root::

    python -m bench.density --seeds 0 1 --jobs 2 --local-linear-windows
        # about 15 minutes on 2 cores: writes docs/density.md, the descent from WINDOWS_START (the local-linear
        # term on cross-shaped and 2x2 windows, a 13-point system) that gave sd.DEFAULT_SCHEDULE
    python -m bench.density --seeds 0 1 --jobs 2 --out /tmp/density_3x3.md
        # the same descent from sd.DEFAULT_WEIGHTS (the term on 3x3 windows, a 25-point system)
    python -m bench.density --quick                # a smoke run on the tiny quick frames

May import :mod:`sparsedepth`, numpy, :mod:`bench.frames`, :mod:`bench.harness` and :mod:`bench.accuracy`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import multiprocessing  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.objective.weights import DENSITY_FIELDS, OPTIONAL_DENSITY_FIELDS  # noqa: E402

from . import harness  # noqa: E402
from .accuracy import dataset_of, load  # noqa: E402

#: The anchor densities of the tuned schedule (observed fraction of all pixels).
ANCHORS = (0.01, 0.05, 0.10)
#: The anchor added below :data:`ANCHORS` after their descent (observed fraction of all pixels), and the fraction of
#: a frame's valid pixels its own tuning and report inputs keep.
LOW_ANCHOR = 0.003
#: The factors of one coordinate step.
FACTORS = (0.5, 2.0)
#: A field's value stays within this factor of its value in the starting weights (both ways).
SPAN = 8.0
#: ``--local-linear-windows``: the descent starts from ``sd.DEFAULT_WEIGHTS`` with the local-linear term moved
#: from 3x3 windows to cross-shaped and 2x2 windows (each at the 3x3 term's weight) ...
WINDOWS_START = sd.DEFAULT_WEIGHTS.replace(beta_local_linear=0.0,
                                           beta_local_linear_cross=sd.DEFAULT_WEIGHTS.beta_local_linear,
                                           beta_local_linear_2x2=sd.DEFAULT_WEIGHTS.beta_local_linear)
#: ... and descends these fields (the 3x3 weight stays 0: a 13-point system instead of 25).
WINDOWS_FIELDS = tuple(name for name in DENSITY_FIELDS if name != "beta_local_linear") + OPTIONAL_DENSITY_FIELDS


def starting_point(args) -> tuple[sd.Weights, tuple, str]:
    """``(weights, fields, name)``: where the descent starts, what it changes, and how the report names the start."""
    if args.local_linear_windows:
        return WINDOWS_START, WINDOWS_FIELDS, "`sd.DEFAULT_WEIGHTS` on cross and 2x2 windows"
    return sd.DEFAULT_WEIGHTS, DENSITY_FIELDS, "`sd.DEFAULT_WEIGHTS`"


class Sample:
    """One sparse input of a frame with its nearest-neighbour errors (the score's denominators)."""

    def __init__(self, frame, fraction, seed):
        self.frame, self.fraction, self.seed = frame, fraction, seed
        self.sparse, self.mask = sd.sample_depth(frame.depth, fraction=fraction, seed=seed)
        self.density = float(self.mask.mean())
        nn = sd.depth_metrics(sd.nearest_fill(self.sparse, self.mask), frame.depth, mask=~self.mask)
        self.nn_rmse, self.nn_mae = nn.rmse, nn.mae

    @property
    def key(self):
        return (self.frame.name, self.fraction, self.seed)


class Scorer:
    """Scores of samples completed with given weights, cached by ``(sample, weights)``."""

    def __init__(self):
        self.cache = {}

    def ratios(self, sample: Sample, weights: sd.Weights) -> tuple[float, float]:
        """``(score, RMSE ratio)`` of ``sample`` completed with ``weights``."""
        key = (sample.key, weights)
        if key not in self.cache:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", sd.ClampWarning)
                depth = sd.complete_depth(sample.frame.image, sample.sparse, sample.mask, weights=weights).depth
            m = sd.depth_metrics(depth, sample.frame.depth, mask=~sample.mask)
            self.cache[key] = (0.5 * (m.rmse / sample.nn_rmse + m.mae / sample.nn_mae), m.rmse / sample.nn_rmse)
        return self.cache[key]

    def mean(self, schedule: sd.DensitySchedule, samples, which=0, *, balanced=False) -> float:
        """Mean score (``which=0``) or RMSE ratio (``which=1``) of ``samples`` completed by ``schedule``.

        ``balanced``: the mean over datasets of each dataset's mean (every dataset counts alike, however many
        frames it has).
        """
        values = {}
        for s in samples:
            key = dataset_of(s.frame.name) if balanced else None
            values.setdefault(key, []).append(self.ratios(s, schedule.weights(s.density))[which])
        return float(np.mean([np.mean(v) for v in values.values()]))


def with_value(schedule: sd.DensitySchedule, anchor: int, name: str, value: float) -> sd.DensitySchedule:
    """``schedule`` with one field of one anchor changed."""
    anchors = [(f, dict(values)) for f, values in schedule.anchors]
    anchors[anchor][1][name] = value
    return sd.DensitySchedule(tuple(anchors), schedule.base)


def descend(samples, *, rounds: int, span: float = SPAN, balanced: bool = True, label: str = "",
            start: sd.DensitySchedule | None = None, tuned=None, scorer: Scorer | None = None,
            start_weights: sd.Weights = sd.DEFAULT_WEIGHTS,
            fields=DENSITY_FIELDS) -> tuple[sd.DensitySchedule, list[float]]:
    """Coordinate descent of a schedule's anchors; the schedule and the score after each round.

    ``start`` (default: ``start_weights`` at every fraction of :data:`ANCHORS`) is the first schedule and
    ``tuned`` the indices of the anchors the descent changes (default: all); ``fields`` are the fields it changes.
    Every field stays within a factor ``span`` of its value in ``start_weights``; ``balanced`` scores the
    dataset-balanced mean.  ``scorer`` (default: a new one) keeps the completions already scored, e.g. those of an
    earlier descent on the same inputs.
    """
    scorer = Scorer() if scorer is None else scorer
    schedule = start if start is not None else sd.DensitySchedule.from_weights(
        tuple((f, start_weights) for f in ANCHORS))
    tuned = range(len(schedule.anchors)) if tuned is None else tuple(tuned)
    best = scorer.mean(schedule, samples, balanced=balanced)
    trace = [best]
    for r in range(rounds):
        changed = False
        for anchor in tuned:
            for name in fields:
                for factor in FACTORS:
                    while True:
                        value = schedule.anchors[anchor][1][name] * factor
                        default = getattr(start_weights, name)
                        if value == 0 or not default / span <= value <= default * span:
                            break
                        candidate = with_value(schedule, anchor, name, value)
                        score = scorer.mean(candidate, samples, balanced=balanced)
                        if score >= best:
                            break
                        schedule, best, changed = candidate, score, True
                        print(f"{label} round {r + 1}: {schedule.anchors[anchor][0]:g} {name} = {value:.4g}: "
                              f"{best:.4f}", file=sys.stderr, flush=True)
        trace.append(best)
        if not changed:
            break
    return schedule, trace


def extend(schedule: sd.DensitySchedule, fraction: float, samples, *, rounds: int, span: float = SPAN,
           balanced: bool = True, label: str = "", scorer: Scorer | None = None,
           start_weights: sd.Weights = sd.DEFAULT_WEIGHTS,
           fields=DENSITY_FIELDS) -> tuple[sd.DensitySchedule, list[float]]:
    """``schedule`` with one anchor added below its lowest, at ``fraction``, tuned with the other anchors fixed.

    The new anchor starts from the values of the lowest anchor (so the first score is the schedule's own: below
    the lowest anchor a schedule takes that anchor's values) and only its fields descend (:func:`descend`).
    """
    lowest = schedule.anchors[0][0]
    if not 0 < fraction < lowest:
        raise ValueError(f"an added anchor lies below the lowest ({lowest:g}); got {fraction:g}")
    start = sd.DensitySchedule(((fraction, dict(schedule.anchors[0][1])),) + tuple(schedule.anchors), schedule.base)
    return descend(samples, rounds=rounds, span=span, balanced=balanced, label=label, start=start, tuned=(0,),
                   scorer=scorer, start_weights=start_weights, fields=fields)


def _descend_job(job):
    """``(label, schedule, trace, extension trace)``: the descent of :data:`ANCHORS` on the inputs at the standard
    fractions, then :data:`LOW_ANCHOR` added by :func:`extend` on every input."""
    label, samples, rounds, span, balanced, start_weights, fields = job
    standard = [s for s in samples if s.fraction in harness.FRACTIONS]
    scorer = Scorer()  # the extension's first score re-reads the descent's last completions of the standard inputs
    schedule, trace = descend(standard, rounds=rounds, span=span, balanced=balanced, label=label, scorer=scorer,
                              start_weights=start_weights, fields=fields)
    schedule, low_trace = extend(schedule, LOW_ANCHOR, samples, rounds=rounds, span=span, balanced=balanced,
                                 label=f"{label} (low)", scorer=scorer, start_weights=start_weights, fields=fields)
    return label, schedule, trace, low_trace


def parse_args(argv):
    parser = argparse.ArgumentParser(prog="python -m bench.density", description=__doc__.split("\n\n")[0])
    parser.add_argument("--step", type=int, default=2, help="frame subsampling (default 2)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="sampling seeds (default 0)")
    parser.add_argument("--rounds", type=int, default=3, help="most rounds of coordinate descent (default 3)")
    parser.add_argument("--jobs", type=int, default=1, help="descents run in parallel processes (default 1)")
    parser.add_argument("--span", type=float, default=SPAN,
                        help=f"each field stays within this factor of its default (default {SPAN:g})")
    parser.add_argument("--unbalanced", action="store_true",
                        help="score the mean over all tuning inputs (default: the mean over datasets of each "
                             "dataset's mean)")
    parser.add_argument("--local-linear-windows", action="store_true",
                        help="start from the defaults with the local-linear term on cross-shaped and 2x2 windows "
                             "instead of 3x3 (WINDOWS_START) and descend their weights (WINDOWS_FIELDS)")
    parser.add_argument("--quick", action="store_true", help="the tiny quick frames, one round (smoke test)")
    parser.add_argument("--out", type=Path, default=harness.DOCS / "density.md", help="markdown output")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    args.argv = [a for a in argv if not a.startswith("--out") and a != str(args.out)]
    if args.quick:
        args.rounds = 1
    start = time.perf_counter()
    tune_frames, report_frames = load(args)
    if not tune_frames or not report_frames:
        print("the shared data folder is absent: nothing to measure", file=sys.stderr)
        return 2
    fractions = (LOW_ANCHOR, *harness.FRACTIONS)
    tune = [Sample(f, p, s) for f in tune_frames for p in fractions for s in args.seeds]
    report = [Sample(f, p, s) for f in report_frames for p in fractions for s in args.seeds]
    held_out = sorted({dataset_of(f.name) for f in tune_frames} & {dataset_of(f.name) for f in report_frames})
    if args.quick:
        held_out = []
    balanced = not args.unbalanced
    start_weights, fields, _ = starting_point(args)
    common = (args.rounds, args.span, balanced, start_weights, fields)
    jobs = [("all", tune, *common)] + [(d, [s for s in tune if dataset_of(s.frame.name) != d], *common)
                                       for d in held_out]
    if args.jobs > 1:
        with multiprocessing.get_context("fork").Pool(min(args.jobs, len(jobs))) as pool:
            tuned = {label: rest for label, *rest in pool.map(_descend_job, jobs)}
    else:
        tuned = {label: rest for label, *rest in map(_descend_job, jobs)}
    text = report_text(args, tune_frames, report_frames, report, tuned, start)
    return harness.publish([text], args.out)


def _schedule_differences(tuned: sd.DensitySchedule, library: sd.DensitySchedule) -> list[str]:
    """Where ``library`` differs from ``tuned``: anchors only one has, and each field of a shared anchor."""
    ours, theirs = dict(tuned.anchors), dict(library.anchors)
    out = [f"an anchor at {100 * f:g} % only {'here' if f in ours else 'in the library'}"
           for f in sorted(set(ours) ^ set(theirs))]
    for f in sorted(set(ours) & set(theirs)):
        mine, lib = tuned.weights(f), library.weights(f)  # a field one schedule does not set is its base's
        out += [f"{100 * f:g} % {name} = {getattr(lib, name):.6g} (tuned here {getattr(mine, name):.6g})"
                for name in DENSITY_FIELDS + OPTIONAL_DENSITY_FIELDS if getattr(lib, name) != getattr(mine, name)]
    if tuned.base != library.base:
        out.append("the fields outside the schedule")
    return out


def report_text(args, tune_frames, report_frames, report, tuned, start) -> str:
    schedule, trace, low_trace = tuned["all"]
    scorer = Scorer()
    start_weights, _, start_name = starting_point(args)
    constant = sd.DensitySchedule.from_weights(((ANCHORS[0], start_weights),))
    without_low = sd.DensitySchedule(schedule.anchors[1:], schedule.base)
    library = sd.DEFAULT_SCHEDULE
    low = f"{100 * LOW_ANCHOR:g} %"
    methods = [(f"constant {start_name}", constant), (f"schedule tuned here without its {low} anchor",
                                                               without_low),
               ("schedule tuned here", schedule), ("library defaults at run time (`sd.default_weights`)", library)]
    fractions = harness.FRACTIONS
    standard = [s for s in report if s.fraction in fractions]

    def mean_rmse(sched, keep=lambda s: True):
        chosen = [s for s in standard if keep(s)]
        return scorer.mean(sched, chosen, which=1) if chosen else float("nan")

    def low_rmse(sched):
        return scorer.mean(sched, [s for s in report if s.fraction == LOW_ANCHOR], which=1)

    rows = []
    for label, sched in methods:
        per = [mean_rmse(sched, lambda s, p=p: s.fraction == p) for p in fractions]
        rows.append([label, f"{low_rmse(sched):.3f}", *(f"{v:.3f}" for v in per), f"{mean_rmse(sched):.3f}"])
    datasets = sorted({dataset_of(f.name) for f in report_frames})
    per_dataset = []
    for d in datasets:
        keep = lambda s, d=d: dataset_of(s.frame.name) == d  # noqa: E731
        per_dataset.append([d, *(f"{mean_rmse(sched, keep):.3f}" for _, sched in methods)])
    lodo, lodo_scores = [], []
    for d in datasets:
        held = [s for s in standard if dataset_of(s.frame.name) == d]
        sched, label = ((tuned[d][0], f"tuned without {d}") if d in tuned
                        else (schedule, "tuned on all (no tuning frame)"))
        lodo_scores += [scorer.ratios(s, sched.weights(s.density))[1] for s in held]
        lodo.append([d, label, f"{scorer.mean(sched, held, which=1):.3f}",
                     f"{scorer.mean(constant, held, which=1):.3f}"])
    anchors = [[name, *(f"{values[name]:.6g}" for _, values in schedule.anchors),
                f"{getattr(start_weights, name):.6g}"] for name in schedule.scheduled]
    densities = [[f.name, f"{100 * np.isfinite(f.depth).mean():.0f} %",
                  *(f"{100 * p * np.isfinite(f.depth).mean():.2g} %" for p in (LOW_ANCHOR, *fractions))]
                 for f in report_frames]
    differences = _schedule_differences(schedule, library)
    library_line = ("The library's `sd.DEFAULT_SCHEDULE` is the schedule tuned here." if not differences else
                    "The library's `sd.DEFAULT_SCHEDULE` differs from the schedule tuned here: "
                    + "; ".join(differences) + ".")
    command = harness.command_line("density", args.argv)
    score_name = 'the mean over all inputs' if args.unbalanced else 'the mean over datasets of each dataset mean'
    lines = [
        *harness.tuned_report_header("Density-scheduled weights", command, args, time.perf_counter() - start,
                                     tune_frames, report_frames),
        "",
        f"Each input keeps {low}, 1, 5 or 10 % of the frame's *valid* pixels; the schedule is evaluated at the "
        "observed fraction of *all* pixels (KITTI's ground truth covers about a fifth of the frame, so its inputs "
        "are completed with the weights of a lower density).",
        "",
        f"Coordinate descent on the tuning frames' inputs at 1 / 5 / 10 % (score (RMSE + MAE) / 2 over nearest's, "
        f"{score_name}; starting from {start_name} at every anchor, every field within a factor {args.span:g} of "
        f"its value there): "
        + " -> ".join(f"{v:.4f}" for v in trace) + f" ({len(trace) - 1} rounds).",
        "",
        f"Then an anchor at {low} of all pixels (without it the schedule keeps the 1 % anchor's values below 1 %), "
        f"starting from those values and descending alone (the other anchors fixed) on every tuning input, "
        f"{low} included: " + " -> ".join(f"{v:.4f}" for v in low_trace) + f" ({len(low_trace) - 1} rounds).",
        "",
        "Tuned anchors (observed fraction of all pixels), beside the constant defaults:",
        "",
        harness.markdown_table(["field", *(f"{100 * f:g} %" for f, _ in schedule.anchors), start_name],
                               anchors, align=["---"] + ["---:"] * (len(schedule.anchors) + 1)),
        "",
        library_line,
        "",
        f"RMSE / nearest-neighbour RMSE on the report frames (lower is better), mean over frames × seeds; the "
        f"mean is over 1 / 5 / 10 % (the {low} inputs are the sparsest a user brings, not part of that mean):",
        "",
        harness.markdown_table(["weights", low, *(f"{100 * f:g} %" for f in fractions), "mean (1 / 5 / 10 %)"],
                               rows, align=["---"] + ["---:"] * (len(fractions) + 2)),
        "",
        "Per dataset (mean over its report frames × 1 / 5 / 10 % × seeds):",
        "",
        harness.markdown_table(["dataset", *(label for label, _ in methods)], per_dataset,
                               align=["---"] + ["---:"] * len(methods)),
        "",
        "Leave-one-dataset-out: for each dataset with tuning frames the descent and the added anchor repeated "
        "without them, scored on that dataset's report frames at 1 / 5 / 10 %:",
        "",
        harness.markdown_table(["held-out dataset", "schedule", "score", f"constant {start_name}"], lodo,
                               align=["---", "---", "---:", "---:"]),
        "",
        f"Leave-one-dataset-out mean over the report frames: {np.mean(lodo_scores):.3f}.",
        "",
        f"Observed fraction of all pixels per report frame (valid ground truth, then {low}, 1, 5 and 10 % of it):",
        "",
        harness.markdown_table(["frame", "valid", low, *(f"{100 * f:g} %" for f in fractions)], densities,
                               align=["---"] + ["---:"] * (len(fractions) + 2)),
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
