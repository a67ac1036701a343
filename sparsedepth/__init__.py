"""sparsedepth: dense depth from an image and a few depth samples, by regularised optimisation.

Turn an RGB image plus sparse depth (LiDAR, an RGB-D frame with holes, a stereo disparity, structure-from-motion
points) into a dense depth map, on a CPU and with no training.

The user's API
--------------
Complete
    :func:`complete_depth` ``(image, sparse_depth, mask=None, ...)``: the dense depth of one frame; its samples are
    the pixels of ``mask``, or the finite pixels of ``sparse_depth``.  Options: ``uncertainty=True``,
    ``max_uncertainty=``, ``quality="fast"`` or ``"best"`` (chosen per input by cross-validation), ``prior=`` (a
    dense map to align and complete around), ``expected_error=True``, ``blowups="flag"`` or ``"remove"`` (local
    blow-ups: :func:`sparsedepth.blowups.flag_blowups`).  :class:`CompletionProblem` sets up once and solves many times.
The result
    :class:`CompletionResult`: ``depth`` (metres, clamped to the observed range), ``uncertainty``, ``converged`` and
    ``message``, ``objective`` and ``terms``, the duality ``gap``, ``clamped``, ``history``, ``expected_rmse``,
    ``blowups``; with ``quality="best"`` a :class:`sparsedepth.selection.BestCompletionResult` (its ``selection``).  Warnings:
    :class:`ClampWarning`, :class:`NoGainWarning`.
Fill holes
    :func:`fill_holes` ``(image, raw_depth)``: the NYU Depth V2 toolbox's colorization fill of a raw RGB-D frame, or
    ``method="complete"``.
Read and write
    :func:`read_image`, :func:`read_depth` (``scale=`` for integer files, ``calib=`` for disparity),
    :func:`write_depth`, :func:`depth_to_points`, :func:`write_ply`, :func:`read_ply`, :func:`colorize_depth`;
    :mod:`~sparsedepth.io` for every format, intrinsics and COLMAP models.
Simulate and score
    :func:`sample_depth` and :func:`sample_mask` (sparse input from a dense map: uniform, keypoints, scan lines,
    sensor holes), :func:`depth_metrics` and :class:`DepthMetrics`, the baselines :func:`nearest_fill`,
    :func:`linear_fill`, :func:`biharmonic_fill`, :func:`colorization_baseline`, and the frames
    :func:`load_motorcycle`, :func:`list_shared_frames`, :func:`load_shared_frame`.
Model
    :class:`Weights`, :data:`DEFAULT_WEIGHTS`, :data:`FAST_WEIGHTS`, :class:`DensitySchedule`,
    :data:`DEFAULT_SCHEDULE`, :func:`default_weights`, :data:`SOLVERS`, :data:`SOLVER_OPTIONS`; registering an
    image to its depth: :func:`estimate_image_shift`, :func:`shift_image`; a prior: :func:`align_prior`.
Whole datasets
    :mod:`~sparsedepth.batch` (folders, the NYU labeled ``.mat``, Dask clusters), :mod:`~sparsedepth.datasets`,
    :mod:`~sparsedepth.holes`.
The command
    ``sparsedepth`` or ``python -m sparsedepth.complete`` (``--help``): one frame, hole filling, batches, the views
    of a COLMAP model; with no arguments, a demo.

Guides
------
In the repository's ``docs/`` (the documentation site: ``python -m mkdocs serve``): ``docs/guides/inputs.md``
(formats and units), ``docs/guides/sensors.md``, ``docs/guides/uncertainty.md``, ``docs/guides/point_clouds.md``,
``docs/guides/hole_filling.md``, ``docs/guides/batches.md``, ``docs/guides/objective.md`` (the objective, the
solvers and the papers), ``docs/guides/command_line.md``, ``docs/colmap.md``, ``docs/glossary.md`` and
``docs/architecture.md`` (the code, layer by layer).

Examples
--------
>>> import numpy as np
>>> import sparsedepth as sd
>>> frame = sd.load_motorcycle()
>>> sparse, mask = sd.sample_depth(frame.depth, fraction=0.05, seed=0)
>>> result = sd.complete_depth(frame.image, sparse, mask)
>>> result.depth.shape == frame.depth.shape, bool(np.isfinite(result.depth).all())
(True, True)
>>> ours = sd.depth_metrics(result.depth, frame.depth, mask=~mask)
>>> nearest = sd.depth_metrics(sd.nearest_fill(sparse, mask), frame.depth, mask=~mask)
>>> bool(ours.rmse < nearest.rmse)
True
"""

from . import datasets, io
from .baselines import biharmonic_fill, colorization_baseline, linear_fill, nearest_fill
from .completion import FAST_WEIGHTS, choose_solver, complete_depth
from .problem import CompletionProblem
from .grid.geodesic import geodesic_fill
from .priors import PRIOR_ALIGNMENTS, align_prior
from .registration import ImageShift, estimate_image_shift, pool_image_shifts, shift_image
from .metrics import DepthMetrics, depth_metrics
from .objective.objective import AbsTerm, Objective, QuadraticTerm, RobustTerm, build_objective, edge_weights
from .objective.robust import PENALTIES, RobustPenalty, robust_penalty
from . import blowups, expected_error, selection
from .result import ClampWarning, CompletionResult, IterationRecord, NoGainWarning, SolverState, UncertaintyCalibration
from .sampling import sample_depth, sample_mask, valid_depth_mask
from .solvers import SOLVER_OPTIONS, SOLVERS
from .objective.weights import (DEFAULT_SCHEDULE, DEFAULT_WEIGHTS, DensitySchedule, Weights, default_weights,
                                observed_fraction, resolve_weights)
from .datasets import (
    Frame,
    list_embedded_frames,
    list_shared_frames,
    load_embedded_frame,
    load_motorcycle,
    load_shared_frame,
    shared_data_dir,
)
from .io import DEPTH_SCALES, depth_to_points, read_depth, read_image, read_ply, write_depth, write_ply

__version__ = "0.1.0"

__all__ = [
    # complete and fill
    "complete_depth", "fill_holes", "CompletionProblem", "CompletionResult", "ClampWarning", "NoGainWarning",
    # model
    "Weights", "DEFAULT_WEIGHTS", "FAST_WEIGHTS", "DensitySchedule", "DEFAULT_SCHEDULE", "default_weights", "SOLVERS",
    "SOLVER_OPTIONS",
    # inputs and outputs
    "read_image", "read_depth", "write_depth", "depth_to_points", "write_ply", "read_ply", "colorize_depth",
    "shift_image", "estimate_image_shift", "align_prior",
    # data, sampling and scores
    "load_motorcycle", "list_shared_frames", "load_shared_frame", "sample_depth", "sample_mask", "valid_depth_mask",
    "depth_metrics", "DepthMetrics", "nearest_fill", "linear_fill", "biharmonic_fill", "colorization_baseline",
    # subpackages
    "io", "datasets", "batch", "holes",
]
from . import batch, holes  # noqa: E402
from .holes.fill import FILL_METHODS, fill_holes  # noqa: E402
from .visualize import colorize_depth  # noqa: E402
