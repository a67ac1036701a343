"""Reference port of the NYU Depth V2 toolbox ``fill_depth_colorization.m``.

This is a deliberately straightforward, loop-per-pixel Python translation of
the MATLAB function (Silberman et al., NYU Depth V2 toolbox; itself a slight
adaptation of Levin, Lischinski & Weiss, "Colorization using optimization",
SIGGRAPH 2004).  It is the correctness and speed *reference* for
:mod:`sparsedepth.holes.colorization` and lives in ``bench/`` because it is slow on
purpose: tens of seconds for a 640x480 frame, like the Python ports of the
toolbox in common use.

Differences from the MATLAB text, all of which leave the solution unchanged:

* Pixels are numbered in C (row-major) order, ``k = i * W + j``, as everywhere
  in :mod:`sparsedepth`; MATLAB numbers them column-major.  The loops still
  visit the pixels column by column as MATLAB does.  This only permutes rows
  and columns of the system.
* The grey image uses MATLAB's documented ``rgb2gray`` weights
  ``0.2989 R + 0.5870 G + 0.1140 B`` (MATLAB internally uses the unrounded
  ``0.298936021293775, 0.587043074451121, 0.114020904255103``; the difference
  is below 1e-4 and is shared with the fast implementation, see
  :data:`sparsedepth.holes.colorization.GREY_WEIGHTS`).
* The set of known pixels is ``depth != 0`` by default (the NYU toolbox also
  treats ``depth == 10`` -- the clipped Kinect maximum -- as missing; pass
  ``known=(depth != 0) & (depth != 10)`` for that behaviour).
* The linear solve is ``scipy.sparse.linalg.spsolve`` (SuperLU) instead of
  MATLAB's backslash (UMFPACK).

May import numpy and scipy only (``tests/test_colorization.py`` loads this file on its own).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

__all__ = ["rgb2gray", "naive_colorization_matrix", "fill_depth_colorization"]


def rgb2gray(img_rgb):
    """Grey image as MATLAB ``rgb2gray`` documents it, input already in [0, 1]."""
    img_rgb = np.asarray(img_rgb, dtype=np.float64)
    if img_rgb.ndim == 2:
        return img_rgb.copy()
    return 0.2989 * img_rgb[..., 0] + 0.5870 * img_rgb[..., 1] + 0.1140 * img_rgb[..., 2]


def naive_colorization_matrix(gray_img, win_rad=1):
    """The toolbox matrix ``A`` (1 on the diagonal, minus the normalised weights).

    A per-pixel loop over the ``(2 win_rad + 1)^2`` window, exactly as the MATLAB
    code builds its triplets.

    Parameters
    ----------
    gray_img : ndarray, shape (H, W)
        Grey image in [0, 1].
    win_rad : int
        Window radius (the toolbox uses 1).

    Returns
    -------
    scipy.sparse.csr_matrix, shape (H*W, H*W)
    """
    gray_img = np.asarray(gray_img, dtype=np.float64)
    H, W = gray_img.shape
    num_pix = H * W
    win_len = (2 * win_rad + 1) ** 2
    rows = np.zeros(num_pix * win_len, dtype=np.int64)
    cols = np.zeros(num_pix * win_len, dtype=np.int64)
    vals = np.zeros(num_pix * win_len)
    gvals = np.zeros(win_len)
    length = 0
    for j in range(W):  # MATLAB order: column by column
        for i in range(H):
            abs_img_ndx = i * W + j
            n_win = 0
            for ii in range(max(0, i - win_rad), min(i + win_rad, H - 1) + 1):
                for jj in range(max(0, j - win_rad), min(j + win_rad, W - 1) + 1):
                    if ii == i and jj == j:
                        continue
                    rows[length] = abs_img_ndx
                    cols[length] = ii * W + jj
                    gvals[n_win] = gray_img[ii, jj]
                    length += 1
                    n_win += 1
            cur_val = gray_img[i, j]
            gvals[n_win] = cur_val
            window = gvals[: n_win + 1]
            c_var = np.mean((window - np.mean(window)) ** 2)
            csig = c_var * 0.6
            if n_win > 0:  # MATLAB: min([]) is [] and the comparison is false
                mgv = np.min((gvals[:n_win] - cur_val) ** 2)
                if csig < (-mgv / np.log(0.01)):
                    csig = -mgv / np.log(0.01)
            if csig < 0.000002:
                csig = 0.000002
            w = np.exp(-((gvals[:n_win] - cur_val) ** 2) / csig)
            w = w / np.sum(w)
            vals[length - n_win : length] = -w
            # the self-reference, along the diagonal
            rows[length] = abs_img_ndx
            cols[length] = abs_img_ndx
            vals[length] = 1.0
            length += 1
    return scipy.sparse.csr_matrix(
        (vals[:length], (rows[:length], cols[:length])), shape=(num_pix, num_pix)
    )


def fill_depth_colorization(img_rgb, img_depth, alpha=1.0, *, known=None, win_rad=1,
                            return_timings=False):
    """Fill the holes of a depth image, the NYU toolbox way (slow reference).

    Parameters
    ----------
    img_rgb : ndarray, shape (H, W, 3) or (H, W)
        Colour (or grey) image with values in [0, 1].
    img_depth : ndarray, shape (H, W)
        Depth in metres; 0 marks a missing value.
    alpha : float
        Weight of the known depth values (the toolbox default is 1).
    known : ndarray of bool, shape (H, W), optional
        Known pixels; default ``img_depth != 0``.
    win_rad : int
        Window radius (the toolbox uses 1).
    return_timings : bool
        Also return ``(assembly_seconds, solve_seconds)``.

    Returns
    -------
    ndarray, shape (H, W)
        The filled (and, at the known pixels, smoothed) depth in metres.
    """
    img_depth = np.asarray(img_depth, dtype=np.float64)
    if known is None:
        known = img_depth != 0
    known = np.asarray(known, dtype=bool)
    t0 = time.perf_counter()
    max_img_abs_depth = np.max(img_depth[known])
    depth = img_depth / max_img_abs_depth
    depth[depth > 1] = 1
    H, W = depth.shape
    gray_img = rgb2gray(img_rgb)
    A = naive_colorization_matrix(gray_img, win_rad)
    vals = known.ravel().astype(np.float64) * alpha
    G = scipy.sparse.diags(vals, format="csr")
    system = (A + G).tocsc()
    rhs = vals * np.where(known, depth, 0.0).ravel()
    t1 = time.perf_counter()
    new_vals = scipy.sparse.linalg.spsolve(system, rhs)
    t2 = time.perf_counter()
    out = new_vals.reshape(H, W) * max_img_abs_depth
    if return_timings:
        return out, (t1 - t0, t2 - t1)
    return out
