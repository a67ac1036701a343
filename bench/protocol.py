"""The depth-completion protocol of the literature: 320x240, centre crop 304x228, 200 and 500 samples.

Run (full)::

    python -m bench.protocol --out docs/results_protocol.md

or ``--quick`` for a smoke test.  As in Ma & Karaman (ICRA 2018) and the
papers that follow them on NYU Depth V2, each frame is resized to 320x240 and
centre-cropped to 304x228; 200 or 500 of its valid depth pixels are sampled
uniformly at random (seeded), and RMSE (m), REL and δ<1.25ᵏ are computed on
the remaining valid pixels.  Resizing: the RGB image with bilinear
interpolation and anti-aliasing (``skimage.transform.resize``, order 1); the
depth with nearest-neighbour interpolation and *no* anti-aliasing (order 0),
applied to the depth with missing values set to 0 and mapped back to
"missing" afterwards, so no depth value is ever blended across an edge or
with a hole.  Frames: the NYU Depth V2 frames among :data:`frames.REPORT_FRAMES`
(registered raw NYU frames after the Eigen crop of :func:`frames.load`, the
labeled/inpainted Gupta-crop frame whole), the ones the literature uses.
Published numbers are on the 654-frame official test split with dense
(inpainted) ground truth; ours are on these few frames only, so they sit
*beside* published numbers, not in the same table.

May import :mod:`bench.harness`, numpy and scikit-image.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from skimage.transform import resize

from . import harness as H

RESIZE = (240, 320)
CROP = (228, 304)
COUNTS = (200, 500)
QUICK_RESIZE, QUICK_CROP, QUICK_COUNTS = (60, 80), (57, 76), (50, 125)


def protocol_frame(frame: H.FrameData, size=RESIZE, crop=CROP) -> H.FrameData:
    """Resize ``frame`` to ``size`` (rows, cols) and centre-crop it to ``crop`` (see the module notes)."""
    image = resize(frame.image, size, order=1, anti_aliasing=True, preserve_range=True)
    image = np.clip(np.round(image), 0, 255).astype(np.uint8)
    valid = np.isfinite(frame.depth) & (frame.depth > 0)
    depth = resize(np.where(valid, frame.depth, 0.0), size, order=0, anti_aliasing=False, preserve_range=True)
    depth = np.where(depth > 0, depth, np.nan)
    r0, c0 = (size[0] - crop[0]) // 2, (size[1] - crop[1]) // 2
    sl = (slice(r0, r0 + crop[0]), slice(c0, c0 + crop[1]))
    return H.FrameData(f"{frame.name} → {crop[1]}x{crop[0]}", np.ascontiguousarray(image[sl]),
                       np.ascontiguousarray(depth[sl]), frame.step, frame.units)


def run(argv=None):
    """Run the protocol; returns ``(markdown, rows)``."""
    args = H.parser(__doc__.splitlines()[0], default_step=1).parse_args(argv)
    t0 = time.perf_counter()
    if args.quick:
        frames = [protocol_frame(f, QUICK_RESIZE, QUICK_CROP) for f in H.quick_frames()]
        counts = QUICK_COUNTS
    else:
        frames = [protocol_frame(f) for f in H.get_frames(args, filter_fn=lambda n: n.startswith("nyu"))]
        counts = COUNTS
    seeds = H.seeds_of(args)
    methods = [H.NEAREST, H.LINEAR, H.BIHARMONIC, H.COLORIZATION, H.ours()]
    records = H.evaluate_all(methods, frames, seeds, counts=counts)
    rows = H.summarise(records, reference="nearest", metrics=("rmse", "rel", "delta1", "delta2", "delta3"))
    table = []
    for c in counts:
        for m in methods:
            r = next(x for x in rows if x["method"] == m.name and x["sampling"] == c)
            table.append([c, m.name, H.fmt(*r["rmse"]), H.fmt(*r["rel"]), H.fmt(*r["delta1"]), H.fmt(*r["delta2"]),
                          H.fmt(*r["delta3"]), H.fmt(*r["runtime"], digits=3), H.fmt(r["time_ratio"], digits=1)])
    body = H.markdown_table(["samples", "method", "RMSE (m)", "REL", "δ<1.25", "δ<1.25²", "δ<1.25³", "time (s)",
                             "time × nearest"], table)
    top = max(counts)
    ranked = sorted((r for r in rows if r["sampling"] == top), key=lambda r: r["rmse"][0])
    body = (f"Headline: {top} samples, RMSE (m) lowest first: "
            + "; ".join(f"{r['method']} {H.fmt(*r['rmse'])} (REL {H.fmt(r['rel'][0])}, δ1 {H.fmt(r['delta1'][0])})"
                        for r in ranked) + ".\n\n") + body
    notes = ("Quick mode: tiny frames resized and cropped at 1/4 of the protocol size (smoke test only). "
             if args.quick else "") + (
        "Ground truth of the raw NYU frames has holes; they are neither sampled nor scored. The frames are "
        "used at full resolution before the resize (`--step` does not apply). Mean ± std over frames × seeds.")
    text = H.section("Literature protocol (NYU Depth V2, 304x228, 200 / 500 samples)",
                     command=H.command_line("protocol", argv or []), frames_=frames, seeds=seeds, body=body,
                     notes=notes, elapsed=time.perf_counter() - t0)
    return text, rows


def main(argv=None) -> int:
    args = H.parser(__doc__.splitlines()[0], default_step=1).parse_args(argv)
    return H.script_main(run, args, argv)


if __name__ == "__main__":
    sys.exit(main())
