"""Moving between the pixel grid and a grid ``f`` times coarser per side, and edge-aware smoothing sweeps.

The real-time mode (``complete_depth(..., quality="fast")``) solves on a
coarse grid and comes back to the full one with these:

* :func:`block_mean` - the mean of each ``f x f`` block (the coarse image);
* :func:`block_sum` - the sum of each ``f x f`` block;
* :func:`block_sample_mean` - the mean of the observed values of each block
  and whether it holds any (the coarse samples);
* :func:`upsample_bilinear` - the coarse depth, bilinearly interpolated between
  the block centres;
* :func:`edge_aware_sweeps` - red-black Gauss-Seidel sweeps on an
  image-weighted smoothness model with the observations held.

The nested iteration of the ADMM solver (option ``warm_start="coarse"``)
moves an L1 problem's solution back with :func:`upsample_bilinear` and its
dual edge field with :func:`upsample_edges`.

May import NumPy, :mod:`sparsedepth._validation`, :mod:`sparsedepth.limits`, :mod:`.edges` and :mod:`.rowbands`.
"""

from __future__ import annotations

import numpy as np

from .._validation import as_float_image, check_count, check_nonnegative_count, check_nonnegative_real
from .edges import pair_distances
from .rowbands import row_bands, rows_per_band
from ..limits import memory_limits

__all__ = ["coarse_shape", "block_mean", "block_sum", "block_sample_mean", "upsample_bilinear", "upsample_edges",
           "edge_aware_sweeps"]


def coarse_shape(shape, factor: int) -> tuple[int, int]:
    """``(ceil(H / f), ceil(W / f))``: the blocks of the last row and column may be partial."""
    factor = check_count(factor, name="factor")
    return -(-int(shape[0]) // factor), -(-int(shape[1]) // factor)


def _block_sums(values, factor, where=None, dtype=None):
    """Sums over each ``f x f`` block (the partial blocks of the last row and column included), leading axes ``(h, w)``.

    Strided adds (faster than a reduction over a middle axis): the rows ``y ≡ o (mod f)`` are added offset by
    offset, then the columns; an offset with one row or column fewer adds to all blocks but the last.  ``where``
    (a boolean ``(H, W)`` array): only those values are summed (the others count as 0), masked a row offset at a
    time.  ``dtype``: the type summed in (default that of ``values``).  A channel axis is summed channel by channel
    (strided adds along a row of one channel are faster than of short runs of all channels).
    """
    if values.ndim == 3:
        return np.stack([_block_sums(values[..., c], factor, where, dtype) for c in range(values.shape[2])], axis=-1)

    def rows_at(offset):
        part = values[offset::factor]
        return part if where is None else np.where(where[offset::factor], part, 0.0)

    rows = rows_at(0)
    rows = rows.astype(dtype) if dtype is not None else rows.copy() if where is None else rows
    for offset in range(1, factor):
        part = rows_at(offset)
        rows[:part.shape[0]] += part
    out = rows[:, 0::factor].copy()
    for offset in range(1, factor):
        part = rows[:, offset::factor]
        out[:, :part.shape[1]] += part
    return out


def _block_counts(shape, factor):
    """The number of pixels of each ``f x f`` block of an ``(H, W)`` grid (``f²`` but in the last row and column)."""
    H, W = shape
    h, w = coarse_shape((H, W), factor)
    rows = np.minimum(factor, H - factor * np.arange(h))
    columns = np.minimum(factor, W - factor * np.arange(w))
    return np.multiply.outer(rows, columns).astype(np.float64)


def block_mean(values, factor: int) -> np.ndarray:
    """The mean of each ``f x f`` block of ``values`` (shape ``(H, W)`` or ``(H, W, C)``), partial blocks included.

    Returns
    -------
    ndarray, shape ``coarse_shape((H, W), f)`` (plus the channel axis), float64
        Summed in the precision of ``values`` (float32 stays float32 until the division); integers of up to 32
        bits and booleans exactly, in an integer type wide enough (uint16 for 8-bit values and ``f <= 16``).
    """
    values = np.asarray(values)
    counts = _block_counts(values.shape[:2], factor)
    if np.issubdtype(values.dtype, np.floating):
        sums = _block_sums(values, factor)
    elif values.dtype.itemsize <= 4 and (values.dtype.kind in "biu"):
        small = values.dtype.itemsize == 1 and values.dtype.kind in "bu" and factor <= 16  # f² · 255 < 2¹⁶
        sums = _block_sums(values, factor, dtype=np.uint16 if small else np.int64)
    else:
        sums = _block_sums(values.astype(np.float64), factor)
    sums = sums.astype(np.float64)
    return sums / (counts if values.ndim == 2 else counts[..., None])


def block_sum(values, factor: int) -> np.ndarray:
    """The sum of each ``f x f`` block of ``values`` (shape ``(H, W)``), partial blocks included, in float64.

    Returns
    -------
    ndarray, shape ``coarse_shape((H, W), f)``
    """
    factor = check_count(factor, name="factor")
    return _block_sums(np.asarray(values, dtype=np.float64), factor)


def block_sample_mean(depth, observed, factor: int):
    """The mean observed depth of each ``f x f`` block and the blocks that hold at least one observation.

    Parameters
    ----------
    depth : ndarray, shape (H, W)
        Finite where ``observed``; other values are ignored.
    observed : ndarray of bool, shape (H, W)
    factor : int

    Returns
    -------
    coarse_depth : ndarray, float64
        The mean of the block's observed values; 0 where it has none.
    coarse_observed : ndarray of bool
    """
    observed = np.asarray(observed, dtype=bool)
    factor = check_count(factor, name="factor")
    # exact: <= f² per block (a bool array is its 0/1 bytes)
    counts = _block_sums(observed.view(np.uint8) if factor < 16 else observed.astype(np.int64), factor)
    sums = _block_sums(np.asarray(depth), factor, where=observed)
    coarse_observed = counts > 0
    return np.where(coarse_observed, sums / np.maximum(counts, 1), 0.0), coarse_observed


def _linear_taps(n_fine, n_coarse, factor, edges=False):
    """Coarse indices ``(i0, i1)`` and weight of ``i1`` for each fine index (block centres as nodes, clamped ends).

    ``edges``: the nodes are the coarse edges (fine position ``(j + 1) f − ½``) and the points the fine edges
    (``x + ½``), as :func:`upsample_edges` places them.
    """
    if edges:
        position = (np.arange(n_fine) + 1.0) / factor - 1.0
    else:
        position = (np.arange(n_fine) + 0.5) / factor - 0.5
    np.clip(position, 0.0, n_coarse - 1, out=position)
    i0 = np.floor(position).astype(np.intp)
    i1 = np.minimum(i0 + 1, n_coarse - 1)
    return i0, i1, position - i0


def _interpolate(coarse, r_taps, c_taps):
    """``coarse`` interpolated by the row taps, then the column taps (each ``(i0, i1, weight of i1)``)."""
    r0, r1, wr = r_taps
    c0, c1, wc = c_taps
    wr = wr.astype(coarse.dtype)[:, None]
    wc = wc.astype(coarse.dtype)
    rows = coarse[r0] * (1 - wr) + coarse[r1] * wr  # (H, w): the coarse rows interpolated
    out = np.take(rows, c0, axis=1)
    out *= 1 - wc
    right = np.take(rows, c1, axis=1)
    right *= wc
    out += right
    return out


def upsample_bilinear(coarse, shape, factor: int) -> np.ndarray:
    r"""The coarse field bilinearly interpolated onto the fine grid of ``shape``.

    The value of coarse pixel ``(i, j)`` sits at the centre of its block, the
    fine position ``((i + ½) f − ½, (j + ½) f − ½)``; fine pixels beyond the
    outermost centres take the nearest centre's row or column (constant
    extension).  Separable: rows, then columns.

    Returns
    -------
    ndarray, shape ``shape``, the dtype of ``coarse`` (float)
    """
    coarse = np.asarray(coarse)
    H, W = int(shape[0]), int(shape[1])
    if coarse.shape != coarse_shape((H, W), factor):
        raise ValueError(f"coarse has shape {coarse.shape}; a {H}x{W} grid at factor {factor} needs "
                         f"{coarse_shape((H, W), factor)}")
    return _interpolate(coarse, _linear_taps(H, coarse.shape[0], factor), _linear_taps(W, coarse.shape[1], factor))


def upsample_edges(coarse, shape, factor: int, axis: int) -> np.ndarray:
    r"""A field on the coarse grid's edges along ``axis`` interpolated onto the fine grid's edges along it.

    Entry ``(i, j)`` of an edge field along ``axis = 1`` belongs to the edge
    between pixels ``(i, j)`` and ``(i, j + 1)`` (the row order of the
    forward difference :func:`~sparsedepth.grid.operators.forward_diff`);
    along ``axis = 0``, to the edge between ``(i, j)`` and ``(i + 1, j)``.

    Parameters
    ----------
    coarse : ndarray, shape ``coarse_shape(shape, factor)``
    shape : tuple of int
        The fine grid ``(H, W)``.
    factor : int
    axis : {0, 1}

    Returns
    -------
    ndarray, shape ``shape``

    Notes
    -----
    Across ``axis`` the values are interpolated as by
    :func:`upsample_bilinear` (block centres).  Along it, the coarse edge
    ``j`` sits halfway between the centres of blocks ``j`` and ``j + 1``,
    at fine position ``(j + 1) f − ½``, and the fine edge ``x`` at ``x +
    ½``; the fine edges are interpolated linearly between the coarse edges
    around them (constant beyond the outermost ones).  With ``f = 2`` the
    fine edge ``2j + 1``, which lies between the two blocks, takes coarse
    edge ``j``'s value, and the fine edge ``2j`` inside block ``j`` the mean
    of coarse edges ``j − 1`` and ``j``.
    """
    coarse = np.asarray(coarse)
    H, W = int(shape[0]), int(shape[1])
    if coarse.shape != coarse_shape((H, W), factor):
        raise ValueError(f"coarse has shape {coarse.shape}; a {H}x{W} grid at factor {factor} needs "
                         f"{coarse_shape((H, W), factor)}")
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 or 1, got {axis!r}")
    taps = [_linear_taps(H, coarse.shape[0], factor), _linear_taps(W, coarse.shape[1], factor)]
    taps[axis] = _linear_taps((H, W)[axis], coarse.shape[axis], factor, edges=True)
    return _interpolate(coarse, *taps)


# the numpydoc docstring (the model in Notes) is most of the length
def edge_aware_sweeps(start, image, depth, observed, *, smoothness: float, kappa: float, sweeps: int,
                      start_factor: int = 1, dtype=np.float32) -> np.ndarray:
    r"""Red-black Gauss-Seidel sweeps on an image-weighted smoothness model, the observations held fixed.

    Parameters
    ----------
    start : ndarray, shape (H, W), or ``coarse_shape((H, W), start_factor)``
        The field to refine; also the model's prior.  With ``start_factor >
        1``, a coarse field whose bilinear interpolation
        (:func:`upsample_bilinear`) is the start, interpolated a band of rows
        at a time (no full-size copy).
    image : ndarray, shape (H, W, C) or (H, W)
        Any image :func:`~sparsedepth._validation.as_float_image` takes
        (uint8, uint16 or floats in [0, 1]), scaled to [0, 1] in float32 a
        band of rows at a time (no float copy of the whole image).
    depth : ndarray, shape (H, W) or (N,)
        The observed values (finite where ``observed``), or only those
        (``depth[observed]``, ``N`` the number of observed pixels).
    observed : ndarray of bool, shape (H, W)
        Where the observations are.
    smoothness : float
        ``λ >= 0`` below.
    kappa : float
        ``κ >= 0`` of the pair weights below.
    sweeps : int
        Red-black sweeps (``>= 0``; 0 returns ``start`` with the observations
        put back).
    start_factor : int
        1 (``start`` is on the grid) or the coarsening of ``start``.
    dtype : {numpy.float32, numpy.float64}
        The type of the returned array; the sweeps compute in float32 either
        way (float64 holds the float32 values exactly).

    Returns
    -------
    ndarray, shape (H, W), ``dtype``

    Notes
    -----
    The model, over the unobserved pixels ``i`` (observed ones are fixed at
    their values)::

        Σ_i (z_i − s_i)² + λ Σ_(i,j) w_ij (z_i − z_j)²,   w_ij = exp(−κ ‖I_i − I_j‖)

    over the 4-neighbour pairs, ``s`` the start.  A Gauss-Seidel update sets
    ``z_i`` to its minimiser with the neighbours fixed,
    ``(s_i + λ Σ_j w_ij z_j) / (1 + λ Σ_j w_ij)``; the pixels of one parity
    of ``y + x`` have no neighbour of the same parity, so each half sweep is
    one vectorised update.  The iteration converges (the model is strictly
    convex) but only over distances of about one pixel per sweep: it
    corrects the start locally, near the observations and across image
    edges, where a weight ``w_ij`` near 0 keeps depth from leaking.
    Computed in float32, each update adding the terms of the left, right,
    upper and lower neighbour in that order.

    Each parity is kept as its own contiguous array, the grid read row by
    row with an odd row length ``P`` (``W``, or ``W + 1`` with a fixed
    column of zero weights), so that the parity of the flat index ``i = P y
    + x`` is that of ``y + x``; the neighbours ``i ± 1`` and ``i ± P`` of a
    pixel are then at constant offsets in the other parity's array.
    """
    smoothness = check_nonnegative_real(smoothness, name="smoothness")
    kappa = check_nonnegative_real(kappa, name="kappa")
    sweeps = check_nonnegative_count(sweeps, name="sweeps")
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise ValueError(f"dtype must be float32 or float64, got {dtype}")
    observed = np.asarray(observed, dtype=bool)
    start_factor = check_count(start_factor, name="start_factor")
    start = np.asarray(start)
    if observed.ndim != 2:
        raise ValueError(f"observed must be an (H, W) array, got shape {observed.shape}")
    if start.shape != coarse_shape(observed.shape, start_factor):
        raise ValueError(f"start has shape {start.shape}; the {observed.shape} grid at start_factor {start_factor} "
                         f"needs {coarse_shape(observed.shape, start_factor)}")
    depth = np.asarray(depth)
    samples = (depth[observed] if depth.ndim == 2 else depth).astype(np.float32)  # the samples in float32
    if samples.shape != (np.count_nonzero(observed),):
        raise ValueError(f"depth has shape {depth.shape}: give the grid's values, or one per observed pixel")
    if sweeps == 0 or smoothness == 0:
        z = (start if start_factor == 1 else upsample_bilinear(start, observed.shape, start_factor)).astype(np.float32)
        z[observed] = samples
        return z.astype(dtype, copy=False)
    layout = _ParityLayout(*observed.shape)
    priors = _parity_start(layout, start, start_factor)
    fields = priors.copy()
    held = layout.entries(observed)  # the observed pixels' entries in the flat (2 * half) parity storage
    fields.reshape(-1)[held] = samples
    across, down = _parity_pair_weights(layout, image, kappa, smoothness)
    inverses = np.ones_like(priors)  # 1 + the pixel's pair weights (left, right, upper, lower), then its reciprocal
    for target in (0, 1):
        _add_pair_weights(inverses[target], across, down, target, layout.offsets(target))
    np.reciprocal(inverses, out=inverses)
    chunk = max(1, memory_limits().sweep_band_values)
    for _ in range(int(sweeps)):
        for target in (0, 1):
            _half_sweep(fields, target, priors, inverses, across, down, layout.offsets(target), chunk)
            fields.reshape(-1)[held] = samples  # the observations stay as they are
    del priors, inverses, across, down  # freed before the result is allocated
    return layout.merge(fields, dtype)


def _parity_start(layout, start, factor):
    """The start split by parity in float32: ``start`` itself (``factor`` 1) or its bilinear interpolation.

    The interpolation (:func:`upsample_bilinear`'s numbers) is computed and stored a band of rows at a time.
    """
    if factor == 1:
        return layout.split(start, np.float32)
    H, W = layout.shape
    priors = np.zeros((2, layout.half), dtype=np.float32)
    r0, r1, wr = _linear_taps(H, start.shape[0], factor)
    columns = _linear_taps(W, start.shape[1], factor)
    band = rows_per_band(W, memory_limits().sweep_band_values, multiple=2)  # even: bands start on even rows
    for rows in row_bands(0, H, band):
        layout.put(priors, _interpolate(start, (r0[rows], r1[rows], wr[rows]), columns), first_row=rows.start)
    return priors


def _parity_pair_weights(layout, image, kappa, smoothness):
    """``(across, down)`` split by parity: ``λ exp(−κ d)`` of each pixel's pair with its right / lower neighbour.

    The image is scaled (:func:`~sparsedepth._validation.as_float_image`, float32) and the pair distances
    (:func:`~sparsedepth.grid.edges.pair_distances`) computed over bands of rows (about ``sweep_band_values``
    pair weights each), and written into the parity storage band by band; the pairs beyond the last column and
    row have weight 0.
    """
    image = np.asarray(image)
    H, W = layout.shape
    if image.shape[:2] != (H, W):
        raise ValueError(f"image has shape {image.shape}; the grid is {H}x{W}")
    across, down = np.zeros((2, 2, layout.half), dtype=np.float32)
    band = rows_per_band(W, memory_limits().sweep_band_values, multiple=2)  # even: bands start on even rows
    for rows in row_bands(0, H, band):
        y0, y1 = rows.start, rows.stop
        distance_across, distance_down = pair_distances(as_float_image(image[y0:y1 + 1], dtype=np.float32))
        layout.put(across, _pair_weights(distance_across[:y1 - y0], kappa, smoothness), first_row=y0)
        layout.put(down, _pair_weights(distance_down, kappa, smoothness), first_row=y0)
    return across, down


class _ParityLayout:
    """The pixels of an ``(H, W)`` grid split by the parity of ``y + x``, each parity a contiguous array.

    The grid is padded to an even number of rows ``H'`` and an odd row length ``P`` (``W``, or ``W + 1``) with fixed
    pixels whose pair weights are 0, and read row by row: flat index ``i = P y + x`` has the parity of ``y + x``.
    Parity ``p`` holds flat index ``2j + p`` at entry ``j`` (``H' P / 2`` entries).  Rows ``2k`` and ``2k + 1`` of
    the grid are entries ``k P .. (k + 1) P − 1`` of either parity: of parity 0, first ``x = 0, 2, ..`` of row
    ``2k`` (``(P + 1) / 2`` of them), then ``x = 1, 3, ..`` of row ``2k + 1``; of parity 1, ``x = 1, 3, ..`` of row
    ``2k`` (``(P − 1) / 2``), then ``x = 0, 2, ..`` of row ``2k + 1``.
    """

    def __init__(self, H, W):
        self.shape = (int(H), int(W))
        self.row = int(W) + 1 - int(W) % 2
        self.pairs_of_rows = (int(H) + 1) // 2
        self.half = self.pairs_of_rows * self.row

    def _views(self, parts, first_row=0):
        """The four strided pieces of ``parts`` (2, half) from grid row ``first_row`` (even) on, and the grid slices
        of an array starting at that row that each holds."""
        even = (self.row + 1) // 2
        start = first_row // 2
        first, second = (part.reshape(self.pairs_of_rows, self.row)[start:] for part in parts)
        return (((first[:, :even]), (slice(0, None, 2), slice(0, None, 2))),
                ((first[:, even:]), (slice(1, None, 2), slice(1, None, 2))),
                ((second[:, :even - 1]), (slice(0, None, 2), slice(1, None, 2))),
                ((second[:, even - 1:]), (slice(1, None, 2), slice(0, None, 2))))

    def put(self, parts, values, first_row=0):
        """Write the grid array ``values`` into ``parts``, cast to their type.

        ``values`` has shape ``(h, w)``, ``w <= W``: grid rows ``first_row .. first_row + h − 1`` (``first_row``
        even), columns ``0 .. w − 1``.
        """
        for view, (rows, columns) in self._views(parts, first_row):
            piece = values[rows, columns]
            np.copyto(view[:piece.shape[0], :piece.shape[1]], piece, casting="unsafe")

    def entries(self, mask):
        """The indices in the flattened ``(2, half)`` storage of the pixels where the ``(H, W)`` mask is True."""
        pixel = np.flatnonzero(mask)  # y W + x
        flat = pixel + (pixel // self.shape[1]) * (self.row - self.shape[1])  # y P + x
        return (flat & 1) * self.half + (flat >> 1)

    def split(self, values, dtype):
        """``(2, half)`` of ``dtype``: the grid array ``values`` (see :meth:`put`) split by parity, 0 elsewhere."""
        parts = np.zeros((2, self.half), dtype=dtype)
        self.put(parts, values)
        return parts

    def merge(self, parts, dtype):
        """The ``(H, W)`` array of ``dtype`` whose pixels are in ``parts`` (the inverse of :meth:`split`)."""
        out = np.empty(self.shape, dtype=dtype)
        for view, (rows, columns) in self._views(parts):
            piece = out[rows, columns]
            piece[...] = view[:piece.shape[0], :piece.shape[1]]
        return out

    def offsets(self, target):
        """Offsets ``(left, right, up, down)`` in the other parity of the neighbours of parity ``target``'s entry ``j``.

        Entry ``j`` of parity 0 is flat ``2j``, whose neighbours ``2j − 1``, ``2j + 1``, ``2j ∓ P`` are entries ``j −
        1``, ``j``, ``j − (P + 1) / 2``, ``j + (P − 1) / 2`` of parity 1; entry ``j`` of parity 1 is flat ``2j + 1``,
        whose neighbours are entries ``j``, ``j + 1``, ``j − (P − 1) / 2``, ``j + (P + 1) / 2`` of parity 0.
        """
        up, down = (self.row + 1) // 2, (self.row - 1) // 2
        return (-1, 0, -up, down) if target == 0 else (0, 1, -down, up)


def _neighbour_terms(across, down, target, offsets):
    """``(pair weights, their offset, the neighbour's offset)`` of the left, right, upper and lower neighbour.

    A pixel's left and upper pairs are its neighbour's right and lower pairs, read at the neighbour's entry of the
    other parity; its right and lower pairs are its own.
    """
    other = 1 - target
    left, right, up, below = offsets
    return ((across[other], left, left), (across[target], 0, right), (down[other], up, up), (down[target], 0, below))


def _overlap(j0, j1, offset, half):
    """``(lo, hi)``: the entries of ``j0:j1`` whose neighbour at ``offset`` is one of the ``half`` entries."""
    return max(j0, -offset), min(j1, half - offset)


def _add_pair_weights(diagonal, across, down, target, offsets):
    """Add to ``diagonal`` (parity ``target``) each pixel's pair weights in the order left, right, up, down."""
    half = diagonal.shape[0]
    for weights, weight_offset, offset in _neighbour_terms(across, down, target, offsets):
        lo, hi = _overlap(0, half, offset, half)
        if hi > lo:
            diagonal[lo:hi] += weights[lo + weight_offset:hi + weight_offset]


def _pair_weights(distance, kappa, smoothness):
    """``smoothness · exp(−κ d)`` in place on the float32 pair distances ``d``."""
    distance *= -kappa
    np.exp(distance, out=distance)
    distance *= smoothness
    return distance


def _half_sweep(fields, target, priors, inverses, across, down, offsets, chunk):
    """Update parity ``target`` of ``fields`` (in place) from its neighbours in the other parity.

    ``fields``, ``priors``, ``inverses``, ``across`` and ``down`` are split by parity
    (:meth:`_ParityLayout.split`); ``across`` and ``down`` hold the pair of each pixel with its right and its lower
    neighbour.  A pixel's left and upper pairs are thus its neighbour's, read at the neighbour's entry of the other
    parity; its right and lower pairs are its own.  ``offsets``: :meth:`_ParityLayout.offsets`.  Every entry is
    updated, the observed ones too (the caller puts them back).  The entries are updated in chunks of ``chunk``
    (the partial sums stay in cache); each adds its terms in the order left, right, up, down.
    """
    near, z = fields[1 - target], fields[target]
    terms = _neighbour_terms(across, down, target, offsets)
    half = z.shape[0]
    product = np.empty(min(chunk, half), dtype=z.dtype)
    for j0 in range(0, half, chunk):
        j1 = min(half, j0 + chunk)
        update = z[j0:j1]  # the other parity alone is read: the update is summed in place
        np.copyto(update, priors[target, j0:j1])
        for weights, weight_offset, offset in terms:
            lo, hi = _overlap(j0, j1, offset, half)
            if hi <= lo:
                continue
            part = product[lo - j0:hi - j0]
            np.multiply(weights[lo + weight_offset:hi + weight_offset], near[lo + offset:hi + offset], out=part)
            update[lo - j0:hi - j0] += part
        update *= inverses[target, j0:j1]
