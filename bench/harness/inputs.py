"""Evaluation frames and their seeded sparse inputs.

:func:`get_frames` loads the reported frames (:data:`bench.frames.REPORT_FRAMES`, never the tuning frames),
optionally subsampled by ``step``; in quick mode it returns two tiny frames instead (a synthetic
piecewise-planar scene and the embedded 160x120 NYU frame subsampled by 2) so that CI runs in seconds.  Without
the shared data folder the embedded Motorcycle (:func:`sparsedepth.load_motorcycle`, the same scene as
``middlebury2014/motorcycle``) stands in.

May import :mod:`sparsedepth`, numpy and :mod:`bench.frames`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

import sparsedepth as sd

from .. import frames as frame_list

__all__ = ["DEFAULT_SEEDS", "FRACTIONS", "FrameData", "synthetic_frame", "quick_frames", "load_frame",
           "report_frame_names", "get_frames", "sample"]

#: Sampling seeds of the table modules.
DEFAULT_SEEDS = (0, 1, 2)
#: Observed fractions of the sparsity and baseline tables.
FRACTIONS = (0.01, 0.05, 0.10)


@dataclass(frozen=True)
class FrameData:
    """One evaluation frame: ``image`` (H, W, 3) uint8, ``depth`` (H, W) float64, NaN = no ground truth."""

    name: str
    image: np.ndarray = field(repr=False)
    depth: np.ndarray = field(repr=False)
    step: int = 1
    units: str = "m"

    @property
    def shape(self):
        return self.depth.shape


def synthetic_frame(shape=(48, 64), seed=0) -> FrameData:
    """A piecewise-planar scene whose depth edges are image edges (for quick smoke tests)."""
    rng = np.random.default_rng(seed)
    H, W = shape
    ii, jj = np.mgrid[0:H, 0:W].astype(float)
    box = (ii > H // 4) & (ii < 3 * H // 4) & (jj > W // 3) & (jj < 2 * W // 3)
    depth = 3.0 + 0.02 * ii - 0.01 * jj
    depth = np.where(box, 1.5 + 0.005 * jj, depth)
    image = np.where(box[..., None], [200, 60, 40], [40, 90, 180]).astype(float)
    image = np.clip(image + 8 * rng.standard_normal((H, W, 3)), 0, 255).astype(np.uint8)
    return FrameData("synthetic/planes", image, depth, 1)


def quick_frames() -> list[FrameData]:
    """The tiny frames of ``--quick``: :func:`synthetic_frame` and the embedded NYU frame at step 2."""
    emb = sd.load_embedded_frame()
    depth = np.array(emb.depth, dtype=float)[::2, ::2]
    return [synthetic_frame(), FrameData("embedded/" + emb.name + " (step 2)", np.ascontiguousarray(emb.image[::2, ::2]),
                                         np.ascontiguousarray(depth), 2)]


def load_frame(name: str, step: int = 1) -> FrameData:
    """A named frame of :mod:`bench.frames` (or ``"motorcycle (embedded)"``), subsampled by ``step``."""
    if name == "motorcycle (embedded)":
        f = sd.load_motorcycle()
        return FrameData(name, np.ascontiguousarray(f.image[::step, ::step]),
                         np.ascontiguousarray(np.array(f.depth, dtype=float)[::step, ::step]), step)
    image, depth = frame_list.load(name, step=step)
    units = "px (disparity)" if name.startswith(("middlebury2003", "middlebury2001")) else "m"
    return FrameData(name, image, depth.astype(float), step, units)


def report_frame_names(selected=None) -> list[str]:
    """REPORT_FRAMES present in the shared folder (or the embedded Motorcycle without it)."""
    names = frame_list.available(frame_list.REPORT_FRAMES)
    if not names:
        names = ["motorcycle (embedded)"]
    if selected:
        unknown = [s for s in selected if s not in names]
        if unknown:
            raise SystemExit(f"unknown or unavailable frames {unknown}; choose from {names}")
        names = list(selected)
    return names


def get_frames(args, *, filter_fn=None) -> list[FrameData]:
    """Frames for a script's parsed ``args`` (``--quick``, ``--frames``, ``--step``)."""
    if args.quick:
        return quick_frames()
    names = report_frame_names(args.frames)
    if filter_fn is not None:
        names = [n for n in names if filter_fn(n)]
    return [load_frame(n, args.step) for n in names]


def sample(frame: FrameData, *, fraction=None, count=None, seed=0):
    """Seeded sparse input from the frame's valid ground truth (``sd.sample_depth``)."""
    return sd.sample_depth(frame.depth, fraction=fraction, count=count, seed=seed)
