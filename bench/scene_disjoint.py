"""Accuracy measured scene-disjoint: leave-one-scene-out over every shared frame, on the input patterns users have.

Run from the repository root::

    python -m bench.scene_disjoint --out docs/scene_disjoint.md --readme README.md   # ~30 min of one core
    python -m bench.scene_disjoint --quick                                           # a smoke run, seconds

Inputs: every shared frame with ground truth (:func:`sparsedepth.list_shared_frames`), at half resolution
(``bench.frames.load(name, step=2)``), grouped by scene (:func:`bench.frames.scene_of`); the patterns of
:data:`PATTERNS` drawn by :func:`sparsedepth.sample_depth` with seeds 0, 1, 2.  Every method is scored by RMSE and
MAE over the valid ground-truth pixels it was not given (:func:`sparsedepth.depth_metrics`), as a ratio to the
nearest fill's on the same input.

Methods: ``default`` (``complete_depth`` with the library's defaults as they are at run time); ``LOSO-tuned``: for
each held-out scene, the configuration of :func:`configurations` (a small grid of the default's knobs) with the
lowest mean RMSE ratio over the inputs of every *other* scene, scored on the held-out scene (:func:`loso_choice`);
``colorization`` (the Levin / NYU-toolbox fill) with its ``alpha`` chosen the same leave-one-scene-out way among
:data:`COLORIZATION_ALPHAS`; ``linear`` (``griddata``); ``fast`` (``quality="fast"``); and ``best``
(``quality="best"``) when the library accepts it.

Every score is cached in ``bench/.cache/scene_disjoint.json`` (by frame, pattern, seed, step and method, a
configuration by its weights), so the leave-one-scene-out choice is table arithmetic and a rerun computes only what
is missing (``--fresh`` recomputes everything; delete the file after a change of the solver).

May import :mod:`sparsedepth`, numpy, :mod:`bench.blas`, :mod:`bench.frames` and :mod:`bench.harness`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import os  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.objective.weights import observed_fraction  # noqa: E402

from . import frames as frame_list  # noqa: E402
from .harness import machine_markdown  # noqa: E402

#: ``(label, sample_depth keywords)`` of every input pattern.  Keypoints carry the SfM-like corruption of
#: ``bench/colmap_scene.py`` and ``bench/outliers.py`` (1 % relative noise, 2 % outliers scaled by 0.7-1.3); the
#: holes (a depth sensor's missing pixels, 70 % of the valid pixels kept) are the dense input, above 10 % observed
#: on every frame whose ground truth covers more than 15 % of the pixels.
PATTERNS = (
    ("uniform 1 %", dict(pattern="uniform", fraction=0.01)),
    ("uniform 5 %", dict(pattern="uniform", fraction=0.05)),
    ("keypoints 500", dict(pattern="keypoints", count=500, noise=0.01, outliers=0.02, outlier_range=(0.7, 1.3))),
    ("keypoints 2000", dict(pattern="keypoints", count=2000, noise=0.01, outliers=0.02, outlier_range=(0.7, 1.3))),
    ("scan lines 8", dict(pattern="scan_lines", spacing=8)),
    ("scan lines 16", dict(pattern="scan_lines", spacing=16)),
    ("holes 0.7", dict(pattern="holes", fraction=0.7)),
)
#: The patterns of ``--quick``.
QUICK_PATTERNS = ("uniform 5 %", "scan lines 8")
#: The frames of ``--quick`` (two small frames of two scenes).
QUICK_FRAMES = ("nyu_mmseg_pseudo/bookstore_0001d_00001", "middlebury2001/tsukuba")
SEEDS = (0, 1, 2)
STEP = 2
#: The colorization fill's weight of the known depth: the toolbox's 1 and two larger values.
COLORIZATION_ALPHAS = (1.0, 10.0, 100.0)
#: The targets of issue 46 (mean RMSE ratio to nearest of the defaults, leave-one-scene-out).
TARGET_UNIFORM, TARGET_ALL = 0.68, 0.72
CACHE = Path(__file__).resolve().parent / ".cache" / "scene_disjoint.json"
#: Bumped when a score's meaning changes, so that old cache entries are not read.
CACHE_VERSION = 1
MARK_START, MARK_END = "<!-- scene-disjoint:start -->", "<!-- scene-disjoint:end -->"
DEFAULT, TUNED, COLOR = "default", "LOSO-tuned", "colorization (LOSO α)"


# --------------------------------------------------------------------------------------------------- configurations

def scan_line_like(mask) -> bool:
    """True when the observed pixels lie on few rows, several per row, as a LiDAR's scan lines do.

    At most half of the rows hold an observation, and those rows hold at least 4 observations each on average
    (so a few scattered samples on a small frame are not taken for scan lines).
    """
    mask = np.asarray(mask, dtype=bool)
    rows = int(np.count_nonzero(mask.any(axis=1)))
    return 0 < rows <= 0.5 * mask.shape[0] and np.count_nonzero(mask) >= 4 * rows


def _scaled(schedule: sd.DensitySchedule, **factors) -> sd.DensitySchedule:
    """``schedule`` with each scheduled field of ``factors`` multiplied by its factor at every anchor."""
    return sd.DensitySchedule(tuple((f, {k: v * factors.get(k, 1.0) for k, v in values.items()})
                                    for f, values in schedule.anchors), schedule.base)


def configurations() -> list[tuple[str, object]]:
    """``[(label, weights_for(mask))]``: the grid the leave-one-scene-out choice picks from (the first: the defaults).

    ``weights_for`` maps an input's mask to the :class:`sparsedepth.Weights` it is solved with.  Each changes one
    knob of the defaults: the geodesic prior fill (``fill_contrast``) off, or off on scan-line-like masks only
    (:func:`scan_line_like`); the trust in the prior fill (``delta`` times 4 at every density); the image-weighted
    terms (``beta_image``, ``beta_second_image`` and the local-linear weights) halved; the schedule's dense end
    (:func:`dense_end`).
    """
    schedule = sd.DEFAULT_SCHEDULE
    image_terms = {k: 0.5 for k in ("beta_image", "beta_second_image", "beta_local_linear",
                                    "beta_local_linear_cross", "beta_local_linear_2x2") if k in schedule.scheduled}
    prior_x4 = _scaled(schedule, delta=4.0)
    image_half = _scaled(schedule, **image_terms)
    dense = dense_end(schedule)

    return [
        ("defaults", lambda mask: sd.default_weights(observed_fraction(mask))),
        ("fill_contrast 0", lambda mask: sd.default_weights(observed_fraction(mask)).replace(fill_contrast=0.0)),
        ("fill_contrast 0 on scan lines", lambda mask: (
            sd.default_weights(observed_fraction(mask)).replace(fill_contrast=0.0) if scan_line_like(mask)
            else sd.default_weights(observed_fraction(mask)))),
        ("delta x4", lambda mask: prior_x4.weights(observed_fraction(mask))),
        ("image terms x0.5", lambda mask: image_half.weights(observed_fraction(mask))),
        ("beta_second x10 at 50 %", lambda mask: dense.weights(observed_fraction(mask))),
    ]


def dense_end(schedule: sd.DensitySchedule, fraction: float = 0.5, factor: float = 10.0) -> sd.DensitySchedule:
    """``schedule`` with ``beta_second`` times ``factor`` from ``fraction`` observed up (the thin-plate smoothness
    across the large holes of a dense sensor input).

    The anchors below ``fraction`` are kept; the schedule's weights at ``fraction``, with ``beta_second`` times
    ``factor``, become the anchor there (replacing any anchor at or above it), so between the densest anchor kept
    and ``fraction`` the change is interpolated in log-density.
    """
    values = {name: getattr(schedule.weights(fraction), name) for name in schedule.scheduled}
    values["beta_second"] *= factor
    kept = tuple((f, v) for f, v in schedule.anchors if f < fraction)
    return sd.DensitySchedule(kept + ((fraction, values),), schedule.base)


def weights_key(weights: sd.Weights) -> str:
    """A short fingerprint of every field of ``weights`` (equal weights, equal key)."""
    text = json.dumps(weights.as_dict(), sort_keys=True)
    return "weights:" + hashlib.sha1(text.encode()).hexdigest()[:16]


def best_key(mask) -> str:
    """The cache key of ``quality="best"`` on an input: with the defaults' fingerprint at its observed fraction."""
    return "best|" + weights_key(sd.default_weights(observed_fraction(mask)))


def best_available() -> bool:
    """True when ``complete_depth`` accepts ``quality="best"``."""
    from sparsedepth import completion

    return "best" in getattr(completion, "QUALITIES", ())


# --------------------------------------------------------------------------------------------------- cache

class ScoreCache:
    """``{key: value}`` in a JSON file, written after every frame (a stopped run resumes where it was)."""

    def __init__(self, path: Path, fresh: bool = False):
        self.path = Path(path)
        self.data = {}
        if self.path.exists() and not fresh:
            stored = json.loads(self.path.read_text())
            if stored.get("version") == CACHE_VERSION:
                self.data = stored["scores"]

    def get(self, key):
        return self.data.get(key)

    def put(self, key, value):
        self.data[key] = value

    def save(self):
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_suffix(".tmp")
        tmp.write_text(json.dumps({"version": CACHE_VERSION, "scores": self.data}, sort_keys=True))
        os.replace(tmp, self.path)


def input_key(frame: str, pattern: str, seed: int, step: int) -> str:
    return f"{frame}|{pattern}|{seed}|step{step}"


# --------------------------------------------------------------------------------------------------- scoring

def _score(prediction, depth, mask) -> dict:
    m = sd.depth_metrics(prediction, depth, mask=~mask)
    return {"rmse": m.rmse, "mae": m.mae}


def _timed(function):
    start_cpu, start = time.process_time(), time.perf_counter()
    out = function()
    return out, time.process_time() - start_cpu, time.perf_counter() - start


def _depth_of(out):
    return out.depth if hasattr(out, "depth") else out


def score_frame(name, image, depth, patterns, seeds, step, cache: ScoreCache, *, with_best: bool, log=print) -> None:
    """Compute the missing scores of every method on every input of one frame, into ``cache``."""
    configs = configurations()
    for label, keywords in patterns:
        for seed in seeds:
            base = input_key(name, label, seed, step)
            info = cache.get(base + "|input")
            if info is not None and "skipped" in info:
                continue
            try:
                sparse, mask = sd.sample_depth(depth, image=image, seed=seed, **keywords)
            except ValueError as exc:  # fewer valid pixels than the pattern asks for
                cache.put(base + "|input", {"skipped": str(exc)})
                continue
            hidden = np.isfinite(depth) & (depth > 0) & ~mask
            if not hidden.any():
                cache.put(base + "|input", {"skipped": "no hidden valid pixel"})
                continue
            methods = {
                "nearest": lambda: sd.nearest_fill(sparse, mask),
                "linear": lambda: sd.linear_fill(sparse, mask),
                "fast": lambda: sd.complete_depth(image, sparse, mask, quality="fast"),
            }
            for alpha in COLORIZATION_ALPHAS:
                methods[f"colorization alpha={alpha:g}"] = (
                    lambda a=alpha: sd.colorization_baseline(image, sparse, mask, alpha=a))
            if with_best:  # keyed by the defaults too: the selection's candidates start from them
                methods[best_key(mask)] = lambda: sd.complete_depth(image, sparse, mask, quality="best")
            for _, weights_for in configs:
                weights = weights_for(mask)
                methods[weights_key(weights)] = lambda w=weights: sd.complete_depth(image, sparse, mask, weights=w)
            cache.put(base + "|input", {"observed": observed_fraction(mask), "samples": int(mask.sum()),
                                        "scan_line_like": bool(scan_line_like(mask))})
            for key, run in methods.items():
                if cache.get(f"{base}|{key}") is not None:
                    continue
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    out, cpu, wall = _timed(run)
                cache.put(f"{base}|{key}", {**_score(_depth_of(out), depth, mask), "cpu": cpu, "wall": wall})
            log(f"  {name} {label} seed {seed}: done", file=sys.stderr, flush=True)


def no_gain_check(name, image, depth, keywords, seed, weights) -> dict:
    """Whether ``complete_depth(..., expected_error=True)`` warns :class:`sparsedepth.NoGainWarning` on one input
    (and how many pixels the local blow-up check flags, when :mod:`sparsedepth.blowups` exists)."""
    sparse, mask = sd.sample_depth(depth, image=image, seed=seed, **keywords)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = sd.complete_depth(image, sparse, mask, weights=weights, expected_error=True)
    out = {"warns": any(issubclass(w.category, sd.NoGainWarning) for w in caught),
           "expected_rmse": float(result.expected_rmse), "expected_nearest_rmse": float(result.expected_nearest_rmse)}
    try:
        from sparsedepth.blowups import flag_blowups
    except ImportError:
        return out
    out["blowup_pixels"] = int(np.count_nonzero(flag_blowups(result.depth, sparse, mask)))
    return out


# --------------------------------------------------------------------------------------------------- tables

def loso_choice(scores, candidates, scene_of) -> dict:
    """For each scene, the candidate with the lowest mean score over the inputs of every *other* scene.

    Parameters
    ----------
    scores : mapping
        ``{(frame, input, candidate): score}`` (lower is better); ``input`` is any hashable (pattern, seed).
    candidates : sequence
        The candidates to choose from, in order of preference on ties.
    scene_of : callable
        Frame name to scene.

    Returns
    -------
    dict
        ``{scene: candidate}`` for every scene of the frames in ``scores``.

    Notes
    -----
    For a held-out scene ``S``, the choice is ``argmin_c mean{ scores[f, i, c] : scene_of(f) != S }`` over the
    inputs ``(f, i)`` that every candidate scored; the scores of ``S`` never enter it.
    """
    by_input = {}
    for (frame, item, candidate), value in scores.items():
        by_input.setdefault((frame, item), {})[candidate] = value
    complete = {k: v for k, v in by_input.items() if all(c in v for c in candidates)}
    scenes = list(dict.fromkeys(scene_of(frame) for frame, _ in by_input))
    choice = {}
    for scene in scenes:
        others = [v for (frame, _), v in complete.items() if scene_of(frame) != scene]
        means = [np.mean([v[c] for v in others]) if others else math.inf for c in candidates]
        choice[scene] = candidates[int(np.argmin(means))]
    return choice


def collect(cache: ScoreCache, frames, patterns, seeds, step, *, with_best: bool):
    """Per-input rows: ``{frame, scene, pattern, seed, observed, rmse: {method: ratio}, mae: {...}, raw...}``."""
    configs = configurations()
    rows = []
    for name, image, depth in frames:
        for label, keywords in patterns:
            for seed in seeds:
                base = input_key(name, label, seed, step)
                info = cache.get(base + "|input")
                if info is None or "skipped" in info:
                    continue
                _, mask = sd.sample_depth(depth, image=image, seed=seed, **keywords)
                near = cache.get(base + "|nearest")
                keys = {"nearest": "nearest", "linear": "linear", "fast": "fast"}
                keys.update({f"colorization α={a:g}": f"colorization alpha={a:g}" for a in COLORIZATION_ALPHAS})
                if with_best:
                    keys["best"] = best_key(mask)
                keys.update({f"config:{c}": weights_key(w(mask)) for c, w in configs})
                entry = {"frame": name, "scene": frame_list.scene_of(name), "pattern": label, "seed": seed,
                         "observed": info["observed"], "keywords": keywords, "rmse": {}, "mae": {}, "cpu": {},
                         "weights": {c: w(mask) for c, w in configs}, "computed": {}}
                for method, key in keys.items():
                    value = cache.get(f"{base}|{key}")
                    if value is None:
                        continue
                    entry["rmse"][method] = value["rmse"] / near["rmse"]
                    entry["mae"][method] = value["mae"] / near["mae"] if near["mae"] > 0 else math.nan
                    entry["cpu"][method] = value["cpu"]
                    entry["computed"][key] = value["cpu"]
                entry["rmse"][DEFAULT] = entry["rmse"][f"config:{configs[0][0]}"]
                entry["mae"][DEFAULT] = entry["mae"][f"config:{configs[0][0]}"]
                entry["cpu"][DEFAULT] = entry["cpu"][f"config:{configs[0][0]}"]
                rows.append(entry)
    return rows


def add_loso_columns(rows):
    """Add the LOSO-tuned default and the LOSO colorization to every row; returns the two ``{scene: choice}``."""
    configs = [f"config:{c}" for c, _ in configurations()]
    alphas = [f"colorization α={a:g}" for a in COLORIZATION_ALPHAS]
    scene_of = {r["frame"]: r["scene"] for r in rows}.get
    choices = {}
    for column, candidates in ((TUNED, configs), (COLOR, alphas)):
        table = {(r["frame"], (r["pattern"], r["seed"]), c): r["rmse"][c] for r in rows for c in candidates}
        choice = loso_choice(table, candidates, scene_of)
        for r in rows:
            chosen = choice[r["scene"]]
            for metric in ("rmse", "mae", "cpu"):
                r[metric][column] = r[metric][chosen]
            r.setdefault("chosen", {})[column] = chosen
        choices[column] = choice
    return choices


def _summary(rows, method, metric):
    values = [(r[metric][method], r) for r in rows if method in r[metric] and np.isfinite(r[metric][method])]
    if not values:
        return math.nan, math.nan, None
    worst_value, worst_row = max(values, key=lambda v: v[0])
    return float(np.mean([v for v, _ in values])), float(worst_value), worst_row


def _input_name(row) -> str:
    return "-" if row is None else f"`{row['frame']}` {row['pattern']} s{row['seed']}"


def _table(header, body) -> list[str]:
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + ["| " + " | ".join(r) + " |" for r in body]


def _groups(rows, patterns):
    return [(label, [r for r in rows if r["pattern"] == label]) for label, _ in patterns] + [("all patterns", rows)]


def methods_of(rows) -> list[str]:
    ordered = [DEFAULT, TUNED, "fast", "best", COLOR, "colorization α=1", "linear"]
    present = set().union(*(r["rmse"] for r in rows)) if rows else set()
    return [m for m in ordered if m in present]


def tuning_scenes() -> set:
    """The scenes of :data:`bench.frames.TUNE_FRAMES` (the defaults were fitted on their frames)."""
    return {frame_list.scene_of(name) for name in frame_list.TUNE_FRAMES}


def untuned(rows) -> list:
    """The rows of scenes without a tuning frame: the only ones on which the ``default`` column is held out."""
    return [r for r in rows if r["scene"] not in tuning_scenes()]


def targets(rows, nogain) -> list[tuple[str, float, float, bool]]:
    """``[(what, measured, target, met)]`` of issue 46's targets, for the defaults and the LOSO-tuned default.

    ``nogain`` maps ``(method, frame, pattern, seed)`` to the expected-error check of an input worse than nearest.
    """
    out = []
    for method, group, where in ((DEFAULT, rows, "every scene"), (DEFAULT, untuned(rows), "scenes without a tuning frame"),
                                 (TUNED, rows, "every scene")):
        if not group:
            continue
        uniform = [r for r in group if r["pattern"].startswith("uniform")]
        mu, _, _ = _summary(uniform, method, "rmse")
        ma, _, _ = _summary(group, method, "rmse")
        unflagged = sum(r["rmse"][method] > 1.0 and not nogain.get((method, r["frame"], r["pattern"], r["seed"]),
                                                                   {}).get("warns", False) for r in group)
        out += [(f"`{method}`, {where}: mean RMSE ratio, uniform inputs", mu, TARGET_UNIFORM, mu <= TARGET_UNIFORM),
                (f"`{method}`, {where}: mean RMSE ratio, every pattern", ma, TARGET_ALL, ma <= TARGET_ALL),
                (f"`{method}`, {where}: inputs worse than nearest (RMSE) and not flagged by `NoGainWarning`",
                 unflagged, 0, unflagged == 0)]
    return out


def in_sample_choice(rows) -> str:
    """The configuration with the lowest mean RMSE ratio over every input (every scene: not a held-out score)."""
    labels = [label for label, _ in configurations()]
    return min(labels, key=lambda c: np.mean([r["rmse"][f"config:{c}"] for r in rows]))


def readme_block(rows, patterns, page="docs/scene_disjoint.md") -> list[str]:
    """The README summary: mean / worst RMSE ratio to nearest of the defaults per pattern (at most 12 lines)."""
    groups = _groups(rows, patterns)
    held = untuned(rows)
    cells = ["{:.2f} / {:.2f}".format(*_summary(group, DEFAULT, "rmse")[:2]) for _, group in groups]
    held_cells = ["{:.2f} / {:.2f}".format(*_summary(group, DEFAULT, "rmse")[:2]) for _, group in _groups(held, patterns)]
    scenes, held_scenes = len({r["scene"] for r in rows}), len({r["scene"] for r in held})
    return ([f"Accuracy per input pattern ({len(rows)} inputs of {scenes} scenes at half resolution): RMSE of "
            "`complete_depth` with its defaults as a ratio to nearest fill's (nearest = 1.0, lower is better), "
            f"mean / worst input, over every scene and over the {held_scenes} scenes that hold no tuning frame:",
            "",
            "| scenes | " + " | ".join(label for label, _ in groups) + " |",
            "|---|" + "---|" * len(groups),
            "| every scene | " + " | ".join(cells) + " |"]
            + ([f"| {held_scenes} never tuned on | " + " | ".join(held_cells) + " |"] if held else [])
            + ["", f"MAE, per scene, the baselines and the worst inputs: [{page}]({page}) "
               "(`python -m bench.scene_disjoint --out docs/scene_disjoint.md --readme README.md`)."])


def replace_block(text: str, block_lines) -> str:
    """``text`` with the lines between :data:`MARK_START` and :data:`MARK_END` replaced by ``block_lines``.

    Raises
    ------
    ValueError
        If the markers are missing, repeated or out of order.
    """
    lines = text.split("\n")
    starts = [i for i, line in enumerate(lines) if line.strip() == MARK_START]
    ends = [i for i, line in enumerate(lines) if line.strip() == MARK_END]
    if len(starts) != 1 or len(ends) != 1 or ends[0] < starts[0]:
        raise ValueError(f"expected one {MARK_START} line followed by one {MARK_END} line")
    return "\n".join(lines[:starts[0] + 1] + list(block_lines) + lines[ends[0]:])


def report(rows, choices, patterns, frames, seeds, step, *, command, seconds, nogain, with_best) -> str:
    """The markdown page (``seconds``: the process time of every score it shows, summed)."""
    methods = methods_of(rows)
    configs = configurations()
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    lines = ["# Accuracy per scene and input pattern, leave-one-scene-out", "",
             f"Made by `{command}`: {seconds:.0f} s of process time on one core for the scores it shows "
             "(each cached once computed, so a rerun computes only what is missing).", "",
             f"Machine: {machine_markdown()}.", ""]
    lines += [
        "Protocol. Every shared frame with ground truth, subsampled by keeping one pixel in "
        f"{step}x{step} (`bench.frames.load(name, step={step})`), grouped by scene "
        "(`bench.frames.scene_of`: frames of one room, one drive or one set-up share a scene). Inputs: "
        "`sd.sample_depth(depth, image=image, seed=s, ...)` with " + "; ".join(
            f"{label}: `{_keywords(k)}`" for label, k in patterns) + f"; seeds {', '.join(map(str, seeds))}. "
        "Scores: RMSE and MAE over the valid ground-truth pixels not given to the method, divided by nearest "
        "fill's on the same input (`sd.nearest_fill`; nearest = 1.0, lower is better). `mean` is over the "
        "inputs (frame x pattern x seed), `worst` the largest ratio of one input.",
        "",
        f"Methods. `{DEFAULT}`: `complete_depth(image, sparse, mask)` with the library's defaults as they are. "
        f"`{TUNED}`: leave-one-scene-out over the configurations below: for each scene, the configuration with the "
        "lowest mean RMSE ratio over the inputs of every other scene (all patterns) is chosen and scored on that "
        f"scene, so no scene is on both sides. `{COLOR}`: `sd.colorization_baseline(image, sparse, mask, alpha=a)` "
        f"with `a` chosen the same way among {', '.join(f'{a:g}' for a in COLORIZATION_ALPHAS)} "
        "(the toolbox's own value, 1, is the column `colorization α=1`). `linear`: `sd.linear_fill`. `fast`: "
        "`complete_depth(..., quality=\"fast\")`."
        + (" `best`: `complete_depth(..., quality=\"best\")`." if with_best else
           " `quality=\"best\"` is not accepted by this version of the library, so it has no column."),
        "",
        "Configurations of the default's knobs (the first is the defaults; the fields not named are the defaults'):",
        ""]
    lines += [f"{i + 1}. {label}" for i, (label, _) in enumerate(configs)]
    lines += ["", "`fill_contrast 0 on scan lines`: the geodesic prior fill is switched off "
              "when the mask is scan-line-like (`bench.scene_disjoint.scan_line_like`: at most half of the rows "
              "hold an observation, at least 4 per such row on average); `delta x4` multiplies the prior's "
              "weight at every anchor of the density schedule; `image terms x0.5` halves `beta_image`, "
              "`beta_second_image` and the local-linear weights at every anchor; `beta_second x10 at 50 %` makes "
              "the schedule's weights at 50 % observed, with ten times their `beta_second`, the anchor there "
              "(interpolated in log-density from the densest anchor below 50 %: "
              "`bench.scene_disjoint.dense_end`; it acts only above that anchor).", ""]

    lines += ["## Summary", ""]
    tuned_scenes = sorted(tuning_scenes() & set(scenes))
    lines += [f"The defaults were fitted on the frames of {len(tuned_scenes)} of these scenes "
              f"({', '.join(f'`{s}`' for s in tuned_scenes)}: `bench/frames.py` TUNE_FRAMES), so the `{DEFAULT}` "
              "column is held out only on the other scenes (rows \"scenes without a tuning frame\"); the "
              f"`{TUNED}` choice among the configurations never sees the scene it is scored on. The density schedule's "
              "anchor at 50 % observed (`sparsedepth/objective/weights.py`, `DEFAULT_SCHEDULE`) is a configuration "
              "this leave-one-scene-out choice picked in every fold, so on the holes inputs (above 10 % observed) "
              "the `default` column has seen every scene.", ""]
    for method, group, where in ((DEFAULT, rows, "every scene"), (DEFAULT, untuned(rows), "scenes without a tuning frame"),
                                 (TUNED, rows, "every scene")):
        if not group:
            continue
        uniform = [r for r in group if r["pattern"].startswith("uniform")]
        lines.append(f"- `{method}`, {where}: mean RMSE / nearest's {_summary(uniform, method, 'rmse')[0]:.3f} on "
                     f"uniform inputs, {_summary(group, method, 'rmse')[0]:.3f} over every pattern (worst input "
                     f"{_summary(group, method, 'rmse')[1]:.3f}, {_input_name(_summary(group, method, 'rmse')[2])}); "
                     f"{sum(r['rmse'][method] > 1 for r in group)} of {len(group)} inputs worse than nearest.")
    lines += ["", "## Targets (issue 46)", ""]
    lines += _table(["what", "measured", "target", "met?"],
                    [[w, f"{m:.3f}" if isinstance(m, float) else str(m), f"<= {t:g}", "met" if ok else "missed"]
                     for w, m, t, ok in targets(rows, nogain)])
    lines += ["", "An input worse than nearest counts as flagged when `complete_depth(..., expected_error=True)` "
              "warns `sd.NoGainWarning` on it (table \"Inputs worse than nearest\" below).", ""]

    for metric, title, subset, where in (("rmse", "RMSE", rows, "every scene"),
                                         ("rmse", "RMSE", untuned(rows), "scenes without a tuning frame"),
                                         ("mae", "MAE", rows, "every scene")):
        if not subset:
            continue
        lines += [f"## {title} / nearest's, mean / worst input, per pattern, {where}", ""]
        body = []
        for label, group in _groups(subset, patterns):
            cells = []
            for m in methods:
                mean, worst, _ = _summary(group, m, metric)
                cells.append(f"{mean:.3f} / {worst:.3f}")
            body.append([label, str(len(group))] + cells)
        lines += _table(["input", "inputs"] + [f"`{m}`" for m in methods], body)
        lines += ["", f"The worst input of each cell above ({title}):", ""]
        body = []
        for label, group in _groups(subset, patterns):
            worst = [_summary(group, m, metric)[2] for m in methods]
            body.append([label] + ["-" if w is None else _input_name(w) if label == "all patterns"
                                   else f"`{w['frame']}` s{w['seed']}" for w in worst])
        lines += _table(["input"] + [f"`{m}`" for m in methods], body) + [""]

    lines += ["## Per scene (RMSE / nearest's, mean / worst over the scene's inputs)", ""]
    body = []
    for scene in scenes:
        group = [r for r in rows if r["scene"] == scene]
        names = sorted({r["frame"] for r in group})
        cells = [f"{_summary(group, m, 'rmse')[0]:.3f} / {_summary(group, m, 'rmse')[1]:.3f}" for m in methods]
        body.append([f"`{scene}`", ", ".join(f"`{n}`" for n in names), str(len(group))] + cells)
    lines += _table(["scene", "frames", "inputs"] + [f"`{m}`" for m in methods], body) + [""]

    lines += ["## Leave-one-scene-out choices", ""]
    body = [[f"`{s}`", choices[TUNED][s].removeprefix("config:"), choices[COLOR][s].removeprefix("colorization ")]
            for s in scenes]
    lines += _table(["held-out scene", f"`{TUNED}` configuration", "colorization"], body) + [""]
    lines += ["Every configuration on every scene (RMSE / nearest's, mean / worst over all inputs; a choice made "
              "here would see the scenes it is scored on, so this table is for reading, not for the headline):", ""]
    body = []
    for label, _ in configs:
        m = f"config:{label}"
        row = [label]
        for plabel, group in _groups(rows, patterns):
            mean, worst, _ = _summary(group, m, "rmse")
            row.append(f"{mean:.3f} / {worst:.3f}")
        row.append(f"{np.mean([r['cpu'][m] for r in rows]):.2f}")
        body.append(row)
    lines += _table(["configuration"] + [label for label, _ in _groups(rows, patterns)] + ["CPU s / input"], body)
    lines += ["", "CPU s / input: mean process time of one `complete_depth` call over every input (one core; "
              "indicative: the machine is shared). The configuration with the lowest mean over every scene: "
              f"{in_sample_choice(rows)}.", ""]

    lines += ["## Inputs worse than nearest", ""]
    for method in (DEFAULT, TUNED):
        worse = [r for r in rows if r["rmse"][method] > 1.0]
        worse_mae = sum(r["mae"][method] > 1.0 for r in rows)
        lines += [f"`{method}`: {len(worse)} of {len(rows)} inputs have an RMSE ratio above 1 ({worse_mae} a MAE "
                  "ratio above 1)." + (" For each, whether `complete_depth(..., expected_error=True)` (same "
                                       "weights) warns `NoGainWarning`:" if worse else ""), ""]
        if worse:
            body = []
            for r in sorted(worse, key=lambda r: -r["rmse"][method]):
                check = nogain.get((method, r["frame"], r["pattern"], r["seed"]), {})
                cells = [_input_name(r), f"{r['rmse'][method]:.3f}", f"{r['mae'][method]:.3f}",
                         f"{100 * r['observed']:.1f} %",
                         "yes" if check.get("warns") else "no",
                         f"{check.get('expected_rmse', math.nan):.3g} / {check.get('expected_nearest_rmse', math.nan):.3g}"]
                if any("blowup_pixels" in c for c in nogain.values()):
                    cells.append(str(check.get("blowup_pixels", "-")))
                body.append(cells)
            header = ["input", "RMSE ratio", "MAE ratio", "observed", "NoGainWarning", "expected RMSE / nearest's"]
            if any("blowup_pixels" in c for c in nogain.values()):
                header.append("pixels flagged by `flag_blowups`")
            lines += _table(header, body) + [""]
            flagged = sum(bool(nogain.get((method, r["frame"], r["pattern"], r["seed"]), {}).get("warns"))
                          for r in worse)
            lines += [f"{flagged} of these {len(worse)} are flagged by the expected-error warning.", ""]

    lines += ["## Frames", ""]
    body = []
    for name, image, depth in frames:
        held = [r for r in rows if r["frame"] == name and r["pattern"].startswith("holes")]
        holes = f"{100 * np.mean([r['observed'] for r in held]):.1f} %" if held else "-"
        valid = np.isfinite(depth) & (depth > 0)
        body.append([f"`{name}`", f"`{frame_list.scene_of(name)}`", f"{depth.shape[1]}x{depth.shape[0]}",
                     f"{100 * valid.mean():.1f} %", holes])
    lines += _table(["frame", "scene", "size", "valid ground truth", "observed with holes 0.7"], body) + [""]
    return "\n".join(lines)


def _keywords(keywords) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in keywords.items())


# --------------------------------------------------------------------------------------------------- main

def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help=f"frames {list(QUICK_FRAMES)}, seed 0, patterns "
                                                        f"{list(QUICK_PATTERNS)}: a smoke run")
    p.add_argument("--out", type=Path, default=None, help="write the page here (e.g. docs/scene_disjoint.md)")
    p.add_argument("--readme", type=Path, default=None,
                   help=f"replace the lines between {MARK_START} and {MARK_END} of this file with a summary")
    p.add_argument("--cache", type=Path, default=None, help=f"score cache (default {CACHE.relative_to(CACHE.parents[2])}"
                                                            "; quick runs: a file beside it)")
    p.add_argument("--fresh", action="store_true", help="ignore the cache and recompute every score")
    p.add_argument("--frames", nargs="+", default=None, help="a subset of the shared frames")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse(argv)
    if sd.shared_data_dir() is None:
        raise SystemExit("the shared frames are missing: set SPARSEDEPTH_DATA (see bench/frames.py)")
    names = list(args.frames or (QUICK_FRAMES if args.quick else sd.list_shared_frames()))
    patterns = tuple(p for p in PATTERNS if not args.quick or p[0] in QUICK_PATTERNS)
    seeds = SEEDS[:1] if args.quick else SEEDS
    cache_path = args.cache or (CACHE.with_name("scene_disjoint_quick.json") if args.quick else CACHE)
    cache = ScoreCache(cache_path, fresh=args.fresh)
    with_best = best_available()
    frames = []
    for name in names:
        image, depth = frame_list.load(name, step=STEP)
        frames.append((name, image, depth))
    for name, image, depth in sorted(frames, key=lambda f: f[2].size):
        score_frame(name, image, depth, patterns, seeds, STEP, cache, with_best=with_best)
        cache.save()
    rows = collect(cache, frames, patterns, seeds, STEP, with_best=with_best)
    choices = add_loso_columns(rows)
    nogain = {}
    for method in (DEFAULT, TUNED):
        for r in rows:
            if r["rmse"][method] <= 1.0:
                continue
            weights = r["weights"][r["chosen"][TUNED].removeprefix("config:")] if method == TUNED else \
                r["weights"][configurations()[0][0]]
            key = f"{input_key(r['frame'], r['pattern'], r['seed'], STEP)}|nogain|{weights_key(weights)}"
            if cache.get(key) is None:
                image, depth = next((im, d) for n, im, d in frames if n == r["frame"])
                cache.put(key, no_gain_check(r["frame"], image, depth, r["keywords"], r["seed"], weights))
                cache.save()
            nogain[(method, r["frame"], r["pattern"], r["seed"])] = cache.get(key)
    command = " ".join(["python", "-m", "bench.scene_disjoint", *(argv if argv is not None else sys.argv[1:])])
    seconds = sum(sum(r["computed"].values()) for r in rows)
    text = report(rows, choices, patterns, frames, seeds, STEP, command=command, seconds=seconds, nogain=nogain,
                  with_best=with_best)
    print(text)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
    if args.readme is not None:
        args.readme.write_text(replace_block(args.readme.read_text(), readme_block(rows, patterns)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
