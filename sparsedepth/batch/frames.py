"""Frames of a batch: the frame types and their discovery on disk.

A frame names its files (:class:`FileFrame`), one frame of an NYU Depth V2
labeled ``.mat`` (:class:`NYUFrame`), one preprocessed NYU ``.h5`` file
(:class:`NYUH5Frame`) or one registered image of a COLMAP model
(:class:`ColmapFrame`); nothing is read until a worker runs it.
:func:`find_frames`, :func:`find_frame_pairs`, :func:`nyu_h5_frames`,
:func:`nyu_frames` and :func:`colmap_frames` build them from a folder or a
file; :func:`absolute_frame` makes their paths absolute before they are sent
to another process.  For a COLMAP scene, :func:`unregistered_images` lists
the image files the model does not know, :func:`colmap_depth_range` the
range of the views' depths and :func:`png_depth_scale` a 16-bit PNG scale
that holds it.

Imports NumPy, the standard library, :mod:`sparsedepth._validation` and
:mod:`sparsedepth.io`.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np

from .._validation import check_folder, check_index
from ..io import ColmapModel, NYUDepthV2Labeled, read_colmap_model, view_depth
from ..io.formats import DISCOVERED_DEPTH_EXTENSIONS, DISCOVERED_IMAGE_EXTENSIONS

__all__ = ["FileFrame", "NYUFrame", "NYUH5Frame", "ColmapFrame", "find_frames", "find_frame_pairs", "nyu_h5_frames",
           "nyu_frames", "colmap_frames", "unregistered_images", "colmap_depth_range", "png_depth_scale",
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


@dataclass(frozen=True)
class ColmapFrame:
    """One registered image of a COLMAP model: its image file and the model's points it observes (read in the worker).

    ``name`` is the image's name in the model without its extension, its
    sub-folders kept (``"cam1/00"`` for ``cam1/00.jpg``): the outputs are
    ``<out_dir>/<name><out_format>``.  ``image_path`` is the file under the
    image folder; the worker reports a missing one as the frame's error.
    ``image_id`` is the model's ``IMAGE_ID`` of the view.
    """

    name: str
    model_dir: str
    image_path: str
    image_id: int


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


def _model(model_dir, model) -> tuple[Path, ColmapModel]:
    """(the model folder or None, the model read from it unless given)."""
    folder = None if model_dir is None else Path(model_dir)
    if model is None:
        model = read_colmap_model(folder, name="model_dir")
    elif not isinstance(model, ColmapModel):
        raise TypeError(f"model must be a ColmapModel (read_colmap_model) or None, got {type(model).__name__}")
    return folder, model


def _output_name(image_name: str) -> str:
    """The frame name of a model's image name: its path without the extension; ``ValueError`` for a name that
    would leave the output folder (absolute, or with a ``..`` part) or has no file name."""
    path = PurePosixPath(image_name.replace("\\", "/"))
    if path.is_absolute() or ".." in path.parts or not path.name or path.name in (".", ".."):
        raise ValueError(f"the COLMAP model names an image {image_name!r}, which is not a path inside the image "
                         "folder (absolute, or with a '..' part); such a view cannot be named in the output folder")
    return str(path.with_suffix("")) if path.suffix else str(path)


def colmap_frames(model_dir, images_dir, *, model: ColmapModel | None = None) -> list[ColmapFrame]:
    """One frame per registered image of a COLMAP model, its file under ``images_dir``.

    Parameters
    ----------
    model_dir : str or os.PathLike
        The model folder (``sparse/0``: ``cameras``, ``images`` and
        ``points3D``, ``.bin`` or ``.txt``).
    images_dir : str or os.PathLike
        The folder the model's image names are relative to (COLMAP's
        ``--image_path``).
    model : ColmapModel, optional
        The model of ``model_dir`` if already read; read here otherwise.

    Returns
    -------
    list of ColmapFrame
        Sorted by image name.  A registered image whose file is missing
        still gets a frame, so that the batch reports it as a failed row; an
        image file the model does not register gets none (see
        :func:`unregistered_images`).

    Raises
    ------
    FileNotFoundError
        If ``images_dir`` is not a folder, or the model folder is missing or
        incomplete.
    ValueError
        If the model is malformed (:func:`~sparsedepth.io.read_colmap_model`),
        registers no image, names an image outside ``images_dir`` (absolute,
        ``..``), or two of its images give the same output name
        (``a.jpg`` and ``a.png``).
    """
    images_dir = check_folder(images_dir, "image folder")
    folder, model = _model(model_dir, model)
    if not model.images:
        raise ValueError(f"the COLMAP model '{folder}' registers no image; nothing to complete")
    frames, seen = [], {}
    for image in sorted(model.images.values(), key=lambda view: view.name):
        name = _output_name(image.name)
        if name in seen:
            raise ValueError(f"the COLMAP model's images {seen[name]!r} and {image.name!r} would both write the "
                             f"output '{name}'; rename one of them")
        seen[name] = image.name
        frames.append(ColmapFrame(name=name, model_dir=str(folder), image_path=str(images_dir / image.name),
                                  image_id=int(image.id)))
    return frames


def unregistered_images(images_dir, model_dir=None, *, model: ColmapModel | None = None) -> list[str]:
    """The image files under ``images_dir`` (searched recursively) that no registered image of the model names.

    Parameters
    ----------
    images_dir : str or os.PathLike
    model_dir : str or os.PathLike, optional
        The model folder, read unless ``model`` is given.
    model : ColmapModel, optional

    Returns
    -------
    list of str
        Their paths relative to ``images_dir`` (``/``-separated), sorted;
        files of the image formats only
        (:data:`sparsedepth.io.formats.DISCOVERED_IMAGE_EXTENSIONS`).
    """
    images_dir = check_folder(images_dir, "image folder")
    if model is None and model_dir is None:
        raise ValueError("give the model folder or the model")
    _, model = _model(model_dir, model)
    registered = {PurePosixPath(image.name.replace("\\", "/")).as_posix() for image in model.images.values()}
    found = (p.relative_to(images_dir).as_posix() for p in images_dir.rglob("*")
             if p.is_file() and p.suffix.lower() in _IMAGE_EXTENSIONS)
    return sorted(name for name in found if name not in registered)


def colmap_depth_range(model_dir=None, *, model: ColmapModel | None = None, max_error=None,
                       min_track=None) -> tuple[float, float] | None:
    """(smallest, largest) depth of the model's points over all its views, as :func:`~sparsedepth.io.view_depth`
    places them (with the same ``max_error`` and ``min_track``); None if no view has a point.

    Depths are in the model's units.  This is the range every view's
    sparse input lies in, and (completion keeping each map within its
    observed range by default) the range of the completed maps.
    """
    if model is None and model_dir is None:
        raise ValueError("give the model folder or the model")
    _, model = _model(model_dir, model)
    low, high = math.inf, -math.inf
    for image_id in model.images:
        depth, mask, _ = view_depth(model, image_id, max_error=max_error, min_track=min_track)
        if mask.any():
            values = depth[mask]
            low, high = min(low, float(values.min())), max(high, float(values.max()))
    return None if high < low else (low, high)


#: The headroom of :func:`png_depth_scale`: depth up to this factor times the largest observed depth is storable.
PNG_HEADROOM = 1.05


def png_depth_scale(max_depth: float, *, headroom: float = PNG_HEADROOM) -> float:
    """A round 16-bit PNG scale (stored value = depth x scale) that stores depth up to ``headroom * max_depth``.

    Parameters
    ----------
    max_depth : float > 0
        The largest depth to store (e.g. :func:`colmap_depth_range`'s).
    headroom : float >= 1

    Returns
    -------
    float
        The largest number of the form :math:`m \\cdot 10^k`, :math:`m \\in \\{1, 2, 5\\}`,
        not above :math:`65535 / (\\mathrm{headroom} \\cdot \\mathrm{max\\_depth})`.

    Raises
    ------
    ValueError
        If ``max_depth`` is not a finite positive number or ``headroom < 1``.

    Notes
    -----
    A round scale keeps the file readable by hand (depth = value / 1000
    when the scale is 1000) at the cost of at most a factor 2.5 of the
    resolution the 16 bits could give; the quantisation step is
    :math:`1 / \\mathrm{scale}`, a relative step of at most
    :math:`2.5 \\cdot \\mathrm{headroom} / 65535 \\approx 4 \\cdot 10^{-5}` of
    ``max_depth``.

    Examples
    --------
    >>> png_depth_scale(38.3)  # 65535 / (1.05 * 38.3) = 1629.6
    1000.0
    >>> png_depth_scale(6.0)  # 10402.4
    10000.0
    >>> png_depth_scale(10.0)  # 6241.4
    5000.0
    """
    if not (isinstance(max_depth, (int, float, np.floating, np.integer)) and math.isfinite(max_depth)
            and max_depth > 0):
        raise ValueError(f"max_depth must be a finite number > 0, got {max_depth!r}")
    if not (isinstance(headroom, (int, float)) and math.isfinite(headroom) and headroom >= 1):
        raise ValueError(f"headroom must be a finite number >= 1, got {headroom!r}")
    limit = np.iinfo(np.uint16).max / (headroom * float(max_depth))
    exponent = math.floor(math.log10(limit))
    candidates = [float(f"{mantissa}e{exponent + shift}") for shift in (-1, 0) for mantissa in (1, 2, 5)]
    return max(scale for scale in candidates if scale <= limit)  # 5e(exponent-1) < 10**exponent <= limit


def absolute_frame(source):
    """The frame with absolute paths (a worker may run in another working directory).

    Parameters
    ----------
    source : FileFrame, NYUFrame, NYUH5Frame or ColmapFrame

    Returns
    -------
    FileFrame, NYUFrame, NYUH5Frame or ColmapFrame
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
    if isinstance(source, ColmapFrame):
        return dataclasses.replace(source, model_dir=os.path.abspath(source.model_dir),
                                   image_path=os.path.abspath(source.image_path))
    raise TypeError(
        f"frames must be FileFrame, NYUFrame, NYUH5Frame or ColmapFrame objects, got {type(source).__name__}; "
        "build them with find_frames, find_frame_pairs, nyu_frames, nyu_h5_frames or colmap_frames"
    )

