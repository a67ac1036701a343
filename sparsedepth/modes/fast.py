"""The real-time mode: :func:`complete_fast` (``complete_depth(..., quality="fast")``).

The image and the observations are averaged over blocks of ``f x f`` pixels, the objective is solved on that coarser
grid (a :class:`~sparsedepth.problem.CompletionProblem` of its own), and the solution is interpolated back and
refined by a few edge-aware sweeps with the observations held.
"""

from __future__ import annotations

import time

import numpy as np

from .._validation import as_depth_and_mask, as_float_image, check_same_shape
from ..grid.resample import block_mean, block_sample_mean, coarse_shape, edge_aware_sweeps
from ..objective.objective import DEFAULT_L1_SMOOTHING
from ..objective.weights import DEFAULT_WEIGHTS, Weights, observed_fraction, resolve_weights
from ..problem import CompletionProblem, checked_start, choose_solver, clamp, observed_range
from ..profiling import phase
from ..result import CompletionResult
from ..solvers.common import Recorder
from ..solvers.quadratic import single_precision_cg

__all__ = ["complete_fast", "fast_factor", "FAST_WEIGHTS", "FAST_COARSE_RTOL", "FAST_SMOOTHNESS", "FAST_KAPPA",
           "FAST_SWEEPS", "FLOAT32_ROUNDING"]

#: The coarse solve of a quadratic objective: Jacobi-preconditioned CG (no multigrid set-up on a grid of a few ten
#: thousand pixels) stopped at this relative residual.
FAST_COARSE_RTOL = 1e-4
#: The edge-aware sweeps on the full grid: ``λ``, ``κ`` and the number of sweeps
#: (:func:`~sparsedepth.grid.resample.edge_aware_sweeps`), chosen on the tuning frames (``python -m bench.fast_mode``).
FAST_SMOOTHNESS, FAST_KAPPA, FAST_SWEEPS = 16.0, 30.0, 3
#: The weights ``quality="fast"`` solves with when given no weights: the image-weighted first- and second-order
#: terms of the 13-point model without the local-linear terms, which do not carry over to a grid 2-4x coarser (its
#: windows then span 6-12 pixels), and the Euclidean nearest fill as ``z_c``; chosen on the tuning frames
#: (``python -m bench.fast_mode``, docs/fast_mode.md, "The fast mode's weights").
FAST_WEIGHTS = DEFAULT_WEIGHTS.replace(beta_local_linear=0.0, beta_image=0.00673, beta_second_image=0.039,
                                       fill_contrast=0.0)
#: Relative moves the clamp does not count: the rounding of the float32 sweeps.
FLOAT32_ROUNDING = 1e-6


def fast_factor(observed_fraction: float) -> int:
    """The coarsening ``f``: the largest of 4, 3 with ``f² ×`` the observed fraction at most 1, else 2.

    A coarse block of ``f x f`` pixels then holds about one observation or
    fewer, so averaging over it loses little; at higher densities a coarser
    grid blurs the detail the samples carry.
    """
    for factor in (4, 3):
        if factor * factor * float(observed_fraction) <= 1.0:
            return factor
    return 2


def complete_fast(image, sparse_depth, mask=None, *, weights=None, l1_smoothing=DEFAULT_L1_SMOOTHING,
                  clip_to_observed=True, x0=None) -> CompletionResult:
    """Complete a sparse depth map in real time: coarse solve, bilinear upsampling, edge-aware sweeps.

    Parameters
    ----------
    image, sparse_depth, mask
        As :func:`sparsedepth.complete_depth`'s.
    weights : Weights, DensitySchedule or None
        ``None``: :data:`FAST_WEIGHTS` (the defaults made for the coarse
        grid); a schedule is evaluated at the observed fraction; weights are
        used as given.
    l1_smoothing : float
        ``ε`` of the smoothed L1 for γ > 0 (depth units).
    clip_to_observed : bool
        Clamp the result to ``[min, max]`` of the observations (default).
    x0 : ndarray, (H, W), optional
        A starting depth: its block means start the coarse solve (pass the
        previous frame's depth along a video).

    Returns
    -------
    CompletionResult
        No full-resolution objective: ``objective`` and ``gap`` are NaN and
        ``terms`` is empty; the iterations and history are those of the
        coarse solve, whose objective values are not computed (NaN).

    Notes
    -----
    The image and the observations are averaged over blocks of ``f x f``
    pixels (:func:`fast_factor`: ``f = 4`` up to one observation per 16
    pixels, 3 up to one per 9, 2 above); the objective of ``weights`` is
    solved on the ``f`` times coarser grid without a duality gap (for γ = 0
    by :func:`~sparsedepth.solvers.quadratic.single_precision_cg` to a relative
    residual of :data:`FAST_COARSE_RTOL`, else by the solver ``"auto"``
    picks); the solution is interpolated bilinearly between the block
    centres and refined by :data:`FAST_SWEEPS` red-black sweeps of
    :func:`~sparsedepth.grid.resample.edge_aware_sweeps` with the
    observations held.  Accuracy and time beside the default's and the fast
    filters': ``python -m bench.fast_mode``.
    """
    start_time = time.perf_counter()
    image = np.asarray(image)
    if not _scaled_by_bands(image):
        image = as_float_image(image, dtype=np.float32)  # a float image's values are checked over the whole image
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    check_same_shape(image.shape[:2], depth.shape, "image", "sparse_depth")
    if weights is None:
        weights = FAST_WEIGHTS
    elif not isinstance(weights, Weights):
        weights = resolve_weights(weights, observed_fraction(observed))
    if not isinstance(clip_to_observed, (bool, np.bool_)):
        raise TypeError(f"clip_to_observed must be True or False; got {type(clip_to_observed).__name__}")
    shape = depth.shape
    if x0 is not None:
        x0 = checked_start(x0, shape)
    factor = fast_factor(np.count_nonzero(observed) / observed.size)
    if min(coarse_shape(shape, factor)) < 2:
        factor = 1
    coarse_depth, coarse_observed = block_sample_mean(depth, observed, factor)
    samples = depth[observed]
    del depth  # the full-size copy is not needed past the block means
    coarse_image = _coarse_image(image, factor)
    # lengths in the user's pixels: a blur of edge_sigma pixels is edge_sigma / f coarse pixels, and a coarse step
    # is f pixels long, so the geodesic fill's cost per unit of image contrast is fill_contrast / f in its steps
    coarse_weights = weights.replace(edge_sigma=weights.edge_sigma / factor,
                                     fill_contrast=weights.fill_contrast / factor)
    problem = CompletionProblem(coarse_image, coarse_depth, coarse_observed, weights=coarse_weights,
                                l1_smoothing=l1_smoothing, clip_to_observed=False)
    start = problem.start(None if x0 is None else block_mean(np.maximum(x0, 0.0), factor))
    name = "cg" if weights.gamma == 0 else choose_solver(weights)
    if name == "cg":
        recorder = Recorder(problem.objective, None, problem.scale, values=False)
        out = single_precision_cg(problem.objective, start, tol=FAST_COARSE_RTOL, max_iter=5000, recorder=recorder)
        coarse_z = out.z * problem.scale
    else:
        out, _ = problem.run(solver=name, start=start, certify=False, objective_values=False, clip=False)
        coarse_z = out.z
    with phase("upsampling and sweeps"):  # the sweeps interpolate the coarse solution band by band as they read it
        z = edge_aware_sweeps(coarse_z.reshape(problem.shape).astype(np.float32), image, samples, observed,
                              smoothness=FAST_SMOOTHNESS, kappa=FAST_KAPPA, sweeps=FAST_SWEEPS, start_factor=factor,
                              dtype=np.float64)
    depth_range = observed_range(samples, clip_to_observed)
    with phase("clamp"):
        z, clamped = clamp(z, depth_range, clip_to_observed, rounding=FLOAT32_ROUNDING)
    return CompletionResult(
        depth=z,
        objective=float("nan"),
        terms={},
        iterations=out.iterations,
        converged=out.converged,
        message=(f"fast mode: {factor}x coarser grid {problem.shape[0]}x{problem.shape[1]} ({name}: "
                 f"{out.message}), bilinear upsampling, {FAST_SWEEPS} edge-aware sweeps"),
        clamped=clamped,
        history=out.history,
        solver=name,
        weights=weights,
        runtime=time.perf_counter() - start_time,
        depth_range=depth_range,
        gap=float("nan"),
        solver_gap=float("nan"),
    )


def _scaled_by_bands(image) -> bool:
    """True for a uint8 or uint16 image of a shape :func:`~sparsedepth._validation.as_float_image` takes.

    Its scaling to [0, 1] checks no values, so it is not made into a float copy of the whole image: its block means
    are taken of the integers (:func:`_coarse_image`) and the sweeps scale it a band of rows at a time
    (:func:`~sparsedepth.grid.resample.edge_aware_sweeps`); any other image is converted, and checked, whole.
    """
    return (image.dtype in (np.uint8, np.uint16) and image.size > 0
            and (image.ndim == 2 or (image.ndim == 3 and image.shape[2] in (1, 3, 4))))


def _coarse_image(image, factor):
    """The block means (:func:`~sparsedepth.grid.resample.block_mean`) of the image scaled to [0, 1].

    A uint8 or uint16 image: the means of its integers (summed exactly) divided by 255 or 65535, its channels as
    :func:`~sparsedepth._validation.as_float_image` takes them (a grey image one channel, alpha dropped); a float
    image (already scaled): its block means, clipped to [0, 1] (float32 means may round past 1).
    """
    if image.dtype in (np.uint8, np.uint16):
        channels = image[..., :3] if image.ndim == 3 else image[..., None]
        return block_mean(channels, factor) / np.iinfo(image.dtype).max
    return np.clip(block_mean(image, factor), 0.0, 1.0)
