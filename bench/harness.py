"""Shared benchmark harness: frames, methods, one evaluation, aggregation, machine info, markdown.

Every benchmark script (``bench/sparsity.py``, ``ablation.py``, ``solvers.py``,
``protocol.py``, ``baselines.py``) builds on this module:

* :func:`get_frames` loads the reported frames (:data:`frames.REPORT_FRAMES`,
  never the tuning frames), optionally subsampled by ``step``; in quick mode
  it returns two tiny frames instead (a synthetic piecewise-planar scene and
  the embedded 160x120 NYU frame subsampled by 2) so that CI runs in seconds.
  Without the shared data folder the embedded Motorcycle
  (:func:`sparsedepth.load_motorcycle`, the same scene as
  ``middlebury2014/motorcycle``) stands in.
* :func:`evaluate` runs one :class:`Method` on one frame at one sparsity and
  seed, and scores it on the valid ground-truth pixels hidden from it.
  Results are cached in-process, so scripts run by ``bench/run_all.py``
  share identical runs (e.g. ours at 5 % in the sparsity and baseline tables).
* :func:`summarise` gives mean ± std over frames × seeds, and same-run time
  ratios to a reference method (Σ t / Σ t_ref over the same frames and seeds).
* :func:`machine_info` / :func:`markdown_table` / :func:`section` write the docs.

Only :func:`sparsedepth.DEFAULT_WEIGHTS` read at run time is used for "ours",
never a copy of its numbers.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import frames as frame_list  # noqa: E402  (bench/ is not a package)

import sparsedepth as sd  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
DEFAULT_SEEDS = (0, 1, 2)
FRACTIONS = (0.01, 0.05, 0.10)


# ----------------------------------------------------------------------------
# frames
# ----------------------------------------------------------------------------
@dataclass(frozen=True)
class FrameData:
    """One evaluation frame: ``image`` (H, W, 3) uint8, ``depth`` (H, W) float64, NaN = no ground truth."""

    name: str
    image: np.ndarray = field(repr=False)
    depth: np.ndarray = field(repr=False)
    step: int = 1
    units: str = "m"

    @property
    def shape(self):
        return self.depth.shape


def synthetic_frame(shape=(48, 64), seed=0) -> FrameData:
    """A piecewise-planar scene whose depth edges are image edges (for quick smoke tests)."""
    rng = np.random.default_rng(seed)
    H, W = shape
    ii, jj = np.mgrid[0:H, 0:W].astype(float)
    box = (ii > H // 4) & (ii < 3 * H // 4) & (jj > W // 3) & (jj < 2 * W // 3)
    depth = 3.0 + 0.02 * ii - 0.01 * jj
    depth = np.where(box, 1.5 + 0.005 * jj, depth)
    image = np.where(box[..., None], [200, 60, 40], [40, 90, 180]).astype(float)
    image = np.clip(image + 8 * rng.standard_normal((H, W, 3)), 0, 255).astype(np.uint8)
    return FrameData("synthetic/planes", image, depth, 1)


def quick_frames() -> list[FrameData]:
    """The tiny frames of ``--quick``: :func:`synthetic_frame` and the embedded NYU frame at step 2."""
    emb = sd.load_embedded_frame()
    depth = np.array(emb.depth, dtype=float)[::2, ::2]
    return [synthetic_frame(), FrameData("embedded/" + emb.name + " (step 2)", np.ascontiguousarray(emb.image[::2, ::2]),
                                         np.ascontiguousarray(depth), 2)]


def load_frame(name: str, step: int = 1) -> FrameData:
    """A named frame of :mod:`frames` (or ``"motorcycle (embedded)"``), subsampled by ``step``."""
    if name == "motorcycle (embedded)":
        f = sd.load_motorcycle()
        return FrameData(name, np.ascontiguousarray(f.image[::step, ::step]),
                         np.ascontiguousarray(np.array(f.depth, dtype=float)[::step, ::step]), step)
    image, depth = frame_list.load(name, step=step)
    units = "px (disparity)" if name.startswith(("middlebury2003", "middlebury2001")) else "m"
    return FrameData(name, image, depth.astype(float), step, units)


def report_frame_names(selected=None) -> list[str]:
    """REPORT_FRAMES present in the shared folder (or the embedded Motorcycle without it)."""
    names = frame_list.available(frame_list.REPORT_FRAMES)
    if not names:
        names = ["motorcycle (embedded)"]
    if selected:
        unknown = [s for s in selected if s not in names]
        if unknown:
            raise SystemExit(f"unknown or unavailable frames {unknown}; choose from {names}")
        names = list(selected)
    return names


def get_frames(args, *, filter_fn=None) -> list[FrameData]:
    """Frames for a script's parsed ``args`` (``--quick``, ``--frames``, ``--step``)."""
    if args.quick:
        return quick_frames()
    names = report_frame_names(args.frames)
    if filter_fn is not None:
        names = [n for n in names if filter_fn(n)]
    return [load_frame(n, args.step) for n in names]


# ----------------------------------------------------------------------------
# methods
# ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Method:
    """A named way of turning ``(image, sparse, mask)`` into dense depth.

    ``run`` returns a dense depth array or a :class:`sparsedepth.CompletionResult`;
    ``key`` identifies identical methods for the cache.
    """

    name: str
    run: Callable = field(repr=False, compare=False)
    key: tuple = ()


def ours(name="ours", *, weights=None, solver="auto", tol=None, max_iter=None, clip_to_observed=True) -> Method:
    """``sparsedepth.complete_depth``; ``weights=None`` reads ``sd.DEFAULT_WEIGHTS`` now.

    ``clip_to_observed=False`` keeps the solver's minimiser as it is (the solver table compares optimisers, not
    the range clamp that follows them); the range clamp's warning is not shown (its count is in the result).
    """
    w = sd.DEFAULT_WEIGHTS if weights is None else weights

    def run(image, sparse, mask):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", sd.ClampWarning)
            return sd.complete_depth(image, sparse, mask, weights=w, solver=solver, tol=tol, max_iter=max_iter,
                                     clip_to_observed=clip_to_observed)

    return Method(name, run, ("complete", w, solver, tol, max_iter, clip_to_observed))


NEAREST = Method("nearest", lambda image, sparse, mask: sd.nearest_fill(sparse, mask), ("nearest",))
LINEAR = Method("linear (griddata)", lambda image, sparse, mask: sd.linear_fill(sparse, mask), ("linear",))
BIHARMONIC = Method("biharmonic (skimage)", lambda image, sparse, mask: sd.biharmonic_fill(sparse, mask),
                    ("biharmonic",))
COLORIZATION = Method("colorization (Levin/NYU)",
                      lambda image, sparse, mask: sd.colorization_baseline(image, sparse, mask), ("colorization",))


# ----------------------------------------------------------------------------
# one evaluation
# ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Record:
    """One method on one frame at one sparsity and seed."""

    method: str
    frame: str
    sampling: object  # fraction (float) or count (int)
    seed: int
    metrics: sd.DepthMetrics
    runtime: float
    objective: float | None = None
    result: object = field(default=None, repr=False, compare=False)


_CACHE: dict = {}
#: Print one line per evaluation to stderr (set by the scripts' ``main``; off in tests).
PROGRESS = False


def sample(frame: FrameData, *, fraction=None, count=None, seed=0):
    """Seeded sparse input from the frame's valid ground truth (``sd.sample_depth``)."""
    return sd.sample_depth(frame.depth, fraction=fraction, count=count, seed=seed)


def evaluate(method: Method, frame: FrameData, *, fraction=None, count=None, seed=0, keep_result=False) -> Record:
    """Run ``method`` on ``frame`` with seeded sparse input; score on the hidden valid pixels.

    ``runtime`` is wall-clock seconds around the method call (for ours it
    includes building the objective).  Identical calls are served from an
    in-process cache.
    """
    key = (method.key, frame.name, frame.step, frame.shape, fraction, count, seed, keep_result)
    if method.key and key in _CACHE:
        rec = _CACHE[key]
        return Record(method.name, *[getattr(rec, f) for f in ("frame", "sampling", "seed", "metrics", "runtime",
                                                                "objective", "result")])
    sparse, mask = sample(frame, fraction=fraction, count=count, seed=seed)
    t0 = time.perf_counter()
    out = method.run(frame.image, sparse, mask)
    runtime = time.perf_counter() - t0
    objective = None
    if isinstance(out, sd.CompletionResult):
        objective = out.objective
        depth = out.depth
    else:
        depth = out
    metrics = sd.depth_metrics(depth, frame.depth, mask=~mask)
    rec = Record(method.name, frame.name, fraction if fraction is not None else count, seed, metrics, runtime,
                 objective, out if keep_result else None)
    if method.key:
        _CACHE[key] = rec
    if PROGRESS:
        print(f"  {method.name:>40s} {frame.name:>40s} {rec.sampling!s:>5s} seed {seed}: RMSE {metrics.rmse:.4g} "
              f"{runtime:.2f} s", file=sys.stderr, flush=True)
    return rec


# ----------------------------------------------------------------------------
# aggregation and formatting
# ----------------------------------------------------------------------------
def mean_std(values) -> tuple[float, float]:
    v = np.asarray(list(values), dtype=float)
    return float(np.mean(v)), float(np.std(v))


def fmt(mean: float, std: float | None = None, digits: int = 3) -> str:
    """``mean ± std`` with ``digits`` significant-ish decimals."""
    def one(x):
        if not np.isfinite(x):
            return str(x)
        if x != 0 and (abs(x) >= 1e4 or abs(x) < 10 ** -(digits + 1)):
            return f"{x:.{digits - 1}e}"
        return f"{x:.{digits}f}"
    return one(mean) if std is None else f"{one(mean)} ± {one(std)}"


def metric(rec: Record, name: str) -> float:
    return rec.runtime if name == "runtime" else float(getattr(rec.metrics, name))


def summarise(records, *, reference: str, metrics=("rmse", "mae", "rel", "delta1")) -> list[dict]:
    """Mean ± std per (method, sampling) over frames × seeds, plus ratios to ``reference``.

    ``rmse_ratio`` is the mean over frames × seeds of RMSE / RMSE of the
    reference on the same frame and input; ``time_ratio`` is Σ t / Σ t_ref
    over the same runs.
    """
    ref = {(r.frame, r.sampling, r.seed): r for r in records if r.method == reference}
    groups: dict = {}
    for r in records:
        groups.setdefault((r.method, r.sampling), []).append(r)
    rows = []
    for (method, sampling), recs in groups.items():
        row = {"method": method, "sampling": sampling, "n": len(recs)}
        for m in (*metrics, "runtime"):
            row[m] = mean_std(metric(r, m) for r in recs)
        pairs = [(r, ref[(r.frame, r.sampling, r.seed)]) for r in recs if (r.frame, r.sampling, r.seed) in ref]
        if pairs:
            row["rmse_ratio"] = mean_std(a.metrics.rmse / b.metrics.rmse for a, b in pairs)
            row["time_ratio"] = sum(a.runtime for a, _ in pairs) / max(sum(b.runtime for _, b in pairs), 1e-12)
        rows.append(row)
    return rows


def markdown_table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def per_frame_table(records, methods, *, value="rmse", sampling=None) -> str:
    """Mean over seeds of one metric, one row per frame, one column per method."""
    frames_ = list(dict.fromkeys(r.frame for r in records))
    rows = []
    for f in frames_:
        row = [f]
        for m in methods:
            vals = [metric(r, value) for r in records if r.frame == f and r.method == m
                    and (sampling is None or r.sampling == sampling)]
            row.append(fmt(*mean_std(vals)) if vals else "–")
        rows.append(row)
    return markdown_table(["frame", *methods], rows)


def _version(mod):
    try:
        return __import__(mod).__version__
    except Exception:  # pragma: no cover - optional packages
        return "not installed"


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine_info() -> dict:
    """CPU model, core count, OS, Python and library versions, date (UTC)."""
    return {
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "os": platform.platform(),
        "python": platform.python_version(),
        "numpy": _version("numpy"),
        "scipy": _version("scipy"),
        "pyamg": _version("pyamg"),
        "scikit-image": _version("skimage"),
        "sparsedepth": sd.__version__,
    }


def machine_markdown(info=None) -> str:
    info = machine_info() if info is None else info
    return (f"{info['date']}; {info['cpu']}, {info['cores']} cores, {info['os']}; Python {info['python']}, "
            f"NumPy {info['numpy']}, SciPy {info['scipy']}, PyAMG {info['pyamg']}, scikit-image "
            f"{info['scikit-image']}, sparsedepth {info['sparsedepth']}")


def weights_markdown(w) -> str:
    return ", ".join(f"{k} = {v:g}" for k, v in w.as_dict().items())


def frames_markdown(frames_) -> str:
    return ", ".join(f"`{f.name}` {f.shape[1]}x{f.shape[0]}" for f in frames_)


def section(title, *, command, frames_, seeds, body, notes="", elapsed=None) -> str:
    """A results section: title, the command, machine, frames, seeds, then the body."""
    lines = [f"## {title}", "", f"Command: `{command}`", "",
             f"Machine: {machine_markdown()}.", "",
             f"Frames ({len(frames_)}): {frames_markdown(frames_)}.", "",
             f"Seeds: {', '.join(map(str, seeds))}. Default weights at run time: {weights_markdown(sd.DEFAULT_WEIGHTS)}."]
    if elapsed is not None:
        lines += ["", f"Wall time of this section: {elapsed:.0f} s."]
    if notes:
        lines += ["", notes.strip()]
    lines += ["", body.strip(), ""]
    return "\n".join(lines)


def command_line(script: str, argv) -> str:
    return " ".join(["python", f"bench/{script}", *map(str, argv)])


# ----------------------------------------------------------------------------
# command line
# ----------------------------------------------------------------------------
def parser(description: str, *, default_step: int) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--quick", action="store_true",
                   help="tiny frames (synthetic + embedded NYU at step 2), one seed: a smoke test in seconds")
    p.add_argument("--step", type=int, default=default_step,
                   help=f"keep every step-th row and column of each frame (default {default_step})")
    p.add_argument("--seeds", type=int, nargs="+", default=list(DEFAULT_SEEDS), help="sampling seeds (default 0 1 2)")
    p.add_argument("--frames", nargs="+", default=None, help="subset of the REPORT frames (default: all available)")
    p.add_argument("--out", type=Path, default=None, help="write the markdown section to this file")
    return p


def script_main(run, args, argv) -> int:
    """The body of every table script's ``main``: progress lines on, ``run(argv)``, then :func:`finish`."""
    global PROGRESS
    PROGRESS = True
    text, _ = run(argv)
    finish(args, text)
    return 0


def finish(args, text: str) -> None:  # noqa: D401
    """Print the section and write it to ``--out`` if given."""
    print(text)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)


def step_note(args) -> str:
    """One sentence on how the frames were reduced."""
    if args.quick:
        return "Quick mode: tiny frames (smoke test only; not a result)."
    if args.step == 1:
        return "Frames at full resolution."
    return (f"Frames subsampled by keeping one pixel in {args.step}x{args.step} (`[::{args.step}, ::{args.step}]` of "
            "the ground truth and the image alike, no interpolation) to keep the run short.")


def seeds_of(args):
    return [args.seeds[0]] if args.quick else list(args.seeds)
