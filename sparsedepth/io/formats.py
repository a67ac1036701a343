"""The file formats: one table (:data:`FORMATS`) from which every list of extensions is derived.

Each :class:`FileFormat` says which extensions it has, what it can hold (an
image, depth, a mask, the uncertainty map), the functions that read and write
it, whether a batch discovers depth files of it, and whether ``--out`` (and
``--uncertainty``, a batch's ``--out-format``) accepts it.  The readers
(:func:`~sparsedepth.io.read_image`, :func:`~sparsedepth.io.read_depth`,
:func:`~sparsedepth.io.read_mask`), the writers
(:func:`~sparsedepth.io.write_depth`, :func:`~sparsedepth.io.write_uncertainty`),
the batch's file discovery (:mod:`sparsedepth.batch.frames`), the batch
options and the command line's choices, checks and help all take their
extensions from here.

A new file format is one entry of :data:`FORMATS` plus its reader/writer
module in :mod:`sparsedepth.io`, whose functions follow the signatures below
(:data:`ImageReader`, :data:`StoredReader`, :data:`MaskReader`,
:data:`Writer`); nothing else changes.

:func:`read_image` and :func:`read_depth_array`, which pick a reader by the
table, and the depth reader of grey images (:func:`read_grey_depth`) live
here too, so the format modules never look the table up.

Imports :mod:`.arrays`, :mod:`.images`, :mod:`.netpbm` and :mod:`.pfm` (the
readers and writers), :mod:`.files`, :mod:`.stored` and
:mod:`sparsedepth._validation` only.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from .._validation import check_input_file
from .arrays import (hdf5_writer, load_array, npy_writer, npz_writer, read_array_depth, read_array_mask,
                     read_hdf5_depth, read_hdf5_mask)
from .files import MAX_PIXELS, check_extension, check_max_pixels, file_label, option_labels
from .images import (normalise_image, png_writer, read_netpbm_image, read_pillow_image, read_tiff_depth,
                     read_tiff_image, tiff_writer)
from .netpbm import check_byteorder
from .stored import as_depth
from .pfm import pfm_writer, read_pfm_depth

__all__ = ["DEPTH_EXTENSIONS", "DISCOVERED_DEPTH_EXTENSIONS", "DISCOVERED_IMAGE_EXTENSIONS", "FORMATS",
           "FileFormat", "IMAGE_EXTENSIONS", "KEYED_EXTENSIONS", "MASK_EXTENSIONS", "NUMPY_EXTENSIONS",
           "OUT_EXTENSIONS", "OUT_FORMATS", "WRITE_EXTENSIONS", "extensions_of", "format_of", "read_image",
           "read_depth_array", "read_grey_depth", "read_single_channel"]

#: ``read(path, byteorder, max_pixels, where, label) -> samples``: the decoded (H, W) or (H, W, C) image as stored.
ImageReader = Callable[[Path, "str | None", "int | None", str, Callable[[str], str]], np.ndarray]
#: ``read(path, key, byteorder, max_pixels, name, option_names) -> (stored, source)``: the stored 2-D depth
#: samples and how messages name them.
StoredReader = Callable[[Path, "str | None", "str | None", "int | None", str, "Mapping[str, str] | None"],
                        "tuple[np.ndarray, str]"]
#: ``read(path, key, max_pixels, name, option_names) -> (array, source)``: a stored 2-D mask (bool allowed).
MaskReader = Callable[[Path, "str | None", "int | None", str, "Mapping[str, str] | None"], "tuple[np.ndarray, str]"]
#: ``writer(values, name) -> write(tmp)``: checks and encodes ``values`` (uint16 for an integer format, else
#: float64 with NaN where missing; ``name`` labels them in messages) and returns the function that writes them.
Writer = Callable[[np.ndarray, str], Callable[[Path], None]]


@dataclass(frozen=True)
class FileFormat:
    """One file format: its extensions, what it holds, its reader(s) and writer.

    Attributes
    ----------
    name : str
        Short name (the first extension without its dot; a batch's
        ``--out-format`` choice).
    extensions : tuple of str
        Lower-case extensions with their dot, the usual one first.
    read_image : ImageReader or None
        Reader of a grey or colour image (:func:`~sparsedepth.io.read_image`);
        None if the format holds no image.  Image formats also hold masks
        (non-zero = observed) and are the images a batch discovers.
    read_depth : StoredReader or None
        Reader of the stored depth samples (:func:`~sparsedepth.io.read_depth`);
        None if the format holds no depth.
    read_mask : MaskReader or None
        Reader of a stored mask array for a format that holds no image
        (:func:`~sparsedepth.io.read_mask`); image formats need none.
    write : Writer or None
        Writer of depth and uncertainty maps (:func:`~sparsedepth.io.write_depth`,
        :func:`~sparsedepth.io.write_uncertainty`); None if not written.
    integer : bool
        Written as 16-bit integers ``round(value * scale)``, 0 where missing
        (else as floats).
    float32 : bool
        Written as float32 (else float64, for a float format).
    keyed : bool
        Holds several named arrays, chosen with ``key=`` (``--depth-key``).
    discovered : bool
        A batch (:func:`~sparsedepth.batch.find_frames`,
        :func:`~sparsedepth.batch.find_frame_pairs`) finds depth files of it.
    out : bool
        ``--out``, ``--uncertainty`` and a batch's ``out_format`` accept it.
    stores : str
        What a written file holds, for help texts.
    """

    name: str
    extensions: tuple[str, ...]
    read_image: ImageReader | None = None
    read_depth: StoredReader | None = None
    read_mask: MaskReader | None = None
    write: Writer | None = None
    integer: bool = False
    float32: bool = False
    keyed: bool = False
    discovered: bool = False
    out: bool = False
    stores: str = ""

    @property
    def holds_image(self) -> bool:
        """:func:`~sparsedepth.io.read_image` reads it."""
        return self.read_image is not None

    @property
    def holds_depth(self) -> bool:
        """:func:`~sparsedepth.io.read_depth` reads it."""
        return self.read_depth is not None

    @property
    def holds_mask(self) -> bool:
        """:func:`~sparsedepth.io.read_mask` reads it (every image format, and stored mask arrays)."""
        return self.read_image is not None or self.read_mask is not None

    @property
    def holds_uncertainty(self) -> bool:
        """:func:`~sparsedepth.io.write_uncertainty` writes it (every format that depth is written in)."""
        return self.write is not None


def read_image(path, *, byteorder: str | None = None, max_pixels: int | None = MAX_PIXELS,
               name: str = "path", option_names: Mapping[str, str] | None = None) -> np.ndarray:
    """Read a grey or colour image as stored (8 or 16 bit).

    Parameters
    ----------
    path : str or os.PathLike
        Image file: PNG, JPEG, PPM/PGM/PNM (ASCII or binary), BMP or TIFF.
    byteorder : {None, 'big', 'little'}, optional
        Byte order of 16-bit binary Netpbm rasters.  The Netpbm standard is
        ``'big'``; some datasets (e.g. the NYU Depth V2 raw ``.pgm`` Kinect
        frames) store little-endian samples despite the header.  ``None``
        (default) reads big-endian but refuses a raster that looks
        byte-swapped (see Notes).  Ignored for other formats.
    max_pixels : int or None, optional
        Largest accepted ``height * width``, checked from the file header
        before decoding (default :data:`MAX_PIXELS`); None for no limit.
        Pillow's own limit ``PIL.Image.MAX_IMAGE_PIXELS`` (twice it, in fact)
        also applies to the formats Pillow decodes.
    name : str, optional
        Label of ``path`` in error messages (e.g. the command-line flag).
    option_names : mapping, optional
        Labels of the keywords in messages, e.g. ``{"byteorder": "--byteorder"}``.

    Returns
    -------
    image : (H, W) or (H, W, 3) ndarray of uint8 or uint16
        The decoded samples, unscaled.  An alpha channel is dropped; 1-bit
        images become uint8 0 (black) and 255 (white).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If ``path`` is not a regular file, the extension is not supported,
        the declared size exceeds ``max_pixels``, the file cannot be decoded,
        or it decodes to something other than a 1/8/16-bit grey or RGB image.
    TypeError
        If ``path`` is not a str or os.PathLike.

    Notes
    -----
    Byte-swap check (``byteorder=None``, 16-bit binary Netpbm of at least
    2x2 pixels): with :math:`V(x)` the mean absolute difference between
    vertical plus horizontal neighbours, the file is refused when
    :math:`4\\,V(\\mathrm{swap}(x)) < V(x)`.  Depth and photographs vary
    slowly, so swapping their bytes moves the noisy low byte into the high
    one and multiplies :math:`V` many times over.

    Examples
    --------
    >>> import numpy as np, imageio.v3 as iio, tempfile, os
    >>> fname = os.path.join(tempfile.mkdtemp(), "grey.png")
    >>> iio.imwrite(fname, np.array([[0, 1000]], dtype=np.uint16))
    >>> read_image(fname)
    array([[   0, 1000]], dtype=uint16)
    """
    label = option_labels(option_names)
    path = check_input_file(path, name=name)
    where = file_label(path, name)
    byteorder = check_byteorder(byteorder, label("byteorder"))
    max_pixels = check_max_pixels(max_pixels, label("max_pixels"))
    ext = check_extension(path, IMAGE_EXTENSIONS, "read image", name)
    image = format_of(ext).read_image(path, byteorder, max_pixels, where, label)
    return normalise_image(image, where)


def read_single_channel(path: Path, byteorder, max_pixels, name: str, option_names) -> np.ndarray:
    """Stored samples of a single-channel PNG/PGM depth image."""
    stored = read_image(path, byteorder=byteorder, max_pixels=max_pixels, name=name,
                        option_names=option_names)
    if stored.ndim != 2:
        raise ValueError(
            f"{file_label(path, name)} has shape {stored.shape}; a depth image must be single-channel "
            "(8- or 16-bit grey)."
        )
    return stored


def read_grey_depth(path: Path, key, byteorder, max_pixels, name: str, option_names) -> tuple[np.ndarray, str]:
    """The depth reader of grey images (PNG, PGM): the stored samples and their source."""
    return read_single_channel(path, byteorder, max_pixels, name, option_names), file_label(path, name)


def read_depth_array(path, *, key: str | None = None, max_pixels: int | None = MAX_PIXELS,
                     name: str = "path", option_names: Mapping[str, str] | None = None) -> np.ndarray:
    """Read a depth map stored with NumPy (``.npy`` or ``.npz``).

    Parameters
    ----------
    path : str or os.PathLike
        ``.npy`` file holding one (H, W) array, or ``.npz`` archive.
    key : str, optional
        Array name inside an ``.npz``.  If omitted, the archive's only array
        is used, or else the one called ``'depth'``.
    max_pixels : int or None, optional
        Largest accepted ``H * W``, checked from the array header before the
        data are read; default :data:`MAX_PIXELS`, None for no limit.
    name : str, optional
        Label of ``path`` in error messages.
    option_names : mapping, optional
        Labels of the keywords in messages, e.g. ``{"key": "--depth-key"}``.

    Returns
    -------
    depth : (H, W) ndarray of float64
        Stored values (no unit conversion: :func:`read_depth` requires a
        ``scale`` for integer arrays), with NaN where they are 0, inf or NaN.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If ``path`` is not a regular file, the file cannot be loaded
        (pickled objects are refused), ``key`` is missing or ambiguous, or
        the array is not a non-negative 2-D real array within ``max_pixels``.
    """
    label = option_labels(option_names)
    path = check_input_file(path, name=name)
    check_extension(path, NUMPY_EXTENSIONS, "read depth array", name)
    max_pixels = check_max_pixels(max_pixels, label("max_pixels"))
    stored, source = load_array(path, key, max_pixels, file_label(path, name), label)
    return as_depth(stored, source)


#: Every supported format.  The order is the order of the extensions in messages and help texts.
FORMATS: tuple[FileFormat, ...] = (
    FileFormat("png", (".png",), read_image=read_pillow_image, read_depth=read_grey_depth, write=png_writer,
               integer=True, discovered=True, out=True,
               stores="16-bit integers, depth x scale"),
    FileFormat("pgm", (".pgm", ".pnm"), read_image=read_netpbm_image, read_depth=read_grey_depth,
               discovered=True),
    FileFormat("ppm", (".ppm",), read_image=read_netpbm_image),
    FileFormat("pfm", (".pfm",), read_depth=read_pfm_depth, write=pfm_writer, float32=True, discovered=True,
               out=True, stores="float32 metres"),
    FileFormat("tif", (".tif", ".tiff"), read_image=read_tiff_image, read_depth=read_tiff_depth, write=tiff_writer,
               float32=True, discovered=True, out=True, stores="float32 metres"),
    FileFormat("npy", (".npy",), read_depth=read_array_depth, read_mask=read_array_mask, write=npy_writer,
               discovered=True, out=True, stores="float64 metres"),
    FileFormat("npz", (".npz",), read_depth=read_array_depth, read_mask=read_array_mask, write=npz_writer,
               keyed=True, discovered=True, out=True, stores="float64 metres, array 'depth'"),
    FileFormat("h5", (".h5", ".hdf5"), read_depth=read_hdf5_depth, read_mask=read_hdf5_mask, write=hdf5_writer,
               keyed=True, discovered=True, out=True, stores="float64 metres, dataset 'depth'"),
    FileFormat("jpg", (".jpg", ".jpeg"), read_image=read_pillow_image),
    FileFormat("bmp", (".bmp",), read_image=read_pillow_image),
)


def extensions_of(test: Callable[[FileFormat], bool]) -> tuple[str, ...]:
    """The extensions of the formats of :data:`FORMATS` for which ``test(format)`` is true, in table order."""
    return tuple(ext for fmt in FORMATS if test(fmt) for ext in fmt.extensions)


_BY_EXTENSION: Mapping[str, FileFormat] = {ext: fmt for fmt in FORMATS for ext in fmt.extensions}


def format_of(extension: str) -> FileFormat:
    """The format of a lower-case ``extension`` (with its dot); ``KeyError`` if there is none."""
    return _BY_EXTENSION[extension]


#: What :func:`~sparsedepth.io.read_image` reads.
IMAGE_EXTENSIONS = extensions_of(lambda f: f.holds_image)
#: What :func:`~sparsedepth.io.read_depth` reads.
DEPTH_EXTENSIONS = extensions_of(lambda f: f.holds_depth)
#: What :func:`~sparsedepth.io.read_mask` reads.
MASK_EXTENSIONS = extensions_of(lambda f: f.holds_mask)
#: Formats whose arrays have names (``key=``).
KEYED_EXTENSIONS = extensions_of(lambda f: f.keyed)
#: What :func:`~sparsedepth.io.read_depth_array` reads (NumPy files).
NUMPY_EXTENSIONS = extensions_of(lambda f: f.read_depth is read_array_depth)
#: What :func:`~sparsedepth.io.write_depth` and :func:`~sparsedepth.io.write_uncertainty` write.
WRITE_EXTENSIONS = extensions_of(lambda f: f.write is not None)
#: What ``--out`` and ``--uncertainty`` accept (and a batch's ``out_format``).
OUT_EXTENSIONS = extensions_of(lambda f: f.out)
#: The choices of a batch's ``--out-format``: the names of the ``out`` formats.
OUT_FORMATS = tuple(fmt.name for fmt in FORMATS if fmt.out)
#: The depth (and ground-truth) files a batch discovers.
DISCOVERED_DEPTH_EXTENSIONS = extensions_of(lambda f: f.discovered)
#: The images a batch discovers: every image format.
DISCOVERED_IMAGE_EXTENSIONS = IMAGE_EXTENSIONS
