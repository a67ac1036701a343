"""Per-pixel uncertainty from two half-sample solves: :func:`complete_with_uncertainty`.

``complete_depth(..., uncertainty=True)`` is this function over the completion problem: the problem is solved with
every sample, then twice more with each half of them (:meth:`~sparsedepth.problem.CompletionProblem.with_samples`:
the image terms are shared), and :func:`sparsedepth.uncertainty.estimate_uncertainty` calibrates the map.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from .._validation import check_nonnegative_real
from ..problem import CompletionProblem, solver_settings
from ..profiling import phase
from ..result import ClampWarning, CompletionResult
from ..uncertainty import MIN_OBSERVED, check_relative_limit, check_uncertainty_shape, estimate_uncertainty, split_samples, too_uncertain

__all__ = ["complete_with_uncertainty"]


def complete_with_uncertainty(problem: CompletionProblem, *, solver="auto", tol=None, max_iter=None, options=None,
                              callback=None, x0=None, max_uncertainty=None,
                              max_relative_uncertainty=None) -> CompletionResult:
    """Solve ``problem`` and estimate each pixel's error; past a limit the depth is left missing.

    Parameters
    ----------
    problem : CompletionProblem
        The completion problem (at least :data:`~sparsedepth.uncertainty.MIN_OBSERVED` observed pixels and a
        frame of at least 2x2 pixels).
    solver, tol, max_iter, options, callback, x0
        As :func:`sparsedepth.complete_depth`'s, for the solve with every sample (the halves use the same solver
        and stopping parameters, no callback, and start from its depth).
    max_uncertainty : float, optional
        Pixels whose uncertainty exceeds it (depth units) are NaN in ``result.depth`` and counted in
        ``result.removed``.
    max_relative_uncertainty : float, optional
        The same for an uncertainty above this fraction of the pixel's depth; with both limits a pixel goes when
        it breaks either (:func:`sparsedepth.uncertainty.too_uncertain`).

    Returns
    -------
    CompletionResult
        The completion with every sample, with ``uncertainty`` and ``uncertainty_calibration``.

    Notes
    -----
    The halves start from the full completion's depth: a start near their answer saves iterations, and every
    solver stops on its own criterion for the half's objective, so the start does not decide where they end.  The
    halves are not certified (their gap is not computed).  No unobserved pixel's uncertainty is below the precision
    of the solve (:meth:`~sparsedepth.problem.CompletionProblem.precision`).
    """
    limited = max_uncertainty is not None or max_relative_uncertainty is not None
    check_uncertainty_shape(problem.shape, name="max_uncertainty" if limited else "uncertainty")
    if max_uncertainty is not None:
        check_nonnegative_real(max_uncertainty, name="max_uncertainty")
    if max_relative_uncertainty is not None:
        check_relative_limit(max_relative_uncertainty)
    observed = problem.observed
    if np.count_nonzero(observed) < MIN_OBSERVED:
        raise ValueError(f"uncertainty needs at least {MIN_OBSERVED} observed pixels (two halves of at least "
                         f"{MIN_OBSERVED // 2}); got {np.count_nonzero(observed)}")
    settings = dict(solver=solver, tol=tol, max_iter=max_iter, options=options)
    result = problem.solve(callback=callback, x0=x0, **settings)
    depth = problem.samples()
    half_a, half_b = split_samples(observed, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClampWarning)  # the halves' clamps are not the user's result
        halves = [problem.with_samples(np.where(half, depth, np.nan), half).solve(
            x0=result.depth, certify=False, evaluate=False, **settings).depth for half in (half_a, half_b)]
    checked_options = solver_settings(problem.weights, solver, tol, max_iter, options)[3]
    with phase("uncertainty map"):
        sigma, calibration = estimate_uncertainty(result.depth, *halves, depth, half_a, half_b, image=problem.image,
                                                  precision=problem.precision(checked_options))
    left_out = too_uncertain(sigma, result.depth, max_uncertainty=max_uncertainty,
                             max_relative_uncertainty=max_relative_uncertainty)
    dense = np.where(left_out, np.nan, result.depth) if limited else result.depth
    removed = int(np.count_nonzero(left_out))
    return dataclasses.replace(result, depth=dense, uncertainty=sigma, uncertainty_calibration=calibration,
                               removed=removed)

