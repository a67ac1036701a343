"""Output planning of the command line: every file a run will write, checked first and written all or nothing.

A run names its inputs and its outputs as :class:`Named` paths (the option
the user typed, what they typed, the file itself).  Before any work,
:func:`check_distinct` refuses an output that is the same file as an input
or as another output, and :func:`check_writable` proves that every output
can be created.  After the work, :func:`commit` writes every output to a
temporary file next to its target and renames them onto their targets only
when all of them were written; on any failure nothing is left behind.

This module imports only the standard library, :mod:`sparsedepth.io` and
:mod:`sparsedepth.cli.messages`; it never prints.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Sequence

from ..io import create_temporary, fsync
from .messages import one_line

__all__ = ["Named", "OutputError", "check_distinct", "check_writable", "commit"]


class OutputError(ValueError):
    """An output that cannot or must not be written; the message is one line naming the option."""


@dataclass(frozen=True)
class Named:
    """A file of a run, named after the option that brought it.

    Attributes
    ----------
    flag : str
        The option, as typed on the command line (``"--out"``, ``"--outdir"``).
    given : str
        The option's value as typed (a file, or the folder holding ``path``).
    path : pathlib.Path
        The file itself.
    create_parent : bool
        Output only: the folder of ``path`` may be missing and is then
        created (with its missing parents) when the outputs are written.
    """

    flag: str
    given: str
    path: Path
    create_parent: bool = False

    @property
    def label(self) -> str:
        """``--out 'a.png'``, or ``--outdir 'd' file 'd/depth.png'`` for a file inside a given folder."""
        if Path(self.given) == self.path:
            return f"{self.flag} '{self.given}'"
        return f"{self.flag} '{self.given}' file '{self.path}'"


def _identity(path: Path) -> tuple:
    """What makes two paths the same file, existing or not.

    An existing file is its ``(st_dev, st_ino)`` after following symbolic
    links (so hard links, symbolic links and ``./..`` spellings of one file
    compare equal, as :func:`os.path.samefile` has it).  A file yet to be
    created is the identity of its (resolved) folder plus its name; if even
    the folder is missing, the fully resolved path.
    """
    real = os.path.realpath(path)
    with contextlib.suppress(OSError):
        st = os.stat(real)
        return ("file", st.st_dev, st.st_ino)
    folder, name = os.path.split(real)
    with contextlib.suppress(OSError):
        st = os.stat(folder)
        return ("entry", st.st_dev, st.st_ino, name)
    return ("path", os.path.normcase(real))


def check_distinct(outputs: Sequence[Named], inputs: Iterable[Named]) -> None:
    """Refuse an output that is an input, or that another output also writes.

    Parameters
    ----------
    outputs : sequence of Named
        Every file the run will write.
    inputs : iterable of Named
        Every file the run reads.  Inputs that do not exist are skipped
        (their reader reports them).

    Raises
    ------
    OutputError
        Naming both options, e.g. ``--out 'a.png' is the same file as
        --depth 'a.png': inputs are never overwritten; choose another --out``.
    """
    read: dict[tuple, Named] = {}
    for source in inputs:
        if os.path.exists(source.path):
            read.setdefault(_identity(source.path), source)
    written: dict[tuple, Named] = {}
    for target in outputs:
        key = _identity(target.path)
        if key in read:
            raise OutputError(f"{target.label} is the same file as {read[key].label}: inputs are never "
                              f"overwritten; choose another {target.flag}")
        if key in written:
            raise OutputError(f"{written[key].label} and {target.label} are the same file: every output "
                              f"needs a path of its own; choose another {target.flag}")
        written[key] = target


def _probe(folder: Path, target: Named) -> None:
    """Create and delete a temporary file in ``folder`` (permission bits say nothing to root)."""
    try:
        os.unlink(create_temporary(folder / target.path.name, "probe"))
    except OSError as exc:
        raise OutputError(f"{target.label}: cannot create a file in folder '{folder}' "
                          f"({exc.strerror or type(exc).__name__}); choose another {target.flag}") from None


def check_writable(outputs: Sequence[Named]) -> None:
    """Prove that every output can be created, by creating (and deleting) a file beside it.

    Parameters
    ----------
    outputs : sequence of Named
        With ``create_parent``, a missing folder is acceptable if its nearest
        existing ancestor is a writable folder.

    Raises
    ------
    OutputError
        If an output is a directory, its folder is missing or not a folder,
        or a file cannot be created there.  One line naming the option.
    """
    probed: set[tuple] = set()
    for target in outputs:
        if target.path.is_dir():
            raise OutputError(f"{target.label} is a directory; give a file name for {target.flag}")
        folder = target.path.parent
        if not folder.is_dir():
            if folder.exists() or os.path.islink(folder):
                raise OutputError(f"{target.label}: '{folder}' is not a folder; choose another {target.flag}")
            if not target.create_parent:
                raise OutputError(f"{target.label}: folder '{folder}' does not exist; create it or choose "
                                  f"another {target.flag}")
            while not folder.exists() and folder != folder.parent:
                if os.path.islink(folder):  # a dangling symbolic link in the way
                    break
                folder = folder.parent
            if not folder.is_dir():
                raise OutputError(f"{target.label}: '{folder}' is not a folder; choose another {target.flag}")
        key = _identity(folder)
        if key not in probed:
            _probe(folder, target)
            probed.add(key)


def _make_folders(folder: Path) -> list[Path]:
    """Create ``folder`` and its missing parents; return the ones created, outermost first."""
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    created = []
    for path in reversed(missing):
        path.mkdir()
        created.append(path)
    return created


def _keep_old(path: Path) -> tuple[bool, Path | None]:
    """(whether ``path`` exists, a hard link to it to put it back or None if links fail)."""
    if not os.path.lexists(path):
        return False, None
    backup = path.parent / f".{path.name}.{secrets.token_hex(6)}.old{path.suffix}"
    try:
        os.link(path, backup, follow_symlinks=False)
    except (OSError, NotImplementedError):
        return True, None
    return True, backup


def commit(items: Sequence[tuple[Named, Callable[[Path], None]]]) -> None:
    """Write every output, or none.

    Parameters
    ----------
    items : sequence of (Named, writer)
        ``writer(tmp)`` writes the output's content to the file ``tmp``
        (created empty beforehand, in the output's folder, with the output's
        extension).

    Raises
    ------
    OutputError
        A writer or a rename failed with an :class:`OSError`: the message
        names the option.  Other exceptions of a writer propagate as they are.
        Either way, nothing is left behind.

    Notes
    -----
    Three steps: (1) each output is written to a new temporary file beside
    its target (missing folders of ``create_parent`` outputs are created
    first); (2) a hard link keeps every file already at a target path;
    (3) the temporary files replace their targets with :func:`os.replace`.
    If anything fails, the targets already replaced get their old file back
    (or are removed if they had none), and the temporary files, the links
    and the folders created are removed, so the file system is as before.
    On file systems without hard links an old file cannot be put back after
    a failure of step (3); steps (1) and (2) never touch a target.
    """
    created: list[Path] = []
    staged: list[tuple[Named, Path]] = []
    kept: dict[Path, tuple[bool, Path | None]] = {}
    replaced: list[Named] = []
    current: Named | None = None
    try:
        try:
            for target, writer in items:
                current = target
                if target.create_parent:
                    created += _make_folders(target.path.parent)
                tmp = create_temporary(target.path)
                staged.append((target, tmp))
                writer(tmp)
            for target, tmp in staged:
                current = target
                fsync(tmp)
                kept[target.path] = _keep_old(target.path)
            for target, tmp in staged:
                current = target
                os.replace(tmp, target.path)
                replaced.append(target)
        except OSError as exc:
            label = current.label if current is not None else "output"
            flag = current.flag if current is not None else "output"
            raise OutputError(f"{label}: could not be written ({exc.strerror or one_line(exc)}); nothing "
                              f"was written; choose another {flag}") from exc
    except BaseException:
        _roll_back(created, staged, kept, replaced)
        raise
    for _, backup in kept.values():
        if backup is not None:
            with contextlib.suppress(OSError):
                os.unlink(backup)




def _roll_back(created, staged, kept, replaced) -> None:
    done = {id(target) for target in replaced}
    for target in reversed(replaced):
        existed, backup = kept[target.path]
        with contextlib.suppress(OSError):
            if backup is not None:
                os.replace(backup, target.path)
            elif not existed:
                os.unlink(target.path)
    for target, tmp in staged:
        if id(target) not in done:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
    for _, backup in kept.values():
        if backup is not None and os.path.lexists(backup):
            with contextlib.suppress(OSError):
                os.unlink(backup)
    for folder in reversed(created):
        with contextlib.suppress(OSError):
            folder.rmdir()
