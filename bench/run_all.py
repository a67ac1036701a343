"""Regenerate ``docs/results.md`` (and the solver PNGs) from every benchmark script, in one process.

Run::

    python bench/run_all.py                 # full run, writes docs/results.md
    python bench/run_all.py --quick --out /tmp/results.md   # seconds-long smoke test

One process, so identical runs are shared between tables (e.g. ours and the
nearest fill at 1/5/10 % in the sparsity and baseline tables).  Each section
records the standalone command that reproduces it, the machine, the frames and
seeds.  Every number in ``docs/results.md`` comes from here; nothing is typed in
by hand.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import ablation  # noqa: E402
import baselines  # noqa: E402
import frames as frame_list  # noqa: E402
import harness as H  # noqa: E402
import protocol  # noqa: E402
import solvers  # noqa: E402
import sparsity  # noqa: E402

SCRIPTS = {"sparsity": sparsity, "baselines": baselines, "ablation": ablation, "solvers": solvers,
           "protocol": protocol}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="every script in --quick mode")
    p.add_argument("--out", type=Path, default=H.DOCS / "results.md")
    p.add_argument("--only", nargs="+", choices=list(SCRIPTS), default=list(SCRIPTS))
    p.add_argument("--assemble", nargs="+", type=Path, default=None,
                   help="run nothing: write --out from section files made by earlier runs (e.g. run in parallel "
                        "with --only ... --out part.md); the text before each file's first '## ' is dropped")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    H.PROGRESS = True
    sections = []
    if args.assemble:
        args.only = []
        for path in args.assemble:
            text = path.read_text()
            sections.append(text[text.index("## "):] if "## " in text else text)
    for name in args.only:
        sub = ["--quick"] if args.quick else []
        t = time.perf_counter()
        if name == "solvers":
            text, _ = solvers.run(sub, plot_dir=args.out.parent)
        else:
            text, _ = SCRIPTS[name].run(sub)
        print(f"[run_all] {name}: {time.perf_counter() - t:.0f} s", file=sys.stderr, flush=True)
        sections.append(text)
    elapsed = time.perf_counter() - t0
    head = [
        "# Benchmark results",
        "",
        "Written by `python bench/run_all.py" + (" --quick" if args.quick else "")
        + (" --assemble ...`" if args.assemble else "`") + "; do not edit by hand. "
        "Each section names the standalone command that reproduces it.",
        "",
        f"Machine: {H.machine_markdown()}. "
        + ("Sections assembled from parallel runs; each gives its own wall time." if args.assemble
           else f"Total wall time: {elapsed / 60:.1f} min."),
        "",
        "Frames: reported tables use `bench/frames.py` REPORT_FRAMES only "
        f"({', '.join(f'`{n}`' for n in frame_list.REPORT_FRAMES)}); the default weights are tuned on the "
        f"disjoint TUNE_FRAMES ({', '.join(f'`{n}`' for n in frame_list.TUNE_FRAMES)}). The embedded "
        "Motorcycle (`sd.load_motorcycle()`) is the same scene as `middlebury2014/motorcycle` and is not counted "
        "twice. Scored pixels: valid ground truth hidden from the method. Sampling is seeded; numbers are mean ± std "
        "over frames × seeds. Runtimes are wall-clock on a shared machine, so the same-run ratios next to them are "
        "the numbers to compare.",
        "",
    ]
    headlines = [line[len("Headline: "):] for text in sections for line in text.splitlines()
                 if line.startswith("Headline: ")]
    titles = [text.splitlines()[0][3:] for text in sections]
    head += ["## Headline numbers", "", "Copied by `run_all.py` from the sections below (defaults at run time: "
             f"{H.weights_markdown(H.sd.DEFAULT_WEIGHTS)}):", ""]
    head += ([f"- {t}: {h}" for t, h in zip(titles, headlines)] if len(titles) == len(headlines)
             else [f"- {h}" for h in headlines])
    head += [""]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(head) + "\n" + "\n".join(sections))
    print(f"[run_all] wrote {args.out} in {elapsed / 60:.1f} min", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
