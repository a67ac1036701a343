"""Netpbm images (PGM/PPM/PNM, ASCII P2/P3 and binary P5/P6), decoded here rather than by a third party.

What lives here: the header parser, the raster decoders, the byte-order
option of 16-bit rasters and the byte-swap check that refuses a raster read
with the wrong byte order (see :func:`sparsedepth.io.read_image`, Notes).

Imports NumPy and :mod:`sparsedepth.io.files` only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from .files import check_pixels, read_bytes

__all__ = ["check_byteorder", "read_netpbm"]

_WHITESPACE = b" \t\r\n\v\f"
_UINT16_MAX = np.iinfo(np.uint16).max
#: A 16-bit raster is refused when swapping its bytes makes it this many times smoother.
_BYTESWAP_RATIO = 4.0


class _Header(NamedTuple):
    """What a Netpbm header declares, and where its raster starts."""

    magic: bytes
    width: int
    height: int
    maxval: int
    channels: int
    end: int  # offset of the first byte after the last header token


def check_byteorder(byteorder, label: str) -> str | None:
    """``byteorder`` if it is ``'big'``, ``'little'`` or None; ``ValueError`` otherwise."""
    if byteorder not in (None, "big", "little"):
        raise ValueError(f"{label} must be 'big', 'little' or None, got {byteorder!r}.")
    return byteorder


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


def _parse_header(data: bytes, where: str) -> _Header:
    """Magic number, size and maximum sample value of a Netpbm file."""
    magic = data[:2]
    if magic not in (b"P2", b"P3", b"P5", b"P6"):
        raise ValueError(
            f"{where}: not a supported Netpbm image (magic {magic!r}); "
            "expected P2/P5 (grey) or P3/P6 (RGB)."
        )
    tokens, end = _netpbm_tokens(data, 2, 3, where)
    try:
        width, height, maxval = (int(t) for t in tokens)
    except ValueError:
        raise ValueError(f"{where}: malformed Netpbm header {tokens!r}.") from None
    if width <= 0 or height <= 0 or not 0 < maxval <= _UINT16_MAX:
        raise ValueError(
            f"{where}: invalid Netpbm header (width {width}, height {height}, maxval {maxval})."
        )
    channels = 3 if magic in (b"P3", b"P6") else 1
    return _Header(magic, width, height, maxval, channels, end)


def _binary_raster(data: bytes, header: _Header, byteorder: str | None, where: str) -> np.ndarray:
    """The flat samples of a P5/P6 raster (uint16 samples in ``byteorder``, big-endian for None)."""
    pos = header.end
    if pos >= len(data) or data[pos] not in _WHITESPACE:
        raise ValueError(f"{where}: malformed Netpbm header (no whitespace before data).")
    pos += 1  # exactly one whitespace character separates header and raster
    if header.maxval < 256:
        dtype = np.dtype(np.uint8)
    else:
        dtype = np.dtype("<u2" if byteorder == "little" else ">u2")
    count = header.width * header.height * header.channels
    expected = count * dtype.itemsize
    available = len(data) - pos
    if available != expected:
        raise ValueError(
            f"{where}: Netpbm raster has {available} bytes, expected {expected} "
            f"for {header.width}x{header.height}x{header.channels} samples of {dtype.itemsize} byte(s) "
            "(truncated file, or a multi-image file, which is not supported)."
        )
    return np.frombuffer(data, dtype=dtype, count=count, offset=pos)


def _ascii_raster(data: bytes, header: _Header, where: str) -> np.ndarray:
    """The flat samples of a P2/P3 raster as int64."""
    try:
        values = np.array(data[header.end:].split()).astype(np.int64)
    except (ValueError, OverflowError):
        raise ValueError(f"{where}: non-integer sample in ASCII Netpbm raster.") from None
    count = header.width * header.height * header.channels
    if values.size != count:
        raise ValueError(f"{where}: ASCII Netpbm raster has {values.size} samples, expected {count}.")
    if values.size and (values.min() < 0 or values.max() > header.maxval):
        raise ValueError(f"{where}: ASCII Netpbm samples outside 0..{header.maxval}.")
    return values


def read_netpbm(path: Path, byteorder: str | None, max_pixels: int | None, where: str,
                label: Callable[[str], str]) -> np.ndarray:
    """Decode a P2/P3 (ASCII) or P5/P6 (binary) Netpbm grey or RGB image as uint8 or uint16."""
    data = read_bytes(path, where)
    header = _parse_header(data, where)
    check_pixels(header.height, header.width, max_pixels, where, label("max_pixels"))
    if header.channels == 3:
        shape = (header.height, header.width, 3)
    else:
        shape = (header.height, header.width)
    out_dtype = np.uint8 if header.maxval < 256 else np.uint16
    if header.magic in (b"P5", b"P6"):
        values = _binary_raster(data, header, byteorder, where).astype(out_dtype).reshape(shape)
        if out_dtype == np.uint16 and byteorder is None:
            _check_byte_order(values, where, label("byteorder"))
        return values
    return _ascii_raster(data, header, where).astype(out_dtype).reshape(shape)
