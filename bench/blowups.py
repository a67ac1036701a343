"""What the local blow-up check catches (``docs/blowups.md``): :func:`sparsedepth.blowups.flag_blowups`.

Run from the repository root::

    python -m bench.blowups --out docs/blowups.md   # every shared frame at step 2, 3 seeds
    python -m bench.blowups --quick                 # synthetic frames only (smoke test)

Every input (a shared frame x a sampling pattern x a seed) is completed once with ``complete_depth(image, sparse,
mask)`` at the default settings, and scored on the valid ground-truth pixels not given to it.  The check's two
thresholds are chosen on the calibration frames (:data:`CALIBRATION_FRAMES` and two synthetic scenes) by
:func:`choose_thresholds`; the other shared frames only report.  ``tum/0`` at 10 % uniform is also run at full
resolution, the case of issue 46.

May import :mod:`sparsedepth`, numpy, :mod:`bench.blas` and :mod:`bench.harness`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import itertools  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.blowups import (BLOWUP_GAP, BLOWUP_MISFIT, BLOWUP_NEIGHBOURS, blowup_evidence,  # noqa: E402
                                 flag_blowups, judge_blowups, remove_blowups)

from . import harness as H  # noqa: E402

#: Calibration frames: the shared frames whose scenes hold no report frame of :mod:`bench.frames` (the thresholds
#: are chosen on these and the synthetic scenes of :func:`synthetic_frames` only).
CALIBRATION_FRAMES = ("middlebury2001/tsukuba", "nyu_mmseg_pseudo/bookstore_0001d_00001",
                      "realsense_d435/000000080", "realsense_d435/000000130")
#: Sampling patterns: (label, ``sd.sample_mask`` keywords).
PATTERNS = (("uniform 1 %", dict(fraction=0.01)), ("uniform 5 %", dict(fraction=0.05)),
            ("uniform 10 %", dict(fraction=0.10)), ("holes 0.7", dict(pattern="holes", fraction=0.7)),
            ("scan lines 8", dict(pattern="scan_lines", spacing=8)))
#: The grid of (gap, misfit) scored on the calibration frames.
GAPS, MISFITS = (0.05, 0.1, 0.15, 0.2, 0.3), (0.05, 0.1, 0.25, 0.5, 1.0)
#: The choice rule: among settings with at most MAX_FALSE of the flagged pixels' errors small and whose check costs
#: at most MAX_COST of the completion's CPU time, the one whose flagged pixels hold the largest share of the squared
#: error beyond their share of the pixels (what removing as many pixels at random would remove).
MAX_FALSE, MAX_COST = 0.10, 0.10
#: A flagged pixel's error is small (a false flag) when it is at most this share of the true depth.
SMALL_ERROR = 0.05


def synthetic_frames(step=1) -> list:
    """Two piecewise-planar scenes (``H.synthetic_frame`` at 240x320): a box whose depth edge the image shows, and
    the same depth under an image of the background's colour and noise (a depth edge the image hides: the
    blow-up case)."""
    shown = H.synthetic_frame((240 // step, 320 // step))
    noise = 8 * np.random.default_rng(1).standard_normal(shown.image.shape)
    hidden_image = np.clip(np.array([40, 90, 180]) + noise, 0, 255).astype(np.uint8)
    return [shown, H.FrameData("synthetic/hidden edge", hidden_image, shown.depth, 1)]


def _inputs(frame, keywords, seed):
    mask = sd.sample_mask(frame.depth, seed=seed, image=frame.image, **keywords)
    return np.where(mask, frame.depth, 0.0), mask


def record(frame, label, keywords, seed, thresholds) -> dict:
    """One input's scores: per (gap, misfit) in ``thresholds``, what the check flags and what removing or
    replacing the flagged pixels does to the RMSE."""
    sparse, mask = _inputs(frame, keywords, seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        cpu = time.process_time()
        depth = sd.complete_depth(frame.image, sparse, mask).depth
        complete_cpu = time.process_time() - cpu
    truth = frame.depth
    scored = sd.valid_depth_mask(truth) & ~mask
    nearest = sd.nearest_fill(sparse, mask)
    error = np.where(scored, depth - truth, 0.0)
    squared = error ** 2
    nearest_squared = np.where(scored, nearest - truth, 0.0) ** 2
    small = scored & (np.abs(error) <= SMALL_ERROR * np.where(scored, truth, 1.0))
    n, total, nearest_total = int(scored.sum()), squared.sum(), nearest_squared.sum()
    rec = {"frame": frame.name, "input": label, "seed": seed, "rmse": np.sqrt(total / n),
           "before": np.sqrt(total / nearest_total), "complete_cpu": complete_cpu}
    cpu = time.process_time()
    flag_blowups(depth, sparse, mask)
    rec["flag_cpu"] = time.process_time() - cpu
    for gap in sorted({g for g, _ in thresholds}, reverse=True):  # the smallest last: its evidence serves all
        cpu = time.process_time()
        evidence = blowup_evidence(depth, sparse, mask, gap=gap, neighbours=BLOWUP_NEIGHBOURS)
        rec["cost", gap] = (time.process_time() - cpu) / complete_cpu
    for gap, misfit in thresholds:
        flagged, inside = np.zeros(depth.shape, dtype=bool), np.zeros(depth.shape, dtype=bool)
        flagged[evidence["rows"], evidence["cols"]] = judge_blowups(evidence, gap=gap, misfit=misfit)
        inside[evidence["rows"], evidence["cols"]] = evidence["inside"]
        flagged_anywhere = flagged.sum() / (~mask).sum()
        flagged &= scored
        kept = scored & ~flagged
        replaced = remove_blowups(depth, flagged, replace="nearest", sparse_depth=sparse, mask=mask)
        replaced_squared = np.where(scored, replaced - truth, 0.0) ** 2
        rec[gap, misfit] = {
            "flagged": flagged.sum() / n,
            "anywhere": flagged_anywhere,
            "error_share": squared[flagged].sum() / total if total else 0.0,
            "false": small[flagged].sum() / max(1, flagged.sum()),
            "inside": inside[flagged].sum() / max(1, flagged.sum()),
            "removed": np.sqrt(squared[kept].sum() / max(nearest_squared[kept].sum(), np.finfo(float).tiny)),
            "kept": np.sqrt(squared[kept].sum() / max(1, kept.sum())) / rec["rmse"] if total else 1.0,
            "replaced": np.sqrt(replaced_squared.sum() / nearest_total),
        }
    return rec


def records(frames, patterns, seeds, thresholds) -> list[dict]:
    out = []
    for frame, (label, keywords), seed in itertools.product(frames, patterns, seeds):
        rec = record(frame, label, keywords, seed, thresholds)
        out.append(rec)
        scores = rec[(BLOWUP_GAP, BLOWUP_MISFIT) if (BLOWUP_GAP, BLOWUP_MISFIT) in rec else thresholds[0]]
        print(f"  {frame.name} {label} seed {seed}: flagged {100 * scores['flagged']:.2f} %, squared error "
              f"{100 * scores['error_share']:.0f} %", file=sys.stderr, flush=True)
    return out


def _mean(recs, key, field) -> float:
    return float(np.mean([r[key][field] for r in recs]))


def choose_thresholds(recs) -> tuple[tuple, list]:
    """The chosen (gap, misfit) and the calibration table's rows (means over calibration inputs)."""
    rows, admissible = [], []
    for gap, misfit in itertools.product(GAPS, MISFITS):
        flagged, share, false = (_mean(recs, (gap, misfit), k) for k in ("flagged", "error_share", "false"))
        cost = float(np.mean([r["cost", gap] for r in recs]))
        if false <= MAX_FALSE and cost <= MAX_COST:
            admissible.append(((gap, misfit), share - flagged))
        rows.append([f"{gap:g}", f"{misfit:g}", f"{100 * flagged:.2f} %", f"{100 * share:.1f} %",
                     f"{100 * (share - flagged):.1f} %", f"{100 * false:.1f} %", f"{cost:.3f}"])
    if not admissible:
        raise SystemExit("no (gap, misfit) of the grid meets the choice rule on the calibration frames")
    chosen = max(admissible, key=lambda item: item[1])[0]
    return chosen, rows


def _summary_rows(recs, key, by) -> list:
    rows = []
    for group_name in dict.fromkeys(r[by] for r in recs):
        group = [r for r in recs if r[by] == group_name]
        before = np.mean([r["before"] for r in group])
        rows.append([group_name, f"{100 * _mean(group, key, 'flagged'):.2f} %",
                     f"{100 * _mean(group, key, 'anywhere'):.2f} %",
                     f"{100 * _mean(group, key, 'error_share'):.0f} %", f"{100 * _mean(group, key, 'false'):.0f} %",
                     f"{100 * _mean(group, key, 'inside'):.0f} %",
                     f"{_mean(group, key, 'kept'):.3f}", f"{before:.3f}", f"{_mean(group, key, 'removed'):.3f}",
                     f"{_mean(group, key, 'replaced'):.3f}"])
    return rows


#: The columns of the summary tables after the first (input or frame).
HEADER = ["", "pixels flagged", "unobserved pixels flagged", "squared error in flagged pixels", "false flags",
          "flagged inside the samples' range", "RMSE of the rest / RMSE", "RMSE / nearest's",
          "after removal (kept pixels)", "after nearest replacement"]


def tables(recs, key) -> str:
    by_input = H.markdown_table(["input", *HEADER[1:]], _summary_rows(recs, key, "input"))
    by_frame = H.markdown_table(["frame", *HEADER[1:]], _summary_rows(recs, key, "frame"))
    return (f"By input (mean over frames and seeds):\n\n{by_input}\n\n"
            f"By frame (mean over inputs and seeds):\n\n{by_frame}")


def summary(cal_recs, rep_recs, tum_recs, key, chosen, seeds, step) -> list[str]:
    """The page's summary bullets, every number from this run."""
    def pct(recs, field, k=key):
        return 100 * _mean(recs, k, field)

    lines = []
    if tum_recs:
        cost = [r["flag_cpu"] / r["complete_cpu"] for r in tum_recs]
        lines.append(
            f"* `tum/0`, uniform 10 %, 640x480 (the case of issue 46), {len(tum_recs)} seeds: `flag_blowups` flags "
            f"{pct(tum_recs, 'flagged'):.2f} % of the scored pixels ({pct(tum_recs, 'anywhere'):.2f} % of all the "
            "unobserved pixels, ground truth or not), which hold "
            f"{pct(tum_recs, 'error_share'):.0f} % of "
            f"the completion's squared error; {pct(tum_recs, 'false'):.0f} % of them have a small error; "
            f"{pct(tum_recs, 'inside'):.0f} % of them lie inside the range of their {BLOWUP_NEIGHBOURS} nearest "
            "samples "
            "(values in the middle of a depth jump, which a local min/max test does not see). Removing them lowers "
            f"the RMSE of the rest to {_mean(tum_recs, key, 'kept'):.2f} of the RMSE. The check costs "
            f"{min(cost):.3f}-{max(cost):.3f} of the completion's CPU time.")
    if not rep_recs:
        return lines
    frames = list(dict.fromkeys(r["frame"] for r in rep_recs))
    by_frame = {f: [r for r in rep_recs if r["frame"] == f] for f in frames}
    false = sorted(frames, key=lambda f: -_mean(by_frame[f], key, "false"))
    lines.append(
        f"* The other frames ({len(frames)} frames at step {step} x {len(PATTERNS)} inputs x {len(seeds)} seeds): "
        f"{pct(rep_recs, 'flagged'):.2f} % of the pixels flagged, holding {pct(rep_recs, 'error_share'):.0f} % of "
        f"the squared error, {pct(rep_recs, 'false'):.0f} % false flags; the RMSE of the rest is "
        f"{_mean(rep_recs, key, 'kept'):.2f} of the RMSE. Most false flags: "
        + ", ".join(f"`{f}` {100 * _mean(by_frame[f], key, 'false'):.0f} %" for f in false[:3])
        + f"; calibration frames: {pct(cal_recs, 'false', chosen):.0f} %.")
    groups = [(by_frame[f], key) for f in frames] + [
        ([r for r in cal_recs if r["frame"] == f], chosen) for f in dict.fromkeys(r["frame"] for r in cal_recs)]
    worse = sum(_mean(g, k, "replaced") > np.mean([r["before"] for r in g]) for g, k in groups)
    inputs = [(r, key) for r in rep_recs] + [(r, chosen) for r in cal_recs]
    with_flags = [(r, k) for r, k in inputs if r[k]["error_share"] > 0]
    lower = sum(r[k]["kept"] < 1 for r, k in with_flags)
    lines.append(
        "* Removal or replacement: replacing the flagged pixels by the nearest sample's value raises the RMSE (over "
        f"nearest fill's) on {worse} of the {len(groups)} frames (calibration and report, mean over inputs); "
        f"setting them to NaN lowers the RMSE of the pixels that remain on {lower} of the {len(with_flags)} inputs "
        "where the flagged pixels hold some error, so `remove_blowups` sets NaN by default.")
    lines.append(
        f"* What it does not catch: {100 - pct(rep_recs, 'error_share'):.0f} % of the squared error on the other "
        "frames stays in pixels it does not flag: errors within τ of some nearby sample's value (a surface "
        "continued a little wrong, a value near one side of an edge), values between two rows of scan lines on "
        "the straight line between them, and pixels whose nearest samples all lie on one scan line. It also flags "
        "pixels whose error is small (the false-flag columns), "
        "most on the frames named above.")
    return lines


def run(argv=()) -> tuple[str, dict]:
    """``(markdown page, results)`` of a run with command-line arguments ``argv``."""
    args = H.parser("What the local blow-up check catches", default_step=2).parse_args(list(argv))
    started = time.perf_counter()
    command = H.command_line("blowups", argv)
    seeds = H.seeds_of(args)
    grid = list(itertools.product(GAPS, MISFITS))
    calibration = synthetic_frames(step=2 if args.quick else 1)
    if not args.quick:
        calibration += [H.load_frame(n, args.step) for n in CALIBRATION_FRAMES]
    cal_started = time.perf_counter()
    cal_recs = records(calibration, PATTERNS, seeds, grid)
    chosen, cal_rows = choose_thresholds(cal_recs)
    cal_elapsed = time.perf_counter() - cal_started
    if chosen != (BLOWUP_GAP, BLOWUP_MISFIT):
        print(f"note: the calibration chose {chosen}; sparsedepth.blowups has ({BLOWUP_GAP}, {BLOWUP_MISFIT})",
              file=sys.stderr)
    key = (BLOWUP_GAP, BLOWUP_MISFIT)
    if args.quick:
        report_frames = H.quick_frames()
    else:
        names = [n for n in sd.list_shared_frames() if n not in CALIBRATION_FRAMES]
        report_frames = [H.load_frame(n, args.step) for n in (args.frames or names)]
    rep_started = time.perf_counter()
    rep_recs = records(report_frames, PATTERNS, seeds, [key])
    rep_elapsed = time.perf_counter() - rep_started
    tum_recs = []
    if not args.quick and "tum/0" in sd.list_shared_frames():
        tum_recs = records([H.load_frame("tum/0", 1)], [PATTERNS[2]], seeds, [key])
    elapsed = time.perf_counter() - started
    definitions = (
        f"{H.step_note(args)} Inputs: `sd.sample_mask(depth, seed=s, image=image, ...)` with "
        + ", ".join(f"{label} (`{', '.join(f'{k}={v!r}' for k, v in kw.items())}`)" for label, kw in PATTERNS)
        + "; each completed by `sd.complete_depth(image, sparse, mask)` and scored on the valid ground-truth "
        "pixels not sampled. *Pixels flagged*: share of the scored pixels that `flag_blowups` flags; *unobserved "
        "pixels flagged*: "
        "share of all the pixels not sampled, ground truth or not. *Squared "
        "error in flagged pixels*: their share of the completion's squared error. *False flags*: share of the "
        f"flagged pixels whose error is at most {100 * SMALL_ERROR:g} % of the true depth. *Flagged inside the "
        "samples' range*: share of the flagged pixels whose depth lies between "
        f"the smallest and the largest of their {BLOWUP_NEIGHBOURS} nearest samples (a local min/max test passes "
        "them). *RMSE of the rest / RMSE*: the "
        "completion's RMSE over the pixels not flagged, over its RMSE over all scored pixels. *RMSE / nearest's*: the "
        "completion's RMSE over nearest fill's (`sd.nearest_fill`). *After removal*: the same ratio over the "
        "pixels that remain when the flagged ones are set to NaN (`remove_blowups(..., replace=\"nan\")`; nearest "
        "fill scored on the same pixels). *After nearest replacement*: the ratio over all scored pixels when the "
        "flagged ones take the nearest sample's value (`remove_blowups(..., replace=\"nearest\")`).")
    cal_section = H.section(
        "Calibration: choosing the thresholds", command=command, frames_=calibration, seeds=seeds,
        body=H.markdown_table(["gap τ", "misfit ρ", "pixels flagged", "squared error in flagged pixels",
                               "error share − pixel share", "false flags", "CPU time / completion's"], cal_rows)
        + f"\n\nChosen: **τ = {chosen[0]:g}, ρ = {chosen[1]:g}**: the largest share of the squared error beyond the "
          "share of the pixels flagged (what removing as many pixels at random would remove) among the settings with "
          f"at most {100 * MAX_FALSE:g} % false flags whose check costs at most {100 * MAX_COST:g} % of the "
          "completion's CPU time (`time.process_time()` of `blowup_evidence` at that τ over `complete_depth`'s, one "
          "run each), means over the calibration inputs. `sparsedepth.blowups` has "
          f"τ = {BLOWUP_GAP:g}, "
          f"ρ = {BLOWUP_MISFIT:g}, K = {BLOWUP_NEIGHBOURS}.\n\nAt the chosen thresholds:\n\n"
          + tables(cal_recs, chosen),
        notes=definitions + " Calibration frames: the two synthetic scenes of `bench.blowups.synthetic_frames` "
        "(a box whose depth edge the image shows; the same depth under an image of the background's colour and "
        "noise) and "
        + ", ".join(f"`{n}`" for n in CALIBRATION_FRAMES) + " (scenes with no report frame of `bench/frames.py`).",
        elapsed=cal_elapsed)
    rep_section = H.section(
        "The other frames (not used to choose the thresholds)", command=command, frames_=report_frames, seeds=seeds,
        body=tables(rep_recs, key), notes=definitions, elapsed=rep_elapsed)
    parts = [cal_section, rep_section]
    if tum_recs:
        cost = [r["flag_cpu"] / r["complete_cpu"] for r in tum_recs]
        parts.append("\n".join([
            "## tum/0, uniform 10 %, 640x480 (issue 46)", "",
            H.markdown_table(["seed", "RMSE (m)", "pixels flagged", "unobserved pixels flagged",
                              "squared error in flagged pixels", "false flags",
                              "flagged inside the samples' range", "RMSE of the rest / RMSE", "RMSE / nearest's",
                              "after removal", "after nearest replacement", "check's CPU time / completion's"],
                             [[r["seed"], f"{r['rmse']:.4f}",
                               f"{100 * r[key]['flagged']:.2f} %", f"{100 * r[key]['anywhere']:.2f} %",
                               f"{100 * r[key]['error_share']:.0f} %",
                               f"{100 * r[key]['false']:.0f} %", f"{100 * r[key]['inside']:.0f} %",
                               f"{r[key]['kept']:.3f}", f"{r['before']:.3f}", f"{r[key]['removed']:.3f}",
                               f"{r[key]['replaced']:.3f}", f"{c:.3f}"] for r, c in zip(tum_recs, cost)]), "",
            "CPU times are `time.process_time()` of one run each (one BLAS thread): `flag_blowups(depth, sparse, "
            "mask)` over `complete_depth(image, sparse, mask)`.", ""]))
    page = "\n".join([
        "# Local blow-ups: what `flag_blowups` catches", "",
        f"Written by `{command}` in {elapsed:.0f} s wall time (all sections).", "",
        f"Machine: {H.machine_markdown()}.", "",
        "`sparsedepth.blowups.flag_blowups(depth, sparse, mask)` flags the completed pixels farther than τ times "
        f"their depth from the value of each of their {BLOWUP_NEIGHBOURS} nearest samples, unless those samples lie "
        "on a plane, in depth or in inverse depth (RMS residual below ρ times that gap), that predicts the pixel's "
        "depth within τ times the depth, or lie on one line (then no plane is determined and the pixel is not "
        "judged); the docstring has the rule.  `remove_blowups` sets the flagged pixels to NaN or to the nearest "
        "sample's value.", "",
        "Summary (numbers of this run, details below):", "",
        *summary(cal_recs, rep_recs, tum_recs, key, chosen, seeds, args.step), "",
        *parts])
    return page, {"chosen": chosen, "calibration": cal_recs, "report": rep_recs, "tum": tum_recs}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    out = H.parser("", default_step=2).parse_args(argv).out
    text, _ = run(argv)
    return H.publish([text], out)


if __name__ == "__main__":
    sys.exit(main())
