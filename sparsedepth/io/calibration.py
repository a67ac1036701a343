"""Stereo and Kinect calibration: ``calib.txt`` files and disparity-to-depth conversions.

What lives here: :class:`StereoCalibration` (Middlebury / ETH3D rectified
stereo), :func:`read_calib`, :func:`disparity_to_depth`,
:class:`KinectDisparity` with the NYU Depth V2 constants :data:`KINECT_NYU`,
and :func:`read_intrinsics` (pinhole intrinsics from the files cameras come
with: a 3x3 K, JSON or YAML, KITTI, COLMAP).

Imports NumPy, :mod:`sparsedepth._validation` and :mod:`.files` /
:mod:`.stored` only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Mapping

import numpy as np

from .._validation import check_input_file, check_intrinsics, check_positive_finite, is_real
from .files import file_label
from .stored import check_real_array

__all__ = ["KINECT_NYU", "KinectDisparity", "StereoCalibration", "disparity_to_depth", "read_calib", "read_intrinsics"]

_MAX_BYTES = 1 << 20
_KNOWN_KEYS = ("cam0", "cam1", "doffs", "baseline", "width", "height", "ndisp")


def _check_doffs(doffs) -> float:
    """``doffs`` as a float; ``ValueError`` unless it is a finite real number."""
    if not is_real(doffs) or not math.isfinite(doffs):
        raise ValueError(f"`doffs` must be a finite number, got {doffs!r}.")
    return float(doffs)


def _readonly(array: np.ndarray) -> np.ndarray:
    """A read-only float64 copy of ``array``."""
    array = np.array(array, dtype=np.float64)
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class StereoCalibration:
    """Rectified stereo calibration in the Middlebury / ETH3D ``calib.txt`` layout.

    Attributes
    ----------
    cam0 : (3, 3) ndarray of float64
        Intrinsic matrix ``[[f, 0, cx], [0, f, cy], [0, 0, 1]]`` of the left
        (reference) camera, in pixels.  Read-only.
    baseline_mm : float
        Camera baseline in millimetres.
    doffs : float
        x-difference of the principal points, ``cx1 - cx0``, in pixels.
    cam1 : (3, 3) ndarray of float64 or None
        Intrinsic matrix of the right camera, if given.
    width, height : int or None
        Image size in pixels, if given.
    ndisp : int or None
        Conservative bound on the number of disparity levels, if given.
    extra : Mapping[str, float or str]
        Any other ``key=value`` entries (``isint``, ``vmin``, ``vmax``, ...).

    Notes
    -----
    Depth follows from disparity ``d`` (pixels) as

    .. math:: Z = \\frac{f \\, B}{d + d_\\mathrm{offs}},

    with ``Z`` in the unit of the baseline; see :func:`disparity_to_depth`.
    """

    cam0: np.ndarray
    baseline_mm: float
    doffs: float = 0.0
    cam1: np.ndarray | None = None
    width: int | None = None
    height: int | None = None
    ndisp: int | None = None
    extra: Mapping[str, float | str] = field(default_factory=dict)

    def __post_init__(self):
        if self.cam0 is None:
            raise ValueError("`cam0` is required.")
        for name in ("cam0", "cam1"):
            matrix = getattr(self, name)
            if matrix is None:
                continue
            matrix = np.asarray(matrix, dtype=np.float64)
            if matrix.shape != (3, 3) or not np.all(np.isfinite(matrix)):
                raise ValueError(f"`{name}` must be a finite 3x3 matrix, got {matrix!r}.")
            if matrix[0, 0] <= 0 or matrix[1, 1] <= 0:
                raise ValueError(f"`{name}` focal lengths must be positive, got {matrix!r}.")
            object.__setattr__(self, name, _readonly(matrix))
        object.__setattr__(self, "baseline_mm", check_positive_finite(self.baseline_mm, label="`baseline_mm`"))
        object.__setattr__(self, "doffs", _check_doffs(self.doffs))
        object.__setattr__(self, "extra", MappingProxyType(dict(self.extra)))

    @property
    def focal_px(self) -> float:
        """Horizontal focal length of ``cam0`` in pixels."""
        return float(self.cam0[0, 0])

    @property
    def cx(self) -> float:
        """Principal point x of ``cam0`` in pixels."""
        return float(self.cam0[0, 2])

    @property
    def cy(self) -> float:
        """Principal point y of ``cam0`` in pixels."""
        return float(self.cam0[1, 2])

    @property
    def intrinsics(self) -> tuple[float, float, float, float]:
        """``(fx, fy, cx, cy)`` of ``cam0`` in pixels."""
        return (float(self.cam0[0, 0]), float(self.cam0[1, 1]), self.cx, self.cy)

    def depth_from_disparity(self, disparity) -> np.ndarray:
        """Metric depth (metres) of a ``cam0`` disparity map; see :func:`disparity_to_depth`."""
        return disparity_to_depth(disparity, self.focal_px, self.baseline_mm, doffs=self.doffs)


@dataclass(frozen=True)
class KinectDisparity:
    """Conversion of raw Kinect v1 disparity units to metres.

    The Kinect v1 stores an 11-bit "disparity" code per pixel; 2047 means no
    measurement.  The NYU Depth V2 toolbox (``depth_rel2depth_abs.m``) turns
    it into metres with the constants of :data:`KINECT_NYU`.

    Attributes
    ----------
    numerator : float
        :math:`a` in the formula below (metres times disparity units).
    offset : float
        :math:`b`, the raw value at which depth would become infinite.
    invalid : int
        Raw code for "no measurement".

    Notes
    -----
    .. math:: Z\\,[\\mathrm{m}] = \\frac{a}{b - r}

    for a raw value :math:`r`; pixels with :math:`r \\ge b`, :math:`r` equal
    to ``invalid`` or not finite are NaN.  Unlike the toolbox, depth is not
    clamped to 10 m (use ``max_depth`` of :func:`read_depth`).  Raw NYU
    frames are not registered to the colour camera: the toolbox projects
    them with the camera parameters, which this conversion does not do.

    References
    ----------
    .. [1] N. Silberman et al., "Indoor segmentation and support inference
       from RGBD images", ECCV 2012 (NYU Depth V2 toolbox, camera_params.m).
    """

    numerator: float = 351.3
    offset: float = 1092.5
    invalid: int = 2047

    def depth_from_disparity(self, disparity) -> np.ndarray:
        """Metres from raw disparity (any shape); NaN where invalid."""
        raw = check_real_array(disparity, "disparity").astype(np.float64)
        valid = np.isfinite(raw) & (raw < self.offset) & (raw != self.invalid)
        depth = np.full(raw.shape, np.nan)
        depth[valid] = self.numerator / (self.offset - raw[valid])
        return depth


#: Kinect v1 constants of the NYU Depth V2 toolbox: metres = 351.3 / (1092.5 - raw).
KINECT_NYU = KinectDisparity()


def _parse_matrix(text: str, key: str, where: str) -> np.ndarray:
    """The 3x3 matrix of a ``[a b c; d e f; g h i]`` entry."""
    body = text.strip()
    if not (body.startswith("[") and body.endswith("]")):
        raise ValueError(f"{where}: `{key}` must look like [f 0 cx; 0 f cy; 0 0 1], got {text!r}.")
    try:
        rows = [[float(v) for v in row.split()] for row in body[1:-1].split(";")]
    except ValueError:
        raise ValueError(f"{where}: `{key}` has a non-numeric entry: {text!r}.") from None
    if len(rows) != 3 or any(len(row) != 3 for row in rows):
        raise ValueError(f"{where}: `{key}` must be a 3x3 matrix, got {text!r}.")
    return np.array(rows, dtype=np.float64)


def read_calib(path, *, name: str = "path") -> StereoCalibration:
    """Read a Middlebury 2014 / ETH3D two-view ``calib.txt`` file.

    Parameters
    ----------
    path : str or os.PathLike
        Text file with one ``key=value`` per line, e.g.::

            cam0=[711.499 0 376.135; 0 711.499 227.447; 0 0 1]
            cam1=[711.499 0 376.135; 0 711.499 227.447; 0 0 1]
            doffs=0
            baseline=59.9432
            width=713
            height=434
            ndisp=713

        ``cam0`` and ``baseline`` (millimetres) are required; ``doffs``
        defaults to 0.
    name : str, optional
        Label of ``path`` in error messages.

    Returns
    -------
    StereoCalibration

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If ``path`` is not a regular file or larger than 1 MiB, a line is not
        ``key=value``, a value does not parse, a key is repeated or a required
        key is missing.
    """
    path = check_input_file(path, name=name)
    where = file_label(path, name)
    entries = _parse_entries(_read_text(path, where), where)
    return _calibration_from_entries(entries, where)


def _read_text(path: Path, where: str) -> str:
    """The ASCII text of a calibration file of at most 1 MiB."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read(_MAX_BYTES + 1)
    except OSError as exc:
        raise ValueError(f"{where}: cannot be read ({exc}).") from None
    if len(raw) > _MAX_BYTES:
        raise ValueError(f"{where}: larger than {_MAX_BYTES} bytes; not a calib.txt file.")
    try:
        return raw.decode("ascii")
    except UnicodeDecodeError:
        raise ValueError(f"{where}: calibration file is not ASCII text.") from None


def _parse_entries(text: str, where: str) -> dict[str, str]:
    """The ``key=value`` lines of a calibration file, each key once, ``cam0`` and ``baseline`` present."""
    entries: dict[str, str] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line:
            continue
        key, sep, value = line.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"{where}, line {number}: expected 'key=value', got {line!r}.")
        if key in entries:
            raise ValueError(f"{where}, line {number}: `{key}` is given twice.")
        entries[key] = value.strip()
    for required in ("cam0", "baseline"):
        if required not in entries:
            raise ValueError(f"{where}: required entry `{required}` is missing.")
    return entries


def _calibration_from_entries(entries: dict[str, str], where: str) -> StereoCalibration:
    """Parse the values of the entries into a :class:`StereoCalibration`; other keys go to ``extra``."""

    def number(key: str) -> float:
        try:
            return float(entries[key])
        except ValueError:
            raise ValueError(f"{where}: `{key}` is not a number: {entries[key]!r}.") from None

    def integer(key: str) -> int | None:
        if key not in entries:
            return None
        value = number(key)
        if not value.is_integer() or value < 0:
            raise ValueError(f"{where}: `{key}` must be a non-negative integer, got {entries[key]!r}.")
        return int(value)

    extra: dict[str, float | str] = {}
    for key, value in entries.items():
        if key in _KNOWN_KEYS:
            continue
        try:
            extra[key] = float(value)
        except ValueError:
            extra[key] = value
    try:
        return StereoCalibration(
            cam0=_parse_matrix(entries["cam0"], "cam0", where),
            cam1=_parse_matrix(entries["cam1"], "cam1", where) if "cam1" in entries else None,
            baseline_mm=number("baseline"),
            doffs=number("doffs") if "doffs" in entries else 0.0,
            width=integer("width"),
            height=integer("height"),
            ndisp=integer("ndisp"),
            extra=extra,
        )
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def disparity_to_depth(disparity, focal_px, baseline_mm, *, doffs=0.0) -> np.ndarray:
    """Convert a rectified-stereo disparity map to metric depth.

    Parameters
    ----------
    disparity : array_like of real numbers
        Disparity in pixels (any shape, typically (H, W)).
    focal_px : float
        Focal length in pixels (positive).
    baseline_mm : float
        Baseline in millimetres (positive).
    doffs : float, optional
        Principal-point offset ``cx1 - cx0`` in pixels (Middlebury ``doffs``).

    Returns
    -------
    depth : ndarray of float64, same shape as ``disparity``
        Depth in metres; NaN where the disparity is invalid, i.e. not finite
        or ``disparity + doffs <= 0``.

    Notes
    -----
    .. math:: Z\\,[\\mathrm{m}] = \\frac{f \\, B}{1000\\,(d + d_\\mathrm{offs})}

    A stored 0 is *not* treated as invalid by itself when ``doffs > 0``;
    convert 0-coded invalid disparities to NaN first (:func:`read_depth_png`
    does this).

    References
    ----------
    .. [1] D. Scharstein et al., "High-resolution stereo datasets with
       subpixel-accurate ground truth", GCPR 2014 (``calib.txt`` format).

    Examples
    --------
    >>> disparity_to_depth([[10.0, 0.0]], 1000.0, 100.0)
    array([[10., nan]])
    """
    disparity = check_real_array(disparity, "disparity")
    focal_px = check_positive_finite(focal_px, label="`focal_px`")
    baseline_mm = check_positive_finite(baseline_mm, label="`baseline_mm`")
    shifted = disparity.astype(np.float64) + _check_doffs(doffs)
    valid = np.isfinite(shifted) & (shifted > 0)
    depth = np.full(shifted.shape, np.nan)
    depth[valid] = (focal_px * baseline_mm / 1000.0) / shifted[valid]
    return depth


#: The KITTI projection matrix :func:`read_intrinsics` reads from a ``calib_cam_to_cam.txt``: the left colour
#: camera's (image_02), the one the depth-completion benchmark's images come from.
KITTI_PROJECTION = "P_rect_02"


def read_intrinsics(path, *, name: str = "path") -> tuple[float, float, float, float]:
    """Pinhole intrinsics ``(fx, fy, cx, cy)`` in pixels from a camera's calibration file.

    Parameters
    ----------
    path : str or os.PathLike
        One of (told apart by extension and content):

        * ``.npy``: a 3x3 matrix ``K`` or four numbers ``fx, fy, cx, cy`` (never unpickled);
        * ``.json``: an object with ``fx``, ``fy``, ``cx``, ``cy``, or with ``K`` / ``camera_matrix`` (3x3,
          row by row), or Open3D's ``PinholeCameraIntrinsic`` file (``intrinsic_matrix``: 9 numbers, column by
          column);
        * text: ``key: value`` lines with ``fx``, ``fy``, ``cx``, ``cy`` (YAML as ClearGrasp / RealSense tools
          write it); a KITTI ``calib_cam_to_cam.txt`` (its :data:`KITTI_PROJECTION` line); a COLMAP
          ``cameras.txt`` holding one SIMPLE_PINHOLE or PINHOLE camera; nine numbers (a 3x3 ``K``, as KITTI's
          ``cam.txt``); or four numbers.
    name : str
        Label of ``path`` in messages (``"--intrinsics"`` on the command line).

    Returns
    -------
    tuple of 4 floats
        Checked by :func:`~sparsedepth._validation.check_intrinsics`.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is not one of the above (the message names the file), is larger than 1 MiB, or holds a camera
        model other than a pinhole one.

    Notes
    -----
    COLMAP puts the centre of the top-left pixel at ``(0.5, 0.5)``; this package at ``(0, 0)`` (as
    :func:`~sparsedepth.depth_to_points` does), so a COLMAP principal point is shifted by −0.5 in both axes.  The
    other formats already use integer pixel centres (OpenCV's convention, which KITTI, Open3D and RealSense follow).
    """
    path = check_input_file(path, name=name)
    where = file_label(path, name)
    suffix = path.suffix.lower()
    if suffix == ".npy":
        try:
            values = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise ValueError(f"{where}: not a NumPy array of numbers ({exc}).") from None
        return _checked(values, where)
    text = _read_text(path, where)
    if suffix == ".json":
        return _json_intrinsics(text, where)
    for reader in (_key_value_intrinsics, _kitti_intrinsics, _colmap_intrinsics):
        values = reader(text, where)
        if values is not None:
            return _checked(values, where)
    try:
        numbers = [float(v) for v in text.split()]
    except ValueError:
        numbers = []
    if len(numbers) in (4, 9):
        return _checked(np.reshape(numbers, (3, 3)) if len(numbers) == 9 else numbers, where)
    raise ValueError(f"{where}: no camera intrinsics found: expected a 3x3 K, four numbers fx fy cx cy, 'fx: ...' "
                     "lines, a KITTI calib_cam_to_cam.txt, a COLMAP cameras.txt or a .json/.npy file.")


def _checked(values, where) -> tuple[float, float, float, float]:
    """``check_intrinsics`` with the file in its messages."""
    try:
        return check_intrinsics(np.asarray(values, dtype=float), name="intrinsics")
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {str(exc).removeprefix('`intrinsics`').lstrip(': ')}") from None


def _json_intrinsics(text, where):
    import json

    try:
        data = json.loads(text)
    except ValueError as exc:
        raise ValueError(f"{where}: not valid JSON ({exc}).") from None
    if not isinstance(data, dict):
        raise ValueError(f"{where}: expected a JSON object with fx, fy, cx, cy or a matrix K.")
    if all(key in data for key in ("fx", "fy", "cx", "cy")):
        return _checked([data[key] for key in ("fx", "fy", "cx", "cy")], where)
    for key in ("K", "camera_matrix"):
        if key in data:
            return _checked(data[key], where)
    if "intrinsic_matrix" in data:  # Open3D's PinholeCameraIntrinsic: column-major
        values = np.asarray(data["intrinsic_matrix"], dtype=float)
        return _checked(values.reshape(3, 3, order="F") if values.size == 9 else values, where)
    raise ValueError(f"{where}: the JSON object has none of fx/fy/cx/cy, K, camera_matrix, intrinsic_matrix.")


def _key_value_intrinsics(text, where):
    """``fx: ...`` lines (YAML, '#' comments), or None when ``fx`` is not among the keys."""
    values = {}
    for line in text.splitlines():
        key, sep, value = line.partition("#")[0].partition(":")
        if sep:
            values[key.strip()] = value.strip()
    if "fx" not in values:
        return None
    try:
        return [float(values[key]) for key in ("fx", "fy", "cx", "cy")]
    except (KeyError, ValueError) as exc:
        raise ValueError(f"{where}: expected fx, fy, cx, cy as 'key: number' lines ({exc}).") from None


def _kitti_intrinsics(text, where):
    """fx, fy, cx, cy of the :data:`KITTI_PROJECTION` line of a ``calib_cam_to_cam.txt``, or None without one."""
    for line in text.splitlines():
        key, sep, value = line.partition(":")
        if sep and key.strip() == KITTI_PROJECTION:
            try:
                P = np.array([float(v) for v in value.split()]).reshape(3, 4)
            except ValueError:
                raise ValueError(f"{where}: {KITTI_PROJECTION} must be 12 numbers (a 3x4 matrix).") from None
            return [P[0, 0], P[1, 1], P[0, 2], P[1, 2]]
    return None


def _colmap_intrinsics(text, where):
    """The one pinhole camera of a COLMAP ``cameras.txt`` (principal point moved to integer pixel centres), or None
    when the text is not one."""
    lines = [line.split() for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    if not lines or not all(len(parts) >= 4 and parts[1].isupper() and parts[0].isdigit() for parts in lines):
        return None
    if len(lines) != 1:
        raise ValueError(f"{where}: a COLMAP cameras.txt with {len(lines)} cameras; give the intrinsics of one.")
    model, params = lines[0][1], lines[0][4:]
    try:
        params = [float(v) for v in params]
    except ValueError:
        raise ValueError(f"{where}: the camera's parameters must be numbers.") from None
    if model == "SIMPLE_PINHOLE" and len(params) == 3:
        f, cx, cy = params
        return [f, f, cx - 0.5, cy - 0.5]
    if model == "PINHOLE" and len(params) == 4:
        fx, fy, cx, cy = params
        return [fx, fy, cx - 0.5, cy - 0.5]
    raise ValueError(f"{where}: COLMAP camera model {model} with {len(params)} parameters is not a pinhole camera; "
                     "run `colmap image_undistorter` and use the undistorted model's cameras.txt.")
