"""COLMAP sparse models: cameras, registered images, 3-D points, and the sparse depth of each view.

What lives here: :func:`read_colmap_model` (a model folder in COLMAP's text or
binary format, as its documentation "Output Format" specifies) and
:func:`write_colmap_model`; the records :class:`Camera`, :class:`Image`,
:class:`Points3D` (one array per field, not one object per point) and
:class:`ColmapModel`; per view, :func:`view_observations` (each 3-D point the
image observes, in the camera frame, with its reprojection) and
:func:`view_depth` (the view's sparse depth map, its mask and the intrinsic
matrix of that pixel grid).

Only the pinhole camera models (``SIMPLE_PINHOLE``, ``PINHOLE``) are read: the
keypoints of a model with distortion are in distorted pixels, so the model is
refused with the fix (``colmap image_undistorter`` writes an undistorted
model and images).

Imports NumPy, the standard library, :mod:`sparsedepth._validation` and
:mod:`.files` only.
"""

from __future__ import annotations

import math
import os
import re
import stat
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .._validation import check_count, check_nonnegative_real, is_int, stat_path
from .files import MAX_PIXELS, atomic_target, check_max_pixels, check_pixels, file_label

__all__ = [
    "Camera",
    "ColmapModel",
    "Image",
    "Points3D",
    "ViewObservations",
    "intrinsic_matrix",
    "read_colmap_model",
    "rotation_from_qvec",
    "view_depth",
    "view_observations",
    "write_colmap_model",
]

#: The camera models read here: COLMAP model id -> (name, number of parameters).
PINHOLE_MODELS = {0: ("SIMPLE_PINHOLE", 3), 1: ("PINHOLE", 4)}

#: COLMAP's camera models with distortion or a non-perspective projection (model id -> name): refused.
DISTORTED_MODELS = {
    2: "SIMPLE_RADIAL", 3: "RADIAL", 4: "OPENCV", 5: "OPENCV_FISHEYE", 6: "FULL_OPENCV", 7: "FOV",
    8: "SIMPLE_RADIAL_FISHEYE", 9: "RADIAL_FISHEYE", 10: "THIN_PRISM_FISHEYE", 11: "RAD_TAN_THIN_PRISM_FISHEYE",
    12: "SIMPLE_DIVISION", 13: "DIVISION", 14: "SIMPLE_FISHEYE", 15: "FISHEYE", 16: "EUCM", 17: "EQUIRECTANGULAR",
}

#: The three files of a model, in the order they are read.
MODEL_FILES = ("cameras", "images", "points3D")

_PINHOLE_IDS = {model: model_id for model_id, (model, _) in PINHOLE_MODELS.items()}
_DISTORTED_IDS = {model: model_id for model_id, model in DISTORTED_MODELS.items()}
_EXTENSIONS = {"binary": ".bin", "text": ".txt"}
_UINT32_MAX = 2**32 - 1
_INT64_MAX = 2**63 - 1
_INT_TOKEN = re.compile(r"[+-]?[0-9]{1,19}")  # int64 has 19 digits; longer tokens are refused before int()
_FLOAT_TOKEN = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_CAMERA_RECORD = struct.Struct("<IiQQ")  # CAMERA_ID, MODEL_ID, WIDTH, HEIGHT
_IMAGE_RECORD = struct.Struct("<I4d3dI")  # IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID
_POINT_RECORD = struct.Struct("<Q3d3Bd")  # POINT3D_ID, X, Y, Z, R, G, B, ERROR (the writer's)
_COUNT = struct.Struct("<Q")
_POINT2D = np.dtype([("x", "<f8"), ("y", "<f8"), ("point3d_id", "<i8")])
_TRACK_ELEMENT = np.dtype([("image_id", "<u4"), ("point2d_idx", "<u4")])
# a point record without its track: POINT3D_ID, X Y Z, R G B, ERROR and the track length (51 bytes, packed)
_POINT_FIXED = np.dtype([("id", "<u8"), ("xyz", "<f8", (3,)), ("rgb", "u1", (3,)), ("error", "<f8"),
                         ("track_length", "<u8")])


def _frozen(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class Camera:
    """One camera of a COLMAP model (intrinsics shared by the images that name it).

    Attributes
    ----------
    id : int
        ``CAMERA_ID``.
    model : str
        ``"SIMPLE_PINHOLE"`` (params ``f, cx, cy``) or ``"PINHOLE"`` (params
        ``fx, fy, cx, cy``).
    width, height : int
        Image size in pixels.
    params : (P,) ndarray of float64
        The model's parameters in pixels, in COLMAP's pixel convention (the
        centre of the top-left pixel is ``(0.5, 0.5)``).
    """

    id: int
    model: str
    width: int
    height: int
    params: np.ndarray


@dataclass(frozen=True, eq=False)
class Image:
    """One registered image of a COLMAP model: its pose and its keypoints.

    Attributes
    ----------
    id : int
        ``IMAGE_ID``.
    qvec : (4,) ndarray of float64
        ``(QW, QX, QY, QZ)``, the world-to-camera rotation as a Hamilton
        quaternion (normalised when used).
    tvec : (3,) ndarray of float64
        ``(TX, TY, TZ)``, the world-to-camera translation.
    camera_id : int
        ``CAMERA_ID`` of its camera.
    name : str
        File name, relative to the project's image folder.
    xys : (N, 2) ndarray of float64
        Keypoints ``(x, y)`` in COLMAP's pixel convention.
    point3d_ids : (N,) ndarray of int64
        ``POINT3D_ID`` each keypoint observes, ``-1`` for none.
    """

    id: int
    qvec: np.ndarray
    tvec: np.ndarray
    camera_id: int
    name: str
    xys: np.ndarray
    point3d_ids: np.ndarray


@dataclass(frozen=True, eq=False)
class Points3D:
    """The 3-D points of a COLMAP model, one array per field (row ``k`` is the ``k``-th point of the file).

    Attributes
    ----------
    ids : (M,) ndarray of int64
        ``POINT3D_ID`` of each point.
    xyz : (M, 3) ndarray of float64
        World coordinates.
    rgb : (M, 3) ndarray of uint8
        Colour.
    error : (M,) ndarray of float64
        Mean reprojection error in pixels.
    track_lengths : (M,) ndarray of int64
        Number of observations of each point.
    track_image_ids, track_point2d_idxs : (T,) ndarray of int64
        The tracks of all points concatenated (``T = track_lengths.sum()``):
        ``IMAGE_ID`` and zero-based keypoint index ``POINT2D_IDX`` of each
        observation.
    """

    ids: np.ndarray
    xyz: np.ndarray
    rgb: np.ndarray
    error: np.ndarray
    track_lengths: np.ndarray
    track_image_ids: np.ndarray
    track_point2d_idxs: np.ndarray
    _sorter: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "_sorter", _frozen(np.argsort(self.ids, kind="stable")))

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def index_of(self, ids) -> np.ndarray:
        """Row of each ``POINT3D_ID`` in ``ids`` (int64 array of the same shape), ``-1`` where absent."""
        ids = np.asarray(ids, dtype=np.int64)
        if len(self) == 0:
            return np.full(ids.shape, -1, dtype=np.int64)
        sorted_ids = self.ids[self._sorter]
        slot = np.minimum(np.searchsorted(sorted_ids, ids), len(self) - 1)
        return np.where(sorted_ids[slot] == ids, self._sorter[slot], -1).astype(np.int64)


@dataclass(frozen=True, eq=False)
class ColmapModel:
    """A COLMAP sparse model: cameras and images by id, and the 3-D points.

    Attributes
    ----------
    cameras : dict of int to Camera
        By ``CAMERA_ID``, in file order.
    images : dict of int to Image
        By ``IMAGE_ID``, in file order.
    points3d : Points3D
        The 3-D points.
    """

    cameras: dict
    images: dict
    points3d: Points3D
    _by_name: dict = field(init=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "_by_name", {image.name: image for image in self.images.values()})

    def image(self, image) -> Image:
        """The image of ``IMAGE_ID`` ``image`` (an int) or of name ``image`` (a str).

        Raises ``KeyError`` naming it if the model has no such image, ``TypeError`` for another type.
        """
        if is_int(image):
            found = self.images.get(int(image))
        elif isinstance(image, str):
            found = self._by_name.get(image)
        else:
            raise TypeError(f"`image` must be an IMAGE_ID (int) or an image name (str), got {type(image).__name__}.")
        if found is None:
            raise KeyError(f"the COLMAP model has no image {image!r} ({len(self.images)} images, e.g. "
                           f"{', '.join(repr(name) for name in list(self._by_name)[:3])}).")
        return found


@dataclass(frozen=True, eq=False)
class ViewObservations:
    """The keypoints of one image that observe a 3-D point, with that point in the camera frame.

    Attributes
    ----------
    image_id : int
        ``IMAGE_ID`` of the view.
    keypoint_indices : (N,) ndarray of int64
        Index of each observation in the image's keypoints (``POINT2D_IDX``).
    point3d_ids : (N,) ndarray of int64
        The observed ``POINT3D_ID``.
    keypoints : (N, 2) ndarray of float64
        Observed ``(x, y)`` in COLMAP's pixel convention.
    points_camera : (N, 3) ndarray of float64
        The 3-D point in the camera frame, ``R X + t``.
    depth : (N,) ndarray of float64
        Its depth along the optical axis, ``points_camera[:, 2]``.
    projected : (N, 2) ndarray of float64
        Its reprojection ``(x, y)`` through the pinhole camera, in COLMAP's
        pixel convention; NaN where ``depth <= 0``.
    error : (N,) ndarray of float64
        The point's mean reprojection error from ``points3D`` (pixels).
    track_lengths : (N,) ndarray of int64
        The point's track length.
    """

    image_id: int
    keypoint_indices: np.ndarray
    point3d_ids: np.ndarray
    keypoints: np.ndarray
    points_camera: np.ndarray
    depth: np.ndarray
    projected: np.ndarray
    error: np.ndarray
    track_lengths: np.ndarray


# --- conventions


def rotation_from_qvec(qvec) -> np.ndarray:
    """The 3x3 rotation matrix of the Hamilton quaternion ``(w, x, y, z)`` (normalised first).

    Parameters
    ----------
    qvec : (4,) array_like of float
        ``(QW, QX, QY, QZ)`` as COLMAP stores it.

    Returns
    -------
    R : (3, 3) ndarray of float64

    Raises
    ------
    ValueError
        If ``qvec`` is not four finite numbers with a non-zero norm.

    Notes
    -----
    With :math:`q = (w, x, y, z)` of unit norm,

    .. math:: R = \\begin{pmatrix}
                  1 - 2(y^2 + z^2) & 2(xy - wz) & 2(xz + wy) \\\\
                  2(xy + wz) & 1 - 2(x^2 + z^2) & 2(yz - wx) \\\\
                  2(xz - wy) & 2(yz + wx) & 1 - 2(x^2 + y^2)
                  \\end{pmatrix},

    the convention of Eigen, which COLMAP uses.  For an :class:`Image`,
    ``R`` maps world to camera coordinates: :math:`X_c = R X + t`.

    Examples
    --------
    >>> rotation_from_qvec([np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)]).round(12) + 0.0  # 90 degrees about z
    array([[ 0., -1.,  0.],
           [ 1.,  0.,  0.],
           [ 0.,  0.,  1.]])
    """
    q = np.asarray(qvec, dtype=np.float64)
    if q.shape != (4,) or not np.all(np.isfinite(q)) or not np.any(q != 0):
        raise ValueError(f"a quaternion must be 4 finite numbers (w, x, y, z) with a non-zero norm, got {qvec!r}.")
    q = q / np.max(np.abs(q))  # first scaled to a largest component of 1, so that the norm cannot overflow
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _pinhole(camera: Camera) -> tuple[float, float, float, float]:
    """``(fx, fy, cx, cy)`` of a pinhole camera, in COLMAP's pixel convention."""
    params = np.asarray(camera.params, dtype=np.float64)
    if camera.model == "SIMPLE_PINHOLE" and params.shape == (3,):
        return float(params[0]), float(params[0]), float(params[1]), float(params[2])
    if camera.model == "PINHOLE" and params.shape == (4,):
        return float(params[0]), float(params[1]), float(params[2]), float(params[3])
    raise ValueError(f"camera {camera.id} is a {camera.model} camera with {params.size} parameter(s); only "
                     "SIMPLE_PINHOLE (f, cx, cy) and PINHOLE (fx, fy, cx, cy) are supported: run "
                     "`colmap image_undistorter` first.")


def intrinsic_matrix(camera: Camera, *, pixel_centres: str = "integer") -> np.ndarray:
    """The 3x3 intrinsic matrix of a pinhole :class:`Camera`.

    Parameters
    ----------
    camera : Camera
        A ``SIMPLE_PINHOLE`` or ``PINHOLE`` camera.
    pixel_centres : {"integer", "half"}, optional
        Where pixel centres are: ``"integer"`` (default) for array indices,
        the pixel in row ``v`` and column ``u`` being at ``(u, v)`` (the
        convention of :func:`~sparsedepth.io.depth_to_points` and OpenCV);
        ``"half"`` for COLMAP's own coordinates, where it is at
        ``(u + 0.5, v + 0.5)``.

    Returns
    -------
    K : (3, 3) ndarray of float64

    Raises
    ------
    ValueError
        For another camera model or ``pixel_centres``.

    Notes
    -----
    .. math:: K = \\begin{pmatrix} f_x & 0 & c_x - s \\\\ 0 & f_y & c_y - s \\\\ 0 & 0 & 1 \\end{pmatrix},

    with :math:`(f_x, f_y, c_x, c_y)` the camera's parameters (COLMAP's
    convention) and :math:`s = 1/2` for ``"integer"``, :math:`s = 0` for
    ``"half"``.

    Examples
    --------
    >>> camera = Camera(1, "PINHOLE", 640, 480, np.array([500.0, 500.0, 320.0, 240.0]))
    >>> intrinsic_matrix(camera)
    array([[500. ,   0. , 319.5],
           [  0. , 500. , 239.5],
           [  0. ,   0. ,   1. ]])
    """
    if pixel_centres not in ("integer", "half"):
        raise ValueError(f"`pixel_centres` must be 'integer' or 'half', got {pixel_centres!r}.")
    fx, fy, cx, cy = _pinhole(camera)
    shift = 0.5 if pixel_centres == "integer" else 0.0
    return np.array([[fx, 0.0, cx - shift], [0.0, fy, cy - shift], [0.0, 0.0, 1.0]])


# --- per view


def view_observations(model: ColmapModel, image) -> ViewObservations:
    """The 3-D points one image observes, in its camera frame, with their reprojections.

    Parameters
    ----------
    model : ColmapModel
        As :func:`read_colmap_model` returns it.
    image : int or str
        ``IMAGE_ID`` or image name.

    Returns
    -------
    ViewObservations
        One row per keypoint with a ``POINT3D_ID``, in keypoint order.

    Raises
    ------
    KeyError
        If the model has no such image.
    ValueError
        If its camera is not a pinhole camera, or the model (built by hand)
        misses its camera or an observed point.

    Notes
    -----
    COLMAP's pose is world-to-camera: a world point :math:`X` is at
    :math:`X_c = R X + t` in the camera frame (:math:`R` from ``qvec`` by
    :func:`rotation_from_qvec`, :math:`t` = ``tvec``; x right, y down, z
    forward).  Its depth is :math:`z_c`, its reprojection
    :math:`(f_x x_c / z_c + c_x,\\ f_y y_c / z_c + c_y)` in COLMAP's pixel
    coordinates (the top-left pixel's centre is ``(0.5, 0.5)``).  On a
    bundle-adjusted model the distance between ``keypoints`` and
    ``projected`` averages about the points' ``error``.
    """
    if not isinstance(model, ColmapModel):
        raise TypeError(f"`model` must be a ColmapModel (see read_colmap_model), got {type(model).__name__}.")
    view = model.image(image)
    camera = model.cameras.get(view.camera_id)
    if camera is None:
        raise ValueError(f"image {view.id} ({view.name!r}) names camera {view.camera_id}, which the model lacks.")
    fx, fy, cx, cy = _pinhole(camera)
    keypoint_indices = np.flatnonzero(view.point3d_ids >= 0)
    point3d_ids = view.point3d_ids[keypoint_indices].astype(np.int64)
    rows = model.points3d.index_of(point3d_ids)
    if np.any(rows < 0):
        missing = point3d_ids[np.argmax(rows < 0)]
        raise ValueError(f"image {view.id} ({view.name!r}) observes POINT3D_ID {missing}, which the model lacks.")
    rotation = rotation_from_qvec(view.qvec)
    with np.errstate(over="ignore", invalid="ignore"):  # a model far beyond float range gives inf / NaN, dropped later
        points_camera = model.points3d.xyz[rows] @ rotation.T + np.asarray(view.tvec, dtype=np.float64)
        depth = points_camera[:, 2].copy()
        in_front = depth > 0
        safe = np.where(in_front, depth, 1.0)
        projected = np.column_stack([fx * points_camera[:, 0] / safe + cx, fy * points_camera[:, 1] / safe + cy])
    projected[~in_front] = np.nan
    return ViewObservations(
        image_id=view.id,
        keypoint_indices=keypoint_indices.astype(np.int64),
        point3d_ids=point3d_ids,
        keypoints=np.asarray(view.xys, dtype=np.float64)[keypoint_indices],
        points_camera=points_camera,
        depth=depth,
        projected=projected,
        error=model.points3d.error[rows].astype(np.float64),
        track_lengths=model.points3d.track_lengths[rows].astype(np.int64),
    )


def view_depth(model: ColmapModel, image, *, max_error=None, min_track=None):
    """The sparse depth map of one view: the depth of each observed 3-D point at its keypoint's pixel.

    Parameters
    ----------
    model : ColmapModel
        As :func:`read_colmap_model` returns it.
    image : int or str
        ``IMAGE_ID`` or image name.
    max_error : float, optional
        Drop points whose mean reprojection error (pixels) is above it.
    min_track : int, optional
        Drop points seen by fewer images.

    Returns
    -------
    depth : (height, width) ndarray of float64
        Depth along the optical axis in the model's units, NaN where no
        point lands.
    mask : (height, width) ndarray of bool
        Where ``depth`` holds a value.
    K : (3, 3) ndarray of float64
        Intrinsic matrix of this pixel grid with integer pixel centres
        (``intrinsic_matrix(camera)``): ``depth_to_points(depth, (K[0, 0],
        K[1, 1], K[0, 2], K[1, 2]))`` back-projects the map into the camera
        frame.

    Raises
    ------
    KeyError
        If the model has no such image.
    ValueError
        If its camera is not a pinhole camera, or ``max_error`` / ``min_track``
        is out of range.

    Notes
    -----
    Each keypoint with a ``POINT3D_ID`` gives :math:`z_c`, the third
    coordinate of :math:`X_c = R X + t` (world-to-camera pose, see
    :func:`view_observations`), written at the pixel that contains the
    keypoint ``(x, y)``: COLMAP puts the centre of the top-left pixel at
    ``(0.5, 0.5)``, so that is row :math:`\\lfloor y \\rfloor`, column
    :math:`\\lfloor x \\rfloor` (the pixel whose centre is nearest).
    Points with :math:`z_c \\le 0`, keypoints outside the image, and points
    failing ``max_error`` or ``min_track`` are dropped; where several land on
    one pixel the nearest is kept.

    Examples
    --------
    One point at depth 2 seen by a 4x3 camera at ``(2.5, 1.5)``, in row 1, column 2:

    >>> camera = Camera(1, "SIMPLE_PINHOLE", 4, 3, np.array([2.0, 2.0, 1.5]))
    >>> image = Image(1, np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), 1, "a.png", np.array([[2.5, 1.5]]),
    ...               np.array([7]))
    >>> points = Points3D(ids=np.array([7]), xyz=np.array([[0.25, 0.0, 2.0]]), rgb=np.zeros((1, 3), np.uint8),
    ...                   error=np.array([0.3]), track_lengths=np.array([1]), track_image_ids=np.array([1]),
    ...                   track_point2d_idxs=np.array([0]))
    >>> depth, mask, K = view_depth(ColmapModel({1: camera}, {1: image}, points), "a.png")
    >>> depth
    array([[nan, nan, nan, nan],
           [nan, nan,  2., nan],
           [nan, nan, nan, nan]])
    """
    if max_error is not None:
        max_error = check_nonnegative_real(max_error, name="`max_error`")
    if min_track is not None:
        min_track = check_count(min_track, name="`min_track`")
    observations = view_observations(model, image)
    camera = model.cameras[model.image(image).camera_id]
    height, width = int(camera.height), int(camera.width)
    columns = np.floor(observations.keypoints[:, 0])
    rows = np.floor(observations.keypoints[:, 1])
    depth_values = observations.depth
    keep = (np.isfinite(depth_values) & (depth_values > 0) & (columns >= 0) & (columns < width)
            & (rows >= 0) & (rows < height))
    if max_error is not None:
        keep &= observations.error <= max_error
    if min_track is not None:
        keep &= observations.track_lengths >= min_track
    flat = rows[keep].astype(np.int64) * width + columns[keep].astype(np.int64)
    values = depth_values[keep]
    order = np.lexsort((values, flat))  # by pixel, then nearest first
    flat, values = flat[order], values[order]
    first = np.ones(flat.shape, dtype=bool)
    first[1:] = flat[1:] != flat[:-1]
    depth = np.full(height * width, np.nan)
    depth[flat[first]] = values[first]
    depth = depth.reshape(height, width)
    return depth, np.isfinite(depth), intrinsic_matrix(camera)


# --- reading: shared checks


def _integer(token: str, at: str, what: str, low: int, high: int) -> int:
    if not _INT_TOKEN.fullmatch(token) or not low <= int(token) <= high:
        raise ValueError(f"{at}: {what} must be an integer in [{low}, {high}], got {token!r:.40}.")
    return int(token)


def _real(token: str, at: str, what: str) -> float:
    value = float(token) if _FLOAT_TOKEN.fullmatch(token) else math.nan
    if not math.isfinite(value):
        raise ValueError(f"{at}: {what} must be a finite number, got {token!r:.40}.")
    return value


def _reals(tokens: list, at: str, what: str) -> np.ndarray:
    if not all(map(_FLOAT_TOKEN.fullmatch, tokens)):
        bad = next(token for token in tokens if not _FLOAT_TOKEN.fullmatch(token))
        raise ValueError(f"{at}: {what} must be finite numbers, got {bad!r:.40}.")
    values = np.array(tokens, dtype=np.float64) if tokens else np.zeros(0)
    if not np.all(np.isfinite(values)):
        bad = tokens[int(np.argmin(np.isfinite(values)))]
        raise ValueError(f"{at}: {what} must be finite numbers, got {bad!r:.40}.")
    return values


def _model_name(model_id, at: str) -> tuple[str, int]:
    """``(name, number of parameters)`` of a pinhole model id; refusal of every other id."""
    if model_id in PINHOLE_MODELS:
        return PINHOLE_MODELS[model_id]
    if model_id in DISTORTED_MODELS:
        _refuse_model(DISTORTED_MODELS[model_id], at)
    raise ValueError(f"{at}: unknown camera model id {model_id}; COLMAP's are "
                     f"{', '.join(f'{i} ({n})' for i, (n, _) in PINHOLE_MODELS.items())}, "
                     f"{', '.join(f'{i} ({n})' for i, n in DISTORTED_MODELS.items())}.")


def _refuse_model(model: str, at: str):
    raise ValueError(f"{at}: camera model {model} is not supported (its keypoints are in distorted pixels); "
                     "only SIMPLE_PINHOLE and PINHOLE are: run `colmap image_undistorter` first and read the "
                     "undistorted model it writes.")


def _camera(camera_id: int, model: str, width: int, height: int, params: np.ndarray, at: str,
            max_pixels: int | None, limit_label: str) -> Camera:
    if width < 1 or height < 1:
        raise ValueError(f"{at}: WIDTH and HEIGHT must be positive, got {width}x{height}.")
    check_pixels(height, width, max_pixels, at, limit_label)
    if not np.all(np.isfinite(params)):
        raise ValueError(f"{at}: the camera parameters must be finite, got {params.tolist()}.")
    focal = params[:1] if model == "SIMPLE_PINHOLE" else params[:2]
    if np.any(focal <= 0):
        raise ValueError(f"{at}: the focal length of a {model} camera must be positive, got {focal.tolist()}.")
    return Camera(camera_id, model, int(width), int(height), _frozen(params.astype(np.float64)))


def _image(image_id, qvec, tvec, camera_id, name, xys, point3d_ids, at: str, points_at: str) -> Image:
    if not np.all(np.isfinite(qvec)) or not np.all(np.isfinite(tvec)) or not np.any(qvec != 0):
        raise ValueError(f"{at}: the pose must be finite with a non-zero quaternion, got QVEC {qvec.tolist()}, "
                         f"TVEC {tvec.tolist()}.")
    if not np.all(np.isfinite(xys)):
        raise ValueError(f"{points_at}: the keypoints X Y must be finite numbers.")
    if np.any(point3d_ids < -1):
        raise ValueError(f"{points_at}: a POINT3D_ID must be >= 0 or -1 (none), got {int(point3d_ids.min())}.")
    return Image(int(image_id), _frozen(qvec), _frozen(tvec), int(camera_id), name, _frozen(xys),
                 _frozen(point3d_ids.astype(np.int64)))


def _add(table: dict, key, value, at: str, what: str) -> None:
    if key in table:
        raise ValueError(f"{at}: {what} {key!r} appears twice.")
    table[key] = value


# --- reading: text


def _text_lines(data: bytes, label: str) -> list[str]:
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{label}: not UTF-8 text (byte offset {exc.start}); expected a COLMAP text file.") from None
    return [line.rstrip("\r") for line in text.split("\n")]


def _is_data(line: str) -> bool:
    stripped = line.strip()
    return bool(stripped) and not stripped.startswith("#")


def _cameras_text(data: bytes, label: str, max_pixels, limit_label: str) -> dict:
    cameras = {}
    for number, line in enumerate(_text_lines(data, label), start=1):
        if not _is_data(line):
            continue
        at = f"{label}, line {number}"
        tokens = line.split()
        if len(tokens) < 4:
            raise ValueError(f"{at}: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[], got {len(tokens)} value(s).")
        camera_id = _integer(tokens[0], at, "CAMERA_ID", 0, _UINT32_MAX)
        model = tokens[1]
        if model in _DISTORTED_IDS:
            _refuse_model(model, at)
        if model not in _PINHOLE_IDS:
            raise ValueError(f"{at}: unknown camera model {model!r:.40}; expected one of COLMAP's "
                             f"({', '.join(name for name, _ in PINHOLE_MODELS.values())}, "
                             f"{', '.join(DISTORTED_MODELS.values())}).")
        count = PINHOLE_MODELS[_PINHOLE_IDS[model]][1]
        if len(tokens) != 4 + count:
            raise ValueError(f"{at}: a {model} camera has {count} parameters, got {len(tokens) - 4}.")
        width = _integer(tokens[2], at, "WIDTH", 1, _INT64_MAX)
        height = _integer(tokens[3], at, "HEIGHT", 1, _INT64_MAX)
        params = _reals(tokens[4:], at, "PARAMS")
        _add(cameras, camera_id, _camera(camera_id, model, width, height, params, at, max_pixels, limit_label),
             at, "CAMERA_ID")
    return cameras


def _images_text(data: bytes, label: str) -> tuple[dict, Callable]:
    lines = _text_lines(data, label)
    images, places = {}, []
    index = 0
    while index < len(lines):
        number, line = index + 1, lines[index]
        index += 1
        if not _is_data(line):
            continue
        at = f"{label}, line {number}"
        tokens = line.split()
        if len(tokens) != 10:
            raise ValueError(f"{at}: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME (10 values), "
                             f"got {len(tokens)}.")
        image_id = _integer(tokens[0], at, "IMAGE_ID", 0, _UINT32_MAX)
        pose = _reals(tokens[1:8], at, "QW QX QY QZ TX TY TZ")
        camera_id = _integer(tokens[8], at, "CAMERA_ID", 0, _UINT32_MAX)
        points_number = index + 1  # the next line holds POINTS2D[], empty if none
        points_line = lines[index] if index < len(lines) else ""
        index += 1
        points_at = f"{label}, line {points_number}"
        tokens2d = points_line.split()
        if len(tokens2d) % 3:
            raise ValueError(f"{points_at}: the line after an image's holds its POINTS2D[] as X Y POINT3D_ID "
                             f"triples (empty if none), got {len(tokens2d)} value(s).")
        xys = _reals(tokens2d[0::3] + tokens2d[1::3], points_at, "POINTS2D X and Y")
        ids_tokens = tokens2d[2::3]
        if not all(map(_INT_TOKEN.fullmatch, ids_tokens)) or any(not -1 <= int(t) <= _INT64_MAX for t in ids_tokens):
            bad = next(t for t in ids_tokens if not _INT_TOKEN.fullmatch(t) or not -1 <= int(t) <= _INT64_MAX)
            raise ValueError(f"{points_at}: a POINT3D_ID must be an integer in [0, {_INT64_MAX}] or -1 (none), "
                             f"got {bad!r:.40}.")
        point3d_ids = np.array([int(t) for t in ids_tokens], dtype=np.int64)
        xys = xys.reshape(2, -1).T.copy()
        image = _image(image_id, pose[:4].copy(), pose[4:].copy(), camera_id, tokens[9], xys, point3d_ids, at,
                       points_at)
        _add(images, image_id, image, at, "IMAGE_ID")
        places.append((at, points_at))
    return images, lambda k, points=False: places[k][1 if points else 0]


def _points_text(data: bytes, label: str) -> tuple[Points3D, Callable]:
    ids, xyz, rgb, error, lengths, track, numbers = [], [], [], [], [], [], []
    for number, line in enumerate(_text_lines(data, label), start=1):
        if not _is_data(line):
            continue
        at = f"{label}, line {number}"
        tokens = line.split()
        if len(tokens) < 8 or (len(tokens) - 8) % 2:
            raise ValueError(f"{at}: expected POINT3D_ID X Y Z R G B ERROR and TRACK[] as IMAGE_ID POINT2D_IDX "
                             f"pairs, got {len(tokens)} value(s).")
        ids.append(_integer(tokens[0], at, "POINT3D_ID", 0, _INT64_MAX))
        xyz.append(_reals(tokens[1:4], at, "X Y Z"))
        rgb.append([_integer(token, at, "R G B", 0, 255) for token in tokens[4:7]])
        error.append(_real(tokens[7], at, "ERROR"))
        pairs = tokens[8:]
        if not all(map(_INT_TOKEN.fullmatch, pairs)) or any(not 0 <= int(t) <= _UINT32_MAX for t in pairs):
            bad = next(t for t in pairs if not _INT_TOKEN.fullmatch(t) or not 0 <= int(t) <= _UINT32_MAX)
            raise ValueError(f"{at}: TRACK[] IMAGE_ID and POINT2D_IDX must be integers in [0, {_UINT32_MAX}], "
                             f"got {bad!r:.40}.")
        track.extend(int(t) for t in pairs)
        lengths.append(len(pairs) // 2)
        numbers.append(number)
    track = np.array(track, dtype=np.int64).reshape(-1, 2)
    points = Points3D(
        ids=_frozen(np.array(ids, dtype=np.int64)),
        xyz=_frozen(np.array(xyz, dtype=np.float64).reshape(-1, 3)),
        rgb=_frozen(np.array(rgb, dtype=np.uint8).reshape(-1, 3)),
        error=_frozen(np.array(error, dtype=np.float64)),
        track_lengths=_frozen(np.array(lengths, dtype=np.int64)),
        track_image_ids=_frozen(track[:, 0].copy()),
        track_point2d_idxs=_frozen(track[:, 1].copy()),
    )
    return points, lambda k: f"{label}, line {numbers[k]}"


# --- reading: binary


class _Bytes:
    """A cursor over the bytes of a binary file whose every read is bounds-checked (one ValueError, with place)."""

    def __init__(self, data: bytes, label: str):
        self.data, self.label, self.offset = data, label, 0
        self.record = "header"

    def at(self, offset: int | None = None) -> str:
        return f"{self.label}, {self.record} (byte offset {self.offset if offset is None else offset})"

    def start(self, record: str) -> None:
        self.record = record

    def need(self, size: int, what: str) -> None:
        """``ValueError`` naming the place unless ``size`` bytes remain."""
        if size > len(self.data) - self.offset:
            raise ValueError(f"{self.at()}: truncated: {what} needs {size} bytes, {len(self.data) - self.offset} "
                             "remain.")

    def unpack(self, layout: struct.Struct, what: str) -> tuple:
        self.need(layout.size, what)
        values = layout.unpack_from(self.data, self.offset)
        self.offset += layout.size
        return values

    def array(self, dtype: np.dtype, count: int, what: str) -> np.ndarray:
        self.need(count * dtype.itemsize, f"{what} ({count} x {dtype.itemsize} bytes)")
        values = np.frombuffer(self.data, dtype=dtype, count=count, offset=self.offset)
        self.offset += count * dtype.itemsize
        return values

    def name(self) -> str:
        end = self.data.find(b"\x00", self.offset)
        if end < 0:
            raise ValueError(f"{self.at()}: truncated: the image NAME has no terminating NUL byte.")
        raw = self.data[self.offset:end]
        try:
            name = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise ValueError(f"{self.at()}: the image NAME is not UTF-8 ({raw[:40]!r}).") from None
        if not name:
            raise ValueError(f"{self.at()}: the image NAME is empty.")
        self.offset = end + 1
        return name

    def count(self, what: str) -> int:
        self.start("header")
        return self.unpack(_COUNT, what)[0]

    def finish(self, count: int, what: str) -> None:
        if self.offset != len(self.data):
            raise ValueError(f"{self.label}: the header declares {count} {what} but {len(self.data) - self.offset} "
                             f"bytes follow the last one (byte offset {self.offset}).")


def _cameras_binary(data: bytes, label: str, max_pixels, limit_label: str) -> dict:
    cursor = _Bytes(data, label)
    count = cursor.count("the number of cameras")
    cameras = {}
    for k in range(count):
        cursor.start(f"camera record {k + 1} of {count}")
        start = cursor.offset
        camera_id, model_id, width, height = cursor.unpack(_CAMERA_RECORD, "CAMERA_ID MODEL_ID WIDTH HEIGHT")
        at = cursor.at(start)
        model, n_params = _model_name(model_id, at)
        params = np.array(cursor.unpack(struct.Struct(f"<{n_params}d"), f"the {model} parameters"))
        _add(cameras, camera_id, _camera(camera_id, model, width, height, params, at, max_pixels, limit_label),
             at, "CAMERA_ID")
    cursor.finish(count, "cameras")
    return cameras


def _images_binary(data: bytes, label: str) -> tuple[dict, Callable]:
    cursor = _Bytes(data, label)
    count = cursor.count("the number of images")
    images, places = {}, []
    for k in range(count):
        cursor.start(f"image record {k + 1} of {count}")
        start = cursor.offset
        at = cursor.at(start)
        image_id, qw, qx, qy, qz, tx, ty, tz, camera_id = cursor.unpack(_IMAGE_RECORD, "IMAGE_ID QVEC TVEC CAMERA_ID")
        name = cursor.name()
        n_points = cursor.unpack(_COUNT, "the number of POINTS2D")[0]
        points = cursor.array(_POINT2D, n_points, "POINTS2D[] as X Y POINT3D_ID")
        xys = np.column_stack([points["x"], points["y"]]).astype(np.float64)
        image = _image(image_id, np.array([qw, qx, qy, qz]), np.array([tx, ty, tz]), camera_id, name, xys,
                       points["point3d_id"].astype(np.int64), at, at)
        _add(images, image_id, image, at, "IMAGE_ID")
        places.append(at)
    cursor.finish(count, "images")
    return images, lambda k, points=False: places[k]


def _byte_ranges(size: int, starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """Boolean mask of the ``size`` bytes inside the disjoint ranges ``[starts[k], stops[k])``."""
    delta = np.zeros(size + 1, dtype=np.int8)
    delta[starts] += 1
    delta[stops] -= 1
    return np.cumsum(delta[:-1], dtype=np.int8) > 0


def _points_binary(data: bytes, label: str) -> tuple[Points3D, Callable]:
    cursor = _Bytes(data, label)
    count = cursor.count("the number of 3-D points")
    # the records have variable lengths: one pass finds where each starts, then every field is gathered at once
    fixed = _POINT_FIXED.itemsize
    starts, offset, size, track_length_at = [], cursor.offset, len(data), _COUNT.unpack_from
    for k in range(count):
        if fixed > size - offset:
            cursor.start(f"point record {k + 1} of {count}")
            cursor.offset = offset
            cursor.need(fixed, "POINT3D_ID X Y Z R G B ERROR and the TRACK length")
        starts.append(offset)
        track_length = track_length_at(data, offset + fixed - 8)[0]
        offset += fixed + 8 * track_length
        if offset > size:
            cursor.start(f"point record {k + 1} of {count}")
            cursor.offset = starts[-1] + fixed
            cursor.need(8 * track_length, f"TRACK[] as IMAGE_ID POINT2D_IDX ({track_length} x 8 bytes)")
    cursor.offset = offset
    cursor.finish(count, "3-D points")
    starts = np.array(starts, dtype=np.int64)
    raw = np.frombuffer(data, dtype=np.uint8)
    records = raw[_byte_ranges(size, starts, starts + fixed)].view(_POINT_FIXED)
    stops = np.append(starts[1:], offset)[:starts.size]
    track = raw[_byte_ranges(size, starts + fixed, stops)].view(_TRACK_ELEMENT)

    def place(k: int) -> str:
        return f"{label}, point record {k + 1} of {count} (byte offset {starts[k]})"

    too_large = records["id"] > _INT64_MAX
    if np.any(too_large):
        k = int(np.argmax(too_large))
        raise ValueError(f"{place(k)}: POINT3D_ID {int(records['id'][k])} is above {_INT64_MAX}.")
    finite = np.all(np.isfinite(records["xyz"]), axis=1) & np.isfinite(records["error"])
    if not np.all(finite):
        k = int(np.argmin(finite))
        raise ValueError(f"{place(k)}: X Y Z and ERROR must be finite, got {records['xyz'][k].tolist()} and "
                         f"{float(records['error'][k])}.")
    points = Points3D(
        ids=_frozen(records["id"].astype(np.int64)),
        xyz=_frozen(records["xyz"].astype(np.float64)),
        rgb=_frozen(records["rgb"].astype(np.uint8)),
        error=_frozen(records["error"].astype(np.float64)),
        track_lengths=_frozen(records["track_length"].astype(np.int64)),
        track_image_ids=_frozen(track["image_id"].astype(np.int64)),
        track_point2d_idxs=_frozen(track["point2d_idx"].astype(np.int64)),
    )
    return points, place


# --- reading: the model


def _check_links(cameras: dict, images: dict, image_at: Callable, points: Points3D, point_at: Callable,
                 points_label: str) -> None:
    """Every reference between the three files resolves, and tracks and observations agree."""
    sorted_ids = np.sort(points.ids)
    duplicate = np.flatnonzero(sorted_ids[1:] == sorted_ids[:-1])
    if duplicate.size:
        twice = sorted_ids[duplicate[0]]
        raise ValueError(f"{point_at(int(np.flatnonzero(points.ids == twice)[1]))}: POINT3D_ID {twice} appears twice.")
    for k, image in enumerate(images.values()):
        if image.camera_id not in cameras:
            raise ValueError(f"{image_at(k)}: image {image.id} names CAMERA_ID {image.camera_id}, which cameras "
                             f"does not define.")
        observed = image.point3d_ids[image.point3d_ids >= 0]
        missing = points.index_of(observed) < 0
        if np.any(missing):
            raise ValueError(f"{image_at(k, points=True)}: image {image.id} observes POINT3D_ID "
                             f"{int(observed[np.argmax(missing)])}, which {points_label} does not define.")
    # each track element names an image, one of its keypoints, and that keypoint observes this point; a track
    # element naming no image gets the padding slot len(images), which has no keypoints
    image_ids = np.array(list(images), dtype=np.int64)
    counts = np.array([image.point3d_ids.size for image in images.values()] + [0], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)])
    observed_ids = np.concatenate([image.point3d_ids for image in images.values()] + [np.array([-1])])
    owner = np.repeat(np.arange(len(points), dtype=np.int64), points.track_lengths)
    sorter = np.argsort(image_ids)
    slot = np.searchsorted(image_ids[sorter], points.track_image_ids)
    position = np.full(slot.shape, len(images), dtype=np.int64)
    inside = slot < len(images)
    position[inside] = sorter[slot[inside]]
    known = np.zeros(slot.shape, dtype=bool)
    known[inside] = image_ids[position[inside]] == points.track_image_ids[inside]
    position[~known] = len(images)
    in_range = known & (points.track_point2d_idxs < counts[position])
    keypoint = np.where(in_range, starts[position] + points.track_point2d_idxs, observed_ids.size - 1)
    agrees = in_range & (observed_ids[keypoint] == points.ids[owner])
    if not np.all(agrees):
        e = int(np.argmin(agrees))
        image_id, idx = int(points.track_image_ids[e]), int(points.track_point2d_idxs[e])
        reason = ("no such IMAGE_ID in images" if not known[e] else
                  f"image {image_id} has {int(counts[position[e]])} keypoints"
                  if not in_range[e] else
                  f"that keypoint observes POINT3D_ID {int(observed_ids[keypoint[e]])}")
        raise ValueError(f"{point_at(int(owner[e]))}: TRACK element (IMAGE_ID {image_id}, POINT2D_IDX {idx}) of "
                         f"POINT3D_ID {int(points.ids[owner[e]])} does not match the images file: {reason}.")
    # and each observation of a point is in its track: as many observations as track elements
    rows = points.index_of(observed_ids[observed_ids >= 0])
    observations = np.bincount(rows, minlength=len(points))
    if np.any(observations != points.track_lengths):
        k = int(np.argmax(observations != points.track_lengths))
        raise ValueError(f"{point_at(k)}: POINT3D_ID {int(points.ids[k])} has a TRACK of "
                         f"{int(points.track_lengths[k])} element(s) but {int(observations[k])} keypoint(s) of the "
                         "images file observe it.")


def _model_folder(path, name: str) -> Path:
    folder, mode = stat_path(path, name=name, missing="COLMAP model folder")
    if not stat.S_ISDIR(mode):
        raise ValueError(f"{file_label(folder, name)} is not a folder; expected a COLMAP model folder holding "
                         "cameras, images and points3D (.bin or .txt).")
    return folder.resolve()


def _choose_format(folder: Path, file_format, name: str) -> str:
    if file_format is not None and file_format not in _EXTENSIONS:
        raise ValueError(f"`file_format` must be 'binary', 'text' or None (binary if present, else text), "
                         f"got {file_format!r}.")
    present = {kind: [(folder / (stem + ext)).exists() or (folder / (stem + ext)).is_symlink() for stem in MODEL_FILES]
               for kind, ext in _EXTENSIONS.items()}
    for kind in ([file_format] if file_format else ["binary", "text"]):
        if all(present[kind]):
            return kind
    wanted = [file_format] if file_format else ["binary", "text"]
    missing = "; ".join(", ".join(stem + _EXTENSIONS[kind] for stem, there in zip(MODEL_FILES, present[kind])
                                  if not there) + f" ({kind})" for kind in wanted)
    raise FileNotFoundError(f"{file_label(folder, name)}: not a complete COLMAP model: missing {missing}.")


def _read_model_file(folder: Path, file_name: str, name: str) -> tuple[bytes, str]:
    """The bytes of ``folder/file_name`` and its label; refused unless a regular file inside ``folder``."""
    path = folder / file_name
    label = file_label(path, name)
    try:
        target = path.resolve(strict=True)
    except (FileNotFoundError, NotADirectoryError):
        raise FileNotFoundError(f"{label}: no such file (a broken symbolic link?).") from None
    except (OSError, RuntimeError) as exc:
        raise ValueError(f"{label}: cannot be resolved ({exc}).") from None
    if not target.is_relative_to(folder):
        raise ValueError(f"{label} is a symbolic link to '{target}', outside the model folder; refused.")
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0)
    try:
        descriptor = os.open(target, flags)
    except OSError as exc:
        raise ValueError(f"{label}: cannot be opened ({exc}).") from None
    with open(descriptor, "rb", closefd=True) as handle:
        if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
            raise ValueError(f"{label} is not a regular file; refused.")
        try:
            return handle.read(), label
        except OSError as exc:
            raise ValueError(f"{label}: cannot be read ({exc}).") from None


def read_colmap_model(path, *, file_format: str | None = None, name: str = "path",
                      max_pixels: int | None = MAX_PIXELS) -> ColmapModel:
    """Read a COLMAP sparse model folder (``cameras``, ``images`` and ``points3D``, binary or text).

    Parameters
    ----------
    path : str or os.PathLike
        The model folder (e.g. ``sparse/0``, or the ``sparse`` folder
        ``colmap image_undistorter`` writes).
    file_format : {"binary", "text"}, optional
        Which files to read: ``cameras.bin``, ``images.bin``,
        ``points3D.bin`` or the ``.txt`` ones.  By default the binary files
        if all three are there (as COLMAP does), else the text files.
    name : str, optional
        How ``path`` is named in messages (``"--colmap"`` on the command
        line).
    max_pixels : int or None, optional
        Largest ``WIDTH * HEIGHT`` accepted for a camera (the size of the
        depth map :func:`view_depth` allocates); None for no limit.

    Returns
    -------
    ColmapModel

    Raises
    ------
    FileNotFoundError
        If the folder is missing or lacks one of the three files.
    ValueError
        If a file is not a regular file, is a symbolic link leading outside
        the folder, or its content is malformed: the message names the file
        and the line (text) or the record and byte offset (binary).  That
        covers a wrong number of values, a value that is not a number (or
        not finite, or out of range), truncated binary data, a declared count
        that does not match the records, a non-positive size, a repeated id,
        an image whose ``CAMERA_ID`` or an observation whose ``POINT3D_ID``
        is not defined, a track that does not match the images' keypoints, an
        unknown camera model, and a camera model with distortion (the
        message says to run ``colmap image_undistorter`` first).
    TypeError
        If ``path`` is not a str or os.PathLike.

    Notes
    -----
    The layout is COLMAP's "Output Format": text files hold one record a
    line (``#`` comments and blank lines are skipped; the line after an
    image's holds its ``POINTS2D[]``, empty when it has none); binary files
    are little-endian, a ``uint64`` count then the records:

    * camera: ``uint32`` CAMERA_ID, ``int32`` MODEL_ID, ``uint64`` WIDTH,
      HEIGHT, ``float64`` PARAMS[];
    * image: ``uint32`` IMAGE_ID, ``float64`` QW QX QY QZ TX TY TZ,
      ``uint32`` CAMERA_ID, the NUL-terminated NAME, ``uint64`` count of
      POINTS2D, each ``float64`` X, Y and ``int64`` POINT3D_ID (``-1`` for
      none);
    * point: ``uint64`` POINT3D_ID, ``float64`` X Y Z, ``uint8`` R G B,
      ``float64`` ERROR, ``uint64`` track length, each ``uint32`` IMAGE_ID,
      POINT2D_IDX.

    Poses are world-to-camera (:math:`X_c = R X + t`, see
    :func:`rotation_from_qvec`); pixel coordinates put the centre of the
    top-left pixel at ``(0.5, 0.5)``.  Only the three files are opened,
    nothing is executed or unpickled.
    """
    folder = _model_folder(path, name)
    limit_label = "`max_pixels`"
    max_pixels = check_max_pixels(max_pixels, limit_label)
    kind = _choose_format(folder, file_format, name)
    ext = _EXTENSIONS[kind]
    contents = {stem: _read_model_file(folder, stem + ext, name) for stem in MODEL_FILES}
    if kind == "binary":
        cameras = _cameras_binary(*contents["cameras"], max_pixels, limit_label)
        images, image_at = _images_binary(*contents["images"])
        points, point_at = _points_binary(*contents["points3D"])
    else:
        cameras = _cameras_text(*contents["cameras"], max_pixels, limit_label)
        images, image_at = _images_text(*contents["images"])
        points, point_at = _points_text(*contents["points3D"])
    _check_links(cameras, images, image_at, points, point_at, "points3D" + ext)
    names = {}
    for k, image in enumerate(images.values()):
        _add(names, image.name, image.id, image_at(k), "image NAME")
    return ColmapModel(cameras=cameras, images=images, points3d=points)


# --- writing


def _text_number(value) -> str:
    return repr(float(value))


def _cameras_bytes(model: ColmapModel, kind: str) -> bytes:
    if kind == "text":
        lines = ["# Camera list with one line of data per camera:", "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
                 f"# Number of cameras: {len(model.cameras)}"]
        for camera in model.cameras.values():
            lines.append(" ".join([str(camera.id), camera.model, str(camera.width), str(camera.height)]
                                  + [_text_number(p) for p in camera.params]))
        return ("\n".join(lines) + "\n").encode()
    out = bytearray(_COUNT.pack(len(model.cameras)))
    for camera in model.cameras.values():
        out += _CAMERA_RECORD.pack(camera.id, _PINHOLE_IDS[camera.model], camera.width, camera.height)
        out += np.asarray(camera.params, dtype="<f8").tobytes()
    return bytes(out)


def _images_bytes(model: ColmapModel, kind: str) -> bytes:
    if kind == "text":
        lines = ["# Image list with two lines of data per image:",
                 "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME", "#   POINTS2D[] as (X, Y, POINT3D_ID)",
                 f"# Number of images: {len(model.images)}"]
        for image in model.images.values():
            lines.append(" ".join([str(image.id)] + [_text_number(v) for v in (*image.qvec, *image.tvec)]
                                  + [str(image.camera_id), image.name]))
            lines.append(" ".join(f"{_text_number(x)} {_text_number(y)} {int(p)}"
                                  for (x, y), p in zip(image.xys, image.point3d_ids)))
        return ("\n".join(lines) + "\n").encode()
    out = bytearray(_COUNT.pack(len(model.images)))
    for image in model.images.values():
        out += _IMAGE_RECORD.pack(image.id, *map(float, image.qvec), *map(float, image.tvec), image.camera_id)
        out += image.name.encode("utf-8") + b"\x00" + _COUNT.pack(len(image.point3d_ids))
        points = np.zeros(len(image.point3d_ids), dtype=_POINT2D)
        points["x"], points["y"], points["point3d_id"] = image.xys[:, 0], image.xys[:, 1], image.point3d_ids
        out += points.tobytes()
    return bytes(out)


def _points_bytes(model: ColmapModel, kind: str) -> bytes:
    points = model.points3d
    ends = np.cumsum(points.track_lengths)
    starts = ends - points.track_lengths
    if kind == "text":
        lines = ["# 3D point list with one line of data per point:",
                 "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)",
                 f"# Number of points: {len(points)}"]
        for k in range(len(points)):
            track = np.column_stack([points.track_image_ids[starts[k]:ends[k]],
                                     points.track_point2d_idxs[starts[k]:ends[k]]]).ravel()
            lines.append(" ".join([str(int(points.ids[k]))] + [_text_number(v) for v in points.xyz[k]]
                                  + [str(int(c)) for c in points.rgb[k]] + [_text_number(points.error[k])]
                                  + [str(int(t)) for t in track]))
        return ("\n".join(lines) + "\n").encode()
    out = bytearray(_COUNT.pack(len(points)))
    for k in range(len(points)):
        out += _POINT_RECORD.pack(int(points.ids[k]), *map(float, points.xyz[k]), *map(int, points.rgb[k]),
                                  float(points.error[k]))
        track = np.zeros(int(points.track_lengths[k]), dtype=_TRACK_ELEMENT)
        track["image_id"] = points.track_image_ids[starts[k]:ends[k]]
        track["point2d_idx"] = points.track_point2d_idxs[starts[k]:ends[k]]
        out += _COUNT.pack(track.size) + track.tobytes()
    return bytes(out)


def write_colmap_model(model: ColmapModel, path, *, file_format: str = "binary") -> None:
    """Write ``model`` to the folder ``path`` as COLMAP's three files, binary or text.

    Parameters
    ----------
    model : ColmapModel
        Pinhole cameras only (what :func:`read_colmap_model` returns).
    path : str or os.PathLike
        An existing folder; ``cameras``, ``images`` and ``points3D`` with the
        extension of ``file_format`` are replaced there, each atomically.
    file_format : {"binary", "text"}, optional
        ``.bin`` (default, COLMAP's default too) or ``.txt``.

    Raises
    ------
    FileNotFoundError
        If the folder does not exist.
    ValueError
        For an unsupported camera model, an image name with white space (the
        text format cannot hold it) or an unknown ``file_format``.

    Notes
    -----
    The layout is the one :func:`read_colmap_model` reads.  Text numbers are
    written with Python's shortest round-trip representation, so a model
    written as text and read back is equal to the original bit for bit.
    """
    if not isinstance(model, ColmapModel):
        raise TypeError(f"`model` must be a ColmapModel, got {type(model).__name__}.")
    if file_format not in _EXTENSIONS:
        raise ValueError(f"`file_format` must be 'binary' or 'text', got {file_format!r}.")
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"`path` must be a str or os.PathLike, got {type(path).__name__}.")
    folder = Path(path)
    if not folder.is_dir():
        raise FileNotFoundError(f"`path`: folder '{folder}' does not exist.")
    for camera in model.cameras.values():
        _pinhole(camera)
    if file_format == "text":
        for image in model.images.values():
            if not image.name or len(image.name.split()) != 1 or image.name.split()[0] != image.name:
                raise ValueError(f"image {image.id}: the name {image.name!r} is empty or holds white space, which "
                                 "the text format cannot store; write the binary format.")
    ext = _EXTENSIONS[file_format]
    writers = {"cameras": _cameras_bytes, "images": _images_bytes, "points3D": _points_bytes}
    for stem in MODEL_FILES:
        data = writers[stem](model, file_format)
        with atomic_target(folder / (stem + ext)) as target:
            target.write_bytes(data)
