"""The command line, ``python -m sparsedepth.complete``: options, output planning, reports.

Modules: :mod:`~sparsedepth.cli.parser` (the options),
:mod:`~sparsedepth.cli.checks` (their combinations),
:mod:`~sparsedepth.cli.single` (one frame), :mod:`~sparsedepth.cli.batch_mode`
(a batch), :mod:`~sparsedepth.cli.report` (table, JSON report, figure),
:mod:`~sparsedepth.cli.outputs` (every output checked first, written all or
nothing), :mod:`~sparsedepth.cli.camera` (intrinsics for ``--ply``),
:mod:`~sparsedepth.cli.messages` (errors and warnings as lines on stderr) and
:mod:`~sparsedepth.cli.command` (:func:`main`).

May import everything of the library; nothing imports it except :mod:`sparsedepth.complete`.
"""

from .command import build_parser, main

__all__ = ["main", "build_parser"]
