"""Filling the holes of raw sensor depth: the NYU toolbox colorization fill and the completion objective.

May import :mod:`sparsedepth.completion` and everything below it.
"""

from .colorization import GREY_WEIGHTS, colorization_fill, colorization_weights, rgb_to_grey
from .fill import FILL_METHODS, fill_holes

__all__ = ["FILL_METHODS", "fill_holes", "GREY_WEIGHTS", "rgb_to_grey", "colorization_weights", "colorization_fill"]
