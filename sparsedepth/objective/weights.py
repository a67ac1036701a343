"""The weights of the objective terms, as one small immutable object.

May import :mod:`sparsedepth._validation` and :mod:`.robust`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

from .._validation import check_nonnegative_real, check_positive_real, is_real
from .robust import PENALTIES

__all__ = ["Weights", "DEFAULT_WEIGHTS", "DensitySchedule", "DENSITY_FIELDS", "DEFAULT_SCHEDULE", "default_weights",
           "check_weights", "weights_settings", "EDGE_PENALTIES", "EDGE_PENALTY_FIELDS",
           "DEFAULT_EDGE_SCALE", "MODEL_FIELDS"]

#: The penalties of the edge term: ``"l1"`` (``|t|``) or a robust penalty of :mod:`sparsedepth.objective.robust`.
EDGE_PENALTIES = ("l1", *PENALTIES)
#: The fields of :class:`Weights` that choose the edge term's penalty (not term weights: a str and a scale).
EDGE_PENALTY_FIELDS = ("edge_penalty", "edge_scale")
#: The fields of :class:`Weights` that shape the terms instead of weighting them (numbers >= 0, 0 = off).
MODEL_FIELDS = ("edge_sigma", "fill_contrast", "depth_jump", "local_linear_eps")
#: The weights of the local-linear terms, by window shape: 3x3, cross and 2x2 (they share ``local_linear_eps``).
LOCAL_LINEAR_FIELDS = ("beta_local_linear", "beta_local_linear_cross", "beta_local_linear_2x2")
#: Default ``edge_scale`` in depth units (metres): 5 cm.
DEFAULT_EDGE_SCALE = 0.05


@dataclass(frozen=True)
class Weights:
    """Weights of the named terms of the completion objective.

    The objective minimised over ``z >= 0`` is (see :mod:`sparsedepth.objective`)::

        F(z) = alpha       Σ M (z - z_obs)²                 data
             + beta        Σ (∂x z)² + (∂y z)²              smooth
             + gamma       Σ w (|∂x z| + |∂y z|)            edge (L1; or Σ w (φ(∂x z) + φ(∂y z)))
             + delta       Σ (z - z_c)²                     prior (nearest or geodesic fill)
             + beta_image  Σ wx (∂x z)² + wy (∂y z)²        smooth_image (image-weighted L2)
             + beta_second Σ (∂xx z)² + (∂yy z)² + 2 (∂xy z)²   second_order
             + beta_second_image  Σ w2 ⊙ (same rows)        second_order_image
             + beta_local_linear  Σ_w min_(a,b) Σ_(i∈w) (z_i − aᵀI_i − b)² + ε‖a‖²   local_linear
             + beta_local_linear_cross  (the same over cross-shaped windows)    local_linear_cross
             + beta_local_linear_2x2    (the same over 2x2 windows)              local_linear_2x2

    with the per-pixel edge weight ``w = exp(-kappa ‖∇I‖)`` of the reference
    paper, the per-pair weights ``wx = exp(-kappa ‖I[i, j+1] - I[i, j]‖)``,
    ``wy = exp(-kappa ‖I[i+1, j] - I[i, j]‖)``, and ``w2`` the smallest pair
    weight a second-difference row spans (see
    :func:`sparsedepth.grid.edges.second_order_edge_weights`).
    The ``local_linear`` term sums over every 3x3 window ``w`` the cost of the
    best affine fit of depth to the image's colour there (the matting
    Laplacian of Levin et al.; ``ε = local_linear_eps``, see
    :mod:`sparsedepth.grid.affinity`); ``local_linear_cross`` and
    ``local_linear_2x2`` sum it over windows of those shapes, whose normal
    equations have 13 and 9 points instead of 25.
    A weight of 0 removes its term, so "L2 only" or "data only" is a choice of weights.
    With ``edge_penalty`` other than ``"l1"`` the edge term penalises each
    difference by the robust ``φ(t) = s ρ(t/s)`` of that name instead of
    ``|t|`` (``s = edge_scale``; see
    :class:`~sparsedepth.objective.robust.RobustPenalty`), which lets depth
    jump where the image has an edge without the staircase of L1.

    Four fields shape the terms rather than weight them (:data:`MODEL_FIELDS`;
    0 switches each off): ``edge_sigma`` blurs the image before every edge
    weight, ``fill_contrast`` makes ``z_c`` the image-aware (geodesic) fill,
    ``depth_jump`` re-solves once with the smoothness relaxed where the
    first solution jumps, and ``local_linear_eps`` is the ridge weight of the
    ``local_linear`` term's window fits (0: none).

    Parameters
    ----------
    alpha, beta, gamma, delta : float
        Data, first-order L2 smoothness, edge-aware L1 and nearest-neighbour
        prior weights (>= 0).
    kappa : float
        Edge sensitivity of ``w`` (>= 0); ``kappa = 0`` makes ``w = 1``.
    beta_image : float
        Image-weighted first-order L2 smoothness (>= 0); an extension beyond
        the reference paper.
    beta_second : float
        Second-order (thin-plate) smoothness (>= 0); an extension beyond the
        reference paper.
    beta_second_image : float
        Image-weighted second-order smoothness (>= 0): a second difference
        that straddles an image edge costs less, so the surface may bend or
        jump there.  An extension beyond the reference paper.
    beta_local_linear : float
        Weight (>= 0) of the windowed local-linear term: depth may follow any
        affine function of the colour inside each 3x3 window, so it bends and
        jumps with the image but not where the image is flat.  Couples pixels
        up to two apart (a 25-point system).  An extension beyond the
        reference paper.
    beta_local_linear_cross : float
        Weight (>= 0) of the same fit over every cross-shaped window (a
        pixel and its four neighbours), the term ``local_linear_cross``:
        couples pixels at most two apart in city-block distance (a 13-point
        system, like the second-order terms').
    beta_local_linear_2x2 : float
        Weight (>= 0) of the same fit over every 2x2 window, the term
        ``local_linear_2x2`` (a 9-point system).
    edge_penalty : {"l1", "charbonnier", "cauchy", "geman_mcclure", "welsch"}
        The penalty of the edge term (weight ``gamma``): ``"l1"`` (default,
        convex) or a robust penalty, Barron's shape ``a`` = 1, 0, -2, -inf
        (Charbonnier is convex, the others are not and are solved by
        ``solver="irls"``, ``"lbfgsb"`` or ``"adam"`` to a stationary point).
    edge_scale : float
        ``s > 0`` of a robust edge penalty, in depth units (metres by
        default 0.05): differences much smaller than ``s`` are smoothed
        quadratically (cost ``t² / (2s)``), larger ones cost about ``|t|``
        (Charbonnier) or less (a jump).  Scales with the depth like ``gamma``.
        Unused with ``"l1"``.
    edge_sigma : float
        Standard deviation in pixels (>= 0) of the Gaussian blur applied to
        the image before the edge weights ``w``, ``wx``, ``wy``, ``w2`` and
        the geodesic fill's step costs
        (:func:`~sparsedepth.grid.edges.smoothed_image`); 0 uses the image as
        it is.
    fill_contrast : float
        ``λ >= 0`` of the prior's target ``z_c``: 0 makes it the Euclidean
        nearest-neighbour fill; ``λ > 0`` the geodesic fill
        (:func:`~sparsedepth.grid.geodesic.geodesic_fill`), the observation
        reached at the least path cost, a step between neighbours costing
        ``1 + λ ‖I_p − I_q‖``, so ``z_c`` does not leak across image edges.
    depth_jump : float
        ``τ >= 0``, relative depth change at which the image-weighted
        smoothness is halved in a second solve: 0 solves once; ``τ > 0``
        solves, multiplies the pair weights ``wx``, ``wy`` (and so ``w2``) by
        ``1 / (1 + (Δz / (τ z̄))²)`` with ``Δz`` the pair's depth difference
        and ``z̄`` its mean depth in the first solution, and solves again
        from it (about twice the time).  Scale-free (a relative change).
    local_linear_eps : float
        ``ε >= 0`` of the ``local_linear`` term, in squared image units
        ([0, 1]² per channel): the ridge penalty ``ε ‖a‖²`` on each window's
        slope.  Windows whose colour varies much less than ``sqrt(ε / 9)``
        fit a constant (depth smooth there); strongly varying windows let
        depth follow the colour.  0 fits without a ridge (the pseudo-inverse
        of the window's colour covariance).  Shared by the three local-linear
        terms; unused while their weights are all 0.

    Raises
    ------
    ValueError
        If a weight is negative, NaN or infinite, ``edge_penalty`` is not a
        name of :data:`EDGE_PENALTIES`, or ``edge_scale`` is not finite and > 0.
    TypeError
        If ``edge_penalty`` is not a str.

    Notes
    -----
    The defaults are the weights chosen on the tuning frames (``bench/frames.py``
    ``TUNE_FRAMES``, never the frames of the reported tables) by the weight
    search of ``python -m bench.tune`` on RMSE and MAE together
    (``docs/tuning.md`` has its scores and the reference paper's objective
    beside them; ``docs/results.md`` the report frames').  The default
    ``gamma`` is 0, the search's choice: the edge-aware L1 term costs a
    non-smooth solve; set ``gamma > 0`` (in units of depth: it scales linearly
    with depth, unlike the quadratic terms) to use it.  With ``gamma = 0``
    multiplying every weight by one number leaves the solution unchanged
    (the :data:`MODEL_FIELDS` are not weights and stay as they are).  The
    default ``edge_sigma = 1`` and ``fill_contrast = 20`` (blurred-image edge
    weights, geodesic ``z_c``), and the local-linear term
    (``beta_local_linear = 0.01``, ``local_linear_eps = 1e-5``, with
    ``beta_image`` and ``beta_second_image`` the weight search's values times
    a factor chosen with it) were chosen on the tuning frames by
    ``python -m bench.accuracy``; ``docs/accuracy.md`` has their scores on the
    report frames and leave-one-dataset-out.

    These are the constant defaults.  Without ``weights``,
    :func:`~sparsedepth.complete_depth` solves with
    :data:`DEFAULT_SCHEDULE`'s weights for the observed fraction of the
    pixels (:func:`default_weights`): this class's values for every field
    but :data:`DENSITY_FIELDS`, which the schedule sets per density
    (``python -m bench.density``, ``docs/density.md``; the anchor at 50 % observed
    ``python -m bench.scene_disjoint``, ``docs/scene_disjoint.md``).
    """

    # Defaults: the weight set chosen by ``python -m bench.tune`` (docs/tuning.md) on bench/frames.py
    # TUNE_FRAMES at 1/5/10 % observed, never on the frames the reported tables use.
    alpha: float = 1.0
    beta: float = 0.0
    gamma: float = 0.0
    delta: float = 0.000131
    kappa: float = 25.0
    # beta_image and beta_second_image: bench.tune's values times the factor chosen with the local-linear term
    # by ``python -m bench.accuracy`` on TUNE_FRAMES (docs/accuracy.md)
    beta_image: float = 0.002019
    beta_second: float = 0.000286
    beta_second_image: float = 0.0117
    edge_penalty: str = "l1"
    edge_scale: float = DEFAULT_EDGE_SCALE
    # edge_sigma and fill_contrast: the grid point of ``python -m bench.accuracy`` best on TUNE_FRAMES
    # (docs/accuracy.md has its scores on REPORT_FRAMES and leave-one-dataset-out)
    edge_sigma: float = 1.0
    fill_contrast: float = 20.0
    depth_jump: float = 0.0
    # beta_local_linear and local_linear_eps: the grid point of ``python -m bench.accuracy`` best on TUNE_FRAMES
    # (docs/accuracy.md has its scores on REPORT_FRAMES and leave-one-dataset-out)
    beta_local_linear: float = 0.01
    local_linear_eps: float = 1e-5
    beta_local_linear_cross: float = 0.0
    beta_local_linear_2x2: float = 0.0

    def __post_init__(self):
        for f in fields(self):
            if f.name in EDGE_PENALTY_FIELDS:
                continue
            label = f.name if f.name in MODEL_FIELDS else f"weight {f.name}"
            value = check_nonnegative_real(getattr(self, f.name), name=label)
            object.__setattr__(self, f.name, value)
        if not isinstance(self.edge_penalty, str):
            raise TypeError(f"edge_penalty must be a str, one of {list(EDGE_PENALTIES)}; got "
                            f"{type(self.edge_penalty).__name__} {self.edge_penalty!r}")
        if self.edge_penalty not in EDGE_PENALTIES:
            raise ValueError(f"unknown edge_penalty {self.edge_penalty!r}; choose one of {list(EDGE_PENALTIES)}")
        object.__setattr__(self, "edge_scale", check_positive_real(self.edge_scale, name="edge_scale"))

    @property
    def robust_edge(self) -> bool:
        """True when the edge term is present (``gamma > 0``) with a robust penalty (not ``"l1"``)."""
        return self.gamma > 0 and self.edge_penalty != "l1"

    @classmethod
    def paper(cls, alpha=1.0, beta=0.1, gamma=0.01, delta=1e-3, kappa=10.0) -> "Weights":
        """The reference paper's objective: its four terms only, every extension term 0.

        ``Weights(alpha=..., beta=...)`` keeps the *default* extension weights
        for the fields it does not name; this constructor sets them, and the
        :data:`MODEL_FIELDS`, to 0 (the paper's edge weights and nearest fill).  Its
        own defaults are untuned weights for the paper's four terms.

        Examples
        --------
        >>> Weights.paper(gamma=0.0).beta_second_image
        0.0
        """
        return cls(alpha=alpha, beta=beta, gamma=gamma, delta=delta, kappa=kappa,
                   beta_image=0.0, beta_second=0.0, beta_second_image=0.0, beta_local_linear=0.0,
                   edge_sigma=0.0, fill_contrast=0.0, depth_jump=0.0, local_linear_eps=0.0)

    def replace(self, **changes) -> "Weights":
        """A copy with some weights changed (``Weights().replace(gamma=0)``)."""
        return replace(self, **changes)

    def as_dict(self, *, used_only=False) -> dict:
        """``{field: value}``; with ``used_only``, without the fields that do not act on this objective.

        Those are ``edge_penalty`` and ``edge_scale`` for the L1 edge term (it
        has no scale), each local-linear weight at 0 (its term is absent),
        ``local_linear_eps`` while all three are 0, and every
        :data:`MODEL_FIELDS` entry at 0 (switched off); reports and batch fingerprints list only what is used, so a
        field that does not act on the objective neither appears in them nor
        changes them.
        """
        items = asdict(self)
        if used_only and self.edge_penalty == "l1":
            for name in EDGE_PENALTY_FIELDS:
                del items[name]
        if used_only:
            for name in LOCAL_LINEAR_FIELDS:
                if items[name] == 0:
                    del items[name]
            if not any(name in items for name in LOCAL_LINEAR_FIELDS):
                del items["local_linear_eps"]
            for name in MODEL_FIELDS:
                if items.get(name, 1) == 0:
                    del items[name]
        return items


DEFAULT_WEIGHTS = Weights()

def check_weights(weights, *, name: str = "weights") -> None:
    """Raise ``TypeError`` unless ``weights`` is a :class:`sparsedepth.Weights`."""
    if not isinstance(weights, Weights):
        hint = "use sd.Weights(**d)" if isinstance(weights, dict) else "use sd.Weights(alpha=..., gamma=...)"
        raise TypeError(f"{name} must be a sparsedepth.Weights; got {type(weights).__name__}: {hint}")


#: The fields of :class:`Weights` a :class:`DensitySchedule` sets (the others come from its base).
DENSITY_FIELDS = ("delta", "kappa", "beta_image", "beta_second", "beta_second_image", "beta_local_linear",
                  "local_linear_eps")
#: Fields a :class:`DensitySchedule` may also set, at every anchor or at none (then they come from its base).
OPTIONAL_DENSITY_FIELDS = ("beta_local_linear_cross", "beta_local_linear_2x2")


@dataclass(frozen=True)
class DensitySchedule:
    """Weights that depend on the observed fraction of pixels: anchors interpolated in log-density.

    Parameters
    ----------
    anchors : sequence of (float, mapping)
        ``(fraction, {field: value})`` pairs, fractions in (0, 1] strictly
        increasing; each mapping gives every field of :data:`DENSITY_FIELDS`,
        and a field of :data:`OPTIONAL_DENSITY_FIELDS` at every anchor or at
        none.
    base : Weights
        The weights of every other field (default :data:`DEFAULT_WEIGHTS`).

    Raises
    ------
    ValueError
        No anchor, fractions not increasing or outside (0, 1], a missing or
        unknown field, an optional field at some anchors only, or a value
        :class:`Weights` rejects.
    TypeError
        ``base`` not a :class:`Weights` or a fraction not a real number.

    Notes
    -----
    With anchors ``f_0 < f_1 < ... < f_n`` and the observed fraction ``f``
    (observed pixels / all pixels), a field of value ``v_i`` at ``f_i`` gets
    ``v = v_i^(1-t) v_(i+1)^t`` with ``t = log(f / f_i) / log(f_(i+1) / f_i)``
    for ``f_i <= f <= f_(i+1)`` (linear interpolation instead of geometric
    when either value is 0), and the nearest anchor's value outside
    ``[f_0, f_n]``.  The sample density is what the weights have to suit: the
    denser the samples, the more the prior ``z_c`` (the fill between close
    samples) can be trusted and the less the image has to carry.

    Examples
    --------
    >>> schedule = DensitySchedule.from_weights(((0.01, DEFAULT_WEIGHTS.replace(delta=1e-4)),
    ...                                          (0.1, DEFAULT_WEIGHTS.replace(delta=1e-3))))
    >>> round(schedule.weights(0.01 * 10 ** 0.5).delta, 12)
    0.000316227766
    """

    anchors: tuple
    base: Weights = DEFAULT_WEIGHTS

    def __post_init__(self):
        check_weights(self.base, name="base")
        anchors = tuple((check_positive_real(f, name="anchor fraction"), dict(values)) for f, values in self.anchors)
        if not anchors:
            raise ValueError("a DensitySchedule needs at least one anchor")
        fractions = [f for f, _ in anchors]
        if fractions[-1] > 1 or any(b <= a for a, b in zip(fractions, fractions[1:])):
            raise ValueError(f"anchor fractions must increase strictly within (0, 1]; got {fractions}")
        optional = set(anchors[0][1]) & set(OPTIONAL_DENSITY_FIELDS)
        for _, values in anchors:
            if set(values) != set(DENSITY_FIELDS) | optional:
                raise ValueError(f"each anchor gives exactly the fields {list(DENSITY_FIELDS)}, and each of "
                                 f"{list(OPTIONAL_DENSITY_FIELDS)} at every anchor or at none; got {sorted(values)}")
            self.base.replace(**values)  # the values Weights accepts
        object.__setattr__(self, "anchors", anchors)

    @property
    def scheduled(self) -> tuple:
        """The fields this schedule sets per density: :data:`DENSITY_FIELDS` and the optional ones it gives."""
        return DENSITY_FIELDS + tuple(name for name in OPTIONAL_DENSITY_FIELDS if name in self.anchors[0][1])

    def __hash__(self):
        return hash((tuple((f, tuple(sorted(values.items()))) for f, values in self.anchors), self.base))

    @classmethod
    def from_weights(cls, anchors, base: Weights = DEFAULT_WEIGHTS) -> "DensitySchedule":
        """The schedule through ``(fraction, Weights)`` anchors.

        Their :data:`DENSITY_FIELDS` are used, and a field of :data:`OPTIONAL_DENSITY_FIELDS` where some anchor's
        value of it is not 0.
        """
        for _, weights in anchors:
            check_weights(weights, name="anchor weights")
        names = DENSITY_FIELDS + tuple(name for name in OPTIONAL_DENSITY_FIELDS
                                       if any(getattr(w, name) != 0 for _, w in anchors))
        return cls(tuple((f, {name: getattr(w, name) for name in names}) for f, w in anchors), base)

    def weights(self, fraction) -> Weights:
        """The :class:`Weights` for an observed ``fraction`` of the pixels (a real number in (0, 1])."""
        if not is_real(fraction):
            raise TypeError(f"fraction must be a real number; got {type(fraction).__name__}")
        fraction = float(fraction)
        if not 0 < fraction <= 1:
            raise ValueError(f"fraction must be in (0, 1]; got {fraction!r}")
        fractions = [f for f, _ in self.anchors]
        if fraction <= fractions[0] or len(fractions) == 1:
            return self.base.replace(**self.anchors[0][1])
        if fraction >= fractions[-1]:
            return self.base.replace(**self.anchors[-1][1])
        i = max(k for k, f in enumerate(fractions) if f <= fraction)
        (f0, low), (f1, high) = self.anchors[i], self.anchors[i + 1]
        t = math.log(fraction / f0) / math.log(f1 / f0)
        return self.base.replace(**{name: _between(low[name], high[name], t) for name in self.scheduled})

    def replace(self, **changes) -> "DensitySchedule":
        """A copy with some fields fixed at every density.

        A field the schedule sets (:attr:`scheduled`) is set at every anchor
        (it no longer depends on the density); any other field of
        :class:`Weights` is set in ``base``.  ``DEFAULT_SCHEDULE.replace(gamma=0.1)`` keeps the
        schedule and adds the edge term.

        Raises
        ------
        TypeError
            An unknown field (as :meth:`Weights.replace`).
        ValueError
            A value :class:`Weights` rejects.
        """
        scheduled = {name: value for name, value in changes.items() if name in self.scheduled}
        base = self.base.replace(**{name: value for name, value in changes.items() if name not in self.scheduled})
        return DensitySchedule(tuple((f, {**values, **scheduled}) for f, values in self.anchors), base)

    def as_dict(self) -> dict:
        """``{"fraction": {field: value}}`` of the anchors (for reports and fingerprints)."""
        return {f"{f:g}": dict(values) for f, values in self.anchors}


def _between(a: float, b: float, t: float) -> float:
    """Geometric interpolation of two non-negative values (linear when either is 0), ``t`` in [0, 1]; exactly ``a``
    at ``t = 0`` (an anchor's own values at its fraction) and ``b`` at ``t = 1``."""
    if a == b or t <= 0:
        return a
    if t >= 1:
        return b
    if a > 0 and b > 0:
        return math.exp((1 - t) * math.log(a) + t * math.log(b))
    return (1 - t) * a + t * b


#: The schedule the library uses when no weights are given (:func:`default_weights`): the anchors up to 10 %
#: observed chosen on the tuning frames by ``python -m bench.density --local-linear-windows`` (docs/density.md has
#: the search and its scores).  The 50 % anchor, for dense input with holes (a depth sensor's), is the 10 % one
#: with ten times its ``beta_second`` (more thin-plate smoothness across large holes): the configuration that the
#: leave-one-scene-out choice of ``python -m bench.scene_disjoint`` picks for every held-out scene
#: (docs/scene_disjoint.md).  The local-linear term sums its fit over cross-shaped and 2x2 windows (a 13-point
#: normal stencil), not 3x3 windows; the other fields are :data:`DEFAULT_WEIGHTS`'.
DEFAULT_SCHEDULE = DensitySchedule((
    (0.003, dict(delta=1.6375e-05, kappa=25.0, beta_image=0.000252375, beta_second=3.575e-05, beta_second_image=0.0936,
                 beta_local_linear=0.0, local_linear_eps=1.25e-06, beta_local_linear_cross=0.0025,
                 beta_local_linear_2x2=0.02)),
    (0.01, dict(delta=3.275e-05, kappa=50.0, beta_image=0.000252375, beta_second=0.001144, beta_second_image=0.0936,
                beta_local_linear=0.0, local_linear_eps=1.25e-06, beta_local_linear_cross=0.00125,
                beta_local_linear_2x2=0.04)),
    (0.05, dict(delta=0.000524, kappa=100.0, beta_image=0.000252375, beta_second=7.15e-05, beta_second_image=0.0936,
                beta_local_linear=0.0, local_linear_eps=1.25e-06, beta_local_linear_cross=0.00125,
                beta_local_linear_2x2=0.08)),
    (0.10, dict(delta=6.55e-05, kappa=100.0, beta_image=0.004038, beta_second=3.575e-05, beta_second_image=0.0936,
                beta_local_linear=0.0, local_linear_eps=5e-06, beta_local_linear_cross=0.00125,
                beta_local_linear_2x2=0.02)),
    (0.50, dict(delta=6.55e-05, kappa=100.0, beta_image=0.004038, beta_second=3.575e-04, beta_second_image=0.0936,
                beta_local_linear=0.0, local_linear_eps=5e-06, beta_local_linear_cross=0.00125,
                beta_local_linear_2x2=0.02)),
))


def default_weights(fraction) -> Weights:
    """The library's default weights for an observed ``fraction`` of the pixels (:data:`DEFAULT_SCHEDULE`)."""
    return DEFAULT_SCHEDULE.weights(fraction)


def observed_fraction(mask) -> float:
    """The fraction of pixels a boolean ``mask`` marks observed (what a :class:`DensitySchedule` is evaluated at)."""
    count, size = int(mask.sum()), int(mask.size)
    return count / size if size else 0.0


def weights_settings(weights) -> dict:
    """Weights or a schedule as plain data: a :class:`Weights`' used fields, or a schedule's base and anchors.

    ``{"base": ..., "density_schedule": {fraction: {field: value}}}`` for a schedule.  ``None`` stands for
    :data:`DEFAULT_SCHEDULE` as it is now.  The batch settings file stores this (a batch resumed after the
    library's defaults changed is refused as a different setting) and the command line's JSON report shows it.
    """
    if isinstance(weights, Weights):
        return weights.as_dict(used_only=True)
    schedule = DEFAULT_SCHEDULE if weights is None else weights
    return {"base": schedule.base.as_dict(used_only=True), "density_schedule": schedule.as_dict()}


def resolve_weights(weights, fraction) -> Weights:
    """The :class:`Weights` to solve with for an observed ``fraction`` of the pixels.

    Parameters
    ----------
    weights : Weights, DensitySchedule or None
        ``None`` is :data:`DEFAULT_SCHEDULE`; a schedule is evaluated at
        ``fraction``; :class:`Weights` are returned as given.
    fraction : float
        Observed pixels / all pixels.  A fraction of 0 (no observation, an
        error the caller reports) gives the lowest anchor's weights.

    Raises
    ------
    TypeError
        ``weights`` of another type.
    """
    if weights is None:
        weights = DEFAULT_SCHEDULE
    if isinstance(weights, DensitySchedule):
        return weights.weights(fraction) if fraction > 0 else weights.weights(weights.anchors[0][0])
    if not isinstance(weights, Weights):
        hint = "use sd.Weights(**d)" if isinstance(weights, dict) else "use sd.Weights(alpha=..., gamma=...)"
        raise TypeError(f"weights must be a sparsedepth.Weights (or a sparsedepth.DensitySchedule, or None for the "
                        f"density-scheduled defaults); got {type(weights).__name__}: {hint}")
    return weights
