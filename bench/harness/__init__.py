"""The one benchmark harness: every benchmark module takes its shared pieces from here.

* :mod:`.inputs` - evaluation frames (reported, quick, synthetic) and their seeded sparse inputs;
* :mod:`.methods` - the compared methods (ours and the baselines) as :class:`Method`;
* :mod:`.evaluation` - one scored run (:func:`evaluate`, cached in-process) and aggregation (:func:`summarise`);
* :mod:`.timing` - wall-clock timing with ``time.perf_counter`` (one call, best of / median of repeats);
* :mod:`.tables` - number formatting and markdown tables from rows;
* :mod:`.machine` - CPU, cores, OS, library versions, BLAS threads;
* :mod:`.report` - the header every report starts with (command, machine, frames, seeds) and writing it;
* :mod:`.cli` - the command line shared by the table modules (``--quick``, ``--step``, ``--seeds``, ...).

Every name is re-exported here, so a benchmark module writes ``from bench import harness as H`` and
``H.evaluate(...)``.  The harness may import :mod:`sparsedepth`, numpy and :mod:`bench.frames`; it never imports
a benchmark module.
"""

from .cli import finish, parser, script_main, seeds_of
from .evaluation import Record, evaluate, evaluate_all, mean_std, metric, show_progress, summarise
from .inputs import (DEFAULT_SEEDS, FRACTIONS, FrameData, get_frames, load_frame, quick_frames, report_frame_names,
                     sample, synthetic_frame)
from .machine import blas_threads, cpu_model, machine_info, machine_markdown, version
from .methods import BIHARMONIC, COLORIZATION, LINEAR, NEAREST, Method, ours
from .report import (DOCS, REPO, command_line, publish, frames_markdown, section, step_note, tuned_report_header, weights_markdown,
                     write_text)
from .tables import fmt, markdown_table, per_frame_table
from .timing import best_of, timed

__all__ = [
    "finish", "parser", "script_main", "seeds_of",
    "Record", "evaluate", "evaluate_all", "mean_std", "metric", "show_progress", "summarise",
    "DEFAULT_SEEDS", "FRACTIONS", "FrameData", "get_frames", "load_frame", "quick_frames", "report_frame_names",
    "sample", "synthetic_frame",
    "blas_threads", "cpu_model", "machine_info", "machine_markdown", "version",
    "BIHARMONIC", "COLORIZATION", "LINEAR", "NEAREST", "Method", "ours",
    "DOCS", "REPO", "command_line", "publish", "frames_markdown", "section", "step_note", "tuned_report_header", "weights_markdown",
    "write_text",
    "fmt", "markdown_table", "per_frame_table",
    "best_of", "timed",
]
