"""Input checks shared by the whole package: one rule per concept, one place for every message.

Every public function checks its arguments here before it works, so the same
concept is refused with the same exception and message everywhere:

- numbers: :func:`is_int`, :func:`is_real`, :func:`check_count` (an integer
  ``>= 1``), :func:`check_positive_real` / :func:`check_nonnegative_real`
  (algorithm parameters: weights, tolerances, ``alpha``, ``kappa``),
  :func:`check_positive_finite` (physical quantities: depth scales, focal
  lengths, baselines); a non-number (a numeric string included) is a
  ``TypeError``, a number out of range a ``ValueError``;
- grid shapes: :func:`check_grid_shape`, :func:`check_same_shape`;
- images, depth and masks: :func:`as_float_image`, :func:`as_depth_and_mask`,
  :func:`check_observed_depth` (every pixel a mask marks as observed holds a
  finite depth ``> 0``), :func:`check_bool_mask`;
- sparse operators on a grid: :func:`as_grid_operator`;
- paths and frame indices: :func:`check_input_file` (a regular file, checked
  with :func:`os.stat` only), :func:`check_folder`, :func:`check_index`, and
  :func:`argument_label` (how an argument is named in a message: a
  command-line flag as typed, a Python name in backticks);
- options passed on as keywords: :func:`check_option_names` (a misspelt key
  is a ``ValueError`` naming it and listing the valid ones);
- colours: :func:`check_rgb_colour` (three integers in [0, 255]).
- camera intrinsics: :func:`check_intrinsics` (``(fx, fy, cx, cy)`` in
  pixels, positive focal lengths).

May import NumPy, SciPy and the standard library; nothing of the package (the
rule for :class:`~sparsedepth.Weights` is :func:`sparsedepth.objective.weights.check_weights`).
"""

from __future__ import annotations

import math
import numbers
import operator
import os
import stat
from pathlib import Path

import numpy as np

__all__ = [
    "is_int",
    "is_real",
    "check_count",
    "check_nonnegative_count",
    "check_positive_real",
    "check_nonnegative_real",
    "check_positive_finite",
    "check_grid_shape",
    "check_same_shape",
    "as_float_image",
    "as_depth_and_mask",
    "check_observed_depth",
    "check_bool_mask",
    "as_grid_operator",
    "argument_label",
    "check_input_file",
    "check_folder",
    "check_index",
    "check_option_names",
    "check_rgb_colour",
    "check_intrinsics",
]


# Numbers

def is_int(value) -> bool:
    """True for a Python or NumPy integer that is not a bool."""
    return isinstance(value, (numbers.Integral, np.integer)) and not isinstance(value, (bool, np.bool_))


def is_real(value) -> bool:
    """True for a Python or NumPy real number (integers included) that is not a bool."""
    return isinstance(value, (numbers.Real, np.floating, np.integer)) and not isinstance(value, (bool, np.bool_))


def check_count(value, *, name: str) -> int:
    """Return ``value`` as an int; ``ValueError`` unless it is an integer (not a bool) ``>= 1``."""
    if not is_int(value) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return int(value)


def check_nonnegative_count(value, *, name: str) -> int:
    """Return ``value`` as an int; ``ValueError`` unless it is an integer (not a bool) ``>= 0``."""
    if not is_int(value) or value < 0:
        raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
    return int(value)


def _real_number(value, name: str) -> float:
    """``value`` as a float; ``TypeError`` unless it is a real number (a 0-d array of one counts, a bool does not)."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if not is_real(value):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__} {value!r}")
    return float(value)


def check_positive_real(value, *, name: str) -> float:
    """Return ``value`` as a float: ``TypeError`` unless a real number, ``ValueError`` unless finite and ``> 0``."""
    number = _real_number(value, name)
    if not np.isfinite(number) or number <= 0:
        raise ValueError(f"{name} must be finite and > 0, got {number!r}")
    return number


def check_nonnegative_real(value, *, name: str) -> float:
    """Return ``value`` as a float: ``TypeError`` unless a real number, ``ValueError`` unless finite and ``>= 0``."""
    number = _real_number(value, name)
    if not np.isfinite(number) or number < 0:
        raise ValueError(f"{name} must be finite and >= 0, got {number!r}")
    return number


def check_positive_finite(value, *, label: str, expected: str = "a real number") -> float:
    """Return ``value`` as a float: ``TypeError`` unless it is a real number, ``ValueError`` unless finite and > 0.

    ``label`` is the argument as it appears in messages (see
    :func:`argument_label`); ``expected`` ends the type message
    "<label> must be <expected>" (e.g. "a positive number or a preset name"
    where a preset name is also accepted).  The rule for depth scales and
    every other strictly positive quantity (focal length, baseline).
    """
    if not is_real(value):
        raise TypeError(f"{label} must be {expected}, got {type(value).__name__}.")
    number = float(value)
    if not math.isfinite(number) or number <= 0:
        raise ValueError(f"{label} must be a finite positive number, got {value!r}.")
    return number


# Grid shapes

def check_grid_shape(shape, *, name: str = "shape") -> tuple[int, int]:
    """Return ``shape`` as ``(H, W)`` of Python ints; ``ValueError`` unless it is two integers ``>= 1``."""
    try:
        values = tuple(shape)
    except TypeError:
        raise ValueError(f"{name} must be a pair (H, W) of integers >= 1, got {shape!r}") from None
    if len(values) != 2 or not all(is_int(v) for v in values) or min(values) < 1:
        raise ValueError(f"{name} must be a pair (H, W) of integers >= 1, got {shape!r}")
    return int(values[0]), int(values[1])


def check_same_shape(shape_a, shape_b, name_a: str, name_b: str) -> None:
    if tuple(shape_a) != tuple(shape_b):
        raise ValueError(f"{name_a} has shape {tuple(shape_a)} but {name_b} has shape {tuple(shape_b)}; they must match")


# Images, depth and masks

def as_float_image(image, *, name: str = "image", dtype=np.float64) -> np.ndarray:
    """Return ``image`` as ``(H, W, C)`` floats in [0, 1] of ``dtype`` (float64 or float32; a new array).

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
        out = arr.astype(dtype)
        out /= 255.0
    elif arr.dtype == np.uint16:
        out = arr.astype(dtype)
        out /= 65535.0
    elif np.issubdtype(arr.dtype, np.floating):
        out = arr.astype(dtype)
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


def as_depth_and_mask(sparse_depth, mask=None, *, name: str = "sparse_depth"):
    """Return ``(depth, mask)``: float64 ``(H, W)`` depth with 0 where unobserved, bool mask.

    Observed depth is finite and ``> 0``: 0 and NaN mean "no measurement".
    Without ``mask``, the observed pixels are those; a negative value is an
    error.  With ``mask`` (True where depth is observed), every pixel it
    marks must hold such a depth: a 0, a negative, a NaN or an infinite value
    there is an error (:func:`check_observed_depth`).

    Raises
    ------
    ValueError
        For a depth that is not a numeric 2-D array, a mask of another shape
        or not boolean (or 0/1), a negative depth without mask, a masked pixel
        without a depth, or no observed pixel.
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
        check_observed_depth(depth[observed], name=name)
    if not observed.any():
        raise ValueError(f"{name} has no observed pixel (no finite value > 0 or nothing in mask); nothing to complete from")
    depth[~observed] = 0.0
    return depth, observed


def check_observed_depth(values, *, name: str = "sparse_depth", mask_name: str = "mask") -> None:
    """``ValueError`` unless every depth in ``values`` (those ``mask_name`` marks as observed) is finite and ``> 0``.

    The message counts the zeros, negatives and NaN/infinite values among
    them.  When they are most of the marked pixels, the mask is most likely
    flipped: scikit-image's inpainting masks (``skimage.restoration``) are
    True where depth is *missing*; the message says so and gives the fix
    (``~mask``).
    """
    values = np.asarray(values, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        zero, negative, nonfinite = values == 0, values < 0, ~np.isfinite(values)
    bad = int(np.count_nonzero(zero | negative | nonfinite))
    if not bad:
        return
    kinds = []
    if zero.any():
        kinds.append(f"0 at {int(np.count_nonzero(zero)):,}")
    if negative.any():
        count = int(np.count_nonzero(negative))
        kinds.append(f"{count:,} negative observed value{'s' if count > 1 else ''} (min {values[negative].min():g})")
    if nonfinite.any():
        count = int(np.count_nonzero(nonfinite))
        kinds.append(f"NaN or infinite values at {count:,} observed pixel{'s' if count > 1 else ''}")
    if 2 * bad > values.size:
        fix = (f"{mask_name} must be True where depth is observed (scikit-image's inpainting masks mean the "
               f"opposite: pass ~{mask_name})")
    else:
        fix = (f"depth must be finite and > 0 where {mask_name} is True: leave those pixels out of {mask_name}, or "
               f"mark missing depth with 0 or NaN and pass no {mask_name}")
    raise ValueError(f"{name} has no depth at {bad:,} of the {values.size:,} pixels {mask_name} marks as observed "
                     f"({'; '.join(kinds)}): {fix}")


def check_bool_mask(mask, shape, *, name: str = "mask", shape_name: str = "depth") -> np.ndarray:
    """Return ``mask`` as an ndarray; ``ValueError`` unless it is boolean and of ``shape`` (that of ``shape_name``)."""
    array = np.asarray(mask)
    if array.dtype != np.bool_:
        raise ValueError(f"{name} must be a boolean array, got dtype {array.dtype}")
    check_same_shape(array.shape, shape, name, shape_name)
    return array


# Sparse operators on a grid

def as_grid_operator(A, shape, *, name: str = "A"):
    """Return ``(A, (H, W))``: ``A`` as canonical float64 CSR (no copy when it already is) and the grid shape.

    ``TypeError`` unless ``A`` is a real scipy.sparse matrix or array;
    ``ValueError`` unless ``shape`` is a grid shape (see
    :func:`check_grid_shape`) and ``A`` is ``(H W, H W)``.
    """
    import scipy.sparse as sp  # only this rule needs SciPy

    if not sp.issparse(A):
        raise TypeError(f"`{name}` must be a scipy.sparse matrix or array, got {type(A).__name__}.")
    h, w = check_grid_shape(shape)
    if A.shape != (h * w, h * w):
        raise ValueError(
            f"`{name}` has shape {A.shape} but a grid of shape {(h, w)} needs "
            f"({h * w}, {h * w}); pass the (H, W) the pixels were flattened from."
        )
    if np.iscomplexobj(A.data):
        raise TypeError(f"`{name}` must be real; complex operators are not supported.")
    if A.format != "csr" or A.dtype != np.float64:
        A = sp.csr_array(A, dtype=np.float64)
    if not A.has_canonical_format:
        A = A.copy()
        A.sum_duplicates()
    return A, (h, w)


# Paths and frame indices

def argument_label(name: str) -> str:
    """How an argument appears in messages: command-line flags as typed (``--depth``), Python names in backticks.

    A name already labelled (in backticks) is returned as it is.
    """
    return name if name.startswith(("-", "`")) else f"`{name}`"


def stat_path(path, *, name: str = "path", missing: str = "file") -> tuple[Path, int]:
    """``(Path(path), st_mode)`` of an existing path, from :func:`os.stat` alone (nothing is opened).

    ``name`` labels the path in messages (see :func:`argument_label`); ``missing`` says what was expected in the
    message of a missing path (``"file"``, ``"COLMAP model folder"``).  Raises ``TypeError`` for a ``name`` that
    is not a non-empty str or a ``path`` that is not a str or os.PathLike, ``FileNotFoundError`` for a missing path
    and ``ValueError`` for one that cannot be examined (permission, embedded NUL, name too long, ...).
    """
    if not isinstance(name, str) or not name:
        raise TypeError(f"`name` must be a non-empty str (the label of the path in messages), got {name!r}.")
    label = argument_label(name)
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{label} must be a str or os.PathLike, got {type(path).__name__}.")
    path = Path(path)
    try:
        return path, os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        raise FileNotFoundError(f"{label}: no such {missing}: '{path}'.") from None
    except (OSError, ValueError) as exc:
        raise ValueError(f"{label} '{path}': cannot be accessed ({exc}).") from None


def check_input_file(path, *, name: str = "path") -> Path:
    """Return ``path`` as a :class:`~pathlib.Path` after checking that it names an existing regular file.

    ``name`` labels the path in messages (see :func:`argument_label`).  Only
    :func:`os.stat` is called, so a FIFO or a device is refused without being
    opened (opening a FIFO blocks until a writer appears).  Raises
    ``TypeError`` for a ``name`` that is not a non-empty str or a ``path``
    that is not a str or os.PathLike, ``FileNotFoundError`` for a missing
    file and ``ValueError`` for a path that cannot be examined or is not a
    regular file (directory, FIFO, device, socket).
    """
    path, mode = stat_path(path, name=name, missing="file")
    label = argument_label(name)
    if not stat.S_ISREG(mode):
        kind = (
            "a directory" if stat.S_ISDIR(mode)
            else "a FIFO (named pipe)" if stat.S_ISFIFO(mode)
            else "a character device" if stat.S_ISCHR(mode)
            else "a block device" if stat.S_ISBLK(mode)
            else "a socket" if stat.S_ISSOCK(mode)
            else "not a regular file"
        )
        raise ValueError(f"{label} '{path}' is {kind}; expected a regular file.")
    return path


def check_folder(folder, name: str) -> Path:
    """Return ``folder`` as a :class:`~pathlib.Path` of an existing directory.

    ``TypeError`` unless it is a ``str`` or ``os.PathLike``; ``FileNotFoundError`` unless it is a directory.
    """
    if not isinstance(folder, (str, os.PathLike)):
        raise TypeError(f"{name} must be a str or os.PathLike, got {type(folder).__name__}")
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"{name} '{folder}' does not exist or is not a directory")
    return folder


def check_index(index, count: int) -> int:
    """Return frame ``index`` of ``count`` frames as ``0 <= i < count`` (negative counts from the end).

    ``TypeError`` unless it is an integer; ``IndexError`` outside ``-count <= index < count``.
    """
    try:
        index = operator.index(index)
    except TypeError:
        raise TypeError(f"frame index must be an integer, got {type(index).__name__}.") from None
    if not -count <= index < count:
        raise IndexError(f"frame index {index} out of range for {count} frames.")
    return index % count


# Options passed on as keywords

def check_option_names(options, valid, *, where: str) -> None:
    """``ValueError`` naming the first key of ``options`` that is not in ``valid``, with the valid keys listed.

    ``where`` says whose options they are (e.g. ``"colorization_baseline"``).
    """
    unknown = [key for key in options if key not in valid]
    if unknown:
        raise ValueError(f"unknown option {unknown[0]!r} for {where}; valid options: {', '.join(sorted(valid))}")


# --- colours

def _intrinsics_of_matrix(matrix, label) -> list:
    """``[fx, fy, cx, cy]`` of a 3x3 pinhole matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``."""
    try:
        K = np.asarray(matrix, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"{label} must be a 3x3 matrix of real numbers, got {matrix!r:.80}.") from None
    if K.shape != (3, 3):
        raise TypeError(f"{label} must be four numbers (fx, fy, cx, cy) or a 3x3 matrix K, got shape {K.shape}.")
    if not np.all(np.isfinite(K)):
        raise ValueError(f"{label}: the matrix K must be finite, got {K.tolist()}.")
    if K[0, 1] != 0 or K[1, 0] != 0:
        raise ValueError(f"{label}: the matrix K has a skew or shear term ({K[0, 1]:g}, {K[1, 0]:g}); only "
                         "pinhole intrinsics [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] are supported.")
    if not np.allclose(K[2], (0.0, 0.0, 1.0), rtol=0, atol=1e-12):
        raise ValueError(f"{label}: the last row of K must be [0, 0, 1], got {K[2].tolist()} (divide K by K[2, 2] "
                         "if it is a scaled pinhole matrix).")
    return [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]


def check_rgb_colour(colour, *, name: str = "colour") -> tuple[int, int, int]:
    """Return an 8-bit sRGB colour as three Python ints.

    ``TypeError`` unless ``colour`` is a sequence of real numbers;
    ``ValueError`` unless there are three and each is an integer in [0, 255].
    """
    try:
        values = tuple(colour)
    except TypeError:
        raise TypeError(f"{name} must be a sequence of 3 integers in [0, 255] (R, G, B), got "
                        f"{type(colour).__name__}") from None
    if not all(is_real(v) for v in values):
        raise TypeError(f"{name} must be 3 integers in [0, 255] (R, G, B), got {colour!r}")
    if len(values) != 3 or not all(float(v).is_integer() and 0 <= v <= 255 for v in values):
        raise ValueError(f"{name} must be 3 integers in [0, 255] (R, G, B), got {colour!r}; e.g. (128, 128, 128)")
    return int(values[0]), int(values[1]), int(values[2])


# --- camera intrinsics

def check_intrinsics(intrinsics, *, name: str = "intrinsics") -> tuple[float, float, float, float]:
    """Return pinhole intrinsics ``(fx, fy, cx, cy)`` in pixels as four Python floats.

    ``intrinsics`` is any of: a sequence ``(fx, fy, cx, cy)``; a 3x3 matrix ``K = [[fx, 0, cx], [0, fy, cy], [0, 0,
    1]]`` (nested sequences or an array); an object with attributes ``fx``, ``fy``, ``cx``, ``cy``; an object with an
    ``intrinsic_matrix`` attribute holding ``K`` (Open3D's ``PinholeCameraIntrinsic``; no Open3D import here).
    ``TypeError`` for anything else; ``ValueError`` for a matrix with a skew term or a last row other than ``[0, 0,
    1]``, and unless the focal lengths ``fx``, ``fy`` are finite and positive and the principal point ``cx``, ``cy``
    is finite.
    """
    label = argument_label(name)
    if hasattr(intrinsics, "intrinsic_matrix"):
        intrinsics = np.asarray(intrinsics.intrinsic_matrix, dtype=float)
    elif all(hasattr(intrinsics, part) for part in ("fx", "fy", "cx", "cy")):
        intrinsics = [getattr(intrinsics, part) for part in ("fx", "fy", "cx", "cy")]
    if isinstance(intrinsics, (str, bytes)) or not hasattr(intrinsics, "__len__"):
        raise TypeError(f"{label} must be a sequence (fx, fy, cx, cy) of four numbers in pixels or a 3x3 matrix K, "
                        f"got {type(intrinsics).__name__}.")
    if np.ndim(intrinsics) == 2 and not isinstance(intrinsics, (str, bytes)):
        values = _intrinsics_of_matrix(intrinsics, label)
    else:
        values = list(intrinsics)
    if len(values) != 4 or not all(is_real(v) for v in values):
        raise TypeError(f"{label} must be four real numbers (fx, fy, cx, cy) in pixels or a 3x3 matrix K, got "
                        f"{len(values)} item(s) ({intrinsics!r:.80}).")
    fx, fy, cx, cy = (float(v) for v in values)
    for part, value in (("fx", fx), ("fy", fy)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{label}: the focal length {part} must be a finite positive number of pixels, "
                             f"got {value!r}.")
    for part, value in (("cx", cx), ("cy", cy)):
        if not math.isfinite(value):
            raise ValueError(f"{label}: the principal point {part} must be a finite number of pixels, got {value!r}.")
    return fx, fy, cx, cy
