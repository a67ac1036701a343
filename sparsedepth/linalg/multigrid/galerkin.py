r"""Coarse operators of the hierarchy: Galerkin products :math:`P^\top A P` computed on stencils.

:func:`galerkin_offsets` gives the coarse stencil's offsets (structure, once
per grid), :func:`galerkin_stencil` its coefficient images (numbers, at every
set-up and :meth:`~.hierarchy.GridMultigrid.update`), by vectorised
arithmetic on the four parity classes of fine pixels, never by a general
sparse matrix product; for the bilinear prolongation of a symmetric stencil
held as whole images, :func:`separable_galerkin_stencil` coarsens the rows,
then the columns, computing half the offsets of each symmetric product.  May import NumPy and :mod:`.stencils`.
"""

from __future__ import annotations

import functools

import numpy as np

from .stencils import mirrored_image

__all__ = ["galerkin_offsets", "galerkin_stencil"]


def galerkin_offsets(offsets):
    """Offsets of P^T A P for the given fine offsets (structural)."""
    return list(_galerkin_offsets(tuple(map(tuple, offsets))))


@functools.lru_cache(maxsize=64)
def _galerkin_offsets(offsets):
    out = set()
    for py in (0, 1):
        for px in (0, 1):
            for dy, dx in offsets:
                qy, ry = divmod(py + dy, 2)
                qx, rx = divmod(px + dx, 2)
                for ey in range(py + 1):
                    for ex in range(px + 1):
                        for fy in range(ry + 1):
                            for fx in range(rx + 1):
                                out.add((qy + fy - ey, qx + fx - ex))
    return tuple(sorted(out))


def galerkin_stencil(offsets, source, interp, shape, coarse_offsets, *, as_list=False):
    r"""Coarse stencil of :math:`P^\top A P` by parity-class stencil arithmetic.

    Returns an array ``(len(coarse_offsets), hc, wc)``, or with ``as_list`` a
    list of ``(hc, wc)`` images, each its own allocation (a caller that
    converts them one by one can free each once converted).

    With separable (bilinear) weights, a source that hands out its rows
    (:meth:`~.stencils.StencilSource.row_reader`) and offsets closed under
    negation, the product is :func:`separable_galerkin_stencil`'s (the same
    coefficients up to the order of the sums); otherwise the parity-class sums
    below.

    For a fine pixel :math:`i = (2Y+p_y, 2X+p_x)`, neighbour offset
    :math:`o = (d_y, d_x)` and parents :math:`e, f \in \{0,1\}^2`,

    .. math::

        A^c_{D}[Y+e_y, X+e_x] \mathrel{+}= W_e(i)\, S_o(i)\, W_f(i+o),
        \qquad D = \lfloor (p+d)/2 \rfloor + f - e ,

    where the floor and the parity :math:`(p+d) \bmod 2` select the class and
    shift of the neighbour :math:`j = i + o`.  All pixels of one parity class
    are processed at once.  The sum is taken in two steps: first, per offset
    :math:`E = \lfloor (p+d)/2 \rfloor + f` of a parent of :math:`j`
    relative to :math:`(Y, X)`, the row of :math:`AP`,
    :math:`(AP)_E(i) = \sum_{o, f} S_o(i) W_f(i+o)`; then
    :math:`A^c_{E-e}[Y+e_y, X+e_x] \mathrel{+}= W_e(i) (AP)_E(i)` for every
    parent :math:`e` of :math:`i`.  That is one product per (offset, parent
    of the neighbour) and one per (E, own parent), instead of one per
    (offset, both parents), and one work image per class at a time.
    """
    h, w = shape
    hc, wc = (h + 1) // 2, (w + 1) // 2
    rows_of = source.row_reader() if interp.separable else None
    if rows_of is not None and _closed_under_negation(offsets) and _closed_under_negation(coarse_offsets):
        return separable_galerkin_stencil(offsets, rows_of, interp.wy, interp.wx, coarse_offsets, as_list=as_list)
    radius = max(max(abs(dy), abs(dx)) for dy, dx in offsets)
    pad = (radius + 1) // 2
    slot = {d: i for i, d in enumerate(coarse_offsets)}
    separable = interp.separable
    if as_list:
        acc = [np.zeros((hc + 1, wc + 1)) for _ in coarse_offsets]
    else:
        acc = np.zeros((len(coarse_offsets), hc + 1, wc + 1))
    padded = {}
    for ry in (0, 1):
        for rx in (0, 1):
            if ry < h and rx < w:
                padded[ry, rx] = interp.padded_cls(ry, rx, pad, separable=separable)
    for py in (0, 1):
        for px in (0, 1):
            if py >= h or px >= w:
                continue
            terms = _ap_terms(offsets, py, px, padded)
            # parent (0, 0) of a class-(0, 0) pixel is the pixel itself: weight 1
            own = {(ey, ex): (None if py == px == 0 else interp.cls(ey, ex, py, px))
                   for ey in range(py + 1) for ex in range(px + 1)}
            _add_class(acc, slot, source.class_images(py, px), terms, own, padded, pad, separable)
    if as_list:
        return [image[:hc, :wc] for image in acc]
    return acc[:, :hc, :wc]


def _ap_terms(offsets, py, px, padded):
    """The (offset, parent of the neighbour) pairs of each parent offset ``E`` of class ``(py, px)``'s rows of AP.

    Returns ``{E: [(k, ry, rx, qy, qx, fy, fx), ...]}`` with ``k`` the
    offset's index, ``(ry, rx)`` the neighbour's class, ``(qy, qx)`` its
    coarse shift and ``(fy, fx)`` its parent.
    """
    terms = {}
    for k, (dy, dx) in enumerate(offsets):
        qy, ry = divmod(py + dy, 2)
        qx, rx = divmod(px + dx, 2)
        if (ry, rx) not in padded:
            continue  # the neighbour class is empty: S_k is zero here
        for fy in range(ry + 1):
            for fx in range(rx + 1):
                terms.setdefault((qy + fy, qx + fx), []).append((k, ry, rx, qy, qx, fy, fx))
    return terms


def _add_class(acc, slot, Ssub, terms, own, padded, pad, separable):
    """Add one parity class's contribution ``W_e (AP)_E`` to the coarse stencil images ``acc`` (in place)."""
    ny, nx = Ssub.shape[1:]
    ap = np.empty((ny, nx))
    tmp = np.empty((ny, nx))
    for (Ey, Ex), pairs in terms.items():
        for n_term, (k, ry, rx, qy, qx, fy, fx) in enumerate(pairs):
            out = ap if n_term == 0 else tmp
            if separable:  # (ny, 1) and (1, nx) factors: no dense weight images
                wfy, wfx = padded[ry, rx]
                np.multiply(Ssub[k], wfy[fy, pad + qy: pad + qy + ny, None], out=out)
                out *= wfx[fx, None, pad + qx: pad + qx + nx]
            else:
                wf = padded[ry, rx][fy, fx, pad + qy: pad + qy + ny, pad + qx: pad + qx + nx]
                np.multiply(Ssub[k], wf, out=out)
            if n_term:
                ap += tmp
        for (ey, ex), we in own.items():
            view = acc[slot[(Ey - ey, Ex - ex)]][ey: ey + ny, ex: ex + nx]
            if we is None:
                view += ap
            else:
                np.multiply(we, ap, out=tmp)
                view += tmp


def _closed_under_negation(offsets):
    """True when ``-o`` is an offset for every offset ``o`` (the stencil of a symmetric operator)."""
    present = set(map(tuple, offsets))
    return all((-dy, -dx) in present for dy, dx in present)


def _upper(dy, dx):
    """True for the centre and the offsets after it in lexicographic order."""
    return dy > 0 or (dy == 0 and dx >= 0)


def _coarsen_rows(offsets, image_of, weights, keep, target_of, *, first=0, targets=None):
    r"""One axis of a bilinear Galerkin product: :math:`P_1^\top A P_1` with :math:`P_1` acting on the rows only.

    Parameters
    ----------
    offsets : list of tuple of int
        Offsets ``(d, e)`` of the operator: ``d`` along the rows (the axis coarsened), ``e`` along the other
        axis (kept as it is).
    image_of : callable
        ``image_of(o)``: the coefficient image of offset ``o`` (float64, zero where the neighbour is outside
        the grid) on the fine rows ``first, first + 1, ...`` (those the coarse rows in `targets` read); called
        at most once per offset, only for offsets that reach a kept target.
    weights : ndarray, shape (2, n)
        Linear weights of the rows (:func:`~.interpolation.linear_weights_1d`): fine row ``i`` has the parents
        ``i // 2`` and ``i // 2 + 1`` with weights ``weights[0, i]`` and ``weights[1, i]``.
    keep : callable
        ``keep(D, e)``: whether the coarse offset ``(D, e)`` is wanted.
    target_of : callable
        ``target_of(D, e)``: the array whose row ``j`` is coarse row ``targets[0] + j``, that the coefficients
        of ``(D, e)`` are added to.
    first : int, default 0
        The fine row that row 0 of the images is.
    targets : tuple of int, optional
        ``(Y0, Y1)``: only the coarse rows ``Y0 <= Y < Y1`` are summed (default all ``(n + 1) // 2``); they
        read the fine rows ``2 Y0 - 2`` to ``2 Y1 - 1`` (within the grid).

    Notes
    -----
    Fine row :math:`2i + p` (class :math:`p`) couples through offset :math:`d` to row :math:`2(i + q) + r`,
    :math:`q = \lfloor (p + d)/2 \rfloor`, :math:`r = (p + d) \bmod 2`; with own parents :math:`i + e`,
    :math:`e \le p`, and neighbour parents :math:`i + q + f`, :math:`f \le r`,

    .. math::

        C_{(q + f - e,\, \cdot)}[i + e] \mathrel{+}= w_e(2i + p)\, a_{(d, \cdot)}(2i + p)\, w_f(2(i + q) + r).

    Away from the last two rows of an even-length axis every weight is 1 (a coarse point) or
    :math:`\tfrac12` (a point between two), so the products are :math:`2^{-(p + r)} a`: one scaled copy of the
    class's rows per offset and one slice addition per pair of parents.  The rows next to the end of an
    even-length axis (whose last point has the weights 1 and 0) are added one by one with their weights.
    Scaling by a power of two is exact, so every product is the one of the general formula; only the order of
    the sums differs.
    """
    n = weights.shape[1]
    Y0, Y1 = (0, (n + 1) // 2) if targets is None else targets
    tail = 2 if n % 2 == 0 else 0
    for d, other in offsets:
        image = None
        for p in (0, 1):
            q, r = divmod(p + d, 2)
            n_p, n_r = len(range(p, n, 2)), len(range(r, n, 2))
            lo, hi = max(0, -q), min(n_p, n_r - q)  # class rows whose neighbour is inside the grid
            end = hi - tail  # from this class row on, the weights of the axis' end
            lo, hi = max(lo, Y0 - 1), min(hi, Y1)  # ... and that have a parent among the coarse rows summed
            pairs = [(e, q + f - e) for e in range(p + 1) for f in range(r + 1) if keep(q + f - e, other)]
            if hi <= lo or not pairs:
                continue
            if image is None:
                image = image_of((d, other))
            mid = max(lo, min(hi, end))

            def rows(a, b):  # the image rows of the class rows a .. b - 1
                return image[2 * a + p - first:2 * (b - 1) + p - first + 1:2]

            if mid > lo:
                part = rows(lo, mid)
                if p + r:
                    part = part * 0.5 ** (p + r)
                for e, D in pairs:
                    a, b = max(lo, Y0 - e), min(mid, Y1 - e)
                    if b > a:
                        target_of(D, other)[a + e - Y0:b + e - Y0] += part[a - lo:b - lo]
            for i in range(mid, hi):
                for e, D in pairs:
                    f = D - q + e
                    weight = weights[e, 2 * i + p] * weights[f, 2 * (i + q) + r]
                    if weight and Y0 <= i + e < Y1:
                        target_of(D, other)[i + e - Y0] += weight * image[2 * i + p - first]


#: Fine stencil values per band of the bilinear Galerkin product (``K`` images of ``2 Y`` fine rows for ``Y``
#: coarse rows): 16 MB of float64, a fraction of a large frame's stencil, and few enough bands that the loops'
#: overhead stays small.
_GALERKIN_BAND_VALUES = 1 << 21


def separable_galerkin_stencil(offsets, rows_of, wy, wx, coarse_offsets, *, as_list=False, band_values=None):
    r"""Coarse stencil of :math:`P^\top A P` for a bilinear :math:`P = P_y \otimes P_x` and a symmetric ``A``.

    Parameters
    ----------
    offsets : list of tuple of int
        Offsets of ``A``'s stencil, closed under negation.
    rows_of : callable
        ``rows_of(y0, y1)``: the stencil on the image rows ``y0:y1``, an array ``(len(offsets), y1 − y0, W)``
        (float64, zero where the neighbour is outside the grid) that stays valid until the next call.
    wy, wx : ndarray, shapes (2, H) and (2, W)
        The 1-D linear weights of the rows and of the columns.
    coarse_offsets : list of tuple of int
        Offsets of the coarse stencil (:func:`galerkin_offsets`), closed under negation.
    as_list : bool, default False
        Return a list of ``(hc, wc)`` images, each its own allocation, instead of one array.
    band_values : int, optional
        Fine stencil values read per band (default 2**21).

    Returns
    -------
    ndarray (len(coarse_offsets), hc, wc) or list of (hc, wc) arrays

    Notes
    -----
    :math:`P^\top A P = P_x'^\top (P_y'^\top A P_y') P_x'` with :math:`P_y' = P_y \otimes I`,
    :math:`P_x' = I \otimes P_x`: the rows are coarsened first (:func:`_coarsen_rows`, giving
    :math:`B = P_y'^\top A P_y'` on an ``(hc, W)`` grid), then the columns of :math:`B`.  Both products are
    symmetric when ``A`` is, so each step computes only the offsets :math:`o \ge (0, 0)` (lexicographically)
    and reads those of :math:`-o` as mirrored images (:func:`~.stencils.mirrored_image`):
    :math:`a_{-o}(p) = a_o(p - o)`; the coarse images of the other offsets are mirrored at the end.
    Coarse row :math:`Y` depends on the fine rows :math:`2Y - 2` to :math:`2Y + 1` only and the column step
    keeps the rows apart, so both steps run over bands of coarse rows: a band of fine rows is read, its part
    of :math:`B` summed and coarsened along the columns while in cache, and neither the whole fine stencil
    nor the whole of :math:`B` is held.  The coefficients equal those of :func:`galerkin_stencil`'s
    parity-class sums up to the order of the additions (rounding).
    """
    h, w = wy.shape[1], wx.shape[1]
    hc, wc = (h + 1) // 2, (w + 1) // 2
    K = len(offsets)
    slot = {tuple(o): k for k, o in enumerate(coarse_offsets)}
    if as_list:
        out = [np.zeros((hc, wc)) for _ in coarse_offsets]
    else:
        out = np.zeros((len(coarse_offsets), hc, wc))
    index = {tuple(o): k for k, o in enumerate(offsets)}
    rows_per_band = min(hc, max(1, (_GALERKIN_BAND_VALUES if band_values is None else band_values)
                                // (2 * K * max(w, 1))))
    partial = {}  # B's offsets (DY, dx) >= (0, 0) on the band's coarse rows, reused band after band
    for Y0 in range(0, hc, rows_per_band):
        Y1 = min(hc, Y0 + rows_per_band)
        first = max(0, 2 * Y0 - 2)
        fine = rows_of(first, min(h, 2 * Y1))
        for image in partial.values():
            image[...] = 0.0

        def row_target(D, dx):
            if (D, dx) not in partial:
                partial[D, dx] = np.zeros((rows_per_band, w))
            return partial[D, dx][:Y1 - Y0]

        _coarsen_rows(offsets, lambda o: fine[index[o]], wy, _upper, row_target, first=first, targets=(Y0, Y1))

        def column_image(o):  # the transposed image of B's offset (DY, dx) = (o[1], o[0]) on the band
            dx, dy = o
            if (dy, dx) in partial:
                return partial[dy, dx][:Y1 - Y0].T
            if (-dy, -dx) in partial:
                return mirrored_image(partial[-dy, -dx][:Y1 - Y0], (-dy, -dx)).T
            return np.zeros((w, Y1 - Y0))

        def column_target(DX, DY):
            if (DY, DX) not in slot:
                raise ValueError(f"the Galerkin product reaches the offset {(DY, DX)}, not in the coarse offsets")
            return out[slot[DY, DX]][Y0:Y1].T

        column_offsets = sorted({(dx, dy) for dy, dx in partial} | {(-dx, -dy) for dy, dx in partial})
        _coarsen_rows(column_offsets, column_image, wx, lambda DX, DY: _upper(DY, DX), column_target)
    del partial
    for (dy, dx), k in slot.items():
        if not _upper(dy, dx):
            mirrored_image(out[slot[-dy, -dx]], (-dy, -dx), out=out[k])
    return out
