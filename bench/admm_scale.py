"""ADMM at scale: time per pixel of the L1 solve at 0.3, 1.2 and 4.9 megapixels (``docs/admm_scale.md``).

Command, from the repository root (about 10 minutes on 2 cores)::

    python -m bench.admm_scale                 # both problems at 1x, 2x, 4x per side, writes docs/admm_scale.md
    python -m bench.admm_scale --scales 1 2    # fewer sizes, prints only (add --write to write the doc)
    python -m bench.admm_scale --variant name '{"polish_preconditioner": "amg"}'   # also run ADMM with these options
    python -m bench.admm_scale --reference     # also a run certified 100 times tighter, for F_best

Everything runs in this one process with one BLAS thread (:func:`bench.blas.one_blas_thread`), so the ratios of
time per pixel compare runs on the same machine under the same load.  Each size's frame is built once and every
variant runs on it, sizes and variants interleaved round by round; the time of a variant is its best over
``--rounds`` rounds (default 1).

Problems (image and dense depth resized 1x, 2x, 4x per side, then sampled):

* ``perf``: the L1 problem of :mod:`bench.perf` (frame ``nyu_metric3d/00000``, depth in metres, 5 % of the valid
  pixels by ``sample_depth(..., fraction=0.05, seed=0)``, :data:`bench.perf.L1_WEIGHTS`);
* ``issue20``: frame ``nyu_metric3d/00050``, depth in metres (F* = 903.16 at 1x), the mask ``(depth > 0) & (U < 0.05)`` with ``U``
  from ``np.random.default_rng(5)``, ``Weights.paper(alpha=1, beta=0.5, gamma=0.2, delta=0.01, kappa=10)``.

Every run is ``sd.complete_depth(..., solver="admm", clip_to_observed=False)`` (the default run: default options).
Per run the table gives the pixels, the time, the time per pixel relative to the same variant at 1x, the ADMM
iterations, the polishes and their CG steps (counted by wrapping the polish), the time spent in the polishes, the
duality-gap certificates and their time, ``F`` relative to the best ``F`` found at that size by any run, the relative
duality gap and whether the run converged (gap certified).

May import :mod:`sparsedepth` (and its ``solvers`` subpackage, whose polish and certificate it wraps to count
them), numpy, scikit-image and :mod:`bench.harness`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.solvers import admm as admm_module  # noqa: E402

from . import harness as H  # noqa: E402

PERF_FRAME = "nyu_metric3d/00000"
ISSUE_FRAME = "nyu_metric3d/00050"
#: bench.perf's L1 weights (copied, so that this module does not import bench.perf and its BLAS set-up twice)
PERF_WEIGHTS = sd.Weights.paper(alpha=1.0, beta=0.1, gamma=0.01, delta=1e-3, kappa=10.0)
ISSUE_WEIGHTS = sd.Weights.paper(alpha=1.0, beta=0.5, gamma=0.2, delta=0.01, kappa=10.0)
DOC = H.REPO / "docs" / "admm_scale.md"
#: Options of the ``--reference`` run: a duality gap certified 100 times tighter than the default's.
REFERENCE = {"target_gap": 1e-8, "check_rtol": 2e-9}


def _resize(image, depth, scale):
    """Image (bilinear) and dense depth (nearest, NaN = invalid) resized ``scale`` times per side."""
    if scale == 1:
        return image, depth
    from skimage.transform import resize

    h, w = depth.shape
    out = (h * scale, w * scale)
    image = (resize(image, out, order=1, anti_aliasing=False) * 255).astype(np.uint8)
    valid = resize(np.isfinite(depth).astype(float), out, order=0) > 0.5
    depth = resize(np.nan_to_num(depth), out, order=0)
    return image, np.where(valid & (depth > 0), depth, np.nan)


def perf_problem(scale):
    """bench.perf's L1 problem at ``scale`` per side: ``(image, sparse, mask, weights)``."""
    fr = sd.load_shared_frame(PERF_FRAME)
    image, depth = _resize(fr.image, np.array(fr.depth), scale)
    sparse, mask = sd.sample_depth(depth, fraction=0.05, seed=0)
    return image, sparse, mask, PERF_WEIGHTS


def issue_problem(scale):
    """Issue 20's L1 problem at ``scale`` per side (depth in metres): ``(image, sparse, mask, weights)``."""
    fr = sd.load_shared_frame(ISSUE_FRAME)
    image, depth = _resize(fr.image, np.array(fr.depth, dtype=float), scale)
    depth = np.nan_to_num(depth)
    mask = (depth > 0) & (np.random.default_rng(5).random(depth.shape) < 0.05)
    return image, np.where(mask, depth, 0.0), mask, ISSUE_WEIGHTS


PROBLEMS = {"perf": perf_problem, "issue20": issue_problem}


class _Counters:
    """Wraps ADMM's polish and certificate (module attributes of :mod:`sparsedepth.solvers.admm`) to count them."""

    def __init__(self):
        self.polish_fn = admm_module.polish_active_set
        self.certificate_cls = admm_module.Certificate
        self.reset()

    def reset(self):
        self.polishes = self.polish_steps = 0
        self.polish_time = self.gap_time = 0.0
        self.gaps = 0

    def install(self):
        counters = self

        def polish(*args, **kwargs):
            start = time.perf_counter()
            out = counters.polish_fn(*args, **kwargs)
            counters.polish_time += time.perf_counter() - start
            counters.polishes += 1
            if out is not None:
                counters.polish_steps += out[3]
            return out

        class Certificate(self.certificate_cls):
            def __init__(self, *args, **kwargs):
                start = time.perf_counter()
                super().__init__(*args, **kwargs)
                counters.gap_time += time.perf_counter() - start

            def gap(self, *args, **kwargs):
                start = time.perf_counter()
                out = super().gap(*args, **kwargs)
                counters.gap_time += time.perf_counter() - start
                counters.gaps += 1
                return out

        admm_module.polish_active_set = polish
        admm_module.Certificate = Certificate


def run_one(problem, options, counters):
    """One ``complete_depth(..., solver="admm")`` with ``options``: a row of measurements."""
    image, sparse, mask, weights = problem
    counters.reset()
    res, seconds = H.timed(sd.complete_depth, image, sparse, mask, weights=weights, solver="admm",
                           options=options or None, clip_to_observed=False)
    return dict(n=int(mask.size), seconds=seconds, iters=res.iterations, polishes=counters.polishes,
                polish_steps=counters.polish_steps, polish_time=counters.polish_time, gaps=counters.gaps,
                gap_time=counters.gap_time,
                F=float(res.objective), gap=float(res.gap), converged=bool(res.converged),
                message=res.message)


def measure(problem_names, scales, variants, rounds):
    """``{(problem, variant, scale): row}``: every variant on every size, best time over ``rounds``."""
    counters = _Counters()
    counters.install()
    rows = {}
    for name in problem_names:
        for scale in scales:
            problem = PROBLEMS[name](scale)
            for _ in range(rounds):
                for vname, options in variants.items():
                    row = run_one(problem, options, counters)
                    key = (name, vname, scale)
                    if key not in rows or row["seconds"] < rows[key]["seconds"]:
                        rows[key] = row
                    print(json.dumps(dict(problem=name, variant=vname, scale=scale,
                                          **{k: v for k, v in row.items() if k != "message"})), flush=True)
            del problem
    return relate(rows)


def relate(rows):
    """Add ``F_rel`` (to the best F of any run at that size) and ``per_pixel`` (to the same variant at its
    smallest measured size) to every row of ``{(problem, variant, scale): row}``."""
    for (name, vname, scale), r in rows.items():
        F_best = min(q["F"] for (p, _, s), q in rows.items() if p == name and s == scale)
        r["F_rel"] = (r["F"] - F_best) / abs(F_best)
        base = rows[(name, vname, min(s for (p, v, s) in rows if p == name and v == vname))]
        r["per_pixel"] = (r["seconds"] / r["n"]) / (base["seconds"] / base["n"])
    return rows


def read_log(path):
    """``{(problem, variant, scale): row}`` from the JSON lines a run printed (the best time per key)."""
    rows = {}
    for line in open(path, encoding="utf-8"):
        if line.startswith("{"):
            row = json.loads(line)
            key = (row.pop("problem"), row.pop("variant"), row.pop("scale"))
            if key not in rows or row["seconds"] < rows[key]["seconds"]:
                rows[key] = row
    return relate(rows)


def table(rows, problem_names, scales, variants):
    """Markdown table of the measurements."""
    header = ["problem", "variant", "pixels", "time (s)", "time/pixel vs 1x", "ADMM iters", "polishes",
              "polish CG steps", "polish (s)", "certificates", "certificate (s)", "(F - F_best)/F_best", "gap/F",
              "converged"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for name in problem_names:
        for vname in variants:
            for scale in scales:
                if (name, vname, scale) not in rows:
                    continue
                r = rows[(name, vname, scale)]
                lines.append("| " + " | ".join([
                    name, vname, f"{r['n'] / 1e6:.2f} M", f"{r['seconds']:.2f}", f"{r['per_pixel']:.2f}",
                    str(r["iters"]), str(r["polishes"]), str(r["polish_steps"]), f"{r['polish_time']:.2f}",
                    str(r.get("gaps", "-")), f"{r['gap_time']:.2f}", f"{r['F_rel']:.1e}",
                    f"{r['gap'] / abs(r['F']):.1e}", "yes" if r["converged"] else "NO"]) + " |")
    return "\n".join(lines)


def report(text, command, variants, *, rendered=False):
    """``docs/admm_scale.md`` (``rendered``: written by ``--render`` from the lines ``command`` printed)."""
    machine = H.machine_markdown()
    written = (f"Measured by `{command}`, written from its printed lines by `python -m bench.admm_scale --render LOG`"
               if rendered else f"Written by `{command}`")
    opts = "\n".join(f"- `{v}`: options `{json.dumps(o)}`" for v, o in variants.items())
    return f"""# ADMM at scale

{written} (from the repository root; see `bench/admm_scale.py` for the problems and what is
timed).

{machine}

Time per pixel of `complete_depth(..., solver="admm", clip_to_observed=False)` at 1x, 2x and 4x per side of a
640x480 frame (0.3, 1.2 and 4.9 megapixels), relative to the same variant at 1x, all in one process with one BLAS
thread. `F_best` is the lowest `F` of any run at that size (with `--reference`, including a run whose duality
gap is certified 100 times tighter); `gap/F` is the certified relative duality gap of the returned point, a bound
on its distance to the optimum.  The machine is shared: the times of a run move with the other users' load (the
report's date and machine are above); the iterations, polishes, CG steps and certificates do not.

Variants:
{opts}

{text}
"""


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m bench.admm_scale", description=__doc__.splitlines()[0])
    parser.add_argument("--scales", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--problems", nargs="+", choices=sorted(PROBLEMS), default=["perf", "issue20"])
    parser.add_argument("--variant", nargs=2, action="append", default=[], metavar=("NAME", "JSON"),
                        help="also run ADMM with these options (JSON dict)")
    parser.add_argument("--no-default", action="store_true", help="skip the default run")
    parser.add_argument("--reference", action="store_true",
                        help=f"also run ADMM with the tight options {REFERENCE} (its F joins F_best)")
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--write", action="store_true", help="write docs/admm_scale.md (default with every size)")
    parser.add_argument("--render", metavar="LOG",
                        help="no measuring: write docs/admm_scale.md from the JSON lines a run printed (saved to LOG)")
    parser.add_argument("--measured-by", default="python -m bench.admm_scale",
                        help="with --render: the command whose printed lines LOG holds")
    args = parser.parse_args(argv)
    if args.render:
        rows = read_log(args.render)
        problems = [p for p in args.problems if any(k[0] == p for k in rows)]
        names = list(dict.fromkeys(k[1] for k in rows))
        scales = sorted({k[2] for k in rows})
        text = table(rows, problems, scales, names)
        print(text)
        variants = {v: (REFERENCE if v == "reference" else {}) for v in names}
        DOC.write_text(report(text, args.measured_by, variants, rendered=True))
        return 0
    variants = {} if args.no_default else {"default": {}}
    variants.update({name: json.loads(spec) for name, spec in args.variant})
    if args.reference:
        variants["reference"] = dict(REFERENCE)
    rows = measure(args.problems, args.scales, variants, args.rounds)
    text = table(rows, args.problems, args.scales, variants)
    print(text)
    argv_used = sys.argv[1:] if argv is None else list(argv)
    if args.write or (args.scales == [1, 2, 4] and not args.no_default):
        DOC.write_text(report(text, H.command_line("admm_scale", argv_used), variants))
    return 0


if __name__ == "__main__":
    sys.exit(main())
