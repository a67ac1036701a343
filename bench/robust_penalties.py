"""Robust edge penalties against the L1 edge term: hidden-pixel RMSE relative to the nearest fill, and time.

Run (about ten minutes on 2 cores)::

    python -m bench.robust_penalties --seeds 0 1 --out robust.md

or ``--quick`` for a seconds-long smoke test on tiny frames.  Frames are :data:`frames.REPORT_FRAMES`
subsampled by ``--step`` (default 4), 5 % of the valid pixels observed.  Every method is
``sparsedepth.complete_depth`` with ``sd.DEFAULT_WEIGHTS`` except the edge term: weight ``gamma`` and, for the
robust penalties, ``edge_scale``, both set per input relative to its median observed depth ``m`` (the frames'
units differ: metres, and pixels of disparity for Middlebury 2003), ``gamma = GAMMA_REL · m`` and
``edge_scale`` in :data:`SCALES_REL` times ``m``; solver ``auto`` (ADMM for L1, IRLS for the robust penalties).

May import :mod:`sparsedepth` and :mod:`bench.harness`.
"""

from __future__ import annotations

import sys
import time
import warnings

import numpy as np

import sparsedepth as sd

from . import harness as H

DEFAULT_STEP = 4
FRACTION = 0.05
#: ``gamma`` relative to the median observed depth (the reference paper's 0.01 at a ~3 m NYU median).
GAMMA_REL = 0.003
#: ``edge_scale`` relative to the median observed depth.
SCALES_REL = (0.01, 0.03, 0.1)
PENALTIES = ("charbonnier", "cauchy", "geman_mcclure", "welsch")


def edge_method(penalty, scale_rel=None) -> H.Method:
    """``complete_depth`` with the default weights plus an edge term of ``penalty`` scaled to the input."""

    def run(image, sparse, mask):
        m = float(np.median(sparse[mask]))
        changes = dict(gamma=GAMMA_REL * m, edge_penalty=penalty)
        if scale_rel is not None:
            changes["edge_scale"] = scale_rel * m
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sd.ClampWarning)
            return sd.complete_depth(image, sparse, mask, weights=sd.DEFAULT_WEIGHTS.replace(**changes))

    name = "l1" if penalty == "l1" else f"{penalty}, s = {scale_rel:g}·m"
    return H.Method(name, run, ("robust_penalties", penalty, scale_rel, GAMMA_REL))


def methods() -> list[H.Method]:
    """The nearest fill, the defaults (no edge term), L1, and every robust penalty at every scale."""
    out = [H.NEAREST, H.ours("defaults (no edge term)"), edge_method("l1")]
    out += [edge_method(p, s) for p in PENALTIES for s in SCALES_REL]
    return out


def run(argv=None):
    """Run the benchmark; returns ``(markdown, rows)`` (rows from :func:`harness.summarise`)."""
    args = H.parser(__doc__.splitlines()[0], default_step=DEFAULT_STEP).parse_args(argv)
    t0 = time.perf_counter()
    frames = H.get_frames(args)
    seeds = H.seeds_of(args)
    ms = methods()
    records = H.evaluate_all(ms, frames, seeds, fractions=[FRACTION], keep_result=True)
    rows = H.summarise(records, reference="nearest")
    header = ["edge term", "RMSE / nearest", "REL", "δ1", "time (s)", "iterations", "converged"]
    table = []
    for m in ms:
        r = next(x for x in rows if x["method"] == m.name)
        results = [rec.result for rec in records if rec.method == m.name]
        if isinstance(results[0], sd.CompletionResult):
            iters = f"{np.mean([res.iterations for res in results]):.0f}"
            conv = f"{sum(res.converged for res in results)}/{len(results)}"
        else:
            iters, conv = "", ""
        table.append([m.name, H.fmt(*r["rmse_ratio"]), H.fmt(*r["rel"]), H.fmt(*r["delta1"]),
                      H.fmt(*r["runtime"], digits=2), iters, conv])
    body = H.markdown_table(header, table)
    body += "\n\nRMSE per frame (mean ± std over seeds), in the frame's depth units:\n\n"
    body += H.per_frame_table(records, [m.name for m in ms])
    notes = (H.step_note(args) + f" {FRACTION:.0%} of the valid pixels observed. `s` is in units of the median "
             f"observed depth m of each input (s = 0.03·m means edge_scale = 0.03 times m) and gamma = {GAMMA_REL:g} · m "
             "for every edge term; the other weights are the defaults. `RMSE / nearest` is the mean over frames × "
             "seeds of the per-input RMSE ratio to the nearest fill (lower is better); time is the wall time of "
             "`complete_depth`; iterations and converged are the solver's (ADMM for L1, IRLS otherwise).")
    text = H.section("Robust edge penalties", command=H.command_line("robust_penalties", argv or []),
                     frames_=frames, seeds=seeds, body=body, notes=notes, elapsed=time.perf_counter() - t0)
    return text, rows


#: The page's title and introduction, before the section :func:`run` writes.
PAGE_INTRO = """# Robust edge penalties

What each robust edge penalty is, how to use it and what the solvers guarantee:
[The objective and the solvers](guides/objective.md#robust-edge-penalties). Compare the times within the table
only: the machine is shared.

"""


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv  # the report's command line shows the options of the run
    args = H.parser(__doc__.splitlines()[0], default_step=DEFAULT_STEP).parse_args(argv)
    return H.script_main(_page, args, argv)


def _page(argv):
    """:func:`run` with the page's title and introduction before its section."""
    text, rows = run(argv)
    return PAGE_INTRO + text, rows


if __name__ == "__main__":
    sys.exit(main())
