"""The completion objective as a sum of named terms, and its assembly for one frame.

Every term is data (:mod:`sparsedepth.objective.terms`): a weight, a sparse
linear operator ``K`` and per-row weights ``r``.  Three kinds exist:

* :class:`~sparsedepth.objective.terms.QuadraticTerm`  ``weight · Σ_k r_k ((K z)_k − d_k)²``
* :class:`~sparsedepth.objective.terms.AbsTerm`        ``weight · Σ_k r_k |(K z)_k|``
* :class:`~sparsedepth.objective.terms.RobustTerm`     ``weight · Σ_k r_k φ((K z)_k)``, ``φ`` a robust
  penalty (:mod:`sparsedepth.objective.robust`); smooth, and non-convex except Charbonnier

:class:`Objective` is their sum.  :func:`build_objective` assembles the terms of the depth-completion problem
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

The terms and the image edge weights (:mod:`sparsedepth.grid.edges`) are
re-exported here.  May import :mod:`sparsedepth.grid`, the nearest fill of
:mod:`sparsedepth.baselines`, :mod:`sparsedepth.profiling` and :mod:`sparsedepth._validation`.
"""

from __future__ import annotations

import hashlib

import numpy as np
import scipy.sparse as sp

from .._validation import as_depth_and_mask, as_float_image, check_positive_real, check_same_shape
from ..baselines import nearest_fill
from ..grid.affinity import local_linear_operator
from ..grid.edges import (PairEdgeWeights, SecondOrderEdgeWeights, edge_weights, image_gradient_magnitude,
                          pair_edge_weights, second_order_edge_weights, smoothed_image)
from ..grid.geodesic import geodesic_fill
from ..grid.operators import StencilOperator, gradient_stencil, hessian_stencil
from ..grid.stencil import SymmetricStencil, stencil_to_csr
from ..profiling import phase
from .terms import AbsTerm, QuadraticTerm, RobustTerm
from .weights import observed_fraction, resolve_weights

__all__ = [
    "QuadraticTerm",
    "AbsTerm",
    "RobustTerm",
    "Objective",
    "build_objective",
    "sample_fill",
    "edge_weights",
    "pair_edge_weights",
    "second_order_edge_weights",
    "image_gradient_magnitude",
    "DEFAULT_L1_SMOOTHING",
]

DEFAULT_L1_SMOOTHING = 1e-4


def _digest(z) -> bytes:
    """A digest of a contiguous float64 vector's bytes: the key of the values kept for the last point."""
    return hashlib.blake2b(memoryview(z).cast("B"), digest_size=16).digest()


class Objective:
    """A sum of named quadratic, L1 and robust terms over a flattened ``(H, W)`` grid.

    Parameters
    ----------
    shape : tuple of int
        Grid shape ``(H, W)``; the unknown ``z`` is a vector of ``H*W`` values
        in C order.
    terms : sequence of QuadraticTerm, AbsTerm or RobustTerm
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
        self.terms = tuple(terms)
        self.l1_smoothing = check_positive_real(l1_smoothing, name="l1_smoothing")
        self._normal = None
        self._last_values = None  # (digest of z, term values) of the last term_values call
        self._last_system = None  # (digest of z, F) of the last system_value call with A assembled
        #: A preconditioner of :meth:`normal_equations`' ``A`` that a solve left for later solves with ``A`` (the
        #: certificate's): the γ = 0 solvers' multigrid hierarchy; None when none is kept.
        self.preconditioner = None

    # -- structure ---------------------------------------------------------
    @property
    def quadratic_terms(self):
        return tuple(t for t in self.terms if isinstance(t, QuadraticTerm) and t.weight > 0)

    @property
    def abs_terms(self):
        return tuple(t for t in self.terms if isinstance(t, AbsTerm) and t.weight > 0)

    @property
    def robust_terms(self):
        return tuple(t for t in self.terms if isinstance(t, RobustTerm) and t.weight > 0)

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
        """Exact value of every named term at ``z`` (flat or ``(H, W)``).

        The values at the last ``z`` asked for are kept (keyed by a digest of
        its bytes, not a copy): a solver's last record, its certificate and
        :func:`~sparsedepth.complete_depth` may all ask for the same final point.
        """
        z = np.ascontiguousarray(self._flat(z))
        digest = _digest(z)
        if self._last_values is None or self._last_values[0] != digest:
            self._last_values = (digest, {t.name: t.value(z) for t in self.terms})
        return dict(self._last_values[1])

    def value(self, z) -> float:
        """Exact objective ``F(z)`` (with ``|t|``, no smoothing)."""
        return float(sum(self.term_values(z).values()))

    def system_value(self, z):
        """``F(z) = zᵀAz − 2bᵀz + c`` from the cached :meth:`normal_equations` (one product), else None.

        None also when ``F`` has terms other than quadratic ones.  For the quadratic solvers' records and the
        scale of a tolerance; :meth:`value` and :meth:`term_values` sum the terms one by one, which is exact to
        a few units of rounding.  The value at the last ``z`` is kept like :meth:`term_values`' (a PCG's last
        record, its certificate and the gap check ask for the same point).

        Notes
        -----
        Near a minimiser ``F`` is a small difference of large numbers (``c`` and ``2bᵀz − zᵀAz``, each about
        ``F(0)``), so the rounding of ``A``'s entries and of the product is magnified by about ``F(0) / F``,
        and by the size of ``A``'s entries against ``F(0)``.
        """
        if self._normal is None or self.has_l1 or self.robust_terms:
            return None
        z = np.ascontiguousarray(self._flat(z))
        digest = _digest(z)
        if self._last_system is None or self._last_system[0] != digest:
            A, b, c = self._normal
            self._last_system = (digest, float(c - 2.0 * np.dot(b, z) + np.dot(z, A @ z)))
        return self._last_system[1]

    def smoothed_value_and_gradient(self, z, eps: float | None = None):
        """Smoothed objective (``|t| → sqrt(t² + ε²)``) and its gradient.

        Quadratic and robust terms enter exactly (they are smooth).

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
        for t in self.robust_terms:
            value += t.value(z)
            grad += t.gradient(z)
        return value, grad

    def l1_subgradient(self, z):
        """Gradient of the quadratic and robust terms plus ``Kᵀ(weight·r·sign(K z))`` (a subgradient of F)."""
        z = self._flat(z)
        grad = self.quadratic_gradient(z)
        for t in self.abs_terms:
            grad += t.operator.T @ (t.scaled_row_weights() * np.sign(t.operator @ z))
        for t in self.robust_terms:
            grad += t.gradient(z)
        return grad

    def quadratic_gradient(self, z):
        z = self._flat(z)
        grad = np.zeros(self.size)
        for t in self.quadratic_terms:
            grad += t.gradient(z)
        return grad

    def normal_equations(self, *, form="csr", cache=True):
        """``(A, b, c)`` with quadratic part ``= zᵀAz − 2bᵀz + c`` (cached unless ``cache=False``).

        For the depth objective ``A = αM + β(∂xᵀ∂x + ∂yᵀ∂y) + δI`` (+ the
        optional terms) and ``b = αM z_obs + δ z_c``.

        Parameters
        ----------
        form : {"csr", "stencil"}, default "csr"
            ``"csr"``: ``A`` as a scipy.sparse CSR array.  ``"stencil"``: ``A``
            as a :class:`~sparsedepth.grid.stencil.SymmetricStencil` (the
            images of its offsets ``>= (0, 0)`` only: 56 instead of 160 bytes
            per pixel for the 13-point system), for the solves that only
            multiply by ``A`` and precondition it
            (:func:`~sparsedepth.linalg.krylov.pcg`,
            :func:`~sparsedepth.linalg.preconditioners.make_preconditioner`);
            the CSR array instead when it is already cached or when a term's
            operator is a general sparse matrix.
        cache : bool, default True
            False: a triple assembled here is not kept (for a caller that
            needs ``A`` once and holds it no longer than its own use); a
            cached one is still returned.

        Notes
        -----
        ``A`` is assembled as a stencil (:meth:`normal_stencil`: one
        coefficient image per neighbour offset, one whole-array operation per
        pair of taps of each term's operator).  The CSR form is that stencil
        converted once to the full in-grid pattern of
        :func:`~sparsedepth.grid.stencil.stencil_to_csr`, which the multigrid
        set-up reads back without sparse diagonal extraction; terms whose
        operator is a general sparse matrix are added as ``K^T diag(r) K``
        products.  The stencil form is assembled directly as the images of the
        offsets ``>= (0, 0)`` (each term writes only the couplings it stores:
        13 images of the 25-point system, not 25): the same numbers as those
        images of the full stencil.  Every term writes a coupling with the same
        value at its two places (the full stencil is exactly symmetric), so
        both forms multiply a vector bit for bit alike.  One form is cached: asking for ``"csr"`` after
        ``"stencil"`` converts the cached stencil and caches the CSR array
        instead.
        """
        if form not in ("csr", "stencil"):
            raise ValueError(f"form must be 'csr' or 'stencil', got {form!r}")
        if self._normal is not None:
            A, b, c = self._normal
            if form == "csr" and not sp.issparse(A):
                with phase("assembly"):
                    self._normal = (A.tocsr(), b, c)
            return self._normal
        with phase("assembly"):
            n = self.size
            offsets, stencil, general = self._stencil_parts(symmetric=form == "stencil")
            if form == "stencil" and not general:
                A = SymmetricStencil(offsets, stencil)
            else:
                A = stencil_to_csr(offsets, stencil)
            del stencil
            for t in general:
                A = A + t.normal_matrix(n)
            if general:
                A = sp.csr_array(A)
                A.sum_duplicates()
                A.sort_indices()
            normal = (A, self.normal_rhs(), self.constant())
        if cache:
            self._normal = normal
            self._last_system = None
        return normal

    def share_matrix(self, other, diagonal=None) -> None:
        """Take ``other``'s assembled matrix ``A``, plus ``diag(diagonal)``, as this objective's own.

        For an objective whose quadratic part is ``other``'s but for a diagonal term (the data term of another
        set of samples: ``diagonal = α (M_new − M_other)``); the caller vouches for that.  ``b`` and ``c`` are this
        objective's own.  Nothing happens when ``other`` has no assembled system or this one has one already.

        Parameters
        ----------
        other : Objective
            An objective of the same shape whose :meth:`normal_equations` were assembled.
        diagonal : ndarray, (H*W,), optional
            Added to the diagonal of a copy of ``other``'s ``A`` (``other``'s is left as it is).
        """
        if other._normal is None or self._normal is not None:
            return
        if other.shape != self.shape:
            raise ValueError(f"share_matrix needs objectives of one shape; got {other.shape} and {self.shape}")
        with phase("assembly"):
            A = other._normal[0]
            if diagonal is not None:
                A = _plus_diagonal(A, np.asarray(diagonal, dtype=np.float64).reshape(-1))
            self._normal = (A, self.normal_rhs(), self.constant())
            self._last_system = None

    def normal_rhs(self) -> np.ndarray:
        """``b`` of :meth:`normal_equations` (the sum of the quadratic terms' ``weight · Kᵀ(r ⊙ d)``), without
        assembling ``A``."""
        b = np.zeros(self.size)
        for t in self.quadratic_terms:
            b += t.normal_rhs(self.size)
        return b

    def constant(self) -> float:
        """The constant ``c`` of :meth:`normal_equations` (the quadratic part at ``z = 0``), without assembling ``A``.
        """
        if self._normal is not None:
            return self._normal[2]
        c = 0.0
        for t in self.quadratic_terms:
            c += t.constant()
        return c

    def clear_cache(self):
        """Forget the cached :meth:`normal_equations` (it is re-assembled on the next call).

        Solvers that keep only a matrix derived from ``A`` (ADMM's ``2A + ρKᵀK``)
        call this so that ``A`` is not held twice (12 bytes per stored entry:
        5 or 13 entries per pixel for the 5- or 13-point system).
        """
        self._normal = None
        self._last_system = None
        self.preconditioner = None

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
        with phase("assembly"):
            offsets, stencil, general = self._stencil_parts()
        if general:
            raise ValueError(f"terms {[t.name for t in general]} have general sparse operators; no stencil form")
        return offsets, stencil

    def _stencil_parts(self, symmetric=False):
        """Stencil of the stencil-form terms, and the list of the other quadratic terms.

        With ``symmetric`` and no other terms, the stencil holds only the images of the offsets ``>= (0, 0)``
        (the stored half of a :class:`~sparsedepth.grid.stencil.SymmetricStencil`), written directly.
        """
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
        symmetric = symmetric and not general
        stored = [o for o in offsets if o >= (0, 0)] if symmetric else offsets
        stencil = np.zeros((len(stored),) + self.shape)
        centre = stored.index((0, 0))
        for t in stencil_terms:
            if t.operator is None:
                r = 1.0 if t.row_weights is None else np.asarray(t.row_weights).reshape(self.shape)
                stencil[centre] += t.weight * r
            elif symmetric:
                t.operator.add_normal_stencil(stencil, stored, t.row_weights, t.weight, symmetric=True)
            else:
                t.operator.add_normal_stencil(stencil, stored, t.row_weights, t.weight)
        return offsets, stencil, general

    def _flat(self, z):
        z = np.asarray(z, dtype=np.float64)
        if z.size != self.size:
            raise ValueError(f"z has {z.size} values, the objective expects {self.size} (shape {self.shape})")
        return z.reshape(-1)


def _plus_diagonal(A, diagonal):
    """A copy of ``A`` (CSR with every diagonal entry stored, or a SymmetricStencil) plus ``diag(diagonal)``."""
    if isinstance(A, SymmetricStencil):
        images = A.data.copy()
        images[A.upper.index((0, 0))] += diagonal.reshape(A.grid_shape)
        return SymmetricStencil(A.offsets, images)
    A = sp.csr_array(A, copy=True)
    rows = np.repeat(np.arange(A.shape[0], dtype=A.indices.dtype), np.diff(A.indptr))
    on_diagonal = np.flatnonzero(A.indices == rows)
    if on_diagonal.size != A.shape[0]:
        raise ValueError("the matrix does not store every diagonal entry")
    A.data[on_diagonal] += diagonal
    return A


def build_objective(
    image,
    sparse_depth,
    mask=None,
    *,
    weights=None,
    l1_smoothing: float = DEFAULT_L1_SMOOTHING,
    pair_factor=None,
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
    weights : Weights, DensitySchedule or None
        ``None`` (default): :data:`~sparsedepth.objective.weights.DEFAULT_SCHEDULE`'s
        weights for the observed fraction of the pixels; a schedule is
        evaluated there; :class:`Weights` are used as given.
    l1_smoothing : float
        ``ε`` of the smoothed L1 (see module notes).
    pair_factor : ndarray, (2*H*W,), optional
        Factors in [0, 1] multiplying the image pair weights ``wx``, ``wy``
        (rows of :func:`~sparsedepth.grid.edges.pair_edge_weights`) before
        the ``smooth_image`` and ``second_order_image`` terms use them (the
        second solve of ``weights.depth_jump``); default 1.

    Returns
    -------
    objective : Objective
        Terms ``data``, ``smooth``, ``edge``, ``prior``, ``smooth_image``,
        ``second_order``, ``second_order_image``, and ``local_linear`` when
        ``weights.beta_local_linear > 0`` (the windowed affine fit to the
        image blurred by ``weights.edge_sigma`` over 3x3 windows,
        :func:`~sparsedepth.grid.affinity.local_linear_operator`), then
        ``local_linear_cross`` and ``local_linear_2x2`` (the same fit over
        cross-shaped and 2x2 windows) when their weights are > 0; ``edge`` is an
        :class:`AbsTerm` for ``weights.edge_penalty = "l1"``, else a
        :class:`RobustTerm` with that penalty and ``weights.edge_scale``.
    coarse : ndarray, (H, W)
        ``z_c``: the nearest-neighbour fill of the observations, or with
        ``weights.fill_contrast > 0`` their geodesic fill on the image
        blurred by ``weights.edge_sigma``.
    mask : ndarray of bool, (H, W)

    Raises
    ------
    ValueError
        For inconsistent shapes, no observed pixel, NaN/inf in the image,
        negative observed depth, wrong dimensions or bad weights.
    TypeError
        If ``weights`` is not a :class:`~sparsedepth.objective.weights.Weights`,
        a :class:`~sparsedepth.objective.weights.DensitySchedule` or ``None``.
    """
    with phase("image terms"):
        return _build_objective(image, sparse_depth, mask, weights, l1_smoothing, pair_factor)


def _build_objective(image, sparse_depth, mask, weights, l1_smoothing, pair_factor):
    """:func:`build_objective`'s work."""
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    weights = resolve_weights(weights, observed_fraction(observed))
    img = smoothed_image(image, weights.edge_sigma)
    check_same_shape(img.shape[:2], depth.shape, "image", "sparse_depth")
    shape = depth.shape
    coarse = _fill(img, depth, observed, weights)
    w = edge_weights(img, weights.kappa).ravel() if weights.gamma > 0 else None
    # with the local-linear term, the blurred image is kept once, as the channel planes that term reads, and the
    # pair weights are computed from them when read (PairEdgeWeights: the numbers of pair_edge_weights)
    local_linear = [(name, weight, window) for name, weight, window in (
        ("local_linear", weights.beta_local_linear, "3x3"),
        ("local_linear_cross", weights.beta_local_linear_cross, "cross"),
        ("local_linear_2x2", weights.beta_local_linear_2x2, "2x2")) if weight > 0]
    planes = np.ascontiguousarray(np.moveaxis(img, -1, 0)) if local_linear else None
    pair = None
    if weights.beta_image > 0 or weights.beta_second_image > 0:
        pair = pair_edge_weights(img, weights.kappa) if planes is None else PairEdgeWeights(planes, weights.kappa)
    if pair is not None and pair_factor is not None:
        factor = np.asarray(pair_factor, dtype=np.float64)
        if factor.shape != pair.shape or not np.all((factor >= 0) & (factor <= 1)):
            raise ValueError(f"pair_factor must be {pair.shape[0]} values in [0, 1] (one per pixel pair); got shape "
                             f"{factor.shape}")
        pair = pair * factor if planes is None else PairEdgeWeights(planes, weights.kappa, factor)
    G = gradient_stencil(shape)
    hessian = hessian_stencil(shape) if (weights.beta_second > 0 or weights.beta_second_image > 0) else None
    # computed from the pair weights block by block when read: not held beside them
    w2 = None if weights.beta_second_image == 0 else SecondOrderEdgeWeights(pair, shape)
    terms = [
        QuadraticTerm("data", weights.alpha, None, observed.reshape(-1), depth.ravel()),  # bool weights: 1/8 memory
        QuadraticTerm("smooth", weights.beta, G),
        _edge_term(weights, G, w),  # one weight per pixel, shared by its x and y edge
        QuadraticTerm("prior", weights.delta, None, None, coarse.ravel()),
        QuadraticTerm("smooth_image", weights.beta_image, G, pair),
        QuadraticTerm("second_order", weights.beta_second, hessian),
        QuadraticTerm("second_order_image", weights.beta_second_image, hessian, w2),
    ]
    for name, weight, window in local_linear:  # no term at weight 0: the term list stays as without it
        terms.append(QuadraticTerm(name, weight, local_linear_operator(np.moveaxis(planes, 0, -1),
                                                                       weights.local_linear_eps, window=window,
                                                                       copy=False)))
    quad_smooth = (weights.beta > 0 or weights.beta_image > 0 or weights.beta_second > 0
                   or weights.beta_second_image > 0 or bool(local_linear))
    if weights.delta == 0 and (weights.alpha == 0 or not (quad_smooth or weights.gamma > 0)):
        raise ValueError(
            "weights leave the problem without a unique solution: need delta > 0, or alpha > 0 together with a "
            f"smoothness weight (beta, gamma, beta_image, beta_second or a local-linear weight); got {weights}"
        )
    return Objective(shape, terms, l1_smoothing=l1_smoothing), coarse, observed


def sample_fill(image, depth, observed, weights):
    """``z_c`` of :func:`build_objective` for these observations: the geodesic or Euclidean nearest-sample fill.

    With ``weights.fill_contrast > 0`` the geodesic fill on the image blurred by ``weights.edge_sigma``
    (:func:`~sparsedepth.grid.geodesic.geodesic_fill`), else the Euclidean nearest fill.  ``depth`` (H, W) holds
    the observations where ``observed`` is True; ``weights`` are resolved :class:`Weights`.
    """
    return _fill(smoothed_image(image, weights.edge_sigma), depth, observed, weights)


def _fill(blurred, depth, observed, weights):
    """:func:`sample_fill` on the image already blurred."""
    with phase("prior fill"):
        if weights.fill_contrast > 0:
            return geodesic_fill(blurred, depth, observed, contrast=weights.fill_contrast)
        return nearest_fill(depth, observed)


def _edge_term(weights, G, w):
    """The ``edge`` term: L1 of ``G z`` weighted by ``w``, or the robust penalty of ``weights.edge_penalty``."""
    if weights.edge_penalty == "l1":
        return AbsTerm("edge", weights.gamma, G, w)
    return RobustTerm("edge", weights.gamma, G, w, weights.edge_penalty, weights.edge_scale)
