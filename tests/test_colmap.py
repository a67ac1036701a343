"""COLMAP models: the reader (text and binary), its refusals, and each view's sparse depth.

The tiny model below is written by hand; its depths are worked out by hand in the comments.  The binary
files of the tests are packed here with :mod:`struct` from COLMAP's documented layout, independently of the
module's writer.
"""

import math
import os
import re
import struct
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from sparsedepth.io.colmap import (
    ColmapModel,
    intrinsic_matrix,
    read_colmap_model,
    rotation_from_qvec,
    view_depth,
    view_observations,
    write_colmap_model,
)
from sparsedepth.io.pointcloud import depth_to_points

FUZZ = settings(derandomize=True, deadline=None, max_examples=int(os.environ.get("SPARSEDEPTH_FUZZ_EXAMPLES", "60")),
                suppress_health_check=[HealthCheck.too_slow])

Q90Z = (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5))  # 90 degrees about z: R = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]

# Camera 1: 8x6, f 10, centre (4, 3).  Camera 2: 10x5, fx 20, fy 10, centre (5, 2.5).
CAMERAS = [(1, "SIMPLE_PINHOLE", 8, 6, (10.0, 4.0, 3.0)), (2, "PINHOLE", 10, 5, (20.0, 10.0, 5.0, 2.5))]
# Image 1 (camera 1, identity pose): point 10 at z 2 projects to (4, 3); point 11 at z 5 to (6, 1.8); point 12 to
# x = -996 (outside); point 14 is behind (z = -1), its keypoint on point 10's pixel.
# Image 2 (camera 2, 90 degrees about z, t = (0, 0, 1)): point 11 -> (0.6, 1, 6), projects to (7, 4.1667);
# point 10 -> (0, 0, 3) to (5, 2.5); point 13 -> (0, 0, 5), its keypoint on point 10's pixel (row 2, column 5).
# Image 3 (camera 1, t = (100, 0, 0)): point 11 projects to x = 206 (outside); point 12 -> (0, 0, 1) to (4, 3).
IMAGES = [
    (1, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1, "a.png",
     [(4.2, 3.1, 10), (1.0, 1.0, -1), (6.0, 1.8, 11), (-996.0, 3.0, 12), (4.9, 3.9, 14)]),
    (2, Q90Z, (0.0, 0.0, 1.0), 2, "b.png", [(7.0, 4.1666667, 11), (5.3, 2.4, 10), (5.4, 2.6, 13)]),
    (3, (1.0, 0.0, 0.0, 0.0), (100.0, 0.0, 0.0), 1, "c.png", [(206.0, 1.8, 11), (4.5, 3.5, 12)]),
]
# POINT3D_ID, xyz, rgb, error, track (IMAGE_ID, POINT2D_IDX)
POINTS = [
    (10, (0.0, 0.0, 2.0), (255, 0, 0), 0.5, [(1, 0), (2, 1)]),
    (11, (1.0, -0.6, 5.0), (0, 255, 0), 2.0, [(1, 2), (2, 0), (3, 0)]),
    (12, (-100.0, 0.0, 1.0), (0, 0, 255), 0.1, [(1, 3), (3, 1)]),
    (13, (0.0, 0.0, 4.0), (9, 9, 9), 0.3, [(2, 2)]),
    (14, (0.0, 0.0, -1.0), (1, 2, 3), 0.2, [(1, 4)]),
]


def _text_files(cameras=CAMERAS, images=IMAGES, points=POINTS) -> dict:
    cam = ["# Camera list with one line of data per camera:", "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]"]
    cam += [" ".join(map(str, (i, m, w, h, *p))) for i, m, w, h, p in cameras]
    img = ["# Image list with two lines of data per image:", ""]
    for i, q, t, c, name, obs in images:
        img.append(" ".join(map(str, (i, *q, *t, c, name))))
        img.append(" ".join(f"{x} {y} {p}" for x, y, p in obs))
    pts = ["# 3D point list with one line of data per point:"]
    pts += [" ".join(map(str, (i, *xyz, *rgb, e, *[v for pair in track for v in pair])))
            for i, xyz, rgb, e, track in points]
    return {"cameras.txt": "\n".join(cam) + "\n", "images.txt": "\n".join(img) + "\n",
            "points3D.txt": "\n".join(pts) + "\n"}


def _binary_files(cameras=CAMERAS, images=IMAGES, points=POINTS) -> dict:
    """COLMAP's binary layout, little-endian, packed field by field."""
    model_ids = {"SIMPLE_PINHOLE": 0, "PINHOLE": 1, "OPENCV": 4}
    cam = struct.pack("<Q", len(cameras))
    for i, m, w, h, p in cameras:
        cam += struct.pack("<iiQQ", i, model_ids[m], w, h) + struct.pack(f"<{len(p)}d", *p)
    img = struct.pack("<Q", len(images))
    for i, q, t, c, name, obs in images:
        img += struct.pack("<i4d3di", i, *q, *t, c) + name.encode() + b"\x00" + struct.pack("<Q", len(obs))
        img += b"".join(struct.pack("<ddq", x, y, p) for x, y, p in obs)
    pts = struct.pack("<Q", len(points))
    for i, xyz, rgb, e, track in points:
        pts += struct.pack("<Q3d3Bd", i, *xyz, *rgb, e) + struct.pack("<Q", len(track))
        pts += b"".join(struct.pack("<ii", image_id, idx) for image_id, idx in track)
    return {"cameras.bin": cam, "images.bin": img, "points3D.bin": pts}


def _write(folder: Path, files: dict) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for name, content in files.items():
        (folder / name).write_bytes(content.encode() if isinstance(content, str) else content)
    return folder


@pytest.fixture
def text_model(tmp_path):
    return _write(tmp_path / "text", _text_files())


@pytest.fixture
def binary_model(tmp_path):
    return _write(tmp_path / "binary", _binary_files())


def _assert_same_model(a: ColmapModel, b: ColmapModel):
    assert list(a.cameras) == list(b.cameras) and list(a.images) == list(b.images)
    for k in a.cameras:
        x, y = a.cameras[k], b.cameras[k]
        assert (x.id, x.model, x.width, x.height) == (y.id, y.model, y.width, y.height)
        np.testing.assert_array_equal(x.params, y.params)
    for k in a.images:
        x, y = a.images[k], b.images[k]
        assert (x.id, x.camera_id, x.name) == (y.id, y.camera_id, y.name)
        for field in ("qvec", "tvec", "xys", "point3d_ids"):
            np.testing.assert_array_equal(getattr(x, field), getattr(y, field))
    for field in ("ids", "xyz", "rgb", "error", "track_lengths", "track_image_ids", "track_point2d_idxs"):
        np.testing.assert_array_equal(getattr(a.points3d, field), getattr(b.points3d, field))
        assert getattr(a.points3d, field).dtype == getattr(b.points3d, field).dtype


# --- reading the tiny model


def test_the_text_reader_returns_the_hand_written_model(text_model):
    model = read_colmap_model(text_model)
    assert [(c.id, c.model, c.width, c.height, c.params.tolist()) for c in model.cameras.values()] == \
        [(i, m, w, h, list(p)) for i, m, w, h, p in CAMERAS]
    image = model.image("b.png")
    assert image is model.image(2) and image.camera_id == 2
    np.testing.assert_array_equal(image.qvec, Q90Z)
    np.testing.assert_array_equal(image.xys, [[7.0, 4.1666667], [5.3, 2.4], [5.4, 2.6]])
    np.testing.assert_array_equal(image.point3d_ids, [11, 10, 13])
    points = model.points3d
    np.testing.assert_array_equal(points.ids, [10, 11, 12, 13, 14])
    np.testing.assert_array_equal(points.rgb[1], [0, 255, 0])
    np.testing.assert_array_equal(points.track_lengths, [2, 3, 2, 1, 1])
    np.testing.assert_array_equal(points.track_image_ids, [1, 2, 1, 2, 3, 1, 3, 2, 1])
    np.testing.assert_array_equal(points.track_point2d_idxs, [0, 1, 2, 0, 0, 3, 1, 2, 4])
    np.testing.assert_array_equal(points.index_of([14, 10, 99]), [4, 0, -1])


def test_binary_packed_by_hand_reads_as_the_text_and_the_writer_round_trips_both(text_model, binary_model, tmp_path):
    from_text = read_colmap_model(text_model)
    from_binary = read_colmap_model(binary_model)
    _assert_same_model(from_text, from_binary)
    for file_format in ("binary", "text"):
        out = tmp_path / f"written_{file_format}"
        out.mkdir()
        write_colmap_model(from_binary, out, file_format=file_format)
        assert sorted(p.name for p in out.iterdir()) == sorted(
            stem + (".bin" if file_format == "binary" else ".txt") for stem in ("cameras", "images", "points3D"))
        _assert_same_model(read_colmap_model(out), from_text)
    # the module's binary writer writes the bytes of COLMAP's layout, as packed by hand
    for name, content in _binary_files().items():
        assert (tmp_path / "written_binary" / name).read_bytes() == content


def test_binary_is_preferred_when_both_are_present_and_file_format_chooses(tmp_path):
    folder = _write(tmp_path / "both", _text_files())
    changed = [(1, "SIMPLE_PINHOLE", 8, 6, (11.0, 4.0, 3.0)), CAMERAS[1]]
    _write(folder, _binary_files(cameras=changed))
    assert read_colmap_model(folder).cameras[1].params[0] == 11.0
    assert read_colmap_model(folder, file_format="text").cameras[1].params[0] == 10.0
    with pytest.raises(ValueError, match="file_format"):
        read_colmap_model(folder, file_format="bin")


def test_an_image_without_keypoints_has_an_empty_line_and_comments_and_blank_lines_are_skipped(tmp_path):
    files = _text_files(images=IMAGES + [(7, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1, "empty.png", [])])
    files["cameras.txt"] = "\n\n   # indented comment\n" + files["cameras.txt"] + "\n\n"
    model = read_colmap_model(_write(tmp_path / "m", files))
    assert model.image(7).xys.shape == (0, 2) and model.image(7).point3d_ids.shape == (0,)
    depth, mask, _ = view_depth(model, 7)
    assert depth.shape == (6, 8) and not mask.any()
    # the same model as binary
    binary = read_colmap_model(_write(tmp_path / "b", _binary_files(images=IMAGES + [
        (7, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1, "empty.png", [])])))
    _assert_same_model(model, binary)


# --- per-view depth


def test_view_depth_matches_the_depths_worked_out_by_hand(text_model):
    model = read_colmap_model(text_model)
    expected = {
        1: {(3, 4): 2.0, (1, 6): 5.0},  # point 14 (behind) and point 12 (outside) dropped
        2: {(4, 7): 6.0, (2, 5): 3.0},  # point 13 (z 5) loses its pixel to point 10 (z 3)
        3: {(3, 4): 1.0},  # point 11 outside
    }
    for image_id, pixels in expected.items():
        depth, mask, K = view_depth(model, image_id)
        camera = model.cameras[model.image(image_id).camera_id]
        assert depth.shape == mask.shape == (camera.height, camera.width) and depth.dtype == np.float64
        assert sorted(zip(*np.nonzero(mask))) == sorted(pixels)
        for (row, column), value in pixels.items():
            assert depth[row, column] == pytest.approx(value, rel=1e-12)
        assert np.all(np.isnan(depth[~mask]))
    _, _, K1 = view_depth(model, "a.png")
    np.testing.assert_array_equal(K1, [[10.0, 0.0, 3.5], [0.0, 10.0, 2.5], [0.0, 0.0, 1.0]])
    _, _, K2 = view_depth(model, "b.png")
    np.testing.assert_array_equal(K2, [[20.0, 0.0, 4.5], [0.0, 10.0, 2.0], [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(intrinsic_matrix(model.cameras[2], pixel_centres="half"),
                                  [[20.0, 0.0, 5.0], [0.0, 10.0, 2.5], [0.0, 0.0, 1.0]])


def test_max_error_and_min_track_drop_points(text_model):
    model = read_colmap_model(text_model)
    depth, mask, _ = view_depth(model, 1, max_error=1.0)  # point 11 has error 2
    assert sorted(zip(*np.nonzero(mask))) == [(3, 4)]
    depth, mask, _ = view_depth(model, 1, min_track=3)  # only point 11 is seen by 3 images
    assert sorted(zip(*np.nonzero(mask))) == [(1, 6)] and depth[1, 6] == pytest.approx(5.0)
    depth, mask, _ = view_depth(model, 2, min_track=2)  # point 13 (track 1) gone, point 10 kept
    assert depth[2, 5] == pytest.approx(3.0)
    for bad in ({"max_error": -1.0}, {"min_track": 0}):
        with pytest.raises(ValueError):
            view_depth(model, 1, **bad)
    with pytest.raises(KeyError, match="nope.png"):
        view_depth(model, "nope.png")


def test_observations_reproject_onto_their_keypoints(text_model):
    model = read_colmap_model(text_model)
    obs = view_observations(model, 2)
    np.testing.assert_array_equal(obs.point3d_ids, [11, 10, 13])
    np.testing.assert_allclose(obs.points_camera, [[0.6, 1.0, 6.0], [0.0, 0.0, 3.0], [0.0, 0.0, 5.0]], atol=1e-12)
    np.testing.assert_allclose(obs.projected, [[7.0, 2.5 + 10 / 6], [5.0, 2.5], [5.0, 2.5]], atol=1e-12)
    behind = view_observations(model, 1)
    assert np.all(np.isnan(behind.projected[behind.point3d_ids == 14]))


@pytest.mark.parametrize("seed", range(5))
def test_the_rotation_is_scipys_of_the_same_hamilton_quaternion(seed):
    q = np.random.default_rng(seed).normal(size=4)
    expected = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()  # scipy orders (x, y, z, w)
    np.testing.assert_allclose(rotation_from_qvec(q), expected, atol=1e-12)
    with pytest.raises(ValueError):
        rotation_from_qvec([0.0, 0.0, 0.0, 0.0])


def test_distorted_and_unknown_camera_models_are_refused_with_the_fix(tmp_path):
    opencv = [(1, "OPENCV", 8, 6, (10.0, 10.0, 4.0, 3.0, 0.1, 0.0, 0.0, 0.0)), CAMERAS[1]]
    for folder in (_write(tmp_path / "t", _text_files(cameras=opencv)),
                   _write(tmp_path / "b", _binary_files(cameras=opencv))):
        with pytest.raises(ValueError, match="OPENCV.*colmap image_undistorter"):
            read_colmap_model(folder)
    cameras = _binary_files()["cameras.bin"]
    unknown = cameras[:12] + struct.pack("<i", 99) + cameras[16:]
    with pytest.raises(ValueError, match=r"cameras\.bin', camera record 1 of 2 \(byte offset 8\): unknown camera "
                                         r"model id 99"):
        read_colmap_model(_write(tmp_path / "u", {**_binary_files(), "cameras.bin": unknown}))


# --- malformed text: one ValueError naming the file and the line


def _lines(text: str) -> list:
    return text.split("\n")


def _replace_line(files: dict, name: str, number: int, line: str) -> dict:
    lines = _lines(files[name])
    lines[number - 1] = line
    return {**files, name: "\n".join(lines)}


# (file, line number, replacement, what the message says); line numbers of _text_files: cameras 3-4, images 3-8,
# points 2-6
TEXT_CASES = [
    ("cameras.txt", 3, "1 SIMPLE_PINHOLE 8 6 10 4", "has 3 parameters, got 2"),
    ("cameras.txt", 3, "1 SIMPLE_PINHOLE 8 six 10 4 3", "HEIGHT must be an integer"),
    ("cameras.txt", 3, "1 SIMPLE_PINHOLE -8 6 10 4 3", "WIDTH must be an integer in \\[1"),
    ("cameras.txt", 3, "1 SIMPLE_PINHOLE 8 0 10 4 3", "HEIGHT must be an integer in \\[1"),
    ("cameras.txt", 3, "1 SIMPLE_PINHOLE 8 6 nan 4 3", "PARAMS must be finite"),
    ("cameras.txt", 3, "1 SIMPLE_PINHOLE 8 6 0 4 3", "focal length"),
    ("cameras.txt", 3, "1 FANCY 8 6 10 4 3", "unknown camera model 'FANCY'"),
    ("cameras.txt", 4, "1 SIMPLE_PINHOLE 8 6 10 4 3", "CAMERA_ID 1 appears twice"),
    ("cameras.txt", 3, "1 SIMPLE_PINHOLE", "expected CAMERA_ID MODEL WIDTH HEIGHT"),
    ("images.txt", 3, "1 1 0 0 0 0 0 0 1", "expected IMAGE_ID .* \\(10 values\\), got 9"),
    ("images.txt", 3, "1 1 0 0 zero 0 0 0 1 a.png", "QW QX QY QZ TX TY TZ must be finite numbers"),
    ("images.txt", 3, "1 0 0 0 0 0 0 0 1 a.png", "non-zero quaternion"),
    ("images.txt", 3, "1 1 0 0 0 0 0 0 9 a.png", "names CAMERA_ID 9, which cameras does not define"),
    ("images.txt", 3, "1_0 1 0 0 0 0 0 0 1 a.png", "IMAGE_ID must be an integer"),
    ("images.txt", 4, "4.2 3.1 10 1.0", "X Y POINT3D_ID triples"),
    ("images.txt", 4, "4.2 3.1 10 1.0 1.0 -2 6.0 1.8 11 -996 3 12 4.9 3.9 14", "POINT3D_ID must be an integer in"),
    ("images.txt", 4, "4.2 3.1 10 1.0 1.0 77 6.0 1.8 11 -996 3 12 4.9 3.9 14", "observes POINT3D_ID 77, which"),
    ("images.txt", 4, "4.2 3.1 10 1.0 inf -1 6.0 1.8 11 -996 3 12 4.9 3.9 14", "X and Y must be finite"),
    ("images.txt", 7, "2 1 0 0 0 100 0 0 1 c.png", "IMAGE_ID 2 appears twice"),
    ("images.txt", 5, "2 1 0 0 0 0 0 1 2 a.png", "image NAME 'a.png' appears twice"),
    ("points3D.txt", 2, "10 0 0 2 255 0 0 0.5 1 0 2", "TRACK\\[\\] as IMAGE_ID POINT2D_IDX pairs, got 11"),
    ("points3D.txt", 2, "10 0 0 2 255 0 0 0.5", "has a TRACK of 0 element\\(s\\) but 2 keypoint"),
    ("points3D.txt", 2, "10 0 0 2 256 0 0 0.5 1 0 2 1", "R G B must be an integer in \\[0, 255\\]"),
    ("points3D.txt", 2, "10 0 0 two 255 0 0 0.5 1 0 2 1", "X Y Z must be finite"),
    ("points3D.txt", 2, "10 0 0 2 255 0 0 0.5 1 0 2 2", "observes POINT3D_ID 13"),
    ("points3D.txt", 2, "10 0 0 2 255 0 0 0.5 1 0 2 9", "image 2 has 3 keypoints"),
    ("points3D.txt", 2, "10 0 0 2 255 0 0 0.5 1 0 5 1", "no such IMAGE_ID"),
    ("points3D.txt", 2, "10 0 0 2 255 0 0 0.5 1 0 2 -1", "must be integers in \\[0"),
    ("points3D.txt", 3, "10 1 -0.6 5 0 255 0 2 1 2 2 0 3 0", "POINT3D_ID 10 appears twice"),
]


@pytest.mark.parametrize("file_name, number, line, message", TEXT_CASES)
def test_malformed_text_is_one_value_error_naming_the_file_and_line(tmp_path, file_name, number, line, message):
    files = _text_files()
    folder = _write(tmp_path / "m", _replace_line(files, file_name, number, line))
    with pytest.raises(ValueError) as info:
        read_colmap_model(folder, name="--colmap")
    text = str(info.value)
    assert text.startswith(f"--colmap '{folder.resolve() / file_name}', line {number}: "), text
    assert re.search(message, text), text


def test_the_line_numbers_count_comments_and_blank_lines(tmp_path):
    files = _text_files()
    files["points3D.txt"] = "# a\n\n# b\n" + files["points3D.txt"].replace("0.5 1 0 2 1", "0.5 1 0 2 9")
    with pytest.raises(ValueError, match=r"points3D\.txt', line 5: TRACK element \(IMAGE_ID 2, POINT2D_IDX 9\)"):
        read_colmap_model(_write(tmp_path / "m", files))
    files = _text_files()
    files["images.txt"] = files["images.txt"].replace("4.2 3.1 10", "4.2 3.1 10 9", 1)
    with pytest.raises(ValueError, match=r"images\.txt', line 4: the line after an image's"):
        read_colmap_model(_write(tmp_path / "n", files))


def test_text_that_is_not_utf8_is_refused(tmp_path):
    files = {**_text_files(), "images.txt": b"1 1 0 0 0 0 0 0 1 \xff.png\n\n"}
    with pytest.raises(ValueError, match=r"images\.txt'.*not UTF-8"):
        read_colmap_model(_write(tmp_path / "m", files))


def test_too_large_a_camera_is_refused_from_its_declared_size(tmp_path):
    files = _text_files(cameras=[(1, "SIMPLE_PINHOLE", 100000, 100000, (10.0, 4.0, 3.0)), CAMERAS[1]])
    with pytest.raises(ValueError, match=r"cameras\.txt', line 3.*max_pixels"):
        read_colmap_model(_write(tmp_path / "m", files))
    assert read_colmap_model(tmp_path / "m", max_pixels=None).cameras[1].width == 100000


# --- malformed binary: one ValueError naming the file and the record / byte offset


def test_every_truncation_of_every_binary_file_is_a_value_error_naming_it(tmp_path):
    good = _binary_files()
    for name, content in good.items():
        for end in range(len(content)):
            folder = _write(tmp_path / f"{name}_{end}", {**good, name: content[:end]})
            with pytest.raises(ValueError, match=re.escape(name) + r"'.*(byte offset \d+|records|point)"):
                read_colmap_model(folder)


def test_binary_counts_that_do_not_match_are_refused(tmp_path):
    good = _binary_files()
    cases = {
        "trailing bytes": ("images.bin", good["images.bin"] + b"\x00", r"images\.bin': the header declares 3 images "
                                                                       r"but 1 bytes follow"),
        "one record too many": ("points3D.bin", struct.pack("<Q", 6) + good["points3D.bin"][8:],
                                r"points3D\.bin', point record 6 of 6 \(byte offset \d+\): truncated"),
        "a huge POINTS2D count": ("images.bin", good["images.bin"][:8 + 64 + 6] + struct.pack("<Q", 2**62)
                                  + good["images.bin"][8 + 64 + 6 + 8:],
                                  r"images\.bin', image record 1 of 3 \(byte offset 86\): truncated"),
        "no NUL after the name": ("images.bin", good["images.bin"][:8 + 64] + b"a.png",
                                  r"images\.bin', image record 1 of 3 .*no terminating NUL"),
        "a zero width": ("cameras.bin", good["cameras.bin"][:16] + struct.pack("<Q", 0) + good["cameras.bin"][24:],
                         r"cameras\.bin', camera record 1 of 2 \(byte offset 8\): WIDTH and HEIGHT must be positive"),
    }
    for label, (name, content, message) in cases.items():
        folder = _write(tmp_path / label.replace(" ", "_"), {**good, name: content})
        with pytest.raises(ValueError, match=message):
            read_colmap_model(folder)


def test_binary_cross_file_errors_name_the_record(tmp_path):
    images = [IMAGES[0], (2, Q90Z, (0.0, 0.0, 1.0), 5, "b.png", IMAGES[1][5]), IMAGES[2]]
    with pytest.raises(ValueError, match=r"images\.bin', image record 2 of 3 \(byte offset \d+\): image 2 names "
                                         r"CAMERA_ID 5"):
        read_colmap_model(_write(tmp_path / "cam", _binary_files(images=images)))
    points = POINTS[:-1]
    with pytest.raises(ValueError, match=r"images\.bin', image record 1 of 3 .*observes POINT3D_ID 14, which "
                                         r"points3D\.bin does not define"):
        read_colmap_model(_write(tmp_path / "pt", _binary_files(points=points)))


# --- the folder and its files


def test_missing_folder_or_files_are_file_not_found_naming_them(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such COLMAP model folder"):
        read_colmap_model(tmp_path / "absent")
    files = _text_files()
    del files["points3D.txt"]
    with pytest.raises(FileNotFoundError, match=r"missing cameras\.bin, images\.bin, points3D\.bin \(binary\); "
                                                r"points3D\.txt \(text\)"):
        read_colmap_model(_write(tmp_path / "m", files))
    with pytest.raises(FileNotFoundError, match=r"missing points3D\.txt \(text\)"):
        read_colmap_model(tmp_path / "m", file_format="text")
    with pytest.raises(ValueError, match="not a folder"):
        read_colmap_model(tmp_path / "m" / "cameras.txt")
    with pytest.raises(TypeError):
        read_colmap_model(3)


def test_a_symlink_leading_outside_the_folder_is_refused(tmp_path):
    outside = _write(tmp_path / "outside", _text_files())
    folder = _write(tmp_path / "model", {k: v for k, v in _text_files().items() if k != "cameras.txt"})
    (folder / "cameras.txt").symlink_to(outside / "cameras.txt")
    with pytest.raises(ValueError, match=r"cameras\.txt' is a symbolic link to .*outside the model folder"):
        read_colmap_model(folder)
    # a link that stays inside the folder is a file of the model
    (folder / "cameras.txt").unlink()
    (folder / "cameras_v2.txt").write_text(_text_files()["cameras.txt"])
    (folder / "cameras.txt").symlink_to("cameras_v2.txt")
    assert len(read_colmap_model(folder).cameras) == 2
    # the folder itself may be reached through a link
    (tmp_path / "link").symlink_to(folder)
    assert len(read_colmap_model(tmp_path / "link").images) == 3


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_fifo_is_refused_without_blocking(tmp_path):
    folder = _write(tmp_path / "model", {k: v for k, v in _text_files().items() if k != "images.txt"})
    os.mkfifo(folder / "images.txt")
    with pytest.raises(ValueError, match=r"images\.txt' is not a regular file"):
        read_colmap_model(folder)


def test_the_text_writer_refuses_names_it_cannot_store(text_model, tmp_path):
    model = read_colmap_model(text_model)
    image = model.images[1]
    spaced = ColmapModel(model.cameras, {**model.images, 1: type(image)(
        image.id, image.qvec, image.tvec, image.camera_id, "a b.png", image.xys, image.point3d_ids)}, model.points3d)
    with pytest.raises(ValueError, match="white space"):
        write_colmap_model(spaced, tmp_path, file_format="text")
    write_colmap_model(spaced, tmp_path, file_format="binary")
    assert read_colmap_model(tmp_path).image("a b.png").id == 1


# --- fuzzing


def _read_or_value_error(files: dict) -> None:
    """Read the model (ValueError allowed); if it reads, every view's depth map is made."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = _write(Path(tmp) / "m", files)
        try:
            model = read_colmap_model(folder, max_pixels=1 << 16)
        except ValueError:
            return
    for image in model.images.values():
        depth, mask, _ = view_depth(model, image.id)
        camera = model.cameras[image.camera_id]
        assert depth.shape == (camera.height, camera.width) and np.all(depth[mask] > 0)


@FUZZ
@given(which=st.sampled_from(["cameras.txt", "images.txt", "points3D.txt"]), data=st.binary(max_size=400))
def test_random_bytes_as_a_text_file_are_a_value_error_or_a_model(which, data):
    _read_or_value_error({**_text_files(), which: data})


@FUZZ
@given(which=st.sampled_from(["cameras.txt", "images.txt", "points3D.txt"]),
       edits=st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 8),
                                st.binary(max_size=6) | st.sampled_from([b" ", b"\n", b"-1", b"#", b"nan", b"1e999",
                                                                         b"99", b"0", b"\r\n"])),
                      min_size=1, max_size=4))
def test_edited_text_files_are_a_value_error_or_a_model(which, edits):
    data = bytearray(_text_files()[which].encode())
    for position, removed, inserted in edits:
        position %= len(data) + 1
        data[position:position + removed] = inserted
    _read_or_value_error({**_text_files(), which: bytes(data)})


@FUZZ
@given(which=st.sampled_from(["cameras.bin", "images.bin", "points3D.bin"]),
       edits=st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 255)), min_size=1, max_size=6))
def test_corrupted_binary_files_are_a_value_error_or_a_model(which, edits):
    data = bytearray(_binary_files()[which])
    for position, value in edits:
        data[position % len(data)] = value
    _read_or_value_error({**_binary_files(), which: bytes(data)})


# --- the shared real scene


@pytest.fixture
def maupertuis(shared_data):
    folder = shared_data / "colmap_maupertuis" / "reconstruction"
    if not folder.is_dir():
        pytest.skip(f"{folder} not present")
    return folder


def test_the_shared_scene_reads_as_documented(maupertuis):
    model = read_colmap_model(maupertuis)
    assert len(model.images) == 4 and len(model.points3d) == 1039 and list(model.cameras) == [1]
    camera = model.cameras[1]
    assert (camera.model, camera.width, camera.height) == ("SIMPLE_PINHOLE", 1919, 1079)
    np.testing.assert_array_equal(camera.params, [1847.53, 959.5, 539.5])
    assert model.points3d.track_lengths.mean() == pytest.approx(3.22907, abs=1e-5)  # the file's header says so


def test_the_shared_scene_depths_and_reprojections(maupertuis):
    model = read_colmap_model(maupertuis)
    for image in model.images.values():
        obs = view_observations(model, image.id)
        distance = np.linalg.norm(obs.keypoints - obs.projected, axis=1)
        # a wrong rotation convention (R transposed, or the inverse pose) misses by hundreds of pixels
        assert distance.mean() < 1.0
        assert distance.mean() == pytest.approx(obs.error.mean(), abs=0.1)
        depth, mask, K = view_depth(model, image.name)
        assert depth.shape == (1079, 1919) and mask.sum() > 500
        assert 12.0 < depth[mask].min() and depth[mask].max() < 39.0
        # back-projecting each pixel with K lands within half a pixel of the point in the camera frame
        points, _ = depth_to_points(depth, (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))
        rows, columns = np.nonzero(mask)
        nearest = {}
        for k in range(len(obs.depth)):
            key = (int(np.floor(obs.keypoints[k, 1])), int(np.floor(obs.keypoints[k, 0])))
            if key in nearest and obs.depth[nearest[key]] <= obs.depth[k]:
                continue
            nearest[key] = k
        truth = obs.points_camera[[nearest[(r, c)] for r, c in zip(rows, columns)]]
        np.testing.assert_allclose(points[:, 2], truth[:, 2], rtol=1e-6)  # float32 storage of the points
        limit = 0.5 * truth[:, 2] / K[0, 0] + 1e-5 * truth[:, 2]
        lateral = np.abs(points[:, :2] - truth[:, :2]).max(axis=1)
        keypoint_offset = np.abs(obs.keypoints - obs.projected)[[nearest[(r, c)] for r, c in zip(rows, columns)]]
        assert np.all(lateral <= limit + keypoint_offset.max(axis=1) * truth[:, 2] / K[0, 0])


def test_the_shared_scene_round_trips_through_binary(maupertuis, tmp_path):
    model = read_colmap_model(maupertuis)
    write_colmap_model(model, tmp_path)
    again = read_colmap_model(tmp_path)
    _assert_same_model(model, again)
    for image_id in model.images:
        a, b = view_depth(model, image_id)[0], view_depth(again, image_id)[0]
        np.testing.assert_array_equal(a, b)
