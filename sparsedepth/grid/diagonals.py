"""A grid stencil as a SciPy DIA array: one band per neighbour offset.

On an ``(H, W)`` grid flattened in C order, the neighbour ``(dy, dx)`` of
pixel ``i`` is ``i + dy W + dx``, so a stencil operator is a banded matrix
with one diagonal per offset.  :func:`stencil_to_dia` stores the stencil's
coefficient images as those diagonals (``scipy.sparse.dia_array``): no index
arrays to build, and a product that runs along contiguous bands.  Its
products equal those of :func:`~sparsedepth.grid.stencil.stencil_to_csr` of
the same stencil bit for bit: the same coefficients summed in the same order
(increasing offset, which is increasing column).

May import NumPy, SciPy and :mod:`.stencil`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .stencil import _check_offsets

__all__ = ["stencil_to_dia"]


def stencil_to_dia(offsets, stencil, *, dtype=None) -> sp.dia_array:
    r"""The matrix of a stencil as a DIA array.

    Parameters
    ----------
    offsets : list of tuple of int
        Distinct offsets ``(dy, dx)``, sorted lexicographically.
    stencil : ndarray, shape (len(offsets), H, W), float32 or float64
        ``stencil[k, y, x] = A[y W + x, (y + dy_k) W + (x + dx_k)]``, 0 where
        the neighbour lies outside the grid (as
        :meth:`~sparsedepth.objective.Objective.normal_stencil` gives it).
    dtype : numpy dtype, optional
        Type of the stored bands (default that of ``stencil``; float32 for
        single-precision products).

    Returns
    -------
    scipy.sparse.dia_array, shape ``(H W, H W)``, of ``dtype``
        One diagonal per flat offset ``k = dy W + dx``, in increasing order.

    Raises
    ------
    ValueError
        For unsorted offsets or a stencil of another shape.

    Notes
    -----
    Row ``i`` of the band of offset ``k`` is ``A[i, i + k] = stencil[k, i]``
    (flattened), so the band is the coefficient image itself, the rows whose
    column ``i + k`` falls outside ``[0, HW)`` left out.  A band that runs
    past the end of an image row multiplies the next row's pixels by the
    coefficients of the pixels whose neighbour leaves the grid: exact zeros.
    On grids narrower than the stencil (``W <= 2 max |dx|``) two offsets can
    share a flat offset; their bands are added.

    Examples
    --------
    >>> S = np.array([[[1.0, 1.0]], [[2.0, 2.0]], [[3.0, 3.0]]])  # 1x2 grid
    >>> stencil_to_dia([(0, -1), (0, 0), (0, 1)], S).toarray()
    array([[2., 3.],
           [1., 2.]])
    """
    offsets = _check_offsets(offsets)
    stencil = np.asarray(stencil)
    if stencil.ndim != 3 or stencil.shape[0] != len(offsets):
        raise ValueError(f"stencil must have shape (len(offsets), H, W) = ({len(offsets)}, H, W), got {stencil.shape}")
    H, W = stencil.shape[1:]
    n = H * W
    bands = {}  # flat offset -> the coefficients of rows max(0, -k) .. min(n, n - k) - 1 (diags_array's convention)
    for (dy, dx), image in zip(offsets, stencil):
        k = dy * W + dx
        if abs(k) >= n:  # the neighbour is outside the grid for every pixel
            continue
        band = image.reshape(-1)[max(0, -k):n - max(0, k)]
        bands[k] = bands[k] + band if k in bands else band
    flat = sorted(bands)
    return sp.diags_array([bands[k] for k in flat], offsets=flat, shape=(n, n),
                          dtype=stencil.dtype if dtype is None else dtype)
