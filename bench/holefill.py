"""Hole filling on real NYU Depth V2 frames whose raw and filled depth are both given.

For every frame of ``../shared/data`` (or ``$SPARSEDEPTH_DATA``) with a raw depth
(``Frame.raw_depth``) - today ``nyu_rcnn_depth/demo``, a labeled-set frame whose
``depth`` is the NYU-provided colorization fill of its ``rawDepths`` - fill the
holes of the raw depth and score against the NYU filled depth on the hole pixels:

* ``nearest``        - nearest-neighbour fill (baseline);
* ``colorization``   - ``sparsedepth.fill_holes(method="colorization")``, our exact
  vectorised NYU-toolbox fill;
* ``naive port``     - :mod:`bench.naive_colorization`, the per-pixel reference port
  of the toolbox (slow; skip with ``--skip-naive``);
* ``complete``       - ``sparsedepth.fill_holes(method="complete")``, our objective
  with the default weights and solver.

Prints a markdown table and writes it, with the command, date, machine and
versions (the text around it is ``bench/templates/holefill.md``), to
``docs/holefill.md`` (``--out`` to change, ``--out -`` for none).  From the repository root::

    python -m bench.holefill

May import :mod:`sparsedepth`, numpy, :mod:`bench.harness` and :mod:`bench.naive_colorization`.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
from pathlib import Path
from string import Template

import numpy as np

import sparsedepth as sd

from . import harness as H
from . import naive_colorization

TEMPLATE = Path(__file__).resolve().parent / "templates" / "holefill.md"


def versions() -> str:
    """sparsedepth, Python, NumPy, SciPy and pyamg versions."""
    return (f"sparsedepth {sd.__version__}, Python {platform.python_version()}, "
            f"NumPy {H.version('numpy')}, SciPy {H.version('scipy')}, pyamg {H.version('pyamg')}")


def machine() -> str:
    """OS, CPU, core count and BLAS threads."""
    threads = os.environ.get("OPENBLAS_NUM_THREADS") or os.environ.get("OMP_NUM_THREADS") or "default"
    return f"{platform.platform()}, {H.cpu_model()}, {os.cpu_count()} CPUs, BLAS threads: {threads}"


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
        out, seconds = H.timed(fn)
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


def frame_table(frame, rows, holes, interior, agreement) -> str:
    """The markdown of one frame: a title line, the table of :func:`measure`'s rows, the agreement line."""
    h, w = frame.shape
    lines = [f"### `{frame.name}` ({w}x{h}, {holes.sum()} hole pixels = {holes.mean():.1%}, "
             f"{interior.sum()} of them at least {BORDER} px from the border)", ""]
    lines.append(H.markdown_table(
        ["method", "RMSE holes [m]", "MAE holes [m]", "REL holes", "δ1 holes", "RMSE interior holes [m]",
         "MAE interior holes [m]", "max \\|out − NYU fill\\| at valid raw pixels [m]", "time [s]"],
        [[name, f"{m.rmse:.4f}", f"{m.mae:.4f}", f"{m.rel:.4f}", f"{m.delta1:.4f}", f"{inner.rmse:.4f}",
          f"{inner.mae:.4f}", f"{known:.4f}", f"{seconds:.2f}"] for name, m, inner, known, seconds in rows],
        align=["---"] + ["---:"] * 8))
    if agreement is not None:
        lines += ["", f"Largest difference between `fill_holes` (colorization) and the naive port: {agreement:.2e} m."]
    lines.append("")
    return "\n".join(lines)


def document(table: str, argv) -> str:
    """``docs/holefill.md``: ``bench/templates/holefill.md`` around ``table``."""
    env = " ".join(f"{k}={os.environ[k]}" for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS") if k in os.environ)
    command = f"{env} {H.command_line('holefill', argv)}".strip()
    return Template(TEMPLATE.read_text()).substitute(
        command=command, date=datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        machine=machine(), versions=versions(), table=table)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--skip-naive", action="store_true", help="do not run the slow per-pixel reference port")
    parser.add_argument("--out", default=str(H.DOCS / "holefill.md"), help="markdown file, '-' for none")
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
    naive = None if args.skip_naive else naive_colorization

    tables = []
    for frame in frames:
        print(f"{frame.name} ...", file=sys.stderr, flush=True)
        tables.append(frame_table(frame, *measure(frame, naive=naive)))
    table = "\n".join(tables)
    print(table)

    if args.out != "-":
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f".{out.name}.tmp")
        tmp.write_text(document(table, argv if argv is not None else sys.argv[1:]))
        os.replace(tmp, out)
        print(f"wrote {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
