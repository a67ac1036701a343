"""Depth maps: the unit of stored values (:data:`DEPTH_SCALES`), :func:`read_depth` and :func:`read_mask`.

Conventions shared by every depth reader:

* Depth is returned as a ``float64`` array in metres (or in the unit the caller
  asks for through ``scale``), with **NaN marking invalid pixels**.  On disk,
  invalid depth is ``0`` in integer formats (PNG/PGM) and ``0``, ``inf`` or
  ``NaN`` in float formats (PFM, NPY, NPZ, HDF5); all of them become NaN.
* Integer depth images store ``depth * scale``; ``scale`` is the divisor used
  when reading (1000 for NYU and other millimetre PNGs, 256 for KITTI, 5000 for
  TUM RGB-D).  Named presets are in :data:`DEPTH_SCALES`.
* Integer arrays (PNG, PGM, TIFF, and integer ``.npy``/``.npz``/HDF5 data)
  need an explicit ``scale``: the library never guesses that integers are
  metres.  Sensor codes for "no measurement" (Kinect v1 2047, RealSense
  65535) are removed with ``invalid_values``.

:func:`read_depth` chooses the format's reader from the extension (the
table of :mod:`.formats`) and applies the scale, the calibration
(:mod:`.calibration`) and the valid range.

Imports NumPy, :mod:`sparsedepth._validation`, :mod:`.formats` and the format
modules of :mod:`sparsedepth.io` only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
import os
import warnings
from pathlib import Path
from types import MappingProxyType
from typing import Callable, Mapping

import numpy as np

from .._validation import argument_label, check_input_file, check_positive_finite, is_real
from .calibration import KinectDisparity, StereoCalibration, read_calib
from .files import MAX_PIXELS, check_extension, check_max_pixels, option_labels
from .formats import (DEPTH_EXTENSIONS, KEYED_EXTENSIONS, MASK_EXTENSIONS, extensions_of, format_of, read_grey_depth,
                      read_image, read_single_channel)
from .netpbm import check_byteorder
from .stored import as_depth, is_real_dtype

__all__ = ["DEPTH_IMAGE_EXTENSIONS", "DEPTH_SCALES", "SENSOR_PRESETS", "SensorPreset", "read_depth", "read_depth_png", "read_mask", "read_stored",
           "resolve_scale"]

#: Named divisors for integer depth images: ``depth = stored_value / scale``.
DEPTH_SCALES: Mapping[str, float] = MappingProxyType(
    {
        "nyu": 1000.0,
        "mm": 1000.0,
        "kitti": 256.0,
        "tum": 5000.0,
        "m": 1.0,
        "metres": 1.0,
        "meters": 1.0,
    }
)

@dataclass(frozen=True)
class SensorPreset:
    """How a depth sensor's files store depth: the divisor to metres, the codes for "no measurement", the range.

    Attributes
    ----------
    scale : float
        Stored value / ``scale`` = metres (:data:`DEPTH_SCALES`).
    invalid_values : tuple of float
        Stored codes that mean "no measurement" besides 0 (always invalid).
    min_depth, max_depth : float
        Depth outside ``[min_depth, max_depth]`` metres counts as missing: the sensor's documented working range,
        widened to what its files hold.
    source : str
        Where the numbers come from.
    """

    scale: float
    invalid_values: tuple
    min_depth: float
    max_depth: float
    source: str


#: ``--sensor`` presets: the depth files of common sensors and datasets.
SENSOR_PRESETS: Mapping[str, SensorPreset] = MappingProxyType({
    "realsense-d4xx": SensorPreset(
        DEPTH_SCALES["mm"], (65535.0,), 0.1, 10.0,
        "Intel RealSense D400 series: 16-bit depth in the SDK's default unit of 1 mm, 0 = no depth (65535 as "
        "written by some recorders); minimum Z about 0.1-0.16 m (D435/D415 at full resolution, less at lower), "
        "range up to about 10 m (Intel D400-series datasheet)"),
    "azure-kinect": SensorPreset(
        DEPTH_SCALES["mm"], (), 0.25, 5.46,
        "Azure Kinect DK: depth in millimetres, 0 = invalid; operating range 0.25-5.46 m over its depth modes "
        "(Azure Kinect DK hardware specification)"),
    "kinect-v1": SensorPreset(
        DEPTH_SCALES["nyu"], (), 0.4, 10.0,
        "Kinect v1 depth registered and stored in millimetres as NYU Depth V2's toolbox and 'sync' PNGs do, 0 = "
        "invalid; ranges 0.4-3 m (near mode) and 0.8-4 m (default), readings kept up to NYU's 10 m (Kinect for "
        "Windows DepthRange; NYU Depth V2). Raw Kinect disparity needs --calib kinect-nyu instead"),
    "kitti-lidar": SensorPreset(
        DEPTH_SCALES["kitti"], (), 0.0, 120.0,
        "KITTI depth PNGs (depth completion devkit): metres = value / 256, 0 = no measurement; Velodyne HDL-64E "
        "range up to about 120 m"),
    "tum": SensorPreset(
        DEPTH_SCALES["tum"], (), 0.4, 10.0,
        "TUM RGB-D benchmark: 16-bit PNG scaled by 5000 (value / 5000 = metres), 0 = no data; a Kinect v1, range "
        "as kinect-v1"),
})

#: What :func:`read_depth_png` reads: the formats whose depth is a grey image (PNG, PGM).
DEPTH_IMAGE_EXTENSIONS = extensions_of(lambda f: f.read_depth is read_grey_depth)
#: What :func:`read_depth` reads (:data:`sparsedepth.io.formats.DEPTH_EXTENSIONS`).
#: Formats whose arrays have names, chosen with ``key``.
_KEYED_EXTENSIONS = KEYED_EXTENSIONS
#: Stored values that sensors use for "no measurement" (warned about when frequent).
_SENSOR_INVALID_CODES = {2047: "Kinect v1", 65535: "16-bit sensors such as RealSense"}


def resolve_scale(scale, name: str = "scale") -> float:
    """Turn a preset name of :data:`DEPTH_SCALES` or a positive number into a float divisor.

    ``name`` is the keyword or flag that labels ``scale`` in messages.
    """
    label = argument_label(name)
    if isinstance(scale, str):
        key = scale.lower()
        if key not in DEPTH_SCALES:
            raise ValueError(
                f"{label}: unknown preset '{scale}'. Known presets: "
                + ", ".join(f"'{k}' ({v:g})" for k, v in DEPTH_SCALES.items())
                + "; or pass a positive number."
            )
        return float(DEPTH_SCALES[key])
    return check_positive_finite(scale, label=label, expected="a positive number or a preset name")


def _check_invalid_values(values, label: str) -> tuple[float, ...]:
    """The stored "no measurement" codes as a tuple of floats (one number or an iterable of finite numbers)."""
    if values is None:
        return ()
    if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
        values = (values,)
    checked = []
    for value in values:
        if not is_real(value) or not math.isfinite(value):
            raise ValueError(f"{label} must hold finite numbers (stored codes such as 2047), got {value!r}.")
        checked.append(float(value))
    return tuple(checked)


def _check_depth_bound(value, label: str) -> float | None:
    """``min_depth`` or ``max_depth`` as a float >= 0, or None."""
    if value is None:
        return None
    if not is_real(value):
        raise TypeError(f"{label} must be a number or None, got {type(value).__name__}.")
    value = float(value)
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"{label} must be a finite number >= 0, got {value!r}.")
    return value


def read_depth_png(path, scale, *, byteorder: str | None = None, max_pixels: int | None = MAX_PIXELS,
                   name: str = "path", option_names: Mapping[str, str] | None = None) -> np.ndarray:
    """Read an integer depth image (16-bit PNG or PGM) as float64 depth.

    Parameters
    ----------
    path : str or os.PathLike
        Single-channel 8- or 16-bit ``.png``, ``.pgm`` or ``.pnm`` file.
    scale : float or str
        Divisor from stored integers to the output unit:
        ``depth = stored / scale``.  1000 for millimetre PNGs (NYU), 256 for
        KITTI, 5000 for TUM RGB-D, or a preset name from :data:`DEPTH_SCALES`
        (``'nyu'``, ``'mm'``, ``'kitti'``, ``'tum'``, ``'m'``).
    byteorder, max_pixels, name, option_names
        As in :func:`read_image`.

    Returns
    -------
    depth : (H, W) ndarray of float64
        Depth in metres (for the presets), NaN where the stored value is 0.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If ``path`` is not a regular file, the extension is not supported,
        the image has several channels, or ``scale`` is not a positive
        number / known preset.

    Examples
    --------
    >>> import numpy as np, imageio.v3 as iio, tempfile, os
    >>> fname = os.path.join(tempfile.mkdtemp(), "depth.png")
    >>> iio.imwrite(fname, np.array([[0, 2500]], dtype=np.uint16))
    >>> read_depth_png(fname, "nyu")
    array([[nan, 2.5]])
    """
    label = option_labels(option_names)
    scale = resolve_scale(scale, label("scale"))
    path = check_input_file(path, name=name)
    check_extension(path, DEPTH_IMAGE_EXTENSIONS, "read depth image", name)
    stored = read_single_channel(path, byteorder, max_pixels, name, option_names)
    depth = stored.astype(np.float64) / scale
    depth[stored == 0] = np.nan
    return depth


# the numpydoc docstring is most of the length; the code is 25 lines of named steps
def read_depth(path, *, scale=None, calib=None, key: str | None = None, byteorder: str | None = None,
               invalid_values=(), min_depth=None, max_depth=None, max_pixels: int | None = MAX_PIXELS,
               name: str = "path", option_names: Mapping[str, str] | None = None) -> np.ndarray:
    """Read a depth (or disparity) map, choosing the reader from the extension.

    Parameters
    ----------
    path : str or os.PathLike
        One of ``.png``, ``.pgm``, ``.pnm`` (integer image), ``.tif`` /
        ``.tiff`` (16-bit integer or float32; a stack of full-size pages is
        refused, reduced previews are ignored), ``.pfm``, ``.npy``,
        ``.npz``, ``.h5`` / ``.hdf5``.
    scale : float or str, optional
        Divisor applied to the stored values, or a preset name from
        :data:`DEPTH_SCALES`.  **Required** whenever the stored values are
        integers, whatever the format (1000 for NYU millimetres, 256 for
        KITTI, 5000 for TUM, 1 for integers that really are metres); defaults
        to 1 for float data and for a :class:`KinectDisparity` ``calib``.
    calib : StereoCalibration or KinectDisparity or str or os.PathLike, optional
        If given, the file holds disparity (after dividing by ``scale``),
        converted to metric depth with the object's
        ``depth_from_disparity``.  A path is read with :func:`read_calib`;
        :data:`KINECT_NYU` converts raw Kinect v1 disparity.
    key : str, optional
        Array name in an ``.npz`` or dataset name in an HDF5 file (HDF5
        default ``'depth'``).
    byteorder : {None, 'big', 'little'}, optional
        Byte order of 16-bit binary Netpbm files; see :func:`read_image`.
    invalid_values : sequence of float, optional
        Stored values (before ``scale``) that mean "no measurement", e.g.
        ``[2047]`` for raw Kinect v1 frames or ``[65535]`` for sensors that
        saturate.  They become NaN like 0, inf and NaN.
    min_depth, max_depth : float, optional
        Valid range of the result (metres for the presets and calibrations):
        values outside become NaN.
    max_pixels : int or None, optional
        Largest accepted ``H * W``, checked from the header before decoding;
        default :data:`MAX_PIXELS`, None for no limit.
    name : str, optional
        Label of ``path`` in error messages (the command line passes the
        flag, e.g. ``"--depth"``).
    option_names : mapping, optional
        Labels of the keywords in messages, e.g. ``{"scale": "--depth-scale"}``;
        default the keyword names.

    Returns
    -------
    depth : (H, W) ndarray of float64
        NaN where invalid (stored 0, inf, NaN or one of ``invalid_values``;
        non-positive disparity; outside ``[min_depth, max_depth]``).

    Raises
    ------
    FileNotFoundError
        If ``path`` (or a ``calib`` path) does not exist.
    ValueError
        If ``path`` is not a regular file, the extension is not supported,
        ``scale`` is missing for integer data, ``key`` is given for a format
        without names, the declared size exceeds ``max_pixels``, an option
        is out of range, or the content is invalid (see the format-specific
        readers).
    TypeError
        If ``path``, ``calib`` or a numeric option has the wrong type.

    Warns
    -----
    UserWarning
        If more than 1 % of the pixels of integer data hold 2047 or 65535
        (the "no measurement" codes of Kinect v1 and of 16-bit sensors) and
        ``invalid_values`` is empty: they are read as depth.

    Notes
    -----
    With stored values :math:`s`, the result is
    :math:`Z = c(s / \\mathrm{scale})` where :math:`c` is the calibration's
    disparity-to-depth conversion (the identity without ``calib``), and NaN
    where :math:`s \\in \\{0, \\pm\\infty, \\mathrm{NaN}\\} \\cup`
    ``invalid_values`` or :math:`Z \\notin [\\mathrm{min\\_depth},
    \\mathrm{max\\_depth}]`.

    See Also
    --------
    read_depth_png, read_pfm, read_depth_array, read_nyu_h5, write_depth

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from sparsedepth.io import read_depth, write_depth
    >>> fname = os.path.join(tempfile.mkdtemp(), "depth.png")
    >>> write_depth(fname, np.array([[1.5, np.nan]]), scale=1000)
    >>> read_depth(fname, scale="mm")
    array([[1.5, nan]])
    """
    label = option_labels(option_names)
    path = check_input_file(path, name=name)
    ext = check_extension(path, DEPTH_EXTENSIONS, "read depth", name)
    if key is not None and ext not in _KEYED_EXTENSIONS:
        raise ValueError(f"{label('key')} only applies to .npz and HDF5 files, not '{ext}'.")
    divisor = None if scale is None else resolve_scale(scale, label("scale"))
    byteorder = check_byteorder(byteorder, label("byteorder"))
    invalid_values = _check_invalid_values(invalid_values, label("invalid_values"))
    min_depth, max_depth = _check_depth_range(min_depth, max_depth, label)
    max_pixels = check_max_pixels(max_pixels, label("max_pixels"))
    calib = _resolve_calib(calib, label, option_names)
    stored, source = _read_stored(path, ext, key, byteorder, max_pixels, name, option_names)
    _check_integer_depth(stored, source, divisor, calib, invalid_values, label)
    values = as_depth(stored, source, invalid_values)
    if divisor is not None and divisor != 1.0:
        values /= divisor
    if calib is not None:
        values = calib.depth_from_disparity(values)
    with np.errstate(invalid="ignore"):
        if min_depth is not None:
            values[values < min_depth] = np.nan
        if max_depth is not None:
            values[values > max_depth] = np.nan
    return values


def _check_depth_range(min_depth, max_depth, label: Callable[[str], str]) -> tuple[float | None, float | None]:
    """``(min_depth, max_depth)`` as floats or None, each >= 0 and in order."""
    min_depth = _check_depth_bound(min_depth, label("min_depth"))
    max_depth = _check_depth_bound(max_depth, label("max_depth"))
    if min_depth is not None and max_depth is not None and min_depth > max_depth:
        raise ValueError(
            f"{label('min_depth')} ({min_depth:g}) is larger than {label('max_depth')} ({max_depth:g})."
        )
    return min_depth, max_depth


def _resolve_calib(calib, label: Callable[[str], str], option_names):
    """``calib`` as a :class:`StereoCalibration` or :class:`KinectDisparity` (a path is read), or None."""
    if calib is None or isinstance(calib, (StereoCalibration, KinectDisparity)):
        return calib
    if isinstance(calib, (str, os.PathLike)):
        return read_calib(calib, name=str((option_names or {}).get("calib", "calib")))
    raise TypeError(
        f"{label('calib')} must be a StereoCalibration, a KinectDisparity or a path to calib.txt, "
        f"got {type(calib).__name__}."
    )


def read_stored(path, *, key=None, byteorder=None, max_pixels=MAX_PIXELS, name: str = "path",
                option_names=None) -> tuple[np.ndarray, str]:
    """The stored 2-D samples of a depth file as they are (no scale, no missing values), and their source.

    Read by the reader :mod:`.formats` lists for the extension: what :func:`read_depth` starts from, for values
    that are all values (a dense prior, whose 0 and negative values are relative depth).  ``ValueError`` for an
    unsupported extension or a non-numeric array.
    """
    path = check_input_file(path, name=name)
    ext = check_extension(path, DEPTH_EXTENSIONS, "read depth", name)
    return _read_stored(path, ext, key, byteorder, max_pixels, name, option_names)


def _read_stored(path: Path, ext: str, key, byteorder, max_pixels, name: str,
                 option_names) -> tuple[np.ndarray, str]:
    """The stored 2-D samples of a depth file, read by its format's reader, and the description of their source."""
    stored, source = format_of(ext).read_depth(path, key, byteorder, max_pixels, name, option_names)
    if not is_real_dtype(stored.dtype):
        raise ValueError(f"{source}: expected integer or float depth, got dtype {stored.dtype}.")
    return stored, source


def _check_integer_depth(stored: np.ndarray, source: str, divisor, calib, invalid_values,
                         label: Callable[[str], str]) -> None:
    """Integer samples need a scale (unless Kinect disparity); warn when sensor "no measurement" codes abound."""
    if not np.issubdtype(stored.dtype, np.integer) or isinstance(calib, KinectDisparity):
        return
    if divisor is None:
        raise ValueError(
            f"{label('scale')} is required for integer depth ({stored.dtype}) such as {source}: e.g. "
            "'nyu' (1000, millimetres), 'kitti' (256), 'tum' (5000) or 1 (integers that are metres)."
        )
    if invalid_values or not stored.size:
        return
    for code, sensor in _SENSOR_INVALID_CODES.items():
        share = float(np.count_nonzero(stored == code)) / stored.size
        if share > 0.01:
            warnings.warn(
                f"{source}: {share:.1%} of the pixels hold {code}, the 'no measurement' code of "
                f"{sensor}; they are read as depth. Pass {label('invalid_values')} {code} "
                "to mark them missing.",
                UserWarning,
                stacklevel=3,  # the caller of read_depth
            )


def read_mask(path, *, key: str | None = None, max_pixels: int | None = MAX_PIXELS,
              name: str = "path", option_names: Mapping[str, str] | None = None) -> np.ndarray:
    """Read a mask of observed pixels.

    Parameters
    ----------
    path : str or os.PathLike
        ``.npy`` / ``.npz`` (boolean, or integers / floats equal to 0 or 1),
        ``.h5`` / ``.hdf5`` (same), or any image :func:`read_image` reads
        (non-zero = observed; 1-bit PNG masks included).
    key : str, optional
        Array name in an ``.npz`` or dataset in an HDF5 file (HDF5 default
        ``'mask'``).
    max_pixels, name, option_names
        As in :func:`read_depth`.

    Returns
    -------
    mask : (H, W) ndarray of bool
        True where depth is observed.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If ``path`` is not a regular file, its format is unsupported, it does
        not hold a 2-D array, or an array holds values other than 0 and 1.
    """
    label = option_labels(option_names)
    path = check_input_file(path, name=name)
    ext = check_extension(path, MASK_EXTENSIONS, "read mask", name)
    max_pixels = check_max_pixels(max_pixels, label("max_pixels"))
    if key is not None and ext not in _KEYED_EXTENSIONS:
        raise ValueError(f"{label('key')} only applies to .npz and HDF5 files, not '{ext}'.")
    fmt = format_of(ext)
    if fmt.holds_image:
        image = read_image(path, max_pixels=max_pixels, name=name, option_names=option_names)
        return image != 0 if image.ndim == 2 else np.any(image != 0, axis=2)
    array, source = fmt.read_mask(path, key, max_pixels, name, option_names)
    if array.size == 0:
        raise ValueError(f"{source}: the mask is empty (shape {array.shape}).")
    if array.dtype != bool:
        if not np.all((array == 0) | (array == 1)):
            raise ValueError(f"{source}: a mask must be boolean or hold only 0 and 1.")
        array = array != 0
    return array
