"""Projected Adam on the smoothed objective, with the projection ``z ← max(z, 0)``.

May import the other modules of :mod:`sparsedepth.solvers`.
"""

from __future__ import annotations

import numpy as np

from .common import objective_floor, output, relative

__all__ = ["solve_adam"]


def solve_adam(objective, x0, *, tol, max_iter, recorder, options):
    """Adam (bias-corrected moments) with the projection ``z ← max(z, 0)``.

    Step ``z ← max(z − η_k m̂/(sqrt(v̂) + 1e-8·scale), 0)`` with ``η_k =
    learning_rate / sqrt(1 + k/decay_steps)``; default ``learning_rate`` is
    ``1e-2`` times the median observed depth.  Converged when the smoothed
    objective decreased by less than ``tol`` (relative) over the last
    ``window`` steps (options: :class:`~sparsedepth.solvers.options.AdamOptions`).
    """
    scale = max(float(np.median(x0[x0 > 0])) if np.any(x0 > 0) else 1.0, 1e-12)
    lr = 1e-2 * scale if options.learning_rate is None else float(options.learning_rate)
    decay = options.decay_steps
    b1, b2 = options.beta1, options.beta2
    window = options.window
    record_every = options.record_every
    floor = objective_floor(objective)
    z = np.maximum(np.asarray(x0, dtype=float).copy(), 0.0)
    m = np.zeros_like(z)
    v = np.zeros_like(z)
    recorder(0, z, fevals=0, gevals=0)
    values = []
    converged = False
    message = f"reached max_iter = {max_iter}"
    k = 0
    while k < max_iter:
        k += 1
        f, g = objective.smoothed_value_and_gradient(z)
        values.append(f)
        m = b1 * m + (1 - b1) * g
        v = b2 * v + (1 - b2) * g * g
        mhat = m / (1 - b1**k)
        vhat = v / (1 - b2**k)
        step = lr / np.sqrt(1.0 + k / decay)
        z = np.maximum(z - step * mhat / (np.sqrt(vhat) + 1e-8 * scale), 0.0)
        if k % record_every == 0:
            recorder(k, z, fevals=k, gevals=k)
        if len(values) > window:
            old = values[-window - 1]
            if 0 <= (old - f) <= tol * abs(f) + floor:
                converged = True
                message = (f"relative decrease over {window} steps {relative(old - f, f):.1e} <= tol {tol:.1e} "
                           f"(or absolute {old - f:.1e} <= floor {floor:.1e})")
                break
    if k % record_every != 0:
        recorder(k, z, fevals=k, gevals=k)
    return output(z, k, converged, message, recorder)
