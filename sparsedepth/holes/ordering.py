"""A fill-reducing elimination order of the pixel grid: nested dissection.

The colorization fill factors the block of its eliminated pixels with a sparse
LU in the order computed here (:func:`nested_dissection_order`).  The order
depends only on the grid shape, so it is cached.

May import NumPy only.
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["segments", "nested_dissection_keys", "nested_dissection_order"]


def segments(lengths):
    """Segment number and index within the segment for consecutive segments."""
    seg = np.repeat(np.arange(lengths.size), lengths)
    starts = np.cumsum(lengths) - lengths
    return seg, np.arange(seg.size) - starts[seg]


@functools.lru_cache(maxsize=8)
def nested_dissection_keys(H, W, leaf=4):
    """Elimination position of every pixel of an H x W grid in a nested-dissection order.

    Rectangles are split recursively across their longer side by a
    one-pixel-wide line (which separates the 8-neighbour grid), the two halves
    numbered first and the separator last; rectangles of at most ``leaf``
    pixels are numbered row by row.  The order depends only on ``(H, W)``, so
    it is computed level by level over all rectangles at once and cached.
    Restricted to any subset of the pixels (the unknown ones), it is a
    fill-reducing order for a sparse LU: the colorization fill gives it to
    SuperLU in place of SuperLU's own minimum-degree orders.
    """
    key = np.empty(H * W, dtype=np.int64)
    r0, r1 = np.array([0]), np.array([H])
    c0, c1 = np.array([0]), np.array([W])
    base = np.array([0])
    while r0.size:
        h, w = r1 - r0, c1 - c0
        area = h * w
        is_leaf = (area <= leaf) | ((h < 3) & (w < 3))
        if is_leaf.any():
            seg, t = segments(area[is_leaf])
            lw = w[is_leaf][seg]
            rows = r0[is_leaf][seg] + t // lw
            cols = c0[is_leaf][seg] + t % lw
            key[rows * W + cols] = base[is_leaf][seg] + t
        split = ~is_leaf
        r0, r1, c0, c1, base, h, w = (a[split] for a in (r0, r1, c0, c1, base, h, w))
        if not r0.size:
            break
        by_row = h >= w  # cut across the longer side
        mid = np.where(by_row, r0 + h // 2, c0 + w // 2)
        a_r1, a_c1 = np.where(by_row, mid, r1), np.where(by_row, c1, mid)
        b_r0, b_c0 = np.where(by_row, mid + 1, r0), np.where(by_row, c0, mid + 1)
        area_a = (a_r1 - r0) * (a_c1 - c0)
        area_b = (r1 - b_r0) * (c1 - b_c0)
        seg, t = segments(np.where(by_row, w, h))
        rows = np.where(by_row[seg], mid[seg], r0[seg] + t)
        cols = np.where(by_row[seg], c0[seg] + t, mid[seg])
        key[rows * W + cols] = (base + area_a + area_b)[seg] + t
        keep_a, keep_b = area_a > 0, area_b > 0
        r0, r1, c0, c1, base = (
            np.concatenate((r0[keep_a], b_r0[keep_b])),
            np.concatenate((a_r1[keep_a], r1[keep_b])),
            np.concatenate((c0[keep_a], b_c0[keep_b])),
            np.concatenate((a_c1[keep_a], c1[keep_b])),
            np.concatenate((base[keep_a], (base + area_a)[keep_b])),
        )
    key.flags.writeable = False
    return key


@functools.lru_cache(maxsize=8)
def nested_dissection_order(H, W):
    """The pixels of an H x W grid in nested-dissection elimination order (cached)."""
    key = nested_dissection_keys(H, W)
    order = np.empty_like(key)
    order[key] = np.arange(key.size)
    order.flags.writeable = False
    return order
