"""Local blow-ups of a completed depth map: pixels far from the value of every nearby sample (:func:`flag_blowups`).

A completion can put a few pixels at a depth no nearby sample supports: at a depth edge the image does not show,
the smoothness terms carry foreground and background into each other and the pixels between the two sides take a
value in the middle of the jump, metres from either.  Cross-validation on held-out samples does not see them (the
samples sit on one side or the other), and the global range clamp does not either (the value lies inside the
range of the samples).  :func:`flag_blowups` marks such pixels from the completed depth and the samples alone;
:func:`remove_blowups` sets them to NaN or to the nearest sample's value.  ``docs/blowups.md``
(``python -m bench.blowups --out docs/blowups.md``) measures what the check catches and what it does not.

May import NumPy, SciPy and :mod:`sparsedepth._validation`.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from ._validation import as_depth_and_mask, check_bool_mask, check_count, check_positive_real, check_same_shape

__all__ = ["flag_blowups", "remove_blowups", "blowup_evidence", "judge_blowups", "BLOWUP_GAP", "BLOWUP_MISFIT",
           "BLOWUP_NEIGHBOURS", "REPLACEMENTS"]

#: ``τ``: a pixel is a candidate when its depth is farther than ``τ · z`` from the value of each of its nearest
#: samples (the calibration scenes' choice: ``python -m bench.blowups``, section "Calibration").
BLOWUP_GAP = 0.1
#: ``ρ``: the nearest samples explain a candidate when a plane fits them to an RMS residual below ``ρ`` times the
#: candidate's gap and predicts its depth within ``τ · z`` (chosen with :data:`BLOWUP_GAP`).
BLOWUP_MISFIT = 0.05
#: ``K``: the number of nearest samples a pixel is compared with.
BLOWUP_NEIGHBOURS = 8
#: The values of :func:`remove_blowups`'s ``replace``.
REPLACEMENTS = ("nan", "nearest")


def flag_blowups(depth, sparse_depth, mask=None, *, gap=BLOWUP_GAP, misfit=BLOWUP_MISFIT,
                 neighbours=BLOWUP_NEIGHBOURS) -> np.ndarray:
    """Mark the completed pixels whose depth no nearby sample supports.

    Parameters
    ----------
    depth : ndarray, (H, W)
        A completed (dense) depth map, e.g. ``complete_depth(...).depth``; NaN pixels are never flagged.
    sparse_depth : ndarray, (H, W)
        The depth samples the completion was made from (any values where ``mask`` is False).
    mask : ndarray of bool, (H, W), optional
        True where ``sparse_depth`` is observed; default: finite and ``> 0``.
    gap : float
        ``τ > 0``: the least distance, as a share of the pixel's depth, between the pixel's depth and the value of
        each of its ``neighbours`` nearest samples (:data:`BLOWUP_GAP`).
    misfit : float
        ``ρ > 0``: the nearest samples explain the pixel's depth when their least-squares plane predicts it within
        ``τ · z`` and fits them to an RMS residual below ``ρ`` times the pixel's gap (:data:`BLOWUP_MISFIT`).
    neighbours : int
        ``K >= 3``: how many nearest samples (Euclidean pixel distance) a pixel is compared with
        (:data:`BLOWUP_NEIGHBOURS`); at most the number of samples.

    Returns
    -------
    ndarray of bool, (H, W)
        True at the unobserved pixels judged blown up; False at every sample.

    Raises
    ------
    ValueError
        For a ``depth`` that is not 2-D or not of the shape of ``sparse_depth``, a bad ``mask`` or samples (as
        :func:`sparsedepth.complete_depth`), fewer than 3 samples, ``gap`` or ``misfit`` not finite and > 0, or a
        ``neighbours`` that is not an integer >= 3.
    TypeError
        For a ``depth`` that is not numeric, or a ``gap`` or ``misfit`` that is not a number.

    Notes
    -----
    For an unobserved pixel ``p`` with completed depth ``z_p``, let ``v_1 … v_K`` be the values of its ``K``
    nearest samples, at offsets ``(Δr_k, Δc_k)`` from ``p``.  Its gap is

    .. math:: g_p = \\min_k |z_p - v_k|,

    and the samples' plane is the least-squares fit ``v_k ≈ a + b Δr_k + c Δc_k`` with RMS residual ``s_p``
    (``a`` is its prediction at ``p``), or the fit of ``1 / v_k`` by ``a' + b' Δr_k + c' Δc_k`` with ``a = 1 / a'``
    and the residual ``s_p`` of ``v_k − 1 / (a' + b' Δr_k + c' Δc_k)``, whichever has the smaller ``s_p`` (a
    plane of the scene is affine in inverse depth in a pinhole image, and in disparity).  The pixel is flagged when

    .. math:: g_p > τ z_p \\quad\\text{and not}\\quad (|z_p - a| \\le τ z_p \\;\\text{and}\\; s_p < ρ g_p).

    The first condition catches values in the middle of a depth jump, which lie inside the range of the nearby
    samples and so pass a local min/max test; the exemption keeps a steep ramp, where the samples are far apart
    in value but lie on one plane through the pixel's depth (scan lines across a floor).  A value between two
    sides of a depth edge leaves a large residual (the samples are not one plane); a spike on a plane is far from
    the plane's prediction.  Where the ``K`` samples lie on one line (next to a scan line) no plane is
    determined and the pixel is not flagged.  A depth edge with a single sample column on either side is a ramp to
    this rule (two values fit a plane exactly), and scan lines show a horizontal edge as two rows of samples only:
    a value on the straight line between the two rows' values is exempt there.

    Only the pixels farther than ``τ z_p`` from the nearest sample's value (``g_p <= |z_p - v_nearest|``, from a
    Euclidean distance transform) go on to the ``K``-nearest-neighbour query (``scipy.spatial.cKDTree``), so the
    cost follows the number of candidates.  :data:`BLOWUP_GAP` and :data:`BLOWUP_MISFIT` are the choice of the
    calibration scenes (``bench.blowups.CALIBRATION_FRAMES`` and two synthetic scenes, none of them a report
    frame); ``python -m bench.blowups`` prints the grid, the rule and the choice (``docs/blowups.md``).

    Examples
    --------
    >>> import numpy as np
    >>> sparse = np.zeros((9, 9)); mask = np.zeros((9, 9), bool)
    >>> mask[::2, ::2] = True; sparse[mask] = np.where(np.nonzero(mask)[1] < 4, 1.0, 3.0)
    >>> depth = np.where(np.arange(9) < 4, 1.0, 3.0) * np.ones((9, 1)); depth[4, 3] = 2.0
    >>> np.argwhere(flag_blowups(depth, sparse, mask)).tolist()
    [[4, 3]]
    """
    completed, samples, observed, gap, neighbours = _check_inputs(depth, sparse_depth, mask, gap, neighbours)
    misfit = check_positive_real(misfit, name="misfit")
    return _flag(completed, samples, observed, gap, misfit, neighbours)


def remove_blowups(depth, flagged, *, replace="nan", sparse_depth=None, mask=None) -> np.ndarray:
    """A copy of ``depth`` with the ``flagged`` pixels set to NaN or to the nearest sample's value.

    Parameters
    ----------
    depth : ndarray, (H, W)
        A completed depth map.
    flagged : ndarray of bool, (H, W)
        The pixels to remove, e.g. from :func:`flag_blowups`.
    replace : {"nan", "nearest"}
        ``"nan"`` (default): NaN, so the removed pixels are missing depth; ``"nearest"``: the value of the nearest
        sample (:func:`sparsedepth.nearest_fill`), which needs ``sparse_depth``; keep ``flagged`` to know which
        pixels were replaced.
    sparse_depth : ndarray, (H, W), optional
        The samples, for ``replace="nearest"``.
    mask : ndarray of bool, (H, W), optional
        True where ``sparse_depth`` is observed; default: finite and ``> 0``.

    Returns
    -------
    ndarray, (H, W), float64
        The input is not modified.

    Raises
    ------
    ValueError
        For an unknown ``replace``, ``replace="nearest"`` without ``sparse_depth``, or arrays of different shapes.

    Notes
    -----
    Replacement by the nearest sample trades a value in the middle of a depth jump (off by about half the jump)
    for the value of one side (right, or off by the whole jump).  ``python -m bench.blowups`` scores both on the
    shared frames (``docs/blowups.md``): there the replacement raises the RMSE over the input's, and removal
    lowers the RMSE of the pixels that remain, so NaN is the default.
    """
    completed = _as_depth(depth)
    flagged = check_bool_mask(flagged, completed.shape, name="flagged", shape_name="depth")
    if not isinstance(replace, str) or replace not in REPLACEMENTS:
        raise ValueError(f"replace must be one of {list(REPLACEMENTS)}, got {replace!r}")
    out = completed.copy()
    if replace == "nan":
        out[flagged] = np.nan
        return out
    if sparse_depth is None:
        raise ValueError('replace="nearest" needs sparse_depth (the samples the depth was completed from)')
    samples, observed = as_depth_and_mask(sparse_depth, mask)
    check_same_shape(samples.shape, completed.shape, "sparse_depth", "depth")
    ii, jj = ndimage.distance_transform_edt(~observed, return_distances=False, return_indices=True)
    out[flagged] = samples[ii[flagged], jj[flagged]]
    return out


def _as_depth(depth) -> np.ndarray:
    completed = np.asarray(depth)
    if completed.ndim != 2:
        raise ValueError(f"depth must be a 2-D (H, W) array, got shape {completed.shape}")
    if not (np.issubdtype(completed.dtype, np.floating) or np.issubdtype(completed.dtype, np.integer)):
        raise TypeError(f"depth must be a numeric array, got dtype {completed.dtype}")
    return completed.astype(np.float64)


def _check_inputs(depth, sparse_depth, mask, gap, neighbours):
    """Checked ``(depth, samples, observed, gap, neighbours)``, ``neighbours`` at most the number of samples."""
    completed = _as_depth(depth)
    samples, observed = as_depth_and_mask(sparse_depth, mask)
    check_same_shape(samples.shape, completed.shape, "sparse_depth", "depth")
    gap = check_positive_real(gap, name="gap")
    neighbours = check_count(neighbours, name="neighbours")
    if neighbours < 3:
        raise ValueError(f"neighbours must be at least 3 (a plane has 3 parameters), got {neighbours}")
    count = int(np.count_nonzero(observed))
    if count < 3:
        raise ValueError(f"sparse_depth has {count} observed pixel(s); at least 3 are needed to fit a plane")
    return completed, samples, observed, gap, min(neighbours, count)


def _flag(completed, samples, observed, gap, misfit, neighbours) -> np.ndarray:
    """The rule of :func:`flag_blowups` on checked inputs."""
    evidence = _evidence(completed, samples, observed, gap, neighbours)
    flagged = np.zeros(completed.shape, dtype=bool)
    flagged[evidence["rows"], evidence["cols"]] = judge_blowups(evidence, gap=gap, misfit=misfit)
    return flagged


def blowup_evidence(depth, sparse_depth, mask=None, *, gap=BLOWUP_GAP, neighbours=BLOWUP_NEIGHBOURS) -> dict:
    """What :func:`flag_blowups` computes at its candidate pixels, to judge them at several thresholds.

    Parameters are those of :func:`flag_blowups`; the candidates are the unobserved pixels farther than
    ``gap · z`` from the nearest sample's value, so the evidence serves every ``gap`` at least this one.

    Returns
    -------
    dict of str to ndarray, each of shape (n,)
        ``rows``, ``cols`` (the candidates), ``depth`` (``z_p``), ``gap`` (``g_p``), ``plane`` (``a``) and
        ``plane_rms`` (``s_p``) in the notation of :func:`flag_blowups`, and ``inside`` (bool: ``z_p`` lies
        strictly between the smallest and the largest ``v_k``, where a local min/max test passes it) and
        ``collinear`` (bool: the ``K`` samples lie on one line, so no plane is fitted and the pixel is not judged).
        :func:`judge_blowups` applies the rule.
    """
    completed, samples, observed, gap, neighbours = _check_inputs(depth, sparse_depth, mask, gap, neighbours)
    return _evidence(completed, samples, observed, gap, neighbours)


def judge_blowups(evidence, *, gap=BLOWUP_GAP, misfit=BLOWUP_MISFIT) -> np.ndarray:
    """The rule of :func:`flag_blowups` on :func:`blowup_evidence`: a bool per candidate, True when flagged."""
    z = evidence["depth"]
    explained = (np.abs(z - evidence["plane"]) <= gap * np.abs(z)) & (evidence["plane_rms"] < misfit * evidence["gap"])
    return (evidence["gap"] > gap * np.abs(z)) & ~explained & ~evidence["collinear"]


def _evidence(completed, samples, observed, gap, neighbours) -> dict:
    """:func:`blowup_evidence` on checked inputs."""
    ii, jj = ndimage.distance_transform_edt(~observed, return_distances=False, return_indices=True)
    with np.errstate(invalid="ignore"):
        candidate = ~observed & (np.abs(completed - samples[ii, jj]) > gap * np.abs(completed))
    rows, cols = np.nonzero(candidate)
    z = completed[rows, cols]
    if rows.size == 0:
        empty = np.zeros(0)
        return {"rows": rows, "cols": cols, "depth": z, "gap": empty, "plane": empty, "plane_rms": empty,
                "inside": np.zeros(0, dtype=bool), "collinear": np.zeros(0, dtype=bool)}
    sample_rows, sample_cols = np.nonzero(observed)
    values = samples[sample_rows, sample_cols]
    _, nearest = cKDTree(np.column_stack([sample_rows, sample_cols])).query(np.column_stack([rows, cols]),
                                                                           k=neighbours)
    nearest = nearest.reshape(rows.size, neighbours)
    near_values = values[nearest]
    design = np.stack([np.ones(nearest.shape), sample_rows[nearest] - rows[:, None],
                       sample_cols[nearest] - cols[:, None]], axis=-1).astype(np.float64)
    normal = np.einsum("nki,nkj->nij", design, design)
    collinear = np.abs(np.linalg.det(normal)) <= 1e-9 * np.einsum("nii->n", normal) ** 3
    plane, plane_rms = _plane_fit(design, normal, collinear, near_values)
    inverse_plane, inverse_rms = _plane_fit(design, normal, collinear, 1.0 / near_values, inverse=True)
    use_inverse = inverse_rms < plane_rms
    return {"rows": rows, "cols": cols, "depth": z, "gap": np.abs(near_values - z[:, None]).min(axis=1),
            "plane": np.where(use_inverse, inverse_plane, plane), "plane_rms": np.minimum(plane_rms, inverse_rms),
            "inside": (near_values.min(axis=1) < z) & (z < near_values.max(axis=1)), "collinear": collinear}


def _plane_fit(design, normal, singular, values, *, inverse=False):
    """``(prediction at the pixel, RMS residual at the samples)`` of the least-squares plane through ``values``, in
    depth units; with ``inverse`` the values are inverse depths and the plane's predictions are inverted back
    (NaN prediction and infinite residual where the plane reaches inverse depth 0 or below)."""
    coefficients = _solve_normal(normal, singular, np.einsum("nki,nk->ni", design, values))
    fitted = np.einsum("nki,ni->nk", design, coefficients)
    prediction = coefficients[:, 0]
    if inverse:
        with np.errstate(divide="ignore", invalid="ignore"):
            valid = (fitted > 0).all(axis=1) & (prediction > 0)
            fitted, values, prediction = 1.0 / fitted, 1.0 / values, np.where(valid, 1.0 / prediction, np.nan)
        rms = np.where(valid, np.sqrt(np.mean((values - np.where(valid[:, None], fitted, 0.0)) ** 2, axis=1)), np.inf)
        return prediction, rms
    return prediction, np.sqrt(np.mean((values - fitted) ** 2, axis=1))


def _solve_normal(normal, singular, rhs) -> np.ndarray:
    """Least-squares coefficients from stacked 3x3 normal equations; the ``singular`` ones (samples on a line) get
    the minimum-norm solution by the pseudo-inverse."""
    out = np.empty_like(rhs)
    if (~singular).any():
        out[~singular] = np.linalg.solve(normal[~singular], rhs[~singular, :, None])[..., 0]
    if singular.any():
        out[singular] = np.einsum("nij,nj->ni", np.linalg.pinv(normal[singular]), rhs[singular])
    return out
