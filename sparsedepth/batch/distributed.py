"""Batches on an existing Dask cluster (the optional ``distributed`` extra).

:func:`run_batch_on_cluster` runs :func:`~sparsedepth.batch.run_batch` with
the frames executed as tasks of a running Dask scheduler - a SLURM
allocation, a Kubernetes deployment, or ``dask scheduler`` plus a few
``dask worker`` processes - while this process (the driver) keeps the CSV.
It needs ``pip install 'sparsedepth[distributed]'``; dask is imported only
inside the functions of this module, so ``import sparsedepth`` never imports
it.

Every worker must be able to import ``sparsedepth`` and to read the frame
files and write into ``out_dir`` under the same absolute paths as the driver
(a shared file system): the driver makes all paths absolute before
submitting.
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import os
import re
import warnings
from pathlib import Path
from typing import Callable, Sequence

from .._validation import is_real
from .frames import absolute_frame
from .options import BatchOptions, BatchSummary
from .run import run_batch
from .worker import one_line

__all__ = [
    "DEFAULT_TIMEOUT",
    "connect",
    "cluster_threads",
    "absolute_frames",
    "remove_stale_outputs",
    "run_batch_on_cluster",
]

#: Seconds to wait for the scheduler (and for its first worker) before giving up.
DEFAULT_TIMEOUT = 15.0

_ENV_ADDRESS = "DASK_SCHEDULER_ADDRESS"


def _import_distributed():
    try:
        import distributed
    except ImportError as exc:
        raise ImportError(
            "running a batch on a Dask cluster needs dask.distributed, which is not installed: "
            "pip install 'sparsedepth[distributed]'"
        ) from exc
    return distributed


def _check_timeout(timeout) -> float:
    if not is_real(timeout) or not timeout > 0:
        raise ValueError(f"timeout must be a positive number of seconds, got {timeout!r}")
    return float(timeout)


def _address_from_file(scheduler_file) -> str:
    path = Path(scheduler_file)
    if not path.is_file():
        raise FileNotFoundError(
            f"scheduler file '{path}' does not exist; start the scheduler with "
            f"'dask scheduler --scheduler-file {path}' first (or give the address instead)"
        )
    try:
        address = json.loads(path.read_text(encoding="utf-8"))["address"]
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(
            f"scheduler file '{path}' is not a Dask scheduler file (JSON with an 'address' entry): {exc}"
        ) from None
    if not isinstance(address, str) or not address:
        raise ValueError(f"scheduler file '{path}' has no usable 'address' entry, got {address!r}")
    return address


def connect(address: str | None = None, *, scheduler_file=None, timeout: float = DEFAULT_TIMEOUT):
    """Connect to a running Dask scheduler and wait for its first worker.

    Parameters
    ----------
    address : str, optional
        Scheduler address, e.g. ``"tcp://10.0.0.5:8786"``.  Default: the
        environment variable ``DASK_SCHEDULER_ADDRESS``.
    scheduler_file : str or os.PathLike, optional
        The JSON file written by ``dask scheduler --scheduler-file PATH``
        (exclusive with ``address``).
    timeout : float
        Seconds to wait for the scheduler to answer, then again at most as
        long for at least one worker.

    Returns
    -------
    distributed.Client
        A client that is not the default Dask client; close it when done.

    Raises
    ------
    ImportError
        If dask.distributed is not installed.
    ValueError
        If both or neither of ``address`` / ``scheduler_file`` are given (and
        ``DASK_SCHEDULER_ADDRESS`` is unset), or ``timeout`` is not positive.
    FileNotFoundError
        If ``scheduler_file`` does not exist (its scheduler has not started).
    OSError
        If the scheduler does not answer within ``timeout`` (``TimeoutError``
        if it has no worker within a second ``timeout``).
    """
    timeout = _check_timeout(timeout)
    if address is not None and scheduler_file is not None:
        raise ValueError("give a scheduler address or a scheduler file, not both")
    if scheduler_file is not None:
        address = _address_from_file(scheduler_file)
    elif address is None:
        address = os.environ.get(_ENV_ADDRESS) or None
        if address is None:
            raise ValueError(f"no scheduler: give its address or scheduler file, or set {_ENV_ADDRESS}")
    distributed = _import_distributed()
    try:
        client = distributed.Client(address, timeout=timeout, set_as_default=False)
    except OSError as exc:
        raise OSError(f"no Dask scheduler answered at {address} within {timeout:g} s ({one_line(exc)})") from None
    try:
        client.wait_for_workers(1, timeout=timeout)
    except (TimeoutError, asyncio.TimeoutError, OSError) as exc:
        client.close()
        raise TimeoutError(
            f"the Dask scheduler at {address} has no worker after {timeout:g} s; start workers with "
            f"'dask worker {address}'"
        ) from exc
    except BaseException:
        client.close()
        raise
    return client


def cluster_threads(client) -> int:
    """Total threads of the cluster's workers now (the sum of their ``nthreads``).

    Parameters
    ----------
    client : distributed.Client

    Returns
    -------
    int
        0 when the cluster has no worker.
    """
    return int(sum(client.nthreads().values()))  # asks the scheduler (scheduler_info() may be a cached copy)


def absolute_frames(frames: Sequence) -> list:
    """The frames with every file path made absolute (resolved in this process's directory).

    Parameters
    ----------
    frames : sequence of FileFrame, NYUFrame or NYUH5Frame

    Returns
    -------
    list
        New frame objects (:func:`sparsedepth.batch.run_batch`'s own rule);
        the given ones are not modified.

    Raises
    ------
    TypeError
        For an object that is not a frame of :mod:`sparsedepth.batch`.
    """
    return [absolute_frame(frame) for frame in frames]


def remove_stale_outputs(out_dir, names, out_format: str) -> list[Path]:
    """Delete the temporary files left by frame attempts that were killed while writing.

    An output is written to ``.<name><ext>.<12 hex digits>.tmp<ext>`` and
    then renamed onto ``<name><ext>`` (:func:`~sparsedepth.write_depth`), so
    a worker killed mid-write leaves such a file beside the complete output
    of the attempt that Dask ran again.  Only names of that exact form, for
    the given frame names, are removed.

    Parameters
    ----------
    out_dir : str or os.PathLike
    names : iterable of str
        Frame names (``FileFrame.name`` / ``NYUFrame.name``).
    out_format : str
        The extension with its dot, e.g. ``".npy"``.

    Returns
    -------
    list of Path
        The files removed.
    """
    out_dir = Path(out_dir)
    wanted = {f"{name}{out_format}" for name in names}
    pattern = re.compile(r"^\.(?P<target>.+)\.[0-9a-f]{12}\.tmp" + re.escape(out_format) + r"$")
    removed = []
    for path in out_dir.iterdir():
        match = pattern.match(path.name)
        if match and match.group("target") in wanted and path.is_file():
            try:
                path.unlink()
            except FileNotFoundError:
                continue
            removed.append(path)
    return removed


# the numpydoc docstring is most of this function's length; its code is about 25 lines
def run_batch_on_cluster(
    frames: Sequence,
    csv_path,
    *,
    options: BatchOptions | None = None,
    client=None,
    address: str | None = None,
    scheduler_file=None,
    timeout: float = DEFAULT_TIMEOUT,
    progress: Callable[[int, int, dict], None] | None = None,
    resume: bool = True,
    overwrite: bool = False,
) -> BatchSummary:
    """:func:`~sparsedepth.batch.run_batch` with every frame a task on a Dask cluster.

    Parameters
    ----------
    frames : sequence of FileFrame or NYUFrame
    csv_path : str or os.PathLike
        Written by this process only, one row per frame as it finishes.
    options : BatchOptions, optional
        Its ``out_dir`` is made absolute before submission.
    client : distributed.Client, optional
        An existing client (left open).  Otherwise one is made with
        :func:`connect` from ``address`` / ``scheduler_file`` / ``timeout``
        (default ``$DASK_SCHEDULER_ADDRESS``) and closed at the end.
    address, scheduler_file, timeout
        See :func:`connect`; not allowed together with ``client``.
    progress : callable, optional
        ``progress(done, total, row)`` in this process after every frame.
    resume, overwrite : bool
        As in :func:`~sparsedepth.batch.run_batch`: a rerun skips the frames
        done before; other settings are refused unless ``overwrite``.

    Returns
    -------
    BatchSummary

    Raises
    ------
    ValueError
        ``client`` together with ``address``/``scheduler_file``, and the
        errors of :func:`connect` and :func:`~sparsedepth.batch.run_batch`.

    Warns
    -----
    RuntimeWarning
        If workers run with ``MALLOC_TRIM_THRESHOLD_`` set, as the Dask
        nanny does by default (see ``docs/cluster.md``).

    Notes
    -----
    Tasks are submitted with ``pure=False`` (a frame is never taken from a
    cache, and two submissions of it are two tasks).  At most ``2 T`` frames
    are in flight, ``T`` being the total threads of the workers when the
    batch starts, so the scheduler always has the next frame queued without
    holding the whole dataset.

    A worker that dies mid-frame costs a retry, not a frame: the scheduler
    runs the task again on another worker, up to
    ``distributed.scheduler.allowed-failures`` times (then the frame gets an
    error row with ``KilledWorker``).  The output of every attempt is written
    to a temporary file renamed into place, so no partial output is ever
    under a frame's name; temporary files of killed attempts are removed at
    the end (:func:`remove_stale_outputs`).
    """
    if client is not None and (address is not None or scheduler_file is not None):
        raise ValueError("give either a client or a scheduler address/file, not both")
    frames = absolute_frames(frames)
    options = BatchOptions() if options is None else options
    if options.out_dir is not None:
        options = dataclasses.replace(options, out_dir=os.path.abspath(options.out_dir))
    own = client is None
    if own:
        client = connect(address, scheduler_file=scheduler_file, timeout=timeout)
    executor = None
    try:
        _warn_malloc_trim(client)
        threads = max(cluster_threads(client), 1)
        executor = client.get_executor(pure=False)
        summary = run_batch(frames, csv_path, options=options, executor=executor, progress=progress,
                            max_in_flight=2 * threads, resume=resume, overwrite=overwrite)
    finally:
        if executor is not None:
            executor.shutdown(wait=False)
        if own:
            client.close()
    if options.out_dir is not None:
        remove_stale_outputs(options.out_dir, [frame.name for frame in frames], options.out_format)
    return summary


def _malloc_trim_threshold():
    """On a worker: its MALLOC_TRIM_THRESHOLD_ (None when unset)."""
    return os.environ.get("MALLOC_TRIM_THRESHOLD_")


def _warn_malloc_trim(client) -> None:
    """Warn if workers run with MALLOC_TRIM_THRESHOLD_ set (the Dask nanny sets it to 65536)."""
    values = {value for value in client.run(_malloc_trim_threshold).values() if value is not None}
    if values:
        warnings.warn(
            f"Dask workers run with MALLOC_TRIM_THRESHOLD_={', '.join(sorted(values))} (the Dask nanny's default), "
            "which pins glibc's mmap threshold and made frames about 2x slower in bench/batch_scale.py; start "
            "workers with 'dask worker --no-nanny' or without it in distributed.nanny.pre-spawn-environ "
            "(docs/cluster.md)",
            RuntimeWarning,
            stacklevel=3,
        )

