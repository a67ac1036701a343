"""Command line: ``python -m sparsedepth.complete``.

Completes one frame (the embedded Middlebury Motorcycle demo, or your image
and depth files), fills the holes of raw depth, or runs a batch of frames.
Everything is done by library functions; this module only parses options,
reads and writes files, prints the table and progress (on stderr), and turns
library errors into one line on stderr with exit code 2.

Exit codes: 0 success (a batch: every frame has an ok row, including frames
skipped because an earlier run did them); 1 a batch finished but some frames
failed (error rows in the CSV); 2 bad options or input (one line on stderr,
before any frame runs), a CSV written with other settings (see --overwrite),
or the CSV could not be written (e.g. a full disk); 130 interrupted by SIGINT
(Ctrl-C); 143 terminated by SIGTERM.  An interrupted or terminated batch
stops its worker processes, removes their temporary files and keeps the rows
of the finished frames: the same command again resumes it.

Files: no output may be an input or another output, and every output is
checked to be creatable before the work starts.  One frame's outputs are
written all or nothing (see :func:`sparsedepth.cli.outputs.commit`).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import datetime
import importlib.util
import io as _io
import json
import math
import os
import platform
import signal
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from .. import __version__
from ..batch import (
    BatchOptions,
    FileFrame,
    default_workers,
    evaluate_frame,
    find_frame_pairs,
    find_frames,
    nyu_frames,
    nyu_h5_frames,
    run_batch,
    settings_path,
)
from ..datasets import load_motorcycle
from ..holes.fill import FILL_METHODS
from .outputs import Named, check_distinct, check_writable, commit
from ..io.formats import (
    DEPTH_SCALES,
    KINECT_NYU,
    MAX_PIXELS,
    depth_writer,
    resolve_scale,
    read_calib,
    read_depth,
    read_image,
    read_mask,
)
from ..result import ClampWarning
from ..solvers.core import SOLVERS
from ..objective.weights import DEFAULT_WEIGHTS, Weights

__all__ = ["main", "build_parser"]

PROG = "python -m sparsedepth.complete"
DEMO_DIR = "sparsedepth-demo"
DEMO_KEEP_FRACTION = 0.05
DEMO_DOWNSAMPLE = 2
_OUT_EXTENSIONS = (".png", ".npy", ".npz", ".h5", ".hdf5", ".pfm")
_FIGURE_EXTENSIONS = (".png", ".pdf", ".svg", ".jpg", ".jpeg")
_LIBRARY_ERRORS = (ValueError, OSError, IndexError, KeyError)  # OSError covers FileNotFoundError
_ABSURD_LOW, _ABSURD_HIGH = 1e-3, 1e3  # metres: a median outside this means a wrong scale
_PROGRESS_EVERY = 1.0  # seconds between progress lines

_WEIGHT_HELP = {
    "alpha": "data fidelity at observed pixels",
    "beta": "first-order L2 smoothness",
    "gamma": "edge-aware L1 smoothness (0 = quadratic objective)",
    "delta": "pull towards the nearest-neighbour fill",
    "kappa": "edge sensitivity of w = exp(-kappa |grad I|)",
    "beta_image": "image-weighted first-order L2 smoothness",
    "beta_second": "second-order (thin-plate) smoothness",
}

EPILOG = f"""\
examples:
  {PROG}
      demo: Middlebury 2014 Motorcycle (every 2nd pixel), keep 5 % of the depth,
      complete it, print nearest-neighbour vs completed, write ./{DEMO_DIR}/
  {PROG} --image rgb.png --depth sparse.png --depth-scale kitti --out dense.png
      complete a sparse KITTI depth PNG (metres = value / 256); the PNG output
      uses the input's scale
  {PROG} --image rgb.png --depth dense.png --depth-scale nyu --keep-fraction 0.02 \\
      --solver irls --gamma 0.02 --json run.json --figure run.png
      simulate 2 % sparse input from a dense NYU map (mm) and score the result
  {PROG} --fill-holes --image images.png --depth rawdepth.png --depth-scale mm \\
      --truth depth.png --out filled.png
      fill the holes of raw Kinect depth the NYU-toolbox way (colorization)
  {PROG} --nyu-mat nyu_depth_v2_labeled.mat --indices 0:100 --fill-holes \\
      --csv fill.csv --workers 4
      a batch: one row of metrics per frame in fill.csv, written as frames
      finish; the same command again skips the frames already done and runs the
      missing and failed ones (--overwrite starts afresh)
  {PROG} --batch image_02/data --batch-depths proj_depth/groundtruth/image_02 \\
      --depth-scale kitti --keep-fraction 0.05 --csv kitti.csv --outdir dense/
      a KITTI-style pair of folders (same file names); --batch on a folder of
      NYU .h5 files (rgb + depth) reads those

depth scales: stored integer value / scale = metres; presets {', '.join(f'{k} ({v:g})' for k, v in DEPTH_SCALES.items())}.
exit codes: 0 ok; 1 batch with failed frames (rows with an error in the CSV);
2 bad option or input (one line on stderr, no output written), a CSV written
with other settings, or the CSV could not be written; 130 SIGINT (Ctrl-C);
143 SIGTERM.  A stopped batch ends its workers, removes their temporary files
and keeps the finished rows: rerun the same command to resume.
"""


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line on stderr (exit code 2)."""

    def error(self, message):  # noqa: D401 - argparse API
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


class _UsageError(Exception):
    """A bad combination of options, found after parsing."""


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def _fraction(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in (0, 1], got {text!r}") from None
    if not 0 < value <= 1:
        raise argparse.ArgumentTypeError(f"expected a number in (0, 1], got {text!r}")
    return value


def _nonnegative(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return value


def _finite(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def _scale(text):
    if text.lower() in DEPTH_SCALES:
        return text.lower()
    try:
        return resolve_scale(float(text))
    except (ValueError, TypeError):
        raise argparse.ArgumentTypeError(
            f"expected a positive number or one of {', '.join(DEPTH_SCALES)}, got {text!r}"
        ) from None


def _indices(text):
    """'5', '0:10', '0:100:10' or '1,4,7' -> slice or list of int."""
    try:
        if ":" in text:
            parts = [int(p) if p.strip() else None for p in text.split(":")]
            if len(parts) > 3:
                raise ValueError
            return slice(*parts)
        return [int(p) for p in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected an index, a range start:stop[:step] or a list i,j,k, got {text!r}"
        ) from None


def build_parser() -> argparse.ArgumentParser:
    """The one argument parser of ``python -m sparsedepth.complete``."""
    parser = _Parser(
        prog=PROG,
        description=(
            "Dense depth from an RGB image and sparse depth by regularised optimisation "
            "(sparsedepth.complete_depth); hole filling of raw depth (sparsedepth.fill_holes); "
            "batches of frames.  Without arguments: a demo on the Middlebury 2014 Motorcycle "
            "frame shipped with scikit-image."
        ),
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    inp = parser.add_argument_group("input (one frame)")
    inp.add_argument("--image", metavar="PATH", help="RGB (or grey) image: png, jpg, ppm, pgm, bmp, tif.")
    inp.add_argument("--depth", metavar="PATH",
                     help="sparse or raw depth (0/NaN/inf = unknown), or a dense map with --keep-*: "
                          "png/pgm/tif, npy, npz, h5 (integer data need --depth-scale), pfm (disparity: needs "
                          "--calib, or --depth-scale m if it holds metres).")
    inp.add_argument("--mask", metavar="PATH",
                     help="optional mask of observed pixels: npy/npz/h5 (bool or 0/1) or an image, 1-bit PNG "
                          "included (non-zero = observed).")
    inp.add_argument("--truth", metavar="PATH",
                     help="optional ground-truth depth (same formats and scale as --depth) to score against, "
                          "on the pixels not observed.")
    inp.add_argument("--depth-scale", type=_scale, metavar="SCALE",
                     help="divisor of stored depth values: nyu or mm (1000), kitti (256), tum (5000), m (1), or a "
                          "number.  Required for integer data (png, pgm, tif, integer npy/npz/h5); float data default "
                          "to 1, except a pfm, which needs this or --calib.")
    inp.add_argument("--depth-key", metavar="NAME", help="array name in an .npz or dataset in an .h5 depth file.")
    inp.add_argument("--calib", metavar="CALIB_TXT",
                     help="Middlebury/ETH3D calib.txt: --depth holds disparity in pixels, converted to metres; "
                          "or kinect-nyu: --depth holds raw Kinect v1 disparity (NYU Depth V2 raw .pgm, with "
                          "--byteorder little), metres = 351.3 / (1092.5 - value), 2047 = missing.")
    inp.add_argument("--byteorder", choices=["big", "little"],
                     help="byte order of 16-bit binary pgm/ppm (default: big, the standard, refusing rasters that "
                          "look byte-swapped); NYU Depth V2 raw .pgm files are little.")
    inp.add_argument("--invalid-value", dest="invalid_values", action="append", type=_finite, metavar="V",
                     help="stored value meaning 'no measurement' in --depth/--truth (repeatable; Kinect v1 2047, "
                          "RealSense 65535); 0, NaN and inf always are.")
    inp.add_argument("--min-depth", type=_nonnegative, metavar="M",
                     help="depth below M metres (after --depth-scale/--calib) counts as missing.")
    inp.add_argument("--max-depth", type=_nonnegative, metavar="M",
                     help="depth above M metres counts as missing.")
    inp.add_argument("--max-pixels", type=_positive_int, default=MAX_PIXELS, metavar="N",
                     help=f"refuse input images declaring more than N pixels, from their header (default {MAX_PIXELS}).")
    inp.add_argument("--downsample", type=_positive_int, metavar="N",
                     help=f"keep every N-th row and column (default {DEMO_DOWNSAMPLE} for the demo, 1 otherwise).")

    sim = parser.add_argument_group("simulated sparse input (scores against the dense map)")
    keep = sim.add_mutually_exclusive_group()
    keep.add_argument("--keep-fraction", type=_fraction, metavar="F",
                      help=f"keep this fraction of the valid depth pixels (demo default {DEMO_KEEP_FRACTION}).")
    keep.add_argument("--keep-count", type=_positive_int, metavar="N", help="keep this many valid depth pixels.")
    sim.add_argument("--seed", type=int, default=0, help="seed of the sampling (default 0).")

    method = parser.add_argument_group("method")
    method.add_argument("--solver", choices=["auto", *sorted(SOLVERS)], default=None,
                        help="solver of complete_depth (default auto: amg for gamma = 0, else admm).")
    for f in dataclasses.fields(Weights):
        method.add_argument(
            f"--{f.name.replace('_', '-')}", dest=f"w_{f.name}", type=_nonnegative, metavar="W",
            help=f"weight {f.name}: {_WEIGHT_HELP.get(f.name, 'a term weight of sparsedepth.Weights')} "
                 f"(default {getattr(DEFAULT_WEIGHTS, f.name):g}).",
        )
    method.add_argument("--tol", type=float, metavar="TOL", help="solver tolerance (meaning per solver).")
    method.add_argument("--max-iter", type=_positive_int, metavar="N", help="maximum solver iterations.")
    method.add_argument("--no-clip", dest="clip_to_observed", action="store_false",
                        help="keep completed depth outside the range of the observed depth (by default the map is "
                             "clamped to [smallest, largest] observed value and the clamped pixels are counted).")
    method.add_argument("--fill-holes", action="store_true",
                        help="hole filling: every valid pixel of --depth is observed, the output is dense.")
    method.add_argument("--fill-method", choices=FILL_METHODS, default="colorization",
                        help="hole-filling method: colorization (NYU toolbox fill_depth_colorization, default) "
                             "or complete (this package's objective).")

    out = parser.add_argument_group("output")
    out.add_argument("--out", metavar="PATH",
                     help="dense depth: .png (16-bit, in the input's scale or --out-scale), .npy, .npz, .h5 or .pfm.")
    out.add_argument("--out-scale", type=_scale, metavar="SCALE",
                     help="scale of a PNG output (default: --depth-scale if given, else mm = 1000).")
    out.add_argument("--json", metavar="PATH", help="metrics, settings and solver history as JSON.")
    out.add_argument("--figure", metavar="PATH",
                     help="image | sparse input | nearest neighbour | completed | absolute error, colour bar in "
                          "metres (.png, .pdf, .svg, .jpg; needs matplotlib: pip install 'sparsedepth[plot]').")
    out.add_argument("--outdir", metavar="DIR",
                     help=f"write depth.npy, depth.png, metrics.json and figure.png (if matplotlib is installed) "
                          f"here (an existing folder; the demo creates its default ./{DEMO_DIR}/); batch: one depth file "
                          "per frame.")
    out.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr.")

    bat = parser.add_argument_group("batch")
    src = bat.add_mutually_exclusive_group()
    src.add_argument("--batch", metavar="DIR",
                     help="folder of frames paired by name: <image-prefix><id>.<ext> with <depth-prefix><id>.<ext>; "
                          "with --batch-depths, the image folder; a folder with no <image-prefix> image but .h5 "
                          "files (searched recursively) is read as NYU .h5 frames (rgb + depth in metres).")
    src.add_argument("--nyu-mat", metavar="FILE",
                     help="NYU Depth V2 labeled .mat (read lazily): --fill-holes fills rawDepths and scores against "
                          "depths; otherwise depths is sampled with --keep-fraction/--keep-count.")
    bat.add_argument("--indices", type=_indices, metavar="RANGE",
                     help="frames of --nyu-mat: 5, 0:10, 0:100:10 or 1,4,7 (default all).")
    bat.add_argument("--image-prefix", default="rgb_", help="image file prefix in --batch (default rgb_).")
    bat.add_argument("--depth-prefix", default="depth_", help="depth file prefix in --batch (default depth_).")
    bat.add_argument("--truth-prefix", default=None, help="optional ground-truth file prefix in --batch.")
    bat.add_argument("--csv", metavar="PATH",
                     help="per-frame metrics, one row per frame, written as frames finish.  If it exists (from the "
                          "same command) the run resumes: frames with an ok row and their output are skipped, "
                          "missing and failed ones run, and each failed row is replaced by the new one.  The "
                          "settings are kept beside it in PATH.settings.json.")
    bat.add_argument("--workers", type=_positive_int, metavar="N",
                     help=f"worker processes (default {default_workers()} here: half the CPUs, at least 1, "
                          "at most 8).")
    bat.add_argument("--out-format", choices=["npy", "npz", "h5", "pfm", "png"], default="npy",
                     help="format of the per-frame outputs in --outdir (default npy).")
    bat.add_argument("--batch-depths", metavar="DIR",
                     help="with --batch DIR: the depth folder, files named like the images (KITTI layout).")
    bat.add_argument("--batch-truths", metavar="DIR",
                     help="with --batch-depths: optional ground-truth folder, files named like the images.")
    bat.add_argument("--overwrite", action="store_true",
                     help="start the batch afresh: replace an existing --csv (even one written with other "
                          "settings) and recompute every frame.")
    _add_cluster_options(parser)
    return parser


def _add_cluster_options(parser) -> None:
    """--scheduler, --scheduler-file, --scheduler-timeout: a batch on a Dask cluster (sparsedepth.batch.distributed)."""
    cluster = parser.add_argument_group(
        "batch on a Dask cluster (pip install 'sparsedepth[distributed]'; frames and --outdir on a file system "
        "the workers share)")
    where = cluster.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run the frames on the Dask scheduler at ADDRESS (e.g. tcp://10.0.0.5:8786); default "
                            "$DASK_SCHEDULER_ADDRESS unless --workers is given.  The CSV is written here.")
    where.add_argument("--scheduler-file", metavar="PATH",
                       help="the JSON file of 'dask scheduler --scheduler-file PATH' (e.g. on SLURM).")
    cluster.add_argument("--scheduler-timeout", type=_positive_float, metavar="SECONDS",
                         help="wait this long for the scheduler, then for its first worker, before exit code 2 "
                              "(default 15).")


def _positive_float(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds > 0, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number of seconds > 0, got {text!r}")
    return value


def _check_cluster_options(args, mode) -> None:
    given = [name for name, value in (("--scheduler", args.scheduler), ("--scheduler-file", args.scheduler_file),
                                      ("--scheduler-timeout", args.scheduler_timeout)) if value is not None]
    if given and mode != "batch":
        raise _UsageError(f"{', '.join(given)} run a batch on a Dask cluster: they need --batch/--nyu-mat")
    if args.workers is not None and (args.scheduler is not None or args.scheduler_file is not None):
        raise _UsageError("--workers sizes the local process pool; with --scheduler/--scheduler-file the "
                          "cluster's workers run the frames")
    if mode == "batch" and _cluster_address(args) is not None and importlib.util.find_spec("distributed") is None:
        raise _UsageError("a batch on a Dask cluster needs dask.distributed, which is not installed: "
                          "pip install 'sparsedepth[distributed]'")


def _cluster_address(args):
    """(address, scheduler_file) of the Dask scheduler of a batch, or None for the local process pool."""
    if args.scheduler_file is not None:
        return None, args.scheduler_file
    address = args.scheduler
    if address is None and args.workers is None:
        address = os.environ.get("DASK_SCHEDULER_ADDRESS") or None
    return (address, None) if address is not None else None


# --------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------
def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _matplotlib():
    """The matplotlib Figure class and Agg canvas, or None if matplotlib is missing."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return None
    return Figure, FigureCanvasAgg


def _weights(args) -> tuple[Weights, dict]:
    given = {f.name: getattr(args, f"w_{f.name}") for f in dataclasses.fields(Weights)}
    given = {k: v for k, v in given.items() if v is not None}
    return DEFAULT_WEIGHTS.replace(**given), given


def _check_output(path, allowed, what) -> Path:
    path = Path(path)
    if path.suffix.lower() not in allowed:
        raise _UsageError(f"{what} '{path}': unsupported extension '{path.suffix or '(none)'}'; use {', '.join(allowed)}")
    return path


_DEPTH_OUTPUTS = ("--out", "depth.npy", "depth.png")


def _one_frame_outputs(args, mode) -> list[tuple[str, Named]]:
    """(kind, file) of every output of one frame; kind is the option or the file name in --outdir."""
    planned = []
    for flag, value in (("--out", args.out), ("--json", args.json), ("--figure", args.figure)):
        if value is not None:
            planned.append((flag, Named(flag, value, Path(value))))
    outdir = DEMO_DIR if mode == "demo" and args.outdir is None else args.outdir
    if outdir is not None:
        names = ["depth.npy", "depth.png", "metrics.json"]
        if _matplotlib() is not None:
            names.append("figure.png")
        planned += [(name, Named("--outdir", outdir, Path(outdir) / name, create_parent=mode == "demo"))
                    for name in names]
    return planned


def _one_frame_inputs(args) -> list[Named]:
    return [Named(flag, value, Path(value)) for flag, value in (
        ("--image", args.image), ("--depth", args.depth), ("--mask", args.mask), ("--truth", args.truth),
        ("--calib", args.calib)) if value is not None]


def _check_png_range(depth, scale, targets, what) -> None:
    """Refuse a PNG output whose depth would overflow 16 bits or round to 0 at ``scale``."""
    if not targets:
        return
    values = depth[np.isfinite(depth) & (depth > 0)]
    if values.size == 0:
        return
    high, low = float(values.max()), float(values.min())
    target = targets[0]
    other = ", or a float format (.npy, .npz, .h5, .pfm)" if target.flag == "--out" else ""
    if np.rint(high * scale) > np.iinfo(np.uint16).max:
        raise _UsageError(f"{target.label}: {what} reaches {high:.6g} m, which overflows a 16-bit PNG at scale "
                          f"{scale:g} ({high * scale:.0f} > 65535); give --out-scale {65535 / high:.6g} or "
                          f"less{other}")
    if np.rint(low * scale) == 0:
        raise _UsageError(f"{target.label}: {what} has {low:.6g} m, which rounds to 0 (invalid) in a PNG at scale "
                          f"{scale:g}; give --out-scale above {0.5 / low:.6g}{other}")


def _validate(args) -> str:
    """Check option combinations; return the mode: 'demo', 'files' or 'batch'."""
    batch = args.batch is not None or args.nyu_mat is not None
    files = args.image is not None or args.depth is not None
    if batch and files:
        raise _UsageError("--batch/--nyu-mat and --image/--depth are exclusive")
    if files and (args.image is None or args.depth is None):
        raise _UsageError("--image and --depth go together")
    mode = "batch" if batch else "files" if files else "demo"
    if mode == "demo" and (args.mask or args.truth or args.calib or args.depth_key):
        raise _UsageError("--mask, --truth, --calib and --depth-key need --image and --depth")
    if mode == "demo" and args.fill_holes:
        raise _UsageError("--fill-holes needs --image and --depth (raw depth), or --batch/--nyu-mat")
    if args.fill_holes and (args.keep_fraction is not None or args.keep_count is not None):
        raise _UsageError("--keep-fraction/--keep-count simulate sparse input; they do not apply to --fill-holes")
    colorization = args.fill_holes and args.fill_method == "colorization"
    if colorization:
        weight_options = [f"--{f.name.replace('_', '-')}" for f in dataclasses.fields(Weights)
                          if getattr(args, f"w_{f.name}") is not None]
        solver_options = [name for name, value in (("--solver", args.solver), ("--tol", args.tol),
                                                   ("--max-iter", args.max_iter)) if value is not None]
        if weight_options or solver_options:
            raise _UsageError(f"{', '.join(weight_options + solver_options)} apply to --fill-method complete, "
                              "not colorization")
    if mode == "batch":
        if args.csv is None:
            raise _UsageError("a batch needs --csv PATH for the per-frame metrics")
        if args.out or args.json or args.figure or args.mask or args.truth or args.calib:
            raise _UsageError("--out, --json, --figure, --mask, --truth and --calib are for one frame; "
                              "a batch writes --csv (and per-frame depth with --outdir)")
        if args.indices is not None and args.nyu_mat is None:
            raise _UsageError("--indices selects frames of --nyu-mat")
        if (args.nyu_mat is not None and not args.fill_holes and args.keep_fraction is None
                and args.keep_count is None):
            raise _UsageError("--nyu-mat without --fill-holes samples the dense depths: give --keep-fraction "
                              "or --keep-count")
        _check_output(args.csv, (".csv",), "--csv")
    else:
        if args.csv or args.workers or args.indices is not None:
            raise _UsageError("--csv, --workers and --indices are for --batch/--nyu-mat")
        if args.out:
            _check_output(args.out, _OUT_EXTENSIONS, "--out")
        if args.json:
            _check_output(args.json, (".json",), "--json")
        if args.figure:
            _check_output(args.figure, _FIGURE_EXTENSIONS, "--figure")
        outputs = [target for _, target in _one_frame_outputs(args, mode)]
        check_distinct(outputs, _one_frame_inputs(args))
        check_writable(outputs)
        if args.figure and _matplotlib() is None:
            raise _UsageError("--figure needs matplotlib, which is not installed: "
                              "pip install 'sparsedepth[plot]' (or matplotlib)")
    _check_cluster_options(args, mode)
    return mode


class _Progress:
    """Solver callback printing the iteration at most every second on stderr."""

    def __init__(self, stream, enabled: bool):
        self.stream, self.enabled = stream, enabled
        self.start = self.last = time.monotonic()

    def __call__(self, state):
        now = time.monotonic()
        if self.enabled and now - self.last >= _PROGRESS_EVERY:
            self.last = now
            print(f"  iteration {state.iteration:5d}  F = {state.objective:.6e}  ({now - self.start:.1f} s)",
                  file=self.stream, flush=True)


def _warn_scale(depth, what, scale, stream) -> None:
    values = depth[np.isfinite(depth) & (depth > 0)]
    if values.size == 0:
        return
    median = float(np.median(values))
    if not _ABSURD_LOW <= median <= _ABSURD_HIGH:
        print(f"warning: {what} has median depth {median:.4g} m with --depth-scale {scale if scale else 1}: "
              "check the scale (presets nyu/mm 1000, kitti 256, tum 5000, m 1)", file=stream)


_READER_FLAGS = {
    "scale": "--depth-scale", "key": "--depth-key", "byteorder": "--byteorder",
    "invalid_values": "--invalid-value", "min_depth": "--min-depth", "max_depth": "--max-depth",
    "max_pixels": "--max-pixels", "calib": "--calib",
}
_KINECT_CALIB = "kinect-nyu"


def _validate_reader_options(args, mode) -> None:
    """Reader options apply to the user's files (one frame or a batch); check their combinations."""
    given = [flag for flag, value in (("--byteorder", args.byteorder), ("--invalid-value", args.invalid_values),
                                      ("--min-depth", args.min_depth), ("--max-depth", args.max_depth))
             if value is not None]
    if args.max_pixels != MAX_PIXELS:
        given.append("--max-pixels")
    if given and mode == "demo":
        raise _UsageError(f"{', '.join(given)} apply to your files (--image/--depth or a batch), not the demo")
    if args.min_depth is not None and args.max_depth is not None and args.min_depth > args.max_depth:
        raise _UsageError(f"--min-depth {args.min_depth:g} is larger than --max-depth {args.max_depth:g}")


def _check_units(path, flag, args) -> None:
    """A PFM holds disparity (Middlebury, ETH3D) unless the user says otherwise."""
    if Path(path).suffix.lower() == ".pfm" and args.calib is None and args.depth_scale is None:
        raise _UsageError(
            f"{flag} '{path}' is a PFM, the Middlebury/ETH3D disparity format (pixels, not metres): give --calib "
            "calib.txt to convert disparity to metres, or --depth-scale m if the file holds depth in metres"
        )


def _read_mask(path, shape, max_pixels) -> np.ndarray:
    array = read_mask(path, max_pixels=max_pixels, name="--mask", option_names=_READER_FLAGS)
    if array.shape != tuple(shape):
        raise ValueError(f"--mask '{path}' has shape {array.shape} but the depth has shape {tuple(shape)}")
    return array


@contextlib.contextmanager
def _warnings_as_lines(stream):
    """Library warnings raised inside the block become one ``warning:`` line each on ``stream``.

    Yields the list of caught warnings, complete once the block has ended.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield caught
    for record in caught:
        text = _one_line(record.message)
        if issubclass(record.category, ClampWarning):
            text += "; --no-clip keeps them"
        print(f"warning: {text}", file=stream)


def _read_depth_flag(path, flag, args, calib, stream) -> np.ndarray:
    """read_depth with the reader options, library warnings printed as one line each."""
    _check_units(path, flag, args)
    with _warnings_as_lines(stream) as caught:
        depth = read_depth(path, scale=args.depth_scale, calib=calib, key=args.depth_key, byteorder=args.byteorder,
                           invalid_values=args.invalid_values or (), min_depth=args.min_depth,
                           max_depth=args.max_depth, max_pixels=args.max_pixels, name=flag,
                           option_names=_READER_FLAGS)
    for record in caught:
        if "Kinect v1" in str(record.message) and calib is not KINECT_NYU:
            print(f"warning: raw Kinect v1 disparity (e.g. NYU Depth V2 raw .pgm) is not metres; "
                  f"--calib {_KINECT_CALIB} converts it", file=stream)
    return depth


def _read_inputs(args, stream):
    """(image, depth, mask, truth, description) of the one-frame mode, in metres."""
    image = read_image(args.image, max_pixels=args.max_pixels, name="--image", option_names=_READER_FLAGS)
    calib = None
    if args.calib is not None:
        calib = KINECT_NYU if args.calib == _KINECT_CALIB else read_calib(args.calib, name="--calib")
    depth = _read_depth_flag(args.depth, "--depth", args, calib, stream)
    if image.shape[:2] != depth.shape:
        raise ValueError(f"--image '{args.image}' is {image.shape[0]}x{image.shape[1]} but --depth '{args.depth}' is "
                         f"{depth.shape[0]}x{depth.shape[1]} (H x W); they must have the same size")
    if not np.any(np.isfinite(depth)):
        raise ValueError(f"--depth '{args.depth}' has no valid pixel (all 0, NaN, inf or excluded by "
                         "--invalid-value/--min-depth/--max-depth)")
    _warn_scale(depth, f"--depth '{args.depth}'", args.depth_scale, stream)
    mask = None if args.mask is None else _read_mask(args.mask, depth.shape, args.max_pixels)
    truth = None
    if args.truth is not None:
        truth = _read_depth_flag(args.truth, "--truth", args, calib, stream)
        if truth.shape != depth.shape:
            raise ValueError(f"--truth '{args.truth}' has shape {truth.shape} but --depth '{args.depth}' has "
                             f"shape {depth.shape}")
        _warn_scale(truth, f"--truth '{args.truth}'", args.depth_scale, stream)
    return image, depth, mask, truth, f"{args.image} + {args.depth}"


def _jsonable(value):
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return _jsonable(value.item())
    return value


def _report(args, argv, outcome, description, weights, weights_given, png_scale) -> dict:
    result = outcome.result
    report = {
        "sparsedepth": __version__,
        "command": [PROG, *argv],
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "machine": {"python": platform.python_version(), "platform": platform.platform(),
                    "processor": platform.machine()},
        "input": description,
        "shape": list(outcome.depth.shape),
        "observed": int(outcome.observed.sum()),
        "method": outcome.method,
        "runtime": outcome.runtime,
        "nearest_runtime": outcome.nearest_runtime,
        "metrics": None if outcome.metrics is None else {
            "scored": outcome.metrics.count,
            "completed": outcome.metrics.as_dict(),
            "nearest": outcome.nearest_metrics.as_dict(),
        },
        "output_png_scale": png_scale,
    }
    if result is not None:
        report.update(
            solver=result.solver, weights=weights.as_dict(), weights_given=weights_given,
            converged=result.converged, message=result.message, iterations=result.iterations,
            objective=result.objective, terms=result.terms, clamped=result.clamped,
            solver_runtime=result.runtime,
            history=[dataclasses.asdict(record) for record in result.history],
        )
    return _jsonable(report)


def _print_table(outcome, description, stream) -> None:
    h, w = outcome.depth.shape
    n_obs = int(outcome.observed.sum())
    print(f"{description}: {h}x{w}, {n_obs} observed pixels ({n_obs / (h * w):.1%})", file=stream)
    if outcome.result is not None:
        r = outcome.result
        print(f"solver {r.solver}: {'converged' if r.converged else 'NOT converged'} after {r.iterations} "
              f"iterations ({r.message})", file=stream)
    if outcome.metrics is None:
        print(f"{outcome.method}: {outcome.runtime:.2f} s; no ground truth to score against "
              "(give --truth, or a dense --depth with --keep-fraction)", file=stream)
        return
    print(f"scored on {outcome.metrics.count} pixels not observed", file=stream)
    print(f"{'method':<28} {'RMSE [m]':>9} {'MAE [m]':>9} {'REL':>8} {'δ1':>7} {'time [s]':>9}", file=stream)
    for name, m, t in (("nearest neighbour", outcome.nearest_metrics, outcome.nearest_runtime),
                       (outcome.method, outcome.metrics, outcome.runtime)):
        print(f"{name:<28} {m.rmse:9.4f} {m.mae:9.4f} {m.rel:8.4f} {m.delta1:7.4f} {t:9.2f}", file=stream)


def _render_figure(image, outcome, extension) -> bytes:
    """image | sparse input | nearest neighbour | completed | |error|, as file bytes."""
    Figure, FigureCanvasAgg = _matplotlib()
    truth = outcome.truth
    panels = 5 if truth is not None else 4
    fig = Figure(figsize=(3.2 * panels + 1.2, 3.0 * image.shape[0] / image.shape[1] + 0.8), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, panels)
    reference = outcome.sparse[outcome.observed] if truth is None else truth[np.isfinite(truth)]
    vmin, vmax = np.percentile(np.concatenate([reference, outcome.depth.ravel()]), [1, 99])
    axes[0].imshow(image, cmap="gray" if image.ndim == 2 else None)
    axes[0].set_title("image")
    depth_im = None
    for ax, data, title in ((axes[1], outcome.sparse, f"input ({int(outcome.observed.sum())} px)"),
                            (axes[2], outcome.nearest, "nearest neighbour"),
                            (axes[3], outcome.depth, outcome.method)):
        depth_im = ax.imshow(np.ma.masked_invalid(data), cmap="turbo", vmin=vmin, vmax=vmax,
                             interpolation="nearest")
        ax.set_title(title)
    fig.colorbar(depth_im, ax=axes[1:4], label="depth [m]", shrink=0.9)
    if truth is not None:
        error = np.abs(outcome.depth - truth)
        err_im = axes[4].imshow(np.ma.masked_invalid(error), cmap="magma", vmin=0,
                                vmax=max(float(np.nanpercentile(error, 99)), 1e-6), interpolation="nearest")
        axes[4].set_title("|output - truth|")
        fig.colorbar(err_im, ax=axes[4], label="absolute error [m]", shrink=0.9)
    for ax in axes:
        ax.set_axis_off()
    buffer = _io.BytesIO()
    fig.savefig(buffer, format=extension.lstrip(".").replace("jpg", "jpeg"), dpi=100)
    return buffer.getvalue()


def _bytes_writer(data: bytes):
    return lambda tmp: Path(tmp).write_bytes(data)


# --------------------------------------------------------------------------------------
# modes
# --------------------------------------------------------------------------------------
def _run_one(args, argv, mode, stdout, stderr) -> int:
    weights, weights_given = _weights(args)
    if mode == "demo":
        frame = load_motorcycle()
        image, depth, mask, truth = frame.image, np.asarray(frame.depth), None, None
        description = "Middlebury 2014 Motorcycle"
        downsample = DEMO_DOWNSAMPLE if args.downsample is None else args.downsample
        keep_fraction = args.keep_fraction
        if keep_fraction is None and args.keep_count is None:
            keep_fraction = DEMO_KEEP_FRACTION
    else:
        image, depth, mask, truth, description = _read_inputs(args, stderr)
        downsample = 1 if args.downsample is None else args.downsample
        keep_fraction = args.keep_fraction
    if downsample > 1:
        description += f" (downsampled by {downsample})"
        image, depth = image[::downsample, ::downsample], depth[::downsample, ::downsample]
        mask = None if mask is None else mask[::downsample, ::downsample]
        truth = None if truth is None else truth[::downsample, ::downsample]
    png_scale = args.out_scale if args.out_scale is not None else (args.depth_scale or 1000.0)
    png_scale = resolve_scale(png_scale)
    planned = _one_frame_outputs(args, mode)
    png_targets = [target for kind, target in planned
                   if kind in _DEPTH_OUTPUTS and target.path.suffix.lower() == ".png"]
    _check_png_range(depth if mask is None else np.where(mask, depth, np.nan), png_scale, png_targets,
                     f"the depth of {'the demo' if mode == 'demo' else '--depth'}")

    complete_fill = args.fill_holes and args.fill_method == "complete"
    use_solver = not args.fill_holes or complete_fill
    with _warnings_as_lines(stderr):
        outcome = evaluate_frame(
            image, depth, mask=mask, truth=truth, task="fill" if args.fill_holes else "complete",
            keep_fraction=keep_fraction, keep_count=args.keep_count, seed=args.seed,
            fill_method=args.fill_method, weights=weights if use_solver else None,
            solver=args.solver or "auto", tol=args.tol, max_iter=args.max_iter,
            callback=_Progress(stderr, not args.quiet) if use_solver else None,
            clip_to_observed=args.clip_to_observed,
        )

    # every output is encoded and checked before any file is touched; commit writes all or none
    _check_png_range(outcome.depth, png_scale, png_targets, "the completed depth")
    report = _report(args, argv, outcome, description, weights, weights_given, png_scale)
    report_text = (json.dumps(report, indent=2, allow_nan=False) + "\n").encode()
    kinds = {kind for kind, _ in planned}
    figure_bytes = None
    if "--figure" in kinds:
        figure_bytes = _render_figure(image, outcome, Path(args.figure).suffix.lower())
    if "figure.png" in kinds and not (args.figure or "").lower().endswith(".png"):
        outdir_figure = _render_figure(image, outcome, ".png")
    else:
        outdir_figure = figure_bytes

    items = []
    for kind, target in planned:
        if kind in _DEPTH_OUTPUTS:
            try:
                writer = depth_writer(target.path, outcome.depth, scale=png_scale)
            except ValueError as exc:
                raise _UsageError(f"{target.label}: {_one_line(exc)}") from None
        elif kind in ("--json", "metrics.json"):
            writer = _bytes_writer(report_text)
        else:
            writer = _bytes_writer(figure_bytes if kind == "--figure" else outdir_figure)
        items.append((target, writer))
    commit(items)
    written = [target.path for _, target in planned]
    if any(target.flag == "--outdir" for _, target in planned) and "figure.png" not in kinds and not args.quiet:
        print("note: matplotlib is not installed, no figure.png (pip install 'sparsedepth[plot]')", file=stderr)

    _print_table(outcome, description, stdout)
    for path in written:
        print(f"wrote {path}", file=stdout)
    return 0


_OPTION_FLAGS = {
    "task": "--fill-holes", "keep_fraction": "--keep-fraction", "keep_count": "--keep-count", "seed": "--seed",
    "fill_method": "--fill-method", "weights": "the weight options", "solver": "--solver", "tol": "--tol",
    "max_iter": "--max-iter", "depth_scale": "--depth-scale", "downsample": "--downsample", "out_dir": "--outdir",
    "out_format": "--out-format", "out_scale": "--out-scale", "clip_to_observed": "--no-clip",
    "byteorder": "--byteorder", "invalid_values": "--invalid-value", "min_depth": "--min-depth",
    "max_depth": "--max-depth", "max_pixels": "--max-pixels",
}


class _Terminated(BaseException):
    """Raised in the batch driver by SIGTERM (a BaseException, like KeyboardInterrupt)."""


def _check_batch_flags(args, mode) -> None:
    if mode != "batch" and (args.batch_depths or args.batch_truths or args.overwrite):
        raise _UsageError("--batch-depths, --batch-truths and --overwrite are for --batch/--nyu-mat")
    if args.batch_depths is not None and args.batch is None:
        raise _UsageError("--batch-depths pairs with --batch DIR (the image folder)")
    if args.batch_truths is not None and args.batch_depths is None:
        raise _UsageError("--batch-truths goes with --batch-depths (--truth-prefix for a --batch folder)")


def _batch_options(args, weights) -> BatchOptions:
    try:
        return BatchOptions(
            task="fill" if args.fill_holes else "complete",
            keep_fraction=args.keep_fraction, keep_count=args.keep_count, seed=args.seed,
            fill_method=args.fill_method, weights=weights, solver=args.solver or "auto",
            tol=args.tol, max_iter=args.max_iter, depth_scale=args.depth_scale,
            downsample=args.downsample or 1, out_dir=args.outdir, out_format="." + args.out_format,
            out_scale=args.out_scale if args.out_scale is not None else (args.depth_scale or 1000.0),
            byteorder=args.byteorder, invalid_values=tuple(args.invalid_values or ()), min_depth=args.min_depth,
            max_depth=args.max_depth, max_pixels=args.max_pixels, clip_to_observed=args.clip_to_observed,
        )
    except (ValueError, TypeError, OSError) as exc:
        flag = _OPTION_FLAGS.get(getattr(exc, "option", None))
        if flag is None:
            raise
        raise _UsageError(f"{flag}: {_one_line(exc)}") from None


def _batch_frames(args):
    if args.nyu_mat is not None:
        return nyu_frames(args.nyu_mat, args.indices)
    if args.batch_depths is not None:
        return find_frame_pairs(args.batch, args.batch_depths, truth_folder=args.batch_truths)
    folder = Path(args.batch)
    if folder.is_dir():
        has_images = any(p.is_file() and p.name.startswith(args.image_prefix) for p in folder.iterdir())
        if not has_images and any(p.suffix.lower() in (".h5", ".hdf5") for p in folder.rglob("*")):
            return nyu_h5_frames(folder)
    return find_frames(folder, image_prefix=args.image_prefix, depth_prefix=args.depth_prefix,
                       truth_prefix=args.truth_prefix)


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"


class _BatchProgress:
    """Progress of a batch on stderr: a tqdm bar on a terminal if tqdm is installed, else one line per frame."""

    def __init__(self, stream, enabled: bool, frames: int):
        self.stream, self.enabled, self.frames = stream, enabled, frames
        self.start = time.monotonic()
        self.bar = None
        self.tqdm = None
        if enabled and getattr(stream, "isatty", lambda: False)():
            try:
                from tqdm import tqdm
            except ImportError:
                pass
            else:
                self.tqdm = tqdm

    def __call__(self, done, total, row):
        if not self.enabled:
            return
        if done == 1 and total < self.frames:
            self._write(f"resuming: {self.frames - total} of {self.frames} frames already done, skipped")
        if row["status"] == "ok":
            score = f"RMSE {float(row['rmse']):.4f} m, " if row.get("rmse") else ""
            text = f"ok, {score}{row.get('runtime', '?')} s"
        else:
            text = f"FAILED: {row.get('error', '')}"
        if self.tqdm is not None:
            if self.bar is None:
                self.bar = self.tqdm(total=total, initial=0, file=self.stream, unit="frame")
            self.bar.update(1)
            if row["status"] != "ok":
                self.bar.write(f"{row['name']}: {text}", file=self.stream)
            return
        elapsed = time.monotonic() - self.start
        rate = done / elapsed if elapsed > 0 else float("inf")
        eta = (total - done) / rate if rate > 0 else 0.0
        self._write(f"[{done}/{total}] {row['name']}: {text}; {rate:.3g} frames/s, ETA {_duration(eta)}")

    def _write(self, text):
        if self.bar is not None:
            self.bar.write(text, file=self.stream)
        else:
            print(text, file=self.stream, flush=True)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _on_signal(signum, frame):  # noqa: ARG001 - signal handler API
    # the first signal decides; the driver then cleans up without being interrupted again
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise _Terminated


def _check_batch_files(args, frames) -> None:
    """Refuse a --csv or --outdir file that is an input or another output; prove every output can be created."""
    inputs = []
    for frame in frames:
        if isinstance(frame, FileFrame):
            paths = [p for p in (frame.image, frame.depth, frame.truth) if p is not None]
            flag, given = "--batch", args.batch
        else:
            paths = [frame.path]
            flag, given = ("--nyu-mat", args.nyu_mat) if args.nyu_mat is not None else ("--batch", args.batch)
        inputs += [Named(flag, given, Path(path)) for path in paths]
    outputs = [Named("--csv", args.csv, Path(args.csv)), Named("--csv", args.csv, settings_path(args.csv))]
    if args.outdir is not None:
        outputs += [Named("--outdir", args.outdir, Path(args.outdir) / f"{frame.name}.{args.out_format}")
                    for frame in frames]
    check_distinct(outputs, inputs)
    check_writable(outputs)


def _run_batch(args, stderr) -> int:
    weights, _ = _weights(args)
    options = _batch_options(args, weights)
    frames = _batch_frames(args)
    _check_batch_files(args, frames)
    reporter = _BatchProgress(stderr, not args.quiet, len(frames))
    previous = {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, _on_signal)
    except ValueError:  # not the main thread: signals stay as they are
        pass
    try:
        cluster = _cluster_address(args)
        if cluster is not None:
            from ..batch.distributed import DEFAULT_TIMEOUT, run_batch_on_cluster
            with _warnings_as_lines(stderr):
                summary = run_batch_on_cluster(frames, args.csv, options=options, progress=reporter,
                                               address=cluster[0], scheduler_file=cluster[1],
                                               timeout=args.scheduler_timeout or DEFAULT_TIMEOUT,
                                               overwrite=args.overwrite)
        else:
            summary = run_batch(frames, args.csv, options=options, max_workers=args.workers, progress=reporter,
                                overwrite=args.overwrite)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; the rows of finished frames are in {args.csv}: run the same command to resume",
              file=stderr)
        return 130
    except _Terminated:
        print(f"{PROG}: terminated (SIGTERM); the rows of finished frames are in {args.csv}: run the same command "
              "to resume", file=stderr)
        return 143
    finally:
        reporter.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    ratio = "" if summary.rmse_ratio is None else \
        f"; mean RMSE / nearest-neighbour RMSE {summary.rmse_ratio:.3f} over {summary.scored} scored frames"
    print(f"{summary.succeeded} of {summary.total} frames done, {summary.failed} failed, {summary.skipped} skipped "
          f"(done before){ratio}; metrics in {summary.csv_path}", file=sys.stdout)
    return 1 if summary.failed else 0


def main(argv=None) -> int:
    """Run the command line; return the exit code (see the module docstring).

    Parameters
    ----------
    argv : list of str, optional
        Arguments without the program name; default ``sys.argv[1:]``.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser()
    stdout, stderr = sys.stdout, sys.stderr
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or a parse error (2, one line already printed)
        return 0 if exc.code is None else int(exc.code)
    try:
        mode = _validate(args)
        _check_batch_flags(args, mode)
        _validate_reader_options(args, mode)
        if mode == "batch":
            return _run_batch(args, stderr)
        return _run_one(args, argv, mode, stdout, stderr)
    except _UsageError as exc:
        print(f"{PROG}: error: {exc}", file=stderr)
        return 2
    except _LIBRARY_ERRORS as exc:
        print(f"{PROG}: error: {_one_line(exc)}", file=stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
