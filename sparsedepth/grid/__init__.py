"""The pixel grid: stencils, finite-difference operators and image-edge weights.

Imports NumPy and SciPy only (and :mod:`sparsedepth._validation`).
"""

from .operators import forward_diff, gradient, hessian_operator, mixed_diff, second_diff
from .stencil import csr_to_stencil, full_pattern_offsets, stencil_to_csr

__all__ = ["forward_diff", "gradient", "second_diff", "mixed_diff", "hessian_operator",
           "stencil_to_csr", "csr_to_stencil", "full_pattern_offsets"]
