"""Writing depth and uncertainty maps: :func:`write_depth` / :func:`depth_writer` and :func:`write_uncertainty` /
:func:`uncertainty_writer`, the format chosen from the extension.

Every write is atomic (see :func:`sparsedepth.io.files.atomic_target`).
:func:`depth_writer` makes every check and encodes the data before anything is
written, so that a caller can check several outputs before writing any.  The
formats written, and the writer of each, are those of :mod:`.formats`; this
module prepares the values (quantised for an integer format, NaN where
missing for a float one).

Imports NumPy, :mod:`.formats` and the format modules of :mod:`sparsedepth.io` only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from .depth import resolve_scale
from .files import atomic_target, check_extension
from .formats import WRITE_EXTENSIONS, FileFormat, format_of
from .stored import check_real_array

__all__ = ["depth_writer", "write_depth", "uncertainty_writer", "write_uncertainty", "png_saturated"]

_UINT16_MAX = np.iinfo(np.uint16).max


def _format(path, what: str) -> FileFormat:
    """The format of ``path``'s extension; ``ValueError`` listing :data:`~sparsedepth.io.formats.WRITE_EXTENSIONS`."""
    return format_of(check_extension(Path(path), WRITE_EXTENSIONS, what))


def _quantise_png(depth: np.ndarray, scale: float) -> np.ndarray:
    """uint16 ``round(depth * scale)``, 0 where NaN; ``ValueError`` if a value overflows or rounds to 0."""
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
        Destination; extension ``.png`` (16-bit integer), ``.tif`` /
        ``.tiff`` (single-page float32), ``.npy``, ``.npz`` (array
        ``depth``), ``.h5`` / ``.hdf5`` (dataset ``depth``) or ``.pfm``.
        Its folder must exist.
    depth : (H, W) array_like of real numbers
        Depth, NaN (or inf, or 0) where invalid.  Must be non-negative.
    scale : float or str, optional
        PNG only: stored value ``= round(depth * scale)`` (1000 stores
        millimetres from metres, 256 KITTI, 5000 TUM), or a preset name from
        :data:`DEPTH_SCALES`.  Float formats always store ``depth`` itself as
        float64 (PFM and TIFF: float32), so read them back without a scale.

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
    Invalid pixels are written as 0 in PNG, NaN in NPY/NPZ/HDF5/TIFF and
    ``inf`` in PFM (the Middlebury convention).  A TIFF is one uncompressed
    page of float32 samples (``minisblack``), depth in the unit given
    (metres from the library's readers), which :func:`read_depth` reads back
    as it is and any TIFF reader sees as 32-bit float.  The file appears only once
    complete: data go to a temporary file in the same folder that then
    replaces ``path`` with :func:`os.replace`; on failure the temporary file
    is removed and an existing ``path`` is left untouched.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from sparsedepth.io import read_depth, write_depth
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
    fmt = _format(path, "write depth")
    scale = resolve_scale(scale)
    values = _checked_map(depth, "depth")
    values[values == 0] = np.nan
    if fmt.integer:
        return fmt.write(_quantise_png(values, scale), "depth")
    return fmt.write(values, "depth")


def _checked_map(array, name: str) -> np.ndarray:
    """A 2-D, non-empty, non-negative float64 copy of ``array``, NaN where it is not finite."""
    array = check_real_array(array, name)
    if array.ndim != 2:
        raise ValueError(f"`{name}` must be a 2-D (H, W) array, got shape {array.shape}.")
    if array.size == 0:
        raise ValueError(f"`{name}` is empty (shape {array.shape}).")
    values = array.astype(np.float64)
    values[~np.isfinite(values)] = np.nan
    if np.any(values < 0):
        raise ValueError(
            f"`{name}` has negative values (min {np.nanmin(values):g}); use NaN for invalid pixels."
        )
    return values


def png_saturated(sigma, scale) -> int:
    """How many finite values of ``sigma`` a 16-bit PNG at ``scale`` stores saturated (above ``65535 / scale``)."""
    values = np.asarray(sigma, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        return int(np.count_nonzero(np.isfinite(values) & (np.rint(values * resolve_scale(scale)) > _UINT16_MAX)))


def write_uncertainty(path, sigma, *, scale=1000.0) -> None:
    """Write an uncertainty map (standard-deviation-like errors), the format chosen from the extension (atomically).

    Parameters
    ----------
    path : str or os.PathLike
        Destination, with the extensions of :func:`write_depth`.
    sigma : (H, W) array_like of real numbers
        Errors ``>= 0`` in the unit of the depth; NaN (or inf) where the
        pixel has no estimate.  ``0`` is an estimate, not a missing value.
    scale : float or str, optional
        PNG only: stored value ``= round(sigma * scale)``, as in
        :func:`write_depth`.

    Raises
    ------
    FileNotFoundError
        If the destination folder does not exist.
    ValueError
        If the extension is not supported, or ``sigma`` is not 2-D or has
        negative values.
    TypeError
        If ``sigma`` is not real-valued.

    Notes
    -----
    Float formats (``.npy``, ``.npz``, ``.h5``, ``.tif``, ``.pfm``) store
    ``sigma`` as it is, 0 included; only pixels without an estimate are
    missing (NaN, ``inf`` in PFM); the float32 formats (TIFF, PFM) store a
    value beyond the float32 range as its largest value.  A 16-bit PNG cannot hold every value and
    never fails on one: 0 means missing there, so an estimate below one unit
    (``1 / scale``) is stored as one unit, and one above the largest value
    ``65535 / scale`` is stored as that value (saturated: read it as "at
    least"; :func:`png_saturated` counts them).  Read a PNG back with
    :func:`read_depth` and the same ``scale``.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> fname = os.path.join(tempfile.mkdtemp(), "sigma.npy")
    >>> write_uncertainty(fname, np.array([[0.0, 0.25, np.nan]]))
    >>> np.load(fname)
    array([[0.  , 0.25,  nan]])
    """
    writer = uncertainty_writer(path, sigma, scale=scale)
    with atomic_target(path) as tmp:
        writer(tmp)


def uncertainty_writer(path, sigma, *, scale=1000.0) -> Callable[[Path], None]:
    """Check and encode ``sigma`` for ``path`` as :func:`write_uncertainty` does; return ``writer(tmp)``.

    Every check happens here, before anything is written (as
    :func:`depth_writer`); the returned function only writes the encoded
    data.  It cannot fail on the values: a PNG saturates (see
    :func:`write_uncertainty`).
    """
    fmt = _format(path, "write uncertainty")
    scale = resolve_scale(scale)
    values = _checked_map(sigma, "sigma")
    if fmt.integer:
        valid = ~np.isnan(values)
        stored = np.zeros(values.shape, dtype=np.uint16)
        stored[valid] = np.clip(np.rint(values[valid] * scale), 1, _UINT16_MAX).astype(np.uint16)
        return fmt.write(stored, "sigma")
    if fmt.float32:
        values = np.minimum(values, np.finfo(np.float32).max)  # NaN stays NaN
    return fmt.write(values, "sigma")
