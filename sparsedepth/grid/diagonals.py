"""A symmetric grid stencil as a SciPy DIA array: one band per neighbour offset.

On an ``(H, W)`` grid flattened in C order, the neighbour ``(dy, dx)`` of
pixel ``i`` is ``i + dy W + dx``, so a stencil operator is a banded matrix
with one diagonal per offset.  :func:`stencil_to_dia` stores those diagonals
as they are (``scipy.sparse.dia_array``): no index arrays to build, and a
product that runs along contiguous bands.  Its products equal those of
:meth:`~sparsedepth.grid.stencil.SymmetricStencil.tocsr` bit for bit: the
same coefficients summed in the same order (increasing offset, which is
increasing column).

May import NumPy, SciPy and :mod:`.stencil`.
"""

from __future__ import annotations

import scipy.sparse as sp

from .stencil import SymmetricStencil

__all__ = ["stencil_to_dia"]


def stencil_to_dia(A: SymmetricStencil) -> sp.dia_array:
    r"""The matrix of a :class:`~sparsedepth.grid.stencil.SymmetricStencil` as a DIA array.

    Parameters
    ----------
    A : SymmetricStencil
        On an ``(H, W)`` grid.

    Returns
    -------
    scipy.sparse.dia_array, shape ``(H W, H W)``, the dtype of ``A``
        One diagonal per flat offset ``k = dy W + dx``, in increasing order.

    Raises
    ------
    TypeError
        If ``A`` is not a SymmetricStencil.

    Notes
    -----
    For a stored offset ``o = (dy, dx) >= (0, 0)`` with image ``S_o``,
    ``A[i, i + k] = S_o[i]`` and, by symmetry, ``A[i + k, i] = S_o[i]``: both
    diagonals are the first ``HW − k`` entries of ``S_o``.  A coefficient
    whose neighbour leaves the grid is 0 in ``S_o``, so a band that runs
    past the end of an image row adds exact zeros.  On grids narrower than
    the stencil (``W <= 2 max |dx|``) two offsets can share a flat offset;
    their bands are added.

    Examples
    --------
    >>> import numpy as np
    >>> A = SymmetricStencil([(0, -1), (0, 0), (0, 1)], [np.array([[2.0, 2.0, 2.0]]), np.array([[-1.0, -1.0, 0.0]])])
    >>> stencil_to_dia(A).toarray()
    array([[ 2., -1.,  0.],
           [-1.,  2., -1.],
           [ 0., -1.,  2.]])
    """
    if not isinstance(A, SymmetricStencil):
        raise TypeError(f"A must be a SymmetricStencil, got {type(A).__name__}")
    H, W = A.grid_shape
    n = H * W
    bands = {}
    for (dy, dx), image in zip(A.upper, A.images):
        k = dy * W + dx
        if k >= n:  # the neighbour is outside every grid row
            continue
        band = image.reshape(-1)[:n - k]
        for offset in ((0,) if k == 0 else (-k, k)):
            bands[offset] = bands[offset] + band if offset in bands else band
    offsets = sorted(bands)
    return sp.diags_array([bands[k] for k in offsets], offsets=offsets, shape=(n, n), dtype=A.dtype)
