"""Time per pixel of the default and fast modes from 0.3 to 5 megapixels, and their 8-MP peak memory (docs/scaling.md).

Command, from the repository root (about 15 minutes on 2 cores; ``--quick`` a
smoke test on small sizes that prints only)::

    nice -n 5 python -m bench.scaling
    python -m bench.scaling --quick

What is measured
----------------
* *Modes.*  ``default``: ``sd.complete_depth(image, sparse, mask)``, whose
  γ = 0 solve keeps ``A`` as CSR below
  :attr:`~sparsedepth.limits.MemoryLimits.stencil_form_pixels` and as a
  :class:`~sparsedepth.grid.stencil.SymmetricStencil` from there on;
  ``default, stencil form at every size``: the same call with the stencil
  form at every size (see :func:`_stencil_form`); ``fast``:
  ``quality="fast"``.
* *Time per pixel.*  Frame ``nyu_metric3d/00000`` (640x480), and the same
  frame resized to 1280x960 and 2560x1920 (image bilinear, depth nearest,
  as :func:`bench.perf.load_problem`), 5 % of the valid pixels observed
  (``seed=0``).  The modes are timed in this one process, rounds
  interleaved over modes and sizes so that a busy spell of the shared
  machine hits every size; the median of the rounds per mode and size is
  divided by the pixel count and reported as a ratio to the 640x480 time
  per pixel of the same mode.  BLAS runs on one thread
  (:func:`bench.blas.one_blas_thread`).
* *Where the default mode's time goes.*  One more call per size timed by
  :func:`sparsedepth.profiling.phase_times`: the exclusive time of each
  phase (the prior fill, the assembly, the multigrid set-up, the iterations,
  the certificate, ...).
* *Peak memory.*  One ``complete_depth`` call per mode on the frame resized to
  3264x2448 (8 megapixels) in a fresh process each (``VmHWM``: the process's
  own peak, reading and resizing the frame included), started before this
  process grows.

May import :mod:`sparsedepth`, :mod:`bench.perf` and :mod:`bench.harness`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import contextlib  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.profiling import PHASES, phase_times  # noqa: E402

from . import harness as H  # noqa: E402
from . import perf  # noqa: E402

DOC = H.REPO / "docs" / "scaling.md"
SIZES = ((480, 640), (960, 1280), (1920, 2560))
QUICK_SIZES = ((120, 160), (240, 320))
MODES = {"default": {}, "default, stencil form at every size": {}, "fast": {"quality": "fast"}}
#: the mode that runs the default solve with ``Objective.normal_equations`` answering in the stencil form
STENCIL_MODE = "default, stencil form at every size"
@contextlib.contextmanager
def _stencil_form(on=True):
    """The γ = 0 solve keeps ``A`` in symmetric stencil form at every size while this is active.

    :func:`sparsedepth.solvers.quadratic.system_form` takes it from
    :attr:`~sparsedepth.limits.MemoryLimits.stencil_form_pixels` on (the
    ``default`` mode); this mode lowers that limit to one pixel.
    """
    if not on:
        yield
        return
    from sparsedepth.limits import limited

    with limited(stencil_form_pixels=1):
        yield


def _complete(problem, mode):
    image, _, sparse, mask = problem
    with warnings.catch_warnings(), _stencil_form(mode == STENCIL_MODE):
        warnings.simplefilter("ignore")  # the clamp warning of resized frames
        start = time.perf_counter()
        result = sd.complete_depth(image, sparse, mask, **MODES[mode])
        return result, time.perf_counter() - start


def _load(shape):
    return perf.load_problem() if shape == (480, 640) else perf.load_problem(shape=shape)


def time_per_pixel(sizes, rounds):
    """Median seconds per mode and size over ``rounds`` interleaved rounds, and the iterations of the last."""
    problems = {s: _load(s) for s in sizes}
    seconds = {(m, s): [] for m in MODES for s in sizes}
    iterations = {}
    for r in range(rounds):
        for m in MODES:
            for s in sizes:
                result, t = _complete(problems[s], m)
                seconds[(m, s)].append(t)
                iterations[(m, s)] = result.iterations
                print(f"round {r}: {m} {s[1]}x{s[0]}: {t:.2f} s, {result.iterations} iterations", flush=True)
    rows = []
    for m in MODES:
        base = float(np.median(seconds[(m, sizes[0])])) / (sizes[0][0] * sizes[0][1])
        for s in sizes:
            median = float(np.median(seconds[(m, s)]))
            rows.append(dict(mode=m, shape=s, seconds=median, runs=seconds[(m, s)],
                             ratio=median / (s[0] * s[1]) / base, iterations=iterations[(m, s)]))
    return rows


def default_parts(sizes):
    """The exclusive seconds of each phase (:mod:`sparsedepth.profiling`) of one default call per size."""
    rows = []
    for s in sizes:
        problem = _load(s)
        with phase_times() as times:
            _complete(problem, "default")
        rows.append(dict(shape=s, total=times.wall, other=times.outside(), **times))
    return rows


def child_memory(mode):
    """One ``complete_depth`` of ``mode`` on the 8-MP frame in this (fresh) process; prints JSON."""
    problem = perf.load_problem(shape=perf.MP8)
    result, t = _complete(problem, mode)
    print(json.dumps(dict(mode=mode, seconds=t, peak_mb=perf._peak_rss_mb(), iterations=result.iterations,
                          depth_sum=float(np.sum(result.depth)))))


def memory_8mp(mode):
    proc = subprocess.run([sys.executable, "-m", "bench.scaling", "--child-memory", mode], capture_output=True,
                          text=True, cwd=H.REPO)
    if proc.returncode != 0:
        return dict(mode=mode, error=proc.stderr.strip().splitlines()[-1] if proc.stderr else "failed")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def report(rows, parts, memory, *, command, rounds, elapsed) -> str:
    sizes = sorted({r["shape"] for r in rows})
    header = ["mode", *(f"{w}x{h} ({h * w / 1e6:.1f} MP)" for h, w in sizes)]
    table = []
    for m in MODES:
        cells = []
        for r in (r for r in rows if r["mode"] == m):
            cells.append(f"{r['ratio']:.2f} ({r['seconds']:.2f} s, {r['iterations']} it.)")
        table.append([m, *cells])
    part_names = [name for name in PHASES if any(name in p for p in parts)] + ["other"]
    part_header = ["size", "total (s)", *(f"{p} (s)" for p in part_names), "prior fill per pixel"]
    base = parts[0].get("prior fill", 0.0) / (parts[0]["shape"][0] * parts[0]["shape"][1]) if parts else 1.0
    part_rows = []
    for p in parts:
        h, w = p["shape"]
        part_rows.append([f"{w}x{h}", f"{p['total']:.2f}", *(f"{p.get(n, 0.0):.2f}" for n in part_names),
                          f"{p.get('prior fill', 0.0) / (h * w) / base:.2f}" if base else "–"])
    mem_rows = [[m["mode"], f"{m['peak_mb']:.0f}" if "peak_mb" in m else m.get("error", "?"),
                 f"{m['seconds']:.1f}" if "seconds" in m else ""] for m in memory]
    lines = ["# Scaling with the image size", "",
             "Written by `python -m bench.scaling` (see `bench/scaling.py` for what is measured and how); do not "
             "edit by hand.", "", H.machine_markdown(), "", f"Command: `{command}`", "",
             "## Time per pixel", "",
             f"Median of {rounds} interleaved rounds per mode and size (one process, BLAS on one thread), divided "
             "by the pixel count, as a ratio to the time per pixel of the same mode at the smallest size (seconds "
             "and iterations in brackets). Goal: within 1.2 up to 5 megapixels.", "",
             H.markdown_table(header, table), "",
             "Where one default call's time goes (the exclusive time of each phase of "
             "`sparsedepth.profiling.phase_times()`; other: the time in no phase; the last column is the prior "
             "fill's time per pixel relative to the smallest size):", "",
             H.markdown_table(part_header, part_rows), "",
             "## Peak memory at 8 megapixels", "",
             "One `complete_depth` call on the frame resized to 3264x2448, each mode in a fresh process (`VmHWM`, "
             "reading and resizing the frame included). Goal: below 2048 MB.", "",
             H.markdown_table(["mode", "peak (MB)", "time (s)"], mem_rows), "",
             f"Wall time of this run: {elapsed:.0f} s.", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.scaling", description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="two small sizes, one round, no 8-MP runs; prints only")
    p.add_argument("--rounds", type=int, default=3, help="interleaved rounds per mode and size (median kept)")
    p.add_argument("--write", action="store_true", help="write docs/scaling.md (default without --quick)")
    p.add_argument("--child-memory", choices=tuple(MODES), help=argparse.SUPPRESS)
    p.add_argument("--memory-only", action="store_true", help="only the 8-MP peak memory of each mode; prints only")
    args = p.parse_args(argv)
    if args.child_memory:
        child_memory(args.child_memory)
        return 0
    start = time.perf_counter()
    command = H.command_line("scaling", ["--quick"] if args.quick else [])
    memory = [] if args.quick else [memory_8mp(m) for m in MODES]  # first, while this process is small
    print("memory:", memory, flush=True)
    if args.memory_only:
        return 0
    sizes = QUICK_SIZES if args.quick else SIZES
    rounds = 1 if args.quick else max(3, args.rounds)
    rows = time_per_pixel(sizes, rounds)
    parts = default_parts(sizes)
    text = report(rows, parts, memory, command=command, rounds=rounds, elapsed=time.perf_counter() - start)
    print(text)
    if args.write or not args.quick:
        H.write_text(DOC, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
