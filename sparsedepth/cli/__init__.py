"""The command line, ``python -m sparsedepth.complete``: options, output planning, reports.

May import everything of the library; nothing imports it except :mod:`sparsedepth.complete`.
"""

from .command import build_parser, main

__all__ = ["main", "build_parser"]
