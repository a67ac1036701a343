r"""Coarse operators of the hierarchy: Galerkin products :math:`P^\top A P` computed on stencils.

:func:`galerkin_offsets` gives the coarse stencil's offsets (structure, once
per grid), :func:`galerkin_stencil` its coefficient images (numbers, at every
set-up and :meth:`~.hierarchy.GridMultigrid.update`), by vectorised
arithmetic on the four parity classes of fine pixels, never by a general
sparse matrix product.  May import NumPy only.
"""

from __future__ import annotations

import numpy as np

__all__ = ["galerkin_offsets", "galerkin_stencil"]


def galerkin_offsets(offsets):
    """Offsets of P^T A P for the given fine offsets (structural)."""
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
    return sorted(out)


def galerkin_stencil(offsets, source, interp, shape, coarse_offsets, *, as_list=False):
    r"""Coarse stencil of :math:`P^\top A P` by parity-class stencil arithmetic.

    Returns an array ``(len(coarse_offsets), hc, wc)``, or with ``as_list`` a
    list of ``(hc, wc)`` images, each its own allocation (a caller that
    converts them one by one can free each once converted).

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
