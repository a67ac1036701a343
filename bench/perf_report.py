"""``docs/performance.md`` from the results of :mod:`bench.perf` (the dict it stores in ``docs/performance.json``).

One small function per part of the report; the prose notes are ``bench/templates/performance_notes.md``, a
:class:`string.Template` filled with the measured iteration counts and memory.  Rendering measures nothing, so
``python -m bench.perf --render`` rewrites the report from the stored results after an edit of its text.

May import :mod:`bench.harness` and the standard library.
"""

from __future__ import annotations

from pathlib import Path
from string import Template

from . import harness as H

__all__ = ["report", "iterations_that_fit"]

NOTES = Path(__file__).resolve().parent / "templates" / "performance_notes.md"
#: The time goal of the quadratic solve at 640x480.
GOAL_SECONDS = 0.3


def fmt(x, spec=".3g"):
    """``format(x, spec)``, or a dash for a missing value."""
    return "—" if x is None else format(x, spec)


def yes(condition) -> str:
    """``"yes"`` or ``"no"``."""
    return "yes" if condition else "no"


def iterations_that_fit(row, budget=GOAL_SECONDS):
    """PCG iterations (one V-cycle and one product each) that ``budget`` seconds leave after the set-up."""
    return max((budget - row["setup"]) / (row["vcycle"] + row["matvec"]), 0.0)


def fit_note(quad):
    """The notes' sentence on how many PCG iterations the 0.3 s goal leaves (from the measured parts)."""
    q = quad[0]
    if "vcycle" not in q:
        return ""
    per_it = q["vcycle"] + q["matvec"]
    fit = iterations_that_fit(q)
    text = (f" One PCG iteration of the 13-point system (a V-cycle and a product with `A`) costs {1e3 * per_it:.0f} ms "
            f"here and the set-up {q['setup']:.2f} s, so the 0.3 s goal leaves {fit:.1f} iterations")
    if fit < 8:
        text += (", where even a textbook multigrid contraction of 0.1 per cycle needs 8 for a relative residual "
                 "of 1e-8: for this 13-point system the goal is out of reach of any V-cycle count on this machine, "
                 "and the remaining lever would be cheaper passes over the matrix, not fewer iterations.")
    else:
        text += f" against the {q['ours_iters']} measured."
    if len(quad) > 1:
        q2 = quad[1]
        text += (f" The paper's 5-point system took {q2['ours']:.3f} s, "
                 f"{'below' if q2['ours'] < 0.3 else 'above'} the 0.3 s goal in this run.")
    return text


def headline_quadratic(quad) -> list[list[str]]:
    """The headline rows of the quadratic systems against ``spsolve``."""
    q = quad[0]
    rows = [["quadratic (13-point, `QUADRATIC_WEIGHTS`), set-up + solve to rel. residual 1e-8 vs `spsolve` "
             "on the same system", f"**{q['ratio']:.1f}×** faster, {q['ours']:.3f} s "
             f"({q['build'] + q['assemble'] + q['ours']:.3f} s with building and assembling the objective)",
             "≥ 10×, < 0.3 s", yes(q['ratio'] >= 10 and q['ours'] < 0.3)]]
    if len(quad) > 1 and "ratio" in quad[1]:
        q2 = quad[1]
        rows.append(["quadratic, the paper's terms alone (5-point) vs `spsolve`",
                     f"**{q2['ratio']:.1f}×**, {q2['ours']:.3f} s "
                     f"({q2['build'] + q2['assemble'] + q2['ours']:.3f} s with the objective)",
                     "(same)", yes(q2['ratio'] >= 10 and q2['ours'] < 0.3)])
    return rows


def headline_others(l1, col, scaling, l1_scaling, mem) -> list[list[str]]:
    """The headline rows of the L1 solve, the hole fill, the scaling and the 8-MP memory."""
    lb = "≥ " if l1.get("ratio_is_lower_bound") else ""
    ratio = l1.get("ratio")
    rows = [["L1 (γ = 0.01), exact F within 1e-6 of the best, vs L-BFGS-B time to that value",
             f"**{lb}{fmt(ratio, '.1f')}×**, {l1['ours_time']:.2f} s (rel. gap {l1['ours_rel']:.1e})",
             "≥ 20×, < 1 s", yes(ratio and ratio >= 20 and l1['ours_time'] < 1)]]
    median = f"; median fill {col['fast_median']:.2f} s: {col['naive'] / col['fast_median']:.0f}×"
    rows.append(["hole filling (colorization) vs naive port",
                 f"**{col['ratio']:.0f}×**, {col['fast']:.2f} s (max diff {col['maxdiff']:.1e} m{median})",
                 "≥ 50×, ≤ 1e-6", yes(col['ratio'] >= 50 and col['maxdiff'] <= 1e-6)])
    base = scaling[0]["solve"] / scaling[0]["n"]
    worst = max(r["solve"] / r["n"] / base for r in scaling[1:]) if len(scaling) > 1 else float("nan")
    rows.append(["scaling, time/pixel at 4× and 16× pixels vs 640×480 (quadratic solve)", f"worst {worst:.2f}×",
                 "≤ 1.5×", yes(worst <= 1.5)])
    l1_base = l1_scaling[0]["seconds"] / l1_scaling[0]["n"]
    l1_rel = l1_scaling[-1]["seconds"] / l1_scaling[-1]["n"] / l1_base
    rows.append(["scaling, time/pixel at 4× pixels vs 640×480 (L1 solve, γ = 0.01)",
                 f"{l1_rel:.2f}× ({l1_scaling[0]['iters']} → {l1_scaling[-1]['iters']} iterations)", "≤ 1.5×",
                 yes(l1_rel <= 1.5)])
    for m in mem:
        if "peak_mb" in m:
            rows.append([f"peak memory, 8-MP `complete_depth` ({m['mode']})",
                         f"{m['peak_mb']:.0f} MB, {m['seconds']:.1f} s", "< 3 GB", yes(m['peak_mb'] < 3072)])
        else:
            rows.append([f"peak memory, 8-MP ({m['mode']})", f"failed: {m['error']}", "< 3 GB", "no"])
    return rows


def machine_text(info) -> str:
    """The machine paragraph, from the ``info`` dict of :func:`bench.perf.machine`."""
    return (f"{info['cpu']}, {info['cores']} cores (shared with other jobs: timings are noisy; ratios are same-run, "
            f"best of 3 for our quadratic solve); Python {info['python']}, NumPy {info['numpy']}, SciPy {info['scipy']}, "
            f"pyamg {info['pyamg']}; BLAS threads = {info['blas_threads']}.\n")


def quadratic_section(quad) -> list[str]:
    """Section 1: the systems, our solve against ``spsolve`` and PyAMG, and the parts of one solve."""
    L = ["## 1. Quadratic problem\n",
         "Assembly of `A, b` (`Objective.normal_equations`) is shared by both methods and reported apart. "
         "Ours = `solve(obj, z_c, solver='amg', tol=1e-8)`: GridMultigrid set-up + PCG, history recording "
         "included.\n"]
    L.append(H.markdown_table(
        ["system", "N", "nnz(A)", "build s", "assemble s", "spsolve s", "ours s (CG its)", "pyamg-RS PCG s (its)",
         "ratio", "‖b−Az‖/‖b‖", "max |z − z_spsolve| m"],
        [[r['problem'], r['n'], r['nnz'], f"{r['build']:.3f}", f"{r['assemble']:.3f}", fmt(r.get('spsolve'), '.2f'),
          f"{r['ours']:.3f} ({r['ours_iters']})", f"{r['pyamg']:.2f} ({r['pyamg_iters']})",
          fmt(r.get('ratio'), '.1f'), f"{r['ours_rel']:.1e}", fmt(r.get('maxdiff'), '.1e')] for r in quad]))
    L.append("")
    if all("vcycle" in r for r in quad):
        L.append("The parts of one solve (best of 3 / 5 / 5): GridMultigrid set-up, one V-cycle, one product with "
                 "`A`; a PCG iteration is one V-cycle and one product, so the 0.3 s goal leaves "
                 "(0.3 s − set-up) / (V-cycle + product) iterations. The V-cycle runs in float32 (the default up to "
                 "2²⁶ non-zeros); the same cycle in float64 (`fine_precision = coarse_precision = 'double'`) is timed "
                 "interleaved with it.\n")
        L.append(H.markdown_table(
            ["system", "set-up s", "V-cycle ms", "V-cycle in float64 ms", "A·x ms", "PCG its measured",
             "its that fit in 0.3 s"],
            [[r['problem'], f"{r['setup']:.3f}", f"{1e3 * r['vcycle']:.1f}", f"{1e3 * r['vcycle_double']:.1f}",
              f"{1e3 * r['matvec']:.1f}", r['ours_iters'], f"{iterations_that_fit(r):.1f}"] for r in quad]))
        L.append("")
    return L


def l1_section(l1, weights) -> list[str]:
    """Section 2: ours, L-BFGS-B, IRLS and the long reference ADMM run on the L1 problem."""
    L = ["## 2. L1 problem (γ > 0)\n",
         f"Weights `{weights}`. Best value F* = {l1['F_best']:.12g}; terms at the reference: "
         + ", ".join(f"{k} {v:.4g}" for k, v in l1["terms"].items() if v) + ".\n"]
    rows = [[f"ours (`solver='auto'` → {l1['ours_solver']}, default tol)", f"{l1['ours_time']:.2f}", l1['ours_iters'],
             f"{l1['ours_rel']:.1e}", format(l1['ours_time'], '.2f') if l1['ours_reached'] else 'not reached'],
            ["L-BFGS-B (SciPy, smoothed, budget)", f"{l1['lbfgsb_time']:.1f}", l1['lbfgsb_iters'],
             f"{l1['lbfgsb_rel']:.1e}",
             fmt(l1['lbfgsb_t_to_target'], '.1f') if l1['lbfgsb_reached'] else 'not reached']]
    if "irls_time" in l1:
        rows.append(["IRLS (tol 1e-9)", f"{l1['irls_time']:.1f}", "", f"{l1['irls_rel']:.1e}",
                     fmt(l1['irls_t_to_target'], '.1f')])
    rows.append(["reference ADMM (long)", f"{l1['ref_time']:.1f}", "", f"{l1['ref_rel']:.1e}", ""])
    L.append(H.markdown_table(["run", "time s", "iterations", "(F − F*)/F*", "time to F*(1+1e-6) s"], rows))
    L.append("")
    return L


def holefill_section(col) -> list[str]:
    """Section 3: the colorization fill against the naive port."""
    return ["## 3. Hole filling (NYU toolbox colorization)\n",
            f"Raw depth of the same frame ({100 * col['holes']:.1f} % holes). `colorization_fill` "
            f"{col['fast']:.2f} s (best of 7; median {col['fast_median']:.2f} s), naive port "
            f"{col['naive']:.1f} s (best of {len(col['naive_runs'])}: "
            f"{', '.join(f'{t:.1f}' for t in col['naive_runs'])} s), interleaved: "
            f"**{col['ratio']:.0f}×**, max |difference| {col['maxdiff']:.1e} m.\n"]


def scaling_section(scaling, l1_scaling, mem) -> list[str]:
    """Section 4: time per pixel of the quadratic and the L1 solve at larger sizes, and the 8-MP runs."""
    base = scaling[0]["solve"] / scaling[0]["n"]
    l1_base = l1_scaling[0]["seconds"] / l1_scaling[0]["n"]
    L = ["## 4. Scaling (quadratic, `QUADRATIC_WEIGHTS`)\n",
         "Best of 3 interleaved rounds per size (set-up + PCG to 1e-8); the whole `complete_depth` call "
         "(objective assembly included) once.\n"]
    L.append(H.markdown_table(
        ["pixels", "solve s (set-up + PCG)", "CG its", "µs / pixel", "relative to 640×480",
         "whole complete_depth s"],
        [[r['n'], f"{r['solve']:.2f}", r['iters'], f"{1e6 * r['solve'] / r['n']:.2f}",
          f"{r['solve'] / r['n'] / base:.2f}", f"{r['total']:.2f}"] for r in scaling]))
    L += ["", "L1 (γ = 0.01, `L1_WEIGHTS`), `solve(..., solver='admm')` with default options, once per size:\n"]
    L.append(H.markdown_table(
        ["pixels", "seconds", "ADMM iterations", "µs / pixel", "relative to 640×480"],
        [[r['n'], f"{r['seconds']:.2f}", r['iters'], f"{1e6 * r['seconds'] / r['n']:.2f}",
          f"{r['seconds'] / r['n'] / l1_base:.2f}"] for r in l1_scaling]))
    L.append("")
    L.append(H.markdown_table(
        ["8-MP run (fresh process)", "pixels", "seconds", "peak MB", "solver"],
        [[m['mode'], m['n'], f"{m['seconds']:.1f}", f"{m['peak_mb']:.0f}",
          f"{m['solver']} ({m['iterations']} its, converged {m['converged']})"] for m in mem if "peak_mb" in m]))
    L.append("")
    return L


def notes(quad, l1, l1_scaling, mem) -> str:
    """The notes (``bench/templates/performance_notes.md``) with this run's counts."""
    l1_mem = next((m for m in mem if m.get("mode") == "l1" and "peak_mb" in m), None)
    return Template(NOTES.read_text()).substitute(
        default_iters=quad[0]["ours_iters"], paper_iters=quad[1]["ours_iters"] if len(quad) > 1 else "?",
        nnz=quad[0]["nnz"], fit_note=fit_note(quad), l1_iters=l1["ours_iters"],
        l1_scaled_iters=l1_scaling[-1]["iters"], l1_base_iters=l1_scaling[0]["iters"],
        l1_peak_clause="" if l1_mem is None else f"; its peak is {l1_mem['peak_mb']:.0f} MB")


def report(quad, l1, col, scaling, l1_scaling, mem, info, command, *, l1_weights) -> str:
    """The whole ``docs/performance.md`` (without its final newline)."""
    L = ["# Performance\n",
         f"Measured by `{command}` (bench/perf.py) on {info['date']}; every ratio is measured in the same run.\n",
         "## Headline (640×480 NYU frame `nyu_metric3d/00000`, 5 % observed)\n",
         H.markdown_table(["target", "measured", "goal", "met"],
                          headline_quadratic(quad) + headline_others(l1, col, scaling, l1_scaling, mem)),
         "",
         "## Machine\n",
         machine_text(info)]
    L += quadratic_section(quad) + l1_section(l1, l1_weights) + holefill_section(col)
    L += scaling_section(scaling, l1_scaling, mem)
    return "\n".join(L) + "\n" + notes(quad, l1, l1_scaling, mem)
