"""Readers and writers for RGB images, depth maps and stereo calibration.

Conventions shared by every function in this module:

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
* Missing files raise :class:`FileNotFoundError`; anything that is not a
  regular file (directory, FIFO, device), unreadable or inconsistent content,
  images declaring more than ``max_pixels`` pixels (default
  :data:`MAX_PIXELS`, checked from the header before decoding) and unknown
  formats raise :class:`ValueError` naming the file and what was expected.
* Every reader takes ``name=``, the label of the path in its messages (the
  command line passes the flag the user typed, e.g. ``"--depth"``); readers
  with options also take ``option_names=``, a mapping from keyword to label.
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
import stat
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Callable, Iterator, Mapping

import h5py
import imageio.v3 as iio
import numpy as np
import tifffile
from PIL import Image

__all__ = [
    "DEPTH_SCALES",
    "KINECT_NYU",
    "KinectDisparity",
    "MAX_PIXELS",
    "NYUDepthV2Labeled",
    "StereoCalibration",
    "disparity_to_depth",
    "read_calib",
    "read_depth",
    "read_depth_array",
    "read_depth_png",
    "read_image",
    "read_mask",
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

#: Default ``max_pixels`` of every reader: larger images are refused from their header.
MAX_PIXELS = 2**27

_IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".ppm", ".pgm", ".pnm", ".bmp", ".tif", ".tiff")
_NETPBM_EXTENSIONS = (".ppm", ".pgm", ".pnm")
_TIFF_EXTENSIONS = (".tif", ".tiff")
_DEPTH_IMAGE_EXTENSIONS = (".png", ".pgm", ".pnm")
_ARRAY_EXTENSIONS = (".npy", ".npz")
_HDF5_EXTENSIONS = (".h5", ".hdf5")
_READ_DEPTH_EXTENSIONS = (
    _DEPTH_IMAGE_EXTENSIONS + _TIFF_EXTENSIONS + (".pfm",) + _ARRAY_EXTENSIONS + _HDF5_EXTENSIONS
)
_MASK_ARRAY_EXTENSIONS = _ARRAY_EXTENSIONS
_CALIB_MAX_BYTES = 1 << 20
#: Stored values that sensors use for "no measurement" (warned about when frequent).
_SENSOR_INVALID_CODES = {2047: "Kinect v1", 65535: "16-bit sensors such as RealSense"}
_BYTESWAP_RATIO = 4.0
_WRITE_DEPTH_EXTENSIONS = (".png", ".pfm") + _ARRAY_EXTENSIONS + _HDF5_EXTENSIONS
_UINT16_MAX = np.iinfo(np.uint16).max
_FLOAT32_MAX = float(np.finfo(np.float32).max)


# --------------------------------------------------------------------------------------
# small shared checks
# --------------------------------------------------------------------------------------
def _label(name: str) -> str:
    """How a name appears in messages: command-line flags as typed, Python names in backticks."""
    return name if name.startswith("-") else f"`{name}`"


def _where(path, name: str) -> str:
    return f"{_label(name)} '{path}'"


def _labels(option_names) -> Callable[[str], str]:
    """Label function for option keywords, overridden by the ``option_names`` mapping."""
    if option_names is None:
        option_names = {}
    elif not isinstance(option_names, Mapping):
        raise TypeError(
            f"`option_names` must be a mapping from keyword to label, got {type(option_names).__name__}."
        )
    return lambda keyword: _label(str(option_names.get(keyword, keyword)))


def _check_name(name) -> str:
    if not isinstance(name, str) or not name:
        raise TypeError(f"`name` must be a non-empty str (the label of the path in messages), got {name!r}.")
    return name


def _check_file(path, name: str = "path") -> Path:
    """Return ``path`` as a :class:`Path` after checking that it is an existing regular file.

    Only :func:`os.stat` is called, so a FIFO or a device is refused without
    being opened (opening a FIFO blocks until a writer appears).
    """
    name = _check_name(name)
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{_label(name)} must be a str or os.PathLike, got {type(path).__name__}.")
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        raise FileNotFoundError(f"{_label(name)}: no such file: '{path}'.") from None
    except (OSError, ValueError) as exc:  # permission, embedded NUL, name too long, ...
        raise ValueError(f"{_where(path, name)}: cannot be accessed ({exc}).") from None
    if not stat.S_ISREG(mode):
        kind = (
            "a directory" if stat.S_ISDIR(mode)
            else "a FIFO (named pipe)" if stat.S_ISFIFO(mode)
            else "a character device" if stat.S_ISCHR(mode)
            else "a block device" if stat.S_ISBLK(mode)
            else "a socket" if stat.S_ISSOCK(mode)
            else "not a regular file"
        )
        raise ValueError(f"{_where(path, name)} is {kind}; expected a regular file.")
    return path


def _read_bytes(path: Path, where: str) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise ValueError(f"{where}: cannot be read ({exc}).") from None


def _check_max_pixels(max_pixels, label: str) -> int | None:
    if max_pixels is None:
        return None
    if isinstance(max_pixels, bool) or not isinstance(max_pixels, numbers.Integral):
        raise TypeError(f"{label} must be a positive integer or None, got {type(max_pixels).__name__}.")
    if max_pixels < 1:
        raise ValueError(f"{label} must be a positive integer or None, got {max_pixels!r}.")
    return int(max_pixels)


def _check_pixels(height: int, width: int, max_pixels: int | None, where: str, label: str) -> None:
    """Refuse a declared size above the pixel limit (before anything is decoded)."""
    if max_pixels is not None and height * width > max_pixels:
        raise ValueError(
            f"{where} declares {width}x{height} = {height * width} pixels, more than the limit "
            f"{max_pixels} ({label}); raise {label} if the file is genuine."
        )


def _suffix(path) -> str:
    return Path(path).suffix.lower()


def _check_extension(path: Path, allowed: tuple[str, ...], what: str, name: str = "path") -> str:
    ext = _suffix(path)
    if ext not in allowed:
        raise ValueError(
            f"cannot {what} {_where(path, name)}: unsupported extension '{ext or '(none)'}'. "
            f"Supported extensions: {', '.join(allowed)}."
        )
    return ext


def resolve_scale(scale, name: str = "scale") -> float:
    """Turn a preset name or a positive number into a float divisor."""
    if isinstance(scale, str):
        key = scale.lower()
        if key not in DEPTH_SCALES:
            raise ValueError(
                f"{_label(name)}: unknown preset '{scale}'. Known presets: "
                + ", ".join(f"'{k}' ({v:g})" for k, v in DEPTH_SCALES.items())
                + "; or pass a positive number."
            )
        return float(DEPTH_SCALES[key])
    if isinstance(scale, bool) or not isinstance(scale, numbers.Real):
        raise TypeError(
            f"{_label(name)} must be a positive number or a preset name, got {type(scale).__name__}."
        )
    value = float(scale)
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"{_label(name)} must be a finite positive number, got {scale!r}.")
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


def _is_real_dtype(dtype) -> bool:
    """Integer or float (not bool, complex, datetime/timedelta, strings or records)."""
    return np.dtype(dtype).kind in "iuf"


def _as_depth(array, source: str, invalid_values=()) -> np.ndarray:
    """Convert a stored 2-D depth array to float64 with NaN for 0/inf/NaN and ``invalid_values``.

    Raises ValueError for a wrong shape, a non-numeric dtype or negative values.
    """
    array = np.asarray(array)
    if array.ndim != 2:
        raise ValueError(f"{source}: expected a 2-D (H, W) depth map, got shape {array.shape}.")
    if not _is_real_dtype(array.dtype):
        raise ValueError(f"{source}: expected integer or float depth, got dtype {array.dtype}.")
    if array.size == 0:
        raise ValueError(f"{source}: the depth map is empty (shape {array.shape}).")
    depth = array.astype(np.float64)  # always a copy
    invalid = ~np.isfinite(depth) | (depth == 0)
    for code in invalid_values:
        invalid |= depth == code
    depth[invalid] = np.nan
    if np.any(depth < 0):  # NaN compares False
        raise ValueError(
            f"{source}: contains negative depth values (min {np.nanmin(depth):g}); "
            "depth must be positive, with 0, inf or NaN for invalid pixels."
        )
    return depth


def _check_invalid_values(values, label: str) -> tuple[float, ...]:
    if values is None:
        return ()
    if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
        values = (values,)
    checked = []
    for value in values:
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
            raise ValueError(f"{label} must hold finite numbers (stored codes such as 2047), got {value!r}.")
        checked.append(float(value))
    return tuple(checked)


def _check_depth_bound(value, label: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{label} must be a number or None, got {type(value).__name__}.")
    value = float(value)
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"{label} must be a finite number >= 0, got {value!r}.")
    return value


# --------------------------------------------------------------------------------------
# atomic writes
# --------------------------------------------------------------------------------------
def fsync(path) -> None:
    """Flush ``path`` to disk before it is renamed into place (best effort: some systems cannot)."""
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def create_temporary(path: Path, kind: str = "tmp") -> Path:
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
def atomic_target(path) -> Iterator[Path]:
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
    tmp = create_temporary(path)
    try:
        yield tmp
        fsync(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


# --------------------------------------------------------------------------------------
# images
# --------------------------------------------------------------------------------------
_WHITESPACE = b" \t\r\n\v\f"


def _netpbm_tokens(data: bytes, start: int, count: int, where: str) -> tuple[list[bytes], int]:
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
            raise ValueError(f"{where}: truncated Netpbm header.")
        tokens.append(data[begin:pos])
    return tokens, pos


def _variation(values: np.ndarray) -> float:
    """Mean absolute difference between vertical and horizontal neighbours."""
    values = values.astype(np.float64)
    return float(np.mean(np.abs(np.diff(values, axis=0))) + np.mean(np.abs(np.diff(values, axis=1))))


def _check_byte_order(values: np.ndarray, where: str, label: str) -> None:
    """Refuse 16-bit samples that are much smoother with their two bytes swapped."""
    if values.shape[0] < 2 or values.shape[1] < 2:
        return
    as_read, swapped = _variation(values), _variation(values.byteswap())
    if swapped * _BYTESWAP_RATIO < as_read:
        raise ValueError(
            f"{where}: the 16-bit samples look byte-swapped (neighbouring pixels differ "
            f"{as_read / max(swapped, 1e-300):.0f} times less with the two bytes of each sample "
            "swapped). NYU Depth V2 raw Kinect .pgm files are little-endian despite the Netpbm "
            f"standard: pass {label} little; pass {label} big to read the file as stored."
        )


def _read_netpbm(path: Path, byteorder: str | None, max_pixels: int | None, where: str,
                 label: Callable[[str], str]) -> np.ndarray:
    """Decode a P2/P3 (ASCII) or P5/P6 (binary) Netpbm grey or RGB image."""
    data = _read_bytes(path, where)
    magic = data[:2]
    if magic not in (b"P2", b"P3", b"P5", b"P6"):
        raise ValueError(
            f"{where}: not a supported Netpbm image (magic {magic!r}); "
            "expected P2/P5 (grey) or P3/P6 (RGB)."
        )
    tokens, pos = _netpbm_tokens(data, 2, 3, where)
    try:
        width, height, maxval = (int(t) for t in tokens)
    except ValueError:
        raise ValueError(f"{where}: malformed Netpbm header {tokens!r}.") from None
    if width <= 0 or height <= 0 or not 0 < maxval <= _UINT16_MAX:
        raise ValueError(
            f"{where}: invalid Netpbm header (width {width}, height {height}, maxval {maxval})."
        )
    _check_pixels(height, width, max_pixels, where, label("max_pixels"))
    channels = 3 if magic in (b"P3", b"P6") else 1
    shape = (height, width, channels) if channels == 3 else (height, width)
    count = width * height * channels
    out_dtype = np.uint8 if maxval < 256 else np.uint16
    if magic in (b"P5", b"P6"):
        if pos >= len(data) or data[pos] not in _WHITESPACE:
            raise ValueError(f"{where}: malformed Netpbm header (no whitespace before data).")
        pos += 1  # exactly one whitespace character separates header and raster
        if out_dtype == np.uint8:
            dtype = np.dtype(np.uint8)
        else:
            dtype = np.dtype("<u2" if byteorder == "little" else ">u2")
        expected = count * dtype.itemsize
        available = len(data) - pos
        if available != expected:
            raise ValueError(
                f"{where}: Netpbm raster has {available} bytes, expected {expected} "
                f"for {width}x{height}x{channels} samples of {dtype.itemsize} byte(s) "
                "(truncated file, or a multi-image file, which is not supported)."
            )
        values = np.frombuffer(data, dtype=dtype, count=count, offset=pos)
        values = values.astype(out_dtype).reshape(shape)
        if out_dtype == np.uint16 and byteorder is None:
            _check_byte_order(values, where, label("byteorder"))
        return values
    try:
        values = np.array(data[pos:].split()).astype(np.int64)
    except (ValueError, OverflowError):
        raise ValueError(f"{where}: non-integer sample in ASCII Netpbm raster.") from None
    if values.size != count:
        raise ValueError(f"{where}: ASCII Netpbm raster has {values.size} samples, expected {count}.")
    if values.size and (values.min() < 0 or values.max() > maxval):
        raise ValueError(f"{where}: ASCII Netpbm samples outside 0..{maxval}.")
    return values.astype(out_dtype).reshape(shape)


def _normalise_image(image: np.ndarray, where: str) -> np.ndarray:
    if image.dtype == bool:  # 1-bit images: black 0, white 255
        image = image.astype(np.uint8) * np.uint8(255)
    if image.dtype not in (np.uint8, np.uint16):
        raise ValueError(
            f"{where} decodes to dtype {image.dtype}; only 1-, 8- and 16-bit images are supported."
        )
    if image.ndim == 3 and image.shape[2] in (1, 2):  # grey (+ alpha)
        image = image[:, :, 0]
    elif image.ndim == 3 and image.shape[2] == 4:  # RGBA
        image = image[:, :, :3]
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
        raise ValueError(
            f"{where} decodes to shape {image.shape}; expected a single (H, W) grey "
            "or (H, W, 3) colour image."
        )
    if image.size == 0:
        raise ValueError(f"{where} decodes to an empty image (shape {image.shape}).")
    return np.ascontiguousarray(image)


def _png_declared_size(path: Path, where: str) -> tuple[int, int] | None:
    """(height, width) from a PNG's IHDR chunk, or None if the file does not start like a PNG."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(24)
    except OSError as exc:
        raise ValueError(f"{where}: cannot be read ({exc}).") from None
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    width, height = int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    return height, width


@contextlib.contextmanager
def _as_value_error(where: str, error) -> Iterator[None]:
    """Exceptions raised in the block by a third-party decoder become ``error(where, exc)``, a ValueError.

    ``MemoryError`` passes through: running out of memory says nothing about the file.
    """
    try:
        yield
    except MemoryError:
        raise
    except Exception as exc:
        raise error(where, exc) from exc


def _decode_error(where: str, exc: BaseException) -> ValueError:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return ValueError(f"could not decode {where}: {text}")


def _read_pillow(path: Path, max_pixels: int | None, where: str, label: str) -> np.ndarray:
    """Decode with Pillow after checking the declared size (PNG IHDR, else a lazy open)."""
    if _suffix(path) == ".png":
        declared = _png_declared_size(path, where)
        if declared is not None:
            _check_pixels(*declared, max_pixels, where, label)
    with warnings.catch_warnings():
        # the pixel limit is ours; Pillow's own bomb warning would only repeat it
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            with Image.open(path) as handle:
                width, height = handle.size
        except Image.DecompressionBombError as exc:
            raise ValueError(
                f"{where}: declares more pixels than Pillow decodes ({exc}); "
                "Pillow's limit is PIL.Image.MAX_IMAGE_PIXELS."
            ) from None
        except MemoryError:
            raise
        except Exception as exc:  # Pillow raises many types on junk (SyntaxError, struct.error, ...)
            raise _decode_error(where, exc) from exc
        _check_pixels(height, width, max_pixels, where, label)
        with _as_value_error(where, _decode_error):
            return np.asarray(iio.imread(path, plugin="pillow"))


def _read_tiff(path: Path, max_pixels: int | None, where: str, label: str) -> np.ndarray:
    """First page of a TIFF with tifffile (keeps 16-bit and float32 samples)."""
    with _as_value_error(where, _decode_error):
        handle = tifffile.TiffFile(path)
    with handle:
        with _as_value_error(where, _decode_error):
            page = handle.pages[0]
            shape = tuple(int(n) for n in page.shape)
        if len(shape) < 2:
            raise ValueError(f"{where}: TIFF page has shape {shape}, expected (H, W) or (H, W, C).")
        _check_pixels(shape[0], shape[1], max_pixels, where, label)
        with _as_value_error(where, _decode_error):
            return np.asarray(page.asarray())


def _check_byteorder(byteorder, label: str) -> str | None:
    if byteorder not in (None, "big", "little"):
        raise ValueError(f"{label} must be 'big', 'little' or None, got {byteorder!r}.")
    return byteorder


def read_image(path, *, byteorder: str | None = None, max_pixels: int | None = MAX_PIXELS,
               name: str = "path", option_names: Mapping[str, str] | None = None) -> np.ndarray:
    """Read a grey or colour image as stored (8 or 16 bit).

    Parameters
    ----------
    path : str or os.PathLike
        Image file: PNG, JPEG, PPM/PGM/PNM (ASCII or binary), BMP or TIFF.
    byteorder : {None, 'big', 'little'}, optional
        Byte order of 16-bit binary Netpbm rasters.  The Netpbm standard is
        ``'big'``; some datasets (e.g. the NYU Depth V2 raw ``.pgm`` Kinect
        frames) store little-endian samples despite the header.  ``None``
        (default) reads big-endian but refuses a raster that looks
        byte-swapped (see Notes).  Ignored for other formats.
    max_pixels : int or None, optional
        Largest accepted ``height * width``, checked from the file header
        before decoding (default :data:`MAX_PIXELS`); None for no limit.
        Pillow's own limit ``PIL.Image.MAX_IMAGE_PIXELS`` (twice it, in fact)
        also applies to the formats Pillow decodes.
    name : str, optional
        Label of ``path`` in error messages (e.g. the command-line flag).
    option_names : mapping, optional
        Labels of the keywords in messages, e.g. ``{"byteorder": "--byteorder"}``.

    Returns
    -------
    image : (H, W) or (H, W, 3) ndarray of uint8 or uint16
        The decoded samples, unscaled.  An alpha channel is dropped; 1-bit
        images become uint8 0 (black) and 255 (white).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If ``path`` is not a regular file, the extension is not supported,
        the declared size exceeds ``max_pixels``, the file cannot be decoded,
        or it decodes to something other than a 1/8/16-bit grey or RGB image.
    TypeError
        If ``path`` is not a str or os.PathLike.

    Notes
    -----
    Byte-swap check (``byteorder=None``, 16-bit binary Netpbm of at least
    2x2 pixels): with :math:`V(x)` the mean absolute difference between
    vertical plus horizontal neighbours, the file is refused when
    :math:`4\\,V(\\mathrm{swap}(x)) < V(x)`.  Depth and photographs vary
    slowly, so swapping their bytes moves the noisy low byte into the high
    one and multiplies :math:`V` (by 8.6 to 275 on the frames in the shared
    data); the NYU raw Kinect frame read big-endian gives a ratio of 0.03.

    Examples
    --------
    >>> import numpy as np, imageio.v3 as iio, tempfile, os
    >>> fname = os.path.join(tempfile.mkdtemp(), "grey.png")
    >>> iio.imwrite(fname, np.array([[0, 1000]], dtype=np.uint16))
    >>> read_image(fname)
    array([[   0, 1000]], dtype=uint16)
    """
    label = _labels(option_names)
    path = _check_file(path, name)
    where = _where(path, name)
    byteorder = _check_byteorder(byteorder, label("byteorder"))
    max_pixels = _check_max_pixels(max_pixels, label("max_pixels"))
    ext = _check_extension(path, _IMAGE_EXTENSIONS, "read image", name)
    if ext in _NETPBM_EXTENSIONS:
        image = _read_netpbm(path, byteorder, max_pixels, where, label)
    else:
        image = _read_pillow(path, max_pixels, where, label("max_pixels"))
    return _normalise_image(image, where)


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
    label = _labels(option_names)
    scale = resolve_scale(scale, label("scale"))
    path = _check_file(path, name)
    _check_extension(path, _DEPTH_IMAGE_EXTENSIONS, "read depth image", name)
    stored = _read_depth_image(path, byteorder, max_pixels, name, option_names)
    depth = stored.astype(np.float64) / scale
    depth[stored == 0] = np.nan
    return depth


def _read_depth_image(path: Path, byteorder, max_pixels, name: str, option_names) -> np.ndarray:
    """Stored samples of a single-channel PNG/PGM depth image."""
    stored = read_image(path, byteorder=byteorder, max_pixels=max_pixels, name=name,
                        option_names=option_names)
    if stored.ndim != 2:
        raise ValueError(
            f"{_where(path, name)} has shape {stored.shape}; a depth image must be single-channel "
            "(8- or 16-bit grey)."
        )
    return stored


# --------------------------------------------------------------------------------------
# PFM
# --------------------------------------------------------------------------------------
_PFM_HEADER = re.compile(rb"\A(PF|Pf)\s+(\d+)\s+(\d+)\s+(\S+)\s")


def read_pfm(path, *, max_pixels: int | None = MAX_PIXELS, name: str = "path",
             option_names: Mapping[str, str] | None = None) -> np.ndarray:
    """Read a Portable Float Map (PFM) file.

    Parameters
    ----------
    path : str or os.PathLike
        ``.pfm`` file: header ``Pf`` (grey) or ``PF`` (colour), ``width height``
        and a scale whose sign gives the byte order (negative = little endian),
        followed by float32 rows stored bottom-to-top.
    max_pixels : int or None, optional
        Largest accepted ``width * height`` (checked from the header before
        the data are read); default :data:`MAX_PIXELS`, None for no limit.
    name : str, optional
        Label of ``path`` in error messages.
    option_names : mapping, optional
        Labels of the keywords in messages, e.g. ``{"max_pixels": "--max-pixels"}``.

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
        If ``path`` is not a regular file, the header is malformed, the scale
        is zero or not finite, the size exceeds ``max_pixels``, or the pixel
        data are shorter or longer than the header announces.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> fname = os.path.join(tempfile.mkdtemp(), "disp.pfm")
    >>> write_pfm(fname, np.array([[1.0, 2.0], [3.0, np.inf]]))
    >>> read_pfm(fname)
    array([[ 1.,  2.],
           [ 3., inf]], dtype=float32)
    """
    label = _labels(option_names)
    path = _check_file(path, name)
    where = _where(path, name)
    max_pixels = _check_max_pixels(max_pixels, label("max_pixels"))
    try:
        with open(path, "rb") as fh:
            head = fh.read(256)
            match = _PFM_HEADER.match(head)
            if match is None:
                raise ValueError(
                    f"{where}: not a PFM file (expected a header 'Pf' or 'PF', width, height, scale)."
                )
            channels = 3 if match.group(1) == b"PF" else 1
            width, height = int(match.group(2)), int(match.group(3))
            try:
                scale = float(match.group(4))
            except ValueError:
                raise ValueError(f"{where}: PFM scale {match.group(4)!r} is not a number.") from None
            if width <= 0 or height <= 0:
                raise ValueError(f"{where}: PFM dimensions must be positive, got {width}x{height}.")
            if not math.isfinite(scale) or scale == 0:
                raise ValueError(
                    f"{where}: PFM scale must be a finite non-zero number (its sign gives the "
                    f"byte order), got {scale!r}."
                )
            _check_pixels(height, width, max_pixels, where, label("max_pixels"))
            offset = match.end()
            fh.seek(offset)
            data = fh.read()
    except OSError as exc:
        raise ValueError(f"{where}: cannot be read ({exc}).") from None
    dtype = np.dtype("<f4" if scale < 0 else ">f4")
    count = width * height * channels
    expected = count * dtype.itemsize
    if len(data) != expected:
        raise ValueError(
            f"{where}: PFM pixel data has {len(data)} bytes, expected {expected} "
            f"for {width}x{height}x{channels} float32 values."
        )
    values = np.frombuffer(data, dtype=dtype, count=count)
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
    with atomic_target(path) as tmp:
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
        raw = _check_real_array(disparity, "disparity").astype(np.float64)
        valid = np.isfinite(raw) & (raw < self.offset) & (raw != self.invalid)
        depth = np.full(raw.shape, np.nan)
        depth[valid] = self.numerator / (self.offset - raw[valid])
        return depth


#: Kinect v1 constants of the NYU Depth V2 toolbox: metres = 351.3 / (1092.5 - raw).
KINECT_NYU = KinectDisparity()


def _parse_matrix(text: str, key: str, where: str) -> np.ndarray:
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
    path = _check_file(path, name)
    where = _where(path, name)
    try:
        with open(path, "rb") as fh:
            raw = fh.read(_CALIB_MAX_BYTES + 1)
    except OSError as exc:
        raise ValueError(f"{where}: cannot be read ({exc}).") from None
    if len(raw) > _CALIB_MAX_BYTES:
        raise ValueError(f"{where}: larger than {_CALIB_MAX_BYTES} bytes; not a calib.txt file.")
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError:
        raise ValueError(f"{where}: calibration file is not ASCII text.") from None
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
        if key in ("cam0", "cam1", "doffs", "baseline", "width", "height", "ndisp"):
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
def _load_error(where: str, exc: BaseException) -> ValueError:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return ValueError(f"could not load {where}: {text}")


def _check_stored_array(shape, dtype, where: str, max_pixels, label: str, *, allow_bool=False) -> None:
    """Shape and dtype checks made from a header, before the data are read."""
    dtype = np.dtype(dtype)
    if dtype.hasobject:
        raise ValueError(
            f"could not load {where}: it holds Python objects (dtype {dtype}); pickled data are refused."
        )
    if len(shape) != 2:
        raise ValueError(f"{where}: expected a 2-D (H, W) depth map, got shape {tuple(shape)}.")
    if not (_is_real_dtype(dtype) or (allow_bool and dtype == bool)):
        kinds = "boolean, integer or float" if allow_bool else "integer or float depth"
        raise ValueError(f"{where}: expected {kinds}, got dtype {dtype}.")
    _check_pixels(int(shape[0]), int(shape[1]), max_pixels, where, label)


def _read_npy_stream(fh, where: str, max_pixels, label: str, *, allow_bool=False) -> np.ndarray:
    """Read one ``.npy`` array from an open binary stream, checking its header first."""
    with _as_value_error(where, _load_error):  # bad magic, malformed header dict, pickled (object) dtype, ...
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
        else:
            raise ValueError(f"unsupported .npy format version {version}")
    _check_stored_array(shape, dtype, where, max_pixels, label, allow_bool=allow_bool)
    count = int(shape[0]) * int(shape[1])
    nbytes = count * dtype.itemsize
    with _as_value_error(where, _load_error):  # OSError, zipfile.BadZipFile (CRC), zlib.error, ...
        data = fh.read(nbytes)
    if len(data) != nbytes:
        raise ValueError(f"could not load {where}: {len(data)} bytes of data, expected {nbytes} (truncated).")
    array = np.frombuffer(data, dtype=dtype, count=count)
    return array.reshape(shape, order="F" if fortran else "C").copy()


def _load_array(path: Path, key: str | None, max_pixels, where: str, label: Callable[[str], str],
                *, allow_bool=False) -> tuple[np.ndarray, str]:
    """The stored (H, W) array of a ``.npy`` or ``.npz`` file and a description of its source."""
    limit = label("max_pixels")
    if _suffix(path) == ".npy":
        if key is not None:
            raise ValueError(f"{label('key')} only applies to .npz archives; omit it for a .npy file.")
        try:
            with open(path, "rb") as fh:
                return _read_npy_stream(fh, where, max_pixels, limit, allow_bool=allow_bool), where
        except OSError as exc:
            raise ValueError(f"{where}: cannot be read ({exc}).") from None
    with _as_value_error(where, _load_error):
        archive = zipfile.ZipFile(path)
    with archive:
        members = [m for m in archive.namelist() if m.endswith(".npy")]
        names = [m[:-4] for m in members]
        if key is None:
            if len(names) == 1:
                key = names[0]
            elif "depth" in names:
                key = "depth"
            elif not names:
                raise ValueError(f"could not load {where}: the archive holds no .npy array.")
            else:
                raise ValueError(f"{where} holds several arrays {names}; choose one with {label('key')}.")
        elif key not in names:
            raise ValueError(f"{label('key')}: '{key}' is not in {where}; available arrays: {names}.")
        source = f"{where} array '{key}'"
        try:
            with archive.open(key + ".npy") as fh:
                return _read_npy_stream(fh, source, max_pixels, limit, allow_bool=allow_bool), source
        except (ValueError, MemoryError):
            raise
        except Exception as exc:
            raise _load_error(source, exc) from exc


def read_depth_array(path, *, key: str | None = None, max_pixels: int | None = MAX_PIXELS,
                     name: str = "path", option_names: Mapping[str, str] | None = None) -> np.ndarray:
    """Read a depth map stored with NumPy (``.npy`` or ``.npz``).

    Parameters
    ----------
    path : str or os.PathLike
        ``.npy`` file holding one (H, W) array, or ``.npz`` archive.
    key : str, optional
        Array name inside an ``.npz``.  If omitted, the archive's only array
        is used, or else the one called ``'depth'``.
    max_pixels : int or None, optional
        Largest accepted ``H * W``, checked from the array header before the
        data are read; default :data:`MAX_PIXELS`, None for no limit.
    name : str, optional
        Label of ``path`` in error messages.
    option_names : mapping, optional
        Labels of the keywords in messages, e.g. ``{"key": "--depth-key"}``.

    Returns
    -------
    depth : (H, W) ndarray of float64
        Stored values (no unit conversion: :func:`read_depth` requires a
        ``scale`` for integer arrays), with NaN where they are 0, inf or NaN.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If ``path`` is not a regular file, the file cannot be loaded
        (pickled objects are refused), ``key`` is missing or ambiguous, or
        the array is not a non-negative 2-D real array within ``max_pixels``.
    """
    label = _labels(option_names)
    path = _check_file(path, name)
    _check_extension(path, _ARRAY_EXTENSIONS, "read depth array", name)
    max_pixels = _check_max_pixels(max_pixels, label("max_pixels"))
    stored, source = _load_array(path, key, max_pixels, _where(path, name), label)
    return _as_depth(stored, source)


def _open_hdf5(path: Path, where: str | None = None) -> h5py.File:
    where = f"'{path}'" if where is None else where
    try:
        return h5py.File(path, "r")
    except MemoryError:
        raise
    except Exception as exc:  # OSError for non-HDF5 content; other types on corrupt superblocks
        raise ValueError(
            f"{where} is not a readable HDF5 file ({exc}). MATLAB .mat files must be "
            "version 7.3 (HDF5); older ones need scipy.io.loadmat."
        ) from exc


def _hdf5_dataset(handle: h5py.File, key: str, where) -> h5py.Dataset:
    try:
        item = handle.get(key)
        if not isinstance(item, h5py.Dataset):
            available = sorted(k for k in handle.keys() if isinstance(handle.get(k), h5py.Dataset))
            raise ValueError(f"{where} has no dataset '{key}'; available datasets: {available}.")
        item.shape, item.dtype  # noqa: B018 - reading the metadata may fail on corrupt files
    except (ValueError, MemoryError):
        raise
    except Exception as exc:
        raise _load_error(f"{where} dataset '{key}'", exc) from exc
    return item


def _hdf5_read(dset: h5py.Dataset, source: str, index=()):
    with _as_value_error(source, _load_error):  # OSError / RuntimeError / KeyError from corrupt chunks or filters
        return dset[index]


def read_nyu_h5(path, *, max_pixels: int | None = MAX_PIXELS, name: str = "path") -> tuple[np.ndarray, np.ndarray]:
    """Read one frame of the preprocessed NYU Depth V2 HDF5 layout.

    This is the one-file-per-frame layout used by most depth-completion code
    (``nyudepthv2/{train,val}/<scene>/<frame>.h5``): dataset ``rgb`` of shape
    (3, H, W) uint8 and dataset ``depth`` of shape (H, W) float32 in metres.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.h5`` file.
    max_pixels : int or None, optional
        Largest accepted ``H * W`` (checked before reading); default
        :data:`MAX_PIXELS`, None for no limit.
    name : str, optional
        Label of ``path`` in error messages.

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
        If ``path`` is not a regular file, not HDF5, lacks ``rgb`` or
        ``depth``, or their shapes or dtypes do not match the layout above.
    """
    path = _check_file(path, name)
    where = _where(path, name)
    max_pixels = _check_max_pixels(max_pixels, "`max_pixels`")
    with _open_hdf5(path, where) as handle:
        rgb = _hdf5_dataset(handle, "rgb", where)
        dset = _hdf5_dataset(handle, "depth", where)
        if rgb.ndim != 3 or rgb.shape[0] != 3 or rgb.dtype != np.uint8:
            raise ValueError(
                f"{where}: dataset 'rgb' must be (3, H, W) uint8, got {rgb.shape} {rgb.dtype}."
            )
        if dset.shape != rgb.shape[1:]:
            raise ValueError(
                f"{where}: dataset 'depth' has shape {dset.shape}, expected {rgb.shape[1:]} "
                "to match 'rgb'."
            )
        _check_stored_array(dset.shape, dset.dtype, f"{where} dataset 'depth'", max_pixels, "`max_pixels`")
        image = np.ascontiguousarray(np.transpose(_hdf5_read(rgb, f"{where} dataset 'rgb'"), (1, 2, 0)))
        depth = _as_depth(_hdf5_read(dset, f"{where} dataset 'depth'"), f"{where} dataset 'depth'")
    return image, depth


def _read_hdf5_array(path: Path, key: str | None, max_pixels, where: str,
                     label: Callable[[str], str], *, allow_bool=False) -> tuple[np.ndarray, str]:
    key = "depth" if key is None else key
    with _open_hdf5(path, where) as handle:
        dset = _hdf5_dataset(handle, key, where)
        source = f"{where} dataset '{key}'"
        _check_stored_array(dset.shape, dset.dtype, source, max_pixels, label("max_pixels"),
                            allow_bool=allow_bool)
        return np.asarray(_hdf5_read(dset, source)), source


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
    name : str, optional
        Label of ``path`` in error messages.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If ``path`` is not a regular file, not HDF5, or the datasets are
        missing or inconsistent.

    Examples
    --------
    >>> with NYUDepthV2Labeled("nyu_depth_v2_labeled.mat") as nyu:  # doctest: +SKIP
    ...     image, depth, raw = nyu[0]
    ...     len(nyu)
    1449
    """

    def __init__(self, path, *, name: str = "path"):
        self.path = _check_file(path, name)
        self._where = _where(self.path, name)
        self._file = _open_hdf5(self.path, self._where)
        try:
            self._images = _hdf5_dataset(self._file, "images", self._where)
            self._depths = _hdf5_dataset(self._file, "depths", self._where)
            self._raw = None
            if "rawDepths" in self._file:
                self._raw = _hdf5_dataset(self._file, "rawDepths", self._where)
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
        except (ValueError, MemoryError, KeyboardInterrupt):
            self._file.close()
            raise
        except Exception as exc:  # corrupt metadata
            self._file.close()
            raise _load_error(self._where, exc) from exc

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
        image = np.ascontiguousarray(_hdf5_read(self._images, f"{self._where} images[{i}]", i).transpose(2, 1, 0))
        depth = _as_depth(_hdf5_read(self._depths, f"{self._where} depths[{i}]", i).T, f"{self._where} depths[{i}]")
        raw = None
        if self._raw is not None:
            source = f"{self._where} rawDepths[{i}]"
            raw = _as_depth(_hdf5_read(self._raw, source, i).T, source)
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
def read_depth(path, *, scale=None, calib=None, key: str | None = None, byteorder: str | None = None,
               invalid_values=(), min_depth=None, max_depth=None, max_pixels: int | None = MAX_PIXELS,
               name: str = "path", option_names: Mapping[str, str] | None = None) -> np.ndarray:
    """Read a depth (or disparity) map, choosing the reader from the extension.

    Parameters
    ----------
    path : str or os.PathLike
        One of ``.png``, ``.pgm``, ``.pnm`` (integer image), ``.tif`` /
        ``.tiff`` (16-bit integer or float32, first page), ``.pfm``,
        ``.npy``, ``.npz``, ``.h5`` / ``.hdf5``.
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
    >>> fname = os.path.join(tempfile.mkdtemp(), "depth.png")
    >>> write_depth(fname, np.array([[1.5, np.nan]]), scale=1000)
    >>> read_depth(fname, scale="mm")
    array([[1.5, nan]])
    """
    label = _labels(option_names)
    path = _check_file(path, name)
    where = _where(path, name)
    ext = _check_extension(path, _READ_DEPTH_EXTENSIONS, "read depth", name)
    if key is not None and ext not in (".npz",) + _HDF5_EXTENSIONS:
        raise ValueError(f"{label('key')} only applies to .npz and HDF5 files, not '{ext}'.")
    divisor = None if scale is None else resolve_scale(scale, label("scale"))
    byteorder = _check_byteorder(byteorder, label("byteorder"))
    invalid_values = _check_invalid_values(invalid_values, label("invalid_values"))
    min_depth = _check_depth_bound(min_depth, label("min_depth"))
    max_depth = _check_depth_bound(max_depth, label("max_depth"))
    if min_depth is not None and max_depth is not None and min_depth > max_depth:
        raise ValueError(
            f"{label('min_depth')} ({min_depth:g}) is larger than {label('max_depth')} ({max_depth:g})."
        )
    max_pixels = _check_max_pixels(max_pixels, label("max_pixels"))
    if calib is not None and not isinstance(calib, (StereoCalibration, KinectDisparity)):
        if isinstance(calib, (str, os.PathLike)):
            calib = read_calib(calib, name=str((option_names or {}).get("calib", "calib")))
        else:
            raise TypeError(
                f"{label('calib')} must be a StereoCalibration, a KinectDisparity or a path to calib.txt, "
                f"got {type(calib).__name__}."
            )

    source = where
    if ext in _DEPTH_IMAGE_EXTENSIONS:
        stored = _read_depth_image(path, byteorder, max_pixels, name, option_names)
    elif ext in _TIFF_EXTENSIONS:
        stored = _read_tiff(path, max_pixels, where, label("max_pixels"))
        if stored.ndim == 3 and stored.shape[2] == 1:
            stored = stored[:, :, 0]
        if stored.ndim != 2:
            raise ValueError(f"{where} has shape {stored.shape}; a depth TIFF must be single-channel.")
    elif ext == ".pfm":
        stored = read_pfm(path, max_pixels=max_pixels, name=name, option_names=option_names)
        if stored.ndim != 2:
            raise ValueError(f"{where} is a colour PFM (shape {stored.shape}); depth must be grey ('Pf').")
    elif ext in _ARRAY_EXTENSIONS:
        stored, source = _load_array(path, key, max_pixels, where, label)
    else:
        stored, source = _read_hdf5_array(path, key, max_pixels, where, label)
    if not _is_real_dtype(stored.dtype):
        raise ValueError(f"{source}: expected integer or float depth, got dtype {stored.dtype}.")

    integer = np.issubdtype(stored.dtype, np.integer)
    if integer and divisor is None:
        if not isinstance(calib, KinectDisparity):
            raise ValueError(
                f"{label('scale')} is required for integer depth ({stored.dtype}) such as {source}: e.g. "
                "'nyu' (1000, millimetres), 'kitti' (256), 'tum' (5000) or 1 (integers that are metres)."
            )
    if integer and not invalid_values and not isinstance(calib, KinectDisparity) and stored.size:
        for code, sensor in _SENSOR_INVALID_CODES.items():
            share = float(np.count_nonzero(stored == code)) / stored.size
            if share > 0.01:
                warnings.warn(
                    f"{source}: {share:.1%} of the pixels hold {code}, the 'no measurement' code of "
                    f"{sensor}; they are read as depth. Pass {label('invalid_values')} {code} "
                    "to mark them missing.",
                    UserWarning,
                    stacklevel=2,
                )
    values = _as_depth(stored, source, invalid_values)
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
    label = _labels(option_names)
    path = _check_file(path, name)
    where = _where(path, name)
    ext = _check_extension(path, _MASK_ARRAY_EXTENSIONS + _HDF5_EXTENSIONS + _IMAGE_EXTENSIONS, "read mask", name)
    max_pixels = _check_max_pixels(max_pixels, label("max_pixels"))
    if key is not None and ext not in (".npz",) + _HDF5_EXTENSIONS:
        raise ValueError(f"{label('key')} only applies to .npz and HDF5 files, not '{ext}'.")
    if ext in _IMAGE_EXTENSIONS:
        image = read_image(path, max_pixels=max_pixels, name=name, option_names=option_names)
        return image != 0 if image.ndim == 2 else np.any(image != 0, axis=2)
    if ext in _ARRAY_EXTENSIONS:
        array, source = _load_array(path, key, max_pixels, where, label, allow_bool=True)
    else:
        array, source = _read_hdf5_array(path, "mask" if key is None else key, max_pixels, where, label,
                                         allow_bool=True)
    if array.size == 0:
        raise ValueError(f"{source}: the mask is empty (shape {array.shape}).")
    if array.dtype != bool:
        if not np.all((array == 0) | (array == 1)):
            raise ValueError(f"{source}: a mask must be boolean or hold only 0 and 1.")
        array = array != 0
    return array


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
    writer = depth_writer(path, depth, scale=scale)
    with atomic_target(path) as tmp:
        writer(tmp)


def depth_writer(path, depth, *, scale=1000.0) -> Callable[[Path], None]:
    """Check and encode ``depth`` for ``path`` as :func:`write_depth` does; return ``writer(tmp)``.

    Every check of :func:`write_depth` (extension, shape, sign, PNG range)
    happens here, before anything is written; the returned function only
    writes the encoded data to the file it is given, in the format of
    ``path``'s extension.
    """
    ext = _check_extension(Path(path), _WRITE_DEPTH_EXTENSIONS, "write depth")
    scale = resolve_scale(scale)
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
