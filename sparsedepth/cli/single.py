"""One frame from the command line: the demo or the user's files, completed or hole-filled, its outputs written.

:func:`plan_outputs` names every file of the run (checked before any work),
:func:`run_one` reads the inputs, runs
:func:`~sparsedepth.batch.evaluate_frame`, encodes every output, writes them
all or none (:func:`~sparsedepth.cli.outputs.commit`) and prints the table.
Imports anything of the library and the other modules of
:mod:`sparsedepth.cli` except the command and batch modes.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from ..batch import evaluate_frame
from ..completion import with_expected_error
from ..datasets import load_motorcycle
from .._validation import check_input_file
from ..io import KINECT_NYU, KinectDisparity, read_calib, read_depth, read_image, read_mask
from ..io import depth_to_points, depth_writer, ply_writer, resolve_scale
from ..io.writing import uncertainty_writer
from ..io.depth import read_stored
from ..priors import as_prior
from ..registration import shift_image
from ..sampling import valid_depth_mask
from ..visualize import colorize_depth
from .camera import KINECT_CALIB, camera_assumption, frame_intrinsics, intrinsics_source
from .frame_checks import check_frame
from .messages import UsageError, one_line, warnings_as_lines
from .outputs import Named, commit
from .parser import DEMO_DIR, DEMO_DOWNSAMPLE, DEMO_KEEP_FRACTION, weights_of
from .report import (blowups_line, build_report, matplotlib_classes, print_table, removal_limits, render_figure,
                     uncertainty_png_line)

__all__ = ["READER_FLAGS", "plan_outputs", "wants_uncertainty", "input_files", "run_one", "expected_error_line"]

_ABSURD_LOW, _ABSURD_HIGH = 1e-3, 1e3  # metres: a median outside this means a wrong scale


_PROGRESS_EVERY = 1.0  # seconds between progress lines


READER_FLAGS = {
    "scale": "--depth-scale", "key": "--depth-key", "byteorder": "--byteorder",
    "invalid_values": "--invalid-value", "min_depth": "--min-depth", "max_depth": "--max-depth",
    "max_pixels": "--max-pixels", "calib": "--calib",
}


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


def _check_units(path, flag, args) -> None:
    """A PFM holds disparity (Middlebury, ETH3D) unless the user says otherwise."""
    if Path(path).suffix.lower() == ".pfm" and args.calib is None and args.depth_scale is None:
        raise UsageError(
            f"{flag} '{path}' is a PFM, the Middlebury/ETH3D disparity format (pixels, not metres): give --calib "
            "calib.txt to convert disparity to metres, or --depth-scale m if the file holds depth in metres"
        )


def _read_mask(path, shape, max_pixels) -> np.ndarray:
    array = read_mask(path, max_pixels=max_pixels, name="--mask", option_names=READER_FLAGS)
    if array.shape != tuple(shape):
        raise ValueError(f"--mask '{path}' has shape {array.shape} but the depth has shape {tuple(shape)}")
    return array


def _read_depth_flag(path, flag, args, calib, stream) -> np.ndarray:
    """read_depth with the reader options, library warnings printed as one line each."""
    _check_units(path, flag, args)
    with warnings_as_lines(stream) as caught:
        depth = read_depth(path, scale=args.depth_scale, calib=calib, key=args.depth_key, byteorder=args.byteorder,
                           invalid_values=args.invalid_values or (), min_depth=args.min_depth,
                           max_depth=args.max_depth, max_pixels=args.max_pixels, name=flag,
                           option_names=READER_FLAGS)
    for record in caught:
        if "Kinect v1" in str(record.message) and calib is not KINECT_NYU:
            print(f"warning: raw Kinect v1 disparity (e.g. NYU Depth V2 raw .pgm) is not metres; "
                  f"--calib {KINECT_CALIB} converts it", file=stream)
    return depth


def _read_inputs(args, stream):
    """(image, depth, mask, truth, description) of the one-frame mode, in metres."""
    image = read_image(args.image, max_pixels=args.max_pixels, name="--image", option_names=READER_FLAGS)
    calib = None
    if args.calib is not None:
        calib = KINECT_NYU if args.calib == KINECT_CALIB else read_calib(args.calib, name="--calib")
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
    prior = None if args.prior is None else _read_prior(args, calib, depth.shape)
    description = f"{args.image} + {args.depth}" + ("" if prior is None else f" + prior {args.prior}")
    return image, depth, mask, truth, prior, description


def _read_prior(args, calib, shape) -> np.ndarray:
    """The --prior map in the units of --depth, checked by :func:`~sparsedepth.priors.as_prior` (the library's rule).

    It is read like --depth (its format, --depth-key, --byteorder and --max-pixels; divided by --depth-scale and
    converted by --calib), but every stored value is a value: a prior is dense, and 0 and negative values are
    relative depth, so --invalid-value, --min-depth and --max-depth, which mark depth readings missing, do not apply.
    NaN or inf anywhere (a non-positive disparity under --calib included) is refused.
    """
    path = check_input_file(args.prior, name="--prior")
    _check_units(path, "--prior", args)
    # io's readers turn 0 into NaN and refuse negatives (depth readings); the prior needs the stored values
    stored, source = read_stored(path, key=args.depth_key, byteorder=args.byteorder, max_pixels=args.max_pixels,
                                 name="--prior", option_names=READER_FLAGS)
    if np.issubdtype(stored.dtype, np.integer) and args.depth_scale is None and not isinstance(calib, KinectDisparity):
        raise UsageError(f"{source} holds integers ({stored.dtype}): give --depth-scale, the divisor of --depth's "
                          "stored values, which --prior shares")
    values = stored.astype(np.float64)
    divisor = 1.0 if args.depth_scale is None else resolve_scale(args.depth_scale, "--depth-scale")
    if divisor != 1.0:
        values /= divisor
    if calib is not None:
        values = calib.depth_from_disparity(values)
    if values.shape != shape:
        raise UsageError(f"--prior '{args.prior}' is {values.shape[0]}x{values.shape[1]} but --depth '{args.depth}' "
                          f"is {shape[0]}x{shape[1]} (H x W); they must have the same size")
    return as_prior(values, shape, name=f"--prior '{args.prior}'", shape_name=f"--depth '{args.depth}'")


_DEPTH_OUTPUTS = ("--out", "depth.npy", "depth.png")
_UNCERTAINTY_OUTPUTS = ("--uncertainty", "uncertainty.npy")
_DEPTH_VIS_OUTPUTS = ("--depth-vis", "depth_vis.png")


def plan_outputs(args, mode) -> list[tuple[str, Named]]:
    """(kind, file) of every output of one frame; kind is the option or the file name in --outdir."""
    planned = []
    for flag, value in (("--out", args.out), ("--uncertainty", args.uncertainty), ("--json", args.json),
                        ("--figure", args.figure), ("--depth-vis", args.depth_vis), ("--ply", args.ply)):
        if value is not None:
            planned.append((flag, Named(flag, value, Path(value))))
    outdir = DEMO_DIR if mode == "demo" and args.outdir is None else args.outdir
    if outdir is not None:
        names = ["depth.npy", "depth.png", "depth_vis.png", "metrics.json"]
        if wants_uncertainty(args):
            names.append("uncertainty.npy")
        if matplotlib_classes() is not None:
            names.append("figure.png")
        if intrinsics_source(args, mode) is not None:
            names.append("points.ply")
        planned += [(name, Named("--outdir", outdir, Path(outdir) / name, create_parent=mode == "demo"))
                    for name in names]
    return planned


def wants_uncertainty(args) -> bool:
    """Whether the run estimates the uncertainty (``--uncertainty``, ``--max-uncertainty`` or
    ``--max-relative-uncertainty`` given)."""
    return (args.uncertainty is not None or args.max_uncertainty is not None
            or args.max_relative_uncertainty is not None)


def input_files(args) -> list[Named]:
    """Every input file of one frame, named by its option."""
    return [Named(flag, value, Path(value)) for flag, value in (
        ("--image", args.image), ("--depth", args.depth), ("--mask", args.mask), ("--truth", args.truth),
        ("--prior", args.prior), ("--calib", args.calib)) if value is not None]


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
        raise UsageError(f"{target.label}: {what} reaches {high:.6g} m, which overflows a 16-bit PNG at scale "
                          f"{scale:g} ({high * scale:.0f} > 65535); give --out-scale {65535 / high:.6g} or "
                          f"less{other}")
    if np.rint(low * scale) == 0:
        raise UsageError(f"{target.label}: {what} has {low:.6g} m, which rounds to 0 (invalid) in a PNG at scale "
                          f"{scale:g}; give --out-scale above {0.5 / low:.6g}{other}")


def _bytes_writer(data: bytes):
    return lambda tmp: Path(tmp).write_bytes(data)


def _load_frame(args, mode, stream):
    """(image, depth, mask, truth, prior, description, keep_fraction, intrinsics) of the demo or the user's files,
    downsampled; intrinsics of the downsampled grid, or None when unknown."""
    demo_intrinsics = None
    if mode == "demo":
        frame = load_motorcycle()
        demo_intrinsics = frame.intrinsics
        image, depth, mask, truth, prior = frame.image, np.asarray(frame.depth), None, None, None
        description = "Middlebury 2014 Motorcycle"
        downsample = DEMO_DOWNSAMPLE if args.downsample is None else args.downsample
        keep_fraction = args.keep_fraction
        if keep_fraction is None and args.keep_count is None:
            keep_fraction = DEMO_KEEP_FRACTION
    else:
        image, depth, mask, truth, prior, description = _read_inputs(args, stream)
        downsample = 1 if args.downsample is None else args.downsample
        keep_fraction = args.keep_fraction
    intrinsics = frame_intrinsics(args, mode, depth.shape, downsample, demo_intrinsics)
    if getattr(args, "camera", None) is not None and intrinsics is not None and not args.quiet:
        print(f"note: {camera_assumption(args.camera)}", file=stream)
    if downsample > 1:
        description += f" (downsampled by {downsample})"
        image, depth = image[::downsample, ::downsample], depth[::downsample, ::downsample]
        mask = None if mask is None else mask[::downsample, ::downsample]
        truth = None if truth is None else truth[::downsample, ::downsample]
        prior = None if prior is None else prior[::downsample, ::downsample]
    return image, depth, mask, truth, prior, description, keep_fraction, intrinsics


def _evaluate(args, image, depth, mask, truth, prior, keep_fraction, weights, stream):
    """:func:`~sparsedepth.batch.evaluate_frame` with the options; warnings and solver progress go to ``stream``,
    and so does a warning line when ``--image-shift auto`` found too few samples to estimate a shift from."""
    complete_fill = args.fill_holes and args.fill_method == "complete"
    use_solver = not args.fill_holes or complete_fill
    with warnings_as_lines(stream):
        outcome = evaluate_frame(
            image, depth, mask=mask, truth=truth, task="fill" if args.fill_holes else "complete",
            keep_fraction=keep_fraction, keep_count=args.keep_count, seed=args.seed,
            fill_method=args.fill_method, weights=weights if use_solver else None,
            solver=args.solver or "auto", tol=args.tol, max_iter=args.max_iter,
            callback=_Progress(stream, not args.quiet) if use_solver and not (args.fast or args.best) else None,
            clip_to_observed=args.clip_to_observed,
            uncertainty=wants_uncertainty(args), max_uncertainty=args.max_uncertainty,
            max_relative_uncertainty=args.max_relative_uncertainty,
            quality="fast" if args.fast else "best" if args.best else "default",
            blowups=args.blowups, expected_error=bool(args.best and args.expected_error),
            prior=prior, prior_alignment=args.prior_alignment or "scale_shift", image_shift=args.image_shift,
        )
    if outcome.image_shift_fallback is not None:
        print(f"warning: --image-shift auto: {outcome.image_shift_fallback}; the image is not moved", file=stream)
    return outcome


def _array_writer(target, values, png_scale):
    """:func:`~sparsedepth.io.depth_writer` of ``values``; its ``ValueError`` is a one-line UsageError naming the flag."""
    try:
        return depth_writer(target.path, values, scale=png_scale)
    except ValueError as exc:
        raise UsageError(f"{target.label}: {one_line(exc)}") from None


def _uncertainty_writer(target, uncertainty, png_scale):
    """:func:`~sparsedepth.io.writing.uncertainty_writer` of the map; its ``ValueError`` is a one-line UsageError."""
    try:
        return uncertainty_writer(target.path, uncertainty, scale=png_scale)
    except ValueError as exc:
        raise UsageError(f"{target.label}: {one_line(exc)}") from None


def _writers(args, planned, outcome, image, report, png_scale, intrinsics=None) -> list:
    """(file, writer) of every planned output, every one encoded and checked before any file is touched."""
    report_text = (json.dumps(report, indent=2, allow_nan=False) + "\n").encode()
    kinds = {kind for kind, _ in planned}
    figure_bytes = None
    if "--figure" in kinds:
        figure_bytes = render_figure(image, outcome, Path(args.figure).suffix.lower())
    if "figure.png" in kinds and not (args.figure or "").lower().endswith(".png"):
        outdir_figure = render_figure(image, outcome, ".png")
    else:
        outdir_figure = figure_bytes
    cloud = None
    if kinds & {"--ply", "points.ply"}:
        cloud = ply_writer(*depth_to_points(outcome.depth, intrinsics, image=image,
                                            name="--intrinsics" if args.intrinsics is not None else "intrinsics"))

    depth_vis_bytes = None
    if kinds & set(_DEPTH_VIS_OUTPUTS):
        depth_vis_bytes = iio.imwrite("<bytes>", colorize_depth(outcome.depth), plugin="pillow", extension=".png")

    items = []
    for kind, target in planned:
        if kind in _DEPTH_OUTPUTS:
            writer = _array_writer(target, outcome.depth, png_scale)
        elif kind in _UNCERTAINTY_OUTPUTS:
            writer = _uncertainty_writer(target, outcome.uncertainty, png_scale)
        elif kind in ("--json", "metrics.json"):
            writer = _bytes_writer(report_text)
        elif kind in _DEPTH_VIS_OUTPUTS:
            writer = _bytes_writer(depth_vis_bytes)
        elif kind in ("--ply", "points.ply"):
            writer = cloud
        else:
            writer = _bytes_writer(figure_bytes if kind == "--figure" else outdir_figure)
        items.append((target, writer))
    return items


def _check_mask_observes_depth(args, valid, mask) -> None:
    """UsageError naming --mask when it marks as observed pixels where --depth has no valid value.

    Without --keep-fraction/--keep-count, --mask says which pixels are observed, so each of them must hold depth
    (the rule of :func:`~sparsedepth._validation.as_depth_and_mask`); with them, it is the region sampled from.
    """
    if args.keep_fraction is not None or args.keep_count is not None:
        return
    marked = int(np.count_nonzero(mask))
    missing = int(np.count_nonzero(mask & ~valid))
    if not missing:
        return
    if 2 * missing > marked:
        fix = ("--mask must be non-zero where depth is observed; an inpainting mask (non-zero where to fill) means "
               "the opposite: invert it")
    else:
        fix = "--mask must mark only pixels with depth: leave those out of it"
    raise UsageError(f"--mask '{args.mask}': --depth '{args.depth}' has no valid value (0, NaN, inf or excluded by "
                     f"--invalid-value/--min-depth/--max-depth) at {missing:,} of the {marked:,} pixels it marks as "
                     f"observed; {fix}")


def _check_observable(args, mode, depth, mask) -> None:
    """UsageError naming the flags when the (downsampled, masked) depth has no valid pixel or fewer than --keep-count,
    or when --mask marks pixels without depth as observed."""
    if depth.ndim != 2 or depth.dtype.kind not in "uif":
        return  # the library names what is wrong with such a depth
    valid = valid_depth_mask(depth)
    if mask is not None and mask.shape == depth.shape:
        _check_mask_observes_depth(args, valid, mask)
        valid &= mask
    count = int(valid.sum())
    source = "the demo's depth" if mode == "demo" else f"--depth '{args.depth}'"
    if count == 0:
        limits = ([f"--mask '{args.mask}'"] if args.mask else []) + (
            [f"--downsample {args.downsample}"] if args.downsample and args.downsample > 1 else [])
        within = f" with {' and '.join(limits)} applied" if limits else ""
        raise UsageError(f"{source} has no valid pixel (finite and > 0){within}: nothing to complete from")
    if args.keep_count is not None and args.keep_count > count:
        raise UsageError(f"--keep-count {args.keep_count} exceeds the {count} valid pixels of {source}")


def _estimate_error(args, image, outcome, weights, stream):
    """``outcome`` with its result's expected RMSEs (:func:`~sparsedepth.expected_error.expected_error` on the
    samples the completion used); the warning that it is not expected to beat nearest fill is one line on
    ``stream``."""
    with warnings_as_lines(stream):
        result = with_expected_error(outcome.result, image, outcome.sparse, outcome.observed,
                                      "fast" if args.fast else "default", weights)
    return dataclasses.replace(outcome, result=result)


def expected_error_line(result) -> str:
    """The line of ``--expected-error``: ``expected RMSE ~ X m (nearest fill ~ Y m)``."""
    return f"expected RMSE ~ {result.expected_rmse:.3g} m (nearest fill ~ {result.expected_nearest_rmse:.3g} m)"


def run_one(args, argv, mode, stdout, stderr) -> int:
    """The demo or one frame of the user's files: complete or fill it, write every output or none, print the table.

    Returns the exit code (0); bad options or files raise
    :class:`~sparsedepth.cli.messages.UsageError` or a library error.
    """
    weights, weights_given = weights_of(args)
    image, depth, mask, truth, prior, description, keep_fraction, intrinsics = _load_frame(args, mode, stderr)
    _check_observable(args, mode, depth, mask)
    check_frame(args, mode, image, depth, mask, intrinsics)
    png_scale = args.out_scale if args.out_scale is not None else (args.depth_scale or 1000.0)
    png_scale = resolve_scale(png_scale)
    planned = plan_outputs(args, mode)
    png_targets = [target for kind, target in planned
                   if kind in _DEPTH_OUTPUTS and target.path.suffix.lower() == ".png"]
    _check_png_range(depth if mask is None else np.where(mask, depth, np.nan), png_scale, png_targets,
                     f"the depth of {'the demo' if mode == 'demo' else '--depth'}")

    outcome = _evaluate(args, image, depth, mask, truth, prior, keep_fraction, weights, stderr)
    if outcome.image_shift != (0, 0):
        image = shift_image(image, outcome.image_shift)  # the figure and the point cloud show the registered image
    if args.expected_error and outcome.result is not None and not args.best:  # --best estimates it as it chooses
        outcome = _estimate_error(args, image, outcome, weights, stderr)

    # every output is encoded and checked before any file is touched; commit writes all or none
    _check_png_range(outcome.depth, png_scale, png_targets, "the completed depth")
    report = build_report(args, argv, outcome, description, weights, weights_given, png_scale, intrinsics)
    commit(_writers(args, planned, outcome, image, report, png_scale, intrinsics))
    written = [target.path for _, target in planned]
    kinds = {kind for kind, _ in planned}
    if any(target.flag == "--outdir" for _, target in planned) and "figure.png" not in kinds and not args.quiet:
        print("note: matplotlib is not installed, no figure.png (pip install 'sparsedepth[plot]')", file=stderr)

    print_table(outcome, description, stdout, image_shift=args.image_shift, limits=removal_limits(args))
    if args.blowups is not None and outcome.result is not None:
        print(blowups_line(args.blowups, outcome.result), file=stdout)
    if args.expected_error and outcome.result is not None:
        print(expected_error_line(outcome.result), file=stdout)
    saturated = uncertainty_png_line(args, outcome, png_scale)
    if saturated is not None:
        print(saturated, file=stdout)
    for path in written:
        print(f"wrote {path}", file=stdout)
    return 0
