"""The options of every solver: one frozen, keyword-only dataclass per solver.

Each class's fields are the solver's option keys with their defaults
(``None``: computed from the problem, see the solver's docstring).  An
instance checks and converts its values when it is made; ``from_mapping``
builds one from the ``options`` dict of :func:`sparsedepth.complete_depth`
and rejects unknown keys.  The messages name ``options['key']`` and the
solver, as the user wrote them.

May import :mod:`sparsedepth._validation`; nothing else of the package.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, fields
from typing import ClassVar

import numpy as np

from .._validation import is_int, is_real

__all__ = ["DEFAULT_GAP_TOL", "SolverOptions", "DirectOptions", "CgOptions", "AmgOptions", "IrlsOptions", "AdmmOptions",
           "LbfgsbOptions", "AdamOptions"]

#: Every solver's default ``gap_tol``: a result is ``converged`` when the duality gap of its depth is at most this
#: fraction of its objective (with the floor of :func:`~sparsedepth.solvers.common.gap_threshold`).
DEFAULT_GAP_TOL = 1e-2

#: The preconditioner choices of the PCG solves.
_PRECONDITIONERS = ("grid", "amg")
_POLISH_PRECONDITIONERS = ("jacobi", "amg")


def _option(default, *, kind=None, positive=False, minimum=1, choices=None, depth_unit=False):
    """A dataclass field with its checking rule.

    ``kind`` defaults to the type of ``default`` (give it for ``None``
    defaults); floats must be finite and ``>= 0`` (``> 0`` when
    ``positive``), ints ``>= minimum``, strings one of ``choices``.
    ``depth_unit`` options are divided by the depth scale with the depth.
    """
    rule = dict(kind=type(default) if kind is None else kind, positive=positive, minimum=minimum, choices=choices,
                depth_unit=depth_unit)
    return field(default=default, metadata=rule)


def _checked(solver, key, value, rule, default):
    """``value`` of ``options[key]`` converted to the option's type; TypeError / ValueError otherwise."""
    kind = rule["kind"]
    if default is None and value is None:
        return None
    where = f"options[{key!r}] of solver {solver!r}"
    if kind is bool:
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{where} must be True or False; got {type(value).__name__} {value!r}")
        return bool(value)
    if kind is int:
        if not is_int(value):
            raise TypeError(f"{where} must be an int; got {type(value).__name__} {value!r}: "
                            f"pass e.g. {key}={int(value) if is_real(value) and np.isfinite(value) else default}")
        if value < rule["minimum"]:
            raise ValueError(f"{where} must be >= {rule['minimum']}; got {value}")
        return int(value)
    if kind is float:
        if not is_real(value):
            raise TypeError(f"{where} must be a number; got {type(value).__name__} {value!r}")
        value = float(value)
        positive = rule["positive"]
        if not (np.isfinite(value) and (value > 0 if positive else value >= 0)):
            raise ValueError(f"{where} must be finite and {'>' if positive else '>='} 0; got {value!r}")
        return value
    if not isinstance(value, str) or value not in rule["choices"]:
        raise ValueError(f"{where} must be one of {list(rule['choices'])}; got {value!r}")
    return value


@dataclass(frozen=True, kw_only=True)
class SolverOptions:
    """Base of the solvers' options classes; ``solver`` is the name the subclass belongs to."""

    solver: ClassVar[str] = ""

    def __post_init__(self):
        for f in fields(self):
            object.__setattr__(self, f.name, _checked(self.solver, f.name, getattr(self, f.name), f.metadata,
                                                      f.default))

    @classmethod
    def from_mapping(cls, options):
        """The options of ``cls.solver`` from a dict of some of its keys (None: every default).

        An instance of ``cls`` is returned as it is.

        Raises
        ------
        ValueError
            For an unknown key (the message lists the valid keys with their
            defaults) or a value out of range.
        TypeError
            When ``options`` is not a dict or an instance of ``cls``, or a
            value has the wrong type.
        """
        if options is None:
            return cls()
        if isinstance(options, cls):
            return options
        if isinstance(options, SolverOptions):
            raise TypeError(f"options has type {type(options).__name__}, the options of solver {options.solver!r}; "
                            f"solver {cls.solver!r} takes a dict or a sparsedepth.solvers.{cls.__name__}")
        if not isinstance(options, dict):
            raise TypeError(f"options must be a dict; got {type(options).__name__}: pass e.g. options=dict(...) "
                            f"or sparsedepth.solvers.{cls.__name__}(...)")
        valid = cls.defaults()
        unknown = [key for key in options if key not in valid]
        if unknown:
            listing = ", ".join(f"{k}={v!r}" for k, v in valid.items()) if valid else "none"
            raise ValueError(f"unknown option {unknown[0]!r} for solver {cls.solver!r}; valid options (default): "
                             f"{listing}")
        return cls(**options)

    @classmethod
    def defaults(cls) -> dict:
        """``{key: default}`` in the order of the fields."""
        return {f.name: f.default for f in fields(cls)}

    def as_dict(self) -> dict:
        """``{key: value}`` in the order of the fields."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def in_depth_units(self, scale):
        """A copy with the options in depth units divided by ``scale``.

        The depth-unit options are ``eps_start``, ``eps_min``, ``scale`` (IRLS),
        ``learning_rate`` (Adam) and ``depth_atol`` (cg, amg); ``None`` stays ``None``.
        """
        scaled = copy.copy(self)
        for f in fields(self):
            value = getattr(self, f.name)
            if f.metadata["depth_unit"] and value is not None:
                object.__setattr__(scaled, f.name, value / scale)
        return scaled


@dataclass(frozen=True, kw_only=True)
class DirectOptions(SolverOptions):
    """Options of the ``direct`` solver (sparse LU).

    Parameters
    ----------
    gap_tol : float, default 1e-2 (:data:`DEFAULT_GAP_TOL`)
        ``converged`` needs the duality gap of the returned depth ``<= gap_tol · max(F, 1e-7 F(0))``.
    """

    solver: ClassVar[str] = "direct"
    gap_tol: float = _option(DEFAULT_GAP_TOL)


@dataclass(frozen=True, kw_only=True)
class CgOptions(SolverOptions):
    """Options of the ``cg`` solver (Jacobi-preconditioned CG).

    Parameters
    ----------
    gap_tol, depth_rtol, depth_atol : float, optional
        As for :class:`AmgOptions`; :func:`sparsedepth.complete_depth` sets
        no depth tolerance for ``cg`` by itself.
    """

    solver: ClassVar[str] = "cg"
    gap_tol: float = _option(DEFAULT_GAP_TOL)
    depth_rtol: float | None = _option(None, kind=float, positive=True)
    depth_atol: float | None = _option(None, kind=float, positive=True, depth_unit=True)


@dataclass(frozen=True, kw_only=True)
class AmgOptions(SolverOptions):
    """Options of the ``amg`` solver (CG preconditioned by a multigrid V-cycle).

    Parameters
    ----------
    preconditioner : {"grid", "amg"}, default "grid"
        ``"grid"``: geometric :class:`~sparsedepth.linalg.multigrid.GridMultigrid`
        built once for ``A``; ``"amg"``: pyamg Ruge–Stüben.
    gap_tol : float, default 1e-2 (:data:`DEFAULT_GAP_TOL`)
        ``converged`` needs the duality gap of the returned depth ``<= gap_tol · max(F, 1e-7 F(0))``.
        The stopping rule that ended the solve (residual or depth change)
        is named in the result's ``message``; the gap is computed after it
        (:func:`~sparsedepth.solvers.core.certify`).
    depth_rtol : float, optional
        Stop when the estimated remaining change of the depth (root mean
        square over the pixels of ``z_k − z*``) is at most ``depth_rtol ·
        s``, ``s`` the depth scale of the solve (the power of two nearest the
        median observed depth, :func:`~sparsedepth.solvers.depth_unit`).
        :func:`sparsedepth.complete_depth` sets it to
        :data:`~sparsedepth.solvers.quadratic.DEFAULT_DEPTH_RTOL` (3e-4)
        when neither ``tol`` nor a depth tolerance is given.
    depth_atol : float, optional
        The same stop at an estimated remaining change of at most
        ``depth_atol`` (depth units).  With both, the larger tolerance
        counts; with neither (default), only the residual rule ``tol``.
    """

    solver: ClassVar[str] = "amg"
    preconditioner: str = _option("grid", choices=_PRECONDITIONERS)
    gap_tol: float = _option(DEFAULT_GAP_TOL)
    depth_rtol: float | None = _option(None, kind=float, positive=True)
    depth_atol: float | None = _option(None, kind=float, positive=True, depth_unit=True)


@dataclass(frozen=True, kw_only=True)
class IrlsOptions(SolverOptions):
    """Options of the ``irls`` solver (:func:`~sparsedepth.solvers.irls.solve_irls`).

    Parameters
    ----------
    gap_tol : float, default 1e-2 (:data:`DEFAULT_GAP_TOL`)
        ``converged`` needs the duality gap of the returned depth ``<= gap_tol · max(F, 1e-7 F(0))``.
    target_gap : float, default 1e-4
        The relative duality gap the solver works to: the smaller of it and
        ``gap_tol`` ends the finishing phase (or the Newton steps, without
        one).
    eps_start, eps_min : float, optional
        First and last smoothing ``ε`` of the reweighting (depth units);
        default ``1e-2`` and ``1e-7`` times ``scale``.
    scale : float, optional
        The typical depth (depth units); default the median positive
        starting value.
    eps_factor : float, default 10.0
        ``ε`` is divided by it whenever the decrease of ``F`` stalls.
    inner_rtol : float, default 1e-6
        Relative residual of each reweighted PCG solve.
    inner_max_iter : int, default 500
        PCG steps per reweighted solve at most.
    preconditioner : {"grid", "amg"}, default "grid"
        One geometric multigrid hierarchy updated numerically, or a pyamg
        hierarchy rebuilt every iteration.
    method : {"newton", "reweighting"}, default "newton"
        ``"newton"``: primal-dual Newton steps on the reweighted systems
        with ε continuation (for L1 terms on the pixel grid); ``"reweighting"``:
        plain majorise–minimise reweighting, whose exact ``F`` never
        increases.  See :func:`~sparsedepth.solvers.irls.solve_irls`.
    newton_rtol : float, default 5e-2
        Relative residual of each Newton system's PCG solve.
    newton_max_inner : int, default 30
        PCG steps per Newton system at most.
    newton_tol : float, default 1e-3
        ``ε`` shrinks when the smoothed problem's relative gradient is below
        it (or after ``level_steps`` Newton steps).
    level_steps : int, default 2
        Newton steps per ``ε`` at most (at ``eps_min``: unlimited).
    tie_band : float, optional
        Rows with ``|(Kz)_k| <=`` it count as tied in the duality gap
        (depth units); default ``1e-3`` times ``scale``.
    certify_below : float, optional
        The gap is computed at the end of each ``ε`` level from ``ε <=``
        it on (depth units); default ``1e-5`` times ``scale``.
    finish : {"admm", "none"}, default "admm"
        The exact finishing phase of ``method="newton"``: with ``"admm"``
        the Newton steps stop once the duality gap is within the larger of
        the target (``target_gap``, ``gap_tol``) and ``newton_gap`` (or when
        they stall), and, unless that already meets the target, ADMM
        iterations with active-set polishes
        (:func:`~sparsedepth.solvers.admm.finish_from`) continue from the
        Newton point and dual to the target; ``"none"``: Newton steps only.
    newton_gap : float, default 1e-2
        The relative duality gap at which the Newton phase hands over to the
        finishing phase (the Newton steps gain most while ``ε`` is large;
        ``python -m bench.solver_gaps`` times the hand-over).
    """

    solver: ClassVar[str] = "irls"
    gap_tol: float = _option(DEFAULT_GAP_TOL)
    target_gap: float = _option(1e-4)
    eps_start: float | None = _option(None, kind=float, positive=True, depth_unit=True)
    eps_min: float | None = _option(None, kind=float, positive=True, depth_unit=True)
    scale: float | None = _option(None, kind=float, positive=True, depth_unit=True)
    eps_factor: float = _option(10.0, positive=True)
    inner_rtol: float = _option(1e-6)
    inner_max_iter: int = _option(500)
    preconditioner: str = _option("grid", choices=_PRECONDITIONERS)
    method: str = _option("newton", kind=str, choices=("newton", "reweighting"))
    newton_rtol: float = _option(5e-2)
    newton_max_inner: int = _option(30)
    newton_tol: float = _option(1e-3)
    level_steps: int = _option(2)
    tie_band: float | None = _option(None, kind=float, positive=True, depth_unit=True)
    certify_below: float | None = _option(None, kind=float, positive=True, depth_unit=True)
    finish: str = _option("admm", kind=str, choices=("admm", "none"))
    newton_gap: float = _option(1e-2)


@dataclass(frozen=True, kw_only=True)
class AdmmOptions(SolverOptions):
    """Options of the ``admm`` solver (:func:`~sparsedepth.solvers.admm.solve_admm`).

    Parameters
    ----------
    rho : float, optional
        The ADMM penalty ``ρ``; default :func:`~sparsedepth.solvers.admm.default_rho`.
    relaxation : float, default 1.9
        Over-relaxation ``a``.
    inner_rtol, inner_factor : float, default 1e-10 and 0.1
        Stopping rule of the inner PCG solve when ``inner_max_iter > 1``:
        ``‖rhs − S z‖ <= max(inner_rtol ‖rhs‖, inner_factor ‖rhs − S z_prev‖)``.
    inner_max_iter : int, default 1
        PCG steps per ADMM iteration at most.
    adapt_iters : int, default 0
        Iterations during which ``ρ`` is adapted by residual balancing (``>= 0``).
    preconditioner : {"grid", "amg"}, default "grid"
        Preconditioner of the inner solves.
    polish : bool, default True
        Finish by exact active-set polishes.
    polish_rounds : int, default 2
        Solves per polish at most (re-tying edges whose sign came out wrong).
    polish_rtol : float, default 1e-7
        Relative residual of the polish's PCG solve.
    polish_preconditioner : {"jacobi", "amg"}, default "jacobi"
        Preconditioner of the polish's PCG solve.
    check_every : int, default 3
        ADMM iterations between the first two polishes.
    check_rtol : float, default 2e-7
        Stop when a polish changes the best polished ``F`` by at most this (relative).
    gap_tol : float, default 1e-2 (:data:`DEFAULT_GAP_TOL`)
        ``converged`` needs the duality gap of the returned depth ``<= gap_tol · max(F, 1e-7 F(0))``.
    target_gap : float, default 1e-6
        The relative duality gap the solver works to: a stop (polishes that
        agree, or the residual rule) is accepted when the gap is within the
        smaller of it and ``gap_tol``.
    restart_from_polish : bool, default False
        After a polish that lowers the best polished ``F``, ADMM goes on
        from the polished point (``z`` and ``u = K z``; ``λ`` kept).
    warm_start : {"none", "coarse"}, default "none"
        ``"coarse"``: nested iteration: a grid of more than ``coarse_above``
        pixels first solves the problem rediscretised on a grid twice as
        coarse per side (recursively) and starts from that solution and its
        dual (:func:`~sparsedepth.solvers.admm.solve_admm`, Notes).
    coarse_above : int, default 600000
        With ``warm_start="coarse"``: the pixel count above which a grid is
        started from the coarser one.
    coarse_gap_tol : float, default 1e-4
        ``target_gap`` of the coarse solves (they only start the fine one).
    """

    solver: ClassVar[str] = "admm"
    rho: float | None = _option(None, kind=float, positive=True)
    relaxation: float = _option(1.9, positive=True)
    inner_rtol: float = _option(1e-10)
    inner_factor: float = _option(0.1)
    inner_max_iter: int = _option(1)
    adapt_iters: int = _option(0, minimum=0)
    preconditioner: str = _option("grid", choices=_PRECONDITIONERS)
    polish: bool = _option(True)
    polish_rounds: int = _option(2)
    polish_rtol: float = _option(1e-7)
    polish_preconditioner: str = _option("jacobi", choices=_POLISH_PRECONDITIONERS)
    check_every: int = _option(3)
    check_rtol: float = _option(2e-7)
    gap_tol: float = _option(DEFAULT_GAP_TOL)
    target_gap: float = _option(1e-6)
    restart_from_polish: bool = _option(False)
    warm_start: str = _option("none", kind=str, choices=("none", "coarse"))
    coarse_above: int = _option(600_000)
    coarse_gap_tol: float = _option(1e-4, positive=True)


@dataclass(frozen=True, kw_only=True)
class LbfgsbOptions(SolverOptions):
    """Options of the ``lbfgsb`` solver (SciPy L-BFGS-B on the smoothed objective).

    Parameters
    ----------
    maxfun : int, optional
        Function evaluations at most; default ``10 max_iter + 100``.
    gtol : float, default 1e-12
        SciPy's projected-gradient tolerance on the scaled problem.
    maxcor : int, default 10
        Correction pairs kept.
    gap_tol : float, default 1e-2 (:data:`DEFAULT_GAP_TOL`)
        ``converged`` needs the duality gap of the returned depth ``<= gap_tol · max(F, 1e-7 F(0))``.
    """

    solver: ClassVar[str] = "lbfgsb"
    maxfun: int | None = _option(None, kind=int)
    gtol: float = _option(1e-12)
    maxcor: int = _option(10)
    gap_tol: float = _option(DEFAULT_GAP_TOL)


@dataclass(frozen=True, kw_only=True)
class AdamOptions(SolverOptions):
    """Options of the ``adam`` solver (projected Adam on the smoothed objective).

    Parameters
    ----------
    learning_rate : float, optional
        ``η`` (depth units); default ``3e-2`` (``"cosine"``) or ``1e-2``
        (``"inverse_sqrt"``) times the median positive starting value.
    schedule : {"cosine", "inverse_sqrt"}, default "cosine"
        ``"cosine"``: ``η_k = η (1 + cos(π (k − 1) / K)) / 2`` for
        ``k = 1 … K``, ``K = min(horizon, max_iter)``, and the solver stops
        after step ``K``; ``"inverse_sqrt"``: ``η_k = η / sqrt(1 + k /
        decay_steps)`` until the stopping rule or ``max_iter``.
    horizon : int, default 1000
        ``K`` of the cosine schedule.
    decay_steps : float, default 200.0
        Of the ``"inverse_sqrt"`` schedule.
    beta1, beta2 : float, default 0.9 and 0.999
        Decay rates of the moment estimates.
    window : int, default 50
        Steps per window of the stop: the mean over the last ``window`` steps against the mean over the
        ``window`` steps before them.
    record_every : int, default 1
        Iterations between history records.
    gap_tol : float, default 1e-2 (:data:`DEFAULT_GAP_TOL`)
        ``converged`` needs the duality gap of the returned depth ``<= gap_tol · max(F, 1e-7 F(0))``.
    """

    solver: ClassVar[str] = "adam"
    learning_rate: float | None = _option(None, kind=float, positive=True, depth_unit=True)
    schedule: str = _option("cosine", kind=str, choices=("cosine", "inverse_sqrt"))
    horizon: int = _option(1000)
    decay_steps: float = _option(200.0, positive=True)
    beta1: float = _option(0.9)
    beta2: float = _option(0.999)
    window: int = _option(50)
    record_every: int = _option(1)
    gap_tol: float = _option(DEFAULT_GAP_TOL)
