"""Whole datasets: frame discovery, resumable runs with a CSV of metrics, worker pools and Dask clusters.

May import everything of the library below the command line; :mod:`sparsedepth.batch.distributed` alone imports
Dask, and only when called.
"""

from .run import (
    CSV_COLUMNS,
    TASKS,
    BatchOptions,
    BatchSummary,
    FileFrame,
    FrameOutcome,
    NYUFrame,
    NYUH5Frame,
    default_workers,
    evaluate_frame,
    find_frame_pairs,
    find_frames,
    nyu_frames,
    nyu_h5_frames,
    run_batch,
    settings_path,
)

__all__ = ["TASKS", "CSV_COLUMNS", "FrameOutcome", "evaluate_frame", "FileFrame", "NYUFrame", "NYUH5Frame",
           "find_frames", "find_frame_pairs", "nyu_frames", "nyu_h5_frames", "BatchOptions", "BatchSummary",
           "default_workers", "settings_path", "run_batch"]
