"""Multigrid interpolation for the completion systems of radius 2: bilinear against operator-dependent (collapsed).

Run (a few minutes on 2 cores)::

    python -m bench.interpolation --out docs/interpolation.md

Every report frame (subsampled by ``--step``, default 1: full size) at 5 % of its valid pixels, seed 0, with two
objectives: the library's defaults at that density and the baseline objective of ``docs/accuracy.md`` (13-point: the
second-order terms); each label gives the points of the objective's normal stencil. Each system is solved as the
default ``amg`` solve does (the hierarchy of :func:`sparsedepth.solvers.quadratic.default_hierarchy`, line
Gauss-Seidel, PCG from the prior fill, stopping at the depth rule), once with ``interpolation="bilinear"`` (what
``"auto"`` picks for these stencils) and once with ``interpolation="operator"``, which reads the radius-2 stencil
collapsed to radius 1 (:class:`sparsedepth.linalg.multigrid.stencils.CollapsedSource`); the order alternates from
one frame to the next. Columns: CG iterations at the depth rule and to the relative residual 1e-8, the wall time of
set-up + depth-rule solve, and the RMS difference of the two depth-rule solutions in units of the depth scale (the
rule's tolerance is :data:`sparsedepth.solvers.quadratic.DEFAULT_DEPTH_RTOL`). Last, the peak memory of one default
``complete_depth`` on the 8-megapixel frame of ``bench.scaling`` with each interpolation (a fresh process each, the
solve's hierarchy built by :func:`operator_hierarchy` for "operator"); not with ``--quick``.

May import :mod:`sparsedepth`, numpy, :mod:`bench.blas`, :mod:`bench.frames` and :mod:`bench.harness`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.linalg import pcg_info  # noqa: E402
from sparsedepth.linalg.multigrid import GridMultigrid  # noqa: E402
from sparsedepth.solvers import depth_unit, scaled_objective  # noqa: E402
from sparsedepth.solvers.quadratic import DEFAULT_DEPTH_RTOL, RemainingChange, system_form  # noqa: E402

from . import frames as frame_list  # noqa: E402
from . import harness as H  # noqa: E402
from .default_runtime import BASELINE  # noqa: E402

FRACTION, SEED = 0.05, 0
INTERPOLATIONS = ("bilinear", "operator")


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--step", type=int, default=1, help="keep every step-th row and column (default 1)")
    p.add_argument("--quick", action="store_true", help="one frame at step 4, no 8-MP memory runs")
    p.add_argument("--child-memory", choices=INTERPOLATIONS, help=argparse.SUPPRESS)
    p.add_argument("--out", type=Path, default=None, help="write the markdown report here")
    return p.parse_args(argv)


def solve(A, b, x0, shape, interpolation):
    """``(set-up + depth-rule seconds, depth-rule iterations, 1e-8 iterations, depth-rule solution)``."""
    start = time.perf_counter()
    mg = GridMultigrid(A, shape, interpolation=interpolation, smoother="line_gauss_seidel")
    depth = pcg_info(A, b, x0=x0, M=mg.aspreconditioner(), rtol=1e-8, maxiter=500,
                     stop=RemainingChange(b.size, DEFAULT_DEPTH_RTOL))
    seconds = time.perf_counter() - start
    residual = pcg_info(A, b, x0=x0, M=mg.aspreconditioner(), rtol=1e-8, maxiter=500)
    return seconds, depth.iterations, residual.iterations, depth.x


def operator_hierarchy(A, shape):
    """:func:`sparsedepth.solvers.quadratic.default_hierarchy` with ``interpolation="operator"``."""
    return GridMultigrid(A, shape, interpolation="operator", smoother="line_gauss_seidel")


def child_memory(interpolation):
    """One default completion of the 8-MP frame in this (fresh) process; prints JSON with its peak memory."""
    import sparsedepth.solvers.quadratic as quadratic

    from . import perf, scaling

    if interpolation == "operator":
        quadratic.default_hierarchy = operator_hierarchy
    result, seconds = scaling._complete(perf.load_problem(shape=perf.MP8), "default")
    print(json.dumps(dict(peak_mb=perf._peak_rss_mb(), seconds=seconds, iterations=result.iterations)))


def memory_8mp(interpolation):
    """``{peak_mb, seconds, iterations}`` of :func:`child_memory` run in a fresh process."""
    proc = subprocess.run([sys.executable, "-m", "bench.interpolation", "--child-memory", interpolation],
                          capture_output=True, text=True, cwd=H.REPO, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def measure(frame, weights, turn):
    """Per interpolation: ``(seconds, iterations at the depth rule, at 1e-8)``, the solutions' RMS difference and
    the points of the normal stencil."""
    sparse, mask = H.sample(frame, fraction=FRACTION, seed=SEED)
    scale = depth_unit(sparse[mask])
    objective, coarse, _ = sd.build_objective(frame.image, sparse, mask,
                                              weights=sd.resolve_weights(weights, sd.observed_fraction(mask)))
    scaled = scaled_objective(objective, scale)
    A, b, _ = scaled.normal_equations(form=system_form(scaled))
    x0 = coarse.ravel() / scale
    order = INTERPOLATIONS if turn % 2 == 0 else INTERPOLATIONS[::-1]
    out = {name: solve(A, b, x0, scaled.shape, name) for name in order}
    difference = float(np.sqrt(np.mean((out["bilinear"][3] - out["operator"][3]) ** 2)))
    return {name: out[name][:3] for name in INTERPOLATIONS}, difference, len(scaled.normal_stencil()[0])


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    if args.child_memory:
        child_memory(args.child_memory)
        return 0
    t0 = time.perf_counter()
    names = frame_list.REPORT_FRAMES
    if args.quick:
        names, args.step = ("middlebury2003/teddy",), 4
    frames = [H.load_frame(n, args.step) for n in frame_list.available(names)]
    if not frames:
        print("the shared data folder is absent: nothing to measure", file=sys.stderr)
        return 2
    rows, totals, turn = [], {}, 0
    for frame in frames:
        for name, weights in (("defaults", None), ("baseline", BASELINE)):
            per, difference, points = measure(frame, weights, turn)
            label = f"{name} ({points}-point)"
            turn += 1
            total = totals.setdefault(label, {name: np.zeros(3) for name in INTERPOLATIONS})
            for name in INTERPOLATIONS:
                total[name] += per[name]
            rows.append([f"`{frame.name}`", label,
                         *(f"{per[name][1]} / {per[name][2]}" for name in INTERPOLATIONS),
                         *(f"{per[name][0]:.2f}" for name in INTERPOLATIONS),
                         f"{per['operator'][0] / per['bilinear'][0]:.2f}", f"{difference:.1e}"])
    for label, total in totals.items():
        rows.append([f"all ({len(frames)} frames)", label,
                     *(f"{int(total[name][1])} / {int(total[name][2])}" for name in INTERPOLATIONS),
                     *(f"{total[name][0]:.2f}" for name in INTERPOLATIONS),
                     f"**{total['operator'][0] / total['bilinear'][0]:.2f}**", ""])
    header = ["frame", "objective", "bilinear: CG its depth / 1e-8", "operator: CG its depth / 1e-8",
              "bilinear: set-up + solve (s)", "operator: set-up + solve (s)", "time operator / bilinear",
              "RMS difference / depth scale"]
    lines = [
        "# Multigrid interpolation for the completion systems",
        "",
        f"Made by `{H.command_line('interpolation', argv)}` (frames subsampled by {args.step}, "
        f"{FRACTION:.0%} observed, seed {SEED}, {time.perf_counter() - t0:.0f} s).",
        "",
        H.machine_markdown(),
        "",
        __doc__.split("\n\n")[2].replace("\n", " "),
        "",
        H.markdown_table(header, rows),
        "",
    ]
    if not args.quick:
        memory = {name: memory_8mp(name) for name in INTERPOLATIONS}
        lines += ["Peak memory of the default completion of the 8-megapixel frame (`VmHWM`, a fresh process each):",
                  "", H.markdown_table(["interpolation", "peak (MB)", "time (s)", "CG iterations"], [
                      [name, f"{m['peak_mb']:.0f}", f"{m['seconds']:.1f}", str(m["iterations"])]
                      for name, m in memory.items()]), ""]
    return H.publish(lines, args.out)


if __name__ == "__main__":
    sys.exit(main())
