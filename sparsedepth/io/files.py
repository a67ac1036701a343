"""File safety shared by every reader and writer: messages, pixel limits, decoder errors and atomic writes.

What lives here: how a path or an option is named in messages (:func:`file_label`,
:func:`option_labels`), the pixel limit checked from a header before decoding
(:data:`MAX_PIXELS`, :func:`check_max_pixels`, :func:`check_pixels`), the
extension check, the translation of a third-party decoder's exceptions into
the reader's ``ValueError`` (:func:`as_value_error`), and atomic writes
(:func:`atomic_target`, :func:`create_temporary`, :func:`fsync`): the data go
to a temporary file in the destination folder, which then replaces the
destination with :func:`os.replace`; if anything fails the temporary file is
removed and the destination is left as it was.

Imports the standard library and :mod:`sparsedepth._validation` only.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from pathlib import Path
from typing import Callable, Iterator, Mapping

from .._validation import argument_label, is_int

__all__ = [
    "MAX_PIXELS",
    "as_value_error",
    "atomic_target",
    "check_extension",
    "check_max_pixels",
    "check_pixels",
    "create_temporary",
    "decode_error",
    "file_label",
    "fsync",
    "load_error",
    "option_labels",
    "read_bytes",
    "suffix",
]

#: Default ``max_pixels`` of every reader: larger images are refused from their header.
MAX_PIXELS = 2**27


def file_label(path, name: str) -> str:
    """The file as messages name it: its label followed by the quoted path."""
    return f"{argument_label(name)} '{path}'"


def option_labels(option_names) -> Callable[[str], str]:
    """Label function for option keywords, overridden by the ``option_names`` mapping."""
    if option_names is None:
        option_names = {}
    elif not isinstance(option_names, Mapping):
        raise TypeError(
            f"`option_names` must be a mapping from keyword to label, got {type(option_names).__name__}."
        )
    return lambda keyword: argument_label(str(option_names.get(keyword, keyword)))


def read_bytes(path: Path, place: str) -> bytes:
    """The whole content of ``path``; an :class:`OSError` becomes a ``ValueError`` naming ``place``."""
    try:
        return path.read_bytes()
    except OSError as exc:
        raise ValueError(f"{place}: cannot be read ({exc}).") from None


def check_max_pixels(max_pixels, label: str) -> int | None:
    """``max_pixels`` as an int, or None (no limit); it must be a positive integer."""
    if max_pixels is None:
        return None
    if not is_int(max_pixels):
        raise TypeError(f"{label} must be a positive integer or None, got {type(max_pixels).__name__}.")
    if max_pixels < 1:
        raise ValueError(f"{label} must be a positive integer or None, got {max_pixels!r}.")
    return int(max_pixels)


def check_pixels(height: int, width: int, max_pixels: int | None, place: str, label: str) -> None:
    """Refuse a declared size above the pixel limit (before anything is decoded)."""
    if max_pixels is not None and height * width > max_pixels:
        raise ValueError(
            f"{place} declares {width}x{height} = {height * width} pixels, more than the limit "
            f"{max_pixels} ({label}); raise {label} if the file is genuine."
        )


def suffix(path) -> str:
    """The lower-case extension of ``path`` (with its dot), ``''`` if none."""
    return Path(path).suffix.lower()


def check_extension(path: Path, allowed: tuple[str, ...], what: str, name: str = "path") -> str:
    """Return the extension of ``path`` if it is one of ``allowed``; ``ValueError`` listing them otherwise."""
    ext = suffix(path)
    if ext not in allowed:
        raise ValueError(
            f"cannot {what} {file_label(path, name)}: unsupported extension '{ext or '(none)'}'. "
            f"Supported extensions: {', '.join(allowed)}."
        )
    return ext


@contextlib.contextmanager
def as_value_error(place: str, error) -> Iterator[None]:
    """Exceptions raised in the block by a third-party decoder become ``error(place, exc)``, a ValueError.

    ``MemoryError`` passes through: running out of memory says nothing about the file.
    """
    try:
        yield
    except MemoryError:
        raise
    except Exception as exc:
        raise error(place, exc) from exc


def decode_error(place: str, exc: BaseException) -> ValueError:
    """``could not decode <place>: <reason>``, for an image decoder's failure."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return ValueError(f"could not decode {place}: {text}")


def load_error(place: str, exc: BaseException) -> ValueError:
    """``could not load <place>: <reason>``, for an array container's failure (NumPy, zip, HDF5)."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return ValueError(f"could not load {place}: {text}")


def fsync(path) -> None:
    """Flush ``path`` to disk before it is renamed into place (best effort: some systems cannot)."""
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def create_temporary(path: Path, kind: str = "tmp") -> Path:
    """Create a new empty file ``.<name>.<random>.<kind><suffix>`` next to ``path``; return its path.

    The file is created with ``O_EXCL`` (nothing existing is ever clobbered)
    and mode ``0o666`` so that the umask applies as for :func:`open`.  The
    name keeps the destination's extension (some encoders choose the format
    from it).  Raises the :class:`OSError` of the failed creation (missing
    or read-only folder, full disk, ...).
    """
    for _ in range(100):
        tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.{kind}{path.suffix}"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:  # pragma: no cover - astronomically unlikely
            continue
        os.close(fd)
        return tmp
    raise FileExistsError(f"could not create a temporary file in '{path.parent}'.")  # pragma: no cover


@contextlib.contextmanager
def atomic_target(path) -> Iterator[Path]:
    """Yield a fresh temporary path next to ``path``; move it onto ``path`` on success.

    The temporary name keeps the destination's extension (some encoders choose
    the format from it).  On any exception the temporary file is removed and
    the exception propagates; ``path`` itself is untouched.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"`path` must be a str or os.PathLike, got {type(path).__name__}.")
    path = Path(path)
    if not path.parent.is_dir():
        raise FileNotFoundError(f"`path`: directory '{path.parent}' does not exist.")
    tmp = create_temporary(path)
    try:
        yield tmp
        fsync(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
