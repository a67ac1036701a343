"""The real-time mode against the default solve and OpenCV's fast global smoother: accuracy and time (``docs/fast_mode.md``).

Command, from the repository root (about 10 minutes on 2 cores)::

    python -m bench.fast_mode            # REPORT_FRAMES at full size and at 640x480, writes docs/fast_mode.md
    python -m bench.fast_mode --quick    # two tiny frames, prints only (a smoke test)

Methods, on the same seeded samples (``sample_depth(..., fraction, seed)``) of each frame:

* ``nearest``: :func:`sparsedepth.nearest_fill` (the reference of every ratio);
* ``default``: ``complete_depth(image, sparse, mask)``;
* ``fast``: ``complete_depth(image, sparse, mask, quality="fast")``;
* ``FGS``: OpenCV's fast global smoother as normalized convolution, ``FGS(depth · mask) / FGS(mask)`` with the
  image as guide (``cv2.ximgproc``, from ``opencv-contrib-python-headless``: ``pip install -e .[bench]``; the rows
  are left out when it is missing), its ``lambda`` and ``sigma_color`` the best of a grid on
  :data:`bench.frames.TUNE_FRAMES` (mean ratio over 1, 5 and 10 %), never on the frames reported.

Accuracy is the RMSE on the valid pixels that were not observed divided by the nearest fill's on the same input
(mean over frames × seeds).  Times are the best of ``--repeat`` calls of each method on each input, the methods'
calls taking turns (:func:`interleaved_best_of`), every method timed in this one process with one BLAS thread and
one OpenCV thread (FGS's time is that of its two filter calls and the division, without the nearest fill it gives
the pixels no sample reaches); ``fast / FGS`` is the mean over inputs of the per-input ratio of the two times, the
number to compare across machines.

May import :mod:`sparsedepth`, numpy, scikit-image, :mod:`bench.frames`, :mod:`bench.blas`, :mod:`bench.fast_peers`
and :mod:`bench.harness`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import itertools  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

import sparsedepth as sd  # noqa: E402

from . import fast_peers  # noqa: E402
from . import frames as frame_list  # noqa: E402
from . import harness as H  # noqa: E402

DOC = H.REPO / "docs" / "fast_mode.md"
FRACTIONS = (0.01, 0.05, 0.10)
#: The grid of FGS settings searched on the tuning frames.
FGS_LAMBDAS = (10.0, 30.0, 100.0, 300.0, 1000.0)
FGS_SIGMAS = (2.0, 4.0, 8.0, 16.0)
#: The second size of every report frame (rows, columns).
VGA = (480, 640)


def _cv2():
    """``cv2`` (with ``ximgproc``) set to one thread, or None."""
    if not fast_peers.available():
        return None
    fast_peers.cv2.setNumThreads(1)
    return fast_peers.cv2


def fgs_fill(image, sparse, mask, *, lam, sigma):
    """:func:`bench.fast_peers.fgs_fill` (the nearest fill where no sample reaches)."""
    return fast_peers.fgs_fill(image, sparse, mask, lam=lam, sigma_color=sigma)


def _resize(frame: H.FrameData, shape) -> H.FrameData:
    """The frame resized to ``shape``: the image bilinearly, the ground truth by nearest neighbour (NaN kept)."""
    from skimage.transform import resize

    if frame.shape == tuple(shape):
        return frame
    image = (resize(frame.image, shape, order=1, anti_aliasing=True) * 255).round().astype(np.uint8)
    valid = resize(np.isfinite(frame.depth).astype(float), shape, order=0) > 0.5
    depth = resize(np.nan_to_num(frame.depth), shape, order=0, anti_aliasing=False)
    depth = np.where(valid & (depth > 0), depth, np.nan)
    return H.FrameData(f"{frame.name} @ {shape[1]}x{shape[0]}", image, depth, frame.step, frame.units)


def _ratio(dense, frame, mask, nearest_rmse):
    hidden = np.isfinite(frame.depth) & ~mask
    filled = hidden & np.isfinite(dense)
    err = np.where(filled, dense - np.nan_to_num(frame.depth), 0.0)
    # pixels a method leaves empty count with the nearest fill's value (FGS far from every sample)
    return float(np.sqrt(np.sum(err[filled] ** 2) / max(np.count_nonzero(hidden), 1))) / nearest_rmse


def _inputs(frames_, fractions, seeds):
    for frame, fraction, seed in itertools.product(frames_, fractions, seeds):
        sparse, mask = sd.sample_depth(frame.depth, fraction=fraction, seed=seed)
        nearest = sd.nearest_fill(sparse, mask)
        hidden = np.isfinite(frame.depth) & ~mask
        nearest_rmse = float(np.sqrt(np.mean((nearest[hidden] - frame.depth[hidden]) ** 2)))
        yield frame, fraction, seed, sparse, mask, nearest, nearest_rmse


def tune_fgs(frames_, seeds=(0,)):
    """``(lam, sigma, mean ratio)``: the FGS setting with the lowest mean RMSE ratio on ``frames_``."""
    inputs = list(_inputs(frames_, FRACTIONS, seeds))
    best = None
    for lam, sigma in itertools.product(FGS_LAMBDAS, FGS_SIGMAS):
        ratios = []
        for frame, _, _, sparse, mask, nearest, nearest_rmse in inputs:
            dense = fgs_fill(frame.image, sparse, mask, lam=lam, sigma=sigma)
            ratios.append(_ratio(dense, frame, mask, nearest_rmse))
        score = float(np.mean(ratios))
        if best is None or score < best[2]:
            best = (lam, sigma, score)
    return best


#: Weights the fast mode could solve with, compared on the tuning frames (``sd.FAST_WEIGHTS`` is the choice).
def weight_candidates():
    return [("`sd.FAST_WEIGHTS`", sd.FAST_WEIGHTS),
            ("`sd.DEFAULT_WEIGHTS` (the constant defaults)", sd.DEFAULT_WEIGHTS),
            ("`sd.FAST_WEIGHTS` with the geodesic fill (fill_contrast = 20)", sd.FAST_WEIGHTS.replace(fill_contrast=20.0))]


def weights_table(frames_, seeds=(0,)):
    """Markdown: each candidate's mean ratio on ``frames_`` at 1/5/10 % and its time relative to the first."""
    from sparsedepth.modes.fast import complete_fast  # the fast mode with exactly the weights given

    candidates = weight_candidates()
    ratios = {label: [] for label, _ in candidates}
    seconds = {label: 0.0 for label, _ in candidates}
    for frame, _, _, sparse, mask, nearest, nearest_rmse in _inputs(frames_, FRACTIONS, seeds):
        for label, weights in candidates:  # interleaved: the same load for each
            run = _quiet(lambda: complete_fast(frame.image, sparse, mask, weights=weights).depth)
            start = time.perf_counter()
            dense = run()
            seconds[label] += time.perf_counter() - start
            ratios[label].append(_ratio(dense, frame, mask, nearest_rmse))
    first = candidates[0][0]
    rows = [[label, f"{np.mean(ratios[label]):.4f}", f"{seconds[label] / seconds[first]:.2f}"] for label, _ in candidates]
    return H.markdown_table(["fast mode with", "mean RMSE / nearest (tuning frames)", "time / first row"], rows)


def _quiet(fn):
    def run(*args, **kwargs):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sd.ClampWarning)
            return fn(*args, **kwargs)
    return run


def measure(frames_, fractions, seeds, repeat, fgs_setting):
    """One record per input: the ratios and times of every method."""
    default = _quiet(lambda im, s, m: sd.complete_depth(im, s, m).depth)
    fast = _quiet(lambda im, s, m: sd.complete_depth(im, s, m, quality="fast").depth)
    records = []
    for frame, fraction, seed, sparse, mask, nearest, nearest_rmse in _inputs(frames_, fractions, seeds):
        rec = dict(frame=frame.name, shape=frame.shape, fraction=fraction, seed=seed)
        t0 = time.perf_counter()
        rec["default"] = _ratio(default(frame.image, sparse, mask), frame, mask, nearest_rmse)
        rec["t_default"] = time.perf_counter() - t0
        rec["fast"] = _ratio(fast(frame.image, sparse, mask), frame, mask, nearest_rmse)
        timed = {"t_fast": lambda: fast(frame.image, sparse, mask), "t_nearest": lambda: sd.nearest_fill(sparse, mask)}
        if fgs_setting is not None:
            lam, sigma = fgs_setting
            rec["fgs"] = _ratio(fgs_fill(frame.image, sparse, mask, lam=lam, sigma=sigma), frame, mask, nearest_rmse)
            # timed without the nearest fill of the pixels no sample reaches: the two filter calls and the division
            timed["t_fgs"] = lambda: fast_peers.fgs_fill(frame.image, sparse, mask, lam=lam, sigma_color=sigma,
                                                         fill=False)
        rec.update(interleaved_best_of(repeat, timed))
        records.append(rec)
        print(f"  {frame.name} {fraction:.0%} seed {seed}: default {rec['default']:.3f}, fast {rec['fast']:.3f}"
              + (f", FGS {rec['fgs']:.3f}" if "fgs" in rec else "")
              + f"; fast {rec['t_fast'] * 1e3:.0f} ms" + (f", FGS {rec['t_fgs'] * 1e3:.0f} ms" if "t_fgs" in rec else ""),
              file=sys.stderr, flush=True)
    return records


def interleaved_best_of(repeat, calls):
    """``{name: seconds}``: the shortest wall time of ``repeat`` calls of each function in ``calls``.

    The calls take turns (one of each, ``repeat`` times), so that a change of the machine's load in between
    reaches every method alike.
    """
    best = dict.fromkeys(calls, float("inf"))
    for _ in range(repeat):
        for name, fn in calls.items():
            start = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - start)
    return best


def summary_table(records, label):
    """Per observed fraction: mean ratios, mean times and the fast / FGS time ratio."""
    has_fgs = any("fgs" in r for r in records)
    header = ["size", "observed", "default", "fast", *(["FGS"] if has_fgs else []), "default (ms)", "fast (ms)",
              *(["FGS (ms)", "fast / FGS time (mean, max)"] if has_fgs else []), "fast / default time"]
    rows = []
    for fraction in sorted({r["fraction"] for r in records}):
        rs = [r for r in records if r["fraction"] == fraction]
        mean = lambda key: float(np.mean([r[key] for r in rs]))  # noqa: E731
        row = [label, f"{fraction:.0%}", f"{mean('default'):.3f}", f"{mean('fast'):.3f}"]
        if has_fgs:
            row.append(f"{mean('fgs'):.3f}")
        row += [f"{1e3 * mean('t_default'):.0f}", f"{1e3 * mean('t_fast'):.0f}"]
        if has_fgs:
            ratios = [r["t_fast"] / r["t_fgs"] for r in rs]
            row += [f"{1e3 * mean('t_fgs'):.0f}", f"{np.mean(ratios):.1f}, {np.max(ratios):.1f}"]
        row.append(f"{np.mean([r['t_fast'] / r['t_default'] for r in rs]):.3f}")
        rows.append(row)
    return H.markdown_table(header, rows)


def per_frame_table(records, fraction):
    has_fgs = any("fgs" in r for r in records)
    header = ["frame", "size", "default", "fast", *(["FGS", "fast / FGS time"] if has_fgs else [])]
    rows = []
    for name in dict.fromkeys(r["frame"] for r in records):
        rs = [r for r in records if r["frame"] == name and r["fraction"] == fraction]
        if not rs:
            continue
        row = [f"`{name}`", f"{rs[0]['shape'][1]}x{rs[0]['shape'][0]}",
               f"{np.mean([r['default'] for r in rs]):.3f}", f"{np.mean([r['fast'] for r in rs]):.3f}"]
        if has_fgs:
            row += [f"{np.mean([r['fgs'] for r in rs]):.3f}", f"{np.mean([r['t_fast'] / r['t_fgs'] for r in rs]):.1f}"]
        rows.append(row)
    return H.markdown_table(header, rows)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="two tiny frames, one seed, prints only (a smoke test)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    p.add_argument("--repeat", type=int, default=5, help="timed calls per method and input (best is kept)")
    p.add_argument("--write", action="store_true", help="write docs/fast_mode.md (default without --quick)")
    args = p.parse_args(argv)
    start = time.perf_counter()
    cv2 = _cv2()
    if args.quick:
        sizes = {"quick": H.quick_frames()}
        tune_frames = H.quick_frames()[:1]
        seeds, repeat = args.seeds[:1], 1
    else:
        report = [H.load_frame(n) for n in H.report_frame_names()]
        sizes = {"full size": report, "640x480": [_resize(f, VGA) for f in report]}
        tune_frames = [H.load_frame(n, step=2) for n in frame_list.available(frame_list.TUNE_FRAMES)]
        seeds, repeat = args.seeds, args.repeat
    fgs_setting = None
    tuned_note = ("OpenCV's `cv2.ximgproc` is not installed: the FGS rows are left out "
                  "(`pip install -e .[bench]`).")
    if cv2 is not None:
        lam, sigma, score = tune_fgs(tune_frames)
        fgs_setting = (lam, sigma)
        tuned_note = (f"FGS setting picked on the tuning frames (step 2, seed 0, 1/5/10 %): lambda = {lam:g}, "
                      f"sigma_color = {sigma:g} (mean ratio there {score:.3f}), from lambda in "
                      f"{list(FGS_LAMBDAS)} and sigma_color in {list(FGS_SIGMAS)}; OpenCV {cv2.__version__}, one "
                      "thread.")
    weights_text = weights_table(tune_frames, seeds=(0,))
    records = {label: measure(frames_, FRACTIONS, seeds, repeat, fgs_setting) for label, frames_ in sizes.items()}
    lines = ["# The real-time mode", "",
             "Written by `python -m bench.fast_mode` (see `bench/fast_mode.py` for what is measured and how); do "
             "not edit by hand.", "", H.machine_markdown(), "",
             f"Frames: {', '.join(f'`{f.name}`' for f in next(iter(sizes.values())))}; seeds "
             f"{', '.join(map(str, seeds))}; best of {repeat} timed calls per method and input.", "",
             tuned_note, "",
             "RMSE on the hidden valid pixels divided by the nearest fill's (mean over frames × seeds), mean time "
             "per frame, and the time of `quality=\"fast\"` relative to FGS and to the default solve on the same "
             "input:", ""]
    for label, recs in records.items():
        lines += [summary_table(recs, label), ""]
    for label, recs in records.items():
        lines += [f"Per frame at 5 % observed ({label}):", "", per_frame_table(recs, 0.05), ""]
    lines += ["## The fast mode's weights", "",
              "Without `weights` `quality=\"fast\"` solves with `sd.FAST_WEIGHTS`, chosen here on the tuning "
              "frames (step 2, seed 0, 1/5/10 %; each candidate run on the same inputs in turn):", "",
              weights_text, ""]
    lines += [f"Wall time of this run: {time.perf_counter() - start:.0f} s.", ""]
    text = "\n".join(lines)
    print(text)
    if args.write or not args.quick:
        H.write_text(DOC, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
