"""Arrays stored with NumPy (``.npy``, ``.npz``) and HDF5 (``.h5``, ``.hdf5``, MATLAB v7.3 ``.mat``).

What lives here: the header-first ``.npy`` reader
(shape, dtype and pixel limit are checked before the data are read; pickled
objects are refused), the ``.npz`` member choice, and the HDF5 helpers that
:mod:`.nyu` and :func:`sparsedepth.io.read_depth` share (:func:`open_hdf5`,
:func:`hdf5_dataset`, :func:`hdf5_read`, :func:`read_hdf5_array`).  HDF5 can
make a reader open other files (external links, virtual datasets, external
raw storage); :func:`hdf5_dataset` refuses all three before anything is read,
so no file the user did not name is ever opened.  The depth and mask readers
and the writers of the NumPy and HDF5 entries of :mod:`.formats` live here too.

Imports NumPy, h5py and :mod:`.files` / :mod:`.stored` only
(:func:`sparsedepth.io.read_depth_array`, which checks the extension against the table, lives in
:mod:`.formats`).
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Callable

import h5py
import numpy as np

from .files import as_value_error, file_label, load_error, option_labels, suffix
from .stored import check_stored_array

__all__ = ["hdf5_dataset", "hdf5_read", "hdf5_writer", "load_array", "npy_writer", "npz_writer", "open_hdf5",
           "read_array_depth", "read_array_mask", "read_hdf5_depth", "read_hdf5_mask", "write_hdf5_file",
           "write_npy_file", "write_npz_file",
           "read_hdf5_array"]



def _read_npy_stream(fh, where: str, max_pixels, label: str, *, allow_bool=False) -> np.ndarray:
    """Read one ``.npy`` array from an open binary stream, checking its header first."""
    with as_value_error(where, load_error):  # bad magic, malformed header dict, pickled (object) dtype, ...
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
        else:
            raise ValueError(f"unsupported .npy format version {version}")
    check_stored_array(shape, dtype, where, max_pixels, label, allow_bool=allow_bool)
    count = int(shape[0]) * int(shape[1])
    nbytes = count * dtype.itemsize
    with as_value_error(where, load_error):  # OSError, zipfile.BadZipFile (CRC), zlib.error, ...
        data = fh.read(nbytes)
    if len(data) != nbytes:
        raise ValueError(f"could not load {where}: {len(data)} bytes of data, expected {nbytes} (truncated).")
    array = np.frombuffer(data, dtype=dtype, count=count)
    return array.reshape(shape, order="F" if fortran else "C").copy()


def _choose_npz_array(names: list[str], key: str | None, where: str, label: Callable[[str], str]) -> str:
    """The archive member to read: ``key``, else the only array, else the one called ``'depth'``."""
    if key is None:
        if len(names) == 1:
            return names[0]
        if "depth" in names:
            return "depth"
        if not names:
            raise ValueError(f"could not load {where}: the archive holds no .npy array.")
        raise ValueError(f"{where} holds several arrays {names}; choose one with {label('key')}.")
    if key not in names:
        raise ValueError(f"{label('key')}: '{key}' is not in {where}; available arrays: {names}.")
    return key


def load_array(path: Path, key: str | None, max_pixels, where: str, label: Callable[[str], str],
                *, allow_bool=False) -> tuple[np.ndarray, str]:
    """The stored (H, W) array of a ``.npy`` or ``.npz`` file and a description of its source."""
    limit = label("max_pixels")
    if suffix(path) == ".npy":
        if key is not None:
            raise ValueError(f"{label('key')} only applies to .npz archives; omit it for a .npy file.")
        try:
            with open(path, "rb") as fh:
                return _read_npy_stream(fh, where, max_pixels, limit, allow_bool=allow_bool), where
        except OSError as exc:
            raise ValueError(f"{where}: cannot be read ({exc}).") from None
    with as_value_error(where, load_error):
        archive = zipfile.ZipFile(path)
    with archive:
        members = [m for m in archive.namelist() if m.endswith(".npy")]
        names = [m[:-4] for m in members]
        key = _choose_npz_array(names, key, where, label)
        source = f"{where} array '{key}'"
        try:
            with archive.open(key + ".npy") as fh:
                return _read_npy_stream(fh, source, max_pixels, limit, allow_bool=allow_bool), source
        except (ValueError, MemoryError):
            raise
        except Exception as exc:
            raise load_error(source, exc) from exc


def open_hdf5(path: Path, where: str | None = None) -> h5py.File:
    """``path`` opened read-only with h5py; ``ValueError`` naming ``where`` if it is not readable HDF5."""
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


#: Soft links followed on one path before it is taken for a cycle.
_MAX_SOFT_LINKS = 32


def _outside_error(where: str, key: str, what: str) -> ValueError:
    """The refusal of dataset ``key``, which ``what`` says is stored outside the file."""
    return ValueError(
        f"{where} dataset '{key}' {what}; sparsedepth reads only data stored in the file itself, so that it never "
        "opens a file you did not name: store the data in the file (e.g. copy it with h5py)."
    )


def _resolve(handle: h5py.File, key: str, where: str):
    """The object at ``key`` in ``handle``, or None if there is none.

    Every link on the path is examined before it is followed: hard links and
    soft links (paths inside the same file) are followed; an external link, or
    a link of a user-defined class, is refused with a ``ValueError`` without
    being opened.
    """
    pending = [part for part in reversed(key.split("/")) if part not in ("", ".")]
    node = handle
    hops = 0
    while pending:
        if not isinstance(node, h5py.Group):
            return None
        part = pending.pop()
        link = node.get(part, getlink=True)
        if link is None:
            return None
        if isinstance(link, h5py.HardLink):
            node = node[part]
        elif isinstance(link, h5py.SoftLink):
            hops += 1
            if hops > _MAX_SOFT_LINKS:
                raise ValueError(f"{where} dataset '{key}': its path follows more than {_MAX_SOFT_LINKS} soft "
                                 "links (a cycle of links); give the dataset's own path.")
            if link.path.startswith("/"):
                node = handle
            pending += [p for p in reversed(link.path.split("/")) if p not in ("", ".")]
        elif isinstance(link, h5py.ExternalLink):
            raise _outside_error(where, key, f"is reached through an external link to '{link.path}' in file "
                                             f"'{link.filename}'")
        else:
            raise _outside_error(where, key, f"is reached through a link of a user-defined class "
                                             f"({type(link).__name__})")
    return node


def _check_storage(dset: h5py.Dataset, key: str, where: str) -> None:
    """Refuse a dataset whose data live in other files: external raw storage or a virtual dataset."""
    if dset.is_virtual:
        raise _outside_error(where, key, "is a virtual dataset (its data are read from other HDF5 files)")
    plist = dset.id.get_create_plist()
    count = plist.get_external_count()
    if count > 0:
        names = [plist.get_external(i)[0].decode(errors="replace") for i in range(count)]
        raise _outside_error(where, key, f"keeps its data in external raw file{'s' if count > 1 else ''} {names}")


def _datasets_here(handle: h5py.File, where: str) -> list[str]:
    """Names of the datasets at the top of ``handle`` that may be read (those reached without leaving the file)."""
    names = []
    for name in handle.keys():
        try:
            if isinstance(_resolve(handle, name, where), h5py.Dataset):
                names.append(name)
        except ValueError:
            continue
    return sorted(names)


def hdf5_dataset(handle: h5py.File, key: str, where, *, optional: bool = False) -> h5py.Dataset | None:
    """Dataset ``key`` of ``handle`` with its metadata readable; ``ValueError`` listing the datasets if absent.

    Nothing outside the file is opened: a path through an external link, a
    virtual dataset and a dataset with external raw storage are refused with
    a ``ValueError`` naming ``where`` and ``key`` (see :func:`_resolve`).
    With ``optional``, an absent ``key`` gives None instead.
    """
    try:
        item = _resolve(handle, key, where)
        if item is None and optional:
            return None
        if not isinstance(item, h5py.Dataset):
            raise ValueError(f"{where} has no dataset '{key}'; available datasets: {_datasets_here(handle, where)}.")
        _check_storage(item, key, where)
        item.shape, item.dtype  # noqa: B018 - reading the metadata may fail on corrupt files
    except (ValueError, MemoryError):
        raise
    except Exception as exc:
        raise load_error(f"{where} dataset '{key}'", exc) from exc
    return item


def hdf5_read(dset: h5py.Dataset, source: str, index=()):
    """``dset[index]``; a corrupt chunk or filter becomes a ``ValueError`` naming ``source``."""
    with as_value_error(source, load_error):  # OSError / RuntimeError / KeyError from corrupt chunks or filters
        return dset[index]


def read_hdf5_array(path: Path, key: str | None, max_pixels, where: str,
                     label: Callable[[str], str], *, allow_bool=False) -> tuple[np.ndarray, str]:
    """The stored (H, W) dataset ``key`` (default ``'depth'``) of an HDF5 file and a description of its source."""
    key = "depth" if key is None else key
    with open_hdf5(path, where) as handle:
        dset = hdf5_dataset(handle, key, where)
        source = f"{where} dataset '{key}'"
        check_stored_array(dset.shape, dset.dtype, source, max_pixels, label("max_pixels"),
                            allow_bool=allow_bool)
        return np.asarray(hdf5_read(dset, source)), source


def read_array_depth(path: Path, key, byteorder, max_pixels, name: str, option_names) -> tuple[np.ndarray, str]:
    """The depth reader of ``.npy`` and ``.npz`` files: the stored array (``key`` in an archive) and its source."""
    return load_array(path, key, max_pixels, file_label(path, name), option_labels(option_names))


def read_hdf5_depth(path: Path, key, byteorder, max_pixels, name: str, option_names) -> tuple[np.ndarray, str]:
    """The depth reader of HDF5 files: dataset ``key`` (default ``'depth'``) and its source."""
    return read_hdf5_array(path, key, max_pixels, file_label(path, name), option_labels(option_names))


def read_array_mask(path: Path, key, max_pixels, name: str, option_names) -> tuple[np.ndarray, str]:
    """The mask reader of ``.npy`` and ``.npz`` files: the stored array, booleans allowed, and its source."""
    return load_array(path, key, max_pixels, file_label(path, name), option_labels(option_names), allow_bool=True)


def read_hdf5_mask(path: Path, key, max_pixels, name: str, option_names) -> tuple[np.ndarray, str]:
    """The mask reader of HDF5 files: dataset ``key`` (default ``'mask'``), booleans allowed, and its source."""
    return read_hdf5_array(path, "mask" if key is None else key, max_pixels, file_label(path, name),
                           option_labels(option_names), allow_bool=True)


def write_npy_file(path: Path, values: np.ndarray) -> None:
    """Write ``values`` to ``path`` as one ``.npy`` array."""
    with open(path, "wb") as fh:
        np.save(fh, values)


def write_npz_file(path: Path, values: np.ndarray) -> None:
    """Write ``values`` to ``path`` as the array ``depth`` of a compressed ``.npz`` archive."""
    with open(path, "wb") as fh:
        np.savez_compressed(fh, depth=values)


def write_hdf5_file(path: Path, values: np.ndarray) -> None:
    """Write ``values`` to ``path`` as the gzip-compressed dataset ``depth`` of a new HDF5 file."""
    with h5py.File(path, "w") as handle:
        handle.create_dataset("depth", data=values, compression="gzip")


def npy_writer(values: np.ndarray, name: str) -> Callable[[Path], None]:
    """The writer of the ``.npy`` format: float64 ``values`` as they are (NaN where missing)."""
    return lambda tmp: write_npy_file(tmp, values)


def npz_writer(values: np.ndarray, name: str) -> Callable[[Path], None]:
    """The writer of the ``.npz`` format: float64 ``values`` as the array ``depth``."""
    return lambda tmp: write_npz_file(tmp, values)


def hdf5_writer(values: np.ndarray, name: str) -> Callable[[Path], None]:
    """The writer of the HDF5 format: float64 ``values`` as the dataset ``depth``."""
    return lambda tmp: write_hdf5_file(tmp, values)
