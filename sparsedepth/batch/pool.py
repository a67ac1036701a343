"""The default worker pool of a batch: its size, its workers' signals and BLAS threads, and its shutdown.

Each worker process of the pool ignores SIGINT (the driver decides what an
interrupt does), has the default SIGTERM action, runs BLAS on one thread, so
that ``N`` workers use ``N`` cores, and on Linux ends with its driver, even a
driver killed by SIGKILL.

Imports only the standard library (``threadpoolctl`` if it is installed).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
from concurrent.futures import ProcessPoolExecutor

from .._system import available_cpus

__all__ = ["default_workers", "init_worker", "end_with_parent", "new_pool", "stop_pool", "loaded_openblas",
           "openblas_function"]


def default_workers() -> int:
    """Worker processes of the default pool: half the CPUs this process may use, at least 1, at most 8.

    On a machine shared with other work (or with hyper-threading) one worker
    per core oversubscribes it: on a 2-core machine 1 worker is chosen.
    """
    return max(1, min(available_cpus() // 2, 8))


def stop_pool(executor: ProcessPoolExecutor, *, terminate: bool) -> None:
    """Shut the default pool down; with ``terminate`` end its worker processes first."""
    if terminate:
        processes = list((getattr(executor, "_processes", None) or {}).values())
        for process in processes:
            with contextlib.suppress(Exception):
                process.terminate()
        for process in processes:
            with contextlib.suppress(Exception):
                process.join(5.0)
                if process.is_alive():
                    process.kill()
                    process.join(5.0)
    executor.shutdown(wait=True)


_BLAS_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
_thread_limit = None  # kept alive in each worker process


def init_worker(driver_pid=None) -> None:
    """Initializer of the default pool's worker processes.

    SIGINT is ignored (the driver decides what an interrupt does and ends
    the workers), SIGTERM gets its default action back (a forked worker
    inherits the driver's handler), and BLAS thread pools are pinned to one
    thread: the environment variables for libraries loaded from now on, and
    for those already loaded (a forked worker has the driver's) ``threadpoolctl``
    if installed, else the thread-count function of every loaded OpenBLAS.
    With ``driver_pid`` (the process that made the pool) the worker ends
    with the driver (:func:`end_with_parent`).
    """
    global _thread_limit
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if driver_pid is not None:
        end_with_parent(driver_pid)
    for name in _BLAS_THREAD_VARIABLES:
        os.environ[name] = "1"
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        _set_openblas_threads(1)
        return
    _thread_limit = threadpool_limits(limits=1)


#: ``PR_SET_PDEATHSIG`` of Linux's ``prctl``: the signal this process gets when its parent ends
_PR_SET_PDEATHSIG = 1


def end_with_parent(parent_pid) -> bool:
    """Ask the kernel to send this process SIGTERM when its parent ``parent_pid`` ends (Linux); returns whether it will.

    A driver ended by SIGKILL cannot stop its workers itself; without this
    they would stay, idle, until killed by hand.  If the parent has already
    ended (this process's parent is no longer ``parent_pid``) the process
    ends at once.  The kernel sends the signal when the *thread* that
    started this process ends: the default pool's workers are started by the
    thread that runs the batch, which outlives them.  Elsewhere (no
    ``prctl``) nothing is set and False is returned.
    """
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError, TypeError):
        return False
    if prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
        return False
    if os.getppid() != parent_pid:
        os.kill(os.getpid(), signal.SIGTERM)
    return True


#: The thread-count functions of the OpenBLAS builds numpy and scipy wheels ship (symbol prefixes and suffixes vary).
_OPENBLAS_PREFIXES = ("openblas", "scipy_openblas")
_OPENBLAS_SUFFIXES = ("", "64_")


def loaded_openblas():
    """The OpenBLAS libraries mapped into this process (from /proc/self/maps; empty elsewhere)."""
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            paths = {line.split()[-1] for line in maps if "openblas" in line.lower() and "/" in line}
    except OSError:
        return []
    libraries = []
    for path in sorted(paths):
        try:
            libraries.append(ctypes.CDLL(path))
        except OSError:
            continue
    return libraries


def openblas_function(library, action):
    """``<prefix>_<action>_num_threads<suffix>`` of an OpenBLAS library (``action`` "get" or "set"), or None."""
    for prefix in _OPENBLAS_PREFIXES:
        for suffix in _OPENBLAS_SUFFIXES:
            function = getattr(library, f"{prefix}_{action}_num_threads{suffix}", None)
            if function is not None:
                return function
    return None


def _set_openblas_threads(count: int) -> None:
    """Set the thread count of every loaded OpenBLAS (what threadpoolctl does for it, without the dependency)."""
    for library in loaded_openblas():
        function = openblas_function(library, "set")
        if function is not None:
            function(ctypes.c_int(count))


def new_pool(workers: int) -> ProcessPoolExecutor:
    """A process pool of ``workers`` processes set up by :func:`init_worker` (ending with this process)."""
    return ProcessPoolExecutor(max_workers=workers, initializer=init_worker, initargs=(os.getpid(),))
