"""Dense depth from a COLMAP scene: SfM-like inputs with ground truth, then a real SfM model (``docs/colmap_scene.md``).

Run from the repository root::

    python -m bench.colmap_scene --out docs/colmap_scene.md   # ~5 min on 2 shared cores
    python -m bench.colmap_scene --quick                      # tiny frames and the scene downscaled 8x (smoke test)

Sections:

* **SfM-like inputs on RGB-D frames with ground truth** (:func:`sfm_like_section`): on each report frame
  (:data:`bench.frames.REPORT_FRAMES`), ``sd.sample_depth(depth, pattern="keypoints", image=..., count=...,
  noise=0.01, outliers=0.02, outlier_range=(0.7, 1.3))`` with 500 and 2000 points and seeds 0, 1, 2; RMSE and MAE
  on the valid pixels hidden from the method for the default completion, the fast mode
  (``quality="fast"``) and the cheap baselines of :mod:`bench.harness.methods` (nearest fill, linear
  interpolation); the ratio of each to the nearest fill's on the same input, its mean and its worst over
  frames x seeds.
* **The real scene: leave-points-out accuracy** (:func:`leave_points_out_section`): the COLMAP model
  ``colmap_maupertuis`` of the shared folder (no ground truth, arbitrary scale); per view, 10 % of the pixels that
  hold a point (:func:`sparsedepth.io.view_depth`) are hidden (seeded), the view is completed from the rest, and
  the completion is scored at the hidden pixels against the points' depths, in the model's units and relative to
  the view's median point depth.
* **The real scene: multi-view consistency** (:func:`consistency_section`): each view completed from all its
  points; every pixel of view i is lifted to 3-D with its completed depth and the model's pose, projected into view
  j, and compared with view j's completed depth at the pixel it lands on (:func:`consistency`), over every ordered
  pair.  Before that, :func:`check_projection` checks the projection on the model's own points (asserted; the mean
  keypoint-transfer error is printed and written on the page).

May import :mod:`sparsedepth`, numpy, scipy, :mod:`bench.blas`, :mod:`bench.frames` and :mod:`bench.harness`.
"""

from __future__ import annotations

from .blas import one_blas_thread

one_blas_thread()

import itertools  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.spatial import Delaunay  # noqa: E402

import sparsedepth as sd  # noqa: E402
from sparsedepth.io import read_colmap_model, view_depth, view_observations  # noqa: E402
from sparsedepth.io.colmap import ColmapModel, rotation_from_qvec  # noqa: E402

from . import harness as H  # noqa: E402

#: Keypoint counts of the SfM-like inputs (and of ``--quick``, on its tiny frames).
COUNTS, QUICK_COUNTS = (500, 2000), (50, 200)
#: Corruption of the SfM-like inputs: relative noise, outlier fraction and the outliers' factor range.
NOISE, OUTLIERS, OUTLIER_RANGE = 0.01, 0.02, (0.7, 1.3)
#: The shared COLMAP scene (a folder of the shared data folder) and its parts.
SCENE, MODEL_FOLDER, IMAGE_FOLDER = "colmap_maupertuis", "reconstruction", "images"
#: Share of a view's points hidden in the leave-points-out test.
HIDDEN_SHARE = 0.10
#: Downscaling factor of the scene in ``--quick``.
QUICK_FACTOR = 8
#: Largest mean keypoint-transfer error (pixels) accepted by the projection check.
MAX_TRANSFER_ERROR = 2.0

DEFAULT = H.ours("default")
FAST = H.Method("fast", lambda image, sparse, mask: _quiet_completion(image, sparse, mask, quality="fast"),
                ("complete", "fast"))
#: The methods of the SfM-like section, the reference (nearest fill) first.
SFM_METHODS = (H.NEAREST, DEFAULT, FAST, H.LINEAR)
#: The methods on the real scene.
SCENE_METHODS = (DEFAULT, H.NEAREST)


def _quiet_completion(image, sparse, mask, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        return sd.complete_depth(image, sparse, mask, **kwargs)


def _dense(out) -> np.ndarray:
    """The depth map of a method's output (an array or a :class:`sparsedepth.CompletionResult`)."""
    return out.depth if isinstance(out, sd.CompletionResult) else np.asarray(out)


# --- geometry


def view_pose(model: ColmapModel, image) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)``, the world-to-camera pose of one view of ``model`` (:math:`X_c = R X + t`)."""
    view = model.image(image)
    return rotation_from_qvec(view.qvec), np.asarray(view.tvec, dtype=np.float64)


def backproject(u, v, z, K) -> np.ndarray:
    """Camera-frame points of the pixels ``(u, v)`` at depth ``z``.

    Parameters
    ----------
    u, v : ndarray of float
        Column and row coordinates with integer pixel centres (the convention of ``K``).
    z : ndarray of float
        Depth along the optical axis, same shape.
    K : (3, 3) ndarray
        Pinhole intrinsic matrix (no skew).

    Returns
    -------
    (..., 3) ndarray of float64

    Notes
    -----
    .. math:: X_c = z \\left(\\frac{u - c_x}{f_x},\\ \\frac{v - c_y}{f_y},\\ 1\\right).
    """
    u, v, z = (np.asarray(a, dtype=np.float64) for a in (u, v, z))
    return np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=-1)


def project(points_camera, K) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(u, v, z)``: pixel coordinates (convention of ``K``) and depth of camera-frame points.

    Notes
    -----
    .. math:: u = f_x x / z + c_x, \\quad v = f_y y / z + c_y.

    ``u`` and ``v`` are NaN where :math:`z \\le 0` (behind the camera).
    """
    points_camera = np.asarray(points_camera, dtype=np.float64)
    x, y, z = points_camera[..., 0], points_camera[..., 1], points_camera[..., 2]
    in_front = z > 0
    safe = np.where(in_front, z, 1.0)
    u = np.where(in_front, K[0, 0] * x / safe + K[0, 2], np.nan)
    v = np.where(in_front, K[1, 1] * y / safe + K[1, 2], np.nan)
    return u, v, z


def transfer(u, v, z, K_from, pose_from, K_to, pose_to) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels ``(u, v)`` of one view at depth ``z`` seen from another view: ``(u', v', z')``.

    Parameters
    ----------
    u, v, z : ndarray of float
        Pixel coordinates (integer pixel centres) and depth in the first view.
    K_from, K_to : (3, 3) ndarray
        Intrinsic matrices of the two views (integer pixel centres).
    pose_from, pose_to : tuple of ndarray
        ``(R, t)``, world-to-camera poses (:func:`view_pose`).

    Returns
    -------
    u, v, z : ndarray of float64
        Pixel coordinates in the second view (NaN behind it) and the depth there.

    Notes
    -----
    With :math:`X_i` the back-projection (:func:`backproject`) of the pixel in view i, the world point is
    :math:`X = R_i^\\top (X_i - t_i)`, in view j it is :math:`X_j = R_j X + t_j`, then :func:`project`.
    """
    (R_from, t_from), (R_to, t_to) = pose_from, pose_to
    world = (backproject(u, v, z, K_from) - t_from) @ R_from  # rows of R^T (X_c - t)
    return project(world @ R_to.T + t_to, K_to)


def depth_at(depth, u, v) -> np.ndarray:
    """``depth`` at the pixel nearest each ``(u, v)`` (integer pixel centres); NaN outside the map."""
    height, width = depth.shape
    with np.errstate(invalid="ignore"):
        columns, rows = np.rint(u), np.rint(v)
        inside = (columns >= 0) & (columns < width) & (rows >= 0) & (rows < height)
    values = np.full(np.shape(u), np.nan)
    values[inside] = depth[rows[inside].astype(np.intp), columns[inside].astype(np.intp)]
    return values


def check_projection(model: ColmapModel) -> dict:
    """Check :func:`project` and :func:`transfer` on the model's own 3-D points; asserts, returns the errors.

    For every view, :func:`project` of each observed point (world to camera by :func:`view_pose`) must give
    ``view_observations(...).projected`` shifted by half a pixel (COLMAP puts the top-left pixel's centre at
    ``(0.5, 0.5)``, ``K`` of :func:`sparsedepth.io.view_depth` at ``(0, 0)``).  For every ordered pair (i, j) and
    every point both observe, the keypoint of view i lifted at the point's depth in i and transferred to j
    (:func:`transfer`) must land on its keypoint in j, up to the bundle adjustment's residuals.

    Returns
    -------
    dict
        ``projection``: largest deviation from the model's reprojections (pixels); ``transfer_mean``,
        ``transfer_max``: mean and largest keypoint-transfer error (pixels) over ``pairs`` observations;
        ``point_error``: mean reprojection error of the points in the model.
    """
    views = list(model.images)
    observations = {i: view_observations(model, i) for i in views}
    K = {i: view_depth(model, i)[2] for i in views}
    pose = {i: view_pose(model, i) for i in views}
    worst_projection = 0.0
    for i in views:
        R, t = pose[i]
        xyz = model.points3d.xyz[model.points3d.index_of(observations[i].point3d_ids)]
        u, v, _ = project(xyz @ R.T + t, K[i])
        worst_projection = max(worst_projection,
                               float(np.max(np.abs(np.column_stack([u, v]) + 0.5 - observations[i].projected))))
    errors = []
    for i, j in itertools.permutations(views, 2):
        a, b = observations[i], observations[j]
        common, in_a, in_b = np.intersect1d(a.point3d_ids, b.point3d_ids, return_indices=True)
        if common.size == 0:
            continue
        u, v, _ = transfer(a.keypoints[in_a, 0] - 0.5, a.keypoints[in_a, 1] - 0.5, a.depth[in_a], K[i], pose[i],
                           K[j], pose[j])
        errors.append(np.hypot(u - (b.keypoints[in_b, 0] - 0.5), v - (b.keypoints[in_b, 1] - 0.5)))
    errors = np.concatenate(errors)
    scale = max(max(abs(float(c.params[1])), abs(float(c.params[-1]))) for c in model.cameras.values())
    assert worst_projection <= 1e-9 * max(scale, 1.0), f"projection differs from the model's by {worst_projection} px"
    assert np.all(np.isfinite(errors)), "a shared point transferred behind a camera"
    assert errors.mean() <= MAX_TRANSFER_ERROR, f"mean keypoint-transfer error {errors.mean():.2f} px"
    return {"projection": worst_projection, "transfer_mean": float(errors.mean()),
            "transfer_max": float(errors.max()), "pairs": int(errors.size),
            "point_error": float(model.points3d.error.mean())}


def consistency(depth_from, K_from, pose_from, depth_to, K_to, pose_to) -> np.ndarray:
    """Per pixel of one view, the relative disagreement of its depth with another view's depth map.

    Every pixel of ``depth_from`` with a finite positive depth is moved into the other view (:func:`transfer`);
    where it lands inside that view, in front of its camera, on a pixel (the nearest, :func:`depth_at`) whose
    ``depth_to`` is finite and positive, the disagreement is :math:`|z_j - z'| / z'`, :math:`z'` the point's depth
    in view j and :math:`z_j` ``depth_to`` there.

    Returns
    -------
    relative : ndarray of float64, the shape of ``depth_from``
        The disagreement, NaN at the pixels where it is not measured.
    """
    rows, columns = np.nonzero(np.isfinite(depth_from) & (depth_from > 0))
    u, v, z = transfer(columns.astype(np.float64), rows.astype(np.float64), depth_from[rows, columns], K_from,
                       pose_from, K_to, pose_to)
    there = depth_at(depth_to, u, v)
    with np.errstate(invalid="ignore"):
        measured = (z > 0) & np.isfinite(there) & (there > 0)
    relative = np.full(np.shape(depth_from), np.nan)
    relative[rows[measured], columns[measured]] = np.abs(there[measured] - z[measured]) / z[measured]
    return relative


def inside_hull(mask) -> np.ndarray:
    """The pixels inside the convex hull of the pixels of ``mask`` (where a completion interpolates)."""
    rows, columns = np.nonzero(mask)
    grid_rows, grid_columns = np.indices(mask.shape)
    queries = np.column_stack([grid_columns.ravel(), grid_rows.ravel()]).astype(np.float64)
    hull = Delaunay(np.column_stack([columns, rows]).astype(np.float64))
    return (hull.find_simplex(queries) >= 0).reshape(mask.shape)


# --- the scene


def downscale_scene(model: ColmapModel, images: dict, factor: int) -> tuple[ColmapModel, dict]:
    """The scene with every image reduced by ``factor`` (mean of ``factor`` x ``factor`` blocks).

    Each image is cropped to a multiple of ``factor`` first.  In COLMAP's coordinates (pixel edges at integers) a
    point at ``x`` is at ``x / factor`` in the reduced image, so the cameras' parameters and the keypoints are divided
    by ``factor``; keypoints now outside the cropped image are dropped by :func:`sparsedepth.io.view_depth`.
    """
    cameras = {cid: replace(c, width=c.width // factor, height=c.height // factor,
                            params=np.asarray(c.params, dtype=np.float64) / factor)
               for cid, c in model.cameras.items()}
    views = {iid: replace(im, xys=np.asarray(im.xys, dtype=np.float64) / factor) for iid, im in model.images.items()}
    reduced = {}
    for name, image in images.items():
        h, w = (image.shape[0] // factor) * factor, (image.shape[1] // factor) * factor
        blocks = image[:h, :w].astype(np.float64).reshape(h // factor, factor, w // factor, factor, -1)
        reduced[name] = np.rint(blocks.mean(axis=(1, 3))).astype(np.uint8)
    return ColmapModel(cameras=cameras, images=views, points3d=model.points3d), reduced


def load_scene(folder: Path, factor: int = 1):
    """``(model, images)`` of the scene folder, images by view name (uint8 RGB), reduced by ``factor`` if > 1."""
    model = read_colmap_model(folder / MODEL_FOLDER)
    images = {}
    for view in model.images.values():
        image = sd.read_image(folder / IMAGE_FOLDER / view.name)
        camera = model.cameras[view.camera_id]
        assert image.shape[:2] == (camera.height, camera.width), f"{view.name}: {image.shape} vs the camera's size"
        images[view.name] = image
    if factor > 1:
        model, images = downscale_scene(model, images, factor)
    return model, images


# --- sections


def sfm_like_records(frames, counts, seeds) -> list[dict]:
    """One record per frame, count, seed and method of :data:`SFM_METHODS`: RMSE, MAE, ratios to nearest, time."""
    records = []
    for frame, count, seed in itertools.product(frames, counts, seeds):
        sparse, mask = sd.sample_depth(frame.depth, pattern="keypoints", image=frame.image, count=count, seed=seed,
                                       noise=NOISE, outliers=OUTLIERS, outlier_range=OUTLIER_RANGE)
        hidden = ~mask
        reference = None
        for method in SFM_METHODS:
            out, seconds = H.timed(method.run, frame.image, sparse, mask)
            metrics = sd.depth_metrics(_dense(out), frame.depth, mask=hidden)
            if reference is None:
                reference = metrics
            records.append({"frame": frame.name, "count": count, "seed": seed, "method": method.name,
                            "observed": int(mask.sum()), "rmse": float(metrics.rmse), "mae": float(metrics.mae),
                            "rmse_ratio": float(metrics.rmse / reference.rmse),
                            "mae_ratio": float(metrics.mae / reference.mae), "seconds": seconds})
            print(f"  {frame.name} {count} seed {seed} {method.name}: RMSE {metrics.rmse:.4g} "
                  f"({metrics.rmse / reference.rmse:.3f} of nearest), {seconds:.2f} s", file=sys.stderr, flush=True)
    return records


def sfm_like_section(frames, counts, seeds, command, step_note) -> tuple[str, list]:
    started = time.perf_counter()
    records = sfm_like_records(frames, counts, seeds)
    names = [m.name for m in SFM_METHODS]
    summary = []
    for count, name in itertools.product(counts, names):
        recs = [r for r in records if r["count"] == count and r["method"] == name]
        rmse_ratio, mae_ratio = np.array([r["rmse_ratio"] for r in recs]), np.array([r["mae_ratio"] for r in recs])
        summary.append([count, name, f"{rmse_ratio.mean():.3f}", f"{rmse_ratio.max():.3f}", f"{mae_ratio.mean():.3f}",
                        f"{mae_ratio.max():.3f}", f"{np.mean([r['seconds'] for r in recs]):.2f}"])
    summary_table = H.markdown_table(
        ["points", "method", "RMSE / nearest (mean)", "RMSE / nearest (worst)", "MAE / nearest (mean)",
         "MAE / nearest (worst)", "time per input (s)"], summary)
    per_frame = []
    for frame, count in itertools.product(frames, counts):
        row = [frame.name, frame.units, count]
        for name in names:
            recs = [r for r in records if r["frame"] == frame.name and r["count"] == count and r["method"] == name]
            row.append(f"{H.fmt(np.mean([r['rmse'] for r in recs]))} / {H.fmt(np.mean([r['mae'] for r in recs]))}")
        per_frame.append(row)
    per_frame_table = H.markdown_table(["frame", "units", "points", *(f"{n}: RMSE / MAE" for n in names)], per_frame)
    notes = (
        f"{step_note} Inputs: `sd.sample_depth(depth, pattern=\"keypoints\", image=image, count=N, seed=s, "
        f"noise={NOISE:g}, outliers={OUTLIERS:g}, outlier_range={OUTLIER_RANGE})` with N in {list(counts)}: corner-"
        f"like pixels with valid ground truth, as SfM keypoints are (the strongest FAST corners, so mostly the same "
        f"pixels for every seed: the seed changes the corruption), each sample multiplied by 1 + {NOISE:g}·N(0, 1), "
        f"or for {100 * OUTLIERS:g} % of them (outliers) by a factor drawn from U{OUTLIER_RANGE} instead. "
        "Methods: `default` = "
        "`complete_depth(image, sparse, mask)`; `fast` = the same with `quality=\"fast\"`; `nearest` = "
        "`sparsedepth.nearest_fill` (the reference); `linear (griddata)` = `sparsedepth.linear_fill`. The other "
        "baselines of `bench/harness/methods.py` (the biharmonic fill and the colorization baseline) are left out: "
        "on full-size frames they take many times the default's time. Scores: RMSE and MAE on the valid "
        "ground-truth pixels not "
        "given to the method, in the frame's units; "
        "the ratios are to the nearest fill's on the same input, mean and worst (largest) over frames x seeds. Time: "
        "one wall-clock call per input (shared machine: indicative only).")
    body = "\n\n".join(["Ratios to the nearest fill over frames x seeds:", summary_table,
                        "Per frame, mean over seeds (frame units):", per_frame_table])
    text = H.section("SfM-like inputs on RGB-D frames with ground truth", command=command, frames_=frames,
                     seeds=seeds, body=body, notes=notes, elapsed=time.perf_counter() - started)
    return text, records


def _view_frames(model, images, depths) -> list:
    return [H.FrameData(f"{SCENE}/{model.image(i).name}", images[model.image(i).name], depths[i][0])
            for i in model.images]


def leave_points_out(image, sparse, mask, seed, methods=SCENE_METHODS, share=HIDDEN_SHARE) -> dict:
    """Hide ``share`` of the pixels of ``mask`` (seeded), complete from the rest; RMSE and MAE at those pixels.

    Returns ``{method name: (rmse, mae)}`` and ``"hidden"``: the number of pixels hidden.
    """
    rng = np.random.default_rng(seed)
    observed = np.flatnonzero(mask)
    hidden = rng.choice(observed, size=max(1, int(round(share * observed.size))), replace=False)
    kept = mask.copy()
    kept.flat[hidden] = False
    kept_sparse = np.where(kept, sparse, np.nan)
    truth = sparse.flat[hidden]
    out = {"hidden": int(hidden.size)}
    for method in methods:
        error = _dense(method.run(image, kept_sparse, kept)).flat[hidden] - truth
        out[method.name] = (float(np.sqrt(np.mean(error ** 2))), float(np.mean(np.abs(error))))
    return out


def leave_points_out_section(model, images, depths, seeds, command, scene_note) -> tuple[str, dict]:
    started = time.perf_counter()
    rows, relative = [], {m.name: [] for m in SCENE_METHODS}
    for i in model.images:
        name = model.image(i).name
        sparse, mask, _ = depths[i]
        median = float(np.median(sparse[mask]))
        runs = []
        for seed in seeds:
            runs.append(leave_points_out(images[name], sparse, mask, seed))
            print(f"  leave-points-out {name} seed {seed}: " + ", ".join(
                f"{m.name} RMSE {runs[-1][m.name][0]:.3g}" for m in SCENE_METHODS), file=sys.stderr, flush=True)
        row = [name, int(mask.sum()), runs[0]["hidden"], f"{median:.2f}"]
        for method in SCENE_METHODS:
            rmse = np.array([r[method.name][0] for r in runs])
            mae = np.array([r[method.name][1] for r in runs])
            relative[method.name].append((rmse / median, mae / median))
            row += [H.fmt(*H.mean_std(rmse)), H.fmt(*H.mean_std(mae)),
                    f"{100 * rmse.mean() / median:.2f} % / {100 * mae.mean() / median:.2f} %"]
        nearest = np.array([r[H.NEAREST.name][0] for r in runs])
        ours = np.array([r[DEFAULT.name][0] for r in runs])
        row.append(f"{np.mean(ours / nearest):.3f}")
        rows.append(row)
    overall, stats = ["all views (mean)", "", "", ""], {}
    for method in SCENE_METHODS:
        rmse_rel = np.mean([r for r, _ in relative[method.name]])
        mae_rel = np.mean([m for _, m in relative[method.name]])
        stats[method.name] = (float(rmse_rel), float(mae_rel))
        overall += ["", "", f"{100 * rmse_rel:.2f} % / {100 * mae_rel:.2f} %"]
    overall.append("")
    rows.append(overall)
    header = ["view", "pixels with a point", "hidden", "median depth"]
    for method in SCENE_METHODS:
        header += [f"{method.name}: RMSE", f"{method.name}: MAE", f"{method.name}: RMSE / MAE rel. to median"]
    header.append("RMSE default / nearest")
    notes = (
        f"{scene_note} Per view, the sparse depth is `sparsedepth.io.view_depth(model, view)` (each point's depth "
        "along the optical axis at the pixel of its keypoint, the nearest kept where two share a pixel). For each "
        f"seed, {100 * HIDDEN_SHARE:g} % of those pixels (`numpy.random.default_rng(seed).choice`, without "
        "replacement) "
        "are hidden, the view is completed from the other 90 % with its photo as the guide, and the completion is "
        "scored at the hidden pixels against the points' depths: RMSE and MAE (mean ± std over the seeds) in the "
        "model's units (arbitrary scale), and relative to the view's median point depth. The points' own depths are "
        "SfM estimates (mean reprojection error "
        f"{float(model.points3d.error.mean()):.2f} px), so this is agreement with held-out SfM points, not accuracy "
        "against a ground truth. Methods: `default` = `complete_depth(image, sparse, mask)`, `nearest` = "
        "`sparsedepth.nearest_fill`.")
    text = H.section("The real scene: leave-points-out accuracy", command=command,
                     frames_=_view_frames(model, images, depths), seeds=seeds, body=H.markdown_table(header, rows),
                     notes=notes, elapsed=time.perf_counter() - started)
    return text, stats


def _percentiles(values) -> tuple[float, float]:
    """Median and 90th percentile of the finite ``values`` (NaN, NaN if none)."""
    values = values[np.isfinite(values)]
    return tuple(map(float, np.percentile(values, [50, 90]))) if values.size else (np.nan, np.nan)


def _percent_pair(stats) -> str:
    return f"{100 * stats[0]:.2f} % / {100 * stats[1]:.1f} %"


def consistency_section(model, images, depths, check, command, scene_note) -> tuple[str, dict]:
    started = time.perf_counter()
    views = list(model.images)
    pose = {i: view_pose(model, i) for i in views}
    hull = {i: inside_hull(depths[i][1]) for i in views}
    completed = {}
    for method in SCENE_METHODS:
        for i in views:
            sparse, mask, _ = depths[i]
            completed[method.name, i] = _dense(method.run(images[model.image(i).name], sparse, mask))
    regions = ("all", "hull")
    rows, pooled = [], {(m.name, region): [] for m in SCENE_METHODS for region in regions}
    for i, j in itertools.permutations(views, 2):
        row = [f"{model.image(i).name} → {model.image(j).name}"]
        for method in SCENE_METHODS:
            relative = consistency(completed[method.name, i], depths[i][2], pose[i], completed[method.name, j],
                                   depths[j][2], pose[j])
            if method is SCENE_METHODS[0]:
                measured = np.isfinite(relative)
                row += [f"{100 * measured.mean():.0f} %", f"{100 * (measured & hull[i]).sum() / measured.size:.0f} %"]
            for region, values in zip(regions, (relative.ravel(), relative[hull[i]])):
                values = values[np.isfinite(values)]
                pooled[method.name, region].append(values)
                row.append(_percent_pair(_percentiles(values)))
        rows.append(row)
    stats = {key: _percentiles(np.concatenate(values)) for key, values in pooled.items()}
    total = ["all ordered pairs (pooled)", "", ""]
    for method in SCENE_METHODS:
        total += [f"**{_percent_pair(stats[method.name, region])}**" for region in regions]
    rows.append(total)
    header = ["view i → view j", "pixels of i measured", "pixels of i measured inside the hull"]
    for method in SCENE_METHODS:
        header += [f"{method.name}: median / 90th pct. (all)", f"{method.name}: median / 90th pct. (hull)"]
    notes = (
        f"{scene_note} Each view completed from all its points (`default`: `complete_depth(image, sparse, mask)`; "
        "`nearest`: `sparsedepth.nearest_fill`). For each ordered pair (i, j), every pixel (u, v) of view i is lifted "
        "to 3-D with its completed depth z and the intrinsic matrix K_i of `view_depth` (integer pixel centres: "
        "X_i = z K_i⁻¹ (u, v, 1)), moved to the world (X = R_iᵀ (X_i − t_i), the model's world-to-camera pose: R_i "
        "from qvec by `sparsedepth.io.colmap.rotation_from_qvec`, t_i = tvec) and into view j "
        "(X_j = R_j X + t_j, z' its third coordinate), and projected with K_j; where it lands in front of camera j "
        "and inside its image, the completed depth z_j of the nearest pixel is read and |z_j − z'| / z' recorded. "
        "'pixels of i measured' is the share of view i's pixels for which that happens ('inside the hull': and that "
        "lie in the convex hull of view i's points). Median and 90th percentile "
        "of |z_j − z'| / z' per pair, then pooled over the pixels of all ordered pairs: '(all)' over every measured "
        "pixel, also where no point is near (sky, image borders: extrapolated depth) and where view j sees another "
        "surface in front (occlusion), which the 90th percentile mostly shows; '(hull)' over the measured pixels of "
        "view i inside the convex hull of its points (where the completion interpolates). "
        f"Projection check on the model's own points (asserted by the bench): projecting each point with K and the "
        f"pose reproduces the model's reprojections to {check['projection']:.1e} px; lifting each keypoint of view i "
        f"at its point's depth and projecting into view j lands on its keypoint there with a mean error of "
        f"**{check['transfer_mean']:.3f} px** (largest {check['transfer_max']:.2f} px, {check['pairs']} "
        f"observations over the ordered pairs; the points' mean reprojection error is {check['point_error']:.2f} px).")
    text = H.section("The real scene: multi-view consistency", command=command,
                     frames_=_view_frames(model, images, depths), seeds=["none (deterministic)"],
                     body=H.markdown_table(header, rows), notes=notes, elapsed=time.perf_counter() - started)
    return text, stats


def summary(results, counts) -> str:
    """The page's summary: the headline numbers of each section, from ``results``."""
    records = results["sfm_like"]

    def mean_ratio(name, count):
        return np.mean([r["rmse_ratio"] for r in records if r["method"] == name and r["count"] == count])

    lines = ["Summary (numbers of this run, details below):", "",
             "* SfM-like inputs, mean RMSE / nearest fill's over frames x seeds at "
             + " and ".join(f"{c} points" for c in counts) + ": "
             + "; ".join(f"{m.name} " + " and ".join(f"{mean_ratio(m.name, c):.3f}" for c in counts)
                         for m in SFM_METHODS[1:]) + "."]
    if "consistency" in results:
        held_out, agreement = results["leave_points_out"], results["consistency"]
        lines.append("* Real scene, held-out points: RMSE relative to the median depth "
                     + ", ".join(f"{name} {100 * held_out[name][0]:.2f} %" for name in held_out)
                     + " (mean over views).")
        lines.append("* Real scene, agreement between views (median |z_j − z'| / z', pooled over ordered pairs): "
                     + "; ".join(f"{m.name} {100 * agreement[m.name, 'all'][0]:.2f} % over all pixels, "
                                 f"{100 * agreement[m.name, 'hull'][0]:.2f} % inside the hull of the points"
                                 for m in SCENE_METHODS) + ".")
    return "\n".join(lines) + "\n"


def parser():
    """The command line: :func:`bench.harness.parser`'s, with ``--scene`` and ``--scene-factor``."""
    p = H.parser("Dense depth from a COLMAP scene: SfM-like inputs with ground truth and a real SfM model",
                 default_step=1)
    p.add_argument("--scene", type=Path, default=None,
                   help=f"the COLMAP scene folder (default: {SCENE} of the shared data folder)")
    p.add_argument("--scene-factor", type=int, default=None,
                   help=f"reduce the scene's images by this factor (default 1; {QUICK_FACTOR} with --quick)")
    return p


def run(argv=()) -> tuple[str, dict]:
    """``(markdown page, results)`` of a run with command-line arguments ``argv``."""
    args = parser().parse_args(list(argv))
    started = time.perf_counter()
    command = H.command_line("colmap_scene", argv)
    seeds = H.seeds_of(args)
    frames = H.get_frames(args)
    counts = QUICK_COUNTS if args.quick else COUNTS
    folder = args.scene
    if folder is None:
        root = sd.shared_data_dir()
        folder = None if root is None else Path(root) / SCENE
    factor = args.scene_factor or (QUICK_FACTOR if args.quick else 1)
    parts = [
        "# Dense depth from a COLMAP scene", "",
        f"Written by `{command}`.", "",
        f"Machine: {H.machine_markdown()}.", "",
        "What is measured: (1) on RGB-D frames with ground truth, SfM-like sparse inputs (keypoint-like pixels, 1 % "
        "noise, 2 % outliers) completed by the default solve, the fast mode and cheap baselines, scored on the hidden "
        "pixels; (2) on a real COLMAP reconstruction without ground truth, how well each view's completion predicts "
        "held-out SfM points, and (3) how well the completed depth maps of the views agree with each other in 3-D.",
        ""]
    summary_at = len(parts)
    parts.append("")
    sfm_text, records = sfm_like_section(frames, counts, seeds, command, H.step_note(args))
    parts.append(sfm_text)
    results = {"sfm_like": records}
    if folder is None or not (folder / MODEL_FOLDER).is_dir():
        parts.append(f"## The real scene\n\nThe scene folder `{folder}` is missing: this part is left out.\n")
    else:
        model, images = load_scene(folder, factor)
        check = check_projection(model)
        print(f"projection check: model reprojections reproduced to {check['projection']:.1e} px; mean "
              f"keypoint-transfer error {check['transfer_mean']:.3f} px over {check['pairs']} observations",
              file=sys.stderr, flush=True)
        depths = {i: view_depth(model, i) for i in model.images}
        camera = next(iter(model.cameras.values()))
        scene_note = (f"Scene: `{SCENE}` ({len(model.images)} views, {len(model.points3d)} points, "
                      f"{camera.model} camera)"
                      + (f", every image reduced {factor}x (means of {factor}x{factor} blocks; cameras and keypoints "
                         f"scaled to match) to {camera.width}x{camera.height}." if factor > 1 else
                         f", images at full size {camera.width}x{camera.height}."))
        held_out_text, held_out = leave_points_out_section(model, images, depths, seeds, command, scene_note)
        consistency_text, agreement = consistency_section(model, images, depths, check, command, scene_note)
        parts += [held_out_text, consistency_text]
        results.update(check=check, leave_points_out=held_out, consistency=agreement)
    parts[summary_at] = summary(results, counts)
    elapsed = time.perf_counter() - started
    parts[2] = f"Written by `{command}` in {elapsed:.0f} s wall time (all sections)."
    results["elapsed"] = elapsed
    return "\n".join(parts), results


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    out = parser().parse_args(argv).out
    text, _ = run(argv)
    return H.publish([text], out)


if __name__ == "__main__":
    sys.exit(main())
