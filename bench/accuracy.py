"""Accuracy ablation of modelling variants: tuned on the tuning frames, reported on unseen frames and datasets.

Each row is one direction of modelling as its own configuration (fields of :class:`sparsedepth.Weights`; every
other weight is that of the baseline, the library's defaults with the modelling fields off):

* ``edge_sigma`` - the image blurred by a Gaussian before every edge weight;
* ``fill_contrast`` (with a larger ``delta``) - the geodesic, image-aware nearest-sample fill as the prior ``z_c``;
* ``depth_jump`` - one re-solve with the image smoothness relaxed where the first solution jumps;
* combinations of the above;
* ``beta_local_linear`` / ``local_linear_eps`` - the windowed local-linear term (the matting Laplacian of Levin et
  al.: depth an affine function of the colour in every 3x3 window), added to the current defaults, with the
  image-weighted smoothness weights ``beta_image`` and ``beta_second_image`` scaled by a factor of the grid.

A row's free parameters are picked on :data:`bench.frames.TUNE_FRAMES` only (the grid point with the lowest mean
RMSE / nearest-neighbour RMSE over frames × 1/5/10 % × seeds, scored by :func:`bench.tune.score`) and that choice
is scored on :data:`bench.frames.REPORT_FRAMES`.  The leave-one-dataset-out table repeats the choice for each
dataset of the report frames using only the tuning frames of the *other* datasets, and scores it on that
dataset's report frames.  Runtime is the wall time of ``complete_depth`` (fills and every solve included) divided
by the baseline's, in the same run, with BLAS on one thread (:func:`bench.blas.one_blas_thread`).

The ``prior=`` argument is checked as a mechanism only (the shared data has no monocular network prediction):
its input is a *degraded copy of the ground truth* (blurred, affinely rescaled), so its numbers say that the
alignment and the residual completion work, never what accuracy a real prior gives.

Run from the repository root::

    python -m bench.accuracy --seeds 0 1   # ~10 min on 2 cores: writes docs/accuracy.md
    python -m bench.accuracy --quick    # a smoke run on the tiny quick frames

May import :mod:`sparsedepth`, numpy, scipy.ndimage, :mod:`bench.frames`, :mod:`bench.harness` and
:func:`bench.tune.score`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import itertools  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy import ndimage  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.objective.weights import MODEL_FIELDS  # noqa: E402

from . import frames as frame_list  # noqa: E402
from . import harness  # noqa: E402
from .tune import score  # noqa: E402

#: The modelling fields of :class:`sparsedepth.Weights` and the local-linear term, all off in the baseline.
OFF = {name: 0.0 for name in (*MODEL_FIELDS, "beta_local_linear")}
#: The image-weighted smoothness weights of ``python -m bench.tune`` (docs/tuning.md), chosen before any modelling
#: field: the baseline keeps them whatever the defaults are, and the local-linear grid scales them.
TUNED_SMOOTHNESS = {"beta_image": 0.00673, "beta_second_image": 0.039}


def baseline() -> sd.Weights:
    """The library's default weights with every modelling field off and the tuned image smoothness (the objective
    before this ablation)."""
    return sd.DEFAULT_WEIGHTS.replace(**OFF, **TUNED_SMOOTHNESS)


def current_defaults() -> dict:
    """``sd.DEFAULT_WEIGHTS`` as changes to :func:`baseline` (the fields where they differ)."""
    base = baseline()
    return {k: v for k, v in sd.DEFAULT_WEIGHTS.as_dict(used_only=True).items() if getattr(base, k) != v}


def variants(quick: bool = False) -> list[tuple[str, list[dict]]]:
    """``[(label, grid)]``: each grid a list of changes to :func:`baseline` (one candidate each)."""
    delta = baseline().delta
    sigmas = (0.5, 1.0, 2.0)
    contrasts = (5.0, 20.0, 50.0)
    deltas = (delta, 10 * delta, 100 * delta)
    jumps = (0.02, 0.05, 0.1)
    local_weights, local_eps, smooth_scales = (0.003, 0.01, 0.03), (1e-6, 1e-5, 1e-4), (0.3, 1.0)
    if quick:
        sigmas, contrasts, deltas, jumps = (1.0,), (20.0,), (delta, 10 * delta), (0.05,)
        local_weights, local_eps, smooth_scales = (0.01,), (1e-5,), (0.3, 1.0)
    return [
        ("baseline (defaults, modelling fields off)", [{}]),
        ("blurred-image edge weights (edge_sigma)", [dict(edge_sigma=s) for s in sigmas]),
        ("geodesic prior fill (fill_contrast, delta)",
         [dict(fill_contrast=c, delta=d) for c, d in itertools.product(contrasts, deltas)]),
        ("depth-aware re-solve (depth_jump)", [dict(depth_jump=j) for j in jumps]),
        ("geodesic fill + blurred edges",
         [dict(edge_sigma=s, fill_contrast=c, delta=d) for s, c, d in itertools.product(sigmas, contrasts, deltas)]),
        (LOCAL_LINEAR, [local_linear(b, e, s) for b, e, s in itertools.product(local_weights, local_eps, smooth_scales)]),
    ]


#: The label of the local-linear variant.
LOCAL_LINEAR = "local-linear windows + geodesic fill + blurred edges"


def local_linear(weight: float, eps: float, smooth_scale: float) -> dict:
    """The changes to :func:`baseline` of one local-linear candidate: the term on top of edge_sigma = 1 and
    fill_contrast = 20 (the defaults it is measured against), the image-weighted smoothness times ``smooth_scale``."""
    return dict(edge_sigma=1.0, fill_contrast=20.0, beta_local_linear=weight, local_linear_eps=eps,
                **{k: smooth_scale * v for k, v in TUNED_SMOOTHNESS.items()})


def dataset_of(name: str) -> str:
    """The dataset family of a frame name (``nyu_metric3d/00050`` -> ``NYU``)."""
    prefix = name.split("/")[0]
    for key, label in (("nyu", "NYU"), ("kitti", "KITTI"), ("middlebury", "Middlebury"), ("eth3d", "ETH3D"),
                       ("tum", "TUM")):
        if prefix.startswith(key):
            return label
    return prefix


def run_grid(grid, frames, fractions, seeds):
    """``[(changes, rmse ratios {(frame, fraction, seed): r}, wall seconds)]`` for every candidate of ``grid``."""
    out = []
    for changes in grid:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sd.ClampWarning)
            _, ratios, seconds = score(baseline().replace(**changes), frames, fractions, seeds, wall=True)
        out.append((changes, ratios, seconds))
        print(f"  {changes or 'baseline'}: {np.mean(list(ratios.values())):.4f} ({seconds:.1f} s)", file=sys.stderr,
              flush=True)
    return out


def mean_over(ratios, keep=lambda frame: True) -> float:
    """Mean of the ratios whose frame passes ``keep`` (NaN if none)."""
    values = [r for (frame, _, _), r in ratios.items() if keep(frame)]
    return float(np.mean(values)) if values else float("nan")


def pick(tuned, keep=lambda frame: True):
    """The candidate of ``tuned`` (a :func:`run_grid` result) with the lowest mean ratio on the kept frames."""
    return min(range(len(tuned)), key=lambda i: mean_over(tuned[i][1], keep))


def per_fraction(ratios, fractions):
    return [mean_over({k: v for k, v in ratios.items() if k[1] == f}) for f in fractions]


def changes_text(changes) -> str:
    return ", ".join(f"{k} = {v:.3g}" for k, v in changes.items()) or "-"


def prior_check(frames, fractions, seeds):
    """Mechanism check of ``prior=``: ``[(label, mean RMSE ratio)]`` with degraded copies of the ground truth."""
    rows = {"no prior (baseline)": [], "prior = 0.5 * blurred truth + 1 (sigma 8 px), scale_shift": [],
            "prior = blurred truth (sigma 8 px) used as the result": []}
    for f in frames:
        valid = np.isfinite(f.depth)
        dense = sd.nearest_fill(np.where(valid, f.depth, 0.0), valid)  # the truth's holes filled: a dense map
        blurred = ndimage.gaussian_filter(dense, 8.0)
        for fraction in fractions:
            for s in seeds:
                sparse, mask = sd.sample_depth(f.depth, fraction=fraction, seed=s)
                hidden = ~mask
                nn = sd.depth_metrics(sd.nearest_fill(sparse, mask), f.depth, mask=hidden).rmse
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", sd.ClampWarning)
                    plain = sd.complete_depth(f.image, sparse, mask, weights=baseline()).depth
                    fused = sd.complete_depth(f.image, sparse, mask, weights=baseline(),
                                              prior=0.5 * blurred + 1.0).depth
                rows["no prior (baseline)"].append(sd.depth_metrics(plain, f.depth, mask=hidden).rmse / nn)
                rows["prior = 0.5 * blurred truth + 1 (sigma 8 px), scale_shift"].append(
                    sd.depth_metrics(fused, f.depth, mask=hidden).rmse / nn)
                rows["prior = blurred truth (sigma 8 px) used as the result"].append(
                    sd.depth_metrics(blurred, f.depth, mask=hidden).rmse / nn)
    return [(label, float(np.mean(v))) for label, v in rows.items()]


def parse_args(argv):
    parser = argparse.ArgumentParser(prog="python -m bench.accuracy", description=__doc__.split("\n\n")[0])
    parser.add_argument("--step", type=int, default=2, help="frame subsampling (default 2)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="sampling seeds (default 0)")
    parser.add_argument("--quick", action="store_true", help="the tiny quick frames, small grids (smoke test)")
    parser.add_argument("--out", type=Path, default=harness.DOCS / "accuracy.md", help="markdown output")
    return parser.parse_args(argv)


def load(args):
    """``(tuning frames, report frames)``; quick mode uses the quick frames for both."""
    if args.quick:
        frames = harness.quick_frames()
        return frames[:1], frames[1:]
    tune = [harness.FrameData(n, *frame_list.load(n, step=args.step), args.step)
            for n in frame_list.available(frame_list.TUNE_FRAMES)]
    report = [harness.load_frame(n, args.step) for n in frame_list.available(frame_list.REPORT_FRAMES)]
    return tune, report


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    args.argv = [a for a in argv if not a.startswith("--out") and a != str(args.out)]
    start = time.perf_counter()
    tune_frames, report_frames = load(args)
    if not tune_frames or not report_frames:
        print("the shared data folder is absent: nothing to measure", file=sys.stderr)
        return 2
    fractions, seeds = harness.FRACTIONS, args.seeds
    rows, results = [], {}
    for label, grid in variants(args.quick):
        print(label, file=sys.stderr, flush=True)
        tuned = run_grid(grid, tune_frames, fractions, seeds)
        best = pick(tuned)
        reported = run_grid([tuned[best][0]], report_frames, fractions, seeds)[0]
        results[label] = (grid, tuned, best, reported)
    base_report = results[variants()[0][0]][3]
    base_tune = results[variants()[0][0]][1][0]
    for label, (grid, tuned, best, reported) in results.items():
        rows.append([label, changes_text(tuned[best][0]), f"{mean_over(tuned[best][1]):.3f}",
                     *(f"{r:.3f}" for r in per_fraction(reported[1], fractions)), f"{mean_over(reported[1]):.3f}",
                     f"{reported[2] / base_report[2]:.2f}"])
    print("current defaults", file=sys.stderr, flush=True)
    defaults = run_grid([current_defaults()], report_frames, fractions, seeds)[0]
    rows.append(["`sd.DEFAULT_WEIGHTS` at run time (constant weights, the density schedule's base; not tuned here)",
                 changes_text({k: v for k, v in defaults[0].items() if v}), "",
                 *(f"{r:.3f}" for r in per_fraction(defaults[1], fractions)), f"{mean_over(defaults[1]):.3f}",
                 f"{defaults[2] / base_report[2]:.2f}"])
    chosen = min((label for label in results if label != variants()[0][0]),
                 key=lambda label: mean_over(results[label][3][1]))
    text = report(args, tune_frames, report_frames, fractions, rows, results, chosen, base_report, base_tune,
                  start)
    return harness.publish([text], args.out)


def lodo_rows(results, label, report_frames, fractions, seeds, base_report):
    """Leave-one-dataset-out rows for ``label``: per report dataset, the choice on the others' tuning frames."""
    grid, tuned, _, _ = results[label]
    rows, scores = [], {}
    for dataset in sorted({dataset_of(f.name) for f in report_frames}):
        i = pick(tuned, keep=lambda frame, d=dataset: dataset_of(frame) != d)
        held = [f for f in report_frames if dataset_of(f.name) == dataset]
        _, ratios, _ = run_grid([tuned[i][0]], held, fractions, seeds)[0]
        scores.update(ratios)
        rows.append([dataset, changes_text(tuned[i][0]), str(len(held)), f"{mean_over(ratios):.3f}",
                     f"{mean_over(base_report[1], keep=lambda frame, d=dataset: dataset_of(frame) == d):.3f}"])
    return rows, mean_over(scores)


def report(args, tune_frames, report_frames, fractions, rows, results, chosen, base_report, base_tune, start):
    lodo, lodo_mean = lodo_rows(results, chosen, report_frames, fractions, args.seeds, base_report)
    per_dataset = []
    reported = results[chosen][3]
    for dataset in sorted({dataset_of(f.name) for f in report_frames}):
        keep = lambda frame, d=dataset: dataset_of(frame) == d  # noqa: E731
        per_dataset.append([dataset, f"{mean_over(base_report[1], keep):.3f}", f"{mean_over(reported[1], keep):.3f}"])
    prior_rows = prior_check(report_frames, fractions, args.seeds)
    command = harness.command_line("accuracy", args.argv)
    lines = [
        *harness.tuned_report_header("Accuracy on unseen frames: modelling variants", command, args, time.perf_counter() - start, tune_frames,
                                     report_frames),
        "",
        f"Baseline weights: {harness.weights_markdown(baseline())}.",
        "",
        "Score: RMSE on the hidden valid pixels divided by the nearest-neighbour fill's RMSE on the same input "
        "(lower is better), mean over frames × sparsities × seeds. Each row's parameters are the grid point best "
        "on the tuning frames; its report-frame numbers use that choice. Time: Σ wall time of `complete_depth` on "
        "the report frames / the baseline's, same run.",
        "",
        f"The row **{LOCAL_LINEAR}** adds the windowed local-linear term (`beta_local_linear`, the matting "
        "Laplacian of Levin, Lischinski & Weiss 2008 over 3x3 windows of the blurred colour image, ridge weight "
        "`local_linear_eps`; `sparsedepth.grid.affinity`) to edge_sigma = 1 and fill_contrast = 20, with "
        "`beta_image` and `beta_second_image` scaled by the factor of the grid; it makes the system 25-point "
        "instead of 13-point.",
        "",
        harness.markdown_table(["variant", "chosen on tuning frames", "tuning score",
                                *(f"report {100 * f:g} %" for f in fractions), "report mean", "time × baseline"],
                               rows, align=["---", "---"] + ["---:"] * (len(fractions) + 3)),
        "",
        f"Per dataset on the report frames, baseline vs **{chosen}** (the variant best on the report frames):",
        "",
        harness.markdown_table(["dataset", "baseline", "chosen variant"], per_dataset, align=["---", "---:", "---:"]),
        "",
        f"Leave-one-dataset-out for **{chosen}**: for each dataset, the grid point best on the tuning frames of the "
        "other datasets, scored on that dataset's report frames (ETH3D and TUM have no tuning frame, so their "
        "choice is the all-tuning-frames one):",
        "",
        harness.markdown_table(["held-out dataset", "chosen without it", "report frames", "score", "baseline"],
                               lodo, align=["---", "---", "---:", "---:", "---:"]),
        "",
        f"Leave-one-dataset-out mean over the report frames: {lodo_mean:.3f} (baseline "
        f"{mean_over(base_report[1]):.3f}).",
        "",
        "## `prior=`: mechanism check only",
        "",
        "No real monocular prediction exists in the shared data, so this is **not** an accuracy claim: the prior "
        "is the ground truth itself (holes filled by nearest neighbour) blurred by a Gaussian of 8 px and "
        "rescaled, i.e. it contains the answer. The rows show that the scale/shift alignment undoes the rescaling "
        "and that completing the residual improves on the prior alone.",
        "",
        harness.markdown_table(["input", "mean RMSE / nearest on the report frames"],
                               [[label, f"{value:.3f}"] for label, value in prior_rows], align=["---", "---:"]),
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
