"""``python -m sparsedepth.complete``: the command line (see :mod:`sparsedepth.cli`)."""

import sys

from .cli import build_parser, main

__all__ = ["main", "build_parser"]

if __name__ == "__main__":
    sys.exit(main())
