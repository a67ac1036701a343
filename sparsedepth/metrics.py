"""Error metrics of a depth map against ground truth.

May import NumPy, :mod:`sparsedepth.sampling` and :mod:`sparsedepth._validation`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ._validation import check_same_shape
from .sampling import valid_depth_mask

__all__ = ["DepthMetrics", "depth_metrics"]


@dataclass(frozen=True)
class DepthMetrics:
    """RMSE, MAE (depth units), REL = mean ``|z − g| / g`` and threshold accuracies.

    ``delta1``/``delta2``/``delta3`` are the fractions of pixels with
    ``max(z/g, g/z) < 1.25``, ``1.25²``, ``1.25³``; ``count`` the number of
    pixels scored.
    """

    rmse: float
    mae: float
    rel: float
    delta1: float
    delta2: float
    delta3: float
    count: int

    def as_dict(self) -> dict:
        return asdict(self)


def depth_metrics(prediction, ground_truth, *, mask=None) -> DepthMetrics:
    """Score ``prediction`` on the pixels where ``ground_truth`` is valid.

    Parameters
    ----------
    prediction, ground_truth : ndarray, (H, W)
        Valid ground truth is finite and ``> 0``.
    mask : ndarray of bool, (H, W), optional
        Further restricts the scored pixels, e.g. ``~observed`` to score only
        the pixels hidden from the solver.

    Raises
    ------
    ValueError
        Shapes differ, the prediction is not finite on scored pixels, or no
        pixel is left to score.
    """
    pred = np.asarray(prediction, dtype=np.float64)
    gt = np.asarray(ground_truth, dtype=np.float64)
    check_same_shape(pred.shape, gt.shape, "prediction", "ground_truth")
    scored = valid_depth_mask(gt)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        check_same_shape(mask.shape, gt.shape, "mask", "ground_truth")
        scored &= mask
    if not scored.any():
        raise ValueError("no pixel to score: ground truth has no valid value inside the mask")
    p, g = pred[scored], gt[scored]
    if not np.all(np.isfinite(p)):
        raise ValueError(f"prediction has {int(np.sum(~np.isfinite(p)))} non-finite values on scored pixels")
    err = p - g
    with np.errstate(divide="ignore"):
        ratio = np.maximum(p / g, np.where(p > 0, g / np.where(p > 0, p, 1.0), np.inf))
    return DepthMetrics(
        rmse=float(np.sqrt(np.mean(err * err))),
        mae=float(np.mean(np.abs(err))),
        rel=float(np.mean(np.abs(err) / g)),
        delta1=float(np.mean(ratio < 1.25)),
        delta2=float(np.mean(ratio < 1.25**2)),
        delta3=float(np.mean(ratio < 1.25**3)),
        count=int(p.size),
    )
