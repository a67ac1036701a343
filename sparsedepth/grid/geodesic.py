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

__all__ = ["geodesic_fill", "nearest_sources", "step_costs", "grid_graph"]


def step_costs(image, contrast: float):
    """Costs ``1 + λ ‖I_p − I_q‖`` of the horizontal and vertical steps, shapes ``(H, W−1)`` and ``(H−1, W)``.

    ``cx[i, j]`` is the cost of the step ``(i, j)–(i, j+1)``, ``cy[i, j]`` that of ``(i, j)–(i+1, j)``.

    Raises
    ------
    ValueError
        If ``contrast`` is not a finite number ``>= 0``, or for a bad image.
    """
    return _scaled_image_step_costs(as_float_image(image), contrast)


def _scaled_image_step_costs(image, contrast):
    """:func:`step_costs` of an image already scaled by :func:`~sparsedepth._validation.as_float_image`."""
    contrast = check_nonnegative_real(contrast, name="contrast")
    dx, dy = pair_distances(image)
    for d in (dx, dy):
        d *= contrast
        d += 1.0
    return dx, dy


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
    ``d(p) = min_s min_paths Σ cost`` over the 4-connected grid with the costs
    of :func:`step_costs`, and the fill takes the value of the minimising
    source ``s``: :func:`nearest_sources`, an exact multi-source shortest-path
    search (the distances of Dijkstra's algorithm on :func:`grid_graph`).
    Where two sources are at exactly the same path cost, either may be chosen.

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
    distance, nearest = nearest_sources(*_scaled_image_step_costs(img, contrast), observed)
    fill = depth.ravel()[nearest]
    if return_distance:
        return fill, distance
    return fill


def nearest_sources(cx, cy, sources):
    """Path cost to the nearest source and which source it is, for every pixel of a 4-connected grid.

    Parameters
    ----------
    cx : ndarray, (H, W−1)
        ``cx[i, j]`` is the cost of the step ``(i, j)–(i, j+1)`` (both ways).
    cy : ndarray, (H−1, W)
        ``cy[i, j]`` is the cost of the step ``(i, j)–(i+1, j)``.
    sources : ndarray of bool, (H, W)
        The pixels at distance 0; at least one.

    Returns
    -------
    distance : ndarray, (H, W), float64
        The least path cost from any source.
    nearest : ndarray, (H, W), intp
        The flat index ``i W + j`` of a source at that cost.

    Raises
    ------
    ValueError
        For shapes that do not fit, no source, or a cost that is not finite
        and ``> 0``.

    Notes
    -----
    A label-setting search in rounds (Dial's buckets, anchored at the least
    tentative distance).  With ``δ`` the least step cost and ``m`` the least
    tentative distance of the pixels reached but not yet final, every such
    pixel ``p`` with ``d(p) < m + δ`` is final: a shorter path to ``p`` would
    leave the final pixels through another reached pixel ``r``, at
    ``d(r) >= m``, and take at least one more step, ``>= m + δ``.  One round
    finalises all of them at once and relaxes their four neighbours with
    array operations, one direction at a time (each direction maps distinct
    pixels to distinct neighbours, so a scatter has no collisions):
    ``d(q) ← min(d(q), d(p) + c_pq)``, ``s(q) ← s(p)`` where it improves.
    Each pixel is final once and relaxed from at most four neighbours; the
    number of rounds is about ``max d / δ``.  The distances are sums of the
    same float64 costs along the same shortest paths as Dijkstra's; among
    sources at exactly equal cost the first to reach a pixel keeps it.

    A round costs a few dozen array calls whatever its size, so after
    ``64 + H W / 128`` rounds (far more than an image needs, but a grid a few
    pixels wide takes one round per step) the search starts again as one
    multi-source Dijkstra search (``scipy.sparse.csgraph.dijkstra`` with
    ``min_only=True``) over :func:`grid_graph`: at most about twice that
    search's time, however thin the grid.
    """
    sources = np.asarray(sources, dtype=bool)
    if sources.ndim != 2:
        raise ValueError(f"sources must be a 2-D (H, W) array, got shape {sources.shape}")
    H, W = sources.shape
    cx, cy = np.asarray(cx, dtype=np.float64), np.asarray(cy, dtype=np.float64)
    if cx.shape != (H, W - 1) or cy.shape != (H - 1, W):
        raise ValueError(f"step costs of shapes {cx.shape} and {cy.shape} do not fit a grid of shape {(H, W)}: "
                         f"expected {(H, W - 1)} and {(H - 1, W)}")
    least_step = min(float(cx.min(initial=np.inf)), float(cy.min(initial=np.inf)))
    if not (np.all(np.isfinite(cx)) and np.all(np.isfinite(cy)) and least_step > 0):
        raise ValueError("step costs must be finite and > 0")
    if not sources.any():
        raise ValueError("sources has no True pixel")
    Wp = W + 2  # a frame of one pixel round the grid, never reached: no bounds checks in the rounds
    steps = np.full((H + 2, Wp, 4), np.inf)  # per pixel: the cost to its right, left, lower, upper neighbour
    steps[1:-1, 1:-2, 0] = cx
    steps[1:-1, 2:-1, 1] = cx
    steps[1:-2, 1:-1, 2] = cy
    steps[2:-1, 1:-1, 3] = cy
    steps = steps.reshape(-1, 4)
    offsets = (1, -1, Wp, -Wp)
    distance = np.full((H + 2, Wp), np.inf)
    distance[1:-1, 1:-1][sources] = 0.0
    nearest = np.zeros((H + 2, Wp), dtype=np.int32 if H * W < np.iinfo(np.int32).max else np.intp)
    nearest[1:-1, 1:-1][sources] = np.flatnonzero(sources)
    # the first round: the sources with a neighbour that is not a source (the others improve nothing)
    open_ = np.zeros((H + 2, Wp), dtype=bool)
    open_[1:-1, 1:-1] = ~sources
    boundary = np.zeros((H + 2, Wp), dtype=bool)
    inner = boundary[1:-1, 1:-1]
    np.logical_or(open_[1:-1, 2:], open_[1:-1, :-2], out=inner)
    inner |= open_[2:, 1:-1]
    inner |= open_[:-2, 1:-1]
    inner &= sources
    del open_
    final = np.flatnonzero(boundary.reshape(-1))
    del boundary
    distance = distance.reshape(-1)
    nearest = nearest.reshape(-1)
    reached = np.empty(0, dtype=np.intp)  # reached, not final; each pixel once
    rounds_left = 64 + H * W // 128
    while final.size:
        rounds_left -= 1
        if rounds_left < 0:  # rounds of a few pixels each (a thin grid): one heap-ordered search costs less
            del steps, distance, nearest, final, reached
            return _dijkstra_nearest_sources(cx, cy, sources)
        d = distance[final]
        s = nearest[final]
        c = np.take(steps, final, axis=0)
        parts = [reached]
        for j, offset in enumerate(offsets):
            q = final + offset
            candidate = c[:, j] + d
            before = distance[q]
            better = (candidate < before).nonzero()[0]
            q = q[better]
            distance[q] = candidate[better]
            nearest[q] = s[better]
            parts.append(q[before[better] == np.inf])
        reached = np.concatenate(parts)
        if not reached.size:
            break
        d = distance[reached]
        now = d < d.min() + least_step
        final = reached[now.nonzero()[0]]
        reached = reached[(~now).nonzero()[0]]
    distance = distance.reshape(H + 2, Wp)[1:-1, 1:-1].copy()
    return distance, nearest.reshape(H + 2, Wp)[1:-1, 1:-1].astype(np.intp)


def _dijkstra_nearest_sources(cx, cy, sources):
    """:func:`nearest_sources` by one multi-source Dijkstra search over :func:`grid_graph`."""
    distance, _, nearest = dijkstra(grid_graph(cx, cy), directed=False, indices=np.flatnonzero(sources),
                                    min_only=True, return_predecessors=True)
    return distance.reshape(sources.shape), nearest.reshape(sources.shape).astype(np.intp)


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
