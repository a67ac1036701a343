"""The completion objective: named terms, their weights, and the objective as their sum.

May import :mod:`sparsedepth.grid` and the nearest fill of :mod:`sparsedepth.baselines`.
"""

from .l1 import StackedL1, is_grid_gradient
from .objective import (
    DEFAULT_L1_SMOOTHING,
    AbsTerm,
    Objective,
    QuadraticTerm,
    build_objective,
    edge_weights,
    image_gradient_magnitude,
    pair_edge_weights,
    second_order_edge_weights,
)
from .weights import DEFAULT_WEIGHTS, Weights

__all__ = ["QuadraticTerm", "AbsTerm", "Objective", "build_objective", "edge_weights", "pair_edge_weights",
           "second_order_edge_weights", "image_gradient_magnitude", "DEFAULT_L1_SMOOTHING", "Weights",
           "DEFAULT_WEIGHTS", "StackedL1", "is_grid_gradient"]
