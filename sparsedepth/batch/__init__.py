"""Whole datasets: frame discovery, resumable runs with a CSV of metrics, worker pools and Dask clusters.

Modules, each by responsibility: :mod:`~sparsedepth.batch.frames` (frame
types and their discovery, the views of a COLMAP model among them), :mod:`~sparsedepth.batch.evaluate` (one frame,
scored), :mod:`~sparsedepth.batch.options` (what to do with every frame),
:mod:`~sparsedepth.batch.worker` (one frame in a worker, one row out),
:mod:`~sparsedepth.batch.csvlog` (the CSV, its settings, resuming),
:mod:`~sparsedepth.batch.pool` (the default process pool),
:mod:`~sparsedepth.batch.run` (:func:`run_batch`, and a COLMAP scene's
``scene.json``: :func:`write_colmap_scene`) and
:mod:`~sparsedepth.batch.distributed` (Dask clusters).

May import everything of the library below the command line, never
:mod:`sparsedepth.cli`; :mod:`sparsedepth.batch.distributed` alone imports
Dask, and only when called.
"""

from .csvlog import CSV_COLUMNS, settings_path
from .evaluate import TASKS, FrameOutcome, evaluate_frame
from .frames import (
    ColmapFrame,
    FileFrame,
    NYUFrame,
    NYUH5Frame,
    colmap_depth_range,
    colmap_frames,
    find_frame_pairs,
    find_frames,
    nyu_frames,
    nyu_h5_frames,
    png_depth_scale,
    unregistered_images,
)
from .options import BatchOptions, BatchSummary
from .pool import default_workers
from .run import SCENE_UNITS, colmap_scene, run_batch, write_colmap_scene

__all__ = ["TASKS", "CSV_COLUMNS", "FrameOutcome", "evaluate_frame", "FileFrame", "NYUFrame", "NYUH5Frame",
           "ColmapFrame", "find_frames", "find_frame_pairs", "nyu_frames", "nyu_h5_frames", "colmap_frames",
           "unregistered_images", "colmap_depth_range", "png_depth_scale", "BatchOptions", "BatchSummary",
           "default_workers", "settings_path", "run_batch", "SCENE_UNITS", "colmap_scene", "write_colmap_scene"]
