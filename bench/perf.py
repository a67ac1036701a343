"""Performance benchmark: same-run ratios on a real 640x480 NYU frame (``docs/performance.md``).

Command, from the repository root (about 25 minutes on 2 cores, 8 of them the 8-MP L1 run; ``--quick`` less)::

    python -m bench.perf            # full run, rewrites docs/performance.md
    python -m bench.perf --quick    # shorter reference runs, no 8-MP L1 run,
                                    # prints only (add --write to write the doc)
    python -m bench.perf --render   # the doc again from docs/performance.json
                                    # (the last full run's numbers), no measuring

Everything runs in this one process (the 8-megapixel memory figures in fresh
child processes, so that their peak is their own).  BLAS is limited to one
thread before numpy is imported (:func:`bench.blas.one_blas_thread`): a
multithreaded OpenBLAS on a shared machine slows short vector operations by an
amount that depends on the other users' load, for ours and the SciPy
references alike.

Problems (frame ``nyu_metric3d/00000``, 5 % of the valid pixels observed,
``sample_depth(..., fraction=0.05, seed=0)``):

1. *Quadratic*: :data:`QUADRATIC_WEIGHTS` (a 13-point system); the
   normal equations ``A z = b`` of :meth:`Objective.normal_equations` are
   assembled once (time reported separately); ``scipy.sparse.linalg.spsolve``
   on them vs ``solve(..., solver="amg")`` (geometric multigrid set-up + PCG to
   ``‖b − Az‖ ≤ 1e-8 ‖b‖`` from the nearest-neighbour fill).  A second,
   5-point system (:data:`PAPER_QUADRATIC`, the paper's quadratic terms) goes
   the same path; the parts of one solve (set-up, V-cycle, product) are timed
   apart.
2. *L1*: the weights :data:`L1_WEIGHTS` (γ = 0.01; relative to the data scale:
   depths are ~1-10 m and the L1 ("edge") term is then ~37 % of F at the
   optimum, so it shapes the solution).  The reference value ``F*`` is the
   best of a long ADMM run (``tol = 1e-7``) and every other run; ours is
   ``solver="auto"`` with default options; L-BFGS-B (SciPy, on the smoothed
   objective, ``l1_smoothing`` default) runs with a generous budget and its
   time to reach ``F ≤ F*(1 + 1e-6)`` is read from its history; if it never
   does, the ratio is reported as a lower bound ``budget / ours``.
3. *Hole filling*: the raw depth of the same frame (holes = NaN → 0) with
   ``colorization_fill`` vs the per-pixel port :mod:`bench.naive_colorization`
   (loop assembly + spsolve); best of 7 fills against best of 2 naive runs,
   interleaved (the fill uses two threads, the naive port one).
4. *Scaling*: image and depth resized to 2× and 4× per side (4× and 16×
   pixels); the quadratic solve of 1. (set-up + solve) and the whole
   ``complete_depth`` call; the L1 solve of 2. at 2× per side; peak
   memory of a whole ``complete_depth`` call on an 8-MP frame (3264x2448)
   measured in a fresh process started before the others (``VmHWM``, image
   decoding included).

The report is rendered by :mod:`bench.perf_report`.  May import :mod:`sparsedepth` and its
subpackages (``sparsedepth.holes``, ``sparsedepth.solvers``, ``sparsedepth.linalg``),
numpy, scipy, scikit-image, :mod:`bench.harness`, :mod:`bench.naive_colorization` and :mod:`bench.perf_report`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse.linalg as spla  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.holes import colorization_fill  # noqa: E402
from sparsedepth.solvers import solve  # noqa: E402

from . import harness as H  # noqa: E402
from . import naive_colorization, perf_report  # noqa: E402
from .harness import timed  # noqa: E402

REPO = H.REPO
FRAME = "nyu_metric3d/00000"
FRACTION = 0.05
SEED = 0
#: The fixed L1 weight set of the gamma > 0 target: the paper's objective with its own weights, written out so
#: that the row does not move when the defaults do.
L1_WEIGHTS = sd.Weights.paper(alpha=1.0, beta=0.1, gamma=0.01, delta=1e-3, kappa=10.0)
#: The 13-point image-weighted quadratic problem of every quadratic row (first- and second-order smoothness weighted by
#: the image's edges, a weak prior to the nearest fill, no modelling option), written out so that the rows do not move
#: when the defaults do.  The defaults' own solve is measured by ``python -m bench.speed`` (its stopping rule) and
#: ``python -m bench.scaling`` (time per pixel and memory).
QUADRATIC_WEIGHTS = sd.Weights(alpha=1.0, beta=0.0, gamma=0.0, delta=0.000131, kappa=25.0, beta_image=0.00673,
                               beta_second=0.000286, beta_second_image=0.039, edge_sigma=0.0, fill_contrast=0.0,
                               beta_local_linear=0.0)
#: The paper's quadratic terms alone (5-point stencil), for comparison with :data:`QUADRATIC_WEIGHTS`.
PAPER_QUADRATIC = sd.Weights.paper(alpha=1.0, beta=0.1, gamma=0.0, delta=1e-3, kappa=10.0)
REL = 1e-6
MP8 = (2448, 3264)
#: Raw results of the last full run (``--render`` rewrites the report from them).
RESULTS = REPO / "docs" / "performance.json"


def load_problem(scale=1, shape=None):
    """Frame (optionally resized ``scale`` times per side or to ``shape``), sparse depth and mask."""
    fr = sd.load_shared_frame(FRAME)
    image, depth = fr.image, fr.depth
    if scale != 1 or shape is not None:
        from skimage.transform import resize

        h, w = depth.shape
        out = (h * scale, w * scale) if shape is None else shape
        image = (resize(image, out, order=1, anti_aliasing=False) * 255).astype(np.uint8)
        valid = resize(np.isfinite(depth).astype(float), out, order=0) > 0.5
        depth = resize(np.nan_to_num(depth), out, order=0)
        depth = np.where(valid & (depth > 0), depth, np.nan)
    sparse, mask = sd.sample_depth(depth, fraction=FRACTION, seed=SEED)
    return image, depth, sparse, mask


def first_time_below(result, target):
    """Time of the first history entry with objective <= target, else None."""
    for rec in result.history:
        if rec.objective <= target:
            return rec.time
    return None


# --------------------------------------------------------------------------
# 1. quadratic problem
# --------------------------------------------------------------------------
def bench_quadratic(image, sparse, mask, weights, label, rows, *, run_spsolve=True):
    """Our multigrid solve of the quadratic system against ``spsolve`` and PyAMG; appends one row to ``rows``."""
    (obj, coarse, _), t_build = timed(sd.build_objective, image, sparse, mask, weights=weights)
    (A, b, _), t_asm = timed(obj.normal_equations)
    x0 = coarse.ravel().copy()
    ours = []
    for _ in range(3):  # best of 3: the machine is shared
        (out, rt), _ = timed(solve, obj, x0, solver="amg", tol=1e-8)
        ours.append(rt)
    t_ours = min(ours)
    (out_amg, t_pyamg), _ = timed(solve, obj, x0, solver="amg", tol=1e-8, options={"preconditioner": "amg"})
    rel = float(np.linalg.norm(b - A @ out.z) / np.linalg.norm(b))
    row = dict(problem=label, n=obj.size, nnz=A.nnz, build=t_build, assemble=t_asm, ours=t_ours,
               ours_iters=out.iterations, ours_rel=rel, pyamg=t_pyamg, pyamg_iters=out_amg.iterations,
               F_ours=obj.value(out.z))
    # the parts of one solve: set-up (best of 3), one V-cycle, one product with A (best of 5 each); the 0.3 s goal
    # leaves (0.3 - set-up) / (V-cycle + product) PCG iterations
    from sparsedepth.linalg.multigrid import GridMultigrid

    row["setup"] = H.best_of(3, GridMultigrid, A, obj.shape, interpolation="auto")
    mg = GridMultigrid(A, obj.shape, interpolation="auto")
    double = GridMultigrid(A, obj.shape, interpolation="auto", fine_precision="double", coarse_precision="double")
    cycles, cycles_double = [], []
    for _ in range(5):  # the default float32 V-cycle against the same cycle in float64, interleaved
        cycles.append(timed(mg.vcycle, b)[1])
        cycles_double.append(timed(double.vcycle, b)[1])
    row["vcycle"], row["vcycle_double"] = min(cycles), min(cycles_double)
    row["matvec"] = H.best_of(5, A.__matmul__, b)
    del mg, double
    if run_spsolve:
        z_sp, t_sp = timed(spla.spsolve, A.tocsc(), b)
        if t_sp < 10:  # best of 2 where affordable, as ours is best of 3
            t_sp = min(t_sp, timed(spla.spsolve, A.tocsc(), b)[1])
        row.update(spsolve=t_sp, ratio=t_sp / t_ours, maxdiff=float(np.abs(out.z - z_sp).max()),
                   F_spsolve=obj.value(z_sp))
    rows.append(row)
    return row


# --------------------------------------------------------------------------
# 2. L1 problem
# --------------------------------------------------------------------------
def bench_l1(image, sparse, mask, quick):
    """Ours, a long reference ADMM, L-BFGS-B with a time budget (and IRLS) on the L1 problem."""
    w = L1_WEIGHTS
    obj, coarse, _ = sd.build_objective(image, sparse, mask, weights=w)
    runs = {}
    ours = []
    for _ in range(2):
        res, _ = timed(sd.complete_depth, image, sparse, mask, weights=w, solver="auto")
        ours.append(res)
    runs["ours"] = min(ours, key=lambda r: r.runtime)
    ref_tol = 1e-6 if quick else 1e-7
    runs["reference"] = sd.complete_depth(image, sparse, mask, weights=w, solver="admm", tol=ref_tol, max_iter=3000)
    budget = 60.0 if quick else 300.0

    def stop_after_budget(state):
        if state.time > budget:
            raise StopIteration

    runs["lbfgsb"] = sd.complete_depth(image, sparse, mask, weights=w, solver="lbfgsb", max_iter=100000,
                                       callback=stop_after_budget, options={"maxfun": 200000})
    if not quick:
        runs["irls"] = sd.complete_depth(image, sparse, mask, weights=w, solver="irls", tol=1e-9)
    F_best = min(min(rec.objective for rec in r.history) for r in runs.values())
    F_best = min(F_best, *(r.objective for r in runs.values()))
    target = F_best * (1 + REL)
    o = runs["ours"]
    t_ours = first_time_below(o, target)
    lb = runs["lbfgsb"]
    t_lb = first_time_below(lb, target)
    out = dict(F_best=F_best, terms=runs["reference"].terms, ours_time=o.runtime, ours_F=o.objective,
               ours_rel=(o.objective - F_best) / F_best, ours_iters=o.iterations, ours_solver=o.solver,
               ours_reached=t_ours is not None, lbfgsb_time=lb.runtime, lbfgsb_F=lb.objective,
               lbfgsb_rel=(lb.objective - F_best) / F_best, lbfgsb_iters=lb.iterations,
               lbfgsb_reached=t_lb is not None, lbfgsb_t_to_target=t_lb,
               ref_time=runs["reference"].runtime, ref_rel=(runs["reference"].objective - F_best) / F_best)
    if "irls" in runs:
        ir = runs["irls"]
        out.update(irls_time=ir.runtime, irls_rel=(ir.objective - F_best) / F_best,
                   irls_t_to_target=first_time_below(ir, target))
    if t_ours is not None:
        out["ratio"] = (t_lb if t_lb is not None else lb.runtime) / o.runtime
        out["ratio_is_lower_bound"] = t_lb is None
    return out


# --------------------------------------------------------------------------
# 3. colorization hole fill
# --------------------------------------------------------------------------
def bench_colorization(quick):
    """Best of 7 fills against best of 2 naive runs (1 with ``quick``), interleaved: 3, naive, 2, naive, 2."""
    fr = sd.load_shared_frame(FRAME)
    raw = np.nan_to_num(fr.depth)
    naive = naive_colorization
    fast, slow = [], []
    for n_fast, run_naive in ((3, True), (2, not quick), (2, False)):
        for _ in range(n_fast):
            out, t = timed(colorization_fill, fr.image, raw)
            fast.append(t)
        if run_naive:
            ref, t_naive = timed(naive.fill_depth_colorization, fr.image / 255.0, raw)
            slow.append(t_naive)
    return dict(fast=min(fast), fast_median=float(np.median(fast)), naive=min(slow), naive_runs=slow,
                ratio=min(slow) / min(fast), maxdiff=float(np.abs(out - ref).max()), holes=float(np.mean(raw == 0)))


# --------------------------------------------------------------------------
# 4. scaling and memory
# --------------------------------------------------------------------------
def bench_scaling(scales, rounds=3):
    """Quadratic solve (set-up + PCG) at several sizes, rounds interleaved, best per size."""
    w = QUADRATIC_WEIGHTS
    problems = {}
    for s in scales:
        image, _, sparse, mask = load_problem(scale=s)
        obj, coarse, _ = sd.build_objective(image, sparse, mask, weights=w)
        obj.normal_equations()
        problems[s] = (image, sparse, mask, obj, coarse)
    best = {s: (np.inf, 0) for s in scales}
    for _ in range(rounds):  # interleaved, so a busy spell of the machine hits every size
        for s in scales:
            obj, coarse = problems[s][3], problems[s][4]
            (out, rt), _ = timed(solve, obj, coarse.ravel().copy(), solver="amg", tol=1e-8)
            if rt < best[s][0]:
                best[s] = (rt, out.iterations)
    rows = []
    for s in scales:
        image, sparse, mask, obj, _ = problems[s]
        res, t_total = timed(sd.complete_depth, image, sparse, mask, weights=w)
        rows.append(dict(scale=s, n=obj.size, solve=best[s][0], iters=best[s][1], total=t_total, F=res.objective))
    return rows


def bench_l1_scaling(scale=2):
    """The L1 solve (``solver='admm'``, default options) at 640x480 and at ``scale``× per side: time per pixel."""
    rows = []
    for s in (1, scale):
        image, _, sparse, mask = load_problem(scale=s)
        obj, coarse, _ = sd.build_objective(image, sparse, mask, weights=L1_WEIGHTS)
        (out, rt), _ = timed(solve, obj, coarse.ravel().copy(), solver="admm")
        rows.append(dict(scale=s, n=obj.size, seconds=rt, iters=out.iterations, converged=out.converged))
    return rows


def _peak_rss_mb():
    """Peak resident memory of this process image in MB.

    ``VmHWM`` of ``/proc/self/status`` where it exists: ``ru_maxrss`` survives
    ``exec``, so a child started from a large parent would report the
    parent's size.
    """
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def child_memory(mode):
    """Run one complete_depth on an 8-MP frame in this (fresh) process; print JSON."""
    image, _, sparse, mask = load_problem(shape=MP8)
    w = QUADRATIC_WEIGHTS if mode == "quadratic" else L1_WEIGHTS
    res, t = timed(sd.complete_depth, image, sparse, mask, weights=w)
    peak = _peak_rss_mb()
    print(json.dumps(dict(mode=mode, n=int(image.shape[0] * image.shape[1]), seconds=t, peak_mb=peak,
                          solver=res.solver, converged=res.converged, iterations=res.iterations)))


def memory_8mp(mode):
    """Peak memory of one 8-MP ``complete_depth`` (``mode`` ``"quadratic"`` or ``"l1"``) in a fresh process."""
    proc = subprocess.run([sys.executable, "-m", "bench.perf", "--child-memory", mode], capture_output=True,
                          text=True, cwd=REPO)
    if proc.returncode != 0:
        return dict(mode=mode, error=proc.stderr.strip().splitlines()[-1] if proc.stderr else "failed")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def machine():
    """CPU, cores, Python and library versions, date and BLAS threads of this run (stored with the results)."""
    return dict(cpu=H.cpu_model(), cores=os.cpu_count(), python=platform.python_version(), numpy=H.version("numpy"),
                scipy=H.version("scipy"), pyamg=H.version("pyamg"), date=datetime.date.today().isoformat(),
                blas_threads=H.blas_threads())


def report(**results) -> str:
    """``docs/performance.md`` from the results of a run (:func:`bench.perf_report.report` with our L1 weights)."""
    return perf_report.report(**results, l1_weights=L1_WEIGHTS)


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m bench.perf", description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter reference runs, no 16x / 8-MP L1 runs")
    parser.add_argument("--write", action="store_true", help="write docs/performance.md (default unless --quick)")
    parser.add_argument("--render", action="store_true",
                        help=f"rewrite docs/performance.md from the results of the last full run ({RESULTS.name}) "
                             "without measuring (after editing the report's text)")
    parser.add_argument("--child-memory", choices=("quadratic", "l1"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child_memory:
        child_memory(args.child_memory)
        return 0
    if args.render:
        saved = json.loads(RESULTS.read_text())
        (REPO / "docs" / "performance.md").write_text(report(**saved) + "\n")
        return 0
    command = H.command_line("perf", ["--quick"] if args.quick else [])
    info = machine()
    print(json.dumps(info))
    # the 8-MP memory runs first, while this process is small (see _peak_rss_mb)
    mem = [memory_8mp("quadratic")]
    if not args.quick:
        mem.append(memory_8mp("l1"))
    print("memory:", mem, flush=True)
    image, depth, sparse, mask = load_problem()
    quad = []
    r = bench_quadratic(image, sparse, mask, QUADRATIC_WEIGHTS, "13-point image-weighted, γ = 0", quad)
    print("quadratic:", r, flush=True)
    r = bench_quadratic(image, sparse, mask, PAPER_QUADRATIC, "paper's terms (5-point), γ = 0", quad,
                        run_spsolve=not args.quick)
    print("quadratic 5-point:", r, flush=True)
    l1 = bench_l1(image, sparse, mask, args.quick)
    print("l1:", l1, flush=True)
    col = bench_colorization(args.quick)
    print("colorization:", col, flush=True)
    scaling = bench_scaling((1, 2) if args.quick else (1, 2, 4))
    print("scaling:", scaling, flush=True)
    l1_scaling = bench_l1_scaling()
    print("l1 scaling:", l1_scaling, flush=True)
    results = dict(quad=quad, l1=l1, col=col, scaling=scaling, l1_scaling=l1_scaling, mem=mem, info=info,
                   command=command)
    write = args.write or not args.quick
    if write:  # the raw results first: a failing report can be redone with --render
        (REPO / "docs").mkdir(exist_ok=True)
        RESULTS.write_text(json.dumps(results, indent=1, default=float) + "\n")
    text = report(**results)
    print(text)
    if write:
        (REPO / "docs" / "performance.md").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
