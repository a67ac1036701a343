"""A completion's expected error without ground truth: distance-matched cross-validation on the samples.

:func:`expected_error` holds out tiles of samples, completes from the rest (``quality="fast"``, cheap), models the
held-out squared error as a function of the distance to the nearest remaining sample, and averages that model over
the unobserved pixels' own distances to the nearest sample.  It gives the expected RMSE of the completion and of
nearest fill; :func:`sparsedepth.complete_depth` with ``expected_error=True`` stores both in its result and warns
(:class:`~sparsedepth.result.NoGainWarning`) when the completion is not expected to beat nearest fill.  Its
accuracy on the report frames: ``python -m bench.expected_error`` (``docs/expected_error.md``).

May import :mod:`sparsedepth.modes.fast` and what it imports.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ._validation import as_depth_and_mask
from .modes.fast import complete_fast

__all__ = ["ExpectedError", "expected_error", "distance_model", "DEFAULT_FACTOR", "MIN_DEFAULT_FACTOR", "TILE_SCALE",
           "TILE_QUANTILE", "MIN_TILE", "MAX_TILE_SHARE", "BIN_RATIO", "MIN_BIN_COUNT", "EXPONENT_BOUNDS",
           "MIN_SAMPLES", "TileFolds", "tile_folds", "held_out_errors", "expected_mse", "departure_factor"]

#: The default completion's RMSE over the fast completion's at the same samples, the median on the calibration
#: scenes (middlebury2001/tsukuba, nyu_mmseg_pseudo/bookstore_0001d_00001, realsense_d435 80 and 130: every
#: pattern of ``python -m bench.expected_error``, seeds 0-2).  The held-out errors are those of fast completions.
DEFAULT_FACTOR = 0.9
#: With the default completion's depth at hand (``completed``), its RMSE is the fast one's times a factor of its own
#: (Notes), at least ``MIN_DEFAULT_FACTOR`` (the smallest default-over-fast RMSE ratio on the calibration scenes is
#: 0.52).
MIN_DEFAULT_FACTOR = 0.5
#: Tiles of side ``TILE_SCALE ×`` the ``TILE_QUANTILE`` quantile of the target pixels' distances to the nearest
#: sample (at least :data:`MIN_TILE` pixels) are held out together, so that the held-out samples' distances to
#: the remaining ones reach those of the pixels the estimate is about (holes, gaps between scan lines).  Chosen
#: on the calibration scenes.
TILE_SCALE, TILE_QUANTILE, MIN_TILE = 2.0, 0.9, 4
#: The largest tile side, as a share of the image's shorter side (so that every fold holds out several tiles).
MAX_TILE_SHARE = 0.125
#: Distance bins of the squared-error model: edges ``0.5 · BIN_RATIO**k`` pixels, a bin used when it holds at
#: least ``MIN_BIN_COUNT`` held-out samples.  Chosen on the calibration scenes.
BIN_RATIO, MIN_BIN_COUNT = 2.0, 20
#: Bounds of the power-law exponent ``p`` of the squared error beyond the largest held-out distance
#: (``e²(d) ∝ d^p``): 0 (no growth) to 2 (the error of a tilted plane extended by a constant).
EXPONENT_BOUNDS = (0.0, 2.0)
#: Fewest observed pixels :func:`expected_error` accepts (every fold must hold some out and keep some).
MIN_SAMPLES = 16


@dataclass(frozen=True)
class ExpectedError:
    """What :func:`expected_error` returns.

    Attributes
    ----------
    rmse : float
        Expected RMSE of the completion (``quality`` as asked) over the target pixels, in the depth's units.
    nearest_rmse : float
        Expected RMSE of nearest fill (:func:`~sparsedepth.nearest_fill`) over the same pixels.
    held_out : int
        Samples the model was fitted on (each predicted once, from the folds that kept it out).
    folds : int
    tile : int
        Side in pixels of the tiles held out together.
    exponent, nearest_exponent : float
        Power-law exponents ``p`` of the two squared-error models beyond the largest held-out distance.
    factor : float
        :attr:`rmse` over the fast completions' modelled RMSE: 1 for ``quality="fast"``, :data:`DEFAULT_FACTOR`
        for the default completion without ``completed``, its own factor with it (Notes).
    largest_distance : float
        Mean distance of the farthest distance bin of the model (pixels); target pixels farther are extrapolated.
    extrapolated : float
        Share of the target pixels farther than :attr:`largest_distance`.
    pixels : int
        Target pixels (unobserved, inside ``region``) the estimate averages over.
    """

    rmse: float
    nearest_rmse: float
    held_out: int
    folds: int
    tile: int = 0
    exponent: float = float("nan")
    nearest_exponent: float = float("nan")
    factor: float = float("nan")
    largest_distance: float = float("nan")
    extrapolated: float = float("nan")
    pixels: int = 0

    @property
    def beats_nearest(self) -> bool:
        """True when the completion is expected to be more accurate than nearest fill."""
        return bool(self.rmse < self.nearest_rmse)


def distance_model(distance, squared_error, *, bin_ratio=BIN_RATIO, min_count=MIN_BIN_COUNT,
                   exponent_bounds=EXPONENT_BOUNDS):
    """The squared error as a function of the distance to the nearest sample, from held-out samples.

    Parameters
    ----------
    distance : ndarray, (N,)
        Each held-out sample's distance (pixels, > 0) to the nearest sample kept in its fold.
    squared_error : ndarray, (N,)
        Its squared error.
    bin_ratio, min_count, exponent_bounds
        As :data:`BIN_RATIO`, :data:`MIN_BIN_COUNT`, :data:`EXPONENT_BOUNDS`.

    Returns
    -------
    model : callable
        ``model(d)``: the expected squared error at distances ``d`` (an array).
    exponent : float
        The power-law exponent ``p`` used beyond the last bin.
    largest : float
        Mean distance of the last bin.

    Notes
    -----
    The held-out samples are put in distance bins with edges ``0.5 · r^k`` (``r = bin_ratio``); a bin with at
    least ``min_count`` samples (or, when none has, every non-empty bin) gives a point ``(d̄_b, m_b)``: its mean
    distance and mean squared error.  Between the points the model is linear in ``m`` over ``log d``, and constant
    below the first.  Beyond the last point ``(d̄_L, m_L)`` it is the power law ``m_L (d / d̄_L)^p`` with ``p``
    the slope of the least-squares line of ``log m_b`` on ``log d̄_b`` weighted by the bins' counts (bins with
    ``m_b > 0``), clipped to ``exponent_bounds`` (``p = 1`` with fewer than two such bins).
    """
    distance = np.asarray(distance, dtype=np.float64)
    squared_error = np.asarray(squared_error, dtype=np.float64)
    edges = [0.5]
    while edges[-1] <= distance.max():
        edges.append(edges[-1] * bin_ratio)
    bins = np.digitize(distance, edges) - 1
    counts = np.bincount(bins, minlength=len(edges))
    sums = np.bincount(bins, squared_error, minlength=len(edges))
    distance_sums = np.bincount(bins, distance, minlength=len(edges))
    used = counts >= min_count
    if not used.any():
        used = counts > 0
    mean_distance, mean_error, weight = distance_sums[used] / counts[used], sums[used] / counts[used], counts[used]
    positive = mean_error > 0
    exponent = 1.0
    if positive.sum() >= 2:
        x, y, w = np.log(mean_distance[positive]), np.log(mean_error[positive]), weight[positive]
        x_mean = np.sum(w * x) / np.sum(w)
        exponent = float(np.sum(w * (x - x_mean) * y) / np.sum(w * (x - x_mean) ** 2))
    exponent = float(np.clip(exponent, *exponent_bounds))
    log_points, last_distance, last_error = np.log(mean_distance), mean_distance[-1], mean_error[-1]

    def model(d):
        d = np.asarray(d, dtype=np.float64)
        inside = np.interp(np.log(np.maximum(d, 1e-12)), log_points, mean_error)
        return np.where(d > last_distance, last_error * (np.maximum(d, last_distance) / last_distance) ** exponent,
                        inside)

    return model, exponent, float(last_distance)


@dataclass(frozen=True)
class TileFolds:
    """What :func:`tile_folds` returns: the folds of a cross-validation on the samples.

    Attributes
    ----------
    fold_of : ndarray of int, (N,)
        Each observed pixel's fold, in the order of ``np.nonzero(observed)``.
    folds : int
    tile : int
        Side in pixels of the tiles (held out together unless the samples themselves were dealt, Notes).
    target_distance : ndarray, (T,)
        Each target pixel's distance to the nearest sample (pixels), in the order of ``np.nonzero(target)``.
    """

    fold_of: np.ndarray
    folds: int
    tile: int
    target_distance: np.ndarray


def tile_folds(observed, target, folds=3, seed=0) -> TileFolds:
    """Deal the samples to ``folds`` folds by square tiles sized to the target pixels' distances to the samples.

    Parameters
    ----------
    observed : ndarray of bool, (H, W)
        The samples.
    target : ndarray of bool, (H, W)
        The pixels whose error the cross-validation is about (at least one).
    folds : int
        Number of folds (>= 2).
    seed : int
        Seeds the dealing (the folds are a function of it).

    Returns
    -------
    TileFolds

    Notes
    -----
    With ``D(x)`` the distance from a target pixel ``x`` to the nearest sample, the tiles have side
    ``s = max(MIN_TILE, min(round(TILE_SCALE · q_TILE_QUANTILE(D)), MAX_TILE_SHARE · min(H, W)))`` and are dealt
    to the folds by a random permutation of the tile indices modulo ``folds``; a sample's fold is its tile's.
    When every sample lands in one fold, the samples themselves are dealt at random instead.
    """
    target_distance = ndimage.distance_transform_edt(~observed)[target]
    tile = int(max(MIN_TILE, min(round(TILE_SCALE * float(np.quantile(target_distance, TILE_QUANTILE))),
                                 MAX_TILE_SHARE * min(observed.shape))))
    rng = np.random.default_rng(seed)
    rows, cols = np.nonzero(observed)
    tiles_down, tiles_across = -(-observed.shape[0] // tile), -(-observed.shape[1] // tile)
    tile_fold = rng.permutation(tiles_down * tiles_across) % folds
    fold_of = tile_fold[(rows // tile) * tiles_across + cols // tile]
    if np.unique(fold_of).size < 2:  # every sample in one fold's tiles: deal the samples themselves
        fold_of = rng.permutation(rows.size) % folds
    return TileFolds(fold_of=fold_of, folds=int(folds), tile=tile, target_distance=target_distance)


def held_out_errors(depth, observed, split: TileFolds, predict) -> tuple[np.ndarray, dict]:
    """The held-out samples' distances to the kept ones and squared errors of each prediction, fold by fold.

    Parameters
    ----------
    depth : ndarray, (H, W)
        The depth, read at the observed pixels.
    observed : ndarray of bool, (H, W)
    split : TileFolds
        The folds (:func:`tile_folds`).
    predict : callable
        ``predict(keep, kept_depth, nearest) -> {name: (H, W) prediction}`` for one fold: ``keep`` the kept
        samples, ``kept_depth`` the depth there (NaN elsewhere), ``nearest`` their nearest fill.

    Returns
    -------
    distances : ndarray, (N,)
        Each held-out sample's distance to the nearest kept sample of its fold.
    squared_errors : dict of str to ndarray, (N,)
        ``"nearest"`` (nearest fill's) and each name ``predict`` returns.
    """
    rows, cols = np.nonzero(observed)
    distances, errors = [], {}
    for fold in range(split.folds):
        held = split.fold_of == fold
        if not held.any() or held.all():
            continue
        keep = observed.copy()
        keep[rows[held], cols[held]] = False
        # nearest fill as sparsedepth.nearest_fill computes it, and the held-out samples' distances
        distance, (near_rows, near_cols) = ndimage.distance_transform_edt(~keep, return_indices=True)
        nearest = depth[near_rows, near_cols]
        held_rows, held_cols = rows[held], cols[held]
        truth = depth[held_rows, held_cols]
        distances.append(distance[held_rows, held_cols])
        predictions = {"nearest": nearest, **predict(keep, np.where(keep, depth, np.nan), nearest)}
        for name, prediction in predictions.items():
            errors.setdefault(name, []).append((prediction[held_rows, held_cols] - truth) ** 2)
    return np.concatenate(distances), {name: np.concatenate(values) for name, values in errors.items()}


def expected_mse(distances, squared_errors, target_distance) -> tuple[float, float, float]:
    """The mean over the target pixels of :func:`distance_model` fitted on held-out ``(distances, squared_errors)``.

    Returns
    -------
    mse : float
        ``mean_x m(D(x))`` over the target distances ``D``.
    exponent, largest : float
        As :func:`distance_model` returns them.
    """
    model, exponent, largest = distance_model(distances, squared_errors)
    return float(np.mean(model(target_distance))), exponent, largest


def departure_factor(completed, fast, target, fast_mse) -> float:
    """The factor ``c`` from a fast completion's expected MSE to the RMSE of ``completed`` (Notes of
    :func:`expected_error`): ``c² = max(1 − mean_T (completed − fast)² / fast_mse, MIN_DEFAULT_FACTOR²)``, NaN
    pixels of ``completed`` left out; 1 when ``fast_mse`` is 0."""
    if fast_mse <= 0:
        return 1.0
    departure = (completed - fast)[target]
    departure = departure[np.isfinite(departure)]
    gain = float(np.mean(departure ** 2)) / fast_mse if departure.size else 0.0
    return float(np.sqrt(max(1.0 - gain, MIN_DEFAULT_FACTOR ** 2)))


def expected_error(image, sparse_depth, mask=None, *, folds=3, seed=0, weights=None, quality="default",
                   region=None, completed=None) -> ExpectedError:
    """Estimate the RMSE of a completion and of nearest fill from the samples alone.

    Parameters
    ----------
    image, sparse_depth, mask
        As :func:`sparsedepth.complete_depth`'s.
    folds : int
        Folds of the cross-validation (>= 2): each holds out about ``1/folds`` of the tiles.
    seed : int
        Seeds the dealing of the tiles to the folds (the estimate is a function of it).
    weights : Weights, DensitySchedule or None
        The fast completions' weights (``None``: :data:`~sparsedepth.FAST_WEIGHTS`).
    quality : {"default", "fast"}
        The completion whose error is estimated: the default one (the fast completions' model times
        :data:`DEFAULT_FACTOR`) or the fast one (the model as measured).
    region : ndarray of bool, (H, W), optional
        The pixels the RMSE is about (the unobserved ones among them); default every unobserved pixel.
    completed : ndarray, (H, W), optional
        With ``quality="default"``: the default completion itself (``result.depth``; NaN pixels are left out),
        which sets the factor from the fast model to it for this input (Notes) at the cost of one more fast
        completion.

    Returns
    -------
    ExpectedError

    Raises
    ------
    ValueError
        Fewer than :data:`MIN_SAMPLES` observed pixels; ``folds`` not an integer >= 2; an unknown ``quality``;
        ``region`` or ``completed`` of another shape, or no unobserved pixel.

    Notes
    -----
    Let ``D(x)`` be the distance from an unobserved pixel ``x`` of the target set ``T`` to the nearest sample
    (``scipy.ndimage.distance_transform_edt``).  The image is cut into square tiles of side
    ``s = max(MIN_TILE, TILE_SCALE · q_0.9(D over T))`` dealt at random to ``folds`` folds; for each fold the
    samples in its tiles are held out, the rest completed (fast mode) and nearest-filled, and each held-out sample
    ``i`` gives its distance ``d_i`` to the nearest kept sample and its two squared errors.  Holding out tiles
    rather than single samples makes the ``d_i`` reach the distances of the pixels to be filled: a held-out
    sample inside a tile is as far from the kept ones as a pixel inside a hole.

    :func:`distance_model` turns each set of ``(d_i, e_i²)`` into ``m(d)``, the expected squared error at
    distance ``d`` (binned means, a power law with a bounded exponent beyond the farthest bin).  The estimates
    are then

    .. math:: \\widehat{RMSE} = c \\sqrt{\\tfrac{1}{|T|} \\sum_{x \\in T} m_{completion}(D(x))}, \\qquad
              \\widehat{RMSE}_{nearest} = \\sqrt{\\tfrac{1}{|T|} \\sum_{x \\in T} m_{nearest}(D(x))}

    with ``c = 1`` for the fast completion.  For the default one, ``c = DEFAULT_FACTOR`` (its RMSE over the fast
    one's, the median on the calibration scenes), or, given the default completion ``z_d`` and the fast
    completion ``z_f`` of all the samples, the factor of this input: taking the default's departure from the fast
    completion as a correction orthogonal to its own error, ``E(z_f − t)² = E(z_d − z_f)² + E(z_d − t)²``, so

    .. math:: c^2 = \\max\\Big(1 - \\frac{\\tfrac{1}{|T|} \\sum_{x \\in T} (z_d - z_f)^2}
              {\\tfrac{1}{|T|} \\sum_{x \\in T} m_{completion}(D(x))}, \\; c_{min}^2\\Big)

    with ``c_min = MIN_DEFAULT_FACTOR``.

    The held-out values are measurements: with samples of noise ``σ`` the estimate is the error against a new
    measurement, ``sqrt(e² + σ²)`` for a true error ``e`` (nearest fill of a constant scene:
    ``σ √2``).  The estimate is about ``T``: pixels where the sensor gives no depth and the scene has none either
    (sky, the zero border of a registered frame) count as far-away pixels.

    Cost: ``folds`` fast completions (one more with ``completed``) and ``folds + 1`` distance transforms (the
    nearest fills are read from those), 0.14-0.28 of a default completion's time at 640x480
    (``docs/expected_error.md``).

    Examples
    --------
    >>> import numpy as np
    >>> import sparsedepth as sd
    >>> truth = np.add.outer(np.linspace(1, 2, 60), np.linspace(0, 1, 80))   # a tilted plane, metres
    >>> image = np.repeat(truth[..., None] / 3, 3, axis=2)
    >>> sparse, mask = sd.sample_depth(truth, fraction=0.05, seed=0)
    >>> estimate = sd.expected_error.expected_error(image, sparse, mask)
    >>> estimate.beats_nearest
    True
    """
    depth, observed = as_depth_and_mask(sparse_depth, mask)
    if isinstance(folds, bool) or not isinstance(folds, (int, np.integer)) or folds < 2:
        raise ValueError(f"folds must be an integer >= 2; got {folds!r}")
    if quality not in ("default", "fast"):
        raise ValueError(f"quality must be one of ['default', 'fast']; got {quality!r}")
    count = int(observed.sum())
    if count < MIN_SAMPLES:
        raise ValueError(f"expected_error needs at least {MIN_SAMPLES} observed pixels; got {count}")
    if completed is not None:
        completed = np.asarray(completed, dtype=np.float64)
        if completed.shape != observed.shape:
            raise ValueError(f"completed has shape {completed.shape} but the depth has shape {observed.shape}")
    target = ~observed
    if region is not None:
        region = np.asarray(region, dtype=bool)
        if region.shape != observed.shape:
            raise ValueError(f"region has shape {region.shape} but the depth has shape {observed.shape}")
        target &= region
    if not target.any():
        raise ValueError("expected_error has no unobserved pixel to estimate the error of"
                         + (" inside region" if region is not None else ""))
    split = tile_folds(observed, target, int(folds), seed)

    def fast_completion(keep, kept_depth, nearest):
        return {"completion": complete_fast(image, kept_depth, keep, weights=weights).depth}

    distances, errors = held_out_errors(depth, observed, split, fast_completion)
    distance_all = split.target_distance
    fast_mse, exponent, largest = expected_mse(distances, errors["completion"], distance_all)
    nearest_mse, nearest_exponent, _ = expected_mse(distances, errors["nearest"], distance_all)
    factor = 1.0 if quality == "fast" else DEFAULT_FACTOR
    if quality == "default" and completed is not None and fast_mse > 0:
        fast = complete_fast(image, np.where(observed, depth, np.nan), observed, weights=weights).depth
        factor = departure_factor(completed, fast, target, fast_mse)
    return ExpectedError(
        rmse=factor * float(np.sqrt(fast_mse)), nearest_rmse=float(np.sqrt(nearest_mse)),
        held_out=int(distances.size), folds=int(folds), tile=split.tile, exponent=exponent,
        nearest_exponent=nearest_exponent, factor=factor, largest_distance=largest,
        extrapolated=float(np.mean(distance_all > largest)), pixels=int(distance_all.size))
