"""What the command line shows of one frame: the table on stdout, the JSON report and the figure.

The three report the same uncertainty statistics over the same pixels
(:func:`uncertainty_statistics`), the RMSE with the same digits
(:func:`rmse_text`), and the figure colours depth as
:func:`sparsedepth.colorize_depth` does (``--depth-vis``).

Imports NumPy, :mod:`sparsedepth` (its version, the input checks of
:mod:`sparsedepth._validation`, the colour map of :mod:`sparsedepth.visualize`)
and, when a figure is drawn, matplotlib; it never writes a file (the caller
commits the bytes).
"""

from __future__ import annotations

import dataclasses
import datetime
import io as _io
import math
import platform

import numpy as np

from .. import __version__
from .._validation import as_float_image
from ..io.writing import png_saturated
from ..objective import weights as weights_module
from ..visualize import DEPTH_COLORMAP, DEPTH_RANGE_PERCENTILES, MISSING_COLOUR, colorize_depth, depth_colour_scale
from .parser import PROG

__all__ = ["matplotlib_classes", "build_report", "print_table", "build_figure", "render_figure", "panel_pixels",
           "sample_radius", "dilate_samples", "uncertainty_png", "uncertainty_png_line", "UNCERTAINTY_PIXELS",
           "uncertainty_statistics", "removal_limits", "metres", "rmse_text", "blowups_removed", "blowups_line"]

_UINT16_MAX = 65535


def matplotlib_classes():
    """The matplotlib Figure class and Agg canvas, or None if matplotlib is missing."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return None
    return Figure, FigureCanvasAgg


def _jsonable(value):
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return _jsonable(value.item())
    return value


def build_report(args, argv, outcome, description, weights, weights_given, png_scale, intrinsics=None) -> dict:
    """The JSON report of one frame: version, command, machine, input, metrics and the solver's result and history.

    Non-finite floats become None, so that the report is strict JSON.
    """
    result = outcome.result
    report = {
        "sparsedepth": __version__,
        "command": [PROG, *argv],
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "machine": {"python": platform.python_version(), "platform": platform.platform(),
                    "processor": platform.machine()},
        "input": description,
        "shape": list(outcome.depth.shape),
        "observed": int(outcome.observed.sum()),
        "method": outcome.method,
        "runtime": outcome.runtime,
        "nearest_runtime": outcome.nearest_runtime,
        "metrics": None if outcome.metrics is None else {
            "scored": outcome.metrics.count,
            "completed": outcome.metrics.as_dict(),
            "nearest": outcome.nearest_metrics.as_dict(),
        },
        "output_png_scale": png_scale,
        "intrinsics": None if intrinsics is None else dict(zip(("fx", "fy", "cx", "cy"), map(float, intrinsics))),
        "image_shift": list(outcome.image_shift),
    }
    if getattr(args, "prior", None) is not None:
        report["prior"] = {"file": args.prior, "alignment": args.prior_alignment or "scale_shift"}
    if result is not None:
        report.update(
            solver=result.solver, weights=result.weights.as_dict(), weights_given=weights_given,
            observed_fraction=float(outcome.observed.mean()), **_weights_source(args, weights),
            converged=result.converged, message=result.message, iterations=result.iterations,
            objective=result.objective, terms=result.terms, clamped=result.clamped,
            gap=_finite_or_none(result.gap), solver_gap=_finite_or_none(result.solver_gap),
            gap_proven=bool(result.gap_proven), solver_runtime=result.runtime,
            history=[dataclasses.asdict(record) for record in result.history],
        )
    if getattr(args, "expected_error", False) and result is not None:
        report.update(expected_rmse=result.expected_rmse, expected_nearest_rmse=result.expected_nearest_rmse)
    if result is not None and result.blowups is not None:
        report["blowups"] = {"action": args.blowups, "flagged": int(np.count_nonzero(result.blowups)),
                             "removed": blowups_removed(result)}
    if result is not None and getattr(result, "selection", None) is not None:
        report["selection"] = {"chosen": result.selection.chosen, "scores": dict(result.selection.scores)}
    if result is not None and result.uncertainty is not None:
        report["uncertainty"] = _uncertainty_summary(outcome, removal_limits(args))
        png = uncertainty_png(args, outcome, png_scale)
        if png is not None:
            report["uncertainty"]["png"] = png
    return _jsonable(report)


def uncertainty_png(args, outcome, png_scale) -> dict | None:
    """With ``--uncertainty X.png``: ``{"scale", "largest", "saturated"}`` of the 16-bit PNG, else None.

    The PNG stores ``round(sigma * scale)`` between 1 and 65535
    (:func:`~sparsedepth.io.writing.write_uncertainty`): ``saturated`` counts
    the pixels whose sigma exceeds ``largest = 65535 / scale`` metres and is
    stored as ``largest``.
    """
    path = getattr(args, "uncertainty", None)
    result = outcome.result
    if path is None or not str(path).lower().endswith(".png") or result is None or result.uncertainty is None:
        return None
    return {"scale": png_scale, "largest": _UINT16_MAX / png_scale,
            "saturated": png_saturated(result.uncertainty, png_scale)}


def uncertainty_png_line(args, outcome, png_scale) -> str | None:
    """The stdout line saying how many sigma values ``--uncertainty X.png`` stores saturated, or None if none is."""
    png = uncertainty_png(args, outcome, png_scale)
    if png is None or not png["saturated"]:
        return None
    return (f"--uncertainty {args.uncertainty}: {png['saturated']} pixels have sigma above {png['largest']:.6g} m, "
            f"the largest value of a 16-bit PNG at scale {png_scale:g}, and are stored as {png['largest']:.6g} m "
            "(read: at least that); .npy, .tif or .pfm store every value")


def _weights_source(args, weights) -> dict:
    """Where the solve's weights came from; with a density schedule, its base and anchors as the batch settings
    file stores them (:func:`~sparsedepth.objective.weights.weights_settings`)."""
    with_options = " with the weight options" if weights is not None else ""
    if getattr(args, "fast", False):
        return {"weights_source": "FAST_WEIGHTS" + with_options}
    if getattr(args, "fill_holes", False):
        return {"weights_source": "DEFAULT_WEIGHTS (hole filling)" + with_options}
    return {"weights_source": "DEFAULT_SCHEDULE at the observed fraction" + with_options,
            "weights_settings": weights_module.weights_settings(weights)}


#: The pixels every uncertainty statistic is taken over (stdout, JSON, figure).
UNCERTAINTY_PIXELS = "unobserved"

#: The uncertainty percentiles reported, by name (the last one ends the figure's colour scale).
_UNCERTAINTY_PERCENTILES = (("median", 50), ("p90", 90), ("p99", 99))


def uncertainty_statistics(uncertainty, observed) -> dict:
    """The uncertainty's named statistics, the same on stdout, in the JSON report and in the figure.

    Parameters
    ----------
    uncertainty : ndarray, (H, W)
        Per-pixel uncertainty in metres.
    observed : ndarray of bool, (H, W)
        The pixels given as samples.

    Returns
    -------
    dict
        ``pixels`` (:data:`UNCERTAINTY_PIXELS`: every pixel not given as a
        sample, the ones a limit leaves missing included), ``count`` (how
        many) and ``median``, ``p90``, ``p99``: the 50th, 90th and 99th
        percentiles (``numpy.percentile``, linear interpolation) of the
        uncertainty over them, in metres; None when there is none.
    """
    values = np.asarray(uncertainty, dtype=np.float64)[~np.asarray(observed, dtype=bool)]
    values = values[np.isfinite(values)]
    statistics = {"pixels": UNCERTAINTY_PIXELS, "count": int(values.size)}
    quantiles = np.percentile(values, [q for _, q in _UNCERTAINTY_PERCENTILES]) if values.size else None
    for i, (name, _) in enumerate(_UNCERTAINTY_PERCENTILES):
        statistics[name] = None if quantiles is None else float(quantiles[i])
    return statistics


def removal_limits(args) -> dict:
    """{flag: value} of the limits that leave uncertain pixels missing (``--max-uncertainty``,
    ``--max-relative-uncertainty``), those given only."""
    return {flag: value for flag, value in (
        ("--max-uncertainty", getattr(args, "max_uncertainty", None)),
        ("--max-relative-uncertainty", getattr(args, "max_relative_uncertainty", None))) if value is not None}


def metres(value) -> str:
    """A length as stdout and the figure print it: three significant digits and the unit (``0.0412 m``)."""
    return f"{value:.3g} m"


def _uncertainty_summary(outcome, limits=None) -> dict:
    """Calibration, :func:`uncertainty_statistics`, the limits and pixels removed, and (with truth) the coverage."""
    result = outcome.result
    summary = {
        "calibration": dataclasses.asdict(result.uncertainty_calibration),
        **uncertainty_statistics(result.uncertainty, outcome.observed),
        "limits": {flag.lstrip("-").replace("-", "_"): value for flag, value in (limits or {}).items()},
        "removed": result.removed - blowups_removed(result),
    }
    if outcome.truth is not None:
        hidden = np.isfinite(outcome.truth) & ~outcome.observed & ~np.isnan(outcome.depth)
        if hidden.any():
            error = np.abs(outcome.depth - outcome.truth)[hidden]
            summary["coverage_1sigma"] = float(np.mean(error <= result.uncertainty[hidden]))
            summary["coverage_2sigma"] = float(np.mean(error <= 2 * result.uncertainty[hidden]))
    return summary


def blowups_removed(result) -> int:
    """The pixels of ``result.removed`` that ``blowups="remove"`` left missing (flagged and NaN; the uncertainty
    limits remove others)."""
    if result.blowups is None:
        return 0
    return int(np.count_nonzero(result.blowups & np.isnan(result.depth)))


def blowups_line(action, result) -> str:
    """The line of ``--blowups``: how many pixels the check flagged, and whether they were left missing."""
    flagged = int(np.count_nonzero(result.blowups))
    share = flagged / result.blowups.size
    done = "left missing" if action == "remove" else "flagged (--blowups remove leaves them missing)"
    return (f"--blowups {action}: {flagged} pixels ({share:.1%}) whose depth no nearby sample supports, {done}")


def _uncertainty_line(statistics) -> str:
    """``uncertainty over the N unobserved pixels: median .., 90th percentile .., 99th percentile ..``."""
    if statistics["median"] is None:
        return "uncertainty: every pixel observed"
    return (f"uncertainty over the {statistics['count']} {statistics['pixels']} pixels: median "
            f"{metres(statistics['median'])}, 90th percentile {metres(statistics['p90'])}, 99th percentile "
            f"{metres(statistics['p99'])}")


def print_table(outcome, description, stream, image_shift=None, limits=None) -> None:
    """The frame, the image shift (when ``image_shift``, the ``--image-shift`` value, is given), the solver's exit,
    the uncertainty's statistics and the pixels ``limits`` (:func:`removal_limits`) left missing, and the
    nearest-neighbour vs method table, on ``stream``."""
    h, w = outcome.depth.shape
    n_obs = int(outcome.observed.sum())
    print(f"{description}: {h}x{w}, {n_obs} observed pixels ({n_obs / (h * w):.1%})", file=stream)
    if image_shift is not None:
        print(_image_shift_line(outcome, image_shift), file=stream)
    if outcome.result is not None:
        r = outcome.result
        print(f"solver {r.solver}: {'converged' if r.converged else 'NOT converged'} after {r.iterations} "
              f"iterations ({r.message})", file=stream)
    if outcome.result is not None and outcome.result.uncertainty is not None:
        summary = _uncertainty_summary(outcome, limits)
        line = _uncertainty_line(summary)
        if "coverage_1sigma" in summary:
            line += (f"; |error| <= 1 sigma on {summary['coverage_1sigma']:.0%}, <= 2 sigma on "
                     f"{summary['coverage_2sigma']:.0%} of the scored pixels")
        print(line, file=stream)
        if limits:
            named = " and ".join(f"{flag} {value:g}" for flag, value in limits.items())
            print(f"{named}: {summary['removed']} pixels ({summary['removed'] / h / w:.1%}) left missing",
                  file=stream)
    if outcome.metrics is None:
        why = ("no ground truth to score against (give --truth, or a dense --depth with --keep-fraction)"
               if outcome.truth is None else
               "nothing to score: the ground truth has no valid pixel that was not observed")
        print(f"{outcome.method}: {outcome.runtime:.2f} s; {why}", file=stream)
        return
    print(f"scored on {outcome.metrics.count} pixels not observed", file=stream)
    print(f"{'method':<28} {'RMSE [m]':>9} {'MAE [m]':>9} {'REL':>8} {'δ1':>7} {'time [s]':>9}", file=stream)
    for name, m, t in (("nearest neighbour", outcome.nearest_metrics, outcome.nearest_runtime),
                       (outcome.method, outcome.metrics, outcome.runtime)):
        print(f"{name:<28} {m.rmse:9.4f} {m.mae:9.4f} {m.rel:8.4f} {m.delta1:7.4f} {t:9.2f}", file=stream)


def _image_shift_line(outcome, image_shift) -> str:
    """The table's line of the shift that moved the image, and where it came from."""
    dy, dx = outcome.image_shift
    if image_shift != "auto":
        source = f"--image-shift {image_shift[0]},{image_shift[1]}"
    elif outcome.image_shift_fallback is None:
        source = "estimated by --image-shift auto"
    else:
        source = "--image-shift auto found too few samples to estimate a shift"
    return f"image moved by dy = {dy} rows, dx = {dx} columns ({source})"


_DPI = 100
_MAX_PANEL_WIDTH = 1000  # pixels: wider frames are drawn at this width
_MIN_PANEL_WIDTH = 320  # pixels: narrower frames are enlarged to this width (room for the titles)


def sample_radius(shape) -> int:
    """Radius in pixels of the disks that show the observed samples in the figure.

    ``round(1.5 max(H, W) / 1000)``, at least 1: about a 3-pixel dot once the
    frame is drawn at :data:`_MAX_PANEL_WIDTH` pixels or less.
    """
    return max(1, round(1.5 * max(shape) / _MAX_PANEL_WIDTH))


def panel_pixels(width: int) -> int:
    """Width in pixels at which a frame ``width`` pixels wide is drawn in the figure: itself, within [320, 1000]."""
    return int(min(max(width, _MIN_PANEL_WIDTH), _MAX_PANEL_WIDTH))


def dilate_samples(sparse, observed, radius: int) -> np.ndarray:
    """The samples spread over disks of ``radius`` pixels (each pixel takes its nearest sample), NaN elsewhere."""
    out = np.where(observed, sparse, np.nan)
    filled = np.array(observed, dtype=bool)
    h, w = filled.shape
    offsets = sorted((dy * dy + dx * dx, dy, dx) for dy in range(-radius, radius + 1)
                     for dx in range(-radius, radius + 1) if 0 < dy * dy + dx * dx <= radius * radius + radius)
    for _, dy, dx in offsets:
        target = (slice(max(dy, 0), h + min(dy, 0)), slice(max(dx, 0), w + min(dx, 0)))
        source = (slice(max(-dy, 0), h + min(-dy, 0)), slice(max(-dx, 0), w + min(-dx, 0)))
        take = ~filled[target] & observed[source]
        out[target][take] = sparse[source][take]
        filled[target] |= take
    return out


def _dimmed(image) -> np.ndarray:
    """The image as a low-contrast grey picture (RGB floats around mid grey), the background of the samples."""
    grey = as_float_image(image).mean(axis=2)
    return np.repeat((0.35 + 0.35 * grey)[:, :, None], 3, axis=2)


def _grey_for_missing(cmap):
    """A copy of a matplotlib colour map with NaN (masked) pixels drawn in neutral grey."""
    return cmap.with_extremes(bad=np.asarray(MISSING_COLOUR) / 255.0)


def rmse_text(metrics) -> str:
    """``RMSE 0.1234 m``, with the digits of the table on stdout; empty without metrics."""
    return "" if metrics is None else f"RMSE {metrics.rmse:.4f} m"


#: Frames at least this many times wider than tall (a KITTI frame) are drawn two panels a row.
_WIDE_FRAME = 2.5

#: The panels in the colours of the depth.
_DEPTH_PANELS = ("image", "input", "nearest", "ours")


def _layout(has_truth: bool, has_uncertainty: bool, wide: bool = False) -> tuple[int, int, dict]:
    """(rows, columns, {panel: (row, column)}): up to 4 panels a row (2 for a ``wide`` frame), the panels of the
    truth in rows of their own."""
    if has_truth:
        second = ["truth", "uncertainty" if has_uncertainty else None, "nearest_error", "ours_error"]
        columns = 2 if wide else 4
        cells = {name: divmod(i, columns) for i, name in enumerate([*_DEPTH_PANELS, *second]) if name is not None}
        return 8 // columns, columns, cells
    names = [*_DEPTH_PANELS, *(["uncertainty"] if has_uncertainty else [])]
    columns = 2 if wide else len(names) if len(names) <= 4 else -(-len(names) // 2)
    return -(-len(names) // columns), columns, {name: divmod(i, columns) for i, name in enumerate(names)}


def _depth_range(outcome) -> tuple[float, float]:
    """(vmin, vmax) of the depth panels: the percentiles :func:`~sparsedepth.visualize.colorize_depth` uses
    (:data:`~sparsedepth.visualize.DEPTH_RANGE_PERCENTILES`) of the measured depths, the truth (or, without one, the
    samples); completed depths outside that range take the colour of its ends, so extrapolated corners do not
    flatten the colours of the measured scene."""
    truth = outcome.truth
    values = outcome.sparse[outcome.observed] if truth is None else truth[np.isfinite(truth) & (truth > 0)]
    vmin, vmax = np.percentile(values, DEPTH_RANGE_PERCENTILES)
    return float(vmin), max(float(vmax), float(vmin) + 1e-6)


def _coloured(depth, colours) -> np.ndarray:
    """``depth`` as :func:`~sparsedepth.visualize.colorize_depth` draws it on the scale ``colours`` (floats in
    [0, 1])."""
    return colorize_depth(depth, vmin=colours.vmin, vmax=colours.vmax, scale=colours.scale) / 255.0


def _depth_panels(axes, image, outcome, colours, font):
    """image | input samples on the dimmed image | nearest | output, depth in the colours of ``colours``."""
    h, w = outcome.depth.shape
    axes["image"].imshow(image, cmap="gray" if np.ndim(image) == 2 else None, interpolation="nearest")
    axes["image"].set_title("image", fontsize=font)

    radius = sample_radius((h, w))
    dots = dilate_samples(outcome.sparse, outcome.observed, radius)
    drawn = np.isfinite(dots)
    picture = _dimmed(image)
    picture[drawn] = _coloured(dots, colours)[drawn]
    axes["input"].imshow(picture, interpolation="nearest")
    n_obs = int(outcome.observed.sum())
    axes["input"].set_title(f"input: {n_obs} samples ({n_obs / (h * w):.1%}), drawn {2 * radius + 1} px wide",
                            fontsize=font)

    axes["nearest"].imshow(_coloured(outcome.nearest, colours), interpolation="nearest")
    axes["nearest"].set_title("\n".join(filter(None, ("nearest neighbour", rmse_text(outcome.nearest_metrics)))),
                              fontsize=font)

    axes["ours"].imshow(_coloured(outcome.depth, colours), interpolation="nearest")
    removed = int(np.count_nonzero(~np.isfinite(outcome.depth)))
    details = ", ".join(filter(None, (rmse_text(outcome.metrics),
                                      f"{removed} px without depth (grey)" if removed else "")))
    axes["ours"].set_title("\n".join(filter(None, (outcome.method, details))), fontsize=font)


def _truth_panels(axes, outcome, colours, font):
    """truth | |nearest - truth| | |output - truth| on one error scale; returns the last error image."""
    truth = outcome.truth
    known = np.isfinite(truth) & (truth > 0)
    axes["truth"].imshow(_coloured(np.where(known, truth, np.nan), colours), interpolation="nearest")
    axes["truth"].set_title(f"truth ({known.mean():.0%} of pixels; grey: none)", fontsize=font)
    errors = [np.where(known, np.abs(data - truth), np.nan) for data in (outcome.nearest, outcome.depth)]
    scored = known if outcome.scored is None else outcome.scored
    pooled = np.concatenate([error[scored & np.isfinite(error)] for error in errors])
    high = float(np.percentile(pooled, 99)) if pooled.size else 1.0
    style = dict(cmap=_grey_for_missing(_colormaps()["viridis"]), vmin=0.0, vmax=max(high, 1e-6),
                 interpolation="nearest")
    for name, error, label, metrics in (("nearest_error", errors[0], "|nearest - truth|", outcome.nearest_metrics),
                                        ("ours_error", errors[1], "|output - truth|", outcome.metrics)):
        shown = axes[name].imshow(np.ma.masked_invalid(error), **style)
        axes[name].set_title("\n".join(filter(None, (label, rmse_text(metrics)))), fontsize=font)
    return shown


#: Decades of the uncertainty panel's logarithmic colour scale, below its top (the 99th percentile).
_UNCERTAINTY_DECADES = 3


def _uncertainty_panel(ax, uncertainty, observed, font):
    """The uncertainty map on a logarithmic colour scale from the 99th percentile of :func:`uncertainty_statistics`
    down :data:`_UNCERTAINTY_DECADES` decades (values beyond in the end colours), NaN in grey, its statistics in the
    title; returns the image (for its bar)."""
    from matplotlib.colors import LogNorm

    statistics = uncertainty_statistics(uncertainty, observed)
    top = statistics["p99"] if statistics["p99"] else 1.0
    norm = LogNorm(vmin=top * 10.0 ** -_UNCERTAINTY_DECADES, vmax=top, clip=True)
    values = np.asarray(uncertainty, dtype=np.float64)
    shown = ax.imshow(np.ma.masked_invalid(np.maximum(values, norm.vmin)),
                      cmap=_grey_for_missing(_colormaps()["YlGnBu_r"]), norm=norm, interpolation="nearest")
    if statistics["median"] is None:
        ax.set_title("uncertainty (every pixel observed)", fontsize=font)
    else:
        ax.set_title(f"uncertainty: median {metres(statistics['median'])}, 90th percentile "
                     f"{metres(statistics['p90'])}\n({statistics['pixels']} pixels; log colours clipped at the "
                     f"99th percentile, {metres(statistics['p99'])})", fontsize=font)
    return shown


def _colour_bar(fig, shown, axes, label, font, location="right"):
    """A colour bar of ``shown`` beside ``axes`` (below them with ``location="bottom"``), labelled ``label``."""
    bar = fig.colorbar(shown, ax=axes, shrink=0.9, pad=0.01, aspect=15 if location == "right" else 30,
                       location=location)
    bar.set_label(label, fontsize=0.8 * font)
    bar.ax.tick_params(labelsize=0.8 * font)
    return bar


def _depth_colour_bar(fig, axes, colours, font):
    """The bar of the depth panels: :data:`~sparsedepth.visualize.DEPTH_COLORMAP` along ``t`` in [0, 1] (near at
    the bottom), ticks at round depths placed where ``colours`` puts them, labelled in metres."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import ListedColormap, Normalize

    shown = ScalarMappable(norm=Normalize(0.0, 1.0), cmap=ListedColormap(DEPTH_COLORMAP[::-1] / 255.0))
    spacing = ", 1/depth scale" if colours.scale == "inverse" else ""
    bar = _colour_bar(fig, shown, axes, f"depth [m]{spacing}", font)
    ticks = colours.ticks()
    bar.set_ticks(colours.position(ticks), labels=[f"{value:g}" for value in ticks])


def _colormaps():
    """matplotlib's registry of colour maps (matplotlib is imported only when a figure is drawn)."""
    from matplotlib import colormaps as registry
    return registry


def build_figure(image, outcome):
    """The figure of one frame as a matplotlib Figure (with an Agg canvas); None without matplotlib.

    Panels: image | input samples (disks of :func:`sample_radius` pixels on the
    dimmed image) | nearest neighbour | the method's output, in the colours of
    :func:`sparsedepth.colorize_depth` (near bright; spaced in inverse depth
    when the range spans a factor of
    :data:`~sparsedepth.visualize.INVERSE_DEPTH_RATIO`) between the 1st and
    99th percentiles of the truth (or samples) and the output, with a colour
    bar in metres; with ground truth, a second row: truth | (uncertainty) |
    |nearest - truth| | |output - truth| on one shared error scale; without
    truth, the uncertainty panel (``outcome.uncertainty``) follows the output.
    A frame at least :data:`_WIDE_FRAME` times wider than tall is drawn two
    panels a row, in the same order.  The uncertainty is drawn in
    logarithmic colours up to the 99th percentile of
    :func:`uncertainty_statistics`, which its title reports as stdout and the
    JSON report do.  Pixels without a value (no truth, or NaN in the output)
    are neutral grey (:data:`~sparsedepth.visualize.MISSING_COLOUR`).  Each
    panel is drawn at about :func:`panel_pixels` pixels wide (the frame's
    width, within [320, 1000]) at 100 dpi.
    """
    classes = matplotlib_classes()
    if classes is None:
        return None
    Figure, FigureCanvasAgg = classes

    h, w = outcome.depth.shape
    rows, columns, cells = _layout(outcome.truth is not None, outcome.uncertainty is not None,
                                   wide=w >= _WIDE_FRAME * h)
    panel_width = panel_pixels(w) / _DPI
    font = max(10.0, 2.0 * panel_width)
    fig = Figure(figsize=(columns * panel_width + 2.2, rows * (panel_width * h / w + 0.9) + 0.2), dpi=_DPI,
                 layout="constrained")
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(rows, columns)
    axes = {name: fig.add_subplot(grid[row, column]) for name, (row, column) in cells.items()}
    for ax in axes.values():
        ax.set_axis_off()

    vmin, vmax = _depth_range(outcome)
    colours = depth_colour_scale(np.array([[vmin, vmax]]), vmin=vmin, vmax=vmax)
    _depth_panels(axes, image, outcome, colours, font)
    other_rows = {row for name, (row, _) in cells.items() if name not in _DEPTH_PANELS}
    _depth_colour_bar(fig, [axes[name] for name in _DEPTH_PANELS if cells[name][0] not in other_rows], colours, font)
    if outcome.truth is not None:
        errors = _truth_panels(axes, outcome, colours, font)
        _colour_bar(fig, errors, [axes["nearest_error"], axes["ours_error"]], "|error| [m], both panels", font)
    if outcome.uncertainty is not None:
        from matplotlib.ticker import FuncFormatter

        shown = _uncertainty_panel(axes["uncertainty"], outcome.uncertainty, outcome.observed, font)
        bar = _colour_bar(fig, shown, axes["uncertainty"], "uncertainty [m]", font,
                          location="bottom" if cells["uncertainty"][1] < columns - 1 else "right")
        bar.formatter = FuncFormatter(lambda value, _: f"{value:g}")
        bar.update_ticks()
    return fig


def render_figure(image, outcome, extension) -> bytes:
    """The figure of :func:`build_figure`, encoded in the format of ``extension`` (".png", ".pdf", ...)."""
    fig = build_figure(image, outcome)
    buffer = _io.BytesIO()
    fig.savefig(buffer, format=extension.lstrip(".").lower().replace("jpg", "jpeg"), dpi=_DPI)
    return buffer.getvalue()


def _finite_or_none(value):
    """``value`` as a float, or None (JSON null) when it is NaN or infinite (no certificate)."""
    value = float(value)
    return value if math.isfinite(value) else None
