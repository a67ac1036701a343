"""SciPy L-BFGS-B on the smoothed objective, with the bounds ``z >= 0``.

May import the other modules of :mod:`sparsedepth.solvers`.
"""

from __future__ import annotations

import numpy as np
import scipy.optimize

from .common import objective_floor, output

__all__ = ["solve_lbfgsb"]


def solve_lbfgsb(objective, x0, *, tol, max_iter, recorder, options):
    """SciPy L-BFGS-B with bounds ``z >= 0`` on the smoothed objective.

    The objective is divided by ``F(x0)`` so that ``ftol = tol`` is a relative
    decrease; ``gtol`` (:class:`~sparsedepth.solvers.options.LbfgsbOptions`)
    defaults to 1e-12 on the scaled problem.
    """
    f0 = max(objective.smoothed_value_and_gradient(x0)[0], objective_floor(objective))
    counts = {"f": 0}

    def fun(z):
        counts["f"] += 1
        v, g = objective.smoothed_value_and_gradient(z)
        return v / f0, g / f0

    recorder(0, x0, fevals=0, gevals=0)
    it = [0]

    def cb(xk):
        it[0] += 1
        recorder(it[0], xk, fevals=counts["f"], gevals=counts["f"])

    res = scipy.optimize.minimize(
        fun,
        x0,
        jac=True,
        method="L-BFGS-B",
        bounds=scipy.optimize.Bounds(0.0, np.inf),
        callback=cb,
        options={
            "maxiter": max_iter,
            "maxfun": 10 * max_iter + 100 if options.maxfun is None else options.maxfun,
            "ftol": tol,
            "gtol": options.gtol,
            "maxcor": options.maxcor,
        },
    )
    return output(res.x, res.nit, res.success, str(res.message), recorder)
