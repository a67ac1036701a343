"""The real frames every benchmark uses, and the split between tuning and reporting.

The library's default weights are tuned on :data:`TUNE_FRAMES` only; every
table in ``docs/`` reports on :data:`REPORT_FRAMES` (plus the embedded
Motorcycle), so the defaults are never fitted to the frames they are judged
on.  The split is by scene (:func:`scene_of`): no scene has a frame on both
sides, since two frames of one room or one drive share surfaces, lighting and
sensor.  :func:`loso_folds` gives the leave-one-scene-out folds of any list of
frames (``python -m bench.scene_disjoint``).  Frames come from
``../shared/data`` (or ``$SPARSEDEPTH_DATA``); see its ``SOURCES.md`` for units.  Registered raw NYU frames are cropped to the Eigen
crop (rows 45:471, cols 41:601), inside the valid region of the registered
frame; every other frame is used whole.

May import :mod:`sparsedepth` and numpy.
"""

from __future__ import annotations

import numpy as np

import sparsedepth as sd

__all__ = ["TUNE_FRAMES", "REPORT_FRAMES", "EIGEN_CROP", "load", "available", "scene_of", "loso_folds",
           "shared_scenes"]

#: Frames the default weights are tuned on (one or more per dataset family).
TUNE_FRAMES = (
    "nyu_metric3d/00000",
    "nyu_metric3d/00100",
    "kitti/0000000005",
    "middlebury2001/tsukuba",
    "nyu_mmseg_pseudo/bookstore_0001d_00001",
)

#: Frames every reported table uses: no scene of :data:`TUNE_FRAMES` among them (:func:`scene_of`).
REPORT_FRAMES = (
    "nyu_rcnn_depth/demo",
    "kitti_raw_0023/0000000000",
    "middlebury2014/motorcycle",
    "middlebury2003/teddy",
    "eth3d/terrace",
    "tum/0",
)

#: Rows and columns of the Eigen crop of a 640x480 registered NYU frame.
EIGEN_CROP = (slice(45, 471), slice(41, 601))


def load(name: str, *, step: int = 1):
    """``(image, depth)`` of one shared frame, cropped and optionally subsampled.

    ``depth`` is float64 with NaN where there is no ground truth, in the
    frame's units (metres, or pixels of disparity for Middlebury 2001/2003).
    ``step > 1`` keeps every ``step``-th row and column (for quick runs).
    """
    frame = sd.load_shared_frame(name)
    image, depth = np.asarray(frame.image), np.array(frame.depth)
    if name.startswith("nyu_metric3d/"):
        image, depth = image[EIGEN_CROP], depth[EIGEN_CROP]
    return np.ascontiguousarray(image[::step, ::step]), np.ascontiguousarray(depth[::step, ::step])


def available(names) -> list[str]:
    """The names among ``names`` that the shared folder has (empty where it is absent)."""
    if sd.shared_data_dir() is None:
        return []
    have = set(sd.list_shared_frames())
    return [n for n in names if n in have]


def shared_scenes() -> dict[str, str]:
    """Frame name to scene name of every shared frame (:func:`sparsedepth.datasets.shared_frame_scenes`)."""
    from sparsedepth.datasets import shared_frame_scenes

    return shared_frame_scenes()


def scene_of(name: str) -> str:
    """The scene of a frame: frames of one room, one drive or one set-up share it.

    The shared frames' scenes are :func:`shared_scenes`'; any other name (a
    synthetic or embedded frame) is a scene of its own.

    Examples
    --------
    >>> scene_of("kitti/0000000050") == scene_of("kitti/0000000005")
    True
    >>> scene_of("kitti/0000000050") == scene_of("kitti_raw_0023/0000000000")
    False
    """
    return shared_scenes().get(name, name)


def loso_folds(names, scene=scene_of) -> list[tuple[str, list[str], list[str]]]:
    """Leave-one-scene-out folds of ``names``: ``[(scene, held_out, others)]``, one per scene, in first-seen order.

    ``held_out`` are the frames of ``scene``, ``others`` every frame of another
    scene, so a choice made on ``others`` never saw ``scene``.  ``scene`` maps
    a name to its scene (default :func:`scene_of`).
    """
    names = list(names)
    scenes = {name: scene(name) for name in names}
    order = list(dict.fromkeys(scenes.values()))
    return [(s, [n for n in names if scenes[n] == s], [n for n in names if scenes[n] != s]) for s in order]
