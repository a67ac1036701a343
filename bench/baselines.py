"""Every baseline side by side with ours, on the same frames and inputs, at 1 %, 5 % and 10 % observed.

Run (full)::

    python -m bench.baselines --out docs/results_baselines.md

or ``--quick`` for a smoke test.  Methods: nearest-neighbour fill,
``scipy.interpolate.griddata`` linear (nearest outside the hull),
``skimage.restoration.inpaint_biharmonic``, the Levin/NYU-toolbox
colorization fill (:func:`sparsedepth.colorization_baseline`) and ours
(``complete_depth`` with the library's defaults, ``sd.DEFAULT_SCHEDULE`` at each input's observed fraction of
the pixels, ``solver="auto"``).  Frames
are :data:`frames.REPORT_FRAMES` subsampled by ``--step`` (default 2: the
biharmonic inpainting takes tens of seconds per full-resolution frame).

May import :mod:`sparsedepth`, :mod:`bench.harness` and :mod:`bench.sparsity` (its table layout).
"""

from __future__ import annotations

import sys
import time

from . import harness as H
from . import sparsity

DEFAULT_STEP = 2


def run(argv=None):
    """Run the benchmark; returns ``(markdown, rows)``."""
    args = H.parser(__doc__.splitlines()[0], default_step=DEFAULT_STEP).parse_args(argv)
    t0 = time.perf_counter()
    frames = H.get_frames(args)
    seeds = H.seeds_of(args)
    methods = [H.NEAREST, H.LINEAR, H.BIHARMONIC, H.COLORIZATION, H.ours()]
    records = H.evaluate_all(methods, frames, seeds, fractions=H.FRACTIONS)
    names = [m.name for m in methods]
    body, rows = sparsity.table(records, H.FRACTIONS, names)
    body += "\n\nRMSE per frame (mean ± std over seeds) at 5 %, in the frame's depth units:\n\n"
    body += H.per_frame_table(records, names, sampling=0.05)
    notes = (H.step_note(args) + " `RMSE / nearest` is the mean over frames × seeds of the per-input ratio; "
             "`time × nearest` is Σ t / Σ t_nearest over the same runs. Biharmonic and linear fills are not "
             "clipped (they may overshoot). The colorization fill smooths the observed pixels too (toolbox α = 1).")
    at5 = sorted((r for r in rows if r["sampling"] == 0.05), key=lambda r: r["rmse_ratio"][0])
    body = ("Headline: at 5 % observed, RMSE / nearest (mean over frames × seeds), lowest first: "
            + "; ".join(f"{r['method']} {H.fmt(*r['rmse_ratio'])}" for r in at5) + ".\n\n") + body
    text = H.section("Baselines side by side", command=H.command_line("baselines", argv or []), frames_=frames,
                     seeds=seeds, body=body, notes=notes, elapsed=time.perf_counter() - t0)
    return text, rows


def main(argv=None) -> int:
    args = H.parser(__doc__.splitlines()[0], default_step=DEFAULT_STEP).parse_args(argv)
    return H.script_main(run, args, argv)


if __name__ == "__main__":
    sys.exit(main())
