"""The batch CSV: its columns, one line per row, the settings fingerprint beside it, reading, resuming and compacting.

The CSV has the header :data:`CSV_COLUMNS` and one line per finished frame,
appended and flushed as the frame finishes (:func:`append_row`).  The
settings of the run (options and frame list) are kept as JSON beside it
(:func:`settings_path`); a rerun with other settings is refused.  A CSV with
several rows for a frame is compacted to the last one (:func:`compact`),
rewritten atomically.  While a batch runs it holds an exclusive lock on
``<csv>.lock`` (:func:`locked`), so that a second batch on the same CSV is
refused instead of appending to a file the first one replaces.

Imports the standard library, :mod:`sparsedepth.io` (atomic writes) and :mod:`sparsedepth.objective.weights`.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import errno
import io as _io
import json
import os
import threading
from pathlib import Path

try:
    import fcntl
except ImportError:  # Windows: no POSIX locks, only batches of one process are told apart
    fcntl = None

from ..io import atomic_target
from ..objective.weights import weights_settings

__all__ = ["CSV_COLUMNS", "LINE_END", "HEADER", "settings_path", "lock_path", "locked", "fingerprint",
           "settings_difference", "csv_line", "append_row", "read_log", "compact", "write_text_atomic", "start_log",
           "compact_file", "write_error"]

#: Columns of the batch CSV, in order.
CSV_COLUMNS = (
    "position", "name", "status", "height", "width", "observed", "scored", "method",
    "rmse", "mae", "rel", "delta1", "nn_rmse", "nn_mae", "nn_rel", "nn_delta1",
    "runtime", "converged", "clamped", "output", "error",
)

LINE_END = "\r\n"  # the csv module's line terminator
HEADER = ",".join(CSV_COLUMNS)
_SETTINGS_FORMAT = 1


def settings_path(csv_path) -> Path:
    """Where :func:`~sparsedepth.batch.run_batch` keeps the settings fingerprint of ``csv_path``: ``<csv>.settings.json``."""
    csv_path = Path(csv_path)
    return csv_path.with_name(csv_path.name + ".settings.json")


def lock_path(csv_path) -> Path:
    """The file a running batch locks so that no other batch writes ``csv_path`` at the same time: ``<csv>.lock``."""
    csv_path = Path(csv_path)
    return csv_path.with_name(csv_path.name + ".lock")


def _holder(fd) -> str:
    with contextlib.suppress(OSError, ValueError):
        pid = int(os.pread(fd, 32, 0).decode("ascii").strip())
        return f" (process {pid})"
    return ""


_HELD: set[str] = set()  # lock files this process holds (POSIX locks do not conflict within one process)
_HELD_GUARD = threading.Lock()


def _refuse(csv_path: Path, path: Path, holder: str):
    return ValueError(
        f"'{csv_path}' is being written by another batch{holder}, which holds '{path.name}'; wait for it to end, "
        "or give another CSV path"
    )


@contextlib.contextmanager
def locked(csv_path: Path):
    """Hold an exclusive lock on :func:`lock_path` of ``csv_path`` for the duration of the block.

    A second batch on the same CSV would append rows to a file that the
    first one replaces when it compacts it (rows lost), and would remove the
    first one's temporary outputs; it is refused with a ``ValueError``
    instead, in another process or in this one.  The lock is a POSIX record
    lock (``lockf``): it ends with the process however it ends, and worker
    processes forked while it is held do not inherit it, so workers left
    behind by a killed driver do not block the next run.  The lock file is
    removed when the block ends.  Where the platform or the file system has
    no such locks, only batches of this process are told apart.
    """
    path = lock_path(csv_path)
    key = os.path.abspath(path)
    with _HELD_GUARD:
        if key in _HELD:
            raise _refuse(csv_path, path, f" (process {os.getpid()}, this one)")
        _HELD.add(key)
    try:
        with _file_lock(csv_path, path):
            yield
    finally:
        with _HELD_GUARD:
            _HELD.discard(key)


@contextlib.contextmanager
def _file_lock(csv_path: Path, path: Path):
    if fcntl is None:
        yield
        return
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno in (errno.EACCES, errno.EAGAIN):
                holder = _holder(fd)
                os.close(fd)
                raise _refuse(csv_path, path, holder) from None
            os.close(fd)  # a file system without locks: run unlocked
            yield
            return
        try:
            current = os.stat(path)
        except FileNotFoundError:
            current = None
        mine = os.fstat(fd)
        if current is not None and (current.st_dev, current.st_ino) == (mine.st_dev, mine.st_ino):
            break
        os.close(fd)  # the holder before us removed the file we locked: lock the new one
    try:
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)
        os.close(fd)


def fingerprint(frames, options) -> dict:
    """The settings of a batch as plain JSON data: the options and the frame list (absolute paths)."""
    settings = dataclasses.asdict(options)
    # the L1 edge term has no scale: its penalty fields are left out, so settings files that do not name them match
    settings["weights"] = weights_settings(options.weights)
    if settings["quality"] == "default":  # batches of the default solve match settings files that do not name it
        del settings["quality"]
    if settings["image_shift"] is None:  # matches settings files that do not name the field
        del settings["image_shift"]
    data = {
        "format": _SETTINGS_FORMAT,
        "options": settings,
        "frames": [[type(f).__name__, *dataclasses.astuple(f)] for f in frames],
    }
    return json.loads(json.dumps(data, allow_nan=False))


def settings_difference(stored, current) -> str:
    """What differs between a stored fingerprint and the current one, in words ("" when nothing does)."""
    if not isinstance(stored, dict) or stored.get("format") != _SETTINGS_FORMAT:
        return "the settings file is not one this version writes"
    parts = []
    old, new = stored.get("options", {}), current["options"]
    changed = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
    if changed:
        parts.append("options " + ", ".join(changed))
    if stored.get("frames") != current["frames"]:
        before, after = stored.get("frames") or [], current["frames"]
        parts.append(f"the frame list ({len(before)} frames before, {len(after)} now)")
    return " and ".join(parts)


def csv_line(row: dict) -> str:
    """One CSV line (with its line end) of ``row``; missing columns are empty."""
    buffer = _io.StringIO()
    csv.DictWriter(buffer, fieldnames=CSV_COLUMNS, restval="", lineterminator=LINE_END).writerow(row)
    return buffer.getvalue()


def _parse_line(line: str) -> dict:
    values = next(csv.reader([line]), [])
    return dict(zip(CSV_COLUMNS, values))


def read_log(csv_path: Path) -> tuple[str, list[tuple[str, dict, str]]]:
    """(file text, [(name, row, line with its line end)]) of an existing batch CSV.

    A last line without its line end (a run killed while writing it) is
    dropped.
    """
    with open(csv_path, newline="", encoding="utf-8") as handle:
        text = handle.read()
    parts = text.split(LINE_END)
    if parts[0] != HEADER and not (len(parts) == 1 and HEADER.startswith(parts[0])):
        raise ValueError(
            f"'{csv_path}' is not a batch CSV of this version (its first line is not the header "
            f"{HEADER!r}); give another CSV path or overwrite=True (command line: --overwrite)"
        )
    entries = []
    for line in parts[1:-1]:
        row = _parse_line(line)
        entries.append((row.get("name", ""), row, line + LINE_END))
    return text, entries


def compact(entries, names) -> list[tuple[str, dict, str]]:
    """The last row of each frame of ``names``, in the order of those rows."""
    last = {name: i for i, (name, _, _) in enumerate(entries) if name in names}
    return [entries[i] for i in sorted(last.values())]


def write_text_atomic(path: Path, text: str) -> None:
    """Replace ``path`` by ``text`` atomically (a temporary file renamed onto it)."""
    with atomic_target(path) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as handle:
            handle.write(text)


def write_error(exc: OSError, path, what: str) -> OSError:
    """``exc`` (a failed write) as an ``OSError`` of the same errno whose message names the file and the option.

    ``what`` says what was being written (``"the row of frame 'a'"``); the
    message names ``path`` and the CSV's argument (``csv_path``, ``--csv``
    on the command line), keeps the system's reason (``No space left on
    device``, ``File too large``) and says that the finished rows are kept.
    """
    reason = exc.strerror or " ".join(str(exc).split()) or type(exc).__name__
    error = OSError(f"could not write {what} to '{path}' (`csv_path`, command line --csv): {reason}; the rows of "
                    "finished frames are kept: free space (or choose another --csv), then run the same batch again "
                    "to resume")
    error.errno = exc.errno
    return error


def append_row(handle, row: dict) -> None:
    """Append the line of ``row`` to the open CSV ``handle`` and flush it, so that it survives an interruption.

    An ``OSError`` (a full disk) names the CSV and the frame (:func:`write_error`).
    """
    try:
        handle.write(csv_line(row))
        handle.flush()
    except OSError as exc:
        raise write_error(exc, handle.name, f"the row of frame '{row.get('name', '')}'") from exc


def _stored_settings(settings: Path):
    """The stored fingerprint: None if the file is missing, ``{}`` if it is not JSON."""
    try:
        return json.loads(settings.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except ValueError:
        return {}


def start_log(csv_path: Path, current: dict, names, *, resume: bool, overwrite: bool) -> list[tuple[str, dict, str]]:
    """Create the CSV and its settings file, or check and compact an existing CSV to resume it.

    Returns the entries kept from an existing CSV (the last row of each frame
    of ``names``), empty for a new one.  An existing CSV is an error without
    ``resume``, or when it was written with other settings (or has rows but
    no settings file); ``overwrite`` starts afresh instead.
    """
    settings = settings_path(csv_path)
    if not csv_path.exists() or overwrite:
        _write_log_file(settings, json.dumps(current, indent=1) + "\n", "the settings of the batch")
        _write_log_file(csv_path, HEADER + LINE_END, "the CSV header")
        return []
    if not resume:
        raise ValueError(f"'{csv_path}' exists; pass resume=True to continue it or overwrite=True to start afresh")
    text, entries = read_log(csv_path)
    stored = _stored_settings(settings)
    if stored is None:
        if entries:
            raise ValueError(
                f"'{csv_path}' has rows but no settings file '{settings.name}', so a resumed run cannot be "
                "checked against it; give another CSV path or overwrite=True (command line: --overwrite)"
            )
        _write_log_file(settings, json.dumps(current, indent=1) + "\n", "the settings of the batch")
    else:
        difference = settings_difference(stored, current)
        if difference:
            raise ValueError(
                f"'{csv_path}' was written with other settings ({difference} differ); to start it afresh pass "
                "overwrite=True (command line: --overwrite), or give another CSV path"
            )
    kept = compact(entries, set(names))
    compacted = HEADER + LINE_END + "".join(line for _, _, line in kept)
    if compacted != text:
        _write_log_file(csv_path, compacted, "the compacted CSV")
    return kept


def _write_log_file(path: Path, text: str, what: str) -> None:
    """:func:`write_text_atomic`; an ``OSError`` names the file and the option (:func:`write_error`)."""
    try:
        write_text_atomic(path, text)
    except OSError as exc:
        raise write_error(exc, path, what) from exc


def compact_file(csv_path: Path, names) -> None:
    """Rewrite the CSV with the last row of each frame of ``names`` if it has more rows than that."""
    _, entries = read_log(csv_path)
    kept = compact(entries, set(names))
    if len(kept) != len(entries):
        write_text_atomic(csv_path, HEADER + LINE_END + "".join(line for _, _, line in kept))
