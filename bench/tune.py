"""Weight tuning: a seeded random search over the objective's weights on the tuning frames.

The library's :data:`sparsedepth.DEFAULT_WEIGHTS` come from this script.  It
searches only :data:`frames.TUNE_FRAMES` (never the frames the tables in
``docs/results.md`` report on), at 1 %, 5 % and 10 % observed, and scores
each candidate by the RMSE and the MAE on the hidden valid pixels *divided by
the nearest-neighbour RMSE and MAE* on the same input: scale-free numbers, so
that a KITTI frame (metres up to 85) counts as much as an NYU one (metres up
to 10).  The selection score of a weight set is the mean of the two ratios
over frames × sparsities × seeds (RMSE alone favours weights that blur depth
edges, which lowers the RMSE but raises the MAE above nearest neighbour's); the best set per sparsity is reported too, to show how
much a per-sparsity choice would gain over the single default.

Search space
------------
The search is over the quadratic objective (``gamma = 0``); with ``gamma =
0`` the minimiser does not change when every weight is multiplied by the same
number, so ``alpha = 1`` fixes the scale.  The other weights are drawn
log-uniformly (or set to 0 with probability 1/3 for the optional terms) from
the ranges in :data:`SPACE`; ``kappa`` uniformly.  ``delta`` is kept at or
above 1e-4: below it the pixels far from every sample are held only by the
fourth-order smoothness, the system's conditioning degrades and the CG
iterations at full resolution grow several-fold, for no gain in accuracy
(searching down to 1e-5 does not lower the mean ratio by more than 1 %).  A few anchor candidates
are always evaluated: the reference paper's weights without its L1 term
(:data:`PAPER_WEIGHTS`), a second-order-only set, the best set of a
coarse manual exploration, and the current defaults.

The edge-aware L1 term (``gamma > 0``) is measured separately by
``--with-l1``: a few values of ``gamma`` added to the best quadratic set,
with ``gamma`` relative to the median observed depth (the L1 term is linear
in depth while the other terms are quadratic, so a fixed ``gamma`` would mean
something else on every dataset).

Run from the repository root::

    python -m bench.tune                  # ~10 min on 2 cores: writes docs/tuning.md
    python -m bench.tune --quick          # a smoke run on one tiny frame
    python -m bench.tune --with-l1        # also measure gamma > 0 (slow)

Frames are subsampled by ``--step`` (default 2) to keep the search within
minutes; the sampling density (fraction of pixels observed) is what the
weights have to suit, and it is the same at every step.

May import :mod:`sparsedepth`, numpy, :mod:`bench.frames` and :mod:`bench.harness`.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

import sparsedepth as sd

from . import frames as frame_list
from . import harness

#: Log-uniform ranges ``(low, high)`` of the searched weights (``alpha = 1``).
SPACE = {
    "beta": (1e-4, 1e-1),
    "beta_image": (1e-4, 1e-1),
    "beta_second": (1e-4, 1.0),
    "beta_second_image": (1e-3, 3.0),
    "delta": (1e-4, 1e-2),
}
#: Uniform range of ``kappa``.
KAPPA = (3.0, 25.0)
#: Terms that may be switched off entirely (probability 1/3 each).
OPTIONAL = ("beta", "beta_image", "beta_second")

#: Relative score margin within which the fastest candidate is chosen.
TIE = 0.01

#: The reference paper's objective with its own weights (its quadratic part is an anchor candidate).
PAPER_WEIGHTS = sd.Weights.paper(alpha=1.0, beta=0.1, gamma=0.01, delta=1e-3, kappa=10.0)


def candidates(n: int, seed: int) -> list[sd.Weights]:
    """Anchors plus ``n`` seeded random weight sets of the quadratic objective."""
    rng = np.random.default_rng(seed)
    out = [
        PAPER_WEIGHTS.replace(gamma=0.0),
        sd.Weights.paper(alpha=1.0, beta=0.0, gamma=0.0, delta=0.0).replace(beta_second=0.1),
        sd.Weights.paper(alpha=1.0, beta=0.0, gamma=0.0, delta=0.0).replace(beta_image=1e-3, beta_second_image=0.1),
        sd.DEFAULT_WEIGHTS.replace(gamma=0.0),
    ]
    for _ in range(n):
        values = {}
        for name, (lo, hi) in SPACE.items():
            values[name] = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
            if name in OPTIONAL and rng.random() < 1 / 3:
                values[name] = 0.0
        values["kappa"] = float(rng.uniform(*KAPPA))
        out.append(sd.Weights(alpha=1.0, gamma=0.0, **values))
    unique = []
    for w in out:
        if w not in unique:
            unique.append(w)
    return unique


def refinements(best: sd.Weights, n: int, seed: int, spread: float = 0.7) -> list[sd.Weights]:
    """``n`` seeded perturbations of ``best``: every non-zero searched weight times ``exp(N(0, spread²))``."""
    rng = np.random.default_rng(seed + 1)
    out = []
    for _ in range(n):
        values = {k: v * float(np.exp(rng.normal(0.0, spread))) for k, v in asdict(best).items()
                  if k in SPACE and v > 0}
        kappa = float(np.clip(best.kappa * np.exp(rng.normal(0.0, spread / 2)), *KAPPA))
        out.append(best.replace(kappa=kappa, **values))
    return out


def score(weights, frames, fractions, seeds, *, gamma_relative=0.0, wall=False):
    """Per (frame, fraction, seed): the mean of the RMSE and MAE ratios to nearest neighbour, the RMSE ratio alone;
    and the total solver time (with ``wall``, the wall time of the whole ``complete_depth`` calls: objective
    assembly, fills and every solve)."""
    ratios = {}
    rmse_ratios = {}
    seconds = 0.0
    for f in frames:
        for fraction in fractions:
            for s in seeds:
                sparse, mask = sd.sample_depth(f.depth, fraction=fraction, seed=s)
                w = weights
                if gamma_relative > 0:
                    w = weights.replace(gamma=gamma_relative * float(np.median(sparse[mask])))
                result, elapsed = harness.timed(sd.complete_depth, f.image, sparse, mask, weights=w, tol=1e-7)
                seconds += elapsed if wall else result.runtime
                nn = sd.depth_metrics(sd.nearest_fill(sparse, mask), f.depth, mask=~mask)
                ours = sd.depth_metrics(result.depth, f.depth, mask=~mask)
                ratios[(f.name, fraction, s)] = 0.5 * (ours.rmse / nn.rmse + ours.mae / nn.mae)
                rmse_ratios[(f.name, fraction, s)] = ours.rmse / nn.rmse
    return ratios, rmse_ratios, seconds


def _fmt(w: sd.Weights) -> str:
    return ", ".join(f"{k}={v}" if isinstance(v, str) else f"{k}={v:.3g}" for k, v in w.as_dict(used_only=True).items()
                     if v != 0 or k in ("alpha", "gamma"))


def parse_args(argv):
    """The command line of :func:`main`."""
    parser = argparse.ArgumentParser(prog="python -m bench.tune", description=__doc__.split("\n\n")[0])
    parser.add_argument("--candidates", type=int, default=40, help="random weight sets (default 40)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the search (default 0)")
    parser.add_argument("--step", type=int, default=2, help="frame subsampling (default 2)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="sampling seeds (default 0)")
    parser.add_argument("--refine", type=int, default=20,
                        help="perturbations of the best random set evaluated afterwards (default 20)")
    parser.add_argument("--with-l1", action="store_true", help="also measure gamma > 0 on the best set")
    parser.add_argument("--quick", action="store_true", help="one tiny frame, 3 candidates (smoke test)")
    parser.add_argument("--out", type=Path, default=harness.DOCS / "tuning.md", help="markdown output")
    return parser.parse_args(argv)


def evaluate_all(batch, frames, fractions, seeds, table, start) -> None:
    """Score every weight set of ``batch`` into ``table`` (rows ``(score, per fraction, weights, s, RMSE ratio)``),
    then sort ``table`` best first."""
    for w in batch:
        ratios, rmse_ratios, seconds = score(w, frames, fractions, seeds)
        per_fraction = {fr: float(np.mean([r for (_, f, _), r in ratios.items() if f == fr])) for fr in fractions}
        rmse_mean = float(np.mean(list(rmse_ratios.values())))
        table.append((float(np.mean(list(ratios.values()))), per_fraction, w, seconds, rmse_mean))
        print(f"[{len(table)}] {table[-1][0]:.3f} (RMSE {rmse_mean:.3f})  {seconds:.1f} s  {_fmt(w)}  "
              f"({time.perf_counter() - start:.0f} s)", file=sys.stderr, flush=True)
    table.sort(key=lambda row: row[0])


def report(args, *, frames, fractions, cands, n_refine, table, near, chosen, l1_rows, seconds) -> str:
    """The markdown of ``docs/tuning.md``."""
    best = chosen[2]
    command = harness.command_line("tune", ["--quick"] if args.quick else [])
    lines = [
        "# Weight tuning",
        "",
        f"Made by `{command}` ({len(cands)} random candidates and "
        f"anchors, then {n_refine} perturbations of the best; search seed {args.seed}, sampling seeds {args.seeds}, "
        f"frames subsampled by {args.step}; {seconds:.0f} s).",
        "",
        harness.machine_markdown(),
        "",
        "Tuning frames (never used in the reported tables): " + ", ".join(f"`{f.name}`" for f in frames) + ".",
        "Score: the mean of RMSE and MAE on the hidden valid pixels, each divided by the nearest-neighbour value on "
        "the same input (lower is better; 1 = no better than nearest neighbour), mean over frames × sparsities × "
        "seeds. Both metrics count: RMSE alone rewards blurring depth edges, which raises the MAE above nearest "
        "neighbour's.",
        "",
        harness.markdown_table(["rank", "score", *(f"{100 * f:g} %" for f in fractions), "RMSE ratio",
                                "solve time s", "weights"],
                               [[rank, f"{mean:.3f}", *(f"{per_fraction[f]:.3f}" for f in fractions),
                                 f"{rmse_mean:.3f}", f"{seconds_:.1f}", _fmt(w)]
                                for rank, (mean, per_fraction, w, seconds_, rmse_mean) in enumerate(table[:10], 1)],
                               align=["---:"] * (len(fractions) + 4) + ["---"]),
    ]
    paper_row = next(row for row in table if row[2] == PAPER_WEIGHTS.replace(gamma=0.0))  # an anchor
    lines += [
        "",
        f"The reference paper's objective (γ = 0): score {paper_row[0]:.3f}, "
        f"RMSE ratio {paper_row[4]:.3f}.",
        "",
        "Best weight set per sparsity (what a per-sparsity default would gain):",
        "",
    ]
    per_sparsity = []
    for f in fractions:
        mean_f, _, w_f = min(((row[1][f], row[1], row[2]) for row in table), key=lambda r: r[0])
        per_sparsity.append([f"{100 * f:g} %", f"{mean_f:.3f}", _fmt(w_f), f"{chosen[1][f]:.3f}"])
    lines.append(harness.markdown_table(["sparsity", "best score", "weights", "score of the chosen defaults"],
                                        per_sparsity, align=["---:", "---:", "---", "---:"]))
    if l1_rows:
        lines += ["", "Adding the edge-aware L1 term to the chosen set (γ = g × median observed depth):", "",
                  harness.markdown_table(["g", "score", "solve time s"],
                                         [[f"{g:g}", f"{m:.3f}", f"{t:.1f}"] for g, m, t in l1_rows],
                                         align=["---:"] * 3)]
    lines += [
        "",
        f"**Chosen defaults** (the fastest of the {len(near)} sets within {100 * TIE:g} % of the best score "
        f"{table[0][0]:.3f}): `{_fmt(best)}`, score {chosen[0]:.3f}, RMSE ratio {chosen[4]:.3f}, solve time "
        f"{chosen[3]:.1f} s (best-scoring set: {table[0][3]:.1f} s).",
        "",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    args = parse_args(argv)
    fractions = harness.FRACTIONS
    if args.quick:
        frames = [harness.synthetic_frame()]
        cands = candidates(3, args.seed)
    else:
        names = frame_list.available(frame_list.TUNE_FRAMES)
        if not names:
            print("the shared data folder is absent: nothing to tune on", file=sys.stderr)
            return 2
        frames = [harness.FrameData(n, *frame_list.load(n, step=args.step), args.step) for n in names]
        cands = candidates(args.candidates, args.seed)

    start = time.perf_counter()
    table = []
    evaluate_all(cands, frames, fractions, args.seeds, table, start)
    n_refine = 2 if args.quick else args.refine
    evaluate_all(refinements(table[0][2], n_refine, args.seed), frames, fractions, args.seeds, table, start)
    # the accuracy landscape is flat near the optimum while the solve time is not (weak priors and
    # strong weight contrasts make the system ill-conditioned): take the fastest set within 1 % of the best
    near = [row for row in table if row[0] <= table[0][0] * (1 + TIE)]
    chosen = min(near, key=lambda row: row[3])

    l1_rows = []
    if args.with_l1:
        for g in (1e-3, 3e-3, 1e-2):
            ratios, _, seconds = score(chosen[2], frames, fractions, args.seeds, gamma_relative=g)
            l1_rows.append((g, float(np.mean(list(ratios.values()))), seconds))

    text = report(args, frames=frames, fractions=fractions, cands=cands, n_refine=n_refine, table=table, near=near,
                  chosen=chosen, l1_rows=l1_rows, seconds=time.perf_counter() - start)
    return harness.publish([text], args.out)


if __name__ == "__main__":
    sys.exit(main())
