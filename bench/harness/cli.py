"""The command line shared by the table modules (sparsity, baselines, ablation, solvers, protocol).

May import :mod:`.evaluation`, :mod:`.inputs` and :mod:`.report`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from .evaluation import show_progress
from .inputs import DEFAULT_SEEDS
from .report import write_text

__all__ = ["parser", "script_main", "finish", "seeds_of"]


def parser(description: str, *, default_step: int) -> argparse.ArgumentParser:
    """``--quick``, ``--step``, ``--seeds``, ``--frames``, ``--out``."""
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
    """The body of every table module's ``main``: progress lines on, ``run(argv)``, then :func:`finish`."""
    show_progress()
    text, _ = run(argv)
    finish(args, text)
    return 0


def finish(args, text: str) -> None:
    """Print the section and write it to ``--out`` if given."""
    print(text)
    if args.out is not None:
        write_text(args.out, text)


def seeds_of(args):
    """The seeds of a run: the first only in quick mode."""
    return [args.seeds[0]] if args.quick else list(args.seeds)
