"""Camera intrinsics of the command line: ``--intrinsics``, ``--camera`` presets, ``--calib``, the demo's own.

:data:`CAMERA_PRESETS` holds the presets with the image size they belong to,
:func:`parse_intrinsics` is the argparse type of ``--intrinsics``,
:func:`intrinsics_source` says before any work whether a run knows its
intrinsics (and :func:`missing_intrinsics_message` what to say when
``--ply`` needs them), and :func:`frame_intrinsics` gives the intrinsics of
the grid the run completes (refusing a preset whose image size differs,
scaled for ``--downsample``).  Imports the standard library,
:mod:`sparsedepth.io`, :data:`sparsedepth.datasets.frame.NYU_RGB_INTRINSICS`
and :mod:`.messages`.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

from .._validation import check_intrinsics
from ..datasets.frame import NYU_RGB_INTRINSICS
from ..io import read_calib
from ..io.calibration import read_intrinsics
from .messages import UsageError

__all__ = ["CAMERA_PRESETS", "CameraPreset", "KINECT_CALIB", "camera_assumption", "frame_intrinsics",
           "intrinsics_source", "missing_intrinsics_message", "parse_intrinsics"]

#: The ``--calib`` value that means raw Kinect disparity (no intrinsics in it).
KINECT_CALIB = "kinect-nyu"


@dataclass(frozen=True)
class CameraPreset:
    """Intrinsics ``(fx, fy, cx, cy)`` in pixels, valid for images of ``height`` x ``width`` pixels."""

    intrinsics: tuple[float, float, float, float]
    height: int
    width: int
    what: str


#: ``--camera`` presets.  nyu: the NYU Depth V2 RGB camera of the registered
#: 640x480 frames (NYU toolbox ``camera_params.m``).  kitti: the left colour
#: camera (image_02) of KITTI, the ``fx, fy, cx, cy`` of ``P2`` (P_rect_02)
#: of the raw-data calibration that the shared KITTI frames
#: (``kitti_metric3d``, 1242x375, Metric3D ``cam_in``) use; other KITTI
#: drives have other calibrations (and sizes), so images of another size are
#: refused.
CAMERA_PRESETS = {
    "nyu": CameraPreset(NYU_RGB_INTRINSICS, 480, 640, "the NYU Depth V2 RGB camera (registered 640x480 frames)"),
    "kitti": CameraPreset((707.0493, 707.0493, 604.0814, 180.5066), 375, 1242,
                          "KITTI image_02, P2 of the shared frames' raw calibration (1242x375 images)"),
}


def camera_assumption(name: str) -> str:
    """The one line a run with ``--camera NAME`` prints: the calibration it assumed and how to give another."""
    preset = CAMERA_PRESETS[name]
    fx, fy, cx, cy = preset.intrinsics
    line = f"--camera {name} assumes {preset.what}: fx {fx:g}, fy {fy:g}, cx {cx:g}, cy {cy:g} px"
    if name == "kitti":
        line += ("; KITTI's calibration differs by recording date (fx 707-722 px, a 2 % error in the point cloud): "
                 "for another date give --intrinsics calib_cam_to_cam.txt of that date (P_rect_02 is read)")
    return line


def parse_intrinsics(text: str) -> tuple[float, float, float, float]:
    """The argparse type of ``--intrinsics``: ``fx,fy,cx,cy`` in pixels (focal lengths positive), or a calibration
    file :func:`~sparsedepth.io.calibration.read_intrinsics` reads (a 3x3 K, JSON/YAML, KITTI, COLMAP)."""
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = None
    if values is None and len(parts) == 1:
        try:
            return read_intrinsics(text, name="--intrinsics")
        except FileNotFoundError:
            raise argparse.ArgumentTypeError(f"expected four numbers fx,fy,cx,cy in pixels or a calibration file, "
                                             f"got {text!r} (no such file)") from None
        except (TypeError, ValueError) as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix("--intrinsics ").rstrip(".")) from None
    if values is None or len(values) != 4:
        raise argparse.ArgumentTypeError(f"expected four numbers fx,fy,cx,cy in pixels or a calibration file, got "
                                         f"{text!r}")
    try:
        return check_intrinsics(values, name="--intrinsics")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{str(exc).removeprefix('--intrinsics: ').rstrip('.')} in {text!r}") from None


def intrinsics_source(args, mode) -> str | None:
    """The option that gives the run its intrinsics (``"--intrinsics"``, ``"--camera"``, ``"--calib"``,
    ``"demo"``), or None when they are unknown."""
    if mode == "demo":
        return "demo"
    if args.intrinsics is not None:
        return "--intrinsics"
    if args.camera is not None:
        return "--camera"
    if args.calib is not None and args.calib != KINECT_CALIB:
        return "--calib"
    return None


def missing_intrinsics_message() -> str:
    """What ``--ply`` says when the run has no intrinsics."""
    return ("--ply needs the camera intrinsics: give --intrinsics fx,fy,cx,cy (pixels), "
            f"--camera {'|'.join(CAMERA_PRESETS)}, or --calib calib.txt (Middlebury/ETH3D cam0)")


def frame_intrinsics(args, mode, full_shape, downsample: int, demo_intrinsics=None):
    """``(fx, fy, cx, cy)`` of the grid the run completes, or None when unknown.

    ``full_shape`` is ``(H, W)`` of the image as read (before
    ``--downsample``); a ``--camera`` preset of another size is a
    :class:`UsageError`.  Keeping every ``downsample``-th pixel from pixel 0
    divides every intrinsic by ``downsample`` (pixel centres at integer
    coordinates; see :func:`sparsedepth.depth_to_points`).
    """
    source = intrinsics_source(args, mode)
    if source is None:
        return None
    if source == "demo":
        intrinsics = demo_intrinsics
    elif source == "--intrinsics":
        intrinsics = args.intrinsics
    elif source == "--camera":
        preset = CAMERA_PRESETS[args.camera]
        if tuple(full_shape) != (preset.height, preset.width):
            raise UsageError(
                f"--camera {args.camera} is {preset.what}, but --image '{args.image}' is "
                f"{full_shape[1]}x{full_shape[0]} (W x H); give --intrinsics fx,fy,cx,cy for this image")
        intrinsics = preset.intrinsics
    else:
        intrinsics = read_calib(args.calib, name="--calib").intrinsics
    if intrinsics is None:
        return None
    return tuple(float(v) / downsample for v in check_intrinsics(intrinsics))
