"""Depth as a picture: :func:`colorize_depth` turns a depth map into an RGB image a viewer can show.

A 16-bit metric PNG looks black in an ordinary image viewer (a few metres
are a few thousand of 65535 grey levels); :func:`colorize_depth` maps depth
through :data:`DEPTH_COLORMAP`, a colour map whose lightness rises steadily
from far (dark blue) to near (pale yellow), and draws missing pixels in a
neutral grey.  :func:`depth_colour_scale` says where it puts each depth (the
range, linear or inverse-depth spacing, round depths for a colour bar's
ticks), so that a figure's colour bar matches its pictures.

Imports NumPy and :mod:`sparsedepth._validation` only (no matplotlib).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._validation import check_rgb_colour, is_real

__all__ = ["DEPTH_COLORMAP", "DEPTH_COLORMAP_ANCHORS", "MISSING_COLOUR", "DEPTH_RANGE_PERCENTILES", "INVERSE_DEPTH_RATIO", "DepthColourScale",
           "depth_colour_scale", "colorize_depth"]

#: sRGB anchors of the depth colour map, far (first) to near (last).  Each is
#: the CIE 1976 L*a*b* colour with lightness L* = 8, 22, 36, 50, 64, 78, 92
#: and hue angle h = 285, 310, 340, 15, 45, 70, 95 degrees (blue, violet,
#: magenta, red, orange, amber, pale yellow), with the largest chroma (at
#: most 85) that stays inside the sRGB gamut, rounded to 8 bits.
DEPTH_COLORMAP_ANCHORS = np.array([
    (0, 23, 57),
    (67, 26, 128),
    (161, 0, 124),
    (236, 0, 88),
    (255, 110, 62),
    (255, 176, 84),
    (255, 232, 135),
], dtype=np.float64)

#: The colour map as a (256, 3) uint8 table, index 0 = far, 255 = near: the
#: anchors interpolated linearly in sRGB at equal spacing.
DEPTH_COLORMAP = np.stack([
    np.interp(np.linspace(0.0, 1.0, 256), np.linspace(0.0, 1.0, len(DEPTH_COLORMAP_ANCHORS)),
              DEPTH_COLORMAP_ANCHORS[:, channel])
    for channel in range(3)
], axis=1).round().astype(np.uint8)
DEPTH_COLORMAP.setflags(write=False)

#: Colour of pixels without depth: mid grey (CIE L* 54, no hue), unlike any
#: colour of the map at that lightness.
MISSING_COLOUR = (128, 128, 128)

#: Percentiles of the valid depths that bound the colours when ``vmin``/``vmax`` are not given.
DEPTH_RANGE_PERCENTILES = (2.0, 98.0)
#: ``scale="auto"`` colours by inverse depth when ``vmax / vmin`` is at least this: a street scene (KITTI: 3-80 m)
#: rather than a room (NYU, TUM, RealSense: a factor of 2-6), where a linear scale would give the near tenth of
#: the range, where most of the structure is, a few colours only.
INVERSE_DEPTH_RATIO = 8.0
_SCALES = ("auto", "linear", "inverse")


def _check_depth(depth) -> np.ndarray:
    array = np.asarray(depth)
    if not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise TypeError(f"depth must be a real-valued array (integer or float), got dtype {array.dtype}; "
                        "convert it with depth.astype(float)")
    if array.ndim != 2:
        raise ValueError(f"depth must be a 2-D (H, W) array, got shape {array.shape}; pass one depth map")
    return array


def _check_limit(value, name: str) -> float | None:
    if value is None:
        return None
    if not is_real(value):
        raise TypeError(f"{name} must be a real number or None, got {type(value).__name__}")
    number = float(value)
    if not np.isfinite(number):
        raise ValueError(f"{name} must be finite, got {value!r}; give a depth in the map's units or None")
    return number


def colorize_depth(depth, *, vmin=None, vmax=None, missing=MISSING_COLOUR, scale="auto") -> np.ndarray:
    """Depth map to an RGB image: near pixels bright and warm, far pixels dark and blue, missing ones grey.

    Parameters
    ----------
    depth : array_like, (H, W)
        Depth in any unit (integers or floats).  Pixels that are NaN,
        infinite or ``<= 0`` are missing.
    vmin, vmax : float, optional
        Depth drawn in the nearest (``vmin``) and the farthest (``vmax``)
        colour; depth outside is clipped to them.  Defaults: the 2nd and
        98th percentiles of the valid pixels, so a few outliers do not
        flatten the picture.
    missing : sequence of 3 ints in [0, 255]
        Colour of the missing pixels (default mid grey, ``(128, 128, 128)``).
    scale : {"auto", "linear", "inverse"}
        Colours equally spaced in depth (``"linear"``) or in inverse depth
        (``"inverse"``, the convention of outdoor depth figures: near
        structure gets most of the colours); ``"auto"`` (default) picks
        ``"inverse"`` when ``vmax / vmin >=`` :data:`INVERSE_DEPTH_RATIO`.

    Returns
    -------
    ndarray of uint8, (H, W, 3)
        A new sRGB image; ``depth`` is not modified.

    Raises
    ------
    TypeError
        ``depth`` is not a numeric array, or ``vmin``/``vmax`` is not a
        real number, or ``missing`` is not a sequence of numbers.
    ValueError
        ``depth`` is not 2-D, ``vmin``/``vmax`` is not finite, both are
        given with ``vmin >= vmax``, or ``missing`` is not three integers in
        [0, 255].

    Notes
    -----
    A valid depth ``d`` becomes the entry ``k = round(255 (1 - t))`` of
    :data:`DEPTH_COLORMAP` with

    .. math:: t = \\operatorname{clip}\\left(\\frac{d - v_{min}}{v_{max} - v_{min}}, 0, 1\\right),

    or with ``scale="inverse"`` ``t = clip((1/v_min − 1/d) / (1/v_min −
    1/v_max), 0, 1)``, so ``vmin`` is entry 255 (pale yellow) and ``vmax``
    entry 0 (dark blue).  When the range is empty (a constant map, or a default limit on
    the wrong side of the given one), ``t`` is 0 below ``vmin``, 1 above it
    and 1/2 at it.

    The map is built from seven anchors of equally spaced CIE L* (8 to 92)
    with hues turning from blue through violet, magenta, red and orange to
    yellow (:data:`DEPTH_COLORMAP_ANCHORS`), interpolated linearly in sRGB:
    lightness increases monotonically towards the near end, so the order of
    depths reads in grey-scale print and for colour-blind viewers, and the
    hue turn separates neighbouring depths better than lightness alone.  It
    is a map of its own (not matplotlib's), in the convention of the KITTI
    and NYU depth figures (near bright, far dark).

    Examples
    --------
    >>> import numpy as np
    >>> rgb = colorize_depth(np.array([[1.0, 2.0], [np.nan, 3.0]]), vmin=1.0, vmax=3.0)
    >>> rgb.shape, rgb.dtype
    ((2, 2, 3), dtype('uint8'))
    >>> rgb[0, 0].tolist(), rgb[1, 1].tolist(), rgb[1, 0].tolist()
    ([255, 232, 135], [0, 23, 57], [128, 128, 128])
    """
    array = _check_depth(depth)
    low, high = _check_limit(vmin, "vmin"), _check_limit(vmax, "vmax")
    if low is not None and high is not None and low >= high:
        raise ValueError(f"vmin must be below vmax, got vmin={low!r} and vmax={high!r}; swap them or widen the range")
    colour = np.asarray(check_rgb_colour(missing, name="missing"), dtype=np.uint8)
    if not isinstance(scale, str) or scale not in _SCALES:
        raise ValueError(f"scale must be one of {list(_SCALES)}, got {scale!r}")

    values = array.astype(np.float64)  # a copy: the caller's array is never modified
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(values) & (values > 0)
    rgb = np.empty(values.shape + (3,), dtype=np.uint8)
    rgb[...] = colour
    if not valid.any():
        return rgb
    colours = _resolve_scale(values[valid], low, high, scale)
    index = np.rint(255.0 * (1.0 - colours.position(values[valid]))).astype(np.intp)
    rgb[valid] = DEPTH_COLORMAP[index]
    return rgb


@dataclass(frozen=True)
class DepthColourScale:
    """Where :func:`colorize_depth` puts a depth on its colour map: the range and the spacing of the colours.

    Attributes
    ----------
    vmin, vmax : float
        Depth of the nearest (pale yellow) and the farthest (dark blue)
        colour, in the depth's units.
    scale : {"linear", "inverse"}
        Colours equally spaced in depth or in inverse depth.
    """

    vmin: float
    vmax: float
    scale: str

    def position(self, depth) -> np.ndarray:
        """Place ``t`` in [0, 1] of each depth between ``vmin`` (0) and ``vmax`` (1), as in :func:`colorize_depth`.

        Parameters
        ----------
        depth : array_like
            Positive depths (any shape).

        Returns
        -------
        ndarray of float64
            ``t``, same shape; colour map entry ``round(255 (1 - t))``.
        """
        d = np.asarray(depth, dtype=np.float64)
        low, high = self.vmin, self.vmax
        if not high > low:
            return 0.5 + 0.5 * np.sign(d - low)
        if self.scale == "inverse":
            return np.clip((1.0 / low - 1.0 / d) / (1.0 / low - 1.0 / high), 0.0, 1.0)
        return np.clip((d - low) / (high - low), 0.0, 1.0)

    def ticks(self, count: int = 6) -> np.ndarray:
        """Round depths in ``[vmin, vmax]`` for the ticks of a colour bar: at most about ``count``, spread evenly.

        Parameters
        ----------
        count : int, default 6
            About how many ticks (at least 2).

        Returns
        -------
        ndarray of float64
            Increasing depths; none when ``vmin == vmax``.

        Notes
        -----
        Linear scale: the multiples in range of the smallest step ``s`` of
        the form 1, 2, 2.5 or 5 times a power of ten with
        ``s >= (vmax - vmin) / (count + 1)``.  Inverse scale: the numbers 1, 1.5,
        2, 3, 4, 5 and 7 times a power of ten in range, kept from the near
        end whenever their :meth:`position` is at least ``0.75 / count``
        beyond the last one kept.
        """
        count = max(int(count), 2)
        low, high = self.vmin, self.vmax
        if not high > low:
            return np.array([low])
        if self.scale == "linear":
            raw = (high - low) / (count + 1)
            power = 10.0 ** np.floor(np.log10(raw))
            step = next(m * power for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * power >= raw * (1 - 1e-9))
            ticks = np.arange(np.ceil(low / step - 1e-9), np.floor(high / step + 1e-9) + 1) * step
            return np.round(ticks, 12)
        powers = 10.0 ** np.arange(np.floor(np.log10(low)), np.ceil(np.log10(high)) + 1)
        candidates = np.unique(np.round(np.outer(powers, (1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 7.0)).ravel(), 12))
        candidates = candidates[(candidates >= low * (1 - 1e-9)) & (candidates <= high * (1 + 1e-9))]
        kept, last = [], -np.inf
        for value, place in zip(candidates, self.position(candidates)):
            if place - last >= 0.75 / count:
                kept.append(value)
                last = place
        return np.array(kept)


def _resolve_scale(valid_values, low, high, scale) -> DepthColourScale:
    """The :class:`DepthColourScale` of the valid depths with the limits given (None: percentiles) and ``scale``."""
    if low is None or high is None:
        p_low, p_high = np.percentile(valid_values, DEPTH_RANGE_PERCENTILES)
        if low is None and high is None:
            low, high = float(p_low), float(p_high)
        elif low is None:
            low = min(float(p_low), high)
        else:
            high = max(float(p_high), low)
    if scale == "auto":
        scale = "inverse" if low > 0 and high >= INVERSE_DEPTH_RATIO * low else "linear"
    if scale == "inverse" and not low > 0:
        scale = "linear"
    return DepthColourScale(float(low), float(high), scale)


def depth_colour_scale(depth, *, vmin=None, vmax=None, scale="auto") -> DepthColourScale:
    """The range and spacing of colours :func:`colorize_depth` uses for ``depth`` with the same arguments.

    For a colour bar beside a picture of :func:`colorize_depth`: the bar's
    colours are ``DEPTH_COLORMAP[round(255 (1 - t))]`` at ``t`` in [0, 1],
    and its ticks :meth:`DepthColourScale.ticks` sit at
    :meth:`DepthColourScale.position`.

    Parameters
    ----------
    depth, vmin, vmax, scale
        As :func:`colorize_depth`'s.

    Returns
    -------
    DepthColourScale
        With ``scale`` ``"linear"`` or ``"inverse"`` (``"auto"`` decided).

    Raises
    ------
    TypeError, ValueError
        As :func:`colorize_depth`; also a ``ValueError`` when a limit is
        left to the percentiles and ``depth`` has no valid pixel.

    Examples
    --------
    >>> import numpy as np
    >>> colours = depth_colour_scale(np.array([[3.0, 80.0]]), vmin=3.0, vmax=80.0)
    >>> colours.scale, colours.ticks().tolist()
    ('inverse', [3.0, 4.0, 5.0, 7.0, 10.0, 20.0])
    """
    array = _check_depth(depth)
    low, high = _check_limit(vmin, "vmin"), _check_limit(vmax, "vmax")
    if low is not None and high is not None and low >= high:
        raise ValueError(f"vmin must be below vmax, got vmin={low!r} and vmax={high!r}; swap them or widen the range")
    if not isinstance(scale, str) or scale not in _SCALES:
        raise ValueError(f"scale must be one of {list(_SCALES)}, got {scale!r}")
    values = array.astype(np.float64)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(values) & (values > 0)
    if (low is None or high is None) and not valid.any():
        raise ValueError("depth has no valid pixel (finite and > 0) to take the colour range from; give vmin and "
                         "vmax")
    return _resolve_scale(values[valid], low, high, scale)
