"""NYU Depth V2 files: the labeled set ``nyu_depth_v2_labeled.mat`` and the preprocessed one-frame ``.h5`` layout.

What lives here: :class:`NYUDepthV2Labeled` (lazy, one frame read at a time)
and :func:`read_nyu_h5`.

Imports NumPy, h5py, :mod:`sparsedepth._validation` and :mod:`.files` /
:mod:`.stored` / :mod:`.arrays` only.
"""

from __future__ import annotations

import operator

import numpy as np

from .._validation import check_input_file
from .arrays import hdf5_dataset, hdf5_read, open_hdf5
from .files import MAX_PIXELS, check_max_pixels, file_label, load_error
from .stored import as_depth, check_stored_array

__all__ = ["NYUDepthV2Labeled", "read_nyu_h5"]


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
        ``depth``, their shapes or dtypes do not match the layout above, or
        one of them is stored outside the file (an external link, a virtual
        dataset or external raw storage, which are never followed).
    """
    path = check_input_file(path, name=name)
    where = file_label(path, name)
    max_pixels = check_max_pixels(max_pixels, "`max_pixels`")
    with open_hdf5(path, where) as handle:
        rgb = hdf5_dataset(handle, "rgb", where)
        dset = hdf5_dataset(handle, "depth", where)
        if rgb.ndim != 3 or rgb.shape[0] != 3 or rgb.dtype != np.uint8:
            raise ValueError(
                f"{where}: dataset 'rgb' must be (3, H, W) uint8, got {rgb.shape} {rgb.dtype}."
            )
        if dset.shape != rgb.shape[1:]:
            raise ValueError(
                f"{where}: dataset 'depth' has shape {dset.shape}, expected {rgb.shape[1:]} "
                "to match 'rgb'."
            )
        check_stored_array(dset.shape, dset.dtype, f"{where} dataset 'depth'", max_pixels, "`max_pixels`")
        image = np.ascontiguousarray(np.transpose(hdf5_read(rgb, f"{where} dataset 'rgb'"), (1, 2, 0)))
        depth = as_depth(hdf5_read(dset, f"{where} dataset 'depth'"), f"{where} dataset 'depth'")
    return image, depth


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
        If ``path`` is not a regular file, not HDF5, the datasets are
        missing or inconsistent, or one of them is stored outside the file
        (an external link, a virtual dataset or external raw storage, which
        are never followed).

    Examples
    --------
    >>> with NYUDepthV2Labeled("nyu_depth_v2_labeled.mat") as nyu:  # doctest: +SKIP
    ...     image, depth, raw = nyu[0]
    ...     len(nyu)
    1449
    """

    def __init__(self, path, *, name: str = "path"):
        self.path = check_input_file(path, name=name)
        self._where = file_label(self.path, name)
        self._file = open_hdf5(self.path, self._where)
        try:
            self._images = hdf5_dataset(self._file, "images", self._where)
            self._depths = hdf5_dataset(self._file, "depths", self._where)
            self._raw = hdf5_dataset(self._file, "rawDepths", self._where, optional=True)
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
            raise load_error(self._where, exc) from exc

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
        """``index`` as a non-negative frame number (negative counts from the end)."""
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
        image = np.ascontiguousarray(hdf5_read(self._images, f"{self._where} images[{i}]", i).transpose(2, 1, 0))
        depth = as_depth(hdf5_read(self._depths, f"{self._where} depths[{i}]", i).T, f"{self._where} depths[{i}]")
        raw = None
        if self._raw is not None:
            source = f"{self._where} rawDepths[{i}]"
            raw = as_depth(hdf5_read(self._raw, source, i).T, source)
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
