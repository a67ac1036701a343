"""Multigrid variants for the default (13-point) quadratic system: iterations and time.

Command, from the repository root (about 1 minute)::

    python -m bench.quadratic_variants

The 640x480 NYU frame of :mod:`bench.perf` (5 % observed, default weights
with γ = 0).  Every variant solves ``A z = b`` by PCG from the nearest-neighbour
fill to ``‖b − Az‖ ≤ 1e-8 ‖b‖``; the time is set-up + solve, best of 2
interleaved rounds.  It backs the "measured and rejected" list of
docs/performance.md: which changes of the V-cycle lower the iteration count
of this fourth-order, edge-weighted operator, and whether they pay.  A
diagnosis follows: the smallest eigenvalue estimates of the preconditioned
operator, where the slowest error of the V-cycle iteration lives, and the
iteration count on the frame cropped to the box of its valid depth.

May import :mod:`sparsedepth` (also ``sparsedepth.linalg.multigrid``), numpy, scipy, pyamg and :mod:`bench.perf`
(its problem).
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from pyamg.multilevel import MultilevelSolver  # noqa: E402
from pyamg.relaxation.relaxation import gauss_seidel  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.grid import gradient  # noqa: E402
from sparsedepth.linalg import GridMultigrid  # noqa: E402
from sparsedepth.objective import pair_edge_weights  # noqa: E402

from . import perf  # noqa: E402


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
    image, depth, sparse, mask = perf.load_problem()
    obj, coarse, _ = sd.build_objective(image, sparse, mask, weights=sd.DEFAULT_WEIGHTS.replace(gamma=0))
    A, b, _ = obj.normal_equations()
    shape, x0 = obj.shape, coarse.ravel()
    pair = pair_edge_weights(image, sd.DEFAULT_WEIGHTS.kappa)
    G = gradient(shape)

    def grid(**options):
        return GridMultigrid(A, shape, interpolation="auto", **options).to_pyamg()

    def aux_operator():
        L = (G.T @ sp.diags(pair) @ G + sp.diags(1e-6 + mask.ravel())).tocsr()
        aux = GridMultigrid(L, shape, interpolation="operator", coarse_precision="double")
        return _galerkin_solver(A, shape, [lvl.P.tocsr() for lvl in aux.levels[:-1]])

    def filtered_operator():
        # Dendy's interpolation from the radius-1 couplings of A itself: its negative off-diagonals between
        # 4-neighbours (symmetrised), the diagonal making every row sum equal A's own
        C = A.tocoo()
        dy = np.abs(C.row // shape[1] - C.col // shape[1])
        dx = np.abs(C.row % shape[1] - C.col % shape[1])
        keep = (dy + dx == 1) & (C.data < 0)
        off = sp.csr_matrix((C.data[keep], (C.row[keep], C.col[keep])), shape=A.shape)
        off = 0.5 * (off + off.T)
        diagonal = np.maximum(np.asarray(A.sum(axis=1)).ravel(), 1e-12) - np.asarray(off.sum(axis=1)).ravel()
        aux = GridMultigrid((off + sp.diags(diagonal)).tocsr(), shape, interpolation="operator",
                            coarse_precision="double")
        return _galerkin_solver(A, shape, [lvl.P.tocsr() for lvl in aux.levels[:-1]])

    variants = [
        ("V(1,1), bilinear (the default)", grid, "V"),
        ("V(2,2)", lambda: grid(sweeps=2), "V"),
        ("V(3,3)", lambda: grid(sweeps=3), "V"),
        ("W(1,1)", grid, "W"),
        ("cubic interpolation", lambda: _galerkin_solver(A, shape, _cubic_prolongations(shape)), "V"),
        ("black-box interpolation of the first-order image-weighted part", aux_operator, "V"),
        ("black-box interpolation of A's negative 4-neighbour couplings", filtered_operator, "V"),
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
    print()
    diagnose(A, shape, image, depth)
    return 0


def _ritz_values(A, precondition, iterations=60, seed=0):
    """Eigenvalue estimates of ``M⁻¹A`` from the Lanczos matrix of ``iterations`` PCG steps (random rhs)."""
    import scipy.linalg

    r = np.random.default_rng(seed).standard_normal(A.shape[0])
    z = precondition(r)
    p, rz = z.copy(), r @ z
    alphas, betas = [], []
    for _ in range(iterations):
        q = A @ p
        alpha = rz / (p @ q)
        r -= alpha * q
        z = precondition(r)
        rz, rz_old = r @ z, rz
        beta = rz / rz_old
        p = z + beta * p
        alphas.append(alpha)
        betas.append(beta)
    alphas, betas = np.array(alphas), np.array(betas)
    diagonal = 1.0 / alphas
    diagonal[1:] += betas[:-1] / alphas[:-1]
    off = np.sqrt(betas[:-1]) / alphas[:-1]
    return scipy.linalg.eigh_tridiagonal(diagonal, off, eigvals_only=True)


def diagnose(A, shape, image, depth):
    """Where the default V-cycle is weak: the small eigenvalues of M⁻¹A and the slowest error's location."""
    mg = GridMultigrid(A, shape, interpolation="auto")
    ritz = _ritz_values(A, mg.vcycle)
    print("Smallest Ritz values of M⁻¹A (V(1,1) as M, 60 Lanczos steps): "
          + ", ".join(f"{v:.3f}" for v in ritz[:8]) + f"; largest {ritz[-1]:.3f}; "
          f"{int(np.sum(ritz < 0.2))} below 0.2.")
    # the slowest error of the stationary V-cycle iteration, from a random start with b = 0
    e = np.random.default_rng(1).standard_normal(A.shape[0])
    for _ in range(80):
        e -= mg.vcycle(A @ e)
        e /= np.linalg.norm(e)
    rate = float(np.linalg.norm(e - mg.vcycle(A @ e)))
    invalid = ~np.isfinite(depth).ravel()
    print(f"Slowest error of the stationary V-cycle iteration (80 cycles from random): contraction {rate:.3f} "
          f"per cycle, {np.sum(e[invalid] ** 2):.0%} of its energy on the {invalid.mean():.0%} of the pixels "
          "without valid depth.")
    # the same problem on the box where most rows and columns have valid depth (Kinect border cut off)
    invalid = ~np.isfinite(depth)
    rows = np.flatnonzero(invalid.mean(axis=1) < 0.5)
    cols = np.flatnonzero(invalid.mean(axis=0) < 0.5)
    box = np.s_[rows[0] + 2: rows[-1] - 1, cols[0] + 2: cols[-1] - 1]
    sparse, mask = sd.sample_depth(depth[box], fraction=perf.FRACTION, seed=perf.SEED)
    obj, coarse, _ = sd.build_objective(image[box], sparse, mask, weights=sd.DEFAULT_WEIGHTS.replace(gamma=0))
    A_box, b_box, _ = obj.normal_equations()
    _, info = GridMultigrid(A_box, obj.shape, interpolation="auto").solve(b_box, x0=coarse.ravel().copy(),
                                                                            rtol=1e-8)
    print(f"Cropped to {obj.shape[0]}x{obj.shape[1]} ({np.mean(invalid[box]):.0%} without valid depth): "
          f"{info.iterations} PCG iterations.")


if __name__ == "__main__":
    sys.exit(main())
