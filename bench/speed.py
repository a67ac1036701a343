"""Speed of the default solve: the depth stopping rule against the residual rule, and the fast filters beside ours.

Run from the repository root::

    nice -n 5 python -m bench.speed --out docs/speed.md     # ~10 min on 2 shared cores
    python -m bench.speed --quick                          # a smoke run on two tiny frames

Sections: where the time of the default, fast and uncertainty completions goes, and the default against a sparse
direct solve (:mod:`bench.time_breakdown`; ``--skip-breakdown`` leaves them out); then these two, and the fast
filters beside ours (``--skip-peers`` leaves it out):

* **Stopping rule** (:func:`stopping_rows`): per report frame at full size (5 % observed, seed 0), the default
  ``amg`` solve stopping on its estimated RMS remaining change (``depth_rtol`` =
  :data:`sparsedepth.solvers.quadratic.DEFAULT_DEPTH_RTOL` of the depth scale) against the same solve stopping at
  the residual rule at the relative residual 1e-8 (``tol=1e-8``) and a tight reference (1e-12).  The PCG time is given in
  *V-cycle-equivalents*: the time of the PCG iterations divided by the median time of one V-cycle of the same
  hierarchy, measured in the same process (set-up separately); the RMSE change is relative to the 1e-8 solve's;
  the remaining change of the returned depth is measured against the tight solve (RMS and max, depth units) and
  compared with the estimate.
* **Fast peers** (:mod:`bench.fast_peers`): OpenCV's fast global smoother and an IP-Basic-style morphological fill,
  tuned on the tuning frames, timed and scored on the report frames beside the nearest fill and ours, with the
  speed/accuracy figure ``docs/figures/speed_accuracy.png``, and ``complete_depth(quality="fast")`` against FGS
  frame by frame, at full size and at 640x480.  Needs ``opencv-contrib-python-headless`` (the
  ``bench`` extra); without it those rows are left out and the report says so.

May import :mod:`sparsedepth`, numpy, :mod:`bench.blas`, :mod:`bench.frames`, :mod:`bench.harness` and
:mod:`bench.fast_peers` and :mod:`bench.time_breakdown`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.linalg import pcg_info  # noqa: E402
from sparsedepth.objective.weights import LOCAL_LINEAR_FIELDS  # noqa: E402
from sparsedepth.solvers import depth_unit, scaled_objective  # noqa: E402
from sparsedepth.solvers.quadratic import (DEFAULT_DEPTH_RTOL, RemainingChange, default_hierarchy,  # noqa: E402
                                           system_form)

from . import fast_peers  # noqa: E402
from . import harness as H  # noqa: E402
from . import time_breakdown  # noqa: E402

#: Observed fraction and seed of the stopping-rule section.
FRACTION, SEED = 0.05, 0

STOP_HEADER = ["frame", "size", "CG its depth / 1e-8", "PCG V-eq. depth / 1e-8", "set-up V-eq.",
               "complete_depth time depth / 1e-8", "RMSE rel. change", "RMS remaining (est. / true)",
               "max remaining", "depth tol."]


def _v_cycle_time(mg, b, repeat=7) -> float:
    """Median wall time of one V-cycle of ``mg`` on ``b``."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        mg.vcycle(b)
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def _pcg_run(A, b, x0, mg, **kwargs):
    start = time.perf_counter()
    result = pcg_info(A, b, x0=x0, M=mg.aspreconditioner(), **kwargs)
    return result, time.perf_counter() - start


def stopping_row(frame) -> dict:
    """One frame of the stopping-rule section (see the module docstring)."""
    sparse, mask = H.sample(frame, fraction=FRACTION, seed=SEED)
    observed = sparse[mask]
    scale = depth_unit(observed)
    objective, coarse, _ = sd.build_objective(frame.image, sparse, mask)
    scaled = scaled_objective(objective, scale)
    A, b, _ = scaled.normal_equations(form=system_form(scaled))
    x0 = coarse.ravel() / scale
    start = time.perf_counter()
    mg = default_hierarchy(A, scaled.shape)
    setup = time.perf_counter() - start
    t_v = _v_cycle_time(mg, b)
    rule = RemainingChange(b.size, DEFAULT_DEPTH_RTOL)
    new, t_new = _pcg_run(A, b, x0, mg, rtol=1e-8, maxiter=500, stop=rule)
    old, t_old = _pcg_run(A, b, x0, mg, rtol=1e-8, maxiter=500)
    tight, _ = _pcg_run(A, b, x0, mg, rtol=1e-12, maxiter=1000)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        res_new = sd.complete_depth(frame.image, sparse, mask)
        res_old = sd.complete_depth(frame.image, sparse, mask, tol=1e-8)
    hidden = ~mask
    rmse_new = sd.depth_metrics(res_new.depth, frame.depth, mask=hidden).rmse
    rmse_old = sd.depth_metrics(res_old.depth, frame.depth, mask=hidden).rmse
    diff = (new.x - tight.x) * scale
    return {"frame": frame.name, "size": f"{frame.shape[1]}x{frame.shape[0]}",
            "its": (new.iterations, old.iterations), "v_eq": (t_new / t_v, t_old / t_v), "setup": setup / t_v,
            "time_ratio": res_new.runtime / res_old.runtime, "rmse_change": (rmse_new - rmse_old) / rmse_old,
            "estimate": rule.estimate * scale, "true_rms": float(np.sqrt(np.mean(diff ** 2))),
            "true_max": float(np.abs(diff).max()), "tol": DEFAULT_DEPTH_RTOL * scale, "rule_met": new.rule_met,
            "same_as_library": res_new.iterations == new.iterations, "units": frame.units}


def stopping_section(frames, argv, started) -> tuple[str, list]:
    rows = [stopping_row(f) for f in frames]
    body = H.markdown_table(STOP_HEADER, [
        [r["frame"], r["size"], f"{r['its'][0]} / {r['its'][1]}", f"{r['v_eq'][0]:.1f} / {r['v_eq'][1]:.1f}",
         f"{r['setup']:.1f}", f"{r['time_ratio']:.2f}", f"{r['rmse_change']:+.1e}",
         f"{r['estimate']:.1e} / {r['true_rms']:.1e}", f"{r['true_max']:.1e}", f"{r['tol']:.1e} {r['units']}"]
        for r in rows])
    v_eq = np.array([r["v_eq"][0] for r in rows])
    worst = max(abs(r["rmse_change"]) for r in rows)
    ratio = np.array([r["estimate"] / r["true_rms"] for r in rows])
    notes = (
        f"At {FRACTION:.0%} observed, seed {SEED}. The default `amg` solve of `complete_depth` (no `tol`) stops when "
        f"the estimated RMS remaining change of the depth (`sparsedepth.solvers.quadratic.RemainingChange`: the "
        f"last CG step times ρ/(1−ρ), ρ the largest step ratio of the last three) is at most `depth_rtol` = "
        f"{DEFAULT_DEPTH_RTOL:g} of the depth scale s (the power of two nearest the median observed depth); "
        f"`tol=1e-8` stops instead at the relative residual 1e-8. PCG V-eq.: the PCG iterations' time "
        f"divided by the median time of one V-cycle of the same hierarchy (same process); set-up: building the "
        f"hierarchy, same unit. `complete_depth` time: the ratio of the two calls' `runtime` (set-up, solve and "
        f"duality gap). RMSE: on the hidden valid pixels, change relative to the 1e-8 solve's. Remaining change: "
        f"of the depth-rule solve against a solve to 1e-12 (depth units, before the range clamp). "
        f"Over the frames: {v_eq.min():.1f}-{v_eq.max():.1f} V-cycle-equivalents (mean {v_eq.mean():.1f}), "
        f"largest |RMSE change| {worst:.1e}, estimate / true RMS remaining change {ratio.min():.2f}-"
        f"{ratio.max():.2f}."
        + ("" if all(r["same_as_library"] for r in rows) else
           " (On some frame the library's solve took another iteration count than this replay: timing noise "
           "cannot change it, so check the replay.)"))
    text = H.section("Stopping rule of the default solve", command=H.command_line("speed", argv), frames_=frames,
                     seeds=[SEED], body=body, notes=notes, elapsed=time.perf_counter() - started)
    return text, rows


#: The objectives of the iteration-count section: which of the default weights are set to 0.
TERM_VARIANTS = {
    "default": {},
    "without the local-linear terms": dict.fromkeys(LOCAL_LINEAR_FIELDS, 0.0),
    "without the second-order terms": {"beta_second": 0.0, "beta_second_image": 0.0},
    "first-order terms only": {**dict.fromkeys(LOCAL_LINEAR_FIELDS, 0.0), "beta_second": 0.0, "beta_second_image": 0.0},
}
TERMS_HEADER = ["frame"] + [f"{name}: CG its depth / 1e-8" for name in TERM_VARIANTS]


def terms_row(frame) -> dict:
    """One frame of the iteration-count section: the default solve of each :data:`TERM_VARIANTS` objective."""
    sparse, mask = H.sample(frame, fraction=FRACTION, seed=SEED)
    scale = depth_unit(sparse[mask])
    base = sd.resolve_weights(None, sd.observed_fraction(mask))
    row = {"frame": frame.name}
    for name, zeroed in TERM_VARIANTS.items():
        objective, coarse, _ = sd.build_objective(frame.image, sparse, mask, weights=base.replace(**zeroed))
        scaled = scaled_objective(objective, scale)
        A, b, _ = scaled.normal_equations(form=system_form(scaled))
        mg = default_hierarchy(A, scaled.shape)
        x0 = coarse.ravel() / scale
        depth = pcg_info(A, b, x0=x0, M=mg.aspreconditioner(), rtol=1e-8, maxiter=500,
                         stop=RemainingChange(b.size, DEFAULT_DEPTH_RTOL))
        residual = pcg_info(A, b, x0=x0, M=mg.aspreconditioner(), rtol=1e-8, maxiter=500)
        row[name] = (depth.iterations, residual.iterations)
    return row


def terms_section(frames, argv, started) -> str:
    rows = [terms_row(f) for f in frames]
    body = H.markdown_table(TERMS_HEADER, [
        [r["frame"]] + [f"{r[name][0]} / {r[name][1]}" for name in TERM_VARIANTS] for r in rows])
    mean = {name: (np.mean([r[name][0] for r in rows]), np.mean([r[name][1] for r in rows])) for name in TERM_VARIANTS}
    notes = (
        f"At {FRACTION:.0%} observed, seed {SEED}: the default weights of that density with some of them set to 0, "
        f"each objective solved like the default solve (the default hierarchy, PCG from the prior fill, stopping at "
        f"the depth rule, and again to the relative residual 1e-8). Means over the frames (depth rule / 1e-8): "
        + "; ".join(f"{name} {d:.1f} / {r:.1f}" for name, (d, r) in mean.items()) + ". "
        "The first-order terms give a 5-point system, whose hierarchy interpolates by the operator (Dendy's "
        "black-box interpolation); the second-order terms (13-point) and the local-linear terms (13-point on "
        "cross and 2x2 windows, 25-point on 3x3 windows) give a stencil of radius 2, whose hierarchy interpolates "
        "bilinearly.")
    return H.section("Iterations by the terms of the objective", command=H.command_line("speed", argv),
                     frames_=frames, seeds=[SEED], body=body, notes=notes, elapsed=time.perf_counter() - started)


def run(argv=(), figure=None):
    """``(markdown, stopping rows)`` of a run with command-line arguments ``argv``; ``figure``: see
    :func:`bench.fast_peers.run_section`."""
    p = H.parser("Speed of the default solve and the fast filters", default_step=1)
    p.add_argument("--skip-peers", action="store_true", help="without the fast filters' section")
    p.add_argument("--skip-breakdown", action="store_true",
                   help="without the time breakdown and the comparison with a direct solve")
    args = p.parse_args(argv)
    started = time.perf_counter()
    frames = H.get_frames(args)
    parts = ["# Speed", "", "Written by `" + H.command_line("speed", argv) + "`.", ""]
    if not args.skip_breakdown:
        parts.append(time_breakdown.run_sections(argv, quick=args.quick))
    stop_text, rows = stopping_section(frames, argv, started)
    parts += [stop_text, terms_section(frames, argv, time.perf_counter())]
    if not args.skip_peers:
        peer_text, _ = fast_peers.run_section(args, argv, figure)
        parts.append(peer_text)
    return "\n".join(parts), rows


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = H.parser("", default_step=1)
    args.add_argument("--skip-peers", action="store_true")
    args.add_argument("--skip-breakdown", action="store_true")
    return H.script_main(run, args.parse_args(argv), argv)


if __name__ == "__main__":
    raise SystemExit(main())
