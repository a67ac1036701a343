"""Moving between the pixel grid and a grid ``f`` times coarser per side, and edge-aware smoothing sweeps.

The real-time mode (``complete_depth(..., quality="fast")``) solves on a
coarse grid and comes back to the full one with these:

* :func:`block_mean` - the mean of each ``f x f`` block (the coarse image);
* :func:`block_sample_mean` - the mean of the observed values of each block
  and whether it holds any (the coarse samples);
* :func:`upsample_bilinear` - the coarse depth, bilinearly interpolated between
  the block centres;
* :func:`edge_aware_sweeps` - red-black Gauss-Seidel sweeps on an
  image-weighted smoothness model with the observations held.

May import NumPy and :mod:`sparsedepth._validation`.
"""

from __future__ import annotations

import numpy as np

from .._validation import check_count, check_nonnegative_real

__all__ = ["coarse_shape", "block_mean", "block_sample_mean", "upsample_bilinear", "edge_aware_sweeps"]


def coarse_shape(shape, factor: int) -> tuple[int, int]:
    """``(ceil(H / f), ceil(W / f))``: the blocks of the last row and column may be partial."""
    factor = check_count(factor, name="factor")
    return -(-int(shape[0]) // factor), -(-int(shape[1]) // factor)


def _block_sums(values, factor):
    """Sums over each ``f x f`` block (zero-padded on the bottom and right), leading axes ``(h, w)``."""
    H, W = values.shape[:2]
    h, w = coarse_shape((H, W), factor)
    padded = np.zeros((h * factor, w * factor) + values.shape[2:], dtype=values.dtype)
    padded[:H, :W] = values
    rows = padded[0::factor].copy()  # strided adds: faster than a reduction over a middle axis
    for offset in range(1, factor):
        rows += padded[offset::factor]
    out = rows[:, 0::factor].copy()
    for offset in range(1, factor):
        out += rows[:, offset::factor]
    return out


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
    counts = _block_sums(np.ones(values.shape[:2]), factor)
    sums = _block_sums(values, factor).astype(np.float64)
    return sums / (counts if values.ndim == 2 else counts[..., None])


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
    counts = _block_sums(observed.astype(np.float64), factor)
    sums = _block_sums(np.where(observed, depth, 0.0), factor)
    coarse_observed = counts > 0
    return np.where(coarse_observed, sums / np.maximum(counts, 1.0), 0.0), coarse_observed


def _linear_taps(n_fine, n_coarse, factor):
    """Coarse indices ``(i0, i1)`` and weight of ``i1`` for each fine index (block centres as nodes, clamped ends)."""
    position = (np.arange(n_fine) + 0.5) / factor - 0.5
    np.clip(position, 0.0, n_coarse - 1, out=position)
    i0 = np.floor(position).astype(np.intp)
    i1 = np.minimum(i0 + 1, n_coarse - 1)
    return i0, i1, position - i0


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
    r0, r1, wr = _linear_taps(H, coarse.shape[0], factor)
    c0, c1, wc = _linear_taps(W, coarse.shape[1], factor)
    wr = wr.astype(coarse.dtype)[:, None]
    wc = wc.astype(coarse.dtype)
    rows = coarse[r0] * (1 - wr) + coarse[r1] * wr  # (H, w): the coarse rows interpolated
    # the columns: gathers along the first axis of the transpose are contiguous row copies
    columns = rows.T
    out = columns[c0] * (1 - wc)[:, None]
    out += columns[c1] * wc[:, None]
    return np.ascontiguousarray(out.T)


def _pair_weights(first, second, kappa, smoothness):
    """``smoothness · exp(−κ ‖first − second‖)`` over the channel axis, in float32 (a sum over the few channels)."""
    total = np.zeros(first.shape[:2], dtype=np.float32)
    for channel in range(first.shape[2]):
        difference = np.subtract(first[..., channel], second[..., channel], dtype=np.float32)
        total += difference * difference
    np.sqrt(total, out=total)
    total *= -kappa
    np.exp(total, out=total)
    total *= smoothness
    return total


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
    if not (isinstance(sweeps, (int, np.integer)) and not isinstance(sweeps, bool) and sweeps >= 0):
        raise ValueError(f"sweeps must be an integer >= 0, got {sweeps!r}")
    observed = np.asarray(observed, dtype=bool)
    prior = np.asarray(start, dtype=np.float32)
    z = prior.copy()
    z[observed] = np.asarray(depth)[observed]
    if sweeps == 0 or smoothness == 0:
        return z
    image = np.asarray(image)
    wx = _pair_weights(image[:, 1:], image[:, :-1], kappa, smoothness)
    wy = _pair_weights(image[1:], image[:-1], kappa, smoothness)
    diagonal = np.ones(z.shape, dtype=np.float32)
    diagonal[:, 1:] += wx
    diagonal[:, :-1] += wx
    diagonal[1:] += wy
    diagonal[:-1] += wy
    inverse = np.reciprocal(diagonal, out=diagonal)
    parity = np.add.outer(np.arange(z.shape[0]), np.arange(z.shape[1])) % 2 == 0
    halves = (parity & ~observed, ~parity & ~observed)
    update = np.empty_like(z)
    across = np.empty_like(wx)  # wx z of the left / right neighbours
    down = np.empty_like(wy)  # wy z of the neighbours above / below
    for _ in range(int(sweeps)):
        for half in halves:
            np.copyto(update, prior)
            update[:, 1:] += np.multiply(wx, z[:, :-1], out=across)
            update[:, :-1] += np.multiply(wx, z[:, 1:], out=across)
            update[1:] += np.multiply(wy, z[:-1], out=down)
            update[:-1] += np.multiply(wy, z[1:], out=down)
            update *= inverse
            np.copyto(z, update, where=half)
    return z
