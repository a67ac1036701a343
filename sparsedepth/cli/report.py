"""What the command line shows of one frame: the table on stdout, the JSON report and the figure.

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
from ..visualize import DEPTH_COLORMAP
from .parser import PROG

__all__ = ["matplotlib_classes", "build_report", "print_table", "build_figure", "render_figure", "panel_pixels",
           "sample_radius", "dilate_samples", "uncertainty_png", "uncertainty_png_line"]

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
    if result is not None and result.uncertainty is not None:
        report["uncertainty"] = _uncertainty_summary(outcome)
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


def _uncertainty_summary(outcome) -> dict:
    """Calibration, quantiles over the unobserved pixels, pixels removed, and (with truth) the coverage."""
    result = outcome.result
    sigma = result.uncertainty[~outcome.observed]
    summary = {
        "calibration": dataclasses.asdict(result.uncertainty_calibration),
        "median": float(np.median(sigma)) if sigma.size else None,
        "p90": float(np.percentile(sigma, 90)) if sigma.size else None,
        "removed": result.removed,
    }
    if outcome.truth is not None:
        hidden = np.isfinite(outcome.truth) & ~outcome.observed & ~np.isnan(outcome.depth)
        if hidden.any():
            error = np.abs(outcome.depth - outcome.truth)[hidden]
            summary["coverage_1sigma"] = float(np.mean(error <= result.uncertainty[hidden]))
            summary["coverage_2sigma"] = float(np.mean(error <= 2 * result.uncertainty[hidden]))
    return summary


def print_table(outcome, description, stream, image_shift=None) -> None:
    """The frame, the image shift (when ``image_shift``, the ``--image-shift`` value, is given), the solver's exit
    and the nearest-neighbour vs method table, on ``stream``."""
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
        summary = _uncertainty_summary(outcome)
        line = (f"uncertainty: median {summary['median']:.3g} m, 90th percentile {summary['p90']:.3g} m over the "
                f"unobserved pixels" if summary["median"] is not None else "uncertainty: every pixel observed")
        if "coverage_1sigma" in summary:
            line += (f"; |error| <= 1 sigma on {summary['coverage_1sigma']:.0%}, <= 2 sigma on "
                     f"{summary['coverage_2sigma']:.0%} of the scored pixels")
        print(line, file=stream)
        if summary["removed"]:
            print(f"--max-uncertainty: {summary['removed']} pixels ({summary['removed'] / h / w:.1%}) left missing",
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
_NEUTRAL_GREY = (0.5, 0.5, 0.5)


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
    return cmap.with_extremes(bad=_NEUTRAL_GREY)


def _rmse_text(metrics) -> str:
    return "" if metrics is None else f"RMSE {metrics.rmse:.3f} m"


def _layout(has_truth: bool, has_uncertainty: bool) -> tuple[int, int, dict]:
    """(rows, columns, {panel: (row, column)}): one row up to 4 panels, two rows beyond."""
    names = ["image", "input", "nearest", "ours"]
    if has_truth:
        cells = {name: (0, i) for i, name in enumerate(names)}
        cells.update(truth=(1, 0), nearest_error=(1, 2), ours_error=(1, 3))
        if has_uncertainty:
            cells["uncertainty"] = (1, 1)
        return 2, 4, cells
    if has_uncertainty:
        names.append("uncertainty")
    if len(names) <= 4:
        return 1, len(names), {name: (0, i) for i, name in enumerate(names)}
    columns = -(-len(names) // 2)
    return 2, columns, {name: divmod(i, columns) for i, name in enumerate(names)}


def _depth_range(outcome) -> tuple[float, float]:
    """(vmin, vmax) of the depth panels: 1st and 99th percentiles of the truth (or samples) and the output."""
    truth = outcome.truth
    reference = outcome.sparse[outcome.observed] if truth is None else truth[np.isfinite(truth) & (truth > 0)]
    values = np.concatenate([reference, outcome.depth[np.isfinite(outcome.depth)]])
    vmin, vmax = np.percentile(values, [1, 99])
    return float(vmin), max(float(vmax), float(vmin) + 1e-6)


def _depth_panels(axes, image, outcome, style, font):
    """image | input samples on the dimmed image | nearest | output; returns the samples' image (for the bar)."""
    h, w = outcome.depth.shape
    axes["image"].imshow(image, cmap="gray" if np.ndim(image) == 2 else None, interpolation="nearest")
    axes["image"].set_title("image", fontsize=font)

    radius = sample_radius((h, w))
    dots = dilate_samples(outcome.sparse, outcome.observed, radius)
    axes["input"].imshow(_dimmed(image), interpolation="nearest")
    samples = axes["input"].imshow(np.ma.masked_invalid(dots),
                                   **{**style, "cmap": style["cmap"].with_extremes(bad=(0, 0, 0, 0))})
    n_obs = int(outcome.observed.sum())
    axes["input"].set_title(f"input: {n_obs} samples ({n_obs / (h * w):.1%}), drawn {2 * radius + 1} px wide",
                            fontsize=font)

    axes["nearest"].imshow(np.ma.masked_invalid(outcome.nearest), **style)
    axes["nearest"].set_title("\n".join(filter(None, ("nearest neighbour", _rmse_text(outcome.nearest_metrics)))),
                              fontsize=font)

    axes["ours"].imshow(np.ma.masked_invalid(outcome.depth), **style)
    removed = int(np.count_nonzero(~np.isfinite(outcome.depth)))
    details = ", ".join(filter(None, (_rmse_text(outcome.metrics),
                                      f"{removed} px without depth (grey)" if removed else "")))
    axes["ours"].set_title("\n".join(filter(None, (outcome.method, details))), fontsize=font)
    return samples


def _truth_panels(axes, outcome, depth_style, font):
    """truth | |nearest - truth| | |output - truth| on one error scale; returns the last error image."""
    truth = outcome.truth
    known = np.isfinite(truth) & (truth > 0)
    axes["truth"].imshow(np.ma.masked_invalid(np.where(known, truth, np.nan)), **depth_style)
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
        axes[name].set_title("\n".join(filter(None, (label, _rmse_text(metrics)))), fontsize=font)
    return shown


def _uncertainty_panel(ax, uncertainty, font):
    """The uncertainty map from 0 to its 99th percentile, NaN in grey; returns the image (for its bar)."""
    values = np.asarray(uncertainty, dtype=np.float64)
    finite = values[np.isfinite(values)]
    top = float(np.percentile(finite, 99)) if finite.size else 1.0
    shown = ax.imshow(np.ma.masked_invalid(values), cmap=_grey_for_missing(_colormaps()["YlGnBu_r"]), vmin=0.0,
                      vmax=max(top, 1e-6), interpolation="nearest")
    ax.set_title(f"uncertainty (median {float(np.median(finite)):.3f} m)" if finite.size else "uncertainty (none)",
                 fontsize=font)
    return shown


def _colour_bar(fig, shown, axes, label, font):
    bar = fig.colorbar(shown, ax=axes, shrink=0.9, pad=0.01, aspect=15)
    bar.set_label(label, fontsize=0.8 * font)
    bar.ax.tick_params(labelsize=0.8 * font)


def _colormaps():
    """matplotlib's registry of colour maps (matplotlib is imported only when a figure is drawn)."""
    from matplotlib import colormaps as registry
    return registry


def build_figure(image, outcome):
    """The figure of one frame as a matplotlib Figure (with an Agg canvas); None without matplotlib.

    Panels: image | input samples (disks of :func:`sample_radius` pixels on the
    dimmed image) | nearest neighbour | the method's output, on one depth
    colour scale (:data:`sparsedepth.visualize.DEPTH_COLORMAP`, near bright);
    with ground truth, a second row: truth | (uncertainty) |
    |nearest - truth| | |output - truth| on one shared error scale; without
    truth, the uncertainty panel (``outcome.uncertainty``) follows the output.
    Pixels without a value (no truth, or NaN in the output) are neutral grey.
    Each panel is drawn at about :func:`panel_pixels` pixels wide (the
    frame's width, within [320, 1000]) at 100 dpi.
    """
    classes = matplotlib_classes()
    if classes is None:
        return None
    Figure, FigureCanvasAgg = classes
    from matplotlib.colors import ListedColormap

    h, w = outcome.depth.shape
    rows, columns, cells = _layout(outcome.truth is not None, outcome.uncertainty is not None)
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
    depth_style = dict(cmap=_grey_for_missing(ListedColormap(DEPTH_COLORMAP[::-1] / 255.0)), vmin=vmin, vmax=vmax,
                       interpolation="nearest")
    samples = _depth_panels(axes, image, outcome, depth_style, font)
    first_row = [axes[name] for name in ("image", "input", "nearest", "ours") if cells[name][0] == 0]
    _colour_bar(fig, samples, first_row, "depth [m]", font)
    if outcome.truth is not None:
        errors = _truth_panels(axes, outcome, depth_style, font)
        _colour_bar(fig, errors, [axes["nearest_error"], axes["ours_error"]], "absolute error [m] (same scale)", font)
    if outcome.uncertainty is not None:
        shown = _uncertainty_panel(axes["uncertainty"], outcome.uncertainty, font)
        _colour_bar(fig, shown, axes["uncertainty"], "uncertainty [m]", font)
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
