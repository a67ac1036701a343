r"""Robust penalties of depth differences: Barron's general loss with a scale in depth units.

A penalty is data (:class:`RobustPenalty`: a name and Barron's shape ``a``)
with three functions of a difference ``t`` and a scale ``s > 0``:
:meth:`~RobustPenalty.value` ``φ(t)``, :meth:`~RobustPenalty.derivative`
``φ'(t)`` and :meth:`~RobustPenalty.weight` ``ω(t) = φ'(t) / t``, the weight
of the quadratic majoriser that iteratively reweighted least squares
minimises.  :data:`PENALTIES` names the members of the family;
:func:`robust_penalty` turns a name or a shape into a penalty.

May import NumPy and :mod:`sparsedepth._validation`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validation import is_real

__all__ = ["RobustPenalty", "PENALTIES", "robust_penalty"]

#: The named members of the family: name → Barron's shape ``a``.
PENALTIES = {
    "charbonnier": 1.0,
    "cauchy": 0.0,
    "geman_mcclure": -2.0,
    "welsch": -np.inf,
}


@dataclass(frozen=True)
class RobustPenalty:
    r"""Barron's general robust loss ``φ(t) = s ρ(t / s; a)``, in the units of ``t``.

    Parameters
    ----------
    shape : float
        Barron's ``a <= 2`` (``-inf`` allowed): 2 is quadratic, 1
        Charbonnier, 0 Cauchy, -2 Geman–McClure, ``-inf`` Welsch.  The
        smaller ``a``, the less a large difference costs.
    name : str
        A label for messages: the member's name in :data:`PENALTIES`, else
        ``"barron(a)"``.

    Notes
    -----
    With ``x = t / s`` and Barron's loss at scale 1,

    .. math::

        \rho(x; a) = \frac{|a - 2|}{a}
                     \left[\left(\frac{x^2}{|a - 2|} + 1\right)^{a/2} - 1\right],

    and its limits :math:`\rho(x; 2) = x^2/2`, :math:`\rho(x; 0) = \log(1 +
    x^2/2)`, :math:`\rho(x; -\infty) = 1 - e^{-x^2/2}`; :math:`\rho(x; 1) =
    \sqrt{x^2 + 1} - 1` (Charbonnier) and :math:`\rho(x; -2) = 2x^2/(x^2 +
    4)` (Geman–McClure).  Every member is :math:`x^2/2 + O(x^4)` near 0, so
    :math:`\varphi(t) = s\,\rho(t/s) \approx t^2 / (2s)` for :math:`|t| \ll
    s`, and Charbonnier is :math:`\varphi(t) \approx |t| - s` for
    :math:`|t| \gg s`: a penalty weight plays the role of the L1 weight γ.
    The derivative and the majoriser weight are

    .. math::

        \varphi'(t) = t\,\omega(t), \qquad
        \omega(t) = \frac{1}{s}\left(\frac{(t/s)^2}{|a - 2|} + 1\right)^{a/2 - 1}

    (:math:`e^{-(t/s)^2/2}/s` for Welsch), finite at :math:`t = 0`
    (:math:`1/s`).  For :math:`a \le 2`, :math:`\varphi` is a concave
    function :math:`g` of :math:`u = t^2` (:math:`g'(u) = \omega/2` does not
    increase with :math:`u`), so its tangent at :math:`t_0^2` lies above it:

    .. math::

        \varphi(t) \le \varphi(t_0) + \tfrac12\,\omega(t_0)\,(t^2 - t_0^2)
        \quad \text{for all } t, t_0,

    with equality at :math:`t = \pm t_0`: the quadratic majoriser of
    iteratively reweighted least squares.

    References
    ----------
    J. T. Barron, "A General and Adaptive Robust Loss Function", CVPR 2019.

    Examples
    --------
    >>> p = robust_penalty("cauchy")
    >>> float(p.value(0.1, 0.1))  # s log(1 + 1/2)
    0.04054651081081644
    >>> float(p.weight(0.0, 0.1))
    10.0
    """

    shape: float
    name: str = ""

    def __post_init__(self):
        a = float(self.shape)
        if np.isnan(a) or a > 2:
            raise ValueError(f"the shape a of a robust penalty must be <= 2 (or -inf), got {self.shape!r}")
        object.__setattr__(self, "shape", a)
        if not self.name:
            object.__setattr__(self, "name", f"barron({a:g})")

    def rho(self, x):
        """Barron's ``ρ(x; a)`` at scale 1 (an array of the shape of ``x``)."""
        x = np.asarray(x, dtype=np.float64)
        a = self.shape
        x2 = x * x
        if a == 2.0:
            return 0.5 * x2
        if a == 1.0:
            return np.hypot(x, 1.0) - 1.0
        if a == 0.0:
            return np.log1p(0.5 * x2)
        if a == -2.0:
            return 2.0 * x2 / (x2 + 4.0)
        if a == -np.inf:
            return -np.expm1(-0.5 * x2)
        b = abs(a - 2.0)
        return (b / a) * np.expm1(0.5 * a * np.log1p(x2 / b))

    def rho_weight(self, x):
        """``ρ'(x) / x`` at scale 1 (its limit 1 at ``x = 0``)."""
        x = np.asarray(x, dtype=np.float64)
        a = self.shape
        x2 = x * x
        if a == 2.0:
            return np.ones_like(x2)
        if a == 1.0:
            return 1.0 / np.sqrt(x2 + 1.0)
        if a == 0.0:
            return 1.0 / (0.5 * x2 + 1.0)
        if a == -2.0:
            return 16.0 / (x2 + 4.0) ** 2
        if a == -np.inf:
            return np.exp(-0.5 * x2)
        return np.exp((0.5 * a - 1.0) * np.log1p(x2 / abs(a - 2.0)))

    def value(self, t, scale):
        """``φ(t) = s ρ(t / s)``."""
        s = float(scale)
        return s * self.rho(np.asarray(t, dtype=np.float64) / s)

    def weight(self, t, scale):
        """``ω(t) = φ'(t) / t`` (``1 / s`` at ``t = 0``)."""
        s = float(scale)
        return self.rho_weight(np.asarray(t, dtype=np.float64) / s) / s

    def derivative(self, t, scale):
        """``φ'(t) = t ω(t)``."""
        t = np.asarray(t, dtype=np.float64)
        return t * self.weight(t, scale)


def robust_penalty(penalty) -> RobustPenalty:
    """The :class:`RobustPenalty` of a name in :data:`PENALTIES`, a shape ``a <= 2``, or a penalty itself.

    Raises
    ------
    ValueError
        For an unknown name (the message lists the names) or a shape above 2 or NaN.
    TypeError
        For anything else.
    """
    if isinstance(penalty, RobustPenalty):
        return penalty
    if isinstance(penalty, str):
        if penalty not in PENALTIES:
            raise ValueError(f"unknown robust penalty {penalty!r}; choose one of {sorted(PENALTIES)} "
                             "or give Barron's shape a <= 2 as a number")
        return RobustPenalty(PENALTIES[penalty], penalty)
    if is_real(penalty):
        return RobustPenalty(float(penalty))
    raise TypeError(f"penalty must be a name in {sorted(PENALTIES)} or a number a <= 2; got "
                    f"{type(penalty).__name__} {penalty!r}")
