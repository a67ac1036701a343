"""One BLAS thread per process, set before numpy is imported.

On a shared machine a multithreaded OpenBLAS makes short vector operations cost many times more, by an amount
that depends on the other users' load; the timing benchmarks (:mod:`bench.perf`,
:mod:`bench.quadratic_variants`, :mod:`bench.batch_scale`) call :func:`one_blas_thread` first, so that every
method (ours and the SciPy references) runs with one thread unless the caller's environment says otherwise.

May import the standard library only (it runs before numpy is imported).
"""

from __future__ import annotations

import os

__all__ = ["BLAS_VARIABLES", "one_blas_thread"]

BLAS_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def one_blas_thread(variables=BLAS_VARIABLES) -> None:
    """Set each of ``variables`` to ``"1"`` unless it is already set."""
    for var in variables:
        os.environ.setdefault(var, "1")
