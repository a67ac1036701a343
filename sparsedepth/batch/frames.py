"""Frames of a batch: the frame types and their discovery on disk.

A frame names its files (:class:`FileFrame`), one frame of an NYU Depth V2
labeled ``.mat`` (:class:`NYUFrame`) or one preprocessed NYU ``.h5`` file
(:class:`NYUH5Frame`); nothing is read until a worker runs it.
:func:`find_frames`, :func:`find_frame_pairs`, :func:`nyu_h5_frames` and
:func:`nyu_frames` build them from a folder or a file;
:func:`absolute_frame` makes their paths absolute before they are sent to
another process.

Imports the standard library, :mod:`sparsedepth._validation` and
:mod:`sparsedepth.io`.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path

from .._validation import check_folder, check_index
from ..io import NYUDepthV2Labeled
from ..io.formats import DISCOVERED_DEPTH_EXTENSIONS, DISCOVERED_IMAGE_EXTENSIONS

__all__ = ["FileFrame", "NYUFrame", "NYUH5Frame", "find_frames", "find_frame_pairs", "nyu_h5_frames", "nyu_frames",
           "absolute_frame"]

#: The files a batch discovers (the table of :mod:`sparsedepth.io.formats`): every depth format that
#: :func:`~sparsedepth.io.read_depth` reads, and every image format.
_DEPTH_EXTENSIONS = DISCOVERED_DEPTH_EXTENSIONS
_IMAGE_EXTENSIONS = DISCOVERED_IMAGE_EXTENSIONS


@dataclass(frozen=True)
class FileFrame:
    """One frame stored as files.

    ``depth`` is None when no depth file was found for the image (the frame
    is then reported as failed); ``truth`` is an optional ground-truth depth.
    ``problem`` says why the frame cannot be completed when its files could
    not be paired (several images of one name, no or several depth files,
    several truth files); the batch reports it as the frame's error.
    """

    name: str
    image: str
    depth: str | None
    truth: str | None = None
    problem: str | None = None


@dataclass(frozen=True)
class NYUFrame:
    """Frame ``index`` of an NYU Depth V2 labeled ``.mat`` (read lazily in the worker)."""

    name: str
    path: str
    index: int


@dataclass(frozen=True)
class NYUH5Frame:
    """One preprocessed NYU Depth V2 ``.h5`` file (``rgb`` + ``depth``, see :func:`~sparsedepth.io.read_nyu_h5`)."""

    name: str
    path: str


_SHOWN = 5  # file names quoted in a "found nothing" error


def _some_names(paths) -> str:
    names = sorted(p.name for p in paths)
    if not names:
        return "no file"
    more = f" and {len(names) - _SHOWN} more" if len(names) > _SHOWN else ""
    return ", ".join(names[:_SHOWN]) + more


def _stem_map(folder: Path, prefix: str, extensions) -> dict[str, list[Path]]:
    found: dict[str, list[Path]] = {}
    for path in folder.iterdir():
        if path.is_file() and path.name.startswith(prefix) and path.suffix.lower() in extensions:
            found.setdefault(path.stem[len(prefix):], []).append(path)
    return found


def _paired(name: str, images: list[Path], depths: list[Path], truths: list[Path]) -> FileFrame:
    """The frame ``name`` of its candidate files; ``depth`` None and ``problem`` set unless they pair up."""
    images, depths, truths = sorted(images), sorted(depths), sorted(truths)
    image = str(images[0])
    if len(images) > 1:
        problem = f"several images are named '{name}' ({_some_names(images)}); keep one"
    elif not depths:
        problem = f"no depth file for image '{image}'"
    elif len(depths) > 1:
        problem = f"several depth files for image '{image}' ({_some_names(depths)}); keep one"
    elif len(truths) > 1:
        problem = f"several ground-truth files for image '{image}' ({_some_names(truths)}); keep one"
    else:
        return FileFrame(name=name, image=image, depth=str(depths[0]), truth=str(truths[0]) if truths else None)
    return FileFrame(name=name, image=image, depth=None, problem=problem)


def _files(folder: Path, extensions) -> list[Path]:
    return [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in extensions]


def find_frames(folder, *, image_prefix: str = "rgb_", depth_prefix: str = "depth_",
                truth_prefix: str | None = None) -> list[FileFrame]:
    """Pair the images and depth maps of a folder by name.

    The convention is ``<image_prefix><id>.<image ext>`` with
    ``<depth_prefix><id>.<depth ext>`` (and, optionally,
    ``<truth_prefix><id>.<depth ext>``): by default ``rgb_0001.png`` goes
    with ``depth_0001.png`` (the KITTI/Metric3D demo layout; use
    ``depth_prefix="sync_depth_"`` for the BTS NYU layout).  Images are the
    files of every image format, depth (and truth) files those of every
    depth format (:data:`sparsedepth.io.formats.DISCOVERED_IMAGE_EXTENSIONS`
    and :data:`~sparsedepth.io.formats.DISCOVERED_DEPTH_EXTENSIONS`: whatever
    :func:`~sparsedepth.io.write_depth` writes is found).  Frames are sorted by id.  For an image folder and a
    depth folder holding the same file names see :func:`find_frame_pairs`;
    for a folder of NYU ``.h5`` files see :func:`nyu_h5_frames`.

    Parameters
    ----------
    folder : str or os.PathLike
    image_prefix, depth_prefix : str
        Non-empty, different file-name prefixes.
    truth_prefix : str, optional
        Prefix of ground-truth depth files (e.g. inpainted depth for a raw
        ``depth``).

    Returns
    -------
    list of FileFrame
        One per image.  An image with no depth file (or several candidates)
        still gets an entry with ``depth=None``, so that the batch reports it
        as a failed frame instead of silently dropping it.

    Raises
    ------
    FileNotFoundError
        If ``folder`` is not a directory.
    ValueError
        If the prefixes are empty or equal, no image matches
        ``image_prefix``, or no image has a depth partner (the message lists
        a few of the files found, so that the right prefix can be given).
    """
    folder = check_folder(folder, "batch folder")
    prefixes = [p for p in (image_prefix, depth_prefix, truth_prefix) if p is not None]
    if any(not p for p in prefixes) or len(set(prefixes)) != len(prefixes):
        raise ValueError(f"file-name prefixes must be non-empty and different, got {prefixes}")
    images = _stem_map(folder, image_prefix, _IMAGE_EXTENSIONS)
    if not images:
        raise ValueError(
            f"no image named '{image_prefix}<id>.<ext>' in '{folder}' "
            f"(extensions {', '.join(_IMAGE_EXTENSIONS)}); found {_some_names(_files(folder, _IMAGE_EXTENSIONS))}: "
            "give the prefix the images share as image_prefix (command line: --image-prefix)"
        )
    depths = _stem_map(folder, depth_prefix, _DEPTH_EXTENSIONS)
    if not set(images) & set(depths):
        candidates = [p for p in _files(folder, _DEPTH_EXTENSIONS) if not p.name.startswith(image_prefix)]
        raise ValueError(
            f"no depth file named '{depth_prefix}<id>.<ext>' matches an image '{image_prefix}<id>' in '{folder}'; "
            f"found {_some_names(candidates)}: give the prefix the depth files share as depth_prefix "
            "(command line: --depth-prefix)"
        )
    truths = _stem_map(folder, truth_prefix, _DEPTH_EXTENSIONS) if truth_prefix else {}
    return [_paired(key, images[key], depths.get(key, []), truths.get(key, [])) for key in sorted(images)]


def find_frame_pairs(image_folder, depth_folder, *, truth_folder=None) -> list[FileFrame]:
    """Pair an image folder with a depth folder holding the same file names (the KITTI layout).

    KITTI depth keeps ``image_02/data/0000000005.png`` beside
    ``proj_depth/groundtruth/image_02/0000000005.png``: an image and its depth
    have the same name (the extensions may differ).  Frames are named by that
    stem and sorted.

    Parameters
    ----------
    image_folder, depth_folder : str or os.PathLike
        Folders of images and of depth files (extensions as :func:`find_frames`).
    truth_folder : str or os.PathLike, optional
        Folder of ground-truth depth files with the same names.

    Returns
    -------
    list of FileFrame
        One per image; ``depth`` (or ``truth``) is None where the folder has
        no unique file of that stem (the batch reports such a frame as failed).

    Raises
    ------
    FileNotFoundError
        If a folder does not exist.
    ValueError
        If ``image_folder`` holds no image, or no image has a depth file of
        the same name (the message lists a few names of each folder).
    """
    image_folder = check_folder(image_folder, "image folder")
    depth_folder = check_folder(depth_folder, "depth folder")
    images = _stem_map(image_folder, "", _IMAGE_EXTENSIONS)
    if not images:
        raise ValueError(f"no image ({', '.join(_IMAGE_EXTENSIONS)}) in image folder '{image_folder}'")
    depths = _stem_map(depth_folder, "", _DEPTH_EXTENSIONS)
    if not set(images) & set(depths):
        raise ValueError(
            f"no depth file in '{depth_folder}' has the name of an image in '{image_folder}': images "
            f"{_some_names(_files(image_folder, _IMAGE_EXTENSIONS))}; depth files "
            f"{_some_names(_files(depth_folder, _DEPTH_EXTENSIONS))}"
        )
    truths = {}
    if truth_folder is not None:
        truths = _stem_map(check_folder(truth_folder, "truth folder"), "", _DEPTH_EXTENSIONS)
    return [_paired(key, images[key], depths.get(key, []), truths.get(key, [])) for key in sorted(images)]


def nyu_h5_frames(folder) -> list[NYUH5Frame]:
    """The ``.h5`` / ``.hdf5`` files under ``folder`` (searched recursively), one frame each.

    This is the preprocessed NYU Depth V2 layout of most depth-completion code
    (``nyudepthv2/val/official/00001.h5``: ``rgb`` (3, H, W) uint8 and
    ``depth`` (H, W) metres, read by :func:`~sparsedepth.io.read_nyu_h5`).
    A frame is named by its path relative to ``folder`` without the
    extension, folders joined by ``_``.

    Raises
    ------
    FileNotFoundError
        If ``folder`` is not a directory.
    ValueError
        If it holds no ``.h5`` file, or two files get the same name.
    """
    folder = check_folder(folder, "h5 folder")
    paths = sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix.lower() in (".h5", ".hdf5"))
    if not paths:
        raise ValueError(f"no .h5 or .hdf5 file under '{folder}'; found {_some_names(p for p in folder.iterdir() if p.is_file())}")
    frames, seen = [], {}
    for path in paths:
        name = "_".join(path.relative_to(folder).with_suffix("").parts)
        if name in seen:
            raise ValueError(f"'{seen[name]}' and '{path}' both give the frame name '{name}'")
        seen[name] = path
        frames.append(NYUH5Frame(name=name, path=str(path)))
    return frames


def nyu_frames(path, indices=None) -> list[NYUFrame]:
    """Frames of an NYU Depth V2 labeled ``.mat`` (checked once, read later, lazily).

    Parameters
    ----------
    path : str or os.PathLike
        ``nyu_depth_v2_labeled.mat`` or an HDF5 file with the same layout
        (see :class:`~sparsedepth.io.NYUDepthV2Labeled`).
    indices : iterable of int or slice, optional
        Frame indices (negative count from the end); default all frames.

    Returns
    -------
    list of NYUFrame

    Raises
    ------
    FileNotFoundError, ValueError
        As :class:`~sparsedepth.io.NYUDepthV2Labeled`.
    IndexError
        An index out of range.
    """
    with NYUDepthV2Labeled(path) as nyu:
        n = len(nyu)
        if indices is None:
            chosen = range(n)
        elif isinstance(indices, slice):
            chosen = range(n)[indices]
        else:
            chosen = [check_index(i, n) for i in indices]
        if len(chosen) == 0:
            raise ValueError(f"no frame selected from '{path}' ({n} frames)")
        return [NYUFrame(name=f"nyu_{i:04d}", path=str(nyu.path), index=int(i)) for i in chosen]


def absolute_frame(source):
    """The frame with absolute paths (a worker may run in another working directory).

    Parameters
    ----------
    source : FileFrame, NYUFrame or NYUH5Frame

    Returns
    -------
    FileFrame, NYUFrame or NYUH5Frame
        A new frame of the same type, its paths resolved in this process's
        directory; ``source`` is not modified.

    Raises
    ------
    TypeError
        For any other object.
    """
    if isinstance(source, FileFrame):
        return dataclasses.replace(
            source, image=os.path.abspath(source.image),
            depth=None if source.depth is None else os.path.abspath(source.depth),
            truth=None if source.truth is None else os.path.abspath(source.truth),
        )
    if isinstance(source, (NYUFrame, NYUH5Frame)):
        return dataclasses.replace(source, path=os.path.abspath(source.path))
    raise TypeError(
        f"frames must be FileFrame, NYUFrame or NYUH5Frame objects, got {type(source).__name__}; "
        "build them with find_frames, find_frame_pairs, nyu_frames or nyu_h5_frames"
    )

