"""Paper Table 3.1: nearest-neighbour fill vs completion at 1 %, 5 % and 10 % observed depth.

Run (full, ~minutes on 2 cores)::

    python -m bench.sparsity --out docs/results_sparsity.md

or ``--quick`` for a seconds-long smoke test on tiny frames.  Frames are
:data:`frames.REPORT_FRAMES` subsampled by ``--step`` (default 2); ours is
``sparsedepth.complete_depth`` with the library's defaults (``sd.DEFAULT_SCHEDULE`` at each input's observed
fraction of the pixels) and ``solver="auto"``.
Every number is the mean ± std over frames × seeds, scored on the valid
ground-truth pixels hidden from the method.

May import :mod:`bench.harness`.
"""

from __future__ import annotations

import sys
import time

from . import harness as H

DEFAULT_STEP = 2


def table(records, fractions, methods, reference="nearest"):
    rows_out, rows = [], H.summarise(records, reference=reference)
    header = ["observed", "method", "RMSE", "MAE", "REL", "δ1", "time (s)", f"time × {reference}",
              f"RMSE / {reference}"]
    for frac in fractions:
        for m in methods:
            r = next(x for x in rows if x["method"] == m and x["sampling"] == frac)
            rows_out.append([f"{frac:.0%}", m, H.fmt(*r["rmse"]), H.fmt(*r["mae"]), H.fmt(*r["rel"]),
                             H.fmt(*r["delta1"]), H.fmt(*r["runtime"], digits=2), H.fmt(r["time_ratio"], digits=1),
                             H.fmt(*r["rmse_ratio"])])
    return H.markdown_table(header, rows_out), rows


def run(argv=None):
    """Run the benchmark; returns ``(markdown, rows)`` (rows from :func:`harness.summarise`)."""
    args = H.parser(__doc__.splitlines()[0], default_step=DEFAULT_STEP).parse_args(argv)
    t0 = time.perf_counter()
    frames = H.get_frames(args)
    seeds = H.seeds_of(args)
    methods = [H.NEAREST, H.ours()]
    records = H.evaluate_all(methods, frames, seeds, fractions=H.FRACTIONS)
    body, rows = table(records, H.FRACTIONS, [m.name for m in methods])
    body += "\n\nRMSE per frame (mean ± std over seeds) at 5 %, in the frame's depth units:\n\n"
    body += H.per_frame_table(records, [m.name for m in methods], sampling=0.05)
    notes = (H.step_note(args) + " RMSE/MAE are averaged over frames of different depth units and ranges "
             "(KITTI tens of metres; Teddy in pixels of disparity), so the scale-free `RMSE / nearest` (mean "
             "over frames × seeds of the per-input ratio) and REL/δ1 are the comparable columns. `time × nearest` "
             "is Σ t / Σ t_nearest over the same runs.")
    at5 = {r["method"]: r for r in rows if r["sampling"] == 0.05}
    if "ours" in at5:
        o = at5["ours"]
        body = (f"Headline: at 5 % observed, ours has {H.fmt(*o['rmse_ratio'])} × the RMSE of the nearest fill "
                f"(mean ± std over {o['n']} inputs) at {H.fmt(o['time_ratio'], digits=0)} × its runtime "
                f"({H.fmt(o['runtime'][0], digits=2)} s per frame).\n\n") + body
    text = H.section("Sparsity (paper Table 3.1)", command=H.command_line("sparsity", argv or []),
                     frames_=frames, seeds=seeds, body=body, notes=notes, elapsed=time.perf_counter() - t0)
    return text, rows


def main(argv=None) -> int:
    args = H.parser(__doc__.splitlines()[0], default_step=DEFAULT_STEP).parse_args(argv)
    return H.script_main(run, args, argv)


if __name__ == "__main__":
    sys.exit(main())
