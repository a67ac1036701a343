"""Fuzzing every reader: random bytes, truncated and corrupted valid files, wrong dtypes and shapes.

A reader given a bad file raises ValueError (FileNotFoundError for a missing one), never another
exception; the command line answers with exit code 2 and one line on stderr.
"""

import contextlib
import io as _io
import os
import tempfile
import warnings
from pathlib import Path

import h5py
import imageio.v3 as iio
import numpy as np
import pytest
import tifffile
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from sparsedepth import io as sio
from sparsedepth.complete import main

EXAMPLES = int(os.environ.get("SPARSEDEPTH_FUZZ_EXAMPLES", "30"))  # raise it for a longer local run
FUZZ = settings(derandomize=True, deadline=None, max_examples=EXAMPLES,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
LIMIT = 1 << 16  # max_pixels while fuzzing: a corrupted header cannot make a reader allocate much


def _valid_files() -> dict:
    """name -> bytes of a small valid file of each format the readers accept."""
    rng = np.random.default_rng(0)
    grey16 = rng.integers(1, 5000, size=(6, 8)).astype(np.uint16)
    rgb = rng.integers(0, 256, size=(6, 8, 3)).astype(np.uint8)
    depth = rng.uniform(0.5, 5.0, size=(6, 8))
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        iio.imwrite(tmp / "grey16.png", grey16)
        iio.imwrite(tmp / "rgb.png", rgb)
        iio.imwrite(tmp / "rgb.jpg", rgb)
        iio.imwrite(tmp / "rgb.bmp", rgb)
        tifffile.imwrite(tmp / "grey16.tif", grey16)
        tifffile.imwrite(tmp / "float.tif", depth.astype(np.float32))
        sio.write_pfm(tmp / "depth.pfm", depth)
        np.save(tmp / "depth.npy", depth)
        np.savez(tmp / "depth.npz", depth=depth, other=grey16)
        with h5py.File(tmp / "depth.h5", "w") as f:
            f.create_dataset("depth", data=depth)
            f.create_dataset("rgb", data=np.transpose(rgb, (2, 0, 1)))
        with h5py.File(tmp / "labeled.mat", "w") as f:
            f.create_dataset("images", data=np.transpose(rgb, (2, 1, 0))[None])
            f.create_dataset("depths", data=depth.T[None].astype(np.float32))
        for path in tmp.iterdir():
            out[path.name] = path.read_bytes()
    out["grey16.pgm"] = b"P5\n8 6\n65535\n" + grey16.astype(">u2").tobytes()
    out["rgb.ppm"] = b"P6\n8 6\n255\n" + rgb.tobytes()
    out["ascii.pgm"] = b"P2\n8 6\n5000\n" + " ".join(map(str, grey16.ravel())).encode() + b"\n"
    out["calib.txt"] = b"cam0=[500 0 4; 0 500 3; 0 0 1]\ncam1=[500 0 4; 0 500 3; 0 0 1]\ndoffs=1\nbaseline=100\n"
    return out


VALID = _valid_files()

def image(p):
    return sio.read_image(p, max_pixels=LIMIT)


def depth(p):
    return sio.read_depth(p, scale=1, max_pixels=LIMIT)


def depth_png(p):
    return sio.read_depth_png(p, 1, max_pixels=LIMIT)


def mask(p):
    return sio.read_mask(p, key="depth" if Path(p).suffix in (".npz", ".h5") else None, max_pixels=LIMIT)


def pfm(p):
    return sio.read_pfm(p, max_pixels=LIMIT)


def array(p):
    return sio.read_depth_array(p, key="depth" if Path(p).suffix == ".npz" else None, max_pixels=LIMIT)


def nyu_h5(p):
    return sio.read_nyu_h5(p, max_pixels=LIMIT)


#: file -> the readers that accept it (every reader appears; each is fuzzed on its files)
READERS = {
    "grey16.png": [image, depth, depth_png],
    "rgb.png": [image, mask],
    "rgb.jpg": [image, mask],
    "rgb.bmp": [image],
    "grey16.tif": [image, depth],
    "float.tif": [depth],
    "grey16.pgm": [image, depth, depth_png],
    "ascii.pgm": [image, depth, depth_png],
    "rgb.ppm": [image],
    "depth.pfm": [pfm, depth],
    "depth.npy": [array, depth],
    "depth.npz": [array, depth],
    "depth.h5": [depth, nyu_h5],
    "labeled.mat": [lambda p: _first_labeled_frame(p)],
    "calib.txt": [sio.read_calib],
}


def _first_labeled_frame(path):
    with sio.NYUDepthV2Labeled(path) as nyu:
        return nyu[0]


def _mutations(data: bytes):
    """Random bytes, a truncation, or a few bytes overwritten (mostly in the header)."""
    n = len(data)
    head = min(n, 256)
    overwrite = st.lists(st.tuples(st.integers(0, head - 1) | st.integers(0, n - 1), st.integers(0, 255)),
                         min_size=1, max_size=6)
    return st.one_of(
        st.binary(max_size=600),
        st.integers(0, n - 1).map(lambda k: data[:k]),
        overwrite.map(lambda edits: _overwrite(data, edits)),
    )


def _overwrite(data, edits):
    buffer = bytearray(data)
    for position, value in edits:
        buffer[position] = value
    return bytes(buffer)


def _call(reader, path):
    """Run a reader; only ValueError may come out for a bad file."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # frequent-sensor-code warnings are allowed
        try:
            reader(path)
        except ValueError:
            pass


def test_every_valid_seed_file_is_read():
    """The seeds are valid: the fuzzing starts from files their readers accept."""
    assert set(READERS) == set(VALID)
    with tempfile.TemporaryDirectory() as tmp:
        for name, data in VALID.items():
            path = Path(tmp) / name
            path.write_bytes(data)
            for reader in READERS[name]:
                reader(path)


@pytest.mark.parametrize("name", sorted(VALID))
def test_fuzzed_files_raise_only_value_error(name):
    ext = Path(name).suffix

    @FUZZ
    @given(data=_mutations(VALID[name]))
    def check(data):
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"fuzz{ext}"
            path.write_bytes(data)
            for reader in READERS[name]:
                _call(reader, path)

    check()


@pytest.mark.parametrize("name", sorted(READERS))
def test_empty_and_missing_files(tmp_path, name):
    ext = Path(name).suffix
    (tmp_path / f"empty{ext}").write_bytes(b"")
    for reader in READERS[name]:
        with pytest.raises(ValueError):
            reader(tmp_path / f"empty{ext}")
        with pytest.raises(FileNotFoundError):
            reader(tmp_path / f"missing{ext}")


def test_wrong_argument_types_raise_type_error(tmp_path):
    for reader in (sio.read_image, sio.read_pfm, sio.read_depth_array, sio.read_depth, sio.read_mask,
                   sio.read_calib, sio.read_nyu_h5, sio.NYUDepthV2Labeled):
        with pytest.raises(TypeError):
            reader(3.5)
    (tmp_path / "d.npy").write_bytes(VALID["depth.npy"])
    with pytest.raises(TypeError):
        sio.read_depth(tmp_path / "d.npy", max_pixels=2.5)
    with pytest.raises(TypeError):
        sio.read_depth(tmp_path / "d.npy", option_names=["--depth"])


_DTYPES = [np.bool_, np.int8, np.int16, np.uint16, np.int64, np.uint64, np.float16, np.float32, np.float64,
           np.complex64, np.dtype("U3"), np.dtype("S2"), np.dtype("datetime64[s]"), np.dtype("timedelta64[s]"),
           np.dtype([("a", "<f4"), ("b", "<i2")])]


@FUZZ
@given(array=hnp.arrays(dtype=st.sampled_from(_DTYPES),
                        shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4)),
       container=st.sampled_from([".npy", ".npz", ".h5"]))
def test_wrong_dtypes_and_shapes(array, container):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"a{container}"
        if container == ".npy":
            np.save(path, array)
        elif container == ".npz":
            np.savez(path, depth=array)
        else:
            try:
                with h5py.File(path, "w") as f:
                    f.create_dataset("depth", data=array)
            except (TypeError, ValueError):
                return  # h5py cannot store this dtype: nothing to read
        real = array.dtype.kind in "iuf"
        for reader in (lambda p: sio.read_depth(p, scale=1), lambda p: sio.read_mask(p, key="depth")):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    out = reader(path)
                except ValueError:
                    continue
            assert out.ndim == 2 and out.shape == array.shape and out.size > 0
            if out.dtype == np.float64:  # read_depth
                assert real and not np.any(out <= 0)
            else:  # read_mask
                assert out.dtype == bool and array.dtype.kind in "biuf"


@pytest.mark.parametrize("name", ["grey16.png", "depth.npy", "depth.pfm", "depth.h5", "grey16.tif"])
def test_cli_fuzzed_depth_exits_2_with_one_line(tmp_path, name):
    rng = np.random.default_rng(1)
    iio.imwrite(tmp_path / "rgb.png", rng.integers(0, 256, size=(6, 8, 3)).astype(np.uint8))
    ext = Path(name).suffix

    @settings(derandomize=True, deadline=None, max_examples=max(EXAMPLES // 3, 1),
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
    @given(data=_mutations(VALID[name]))
    def check(data):
        depth = tmp_path / f"fuzz{ext}"
        depth.write_bytes(data)
        argv = ["--image", str(tmp_path / "rgb.png"), "--depth", str(depth), "--depth-scale", "m",
                "--fill-holes", "--max-pixels", str(LIMIT), "-q"]
        err, out = _io.StringIO(), _io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            rc = main(argv)
        assert rc in (0, 2), (rc, err.getvalue())
        if rc == 2:
            lines = err.getvalue().strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("python -m sparsedepth.complete: error: "), lines
            assert "--depth" in lines[0] or "--image" in lines[0], lines

    check()
    os.remove(tmp_path / f"fuzz{ext}")
