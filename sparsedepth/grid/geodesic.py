"""Image-aware nearest-sample fills: the nearest observation along paths that avoid crossing image edges.

:func:`geodesic_fill` gives every pixel the value of the observation it reaches at the smallest *path cost* on
the 4-connected pixel grid, where a step between neighbours ``p`` and ``q`` costs ``1 + λ ‖I_p − I_q‖`` (``I``
the [0, 1]-scaled image, ``‖·‖`` the Euclidean norm over the channels).  With ``λ = 0`` the cost is the
city-block distance; with ``λ > 0`` a path that crosses a strong image edge is long, so a pixel takes its value
from a sample on its own side of the edge (the same object, usually the same depth).

May import NumPy, SciPy, :mod:`sparsedepth._validation` and :mod:`.edges`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from .._validation import as_depth_and_mask, as_float_image, check_nonnegative_real, check_same_shape
from .edges import pair_distances

__all__ = ["geodesic_fill", "step_costs"]


def step_costs(image, contrast: float):
    """Costs ``1 + λ ‖I_p − I_q‖`` of the horizontal and vertical steps, shapes ``(H, W−1)`` and ``(H−1, W)``.

    ``cx[i, j]`` is the cost of the step ``(i, j)–(i, j+1)``, ``cy[i, j]`` that of ``(i, j)–(i+1, j)``.

    Raises
    ------
    ValueError
        If ``contrast`` is not a finite number ``>= 0``, or for a bad image.
    """
    contrast = check_nonnegative_real(contrast, name="contrast")
    dx, dy = pair_distances(as_float_image(image))
    return 1.0 + contrast * dx, 1.0 + contrast * dy


def geodesic_fill(image, sparse_depth, mask=None, *, contrast: float = 10.0, return_distance: bool = False):
    """Fill every pixel with the observation nearest to it in image-aware path cost.

    Parameters
    ----------
    image : ndarray, (H, W, 3) or (H, W)
        uint8 (÷255), uint16 (÷65535) or float in [0, 1].
    sparse_depth : ndarray, (H, W)
        Depth at the observed pixels.
    mask : ndarray of bool, (H, W), optional
        True where depth is observed; default: finite and ``> 0``.
    contrast : float
        ``λ >= 0`` of the step cost ``1 + λ ‖I_p − I_q‖``; 0 gives the
        city-block nearest sample.
    return_distance : bool
        Also return the path cost to the chosen sample.

    Returns
    -------
    fill : ndarray, (H, W), float64
        Equal to the observation at every observed pixel.
    distance : ndarray, (H, W), float64
        Only with ``return_distance``: the path cost (0 at the observations).

    Raises
    ------
    ValueError
        For inconsistent shapes, no observed pixel, a bad image or a negative
        or non-finite ``contrast``.

    Notes
    -----
    One multi-source Dijkstra search (``scipy.sparse.csgraph.dijkstra`` with
    ``min_only=True``) over the 4-connected grid graph with the costs of
    :func:`step_costs`: ``d(p) = min_s min_paths Σ cost``, and the fill takes
    the value of the minimising source ``s``.  Ties between sources are
    broken by the search order.  ``O(N log N)`` for ``N = H W`` pixels.

    Examples
    --------
    >>> import numpy as np
    >>> image = np.zeros((1, 5)); image[:, 3:] = 1.0          # an image edge between columns 2 and 3
    >>> depth = np.array([[1.0, 0, 0, 0, 5.0]])
    >>> geodesic_fill(image, depth, contrast=10.0)
    array([[1., 1., 1., 5., 5.]])
    """
    return_distance = bool(return_distance)
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    img = as_float_image(image)
    check_same_shape(img.shape[:2], depth.shape, "image", "sparse_depth")
    cx, cy = step_costs(img, contrast)
    H, W = depth.shape
    index = np.arange(H * W).reshape(H, W)
    rows = np.concatenate([index[:, :-1].ravel(), index[:-1, :].ravel()])
    cols = np.concatenate([index[:, 1:].ravel(), index[1:, :].ravel()])
    graph = sp.csr_array((np.concatenate([cx.ravel(), cy.ravel()]), (rows, cols)), shape=(H * W, H * W))
    sources = np.flatnonzero(observed)
    distance, _, nearest = dijkstra(graph, directed=False, indices=sources, min_only=True, return_predecessors=True)
    fill = depth.ravel()[nearest].reshape(H, W)
    if return_distance:
        return fill, distance.reshape(H, W)
    return fill
