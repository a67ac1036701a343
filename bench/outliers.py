"""Do SfM-like outliers cost enough to be worth rejecting before a completion? (``docs/outliers.md``)

Run from the repository root::

    python -m bench.outliers --out docs/outliers.md   # ~12 min on 2 shared cores
    python -m bench.outliers --quick                 # tiny frames (smoke test)

Inputs as :mod:`bench.colmap_scene`'s SfM-like section (``sd.sample_depth(..., pattern="keypoints", count=N,
noise=0.01, outliers=p, outlier_range=(0.7, 1.3))``, N = 500 and 2000) and a uniform 5 % input with the same
corruption, at outlier shares p = 0, 2 % and 5 %.  The clean counterpart of an input (p = 0, same seed) has the same
pixels and the same noise: only the outliers differ, so the true outliers are known.  Three completions of each
input are scored on the hidden valid pixels:

* ``default``: ``complete_depth(image, sparse, mask)`` from every sample;
* ``oracle``: the same without the true outliers (the most any rejection can gain);
* ``leave-out rejection``: the same without the samples flagged by :func:`leave_out_flags` (k-fold leave-out
  prediction by the fast mode, a threshold on the log ratio over a robust scale), its threshold chosen on the
  tuning frames (:data:`TUNE_FRAMES`, scenes without a report frame) by :func:`tuning_section`.

May import :mod:`sparsedepth`, numpy, :mod:`bench.blas`, :mod:`bench.frames` and :mod:`bench.harness`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import itertools  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402
from scipy import ndimage  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.modes.fast import complete_fast  # noqa: E402

from . import harness as H  # noqa: E402

#: The inputs: (pattern, keypoint count or uniform fraction); ``--quick`` uses :data:`QUICK_INPUTS`.
INPUTS = (("keypoints", 500), ("keypoints", 2000), ("uniform", 0.05))
QUICK_INPUTS = (("keypoints", 50), ("keypoints", 200), ("uniform", 0.05))
#: Outlier shares, relative noise and the outliers' factor range (as :mod:`bench.colmap_scene`).
LEVELS, NOISE, OUTLIER_RANGE = (0.0, 0.02, 0.05), 0.01, (0.7, 1.3)
#: Tuning frames: the shared frames whose scenes hold no report frame (``sd.datasets.shared_frame_scenes()``)
#: that are small enough for this run; the two RealSense frames (1280x720) are left out for time.
TUNE_FRAMES = ("middlebury2001/tsukuba", "nyu_mmseg_pseudo/bookstore_0001d_00001")
#: Thresholds tried on the tuning frames (robust scales), folds of the leave-out and the relative floor.
THRESHOLDS, FOLDS, RELATIVE_FLOOR = (5.0, 8.0, 12.0, 20.0), 5, 0.05
#: What "pays" means (issue 48): mean RMSE gain at 2 % outliers and largest mean loss on clean inputs.
REQUIRED_GAIN, ALLOWED_CLEAN_LOSS = 0.03, 0.005
#: The depth-edge band of the ground truth (:func:`depth_edge_band`): relative 3x3 depth range and half-width (px).
EDGE_JUMP, EDGE_BAND = 0.05, 2


def leave_out_flags(image, sparse, mask, *, threshold, folds=FOLDS, floor=RELATIVE_FLOOR, seed=0) -> np.ndarray:
    """The samples a leave-out prediction calls outliers (a bool map, True at a flagged sample).

    The samples are dealt at random (``seed``) to ``folds`` folds; each fold's samples are predicted by a fast
    completion (``quality="fast"``) of the others.  With ``r_i = log(z_i / ẑ_i)``, ``m`` the median of the ``r_i``
    and ``s = 1.4826 · median |r_i − m|``, sample i is flagged when ``|r_i − m| > threshold · s`` and
    ``|r_i − m| > floor`` (outliers are multiplicative; the floor keeps a clean plane's samples).
    """
    rows, cols = np.nonzero(mask)
    fold_of = np.random.default_rng(seed).permutation(rows.size) % folds
    predicted = np.empty(rows.size)
    for fold in range(folds):
        held = fold_of == fold
        keep = mask.copy()
        keep[rows[held], cols[held]] = False
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sd.ClampWarning)
            depth = complete_fast(image, np.where(keep, sparse, np.nan), keep).depth
        predicted[held] = depth[rows[held], cols[held]]
    log_ratio = np.log(sparse[rows, cols] / np.maximum(predicted, np.finfo(float).tiny))
    deviation = np.abs(log_ratio - np.median(log_ratio))
    scale = 1.4826 * np.median(deviation)
    flagged = np.zeros(mask.shape, dtype=bool)
    flagged[rows, cols] = (deviation > threshold * scale) & (deviation > floor)
    return flagged


def depth_edge_band(depth) -> np.ndarray:
    """Valid pixels within :data:`EDGE_BAND` pixels of a ground-truth depth edge.

    A valid pixel is on an edge when the depth range of its 3x3 neighbourhood (valid pixels only) exceeds
    :data:`EDGE_JUMP` times its depth (as ``sparsedepth.sampling.HOLE_EDGE_JUMP`` marks a sensor's edge pixels);
    the band is those pixels widened by a square of side ``2 · EDGE_BAND + 1``.
    """
    valid = sd.valid_depth_mask(depth)
    local_max = ndimage.maximum_filter(np.where(valid, depth, -np.inf), size=3, mode="nearest")
    local_min = ndimage.minimum_filter(np.where(valid, depth, np.inf), size=3, mode="nearest")
    with np.errstate(invalid="ignore"):
        edge = valid & (local_max - local_min > EDGE_JUMP * np.where(valid, depth, 1.0))
    return valid & ndimage.maximum_filter(edge, size=2 * EDGE_BAND + 1)


def _completion(image, sparse, mask) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        return sd.complete_depth(image, sparse, mask).depth


def _inputs(frame, pattern, amount, level, seed):
    """``(sparse, mask, true outliers)`` of one input."""
    kwargs = dict(pattern=pattern, seed=seed, noise=NOISE, outlier_range=OUTLIER_RANGE)
    if pattern == "keypoints":
        kwargs.update(image=frame.image, count=amount)
    else:
        kwargs.update(fraction=amount)
    clean, mask = sd.sample_depth(frame.depth, outliers=0.0, **kwargs)
    sparse, same = sd.sample_depth(frame.depth, outliers=level, **kwargs)
    assert np.array_equal(mask, same)
    return sparse, mask, mask & (sparse != clean)


def _label(pattern, amount) -> str:
    return f"keypoints {amount}" if pattern == "keypoints" else f"uniform {100 * amount:g} %"


def records(frames, inputs, seeds, thresholds, oracle=True) -> list[dict]:
    """One record per frame, input, level and seed: RMSE/MAE of each completion, what each rejection dropped."""
    out = []
    bands = {frame.name: depth_edge_band(frame.depth) for frame in frames}
    for frame, (pattern, amount), seed, level in itertools.product(frames, inputs, seeds, LEVELS):
        sparse, mask, outlier = _inputs(frame, pattern, amount, level, seed)
        hidden, band = ~mask, bands[frame.name]
        rec = {"frame": frame.name, "input": _label(pattern, amount), "seed": seed, "level": level,
               "samples": int(mask.sum()), "outliers": int(outlier.sum()),
               "inliers_at_edges": int((mask & ~outlier & band).sum())}
        metrics = sd.depth_metrics(_completion(frame.image, sparse, mask), frame.depth, mask=hidden)
        rec["default"] = (float(metrics.rmse), float(metrics.mae))
        if oracle:
            if outlier.any():
                metrics = sd.depth_metrics(_completion(frame.image, sparse, mask & ~outlier), frame.depth,
                                           mask=hidden)
            rec["oracle"] = (float(metrics.rmse), float(metrics.mae))
        for threshold in thresholds:
            started = time.perf_counter()
            flagged = leave_out_flags(frame.image, sparse, mask, threshold=threshold)
            seconds = time.perf_counter() - started
            metrics = sd.depth_metrics(_completion(frame.image, sparse, mask & ~flagged), frame.depth, mask=hidden)
            rec[threshold] = {"rmse": float(metrics.rmse), "mae": float(metrics.mae), "seconds": seconds,
                              "inliers_dropped": int((flagged & ~outlier).sum()),
                              "inliers_dropped_at_edges": int((flagged & ~outlier & band).sum()),
                              "outliers_found": int((flagged & outlier).sum())}
        out.append(rec)
        print(f"  {frame.name} {rec['input']} seed {seed} {100 * level:g} %: default RMSE {rec['default'][0]:.4g}, "
              + ", ".join(f"t={t:g} {rec[t]['rmse'] / rec['default'][0]:.3f}" for t in thresholds),
              file=sys.stderr, flush=True)
    return out


def _ratio(recs, key, reference="default", index=0) -> float:
    """Mean over records of ``key``'s RMSE (``index`` 0) or MAE (1) over ``reference``'s."""
    def value(rec, name):
        v = rec[name]
        return v[("rmse", "mae")[index]] if isinstance(v, dict) else v[index]
    return float(np.mean([value(r, key) / value(r, reference) for r in recs]))


def _clean_reference(recs, all_recs):
    """For each record, its clean counterpart (same frame, input, seed, level 0)."""
    clean = {(r["frame"], r["input"], r["seed"]): r for r in all_recs if r["level"] == 0}
    return [clean[r["frame"], r["input"], r["seed"]] for r in recs]


def choose_threshold(recs, thresholds) -> tuple[float, list]:
    """The tuned threshold and the tuning table's rows.

    Per threshold: the mean RMSE ratio to ``default`` on the clean inputs and at 2 % outliers.  Chosen: the
    threshold with the lowest ratio at 2 % among those losing at most :data:`ALLOWED_CLEAN_LOSS` on clean inputs;
    if none does, the one losing least on clean inputs.
    """
    rows, scores = [], {}
    for threshold in thresholds:
        clean = _ratio([r for r in recs if r["level"] == 0], threshold)
        at2 = _ratio([r for r in recs if r["level"] == 0.02], threshold)
        at5 = _ratio([r for r in recs if r["level"] == 0.05], threshold)
        dropped = np.sum([r[threshold]["inliers_dropped"] for r in recs]) / np.sum(
            [r["samples"] - r["outliers"] for r in recs])
        scores[threshold] = (clean, at2)
        rows.append([f"{threshold:g}", f"{clean:.3f}", f"{at2:.3f}", f"{at5:.3f}", f"{100 * dropped:.1f} %"])
    admissible = [t for t in thresholds if scores[t][0] <= 1 + ALLOWED_CLEAN_LOSS]
    chosen = min(admissible, key=lambda t: scores[t][1]) if admissible else min(thresholds, key=lambda t: scores[t][0])
    return chosen, rows


def report_tables(recs, threshold) -> tuple[str, dict]:
    """The report frames' tables: cost of outliers, the oracle's and the rejection's gains, what was dropped."""
    labels = list(dict.fromkeys(r["input"] for r in recs))
    rows, stats = [], {}
    for label, level in itertools.product(labels, LEVELS):
        group = [r for r in recs if r["input"] == label and r["level"] == level]
        clean = _clean_reference(group, recs)
        cost = np.mean([r["default"][0] / c["default"][0] for r, c in zip(group, clean)])
        oracle = _ratio(group, "oracle")
        rejection = _ratio(group, threshold)
        mae_rejection = _ratio(group, threshold, index=1)
        inliers = np.sum([r["samples"] - r["outliers"] for r in group])
        dropped = np.sum([r[threshold]["inliers_dropped"] for r in group]) / inliers
        found = (np.sum([r[threshold]["outliers_found"] for r in group])
                 / max(1, np.sum([r["outliers"] for r in group])))
        seconds = np.mean([r[threshold]["seconds"] for r in group])
        dropped_count = np.sum([r[threshold]["inliers_dropped"] for r in group])
        at_edges = np.sum([r[threshold]["inliers_dropped_at_edges"] for r in group]) / max(1, dropped_count)
        edge_share = np.sum([r["inliers_at_edges"] for r in group]) / inliers
        stats[label, level] = {"cost": cost, "oracle": oracle, "rejection": rejection}
        rows.append([label, f"{100 * level:g} %", f"{cost:.3f}", f"{oracle:.3f}", f"{rejection:.3f}",
                     f"{mae_rejection:.3f}", f"{100 * found:.0f} %" if level else "–", f"{100 * dropped:.1f} %",
                     f"{100 * at_edges:.0f} % (of all inliers: {100 * edge_share:.0f} %)", f"{seconds:.2f}"])
    table = H.markdown_table(
        ["input", "outliers", "default RMSE / clean default's", "oracle RMSE / default's",
         f"rejection (t = {threshold:g}) RMSE / default's", "rejection MAE / default's", "outliers found",
         "true inliers dropped", "dropped inliers at depth edges", "rejection time (s)"], rows)
    per_frame = []
    for frame in dict.fromkeys(r["frame"] for r in recs):
        row = [frame]
        for label in labels:
            group = [r for r in recs if r["frame"] == frame and r["input"] == label]
            row.append(" / ".join(f"{_ratio([r for r in group if r['level'] == lv], threshold):.3f}"
                                  for lv in LEVELS))
        per_frame.append(row)
    frame_table = H.markdown_table(["frame", *(f"{label}: rejection / default at 0 / 2 / 5 %" for label in labels)],
                                   per_frame)
    return table + "\n\nPer frame, RMSE of the rejection over the default's (mean over seeds):\n\n" + frame_table, stats


def run(argv=()) -> tuple[str, dict]:
    """``(markdown page, results)`` of a run with command-line arguments ``argv``."""
    args = H.parser("Do SfM-like outliers cost enough to reject them?", default_step=1).parse_args(list(argv))
    started = time.perf_counter()
    command = H.command_line("outliers", argv)
    seeds = H.seeds_of(args)
    inputs = QUICK_INPUTS if args.quick else INPUTS
    tune_frames = H.quick_frames() if args.quick else [H.load_frame(n, args.step) for n in TUNE_FRAMES]
    tune_started = time.perf_counter()
    tune_recs = records(tune_frames, inputs, seeds, THRESHOLDS, oracle=False)
    threshold, tune_rows = choose_threshold(tune_recs, THRESHOLDS)
    tune_elapsed = time.perf_counter() - tune_started
    frames = H.get_frames(args)
    report_started = time.perf_counter()
    recs = records(frames, inputs, seeds, (threshold,))
    body, stats = report_tables(recs, threshold)
    report_elapsed = time.perf_counter() - report_started
    key = [label for label in dict.fromkeys(r["input"] for r in recs) if label.startswith("keypoints")]
    gain = np.mean([1 - stats[label, 0.02]["rejection"] for label in key])
    clean_loss = np.mean([stats[label, 0.0]["rejection"] - 1 for label in key])
    oracle_gain = np.mean([1 - stats[label, 0.02]["oracle"] for label in key])
    pays = gain >= REQUIRED_GAIN and clean_loss <= ALLOWED_CLEAN_LOSS
    setup = (
        f"{H.step_note(args)} Inputs: `sd.sample_depth(depth, pattern=\"keypoints\", image=image, count=N, seed=s, "
        f"noise={NOISE:g}, outliers=p, outlier_range={OUTLIER_RANGE})` with N in "
        f"{[a for p, a in inputs if p == 'keypoints']}, and the same with `pattern=\"uniform\", fraction=0.05`; "
        f"p in {[f'{100 * lv:g} %' for lv in LEVELS]}. The input at p = 0 with the same seed has the same pixels and "
        "noise, so the true outliers are the samples that differ from it. Completions, all `complete_depth(image, "
        "sparse, mask)` with the default settings, scored (RMSE, MAE) on the valid ground-truth pixels not given to "
        "the method: `default` from every sample; `oracle` without the true outliers; `rejection` without the "
        "samples flagged by `bench.outliers.leave_out_flags`: the samples dealt at random to "
        f"{FOLDS} folds, each fold predicted by `complete_depth(..., quality=\"fast\")` of the other folds, "
        "r = log(sample / prediction), flagged when |r − median r| exceeds t times 1.4826 · median |r − median r| "
        f"and {RELATIVE_FLOOR:g}. 'Outliers found' is the share of true outliers flagged, 'true inliers dropped' the "
        "share of the other samples flagged; 'dropped inliers at depth edges' the share of those within "
        f"{EDGE_BAND} px of a ground-truth depth edge (a 3x3 depth range above {100 * EDGE_JUMP:g} % of the depth; "
        "`bench.outliers.depth_edge_band`), next to the share of all true inliers that lie there.")
    tuning = H.section(
        "Tuning the threshold (tuning frames)", command=command, frames_=tune_frames, seeds=seeds,
        body=H.markdown_table(["t", "RMSE / default's, clean", "at 2 % outliers", "at 5 % outliers",
                               "true inliers dropped (all levels)"], tune_rows)
        + f"\n\nChosen: **t = {threshold:g}** (the lowest RMSE at 2 % outliers among the thresholds losing at most "
          f"{100 * ALLOWED_CLEAN_LOSS:g} % on clean inputs, or, when none does, the one losing least).\n",
        notes=setup + f" Frames: {', '.join(f'`{n}`' for n in TUNE_FRAMES)} (scenes with no report frame; the two "
        "RealSense tuning frames, 1280x720, are left out to keep the run short). RMSE ratios: mean over frames x "
        "inputs x seeds of the rejection's RMSE over the default's on the same input.",
        elapsed=tune_elapsed)
    report = H.section(
        "Cost of outliers and what rejecting them gains (report frames)", command=command, frames_=frames,
        seeds=seeds, body=body,
        notes=setup + " Ratios: mean over frames x seeds; 'default RMSE / clean default's' is the cost of the "
        "outliers, the oracle's ratio the most any rejection could gain, the rejection's ratio what it gains "
        "(below 1) or loses (above 1).",
        elapsed=report_elapsed)
    def change(ratio) -> str:
        return f"{100 * (ratio - 1):+.1f} %"

    uniform = [label for label in dict.fromkeys(r["input"] for r in recs) if label.startswith("uniform")]
    verdict = [
        "* Keypoint inputs (the SfM case), mean over " + " and ".join(k.split()[1] for k in key) + " points: "
        f"RMSE change of the default caused by 2 % outliers {change(np.mean([stats[k, 0.02]['cost'] for k in key]))}"
        f", by 5 % {change(np.mean([stats[k, 0.05]['cost'] for k in key]))}; removing exactly the true outliers "
        f"(oracle) changes it by {change(1 - oracle_gain)} at 2 %.",
        f"* Leave-out rejection (t = {threshold:g}, tuned on the tuning frames), keypoint inputs: RMSE change "
        f"{change(1 - gain)} at 2 % outliers, {change(1 + clean_loss)} on clean inputs.",
        *[f"* {label.capitalize()} input: RMSE change by 2 % outliers {change(stats[label, 0.02]['cost'])}; the oracle "
          f"{change(stats[label, 0.02]['oracle'])}, the rejection {change(stats[label, 0.02]['rejection'])} at 2 % "
          f"(clean inputs: {change(stats[label, 0.0]['rejection'])})." for label in uniform],
        f"* Verdict: {'it pays' if pays else 'it does not pay'} by issue 48's bar (a mean RMSE gain of at least "
        f"{100 * REQUIRED_GAIN:g} % at 2 % outliers on keypoint inputs, a loss of at most "
        f"{100 * ALLOWED_CLEAN_LOSS:g} % on clean ones)" + ("." if pays else ": no outlier rejection in the library.")]
    elapsed = time.perf_counter() - started
    page = "\n".join([
        "# Rejecting outlying depth samples before a completion", "",
        f"Written by `{command}` in {elapsed:.0f} s wall time (all sections).", "",
        f"Machine: {H.machine_markdown()}.", "",
        "What is measured: how much a few percent of gross outliers (samples multiplied by a factor in "
        f"U{OUTLIER_RANGE}, as SfM points carry) raise the RMSE of the default completion, how much removing exactly "
        "those outliers would gain (oracle), and how much a leave-out rejection gains and loses, with its threshold "
        "tuned on frames of other scenes.", "",
        "Summary (numbers of this run, details below):", "",
        *verdict, "",
        tuning, report])
    return page, {"threshold": threshold, "stats": stats, "gain": gain, "clean_loss": clean_loss, "pays": pays}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    out = H.parser("", default_step=1).parse_args(argv).out
    text, _ = run(argv)
    return H.publish([text], out)


if __name__ == "__main__":
    sys.exit(main())
