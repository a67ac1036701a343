"""Image-to-depth registration: does shifting the image onto the samples' depth edges help the default completion?

Run (about fifteen minutes on 2 cores)::

    python -m bench.registration --seeds 0 1 --out docs/registration.md

For every tuning and report frame (subsampled by ``--step``, default 2), at 1 / 5 / 10 % of its valid pixels and
every seed, :func:`sparsedepth.estimate_image_shift` estimates the image's shift from that input's samples alone;
the input is then completed with the default weights: unshifted, with the image shifted by the estimate of that
input, and with one shift per frame calibrated on its densest (10 %) inputs (their held-out errors summed; a
stand-in for measuring a sensor's shift once on dense frames and giving it to every frame), with the ``min_gain``
threshold chosen on the tuning frames and without a threshold.  The calibration's 10 % inputs are samples of the
same frame whose inputs are scored (two numbers fitted per frame; a sensor's other frames were not available).
The score is the RMSE on the hidden valid pixels over the nearest fill's, as in ``docs/density.md``.

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

from . import frames as frame_list
from . import harness as H
from .accuracy import dataset_of

FRACTIONS = (0.01, 0.05, 0.10)
#: The ``min_gain`` candidates, chosen among on the tuning frames.
GAINS = (1.0, 1.05, 1.1, 1.2, 1.5)


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--step", type=int, default=2, help="keep every step-th row and column (default 2)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1], help="sampling seeds (default 0 1)")
    p.add_argument("--max-shift", type=int, default=2, help="largest |dy|, |dx| tried (default 2)")
    p.add_argument("--quick", action="store_true", help="one tuning and one report frame at step 4, one seed")
    p.add_argument("--out", type=Path, default=None, help="write the markdown report here")
    return p.parse_args(argv)


class Input:
    """One sparse input of a frame: its samples, the nearest fill's RMSE, the shift estimate and the scores."""

    def __init__(self, frame, fraction, seed, max_shift):
        self.frame, self.fraction, self.seed = frame, fraction, seed
        self.sparse, self.mask = sd.sample_depth(frame.depth, fraction=fraction, seed=seed)
        self.nn_rmse = sd.depth_metrics(sd.nearest_fill(self.sparse, self.mask), frame.depth, mask=~self.mask).rmse
        start = time.perf_counter()
        self.estimate = sd.estimate_image_shift(frame.image, self.sparse, self.mask, max_shift=max_shift, seed=seed)
        self.estimate_seconds = time.perf_counter() - start
        self.scores, self.solve_seconds = {}, {}

    def ratio(self, shift) -> float:
        """RMSE / nearest of the default completion with the image shifted by ``shift``."""
        if shift not in self.scores:
            start = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", sd.ClampWarning)
                depth = sd.complete_depth(sd.shift_image(self.frame.image, shift), self.sparse, self.mask).depth
            self.solve_seconds[shift] = time.perf_counter() - start
            self.scores[shift] = sd.depth_metrics(depth, self.frame.depth, mask=~self.mask).rmse / self.nn_rmse
        return self.scores[shift]


def calibrated_estimate(inputs) -> sd.ImageShift:
    """The densest of ``inputs`` pooled by :func:`sparsedepth.pool_image_shifts` (each sample counts once)."""
    densest = max(i.fraction for i in inputs)
    return sd.pool_image_shifts([i.estimate for i in inputs if i.fraction == densest])


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    t0 = time.perf_counter()
    if args.quick:
        tune_names, report_names, args.step, args.seeds = frame_list.TUNE_FRAMES[3:4], ("tum/0",), 4, args.seeds[:1]
    else:
        tune_names, report_names = frame_list.TUNE_FRAMES, frame_list.REPORT_FRAMES
    tune = [H.load_frame(n, args.step) for n in frame_list.available(tune_names)]
    report = [H.load_frame(n, args.step) for n in frame_list.available(report_names)]
    inputs = {}
    for frame in tune + report:
        inputs[frame.name] = [Input(frame, f, s, args.max_shift) for f in FRACTIONS for s in args.seeds]
        print(f"{frame.name}: shifts {[i.estimate.best for i in inputs[frame.name]]}, "
              f"gains {[round(i.estimate.gain, 3) for i in inputs[frame.name]]}", flush=True)
    calibration = {name: calibrated_estimate(ins) for name, ins in inputs.items()}

    def mean_over(names, score):
        return float(np.mean([score(i) for n in names for i in inputs[n]]))

    tune_names_ = [f.name for f in tune]
    gain_scores = {g: mean_over(tune_names_, lambda i, g=g: i.ratio(i.estimate.shift_at(g))) for g in GAINS}
    gain = min(GAINS, key=lambda g: (round(gain_scores[g], 4), -g))
    calibration_scores = {g: mean_over(tune_names_, lambda i, g=g: i.ratio(calibration[i.frame.name].shift_at(g)))
                          for g in GAINS}
    calibration_gain = min(GAINS, key=lambda g: (round(calibration_scores[g], 4), -g))
    pooled = {name: c.shift_at(calibration_gain) for name, c in calibration.items()}
    measured = {name: c.shift_at(1.0) for name, c in calibration.items()}
    ways = {
        "unshifted": lambda i: i.ratio((0, 0)),
        f"per-input estimate (min_gain {gain:g})": lambda i: i.ratio(i.estimate.shift_at(gain)),
        f"calibrated on the 10 % inputs (min_gain {calibration_gain:g})": lambda i: i.ratio(pooled[i.frame.name]),
        "calibrated on the 10 % inputs, always applied (min_gain 1)": lambda i: i.ratio(measured[i.frame.name]),
    }
    text = report_text(args, argv, tune, report, inputs, measured, ways, gain, (gain_scores, calibration_scores),
                       time.perf_counter() - t0)
    return H.publish([text], args.out)


def report_text(args, argv, tune, report, inputs, pooled, ways, gain, gain_scores, seconds) -> str:
    lines = H.tuned_report_header("Image-to-depth registration", H.command_line("registration", argv), args, seconds,
                                  tune, report)
    lines += ["", __doc__.split("\n\n")[3].replace("\n", " "), ""]
    lines += ["`min_gain` on the tuning frames (mean RMSE / nearest; the largest of the best is kept):", ""]
    per_input, calibrated = gain_scores
    lines.append(H.markdown_table(["min_gain", "per-input estimate", "calibrated on the 10 % inputs"],
                                  [[f"{g:g}", f"{per_input[g]:.4f}", f"{calibrated[g]:.4f}"] for g in GAINS]))
    names = [f.name for f in report]
    rows = []
    for way, score in ways.items():
        per = [float(np.mean([score(i) for n in names for i in inputs[n] if i.fraction == f])) for f in FRACTIONS]
        rows.append([way] + [f"{v:.3f}" for v in per] + [f"{np.mean(per):.3f}"])
    lines += ["", "RMSE / nearest on the report frames, mean over frames × seeds:", ""]
    lines.append(H.markdown_table(["image", "1 %", "5 %", "10 %", "mean"], rows))
    lines += ["", "Per report frame (mean over densities × seeds), with the shifts chosen (dy, dx) in the subsampled "
              "frame's pixels:", ""]
    rows = []
    for name in names:
        ins = inputs[name]
        chosen = sorted({str(i.estimate.shift_at(gain)) for i in ins})
        rows.append([f"`{name}`", dataset_of(name)] + [f"{np.mean([s(i) for i in ins]):.3f}" for s in ways.values()]
                    + [", ".join(chosen), str(pooled[name])])
    lines.append(H.markdown_table(["frame", "dataset"] + list(ways) + ["per-input shifts",
                                                                        "calibrated shift (min_gain 1)"], rows))
    per_dataset = {}
    for name in names:
        per_dataset.setdefault(dataset_of(name), []).extend(inputs[name])
    lines += ["", "Per dataset of the report frames:", ""]
    lines.append(H.markdown_table(["dataset"] + list(ways), [[d] + [f"{np.mean([s(i) for i in ins]):.3f}"
                                                                   for s in ways.values()]
                                                             for d, ins in per_dataset.items()]))
    lines += ["", "Per tuning frame (mean over densities × seeds), the frame's calibrated shift always applied:", ""]
    rows = [[f"`{f.name}`", f"{np.mean([i.ratio((0, 0)) for i in inputs[f.name]]):.3f}",
             f"{np.mean([i.ratio(pooled[f.name]) for i in inputs[f.name]]):.3f}", str(pooled[f.name])] for f in tune]
    lines.append(H.markdown_table(["frame", "unshifted", "calibrated, always applied", "calibrated shift"], rows))
    every = [i for n in names for i in inputs[n]]
    estimate_time = sum(i.estimate_seconds for i in every)
    solve_time = sum(i.solve_seconds[(0, 0)] for i in every)
    lines += ["", f"Time: estimating the shift took {estimate_time / solve_time:.2f} × the unshifted completions' "
              f"wall time on the report frames (max_shift {args.max_shift}, 4 folds, same run).", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
