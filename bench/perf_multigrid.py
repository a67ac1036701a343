"""Benchmark: grid multigrid vs pyamg vs spsolve on depth-completion systems.

Builds the systems itself, on a real NYU Depth V2 frame
(``../shared/data/nyu_metric3d/rgb_00000.jpg`` and ``sync_depth_00000.png``,
resized for the larger grids)::

    A = diag(a) + Dx^T diag(wx) Dx + Dy^T diag(wy) Dy,   b = a_obs * z_obs

with a random 5 % observation mask (alpha = 1) plus delta everywhere, and

* ``quad``: constant weights beta = 1, delta in {1e-2, 1e-4};
* ``image``: edge-aware weights w = exp(-kappa |I(p) - I(q)|), kappa = 10, I the
  grey image in [0, 1] (w spans ~5e-5 .. 1), delta = 1e-2;
* ``irls``: three IRLS steps of isotropic TV: w = 1 / max(|grad z_{k-1}|, eps),
  eps = 1e-4 m, clipped to [1e-2, 1e4], z_0 the ``quad`` solution; the weight
  sequence is computed once and every method solves the same three systems
  (the grid hierarchy is built once and then ``update()``-d).

Each method solves to relative residual ||b - A x|| / ||b|| <= 1e-8 (CG's
stopping rule; the true residual reached is reported).  Times are wall-clock
seconds (best of ``--repeat`` at 640x480), memory is the peak resident memory
used on top of the process before the method started (Linux VmHWM, reset
before each method; A and b themselves are not included).

Run ``python bench/perf_multigrid.py`` (about ten minutes on 2 cores);
``--sizes 1`` for 640x480 only; ``--mem8mp`` for the 8-megapixel memory check
alone (run automatically at the end, in a fresh process).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy import ndimage
from skimage.color import rgb2gray
from skimage.io import imread
from skimage.transform import resize

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from sparsedepth.linalg.multigrid import GridMultigrid, solve_spd  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "nyu_metric3d"
RTOL = 1e-8
BASE = (480, 640)


# --------------------------------------------------------------------------
# memory (Linux): peak RSS since the last reset
# --------------------------------------------------------------------------
def _status(key):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key):
                return int(line.split()[1]) / 1024.0  # MB
    return float("nan")


def reset_peak():
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass
    return _status("VmRSS")


def peak_since(rss_before):
    return _status("VmHWM") - rss_before


# --------------------------------------------------------------------------
# test systems
# --------------------------------------------------------------------------
def assemble(shape, a, wx, wy):
    """CSR of diag(a) + Dx^T diag(wx) Dx + Dy^T diag(wy) Dy (5-point), lean."""
    h, w = shape
    n = h * w
    wx = np.array(np.broadcast_to(np.reshape(wx, (-1, w) if np.size(wx) > 1 else ()),
                                  (h, w)), dtype=float)
    wy = np.array(np.broadcast_to(np.reshape(wy, (-1, w) if np.size(wy) > 1 else ()),
                                  (h, w)), dtype=float)
    a = np.broadcast_to(np.reshape(a, (-1, w) if np.size(a) > 1 else ()), (h, w))
    wx[:, -1] = 0.0  # no edge beyond the last column / row (Neumann)
    wy[-1, :] = 0.0
    west = np.zeros((h, w))
    west[:, 1:] = wx[:, :-1]
    north = np.zeros((h, w))
    north[1:, :] = wy[:-1, :]
    centre = a + wx + west + wy + north
    # entries per row in column order: N, W, C, E, S
    vals = np.stack([-north, -west, centre, -wx, -wy], axis=-1).reshape(n, 5)
    valid = np.ones((h, w, 5), bool)
    valid[0, :, 0] = False
    valid[:, 0, 1] = False
    valid[:, -1, 3] = False
    valid[-1, :, 4] = False
    valid = valid.reshape(n, 5)
    del north, west, centre
    idx = np.int32 if 5 * n < 2**31 else np.int64
    indptr = np.zeros(n + 1, idx)
    np.cumsum(valid.sum(axis=1), out=indptr[1:])
    flat = np.flatnonzero(valid).astype(idx)
    rows, ks = np.divmod(flat, idx(5))
    del flat
    delta = np.array([-w, -1, 0, 1, w], dtype=idx)
    indices = rows + delta[ks]
    del rows, ks
    data = vals[valid]
    A = sp.csr_array((data, indices, indptr), shape=(n, n))
    A.has_sorted_indices = True
    return A


_CACHE = {}


def frame(shape):
    """Grey image in [0, 1] and hole-filled depth (m), resized to `shape`."""
    if shape not in _CACHE:
        grey = rgb2gray(imread(DATA / "rgb_00000.jpg"))
        depth = imread(DATA / "sync_depth_00000.png").astype(float) / 1000.0
        missing = depth == 0
        nearest = ndimage.distance_transform_edt(
            missing, return_distances=False, return_indices=True)
        depth = depth[tuple(nearest)]
        if shape != grey.shape:
            grey = resize(grey, shape, order=1, anti_aliasing=False)
            depth = resize(depth, shape, order=1, anti_aliasing=False)
        _CACHE.clear()
        _CACHE[shape] = (grey, depth)
    return _CACHE[shape]


def observations(shape, seed=0):
    _, depth = frame(shape)
    rng = np.random.default_rng(seed)
    mask = rng.random(shape) < 0.05
    return mask, depth


def quad_system(shape, delta):
    mask, depth = observations(shape)
    a = mask * 1.0 + delta
    A = assemble(shape, a, 1.0, 1.0)
    b = (mask * depth).ravel()
    return A, b


def image_system(shape, delta=1e-2, kappa=10.0):
    grey, _ = frame(shape)
    mask, depth = observations(shape)
    wx = np.zeros(shape)
    wx[:, :-1] = np.exp(-kappa * np.abs(np.diff(grey, axis=1)))
    wy = np.zeros(shape)
    wy[:-1, :] = np.exp(-kappa * np.abs(np.diff(grey, axis=0)))
    A = assemble(shape, mask * 1.0 + delta, wx, wy)
    return A, (mask * depth).ravel()


def irls_weights(z, eps=1e-4, lo=1e-2, hi=1e4):
    gx = np.zeros_like(z)
    gx[:, :-1] = np.diff(z, axis=1)
    gy = np.zeros_like(z)
    gy[:-1, :] = np.diff(z, axis=0)
    w = np.clip(1.0 / np.maximum(np.hypot(gx, gy), eps), lo, hi)
    return w


def irls_systems(shape, steps=3, delta=1e-2):
    """The IRLS sequence (computed once with the grid solver)."""
    mask, depth = observations(shape)
    a = mask * 1.0 + delta
    b = (mask * depth).ravel()
    A = assemble(shape, a, 1.0, 1.0)
    z, _ = solve_spd(A, b, shape, rtol=RTOL)
    systems = []
    for _ in range(steps):
        w = irls_weights(z.reshape(shape))
        A = assemble(shape, a, w, w)
        systems.append(A)
        z, _ = solve_spd(A, b, shape, rtol=RTOL, interpolation="operator")
    return systems, b, (float(w.min()), float(w.max()))


# --------------------------------------------------------------------------
# methods: name -> (setup(A, shape) -> preconditioner, update(prec, A) or None)
# --------------------------------------------------------------------------
def _pyamg_rs(A, shape):
    import pyamg

    return pyamg.ruge_stuben_solver(A, max_coarse=500, coarse_solver="splu")


def _pyamg_sa(A, shape):
    import pyamg

    return pyamg.smoothed_aggregation_solver(A, max_coarse=500, coarse_solver="splu")


METHODS = {
    "grid-bilinear": (lambda A, s: GridMultigrid(A, s), lambda m, A: m.update(A)),
    "grid-operator": (lambda A, s: GridMultigrid(A, s, interpolation="operator"),
                      lambda m, A: m.update(A)),
    "grid-operator-2": (
        lambda A, s: GridMultigrid(A, s, interpolation="operator", sweeps=2),
        lambda m, A: m.update(A)),
    "pyamg-rs": (_pyamg_rs, None),
    "pyamg-sa": (_pyamg_sa, None),
}


def run_pcg(method, A, b, shape):
    """Setup + PCG solve; returns a dict of measurements."""
    setup, _ = METHODS[method]
    rss = reset_peak()
    t0 = time.perf_counter()
    prec = setup(A, shape)
    t1 = time.perf_counter()
    x, info = solve_spd(A, b, shape, rtol=RTOL, preconditioner=prec,
                        maxiter=3000)
    t2 = time.perf_counter()
    peak = peak_since(rss)
    return dict(setup=t1 - t0, solve=t2 - t1, iters=str(info.iterations),
                relres=float(np.linalg.norm(b - A @ x) / np.linalg.norm(b)),
                peak=peak, prec=prec)


def run_spsolve(A, b, shape):
    rss = reset_peak()
    t0 = time.perf_counter()
    x = spla.spsolve(sp.csc_matrix(A), b)
    t1 = time.perf_counter()
    peak = peak_since(rss)
    return dict(setup=0.0, solve=t1 - t0, iters="-",
                relres=float(np.linalg.norm(b - A @ x) / np.linalg.norm(b)),
                peak=peak, prec=None)


def run_irls(method, systems, b, shape):
    setup, update = METHODS[method]
    rss = reset_peak()
    t_setup = t_solve = 0.0
    iters, rel = [], []
    prec = None
    for A in systems:
        t0 = time.perf_counter()
        if prec is None or update is None:
            prec = setup(A, shape)
        else:
            update(prec, A)
        t1 = time.perf_counter()
        x, info = solve_spd(A, b, shape, rtol=RTOL, preconditioner=prec,
                            maxiter=3000)
        t2 = time.perf_counter()
        t_setup += t1 - t0
        t_solve += t2 - t1
        iters.append(str(info.iterations))
        rel.append(float(np.linalg.norm(b - A @ x) / np.linalg.norm(b)))
    return dict(setup=t_setup, solve=t_solve, iters="/".join(iters),
                relres=max(rel), peak=peak_since(rss), prec=prec)


def best_of(fn, repeat):
    runs = [fn() for _ in range(repeat)]
    best = min(runs, key=lambda r: r["setup"] + r["solve"])
    best["peak"] = max(r["peak"] for r in runs)
    return best


# --------------------------------------------------------------------------
# table
# --------------------------------------------------------------------------
HEADER = (f"{'grid':>10} {'case':<12} {'method':<16} {'setup s':>8} {'solve s':>8} "
          f"{'total s':>8} {'CG its':>10} {'rel.res':>8} {'us/px':>7} {'peak MB':>8} "
          f"{'x spsolve':>9} {'x RS':>6} {'x SA':>6}")


def print_rows(shape, case, results):
    n = shape[0] * shape[1]
    totals = {m: r["setup"] + r["solve"] for m, r in results.items()}
    for m, r in results.items():
        t = totals[m]

        def ratio(ref):
            return f"{totals[ref] / t:.1f}" if ref in totals and ref != m else "-"

        print(f"{f'{shape[1]}x{shape[0]}':>10} {case:<12} {m:<16} {r['setup']:8.3f} "
              f"{r['solve']:8.3f} {t:8.3f} {r['iters']:>10} {r['relres']:8.1e} "
              f"{1e6 * t / n:7.3f} {r['peak']:8.0f} {ratio('spsolve'):>9} "
              f"{ratio('pyamg-rs'):>6} {ratio('pyamg-sa'):>6}", flush=True)


def bench(scales, repeat, methods):
    summary = {}
    for scale in scales:
        f = int(round(np.sqrt(scale)))
        shape = (BASE[0] * f, BASE[1] * f)
        rep = repeat if scale == 1 else 1
        cases = [("quad d=1e-2", lambda: quad_system(shape, 1e-2)),
                 ("quad d=1e-4", lambda: quad_system(shape, 1e-4)),
                 ("image", lambda: image_system(shape))]
        for case, make in cases:
            A, b = make()
            results = {}
            if scale == 1:
                results["spsolve"] = best_of(lambda: run_spsolve(A, b, shape), 1)
            for m in methods:
                results[m] = best_of(lambda: run_pcg(m, A, b, shape), rep)
            print_rows(shape, case, results)
            summary[(scale, case)] = results
            if scale == 1 and case == "quad d=1e-2":
                print("\n" + repr(results["grid-bilinear"]["prec"]) + "\n", flush=True)
            del A, b
        systems, b, (wmin, wmax) = irls_systems(shape)
        results = {m: best_of(lambda: run_irls(m, systems, b, shape), rep)
                   for m in methods}
        print_rows(shape, "irls x3", results)
        print(f"{'':>10} (IRLS weights in the last step span {wmin:.2g} .. {wmax:.2g}; "
              "setup = first build + updates)", flush=True)
        summary[(scale, "irls x3")] = results
        # re-setup cost: update() vs a fresh build for the last IRLS system
        for m in ("grid-bilinear", "grid-operator"):
            if m not in methods:
                continue
            mg = GridMultigrid(systems[0], shape,
                               interpolation=m.split("-")[1])
            t_up = min(_timed(lambda: mg.update(systems[-1])) for _ in range(rep))
            t_new = min(_timed(lambda: GridMultigrid(
                systems[-1], shape, interpolation=m.split("-")[1])) for _ in range(rep))
            print(f"{'':>10} {m}: update() {t_up:.3f} s vs fresh build {t_new:.3f} s",
                  flush=True)
        del systems
        print(flush=True)
    return summary


def _timed(fn):
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def scaling_report(summary, methods):
    print("time per pixel relative to 640x480 (target <= 1.5):")
    scales = sorted({k[0] for k in summary})
    cases = sorted({k[1] for k in summary}, key=lambda c: list(k[1] for k in summary).index(c))
    for case in cases:
        for m in methods:
            base = summary.get((1, case), {}).get(m)
            if base is None:
                continue
            tb = (base["setup"] + base["solve"]) / (BASE[0] * BASE[1])
            cells = []
            for s in scales[1:]:
                r = summary.get((s, case), {}).get(m)
                if r is None:
                    continue
                t = (r["setup"] + r["solve"]) / (BASE[0] * BASE[1] * s)
                cells.append(f"{s}x: {t / tb:.2f}")
            print(f"  {case:<12} {m:<16} " + "  ".join(cells))


# --------------------------------------------------------------------------
# 8-megapixel memory check (fresh process)
# --------------------------------------------------------------------------
def mem8mp(method):
    shape = (2448, 3264)  # 7.99 megapixels
    n = shape[0] * shape[1]
    rng = np.random.default_rng(0)
    mask = rng.random(shape) < 0.05
    z = 1.0 + rng.random(shape)
    A = assemble(shape, mask * 1.0 + 1e-2, 1.0, 1.0)
    b = (mask * z).ravel()
    del mask, z
    peak_assembly = _status("VmHWM")
    rss_system = reset_peak()
    t0 = time.perf_counter()
    setup, _ = METHODS[method]
    prec = setup(A, shape)
    t1 = time.perf_counter()
    x, info = solve_spd(A, b, shape, rtol=RTOL, preconditioner=prec)
    t2 = time.perf_counter()
    rel = np.linalg.norm(b - A @ x) / np.linalg.norm(b)
    nbytes = A.data.nbytes + A.indices.nbytes + A.indptr.nbytes
    print(f"8MP {shape[1]}x{shape[0]} {method}: setup {t1 - t0:.2f} s, solve {t2 - t1:.2f} s, "
          f"{info.iterations} CG its, rel.res {rel:.1e}, {1e6 * (t2 - t0) / n:.3f} us/px; "
          f"RSS with A, b built {rss_system:.0f} MB (A alone {nbytes / 2**20:.0f} MB; "
          f"assembly peak {peak_assembly:.0f} MB), peak RSS during setup + solve "
          f"{_status('VmHWM'):.0f} MB", flush=True)


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python bench/perf_multigrid.py",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 4, 16],
                        help="pixel-count multiples of 640x480 (squares: 1, 4, 16)")
    parser.add_argument("--repeat", type=int, default=3,
                        help="repeats at 640x480 (best time kept)")
    parser.add_argument("--methods", nargs="+", default=list(METHODS),
                        choices=list(METHODS))
    parser.add_argument("--mem8mp", metavar="METHOD", nargs="?", const="all",
                        help="only run the 8-megapixel memory check")
    parser.add_argument("--no-mem8mp", action="store_true",
                        help="skip the 8-megapixel memory check")
    args = parser.parse_args(argv)
    if args.mem8mp is not None and args.mem8mp != "all":
        mem8mp(args.mem8mp)
        return 0
    if args.mem8mp is None:
        print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs; "
              f"rtol {RTOL:g}")
        print(HEADER)
        summary = bench(args.sizes, args.repeat, args.methods)
        scaling_report(summary, args.methods)
    if not args.no_mem8mp:
        for m in ("grid-bilinear", "grid-operator"):
            subprocess.run([sys.executable, __file__, "--mem8mp", m], check=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
