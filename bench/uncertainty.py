"""Uncertainty: how well ``result.uncertainty`` ranks and covers the errors of the hidden pixels.

Run (full, ~10-30 minutes on 2 cores)::

    python -m bench.uncertainty --out docs/uncertainty.md

or ``--quick`` for a smoke test on tiny frames.  Frames are
:data:`frames.REPORT_FRAMES` at full resolution (``--step 1``), never the
tuning frames; the sparse input keeps 1 %, 5 % and 10 % of the valid ground
truth at random (seeds 0, 1, 2; ``--seeds`` to change).  For each input,
``complete_depth(..., uncertainty=True)`` with the default weights; scored on
the valid ground-truth pixels the method did not see:

* **ranking**: RMSE over the half of the hidden pixels with the lowest
  uncertainty divided by the RMSE over all hidden pixels (lower is better;
  sorting by the true error gives the floor), beside the same ratio for the
  simple cues "nearest dev." ``|z - z_nn|``, "slope × dist." ``|grad z| d``
  (``d`` the distance to the nearest sample), their sum, and ``d`` alone;
* **coverage**: fraction of hidden pixels with ``|error| <= sigma`` and
  ``<= 2 sigma``, beside the same fractions on the held-out observations the
  calibration was fitted on;
* **cost**: runtime with ``uncertainty=True`` divided by the runtime without
  (same process, same input).

May import :mod:`bench.harness`.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path
from string import Template

import numpy as np
from scipy import ndimage

import sparsedepth as sd
from sparsedepth import uncertainty as unc
from sparsedepth.solvers.quadratic import DEFAULT_DEPTH_RTOL

from . import harness as H

TEMPLATE = Path(__file__).resolve().parent / "templates" / "uncertainty.md"
DEFAULT_STEP = 1
DEFAULT_SEEDS = (0, 1, 2)
#: The target of the ranking ratio (RMSE of the better half / RMSE of all hidden pixels).
RANKING_TARGET = 0.12
#: The coverage windows at 1 and 2 sigma.
COVERAGE_WINDOWS = ((0.60, 0.76), (0.90, 0.98))

CUES = ("ours", "nearest dev.", "slope × dist.", "nearest dev. + slope × dist.", "distance", "true error")


def ranking_ratio(errors, score) -> float:
    """RMSE over the half of ``errors`` with the lowest ``score``, divided by the RMSE over all."""
    order = np.argsort(score, kind="stable")
    better = errors[order[: errors.size // 2]]
    return float(np.sqrt(np.mean(better ** 2)) / np.sqrt(np.mean(errors ** 2)))


def simple_cues(depth, sparse, observed) -> dict:
    """The single-completion cues the ranking is compared with, as (H, W) maps."""
    distance, (rows, cols) = ndimage.distance_transform_edt(~observed, return_indices=True)
    nearest = np.where(observed, sparse, 0.0)[rows, cols]
    grad_rows, grad_cols = np.gradient(depth)
    difference = np.abs(depth - nearest)
    slope = np.hypot(grad_rows, grad_cols) * distance
    return {"nearest dev.": difference, "slope × dist.": slope, "nearest dev. + slope × dist.": difference + slope,
            "distance": distance}


def evaluate(frame, fraction, seed) -> dict:
    """One input: the ranking ratios, coverages and cost of the uncertainty."""
    sparse, mask = H.sample(frame, fraction=fraction, seed=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        start = time.perf_counter()
        sd.complete_depth(frame.image, sparse, mask)
        plain = time.perf_counter() - start
        start = time.perf_counter()
        result = sd.complete_depth(frame.image, sparse, mask, uncertainty=True)
        with_uncertainty = time.perf_counter() - start
    hidden = np.isfinite(frame.depth) & ~mask
    errors = np.abs(result.depth - frame.depth)[hidden]
    sigma = result.uncertainty[hidden]
    maps = {"ours": result.uncertainty, **simple_cues(result.depth, sparse, mask)}
    ranking = {name: ranking_ratio(errors, value[hidden]) for name, value in maps.items()}
    ranking["true error"] = ranking_ratio(errors, errors)
    cal = result.uncertainty_calibration
    return dict(frame=frame.name, fraction=fraction, seed=seed, ranking=ranking,
                cover1=float(np.mean(errors <= sigma)), cover2=float(np.mean(errors <= 2 * sigma)),
                held1=cal.coverage_1sigma, held2=cal.coverage_2sigma, held_out=cal.held_out,
                cost=with_uncertainty / plain)


def _mean(rows, key):
    return float(np.mean([key(r) for r in rows]))


def summary_table(records, fractions) -> str:
    header = ["observed", *[f"rank: {c}" for c in CUES], "≤ 1σ", "≤ 2σ", "held-out ≤ 1σ", "held-out ≤ 2σ",
              "time × plain"]
    rows = []
    for frac in fractions:
        sel = [r for r in records if r["fraction"] == frac]
        rows.append([f"{frac:.0%}", *[H.fmt(_mean(sel, lambda r, c=c: r["ranking"][c])) for c in CUES],
                     H.fmt(_mean(sel, lambda r: r["cover1"])), H.fmt(_mean(sel, lambda r: r["cover2"])),
                     H.fmt(_mean(sel, lambda r: r["held1"])), H.fmt(_mean(sel, lambda r: r["held2"])),
                     H.fmt(_mean(sel, lambda r: r["cost"]), digits=1)])
    return H.markdown_table(header, rows)


def per_frame_table(records) -> str:
    header = ["frame", "observed", "seed", "rank: ours", "rank: nearest dev. + slope × dist.", "rank: true error",
              "≤ 1σ", "≤ 2σ", "held-out obs."]
    rows = [[r["frame"], f"{r['fraction']:.0%}", str(r["seed"]), H.fmt(r["ranking"]["ours"]),
             H.fmt(r["ranking"]["nearest dev. + slope × dist."]), H.fmt(r["ranking"]["true error"]),
             H.fmt(r["cover1"]), H.fmt(r["cover2"]), str(r["held_out"])] for r in records]
    return H.markdown_table(header, rows)


def verdict(records, fractions) -> str:
    """One line per target: met or not, with the numbers."""
    lines = []
    for frac in fractions:
        sel = [r for r in records if r["fraction"] == frac]
        rank = _mean(sel, lambda r: r["ranking"]["ours"])
        c1, c2 = _mean(sel, lambda r: r["cover1"]), _mean(sel, lambda r: r["cover2"])
        (lo1, hi1), (lo2, hi2) = COVERAGE_WINDOWS
        lines.append(
            f"- {frac:.0%}: ranking {rank:.3f} ({'meets' if rank <= RANKING_TARGET else 'misses'} ≤ "
            f"{RANKING_TARGET}); coverage {c1:.3f} at 1σ ({'in' if lo1 <= c1 <= hi1 else 'outside'} "
            f"{lo1}–{hi1}), {c2:.3f} at 2σ ({'in' if lo2 <= c2 <= hi2 else 'outside'} {lo2}–{hi2}).")
    return "\n".join(lines)


def run(argv=None):
    """Run the benchmark; returns ``(markdown, records)``."""
    p = H.parser(__doc__.splitlines()[0], default_step=DEFAULT_STEP)
    p.set_defaults(seeds=list(DEFAULT_SEEDS))
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    frames = H.get_frames(args)
    seeds = H.seeds_of(args)
    records = []
    for frame in frames:
        for frac in H.FRACTIONS:
            for seed in seeds:
                records.append(evaluate(frame, frac, seed))
                print(f"  {frame.name} {frac:.0%} seed {seed}: ranking {records[-1]['ranking']['ours']:.3f}",
                      file=sys.stderr, flush=True)
    body = ("Means over frames × seeds, per observed fraction. Targets: ranking ≤ "
            f"{RANKING_TARGET}; coverage {COVERAGE_WINDOWS[0][0]}–{COVERAGE_WINDOWS[0][1]} at 1σ and "
            f"{COVERAGE_WINDOWS[1][0]}–{COVERAGE_WINDOWS[1][1]} at 2σ.\n\n" + verdict(records, H.FRACTIONS)
            + "\n\n" + summary_table(records, H.FRACTIONS) + "\n\nPer input:\n\n" + per_frame_table(records))
    notes = (H.step_note(args) + " Cues: nearest dev. = |z − z_nn| (z_nn the nearest-sample fill), slope × dist. = "
             "|∇z| · d (d the distance to the nearest sample in pixels), distance = d. `rank: X` is the RMSE over the half of the hidden pixels with the lowest X "
             "divided by the RMSE over all hidden pixels; `held-out` columns are the calibration's own coverage "
             "on the observations each half-sample completion did not see.")
    section = H.section("Measured on the report frames", command=H.command_line("uncertainty", argv or []),
                        frames_=frames, seeds=seeds, body=body, notes=notes, elapsed=time.perf_counter() - t0)
    text = Template(TEMPLATE.read_text()).substitute(
        section=section, target1=f"{unc.TARGET_COVERAGE[0]:.0%}", target2=f"{unc.TARGET_COVERAGE[1]:.0%}",
        neighbours=unc.NOVELTY_NEIGHBOURS, novelty=f"{unc.NOVELTY_WEIGHT:.0%}",
        precision=f"{DEFAULT_DEPTH_RTOL:.0e}".replace("e-0", "e-"),
        cover1=f"{_mean(records, lambda r: r['cover1']):.0%}",
        cover2=f"{_mean(records, lambda r: r['cover2']):.0%}", cost=f"{_mean(records, lambda r: r['cost']):.1f}")
    return text, records


def main(argv=None) -> int:
    p = H.parser(__doc__.splitlines()[0], default_step=DEFAULT_STEP)
    return H.script_main(run, p.parse_args(argv), argv)


if __name__ == "__main__":
    sys.exit(main())
