"""Readers and writers for RGB images, depth maps and stereo calibration.

Conventions shared by every function in this module:

* Depth is returned as a ``float64`` array in metres (or in the unit the caller
  asks for through ``scale``), with **NaN marking invalid pixels**.  On disk,
  invalid depth is ``0`` in integer formats (PNG/PGM) and ``0``, ``inf`` or
  ``NaN`` in float formats (PFM, NPY, NPZ, HDF5); all of them become NaN.
* Integer depth images store ``depth * scale``; ``scale`` is the divisor used
  when reading (1000 for NYU and other millimetre PNGs, 256 for KITTI, 5000 for
  TUM RGB-D).  Named presets are in :data:`DEPTH_SCALES`.
* Missing files raise :class:`FileNotFoundError`; unreadable or inconsistent
  content and unknown formats raise :class:`ValueError` naming the file and
  what was expected.
* Every writer is atomic: the data go to a temporary file in the destination
  folder, which then replaces the destination with :func:`os.replace`.  If
  anything fails, the temporary file is removed and the destination is left
  as it was.
"""

from __future__ import annotations

import contextlib
import math
import numbers
import operator
import os
import re
import secrets
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Callable, Iterator, Mapping

import h5py
import imageio.v3 as iio
import numpy as np

__all__ = [
    "DEPTH_SCALES",
    "NYUDepthV2Labeled",
    "StereoCalibration",
    "disparity_to_depth",
    "read_calib",
    "read_depth",
    "read_depth_array",
    "read_depth_png",
    "read_image",
    "read_nyu_h5",
    "read_pfm",
    "write_depth",
    "write_pfm",
]

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

_IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".ppm", ".pgm", ".pnm", ".bmp", ".tif", ".tiff")
_NETPBM_EXTENSIONS = (".ppm", ".pgm", ".pnm")
_DEPTH_IMAGE_EXTENSIONS = (".png", ".pgm", ".pnm")
_ARRAY_EXTENSIONS = (".npy", ".npz")
_HDF5_EXTENSIONS = (".h5", ".hdf5")
_READ_DEPTH_EXTENSIONS = _DEPTH_IMAGE_EXTENSIONS + (".pfm",) + _ARRAY_EXTENSIONS + _HDF5_EXTENSIONS
_WRITE_DEPTH_EXTENSIONS = (".png", ".pfm") + _ARRAY_EXTENSIONS + _HDF5_EXTENSIONS
_UINT16_MAX = np.iinfo(np.uint16).max
_FLOAT32_MAX = float(np.finfo(np.float32).max)


# --------------------------------------------------------------------------------------
# small shared checks
# --------------------------------------------------------------------------------------
def _check_file(path, name: str = "path") -> Path:
    """Return ``path`` as a :class:`Path` after checking that it is an existing file."""
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"`{name}` must be a str or os.PathLike, got {type(path).__name__}.")
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"`{name}`: no such file: '{path}'.")
    if path.is_dir():
        raise IsADirectoryError(f"`{name}`: '{path}' is a directory, expected a file.")
    return path


def _suffix(path) -> str:
    return Path(path).suffix.lower()


def _check_extension(path: Path, allowed: tuple[str, ...], what: str) -> str:
    ext = _suffix(path)
    if ext not in allowed:
        raise ValueError(
            f"cannot {what} '{path}': unsupported extension '{ext or '(none)'}'. "
            f"Supported extensions: {', '.join(allowed)}."
        )
    return ext


def _resolve_scale(scale, name: str = "scale") -> float:
    """Turn a preset name or a positive number into a float divisor."""
    if isinstance(scale, str):
        key = scale.lower()
        if key not in DEPTH_SCALES:
            raise ValueError(
                f"`{name}`: unknown preset '{scale}'. Known presets: "
                + ", ".join(f"'{k}' ({v:g})" for k, v in DEPTH_SCALES.items())
                + "; or pass a positive number."
            )
        return float(DEPTH_SCALES[key])
    if isinstance(scale, bool) or not isinstance(scale, numbers.Real):
        raise TypeError(
            f"`{name}` must be a positive number or a preset name, got {type(scale).__name__}."
        )
    value = float(scale)
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"`{name}` must be a finite positive number, got {scale!r}.")
    return value


def _check_positive_finite(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"`{name}` must be a real number, got {type(value).__name__}.")
    value = float(value)
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"`{name}` must be a finite positive number, got {value!r}.")
    return value


def _check_real_array(array, name: str) -> np.ndarray:
    array = np.asarray(array)
    if array.dtype == bool or not (
        np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)
    ):
        raise TypeError(
            f"`{name}` must hold real numbers (integer or float), got dtype {array.dtype}."
        )
    return array


def _as_depth(array, source: str) -> np.ndarray:
    """Convert a stored 2-D depth array to float64 with NaN for 0/inf/NaN.

    Raises ValueError for a wrong shape, a non-numeric dtype or negative values.
    """
    array = np.asarray(array)
    if array.ndim != 2:
        raise ValueError(f"{source}: expected a 2-D (H, W) depth map, got shape {array.shape}.")
    if array.dtype == bool or not (
        np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)
    ):
        raise ValueError(f"{source}: expected integer or float depth, got dtype {array.dtype}.")
    depth = array.astype(np.float64)  # always a copy
    invalid = ~np.isfinite(depth) | (depth == 0)
    depth[invalid] = np.nan
    if np.any(depth < 0):  # NaN compares False
        raise ValueError(
            f"{source}: contains negative depth values (min {np.nanmin(depth):g}); "
            "depth must be positive, with 0, inf or NaN for invalid pixels."
        )
    return depth


# --------------------------------------------------------------------------------------
# atomic writes
# --------------------------------------------------------------------------------------
def _create_temporary(path: Path, kind: str = "tmp") -> Path:
    """Create a new empty file ``.<name>.<random>.<kind><suffix>`` next to ``path``; return its path.

    The file is created with ``O_EXCL`` (nothing existing is ever clobbered)
    and mode ``0o666`` so that the umask applies as for :func:`open`.  The
    name keeps the destination's extension (some encoders choose the format
    from it).  Raises the :class:`OSError` of the failed creation (missing
    or read-only folder, full disk, ...).
    """
    for _ in range(100):
        tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.{kind}{path.suffix}"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:  # pragma: no cover - astronomically unlikely
            continue
        os.close(fd)
        return tmp
    raise FileExistsError(f"could not create a temporary file in '{path.parent}'.")  # pragma: no cover


@contextlib.contextmanager
def _atomic_target(path) -> Iterator[Path]:
    """Yield a fresh temporary path next to ``path``; move it onto ``path`` on success.

    The temporary name keeps the destination's extension (some encoders choose
    the format from it).  On any exception the temporary file is removed and
    the exception propagates; ``path`` itself is untouched.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"`path` must be a str or os.PathLike, got {type(path).__name__}.")
    path = Path(path)
    if not path.parent.is_dir():
        raise FileNotFoundError(f"`path`: directory '{path.parent}' does not exist.")
    tmp = _create_temporary(path)
    try:
        yield tmp
        with contextlib.suppress(OSError):  # durability is best effort (e.g. Windows)
            fd = os.open(tmp, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


# --------------------------------------------------------------------------------------
# images
# --------------------------------------------------------------------------------------
_WHITESPACE = b" \t\r\n\v\f"


def _netpbm_tokens(data: bytes, start: int, count: int, path: Path) -> tuple[list[bytes], int]:
    """Read ``count`` header tokens (skipping whitespace and ``#`` comments)."""
    tokens = []
    pos = start
    n = len(data)
    while len(tokens) < count:
        while pos < n and (data[pos] in _WHITESPACE or data[pos] == ord("#")):
            if data[pos] == ord("#"):
                newline = data.find(b"\n", pos)
                pos = n if newline < 0 else newline + 1
            else:
                pos += 1
        begin = pos
        while pos < n and data[pos] not in _WHITESPACE and data[pos] != ord("#"):
            pos += 1
        if begin == pos:
            raise ValueError(f"'{path}': truncated Netpbm header.")
        tokens.append(data[begin:pos])
    return tokens, pos


def _read_netpbm(path: Path, byteorder: str) -> np.ndarray:
    """Decode a P2/P3 (ASCII) or P5/P6 (binary) Netpbm grey or RGB image."""
    data = path.read_bytes()
    magic = data[:2]
    if magic not in (b"P2", b"P3", b"P5", b"P6"):
        raise ValueError(
            f"'{path}': not a supported Netpbm image (magic {magic!r}); "
            "expected P2/P5 (grey) or P3/P6 (RGB)."
        )
    tokens, pos = _netpbm_tokens(data, 2, 3, path)
    try:
        width, height, maxval = (int(t) for t in tokens)
    except ValueError:
        raise ValueError(f"'{path}': malformed Netpbm header {tokens!r}.") from None
    if width <= 0 or height <= 0 or not 0 < maxval <= _UINT16_MAX:
        raise ValueError(
            f"'{path}': invalid Netpbm header (width {width}, height {height}, maxval {maxval})."
        )
    channels = 3 if magic in (b"P3", b"P6") else 1
    shape = (height, width, channels) if channels == 3 else (height, width)
    count = width * height * channels
    out_dtype = np.uint8 if maxval < 256 else np.uint16
    if magic in (b"P5", b"P6"):
        if pos >= len(data) or data[pos] not in _WHITESPACE:
            raise ValueError(f"'{path}': malformed Netpbm header (no whitespace before data).")
        pos += 1  # exactly one whitespace character separates header and raster
        if out_dtype == np.uint8:
            dtype = np.dtype(np.uint8)
        else:
            dtype = np.dtype(">u2" if byteorder == "big" else "<u2")
        expected = count * dtype.itemsize
        available = len(data) - pos
        if available != expected:
            raise ValueError(
                f"'{path}': Netpbm raster has {available} bytes, expected {expected} "
                f"for {width}x{height}x{channels} samples of {dtype.itemsize} byte(s) "
                "(truncated file, or a multi-image file, which is not supported)."
            )
        values = np.frombuffer(data, dtype=dtype, count=count, offset=pos)
        return values.astype(out_dtype).reshape(shape)
    try:
        values = np.array(data[pos:].split()).astype(np.int64)
    except ValueError:
        raise ValueError(f"'{path}': non-integer sample in ASCII Netpbm raster.") from None
    if values.size != count:
        raise ValueError(f"'{path}': ASCII Netpbm raster has {values.size} samples, expected {count}.")
    if values.size and (values.min() < 0 or values.max() > maxval):
        raise ValueError(f"'{path}': ASCII Netpbm samples outside 0..{maxval}.")
    return values.astype(out_dtype).reshape(shape)


def _normalise_image(image: np.ndarray, path: Path) -> np.ndarray:
    if image.dtype not in (np.uint8, np.uint16):
        raise ValueError(
            f"'{path}' decodes to dtype {image.dtype}; only 8- and 16-bit images are supported."
        )
    if image.ndim == 3 and image.shape[2] in (1, 2):  # grey (+ alpha)
        image = image[:, :, 0]
    elif image.ndim == 3 and image.shape[2] == 4:  # RGBA
        image = image[:, :, :3]
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
        raise ValueError(
            f"'{path}' decodes to shape {image.shape}; expected a single (H, W) grey "
            "or (H, W, 3) colour image."
        )
    return np.ascontiguousarray(image)


def read_image(path, *, byteorder: str = "big") -> np.ndarray:
    """Read a grey or colour image as stored (8 or 16 bit).

    Parameters
    ----------
    path : str or os.PathLike
        Image file: PNG, JPEG, PPM/PGM/PNM (ASCII or binary), BMP or TIFF.
    byteorder : {'big', 'little'}, optional
        Byte order of 16-bit binary Netpbm rasters.  The Netpbm standard is
        ``'big'``; some datasets (e.g. the NYU Depth V2 raw ``.pgm`` Kinect
        frames) store little-endian samples despite the header.  Ignored for
        other formats.

    Returns
    -------
    image : (H, W) or (H, W, 3) ndarray of uint8 or uint16
        The decoded samples, unscaled.  An alpha channel is dropped.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the extension is not supported, the file cannot be decoded, or it
        decodes to something other than an 8/16-bit grey or RGB image.

    Examples
    --------
    >>> import numpy as np, imageio.v3 as iio, tempfile, os
    >>> fname = os.path.join(tempfile.mkdtemp(), "grey.png")
    >>> iio.imwrite(fname, np.array([[0, 1000]], dtype=np.uint16))
    >>> read_image(fname)
    array([[   0, 1000]], dtype=uint16)
    """
    path = _check_file(path)
    if byteorder not in ("big", "little"):
        raise ValueError(f"`byteorder` must be 'big' or 'little', got {byteorder!r}.")
    ext = _check_extension(path, _IMAGE_EXTENSIONS, "read image")
    if ext in _NETPBM_EXTENSIONS:
        image = _read_netpbm(path, byteorder)
    else:
        try:
            image = iio.imread(path, plugin="pillow")
        except (OSError, ValueError, SyntaxError) as exc:  # PIL raises SyntaxError on some junk
            raise ValueError(f"could not decode image '{path}': {exc}") from exc
        image = np.asarray(image)
    return _normalise_image(image, path)


def read_depth_png(path, scale) -> np.ndarray:
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

    Returns
    -------
    depth : (H, W) ndarray of float64
        Depth in metres (for the presets), NaN where the stored value is 0.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the extension is not supported, the image has several channels, or
        ``scale`` is not a positive number / known preset.

    Examples
    --------
    >>> import numpy as np, imageio.v3 as iio, tempfile, os
    >>> fname = os.path.join(tempfile.mkdtemp(), "depth.png")
    >>> iio.imwrite(fname, np.array([[0, 2500]], dtype=np.uint16))
    >>> read_depth_png(fname, "nyu")
    array([[nan, 2.5]])
    """
    scale = _resolve_scale(scale)
    path = _check_file(path)
    _check_extension(path, _DEPTH_IMAGE_EXTENSIONS, "read depth image")
    stored = read_image(path)
    if stored.ndim != 2:
        raise ValueError(
            f"'{path}' has shape {stored.shape}; a depth image must be single-channel "
            "(8- or 16-bit grey)."
        )
    depth = stored.astype(np.float64) / scale
    depth[stored == 0] = np.nan
    return depth


# --------------------------------------------------------------------------------------
# PFM
# --------------------------------------------------------------------------------------
_PFM_HEADER = re.compile(rb"\A(PF|Pf)\s+(\d+)\s+(\d+)\s+(\S+)\s")


def read_pfm(path) -> np.ndarray:
    """Read a Portable Float Map (PFM) file.

    Parameters
    ----------
    path : str or os.PathLike
        ``.pfm`` file: header ``Pf`` (grey) or ``PF`` (colour), ``width height``
        and a scale whose sign gives the byte order (negative = little endian),
        followed by float32 rows stored bottom-to-top.

    Returns
    -------
    array : (H, W) or (H, W, 3) ndarray of float32
        The stored values with the first row at the top of the image.  Values
        are returned unchanged (``inf`` typically marks unknown disparity).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the header is malformed, the scale is zero or not finite, or the
        pixel data are shorter or longer than the header announces.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> fname = os.path.join(tempfile.mkdtemp(), "disp.pfm")
    >>> write_pfm(fname, np.array([[1.0, 2.0], [3.0, np.inf]]))
    >>> read_pfm(fname)
    array([[ 1.,  2.],
           [ 3., inf]], dtype=float32)
    """
    path = _check_file(path)
    data = path.read_bytes()
    match = _PFM_HEADER.match(data[:256])
    if match is None:
        raise ValueError(
            f"'{path}': not a PFM file (expected a header 'Pf' or 'PF', width, height, scale)."
        )
    channels = 3 if match.group(1) == b"PF" else 1
    width, height = int(match.group(2)), int(match.group(3))
    try:
        scale = float(match.group(4))
    except ValueError:
        raise ValueError(f"'{path}': PFM scale {match.group(4)!r} is not a number.") from None
    if width <= 0 or height <= 0:
        raise ValueError(f"'{path}': PFM dimensions must be positive, got {width}x{height}.")
    if not math.isfinite(scale) or scale == 0:
        raise ValueError(
            f"'{path}': PFM scale must be a finite non-zero number (its sign gives the "
            f"byte order), got {scale!r}."
        )
    dtype = np.dtype("<f4" if scale < 0 else ">f4")
    offset = match.end()
    count = width * height * channels
    expected = count * dtype.itemsize
    if len(data) - offset != expected:
        raise ValueError(
            f"'{path}': PFM pixel data has {len(data) - offset} bytes, expected {expected} "
            f"for {width}x{height}x{channels} float32 values."
        )
    values = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
    shape = (height, width, 3) if channels == 3 else (height, width)
    return np.ascontiguousarray(values.reshape(shape)[::-1], dtype=np.float32)


def _write_pfm_file(path: Path, values: np.ndarray, byteorder: str) -> None:
    colour = values.ndim == 3
    height, width = values.shape[:2]
    sign = "-1" if byteorder == "little" else "1"
    header = f"{'PF' if colour else 'Pf'}\n{width} {height}\n{sign}\n".encode("ascii")
    dtype = "<f4" if byteorder == "little" else ">f4"
    with open(path, "wb") as fh:
        fh.write(header)
        fh.write(np.ascontiguousarray(values[::-1], dtype=dtype).tobytes())


def _check_pfm_values(array, name: str) -> np.ndarray:
    array = _check_real_array(array, name)
    if not (array.ndim == 2 or (array.ndim == 3 and array.shape[2] == 3)):
        raise ValueError(
            f"`{name}` must have shape (H, W) or (H, W, 3) for PFM, got {array.shape}."
        )
    if array.size == 0:
        raise ValueError(f"`{name}` is empty (shape {array.shape}).")
    values = array.astype(np.float64)
    finite = values[np.isfinite(values)]
    if finite.size and np.abs(finite).max() > _FLOAT32_MAX:
        raise ValueError(
            f"`{name}` has finite values beyond the float32 range (max |value| "
            f"{np.abs(finite).max():g}); PFM stores float32."
        )
    return values


def write_pfm(path, array, *, byteorder: str = "little") -> None:
    """Write a grey or colour array as a PFM file (atomically).

    Parameters
    ----------
    path : str or os.PathLike
        Destination file; its folder must exist.
    array : (H, W) or (H, W, 3) array_like of real numbers
        Values to store, converted to float32.  Non-finite values are kept.
    byteorder : {'little', 'big'}, optional
        Byte order of the stored floats; written as the sign of the header
        scale (``-1`` little endian, ``1`` big endian).

    Raises
    ------
    FileNotFoundError
        If the destination folder does not exist.
    ValueError
        If ``array`` has the wrong shape, is empty or has finite values that do
        not fit in float32, or ``byteorder`` is unknown.
    TypeError
        If ``array`` is not real-valued.

    Notes
    -----
    Rows are written bottom-to-top, as the format requires, so that
    ``read_pfm(path)`` returns ``array`` (as float32).
    """
    if byteorder not in ("big", "little"):
        raise ValueError(f"`byteorder` must be 'little' or 'big', got {byteorder!r}.")
    values = _check_pfm_values(array, "array")
    with _atomic_target(path) as tmp:
        _write_pfm_file(tmp, values, byteorder)


# --------------------------------------------------------------------------------------
# stereo calibration
# --------------------------------------------------------------------------------------
def _readonly(array: np.ndarray) -> np.ndarray:
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
        object.__setattr__(self, "baseline_mm", _check_positive_finite(self.baseline_mm, "baseline_mm"))
        if isinstance(self.doffs, bool) or not isinstance(self.doffs, numbers.Real) or not math.isfinite(self.doffs):
            raise ValueError(f"`doffs` must be a finite number, got {self.doffs!r}.")
        object.__setattr__(self, "doffs", float(self.doffs))
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


def _parse_matrix(text: str, key: str, path: Path) -> np.ndarray:
    body = text.strip()
    if not (body.startswith("[") and body.endswith("]")):
        raise ValueError(f"'{path}': `{key}` must look like [f 0 cx; 0 f cy; 0 0 1], got {text!r}.")
    try:
        rows = [[float(v) for v in row.split()] for row in body[1:-1].split(";")]
    except ValueError:
        raise ValueError(f"'{path}': `{key}` has a non-numeric entry: {text!r}.") from None
    if len(rows) != 3 or any(len(row) != 3 for row in rows):
        raise ValueError(f"'{path}': `{key}` must be a 3x3 matrix, got {text!r}.")
    return np.array(rows, dtype=np.float64)


def read_calib(path) -> StereoCalibration:
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

    Returns
    -------
    StereoCalibration

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If a line is not ``key=value``, a value does not parse, a key is
        repeated or a required key is missing.
    """
    path = _check_file(path)
    try:
        text = path.read_text(encoding="ascii")
    except UnicodeDecodeError:
        raise ValueError(f"'{path}': calibration file is not ASCII text.") from None
    entries: dict[str, str] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line:
            continue
        key, sep, value = line.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"'{path}', line {number}: expected 'key=value', got {line!r}.")
        if key in entries:
            raise ValueError(f"'{path}', line {number}: `{key}` is given twice.")
        entries[key] = value.strip()
    for required in ("cam0", "baseline"):
        if required not in entries:
            raise ValueError(f"'{path}': required entry `{required}` is missing.")

    def number(key: str) -> float:
        try:
            return float(entries[key])
        except ValueError:
            raise ValueError(f"'{path}': `{key}` is not a number: {entries[key]!r}.") from None

    def integer(key: str) -> int | None:
        if key not in entries:
            return None
        value = number(key)
        if not value.is_integer() or value < 0:
            raise ValueError(f"'{path}': `{key}` must be a non-negative integer, got {entries[key]!r}.")
        return int(value)

    extra: dict[str, float | str] = {}
    for key, value in entries.items():
        if key in ("cam0", "cam1", "doffs", "baseline", "width", "height", "ndisp"):
            continue
        try:
            extra[key] = float(value)
        except ValueError:
            extra[key] = value
    try:
        return StereoCalibration(
            cam0=_parse_matrix(entries["cam0"], "cam0", path),
            cam1=_parse_matrix(entries["cam1"], "cam1", path) if "cam1" in entries else None,
            baseline_mm=number("baseline"),
            doffs=number("doffs") if "doffs" in entries else 0.0,
            width=integer("width"),
            height=integer("height"),
            ndisp=integer("ndisp"),
            extra=extra,
        )
    except (TypeError, ValueError) as exc:
        raise ValueError(f"'{path}': {exc}") from None


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
    disparity = _check_real_array(disparity, "disparity")
    focal_px = _check_positive_finite(focal_px, "focal_px")
    baseline_mm = _check_positive_finite(baseline_mm, "baseline_mm")
    if isinstance(doffs, bool) or not isinstance(doffs, numbers.Real) or not math.isfinite(doffs):
        raise ValueError(f"`doffs` must be a finite number, got {doffs!r}.")
    shifted = disparity.astype(np.float64) + float(doffs)
    valid = np.isfinite(shifted) & (shifted > 0)
    depth = np.full(shifted.shape, np.nan)
    depth[valid] = (focal_px * baseline_mm / 1000.0) / shifted[valid]
    return depth


# --------------------------------------------------------------------------------------
# NPY / NPZ / HDF5
# --------------------------------------------------------------------------------------
def read_depth_array(path, *, key: str | None = None) -> np.ndarray:
    """Read a depth map stored with NumPy (``.npy`` or ``.npz``).

    Parameters
    ----------
    path : str or os.PathLike
        ``.npy`` file holding one (H, W) array, or ``.npz`` archive.
    key : str, optional
        Array name inside an ``.npz``.  If omitted, the archive's only array
        is used, or else the one called ``'depth'``.

    Returns
    -------
    depth : (H, W) ndarray of float64
        Stored values (no unit conversion), with NaN where they are 0, inf or
        NaN.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file cannot be loaded (pickled objects are refused), ``key`` is
        missing or ambiguous, or the array is not a non-negative 2-D real array.
    """
    path = _check_file(path)
    ext = _check_extension(path, _ARRAY_EXTENSIONS, "read depth array")
    if ext == ".npy" and key is not None:
        raise ValueError("`key` only applies to .npz archives; omit it for a .npy file.")
    try:
        loaded = np.load(path, allow_pickle=False)
    except Exception as exc:  # corrupt archive, pickled content, ...
        raise ValueError(f"could not load '{path}': {exc}") from exc
    if ext == ".npy":
        return _as_depth(loaded, f"'{path}'")
    with loaded:
        names = list(loaded.files)
        if key is None:
            if len(names) == 1:
                key = names[0]
            elif "depth" in names:
                key = "depth"
            else:
                raise ValueError(
                    f"'{path}' holds several arrays {names}; choose one with `key=`."
                )
        elif key not in names:
            raise ValueError(f"`key`: '{key}' is not in '{path}'; available arrays: {names}.")
        try:
            array = loaded[key]
        except Exception as exc:
            raise ValueError(f"could not load array '{key}' from '{path}': {exc}") from exc
    return _as_depth(array, f"'{path}' array '{key}'")


def _open_hdf5(path: Path) -> h5py.File:
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        raise ValueError(
            f"'{path}' is not a readable HDF5 file ({exc}). MATLAB .mat files must be "
            "version 7.3 (HDF5); older ones need scipy.io.loadmat."
        ) from exc


def _hdf5_dataset(handle: h5py.File, key: str, path: Path) -> h5py.Dataset:
    item = handle.get(key)
    if not isinstance(item, h5py.Dataset):
        available = sorted(k for k in handle.keys() if isinstance(handle[k], h5py.Dataset))
        raise ValueError(f"'{path}' has no dataset '{key}'; available datasets: {available}.")
    return item


def read_nyu_h5(path) -> tuple[np.ndarray, np.ndarray]:
    """Read one frame of the preprocessed NYU Depth V2 HDF5 layout.

    This is the one-file-per-frame layout used by most depth-completion code
    (``nyudepthv2/{train,val}/<scene>/<frame>.h5``): dataset ``rgb`` of shape
    (3, H, W) uint8 and dataset ``depth`` of shape (H, W) float32 in metres.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.h5`` file.

    Returns
    -------
    image : (H, W, 3) ndarray of uint8
    depth : (H, W) ndarray of float64
        Metres, NaN where the stored depth is 0 or not finite.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is not HDF5, lacks ``rgb`` or ``depth``, or their shapes or
        dtypes do not match the layout above.
    """
    path = _check_file(path)
    with _open_hdf5(path) as handle:
        rgb = _hdf5_dataset(handle, "rgb", path)
        dset = _hdf5_dataset(handle, "depth", path)
        if rgb.ndim != 3 or rgb.shape[0] != 3 or rgb.dtype != np.uint8:
            raise ValueError(
                f"'{path}': dataset 'rgb' must be (3, H, W) uint8, got {rgb.shape} {rgb.dtype}."
            )
        if dset.shape != rgb.shape[1:]:
            raise ValueError(
                f"'{path}': dataset 'depth' has shape {dset.shape}, expected {rgb.shape[1:]} "
                "to match 'rgb'."
            )
        image = np.ascontiguousarray(np.transpose(rgb[()], (1, 2, 0)))
        depth = _as_depth(dset[()], f"'{path}' dataset 'depth'")
    return image, depth


def _read_hdf5_depth(path: Path, key: str | None) -> np.ndarray:
    key = "depth" if key is None else key
    with _open_hdf5(path) as handle:
        data = _hdf5_dataset(handle, key, path)[()]
    return _as_depth(data, f"'{path}' dataset '{key}'")


class NYUDepthV2Labeled:
    """Lazy reader for the NYU Depth V2 labeled set ``nyu_depth_v2_labeled.mat``.

    The file is MATLAB v7.3, i.e. HDF5.  MATLAB's column-major (H, W, 3, N)
    and (H, W, N) arrays appear in HDF5 with reversed axes, so h5py sees
    ``images`` as (N, 3, W, H) uint8, ``depths`` (inpainted, metres) and
    ``rawDepths`` (raw Kinect, metres, 0 = missing) as (N, W, H) float32.
    Only the requested frame is read from disk.

    Parameters
    ----------
    path : str or os.PathLike
        Path of ``nyu_depth_v2_labeled.mat`` (or any HDF5 file with the same
        layout).  ``rawDepths`` is optional.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is not HDF5 or the datasets are missing or inconsistent.

    Examples
    --------
    >>> with NYUDepthV2Labeled("nyu_depth_v2_labeled.mat") as nyu:  # doctest: +SKIP
    ...     image, depth, raw = nyu[0]
    ...     len(nyu)
    1449
    """

    def __init__(self, path):
        self.path = _check_file(path)
        self._file = _open_hdf5(self.path)
        try:
            self._images = _hdf5_dataset(self._file, "images", self.path)
            self._depths = _hdf5_dataset(self._file, "depths", self.path)
            self._raw = self._file.get("rawDepths")
            images, depths = self._images, self._depths
            if images.ndim != 4 or images.shape[1] != 3 or images.dtype != np.uint8:
                raise ValueError(
                    f"'{self.path}': dataset 'images' must be (N, 3, W, H) uint8, "
                    f"got {images.shape} {images.dtype}."
                )
            expected = (images.shape[0],) + images.shape[2:]
            if depths.shape != expected:
                raise ValueError(
                    f"'{self.path}': dataset 'depths' has shape {depths.shape}, expected {expected}."
                )
            if self._raw is not None and self._raw.shape != expected:
                raise ValueError(
                    f"'{self.path}': dataset 'rawDepths' has shape {self._raw.shape}, "
                    f"expected {expected}."
                )
        except BaseException:
            self._file.close()
            raise

    def __len__(self) -> int:
        return int(self._images.shape[0])

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of every frame."""
        return (int(self._images.shape[3]), int(self._images.shape[2]))

    @property
    def has_raw(self) -> bool:
        """Whether the file has ``rawDepths``."""
        return self._raw is not None

    def _index(self, index) -> int:
        try:
            index = operator.index(index)
        except TypeError:
            raise TypeError(
                f"frame index must be an integer, got {type(index).__name__}."
            ) from None
        n = len(self)
        if not -n <= index < n:
            raise IndexError(f"frame index {index} out of range for {n} frames.")
        return index % n

    def __getitem__(self, index) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Read frame ``index``.

        Returns
        -------
        image : (H, W, 3) ndarray of uint8
        depth : (H, W) ndarray of float64
            Inpainted depth in metres (NaN where 0).
        raw_depth : (H, W) ndarray of float64 or None
            Raw Kinect depth in metres, NaN where missing; None if the file
            has no ``rawDepths``.
        """
        if self._file.id is None or not self._file.id.valid:
            raise ValueError(f"'{self.path}' has been closed.")
        i = self._index(index)
        image = np.ascontiguousarray(self._images[i].transpose(2, 1, 0))
        depth = _as_depth(self._depths[i].T, f"'{self.path}' depths[{i}]")
        raw = None
        if self._raw is not None:
            raw = _as_depth(self._raw[i].T, f"'{self.path}' rawDepths[{i}]")
        return image, depth, raw

    def __iter__(self):
        for i in range(len(self)):
            yield self[i]

    def close(self) -> None:
        """Close the underlying HDF5 file."""
        self._file.close()

    def __enter__(self) -> "NYUDepthV2Labeled":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        height, width = self.shape
        return (
            f"NYUDepthV2Labeled('{self.path}', frames={len(self)}, shape=({height}, {width}), "
            f"raw={self.has_raw})"
        )


# --------------------------------------------------------------------------------------
# dispatchers
# --------------------------------------------------------------------------------------
def read_depth(path, *, scale=None, calib=None, key: str | None = None) -> np.ndarray:
    """Read a depth (or disparity) map, choosing the reader from the extension.

    Parameters
    ----------
    path : str or os.PathLike
        One of ``.png``, ``.pgm``, ``.pnm`` (integer image), ``.pfm``, ``.npy``,
        ``.npz``, ``.h5`` / ``.hdf5``.
    scale : float or str, optional
        Divisor applied to the stored values, or a preset name from
        :data:`DEPTH_SCALES`.  **Required** for integer images (1000 for NYU,
        256 for KITTI, 5000 for TUM); defaults to 1 for float formats.
    calib : StereoCalibration or str or os.PathLike, optional
        If given, the file holds disparity in pixels (after dividing by
        ``scale``), converted to metric depth with
        :meth:`StereoCalibration.depth_from_disparity`.  A path is read with
        :func:`read_calib`.
    key : str, optional
        Array name in an ``.npz`` or dataset name in an HDF5 file (HDF5
        default ``'depth'``).

    Returns
    -------
    depth : (H, W) ndarray of float64
        NaN where invalid (stored 0, inf or NaN; non-positive disparity).

    Raises
    ------
    FileNotFoundError
        If ``path`` (or a ``calib`` path) does not exist.
    ValueError
        If the extension is not supported, ``scale`` is missing for an integer
        image, ``key`` is given for a format without names, or the content is
        invalid (see the format-specific readers).

    See Also
    --------
    read_depth_png, read_pfm, read_depth_array, read_nyu_h5, write_depth

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> fname = os.path.join(tempfile.mkdtemp(), "depth.png")
    >>> write_depth(fname, np.array([[1.5, np.nan]]), scale=1000)
    >>> read_depth(fname, scale="mm")
    array([[1.5, nan]])
    """
    path = _check_file(path)
    ext = _check_extension(path, _READ_DEPTH_EXTENSIONS, "read depth")
    if key is not None and ext not in (".npz",) + _HDF5_EXTENSIONS:
        raise ValueError(f"`key` only applies to .npz and HDF5 files, not '{ext}'.")
    if calib is not None and not isinstance(calib, StereoCalibration):
        if isinstance(calib, (str, os.PathLike)):
            calib = read_calib(calib)
        else:
            raise TypeError(
                f"`calib` must be a StereoCalibration or a path to calib.txt, got {type(calib).__name__}."
            )
    if ext in _DEPTH_IMAGE_EXTENSIONS:
        if scale is None:
            raise ValueError(
                f"`scale` is required for integer depth images such as '{path.name}': e.g. "
                "scale='nyu' (1000, millimetres), 'kitti' (256), 'tum' (5000) or 1 (stored metres)."
            )
        values = read_depth_png(path, scale)
    else:
        divisor = 1.0 if scale is None else _resolve_scale(scale)
        if ext == ".pfm":
            stored = read_pfm(path)
            if stored.ndim != 2:
                raise ValueError(f"'{path}' is a colour PFM (shape {stored.shape}); depth must be grey ('Pf').")
            values = _as_depth(stored, f"'{path}'")
        elif ext in _ARRAY_EXTENSIONS:
            values = read_depth_array(path, key=key)
        else:
            values = _read_hdf5_depth(path, key)
        if divisor != 1.0:
            values /= divisor
    if calib is not None:
        return calib.depth_from_disparity(values)
    return values


def _write_png_file(path: Path, stored: np.ndarray) -> None:
    iio.imwrite(path, stored, plugin="pillow", extension=".png")


def _write_npy_file(path: Path, depth: np.ndarray) -> None:
    with open(path, "wb") as fh:
        np.save(fh, depth)


def _write_npz_file(path: Path, depth: np.ndarray) -> None:
    with open(path, "wb") as fh:
        np.savez_compressed(fh, depth=depth)


def _write_hdf5_file(path: Path, depth: np.ndarray) -> None:
    with h5py.File(path, "w") as handle:
        handle.create_dataset("depth", data=depth, compression="gzip")


def _quantise_png(depth: np.ndarray, scale: float) -> np.ndarray:
    valid = ~np.isnan(depth)
    stored = np.zeros(depth.shape, dtype=np.uint16)
    if not np.any(valid):
        return stored
    values = np.rint(depth[valid] * scale)
    too_large = values > _UINT16_MAX
    if np.any(too_large):
        raise ValueError(
            f"`depth` up to {depth[valid].max():g} overflows 16-bit PNG at scale {scale:g} "
            f"(largest storable value {_UINT16_MAX / scale:g}); use a smaller `scale` or a "
            "float format (.npy, .npz, .h5, .pfm)."
        )
    rounds_to_zero = values == 0
    if np.any(rounds_to_zero):
        raise ValueError(
            f"`depth` has {int(rounds_to_zero.sum())} positive value(s) (min "
            f"{depth[valid].min():g}) that round to 0 at scale {scale:g} and would be read "
            "back as invalid; use a larger `scale` or a float format."
        )
    stored[valid] = values.astype(np.uint16)
    return stored


def write_depth(path, depth, *, scale=1000.0) -> None:
    """Write a depth map, choosing the format from the extension (atomically).

    Parameters
    ----------
    path : str or os.PathLike
        Destination; extension ``.png`` (16-bit integer), ``.npy``, ``.npz``
        (array ``depth``), ``.h5`` / ``.hdf5`` (dataset ``depth``) or ``.pfm``.
        Its folder must exist.
    depth : (H, W) array_like of real numbers
        Depth, NaN (or inf, or 0) where invalid.  Must be non-negative.
    scale : float or str, optional
        PNG only: stored value ``= round(depth * scale)`` (1000 stores
        millimetres from metres, 256 KITTI, 5000 TUM), or a preset name from
        :data:`DEPTH_SCALES`.  Float formats always store ``depth`` itself as
        float64 (PFM: float32), so read them back without a scale.

    Raises
    ------
    FileNotFoundError
        If the destination folder does not exist.
    ValueError
        If the extension is not supported, ``depth`` is not 2-D or has
        negative values, or (PNG) a value overflows 65535 or rounds to 0.
    TypeError
        If ``depth`` is not real-valued.

    Notes
    -----
    Invalid pixels are written as 0 in PNG, NaN in NPY/NPZ/HDF5 and ``inf``
    in PFM (the Middlebury convention).  The file appears only once
    complete: data go to a temporary file in the same folder that then
    replaces ``path`` with :func:`os.replace`; on failure the temporary file
    is removed and an existing ``path`` is left untouched.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> fname = os.path.join(tempfile.mkdtemp(), "depth.npy")
    >>> write_depth(fname, np.array([[1.0, np.nan]]))
    >>> read_depth(fname)
    array([[ 1., nan]])
    """
    writer = _depth_writer(path, depth, scale=scale)
    with _atomic_target(path) as tmp:
        writer(tmp)


def _depth_writer(path, depth, *, scale=1000.0) -> Callable[[Path], None]:
    """Check and encode ``depth`` for ``path`` as :func:`write_depth` does; return ``writer(tmp)``.

    Every check of :func:`write_depth` (extension, shape, sign, PNG range)
    happens here, before anything is written; the returned function only
    writes the encoded data to the file it is given, in the format of
    ``path``'s extension.
    """
    ext = _check_extension(Path(path), _WRITE_DEPTH_EXTENSIONS, "write depth")
    scale = _resolve_scale(scale)
    array = _check_real_array(depth, "depth")
    if array.ndim != 2:
        raise ValueError(f"`depth` must be a 2-D (H, W) array, got shape {array.shape}.")
    if array.size == 0:
        raise ValueError(f"`depth` is empty (shape {array.shape}).")
    values = array.astype(np.float64)
    values[~np.isfinite(values)] = np.nan
    if np.any(values < 0):
        raise ValueError(
            f"`depth` has negative values (min {np.nanmin(values):g}); use NaN for invalid pixels."
        )
    values[values == 0] = np.nan
    writer: Callable[[Path], None]
    if ext == ".png":
        stored = _quantise_png(values, scale)
        writer = lambda tmp: _write_png_file(tmp, stored)  # noqa: E731
    elif ext == ".npy":
        writer = lambda tmp: _write_npy_file(tmp, values)  # noqa: E731
    elif ext == ".npz":
        writer = lambda tmp: _write_npz_file(tmp, values)  # noqa: E731
    elif ext in _HDF5_EXTENSIONS:
        writer = lambda tmp: _write_hdf5_file(tmp, values)  # noqa: E731
    else:  # .pfm
        pfm = _check_pfm_values(np.where(np.isnan(values), np.inf, values), "depth")
        writer = lambda tmp: _write_pfm_file(tmp, pfm, "little")  # noqa: E731
    return writer
