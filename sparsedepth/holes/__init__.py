"""Filling the holes of raw sensor depth: the NYU toolbox colorization fill and the completion objective.

``fill`` (:func:`fill_holes`, the front door of both methods), ``colorization``
(the exact NYU toolbox fill), and its parts: ``affinity`` (grey image, window
weights, sparse rows), ``ordering`` (nested-dissection elimination order),
``schur`` (the block elimination and GMRES on the Schur complement).

May import :mod:`sparsedepth.completion` and everything below it.
"""

from .affinity import GREY_WEIGHTS, colorization_weights, rgb_to_grey
from .colorization import colorization_fill
from .fill import FILL_METHODS, fill_holes

__all__ = ["FILL_METHODS", "fill_holes", "GREY_WEIGHTS", "rgb_to_grey", "colorization_weights", "colorization_fill"]
