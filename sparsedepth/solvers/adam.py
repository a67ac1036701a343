"""Projected Adam on the smoothed objective, with the projection ``z ← max(z, 0)``.

May import the other modules of :mod:`sparsedepth.solvers`.
"""

from __future__ import annotations

import numpy as np

from .common import objective_floor, output, relative

__all__ = ["solve_adam", "step_size", "window_means_stalled"]


def step_size(options, learning_rate, k, horizon):
    """``η_k`` of the schedule (see :class:`~sparsedepth.solvers.options.AdamOptions`)."""
    if options.schedule == "cosine":
        return learning_rate * 0.5 * (1.0 + np.cos(np.pi * (k - 1) / horizon))
    return learning_rate / np.sqrt(1.0 + k / options.decay_steps)


def window_means_stalled(values, window, tol, floor):
    """``(earlier, last)`` window means when the last ``2 window`` values have stalled, else ``None``.

    ``earlier`` and ``last`` are the means of the smoothed objective over the ``window`` steps before the last
    ``window`` and over the last ``window``; stalled means ``0 <= earlier − last <= tol |last| + floor``.  Adam's
    values oscillate while its step is large: comparing two window means instead of two single values keeps an
    oscillation's low point from reading as a plateau.
    """
    if len(values) < 2 * window:
        return None
    tail = np.asarray(values[-2 * window:], dtype=float)
    earlier, last = float(tail[:window].mean()), float(tail[window:].mean())
    return (earlier, last) if 0 <= earlier - last <= tol * abs(last) + floor else None


def solve_adam(objective, x0, *, tol, max_iter, recorder, options):
    """Adam (bias-corrected moments) with the projection ``z ← max(z, 0)``.

    Step ``z ← max(z − η_k m̂/(sqrt(v̂) + 1e-8·scale), 0)``.  With the default
    ``"cosine"`` schedule ``η_k`` falls from ``learning_rate`` (default
    ``3e-2`` times the median observed depth) to nearly 0 over ``K =
    min(horizon, max_iter)`` steps, and the solver stops after step ``K``
    (``converged`` then rests on the duality gap, see
    :func:`sparsedepth.solvers.solve`); with ``"inverse_sqrt"`` ``η_k =
    learning_rate / sqrt(1 + k/decay_steps)`` (default ``learning_rate``
    ``1e-2`` times the median depth).  Either stops early, converged, when
    the mean of the smoothed objective over the last ``window`` steps is
    less than ``tol`` (relative) below its mean over the ``window`` steps
    before them (options:
    :class:`~sparsedepth.solvers.options.AdamOptions`).
    """
    scale = max(float(np.median(x0[x0 > 0])) if np.any(x0 > 0) else 1.0, 1e-12)
    cosine = options.schedule == "cosine"
    default_rate = 3e-2 if cosine else 1e-2
    lr = default_rate * scale if options.learning_rate is None else float(options.learning_rate)
    horizon = min(options.horizon, max_iter) if cosine else max_iter
    b1, b2 = options.beta1, options.beta2
    window = options.window
    record_every = options.record_every
    floor = objective_floor(objective)
    z = np.maximum(np.asarray(x0, dtype=float).copy(), 0.0)
    m = np.zeros_like(z)
    v = np.zeros_like(z)
    recorder(0, z, fevals=0, gevals=0)
    values = []
    converged = cosine
    message = f"cosine schedule ended after {horizon} steps" if cosine else f"reached max_iter = {max_iter}"
    k = 0
    while k < horizon:
        k += 1
        f, g = objective.smoothed_value_and_gradient(z)
        values.append(f)
        m = b1 * m + (1 - b1) * g
        v = b2 * v + (1 - b2) * g * g
        mhat = m / (1 - b1**k)
        vhat = v / (1 - b2**k)
        step = step_size(options, lr, k, horizon)
        z = np.maximum(z - step * mhat / (np.sqrt(vhat) + 1e-8 * scale), 0.0)
        if k % record_every == 0:
            recorder(k, z, fevals=k, gevals=k)
        means = window_means_stalled(values, window, tol, floor)
        if means is not None:
            earlier, last = means
            converged = True
            message = (f"relative decrease of the mean over the last {window} steps from the {window} before "
                       f"{relative(earlier - last, last):.1e} <= tol {tol:.1e} "
                       f"(or absolute {earlier - last:.1e} <= floor {floor:.1e})")
            break
    if k % record_every != 0:
        recorder(k, z, fevals=k, gevals=k)
    return output(z, k, converged, message, recorder)
