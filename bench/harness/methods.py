"""The compared methods: ours (``sparsedepth.complete_depth``) and the baselines, each a :class:`Method`.

Only the library's defaults read at run time (``sparsedepth.DEFAULT_SCHEDULE``) are used for "ours", never a copy of its numbers.

May import :mod:`sparsedepth`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Callable

import sparsedepth as sd

__all__ = ["Method", "ours", "NEAREST", "LINEAR", "BIHARMONIC", "COLORIZATION"]


@dataclass(frozen=True)
class Method:
    """A named way of turning ``(image, sparse, mask)`` into dense depth.

    ``run`` returns a dense depth array or a :class:`sparsedepth.CompletionResult`;
    ``key`` identifies identical methods for the cache.
    """

    name: str
    run: Callable = field(repr=False, compare=False)
    key: tuple = ()


def ours(name="ours", *, weights=None, solver="auto", tol=None, max_iter=None, clip_to_observed=True,
         options=None) -> Method:
    """``sparsedepth.complete_depth``; ``weights=None`` uses the library's defaults now (``sd.DEFAULT_SCHEDULE``
    evaluated at each input's observed fraction of the pixels).

    ``clip_to_observed=False`` keeps the solver's minimiser as it is (the solver table compares optimisers, not
    the range clamp that follows them); the range clamp's warning is not shown (its count is in the result).
    """
    w = sd.DEFAULT_SCHEDULE if weights is None else weights

    def run(image, sparse, mask):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sd.ClampWarning)
            return sd.complete_depth(image, sparse, mask, weights=w, solver=solver, tol=tol, max_iter=max_iter,
                                     clip_to_observed=clip_to_observed, options=options)

    key_options = None if options is None else tuple(sorted(options.items()))
    return Method(name, run, ("complete", w, solver, tol, max_iter, clip_to_observed, key_options))


NEAREST = Method("nearest", lambda image, sparse, mask: sd.nearest_fill(sparse, mask), ("nearest",))
LINEAR = Method("linear (griddata)", lambda image, sparse, mask: sd.linear_fill(sparse, mask), ("linear",))
BIHARMONIC = Method("biharmonic (skimage)", lambda image, sparse, mask: sd.biharmonic_fill(sparse, mask),
                    ("biharmonic",))
COLORIZATION = Method("colorization (Levin/NYU)",
                      lambda image, sparse, mask: sd.colorization_baseline(image, sparse, mask), ("colorization",))
