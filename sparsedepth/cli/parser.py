"""The options of ``python -m sparsedepth.complete``: one argparse parser, built group by group.

Each argument group has its own small function; the types of the option
values are checked while parsing (an error is one line on stderr, exit
code 2).  ``--help`` prints the common options of each task (:data:`COMMON_OPTIONS`,
at most 80 lines at 80 columns), ``--help-all`` every option with its full help.  Imports the standard library, :mod:`sparsedepth.io` (scales, pixel
limit), the solver and fill-method names, :class:`~sparsedepth.Weights`,
:func:`~sparsedepth.batch.default_workers`, ``sparsedepth.__version__`` and
the camera presets of :mod:`.camera`.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import math
import re
import shutil
import sys
import textwrap

from ..batch import default_workers
from ..completion import FAST_WEIGHTS
from ..holes import FILL_METHODS
from ..io import DEPTH_SCALES, MAX_PIXELS
from ..io.depth import SENSOR_PRESETS
from ..io import resolve_scale
from ..io.formats import DEPTH_EXTENSIONS, FORMATS, IMAGE_EXTENSIONS, OUT_FORMATS
from ..objective import DEFAULT_WEIGHTS, EDGE_PENALTIES, Weights
from ..objective import weights as weights_module
from ..objective.weights import DENSITY_FIELDS, MODEL_FIELDS
from ..priors import PRIOR_ALIGNMENTS
from ..solvers import SOLVERS
from .camera import CAMERA_PRESETS, parse_intrinsics

__all__ = ["PROG", "DEMO_DIR", "DEMO_KEEP_FRACTION", "DEMO_DOWNSAMPLE", "COMMON_OPTIONS", "EPILOG", "build_parser",
           "common_help", "weights_of"]

PROG = "python -m sparsedepth.complete"


DEMO_DIR = "sparsedepth-demo"


DEMO_KEEP_FRACTION = 0.05


DEMO_DOWNSAMPLE = 2


_WEIGHT_HELP = {
    "alpha": "data fidelity at observed pixels",
    "beta": "first-order L2 smoothness",
    "gamma": "edge-aware L1 smoothness (0 = quadratic objective)",
    "delta": "pull towards the nearest-neighbour fill",
    "kappa": "edge sensitivity of w = exp(-kappa |grad I|)",
    "beta_image": "image-weighted first-order L2 smoothness",
    "beta_second": "second-order (thin-plate) smoothness",
    "edge_penalty": "penalty of the edge term: l1 (convex, default) or a robust penalty that lets depth jump at "
                    "image edges (charbonnier convex; cauchy, geman_mcclure, welsch non-convex, solved by irls)",
    "edge_scale": "scale s of a robust --edge-penalty in metres: differences well below s are smoothed "
                  "quadratically, larger ones are allowed to jump",
    "edge_sigma": "blur (pixels) of the image before the edge weights; 0 = none",
    "fill_contrast": "image contrast cost of the prior's geodesic nearest-sample fill; 0 = Euclidean nearest fill",
    "depth_jump": "relative depth change at which a second solve relaxes the image smoothness; 0 = one solve",
    "beta_local_linear": "windowed local-linear term: in every 3x3 window depth is fitted as an affine function of "
                         "the colour (matting Laplacian)",
    "beta_local_linear_cross": "the local-linear term over cross-shaped windows (a pixel and its four neighbours; "
                               "a 13-point system instead of the 3x3 windows' 25 points)",
    "beta_local_linear_2x2": "the local-linear term over 2x2 windows (a 9-point system)",
    "local_linear_eps": "ridge weight on the slope of the local-linear fits, in squared [0, 1] image units; "
                        "0 = no ridge",
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
  {PROG} --colmap sparse/0 --images images --outdir depth
      dense depth for every registered view of a COLMAP model, from its 3-D
      points: depth/00.png for images/00.jpg (16-bit, model units x the scale
      in depth/scene.json), rows in depth/views.csv; resumable (docs/colmap.md)

depth scales: stored integer value / scale = metres; presets {', '.join(f'{k} ({v:g})' for k, v in DEPTH_SCALES.items())}.
exit codes: 0 ok; 1 batch with failed frames (rows with an error in the CSV);
2 bad option or input (one line on stderr, no output written), a CSV written
with other settings, or the CSV could not be written; 130 SIGINT (Ctrl-C);
143 SIGTERM.  A stopped batch ends its workers, removes their temporary files
and keeps the finished rows: rerun the same command to resume.
"""


#: The options ``--help`` shows, by task, each with a one-line summary; ``--help-all`` shows them all, in full.
COMMON_OPTIONS = (
    ("complete one frame (no --image/--depth: the demo)", (
        ("--image", "RGB (or grey) image."),
        ("--depth", "sparse or raw depth (0/NaN/inf = unknown), or a dense map with --keep-fraction."),
        ("--depth-scale", "divisor of stored integer depth: nyu or mm (1000), kitti (256), tum (5000), m (1), or "
                          "a number."),
        ("--sensor", f"the depth files of a sensor: {', '.join(SENSOR_PRESETS)} (scale, invalid codes, range)."),
        ("--keep-fraction", "simulate sparse input: keep this fraction of the valid depth, score on the rest."),
        ("--truth", "ground-truth depth to score against."),
        ("--solver", "solver (default auto)."),
        ("--fast", "real-time mode: a solve on a coarser grid, less accurate (docs/fast_mode.md)."),
        ("--best", "choose per input among fixed candidates by cross-validation on the samples "
                   "(docs/best_quality.md)."),
        ("--blowups", "flag or remove completed pixels that no nearby sample supports (docs/blowups.md)."),
    )),
    ("fill holes", (
        ("--fill-holes", "fill the holes of raw depth (every valid pixel observed)."),
        ("--fill-method", "colorization (NYU toolbox, default) or complete."),
    )),
    ("batch", (
        ("--batch", "folder of frames rgb_<id>.<ext> + depth_<id>.<ext> (or of NYU .h5 files)."),
        ("--batch-depths", "with --batch DIR: the depth folder, files named like the images (KITTI)."),
        ("--nyu-mat", "NYU Depth V2 labeled .mat."),
        ("--csv", "per-frame metrics; an existing CSV of the same command resumes the run."),
        ("--workers", "worker processes."),
    )),
    ("dense depth for every view of a COLMAP model (docs/colmap.md)", (
        ("--colmap", "the model folder (sparse/0); its 3-D points are each view's samples."),
        ("--images", "with --colmap: the folder of its images; writes --outdir/<image>.png and scene.json."),
    )),
    ("outputs", (
        ("--out", f"dense depth ({', '.join(OUT_FORMATS)})."),
        ("--json", "metrics, settings and solver history."),
        ("--figure", "image, input, result and errors (needs matplotlib)."),
        ("--ply", "coloured point cloud (needs --intrinsics, --camera or --calib)."),
        ("--outdir", "a folder for every output (a batch: one depth file per frame)."),
        ("-q", "no progress on stderr."),
    )),
)

_COMMON_TAIL = """\
example:
  {prog} --image rgb.png --depth sparse.png \\
      --depth-scale kitti --out dense.png
exit codes: 0 ok; 1 batch with failed frames; 2 bad option or input (one line on
stderr, no output written); 130 SIGINT; 143 SIGTERM.
--help-all lists the {others} other options (weights, formats, camera, cluster, ...).
"""


class _HelpAll(argparse.Action):
    """``--help-all``: print every option with its full help (argparse's help), then exit 0."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        parser.print_help()
        parser.exit()


class _StoreGiven(argparse._StoreAction):
    """Store the value and set ``<dest>_given`` (``--out-format``: its default depends on the mode)."""

    def __call__(self, parser, namespace, values, option_string=None):
        super().__call__(parser, namespace, values, option_string)
        setattr(namespace, f"{self.dest}_given", True)


class _CommonHelp(_HelpAll):
    """``-h`` / ``--help``: print :func:`common_help`, then exit 0."""

    def __call__(self, parser, namespace, values, option_string=None):
        sys.stdout.write(common_help(parser))
        parser.exit()


def common_help(parser) -> str:
    """The text of ``--help``: usage, description, :data:`COMMON_OPTIONS` by task, an example, the exit codes.

    Formatted at the terminal's width, but never narrower than 80 columns (so at most 80 lines).
    """
    width = max(shutil.get_terminal_size().columns, 80) - 2
    formatter = parser.formatter_class(prog=parser.prog, width=width)
    formatter.add_usage("%(prog)s [options]", None, [])
    formatter.add_text(textwrap.fill(parser.description, width))
    actions = {flag: action for action in parser._actions for flag in action.option_strings}
    for title, options in COMMON_OPTIONS:
        formatter.start_section(title)
        for flag, summary in options:
            shown = copy.copy(actions[flag])
            shown.help = summary
            formatter.add_argument(shown)
        formatter.end_section()
    help_flags = ("--help", "--help-all", "--version")
    formatter.start_section("help")
    formatter.add_arguments([actions[flag] for flag in help_flags])
    formatter.end_section()
    shown = {flag for _, options in COMMON_OPTIONS for flag, _ in options} | set(help_flags)
    others = sum(1 for action in parser._actions if action.option_strings and not shown & set(action.option_strings))
    return formatter.format_help() + "\n" + _COMMON_TAIL.format(prog=parser.prog, others=others)


#: Options whose value may start with a minus sign followed by a comma list (``--image-shift -1,2``), which argparse
#: would otherwise take for an option; :class:`_Parser` passes such a value on as ``--image-shift=-1,2``.
_SIGNED_PAIR_OPTIONS = ("--image-shift",)
_SIGNED_PAIR = re.compile(r"-\d+,")


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line on stderr (exit code 2)."""

    def error(self, message):  # noqa: D401 - argparse API
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")

    def parse_known_args(self, args=None, namespace=None):
        args = sys.argv[1:] if args is None else list(args)
        return super().parse_known_args(_join_signed_pairs(args), namespace)


def _join_signed_pairs(args) -> list:
    """``args`` with ``OPTION VALUE`` written ``OPTION=VALUE`` where VALUE starts like ``-1,`` (see
    :data:`_SIGNED_PAIR_OPTIONS`)."""
    joined, i = [], 0
    while i < len(args):
        if (args[i] in _SIGNED_PAIR_OPTIONS and i + 1 < len(args) and isinstance(args[i + 1], str)
                and _SIGNED_PAIR.match(args[i + 1])):
            joined.append(f"{args[i]}={args[i + 1]}")
            i += 2
        else:
            joined.append(args[i])
            i += 1
    return joined


def _listed(extensions) -> str:
    """``png, pgm, ...``: extensions for a help text, without their dots."""
    return ", ".join(ext[1:] for ext in extensions)


#: The formats of --out with what each stores (the table of sparsedepth.io.formats).
_OUT_HELP = "; ".join(f"{'/'.join(f.extensions)} ({f.stores})" for f in FORMATS if f.out)


def _int_at_least(lowest, expected):
    """An argparse type: an integer of at least ``lowest``; ``expected`` describes it in the error."""

    def parse(text):
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < lowest:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return value

    return parse


_positive_int = _int_at_least(1, "a positive integer")
_nonnegative_int = _int_at_least(0, "an integer >= 0")


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


def _relative(text):
    """An argparse type: a fraction of the depth, a finite number > 0 (0.1 = 10 %)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a fraction of the depth > 0 (0.1 = 10 %), got {text!r}")
    return value


def _finite(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def _positive(what):
    """An argparse type: a finite number > 0, the messages naming ``what`` (e.g. "depth in metres")."""

    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a {what} > 0, got {text!r}") from None
        if not (math.isfinite(value) and value > 0):
            raise argparse.ArgumentTypeError(f"expected a finite {what} > 0, got {text!r}")
        return value

    return parse


_positive_metres = _positive("depth in metres")
_positive_float = _positive("number of seconds")


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


def _image_shift(text):
    """'DY,DX' (two integers) -> (dy, dx); 'auto' -> 'auto'."""
    if text.strip().lower() == "auto":
        return "auto"
    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        return int(parts[0]), int(parts[1])
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected two integers DY,DX (pixels, e.g. 0,-2) or auto, got {text!r}"
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
        add_help=False,
    )
    from .. import __version__

    parser.add_argument("-h", "--help", action=_CommonHelp,
                        help="print the common options of each task and exit (--help-all: every option).")
    parser.add_argument("--help-all", action=_HelpAll, help="print every option with its full help and exit.")

    parser.add_argument("--version", action="version", version=f"sparsedepth {__version__}",
                        help="print 'sparsedepth <version>' and exit.")
    _add_input_options(parser)
    _add_camera_options(parser)
    _add_simulation_options(parser)
    _add_method_options(parser)
    _add_output_options(parser)
    _add_batch_options(parser)
    _add_colmap_options(parser)
    _add_cluster_options(parser)
    return parser


def _add_input_options(parser) -> None:
    """--image, --depth and the options of reading the files of one frame or a batch."""
    inp = parser.add_argument_group("input (one frame)")
    inp.add_argument("--image", metavar="PATH", help=f"RGB (or grey) image: {_listed(IMAGE_EXTENSIONS)}.")
    inp.add_argument("--depth", metavar="PATH",
                     help="sparse or raw depth (0/NaN/inf = unknown), or a dense map with --keep-*: "
                          f"{_listed(DEPTH_EXTENSIONS)} (integer data need --depth-scale; a pfm, Middlebury "
                          "disparity, needs --calib, or --depth-scale m if it holds metres).")
    inp.add_argument("--mask", metavar="PATH",
                     help="optional mask of observed pixels: npy/npz/h5 (bool or 0/1) or an image, 1-bit PNG "
                          "included (non-zero = observed); each pixel it marks must hold a valid --depth value, "
                          "unless --keep-fraction/--keep-count sample within it. An inpainting mask (non-zero where "
                          "to fill) is the opposite: invert it.")
    inp.add_argument("--truth", metavar="PATH",
                     help="optional ground-truth depth (same formats and scale as --depth) to score against, "
                          "on the pixels not observed.")
    inp.add_argument("--prior", metavar="PATH",
                     help="optional dense map from elsewhere (e.g. a monocular network's prediction; depth, not "
                          "inverse depth), in --depth's formats, divided by --depth-scale and converted by --calib "
                          "like --depth; every stored value is a value: 0 and negatives are relative depth, "
                          "--invalid-value/--min-depth/--max-depth do not apply, NaN/inf are refused. Aligned to the "
                          "samples (--prior-alignment) and completed around (complete_depth(prior=...)).")
    inp.add_argument("--prior-alignment", choices=list(PRIOR_ALIGNMENTS), metavar="{" + ",".join(PRIOR_ALIGNMENTS) + "}",
                     help="least-squares fit of s * prior + t to the samples: scale_shift (default; relative "
                          "depth), scale, or none (a metric prior used as it is).")
    inp.add_argument("--depth-scale", type=_scale, metavar="SCALE",
                     help="divisor of stored depth values: nyu or mm (1000), kitti (256), tum (5000), m (1), or a "
                          "number.  Required for integer data (png, pgm, tif, integer npy/npz/h5); float data default "
                          "to 1, except a pfm, which needs this or --calib.")
    inp.add_argument("--sensor", choices=list(SENSOR_PRESETS), metavar="{" + ",".join(SENSOR_PRESETS) + "}",
                     help="how a sensor's or dataset's depth files store depth: sets --depth-scale, adds its "
                          "'no measurement' codes to --invalid-value and its working range as --min-depth/--max-depth "
                          "(each of those given explicitly wins). "
                          + "; ".join(f"{name}: scale {p.scale:g}, {p.min_depth:g}-{p.max_depth:g} m"
                                      + (f", invalid {', '.join(f'{v:g}' for v in p.invalid_values)}"
                                         if p.invalid_values else "")
                                      for name, p in SENSOR_PRESETS.items())
                          + ". Sources: sparsedepth.io.depth.SENSOR_PRESETS.")
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



def _add_camera_options(parser) -> None:
    """--intrinsics / --camera: the pinhole camera of --image, for --ply."""
    cam = parser.add_argument_group("camera (for --ply; --calib calib.txt gives them too)")
    which = cam.add_mutually_exclusive_group()
    which.add_argument("--intrinsics", type=parse_intrinsics, metavar="FX,FY,CX,CY|FILE",
                       help="pinhole intrinsics of --image in pixels (pixel centres at integer coordinates, "
                            "column u, row v from 0), or a file holding them: a 3x3 K (.txt, .npy; KITTI cam.txt), "
                            "JSON (fx/fy/cx/cy, K, Open3D's), 'fx: ...' YAML (RealSense), KITTI "
                            "calib_cam_to_cam.txt (P_rect_02), COLMAP cameras.txt (one pinhole camera); scaled by "
                            "--downsample.")
    presets = "; ".join(f"{name}: {preset.what}" for name, preset in CAMERA_PRESETS.items())
    which.add_argument("--camera", choices=sorted(CAMERA_PRESETS),
                       help=f"intrinsics preset. {presets}. Other image sizes are refused.")


def _add_simulation_options(parser) -> None:
    """--keep-fraction / --keep-count and --seed: sparse input sampled from a dense map."""
    sim = parser.add_argument_group("simulated sparse input (scores against the dense map)")
    keep = sim.add_mutually_exclusive_group()
    keep.add_argument("--keep-fraction", type=_fraction, metavar="F",
                      help=f"keep this fraction of the valid depth pixels (demo default {DEMO_KEEP_FRACTION}).")
    keep.add_argument("--keep-count", type=_positive_int, metavar="N", help="keep this many valid depth pixels.")
    sim.add_argument("--seed", type=_nonnegative_int, default=0, help="seed of the sampling (default 0).")



def _add_method_options(parser) -> None:
    """--solver, one option per term weight, the solver limits and the hole-filling method."""
    method = parser.add_argument_group("method")
    method.add_argument("--solver", choices=["auto", *sorted(SOLVERS)], default=None,
                        help="solver of complete_depth (default auto: amg for gamma = 0, irls for a robust "
                             "--edge-penalty, else admm).")
    for f in dataclasses.fields(Weights):
        flag = f"--{f.name.replace('_', '-')}"
        default = getattr(FAST_WEIGHTS if f.name in DENSITY_FIELDS else DEFAULT_WEIGHTS, f.name)
        if f.name == "edge_penalty":
            method.add_argument(flag, dest=f"w_{f.name}", choices=EDGE_PENALTIES, metavar="NAME",
                                help=f"{_WEIGHT_HELP[f.name]}; one of {', '.join(EDGE_PENALTIES)} "
                                     f"(default {default}).")
            continue
        kind, metavar = ((_positive_metres, "METRES") if f.name == "edge_scale"
                         else (_nonnegative, "V") if f.name in MODEL_FIELDS else (_nonnegative, "W"))
        what = "" if f.name == "edge_scale" else "option " if f.name in MODEL_FIELDS else "weight "
        scheduled = f" (default: by the observed fraction of the pixels, sparsedepth.DEFAULT_SCHEDULE; {default:g} " \
            f"with --fast)" if f.name in DENSITY_FIELDS else f" (default {default:g})."
        method.add_argument(
            flag, dest=f"w_{f.name}", type=kind, metavar=metavar,
            help=f"{what}{f.name}: {_WEIGHT_HELP.get(f.name, 'a term weight of sparsedepth.Weights')}{scheduled}",
        )
    method.add_argument("--fast", action="store_true",
                        help="real-time mode: solve on a 2-4x coarser grid, upsample, refine by a few edge-aware "
                             "sweeps (its speed and accuracy beside the default's: docs/fast_mode.md, "
                             "python -m bench.fast_mode).")
    method.add_argument("--best", action="store_true",
                        help="choose the completion per input among a few fixed candidates (the defaults, the "
                             "image trusted less or not at all, a blend with nearest fill, nearest fill) by "
                             "cross-validation on the samples; the defaults unless another is expected clearly "
                             "more accurate.  The choice is printed in the method's name.  Not with --fast, "
                             "--solver, --tol, --max-iter, the uncertainty options or --prior; its accuracy and "
                             "time: docs/best_quality.md (python -m bench.best_quality).")
    method.add_argument("--tol", type=_nonnegative, metavar="TOL", help="solver tolerance (meaning per solver).")
    method.add_argument("--max-iter", type=_positive_int, metavar="N", help="maximum solver iterations.")
    method.add_argument("--no-clip", dest="clip_to_observed", action="store_false",
                        help="keep completed depth outside the range of the observed depth (by default the map is "
                             "clamped to [smallest, largest] observed value and the clamped pixels are counted).")
    method.add_argument("--fill-holes", action="store_true",
                        help="hole filling: every valid pixel of --depth is observed, the output is dense.")
    method.add_argument("--fill-method", choices=FILL_METHODS,
                        help="with --fill-holes, the hole-filling method: colorization (NYU toolbox "
                             "fill_depth_colorization, default) or complete (this package's objective).")
    method.add_argument("--image-shift", type=_image_shift, metavar="DY,DX|auto",
                        help="register the image to the depth: move it DY rows down and DX columns right (negative: "
                             "up, left; border repeated) before completion or hole filling, in pixels of the frame "
                             "completed (after --downsample); e.g. 0,-2.  Some RGB-D sensors (Kinect v1, TUM RGB-D) "
                             "leave the depth edges a few pixels off the image edges.  auto estimates the shift from "
                             "the frame's own depth samples (sparsedepth.estimate_image_shift, 100 image-aware fills: "
                             "several times the completion's time; no shift when a frame has too few samples); in a "
                             "batch, auto measures one shift on up to 8 of its frames (spread evenly, estimates "
                             "pooled by sparsedepth.pool_image_shifts) and uses it for all.  docs/registration.md "
                             "measures it.  A sensor's shift is better measured once on dense frames and given as "
                             "DY,DX.  The figure and --ply colours use the moved image.")



def _add_output_options(parser) -> None:
    """--out, --uncertainty, --max-uncertainty, --max-relative-uncertainty, --json, --expected-error, --figure,
    --depth-vis, --outdir and -q."""
    out = parser.add_argument_group("output")
    out.add_argument("--out", metavar="PATH",
                     help=f"dense depth: {_OUT_HELP}; a PNG's scale is the input's or --out-scale.")
    out.add_argument("--out-scale", type=_scale, metavar="SCALE",
                     help="scale of a PNG output (default: --depth-scale if given, else mm = 1000; --colmap: the "
                          "largest of 1, 2, 5 x 10^k that stores 1.05 x the largest depth of the model's points, "
                          "written in scene.json).")
    out.add_argument("--uncertainty", metavar="PATH",
                     help="per-pixel uncertainty in metres (a standard-deviation-like error estimate, calibrated "
                          "on held-out samples; two more solves), in any --out format: .npy, .npz, .h5, .tif and "
                          ".pfm store it as it is (0 included; missing only where there is no estimate); a 16-bit "
                          "PNG stores between one unit of its scale and its largest value 65535/scale (a larger "
                          "sigma is stored as that value: read it as 'at least'; the count is reported).  With "
                          "--colmap: an existing folder other than --outdir, one map per view named like its depth "
                          "map (--out-format, the depth's PNG scale, model units).")
    out.add_argument("--max-uncertainty", type=_nonnegative, metavar="M",
                     help="leave the pixels whose uncertainty (the expected error of their depth, in metres; not a "
                          "depth) exceeds M metres missing in --out, --depth-vis, --ply and the figure (0 in PNG, "
                          "NaN in float formats) instead of extrapolating; the count is reported.  A limit in metres "
                          "keeps far pixels less often than near ones: --max-relative-uncertainty sets it as a "
                          "fraction of each pixel's depth.")
    out.add_argument("--max-relative-uncertainty", type=_relative, metavar="R",
                     help="leave the pixels whose uncertainty exceeds R times their depth missing, as "
                          "--max-uncertainty does (0.1: an expected error over 10 %% of the depth).  With "
                          "--max-uncertainty too, a pixel is left out when it exceeds either limit.  The share of "
                          "the pixels each limit leaves out on real frames: docs/figures/uncertainty_limits.csv "
                          "(python -m bench.figures).")
    out.add_argument("--blowups", choices=("flag", "remove"),
                     help="check the completed depth for local blow-ups: pixels whose depth no nearby sample "
                          "supports (none of their 8 nearest samples within 10 %% of it, and no plane through those "
                          "samples predicting it), typically a value in the middle of a depth jump.  flag: count "
                          "them (stdout, --json); remove: also leave them missing in every output, as "
                          "--max-uncertainty does.  One frame.  What it catches and what it flags wrongly: "
                          "docs/blowups.md (python -m bench.blowups).")
    out.add_argument("--json", metavar="PATH", help="metrics, settings and solver history as JSON.")
    out.add_argument("--expected-error", action="store_true",
                     help="also estimate, from the samples alone (cross-validation with fast completions), "
                          "the RMSE over the unobserved pixels of the "
                          "output and of nearest fill: one line 'expected RMSE ~ X m (nearest fill ~ Y m)', both in "
                          "--json, and a warning when the output is not expected to beat nearest fill.  One frame (the "
                          "demo or --image/--depth); not with --prior or --fill-method colorization.  "
                          "docs/expected_error.md measures its accuracy and its time beside a completion's.")
    out.add_argument("--ply", metavar="PATH",
                     help="coloured 3-D point cloud of the completed depth (binary PLY, metres, camera frame; "
                          "colours of --image); needs --intrinsics, --camera or --calib calib.txt (the demo "
                          "knows its own).  Pixels without depth are skipped.")
    out.add_argument("--figure", metavar="PATH",
                     help="image | input samples | nearest neighbour | completed, in --depth-vis's colours with a "
                          "colour bar in metres, and with ground truth: truth | both absolute errors on one scale; "
                          "the uncertainty when computed (log colours clipped at its 99th percentile; its title "
                          "gives the statistics stdout and --json give); each panel at about the frame's width, "
                          "two a row for a frame 2.5 times wider than tall (.png, .pdf, .svg, .jpg; needs "
                          "matplotlib: pip install 'sparsedepth[plot]').")
    out.add_argument("--depth-vis", metavar="PATH",
                     help="the output depth as a colour picture (.png, 8-bit RGB: near bright yellow, far dark "
                          "blue, missing grey) for any image viewer; no matplotlib needed.")
    out.add_argument("--outdir", metavar="DIR",
                     help=f"write depth.npy, depth.png, depth_vis.png, metrics.json, figure.png (if matplotlib is "
                          "installed), points.ply (if the intrinsics are known) and, with --uncertainty, "
                          "--max-uncertainty or --max-relative-uncertainty, uncertainty.npy "
                          f"here (an existing folder; the demo creates its default ./{DEMO_DIR}/); batch: one depth file "
                          "per frame; --colmap: one depth map per view named after its image (00.png for 00.jpg, "
                          "sub-folders kept), scene.json and, by default, the --csv views.csv.")
    out.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr.")



def _add_batch_options(parser) -> None:
    """--batch / --nyu-mat / --colmap, the frame selection, --csv, --workers and --overwrite."""
    bat = parser.add_argument_group("batch")
    src = bat.add_mutually_exclusive_group()
    src.add_argument("--batch", metavar="DIR",
                     help="folder of frames paired by name: <image-prefix><id>.<ext> with <depth-prefix><id>.<ext>; "
                          "with --batch-depths, the image folder; a folder with no <image-prefix> image but .h5 "
                          "files (searched recursively) is read as NYU .h5 frames (rgb + depth in metres).")
    src.add_argument("--nyu-mat", metavar="FILE",
                     help="NYU Depth V2 labeled .mat (read lazily): --fill-holes fills rawDepths and scores against "
                          "depths; otherwise depths is sampled with --keep-fraction/--keep-count.")
    src.add_argument("--colmap", metavar="DIR",
                     help="a COLMAP sparse model folder (cameras, images, points3D; .bin or .txt; pinhole cameras, "
                          "i.e. after `colmap image_undistorter`): complete every registered view from the model's "
                          "3-D points it observes, in the model's units (no scoring); needs --images and --outdir.")
    bat.add_argument("--indices", type=_indices, metavar="RANGE",
                     help="frames of --nyu-mat: 5, 0:10, 0:100:10 or 1,4,7 (default all).")
    bat.add_argument("--image-prefix", default="rgb_", help="image file prefix in --batch (default rgb_).")
    bat.add_argument("--depth-prefix", default="depth_", help="depth file prefix in --batch (default depth_).")
    bat.add_argument("--truth-prefix", default=None, help="optional ground-truth file prefix in --batch.")
    bat.add_argument("--csv", metavar="PATH",
                     help="per-frame metrics, one row per frame, written as frames finish.  If it exists (from the "
                          "same command) the run resumes: frames with an ok row and their output are skipped, "
                          "missing and failed ones run, and each failed row is replaced by the new one.  The "
                          "settings are kept beside it in PATH.settings.json.  --colmap: default "
                          "<--outdir>/views.csv.")
    bat.add_argument("--workers", type=_positive_int, metavar="N",
                     help=f"worker processes (default {default_workers()} here: half the CPUs, at least 1, "
                          "at most 8).")
    bat.add_argument("--out-format", choices=list(OUT_FORMATS), default="npy", action=_StoreGiven,
                     help="format of the per-frame outputs in --outdir (default npy; --colmap: png, 16-bit at the "
                          "scale of --out-scale; npy, pfm, tif and h5 store float depth as it is).")
    bat.add_argument("--batch-depths", metavar="DIR",
                     help="with --batch DIR: the depth folder, files named like the images (KITTI layout).")
    bat.add_argument("--batch-truths", metavar="DIR",
                     help="with --batch-depths: optional ground-truth folder, files named like the images.")
    bat.add_argument("--overwrite", action="store_true",
                     help="start the batch afresh: replace an existing --csv (even one written with other "
                          "settings) and recompute every frame.")


def _add_colmap_options(parser) -> None:
    """--images, --colmap-max-error and --colmap-min-track: the views of a --colmap model."""
    colmap = parser.add_argument_group("COLMAP views (with --colmap; docs/colmap.md)")
    colmap.add_argument("--images", metavar="DIR",
                        help="the folder the model's image names are relative to (COLMAP's image path; the "
                             "undistorted images for an undistorted model).  A registered image whose file is "
                             "missing is a failed row; image files the model does not register are skipped and "
                             "counted.")
    colmap.add_argument("--colmap-max-error", type=_nonnegative, metavar="PX",
                        help="use only the 3-D points whose mean reprojection error is at most PX pixels (default: "
                             "every point).")
    colmap.add_argument("--colmap-min-track", type=_positive_int, metavar="N",
                        help="use only the 3-D points seen by at least N images (default: every point).")


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


def weights_of(args) -> tuple:
    """(the weights of the options, {name: value} of the weights given on the command line).

    No weight option: ``None``, the library's defaults (the density schedule, ``FAST_WEIGHTS`` with ``--fast``,
    ``DEFAULT_WEIGHTS`` for ``--fill-holes``).  With some: :data:`~sparsedepth.DEFAULT_SCHEDULE` with those fields
    fixed at every density, or the ``--fast`` / ``--fill-holes`` defaults with them changed.
    """
    given = {f.name: getattr(args, f"w_{f.name}") for f in dataclasses.fields(Weights)}
    given = {k: v for k, v in given.items() if v is not None}
    if not given:
        return None, given
    if getattr(args, "fast", False):
        return FAST_WEIGHTS.replace(**given), given
    if getattr(args, "fill_holes", False):
        return DEFAULT_WEIGHTS.replace(**given), given
    return weights_module.DEFAULT_SCHEDULE.replace(**given), given
