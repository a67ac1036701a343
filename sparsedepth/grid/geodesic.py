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

__all__ = ["geodesic_fill", "step_costs", "grid_graph"]


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
    graph = grid_graph(*step_costs(img, contrast))
    sources = np.flatnonzero(observed)
    distance, _, nearest = dijkstra(graph, directed=False, indices=sources, min_only=True, return_predecessors=True)
    del graph
    fill = depth.ravel()[nearest].reshape(depth.shape)
    if return_distance:
        return fill, distance.reshape(depth.shape)
    return fill


def grid_graph(cx, cy):
    """The 4-connected grid graph with step costs ``cx`` (to the right) and ``cy`` (down), as canonical CSR.

    Row ``p = i W + j`` stores its edge to ``p + 1`` (when ``j < W − 1``),
    then its edge to ``p + W`` (when ``i < H − 1``); each undirected edge
    once.  Written straight into the CSR arrays (float64 costs, int32
    indices when they fit): no coordinate lists, no sort.
    """
    H, W = cy.shape[0] + 1, cx.shape[1] + 1
    n = H * W
    itype = np.int32 if 2 * n < np.iinfo(np.int32).max else np.int64
    per_row = np.full((H, W), 2, dtype=itype)  # edges stored in each pixel's row
    per_row[:, -1] -= 1
    per_row[-1, :] -= 1
    indptr = np.zeros(n + 1, dtype=itype)
    np.cumsum(per_row.reshape(-1), out=indptr[1:])
    del per_row
    nnz = int(indptr[-1])
    data = np.empty(nnz)
    indices = np.empty(nnz, dtype=itype)
    top = (H - 1) * (2 * W - 1)  # the image rows above the last: 2 W − 1 edges each
    if H > 1:
        d = data[:top].reshape(H - 1, 2 * W - 1)
        c = indices[:top].reshape(H - 1, 2 * W - 1)
        here = np.arange(n - W, dtype=itype).reshape(H - 1, W)
        d[:, 0:2 * W - 2:2] = cx[:-1]
        c[:, 0:2 * W - 2:2] = here[:, :-1] + 1
        d[:, 1:2 * W - 2:2] = cy[:, :-1]
        c[:, 1:2 * W - 2:2] = here[:, :-1] + W
        d[:, -1] = cy[:, -1]
        c[:, -1] = here[:, -1] + W
    data[top:] = cx[-1]
    indices[top:] = np.arange(n - W + 1, n, dtype=itype)
    return sp.csr_array((data, indices, indptr), shape=(n, n))
