"""The completion objective as a sum of named terms.

Every term is data: a weight, a sparse linear operator ``K`` and per-row
weights ``r``.  Two kinds exist:

* :class:`QuadraticTerm`  ``weight · Σ_k r_k ((K z)_k − d_k)²``
* :class:`AbsTerm`        ``weight · Σ_k r_k |(K z)_k|``

:func:`build_objective` assembles the terms of the depth-completion problem
from an image, sparse depth and :class:`~sparsedepth.objective.weights.Weights`; a
variant of the problem ("L2 only", "data only", ...) is a choice of weights,
never a code path of its own.

Smoothing of the L1 term
------------------------
The exact objective uses ``|t|``.  Gradient-based solvers (L-BFGS-B, Adam)
minimise the smoothed objective in which ``|t|`` is replaced by
``sqrt(t² + ε²)``; its gradient is ``t / sqrt(t² + ε²)``.  ``ε`` (in depth
units, metres by default) is :attr:`Objective.l1_smoothing`, default
``DEFAULT_L1_SMOOTHING = 1e-4``.  Every solver reports the *exact* objective.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
import scipy.sparse as sp

from .._validation import as_depth_and_mask, as_float_image, check_same_shape, check_weights
from ..baselines import nearest_fill
from ..grid.operators import StencilOperator, gradient_stencil, hessian_stencil
from ..grid.stencil import stencil_to_csr
from .weights import DEFAULT_WEIGHTS, Weights

__all__ = [
    "QuadraticTerm",
    "AbsTerm",
    "Objective",
    "build_objective",
    "edge_weights",
    "pair_edge_weights",
    "second_order_edge_weights",
    "image_gradient_magnitude",
    "DEFAULT_L1_SMOOTHING",
]

DEFAULT_L1_SMOOTHING = 1e-4


def _apply(operator, z):
    return z if operator is None else operator @ z


def _apply_adjoint(operator, v):
    return v if operator is None else operator.T @ v


@dataclass(frozen=True, eq=False)
class QuadraticTerm:
    """``weight · Σ_k r_k ((K z)_k − d_k)²``.

    Parameters
    ----------
    name : str
        Name used in per-term reports.
    weight : float
        Non-negative scalar weight.
    operator : scipy.sparse matrix or StencilOperator of shape (m, N), or None
        ``K``; ``None`` means the identity (``m = N``).  A
        :class:`~sparsedepth.grid.operators.StencilOperator` is applied matrix-free
        and lets :meth:`Objective.normal_equations` assemble ``KᵀK`` as a
        stencil.
    row_weights : ndarray of shape (m,), or None
        ``r >= 0`` (float, or bool for a 0/1 selection such as the data
        term's observation mask); ``None`` means all ones.
    target : ndarray of shape (m,), or None
        ``d``; ``None`` means zeros.
    """

    name: str
    weight: float
    operator: Optional[object] = None
    row_weights: Optional[np.ndarray] = None
    target: Optional[np.ndarray] = None

    def residual(self, z):
        t = _apply(self.operator, z)
        return t if self.target is None else t - self.target

    def _block_residuals(self, z):
        """``(rows, K_b z − d_b)`` per block: one ``H*W`` work vector for a StencilOperator."""
        K = self.operator
        if not isinstance(K, StencilOperator):
            yield slice(None), self.residual(z)
            return
        n = K.shape[1]
        work = np.empty(n)
        for b in range(len(K.blocks)):
            rows = slice(b * n, (b + 1) * n)
            K.block_matvec(z, b, out=work)
            if self.target is not None:
                work -= self.target[rows]
            yield rows, work

    def value(self, z) -> float:
        if self.weight == 0:
            return 0.0
        total = 0.0
        for rows, res in self._block_residuals(z):
            sq = res * res
            if self.row_weights is not None:
                sq *= self.row_weights[rows]
            total += float(np.sum(sq))
        return float(self.weight * total)

    def gradient(self, z):
        """``2 · weight · Kᵀ (r ⊙ (K z − d))``."""
        if self.weight == 0:
            return np.zeros_like(z)
        if not isinstance(self.operator, StencilOperator):
            res = self.residual(z)
            if self.row_weights is not None:
                res = res * self.row_weights
            return 2.0 * self.weight * _apply_adjoint(self.operator, res)
        grad = np.zeros(self.operator.shape[1])
        for b, (rows, res) in enumerate(self._block_residuals(z)):
            if self.row_weights is not None:
                res *= self.row_weights[rows]
            self.operator.block_rmatvec_add(grad, b, res)
        grad *= 2.0 * self.weight
        return grad

    def normal_matrix(self, n: int) -> sp.csr_matrix:
        """Half the Hessian: ``weight · Kᵀ diag(r) K`` (sparse, ``(n, n)``)."""
        r = np.ones(n if self.operator is None else self.operator.shape[0]) if self.row_weights is None else self.row_weights
        if self.operator is None:
            return sp.diags(self.weight * r, format="csr")
        K = self.operator
        if isinstance(K, StencilOperator):
            offsets = K.offsets()
            stencil = np.zeros((len(offsets),) + K.grid_shape)
            K.add_normal_stencil(stencil, offsets, self.row_weights, self.weight)
            return sp.csr_matrix(stencil_to_csr(offsets, stencil))
        return (K.T @ sp.diags(self.weight * r) @ K).tocsr()

    def normal_rhs(self, n: int):
        """``weight · Kᵀ (r ⊙ d)``: the right-hand side contribution."""
        if self.target is None or self.weight == 0:
            return np.zeros(n)
        d = self.target if self.row_weights is None else self.row_weights * self.target
        return self.weight * _apply_adjoint(self.operator, d)

    def constant(self) -> float:
        """``weight · Σ r d²``: the value at ``K z = 0``."""
        if self.target is None:
            return 0.0
        d2 = self.target**2
        if self.row_weights is not None:
            d2 = d2 * self.row_weights
        return float(self.weight * np.sum(d2))


@dataclass(frozen=True, eq=False)
class AbsTerm:
    """``weight · Σ_k r_k |(K z)_k|`` (weighted L1 of a linear map of ``z``).

    Parameters
    ----------
    name : str
    weight : float
    operator : scipy.sparse matrix or StencilOperator of shape (m, N)
        ``build_objective`` passes the matrix-free
        :func:`~sparsedepth.grid.operators.gradient_stencil`; the L1 solvers
        recognise it (:class:`~sparsedepth.objective.l1.StackedL1`) and apply it by
        slicing.
    row_weights : ndarray of shape (m,) or (N,), or None
        ``r``; shape ``(N,)`` (with ``m`` a multiple of ``N``, e.g. the two
        blocks of the gradient) means the same weights for every block of
        ``N`` rows, stored once (``build_objective`` passes the edge weights
        of the pixels so: half the memory of the stacked ``r``).
    """

    name: str
    weight: float
    operator: object
    row_weights: Optional[np.ndarray] = None

    def __post_init__(self):
        if self.row_weights is not None:
            m, n = self.operator.shape
            size = np.shape(self.row_weights)[0] if np.ndim(self.row_weights) == 1 else -1
            if size != m and not (size == n and n > 0 and m % n == 0):
                raise ValueError(f"row_weights of term {self.name!r} must have shape ({m},) or ({n},) "
                                 f"(shared by the {m // max(n, 1)} blocks), got {np.shape(self.row_weights)}")

    def row_weight_blocks(self) -> int:
        """How many times the stored ``row_weights`` repeat along the rows (1 when of shape (m,))."""
        if self.row_weights is None:
            return 1
        return self.operator.shape[0] // np.shape(self.row_weights)[0]

    def scaled_row_weights(self):
        """``weight · r`` as an array of shape (m,)."""
        m = self.operator.shape[0]
        if self.row_weights is None:
            return np.full(m, float(self.weight))
        return self.weight * np.tile(np.asarray(self.row_weights, dtype=np.float64), self.row_weight_blocks())

    def value(self, z) -> float:
        if self.weight == 0:
            return 0.0
        return float(np.sum(self.scaled_row_weights() * np.abs(self.operator @ z)))

    def smoothed_value(self, z, eps: float) -> float:
        """``weight · Σ r sqrt((K z)² + ε²)``."""
        if self.weight == 0:
            return 0.0
        t = self.operator @ z
        return float(np.sum(self.scaled_row_weights() * np.sqrt(t * t + eps * eps)))

    def smoothed_gradient(self, z, eps: float):
        """``weight · Kᵀ (r ⊙ t / sqrt(t² + ε²))`` with ``t = K z``."""
        if self.weight == 0:
            return np.zeros_like(z)
        t = self.operator @ z
        return self.operator.T @ (self.scaled_row_weights() * t / np.sqrt(t * t + eps * eps))


class Objective:
    """A sum of named quadratic and L1 terms over a flattened ``(H, W)`` grid.

    Parameters
    ----------
    shape : tuple of int
        Grid shape ``(H, W)``; the unknown ``z`` is a vector of ``H*W`` values
        in C order.
    terms : sequence of QuadraticTerm or AbsTerm
        Term names must be unique.
    l1_smoothing : float
        ``ε`` of the smoothed ``|t| ≈ sqrt(t² + ε²)`` used by
        :meth:`smoothed_value_and_gradient`.

    Notes
    -----
    The quadratic part equals ``zᵀ A z − 2 bᵀ z + c`` with ``(A, b, c)`` from
    :meth:`normal_equations`, so for an objective without L1 terms the
    minimiser solves ``A z = b``.
    """

    def __init__(self, shape, terms, *, l1_smoothing: float = DEFAULT_L1_SMOOTHING):
        self.shape = tuple(int(s) for s in shape)
        self.size = self.shape[0] * self.shape[1]
        names = [t.name for t in terms]
        if len(set(names)) != len(names):
            raise ValueError(f"term names must be unique, got {names}")
        if not (np.isfinite(l1_smoothing) and l1_smoothing > 0):
            raise ValueError(f"l1_smoothing must be > 0, got {l1_smoothing!r}")
        self.terms = tuple(terms)
        self.l1_smoothing = float(l1_smoothing)
        self._normal = None

    # -- structure ---------------------------------------------------------
    @property
    def quadratic_terms(self):
        return tuple(t for t in self.terms if isinstance(t, QuadraticTerm) and t.weight > 0)

    @property
    def abs_terms(self):
        return tuple(t for t in self.terms if isinstance(t, AbsTerm) and t.weight > 0)

    @property
    def has_l1(self) -> bool:
        """True when an L1 term has a positive weight (the problem is non-smooth)."""
        return bool(self.abs_terms)

    def term(self, name):
        for t in self.terms:
            if t.name == name:
                return t
        raise KeyError(name)

    # -- values ------------------------------------------------------------
    def term_values(self, z) -> dict:
        """Exact value of every named term at ``z`` (flat or ``(H, W)``)."""
        z = self._flat(z)
        return {t.name: t.value(z) for t in self.terms}

    def value(self, z) -> float:
        """Exact objective ``F(z)`` (with ``|t|``, no smoothing)."""
        return float(sum(self.term_values(z).values()))

    def smoothed_value_and_gradient(self, z, eps: float | None = None):
        """Smoothed objective (``|t| → sqrt(t² + ε²)``) and its gradient.

        Returns
        -------
        value : float
        grad : ndarray of shape (H*W,)
        """
        eps = self.l1_smoothing if eps is None else float(eps)
        z = self._flat(z)
        value = 0.0
        grad = np.zeros(self.size)
        for t in self.quadratic_terms:
            value += t.value(z)
            grad += t.gradient(z)
        for t in self.abs_terms:
            value += t.smoothed_value(z, eps)
            grad += t.smoothed_gradient(z, eps)
        return value, grad

    def l1_subgradient(self, z):
        """Gradient of the quadratic part plus ``Kᵀ(weight·r·sign(K z))`` (a subgradient of F)."""
        z = self._flat(z)
        grad = self.quadratic_gradient(z)
        for t in self.abs_terms:
            grad += t.operator.T @ (t.scaled_row_weights() * np.sign(t.operator @ z))
        return grad

    def quadratic_gradient(self, z):
        z = self._flat(z)
        grad = np.zeros(self.size)
        for t in self.quadratic_terms:
            grad += t.gradient(z)
        return grad

    def normal_equations(self):
        """``(A, b, c)`` with quadratic part ``= zᵀAz − 2bᵀz + c`` (cached).

        For the depth objective ``A = αM + β(∂xᵀ∂x + ∂yᵀ∂y) + δI`` (+ the
        optional terms) and ``b = αM z_obs + δ z_c``.

        Notes
        -----
        ``A`` is assembled as a stencil (:meth:`normal_stencil`: one
        coefficient image per neighbour offset, one whole-array operation per
        pair of taps of each term's operator) and converted once to CSR in
        the full in-grid pattern of :func:`~sparsedepth.grid.stencil.stencil_to_csr`,
        which the multigrid set-up reads back without sparse diagonal
        extraction.  Terms whose operator is a general sparse matrix are
        added as ``K^T diag(r) K`` products.
        """
        if self._normal is None:
            n = self.size
            offsets, stencil, general = self._stencil_parts()
            A = stencil_to_csr(offsets, stencil)
            del stencil
            for t in general:
                A = A + t.normal_matrix(n)
            if general:
                A = sp.csr_array(A)
                A.sum_duplicates()
                A.sort_indices()
            b = np.zeros(n)
            c = 0.0
            for t in self.quadratic_terms:
                b += t.normal_rhs(n)
                c += t.constant()
            self._normal = (A, b, c)
        return self._normal

    def clear_cache(self):
        """Forget the cached :meth:`normal_equations` (it is re-assembled on the next call).

        Solvers that keep only a matrix derived from ``A`` (ADMM's ``2A + ρKᵀK``)
        call this so that ``A`` is not held twice (12 bytes per stored entry:
        5 or 13 entries per pixel for the 5- or 13-point system).
        """
        self._normal = None

    def normal_stencil(self):
        """Stencil of the quadratic part's matrix ``A`` (see :mod:`sparsedepth.grid.stencil`).

        Returns
        -------
        offsets : list of tuple of int
            Neighbour offsets ``(dy, dx)``, sorted.
        stencil : ndarray, shape (len(offsets), H, W)
            ``stencil[k, y, x] = A[y*W + x, (y+dy_k)*W + (x+dx_k)]`` (0 outside the grid).

        Raises
        ------
        ValueError
            If a quadratic term's operator is a general sparse matrix (not a
            :class:`~sparsedepth.grid.operators.StencilOperator`).
        """
        offsets, stencil, general = self._stencil_parts()
        if general:
            raise ValueError(f"terms {[t.name for t in general]} have general sparse operators; no stencil form")
        return offsets, stencil

    def _stencil_parts(self):
        """Stencil of the stencil-form terms, and the list of the other quadratic terms."""
        offsets = {(0, 0)}
        stencil_terms, general = [], []
        for t in self.quadratic_terms:
            if t.operator is None:
                stencil_terms.append(t)
            elif isinstance(t.operator, StencilOperator):
                stencil_terms.append(t)
                offsets.update(t.operator.offsets())
            else:
                general.append(t)
        offsets = sorted(offsets)
        stencil = np.zeros((len(offsets),) + self.shape)
        centre = offsets.index((0, 0))
        for t in stencil_terms:
            if t.operator is None:
                r = 1.0 if t.row_weights is None else np.asarray(t.row_weights).reshape(self.shape)
                stencil[centre] += t.weight * r
            else:
                t.operator.add_normal_stencil(stencil, offsets, t.row_weights, t.weight)
        return offsets, stencil, general

    def _flat(self, z):
        z = np.asarray(z, dtype=np.float64)
        if z.size != self.size:
            raise ValueError(f"z has {z.size} values, the objective expects {self.size} (shape {self.shape})")
        return z.reshape(-1)


def image_gradient_magnitude(image) -> np.ndarray:
    """``‖∇I‖ = sqrt(Σ_c (∂x I_c)² + (∂y I_c)²)`` per pixel, shape ``(H, W)``.

    ``image`` is converted to [0, 1] floats first (uint8 ÷ 255, uint16 ÷ 65535);
    the differences are the forward differences of :mod:`sparsedepth.grid.operators`
    (zero in the last column / row).
    """
    img = as_float_image(image)
    gx = np.zeros_like(img)
    gy = np.zeros_like(img)
    gx[:, :-1] = img[:, 1:] - img[:, :-1]
    gy[:-1, :] = img[1:, :] - img[:-1, :]
    return np.sqrt(np.sum(gx * gx + gy * gy, axis=2))


def edge_weights(image, kappa: float) -> np.ndarray:
    """The reference paper's edge weight ``w = exp(−κ ‖∇I‖)``, shape ``(H, W)``."""
    if not (np.isfinite(kappa) and kappa >= 0):
        raise ValueError(f"kappa must be finite and >= 0, got {kappa!r}")
    return np.exp(-float(kappa) * image_gradient_magnitude(image))


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
    """
    if not (np.isfinite(kappa) and kappa >= 0):
        raise ValueError(f"kappa must be finite and >= 0, got {kappa!r}")
    img = as_float_image(image)
    H, W = img.shape[:2]
    dx = np.zeros((H, W))
    dy = np.zeros((H, W))
    dx[:, :-1] = np.sqrt(np.sum((img[:, 1:] - img[:, :-1]) ** 2, axis=2))
    dy[:-1, :] = np.sqrt(np.sum((img[1:, :] - img[:-1, :]) ** 2, axis=2))
    return np.exp(-float(kappa) * np.concatenate([dx.ravel(), dy.ravel()]))


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
    H, W = shape
    wx = np.asarray(pair_weights[: H * W]).reshape(H, W)
    wy = np.asarray(pair_weights[H * W :]).reshape(H, W)
    wxx = wx.copy()
    wxx[:, 1:] = np.minimum(wx[:, 1:], wx[:, :-1])
    wyy = wy.copy()
    wyy[1:, :] = np.minimum(wy[1:, :], wy[:-1, :])
    wxy = np.minimum(wx, wy)
    wxy[:-1, :] = np.minimum(wxy[:-1, :], wx[1:, :])
    wxy[:, :-1] = np.minimum(wxy[:, :-1], wy[:, 1:])
    return np.concatenate([wxx.ravel(), wyy.ravel(), wxy.ravel()])


def build_objective(
    image,
    sparse_depth,
    mask=None,
    *,
    weights: Weights = DEFAULT_WEIGHTS,
    l1_smoothing: float = DEFAULT_L1_SMOOTHING,
):
    """Assemble the completion objective for one frame.

    Parameters
    ----------
    image : ndarray, (H, W, 3) or (H, W)
        uint8, uint16 or float in [0, 1].
    sparse_depth : ndarray, (H, W)
        Depth (metres) at observed pixels.
    mask : ndarray of bool, (H, W), optional
        True where depth is observed; default: finite and ``> 0``.
    weights : Weights
    l1_smoothing : float
        ``ε`` of the smoothed L1 (see module notes).

    Returns
    -------
    objective : Objective
        Terms ``data``, ``smooth``, ``edge``, ``prior``, ``smooth_image``,
        ``second_order``, ``second_order_image``.
    coarse : ndarray, (H, W)
        ``z_c``, the nearest-neighbour fill of the observations.
    mask : ndarray of bool, (H, W)

    Raises
    ------
    ValueError
        For inconsistent shapes, no observed pixel, NaN/inf in the image,
        negative observed depth, wrong dimensions or bad weights.
    TypeError
        If ``weights`` is not a :class:`~sparsedepth.objective.weights.Weights`.
    """
    check_weights(weights)
    img = as_float_image(image)
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    check_same_shape(img.shape[:2], depth.shape, "image", "sparse_depth")
    shape = depth.shape
    n = depth.size
    coarse = nearest_fill(depth, observed)
    w = edge_weights(img, weights.kappa).ravel() if weights.gamma > 0 else None
    pair = pair_edge_weights(img, weights.kappa) if (weights.beta_image > 0 or weights.beta_second_image > 0) else None
    G = gradient_stencil(shape)
    hessian = hessian_stencil(shape) if (weights.beta_second > 0 or weights.beta_second_image > 0) else None
    w2 = None if weights.beta_second_image == 0 else second_order_edge_weights(pair, shape)
    terms = [
        QuadraticTerm("data", weights.alpha, None, observed.reshape(-1), depth.ravel()),  # bool weights: 1/8 memory
        QuadraticTerm("smooth", weights.beta, G),
        AbsTerm("edge", weights.gamma, G, w),  # one weight per pixel, shared by its x and y edge
        QuadraticTerm("prior", weights.delta, None, None, coarse.ravel()),
        QuadraticTerm("smooth_image", weights.beta_image, G, pair),
        QuadraticTerm("second_order", weights.beta_second, hessian),
        QuadraticTerm("second_order_image", weights.beta_second_image, hessian, w2),
    ]
    quad_smooth = weights.beta > 0 or weights.beta_image > 0 or weights.beta_second > 0 or weights.beta_second_image > 0
    if weights.delta == 0 and (weights.alpha == 0 or not (quad_smooth or weights.gamma > 0)):
        raise ValueError(
            "weights leave the problem without a unique solution: need delta > 0, or alpha > 0 together with a "
            f"smoothness weight (beta, gamma, beta_image or beta_second); got {weights}"
        )
    return Objective(shape, terms, l1_smoothing=l1_smoothing), coarse, observed
