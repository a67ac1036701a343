"""The figures of ``docs/uncertainty.md``: real frames completed by the command line, with and without
``--max-uncertainty``.

Run::

    python -m bench.figures            # writes docs/figures/*.png (needs matplotlib and ../shared/data)

Each picture is exactly what the command line writes: 5 % of the frame's valid ground truth kept at random
(seed 0), the default weights; ``<frame>_all_vis.png`` is ``--depth-vis`` of the plain run,
``<frame>_trusted_vis.png`` and ``<frame>_trusted.jpg`` (``--figure``, with the uncertainty panel) those of
the run with ``--max-uncertainty``.  Frames: KITTI
0000000050 (LiDAR ground truth only in the lower part: the sky has no sample), NYU Depth V2 00050 whole
(the registered Kinect frame with its zero border, not the Eigen crop) and TUM 0 (border holes).

May import :mod:`sparsedepth` and :mod:`bench.harness`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import sparsedepth as sd
from sparsedepth.complete import main as command

from .harness import DOCS

FIGURES = DOCS / "figures"

#: (figure name, image file, depth file, --depth-scale, --max-uncertainty in metres)
CASES = (
    ("kitti_0000000050", "kitti_metric3d/rgb_0000000050.png", "kitti_metric3d/depth_0000000050.png", "kitti", "2"),
    ("nyu_00050", "nyu_metric3d/rgb_00050.jpg", "nyu_metric3d/sync_depth_00050.png", "nyu", "0.2"),
    ("tum_0", "tum_open3d/TUM_color.png", "tum_open3d/TUM_depth.png", "tum", "0.2"),
)


def argv_of(root: Path, image: str, depth: str, scale: str, out: Path, max_uncertainty=None) -> list[str]:
    """The command line of one run: its ``--depth-vis`` picture and, with ``max_uncertainty``, the figure (JPEG)."""
    argv = ["--image", str(root / image), "--depth", str(root / depth), "--depth-scale", scale,
            "--keep-fraction", "0.05", "--seed", "0", "--depth-vis", str(out.with_name(out.name + "_vis.png")), "-q"]
    if max_uncertainty is not None:
        argv += ["--max-uncertainty", max_uncertainty, "--figure", str(out.with_name(out.name + ".jpg"))]
    return argv


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=FIGURES, help=f"folder of the figures (default {FIGURES})")
    args = p.parse_args(argv)
    root = sd.shared_data_dir()
    if root is None:
        print("the shared data folder (../shared/data or $SPARSEDEPTH_DATA) is missing", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    for name, image, depth, scale, limit in CASES:
        for suffix, max_uncertainty in (("_all", None), ("_trusted", limit)):
            out = args.out / f"{name}{suffix}"
            line = argv_of(Path(root), image, depth, scale, out, max_uncertainty)
            print("python -m sparsedepth.complete " + " ".join(line), flush=True)
            status = command(line)
            if status:
                return status
    return 0


if __name__ == "__main__":
    sys.exit(main())
