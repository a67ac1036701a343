"""What the command line shows of one frame: the table on stdout, the JSON report and the figure.

Imports NumPy, :mod:`sparsedepth` (its version) and, when a figure is
drawn, matplotlib; it never writes a file (the caller commits the bytes).
"""

from __future__ import annotations

import dataclasses
import datetime
import io as _io
import math
import platform

import numpy as np

from .. import __version__
from .parser import PROG

__all__ = ["matplotlib_classes", "build_report", "print_table", "render_figure"]


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


def build_report(args, argv, outcome, description, weights, weights_given, png_scale) -> dict:
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
    }
    if result is not None:
        report.update(
            solver=result.solver, weights=weights.as_dict(), weights_given=weights_given,
            converged=result.converged, message=result.message, iterations=result.iterations,
            objective=result.objective, terms=result.terms, clamped=result.clamped,
            solver_runtime=result.runtime,
            history=[dataclasses.asdict(record) for record in result.history],
        )
    if result is not None and result.uncertainty is not None:
        report["uncertainty"] = _uncertainty_summary(outcome)
    return _jsonable(report)


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


def print_table(outcome, description, stream) -> None:
    """The frame, the solver's exit and the nearest-neighbour vs method table, on ``stream``."""
    h, w = outcome.depth.shape
    n_obs = int(outcome.observed.sum())
    print(f"{description}: {h}x{w}, {n_obs} observed pixels ({n_obs / (h * w):.1%})", file=stream)
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
        print(f"{outcome.method}: {outcome.runtime:.2f} s; no ground truth to score against "
              "(give --truth, or a dense --depth with --keep-fraction)", file=stream)
        return
    print(f"scored on {outcome.metrics.count} pixels not observed", file=stream)
    print(f"{'method':<28} {'RMSE [m]':>9} {'MAE [m]':>9} {'REL':>8} {'δ1':>7} {'time [s]':>9}", file=stream)
    for name, m, t in (("nearest neighbour", outcome.nearest_metrics, outcome.nearest_runtime),
                       (outcome.method, outcome.metrics, outcome.runtime)):
        print(f"{name:<28} {m.rmse:9.4f} {m.mae:9.4f} {m.rel:8.4f} {m.delta1:7.4f} {t:9.2f}", file=stream)


def render_figure(image, outcome, extension) -> bytes:
    """image | sparse input | nearest neighbour | completed | |error|, as file bytes."""
    Figure, FigureCanvasAgg = matplotlib_classes()
    truth = outcome.truth
    panels = 5 if truth is not None else 4
    fig = Figure(figsize=(3.2 * panels + 1.2, 3.0 * image.shape[0] / image.shape[1] + 0.8), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, panels)
    reference = outcome.sparse[outcome.observed] if truth is None else truth[np.isfinite(truth)]
    vmin, vmax = np.percentile(np.concatenate([reference, outcome.depth.ravel()]), [1, 99])
    axes[0].imshow(image, cmap="gray" if image.ndim == 2 else None)
    axes[0].set_title("image")
    depth_im = None
    for ax, data, title in ((axes[1], outcome.sparse, f"input ({int(outcome.observed.sum())} px)"),
                            (axes[2], outcome.nearest, "nearest neighbour"),
                            (axes[3], outcome.depth, outcome.method)):
        depth_im = ax.imshow(np.ma.masked_invalid(data), cmap="turbo", vmin=vmin, vmax=vmax,
                             interpolation="nearest")
        ax.set_title(title)
    fig.colorbar(depth_im, ax=axes[1:4], label="depth [m]", shrink=0.9)
    if truth is not None:
        error = np.abs(outcome.depth - truth)
        err_im = axes[4].imshow(np.ma.masked_invalid(error), cmap="magma", vmin=0,
                                vmax=max(float(np.nanpercentile(error, 99)), 1e-6), interpolation="nearest")
        axes[4].set_title("|output - truth|")
        fig.colorbar(err_im, ax=axes[4], label="absolute error [m]", shrink=0.9)
    for ax in axes:
        ax.set_axis_off()
    buffer = _io.BytesIO()
    fig.savefig(buffer, format=extension.lstrip(".").replace("jpg", "jpeg"), dpi=100)
    return buffer.getvalue()
