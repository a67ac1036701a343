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
import concurrent.futures
import dataclasses
import ipaddress
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
from .worker import one_line, remove_temporaries

__all__ = [
    "DEFAULT_TIMEOUT",
    "connect",
    "scheduler_address",
    "cluster_threads",
    "absolute_frames",
    "run_batch_on_cluster",
]

#: Seconds to wait for the scheduler (and for its first worker) before giving up.
DEFAULT_TIMEOUT = 15.0

_ENV_ADDRESS = "DASK_SCHEDULER_ADDRESS"

#: The address schemes of a scheduler reachable from other processes (``inproc://`` lives inside one process).
_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")

_HOST_NAME = re.compile(r"[A-Za-z0-9_]([A-Za-z0-9_.-]*[A-Za-z0-9_])?")

#: Extra seconds the handshake is given beyond the timeout, so that an unreachable address is reported as such.
_HANDSHAKE_GRACE = 0.25


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


def _address_error(described: str, reason: str, option: str | None) -> ValueError:
    """A malformed scheduler address (``described``: its source and value); ``option`` lets the command line name
    its flag."""
    exc = ValueError(f"{described} is not a Dask scheduler address: {reason}; give tcp://HOST:PORT, "
                     "e.g. tcp://10.0.0.5:8786")
    exc.option = option
    return exc


def _address_problem(address: str) -> str | None:
    """What is wrong with ``address`` as ``[scheme://]host:port``, or None if nothing is."""
    if not address:
        return "it is empty"
    if any(c.isspace() or not c.isprintable() for c in address):
        return "it contains white space or control characters"
    scheme, sep, location = address.partition("://")
    if not sep:
        scheme, location = "tcp", address
    if scheme == "inproc":
        return "inproc:// names a scheduler inside one process, which a batch's driver cannot reach"
    if scheme not in _SCHEMES:
        return f"unknown scheme '{scheme}://' (known: {', '.join(s + '://' for s in _SCHEMES)})"
    if location.startswith("["):
        host, bracket, rest = location[1:].partition("]")
        if not bracket:
            return "the IPv6 address has no closing ']'"
        try:
            ipaddress.IPv6Address(host.split("%")[0])
        except ValueError:
            return f"'{host}' is not an IPv6 address"
        if not rest.startswith(":"):
            return "no port after the IPv6 address"
        port = rest[1:]
    else:
        host, colon, port = location.rpartition(":")
        if not colon:
            return "no port"
        if ":" in host:
            return "an IPv6 address needs brackets, as in tcp://[::1]:8786"
        if not _HOST_NAME.fullmatch(host):
            return f"'{host}' is not a host name or IP address" if host else "no host"
    if not (port.isascii() and port.isdigit()) or not 0 < int(port) < 65536:
        return f"'{port}' is not a port number (1 to 65535)" if port else "no port"
    return None


def _check_address(address, described: str, option: str | None) -> str:
    """``address`` if well formed; else a ValueError starting with ``described`` (its source and value)."""
    if not isinstance(address, str):
        raise TypeError(f"{described} must be a str such as 'tcp://10.0.0.5:8786', got {type(address).__name__}")
    problem = _address_problem(address)
    if problem is not None:
        raise _address_error(described, problem, option)
    return address


def _address_from_file(scheduler_file) -> str:
    path = Path(scheduler_file)
    if not path.is_file():
        exc = FileNotFoundError(
            f"scheduler file '{path}' does not exist; start the scheduler with "
            f"'dask scheduler --scheduler-file {path}' first (or give the address instead)"
        )
        exc.option = "scheduler_file"
        raise exc
    try:
        address = json.loads(path.read_text(encoding="utf-8"))["address"]
    except (ValueError, KeyError, TypeError, OSError) as exc:
        error = ValueError(
            f"scheduler file '{path}' is not a Dask scheduler file (JSON with an 'address' entry): {exc}"
        )
        error.option = "scheduler_file"
        raise error from None
    described = f"the address {address!r} in scheduler file '{path}'"
    if not isinstance(address, str):
        raise _address_error(described, "it is not a string", "scheduler_file")
    return _check_address(address, described, "scheduler_file")


def scheduler_address(address: str | None = None, *, scheduler_file=None) -> str:
    """The scheduler address :func:`connect` would use, checked without connecting.

    Parameters
    ----------
    address : str, optional
        ``[scheme://]host:port`` with scheme ``tcp`` (the default), ``tls``,
        ``ws``, ``wss`` or ``ucx``; an IPv6 host in brackets.  Default: the
        environment variable ``DASK_SCHEDULER_ADDRESS``.
    scheduler_file : str or os.PathLike, optional
        The JSON file of ``dask scheduler --scheduler-file PATH`` (exclusive
        with ``address``).

    Returns
    -------
    str
        The address.

    Raises
    ------
    ValueError
        If both or neither are given (and ``DASK_SCHEDULER_ADDRESS`` is
        unset or empty), the scheduler file is not one, or the address is
        malformed (empty, unclosed ``[``, no port, ``inproc://``, an unknown
        scheme, ...): the message names where the address came from.  Its
        ``option`` attribute is ``"address"``, ``"scheduler_file"`` or None
        (the environment variable).
    FileNotFoundError
        If ``scheduler_file`` does not exist.
    TypeError
        If ``address`` is not a str.
    """
    if address is not None and scheduler_file is not None:
        raise ValueError("give a scheduler address or a scheduler file, not both")
    if scheduler_file is not None:
        return _address_from_file(scheduler_file)
    if address is not None:
        return _check_address(address, f"scheduler address {address!r}", "address")
    address = os.environ.get(_ENV_ADDRESS) or None
    if address is None:
        raise ValueError(f"no scheduler: give its address or scheduler file, or set {_ENV_ADDRESS}")
    return _check_address(address, f"{_ENV_ADDRESS} {address!r}", None)


def _handshake(distributed, address: str, timeout: float) -> None:
    """Open one connection to ``address`` and wait for the Dask handshake, at most ``timeout`` seconds.

    :class:`distributed.Client` waits for the handshake without a time limit,
    so a server that accepts TCP connections but does not speak Dask (any
    other program on that port) would keep it waiting forever.  The
    connection is made in an event loop of its own, on a thread of its own,
    so that this works whether or not the caller runs an event loop.
    """
    connection_args = distributed.Security().get_connection_args("client")

    async def handshake():
        comm = await distributed.comm.connect(address, timeout=timeout, **connection_args)
        await comm.close()

    def run():
        asyncio.run(asyncio.wait_for(handshake(), timeout + _HANDSHAKE_GRACE))

    failure = f"no Dask scheduler answered at {address} within {timeout:g} s"
    with concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="sparsedepth-handshake") as pool:
        try:
            pool.submit(run).result()
        except (TimeoutError, asyncio.TimeoutError):
            raise OSError(f"{failure}: nothing accepted a connection there, or what did (another program on that "
                          "port?) did not answer the Dask handshake") from None
        except OSError as exc:
            raise OSError(f"{failure} ({one_line(exc)})") from None
        except MemoryError:  # another protocol's first bytes read as a Dask frame length ask for exabytes
            raise OSError(f"{failure}: the server there does not speak the Dask protocol (its first bytes are "
                          "not a Dask message)") from None
        except Exception as exc:  # a message that does not decode, a TLS set-up error, ...
            raise OSError(f"{failure}: the server there does not speak the Dask protocol ({one_line(exc)})") \
                from None


def connect(address: str | None = None, *, scheduler_file=None, timeout: float = DEFAULT_TIMEOUT):
    """Connect to a running Dask scheduler and wait for its first worker.

    Parameters
    ----------
    address : str, optional
        Scheduler address, e.g. ``"tcp://10.0.0.5:8786"`` (see
        :func:`scheduler_address`).  Default: the environment variable
        ``DASK_SCHEDULER_ADDRESS``.
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
        ``DASK_SCHEDULER_ADDRESS`` is unset), the address is malformed (see
        :func:`scheduler_address`; checked before any client is made), or
        ``timeout`` is not positive.
    FileNotFoundError
        If ``scheduler_file`` does not exist (its scheduler has not started).
    OSError
        If no Dask scheduler answers within ``timeout``: nothing accepts a
        connection at the address, or what does does not answer the Dask
        handshake (``TimeoutError`` if the scheduler has no worker within a
        second ``timeout``).

    Notes
    -----
    Before the client is made, one connection is opened to the address and
    closed again once the scheduler has answered Dask's handshake, within
    ``timeout``: :class:`distributed.Client` itself would wait for that
    answer without limit.
    """
    timeout = _check_timeout(timeout)
    address = scheduler_address(address, scheduler_file=scheduler_file)
    distributed = _import_distributed()
    _handshake(distributed, address, timeout)
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
    the end (:func:`~sparsedepth.batch.worker.remove_temporaries`).
    """
    if client is not None and (address is not None or scheduler_file is not None):
        raise ValueError("give either a client or a scheduler address/file, not both")
    frames = absolute_frames(frames)
    options = BatchOptions() if options is None else options
    folders = {key: os.path.abspath(getattr(options, key)) for key in ("out_dir", "uncertainty_dir")
               if getattr(options, key) is not None}
    options = dataclasses.replace(options, **folders)
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
    remove_temporaries([frame.name for frame in frames], options)
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
            "which pins glibc's mmap threshold and slows frames down (python -m bench.batch_scale --malloc-trim, "
            "docs/batch_scale_malloc_trim.md); start workers with 'dask worker --no-nanny' or without it in "
            "distributed.nanny.pre-spawn-environ (docs/cluster.md)",
            RuntimeWarning,
            stacklevel=3,
        )

