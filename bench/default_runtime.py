"""Runtime of the default completion against the baseline objective of ``docs/accuracy.md``, same process.

Run (a few minutes on 2 cores)::

    python -m bench.default_runtime --out docs/default_runtime.md

Every report frame (subsampled by ``--step``, default 2) at 1 / 5 / 10 % of its valid pixels and every seed is
completed with the library's defaults (``sd.complete_depth`` without ``weights=``), with the defaults without the
local-linear terms (:data:`WITHOUT_LOCAL_LINEAR`: every local-linear weight 0 at every density) and with
:data:`BASELINE` (the baseline row of ``docs/accuracy.md``: the density-independent weights without the modelling
fields edge_sigma, fill_contrast and the local-linear term), the order of the three turning from one input to the
next, the whole pass ``--repeats`` times. A ratio is Σ wall time of a setting over Σ wall time of the baseline over
every pass (and the same in process CPU time); each pass's own ratio of the defaults shows the spread of the
measurement on a shared machine.

May import :mod:`sparsedepth`, :mod:`bench.harness` and :mod:`bench.frames`.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import sparsedepth as sd
from sparsedepth.objective.weights import LOCAL_LINEAR_FIELDS

from . import frames as frame_list
from . import harness as H

FRACTIONS = (0.01, 0.05, 0.10)
#: The baseline objective of docs/accuracy.md (its "Baseline weights"), modelling fields off.
BASELINE = sd.Weights(alpha=1, beta=0, gamma=0, delta=0.000131, kappa=25, beta_image=0.00673, beta_second=0.000286,
                      beta_second_image=0.039, edge_sigma=0, fill_contrast=0, beta_local_linear=0)
#: The library's defaults with the local-linear terms (every window shape) switched off at every anchor (the rest
#: as in the defaults).
WITHOUT_LOCAL_LINEAR = sd.DEFAULT_SCHEDULE.replace(**dict.fromkeys(LOCAL_LINEAR_FIELDS, 0.0))
#: (label, weights) of the settings timed, ``None`` for the library's defaults; the baseline last.
SETTINGS = (("defaults", None), ("without local-linear", WITHOUT_LOCAL_LINEAR), ("baseline", BASELINE))


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--step", type=int, default=2, help="keep every step-th row and column (default 2)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1], help="sampling seeds (default 0 1)")
    p.add_argument("--repeats", type=int, default=None, help="passes over every input (default 3; 1 with --quick)")
    p.add_argument("--quick", action="store_true", help="one frame at step 4, one seed")
    p.add_argument("--out", type=Path, default=None, help="write the markdown report here")
    return p.parse_args(argv)


def timed_completion(image, sparse, mask, weights):
    """(wall seconds, process CPU seconds) of one completion."""
    wall, cpu = time.perf_counter(), time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        sd.complete_depth(image, sparse, mask, weights=weights)
    return time.perf_counter() - wall, time.process_time() - cpu


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    t0 = time.perf_counter()
    names = frame_list.REPORT_FRAMES
    if args.quick:
        names, args.step, args.seeds = ("middlebury2003/teddy",), 4, args.seeds[:1]
    if args.repeats is None:
        args.repeats = 1 if args.quick else 3
    if args.repeats < 1:
        raise SystemExit("--repeats must be at least 1")
    frames = [H.load_frame(n, args.step) for n in frame_list.available(names)]
    labels = [label for label, _ in SETTINGS]
    times = {}  # frame -> {label: [wall, cpu]}
    passes = []  # per pass: {label: [wall, cpu]}
    turn = 0
    for _ in range(args.repeats):
        this_pass = {label: np.zeros(2) for label in labels}
        for frame in frames:
            per = times.setdefault(frame.name, {label: np.zeros(2) for label in labels})
            for fraction in FRACTIONS:
                for seed in args.seeds:
                    sparse, mask = sd.sample_depth(frame.depth, fraction=fraction, seed=seed)
                    k = turn % len(SETTINGS)
                    for label, weights in SETTINGS[k:] + SETTINGS[:k]:
                        seconds = timed_completion(frame.image, sparse, mask, weights)
                        per[label] += seconds
                        this_pass[label] += seconds
                    turn += 1
        passes.append(this_pass)
    total = {label: sum(t[label] for t in times.values()) for label in labels}

    def cells(t, bold=False):
        ratio = [f"{t[label][0] / t['baseline'][0]:.2f}" for label in labels[:-1]]
        if bold:
            ratio = [f"**{r}**" for r in ratio]
        return [f"{t['baseline'][0]:.2f}", f"{t['defaults'][0]:.2f}", ratio[0], f"{t['without local-linear'][0]:.2f}",
                ratio[1]]

    rows = [[f"`{name}`", *cells(t)] for name, t in times.items()]
    rows.append(["all", *cells(total, bold=True)])
    cpu = {label: total[label][1] / total["baseline"][1] for label in labels[:-1]}
    lines = [
        "# Runtime of the default completion",
        "",
        f"Made by `{H.command_line('default_runtime', argv)}` (frames subsampled by {args.step}, sampling seeds "
        f"{args.seeds}, {time.perf_counter() - t0:.0f} s).",
        "",
        H.machine_markdown(),
        "",
        __doc__.split("\n\n")[2].replace("\n", " "),
        "",
        H.markdown_table(["frame", "baseline (s)", "defaults (s)", "defaults / baseline",
                          "defaults without local-linear (s)", "without local-linear / baseline"], rows),
        "",
        f"In process CPU time: defaults / baseline = {cpu['defaults']:.2f}; defaults without local-linear / baseline "
        f"= {cpu['without local-linear']:.2f}.",
        "",
        f"Per pass ({args.repeats}), defaults / baseline in wall / CPU time: "
        + ", ".join(f"{p['defaults'][0] / p['baseline'][0]:.2f} / {p['defaults'][1] / p['baseline'][1]:.2f}"
                    for p in passes) + ".",
        "",
    ]
    return H.publish(lines, args.out)


if __name__ == "__main__":
    sys.exit(main())
