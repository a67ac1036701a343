"""sparsedepth: dense depth from an image and a few depth samples.

Depth completion and hole filling by regularised optimisation with sparse
linear algebra (scipy.sparse, pyamg).  The main entry point is
:func:`complete_depth`.
"""

from . import datasets, io
from .baselines import biharmonic_fill, colorization_baseline, linear_fill, nearest_fill
from .completion import choose_solver, complete_depth
from .metrics import DepthMetrics, depth_metrics
from .objective.objective import AbsTerm, Objective, QuadraticTerm, build_objective, edge_weights
from .result import ClampWarning, CompletionResult, IterationRecord, SolverState
from .sampling import sample_depth, sample_mask, valid_depth_mask
from .solvers import SOLVER_OPTIONS, SOLVERS
from .objective.weights import DEFAULT_WEIGHTS, Weights
from .datasets import (
    Frame,
    list_embedded_frames,
    list_shared_frames,
    load_embedded_frame,
    load_motorcycle,
    load_shared_frame,
    shared_data_dir,
)
from .io import DEPTH_SCALES, read_depth, read_image, write_depth

__version__ = "0.1.0"

__all__ = [
    "complete_depth",
    "choose_solver",
    "Weights",
    "DEFAULT_WEIGHTS",
    "CompletionResult",
    "ClampWarning",
    "IterationRecord",
    "SolverState",
    "Objective",
    "QuadraticTerm",
    "AbsTerm",
    "build_objective",
    "edge_weights",
    "nearest_fill",
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
    "DEPTH_SCALES",
    "io",
    "datasets",
]
from . import batch, holes  # noqa: E402
from .holes.fill import FILL_METHODS, fill_holes  # noqa: E402

__all__ += ["fill_holes", "FILL_METHODS", "holes", "batch"]
