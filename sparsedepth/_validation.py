"""Input checks shared by the public functions (one place for every message).

One rule per concept: image, depth and mask, grid shape, numbers.  May import
NumPy (and, inside :func:`check_weights`, :class:`sparsedepth.Weights`).
"""

from __future__ import annotations

import numbers

import numpy as np

__all__ = ["as_float_image", "as_depth_and_mask", "check_same_shape", "check_weights", "check_grid_shape",
           "is_int", "is_real"]


def is_int(value) -> bool:
    """True for a Python or NumPy integer that is not a bool."""
    return isinstance(value, (numbers.Integral, np.integer)) and not isinstance(value, (bool, np.bool_))


def is_real(value) -> bool:
    """True for a Python or NumPy real number (integers included) that is not a bool."""
    return isinstance(value, (numbers.Real, np.floating, np.integer)) and not isinstance(value, (bool, np.bool_))


def check_grid_shape(shape, *, name: str = "shape") -> tuple[int, int]:
    """Return ``shape`` as ``(H, W)`` of Python ints; ``ValueError`` unless it is two integers ``>= 1``."""
    try:
        values = tuple(shape)
    except TypeError:
        raise ValueError(f"{name} must be a pair (H, W) of integers >= 1, got {shape!r}") from None
    if len(values) != 2 or not all(is_int(v) for v in values) or min(values) < 1:
        raise ValueError(f"{name} must be a pair (H, W) of integers >= 1, got {shape!r}")
    return int(values[0]), int(values[1])


def check_weights(weights, *, name: str = "weights") -> None:
    """Raise ``TypeError`` unless ``weights`` is a :class:`sparsedepth.Weights`."""
    from .objective.weights import Weights

    if not isinstance(weights, Weights):
        hint = "use sd.Weights(**d)" if isinstance(weights, dict) else "use sd.Weights(alpha=..., gamma=...)"
        raise TypeError(f"{name} must be a sparsedepth.Weights; got {type(weights).__name__}: {hint}")


def as_float_image(image, *, name: str = "image") -> np.ndarray:
    """Return ``image`` as float64 ``(H, W, C)`` in [0, 1] (a new array).

    uint8 is divided by 255, uint16 by 65535; floats must already lie in
    [0, 1].  Grey images ``(H, W)`` get a channel axis.
    """
    arr = np.asarray(image)
    if arr.ndim not in (2, 3):
        raise ValueError(
            f"{name} must have shape (H, W) or (H, W, C); got {arr.ndim} dimensions with shape {arr.shape}"
        )
    if arr.ndim == 3 and arr.shape[2] not in (1, 3, 4):
        raise ValueError(
            f"{name} has shape {arr.shape}: the last axis must hold 1, 3 or 4 channels (channels last)"
        )
    if arr.ndim == 3 and arr.shape[2] == 4:
        arr = arr[..., :3]  # drop alpha
    if arr.size == 0:
        raise ValueError(f"{name} is empty (shape {arr.shape})")
    if arr.dtype == np.uint8:
        out = arr.astype(np.float64) / 255.0
    elif arr.dtype == np.uint16:
        out = arr.astype(np.float64) / 65535.0
    elif np.issubdtype(arr.dtype, np.floating):
        out = arr.astype(np.float64)
        if not np.all(np.isfinite(out)):
            raise ValueError(f"{name} contains NaN or infinite values; fill or mask them before completing")
        lo, hi = float(out.min()), float(out.max())
        if lo < 0.0 or hi > 1.0:
            raise ValueError(
                f"float {name} must lie in [0, 1], got values in [{lo:g}, {hi:g}]; "
                "pass uint8/uint16 or divide by the maximum"
            )
    else:
        raise ValueError(f"{name} dtype must be uint8, uint16 or float, got {arr.dtype}")
    if out.ndim == 2:
        out = out[:, :, None]
    return out


def check_same_shape(shape_a, shape_b, name_a: str, name_b: str) -> None:
    if tuple(shape_a) != tuple(shape_b):
        raise ValueError(f"{name_a} has shape {tuple(shape_a)} but {name_b} has shape {tuple(shape_b)}; they must match")


def as_depth_and_mask(sparse_depth, mask=None, *, name: str = "sparse_depth"):
    """Return ``(depth, mask)``: float64 ``(H, W)`` depth with 0 where unobserved, bool mask.

    Without ``mask``, observed means finite and ``> 0`` (0 and NaN mean "no
    measurement").  With ``mask``, every masked value must be finite and ``>= 0``.
    """
    depth = np.asarray(sparse_depth)
    if depth.ndim != 2:
        raise ValueError(f"{name} must be a 2-D (H, W) array, got shape {depth.shape}")
    if not (np.issubdtype(depth.dtype, np.floating) or np.issubdtype(depth.dtype, np.integer)):
        raise ValueError(f"{name} dtype must be numeric, got {depth.dtype}")
    depth = depth.astype(np.float64)  # copy: the caller's array is never modified
    if mask is None:
        with np.errstate(invalid="ignore"):
            negative = depth < 0
            observed = np.isfinite(depth) & (depth > 0)
        if negative.any():
            raise ValueError(
                f"{name} has {int(np.count_nonzero(negative))} negative values (min {depth[negative].min():g}) and no "
                "mask; depth must be >= 0: mark missing depth with 0 or NaN, or pass mask (True where observed)"
            )
    else:
        observed = np.asarray(mask)
        check_same_shape(observed.shape, depth.shape, "mask", name)
        if observed.dtype != bool:
            if not np.all(np.isin(observed, (0, 1))):
                raise ValueError("mask must be boolean (or 0/1), with True where depth is observed")
            observed = observed.astype(bool)
        else:
            observed = observed.copy()
        values = depth[observed]
        if not np.all(np.isfinite(values)):
            raise ValueError(f"{name} has NaN or infinite values at {int(np.sum(~np.isfinite(values)))} observed (masked) pixels")
    if not observed.any():
        raise ValueError(f"{name} has no observed pixel (no finite value > 0 or nothing in mask); nothing to complete from")
    obs_values = depth[observed]
    if np.any(obs_values < 0):
        raise ValueError(
            f"{name} has {int(np.sum(obs_values < 0))} negative observed values (min {obs_values.min():g}); depth must be >= 0"
        )
    depth[~observed] = 0.0
    return depth, observed


# --- positive number
__all__ += ["check_positive_real"]


def check_positive_real(value, *, name: str) -> float:
    """Return ``value`` as a float; ``ValueError`` unless it converts to a finite number ``> 0``."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, got {value!r}") from None
    if not np.isfinite(number) or number <= 0:
        raise ValueError(f"{name} must be finite and > 0, got {number!r}")
    return number


# --- non-negative number
__all__ += ["check_nonnegative_real"]


def check_nonnegative_real(value, *, name: str) -> float:
    """Return ``value`` as a float; ``ValueError`` unless it converts to a finite number ``>= 0``."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(number) or number < 0:
        raise ValueError(f"{name} must be finite and >= 0, got {number!r}")
    return number


# --- count (an integer >= 1)
__all__ += ["check_count"]


def check_count(value, *, name: str) -> int:
    """Return ``value`` as an int; ``ValueError`` unless it is an integer (not a bool) ``>= 1``."""
    if not is_int(value) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return int(value)


# --- boolean mask
__all__ += ["check_bool_mask"]


def check_bool_mask(mask, shape, *, name: str = "mask", shape_name: str = "depth") -> np.ndarray:
    """Return ``mask`` as an ndarray; ``ValueError`` unless it is boolean and of ``shape`` (that of ``shape_name``)."""
    array = np.asarray(mask)
    if array.dtype != np.bool_:
        raise ValueError(f"{name} must be a boolean array, got dtype {array.dtype}")
    check_same_shape(array.shape, shape, name, shape_name)
    return array
