"""The table of file formats (sparsedepth.io.formats): every list of extensions says what the table says."""

import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.batch import BatchOptions, find_frame_pairs, find_frames
from sparsedepth.batch import frames as batch_frames
from sparsedepth.cli import checks as cli_checks
from sparsedepth.cli.parser import build_parser
from sparsedepth.io import formats
from sparsedepth.io.formats import FORMATS
from sparsedepth.io.writing import write_uncertainty

DEPTH = np.array([[1.5, np.nan, 2.25], [0.75, 3.0, 1.125]])  # exact in float32 and in millimetres
IMAGE = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)


def _extensions(test):
    return {ext for fmt in FORMATS if test(fmt) for ext in fmt.extensions}


def _action(parser, flag):
    return next(a for a in parser._actions if flag in a.option_strings)


def test_a_batch_finds_a_frame_pair_in_every_depth_format_write_depth_writes(tmp_path):
    written = _extensions(lambda f: f.write is not None)
    assert {".png", ".tif", ".tiff", ".pfm", ".npy", ".npz", ".h5", ".hdf5"} <= written
    for ext in sorted(written):
        images, depths, flat = (tmp_path / ext[1:] / sub for sub in ("images", "depths", "flat"))
        for folder in (images, depths, flat):
            folder.mkdir(parents=True)
        iio.imwrite(images / "0001.png", IMAGE)
        iio.imwrite(flat / "rgb_0001.png", IMAGE)
        sd.write_depth(depths / f"0001{ext}", DEPTH, scale=1000)
        sd.write_depth(flat / f"depth_0001{ext}", DEPTH, scale=1000)
        scale = "mm" if ext == ".png" else None
        (pair,) = find_frame_pairs(images, depths)
        assert pair.depth == str(depths / f"0001{ext}"), ext
        (frame,) = find_frames(flat)
        assert frame.depth == str(flat / f"depth_0001{ext}"), ext
        np.testing.assert_array_equal(sd.read_depth(pair.depth, scale=scale), DEPTH)


def test_every_list_of_extensions_is_the_table_s():
    images = _extensions(lambda f: f.read_image is not None)
    depths = _extensions(lambda f: f.read_depth is not None)
    outs = _extensions(lambda f: f.out)
    assert set(formats.IMAGE_EXTENSIONS) == images
    assert set(formats.DEPTH_EXTENSIONS) == depths
    assert set(formats.MASK_EXTENSIONS) == images | _extensions(lambda f: f.read_mask is not None)
    assert set(formats.WRITE_EXTENSIONS) == _extensions(lambda f: f.write is not None)
    # a batch discovers every depth format and every image format
    assert set(batch_frames._DEPTH_EXTENSIONS) == _extensions(lambda f: f.discovered) == depths
    assert set(batch_frames._IMAGE_EXTENSIONS) == images
    # the command line: --out / --uncertainty, and a batch's --out-format and out_format
    assert set(cli_checks._OUT_EXTENSIONS) == outs
    parser = build_parser()
    choices = _action(parser, "--out-format").choices
    assert sorted(f".{c}" for c in choices) == sorted(fmt.extensions[0] for fmt in FORMATS if fmt.out)
    assert _action(parser, "--out-format").default in choices
    for ext in sorted(outs | {".jpg", ".pgm", ".txt"}):
        if ext in outs:
            assert BatchOptions(out_format=ext).out_format == ext
        else:
            with pytest.raises(ValueError, match="out_format"):
                BatchOptions(out_format=ext)
    # every format's extensions are lower case, with their dot, and belong to it alone
    every = [ext for fmt in FORMATS for ext in fmt.extensions]
    assert len(every) == len(set(every)) and all(e.startswith(".") and e == e.lower() for e in every)
    assert all(fmt.name == fmt.extensions[0][1:] for fmt in FORMATS)


def test_the_readers_and_writers_follow_the_table(tmp_path):
    written = _extensions(lambda f: f.write is not None)
    for ext in sorted(_extensions(lambda f: True) | {".gif", ".exr"}):
        path = tmp_path / f"d{ext}"
        if ext in written:
            sd.write_depth(path, DEPTH, scale=1000)
            write_uncertainty(tmp_path / f"s{ext}", DEPTH, scale=1000)
            np.testing.assert_array_equal(sd.read_depth(path, scale="mm" if ext == ".png" else None), DEPTH)
        else:
            with pytest.raises(ValueError, match="unsupported extension"):
                sd.write_depth(path, DEPTH)
            with pytest.raises(ValueError, match="unsupported extension"):
                write_uncertainty(path, DEPTH)
            path.write_bytes(b"not an image")
        for reader, extensions in ((sd.read_depth, formats.DEPTH_EXTENSIONS), (sd.read_image, formats.IMAGE_EXTENSIONS),
                                   (sd.io.read_mask, formats.MASK_EXTENSIONS)):
            if ext not in extensions:
                with pytest.raises(ValueError, match="unsupported extension"):
                    reader(path)
