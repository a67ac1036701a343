"""Real RGB + depth frames: shipped samples, the shared data folder and NYU files.

Every loader returns a :class:`Frame` whose ``depth`` is the ground truth as
float64 with NaN for invalid pixels, in metres (``units="m"``) or, for
uncalibrated stereo data, disparity in pixels (``units="disparity_px"``).

Three sources:

* :func:`load_motorcycle` - the Middlebury 2014 *Motorcycle* pair shipped with
  scikit-image (always available);
* :func:`load_embedded_frame` - small frames shipped in ``sparsedepth/data``
  (see ``sparsedepth/data/SOURCES.md``), always available;
* :func:`load_shared_frame` - the frames of the ``shared/data`` folder (see its
  ``SOURCES.md``), located by :func:`shared_data_dir`.

:func:`load_nyu_labeled` reads one frame of the NYU Depth V2 labeled ``.mat``.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Callable

import numpy as np

from .io import (
    NYUDepthV2Labeled,
    StereoCalibration,
    read_calib,
    read_depth,
    read_depth_array,
    read_depth_png,
    read_image,
)

__all__ = [
    "Frame",
    "MOTORCYCLE_CALIBRATION",
    "NYU_RGB_INTRINSICS",
    "list_embedded_frames",
    "list_shared_frames",
    "load_embedded_frame",
    "load_motorcycle",
    "load_nyu_labeled",
    "load_shared_frame",
    "shared_data_dir",
]

UNITS = ("m", "disparity_px")

#: NYU Depth V2 RGB camera ``(fx, fy, cx, cy)`` in pixels for the registered
#: 640x480 frames (NYU toolbox ``camera_params.m``).
NYU_RGB_INTRINSICS = (518.8579, 519.46961, 325.58245, 253.73617)

#: Calibration of scikit-image's quarter-resolution Middlebury 2014 Motorcycle
#: pair, from the docstring of :func:`skimage.data.stereo_motorcycle`.
MOTORCYCLE_CALIBRATION = StereoCalibration(
    cam0=[[994.978, 0.0, 311.193], [0.0, 994.978, 254.877], [0.0, 0.0, 1.0]],
    cam1=[[994.978, 0.0, 311.193 + 31.086], [0.0, 994.978, 254.877], [0.0, 0.0, 1.0]],
    doffs=31.086,
    baseline_mm=193.001,
    width=741,
    height=500,
)


def _frozen(array: np.ndarray) -> np.ndarray:
    view = array.view()
    view.setflags(write=False)
    return view


@dataclass(frozen=True, eq=False)
class Frame:
    """One RGB image with its ground-truth depth.

    Attributes
    ----------
    name : str
        Identifier such as ``"nyu_metric3d/00050"`` or ``"eth3d/terrace"``.
    dataset : str
        Dataset of origin, e.g. ``"NYU Depth V2"``.
    image : (H, W, 3) ndarray of uint8
        RGB image registered with the depth.
    depth : (H, W) ndarray of float64
        Ground truth, NaN where unknown; positive elsewhere.  In metres when
        ``units == "m"``, in pixels of disparity when
        ``units == "disparity_px"``.
    raw_depth : (H, W) ndarray of float64 or None
        The raw sensor depth, for frames whose ``depth`` is a processed
        (e.g. inpainted) version of it; same units and conventions.
    units : {'m', 'disparity_px'}
        Unit of ``depth`` and ``raw_depth``.
    source : str
        Where the data came from (file paths or a description).
    intrinsics : tuple of 4 floats or None
        ``(fx, fy, cx, cy)`` of the RGB camera in pixels, if known.

    Notes
    -----
    The arrays are read-only views; copy them before modifying.
    """

    name: str
    dataset: str
    image: np.ndarray
    depth: np.ndarray
    raw_depth: np.ndarray | None = None
    units: str = "m"
    source: str = ""
    intrinsics: tuple[float, float, float, float] | None = None

    def __post_init__(self):
        for field_name in ("name", "dataset", "source"):
            if not isinstance(getattr(self, field_name), str):
                raise TypeError(f"`{field_name}` must be a str, got {type(getattr(self, field_name)).__name__}.")
        if self.units not in UNITS:
            raise ValueError(f"`units` must be one of {UNITS}, got {self.units!r}.")
        image = np.asarray(self.image)
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            raise ValueError(
                f"`image` must be an (H, W, 3) uint8 array, got shape {image.shape} dtype {image.dtype}."
            )
        object.__setattr__(self, "image", _frozen(image))
        for field_name in ("depth", "raw_depth"):
            value = getattr(self, field_name)
            if value is None and field_name == "raw_depth":
                continue
            value = np.asarray(value)
            if value.dtype != np.float64 or value.shape != image.shape[:2]:
                raise ValueError(
                    f"`{field_name}` must be a float64 array of shape {image.shape[:2]} (the image's), "
                    f"got shape {value.shape} dtype {value.dtype}."
                )
            if np.any(np.isinf(value)) or np.any(value <= 0):
                raise ValueError(
                    f"`{field_name}` must be positive with NaN for invalid pixels "
                    "(found inf or values <= 0)."
                )
            object.__setattr__(self, field_name, _frozen(value))
        if self.intrinsics is not None:
            values = tuple(float(v) for v in self.intrinsics)
            if len(values) != 4 or not all(np.isfinite(values)) or values[0] <= 0 or values[1] <= 0:
                raise ValueError(
                    f"`intrinsics` must be (fx, fy, cx, cy) with positive focal lengths, got {self.intrinsics!r}."
                )
            object.__setattr__(self, "intrinsics", values)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W)."""
        return self.depth.shape

    @property
    def valid(self) -> np.ndarray:
        """Boolean (H, W) mask of pixels with ground truth."""
        return ~np.isnan(self.depth)

    def __repr__(self) -> str:
        return (
            f"Frame(name={self.name!r}, dataset={self.dataset!r}, shape={self.shape}, units={self.units!r}, "
            f"valid={self.valid.mean():.1%}, raw_depth={'yes' if self.raw_depth is not None else 'no'})"
        )


def _as_rgb(image: np.ndarray, path) -> np.ndarray:
    if image.dtype != np.uint8:
        raise ValueError(f"'{path}': expected an 8-bit RGB image, got dtype {image.dtype}.")
    if image.ndim == 2:
        image = np.repeat(image[:, :, None], 3, axis=2)
    return image


# --------------------------------------------------------------------------------------
# scikit-image Motorcycle
# --------------------------------------------------------------------------------------
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


# --------------------------------------------------------------------------------------
# NYU Depth V2 labeled
# --------------------------------------------------------------------------------------
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
        i = nyu._index(index)
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


# --------------------------------------------------------------------------------------
# shared/data
# --------------------------------------------------------------------------------------
def shared_data_dir() -> Path | None:
    """Locate the shared real-data folder.

    Returns
    -------
    Path or None
        The value of the environment variable ``SPARSEDEPTH_DATA`` if it is
        set and non-empty (returned as is, even if it does not exist, so that a
        wrong setting fails loudly); otherwise ``../shared/data`` relative to
        the repository root (the folder that contains the ``sparsedepth``
        package) if that is a directory; otherwise None.
    """
    env = os.environ.get("SPARSEDEPTH_DATA")
    if env:
        return Path(env)
    candidate = Path(__file__).resolve().parent.parent.parent / "shared" / "data"
    return candidate if candidate.is_dir() else None


def _intrinsics_from_annotations(path: Path, depth_name: str):
    """``cam_in`` of the Metric3D ``test_annotations.json`` entry for ``depth_name``."""
    if not path.is_file():
        return None
    entries = json.loads(path.read_text()).get("files", [])
    for entry in entries:
        if Path(entry.get("depth", "")).name == depth_name:
            return tuple(float(v) for v in entry["cam_in"])
    return None


def _load_nyu_metric3d(root: Path, frame: str) -> Frame:
    folder = root / "nyu_metric3d"
    image_path, depth_path = folder / f"rgb_{frame}.jpg", folder / f"sync_depth_{frame}.png"
    intrinsics = _intrinsics_from_annotations(folder / "test_annotations.json", depth_path.name)
    return Frame(
        name=f"nyu_metric3d/{frame}",
        dataset="NYU Depth V2",
        image=_as_rgb(read_image(image_path), image_path),
        depth=read_depth_png(depth_path, 1000.0),
        units="m",
        source=f"{image_path}; {depth_path}",
        intrinsics=intrinsics,
    )


def _load_nyu_rcnn(root: Path) -> Frame:
    folder = root / "nyu_rcnn_depth"
    paths = [folder / "images.png", folder / "depth.png", folder / "rawdepth.png"]
    return Frame(
        name="nyu_rcnn_depth/demo",
        dataset="NYU Depth V2",
        image=_as_rgb(read_image(paths[0]), paths[0]),
        depth=read_depth_png(paths[1], 1000.0),
        raw_depth=read_depth_png(paths[2], 1000.0),
        units="m",
        source="; ".join(map(str, paths)),
    )


_MMSEG_NAME = "bookstore_0001d_00001"
_MMSEG_CLIP_M = 10.0  # stored 10000 mm: the depth was clipped there


def _nyu_mmseg_frame(image_path, depth_path, source: str) -> Frame:
    depth = read_depth_png(depth_path, 1000.0)
    depth[depth == _MMSEG_CLIP_M] = np.nan
    return Frame(
        name=f"nyu_mmseg_pseudo/{_MMSEG_NAME}",
        dataset="NYU Depth V2",
        image=_as_rgb(read_image(image_path), image_path),
        depth=depth,
        units="m",
        source=source,
    )


def _load_nyu_mmseg(root: Path) -> Frame:
    folder = root / "nyu_mmseg_pseudo"
    image_path, depth_path = folder / f"{_MMSEG_NAME}.jpg", folder / f"{_MMSEG_NAME}.png"
    return _nyu_mmseg_frame(image_path, depth_path, f"{image_path}; {depth_path}")


def _load_kitti(root: Path, frame: str) -> Frame:
    folder = root / "kitti_metric3d"
    image_path, depth_path = folder / f"rgb_{frame}.png", folder / f"depth_{frame}.png"
    return Frame(
        name=f"kitti/{frame}",
        dataset="KITTI",
        image=_as_rgb(read_image(image_path), image_path),
        depth=read_depth_png(depth_path, 256.0),
        units="m",
        source=f"{image_path}; {depth_path}",
        intrinsics=_intrinsics_from_annotations(folder / "test_annotations.json", f"{frame}.png"),
    )


def _load_motorcycle_shared(root: Path) -> Frame:
    folder = root / "middlebury2014_skimage"
    image_path, disp_path = folder / "motorcycle_left.png", folder / "motorcycle_disp.npz"
    return Frame(
        name="middlebury2014/motorcycle",
        dataset="Middlebury 2014",
        image=_as_rgb(read_image(image_path), image_path),
        depth=MOTORCYCLE_CALIBRATION.depth_from_disparity(read_depth_array(disp_path, key="arr_0")),
        units="m",
        source=f"{image_path}; {disp_path}",
        intrinsics=MOTORCYCLE_CALIBRATION.intrinsics,
    )


def _load_middlebury_acv(root: Path, scene: str) -> Frame:
    # Middlebury 2001/2003 pairs come without calibration: ground truth stays disparity.
    image_name, disp_name, factor, year = {
        "teddy": ("im2.png", "disp2.png", 4.0, 2003),
        "tsukuba": ("im3.png", "disp3.pgm", 16.0, 2001),
    }[scene]
    folder = root / "middlebury_acv" / scene
    image_path, disp_path = folder / image_name, folder / disp_name
    return Frame(
        name=f"middlebury{year}/{scene}",
        dataset=f"Middlebury {year}",
        image=_as_rgb(read_image(image_path), image_path),
        depth=read_depth_png(disp_path, factor),
        units="disparity_px",
        source=f"{image_path}; {disp_path}",
    )


def _load_eth3d(root: Path) -> Frame:
    folder = root / "eth3d_twoview" / "terrace"
    image_path, disp_path, calib_path = folder / "im0.png", folder / "disp0.pfm", folder / "calib.txt"
    calib = read_calib(calib_path)
    return Frame(
        name="eth3d/terrace",
        dataset="ETH3D",
        image=_as_rgb(read_image(image_path), image_path),
        depth=read_depth(disp_path, calib=calib),
        units="m",
        source=f"{image_path}; {disp_path}; {calib_path}",
        intrinsics=calib.intrinsics,
    )


def _load_tum(root: Path) -> Frame:
    folder = root / "tum_open3d"
    image_path, depth_path = folder / "TUM_color.png", folder / "TUM_depth.png"
    return Frame(
        name="tum/0",
        dataset="TUM RGB-D",
        image=_as_rgb(read_image(image_path), image_path),
        depth=read_depth_png(depth_path, 5000.0),
        units="m",
        source=f"{image_path}; {depth_path}",
    )


@dataclass(frozen=True)
class _Entry:
    files: tuple[str, ...]
    load: Callable[[Path], Frame]


def _registry() -> dict[str, _Entry]:
    entries: dict[str, _Entry] = {}
    for frame in ("00000", "00050", "00100"):
        entries[f"nyu_metric3d/{frame}"] = _Entry(
            (f"nyu_metric3d/rgb_{frame}.jpg", f"nyu_metric3d/sync_depth_{frame}.png"),
            lambda root, frame=frame: _load_nyu_metric3d(root, frame),
        )
    entries["nyu_rcnn_depth/demo"] = _Entry(
        ("nyu_rcnn_depth/images.png", "nyu_rcnn_depth/depth.png", "nyu_rcnn_depth/rawdepth.png"),
        _load_nyu_rcnn,
    )
    entries[f"nyu_mmseg_pseudo/{_MMSEG_NAME}"] = _Entry(
        (f"nyu_mmseg_pseudo/{_MMSEG_NAME}.jpg", f"nyu_mmseg_pseudo/{_MMSEG_NAME}.png"), _load_nyu_mmseg
    )
    for frame in ("0000000005", "0000000050", "0000000100"):
        entries[f"kitti/{frame}"] = _Entry(
            (f"kitti_metric3d/rgb_{frame}.png", f"kitti_metric3d/depth_{frame}.png"),
            lambda root, frame=frame: _load_kitti(root, frame),
        )
    entries["middlebury2014/motorcycle"] = _Entry(
        ("middlebury2014_skimage/motorcycle_left.png", "middlebury2014_skimage/motorcycle_disp.npz"),
        _load_motorcycle_shared,
    )
    entries["middlebury2003/teddy"] = _Entry(
        ("middlebury_acv/teddy/im2.png", "middlebury_acv/teddy/disp2.png"),
        lambda root: _load_middlebury_acv(root, "teddy"),
    )
    entries["middlebury2001/tsukuba"] = _Entry(
        ("middlebury_acv/tsukuba/im3.png", "middlebury_acv/tsukuba/disp3.pgm"),
        lambda root: _load_middlebury_acv(root, "tsukuba"),
    )
    entries["eth3d/terrace"] = _Entry(
        ("eth3d_twoview/terrace/im0.png", "eth3d_twoview/terrace/disp0.pfm", "eth3d_twoview/terrace/calib.txt"),
        _load_eth3d,
    )
    entries["tum/0"] = _Entry(("tum_open3d/TUM_color.png", "tum_open3d/TUM_depth.png"), _load_tum)
    return entries


_SHARED = _registry()


def _shared_root(root, *, required: bool) -> Path | None:
    if root is None:
        root = shared_data_dir()
        if root is None:
            if required:
                raise FileNotFoundError(
                    "no shared data folder: set the SPARSEDEPTH_DATA environment variable or pass `root=`."
                )
            return None
    elif not isinstance(root, (str, os.PathLike)):
        raise TypeError(f"`root` must be a str or os.PathLike, got {type(root).__name__}.")
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"`root`: shared data folder '{root}' does not exist.")
    return root


def list_shared_frames(root=None) -> list[str]:
    """Names of the shared-data frames whose files are present.

    Parameters
    ----------
    root : str or os.PathLike, optional
        The shared data folder; default :func:`shared_data_dir`.

    Returns
    -------
    list of str
        E.g. ``["nyu_metric3d/00000", ..., "kitti/0000000005", ...,
        "middlebury2014/motorcycle", "eth3d/terrace", "tum/0"]``; empty if
        ``root`` is omitted and no shared data folder is found.

    Raises
    ------
    FileNotFoundError
        If ``root`` (given, or from ``SPARSEDEPTH_DATA``) is not a directory.
    """
    root = _shared_root(root, required=False)
    if root is None:
        return []
    return [name for name, entry in _SHARED.items() if all((root / f).is_file() for f in entry.files)]


def load_shared_frame(name: str, root=None) -> Frame:
    """Load one frame of the shared data folder with its ground truth.

    Parameters
    ----------
    name : str
        One of:

        * ``"nyu_metric3d/00000"``, ``"/00050"``, ``"/00100"`` - NYU Depth V2
          (BTS "sync" frames), 640x480.  Ground truth = the **raw** projected
          Kinect depth (mm / 1000): zero border and 5-15 % holes are NaN.
        * ``"nyu_rcnn_depth/demo"`` - NYU labeled frame (Gupta crop, 560x425):
          ``depth`` = the colorization-inpainted dense map, ``raw_depth`` = the
          raw Kinect depth (16.7 % missing).
        * ``"nyu_mmseg_pseudo/bookstore_0001d_00001"`` - NYU, 160x120.  The
          stored value 10000 (10 m) is the clip value of this fixture, not a
          measurement, and is treated as **invalid** (NaN), like 0.
        * ``"kitti/0000000005"``, ``"/0000000050"``, ``"/0000000100"`` - KITTI
          depth annotated ground truth (v / 256 m), semi-dense (about 20 %).
        * ``"middlebury2014/motorcycle"`` - disparity + calibration -> metres
          (same as :func:`load_motorcycle`).
        * ``"middlebury2003/teddy"`` (disparity = v / 4) and
          ``"middlebury2001/tsukuba"`` (v / 16) - no calibration, so the
          ground truth is **disparity in pixels** (``units="disparity_px"``).
        * ``"eth3d/terrace"`` - PFM disparity + ``calib.txt`` -> metres
          (2.4-5.3 m, 53 % valid).
        * ``"tum/0"`` - TUM RGB-D raw depth (v / 5000 m).

        The unregistered NYU raw Kinect frame (``nyu_raw_open3d``) is not a
        frame here; its PGM can be read with
        ``sparsedepth.io.read_image(path, byteorder="little")``.
    root : str or os.PathLike, optional
        The shared data folder; default :func:`shared_data_dir`.

    Returns
    -------
    Frame

    Raises
    ------
    ValueError
        If ``name`` is unknown.
    FileNotFoundError
        If the folder or one of the frame's files is missing.
    """
    if name not in _SHARED:
        raise ValueError(
            f"`name`: unknown shared frame {name!r}. Known frames: {', '.join(_SHARED)}."
        )
    root = _shared_root(root, required=True)
    entry = _SHARED[name]
    for relative in entry.files:
        if not (root / relative).is_file():
            raise FileNotFoundError(f"shared frame {name!r}: missing file '{root / relative}'.")
    return entry.load(root)


# --------------------------------------------------------------------------------------
# embedded frames (sparsedepth/data)
# --------------------------------------------------------------------------------------
#: file name -> sha256 of the files in sparsedepth/data (see SOURCES.md there)
_EMBEDDED_SHA256 = {
    f"{_MMSEG_NAME}.jpg": "e7528c309c3c4799373a395dc44615a2faacffd3308467ddc48589eb2a2ab9fb",
    f"{_MMSEG_NAME}.png": "1f6a23a7572fcd6d6b754222c8da6663e8d0351e835372c100e0db3ee8b9d52f",
}
_EMBEDDED = {f"nyu_mmseg_pseudo/{_MMSEG_NAME}": (f"{_MMSEG_NAME}.jpg", f"{_MMSEG_NAME}.png")}


def list_embedded_frames() -> list[str]:
    """Names of the frames shipped inside the package (``sparsedepth/data``)."""
    return list(_EMBEDDED)


def load_embedded_frame(name: str = f"nyu_mmseg_pseudo/{_MMSEG_NAME}") -> Frame:
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
        return _nyu_mmseg_frame(image_path, depth_path, f"sparsedepth/data/{image_name}; sparsedepth/data/{depth_name}")
