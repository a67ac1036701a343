"""The pictures of the docs: front-page figures of four sensors, the overview, and the uncertainty limits.

Run::

    python -m bench.figures            # writes docs/figures/ (needs matplotlib and the shared data folder)

Every picture comes from runs of the command line, ``python -m sparsedepth.complete`` (the commands are
printed), on the shared frames (``$SPARSEDEPTH_DATA`` or ``../shared/data``) with 5 % of the frame's valid ground
truth kept at random (seed 0) and the default weights:

* ``<sensor>.png`` (:data:`FRONT`): the ``--figure`` of a run with ``--uncertainty``, for KITTI
  (``kitti_metric3d`` 0000000050, the bottom 256 rows: the LiDAR sees nothing above them), NYU Depth V2
  (``nyu_metric3d`` 00050, the area with depth inside the frame's border), RealSense D435
  (``realsense_cleargrasp`` 000000080) and TUM RGB-D (``tum_open3d``), copied by :func:`for_docs` (at most
  :data:`DOCS_WIDTH` pixels wide, 256 colours, under :data:`MAX_BYTES`).
* ``overview.png``: image | sparse input | completed depth | the completed depth's coloured point cloud
  (:func:`sparsedepth.io.depth_to_points`) seen from a viewpoint turned :data:`VIEW_TURN` degrees, of the
  KITTI run.
* ``uncertainty_limits.csv``: the percentage of the pixels that ``--max-uncertainty M`` and
  ``--max-relative-uncertainty R`` leave missing (:func:`sparsedepth.uncertainty.too_uncertain`, the rule of the
  command line) on those runs and on the whole KITTI frame 0000000005 with its LiDAR ground truth as the input:
  of the frame, of the measured region (the unobserved pixels with ground truth; on the LiDAR run, the pixels
  between its points) and of that region's nearest quarter by completed depth (near objects; on KITTI the road in
  front of the car).  On the whole KITTI frame the LiDAR sees nothing above the street: the sky is most of what
  the limits leave missing there.
* ``<frame>_all_vis.png``, ``<frame>_trusted_vis.png`` and ``<frame>_trusted.jpg`` (:data:`CASES`, the figures of
  ``docs/uncertainty.md``): ``--depth-vis`` of the plain run, and ``--depth-vis`` and ``--figure`` (copied by
  :func:`for_docs` as a JPEG) of the run with ``--max-uncertainty``.

May import :mod:`sparsedepth`, :mod:`bench.harness`, matplotlib and Pillow (matplotlib's).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from scipy import ndimage

import sparsedepth as sd
from sparsedepth.batch.evaluate import frame_observations
from sparsedepth.cli.report import dilate_samples, sample_radius
from sparsedepth.complete import main as command
from sparsedepth.io import depth_to_points
from sparsedepth.uncertainty import too_uncertain

from .harness import DOCS

FIGURES = DOCS / "figures"

#: Largest size of a picture in docs/figures, in bytes.
MAX_BYTES = 300_000

#: Largest width of a figure copied into docs/figures, in pixels.
DOCS_WIDTH = 1400

#: Degrees the point cloud of the overview is turned about the vertical axis, and tilted down.
VIEW_TURN, VIEW_TILT = 28.0, 12.0


@dataclass(frozen=True)
class Frame:
    """A shared frame: its files, how its depth is stored, the rows and columns shown, its camera."""

    name: str
    title: str
    image: str
    depth: str
    options: tuple
    rows: tuple = (None, None)
    columns: tuple = (None, None)
    intrinsics: tuple | None = None

    @property
    def window(self) -> tuple[slice, slice]:
        """The rows and columns shown, as slices of the shared files' arrays."""
        return slice(*self.rows), slice(*self.columns)


#: The front-page frames (see the module's docstring).
FRONT = (
    Frame("kitti", "KITTI (LiDAR), kitti_metric3d 0000000050", "kitti_metric3d/rgb_0000000050.png",
          "kitti_metric3d/depth_0000000050.png", ("--depth-scale", "kitti"), rows=(119, None),
          intrinsics=(707.0493, 707.0493, 604.0814, 180.5066)),
    Frame("nyu", "NYU Depth V2 (Kinect), nyu_metric3d 00050", "nyu_metric3d/rgb_00050.jpg",
          "nyu_metric3d/sync_depth_00050.png", ("--depth-scale", "nyu"), rows=(44, 472),
          columns=(40, 600)),
    Frame("realsense", "RealSense D435, realsense_cleargrasp 000000080", "realsense_cleargrasp/rgb_000000080.jpg",
          "realsense_cleargrasp/depth_000000080.npz", ("--depth-key", "depth")),
    Frame("tum", "TUM RGB-D (Kinect), tum_open3d", "tum_open3d/TUM_color.png", "tum_open3d/TUM_depth.png",
          ("--depth-scale", "tum")),
)

#: The whole KITTI frame the limits are also measured on, its LiDAR ground truth as the input.
KITTI_LIDAR = Frame("kitti_lidar", "KITTI 0000000005, whole frame, LiDAR as input", "kitti_metric3d/rgb_0000000005.png",
                    "kitti_metric3d/depth_0000000005.png", ("--depth-scale", "kitti"))

#: The limits of uncertainty_limits.csv.
ABSOLUTE_LIMITS = (0.1, 0.5, 2.0)
RELATIVE_LIMITS = (0.05, 0.1, 0.2)

#: (figure name, image file, depth file, --depth-scale, --max-uncertainty in metres): docs/uncertainty.md's.
CASES = (
    ("kitti_0000000050", "kitti_metric3d/rgb_0000000050.png", "kitti_metric3d/depth_0000000050.png", "kitti", "2"),
    ("nyu_00050", "nyu_metric3d/rgb_00050.jpg", "nyu_metric3d/sync_depth_00050.png", "nyu", "0.2"),
    ("tum_0", "tum_open3d/TUM_color.png", "tum_open3d/TUM_depth.png", "tum", "0.2"),
)


def _run(argv) -> None:
    """Run the command line, printing it first; a failure ends the script."""
    print("python -m sparsedepth.complete " + " ".join(map(str, argv)), flush=True)
    status = command([str(a) for a in argv])
    if status:
        raise SystemExit(status)


def _read_depth(path: Path, options) -> np.ndarray:
    """The depth of a file in metres (NaN where missing): an .npz array named by ``--depth-key``, a float .npy in
    metres, or an integer image divided by ``--depth-scale``."""
    key = dict(zip(options[::2], options[1::2]))
    if path.suffix == ".npz":
        values = np.load(path)[key["--depth-key"]].astype(np.float64)
    elif path.suffix == ".npy":
        values = np.load(path).astype(np.float64)
    else:
        values = iio.imread(path).astype(np.float64) / sd.io.resolve_scale(key["--depth-scale"])
    return np.where(np.isfinite(values) & (values > 0), values, np.nan)


def frame_files(frame: Frame, root: Path, folder: Path) -> tuple[Path, Path, list]:
    """(image, depth, options) of ``frame`` for the command line: the shared files, or the rows and columns shown
    written to ``folder`` (PNG image, float .npy depth in metres)."""
    if frame.rows == frame.columns == (None, None):
        return root / frame.image, root / frame.depth, list(frame.options)
    window = frame.window
    image = folder / f"{frame.name}_image.png"
    depth = folder / f"{frame.name}_depth.npy"
    iio.imwrite(image, iio.imread(root / frame.image)[window])
    np.save(depth, _read_depth(root / frame.depth, frame.options)[window])
    return image, depth, []


def for_docs(png: bytes, *, jpeg: bool = False) -> bytes:
    """A figure for docs/figures: at most :data:`DOCS_WIDTH` pixels wide (Lanczos), a PNG of 256 colours (octree
    quantisation) or a JPEG (quality 90), narrowed by steps of 200 pixels until it fits in :data:`MAX_BYTES`."""
    from PIL import Image

    picture = Image.open(io.BytesIO(png)).convert("RGB")
    for width in range(min(DOCS_WIDTH, picture.width), 599, -200):
        sized = picture.resize((width, round(picture.height * width / picture.width)), Image.Resampling.LANCZOS)
        out = io.BytesIO()
        if jpeg:
            sized.save(out, format="JPEG", quality=90, optimize=True)
        else:
            sized.quantize(colors=256, method=Image.Quantize.FASTOCTREE).save(out, format="PNG", optimize=True)
        if out.tell() <= MAX_BYTES:
            break
    return out.getvalue()


def _write(path: Path, data: bytes) -> None:
    if len(data) > MAX_BYTES:
        print(f"warning: {path} is {len(data)} bytes, more than {MAX_BYTES}", file=sys.stderr)
    path.write_bytes(data)
    print(f"wrote {path} ({len(data) // 1000} kB)", flush=True)


def run_frame(frame: Frame, root: Path, folder: Path, *, keep_fraction="0.05") -> dict:
    """Run the command line on ``frame`` with ``--uncertainty`` and ``--figure``: its inputs and outputs, read back.

    Returns ``image``, ``measured`` (the depth file in metres), ``observed`` (the pixels given as samples: the
    command line's own draw, :func:`sparsedepth.batch.evaluate.frame_observations` with the same seed), ``truth``
    (``measured`` with ``keep_fraction``, else None), ``depth``, ``sigma``, ``figure`` (PNG bytes) and ``report``.
    """
    image, depth, options = frame_files(frame, root, folder)
    out = {kind: folder / f"{frame.name}_{kind}{suffix}" for kind, suffix in (
        ("figure", ".png"), ("completed", ".npy"), ("sigma", ".npy"), ("report", ".json"))}
    sampling = ["--keep-fraction", keep_fraction, "--seed", "0"] if keep_fraction else []
    _run(["--image", image, "--depth", depth, *options, *sampling, "--uncertainty", out["sigma"],
          "--out", out["completed"], "--json", out["report"], "--figure", out["figure"], "-q"])
    pixels, measured = iio.imread(image), _read_depth(Path(depth), options)
    observed = frame_observations(pixels, measured, keep_fraction=float(keep_fraction) if keep_fraction else None,
                                  seed=0)[2]
    report = json.loads(out["report"].read_text())
    if int(observed.sum()) != report["observed"]:
        raise SystemExit(f"{frame.name}: {int(observed.sum())} samples drawn here, {report['observed']} by the run")
    return {"image": pixels, "measured": measured, "observed": observed,
            "truth": measured if keep_fraction else None, "depth": np.load(out["completed"]),
            "sigma": np.load(out["sigma"]), "figure": out["figure"].read_bytes(), "report": report}


#: The columns of uncertainty_limits.csv.
LIMITS_HEADER = ("frame", "option", "limit", "% of the frame", "% of the measured region",
                 "% of its nearest quarter")


def limits_rows(name: str, run: dict) -> list[list]:
    """The rows of uncertainty_limits.csv of one run (:data:`LIMITS_HEADER`): the percentage of the frame, of the
    measured region and of its nearest quarter that each limit leaves missing, to one decimal.

    The measured region: the unobserved pixels with ground truth, or, when every measurement was an input (the
    LiDAR run), the unobserved pixels between them (:func:`scipy.ndimage.binary_closing`, 3 iterations).  Its
    nearest quarter: the pixels of the region whose completed depth is at most the region's 25th percentile.
    """
    depth, sigma, observed = run["depth"], run["sigma"], run["observed"]
    measured = np.isfinite(run["measured"])
    region = measured & ~observed
    if not region.any():
        region = ndimage.binary_closing(measured, iterations=3) & ~observed
    near = region & (depth <= np.percentile(depth[region], 25))
    rows = []
    for flag, limits, key in (("--max-uncertainty", ABSOLUTE_LIMITS, "max_uncertainty"),
                              ("--max-relative-uncertainty", RELATIVE_LIMITS, "max_relative_uncertainty")):
        for limit in limits:
            left_out = too_uncertain(sigma, depth, **{key: limit})
            rows.append([name, flag, f"{limit:g}", *(f"{100 * left_out[where].mean():.1f}"
                                                     for where in (Ellipsis, region, near))])
    return rows


def write_limits_table(path: Path, rows: list[list]) -> None:
    """docs/figures/uncertainty_limits.csv: :data:`LIMITS_HEADER` and the rows of :func:`limits_rows`."""
    with open(path, "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(LIMITS_HEADER)
        writer.writerows(rows)
    print(f"wrote {path}", flush=True)


def _turned_view(points, colours, shape, *, step: int = 2) -> np.ndarray:
    """The coloured points seen from a camera turned :data:`VIEW_TURN` degrees about the vertical axis through the
    median depth, tilted :data:`VIEW_TILT` degrees down and moved back, as an RGB picture of ``shape``.

    Each point is a ``2 x 2`` splat in a picture ``step`` times smaller (a z-buffer keeps the nearest), enlarged
    ``step`` times: a solid surface without the gaps between the points.  Light grey where no point falls.
    """
    h, w = shape[0] // step, shape[1] // step
    centre = np.array([0.0, 0.0, float(np.median(points[:, 2]))])
    turn, tilt = np.radians(VIEW_TURN), np.radians(VIEW_TILT)
    about_y = np.array([[np.cos(turn), 0, np.sin(turn)], [0, 1, 0], [-np.sin(turn), 0, np.cos(turn)]])
    about_x = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    moved = (points - centre) @ (about_x @ about_y).T + centre * np.array([0.0, 0.0, 1.4])
    ahead = moved[:, 2] > 0.05 * centre[2]
    moved, colours = moved[ahead], colours[ahead]
    focal = 1.0 * w
    u = np.rint(focal * moved[:, 0] / moved[:, 2] + w / 2).astype(int)
    v = np.rint(focal * moved[:, 1] / moved[:, 2] + h / 2).astype(int)
    picture = np.full((h, w, 3), 235, dtype=np.uint8)
    zbuffer = np.full((h, w), np.inf)
    order = np.argsort(-moved[:, 2])  # far first: nearer points overwrite them
    u, v, z, colours = u[order], v[order], moved[order, 2], colours[order]
    for dv in (0, 1):
        for du in (0, 1):
            uu, vv = u + du, v + dv
            inside = (uu >= 0) & (uu < w) & (vv >= 0) & (vv < h)
            ui, vi, zi, ci = uu[inside], vv[inside], z[inside], colours[inside]
            nearer = zi < zbuffer[vi, ui]
            picture[vi[nearer], ui[nearer]] = ci[nearer]
            zbuffer[vi[nearer], ui[nearer]] = zi[nearer]
    return np.repeat(np.repeat(picture, step, axis=0), step, axis=1)


def write_overview(path: Path, frame: Frame, run: dict) -> None:
    """overview.png: image | sparse input | completed | point cloud, from the run of ``frame`` (two panels a row
    for a frame at least 2.5 times wider than tall, else one row)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    image, depth = run["image"], run["depth"]
    observed = run["observed"]
    sparse = np.where(observed, run["measured"], np.nan)
    colours = sd.visualize.depth_colour_scale(depth)
    dots = dilate_samples(sparse, observed, sample_radius(depth.shape))
    grey = image.mean(axis=2, keepdims=True) / 255.0
    sparse_picture = np.repeat(0.25 + 0.3 * grey, 3, axis=2)
    drawn = np.isfinite(dots)
    sparse_picture[drawn] = sd.colorize_depth(dots, vmin=colours.vmin, vmax=colours.vmax,
                                              scale=colours.scale)[drawn] / 255.0
    completed = sd.colorize_depth(depth, vmin=colours.vmin, vmax=colours.vmax, scale=colours.scale)
    fx, fy, cx, cy = frame.intrinsics
    top, left = frame.rows[0] or 0, frame.columns[0] or 0
    points, point_colours = depth_to_points(depth, (fx, fy, cx - left, cy - top), image=image)
    far = points[:, 2] <= np.percentile(points[:, 2], 97)
    cloud = _turned_view(points[far], point_colours[far], depth.shape)

    h, w = depth.shape
    columns = 2 if w >= 2.5 * h else 4
    rows = 4 // columns
    panel, title_height = 18.0 / columns, 0.4
    cell_height = panel * h / w + title_height
    fig = Figure(figsize=(columns * panel, rows * cell_height), dpi=100)
    FigureCanvasAgg(fig)
    titles = ("image", f"input: {int(observed.sum())} depth samples ({observed.mean():.1%} of the pixels)",
              "completed: python -m sparsedepth.complete", "its coloured point cloud, seen from the side")
    for i, (picture, title) in enumerate(zip((image, sparse_picture, completed, cloud), titles)):
        row, column = divmod(i, columns)
        ax = fig.add_axes((column / columns + 0.002, (rows - 1 - row) / rows, 1 / columns - 0.004,
                           (panel * h / w) / (rows * cell_height)))
        ax.imshow(picture, interpolation="nearest")
        ax.set_axis_off()
        ax.set_title(title, fontsize=13)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    _write(path, for_docs(buffer.getvalue()))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=FIGURES, help=f"folder of the figures (default {FIGURES})")
    args = p.parse_args(argv)
    root = sd.shared_data_dir()
    if root is None:
        print("the shared data folder (../shared/data or $SPARSEDEPTH_DATA) is missing", file=sys.stderr)
        return 2
    root = Path(root)
    args.out.mkdir(parents=True, exist_ok=True)
    limit_rows = []
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        for frame in FRONT:
            run = run_frame(frame, root, folder)
            _write(args.out / f"{frame.name}.png", for_docs(run["figure"]))
            limit_rows += limits_rows(frame.title, run)
            if frame.name == "kitti":
                write_overview(args.out / "overview.png", frame, run)
        lidar = run_frame(KITTI_LIDAR, root, folder, keep_fraction=None)
        limit_rows += limits_rows(KITTI_LIDAR.title, lidar)
        write_limits_table(args.out / "uncertainty_limits.csv", limit_rows)

        for name, image, depth, scale, limit in CASES:
            common = ["--image", root / image, "--depth", root / depth, "--depth-scale", scale, "--keep-fraction",
                      "0.05", "--seed", "0", "-q"]
            _run([*common, "--depth-vis", args.out / f"{name}_all_vis.png"])
            figure = folder / f"{name}_trusted.png"
            _run([*common, "--max-uncertainty", limit, "--depth-vis", args.out / f"{name}_trusted_vis.png",
                  "--figure", figure])
            _write(args.out / f"{name}_trusted.jpg", for_docs(figure.read_bytes(), jpeg=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
