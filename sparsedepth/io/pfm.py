"""Portable Float Map (PFM) files: grey ``Pf`` or colour ``PF`` float32 rasters stored bottom-to-top.

What lives here: :func:`read_pfm`, :func:`write_pfm` and the depth reader and
writer of the PFM entry of :mod:`.formats` (:func:`read_pfm_depth`,
:func:`pfm_writer`, built on :func:`check_pfm_values` and :func:`write_pfm_file`).

Imports NumPy, :mod:`sparsedepth._validation` and :mod:`.files` /
:mod:`.stored` only.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from .._validation import check_input_file
from .files import MAX_PIXELS, atomic_target, check_max_pixels, check_pixels, file_label, option_labels
from .stored import check_real_array

__all__ = ["check_pfm_values", "pfm_writer", "read_pfm", "read_pfm_depth", "write_pfm", "write_pfm_file"]

_FLOAT32_MAX = float(np.finfo(np.float32).max)
_PFM_HEADER = re.compile(rb"\A(PF|Pf)\s+(\d+)\s+(\d+)\s+(\S+)\s")


def _read_header(head: bytes, where: str) -> tuple[int, int, int, float, int]:
    """``(channels, width, height, scale, offset of the data)`` from the first bytes of a PFM file."""
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
    return channels, width, height, scale, match.end()


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
    label = option_labels(option_names)
    path = check_input_file(path, name=name)
    where = file_label(path, name)
    max_pixels = check_max_pixels(max_pixels, label("max_pixels"))
    try:
        with open(path, "rb") as fh:
            channels, width, height, scale, offset = _read_header(fh.read(256), where)
            check_pixels(height, width, max_pixels, where, label("max_pixels"))
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


def read_pfm_depth(path: Path, key, byteorder, max_pixels, name: str, option_names) -> tuple[np.ndarray, str]:
    """The depth reader of PFM files: the grey ``Pf`` samples and their source (a colour ``PF`` is refused)."""
    stored = read_pfm(path, max_pixels=max_pixels, name=name, option_names=option_names)
    where = file_label(path, name)
    if stored.ndim != 2:
        raise ValueError(f"{where} is a colour PFM (shape {stored.shape}); depth must be grey ('Pf').")
    return stored, where


def pfm_writer(values: np.ndarray, name: str) -> Callable[[Path], None]:
    """The writer of the PFM format: float64 ``values``, NaN where missing, stored little-endian with ``inf`` there.

    Raises ``ValueError`` naming ``name`` if a finite value exceeds the float32 range.
    """
    pfm = check_pfm_values(np.where(np.isnan(values), np.inf, values), name)
    return lambda tmp: write_pfm_file(tmp, pfm, "little")


def write_pfm_file(path: Path, values: np.ndarray, byteorder: str) -> None:
    """Write checked ``values`` (see :func:`check_pfm_values`) to ``path`` as PFM, rows bottom-to-top."""
    colour = values.ndim == 3
    height, width = values.shape[:2]
    sign = "-1" if byteorder == "little" else "1"
    header = f"{'PF' if colour else 'Pf'}\n{width} {height}\n{sign}\n".encode("ascii")
    dtype = "<f4" if byteorder == "little" else ">f4"
    with open(path, "wb") as fh:
        fh.write(header)
        fh.write(np.ascontiguousarray(values[::-1], dtype=dtype).tobytes())


def check_pfm_values(array, name: str) -> np.ndarray:
    """``array`` as float64 after checking it is a non-empty (H, W) or (H, W, 3) array that fits float32."""
    array = check_real_array(array, name)
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
    values = check_pfm_values(array, "array")
    with atomic_target(path) as tmp:
        write_pfm_file(tmp, values, byteorder)
