"""Hole filling on real NYU Depth V2 frames whose raw and filled depth are both given.

For every frame of ``../shared/data`` (or ``$SPARSEDEPTH_DATA``) with a raw depth
(``Frame.raw_depth``) - today ``nyu_rcnn_depth/demo``, a labeled-set frame whose
``depth`` is the NYU-provided colorization fill of its ``rawDepths`` - fill the
holes of the raw depth and score against the NYU filled depth on the hole pixels:

* ``nearest``        - nearest-neighbour fill (baseline);
* ``colorization``   - ``sparsedepth.fill_holes(method="colorization")``, our exact
  vectorised NYU-toolbox fill;
* ``naive port``     - ``bench/naive_colorization.py``, the per-pixel reference port
  of the toolbox (slow; skip with ``--skip-naive``);
* ``complete``       - ``sparsedepth.fill_holes(method="complete")``, our objective
  with the default weights and solver.

Prints a markdown table and writes it, with the command, date, machine and
versions, to ``docs/holefill.md`` (``--out`` to change, ``--out -`` for none).

    python bench/holefill.py
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import sparsedepth as sd  # noqa: E402


def _naive_module():
    spec = importlib.util.spec_from_file_location("naive_colorization", REPO / "bench" / "naive_colorization.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _timed(fn):
    start = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - start


def _versions() -> str:
    import pyamg
    import scipy

    try:
        commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown"
    return (f"sparsedepth {sd.__version__} (git {commit}), Python {platform.python_version()}, "
            f"NumPy {np.__version__}, SciPy {scipy.__version__}, pyamg {pyamg.__version__}")


def _machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    threads = os.environ.get("OPENBLAS_NUM_THREADS") or os.environ.get("OMP_NUM_THREADS") or "default"
    return f"{platform.platform()}, {cpu}, {os.cpu_count()} CPUs, BLAS threads: {threads}"


BORDER = 20  # pixels: "interior" holes are at least this far from the image border


def measure(frame, *, naive=None):
    """Rows (method, metrics on holes, on interior holes, max |diff| at valid raw pixels, seconds)."""
    raw, filled = frame.raw_depth, frame.depth
    holes = np.isnan(raw) & np.isfinite(filled)
    interior = np.zeros_like(holes)
    interior[BORDER:-BORDER, BORDER:-BORDER] = True
    interior &= holes
    valid = np.isfinite(raw)
    runs = [("nearest neighbour", lambda: sd.nearest_fill(raw))]
    runs.append(("colorization (sparsedepth.fill_holes)", lambda: sd.fill_holes(frame.image, raw)))
    if naive is not None:
        runs.append(("colorization, naive per-pixel port",
                     lambda: naive.fill_depth_colorization(frame.image / 255.0, np.nan_to_num(raw))))
    runs.append(("complete (fill_holes method='complete')",
                 lambda: sd.fill_holes(frame.image, raw, method="complete")))
    rows, outputs = [], {}
    for name, fn in runs:
        out, seconds = _timed(fn)
        outputs[name] = out
        metrics = sd.depth_metrics(out, filled, mask=holes)
        inner = sd.depth_metrics(out, filled, mask=interior)
        known = float(np.max(np.abs(out - filled)[valid]))
        rows.append((name, metrics, inner, known, seconds))
    agreement = None
    if naive is not None:
        agreement = float(np.max(np.abs(outputs["colorization (sparsedepth.fill_holes)"]
                                        - outputs["colorization, naive per-pixel port"])))
    return rows, holes, interior, agreement


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--skip-naive", action="store_true", help="do not run the slow per-pixel reference port")
    parser.add_argument("--out", default=str(REPO / "docs" / "holefill.md"), help="markdown file, '-' for none")
    args = parser.parse_args(argv)

    root = sd.shared_data_dir()
    if root is None or not Path(root).is_dir():
        print("no shared data folder (../shared/data or $SPARSEDEPTH_DATA); nothing to measure", file=sys.stderr)
        return 2
    frames = [sd.load_shared_frame(name) for name in sd.list_shared_frames()]
    frames = [f for f in frames if f.raw_depth is not None]
    if not frames:
        print(f"no frame with both raw and filled depth in {root}", file=sys.stderr)
        return 2
    naive = None if args.skip_naive else _naive_module()

    lines = []
    for frame in frames:
        print(f"{frame.name} ...", file=sys.stderr, flush=True)
        rows, holes, interior, agreement = measure(frame, naive=naive)
        h, w = frame.shape
        lines.append(f"### `{frame.name}` ({w}x{h}, {holes.sum()} hole pixels = {holes.mean():.1%}, "
                     f"{interior.sum()} of them at least {BORDER} px from the border)")
        lines.append("")
        lines.append("| method | RMSE holes [m] | MAE holes [m] | REL holes | δ1 holes "
                     "| RMSE interior holes [m] | MAE interior holes [m] "
                     "| max \\|out − NYU fill\\| at valid raw pixels [m] | time [s] |")
        lines.append("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        for name, m, inner, known, seconds in rows:
            lines.append(f"| {name} | {m.rmse:.4f} | {m.mae:.4f} | {m.rel:.4f} | {m.delta1:.4f} "
                         f"| {inner.rmse:.4f} | {inner.mae:.4f} | {known:.4f} | {seconds:.2f} |")
        if agreement is not None:
            lines.append("")
            lines.append(f"Largest difference between `fill_holes` (colorization) and the naive port: "
                         f"{agreement:.2e} m.")
        lines.append("")
    table = "\n".join(lines)
    print(table)

    if args.out != "-":
        env = " ".join(f"{k}={os.environ[k]}" for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS") if k in os.environ)
        command = f"{env} python bench/holefill.py " + " ".join(argv if argv is not None else sys.argv[1:])
        doc = f"""# Hole filling on real NYU Depth V2 frames

Raw Kinect depth has holes; NYU Depth V2 ships, for its labeled frames, a filled version made with the toolbox's
`fill_depth_colorization` (Levin et al. colorization).  This measures our fills against that NYU-provided filled
depth, **on the hole pixels only** (the pixels where the raw depth is missing), on every frame of the shared data
folder that has both (`Frame.raw_depth` and `Frame.depth`).  Lower is better; the NYU fill is the reference, so
this measures how well a method reproduces the toolbox, not the true depth (which is unknown in the holes).

- command: `{command.strip()}`
- date: {datetime.datetime.now().astimezone().isoformat(timespec="seconds")}
- machine: {_machine()}
- versions: {_versions()}
- times are single wall-clock runs (data loading excluded) on a shared machine; treat them as indicative

{table}
Notes:

- `nyu_rcnn_depth/demo` is the Gupta et al. 560x425 crop of a 640x480 labeled frame: NYU filled the full frame,
  so near the crop border the NYU fill saw depth (and image) that the crop does not contain.  That is where the
  colorization fill differs from the NYU fill (compare the "interior holes" columns, at least 20 px from the
  border, with the columns over all holes); this frame has no clipped 10 m raw value, so the toolbox's
  treatment of 10 m as a hole plays no role.
- The NYU filled depth itself differs from the valid raw depth at many pixels (the nearest-neighbour row of the
  "valid raw pixels" column is exactly that difference), so it is not only a fill of the same raw map.
- Neither colorization nor `complete` reproduces the valid raw pixels exactly (finite data weight): see the
  column "max |out − NYU fill| at valid raw pixels".
- `complete` uses the default weights and `solver="auto"` at the commit above; it is not tuned to imitate the
  NYU fill, so its error against the NYU fill is not an error against the true depth.
"""
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f".{out.name}.tmp")
        tmp.write_text(doc)
        os.replace(tmp, out)
        print(f"wrote {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
