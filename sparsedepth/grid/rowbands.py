"""Bands of image rows: the pieces in which the grid kernels stream a large image through the cache.

A kernel that applies many NumPy operations to a whole image reads and writes
each of its temporaries from memory once per operation.  Applied to a band of
a few hundred kilobytes at a time, the same operations keep their partial
results in cache.  The stencil product (:mod:`.stencil`), the tap sums of
:class:`~.operators.StencilOperator`, the image pair distances (:mod:`.edges`),
the edge-aware sweeps (:mod:`.resample`) and the band-wise multigrid sweeps
(:class:`sparsedepth.linalg.multigrid.bands.BandedStencil`) cut their rows with
these two functions.

May import NumPy only.
"""

from __future__ import annotations

__all__ = ["rows_per_band", "row_bands"]


def rows_per_band(width, values, *, multiple=1):
    """Rows of a band holding about ``values`` values of a ``width``-wide image.

    Parameters
    ----------
    width : int
        Values per image row.
    values : int
        Target number of values per band.
    multiple : int, default 1
        The rows per band are a positive multiple of it (2: every band starts
        on a row of the same parity).

    Returns
    -------
    int
        ``values // width`` rounded down to a multiple of `multiple`, at least `multiple`.
    """
    rows = max(1, int(values) // max(int(width), 1))
    return max(int(multiple), rows - rows % int(multiple))


def row_bands(start, stop, rows):
    """The rows ``start:stop`` cut into consecutive bands of ``rows`` rows.

    Parameters
    ----------
    start, stop : int
        First row and one past the last.
    rows : int
        Rows per band (the last band may be shorter).

    Returns
    -------
    list of slice
        ``[slice(start, start + rows), slice(start + rows, start + 2 rows), ..., slice(..., stop)]``;
        empty when ``stop <= start``.
    """
    return [slice(y0, min(stop, y0 + rows)) for y0 in range(start, stop, rows)]
