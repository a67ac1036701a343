"""The shared real-data folder: where it is, which frames it holds and how each is read.

What lives here: :func:`shared_data_dir` (the folder, from
``SPARSEDEPTH_DATA`` or beside the repository), one loader per source of that
folder (see its ``SOURCES.md`` for the units), the registry of frame name ->
files + loader + scene, :func:`list_shared_frames`, :func:`load_shared_frame` and :func:`shared_frame_scenes`
(which frames show one scene: a benchmark keeps a scene on one side of a tuning/report split).

Imports :mod:`sparsedepth.io` and :mod:`.frame` only.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .._validation import check_folder
from ..io import read_calib, read_depth, read_depth_array, read_depth_png, read_image
from ..io.calibration import read_intrinsics
from .frame import MMSEG_NAME, MOTORCYCLE_CALIBRATION, Frame, as_rgb, nyu_mmseg_frame

__all__ = ["list_shared_frames", "load_shared_frame", "shared_data_dir", "shared_frame_scenes"]


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
    repository = Path(__file__).resolve().parents[2]  # sparsedepth/datasets/shared.py -> the folder holding sparsedepth
    candidate = repository.parent / "shared" / "data"
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
        image=as_rgb(read_image(image_path), image_path),
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
        image=as_rgb(read_image(paths[0]), paths[0]),
        depth=read_depth_png(paths[1], 1000.0),
        raw_depth=read_depth_png(paths[2], 1000.0),
        units="m",
        source="; ".join(map(str, paths)),
    )


def _load_nyu_mmseg(root: Path) -> Frame:
    folder = root / "nyu_mmseg_pseudo"
    image_path, depth_path = folder / f"{MMSEG_NAME}.jpg", folder / f"{MMSEG_NAME}.png"
    return nyu_mmseg_frame(image_path, depth_path, f"{image_path}; {depth_path}")


def _load_kitti(root: Path, frame: str) -> Frame:
    folder = root / "kitti_metric3d"
    image_path, depth_path = folder / f"rgb_{frame}.png", folder / f"depth_{frame}.png"
    return Frame(
        name=f"kitti/{frame}",
        dataset="KITTI",
        image=as_rgb(read_image(image_path), image_path),
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
        image=as_rgb(read_image(image_path), image_path),
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
        image=as_rgb(read_image(image_path), image_path),
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
        image=as_rgb(read_image(image_path), image_path),
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
        image=as_rgb(read_image(image_path), image_path),
        depth=read_depth_png(depth_path, 5000.0),
        units="m",
        source=f"{image_path}; {depth_path}",
    )


def _load_realsense(root: Path, frame: str) -> Frame:
    folder = root / "realsense_cleargrasp"
    image_path, depth_path = folder / f"rgb_{frame}.jpg", folder / f"depth_{frame}.npz"
    calib_path = folder / "camera_intrinsics.yaml"
    return Frame(
        name=f"realsense_d435/{frame}",
        dataset="ClearGrasp (RealSense D435)",
        image=as_rgb(read_image(image_path), image_path),
        depth=read_depth_array(depth_path, key="depth"),
        units="m",
        source=f"{image_path}; {depth_path}; {calib_path}",
        intrinsics=read_intrinsics(calib_path),
    )


def _load_kitti_raw(root: Path, frame: str) -> Frame:
    folder = root / "kitti_raw_0023"
    image_path, depth_path, cam_path = folder / f"rgb_{frame}.png", folder / f"velodyne_{frame}.npz", folder / "cam.txt"
    return Frame(
        name=f"kitti_raw_0023/{frame}",
        dataset="KITTI raw (drive 2011_09_26_0023)",
        image=as_rgb(read_image(image_path), image_path),
        depth=read_depth_array(depth_path, key="velodyne_depth"),
        units="m",
        source=f"{image_path}; {depth_path}; {cam_path}",
        intrinsics=read_intrinsics(cam_path),
    )


@dataclass(frozen=True)
class _Entry:
    files: tuple[str, ...]
    load: Callable[[Path], Frame]
    scene: str


def _registry() -> dict[str, _Entry]:
    entries: dict[str, _Entry] = {}
    for frame in ("00000", "00050", "00100"):
        entries[f"nyu_metric3d/{frame}"] = _Entry(
            (f"nyu_metric3d/rgb_{frame}.jpg", f"nyu_metric3d/sync_depth_{frame}.png"),
            lambda root, frame=frame: _load_nyu_metric3d(root, frame), "nyu/basement",
        )
    entries["nyu_rcnn_depth/demo"] = _Entry(
        ("nyu_rcnn_depth/images.png", "nyu_rcnn_depth/depth.png", "nyu_rcnn_depth/rawdepth.png"),
        _load_nyu_rcnn, "nyu/rcnn_demo",
    )
    entries[f"nyu_mmseg_pseudo/{MMSEG_NAME}"] = _Entry(
        (f"nyu_mmseg_pseudo/{MMSEG_NAME}.jpg", f"nyu_mmseg_pseudo/{MMSEG_NAME}.png"), _load_nyu_mmseg,
        "nyu/bookstore_0001d",
    )
    for frame in ("0000000005", "0000000050", "0000000100"):
        entries[f"kitti/{frame}"] = _Entry(
            (f"kitti_metric3d/rgb_{frame}.png", f"kitti_metric3d/depth_{frame}.png"),
            lambda root, frame=frame: _load_kitti(root, frame), "kitti/metric3d_drive",
        )
    for frame in ("0000000000", "0000000006"):
        entries[f"kitti_raw_0023/{frame}"] = _Entry(
            (f"kitti_raw_0023/rgb_{frame}.png", f"kitti_raw_0023/velodyne_{frame}.npz", "kitti_raw_0023/cam.txt"),
            lambda root, frame=frame: _load_kitti_raw(root, frame), "kitti/2011_09_26_drive_0023",
        )
    entries["middlebury2014/motorcycle"] = _Entry(
        ("middlebury2014_skimage/motorcycle_left.png", "middlebury2014_skimage/motorcycle_disp.npz"),
        _load_motorcycle_shared, "middlebury/motorcycle",
    )
    entries["middlebury2003/teddy"] = _Entry(
        ("middlebury_acv/teddy/im2.png", "middlebury_acv/teddy/disp2.png"),
        lambda root: _load_middlebury_acv(root, "teddy"), "middlebury/teddy",
    )
    entries["middlebury2001/tsukuba"] = _Entry(
        ("middlebury_acv/tsukuba/im3.png", "middlebury_acv/tsukuba/disp3.pgm"),
        lambda root: _load_middlebury_acv(root, "tsukuba"), "middlebury/tsukuba",
    )
    entries["eth3d/terrace"] = _Entry(
        ("eth3d_twoview/terrace/im0.png", "eth3d_twoview/terrace/disp0.pfm", "eth3d_twoview/terrace/calib.txt"),
        _load_eth3d, "eth3d/terrace",
    )
    entries["tum/0"] = _Entry(("tum_open3d/TUM_color.png", "tum_open3d/TUM_depth.png"), _load_tum, "tum/0")
    for frame in ("000000080", "000000130"):
        entries[f"realsense_d435/{frame}"] = _Entry(
            (f"realsense_cleargrasp/rgb_{frame}.jpg", f"realsense_cleargrasp/depth_{frame}.npz",
             "realsense_cleargrasp/camera_intrinsics.yaml"),
            lambda root, frame=frame: _load_realsense(root, frame), "realsense/cleargrasp_table",
        )
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
    return check_folder(root, "`root` (the shared data folder)")


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


def shared_frame_scenes() -> dict[str, str]:
    """The scene of every shared frame: frames of one scene (one room, one drive, one set-up) share a name.

    A benchmark that tunes on some frames and reports on others keeps each scene on one side
    (``../shared/data/SOURCES.md`` says which frames share a scene).

    Returns
    -------
    dict of str to str
        Frame name (as :func:`list_shared_frames` gives it) to scene name, e.g. ``"nyu_metric3d/00050"`` to
        ``"nyu/basement"``; every known frame, present or not.
    """
    return {name: entry.scene for name, entry in _SHARED.items()}


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
        * ``"realsense_d435/000000080"``, ``"/000000130"`` - ClearGrasp's RealSense D435 frames, 1280x720, the
          sensor's depth in metres (NaN = no return, 9-21 %); one table set-up.
        * ``"kitti_raw_0023/0000000000"``, ``"/0000000006"`` - a second KITTI drive: the raw Velodyne scan
          projected into image_02 (about 4 % of the pixels), not a dense ground truth: score a completion on the
          scan points it was not given.

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
