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

May import NumPy, :mod:`sparsedepth._validation`, :mod:`.edges` and :mod:`.rowbands`.
"""

from __future__ import annotations

import numpy as np

from .._validation import check_count, check_nonnegative_count, check_nonnegative_real
from .edges import pair_distances
from .rowbands import row_bands, rows_per_band
from ..limits import memory_limits

__all__ = ["coarse_shape", "block_mean", "block_sum", "block_sample_mean", "upsample_bilinear", "upsample_edges",
           "edge_aware_sweeps"]


def coarse_shape(shape, factor: int) -> tuple[int, int]:
    """``(ceil(H / f), ceil(W / f))``: the blocks of the last row and column may be partial."""
    factor = check_count(factor, name="factor")
    return -(-int(shape[0]) // factor), -(-int(shape[1]) // factor)


def _block_sums(values, factor):
    """Sums over each ``f x f`` block (the partial blocks of the last row and column included), leading axes ``(h, w)``.

    Strided adds (faster than a reduction over a middle axis): the rows ``y ≡ o (mod f)`` are added offset by
    offset, then the columns; an offset with one row or column fewer adds to all blocks but the last.
    """
    rows = values[0::factor].copy()
    for offset in range(1, factor):
        part = values[offset::factor]
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
        Summed in the precision of ``values`` (float32 stays float32 until the division).
    """
    values = np.asarray(values)
    if not np.issubdtype(values.dtype, np.floating):
        values = values.astype(np.float64)
    counts = _block_counts(values.shape[:2], factor)
    sums = _block_sums(values, factor).astype(np.float64)
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
    counts = _block_sums(observed.astype(np.uint8 if factor < 16 else np.int64), factor)  # exact: <= f² per block
    sums = _block_sums(np.where(observed, depth, 0.0), factor)
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
    # the columns: gathers along the first axis of the transpose are contiguous row copies
    columns = rows.T
    out = columns[c0] * (1 - wc)[:, None]
    out += columns[c1] * wc[:, None]
    return np.ascontiguousarray(out.T)


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
def edge_aware_sweeps(start, image, depth, observed, *, smoothness: float, kappa: float, sweeps: int) -> np.ndarray:
    r"""Red-black Gauss-Seidel sweeps on an image-weighted smoothness model, the observations held fixed.

    Parameters
    ----------
    start : ndarray, shape (H, W)
        The field to refine (e.g. a coarse solution upsampled); also the
        model's prior.
    image : ndarray, shape (H, W, C)
        Floats in [0, 1] (:func:`~sparsedepth._validation.as_float_image`;
        float32 is enough and faster).
    depth, observed : ndarray, shape (H, W)
        Observed values (finite where ``observed``) and where they are.
    smoothness : float
        ``λ >= 0`` below.
    kappa : float
        ``κ >= 0`` of the pair weights below.
    sweeps : int
        Red-black sweeps (``>= 0``; 0 returns ``start`` with the observations
        put back).

    Returns
    -------
    ndarray, shape (H, W), float32

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
    Computed in float32.
    """
    smoothness = check_nonnegative_real(smoothness, name="smoothness")
    kappa = check_nonnegative_real(kappa, name="kappa")
    sweeps = check_nonnegative_count(sweeps, name="sweeps")
    observed = np.asarray(observed, dtype=bool)
    prior = np.asarray(start, dtype=np.float32)
    z = prior.copy()
    np.copyto(z, np.asarray(depth), where=observed, casting="unsafe")  # the samples in float32
    if sweeps == 0 or smoothness == 0:
        return z
    image = np.asarray(image)
    H, W = z.shape
    padded = W + W % 2  # an even width: the last column of an odd-width grid is a fixed pixel without links
    wx = np.zeros((H, padded), dtype=np.float32)  # wx[y, x]: the pair (x, x + 1)
    wy = np.zeros((H, padded), dtype=np.float32)  # wy[y, x]: the pair (y, y + 1)
    across, down = pair_distances(np.asarray(image, dtype=np.float32))
    wx[:, :W - 1] = _pair_weights(across, kappa, smoothness)
    wy[:-1, :W] = _pair_weights(down, kappa, smoothness)
    diagonal = np.ones((H, padded), dtype=np.float32)
    diagonal[:, 1:] += wx[:, :-1]
    diagonal += wx
    diagonal[1:] += wy[:-1]
    diagonal += wy
    inverse = np.reciprocal(diagonal, out=diagonal)
    full = np.zeros((H, padded), dtype=np.float32)
    full[:, :W] = prior
    priors = _split_parity(full)
    full[:, :W] = z
    fields = _split_parity(full)
    free = np.zeros((H, padded), dtype=bool)
    free[:, :W] = ~observed
    frees = _split_parity(free)
    inverses = _split_parity(inverse)
    vertical = _split_parity(wy)
    # each parity of y + x as an (H, padded / 2) array: a half sweep touches only the pixels it updates; the
    # horizontal pair weights are read as views: wx[:, 0::2] (pairs (2k, 2k + 1)) and wx[:, 1::2] ((2k + 1, 2k + 2))
    horizontal = (wx[:, 0::2], wx[:, 1::2])
    for _ in range(int(sweeps)):
        for target in (0, 1):
            _half_sweep(fields[target], fields[1 - target], priors[target], inverses[target], frees[target],
                        horizontal, vertical[1 - target], vertical[target], row_offset=target)
    return _merge_parity(*fields)[:, :W]




def _pair_weights(distance, kappa, smoothness):
    """``smoothness · exp(−κ d)`` in place on the float32 pair distances ``d``."""
    distance *= -kappa
    np.exp(distance, out=distance)
    distance *= smoothness
    return distance


def _split_parity(a):
    """``(even, odd)``: the entries with ``y + x`` even / odd of an even-width ``a``, row by row, ``(H, W / 2)`` each."""
    even = np.empty((a.shape[0], a.shape[1] // 2), dtype=a.dtype)
    odd = np.empty_like(even)
    even[0::2], even[1::2] = a[0::2, 0::2], a[1::2, 1::2]
    odd[0::2], odd[1::2] = a[0::2, 1::2], a[1::2, 0::2]
    return even, odd


def _merge_parity(even, odd):
    """The inverse of :func:`_split_parity`."""
    out = np.empty((even.shape[0], 2 * even.shape[1]), dtype=even.dtype)
    out[0::2, 0::2], out[1::2, 1::2] = even[0::2], even[1::2]
    out[0::2, 1::2], out[1::2, 0::2] = odd[0::2], odd[1::2]
    return out


def _half_sweep(target, other, prior, inverse, free, horizontal, weight_above, weight_below, *, row_offset):
    """Update ``target`` (one parity, in place) from its neighbours in ``other`` (the other parity).

    In the rows where the target's pixels sit at even ``x`` (``y + row_offset`` even), entry ``k`` is at ``x =
    2k``: its left neighbour is ``other[y, k − 1]`` (pair weight ``wx[y, 2k − 1]``) and its right one ``other[y,
    k]`` (``wx[y, 2k]``); in the other rows it is at ``x = 2k + 1``, with neighbours ``other[y, k]`` (``wx[y,
    2k]``) and ``other[y, k + 1]`` (``wx[y, 2k + 1]``).  Above and below are ``other[y ∓ 1, k]``, whose pair
    weights are the vertical weights of the pixel above (``weight_above``, the other parity's) and of the pixel
    itself (``weight_below``).  Computed over bands of rows (``sweep_band_values`` values each,
    :class:`~sparsedepth.limits.MemoryLimits`), so that the partial sums stay in cache; each pixel adds its terms in the same order as a whole-array update.
    """
    pairs_even, pairs_odd = horizontal  # wx[:, 2k] and wx[:, 2k + 1]
    H = target.shape[0]
    band = rows_per_band(target.shape[1], memory_limits().sweep_band_values, multiple=2)  # even: a band's rows keep their parity
    work = np.empty((min(band, H),) + target.shape[1:], dtype=target.dtype)
    term = np.empty_like(work)
    at_even = slice(row_offset, None, 2)  # rows (of a band starting at an even row) whose target pixels have even x
    at_odd = slice(1 - row_offset, None, 2)
    for rows in row_bands(0, H, band):
        y0, y1 = rows.start, rows.stop
        update, t = work[:y1 - y0], term[:y1 - y0]
        np.copyto(update, prior[rows])
        near, odd_pairs, even_pairs = other[rows], pairs_odd[rows], pairs_even[rows]
        np.multiply(odd_pairs[at_even, :-1], near[at_even, :-1], out=t[at_even, :-1])
        update[at_even, 1:] += t[at_even, :-1]
        np.multiply(even_pairs[at_even], near[at_even], out=t[at_even])
        update[at_even] += t[at_even]
        np.multiply(even_pairs[at_odd], near[at_odd], out=t[at_odd])
        update[at_odd] += t[at_odd]
        np.multiply(odd_pairs[at_odd, :-1], near[at_odd, 1:], out=t[at_odd, :-1])
        update[at_odd, :-1] += t[at_odd, :-1]
        lo = max(y0, 1)  # rows y >= 1: + w_above[y − 1] z[y − 1]
        np.multiply(weight_above[lo - 1:y1 - 1], other[lo - 1:y1 - 1], out=t[lo - y0:])
        update[lo - y0:] += t[lo - y0:]
        hi = min(y1, H - 1)  # rows y <= H − 2: + w_below[y] z[y + 1]
        np.multiply(weight_below[y0:hi], other[y0 + 1:hi + 1], out=t[:hi - y0])
        update[:hi - y0] += t[:hi - y0]
        update *= inverse[rows]
        np.copyto(target[rows], update, where=free[rows])
