"""Paper Table 3.2 at 5 % observed: which terms of the objective matter, plus the extension terms.

Run (full)::

    python -m bench.ablation --out docs/results_ablation.md

or ``--quick`` for a smoke test.  The paper's rows use the reference paper's
objective with its own weights (:meth:`sparsedepth.Weights.paper`: α = 1,
β = 0.1, γ = 0.01, δ = 1e-3, κ = 10) with some weights set to 0 by
``Weights.replace``; the tuned defaults (``sd.DEFAULT_WEIGHTS``, read at run
time) may have β = γ = 0, so they could not show the paper's terms.  All are
solved with ``solver="auto"``:

* data only: α and δ (the nearest-neighbour prior; with α alone the hidden
  pixels are undetermined, and with β = γ = 0 every δ > 0 gives the nearest
  fill there);
* edge only: α, γ;  L2 only: α, β;  L2 + edge: α, β, γ;
* full objective of the paper: α, β, γ, δ;
* extension terms: the paper's objective plus each weight of
  ``Weights`` beyond α, β, γ, δ, κ (``beta_image`` image-weighted L2,
  ``beta_second`` second-order, ``beta_second_image`` image-weighted
  second-order, the local-linear terms), one at a time, at its default
  weight if > 0, else at the density schedule's weight at 5 % (with the
  schedule's ``local_linear_eps``) if > 0, else at the paper's β, and
  each modelling option the defaults use (``edge_sigma`` blurred edge
  weights, ``fill_contrast`` the image-aware prior fill, ``depth_jump``)
  at its default; the image-weighted L2 *instead of* the
  plain L2; and the tuned defaults.

Variants equal to an earlier one (e.g. when a default weight is 0) are
listed once.  Frames are subsampled by ``--step`` (default 4).

May import :mod:`sparsedepth` and :mod:`bench.harness`.
"""

from __future__ import annotations

import sys
import time

import sparsedepth as sd
from sparsedepth.objective.weights import (DEFAULT_SCHEDULE, EDGE_PENALTY_FIELDS, LOCAL_LINEAR_FIELDS, MODEL_FIELDS,
                                           resolve_weights)

from . import harness as H

DEFAULT_STEP = 4
FRACTION = 0.05
PAPER_FIELDS = ("alpha", "beta", "gamma", "delta", "kappa")
EXT_LABELS = {"beta_image": "image-weighted L2", "beta_second": "second-order",
              "beta_second_image": "image-weighted second-order", "edge_sigma": "edge weights of a blurred image",
              "fill_contrast": "image-aware (geodesic) prior fill", "depth_jump": "depth-aware re-solve",
              "beta_local_linear": "windowed local-linear (matting Laplacian)",
              "beta_local_linear_cross": "local-linear on cross-shaped windows",
              "beta_local_linear_2x2": "local-linear on 2x2 windows"}
#: Fields that only shape other terms (not a row of their own): the rows of those terms carry the default's value.
PARAMETER_OF = {"local_linear_eps": LOCAL_LINEAR_FIELDS}


def variants(D=None, P=None):
    """``[(label, Weights)]``: the paper's terms from ``P``, extensions and defaults from ``D``; duplicates dropped.

    ``P`` (default :meth:`sparsedepth.Weights.paper`, the reference paper's objective with its own weights) gives
    the rows of paper Table 3.2; ``D`` (default ``sd.DEFAULT_WEIGHTS``, whose tuned β and γ may be 0) gives the
    weight of each extension term added to the paper's objective, and the last row.
    """
    D = sd.DEFAULT_WEIGHTS if D is None else D
    P = sd.Weights.paper() if P is None else P
    # every weight beyond the paper's alpha, beta, gamma, delta, kappa is an extension term
    ext = [k for k in D.as_dict() if k not in PAPER_FIELDS and k not in EDGE_PENALTY_FIELDS]
    # a modelling option (not a term) is a row only where the defaults use it: it has no paper-like value
    ext = [k for k in ext if (k not in MODEL_FIELDS or getattr(D, k) > 0) and k not in PARAMETER_OF]
    no_ext = {k: 0.0 for k in (*ext, *MODEL_FIELDS)}
    P = P.replace(**no_ext)
    prior = P.delta if P.delta > 0 else 1e-6 * max(P.alpha, 1.0)
    w_img = D.beta_image if D.beta_image > 0 else P.beta
    out = [
        ("data only (α, δ)", P.replace(beta=0.0, gamma=0.0, delta=prior)),
        ("edge only (α, γ)", P.replace(beta=0.0, delta=0.0)),
        ("L2 only (α, β)", P.replace(gamma=0.0, delta=0.0)),
        ("L2 + edge (α, β, γ)", P.replace(delta=0.0)),
        ("full objective of the paper (α, β, γ, δ)", P),
    ]
    scheduled = resolve_weights(DEFAULT_SCHEDULE, FRACTION)
    for k in ext:
        source = D if getattr(D, k) > 0 or getattr(scheduled, k) == 0 else scheduled
        value = getattr(source, k) if getattr(source, k) > 0 else P.beta
        shape = {name: getattr(source, name) for name, terms in PARAMETER_OF.items() if k in terms}
        label = ", ".join(f"{name} = {v:g}" for name, v in {k: value, **shape}.items())
        out.append((f"paper + {EXT_LABELS.get(k, k)} ({label})", P.replace(**{k: value}, **shape)))
        if k == "beta_image":
            out.append((f"image-weighted L2 instead of L2 (beta = 0, beta_image = {w_img:g})",
                        P.replace(beta=0.0, beta_image=w_img)))
    out.append(("defaults (sd.DEFAULT_WEIGHTS)", D))
    seen, kept = {}, []
    for label, w in out:
        if w in seen:
            continue
        if w.alpha == 0 or (w.beta == w.gamma == w.beta_image == w.beta_second == 0 and w.delta == 0):
            continue
        if label.startswith(("edge only", "L2 + edge")) and w.gamma == 0:
            continue  # gamma = 0 in the defaults: no edge term to ablate
        if label.startswith(("L2 only", "L2 + edge")) and w.beta == 0:
            continue
        seen[w] = label
        kept.append((label, w))
    return kept


def run(argv=None):
    """Run the ablation; returns ``(markdown, rows)``."""
    args = H.parser(__doc__.splitlines()[0], default_step=DEFAULT_STEP).parse_args(argv)
    t0 = time.perf_counter()
    frames = H.get_frames(args)
    seeds = H.seeds_of(args)
    vs = variants()
    methods = [H.ours(label, weights=w) for label, w in vs]
    ref = "full objective of the paper (α, β, γ, δ)"
    if ref not in [m.name for m in methods]:
        ref = methods[-1].name
    records = H.evaluate_all(methods, frames, seeds, fractions=[FRACTION])
    rows = H.summarise(records, reference=ref)
    header = ["variant", "weights", "RMSE", "MAE", "REL", "δ1", "RMSE / paper", "time (s)", "time × paper"]
    table = []
    for (label, w), m in zip(vs, methods):
        r = next(x for x in rows if x["method"] == m.name)
        nz = ", ".join(f"{k} {v:g}" for k, v in w.as_dict().items()
                       if k not in EDGE_PENALTY_FIELDS and v > 0 and k != "kappa")
        table.append([label, nz, H.fmt(*r["rmse"]), H.fmt(*r["mae"]), H.fmt(*r["rel"]), H.fmt(*r["delta1"]),
                      H.fmt(*r["rmse_ratio"]), H.fmt(*r["runtime"], digits=2), H.fmt(r["time_ratio"], digits=2)])
    body = H.markdown_table(header, table)
    body += "\n\nRMSE per frame (mean ± std over seeds), in the frame's depth units:\n\n"
    body += H.per_frame_table(records, [m.name for m in methods])
    ext = [r for r in rows if r["method"].startswith(("paper +", "image-weighted"))]
    paper = {(r.frame, r.seed): r.metrics.rmse for r in records if r.method == ref}

    def wins(name):
        pairs = [(r.metrics.rmse, paper[(r.frame, r.seed)]) for r in records if r.method == name]
        return sum(a < b for a, b in pairs), len(pairs)

    verdict = "; ".join(f"{r['method']}: RMSE / paper = {H.fmt(*r['rmse_ratio'])}, lower on "
                        "{}/{} inputs".format(*wins(r["method"])) for r in ext)
    notes = (H.step_note(args) + f" {FRACTION:.0%} of the valid pixels observed; solver `auto`; κ = "
             f"{sd.DEFAULT_WEIGHTS.kappa:g} throughout. `RMSE / paper` is the mean over frames × seeds of the "
             "per-input RMSE ratio to the paper's full objective; `time × paper` is Σ t / Σ t_paper.\n\n"
             f"Headline: extension terms, {verdict}.")
    text = H.section("Ablation (paper Table 3.2) and extension terms", command=H.command_line("ablation", argv or []),
                     frames_=frames, seeds=seeds, body=body, notes=notes, elapsed=time.perf_counter() - t0)
    return text, rows


def main(argv=None) -> int:
    args = H.parser(__doc__.splitlines()[0], default_step=DEFAULT_STEP).parse_args(argv)
    return H.script_main(run, args, argv)


if __name__ == "__main__":
    sys.exit(main())
