"""Image-to-depth registration: shift the image onto the depth, and estimate the shift from the samples.

A depth sensor registered to a colour camera by its factory calibration (Kinect v1, many RGB-D and LiDAR rigs)
leaves the depth edges a pixel or a few away from the image edges.  Every image-guided term of the objective then
puts the depth jumps in the wrong place.  :func:`shift_image` moves the image by a whole number of pixels;
:func:`estimate_image_shift` finds that shift from the sparse samples alone, by cross-validation: the shift under
which an image-aware fill from some of the samples best predicts the others.

May import NumPy, :mod:`sparsedepth._validation` and :mod:`sparsedepth.grid`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ._validation import (
    as_depth_and_mask,
    as_float_image,
    check_count,
    check_nonnegative_count,
    check_nonnegative_real,
    check_same_shape,
    is_int,
)
from .grid.geodesic import geodesic_fill

__all__ = ["ImageShift", "shift_image", "estimate_image_shift", "pool_image_shifts", "check_shift",
           "check_image_shift", "check_shift_fits"]


def check_shift(shift, *, name: str = "shift") -> tuple[int, int]:
    """``shift`` as ``(dy, dx)`` ints; ``TypeError`` unless it is a pair of integers (not bools)."""
    try:
        pair = tuple(shift)
    except TypeError:
        raise TypeError(f"{name} must be a pair of integers (dy, dx), got {shift!r}") from None
    if len(pair) != 2 or not all(is_int(v) for v in pair):
        raise TypeError(f"{name} must be a pair of integers (dy, dx), got {shift!r}")
    return int(pair[0]), int(pair[1])


def check_image_shift(value, *, name: str = "image_shift"):
    """An ``image_shift`` option: None, ``"auto"`` or ``(dy, dx)`` ints.

    ``ValueError`` for a string other than ``"auto"``, ``TypeError`` for
    anything else that is not a pair of integers.
    """
    if value is None:
        return None
    if isinstance(value, str):
        if value != "auto":
            raise ValueError(f"{name} must be None, 'auto' or a pair of integers (dy, dx), got {value!r}")
        return value
    return check_shift(value, name=name)


def check_shift_fits(shift, shape, *, name: str = "shift") -> tuple[int, int]:
    """``shift`` as ``(dy, dx)`` ints that keep part of an image of ``shape`` in its frame.

    ``TypeError`` unless ``shift`` is a pair of integers; ``ValueError``
    naming ``name``, the shift and the frame size unless ``|dy| < H`` and
    ``|dx| < W`` (a larger shift moves the whole image out of its frame:
    every pixel would repeat one border row or column).  Python integers of
    any size are compared exactly (no overflow).
    """
    dy, dx = check_shift(shift, name=name)
    H, W = (int(n) for n in tuple(shape)[:2])
    if abs(dy) >= H or abs(dx) >= W:
        raise ValueError(f"{name} ({dy}, {dx}) moves the image out of its {H}x{W} (H x W) frame: give "
                         f"|dy| < {H} and |dx| < {W} (a registration shift is a few pixels, e.g. (0, -2))")
    return dy, dx


def shift_image(image, shift) -> np.ndarray:
    """The image moved by ``shift = (dy, dx)`` pixels, its border rows and columns repeated into the gap.

    Parameters
    ----------
    image : ndarray, (H, W) or (H, W, C)
        Any dtype; the result keeps it.
    shift : pair of int
        ``(dy, dx)``: the content moves ``dy`` rows down and ``dx`` columns
        right (negative: up, left); ``|dy| < H`` and ``|dx| < W``.

    Returns
    -------
    ndarray
        Same shape and dtype: ``out[y, x] = image[clip(y − dy), clip(x − dx)]``.

    Raises
    ------
    TypeError
        If ``shift`` is not a pair of integers.
    ValueError
        If ``image`` is not 2-D or 3-D, or ``shift`` moves it out of its
        frame (``|dy| >= H`` or ``|dx| >= W``).

    Examples
    --------
    >>> import numpy as np
    >>> shift_image(np.array([[1, 2, 3]]), (0, 1))
    array([[1, 1, 2]])
    """
    check_shift(shift)
    image = np.asarray(image)
    if image.ndim not in (2, 3):
        raise ValueError(f"image must be (H, W) or (H, W, C), got shape {image.shape}")
    H, W = image.shape[:2]
    return _moved(image, *check_shift_fits(shift, (H, W)))


def _moved(image, dy: int, dx: int) -> np.ndarray:
    """:func:`shift_image` without its checks (any ``dy``, ``dx`` that fit a C long)."""
    H, W = image.shape[:2]
    rows = np.clip(np.arange(H) - dy, 0, H - 1)
    cols = np.clip(np.arange(W) - dx, 0, W - 1)
    return image[rows[:, None], cols[None, :]]


@dataclass(frozen=True)
class ImageShift:
    """The result of :func:`estimate_image_shift` (or of :func:`pool_image_shifts`).

    Attributes
    ----------
    shift : tuple of int
        ``(dy, dx)`` to pass to :func:`shift_image`; ``(0, 0)`` when no shift
        beats the unshifted image by ``min_gain``.
    errors : ndarray, (2 R + 1, 2 R + 1)
        Mean absolute error of the held-out samples for every candidate;
        ``errors[R + dy, R + dx]`` is that of the shift ``(dy, dx)``.
    gain : float
        ``errors`` of the unshifted image over the smallest ``errors`` (>= 1).
    samples : int
        The held-out observations ``errors`` is the mean over (every observed
        pixel of the input, or of all the pooled inputs).
    """

    shift: tuple[int, int]
    errors: np.ndarray
    gain: float
    samples: int

    @property
    def best(self) -> tuple[int, int]:
        """The candidate of the smallest error (before the ``min_gain`` test)."""
        return _smallest_best(self.errors)

    def shift_at(self, min_gain: float) -> tuple[int, int]:
        """The shift under another ``min_gain``: :attr:`best` if ``gain > 1`` and ``gain >= min_gain``, else (0, 0)."""
        return self.best if self.gain > 1 and self.gain >= min_gain else (0, 0)


def estimate_image_shift(image, sparse_depth, mask=None, *, max_shift: int = 2, folds: int = 4,
                         fill_contrast: float = 20.0, min_gain: float = 1.0, seed: int = 0) -> ImageShift:
    """Estimate the shift that registers the image to the depth samples, by cross-validation.

    Parameters
    ----------
    image : ndarray, (H, W, 3) or (H, W)
        uint8, uint16 or float in [0, 1], as for :func:`complete_depth`.
    sparse_depth : ndarray, (H, W)
        Depth at the observed pixels.
    mask : ndarray of bool, (H, W), optional
        True where depth is observed; default: finite and ``> 0``.
    max_shift : int
        Candidates are every ``(dy, dx)`` with ``|dy|, |dx| <= max_shift``.
    folds : int
        The samples are split at random into this many groups; each group is
        predicted from the others.
    fill_contrast : float
        ``λ`` of the image-aware fill (:func:`geodesic_fill`) that predicts
        the held-out samples.
    min_gain : float
        A shift is returned only if the unshifted image's error is at least
        ``min_gain`` times the smallest; otherwise ``(0, 0)``.
    seed : int
        Seed of the split into groups.

    Returns
    -------
    ImageShift

    Raises
    ------
    ValueError
        For inconsistent shapes, a bad image, fewer than ``2 * folds``
        observed pixels, ``max_shift``, ``folds`` or ``seed`` that is not an
        integer (``max_shift, seed >= 0``, ``folds >= 2``), a negative
        ``fill_contrast`` or ``min_gain < 1``.
    TypeError
        If ``fill_contrast`` or ``min_gain`` is not a number.

    Notes
    -----
    For every candidate shift ``s`` and group ``g``, the image shifted by
    ``s`` guides a geodesic nearest-sample fill from the samples outside
    ``g``; the candidate's error is the mean of ``|fill(p) − z(p)|`` over the
    held-out samples ``p`` of every group.  A fill that takes a held-out
    sample's value from across a depth edge errs by the size of the jump, so
    the shift that puts the image edges where the samples' depth edges are
    predicts best.  The image is moved (:func:`shift_image`), never the
    depth.  Cost: ``folds (2 max_shift + 1)²`` fills of ``O(N log N)``.

    The estimate rests on the samples next to depth edges: with few samples
    it is noisy (``python -m bench.registration`` compares per-input and
    pooled estimates: ``docs/registration.md``), so a sensor's shift is
    better estimated once over several of its frames (:func:`pool_image_shifts`
    sums the ``errors`` of each, weighted by ``samples``, and takes the
    smallest) and then given to every frame.

    Examples
    --------
    >>> import numpy as np
    >>> depth = np.where(np.arange(40) < 20, 1.0, 3.0) * np.ones((40, 1))   # depth edge after column 19
    >>> image = (np.arange(40) >= 22) * np.ones((40, 1))                   # image edge 2 columns to the right
    >>> mask = np.random.default_rng(0).random((40, 40)) < 0.3
    >>> estimate_image_shift(image, np.where(mask, depth, 0), mask).shift
    (0, -2)
    """
    max_shift = check_nonnegative_count(max_shift, name="max_shift")
    folds = check_count(folds, name="folds")
    if folds < 2:
        raise ValueError(f"folds must be an integer >= 2, got {folds}")
    fill_contrast = check_nonnegative_real(fill_contrast, name="fill_contrast")
    min_gain = _check_min_gain(min_gain)
    seed = check_nonnegative_count(seed, name="seed")
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    img = as_float_image(image)
    check_same_shape(img.shape[:2], depth.shape, "image", "sparse_depth")
    samples = np.flatnonzero(observed)
    if samples.size < 2 * folds:
        raise ValueError(f"estimating an image shift needs at least {2 * folds} observed pixels "
                         f"(2 per fold, folds={folds}); got {samples.size}")
    # a random permutation cut into equal groups: every group is non-empty
    group = np.empty(samples.size, dtype=np.intp)
    group[np.random.default_rng(seed).permutation(samples.size)] = np.arange(samples.size) % folds
    values = depth.ravel()[samples]
    held_out = [np.flatnonzero(group == g) for g in range(folds)]  # positions in `samples` of each group
    kept_masks = []
    for held in held_out:
        kept = observed.copy()
        kept.ravel()[samples[held]] = False
        kept_masks.append(kept)
    size = 2 * max_shift + 1
    errors = np.empty((size, size))
    for i in range(size):
        for j in range(size):
            moved = _moved(img, i - max_shift, j - max_shift)
            total = 0.0
            for held, kept in zip(held_out, kept_masks):
                fill = geodesic_fill(moved, depth, kept, contrast=fill_contrast)
                total += float(np.abs(fill.ravel()[samples[held]] - values[held]).sum())
            errors[i, j] = total / samples.size
    return _chosen(errors, samples.size, min_gain)


def pool_image_shifts(estimates, *, min_gain: float = 1.0) -> ImageShift:
    """One shift from several estimates (e.g. of frames of one sensor): their errors averaged over all their samples.

    Parameters
    ----------
    estimates : sequence of ImageShift
        From :func:`estimate_image_shift` (or earlier pools), all with error
        maps of the same size (the same ``max_shift``).
    min_gain : float
        The pooled shift is returned only if the unshifted image's pooled
        error is at least ``min_gain`` times the smallest; otherwise
        ``(0, 0)``.

    Returns
    -------
    ImageShift
        ``errors`` the pooled error map, ``samples`` the total of the
        estimates' samples, ``gain`` and ``shift`` from the pooled errors as
        in :func:`estimate_image_shift`.

    Raises
    ------
    ValueError
        If ``estimates`` is empty, the error maps differ in size, a
        ``samples`` count is not positive or ``min_gain < 1``.
    TypeError
        If an item is not an :class:`ImageShift` or ``min_gain`` is not a
        number.

    Notes
    -----
    With ``E_i`` the error map of estimate ``i`` (a mean over its ``n_i``
    held-out samples)::

        E = Σ_i n_i E_i / Σ_i n_i,        n = Σ_i n_i,

    the mean held-out error over every sample of every estimate, each
    sample counting once.  With ``E_0`` the entry of the unshifted image and
    ``s*`` the candidate of the smallest entry (ties: the shortest shift),
    ``gain = E_0 / min E`` and ``shift = s*`` if ``gain > 1`` and
    ``gain >= min_gain``, else ``(0, 0)``.  A single estimate pools to
    itself (with ``min_gain`` applied again).

    An estimate from a few sparse samples is noisy; summing the held-out
    errors of several inputs before taking the smallest is what makes a
    sensor's shift reliable (``docs/registration.md``).

    Examples
    --------
    >>> import numpy as np
    >>> a = ImageShift(shift=(0, 1), errors=np.array([[3.0, 3, 3], [3, 2, 1], [3, 3, 3]]), gain=2.0, samples=30)
    >>> b = ImageShift(shift=(0, 0), errors=np.array([[3.0, 3, 3], [3, 1, 3], [3, 3, 3]]), gain=1.0, samples=10)
    >>> pooled = pool_image_shifts([a, b])
    >>> pooled.errors[1]
    array([3.  , 1.75, 1.5 ])
    >>> pooled.shift, pooled.samples, round(pooled.gain, 3)
    ((0, 1), 40, 1.167)
    """
    min_gain = _check_min_gain(min_gain)
    estimates = list(estimates)
    if not estimates:
        raise ValueError("pool_image_shifts needs at least one estimate")
    for item in estimates:
        if not isinstance(item, ImageShift):
            raise TypeError(f"pool_image_shifts pools ImageShift objects, got {type(item).__name__}")
    shape = np.shape(estimates[0].errors)
    for item in estimates:
        if np.shape(item.errors) != shape:
            raise ValueError(f"the error maps must have the same size (the same max_shift); got {shape} and "
                             f"{np.shape(item.errors)}")
        if not is_int(item.samples) or item.samples < 1:
            raise ValueError(f"every estimate needs a positive samples count, got {item.samples!r}")
    samples = sum(int(item.samples) for item in estimates)
    errors = sum(np.asarray(item.errors, dtype=float) * int(item.samples) for item in estimates) / samples
    return _chosen(errors, samples, min_gain)


def _chosen(errors, samples: int, min_gain: float) -> ImageShift:
    """The ImageShift of an error map: its gain, and its best candidate if the gain passes ``min_gain``."""
    R = errors.shape[0] // 2
    smallest = float(errors.min())
    unshifted = float(errors[R, R])
    gain = unshifted / smallest if smallest > 0 else (1.0 if unshifted == 0 else np.inf)
    unchosen = ImageShift(shift=(0, 0), errors=errors, gain=gain, samples=int(samples))
    return replace(unchosen, shift=unchosen.shift_at(min_gain))


def _check_min_gain(min_gain) -> float:
    """``min_gain`` as a float: ``TypeError`` unless a number, ``ValueError`` unless finite and ``>= 1``."""
    min_gain = check_nonnegative_real(min_gain, name="min_gain")
    if min_gain < 1:
        raise ValueError(f"min_gain must be >= 1, got {min_gain!r}")
    return min_gain


def _smallest_best(errors) -> tuple[int, int]:
    """The candidate of the smallest error; among ties, the shortest shift (then the first in row order)."""
    R = errors.shape[0] // 2
    dy, dx = np.mgrid[-R:R + 1, -R:R + 1]
    order = np.lexsort(((dy ** 2 + dx ** 2).ravel(), errors.ravel()))
    k = int(order[0])
    return int(dy.ravel()[k]), int(dx.ravel()[k])
