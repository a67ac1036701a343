"""Images: PNG, JPEG, BMP and TIFF through Pillow, imageio and tifffile, Netpbm through :mod:`.netpbm`.

What lives here: the image readers of the formats of :mod:`.formats`
(Pillow, Netpbm, TIFF; each returns the grey or colour samples as stored, 8
or 16 bit), the TIFF reader that keeps 16-bit and float32 samples, the depth
reader of TIFFs (:func:`read_tiff_depth`) and the PNG and TIFF writers
(:func:`png_writer`, :func:`tiff_writer`).  Every size is checked against the
pixel limit from the header before decoding.  :func:`sparsedepth.io.read_image`,
which picks the reader by the table, lives in :mod:`.formats`.

Imports NumPy, Pillow, imageio, tifffile and :mod:`.files` / :mod:`.netpbm` only.
"""

from __future__ import annotations

import warnings
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

import imageio.v3 as iio
import numpy as np
import tifffile
from PIL import Image

from .files import as_value_error, check_pixels, decode_error, file_label, option_labels, suffix
from .netpbm import read_netpbm

__all__ = ["png_writer", "read_netpbm_image", "read_pillow_image",
           "read_tiff", "read_tiff_depth", "read_tiff_image", "tiff_writer",
           "write_png_file", "write_tiff_file"]

_FLOAT32_MAX = float(np.finfo(np.float32).max)


def normalise_image(image: np.ndarray, where: str) -> np.ndarray:
    """Decoded samples as contiguous (H, W) or (H, W, 3) uint8/uint16: 1-bit to 0/255, grey+alpha and RGBA lose alpha."""
    if image.dtype == bool:  # 1-bit images: black 0, white 255
        image = image.astype(np.uint8) * np.uint8(255)
    if image.dtype not in (np.uint8, np.uint16):
        raise ValueError(
            f"{where} decodes to dtype {image.dtype}; only 1-, 8- and 16-bit images are supported."
        )
    if image.ndim == 3 and image.shape[2] in (1, 2):  # grey (+ alpha)
        image = image[:, :, 0]
    elif image.ndim == 3 and image.shape[2] == 4:  # RGBA
        image = image[:, :, :3]
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
        raise ValueError(
            f"{where} decodes to shape {image.shape}; expected a single (H, W) grey "
            "or (H, W, 3) colour image."
        )
    if image.size == 0:
        raise ValueError(f"{where} decodes to an empty image (shape {image.shape}).")
    return np.ascontiguousarray(image)


def _png_declared_size(path: Path, where: str) -> tuple[int, int] | None:
    """(height, width) from a PNG's IHDR chunk, or None if the file does not start like a PNG."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(24)
    except OSError as exc:
        raise ValueError(f"{where}: cannot be read ({exc}).") from None
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    width, height = int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    return height, width


def _read_pillow(path: Path, max_pixels: int | None, where: str, label: str) -> np.ndarray:
    """Decode with Pillow after checking the declared size (PNG IHDR, else a lazy open)."""
    if suffix(path) == ".png":
        declared = _png_declared_size(path, where)
        if declared is not None:
            check_pixels(*declared, max_pixels, where, label)
    with warnings.catch_warnings():
        # the pixel limit is ours; Pillow's own bomb warning would only repeat it
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            with Image.open(path) as handle:
                width, height = handle.size
        except Image.DecompressionBombError as exc:
            raise ValueError(
                f"{where}: declares more pixels than Pillow decodes ({exc}); "
                "Pillow's limit is PIL.Image.MAX_IMAGE_PIXELS."
            ) from None
        except MemoryError:
            raise
        except Exception as exc:  # Pillow raises many types on junk (SyntaxError, struct.error, ...)
            raise decode_error(where, exc) from exc
        check_pixels(height, width, max_pixels, where, label)
        with as_value_error(where, decode_error):
            return np.asarray(iio.imread(path, plugin="pillow"))


@contextmanager
def _tiff_of_one_image(path: Path, where: str) -> Iterator[tifffile.TiffFile]:
    """The open TIFF, refused when it holds several full-size pages (a stack); reduced previews are allowed."""
    with as_value_error(where, decode_error):
        handle = tifffile.TiffFile(path)
    with handle:
        with as_value_error(where, decode_error):
            images = 1 + sum(1 for page in handle.pages[1:] if not page.is_reduced)
        if images > 1:
            raise ValueError(f"{where} is a TIFF of {images} images (pages); save the one to use as a file of its "
                             "own.")
        yield handle


def read_tiff(path: Path, max_pixels: int | None, where: str, label: str) -> np.ndarray:
    """The one image of a TIFF with tifffile (keeps 16-bit and float32 samples).

    Reduced-resolution pages (previews, pyramid levels) after the first are
    ignored; a file of several full images (a stack) is refused, since which
    of them to complete cannot be guessed.
    """
    with _tiff_of_one_image(path, where) as handle:
        with as_value_error(where, decode_error):
            page = handle.pages[0]
            shape = tuple(int(n) for n in page.shape)
        if len(shape) < 2:
            raise ValueError(f"{where}: TIFF page has shape {shape}, expected (H, W) or (H, W, C).")
        check_pixels(shape[0], shape[1], max_pixels, where, label)
        with as_value_error(where, decode_error):
            return np.asarray(page.asarray())


def read_pillow_image(path: Path, byteorder, max_pixels: int | None, where: str,
                      label: Callable[[str], str]) -> np.ndarray:
    """The image reader of PNG, JPEG and BMP (Pillow); ``byteorder`` does not apply."""
    return _read_pillow(path, max_pixels, where, label("max_pixels"))


def read_netpbm_image(path: Path, byteorder, max_pixels: int | None, where: str,
                      label: Callable[[str], str]) -> np.ndarray:
    """The image reader of Netpbm files (:mod:`.netpbm`)."""
    return read_netpbm(path, byteorder, max_pixels, where, label)


def read_tiff_image(path: Path, byteorder, max_pixels: int | None, where: str,
                    label: Callable[[str], str]) -> np.ndarray:
    """The image reader of TIFFs: Pillow, after refusing a stack of full-size pages."""
    with _tiff_of_one_image(path, where):  # Pillow decodes the first page whatever follows it
        pass
    return _read_pillow(path, max_pixels, where, label("max_pixels"))


def read_tiff_depth(path: Path, key, byteorder, max_pixels, name: str, option_names) -> tuple[np.ndarray, str]:
    """The depth reader of TIFFs: the samples of the one single-channel image (16-bit or float32) and their source."""
    where = file_label(path, name)
    stored = read_tiff(path, max_pixels, where, option_labels(option_names)("max_pixels"))
    if stored.ndim == 3 and stored.shape[2] == 1:
        stored = stored[:, :, 0]
    if stored.ndim != 2:
        raise ValueError(f"{where} has shape {stored.shape}; a depth TIFF must be single-channel.")
    return stored, where


def write_png_file(path: Path, stored: np.ndarray) -> None:
    """Write uint16 samples to ``path`` as a 16-bit grey PNG."""
    iio.imwrite(path, stored, plugin="pillow", extension=".png")


def png_writer(stored: np.ndarray, name: str) -> Callable[[Path], None]:
    """The writer of the PNG format: ``stored`` is the uint16 map (:mod:`.writing` quantises it)."""
    return lambda tmp: write_png_file(tmp, stored)


def write_tiff_file(path: Path, values: np.ndarray) -> None:
    """Write float32 samples to ``path`` as one uncompressed ``minisblack`` TIFF page."""
    tifffile.imwrite(path, values, photometric="minisblack", metadata=None)


def tiff_writer(values: np.ndarray, name: str) -> Callable[[Path], None]:
    """The writer of the TIFF format: float64 ``values`` (NaN where missing) stored as float32.

    Raises ``ValueError`` naming ``name`` if a finite value exceeds the float32 range.
    """
    finite = values[np.isfinite(values)]
    if finite.size and finite.max() > _FLOAT32_MAX:
        raise ValueError(f"`{name}` up to {finite.max():g} exceeds the float32 range of a TIFF; "
                         "use .npy, .npz or .h5 (float64).")
    single = values.astype(np.float32)
    return lambda tmp: write_tiff_file(tmp, single)
