"""The pixel grid: finite-difference operators, stencils and the image gradient.

``operators`` (sparse and matrix-free difference operators), ``stencil``
(stencil images and their CSR form), ``diagonals`` (a symmetric stencil as a
DIA array), ``edges`` (the image gradient and the edge weights built from
it), ``affinity`` (the windowed local-linear image affinities: the matting
Laplacian), ``geodesic`` (the image-aware nearest-sample fill), ``resample``
(block means onto a coarser grid, bilinear upsampling back, edge-aware smoothing sweeps: the
real-time mode).

May import NumPy, SciPy and :mod:`sparsedepth._validation` only.
"""

from .affinity import LocalLinearOperator, local_linear_operator
from .diagonals import stencil_to_dia
from .edges import edge_weights, image_gradient_magnitude, pair_edge_weights, second_order_edge_weights, smoothed_image
from .geodesic import geodesic_fill
from .operators import (StencilOperator, forward_diff, gradient, gradient_stencil, hessian_operator, hessian_stencil,
                        mixed_diff, second_diff)
from .resample import block_mean, block_sample_mean, coarse_shape, edge_aware_sweeps, upsample_bilinear
from .stencil import csr_to_stencil, full_pattern_offsets, stencil_to_csr

__all__ = ["forward_diff", "gradient", "second_diff", "mixed_diff", "hessian_operator", "StencilOperator",
           "gradient_stencil", "hessian_stencil",
           "stencil_to_csr", "csr_to_stencil", "full_pattern_offsets", "stencil_to_dia",
           "image_gradient_magnitude", "edge_weights", "pair_edge_weights", "second_order_edge_weights",
           "smoothed_image", "geodesic_fill", "LocalLinearOperator", "local_linear_operator",
           "coarse_shape", "block_mean", "block_sample_mean", "upsample_bilinear", "edge_aware_sweeps"]
