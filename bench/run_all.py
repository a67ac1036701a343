"""Regenerate ``docs/results.md`` (and the solver PNGs) from every table module, in one process.

Run from the repository root::

    python -m bench.run_all                 # full run, writes docs/results.md
    python -m bench.run_all --quick --out /tmp/results.md   # seconds-long smoke test

Modules that share runs (ours and the nearest fill at 1/5/10 % in the
sparsity and baseline tables) run in one process and share an in-process
cache; the three groups (sparsity + baselines, ablation, solvers + protocol)
run in ``--jobs`` parallel processes (default 2).  Each section
records the standalone command that reproduces it, the machine, the frames and
seeds.  Every number in ``docs/results.md`` comes from here; nothing is typed in
by hand.

May import :mod:`bench.harness`, :mod:`bench.frames` and the table modules it runs.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import sparsedepth as sd

from . import ablation, baselines, protocol, solvers, sparsity
from . import frames as frame_list
from . import harness as H

SCRIPTS = {"sparsity": sparsity, "baselines": baselines, "ablation": ablation, "solvers": solvers,
           "protocol": protocol}
#: Scripts that share cached runs stay in one process; the groups run in parallel with --jobs > 1.
GROUPS = (("sparsity", "baselines"), ("ablation",), ("solvers", "protocol"))


def run_group(names, sub, plot_dir):
    """Run the scripts ``names`` in order in this process; ``[(name, markdown, seconds)]``.

    ``plot_dir`` None: the solver script draws no figures.
    """
    H.show_progress()
    out = []
    for name in names:
        t = time.perf_counter()
        if name == "solvers":
            text, _ = (solvers.run(sub, plot_dir=plot_dir) if plot_dir is not None
                       else solvers.run(sub + ["--no-plot"]))
        else:
            text, _ = SCRIPTS[name].run(sub)
        out.append((name, text, time.perf_counter() - t))
        print(f"[run_all] {name}: {out[-1][2]:.0f} s", file=sys.stderr, flush=True)
    return out


def parse_args(argv):
    """The command line of :func:`main`."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="every script in --quick mode")
    p.add_argument("--out", type=Path, default=H.DOCS / "results.md")
    p.add_argument("--seeds", type=int, nargs="+", default=None,
                   help="sampling seeds for every script (default: each script's own, 0 1 2; solvers 0)")
    p.add_argument("--only", nargs="+", choices=list(SCRIPTS), default=list(SCRIPTS))
    p.add_argument("--jobs", type=int, default=2,
                   help="processes running the script groups in parallel (default 2, one per core here)")
    p.add_argument("--assemble", nargs="+", type=Path, default=None,
                   help="run nothing: write --out from the sections of files made by earlier runs (--only ... "
                        "--out part.md); a later file's section replaces an earlier one with the same title")
    p.add_argument("--no-plot", action="store_true",
                   help="no solver figures (they need matplotlib, the 'plot' extra)")
    return p.parse_args(argv)


def assembled_sections(paths) -> list[str]:
    """The sections of earlier runs' files; a later file's section replaces an earlier one of the same title."""
    by_title = {}
    for path in paths:
        for part in ("\n" + path.read_text()).split("\n## ")[1:]:
            title = part.splitlines()[0]
            if title != "Headline numbers":
                by_title[title] = "## " + part.rstrip() + "\n"
    return list(by_title.values())


def run_groups(args, plot_dir) -> dict:
    """Run the selected modules, their groups in ``args.jobs`` processes; ``{name: markdown}``."""
    sub = (["--quick"] if args.quick else []) + (["--seeds", *map(str, args.seeds)] if args.seeds else [])
    groups = [[n for n in g if n in args.only] for g in GROUPS]
    groups = [g for g in groups if g]
    if args.jobs > 1 and len(groups) > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            done = list(pool.map(run_group, groups, [sub] * len(groups), [plot_dir] * len(groups)))
    else:
        done = [run_group(g, sub, plot_dir) for g in groups]
    return {name: text for group in done for name, text, _ in group}


def results_header(args, sections, elapsed) -> list[str]:
    """The lines of ``results.md`` above the sections: command, machine, frames, headline numbers."""
    command = H.command_line("run_all", (["--quick"] if args.quick else [])
                             + (["--seeds", *args.seeds] if args.seeds else []) + (["--assemble", "..."]
                                                                                   if args.assemble else []))
    head = [
        "# Benchmark results",
        "",
        f"Written by `{command}`; do not edit by hand. Each section names the standalone command that reproduces it.",
        "",
        f"Machine: {H.machine_markdown()}. "
        + ("Sections assembled from parallel runs; each gives its own wall time." if args.assemble
           else f"Total wall time: {elapsed / 60:.1f} min ({args.jobs} parallel processes)."),
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
             f"{H.weights_markdown(sd.DEFAULT_SCHEDULE)}):", ""]
    head += ([f"- {t}: {h}" for t, h in zip(titles, headlines)] if len(titles) == len(headlines)
             else [f"- {h}" for h in headlines])
    return head + [""]


def main(argv=None) -> int:
    args = parse_args(argv)
    if "solvers" in args.only and not args.no_plot and not args.assemble:
        if importlib.util.find_spec("matplotlib") is None:  # fail now, not after the other groups' 15 minutes
            print("run_all: the solver figures need matplotlib (pip install 'sparsedepth[plot]'); "
                  "install it or pass --no-plot", file=sys.stderr)
            return 2
    plot_dir = None if args.no_plot else args.out.parent
    t0 = time.perf_counter()
    H.show_progress()
    sections = []
    if args.assemble:
        args.only = []
        sections = assembled_sections(args.assemble)
    texts = run_groups(args, plot_dir)
    sections += [texts[n] for n in SCRIPTS if n in texts]
    elapsed = time.perf_counter() - t0
    H.write_text(args.out, "\n".join(results_header(args, sections, elapsed)) + "\n" + "\n".join(sections))
    print(f"[run_all] wrote {args.out} in {elapsed / 60:.1f} min", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
