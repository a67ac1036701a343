"""Command line: ``python -m sparsedepth.complete``.

Completes one frame (the embedded Middlebury Motorcycle demo, or your image
and depth files), fills the holes of raw depth, or runs a batch of frames.
Everything is done by library functions; this module only parses options,
reads and writes files, prints the table and progress (on stderr), and turns
library errors into one line on stderr with exit code 2.

Exit codes: 0 success; 1 a batch finished but some frames failed (see the
CSV); 2 bad options or input (nothing written); 130 interrupted.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import io as _io
import json
import math
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from . import __version__
from .batch import BatchOptions, evaluate_frame, find_frames, nyu_frames, run_batch
from .datasets import load_motorcycle
from .holes import FILL_METHODS
from .io import (
    DEPTH_SCALES,
    KINECT_NYU,
    MAX_PIXELS,
    _atomic_target,
    _resolve_scale,
    read_calib,
    read_depth,
    read_image,
    read_mask,
    write_depth,
)
from .solvers import SOLVERS
from .weights import DEFAULT_WEIGHTS, Weights

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
      a batch: per-frame metrics appended to fill.csv as frames finish

depth scales: stored integer value / scale = metres; presets {', '.join(f'{k} ({v:g})' for k, v in DEPTH_SCALES.items())}.
exit codes: 0 ok; 1 batch with failed frames (rows with an error in the CSV);
2 bad option or input (one line on stderr, no output written); 130 interrupted.
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
        return _resolve_scale(float(text))
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
                     help="folder of frames paired by name: <image-prefix><id>.<ext> with <depth-prefix><id>.<ext>.")
    src.add_argument("--nyu-mat", metavar="FILE",
                     help="NYU Depth V2 labeled .mat (read lazily): --fill-holes fills rawDepths and scores against "
                          "depths; otherwise depths is sampled with --keep-fraction/--keep-count.")
    bat.add_argument("--indices", type=_indices, metavar="RANGE",
                     help="frames of --nyu-mat: 5, 0:10, 0:100:10 or 1,4,7 (default all).")
    bat.add_argument("--image-prefix", default="rgb_", help="image file prefix in --batch (default rgb_).")
    bat.add_argument("--depth-prefix", default="depth_", help="depth file prefix in --batch (default depth_).")
    bat.add_argument("--truth-prefix", default=None, help="optional ground-truth file prefix in --batch.")
    bat.add_argument("--csv", metavar="PATH", help="per-frame metrics, one row appended per finished frame.")
    bat.add_argument("--workers", type=_positive_int, metavar="N",
                     help="worker processes (default: number of CPUs).")
    bat.add_argument("--out-format", choices=["npy", "npz", "h5", "pfm", "png"], default="npy",
                     help="format of the per-frame outputs in --outdir (default npy).")
    return parser


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
    if not path.parent.is_dir():
        raise _UsageError(f"{what} '{path}': folder '{path.parent}' does not exist")
    return path


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
        if args.outdir is not None and not Path(args.outdir).is_dir():
            raise _UsageError(f"--outdir '{args.outdir}' does not exist")
    else:
        if args.csv or args.workers or args.indices is not None:
            raise _UsageError("--csv, --workers and --indices are for --batch/--nyu-mat")
        if args.out:
            _check_output(args.out, _OUT_EXTENSIONS, "--out")
        if args.json:
            _check_output(args.json, (".json",), "--json")
        if args.figure:
            _check_output(args.figure, _FIGURE_EXTENSIONS, "--figure")
            if _matplotlib() is None:
                raise _UsageError("--figure needs matplotlib, which is not installed: "
                                  "pip install 'sparsedepth[plot]' (or matplotlib)")
        if args.outdir is not None and mode == "files" and not Path(args.outdir).is_dir():
            raise _UsageError(f"--outdir '{args.outdir}' does not exist")
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
    """Reader options apply to the one-frame mode; check their combinations."""
    given = [flag for flag, value in (("--byteorder", args.byteorder), ("--invalid-value", args.invalid_values),
                                      ("--min-depth", args.min_depth), ("--max-depth", args.max_depth))
             if value is not None]
    if args.max_pixels != MAX_PIXELS:
        given.append("--max-pixels")
    if given and mode != "files":
        raise _UsageError(f"{', '.join(given)} apply to --image/--depth (one frame)")
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


def _read_depth_flag(path, flag, args, calib, stream) -> np.ndarray:
    """read_depth with the reader options, library warnings printed as one line each."""
    _check_units(path, flag, args)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        depth = read_depth(path, scale=args.depth_scale, calib=calib, key=args.depth_key, byteorder=args.byteorder,
                           invalid_values=args.invalid_values or (), min_depth=args.min_depth,
                           max_depth=args.max_depth, max_pixels=args.max_pixels, name=flag,
                           option_names=_READER_FLAGS)
    for record in caught:
        print(f"warning: {_one_line(record.message)}", file=stream)
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


def _write_bytes(path, data: bytes) -> None:
    with _atomic_target(path) as tmp:
        Path(tmp).write_bytes(data)


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
        outdir = Path(DEMO_DIR if args.outdir is None else args.outdir)
    else:
        image, depth, mask, truth, description = _read_inputs(args, stderr)
        downsample = 1 if args.downsample is None else args.downsample
        keep_fraction = args.keep_fraction
        outdir = None if args.outdir is None else Path(args.outdir)
    if downsample > 1:
        description += f" (downsampled by {downsample})"
        image, depth = image[::downsample, ::downsample], depth[::downsample, ::downsample]
        mask = None if mask is None else mask[::downsample, ::downsample]
        truth = None if truth is None else truth[::downsample, ::downsample]
    png_scale = args.out_scale if args.out_scale is not None else (args.depth_scale or 1000.0)
    png_scale = _resolve_scale(png_scale)

    complete_fill = args.fill_holes and args.fill_method == "complete"
    use_solver = not args.fill_holes or complete_fill
    outcome = evaluate_frame(
        image, depth, mask=mask, truth=truth, task="fill" if args.fill_holes else "complete",
        keep_fraction=keep_fraction, keep_count=args.keep_count, seed=args.seed,
        fill_method=args.fill_method, weights=weights if use_solver else None,
        solver=args.solver or "auto", tol=args.tol, max_iter=args.max_iter,
        callback=_Progress(stderr, not args.quiet) if use_solver else None,
    )

    # everything to write is computed first, so that a failure leaves no partial set
    report = _report(args, argv, outcome, description, weights, weights_given, png_scale)
    report_text = json.dumps(report, indent=2, allow_nan=False) + "\n"
    figure_bytes = None
    if args.figure:
        figure_bytes = _render_figure(image, outcome, Path(args.figure).suffix.lower())
    outdir_figure = None
    if outdir is not None:
        if _matplotlib() is not None:
            outdir_figure = figure_bytes if (args.figure or "").lower().endswith(".png") else \
                _render_figure(image, outcome, ".png")
        elif not args.quiet:
            print("note: matplotlib is not installed, no figure.png (pip install 'sparsedepth[plot]')", file=stderr)

    written = []
    if args.out:
        write_depth(args.out, outcome.depth, scale=png_scale)
        written.append(args.out)
    if outdir is not None:
        outdir.mkdir(parents=True, exist_ok=True)
        write_depth(outdir / "depth.npy", outcome.depth)
        write_depth(outdir / "depth.png", outcome.depth, scale=png_scale)
        _write_bytes(outdir / "metrics.json", report_text.encode())
        written += [outdir / "depth.npy", outdir / "depth.png", outdir / "metrics.json"]
        if outdir_figure is not None:
            _write_bytes(outdir / "figure.png", outdir_figure)
            written.append(outdir / "figure.png")
    if args.json:
        _write_bytes(args.json, report_text.encode())
        written.append(args.json)
    if figure_bytes is not None:
        _write_bytes(args.figure, figure_bytes)
        written.append(args.figure)

    _print_table(outcome, description, stdout)
    for path in written:
        print(f"wrote {path}", file=stdout)
    return 0


def _run_batch(args, stderr) -> int:
    weights, _ = _weights(args)
    options = BatchOptions(
        task="fill" if args.fill_holes else "complete",
        keep_fraction=args.keep_fraction, keep_count=args.keep_count, seed=args.seed,
        fill_method=args.fill_method, weights=weights, solver=args.solver or "auto",
        tol=args.tol, max_iter=args.max_iter, depth_scale=args.depth_scale,
        downsample=args.downsample or 1, out_dir=args.outdir, out_format="." + args.out_format,
        out_scale=args.out_scale if args.out_scale is not None else (args.depth_scale or 1000.0),
    )
    if args.batch is not None:
        frames = find_frames(args.batch, image_prefix=args.image_prefix, depth_prefix=args.depth_prefix,
                             truth_prefix=args.truth_prefix)
    else:
        frames = nyu_frames(args.nyu_mat, args.indices)

    def progress(done, total, row):
        if args.quiet:
            return
        if row["status"] == "ok":
            score = f"RMSE {float(row['rmse']):.4f} m, " if row.get("rmse") else ""
            text = f"ok, {score}{row.get('runtime', '?')} s"
        else:
            text = f"FAILED: {row.get('error', '')}"
        print(f"[{done}/{total}] {row['name']}: {text}", file=stderr, flush=True)

    summary = run_batch(frames, args.csv, options=options, max_workers=args.workers, progress=progress)
    print(f"{summary.succeeded} of {summary.total} frames done, {summary.failed} failed; metrics in {summary.csv_path}",
          file=sys.stdout)
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
