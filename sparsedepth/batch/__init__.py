"""Whole datasets: frame discovery, resumable runs with a CSV of metrics, worker pools and Dask clusters.

Modules, each by responsibility: :mod:`~sparsedepth.batch.frames` (frame
types and their discovery), :mod:`~sparsedepth.batch.evaluate` (one frame,
scored), :mod:`~sparsedepth.batch.options` (what to do with every frame),
:mod:`~sparsedepth.batch.worker` (one frame in a worker, one row out),
:mod:`~sparsedepth.batch.csvlog` (the CSV, its settings, resuming),
:mod:`~sparsedepth.batch.pool` (the default process pool),
:mod:`~sparsedepth.batch.run` (:func:`run_batch`) and
:mod:`~sparsedepth.batch.distributed` (Dask clusters).

May import everything of the library below the command line, never
:mod:`sparsedepth.cli`; :mod:`sparsedepth.batch.distributed` alone imports
Dask, and only when called.
"""

from .csvlog import CSV_COLUMNS, settings_path
from .evaluate import TASKS, FrameOutcome, evaluate_frame
from .frames import FileFrame, NYUFrame, NYUH5Frame, find_frame_pairs, find_frames, nyu_frames, nyu_h5_frames
from .options import BatchOptions, BatchSummary
from .pool import default_workers
from .run import run_batch

__all__ = ["TASKS", "CSV_COLUMNS", "FrameOutcome", "evaluate_frame", "FileFrame", "NYUFrame", "NYUH5Frame",
           "find_frames", "find_frame_pairs", "nyu_frames", "nyu_h5_frames", "BatchOptions", "BatchSummary",
           "default_workers", "settings_path", "run_batch"]
