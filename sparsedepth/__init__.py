"""sparsedepth: dense depth from an image and a few depth samples, by regularised optimisation.

Turn an RGB image plus a few percent of depth pixels into a dense depth map, or fill the holes of a raw depth
sensor, with no training and on a CPU.  ``python -m sparsedepth.complete`` is the command line (``--help``); the
guides and the measured results are the Markdown pages of the repository's ``docs/`` folder (``docs/colmap.md``
for structure-from-motion scenes, ``docs/architecture.md`` for the code).

The user's API
--------------
Complete and fill
    :func:`complete_depth` (``quality="fast"``, ``prior=``, ``uncertainty=``), :func:`fill_holes`,
    :class:`CompletionProblem` (set up once, solve many times), :class:`CompletionResult`, :class:`ClampWarning`,
    :class:`NoGainWarning` (``complete_depth(..., expected_error=True)``, :mod:`~sparsedepth.expected_error`).
Model
    :class:`Weights`, :data:`DEFAULT_WEIGHTS`, :data:`FAST_WEIGHTS`, :class:`DensitySchedule`,
    :data:`DEFAULT_SCHEDULE`, :func:`default_weights`, :data:`SOLVERS`, :data:`SOLVER_OPTIONS`.
Inputs and outputs
    :func:`read_image`, :func:`read_depth`, :func:`write_depth`, :func:`depth_to_points`, :func:`write_ply`,
    :func:`read_ply`, :func:`colorize_depth`, :func:`shift_image`, :func:`estimate_image_shift`,
    :func:`align_prior`.
Data, sampling and scores
    :func:`load_motorcycle`, :func:`list_shared_frames`, :func:`load_shared_frame`, :func:`sample_depth`,
    :func:`sample_mask`, :func:`valid_depth_mask`, :func:`depth_metrics`, :class:`DepthMetrics`, and the
    baselines :func:`nearest_fill`, :func:`linear_fill`, :func:`biharmonic_fill`, :func:`colorization_baseline`.
Subpackages
    :mod:`~sparsedepth.io` (files), :mod:`~sparsedepth.datasets` (real frames), :mod:`~sparsedepth.batch` (whole
    datasets, Dask clusters), :mod:`~sparsedepth.holes` (hole filling).

Where things live
-----------------
From the bottom layer up: ``_validation`` (every input check), ``limits`` (the sizes at which large frames are
stored more leanly: one settings object), ``result``, ``grid/`` (stencils, operators, edge
weights, affinities, the geodesic fill), ``io/`` (formats in one table: ``io.formats``), ``linalg/`` (Krylov
loops, preconditioners, multigrid), ``sampling``, ``metrics``, ``baselines``, ``priors``, ``registration``,
``visualize``, ``objective/`` (the objective as a sum of named terms and their :class:`Weights`), ``solvers/`` (one
registry, one options class per solver, the duality-gap certificate), ``uncertainty`` (the error map's
calibration), ``problem`` (:class:`CompletionProblem`), ``modes/`` (fast, prior, uncertainty), ``completion``
(:func:`complete_depth`), ``holes/``, ``datasets``, ``batch/``, ``cli/``.  Each folder's ``__init__`` says what it
holds and what it may import; ``docs/architecture.md`` follows one frame through them and says which files a new
term, solver or file format touches.

Other names (``build_objective``, ``Objective`` and the term classes, ``observed_fraction``,
``resolve_weights``, ``choose_solver``, ``geodesic_fill``, ``pool_image_shifts``, ``ImageShift``,
``PRIOR_ALIGNMENTS``, the robust penalties, the record types, the embedded-frame loaders, ``DEPTH_SCALES``,
``FILL_METHODS``) are attributes of the package too, outside ``__all__``; their home is the subpackage that defines
them.
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
from . import expected_error
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
