"""The sizes at which the package changes how it stores or processes an array: one documented settings object.

Large frames are solved with the same mathematics as small ones but with less memory: an operator kept as a
stencil instead of a CSR matrix, coarse multigrid levels in single precision, arrays processed a band of rows at a
time.  :class:`MemoryLimits` holds every size at which such a switch happens; :func:`memory_limits` returns the
limits in force and :func:`limited` changes some of them inside a ``with`` block (the tests use it to run the
large-frame paths on small arrays, ``bench.scaling`` to time both storage forms at every size).  The answers do not
depend on these sizes beyond rounding: only memory and time do.

Imports nothing of the package.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses

__all__ = ["MemoryLimits", "memory_limits", "limited"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class MemoryLimits:
    """Every size at which the package switches to a leaner way of storing or processing an array.

    Parameters
    ----------
    stencil_form_pixels : int, default 2**22
        Frames of at least this many pixels solve γ = 0 with ``A`` as a symmetric stencil
        (:func:`sparsedepth.solvers.quadratic.system_form`) instead of a CSR matrix.
    reduced_matrix_pixels : int, default 2**21
        Below this many pixels ADMM's active-set polish merges the previous reduced matrix (a smaller matrix than
        ``A``) and ADMM keeps its certificate's hierarchy between checks; from it on it works lean
        (:mod:`sparsedepth.solvers.active_set`).
    single_coarse_pixels : int, default 2**21
        Fine grids of at least this many pixels keep the coarse multigrid levels in float32
        (:class:`~sparsedepth.linalg.multigrid.GridMultigrid`, ``coarse_precision="auto"``).
    single_fine_values : int, default 2**26
        A fine operator with at most this many stored values is smoothed from a float32 copy
        (``fine_precision="auto"``); a larger one is swept from its own float64 values.
    keep_stencil_pixels : int, default 2**21
        Fine grids of fewer pixels let the multigrid set-up (:class:`~sparsedepth.linalg.multigrid.GridMultigrid`)
        hold whole stencil arrays: each CSR coarse level's ``(K, H, W)`` float64 stencil is kept as the source of
        the next level's product, with ``interpolation="operator"`` (read a parity class at a time) the fine
        operator is read into one such array once, and the line smoother's images of a fine CSR operator are
        copied as the bilinear Galerkin product reads its rows.  From it on, a coarse level's stencil is read
        back by position from its CSR form (when the grid's centre row holds every offset) and the line smoother
        reads its images from the matrix.  The bilinear product reads every level a band of rows at a time
        either way.
    banded_coarse_pixels : int, default 2**18
        Coarse levels of at least this many pixels are assembled band by band (the Galerkin products).
    gather_pixels : int, default 2**15
        Pixels gathered at a time by the line smoother's stencil rows.
    stencil_band_values : int, default 2**17
        Values per band when a symmetric stencil is read band by band (``linalg.multigrid.bands``).
    operator_band_values : int, default 2**16
        Values per band of the grid operators' banded products (``grid.operators``).
    transfer_band_pixels : int, default 2**16
        Fine pixels per band of the multigrid transfers (``linalg.multigrid.transfer``).
    affinity_band_pixels : int, default 2**15
        Pixels per band of the local-linear affinities (``grid.affinity``).
    norm_band_values : int, default 2**16
        Values per band of the image-gradient norms (``grid.edges``).
    sweep_band_values : int, default 2**17
        Values per band of the fast mode's edge-aware sweep weights (``grid.resample``).
    """

    stencil_form_pixels: int = 1 << 22
    reduced_matrix_pixels: int = 1 << 21
    single_coarse_pixels: int = 1 << 21
    single_fine_values: int = 1 << 26
    keep_stencil_pixels: int = 1 << 21
    banded_coarse_pixels: int = 1 << 18
    gather_pixels: int = 1 << 15
    stencil_band_values: int = 1 << 17
    operator_band_values: int = 1 << 16
    transfer_band_pixels: int = 1 << 16
    affinity_band_pixels: int = 1 << 15
    norm_band_values: int = 1 << 16
    sweep_band_values: int = 1 << 17

    def __post_init__(self):
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"memory limit {field.name} must be an int >= 0; got {value!r}")


_CURRENT = contextvars.ContextVar("sparsedepth_memory_limits", default=MemoryLimits())


def memory_limits() -> MemoryLimits:
    """The :class:`MemoryLimits` in force (the defaults, or those of the innermost :func:`limited` block)."""
    return _CURRENT.get()


@contextlib.contextmanager
def limited(**changes):
    """Change some :class:`MemoryLimits` inside a ``with`` block; the previous limits come back after it.

    Examples
    --------
    >>> from sparsedepth.limits import limited, memory_limits
    >>> with limited(stencil_form_pixels=1):
    ...     memory_limits().stencil_form_pixels
    1
    >>> memory_limits().stencil_form_pixels == 1 << 22
    True
    """
    unknown = sorted(set(changes) - {f.name for f in dataclasses.fields(MemoryLimits)})
    if unknown:
        raise ValueError(f"unknown memory limit(s) {unknown}; valid: "
                         f"{[f.name for f in dataclasses.fields(MemoryLimits)]}")
    token = _CURRENT.set(dataclasses.replace(_CURRENT.get(), **changes))
    try:
        yield _CURRENT.get()
    finally:
        _CURRENT.reset(token)
