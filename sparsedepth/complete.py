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
import importlib.util
import io as _io
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from . import __version__
from .batch import BatchOptions, evaluate_frame, find_frames, nyu_frames, run_batch
from .datasets import load_motorcycle
from .holes import FILL_METHODS
from .io import DEPTH_SCALES, _atomic_target, _resolve_scale, read_depth, read_image, write_depth
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
                          "png/pgm (needs --depth-scale), pfm, npy, npz, h5.")
    inp.add_argument("--mask", metavar="PATH",
                     help="optional mask of observed pixels: npy/npz (bool or 0/1) or an image (non-zero = observed).")
    inp.add_argument("--truth", metavar="PATH",
                     help="optional ground-truth depth (same formats and scale as --depth) to score against, "
                          "on the pixels not observed.")
    inp.add_argument("--depth-scale", type=_scale, metavar="SCALE",
                     help="divisor of stored depth values: nyu or mm (1000), kitti (256), tum (5000), m (1), or a "
                          "number.  Required for integer images; float files default to 1.")
    inp.add_argument("--depth-key", metavar="NAME", help="array name in an .npz or dataset in an .h5 depth file.")
    inp.add_argument("--calib", metavar="CALIB_TXT",
                     help="Middlebury/ETH3D calib.txt: --depth holds disparity in pixels, converted to metres.")
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
    _add_cluster_options(parser)
    return parser


def _add_cluster_options(parser) -> None:
    """--scheduler, --scheduler-file, --scheduler-timeout: a batch on a Dask cluster (sparsedepth.distributed)."""
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


def _read_mask(path, shape) -> np.ndarray:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"--mask: no such file: '{path}'")
    suffix = path.suffix.lower()
    if suffix == ".npy":
        array = np.load(path, allow_pickle=False)
    elif suffix == ".npz":
        with np.load(path, allow_pickle=False) as data:
            array = data[data.files[0]]
    else:
        image = read_image(path)
        array = image != 0 if image.ndim == 2 else np.any(image != 0, axis=2)
    if array.dtype != bool:
        if not np.all(np.isin(array, (0, 1))):
            raise ValueError(f"--mask '{path}' must be boolean or 0/1")
        array = array.astype(bool)
    if array.shape != tuple(shape):
        raise ValueError(f"--mask '{path}' has shape {array.shape} but the depth has shape {tuple(shape)}")
    return array


def _read_inputs(args, stream):
    """(image, depth, mask, truth, description) of the one-frame mode, in metres."""
    image = read_image(args.image)
    depth = read_depth(args.depth, scale=args.depth_scale, calib=args.calib, key=args.depth_key)
    if image.shape[:2] != depth.shape:
        raise ValueError(f"image '{args.image}' is {image.shape[0]}x{image.shape[1]} but depth '{args.depth}' is "
                         f"{depth.shape[0]}x{depth.shape[1]} (H x W); they must have the same size")
    if not np.any(np.isfinite(depth)):
        raise ValueError(f"depth '{args.depth}' has no valid pixel (all 0, NaN or inf)")
    _warn_scale(depth, f"depth '{args.depth}'", args.depth_scale, stream)
    mask = None if args.mask is None else _read_mask(args.mask, depth.shape)
    truth = None
    if args.truth is not None:
        truth = read_depth(args.truth, scale=args.depth_scale, calib=args.calib, key=args.depth_key)
        if truth.shape != depth.shape:
            raise ValueError(f"truth '{args.truth}' has shape {truth.shape} but depth '{args.depth}' has "
                             f"shape {depth.shape}")
        _warn_scale(truth, f"truth '{args.truth}'", args.depth_scale, stream)
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

    cluster = _cluster_address(args)
    if cluster is not None:
        from .distributed import DEFAULT_TIMEOUT, run_batch_on_cluster
        summary = run_batch_on_cluster(frames, args.csv, options=options, progress=progress, address=cluster[0],
                                       scheduler_file=cluster[1], timeout=args.scheduler_timeout or DEFAULT_TIMEOUT)
    else:
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
