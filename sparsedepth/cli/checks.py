"""Checks of option combinations after parsing: which mode a command runs, and what it may not combine.

Every problem is a :class:`~sparsedepth.cli.messages.UsageError` raised
before any file is read or written.  Imports the standard library, the
other modules of :mod:`sparsedepth.cli`, :mod:`sparsedepth.io`, the weights
of :mod:`sparsedepth.objective` and the solver registry.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import os
from pathlib import Path

from ..io import MAX_PIXELS
from ..io.depth import SENSOR_PRESETS
from ..io.formats import OUT_EXTENSIONS
from ..completion import argument_conflict
from ..objective import DEFAULT_WEIGHTS, Weights
from ..solvers.registry import REGISTRY
from .camera import KINECT_CALIB, intrinsics_source, missing_intrinsics_message
from .frame_checks import check_frame
from .messages import UsageError
from .outputs import check_distinct, check_writable
from .report import matplotlib_classes
from .single import input_files, plan_outputs

__all__ = ["check_options", "check_frame", "cluster_address", "COLMAP_CSV", "COLMAP_SCENE"]


_OUT_EXTENSIONS = OUT_EXTENSIONS  # --out and --uncertainty: the table of sparsedepth.io.formats


_FIGURE_EXTENSIONS = (".png", ".pdf", ".svg", ".jpg", ".jpeg")


def _check_output(path, allowed, what) -> Path:
    path = Path(path)
    if path.suffix.lower() not in allowed:
        raise UsageError(f"{what} '{path}': unsupported extension '{path.suffix or '(none)'}'; use {', '.join(allowed)}")
    return path


def _check_combinations(args) -> str:
    """Check option combinations; return the mode: 'demo', 'files' or 'batch' (--batch, --nyu-mat or --colmap)."""
    batch = args.batch is not None or args.nyu_mat is not None or args.colmap is not None
    files = args.image is not None or args.depth is not None
    if batch and files:
        source = "--colmap" if args.colmap is not None else "--batch/--nyu-mat"
        raise UsageError(f"{source} and --image/--depth are exclusive")
    _check_colmap(args)
    if files and (args.image is None or args.depth is None):
        raise UsageError("--image and --depth go together")
    mode = "batch" if batch else "files" if files else "demo"
    if mode == "demo" and (args.mask or args.truth or args.calib or args.depth_key):
        raise UsageError("--mask, --truth, --calib and --depth-key need --image and --depth")
    if mode == "demo" and args.fill_holes:
        raise UsageError("--fill-holes needs --image and --depth (raw depth), or --batch/--nyu-mat")
    if args.fill_method is not None and not args.fill_holes:
        raise UsageError(f"--fill-method {args.fill_method} chooses how --fill-holes fills; add --fill-holes or "
                          "drop --fill-method")
    if args.fill_method is None:
        args.fill_method = "colorization"
    if args.fill_holes and (args.keep_fraction is not None or args.keep_count is not None):
        raise UsageError("--keep-fraction/--keep-count simulate sparse input; they do not apply to --fill-holes")
    colorization = args.fill_holes and args.fill_method == "colorization"
    _check_argument_rules(args, colorization)
    _check_camera_options(args, mode)
    _check_image_shift(args)
    _check_edge_penalty(args)
    _check_prior(args, mode)
    if args.fast and args.best:
        raise UsageError("--best and --fast are two ways to complete a frame: give one")
    if mode == "batch":
        if args.colmap is None and (args.uncertainty is not None or args.max_uncertainty is not None
                                    or args.max_relative_uncertainty is not None):
            raise UsageError("--uncertainty, --max-uncertainty and --max-relative-uncertainty are for one frame, "
                              "not a batch")
        if args.blowups is not None:
            raise UsageError("--blowups is for one frame, not a batch")
        if args.colmap is not None and args.csv is None:
            args.csv = str(Path(args.outdir) / COLMAP_CSV)
        if args.csv is None:
            raise UsageError("a batch needs --csv PATH for the per-frame metrics")
        if args.out or args.json or args.figure or args.mask or args.truth or args.calib:
            raise UsageError("--out, --json, --figure, --mask, --truth and --calib are for one frame; "
                              "a batch writes --csv (and per-frame depth with --outdir)")
        if args.depth_vis:
            raise UsageError("--depth-vis is for one frame; a batch writes --csv (and per-frame depth with --outdir)")
        if args.expected_error:
            raise UsageError("--expected-error is for one frame; a batch with ground truth scores every frame in --csv")
        if args.indices is not None and args.nyu_mat is None:
            raise UsageError("--indices selects frames of --nyu-mat")
        if (args.nyu_mat is not None and not args.fill_holes and args.keep_fraction is None
                and args.keep_count is None):
            raise UsageError("--nyu-mat without --fill-holes samples the dense depths: give --keep-fraction "
                              "or --keep-count")
        _check_output(args.csv, (".csv",), "--csv")
    else:
        if args.csv or args.workers or args.indices is not None:
            raise UsageError("--csv, --workers and --indices are for --batch/--nyu-mat/--colmap")
        if args.out:
            _check_output(args.out, _OUT_EXTENSIONS, "--out")
        if args.uncertainty:
            _check_output(args.uncertainty, _OUT_EXTENSIONS, "--uncertainty")
        if args.json:
            _check_output(args.json, (".json",), "--json")
        if args.ply:
            _check_output(args.ply, (".ply",), "--ply")
        if args.figure:
            _check_output(args.figure, _FIGURE_EXTENSIONS, "--figure")
        if args.depth_vis:
            _check_output(args.depth_vis, (".png",), "--depth-vis")
        outputs = [target for _, target in plan_outputs(args, mode)]
        check_distinct(outputs, input_files(args))
        check_writable(outputs)
        if args.figure and matplotlib_classes() is None:
            raise UsageError("--figure needs matplotlib, which is not installed: "
                              "pip install 'sparsedepth[plot]' (or matplotlib)")
    _check_cluster_options(args, mode)
    return mode


#: The CSV of a --colmap run when --csv is not given, in --outdir.
COLMAP_CSV = "views.csv"

#: The scene description a --colmap run writes in --outdir.
COLMAP_SCENE = "scene.json"


def _check_colmap(args) -> None:
    """--colmap needs --images and --outdir; its samples are the model's points, so the options that read depth
    files or simulate samples do not apply; --images and --colmap-* need --colmap."""
    if args.colmap is None:
        given = [flag for flag, value in (("--images", args.images), ("--colmap-max-error", args.colmap_max_error),
                                          ("--colmap-min-track", args.colmap_min_track)) if value is not None]
        if given:
            raise UsageError(f"{', '.join(given)} {'go' if len(given) > 1 else 'goes'} with --colmap DIR (the "
                              "COLMAP model whose views are completed)")
        return
    if args.images is None:
        raise UsageError(f"--colmap '{args.colmap}' needs --images DIR, the folder the model's image names are "
                          "relative to")
    if args.outdir is None:
        raise UsageError(f"--colmap '{args.colmap}' needs --outdir DIR, the (existing) folder of the depth maps")
    not_here = [flag for flag, value in (
        ("--keep-fraction", args.keep_fraction), ("--keep-count", args.keep_count),
        ("--fill-holes", args.fill_holes or None), ("--fill-method", args.fill_method),
        ("--downsample", args.downsample), ("--depth-scale", args.depth_scale), ("--byteorder", args.byteorder),
        ("--invalid-value", args.invalid_values), ("--min-depth", args.min_depth), ("--max-depth", args.max_depth),
        ("--max-uncertainty", args.max_uncertainty), ("--max-relative-uncertainty", args.max_relative_uncertainty),
        ("--truth-prefix", args.truth_prefix),
        ("--batch-depths", args.batch_depths), ("--batch-truths", args.batch_truths)) if value is not None]
    not_here += [flag for flag, value, default in (("--image-prefix", args.image_prefix, "rgb_"),
                                                   ("--depth-prefix", args.depth_prefix, "depth_"))
                 if value != default]
    if not_here:
        raise UsageError(f"{', '.join(not_here)} {'do' if len(not_here) > 1 else 'does'} not apply to --colmap: "
                          "each view's samples are the model's 3-D points it observes, at full resolution, in "
                          "the model's units (filter them with --colmap-max-error/--colmap-min-track)")
    if args.uncertainty is not None:
        if not Path(args.uncertainty).is_dir():
            raise UsageError(f"--uncertainty '{args.uncertainty}': with --colmap, an existing folder for one "
                              "uncertainty map per view; create it first")
        if Path(args.uncertainty).resolve() == Path(args.outdir).resolve():
            raise UsageError(f"--uncertainty '{args.uncertainty}' is --outdir: the uncertainty maps have the "
                              "depth maps' names; give another folder")


def _check_image_shift(args) -> None:
    """--image-shift DY,DX: no frame this run may read (at most --max-pixels pixels, so at most that many rows or
    columns) keeps any of its image under a larger shift; the frame's own size is checked by :func:`check_frame`."""
    if not isinstance(args.image_shift, tuple):
        return
    dy, dx = args.image_shift
    if max(abs(dy), abs(dx)) >= args.max_pixels:
        raise UsageError(f"--image-shift {dy},{dx} moves the image out of any frame this run may read (frames of "
                          f"at most {args.max_pixels} pixels, --max-pixels, have no more rows or columns than that); "
                          "a registration shift is a few pixels, e.g. --image-shift 0,-2")


def _check_argument_rules(args, colorization) -> None:
    """The library's rules of which arguments go together (:data:`~sparsedepth.completion.ARGUMENT_RULES`), in flags."""
    weight_flags = [f"--{f.name.replace('_', '-')}" for f in dataclasses.fields(Weights)
                    if getattr(args, f"w_{f.name}") is not None]
    flags = {"colorization": ["--fill-method colorization"], "weights": weight_flags,
             "solver": ["--solver"] if args.solver not in (None, "auto") else [],
             "tol": ["--tol"] if args.tol is not None else [],
             "max_iter": ["--max-iter"] if args.max_iter is not None else [],
             "quality": ["--fast"] if args.fast else [],
             "best": ["--best"] if args.best else [],
             "uncertainty": ["--uncertainty"] if args.uncertainty is not None else [],
             "max_uncertainty": [flag for flag, value in (("--max-uncertainty", args.max_uncertainty),
                                                           ("--max-relative-uncertainty",
                                                            args.max_relative_uncertainty)) if value is not None],
             "prior": ["--prior"] if args.prior is not None else [],
             "expected_error": ["--expected-error"] if args.expected_error else [],
             "blowups": [f"--blowups {args.blowups}"] if args.blowups is not None else []}
    if not colorization:
        flags["colorization"] = []
    conflict = argument_conflict(name for name, given in flags.items() if given)
    if conflict is not None:
        argument, why, excluded = conflict
        named = [flag for name in excluded for flag in flags[name]]
        raise UsageError(f"{flags[argument][0]} {why} {', '.join(named)}")


def _check_prior(args, mode) -> None:
    """--prior: one frame of the user's files (the rules of which options go with it: :func:`_check_argument_rules`)."""
    if args.prior is None:
        if args.prior_alignment is not None:
            raise UsageError("--prior-alignment aligns --prior: give --prior PATH too")
        return
    if mode != "files":
        raise UsageError("--prior needs --image and --depth (one frame): it must match that frame's pixels")


def _check_edge_penalty(args) -> None:
    """--edge-penalty and --edge-scale: a robust penalty needs --gamma > 0 and a solver that handles it."""
    penalty = args.w_edge_penalty or DEFAULT_WEIGHTS.edge_penalty
    gamma = DEFAULT_WEIGHTS.gamma if args.w_gamma is None else args.w_gamma
    if args.w_edge_scale is not None and penalty == "l1":
        raise UsageError("--edge-scale is the scale of a robust --edge-penalty (charbonnier, cauchy, "
                          "geman_mcclure, welsch); the l1 edge penalty has none")
    if penalty != "l1" and gamma == 0:
        raise UsageError(f"--edge-penalty {penalty} weights the edge term, which --gamma {gamma:g} removes: give "
                          "--gamma > 0 (e.g. --gamma 0.01)")
    if penalty != "l1" and args.solver not in (None, "auto") and not REGISTRY[args.solver].robust:
        raise UsageError(f"--solver {args.solver} cannot minimise the robust --edge-penalty {penalty}; use --solver "
                          "irls (the default for it), lbfgsb or adam")


def _check_camera_options(args, mode) -> None:
    """--ply, --intrinsics and --camera: one frame only, one source of intrinsics, none missing for --ply."""
    given = [flag for flag, value in (("--ply", args.ply), ("--intrinsics", args.intrinsics),
                                      ("--camera", args.camera)) if value is not None]
    if mode == "batch" and given:
        raise UsageError(f"{', '.join(given)}: point clouds are written for one frame (--image/--depth or the "
                          "demo), not for --batch/--nyu-mat/--colmap")
    explicit = "--intrinsics" if args.intrinsics is not None else "--camera" if args.camera is not None else None
    if mode == "demo" and explicit:
        raise UsageError(f"{explicit} is for --image/--depth; the demo uses the calibration of its own frame "
                          "(Middlebury 2014 Motorcycle)")
    if explicit and args.calib is not None and args.calib != KINECT_CALIB:
        raise UsageError(f"--calib '{args.calib}' gives the intrinsics (cam0) already; drop {explicit}")
    if args.ply is not None and intrinsics_source(args, mode) is None:
        raise UsageError(missing_intrinsics_message())


def _check_batch_flags(args, mode) -> None:
    if mode != "batch" and (args.batch_depths or args.batch_truths or args.overwrite):
        raise UsageError("--batch-depths, --batch-truths and --overwrite are for --batch/--nyu-mat/--colmap")
    if args.batch_depths is not None and args.batch is None:
        raise UsageError("--batch-depths pairs with --batch DIR (the image folder)")
    if args.batch_truths is not None and args.batch_depths is None:
        raise UsageError("--batch-truths goes with --batch-depths (--truth-prefix for a --batch folder)")


def _apply_sensor(args, mode) -> None:
    """``--sensor``: the preset's scale, invalid codes and range where the user gave none of their own."""
    name = getattr(args, "sensor", None)
    if name is None:
        return
    if mode == "demo":
        raise UsageError(f"--sensor {name} describes your --depth files; the demo has its own")
    if args.colmap is not None:
        raise UsageError(f"--sensor {name} describes depth files; --colmap takes the depth from the model's points")
    preset = SENSOR_PRESETS[name]
    if args.depth_scale is None:
        args.depth_scale = preset.scale
    if preset.invalid_values:
        given = list(args.invalid_values or [])
        args.invalid_values = given + [v for v in preset.invalid_values if v not in given]
    if args.min_depth is None and preset.min_depth > 0:
        args.min_depth = preset.min_depth
    if args.max_depth is None:
        args.max_depth = preset.max_depth


def _check_reader_options(args, mode) -> None:
    """Reader options apply to the user's files (one frame or a batch); check their combinations."""
    given = [flag for flag, value in (("--byteorder", args.byteorder), ("--invalid-value", args.invalid_values),
                                      ("--min-depth", args.min_depth), ("--max-depth", args.max_depth))
             if value is not None]
    if args.max_pixels != MAX_PIXELS:
        given.append("--max-pixels")
    if given and mode == "demo":
        raise UsageError(f"{', '.join(given)} apply to your files (--image/--depth or a batch), not the demo")
    if args.min_depth is not None and args.max_depth is not None and args.min_depth > args.max_depth:
        raise UsageError(f"--min-depth {args.min_depth:g} is larger than --max-depth {args.max_depth:g}")


def _check_cluster_options(args, mode) -> None:
    given = [name for name, value in (("--scheduler", args.scheduler), ("--scheduler-file", args.scheduler_file),
                                      ("--scheduler-timeout", args.scheduler_timeout)) if value is not None]
    if given and mode != "batch":
        raise UsageError(f"{', '.join(given)} run a batch on a Dask cluster: they need --batch/--nyu-mat/--colmap")
    if args.workers is not None and (args.scheduler is not None or args.scheduler_file is not None):
        raise UsageError("--workers sizes the local process pool; with --scheduler/--scheduler-file the "
                          "cluster's workers run the frames")
    if mode == "batch" and cluster_address(args) is not None and importlib.util.find_spec("distributed") is None:
        raise UsageError("a batch on a Dask cluster needs dask.distributed, which is not installed: "
                          "pip install 'sparsedepth[distributed]'")


def cluster_address(args):
    """(address, scheduler_file) of the Dask scheduler of a batch, or None for the local process pool."""
    if args.scheduler_file is not None:
        return None, args.scheduler_file
    address = args.scheduler
    if address is None and args.workers is None:
        address = os.environ.get("DASK_SCHEDULER_ADDRESS") or None
    return (address, None) if address is not None else None


def check_options(args) -> str:
    """Check the parsed options together; return the mode: ``"demo"``, ``"files"`` or ``"batch"``.

    ``args.fill_method`` left unset becomes ``"colorization"`` (it is only given with ``--fill-holes``).
    """
    mode = _check_combinations(args)
    _apply_sensor(args, mode)
    _check_batch_flags(args, mode)
    _check_reader_options(args, mode)
    return mode
