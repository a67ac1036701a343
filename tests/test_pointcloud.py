"""depth_to_points, write_ply and read_ply.

Every point is checked against the pinhole formula evaluated here pixel by
pixel, and every PLY file against a small parser written in this file.
"""

import math
import os

import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth._validation import check_intrinsics

HEADER_RGB = [
    "ply",
    "format binary_little_endian 1.0",
    f"comment {sd.io.pointcloud.PLY_COMMENT}",
    None,  # element vertex N, checked with N
    "property float x",
    "property float y",
    "property float z",
    "property uchar red",
    "property uchar green",
    "property uchar blue",
    "end_header",
]


def parse_ply(path):
    """Independent reader: header lines, then the records with np.frombuffer."""
    raw = open(path, "rb").read()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    lines = raw[:end].decode("ascii").split("\n")[:-1]
    count = int(lines[3].split()[2])
    names = [line.split()[2] for line in lines if line.startswith("property")]
    types = {"float": "<f4", "uchar": "u1"}
    dtype = np.dtype([(line.split()[2], types[line.split()[1]]) for line in lines if line.startswith("property")])
    assert len(raw) - end == count * dtype.itemsize  # nothing missing, nothing after the records
    records = np.frombuffer(raw[end:], dtype=dtype)
    xyz = np.stack([records[n] for n in ("x", "y", "z")], axis=1)
    rgb = np.stack([records[n] for n in ("red", "green", "blue")], axis=1) if "red" in names else None
    return lines, count, xyz, rgb


def pinhole(depth, intrinsics, image=None):
    """Points (float64) and colours of every pixel with positive finite depth, one pixel at a time."""
    fx, fy, cx, cy = intrinsics
    points, colors = [], []
    for v in range(depth.shape[0]):
        for u in range(depth.shape[1]):
            z = float(depth[v, u])
            if math.isfinite(z) and z > 0:
                points.append(((u - cx) * z / fx, (v - cy) * z / fy, z))
                if image is not None:
                    colors.append(image[v, u] if image.ndim == 3 else [image[v, u]] * 3)
    return np.array(points).reshape(-1, 3), (np.array(colors, dtype=np.uint8).reshape(-1, 3) if image is not None
                                             else None)


# ----------------------------------------------------------------------------- depth_to_points
def test_depth_to_points_is_the_pinhole_formula_and_skips_missing_pixels():
    depth = np.array([[2.0, np.nan, 0.0], [-1.0, np.inf, 4.5], [1.0, 3.0, 0.25]])
    image = np.arange(27, dtype=np.uint8).reshape(3, 3, 3)
    intrinsics = (500.0, 400.0, 1.5, 0.75)
    points, colors = sd.depth_to_points(depth, intrinsics, image=image)
    expected, expected_colors = pinhole(depth, intrinsics, image)
    assert points.dtype == np.float32 and colors.dtype == np.uint8
    assert points.shape == (5, 3) and colors.shape == (5, 3)
    np.testing.assert_allclose(points, expected, rtol=1e-6)
    np.testing.assert_array_equal(colors, expected_colors)
    # by hand: pixel (row 0, col 0) with z = 2 -> x = (0 - 1.5) 2 / 500, y = (0 - 0.75) 2 / 400
    np.testing.assert_allclose(points[0], [-0.006, -0.00375, 2.0], rtol=1e-6)
    assert sd.depth_to_points(depth, intrinsics)[1] is None


def test_depth_to_points_does_not_modify_its_inputs():
    depth = np.array([[1.0, np.nan], [2.0, 3.0]])
    image = np.full((2, 2, 3), 7, dtype=np.uint8)
    before = depth.copy(), image.copy()
    sd.depth_to_points(depth, (1.0, 1.0, 0.0, 0.0), image=image)
    np.testing.assert_array_equal(depth, before[0])
    np.testing.assert_array_equal(image, before[1])


@pytest.mark.parametrize("image, expected", [
    (np.array([[10, 200]], dtype=np.uint8), [[10, 10, 10], [200, 200, 200]]),  # grey -> grey colours
    (np.array([[[1, 2, 3, 4], [5, 6, 7, 8]]], dtype=np.uint8), [[1, 2, 3], [5, 6, 7]]),  # alpha dropped
    (np.array([[0, 65535]], dtype=np.uint16), [[0, 0, 0], [255, 255, 255]]),  # 16 bit
    (np.array([[[0.0, 0.5, 1.0], [1.0, 1.0, 1.0]]]), [[0, 128, 255], [255, 255, 255]]),  # float in [0, 1]
])
def test_depth_to_points_colours(image, expected):
    _, colors = sd.depth_to_points(np.array([[1.0, 2.0]]), (1.0, 1.0, 0.0, 0.0), image=image)
    np.testing.assert_array_equal(colors, expected)


def test_downsampled_intrinsics_put_every_kept_pixel_where_the_full_grid_does():
    rng = np.random.default_rng(3)
    depth = rng.uniform(0.5, 9.0, (30, 41))
    intrinsics = (525.0, 520.0, 19.7, 14.2)
    n = 3
    fx, fy, cx, cy = intrinsics
    small, _ = sd.depth_to_points(depth[::n, ::n], (fx / n, fy / n, cx / n, cy / n))
    full, _ = pinhole(depth, intrinsics)
    rows, cols = np.nonzero(np.ones(depth.shape, bool))
    kept = ((rows % n == 0) & (cols % n == 0))
    np.testing.assert_allclose(small, full[kept], rtol=2e-6, atol=1e-7)


@pytest.mark.parametrize("intrinsics, error, match", [
    ((1.0, 1.0, 0.0), TypeError, "four real numbers"),
    ([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], ValueError, "skew"),
    (2 * np.eye(3), ValueError, "last row"),
    (np.eye(2), TypeError, "3x3"),
    ([[1.0, 0.0, np.nan], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], ValueError, "finite"),
    ("1,1,0,0", TypeError, "sequence"),
    ((0.0, 1.0, 0.0, 0.0), ValueError, "fx"),
    ((1.0, -2.0, 0.0, 0.0), ValueError, "fy"),
    ((1.0, 1.0, np.nan, 0.0), ValueError, "cx"),
    ((1.0, 1.0, 0.0, np.inf), ValueError, "cy"),
])
def test_bad_intrinsics(intrinsics, error, match):
    with pytest.raises(error, match=match):
        check_intrinsics(intrinsics)
    with pytest.raises(error, match="`intrinsics`"):
        sd.depth_to_points(np.ones((2, 2)), intrinsics)


def test_depth_to_points_bad_arrays():
    with pytest.raises(ValueError, match="2-D"):
        sd.depth_to_points(np.ones(3), (1, 1, 0, 0))
    with pytest.raises(ValueError, match="same pixel grid"):
        sd.depth_to_points(np.ones((2, 2)), (1, 1, 0, 0), image=np.zeros((2, 3, 3), np.uint8))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        sd.depth_to_points(np.ones((1, 1)), (1, 1, 0, 0), image=np.full((1, 1, 3), 2.0))
    with pytest.raises(TypeError, match="depth"):
        sd.depth_to_points(np.array([["a"]]), (1, 1, 0, 0))


# ----------------------------------------------------------------------------- PLY files
def test_write_ply_header_and_records_follow_the_spec(tmp_path):
    points = np.array([[0.5, -1.25, 3.0], [1e-3, 2.0, 40.0], [-7.0, 0.0, 0.1]])
    colors = np.array([[255, 0, 1], [2, 3, 4], [128, 64, 32]], dtype=np.uint8)
    sd.write_ply(tmp_path / "c.ply", points, colors)
    lines, count, xyz, rgb = parse_ply(tmp_path / "c.ply")
    expected = list(HEADER_RGB)
    expected[3] = "element vertex 3"
    assert lines == expected and count == 3
    np.testing.assert_array_equal(xyz, points.astype(np.float32))
    np.testing.assert_array_equal(rgb, colors)
    back, back_colors = sd.read_ply(tmp_path / "c.ply")
    assert back.dtype == np.float32 and back_colors.dtype == np.uint8
    np.testing.assert_array_equal(back, points.astype(np.float32))
    np.testing.assert_array_equal(back_colors, colors)
    assert os.listdir(tmp_path) == ["c.ply"]  # no temporary file left


def test_write_ply_without_colours_and_empty(tmp_path):
    sd.write_ply(tmp_path / "p.ply", [[1.0, 2.0, 3.0]])
    lines, count, xyz, rgb = parse_ply(tmp_path / "p.ply")
    assert lines == [line for line in HEADER_RGB[:3]] + ["element vertex 1"] + HEADER_RGB[4:7] + ["end_header"]
    assert rgb is None and xyz.tolist() == [[1.0, 2.0, 3.0]]
    points, colors = sd.read_ply(tmp_path / "p.ply")
    assert colors is None and points.tolist() == [[1.0, 2.0, 3.0]]
    sd.write_ply(tmp_path / "e.ply", np.zeros((0, 3)), np.zeros((0, 3), np.uint8))
    points, colors = sd.read_ply(tmp_path / "e.ply")
    assert points.shape == (0, 3) and colors.shape == (0, 3)


def test_read_ascii_ply(tmp_path):
    text = ("ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 2\nproperty float x\nproperty float y\n"
            "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
            "0.5 -1 2.25 255 0 7\n1e-3 4 5 1 2 3\n")
    (tmp_path / "a.ply").write_text(text)
    points, colors = sd.read_ply(tmp_path / "a.ply")
    np.testing.assert_array_equal(points, np.array([[0.5, -1, 2.25], [1e-3, 4, 5]], dtype=np.float32))
    np.testing.assert_array_equal(colors, [[255, 0, 7], [1, 2, 3]])
    (tmp_path / "b.ply").write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float32 x\n"
                                    "property float32 y\nproperty float32 z\nend_header\n1 2 3\n")
    points, colors = sd.read_ply(tmp_path / "b.ply")
    assert colors is None and points.tolist() == [[1, 2, 3]]


def _ply(fmt="binary_little_endian 1.0", elements="element vertex 1\nproperty float x\nproperty float y\n"
         "property float z\n", body=b"\0" * 12):
    return f"ply\nformat {fmt}\n{elements}end_header\n".encode() + body


@pytest.mark.parametrize("content, match", [
    (b"solid cube\n", "not a PLY file"),
    (_ply(fmt="binary_big_endian 1.0"), "binary_big_endian 1.0"),
    (_ply(elements="element vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                   "element face 0\nproperty list uchar int vertex_indices\n"), "element face 0"),
    (_ply(elements="element vertex 1\nproperty double x\nproperty double y\nproperty double z\n",
          body=b"\0" * 24), "double x"),
    (_ply(elements="element vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                   "property float nx\n", body=b"\0" * 16), "float nx"),
    (_ply(body=b"\0" * 11), "11 bytes"),
    (_ply(body=b"\0" * 13), "13 bytes"),
    (_ply(fmt="ascii 1.0", body=b"1 2 3\n4 5 6\n"), "found 2 line"),
    (_ply(fmt="ascii 1.0", body=b"1 2 x\n"), "not a number"),
    (_ply(fmt="ascii 1.0", elements="element vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
          "property uchar red\nproperty uchar green\nproperty uchar blue\n", body=b"1 2 3 256 0 0\n"), "0, 255"),
])
def test_read_ply_refuses_what_it_does_not_read(tmp_path, content, match):
    (tmp_path / "x.ply").write_bytes(content)
    with pytest.raises(ValueError, match=match) as info:
        sd.read_ply(tmp_path / "x.ply", name="--cloud")
    assert "--cloud" in str(info.value)


def test_ply_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        sd.read_ply(tmp_path / "none.ply")
    with pytest.raises(FileNotFoundError):
        sd.write_ply(tmp_path / "missing" / "p.ply", [[0, 0, 1]])
    with pytest.raises(ValueError, match="extension"):
        sd.write_ply(tmp_path / "p.xyz", [[0, 0, 1]])
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        sd.write_ply(tmp_path / "p.ply", [[0, 0]])
    with pytest.raises(ValueError, match="NaN or infinite"):
        sd.write_ply(tmp_path / "p.ply", [[0, np.nan, 1]])
    with pytest.raises(ValueError, match="float32 range"):
        sd.write_ply(tmp_path / "p.ply", [[0, 1e39, 1]])
    with pytest.raises(ValueError, match=r"\[0, 255\]"):
        sd.write_ply(tmp_path / "p.ply", [[0, 0, 1]], [[0, 0, 256]])
    with pytest.raises(ValueError, match="colors"):
        sd.write_ply(tmp_path / "p.ply", [[0, 0, 1]], [[0, 0]])
    assert os.listdir(tmp_path) == []


def test_write_ply_failure_leaves_an_existing_file_alone(tmp_path):
    sd.write_ply(tmp_path / "p.ply", [[0, 0, 1]])
    before = (tmp_path / "p.ply").read_bytes()
    with pytest.raises(ValueError):
        sd.write_ply(tmp_path / "p.ply", [[0, np.inf, 1]])
    assert (tmp_path / "p.ply").read_bytes() == before and os.listdir(tmp_path) == ["p.ply"]


def test_intrinsics_as_a_matrix_or_a_camera_object_give_the_same_points():
    fx, fy, cx, cy = 525.0, 520.5, 319.5, 239.5
    depth = np.random.default_rng(0).uniform(1, 3, (6, 8))
    expected, _ = sd.depth_to_points(depth, (fx, fy, cx, cy))
    K = [[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]

    class WithMatrix:  # as Open3D's PinholeCameraIntrinsic offers it
        intrinsic_matrix = np.array(K)

    class WithParts:
        def __init__(self):
            self.fx, self.fy, self.cx, self.cy = fx, fy, cx, cy

    for intrinsics in (K, np.array(K), WithMatrix(), WithParts()):
        assert check_intrinsics(intrinsics) == (fx, fy, cx, cy)
        points, _ = sd.depth_to_points(depth, intrinsics)
        np.testing.assert_array_equal(points, expected)
