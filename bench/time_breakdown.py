"""Where a completion's time goes, and the default against a sparse direct solve of the simplest system.

Two sections of ``docs/speed.md`` (``python -m bench.speed``), or on their own::

    python -m bench.time_breakdown            # ~5 min on 2 cores; prints the markdown
    python -m bench.time_breakdown --quick    # a smoke run on small frames

* **Time breakdown** (:func:`breakdown_rows`): the default completion, the fast mode and the uncertainty on the
  640x480 frame of ``bench.perf`` (``nyu_metric3d/00000``, 5 % observed, seed 0) and on the same frame resized to
  2560x1920 (4.9 MP), timed by :func:`sparsedepth.profiling.phase_times`: each phase's exclusive wall time in the
  fastest of ``--repeats`` calls (one call at 4.9 MP).
* **Against a direct solve** (:func:`direct_rows`): per report frame at full size (5 % observed, seed 0), the
  default ``complete_depth`` time (best of 3) divided by the time of ``scipy.sparse.linalg.spsolve`` on the
  5-point system of the paper's quadratic terms (``bench.perf.PAPER_QUADRATIC``) of the same input (best of 2;
  assembly not timed), both in this process.

May import :mod:`sparsedepth`, numpy, scipy, :mod:`bench.blas`, :mod:`bench.harness`, :mod:`bench.perf` and
:mod:`bench.frames`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse.linalg as spla  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.profiling import PHASES, phase_times  # noqa: E402

from . import frames as frame_list  # noqa: E402
from . import harness as H  # noqa: E402
from . import perf  # noqa: E402

#: The completions broken down, as ``complete_depth`` keyword arguments.
MODES = {"default": {}, "fast": {"quality": "fast"}, "uncertainty": {"uncertainty": True}}
SIZES = ((480, 640), (1920, 2560))
QUICK_SIZES = ((120, 160), (240, 320))
#: The columns of the breakdown: a label and the phases of :data:`sparsedepth.profiling.PHASES` it sums.
COLUMNS = (("set-up", ("image terms",)), ("prior fill", ("prior fill",)), ("assembly", ("assembly",)),
           ("hierarchy", ("hierarchy",)), ("iterations", ("iterations",)), ("certificate", ("certificate",)),
           ("term values", ("term values",)), ("upsampling + sweeps", ("upsampling and sweeps",)),
           ("clamp", ("clamp",)), ("uncertainty map", ("uncertainty map",)))
assert {p for _, phases in COLUMNS for p in phases} == set(PHASES)


def _input(shape, quick):
    if quick:
        frame = sd.load_embedded_frame()
        from skimage.transform import resize

        image = (resize(frame.image, shape, order=1, anti_aliasing=False) * 255).astype(np.uint8)
        depth = resize(np.nan_to_num(np.asarray(frame.depth, dtype=float)), shape, order=0)
        depth[depth <= 0] = np.nan
        sparse, mask = sd.sample_depth(depth, fraction=perf.FRACTION, seed=perf.SEED)
        return image, sparse, mask
    image, _, sparse, mask = perf.load_problem() if shape == (480, 640) else perf.load_problem(shape=shape)
    return image, sparse, mask


def _timed(image, sparse, mask, kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the clamp warnings of a resized frame
        with phase_times() as times:
            sd.complete_depth(image, sparse, mask, **kwargs)
    return times


def breakdown_rows(sizes, repeats):
    """Per size and mode: the :class:`~sparsedepth.profiling.PhaseTimes` of the fastest of ``repeats`` calls."""
    rows = []
    for shape in sizes:
        image, sparse, mask = _input(shape, repeats == 1 and shape[0] < 480)
        n = repeats if shape[0] * shape[1] <= 1 << 20 else 1
        for mode, kwargs in MODES.items():
            runs = [_timed(image, sparse, mask, kwargs) for _ in range(n)]
            best = min(runs, key=lambda t: t.wall)
            print(f"{mode} {shape[1]}x{shape[0]}: {best.wall:.3f} s", flush=True)
            rows.append(dict(mode=mode, shape=shape, times=best))
    return rows


def breakdown_table(rows) -> str:
    header = ["mode", "size", "total (s)"] + [label for label, _ in COLUMNS] + ["other", "not iterations / iterations"]
    body = []
    for row in rows:
        t = row["times"]
        cells = [sum(t.get(p, 0.0) for p in phases) for _, phases in COLUMNS]
        iterations = t.get("iterations", 0.0)
        rest = t.wall - iterations
        body.append([row["mode"], f"{row['shape'][1]}x{row['shape'][0]}", f"{t.wall:.3f}"]
                    + [f"{c:.3f}" if c else "–" for c in cells] + [f"{t.outside():.3f}",
                                                                   f"{rest / iterations:.2f}" if iterations else "–"])
    return H.markdown_table(header, body)


def direct_rows(frames, quick=False):
    """Per frame: default time (best of 3), spsolve time of the 5-point system (best of 2), their ratio, RMSE."""
    rows = []
    for frame in frames:
        sparse, mask = sd.sample_depth(frame.depth, fraction=perf.FRACTION, seed=perf.SEED)
        objective, _, _ = sd.build_objective(frame.image, sparse, mask, weights=perf.PAPER_QUADRATIC)
        A, b, _ = objective.normal_equations()
        A = A.tocsc()
        direct = []
        for _ in range(1 if quick else 2):
            start = time.perf_counter()
            spla.spsolve(A, b)
            direct.append(time.perf_counter() - start)
        del A, b, objective
        ours = []
        for _ in range(1 if quick else 3):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", sd.ClampWarning)
                start = time.perf_counter()
                result = sd.complete_depth(frame.image, sparse, mask)
                ours.append(time.perf_counter() - start)
        hidden = np.isfinite(frame.depth) & ~mask
        rmse = float(np.sqrt(np.mean((result.depth[hidden] - frame.depth[hidden]) ** 2)))
        rows.append(dict(frame=frame.name, shape=frame.shape, direct=min(direct), ours=min(ours),
                         ratio=min(ours) / min(direct), rmse=rmse, iterations=result.iterations))
        print(f"{frame.name}: default {min(ours):.3f} s, spsolve {min(direct):.3f} s", flush=True)
    return rows


def direct_table(rows) -> str:
    body = [[f"`{r['frame']}`", f"{r['shape'][1]}x{r['shape'][0]}", f"{r['ours']:.3f}", f"{r['direct']:.3f}",
             f"{r['ratio']:.2f}", str(r["iterations"]), f"{r['rmse']:.5g}"] for r in rows]
    ratios = [r["ratio"] for r in rows]
    body.append(["mean", "", "", "", f"**{np.mean(ratios):.2f}**", "", ""])
    return H.markdown_table(["frame", "size", "default (s)", "spsolve, 5-point (s)", "default / spsolve",
                             "CG iterations", "RMSE (hidden pixels)"], body)


def run_sections(argv=(), quick=False, repeats=3) -> str:
    """The markdown of both sections."""
    started = time.perf_counter()
    frames = H.quick_frames() if quick else [H.load_frame(n) for n in frame_list.available(frame_list.REPORT_FRAMES)]
    direct = direct_rows(frames, quick)
    direct_text = H.section(
        "The default against a direct solve", command=H.command_line("speed", argv), frames_=frames,
        seeds=[perf.SEED], body=direct_table(direct), elapsed=time.perf_counter() - started,
        notes=(f"At {perf.FRACTION:.0%} observed. Default: `sd.complete_depth(image, sparse, mask)`, wall time of "
               "the whole call, best of 3. spsolve: `scipy.sparse.linalg.spsolve` (SuperLU) on `A z = b` of the "
               "paper's quadratic terms alone (data, first-order smoothness and prior, a 5-point system; "
               "`bench.perf.PAPER_QUADRATIC`), assembled beforehand and not timed, best of 2. Both in this "
               "process, so the ratio is the number to compare across machines. RMSE: of the default's depth on "
               "the hidden valid pixels (depth units)."))
    started = time.perf_counter()
    sizes = QUICK_SIZES if quick else SIZES
    breakdown = breakdown_rows(sizes, 1 if quick else repeats)
    name = "embedded NYU (resized)" if quick else f"{perf.FRAME} (whole frame, bench.perf.load_problem)"
    timed = [H.FrameData(name, np.broadcast_to(np.nan, (*shape, 3)), np.broadcast_to(np.nan, shape)) for shape in sizes]
    breakdown_text = H.section(
        "Where the time goes", command=H.command_line("speed", argv), frames_=timed, seeds=[perf.SEED],
        body=breakdown_table(breakdown),
        elapsed=time.perf_counter() - started,
        notes=(f"`{perf.FRAME}` at {perf.FRACTION:.0%} observed, at 640x480 and resized to 2560x1920 "
               "(`bench.perf.load_problem`). Each phase's exclusive wall time (seconds) as "
               "`sparsedepth.profiling.phase_times()` measures it, in the fastest of "
               f"{repeats} calls at 640x480 and of one at 2560x1920. set-up: the image terms (edge weights, the "
               "objective's terms, the depth unit); prior fill: the nearest-sample (geodesic) fill z_c; assembly: "
               "the normal equations (with the local-linear affinities, computed there); hierarchy: the multigrid "
               "set-up; iterations: the solver's loop (PCG: V-cycles and products); certificate: the duality gap "
               "of the returned depth; term values: every term at the returned depth; upsampling + sweeps: the fast "
               "mode's interpolation to the full grid and its edge-aware sweeps; uncertainty map: turning the "
               "half-sample solves into sigma; other: validation, conversions and the rest. The uncertainty's row "
               "sums its three solves (all samples, then each half) phase by phase. Last column: the time that is "
               "not an iteration over the iterations' time."))
    return "\n".join([breakdown_text, direct_text])


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small frames, one call each")
    p.add_argument("--repeats", type=int, default=3, help="calls per mode at 640x480 (default 3)")
    args = p.parse_args(argv)
    print(run_sections(argv, quick=args.quick, repeats=args.repeats))
    return 0


if __name__ == "__main__":
    sys.exit(main())
