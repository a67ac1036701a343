"""The image gradient on the pixel grid and the edge weights built from it.

Every image-gradient quantity of the package is computed here, from one pair of
forward differences (:func:`image_differences`, the rows of
:func:`~sparsedepth.grid.operators.gradient` applied to every channel):

* :func:`image_gradient_magnitude` - ``‖∇I‖`` per pixel;
* :func:`edge_weights` - the reference paper's per-pixel ``exp(−κ ‖∇I‖)``;
* :func:`pair_edge_weights` - one weight per pixel pair (per gradient row)
  (:class:`PairEdgeWeights`: the same, one block at a time on request);
* :func:`second_order_edge_weights` - the weights of the second-difference rows
  (:class:`SecondOrderEdgeWeights`: the same, one block at a time on request);
* :func:`smoothed_image` - the image blurred by a Gaussian before any of the above (``Weights.edge_sigma``).

May import NumPy, :mod:`scipy.ndimage`, :mod:`sparsedepth._validation` and :mod:`.rowbands`.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .._validation import as_float_image, check_grid_shape, check_nonnegative_real
from .rowbands import row_bands, rows_per_band
from ..limits import memory_limits

__all__ = [
    "image_differences",
    "image_gradient_magnitude",
    "edge_weights",
    "pair_distances",
    "pair_edge_weights",
    "PairEdgeWeights",
    "second_order_edge_weights",
    "SecondOrderEdgeWeights",
    "smoothed_image",
]


def smoothed_image(image, sigma: float) -> np.ndarray:
    """The [0, 1]-scaled image blurred by a Gaussian of standard deviation ``sigma`` pixels, channel by channel.

    ``sigma = 0`` returns :func:`~sparsedepth._validation.as_float_image` of
    the image unchanged, so every weight computed from it is bit-identical to
    the weight of the unblurred image.

    Raises
    ------
    ValueError
        If ``sigma`` is not a finite number ``>= 0``, or for a bad image.

    Notes
    -----
    ``scipy.ndimage.gaussian_filter`` with ``sigma`` along the rows and
    columns, 0 along the channels, and mirrored borders (``mode="reflect"``).
    Blurring before differencing makes the edge weights follow object
    boundaries rather than texture and JPEG noise: a two-pixel difference of
    the blurred image is a difference of local means.
    """
    sigma = check_nonnegative_real(sigma, name="edge_sigma")
    img = as_float_image(image)
    if sigma == 0:
        return img
    blurred = ndimage.gaussian_filter(img, sigma=(sigma, sigma, 0.0), mode="reflect")
    return np.clip(blurred, 0.0, 1.0, out=blurred)  # a mean of [0, 1] values, up to rounding


def image_differences(image):
    """Forward differences ``(∂x I, ∂y I)`` of every channel, each of shape ``(H, W, C)``.

    ``image`` is converted to [0, 1] floats first (uint8 ÷ 255, uint16 ÷ 65535,
    see :func:`sparsedepth._validation.as_float_image`); ``∂x I[i, j] =
    I[i, j+1] − I[i, j]`` and ``∂y I[i, j] = I[i+1, j] − I[i, j]``, zero in the
    last column / row, as the rows of :func:`~sparsedepth.grid.operators.gradient`.
    """
    img = as_float_image(image)
    gx = np.zeros_like(img)
    gy = np.zeros_like(img)
    gx[:, :-1] = img[:, 1:] - img[:, :-1]
    gy[:-1, :] = img[1:, :] - img[:-1, :]
    return gx, gy


def image_gradient_magnitude(image) -> np.ndarray:
    """``‖∇I‖ = sqrt(Σ_c (∂x I_c)² + (∂y I_c)²)`` per pixel, shape ``(H, W)``.

    ``image`` is converted to [0, 1] floats first (uint8 ÷ 255, uint16 ÷ 65535);
    the differences are those of :func:`image_differences` (zero in the last
    column / row).
    """
    gx, gy = image_differences(image)
    return np.sqrt(np.sum(gx * gx + gy * gy, axis=2))


def edge_weights(image, kappa: float) -> np.ndarray:
    """The reference paper's edge weight ``w = exp(−κ ‖∇I‖)``, shape ``(H, W)``.

    Raises
    ------
    ValueError
        If ``kappa`` is not a finite number ``>= 0``, or for a bad image.
    """
    kappa = check_nonnegative_real(kappa, name="kappa")
    return np.exp(-kappa * image_gradient_magnitude(image))


def pair_distances(image):
    """``‖I[i, j+1] − I[i, j]‖`` and ``‖I[i+1, j] − I[i, j]‖``, shapes ``(H, W−1)`` and ``(H−1, W)``.

    ``image`` is an already scaled float ``(H, W, C)`` array
    (:func:`~sparsedepth._validation.as_float_image`); the norms are over the
    channels, in the image's precision (float32 stays float32).
    """
    planes = np.moveaxis(image, -1, 0)  # a view: channel c is the same strided slice as image[..., c]
    return _plane_norm(planes[:, :, 1:], planes[:, :, :-1]), _plane_norm(planes[:, 1:], planes[:, :-1])


def pair_edge_weights(image, kappa: float) -> np.ndarray:
    """Per-pair image weights aligned with the rows of :func:`~sparsedepth.grid.operators.gradient`.

    Row ``(i, j)`` of the horizontal block gets ``exp(−κ ‖I[i, j+1] − I[i, j]‖)``
    and row ``(i, j)`` of the vertical block ``exp(−κ ‖I[i+1, j] − I[i, j]‖)``,
    with ``‖·‖`` the Euclidean norm over the channels of the [0, 1]-scaled
    image.  Unlike the reference paper's per-pixel :func:`edge_weights`, a
    horizontal difference is not weakened by a vertical image edge.  The rows
    of the last column / last row (whose differences are zero) get 1.

    Returns
    -------
    ndarray, shape (2*H*W,)

    Raises
    ------
    ValueError
        If ``kappa`` is not a finite number ``>= 0``, or for a bad image.
    """
    kappa = check_nonnegative_real(kappa, name="kappa")
    img = as_float_image(image)
    H, W = img.shape[:2]
    dx, dy = np.zeros((H, W)), np.zeros((H, W))  # the last column / row: no pair, distance 0, weight 1
    dx[:, :-1], dy[:-1] = pair_distances(img)
    return np.exp(-kappa * np.concatenate([dx.ravel(), dy.ravel()]))


class PairEdgeWeights:
    """:func:`pair_edge_weights` of an image given as channel planes, computed a block at a time when read.

    The weights of the horizontal pairs (rows ``0 .. H W − 1``) or of the
    vertical ones (the next ``H W``) are computed on request from the planes,
    which the caller keeps anyway (the local-linear term's image), so the
    ``2 H W`` weights are not held.  A slice within one block
    is that block's part; ``np.asarray(weights)`` and any other index give
    the whole array.  The numbers are those of :func:`pair_edge_weights` of
    the ``(H, W, C)`` image, times ``factor`` when given.

    Parameters
    ----------
    planes : ndarray, shape (C, H, W)
        The [0, 1]-scaled image, one channel per plane (kept by reference).
    kappa : float
        ``κ >= 0``.
    factor : ndarray, shape (2*H*W,), optional
        Multiplies the weights (``Weights.depth_jump``'s pair factors).

    Attributes
    ----------
    shape : tuple of int
        ``(2*H*W,)``.
    ndim : int
    dtype : numpy.dtype
    """

    ndim = 1
    dtype = np.dtype(np.float64)

    def __init__(self, planes, kappa, factor=None):
        self.planes = np.asarray(planes, dtype=np.float64)
        if self.planes.ndim != 3:
            raise ValueError(f"planes must have shape (C, H, W), got {self.planes.shape}")
        self.kappa = check_nonnegative_real(kappa, name="kappa")
        H, W = self.grid_shape = self.planes.shape[1:]
        self.shape = (2 * H * W,)
        self.factor = None if factor is None else np.asarray(factor, dtype=np.float64)
        if self.factor is not None and self.factor.shape != self.shape:
            raise ValueError(f"factor must have shape {self.shape}, got {self.factor.shape}")

    def __len__(self):
        return self.shape[0]

    def _block(self, block):
        """Block 0 (horizontal pairs) or 1 (vertical pairs), flat."""
        H, W = self.grid_shape
        planes = self.planes
        weights = np.zeros((H, W))  # the distances; the last column / row: no pair, distance 0, weight 1
        if block == 0:
            weights[:, :-1] = _plane_norm(planes[:, :, 1:], planes[:, :, :-1])
        else:
            weights[:-1] = _plane_norm(planes[:, 1:], planes[:, :-1])
        weights *= -self.kappa
        np.exp(weights, out=weights)
        weights = weights.ravel()
        if self.factor is not None:
            n = H * W
            weights *= self.factor[block * n:(block + 1) * n]
        return weights

    def __array__(self, dtype=None, copy=None):
        out = np.concatenate([self._block(0), self._block(1)])
        return out if dtype is None else out.astype(dtype, copy=False)

    def __getitem__(self, key):
        n = self.shape[0] // 2
        if isinstance(key, slice) and key.step in (None, 1):
            start, stop, _ = key.indices(self.shape[0])
            if stop > start and start // n == (stop - 1) // n:  # within one block
                block = start // n
                return self._block(block)[start - block * n:stop - block * n]
        return np.asarray(self)[key]

    def __repr__(self):
        return f"PairEdgeWeights(grid_shape={self.grid_shape}, kappa={self.kappa})"




def _plane_norm(first, second):
    """``‖first − second‖`` over the first axis (channel planes), summed channel by channel.

    One channel's difference is formed, squared and added at a time (no ``(C, …)`` temporary, and faster than a
    reduction along the channel axis), over bands of rows (``norm_band_values`` values each,
    :class:`~sparsedepth.limits.MemoryLimits`), so that a band of an interleaved image is read from memory once for all its channels.
    """
    _, h, w = first.shape
    total = np.empty((h, w), dtype=np.result_type(first.dtype, second.dtype))
    band = rows_per_band(w, memory_limits().norm_band_values)
    difference = np.empty((min(band, h), w), dtype=total.dtype)
    for rows in row_bands(0, h, band):
        part, work = total[rows], difference[:rows.stop - rows.start]
        np.subtract(first[0, rows], second[0, rows], out=part)
        part *= part
        for channel in range(1, first.shape[0]):
            np.subtract(first[channel, rows], second[channel, rows], out=work)
            work *= work
            part += work
        np.sqrt(part, out=part)
    return total


def second_order_edge_weights(pair_weights, shape) -> np.ndarray:
    """Row weights for :func:`~sparsedepth.grid.operators.hessian_operator` from pair weights.

    A second-difference row gets the smallest pair weight among the pixel
    pairs it spans: ``∂xx`` at ``(i, j)`` spans ``(i, j−1)–(i, j)`` and
    ``(i, j)–(i, j+1)``; ``∂yy`` likewise vertically; ``∂xy`` at ``(i, j)``
    spans the four sides of the square ``(i, j), (i, j+1), (i+1, j), (i+1, j+1)``.

    Parameters
    ----------
    pair_weights : ndarray, shape (2*H*W,)
        From :func:`pair_edge_weights`.
    shape : tuple of int
        ``(H, W)``.

    Returns
    -------
    ndarray, shape (3*H*W,)
    """
    H, W = check_grid_shape(shape)
    return np.concatenate([_second_order_block(pair_weights, (H, W), b) for b in range(3)])


def _second_order_block(pair_weights, shape, block):
    """Block ``block`` (0: ``∂xx``, 1: ``∂yy``, 2: ``∂xy``) of :func:`second_order_edge_weights`, flat."""
    H, W = shape
    if block == 0:
        wx = np.asarray(pair_weights[: H * W]).reshape(H, W)
        wxx = wx.copy()
        wxx[:, 1:] = np.minimum(wx[:, 1:], wx[:, :-1])
        return wxx.ravel()
    wy = np.asarray(pair_weights[H * W :]).reshape(H, W)
    if block == 1:
        wyy = wy.copy()
        wyy[1:, :] = np.minimum(wy[1:, :], wy[:-1, :])
        return wyy.ravel()
    wx = np.asarray(pair_weights[: H * W]).reshape(H, W)
    wxy = np.minimum(wx, wy)
    wxy[:-1, :] = np.minimum(wxy[:-1, :], wx[1:, :])
    wxy[:, :-1] = np.minimum(wxy[:, :-1], wy[:, 1:])
    return wxy.ravel()


class SecondOrderEdgeWeights:
    """:func:`second_order_edge_weights` of ``pair_weights`` as row weights that are computed when read.

    A term's rows are read a block at a time (``weights[b*H*W:(b+1)*H*W]``, or
    a part of one block): such a slice is computed from the pair weights on
    request, so nothing but the pair weights (which the first-order image term
    keeps anyway) is held.  ``np.asarray(weights)`` and any
    other index give the whole array of :func:`second_order_edge_weights`; the
    numbers are the same either way.

    Parameters
    ----------
    pair_weights : ndarray or PairEdgeWeights, shape (2*H*W,)
        From :func:`pair_edge_weights` (kept by reference, not copied), or a
        :class:`PairEdgeWeights` (read a block at a time).
    shape : tuple of int
        ``(H, W)``.

    Attributes
    ----------
    shape : tuple of int
        ``(3*H*W,)``.
    ndim : int
    dtype : numpy.dtype
    """

    ndim = 1

    def __init__(self, pair_weights, shape):
        self.grid_shape = check_grid_shape(shape)
        n = self.grid_shape[0] * self.grid_shape[1]
        self.pair_weights = pair_weights if isinstance(pair_weights, PairEdgeWeights) else np.asarray(pair_weights)
        if self.pair_weights.shape != (2 * n,):
            raise ValueError(f"pair_weights must have shape ({2 * n},) for a grid of shape {self.grid_shape}, got "
                             f"{self.pair_weights.shape}")
        self.shape = (3 * n,)
        self.dtype = self.pair_weights.dtype

    def __len__(self):
        return self.shape[0]

    def __array__(self, dtype=None, copy=None):
        out = second_order_edge_weights(self.pair_weights, self.grid_shape)
        return out if dtype is None else out.astype(dtype, copy=False)

    def __getitem__(self, key):
        n = self.shape[0] // 3
        if isinstance(key, slice) and key.step in (None, 1):
            start, stop, _ = key.indices(self.shape[0])
            if stop > start and start // n == (stop - 1) // n:  # within one block
                block = start // n
                return _second_order_block(self.pair_weights, self.grid_shape, block)[start - block * n:stop - block * n]
        return np.asarray(self)[key]

    def __repr__(self):
        return f"SecondOrderEdgeWeights(grid_shape={self.grid_shape})"
