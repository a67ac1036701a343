"""Multigrid variants for the default (13-point) quadratic system: iterations and time.

Command (about 2 minutes)::

    python bench/quadratic_variants.py

The 640x480 NYU frame of ``bench/perf.py`` (5 % observed, default weights
with γ = 0).  Every variant solves ``A z = b`` by PCG from the nearest-neighbour
fill to ``‖b − Az‖ ≤ 1e-8 ‖b‖``; the time is set-up + solve, best of 2
interleaved rounds.  It backs the "measured and rejected" list of
docs/performance.md: which changes of the V-cycle lower the iteration count
of this fourth-order, edge-weighted operator, and whether they pay.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from pyamg.multilevel import MultilevelSolver  # noqa: E402
from pyamg.relaxation.relaxation import gauss_seidel  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import perf  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.multigrid import GridMultigrid  # noqa: E402


def _interp_1d(n, cubic):
    """1-D interpolation from the even points: linear, or 4-point cubic away from the ends."""
    nc = (n + 1) // 2
    rows, cols, vals = [], [], []
    for i in range(n):  # set-up of a small (n x n/2) matrix; not on the solve path
        j = i // 2
        if i % 2 == 0:
            taps = ((j, 1.0),)
        elif cubic and j >= 1 and j + 2 < nc:
            taps = ((j - 1, -1 / 16), (j, 9 / 16), (j + 1, 9 / 16), (j + 2, -1 / 16))
        elif j + 1 < nc:
            taps = ((j, 0.5), (j + 1, 0.5))
        else:
            taps = ((j, 1.0),)
        for c, v in taps:
            rows.append(i)
            cols.append(c)
            vals.append(v)
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, nc))


def _galerkin_solver(A, shape, prolongations):
    """pyamg hierarchy with the given prolongation per level (Galerkin products, symmetric GS)."""
    levels = []
    for P in prolongations + [None]:
        lvl = MultilevelSolver.Level()
        lvl.A = A
        levels.append(lvl)
        if P is None:
            break
        lvl.P, lvl.R = P, P.T.tocsr()
        A = (lvl.R @ A @ P).tocsr()
    ml = MultilevelSolver(levels, coarse_solver="splu")
    ml.symmetric_smoothing = True
    for lvl in levels[:-1]:
        lvl.presmoother = lambda A, x, b: gauss_seidel(A, x, b, sweep="forward")
        lvl.postsmoother = lambda A, x, b: gauss_seidel(A, x, b, sweep="backward")
    return ml


def _cubic_prolongations(shape, max_coarse=1024):
    out, (h, w) = [], shape
    while h * w > max_coarse:
        out.append(sp.kron(_interp_1d(h, True), _interp_1d(w, True), format="csr"))
        h, w = (h + 1) // 2, (w + 1) // 2
    return out


def main():
    image, _, sparse, mask = perf.load_problem()
    obj, coarse, _ = sd.build_objective(image, sparse, mask, weights=sd.DEFAULT_WEIGHTS.replace(gamma=0))
    A, b, _ = obj.normal_equations()
    shape, x0 = obj.shape, coarse.ravel()
    pair = sd.objective.pair_edge_weights(image, sd.DEFAULT_WEIGHTS.kappa)
    G = sd.operators.gradient(shape)

    def grid(**options):
        return GridMultigrid(A, shape, interpolation="auto", **options).to_pyamg()

    def aux_operator():
        L = (G.T @ sp.diags(pair) @ G + sp.diags(1e-6 + mask.ravel())).tocsr()
        aux = GridMultigrid(L, shape, interpolation="operator", coarse_precision="double")
        return _galerkin_solver(A, shape, [lvl.P for lvl in aux.levels[:-1]])

    variants = [
        ("V(1,1), bilinear (the default)", grid, "V"),
        ("V(2,2)", lambda: grid(sweeps=2), "V"),
        ("V(3,3)", lambda: grid(sweeps=3), "V"),
        ("W(1,1)", grid, "W"),
        ("cubic interpolation", lambda: _galerkin_solver(A, shape, _cubic_prolongations(shape)), "V"),
        ("black-box interpolation of the first-order image-weighted part", aux_operator, "V"),
    ]
    best = {}
    for _ in range(2):
        for label, build, cycle in variants:
            t = time.perf_counter()
            ml = build()
            residuals = []
            z = ml.solve(b, x0=x0.copy(), tol=1e-8, accel="cg", cycle=cycle, residuals=residuals, maxiter=300)
            elapsed = time.perf_counter() - t
            rel = float(np.linalg.norm(b - A @ z) / np.linalg.norm(b))
            if label not in best or elapsed < best[label][0]:
                best[label] = (elapsed, len(residuals) - 1, rel)
    print("| V-cycle variant | PCG iterations | set-up + solve s | ‖b−Az‖/‖b‖ |")
    print("|---|---|---|---|")
    for label, _, _ in variants:
        elapsed, its, rel = best[label]
        print(f"| {label} | {its} | {elapsed:.2f} | {rel:.1e} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
