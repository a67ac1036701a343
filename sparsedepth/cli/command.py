"""Command line: ``python -m sparsedepth.complete``.

Completes one frame (the embedded Middlebury Motorcycle demo, or your image
and depth files), fills the holes of raw depth, or runs a batch of frames.
Everything is done by library functions; this module only parses options,
reads and writes files, prints the table and progress (on stderr), and turns
library errors into one line on stderr with exit code 2.

Exit codes: 0 success (a batch: every frame has an ok row, including frames
skipped because an earlier run did them); 1 a batch finished but some frames
failed (error rows in the CSV); 2 bad options or input (one line on stderr,
before any frame runs), a CSV written with other settings (see --overwrite),
or the CSV could not be written (e.g. a full disk); 130 interrupted by SIGINT
(Ctrl-C); 143 terminated by SIGTERM.  An interrupted or terminated batch
stops its worker processes, removes their temporary files and keeps the rows
of the finished frames: the same command again resumes it.

``--help`` prints the common options of each task, ``--help-all`` every
option (:mod:`~sparsedepth.cli.parser`).

Files: no output may be an input or another output, and every output is
checked to be creatable before the work starts.  One frame's outputs are
written all or nothing (see :func:`sparsedepth.cli.outputs.commit`).

This module parses the options and dispatches to the one-frame mode
(:mod:`~sparsedepth.cli.single`) or the batch mode
(:mod:`~sparsedepth.cli.batch_mode`); it imports the other modules of
:mod:`sparsedepth.cli`.
"""


from __future__ import annotations

import sys

from .batch_mode import run_batch_mode
from .checks import check_options
from .messages import LIBRARY_ERRORS, UsageError, one_line
from .parser import PROG, build_parser
from .single import run_one

__all__ = ["main", "build_parser"]


def main(argv=None) -> int:
    """Run the command line; return the exit code (see the module docstring).

    Parameters
    ----------
    argv : list of str, optional
        Arguments without the program name; default ``sys.argv[1:]``.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser()
    stdout, stderr = sys.stdout, sys.stderr
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --help-all, --version (0) or a parse error (2, one line already printed)
        return 0 if exc.code is None else int(exc.code)
    try:
        mode = check_options(args)
        if mode == "batch":
            return run_batch_mode(args, stderr, argv)
        return run_one(args, argv, mode, stdout, stderr)
    except UsageError as exc:
        print(f"{PROG}: error: {exc}", file=stderr)
        return 2
    except LIBRARY_ERRORS as exc:
        print(f"{PROG}: error: {one_line(exc)}", file=stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
