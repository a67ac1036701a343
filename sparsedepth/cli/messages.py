"""How the command line reports problems: usage errors, library errors and warnings, each one line on stderr.

Imports the standard library, :class:`~sparsedepth.ClampWarning` and the one-line form of an exception
(:func:`sparsedepth.batch.worker.one_line`, which the batch CSV uses too).
"""

from __future__ import annotations

import contextlib
import warnings

from ..batch.worker import one_line
from ..result import ClampWarning, RangeOutlierWarning

__all__ = ["LIBRARY_ERRORS", "UsageError", "one_line", "warnings_as_lines"]

LIBRARY_ERRORS = (ValueError, OSError, IndexError, KeyError)  # OSError covers FileNotFoundError


class UsageError(Exception):
    """A bad combination of options, found after parsing."""


@contextlib.contextmanager
def warnings_as_lines(stream):
    """Library warnings raised inside the block become one ``warning:`` line each on ``stream``.

    Yields the list of caught warnings, complete once the block has ended.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield caught
    for record in caught:
        text = one_line(record.message)
        if issubclass(record.category, ClampWarning) and not issubclass(record.category, RangeOutlierWarning):
            text += "; --no-clip keeps them"
        print(f"warning: {text}", file=stream)
