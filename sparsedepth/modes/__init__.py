"""The modes of :func:`sparsedepth.complete_depth` beyond one solve, each a function over a completion problem.

- :mod:`~sparsedepth.modes.fast`: :func:`complete_fast`, the real-time mode (a solve on a coarser grid, upsampled
  and refined by edge-aware sweeps);
- :mod:`~sparsedepth.modes.prior`: :func:`complete_with_prior`, a dense prior aligned to the samples and the
  residual completed;
- :mod:`~sparsedepth.modes.uncertainty`: :func:`complete_with_uncertainty`, the per-pixel uncertainty from two
  half-sample solves of the same problem.

May import :mod:`sparsedepth.problem` and everything below it (:mod:`sparsedepth.solvers`,
:mod:`sparsedepth.objective`, :mod:`sparsedepth.grid`, :mod:`sparsedepth.priors`,
:mod:`sparsedepth.uncertainty`, :mod:`sparsedepth.result`, :mod:`sparsedepth._validation`); never
:mod:`sparsedepth.completion` (which calls them).
"""

from .fast import FAST_WEIGHTS, complete_fast, fast_factor
from .prior import complete_with_prior
from .uncertainty import complete_with_uncertainty

__all__ = ["complete_fast", "complete_with_prior", "complete_with_uncertainty", "fast_factor", "FAST_WEIGHTS"]
