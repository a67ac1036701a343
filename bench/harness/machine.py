"""What the reports say about the machine: CPU model, cores, OS, Python and library versions, BLAS threads.

May import :mod:`sparsedepth` and the standard library.
"""

from __future__ import annotations

import datetime
import os
import platform
from pathlib import Path

import sparsedepth as sd

__all__ = ["version", "cpu_model", "blas_threads", "machine_info", "machine_markdown"]



def version(module: str) -> str:
    """``module.__version__``, or ``"not installed"``."""
    try:
        return __import__(module).__version__
    except Exception:  # pragma: no cover - optional packages
        return "not installed"


def cpu_model() -> str:
    """The CPU's model name from ``/proc/cpuinfo`` (else what :mod:`platform` knows)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def blas_threads():
    """``$OPENBLAS_NUM_THREADS`` (``None`` when unset)."""
    return os.environ.get("OPENBLAS_NUM_THREADS")


def machine_info() -> dict:
    """CPU model, core count, OS, Python and library versions, date (UTC)."""
    return {
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "os": platform.platform(),
        "python": platform.python_version(),
        "numpy": version("numpy"),
        "scipy": version("scipy"),
        "pyamg": version("pyamg"),
        "scikit-image": version("skimage"),
        "sparsedepth": sd.__version__,
    }


def machine_markdown(info=None) -> str:
    """:func:`machine_info` as one sentence of the report header."""
    info = machine_info() if info is None else info
    return (f"{info['date']}; {info['cpu']}, {info['cores']} cores, {info['os']}; Python {info['python']}, "
            f"NumPy {info['numpy']}, SciPy {info['scipy']}, PyAMG {info['pyamg']}, scikit-image "
            f"{info['scikit-image']}, sparsedepth {info['sparsedepth']}")
