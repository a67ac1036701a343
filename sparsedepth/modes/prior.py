"""A dense prior brought by the user: :func:`complete_with_prior` (``complete_depth(..., prior=...)``)."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from .._validation import as_depth_and_mask
from ..objective.objective import DEFAULT_L1_SMOOTHING
from ..priors import align_prior
from ..problem import CompletionProblem, observed_range, warn_clamped
from ..result import ClampWarning, CompletionResult

__all__ = ["complete_with_prior"]


def complete_with_prior(image, sparse_depth, mask, prior, *, alignment="scale_shift", weights=None,
                        solver="auto", tol=None, max_iter=None, callback=None, options=None,
                        l1_smoothing=DEFAULT_L1_SMOOTHING, clip_to_observed=True, x0=None) -> CompletionResult:
    """Complete the residual of a dense prior aligned to the samples, and add the prior back.

    Parameters
    ----------
    image, sparse_depth, mask
        As :func:`sparsedepth.complete_depth`'s.
    prior : ndarray, (H, W)
        A dense, finite depth map (e.g. a monocular network's prediction; metric or relative).
    alignment : {"scale_shift", "scale", "none"}
        Least-squares fit of ``s · prior + t`` to the samples (:func:`sparsedepth.priors.align_prior`).
    weights, solver, tol, max_iter, callback, options, l1_smoothing, clip_to_observed, x0
        As :func:`sparsedepth.complete_depth`'s; ``x0`` is a starting depth.

    Returns
    -------
    CompletionResult
        ``objective``, ``terms``, ``history`` and ``gap`` are those of the residual problem at the residual of the
        depth returned.

    Notes
    -----
    With ``P = s · prior + t`` the aligned prior, the objective completes the residual ``r = z − P`` from ``r_obs =
    z_obs − P``, shifted by a constant ``c`` so that every residual sample is positive (for the bound ``>= 0``), so
    between the samples the result follows the prior's shape and the smoothness terms act on its error: ``z = P − c
    + r``.  The residual is clamped to ``[low − P + c, high − P + c]`` per pixel, so that ``z`` lies in the range
    ``[low, high]`` of the observations.  A prior equal to the truth up to scale and shift gives back the truth (a
    zero residual).
    """
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    aligned, _, _ = align_prior(prior, depth, observed, alignment=alignment)
    values = depth[observed]
    residual = values - aligned[observed]
    depth_range = observed_range(values, clip_to_observed)
    # c keeps every residual sample >= the median depth: positive, and of the depth's magnitude for the scaling
    shift = float(np.median(values)) + max(0.0, -float(residual.min()))
    shifted = np.zeros_like(depth)
    shifted[observed] = residual + shift
    offset = shift - aligned  # r = z + offset
    start = None if x0 is None else _residual_start(x0, offset)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClampWarning)  # the residual's clamp is the user's: warned about below
        problem = CompletionProblem(image, shifted, observed, weights=weights, l1_smoothing=l1_smoothing,
                                    clip_to_observed=clip_to_observed,
                                    bounds=(depth_range[0] + offset, depth_range[1] + offset))
        result = problem.solve(solver=solver, tol=tol, max_iter=max_iter, callback=callback, options=options,
                               x0=start)
    z = np.clip(result.depth - offset, *depth_range)  # moves rounding only: the residual is in its bounds
    warn_clamped(result.clamped, z.size, depth_range, clip_to_observed)
    return dataclasses.replace(result, depth=z, depth_range=depth_range)


def _residual_start(x0, offset):
    """The residual problem's start ``x0 − P + c`` (``x0`` checked like a depth start)."""
    start = np.asarray(x0, dtype=np.float64)
    if start.shape != offset.shape:
        raise ValueError(f"x0 has shape {start.shape}, expected {offset.shape}")
    if not np.all(np.isfinite(start)):
        raise ValueError("x0 contains NaN or infinite values")
    return np.maximum(start + offset, 0.0)
