"""Sparse finite-difference operators on an image grid.

Pixels are flattened in C order (row-major): pixel ``(i, j)`` of an ``(H, W)``
grid has index ``i * W + j``.  Every operator is a ``scipy.sparse`` CSR matrix
built by vectorised index arithmetic and cached per grid shape, so building the
same operator twice costs nothing.

Boundary convention (Neumann): a forward difference is zero in the last column
(horizontal) or the last row (vertical); the operators keep one row per pixel so
that the row of pixel ``(i, j)`` of ``forward_diff(shape, axis=1)`` is
``z[i, j+1] - z[i, j]`` (``0`` when ``j = W - 1``).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.sparse as sp

__all__ = [
    "forward_diff",
    "gradient",
    "second_diff",
    "mixed_diff",
    "hessian_operator",
]


def _check_shape(shape):
    shape = tuple(int(s) for s in shape)
    if len(shape) != 2 or min(shape) < 1:
        raise ValueError(f"shape must be (H, W) with H, W >= 1, got {shape}")
    return shape


@lru_cache(maxsize=16)
def _forward_diff_1d(n: int) -> sp.csr_matrix:
    """``(n, n)`` forward difference with a zero last row."""
    main = -np.ones(n)
    main[-1] = 0.0
    upper = np.ones(n - 1)
    return sp.diags([main, upper], [0, 1], shape=(n, n), format="csr")


@lru_cache(maxsize=16)
def _forward_diff_cached(shape: tuple[int, int], axis: int) -> sp.csr_matrix:
    H, W = shape
    if axis == 1:
        op = sp.kron(sp.identity(H, format="csr"), _forward_diff_1d(W), format="csr")
    else:
        op = sp.kron(_forward_diff_1d(H), sp.identity(W, format="csr"), format="csr")
    op.eliminate_zeros()
    op.sort_indices()
    return op


def forward_diff(shape, axis: int) -> sp.csr_matrix:
    """Forward difference along one axis of an ``(H, W)`` grid.

    Parameters
    ----------
    shape : tuple of int
        Grid shape ``(H, W)``.
    axis : {0, 1}
        ``1`` for the horizontal difference ``∂x z[i, j] = z[i, j+1] - z[i, j]``,
        ``0`` for the vertical difference ``∂y z[i, j] = z[i+1, j] - z[i, j]``.

    Returns
    -------
    scipy.sparse.csr_matrix
        ``(H*W, H*W)`` operator; rows of the last column (axis 1) or last row
        (axis 0) are zero (Neumann boundary).

    Examples
    --------
    >>> z = np.arange(6.0).reshape(2, 3)
    >>> (forward_diff((2, 3), axis=1) @ z.ravel()).reshape(2, 3)
    array([[1., 1., 0.],
           [1., 1., 0.]])
    """
    shape = _check_shape(shape)
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 or 1, got {axis!r}")
    return _forward_diff_cached(shape, axis)


@lru_cache(maxsize=16)
def _gradient_cached(shape):
    return sp.vstack([_forward_diff_cached(shape, 1), _forward_diff_cached(shape, 0)], format="csr")


def gradient(shape) -> sp.csr_matrix:
    """Stacked gradient ``[∂x; ∂y]`` of an ``(H, W)`` grid, shape ``(2*H*W, H*W)``.

    The first ``H*W`` rows are the horizontal differences, the last ``H*W`` the
    vertical ones (see :func:`forward_diff`).
    """
    return _gradient_cached(_check_shape(shape))


@lru_cache(maxsize=16)
def _second_diff_1d(n: int) -> sp.csr_matrix:
    """``(n, n)`` central second difference, zero in the first and last row."""
    if n < 3:
        return sp.csr_matrix((n, n))
    lower = np.ones(n - 1)
    main = -2.0 * np.ones(n)
    upper = np.ones(n - 1)
    lower[-1] = 0.0  # row n-1 is zero
    main[[0, -1]] = 0.0
    upper[0] = 0.0  # row 0 is zero
    op = sp.diags([lower, main, upper], [-1, 0, 1], shape=(n, n), format="csr")
    op.eliminate_zeros()
    return op


@lru_cache(maxsize=16)
def _second_diff_cached(shape, axis):
    H, W = shape
    if axis == 1:
        return sp.kron(sp.identity(H, format="csr"), _second_diff_1d(W), format="csr")
    return sp.kron(_second_diff_1d(H), sp.identity(W, format="csr"), format="csr")


def second_diff(shape, axis: int) -> sp.csr_matrix:
    """Central second difference along one axis, zero on the first/last line.

    Row of pixel ``(i, j)`` for ``axis=1``: ``z[i, j-1] - 2 z[i, j] + z[i, j+1]``
    for ``0 < j < W-1`` and ``0`` on the first and last column.
    """
    shape = _check_shape(shape)
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 or 1, got {axis!r}")
    return _second_diff_cached(shape, axis)


@lru_cache(maxsize=16)
def _mixed_diff_cached(shape):
    op = (_forward_diff_cached(shape, 0) @ _forward_diff_cached(shape, 1)).tocsr()
    op.eliminate_zeros()
    return op


def mixed_diff(shape) -> sp.csr_matrix:
    """Mixed difference ``∂y ∂x z``: ``z[i+1,j+1] - z[i+1,j] - z[i,j+1] + z[i,j]``.

    Zero in the last row and the last column.
    """
    return _mixed_diff_cached(_check_shape(shape))


@lru_cache(maxsize=16)
def _hessian_cached(shape):
    return sp.vstack(
        [_second_diff_cached(shape, 1), _second_diff_cached(shape, 0), np.sqrt(2.0) * _mixed_diff_cached(shape)],
        format="csr",
    )


def hessian_operator(shape) -> sp.csr_matrix:
    """Stacked second derivatives ``[∂xx; ∂yy; √2 ∂xy]``, shape ``(3*H*W, H*W)``.

    ``‖hessian_operator(shape) @ z‖²`` is the discrete thin-plate (Frobenius
    norm of the Hessian) energy; it vanishes exactly on affine ramps
    ``z = a + b*i + c*j``.
    """
    return _hessian_cached(_check_shape(shape))
