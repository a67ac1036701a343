"""Stored samples to depth: the dtype and shape rules every format's content must meet.

What lives here: which dtypes count as real numbers (:func:`is_real_dtype`,
:func:`check_real_array`), the checks made from an array header before its
data are read (:func:`check_stored_array`) and the conversion of a stored
2-D array to float64 depth with NaN for invalid pixels (:func:`as_depth`).

Imports NumPy and :mod:`sparsedepth.io.files` only.
"""

from __future__ import annotations

import numpy as np

from .files import check_pixels

__all__ = ["as_depth", "check_real_array", "check_stored_array", "is_real_dtype"]


def is_real_dtype(dtype) -> bool:
    """Integer or float (not bool, complex, datetime/timedelta, strings or records)."""
    return np.dtype(dtype).kind in "iuf"


def check_real_array(array, name: str) -> np.ndarray:
    """``array`` as an ndarray; ``TypeError`` naming ``name`` unless it holds integers or floats."""
    array = np.asarray(array)
    if array.dtype == bool or not (
        np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)
    ):
        raise TypeError(
            f"`{name}` must hold real numbers (integer or float), got dtype {array.dtype}."
        )
    return array


def as_depth(array, source: str, invalid_values=()) -> np.ndarray:
    """Convert a stored 2-D depth array to float64 with NaN for 0/inf/NaN and ``invalid_values``.

    Raises ValueError for a wrong shape, a non-numeric dtype or negative values.
    """
    array = np.asarray(array)
    if array.ndim != 2:
        raise ValueError(f"{source}: expected a 2-D (H, W) depth map, got shape {array.shape}.")
    if not is_real_dtype(array.dtype):
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


def check_stored_array(shape, dtype, source: str, max_pixels, label: str, *, allow_bool=False) -> None:
    """Shape and dtype checks made from a header, before the data are read."""
    dtype = np.dtype(dtype)
    if dtype.hasobject:
        raise ValueError(
            f"could not load {source}: it holds Python objects (dtype {dtype}); pickled data are refused."
        )
    if len(shape) != 2:
        raise ValueError(f"{source}: expected a 2-D (H, W) depth map, got shape {tuple(shape)}.")
    if not (is_real_dtype(dtype) or (allow_bool and dtype == bool)):
        kinds = "boolean, integer or float" if allow_bool else "integer or float depth"
        raise ValueError(f"{source}: expected {kinds}, got dtype {dtype}.")
    check_pixels(int(shape[0]), int(shape[1]), max_pixels, source, label)
