"""The public entry point: :func:`complete_depth`."""

from __future__ import annotations

import numpy as np

from .objective import DEFAULT_L1_SMOOTHING, build_objective
from .result import CompletionResult
from .solvers import SOLVERS, solve
from .weights import DEFAULT_WEIGHTS, Weights

__all__ = ["complete_depth", "choose_solver"]


def choose_solver(weights: Weights) -> str:
    """The solver ``solver="auto"`` picks: ``"amg"`` for γ = 0, else ``"admm"``."""
    return "amg" if weights.gamma == 0 else "admm"


def complete_depth(
    image,
    sparse_depth,
    mask=None,
    *,
    weights: Weights = DEFAULT_WEIGHTS,
    solver: str = "auto",
    tol: float | None = None,
    max_iter: int | None = None,
    callback=None,
    x0=None,
    l1_smoothing: float = DEFAULT_L1_SMOOTHING,
    options: dict | None = None,
) -> CompletionResult:
    """Complete a sparse depth map into a dense one, guided by an image.

    Minimises over ``z >= 0``::

        F(z) = α Σ M (z − z_obs)² + β Σ (∂x z)² + (∂y z)²
             + γ Σ w (|∂x z| + |∂y z|) + δ Σ (z − z_c)²   (+ optional terms)

    with ``w = exp(−κ ‖∇I‖)`` and ``z_c`` the nearest-neighbour fill of the
    observations (see :class:`~sparsedepth.weights.Weights`).

    Parameters
    ----------
    image : ndarray, (H, W, 3) or (H, W)
        uint8 (÷255), uint16 (÷65535) or float in [0, 1].
    sparse_depth : ndarray, (H, W)
        Depth in metres at the observed pixels.
    mask : ndarray of bool, (H, W), optional
        True where depth is observed.  Default: finite and ``> 0`` (0 and NaN
        mean "no measurement").
    weights : Weights
        Term weights; default :data:`~sparsedepth.weights.DEFAULT_WEIGHTS`.
    solver : {"auto", "direct", "cg", "amg", "irls", "admm", "lbfgsb", "adam"}
        ``"auto"`` is ``"amg"`` for γ = 0 and ``"admm"`` otherwise.  The stopping
        rule of each is in :mod:`sparsedepth.solvers`.
    tol : float, optional
        Solver tolerance (meaning per solver; default per solver).
    max_iter : int, optional
        Maximum number of (outer) iterations.
    callback : callable, optional
        ``callback(state)`` with a :class:`~sparsedepth.result.SolverState`
        after every iteration; raise ``StopIteration`` to stop.
    x0 : ndarray, (H, W), optional
        Starting point; default ``z_c``.
    l1_smoothing : float
        ``ε`` of the smoothed L1 used by the gradient-based solvers.
    options : dict, optional
        Solver-specific options (see each solver's docstring).

    Returns
    -------
    CompletionResult

    Raises
    ------
    ValueError
        Inconsistent shapes, no observed pixel, NaN/inf in the image, negative
        observed depth, wrong number of dimensions, a negative weight, an unknown
        solver, or a quadratic-only solver with γ > 0.

    Examples
    --------
    >>> import numpy as np, sparsedepth
    >>> rng = np.random.default_rng(0)
    >>> image = rng.random((40, 50, 3))
    >>> truth = np.add.outer(np.linspace(1, 2, 40), np.linspace(0, 1, 50))
    >>> sparse, mask = sparsedepth.sample_depth(truth, fraction=0.05, seed=0)
    >>> result = sparsedepth.complete_depth(image, sparse, mask)
    >>> result.depth.shape
    (40, 50)
    """
    name = choose_solver(weights) if solver == "auto" else solver
    if name not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {['auto', *sorted(SOLVERS)]}")
    objective, coarse, observed = build_objective(image, sparse_depth, mask, weights=weights, l1_smoothing=l1_smoothing)
    if x0 is None:
        start = coarse.reshape(-1).view()  # no copy (8-MP memory); every solver copies its start
        start.flags.writeable = False  # ... and the prior's target must stay intact
    else:
        start = np.asarray(x0, dtype=np.float64)
        if start.shape != objective.shape:
            raise ValueError(f"x0 has shape {start.shape}, expected {objective.shape}")
        if not np.all(np.isfinite(start)):
            raise ValueError("x0 contains NaN or infinite values")
        start = np.maximum(start.ravel(), 0.0)
    out, runtime = solve(objective, start, solver=name, tol=tol, max_iter=max_iter, callback=callback, options=options)
    z = out.z
    negative = z < 0
    z = np.where(negative, 0.0, z)
    clamped = int(np.count_nonzero(negative | (z == 0)))
    terms = objective.term_values(z)
    return CompletionResult(
        depth=z.reshape(objective.shape),
        objective=float(sum(terms.values())),
        terms=terms,
        iterations=out.iterations,
        converged=out.converged,
        message=out.message,
        clamped=clamped,
        history=out.history,
        solver=name,
        weights=weights,
        runtime=runtime,
    )
