"""Checks of one frame as it will be completed (read, downsampled), before any solve.

:func:`check_frame` is called by the one-frame mode after reading its files; each failure is one
:class:`~sparsedepth.cli.messages.UsageError` line naming the option.  Imports the library's checks,
:mod:`~sparsedepth.cli.camera` and :mod:`~sparsedepth.cli.messages`.
"""

from __future__ import annotations

import numpy as np

from ..registration import check_shift_fits
from ..uncertainty import check_uncertainty_shape
from .camera import intrinsics_source
from .messages import UsageError

__all__ = ["check_frame"]


def check_frame(args, mode, image, depth, mask=None, intrinsics=None) -> None:
    """Checks that need the frame as it will be completed (read, downsampled) but no solve.

    Parameters
    ----------
    args : argparse.Namespace
        The checked options (:func:`check_options`).
    mode : str
        ``"demo"`` or ``"files"``.
    image : ndarray, (H, W) or (H, W, C)
        The image, after ``--downsample``.
    depth : ndarray, (H, W)
        The depth in metres after ``--downsample``, NaN (or 0) where missing.
    mask : ndarray of bool, optional
        ``--mask`` after ``--downsample``.
    intrinsics : tuple of 4 float, optional
        ``(fx, fy, cx, cy)`` of this grid, when a point cloud is written.

    Raises
    ------
    UsageError
        One line naming the option: an ``--image-shift`` that moves the
        image out of the frame, ``--uncertainty``/``--max-uncertainty`` on a
        frame smaller than 2x2 pixels, or intrinsics under which the point
        cloud of ``--ply`` (``points.ply`` of ``--outdir``) leaves the
        float32 range of a PLY file.  The last is checked when the output is
        clamped to the range of the samples (the default): the largest
        sample bounds the completed depth.
    """
    shape = np.shape(depth)[:2]
    where = f"this frame ({'the demo' if mode == 'demo' else f'--image {args.image!r}'}"
    where += f", after --downsample {args.downsample})" if args.downsample and args.downsample > 1 else ")"
    if isinstance(args.image_shift, tuple):
        try:
            check_shift_fits(args.image_shift, shape, name="--image-shift")
        except ValueError as exc:
            raise UsageError(f"{exc} of {where}") from None
    wanted = [flag for flag, value in (("--uncertainty", args.uncertainty), ("--max-uncertainty", args.max_uncertainty),
                                       ("--max-relative-uncertainty", args.max_relative_uncertainty))
              if value is not None]
    if wanted and not (args.fill_holes and args.fill_method == "colorization"):
        try:
            check_uncertainty_shape(shape, name="/".join(wanted))
        except ValueError as exc:
            raise UsageError(f"{exc}, {where}") from None
    if intrinsics is not None and args.clip_to_observed:
        _check_point_range(args, mode, shape, depth if mask is None else np.where(mask, depth, np.nan), intrinsics)


def _check_point_range(args, mode, shape, depth, intrinsics) -> None:
    """UsageError naming the intrinsics' option and --ply when the farthest point leaves the float32 range."""
    values = np.asarray(depth, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        values = values[np.isfinite(values) & (values > 0)]
    if values.size == 0:
        return
    far = float(values.max())
    fx, fy, cx, cy = (float(v) for v in intrinsics)
    height, width = shape
    x = max(abs(cx), abs(width - 1 - cx)) * far / fx
    y = max(abs(cy), abs(height - 1 - cy)) * far / fy
    limit = float(np.finfo(np.float32).max)
    if max(x, y, far) <= limit:
        return
    source = intrinsics_source(args, mode)
    given = {"--intrinsics": f"--intrinsics {','.join(f'{v:g}' for v in args.intrinsics or ())}",
             "--camera": f"--camera {args.camera}", "--calib": f"--calib '{args.calib}'"}.get(source, source)
    output = "--ply" if args.ply is not None else "--outdir's points.ply"
    scaled = f" (divided by --downsample {args.downsample})" if args.downsample and args.downsample > 1 else ""
    raise UsageError(f"{given}{scaled}: the {output} point cloud of this {height}x{width} (H x W) frame with depth "
                     f"up to {far:.4g} m reaches |{'x' if x >= y else 'y'}| = {max(x, y):.3g} m, beyond the float32 "
                     f"range of a PLY file ({limit:.3g}); intrinsics are in pixels (focal lengths of hundreds to "
                     "thousands for common cameras)")

