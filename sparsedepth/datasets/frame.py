"""The :class:`Frame` type, its units, the camera constants and the helpers every frame source shares.

What lives here: :class:`Frame` and :data:`UNITS`; :data:`NYU_RGB_INTRINSICS`
and :data:`MOTORCYCLE_CALIBRATION`; :func:`as_rgb`; and the builder of the
NYU mmsegmentation frame (:func:`nyu_mmseg_frame`), which both the shipped
copy (:mod:`.embedded`) and the shared-folder copy (:mod:`.shared`) use.

Imports NumPy and :mod:`sparsedepth.io` only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..io import StereoCalibration, read_depth_png, read_image

__all__ = [
    "Frame",
    "MMSEG_CLIP_M",
    "MMSEG_NAME",
    "MOTORCYCLE_CALIBRATION",
    "NYU_RGB_INTRINSICS",
    "UNITS",
    "as_rgb",
    "nyu_mmseg_frame",
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


def as_rgb(image: np.ndarray, path) -> np.ndarray:
    """``image`` as (H, W, 3) RGB: a grey image is repeated on three channels.

    Raises ``ValueError`` naming ``path`` unless ``image`` is 8-bit.
    """
    if image.dtype != np.uint8:
        raise ValueError(f"'{path}': expected an 8-bit RGB image, got dtype {image.dtype}.")
    if image.ndim == 2:
        image = np.repeat(image[:, :, None], 3, axis=2)
    return image


MMSEG_NAME = "bookstore_0001d_00001"
MMSEG_CLIP_M = 10.0  # stored 10000 mm: the depth was clipped there


def nyu_mmseg_frame(image_path, depth_path, source: str) -> Frame:
    """The NYU ``bookstore_0001d_00001`` frame (mmsegmentation fixture) from its two files.

    Depth is mm / 1000; the stored 0 and the clip value :data:`MMSEG_CLIP_M`
    (10000 mm) are invalid (NaN).  ``source`` is the frame's ``source`` text.
    """
    depth = read_depth_png(depth_path, 1000.0)
    depth[depth == MMSEG_CLIP_M] = np.nan
    return Frame(
        name=f"nyu_mmseg_pseudo/{MMSEG_NAME}",
        dataset="NYU Depth V2",
        image=as_rgb(read_image(image_path), image_path),
        depth=depth,
        units="m",
        source=source,
    )
