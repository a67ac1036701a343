"""Frames that need no external folder: the shipped samples, scikit-image's Motorcycle and NYU labeled files.

What lives here: :func:`load_motorcycle` (the Middlebury 2014 pair shipped
with scikit-image), :func:`list_embedded_frames` and
:func:`load_embedded_frame` (the small frames in ``sparsedepth/data``,
checked against their sha256), and :func:`load_nyu_labeled` (one frame of a
NYU Depth V2 labeled ``.mat`` file the caller names).

The shipped files are found with ``importlib.resources`` in the
``sparsedepth`` package itself (its ``data`` folder), not in this subpackage.

Imports NumPy, scikit-image, :mod:`sparsedepth.io`, :mod:`sparsedepth._validation` and :mod:`.frame` only.
"""

from __future__ import annotations

import hashlib
from importlib import resources

import numpy as np

from .._validation import check_index
from ..io import NYUDepthV2Labeled
from .frame import MMSEG_NAME, MOTORCYCLE_CALIBRATION, NYU_RGB_INTRINSICS, Frame, nyu_mmseg_frame

__all__ = ["list_embedded_frames", "load_embedded_frame", "load_motorcycle", "load_nyu_labeled"]


def load_motorcycle() -> Frame:
    """Middlebury 2014 *Motorcycle* (left view) with metric ground-truth depth.

    Uses the quarter-resolution pair shipped with scikit-image
    (:func:`skimage.data.stereo_motorcycle`) and its calibration, given in that
    function's docstring: focal length 994.978 px, principal point
    (311.193, 254.877) px, ``doffs`` 31.086 px, baseline 193.001 mm
    (:data:`MOTORCYCLE_CALIBRATION`).

    Returns
    -------
    Frame
        ``name="middlebury2014/motorcycle"``, image (500, 741, 3) uint8,
        ``depth`` in metres (about 2.1-5.0 m), NaN where the disparity has no
        ground truth (about 7 % of the pixels).

    Notes
    -----
    .. math:: Z\\,[\\mathrm{m}] = \\frac{f \\, B}{1000\\,(d + d_\\mathrm{offs})}

    References
    ----------
    .. [1] D. Scharstein, H. Hirschmueller, Y. Kitajima, G. Krathwohl, N. Nesic,
       X. Wang, P. Westling, "High-resolution stereo datasets with
       subpixel-accurate ground truth", GCPR 2014.

    Examples
    --------
    >>> frame = load_motorcycle()
    >>> frame.shape
    (500, 741)
    """
    import skimage
    import skimage.data

    left, _right, disparity = skimage.data.stereo_motorcycle()
    return Frame(
        name="middlebury2014/motorcycle",
        dataset="Middlebury 2014",
        image=np.ascontiguousarray(left),
        depth=MOTORCYCLE_CALIBRATION.depth_from_disparity(disparity),
        units="m",
        source=f"skimage.data.stereo_motorcycle() (scikit-image {skimage.__version__})",
        intrinsics=MOTORCYCLE_CALIBRATION.intrinsics,
    )


def load_nyu_labeled(path, index: int) -> Frame:
    """Frame ``index`` of the NYU Depth V2 labeled set (``nyu_depth_v2_labeled.mat``).

    Parameters
    ----------
    path : str or os.PathLike
        The MATLAB v7.3 (HDF5) file; only the requested frame is read.
    index : int
        Frame number (0-based; negative counts from the end).

    Returns
    -------
    Frame
        ``depth`` is the labeled set's inpainted dense ``depths`` (metres),
        ``raw_depth`` its raw Kinect ``rawDepths`` with NaN where missing.

    Raises
    ------
    FileNotFoundError, ValueError, IndexError
        See :class:`sparsedepth.io.NYUDepthV2Labeled`.
    """
    with NYUDepthV2Labeled(path) as nyu:
        i = check_index(index, len(nyu))
        image, depth, raw = nyu[i]
        return Frame(
            name=f"nyu_labeled/{i:04d}",
            dataset="NYU Depth V2",
            image=image,
            depth=depth,
            raw_depth=raw,
            units="m",
            source=f"{nyu.path} [frame {i}]",
            intrinsics=NYU_RGB_INTRINSICS if image.shape[:2] == (480, 640) else None,
        )


#: file name -> sha256 of the files in sparsedepth/data (see SOURCES.md there)
_EMBEDDED_SHA256 = {
    f"{MMSEG_NAME}.jpg": "e7528c309c3c4799373a395dc44615a2faacffd3308467ddc48589eb2a2ab9fb",
    f"{MMSEG_NAME}.png": "1f6a23a7572fcd6d6b754222c8da6663e8d0351e835372c100e0db3ee8b9d52f",
}
_EMBEDDED = {f"nyu_mmseg_pseudo/{MMSEG_NAME}": (f"{MMSEG_NAME}.jpg", f"{MMSEG_NAME}.png")}


def list_embedded_frames() -> list[str]:
    """Names of the frames shipped inside the package (``sparsedepth/data``)."""
    return list(_EMBEDDED)


def load_embedded_frame(name: str = f"nyu_mmseg_pseudo/{MMSEG_NAME}") -> Frame:
    """Load a small real frame shipped with the package; no external data needed.

    Parameters
    ----------
    name : str, optional
        One of :func:`list_embedded_frames`.  Currently only
        ``"nyu_mmseg_pseudo/bookstore_0001d_00001"``: an NYU Depth V2 frame
        downscaled to 160x120, depth in mm / 1000, where both 0 and the clip
        value 10000 (10 m) are invalid, leaving 51.5 % valid pixels
        (1.49-9.99 m).

    Returns
    -------
    Frame

    Raises
    ------
    ValueError
        If ``name`` is unknown, or a shipped file fails its sha256 check.

    Examples
    --------
    >>> frame = load_embedded_frame()
    >>> frame.shape, frame.units
    ((120, 160), 'm')
    """
    if name not in _EMBEDDED:
        raise ValueError(f"`name`: unknown embedded frame {name!r}. Known frames: {', '.join(_EMBEDDED)}.")
    data = resources.files("sparsedepth").joinpath("data")
    image_name, depth_name = _EMBEDDED[name]
    for file_name in (image_name, depth_name):
        digest = hashlib.sha256(data.joinpath(file_name).read_bytes()).hexdigest()
        if digest != _EMBEDDED_SHA256[file_name]:
            raise ValueError(
                f"embedded file sparsedepth/data/{file_name} is corrupt: sha256 {digest}, "
                f"expected {_EMBEDDED_SHA256[file_name]}."
            )
    with resources.as_file(data.joinpath(image_name)) as image_path, resources.as_file(
        data.joinpath(depth_name)
    ) as depth_path:
        return nyu_mmseg_frame(image_path, depth_path, f"sparsedepth/data/{image_name}; sparsedepth/data/{depth_name}")
