"""The completion objective: named terms, their weights, and the objective as their sum.

``terms`` (the quadratic, L1 and robust terms), ``robust`` (the robust
penalties of the robust terms), ``objective`` (their sum and its assembly for
a frame), ``weights`` (the term weights), ``l1`` (the stacked L1 operator the
non-smooth solvers use).  The image edge weights live in
:mod:`sparsedepth.grid.edges` and are re-exported here.

May import :mod:`sparsedepth.grid`, the nearest fill of
:mod:`sparsedepth.baselines` and :mod:`sparsedepth._validation`.
"""

from .l1 import StackedL1, is_grid_gradient
from ..grid.edges import edge_weights, image_gradient_magnitude, pair_edge_weights, second_order_edge_weights
from .objective import DEFAULT_L1_SMOOTHING, Objective, build_objective
from .robust import PENALTIES, RobustPenalty, robust_penalty
from .terms import AbsTerm, QuadraticTerm, RobustTerm
from .weights import (DEFAULT_SCHEDULE, DEFAULT_WEIGHTS, EDGE_PENALTIES, DensitySchedule, Weights, default_weights,
                      observed_fraction, resolve_weights)

__all__ = ["QuadraticTerm", "AbsTerm", "RobustTerm", "Objective", "build_objective", "edge_weights",
           "pair_edge_weights", "second_order_edge_weights", "image_gradient_magnitude", "DEFAULT_L1_SMOOTHING", "Weights",
           "DEFAULT_WEIGHTS", "StackedL1", "is_grid_gradient", "RobustPenalty", "robust_penalty", "PENALTIES",
           "EDGE_PENALTIES", "DensitySchedule", "DEFAULT_SCHEDULE", "default_weights", "observed_fraction",
           "resolve_weights"]
