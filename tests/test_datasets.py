"""Tests for sparsedepth.datasets.

Ground truth is re-derived independently (imageio / numpy / the documented
unit conventions of shared/data/SOURCES.md) rather than through sparsedepth.io.
"""

import re
from pathlib import Path

import h5py
import imageio.v3 as iio
import numpy as np
import pytest
import skimage.data

import sparsedepth
from sparsedepth import datasets as ds
from sparsedepth.datasets import embedded, shared

ALL_SHARED = [
    "nyu_metric3d/00000",
    "nyu_metric3d/00050",
    "nyu_metric3d/00100",
    "nyu_rcnn_depth/demo",
    "nyu_mmseg_pseudo/bookstore_0001d_00001",
    "kitti/0000000005",
    "kitti/0000000050",
    "kitti/0000000100",
    "kitti_raw_0023/0000000000",
    "kitti_raw_0023/0000000006",
    "middlebury2014/motorcycle",
    "middlebury2003/teddy",
    "middlebury2001/tsukuba",
    "eth3d/terrace",
    "tum/0",
    "realsense_d435/000000080",
    "realsense_d435/000000130",
]

# name prefix -> (units, min, max, valid fraction lo, hi), from shared/data/SOURCES.md
EXPECTED = {
    "nyu_metric3d": ("m", 0.3, 10.0, 0.55, 0.85),
    "nyu_rcnn_depth": ("m", 0.3, 10.0, 1.0, 1.0),
    "nyu_mmseg_pseudo": ("m", 0.3, 10.0, 0.45, 0.60),
    "kitti": ("m", 1.0, 90.0, 0.15, 0.25),
    "middlebury2014": ("m", 2.0, 5.1, 0.90, 0.95),
    "middlebury2003": ("disparity_px", 1.0, 255 / 4, 0.90, 1.0),
    "middlebury2001": ("disparity_px", 1.0, 255 / 16, 0.70, 0.90),
    "eth3d": ("m", 2.4, 5.3, 0.50, 0.56),
    "tum": ("m", 1.4, 9.4, 0.75, 0.85),
    "realsense_d435": ("m", 0.3, 1.1, 0.78, 0.92),
    "kitti_raw_0023": ("m", 4.5, 80.0, 0.035, 0.045),
}

SHARED_ROOT = ds.shared_data_dir()
SHARED_NAMES = ds.list_shared_frames() or ["<shared data absent>"]


def _nan_where(values, invalid):
    out = values.astype(np.float64)
    out[invalid] = np.nan
    return out


def _png_depth(path, divisor, *, invalid_values=(0,)):
    stored = iio.imread(path)
    return _nan_where(stored / divisor, np.isin(stored, invalid_values))


def _independent_ground_truth(root: Path, name: str) -> np.ndarray:
    """Ground truth recomputed from the raw files with the SOURCES.md conventions."""
    prefix, frame = name.split("/")
    if prefix == "nyu_metric3d":
        return _png_depth(root / prefix / f"sync_depth_{frame}.png", 1000)
    if prefix == "nyu_rcnn_depth":
        return _png_depth(root / prefix / "depth.png", 1000)
    if prefix == "nyu_mmseg_pseudo":
        return _png_depth(root / prefix / f"{frame}.png", 1000, invalid_values=(0, 10000))
    if prefix == "kitti":
        return _png_depth(root / "kitti_metric3d" / f"depth_{frame}.png", 256)
    if prefix == "tum":
        return _png_depth(root / "tum_open3d" / "TUM_depth.png", 5000)
    if prefix == "middlebury2003":
        return _png_depth(root / "middlebury_acv/teddy/disp2.png", 4)
    if prefix == "middlebury2001":
        return _png_depth(root / "middlebury_acv/tsukuba/disp3.pgm", 16)
    if prefix == "middlebury2014":
        disp = np.load(root / "middlebury2014_skimage/motorcycle_disp.npz")["arr_0"].astype(np.float64)
        return _nan_where(193.001 * 994.978 / (disp + 31.086) / 1000, ~np.isfinite(disp))
    if prefix == "eth3d":
        raw = (root / "eth3d_twoview/terrace/disp0.pfm").read_bytes()
        header = b"Pf\n713 434\n-1\n"
        assert raw.startswith(header)
        disp = np.frombuffer(raw[len(header):], "<f4").reshape(434, 713)[::-1].astype(np.float64)
        return _nan_where(711.499 * 59.9432 / 1000 / disp, ~np.isfinite(disp))
    if prefix == "realsense_d435":
        stored = np.load(root / "realsense_cleargrasp" / f"depth_{frame}.npz")["depth"].astype(np.float64)
        return _nan_where(stored, ~(np.isfinite(stored) & (stored > 0)))
    if prefix == "kitti_raw_0023":
        stored = np.load(root / "kitti_raw_0023" / f"velodyne_{frame}.npz")["velodyne_depth"].astype(np.float64)
        return _nan_where(stored, ~(stored > 0))
    raise AssertionError(name)


# ------------------------------------------------------------------------------------
# real shared frames
# ------------------------------------------------------------------------------------
def test_all_shared_frames_listed():
    if SHARED_ROOT is None:
        pytest.skip("../shared/data not present")
    assert ds.list_shared_frames() == ALL_SHARED


@pytest.mark.parametrize("name", SHARED_NAMES)
def test_shared_frame(name):
    if SHARED_ROOT is None:
        pytest.skip("../shared/data not present")
    frame = ds.load_shared_frame(name)
    units, lo, hi, valid_lo, valid_hi = EXPECTED[name.split("/")[0]]
    assert frame.name == name
    assert frame.units == units
    assert frame.image.dtype == np.uint8 and frame.image.shape == frame.depth.shape + (3,)
    assert frame.depth.dtype == np.float64
    valid = frame.valid
    assert valid_lo <= valid.mean() <= valid_hi
    assert lo <= frame.depth[valid].min() and frame.depth[valid].max() <= hi
    expected = _independent_ground_truth(SHARED_ROOT, name)
    np.testing.assert_allclose(frame.depth, expected, rtol=1e-12, atol=0)  # NaNs must coincide
    assert frame.image.std() > 10  # a real picture, not a blank array


def test_shared_rcnn_raw_depth():
    if SHARED_ROOT is None or "nyu_rcnn_depth/demo" not in ds.list_shared_frames():
        pytest.skip("../shared/data not present")
    frame = ds.load_shared_frame("nyu_rcnn_depth/demo")
    np.testing.assert_array_equal(frame.raw_depth, _png_depth(SHARED_ROOT / "nyu_rcnn_depth/rawdepth.png", 1000))
    raw_valid = ~np.isnan(frame.raw_depth)
    assert 0.80 <= raw_valid.mean() <= 0.86  # 16.7 % missing
    # the inpainted depth agrees with the raw measurements where these exist (within 5 cm on 95 %)
    diff = np.abs(frame.depth[raw_valid] - frame.raw_depth[raw_valid])
    assert np.quantile(diff, 0.95) < 0.05


def test_shared_intrinsics_and_motorcycle_agree():
    if SHARED_ROOT is None:
        pytest.skip("../shared/data not present")
    nyu = ds.load_shared_frame("nyu_metric3d/00050")
    assert nyu.intrinsics == ds.NYU_RGB_INTRINSICS
    assert ds.load_shared_frame("kitti/0000000005").intrinsics == (707.0493, 707.0493, 604.0814, 180.5066)
    assert ds.load_shared_frame("eth3d/terrace").intrinsics == (711.499, 711.499, 376.135, 227.447)
    shared = ds.load_shared_frame("middlebury2014/motorcycle")
    packaged = ds.load_motorcycle()
    np.testing.assert_array_equal(shared.image, packaged.image)
    np.testing.assert_array_equal(shared.depth, packaged.depth)
    embedded = ds.load_embedded_frame()
    mmseg = ds.load_shared_frame(embedded.name)
    np.testing.assert_array_equal(mmseg.image, embedded.image)
    np.testing.assert_array_equal(mmseg.depth, embedded.depth)


# ------------------------------------------------------------------------------------
# frames that never need shared/data
# ------------------------------------------------------------------------------------
def test_load_motorcycle():
    frame = ds.load_motorcycle()
    left, _, disp = skimage.data.stereo_motorcycle()
    disp = disp.astype(np.float64)
    expected = _nan_where(193.001 * 994.978 / (disp + 31.086) / 1000, ~np.isfinite(disp))
    np.testing.assert_allclose(frame.depth, expected, rtol=1e-12)
    np.testing.assert_array_equal(frame.image, left)
    assert frame.shape == (500, 741) and frame.units == "m"
    assert 0.90 < frame.valid.mean() < 0.95
    assert 2.0 < np.nanmin(frame.depth) and np.nanmax(frame.depth) < 5.1
    assert frame.intrinsics == (994.978, 994.978, 311.193, 254.877)
    assert "stereo_motorcycle" in frame.source


def test_embedded_frame():
    assert ds.list_embedded_frames() == ["nyu_mmseg_pseudo/bookstore_0001d_00001"]
    frame = ds.load_embedded_frame("nyu_mmseg_pseudo/bookstore_0001d_00001")
    data = Path(sparsedepth.__file__).parent / "data"
    stored = iio.imread(data / "bookstore_0001d_00001.png")
    assert stored.dtype == np.uint16 and stored.shape == (120, 160)
    expected = _nan_where(stored / 1000, (stored == 0) | (stored == 10000))
    np.testing.assert_array_equal(frame.depth, expected)
    assert frame.image.shape == (120, 160, 3) and frame.image.dtype == np.uint8
    assert frame.image.std() > 10
    assert 0.50 < frame.valid.mean() < 0.53  # 33.8 % zeros + 14.7 % clipped at 10 m
    assert 1.4 < np.nanmin(frame.depth) and np.nanmax(frame.depth) < 10.0
    assert frame.raw_depth is None and frame.dataset == "NYU Depth V2"


def test_embedded_sources_document_the_checksums():
    text = (Path(sparsedepth.__file__).parent / "data" / "SOURCES.md").read_text()
    for file_name, digest in embedded._EMBEDDED_SHA256.items():
        assert file_name in text and digest in text


def test_embedded_frame_errors(monkeypatch):
    with pytest.raises(ValueError, match="unknown embedded frame 'nope'"):
        ds.load_embedded_frame("nope")
    monkeypatch.setitem(embedded._EMBEDDED_SHA256, "bookstore_0001d_00001.png", "0" * 64)
    with pytest.raises(ValueError, match="is corrupt"):
        ds.load_embedded_frame()


# ------------------------------------------------------------------------------------
# Frame
# ------------------------------------------------------------------------------------
def _frame(**overrides):
    kwargs = dict(
        name="t/0",
        dataset="test",
        image=np.zeros((2, 3, 3), np.uint8),
        depth=np.array([[1.0, np.nan, 2.0], [3.0, 4.0, 5.0]]),
    )
    kwargs.update(overrides)
    return ds.Frame(**kwargs)


def test_frame_fields_are_read_only():
    frame = _frame(intrinsics=[1, 2, 3, 4])
    assert frame.shape == (2, 3) and frame.units == "m" and frame.raw_depth is None
    np.testing.assert_array_equal(frame.valid, [[True, False, True], [True, True, True]])
    assert frame.intrinsics == (1.0, 2.0, 3.0, 4.0)
    with pytest.raises(ValueError, match="read-only"):
        frame.depth[0, 0] = 7.0
    with pytest.raises(AttributeError):
        frame.name = "x"
    assert "valid=83.3%" in repr(frame)


@pytest.mark.parametrize(
    "overrides, exc, match",
    [
        ({"image": np.zeros((2, 3), np.uint8)}, ValueError, r"`image` must be an \(H, W, 3\) uint8"),
        ({"image": np.zeros((2, 3, 3), np.uint16)}, ValueError, "uint8"),
        ({"depth": np.ones((3, 2))}, ValueError, r"`depth` must be a float64 array of shape \(2, 3\)"),
        ({"depth": np.ones((2, 3), np.float32)}, ValueError, "float64"),
        ({"depth": np.array([[1.0, 0.0, 1.0], [1.0, 1.0, 1.0]])}, ValueError, "positive"),
        ({"depth": np.array([[1.0, np.inf, 1.0], [1.0, 1.0, 1.0]])}, ValueError, "inf"),
        ({"raw_depth": np.ones((2, 2))}, ValueError, "`raw_depth`"),
        ({"units": "mm"}, ValueError, "`units`"),
        ({"intrinsics": (0, 1, 2, 3)}, ValueError, "`intrinsics`"),
        ({"intrinsics": (1, 2, 3)}, ValueError, "`intrinsics`"),
        ({"name": 3}, TypeError, "`name`"),
    ],
)
def test_frame_validation(overrides, exc, match):
    with pytest.raises(exc, match=match):
        _frame(**overrides)


# ------------------------------------------------------------------------------------
# shared-data discovery with a hand-made folder
# ------------------------------------------------------------------------------------
def _pfm(rows):
    rows = np.asarray(rows, dtype="<f4")
    return f"Pf\n{rows.shape[1]} {rows.shape[0]}\n-1\n".encode() + rows[::-1].tobytes()


@pytest.fixture
def fake_root(tmp_path):
    """A tiny shared/data folder with a TUM, an ETH3D and a Teddy frame made by hand."""
    rng = np.random.default_rng(3)
    (tmp_path / "tum_open3d").mkdir()
    iio.imwrite(tmp_path / "tum_open3d/TUM_color.png", rng.integers(0, 256, (2, 3, 3), dtype=np.uint8))
    iio.imwrite(tmp_path / "tum_open3d/TUM_depth.png", np.array([[0, 5000, 10000], [2500, 1, 65535]], np.uint16))
    eth = tmp_path / "eth3d_twoview/terrace"
    eth.mkdir(parents=True)
    iio.imwrite(eth / "im0.png", rng.integers(0, 256, (2, 2, 3), dtype=np.uint8))
    (eth / "disp0.pfm").write_bytes(_pfm([[10.0, np.inf], [40.0, 20.0]]))
    (eth / "calib.txt").write_text("cam0=[500 0 1; 0 500 1; 0 0 1]\ndoffs=0\nbaseline=200\nwidth=2\nheight=2\n")
    teddy = tmp_path / "middlebury_acv/teddy"
    teddy.mkdir(parents=True)
    iio.imwrite(teddy / "im2.png", rng.integers(0, 256, (1, 2, 3), dtype=np.uint8))
    iio.imwrite(teddy / "disp2.png", np.array([[0, 50]], np.uint8))
    return tmp_path


def test_fake_root_frames(fake_root):
    assert ds.list_shared_frames(fake_root) == ["middlebury2003/teddy", "eth3d/terrace", "tum/0"]
    tum = ds.load_shared_frame("tum/0", root=fake_root)
    np.testing.assert_array_equal(tum.depth, [[np.nan, 1.0, 2.0], [0.5, 0.0002, 13.107]])
    np.testing.assert_array_equal(tum.image, iio.imread(fake_root / "tum_open3d/TUM_color.png"))
    eth = ds.load_shared_frame("eth3d/terrace", root=str(fake_root))
    np.testing.assert_array_equal(eth.depth, [[10.0, np.nan], [2.5, 5.0]])  # 500 px * 0.2 m / d
    assert eth.intrinsics == (500.0, 500.0, 1.0, 1.0)
    teddy = ds.load_shared_frame("middlebury2003/teddy", root=fake_root)
    assert teddy.units == "disparity_px" and teddy.dataset == "Middlebury 2003"
    np.testing.assert_array_equal(teddy.depth, [[np.nan, 12.5]])


def test_shared_data_dir_env(monkeypatch, fake_root):
    monkeypatch.setenv("SPARSEDEPTH_DATA", str(fake_root))
    assert ds.shared_data_dir() == fake_root
    assert "tum/0" in ds.list_shared_frames()
    np.testing.assert_array_equal(ds.load_shared_frame("tum/0").depth[0, 1:], [1.0, 2.0])
    monkeypatch.setenv("SPARSEDEPTH_DATA", str(fake_root / "nowhere"))
    assert ds.shared_data_dir() == fake_root / "nowhere"
    with pytest.raises(FileNotFoundError, match="nowhere"):
        ds.list_shared_frames()
    monkeypatch.setenv("SPARSEDEPTH_DATA", "")
    default = ds.shared_data_dir()
    assert default is None or default == (Path(sparsedepth.__file__).resolve().parents[2] / "shared" / "data")


def test_shared_data_dir_default_is_beside_the_repository(monkeypatch):
    beside = Path(sparsedepth.__file__).resolve().parents[2] / "shared" / "data"
    if not beside.is_dir():
        pytest.skip(f"no shared data folder at {beside}")
    monkeypatch.delenv("SPARSEDEPTH_DATA", raising=False)
    assert ds.shared_data_dir() == beside
    assert shared.shared_data_dir() == beside


def test_shared_errors(monkeypatch, fake_root):
    with pytest.raises(ValueError, match=re.escape("unknown shared frame 'kitti/1'. Known frames: nyu_metric3d/00000")):
        ds.load_shared_frame("kitti/1", root=fake_root)
    with pytest.raises(FileNotFoundError, match="missing file .*sync_depth_00000.png|missing file .*rgb_00000.jpg"):
        ds.load_shared_frame("nyu_metric3d/00000", root=fake_root)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        ds.list_shared_frames(fake_root / "missing")
    with pytest.raises(TypeError, match="`root`"):
        ds.list_shared_frames(3)
    monkeypatch.setattr(shared, "shared_data_dir", lambda: None)
    assert ds.list_shared_frames() == []
    with pytest.raises(FileNotFoundError, match="SPARSEDEPTH_DATA"):
        ds.load_shared_frame("tum/0")


# ------------------------------------------------------------------------------------
# NYU labeled
# ------------------------------------------------------------------------------------
def test_load_nyu_labeled(tmp_path):
    rng = np.random.default_rng(4)
    images = rng.integers(0, 256, size=(2, 3, 4, 3), dtype=np.uint8)  # (N, H, W, 3)
    depths = rng.uniform(1.0, 9.0, size=(2, 3, 4)).astype(np.float32)
    raws = depths.copy()
    raws[:, 0, 0] = 0.0
    with h5py.File(tmp_path / "nyu.mat", "w") as f:  # MATLAB v7.3 axis order
        f["images"] = images.transpose(0, 3, 2, 1)
        f["depths"] = depths.transpose(0, 2, 1)
        f["rawDepths"] = raws.transpose(0, 2, 1)
    frame = ds.load_nyu_labeled(tmp_path / "nyu.mat", -1)
    assert frame.name == "nyu_labeled/0001"
    np.testing.assert_array_equal(frame.image, images[1])
    np.testing.assert_array_equal(frame.depth, depths[1].astype(np.float64))
    np.testing.assert_array_equal(frame.raw_depth, _nan_where(raws[1], raws[1] == 0))
    assert frame.intrinsics is None  # not the 640x480 frame the NYU intrinsics belong to
    with pytest.raises(IndexError):
        ds.load_nyu_labeled(tmp_path / "nyu.mat", 2)


def test_frames_of_one_scene_share_its_name():
    scenes = ds.shared_frame_scenes()
    assert set(scenes) == set(ALL_SHARED)
    # SOURCES.md: one basement, one KITTI drive per folder, one table set-up; the other frames are scenes of their own
    groups = {}
    for name, scene in scenes.items():
        groups.setdefault(scene, set()).add(name)
    shared = {frozenset(g) for g in groups.values() if len(g) > 1}
    assert shared == {frozenset(f"nyu_metric3d/{f}" for f in ("00000", "00050", "00100")),
                      frozenset(f"kitti/{f}" for f in ("0000000005", "0000000050", "0000000100")),
                      frozenset(f"kitti_raw_0023/{f}" for f in ("0000000000", "0000000006")),
                      frozenset(f"realsense_d435/{f}" for f in ("000000080", "000000130"))}


def test_new_frames_carry_their_intrinsics():
    if SHARED_ROOT is None:
        pytest.skip("../shared/data not present")
    assert ds.load_shared_frame("realsense_d435/000000080").intrinsics == (921.0, 921.0, 642.0, 359.0)
    fx, fy, cx, cy = ds.load_shared_frame("kitti_raw_0023/0000000006").intrinsics
    assert (fx, fy, cx, cy) == pytest.approx((721.5377, 721.5377, 609.5593, 172.854), rel=1e-12)
