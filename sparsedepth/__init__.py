"""sparsedepth: dense depth from an image and a few depth samples.

Depth completion and hole filling by regularised optimisation with sparse
linear algebra (scipy.sparse, pyamg).  The main entry point is
:func:`complete_depth`; :func:`fill_holes` fills raw sensor depth;
``python -m sparsedepth.complete`` is the command line.

The map of the package, from the bottom layer up (each part may import only
the parts listed before it, NumPy, SciPy, pyamg, scikit-image and h5py;
``docs/architecture.md`` follows one frame through it):

``_validation``
    Every input check, one rule per concept (numbers, grid shapes, images,
    depth and masks, sparse grid operators, weights, paths).  Imports nothing
    of the package.
``result``
    :class:`CompletionResult`, :class:`IterationRecord`, :class:`SolverState`,
    :class:`UncertaintyCalibration`, :class:`ClampWarning`: the types every solver and :func:`complete_depth`
    return.
``grid/``
    The pixel grid: stencils (``stencil``), finite-difference operators
    (``operators``), the image gradient and edge weights (``edges``), the
    windowed local-linear affinities (``affinity``: the matting Laplacian), the
    image-aware nearest-sample fill (``geodesic``).
``io/``
    Files: images, depth formats and their units, calibration, NumPy/HDF5
    arrays, NYU Depth V2 files, point clouds (pinhole back-projection, PLY),
    atomic writes.  Imports ``_validation`` only.
``linalg/``
    Sparse SPD solves: every Krylov loop (``krylov``: CG, warm-started CG
    steps, GMRES), preconditioners by name, and the geometric multigrid
    (``multigrid/``).  Imports ``grid``.
``sampling``, ``metrics``, ``baselines``
    Sparse input from dense depth, error metrics, and the fills a user would
    otherwise reach for (nearest, linear, biharmonic, colorization;
    ``colorization_baseline`` imports ``holes.colorization`` when called).
``priors``
    A dense depth map the user brings (``complete_depth(..., prior=)``):
    checks and the least-squares scale/shift alignment to the samples.
``registration``
    Image-to-depth registration: :func:`shift_image` and the cross-validated
    :func:`estimate_image_shift`, :func:`pool_image_shifts` (imports ``grid``).
``visualize``
    :func:`colorize_depth`: a depth map as an RGB picture (NumPy only).
``objective/``
    The objective as a sum of named terms (``terms``, ``objective``), their
    :class:`Weights` (``weights``), and the stacked L1 operator (``l1``).
    Imports ``grid`` and the nearest fill of ``baselines``.
``solvers/``
    One module per solver family (``quadratic``, ``irls``, ``admm`` with
    ``active_set``, ``lbfgsb``, ``adam``), one ``registry``, one options
    dataclass per solver (``options``), the duality-gap ``certificate``, and
    the front door ``core`` (checks, depth scaling, :func:`solve`).  Imports
    ``objective``, ``linalg``, ``grid``, ``result``.
``uncertainty``
    The per-pixel error estimate of a completion and its calibration on
    held-out observations (never solves; imports ``result``).
``completion``
    :func:`complete_depth`: checks, objective, scaled solve, clamp, and the
    uncertainty map from two half-sample solves.
``holes/``
    :func:`fill_holes`: the NYU toolbox colorization fill (``affinity``,
    ``ordering``, ``schur``, ``colorization``) and the completion objective
    with every valid raw pixel observed (``fill``).  Imports ``completion``,
    ``linalg``, ``grid``.
``datasets``
    Real frames: the shipped samples, the shared data folder, NYU files.
    Imports ``io``.
``batch/``
    Whole datasets: frame discovery (``frames``), one frame (``evaluate``,
    ``worker``), options, the resumable CSV (``csvlog``), the worker pool
    (``pool``), :func:`~sparsedepth.batch.run_batch` (``run``) and Dask
    clusters (``distributed``, the only module that imports Dask, when
    called).  Imports everything above except ``cli``.
``cli/``
    The command line: the parser, option checks, one frame, batches, output
    planning (all or nothing), reports.  Imported only by ``complete``, the
    ``python -m sparsedepth.complete`` entry point.

Where a change goes: a new solver is a module in ``solvers/`` plus a line in
``solvers/registry.py`` and an options class in ``solvers/options.py``; a new
term is a :class:`QuadraticTerm`/:class:`AbsTerm`/:class:`RobustTerm` built in
``objective/objective.py`` with its weight in ``objective/weights.py``; a new
file format is a module in ``io/`` dispatched from ``io/depth.py`` or
``io/images.py``; a new command-line flag is an argument group in
``cli/parser.py`` and its use in ``cli/single.py`` or ``cli/batch_mode.py``.
"""

from . import datasets, io
from .baselines import biharmonic_fill, colorization_baseline, linear_fill, nearest_fill
from .completion import FAST_WEIGHTS, choose_solver, complete_depth
from .grid.geodesic import geodesic_fill
from .priors import PRIOR_ALIGNMENTS, align_prior
from .registration import ImageShift, estimate_image_shift, pool_image_shifts, shift_image
from .metrics import DepthMetrics, depth_metrics
from .objective.objective import AbsTerm, Objective, QuadraticTerm, RobustTerm, build_objective, edge_weights
from .objective.robust import PENALTIES, RobustPenalty, robust_penalty
from .result import ClampWarning, CompletionResult, IterationRecord, SolverState, UncertaintyCalibration
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
    "complete_depth",
    "choose_solver",
    "Weights",
    "DEFAULT_WEIGHTS",
    "DensitySchedule",
    "DEFAULT_SCHEDULE",
    "default_weights",
    "observed_fraction",
    "resolve_weights",
    "FAST_WEIGHTS",
    "CompletionResult",
    "ClampWarning",
    "UncertaintyCalibration",
    "IterationRecord",
    "SolverState",
    "Objective",
    "QuadraticTerm",
    "AbsTerm",
    "RobustTerm",
    "RobustPenalty",
    "robust_penalty",
    "PENALTIES",
    "build_objective",
    "edge_weights",
    "nearest_fill",
    "geodesic_fill",
    "align_prior",
    "PRIOR_ALIGNMENTS",
    "shift_image",
    "estimate_image_shift",
    "pool_image_shifts",
    "ImageShift",
    "linear_fill",
    "biharmonic_fill",
    "colorization_baseline",
    "depth_metrics",
    "DepthMetrics",
    "sample_depth",
    "sample_mask",
    "valid_depth_mask",
    "SOLVERS",
    "SOLVER_OPTIONS",
    "Frame",
    "load_motorcycle",
    "load_embedded_frame",
    "list_embedded_frames",
    "list_shared_frames",
    "load_shared_frame",
    "shared_data_dir",
    "read_image",
    "read_depth",
    "write_depth",
    "depth_to_points",
    "write_ply",
    "read_ply",
    "DEPTH_SCALES",
    "io",
    "datasets",
]
from . import batch, holes  # noqa: E402
from .holes.fill import FILL_METHODS, fill_holes  # noqa: E402

__all__ += ["fill_holes", "FILL_METHODS", "holes", "batch"]
from .visualize import colorize_depth  # noqa: E402

__all__ += ["colorize_depth"]
