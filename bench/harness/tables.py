"""Number formatting and markdown tables.

May import numpy and :mod:`.evaluation`.
"""

from __future__ import annotations

import numpy as np

from .evaluation import mean_std, metric

__all__ = ["fmt", "markdown_table", "per_frame_table"]


def fmt(mean: float, std: float | None = None, digits: int = 3) -> str:
    """``mean ± std`` with ``digits`` significant-ish decimals."""
    def one(x):
        if not np.isfinite(x):
            return str(x)
        if x != 0 and (abs(x) >= 1e4 or abs(x) < 10 ** -(digits + 1)):
            return f"{x:.{digits - 1}e}"
        return f"{x:.{digits}f}"
    return one(mean) if std is None else f"{one(mean)} ± {one(std)}"


def markdown_table(header, rows, *, align=None) -> str:
    """A markdown table: the ``header`` cells, then one line per row (cells through ``str``).

    ``align`` gives each column's separator cell (e.g. ``"---"`` or ``"---:"``); default ``"---"`` for all.
    A cell is written with one space on either side; an empty cell as a single space (``| |``).
    """
    align = ["---"] * len(header) if align is None else list(align)
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(align) + "|"]
    lines += ["|" + "|".join(f" {c} " if str(c) else " " for c in row) + "|" for row in rows]
    return "\n".join(lines)


def per_frame_table(records, methods, *, value="rmse", sampling=None) -> str:
    """Mean over seeds of one metric, one row per frame, one column per method."""
    frames_ = list(dict.fromkeys(r.frame for r in records))
    rows = []
    for f in frames_:
        row = [f]
        for m in methods:
            vals = [metric(r, value) for r in records if r.frame == f and r.method == m
                    and (sampling is None or r.sampling == sampling)]
            row.append(fmt(*mean_std(vals)) if vals else "–")
        rows.append(row)
    return markdown_table(["frame", *methods], rows)
