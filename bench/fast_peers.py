"""The fast filters people use for depth at camera rate, as baselines: FGS normalized convolution and IP-Basic.

* **FGS** - OpenCV's fast global smoother (``cv2.ximgproc.fastGlobalSmootherFilter``, Min et al. 2014) as a
  normalized convolution: the filter of ``depth · mask`` divided by the filter of ``mask``, both guided by the
  image.  Settings: ``lambda`` and ``sigma_color``.
* **IP-Basic** - the morphological fill of Ku, Harakeh and Waslander (CRV 2018, "In defense of classical image
  processing"), re-implemented here with OpenCV after its ``fill_in_fast``: depth inverted (``d_max − d``, so
  dilation keeps the nearest surface), a dilation with a custom kernel, a closing with a 5x5 kernel, empty pixels
  filled from a 7x7 dilation, then from a 31x31 one, a 5x5 median blur and a 5x5 Gaussian (or bilateral)
  blur of the valid pixels, inverted back; any pixel still empty gets the nearest fill (in place of the
  original's extension of the top row of values upwards, a LiDAR-specific step).  Settings: the dilation kernel
  and the final blur.

Each is tuned on :data:`bench.frames.TUNE_FRAMES` only (every ``TUNE_STEP``-th row and column, like
``bench.tune``, 5 % observed, seed 0): the setting of lowest mean RMSE / nearest-fill RMSE of a small grid
(:data:`FGS_GRID`, :data:`IPBASIC_GRID`) is then timed and scored on the report frames at full size, beside the
nearest fill and ``complete_depth`` (default, with ``tol=1e-8``, the previous stop, and ``quality="fast"``).
The fast mode against FGS frame by frame is :mod:`bench.fast_mode`, which uses :func:`fgs_fill`.  The library
never imports ``cv2``; without ``opencv-contrib-python-headless`` (the ``bench`` extra) these rows are skipped and the
report says so.

Run through :mod:`bench.speed` (``python -m bench.speed``), which writes ``docs/speed.md`` and
``docs/figures/speed_accuracy.png``.

May import :mod:`sparsedepth`, numpy, :mod:`bench.frames`, :mod:`bench.harness`, OpenCV and (for the figure)
matplotlib.
"""

from __future__ import annotations

import itertools
import time
import warnings

import numpy as np

import sparsedepth as sd

from . import frames as frame_list
from . import harness as H

try:  # the benchmark-only extra
    import cv2
except ImportError:  # pragma: no cover - depends on the environment
    cv2 = None

#: Settings searched for FGS: ``(lambda, sigma_color)`` (20).
FGS_GRID = tuple(itertools.product((1.0, 3.0, 10.0, 30.0, 100.0), (5.0, 10.0, 20.0, 40.0)))
#: Settings searched for IP-Basic: ``(dilation kernel, final blur)`` (18).
IPBASIC_GRID = tuple(itertools.product(("full3", "full5", "full7", "cross5", "diamond5", "diamond7"),
                                       ("gaussian", "bilateral", "none")))
#: Subsampling of the tuning frames, observed fraction and seed of the tuning.
TUNE_STEP, TUNE_FRACTION, TUNE_SEED = 2, 0.05, 0
#: Observed fractions and seed of the reported rows.
FRACTIONS, SEED = (0.05, 0.01), 0
#: Where the figure goes.
FIGURE = H.DOCS / "figures" / "speed_accuracy.png"


def available() -> bool:
    """True when OpenCV with the contrib module ``ximgproc`` is importable."""
    return cv2 is not None and hasattr(cv2, "ximgproc")


def fgs_fill(image, sparse, mask, *, lam, sigma_color, fill=True):
    """FGS normalized convolution: ``FGS(d · m) / FGS(m)`` guided by ``image`` (uint8).

    Where ``FGS(m) <= 1e-6`` (far from every sample) the quotient is undefined: those pixels get the nearest fill
    (``fill=True``) or 0 (``fill=False``, the bare filter, for timing).
    """
    guide = np.ascontiguousarray(image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2))
    m = mask.astype(np.float32)
    d = np.where(mask, sparse, 0.0).astype(np.float32)
    num = cv2.ximgproc.fastGlobalSmootherFilter(guide, d, lam, sigma_color)
    den = cv2.ximgproc.fastGlobalSmootherFilter(guide, m, lam, sigma_color)
    ok = den > 1e-6
    out = np.where(ok, num / np.where(ok, den, 1.0), 0.0).astype(np.float64)
    if fill and not ok.all():
        out[~ok] = sd.nearest_fill(sparse, mask)[~ok]
    return out


def _kernel(name):
    size = int(name[-1])
    if name.startswith("full"):
        return np.ones((size, size), np.uint8)
    r = size // 2
    ii, jj = np.mgrid[-r:r + 1, -r:r + 1]
    if name.startswith("cross"):
        return ((ii == 0) | (jj == 0)).astype(np.uint8)
    return (np.abs(ii) + np.abs(jj) <= r).astype(np.uint8)  # diamond


def ipbasic_fill(image, sparse, mask, *, kernel, blur):
    """IP-Basic-style fill (see the module docstring); ``image`` is not used (the method ignores it)."""
    depth = np.where(mask, sparse, 0.0).astype(np.float32)
    d_max = float(depth.max()) * 1.1 + 1e-6
    inv = np.where(depth > 0, d_max - depth, 0.0).astype(np.float32)
    inv = cv2.dilate(inv, _kernel(kernel))
    inv = cv2.morphologyEx(inv, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
    for size in (7, 31):
        empty = inv < 1e-6
        grown = cv2.dilate(inv, np.ones((size, size), np.uint8))
        inv[empty] = grown[empty]
    valid = inv > 1e-6
    med = cv2.medianBlur(inv, 5)
    inv[valid] = med[valid]
    if blur == "gaussian":
        smooth = cv2.GaussianBlur(inv, (5, 5), 0)
        inv[valid] = smooth[valid]
    elif blur == "bilateral":
        smooth = cv2.bilateralFilter(inv, 5, 1.5 * d_max / 100.0, 2.0)
        inv[valid] = smooth[valid]
    out = np.where(inv > 1e-6, d_max - inv, 0.0).astype(np.float64)
    holes = out <= 0
    if holes.any():
        out[holes] = sd.nearest_fill(sparse, mask)[holes]
    return out


def _fast(image, sparse, mask):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        return sd.complete_depth(image, sparse, mask, quality="fast")


#: ``complete_depth(quality="fast")``.
FAST = H.Method("sparsedepth (fast)", _fast, ("complete", "fast"))
def fgs_method(lam, sigma_color) -> H.Method:
    return H.Method(f"FGS (λ={lam:g}, σ={sigma_color:g})",
                    lambda image, sparse, mask: fgs_fill(image, sparse, mask, lam=lam, sigma_color=sigma_color),
                    ("fgs", lam, sigma_color))


def ipbasic_method(kernel, blur) -> H.Method:
    return H.Method(f"IP-Basic ({kernel}, {blur})",
                    lambda image, sparse, mask: ipbasic_fill(image, sparse, mask, kernel=kernel, blur=blur),
                    ("ipbasic", kernel, blur))


def tune(make, grid, frames) -> tuple:
    """The setting of ``grid`` with the lowest mean RMSE / nearest RMSE over ``frames``; ``(setting, score, all)``."""
    scores = {}
    for setting in grid:
        method = make(*setting)
        ratios = []
        for f in frames:
            rec = H.evaluate(method, f, fraction=TUNE_FRACTION, seed=TUNE_SEED)
            ref = H.evaluate(H.NEAREST, f, fraction=TUNE_FRACTION, seed=TUNE_SEED)
            ratios.append(rec.metrics.rmse / ref.metrics.rmse)
        scores[setting] = float(np.mean(ratios))
    best = min(scores, key=scores.get)
    return best, scores[best], scores


def _tuning_frames(quick):
    if quick:
        return H.quick_frames()
    names = frame_list.available(frame_list.TUNE_FRAMES)
    return [H.load_frame(n, TUNE_STEP) for n in names]


def plot(points, path):
    """``points``: ``[(label, fraction, mean time, mean RMSE ratio)]`` → a log-time scatter."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    markers = {FRACTIONS[0]: "o", FRACTIONS[-1]: "s"}
    labels = sorted({p[0] for p in points})
    colours = {label: plt.cm.tab10(i % 10) for i, label in enumerate(labels)}
    for label, fraction, t, ratio in points:
        ax.scatter(t, ratio, marker=markers.get(fraction, "^"), color=colours[label], s=50,
                   label=f"{label}, {fraction:.0%}")
    ax.set_xscale("log")
    ax.set_xlabel("time per frame (s, log scale)")
    ax.set_ylabel("RMSE / nearest-fill RMSE (lower is better)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    ax.set_title("Speed and accuracy on the report frames")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_section(args, argv, figure=None) -> tuple[str, list]:
    """The fast-peers section of ``docs/speed.md`` for the parsed ``args`` of :mod:`bench.speed`.

    The figure goes to ``figure``; by default to :data:`FIGURE`, and nowhere in quick mode.
    """
    started = time.perf_counter()
    frames = H.get_frames(args)
    methods = [H.NEAREST, H.ours("sparsedepth (default)"), H.ours("sparsedepth (tol=1e-8)", tol=1e-8), FAST]
    tuning_note = ""
    if available():
        tune_frames = _tuning_frames(args.quick)
        fgs_best, fgs_score, _ = tune(fgs_method, FGS_GRID, tune_frames)
        ip_best, ip_score, _ = tune(ipbasic_method, IPBASIC_GRID, tune_frames)
        methods += [fgs_method(*fgs_best), ipbasic_method(*ip_best)]
        tuning_note = (
            f"Tuned on {', '.join(f.name for f in tune_frames)} (step {TUNE_STEP}, {TUNE_FRACTION:.0%}, seed "
            f"{TUNE_SEED}): FGS over {len(FGS_GRID)} settings (λ × σ_color), best λ = {fgs_best[0]:g}, σ_color = "
            f"{fgs_best[1]:g} (mean RMSE ratio {fgs_score:.3f} on the tuning frames); IP-Basic over "
            f"{len(IPBASIC_GRID)} settings (kernel × blur), best {ip_best[0]}, {ip_best[1]} ({ip_score:.3f}). "
            f"OpenCV {cv2.__version__}.")
    else:
        tuning_note = ("**OpenCV (`opencv-contrib-python-headless`, the `bench` extra) is not installed: the FGS "
                       "and IP-Basic rows are left out.**")
    records = H.evaluate_all(methods, frames, [SEED], fractions=FRACTIONS)
    rows, points = [], []
    ref_name = methods[-2].name if available() else H.NEAREST.name  # FGS
    for fraction in FRACTIONS:
        recs = [r for r in records if r.sampling == fraction]
        nearest = {r.frame: r for r in recs if r.method == H.NEAREST.name}
        ref = {r.frame: r for r in recs if r.method == ref_name}
        for m in methods:
            mine = [r for r in recs if r.method == m.name]
            ratio = float(np.mean([r.metrics.rmse / nearest[r.frame].metrics.rmse for r in mine]))
            t = float(np.mean([r.runtime for r in mine]))
            t_ref = sum(r.runtime for r in mine) / max(sum(ref[r.frame].runtime for r in mine), 1e-12)
            rows.append([f"{fraction:.0%}", m.name, f"{ratio:.3f}", f"{t * 1e3:.0f}", f"{t_ref:.1f}"])
            points.append((m.name, fraction, t, ratio))
    body = H.markdown_table(["observed", "method", "RMSE / nearest", "time (ms, mean)", f"time × {ref_name}"],
                            rows)
    figure_note = ""
    figure = figure if figure is not None or args.quick else FIGURE
    if figure is not None:
        try:
            plot(points, figure)
            figure_note = f"\n\n![speed and accuracy](figures/{figure.name})"
        except ImportError:  # pragma: no cover - matplotlib is in the bench extra
            figure_note = "\n\n(matplotlib missing: no figure.)"
    body += ("\n\nThe fast mode against FGS frame by frame, at full size and 640x480, 1 / 5 / 10 % observed, with the "
             "targets of issue 22 item 2: `python -m bench.fast_mode` → [`fast_mode.md`](fast_mode.md).")
    notes = (f"Seed {SEED}. RMSE / nearest: mean over the frames of the RMSE on the hidden valid pixels divided by "
             f"the nearest fill's on the same input. Time: wall time of one call per frame and fraction (ours: "
             f"`complete_depth` with the objective's set-up; the filters: the OpenCV calls and the conversions, and "
             f"for FGS the nearest fill of the pixels where its normalized convolution is 0/0), "
             f"on a shared 2-core machine, so the ratio column (same run) is the number to compare. {tuning_note}")
    text = H.section("Fast filters beside ours", command=H.command_line("speed", argv), frames_=frames,
                     seeds=[SEED], body=body + figure_note, notes=notes, elapsed=time.perf_counter() - started)
    return text, rows
