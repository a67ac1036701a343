"""Baselines a user would otherwise reach for (nearest-neighbour fill, ...)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ._validation import as_depth_and_mask

__all__ = ["nearest_fill"]


def nearest_fill(sparse_depth, mask=None) -> np.ndarray:
    """Nearest-neighbour fill: each pixel takes the value of the nearest observed pixel.

    Distance is Euclidean in pixel units (``scipy.ndimage.distance_transform_edt``
    with ``return_indices``); ties are broken as that function does.

    Parameters
    ----------
    sparse_depth : ndarray, (H, W)
    mask : ndarray of bool, (H, W), optional
        True where depth is observed; default: finite and ``> 0``.

    Returns
    -------
    ndarray, (H, W), float64
        Equal to the observation at every observed pixel.
    """
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    _, (ii, jj) = ndimage.distance_transform_edt(~observed, return_distances=True, return_indices=True)
    return depth[ii, jj]
