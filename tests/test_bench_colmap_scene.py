"""bench.colmap_scene: the projection helpers on a hand-made two-camera set-up, and the quick run on the scene."""

import importlib

import numpy as np
import pytest

from sparsedepth.io.colmap import Camera, ColmapModel, Image, Points3D, view_depth

colmap_scene = importlib.import_module("bench.colmap_scene")

#: Camera 1: the world frame itself; camera 2: turned -90 degrees about y (x_c = -Z, y_c = Y, z_c = X) then moved.
R2 = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
T2 = np.array([12.0, 0.0, 4.0])
QVEC2 = np.array([np.sqrt(0.5), 0.0, -np.sqrt(0.5), 0.0])  # cos(-45°) + sin(-45°) j
K1 = np.array([[100.0, 0.0, 50.0], [0.0, 100.0, 40.0], [0.0, 0.0, 1.0]])
K2 = np.array([[200.0, 0.0, 30.0], [0.0, 200.0, 20.0], [0.0, 0.0, 1.0]])
POINT = np.array([1.0, 2.0, 10.0])
# By hand: in camera 1 the point is (1, 2, 10): u = 100 * 1/10 + 50 = 60, v = 100 * 2/10 + 40 = 60, z = 10.
# In camera 2: R2 X + t2 = (-10 + 12, 2, 1 + 4) = (2, 2, 5): u = 200 * 2/5 + 30 = 110, v = 200 * 2/5 + 20 = 100, z = 5.
PIXEL1, PIXEL2 = (60.0, 60.0, 10.0), (110.0, 100.0, 5.0)


def two_camera_model():
    """The set-up above as a COLMAP model: the point observed by both, keypoints in COLMAP's (+0.5) convention."""
    cameras = {1: Camera(1, "PINHOLE", 100, 80, np.array([100.0, 100.0, 50.5, 40.5])),
               2: Camera(2, "PINHOLE", 140, 120, np.array([200.0, 200.0, 30.5, 20.5]))}
    images = {1: Image(1, np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), 1, "a.png", np.array([[60.5, 60.5]]),
                       np.array([7])),
              2: Image(2, QVEC2, T2, 2, "b.png", np.array([[110.5, 100.5]]), np.array([7]))}
    points = Points3D(ids=np.array([7]), xyz=POINT[None], rgb=np.zeros((1, 3), np.uint8), error=np.array([0.0]),
                      track_lengths=np.array([2]), track_image_ids=np.array([1, 2]),
                      track_point2d_idxs=np.array([0, 0]))
    return ColmapModel(cameras, images, points)


def test_project_and_backproject_a_known_point():
    u, v, z = colmap_scene.project(POINT, K1)
    np.testing.assert_allclose([u, v, z], PIXEL1, rtol=1e-12)
    u, v, z = colmap_scene.project(POINT @ R2.T + T2, K2)
    np.testing.assert_allclose([u, v, z], PIXEL2, rtol=1e-12)
    np.testing.assert_allclose(colmap_scene.backproject(*PIXEL1, K1), POINT, rtol=1e-12)
    np.testing.assert_allclose(colmap_scene.backproject(*PIXEL2, K2), [2.0, 2.0, 5.0], rtol=1e-12)
    u, v, z = colmap_scene.project(np.array([[1.0, 2.0, -3.0]]), K1)  # behind the camera
    assert np.isnan(u[0]) and np.isnan(v[0]) and z[0] == -3.0


def test_transfer_between_two_known_cameras():
    pose1, pose2 = (np.eye(3), np.zeros(3)), (R2, T2)
    np.testing.assert_allclose(colmap_scene.transfer(*PIXEL1, K1, pose1, K2, pose2), PIXEL2, rtol=1e-12)
    np.testing.assert_allclose(colmap_scene.transfer(*PIXEL2, K2, pose2, K1, pose1), PIXEL1, rtol=1e-12)
    # arrays of pixels: each moves on its own
    u, v, z = colmap_scene.transfer(np.array([60.0, 50.0]), np.array([60.0, 40.0]), np.array([10.0, 10.0]), K1,
                                    pose1, K2, pose2)
    # the second pixel is the optical axis of camera 1: X = (0, 0, 10) -> (-10 + 12, 0, 4) in camera 2
    np.testing.assert_allclose(u, [110.0, 200.0 * 2 / 4 + 30], rtol=1e-12)
    np.testing.assert_allclose(v, [100.0, 20.0], rtol=1e-12)
    np.testing.assert_allclose(z, [5.0, 4.0], rtol=1e-12)


def test_pose_and_intrinsics_from_a_colmap_model():
    model = two_camera_model()
    R, t = colmap_scene.view_pose(model, "b.png")
    np.testing.assert_allclose(R, R2, atol=1e-15)
    np.testing.assert_array_equal(t, T2)
    _, mask, K = view_depth(model, 2)
    np.testing.assert_array_equal(K, K2)  # integer pixel centres: COLMAP's 30.5 is 30
    assert mask[100, 110] and mask.sum() == 1  # the keypoint (110.5, 100.5) is the centre of row 100, column 110
    check = colmap_scene.check_projection(model)
    assert check["projection"] <= 1e-12 and check["transfer_mean"] <= 1e-12 and check["pairs"] == 2


def test_projection_check_catches_a_keypoint_off_its_point():
    model = two_camera_model()
    slipped = dict(model.images)
    slipped[2] = Image(2, QVEC2, T2, 2, "b.png", np.array([[110.5 + 6.0, 100.5]]), np.array([7]))
    # transferred 1 -> 2 it misses by 6 px; 2 -> 1 by 0.34 px (that slip is mostly along camera 1's axis): mean 3.2 px
    with pytest.raises(AssertionError, match="mean keypoint-transfer error"):
        colmap_scene.check_projection(ColmapModel(model.cameras, slipped, model.points3d))


def test_depth_at_and_consistency_of_one_plane_seen_twice():
    depth = np.arange(12.0).reshape(3, 4)
    values = colmap_scene.depth_at(depth, np.array([0.4, 2.6, 3.49, -0.6, 4.0]), np.array([0.0, 1.4, 2.0, 0.0, 0.0]))
    np.testing.assert_array_equal(values[:3], [0.0, 7.0, 11.0])
    assert np.isnan(values[3]) and np.isnan(values[4])
    # a fronto-parallel plane Z = 10 seen by camera 1 and by camera 1 moved 1 unit along x: the maps agree exactly
    K = np.array([[50.0, 0.0, 20.0], [0.0, 50.0, 15.0], [0.0, 0.0, 1.0]])
    plane = np.full((30, 40), 10.0)
    relative = colmap_scene.consistency(plane, K, (np.eye(3), np.zeros(3)), plane, K,
                                        (np.eye(3), np.array([-1.0, 0.0, 0.0])))
    # 1 unit at depth 10 is 5 pixels: u' = u - 5, so the 5 left-most columns (u' rounds below 0) land outside
    assert np.all(np.isnan(relative[:, :5])) and np.all(relative[:, 5:] == 0.0)
    plane[:, -1] = np.nan  # no depth in the last column of the first map: not measured
    relative = colmap_scene.consistency(plane, K, (np.eye(3), np.zeros(3)), plane * 1.1, K,
                                        (np.eye(3), np.zeros(3)))
    np.testing.assert_allclose(relative[:, :-1], 0.1, rtol=1e-12)
    assert np.all(np.isnan(relative[:, -1]))


def test_inside_hull_of_three_points():
    mask = np.zeros((5, 6), bool)
    mask[0, 0] = mask[0, 4] = mask[4, 0] = True  # the triangle x + y <= 4 (x columns, y rows)
    rows, columns = np.indices(mask.shape)
    np.testing.assert_array_equal(colmap_scene.inside_hull(mask), rows + columns <= 4)


def test_downscaled_scene_keeps_points_on_their_keypoints():
    model = two_camera_model()
    images = {"a.png": np.zeros((80, 100, 3), np.uint8), "b.png": np.full((120, 140, 3), 200, np.uint8)}
    small, reduced = colmap_scene.downscale_scene(model, images, 2)
    assert reduced["b.png"].shape == (60, 70, 3) and np.all(reduced["b.png"] == 200)
    assert small.cameras[2].width == 70 and small.cameras[2].height == 60
    check = colmap_scene.check_projection(small)
    assert check["projection"] <= 1e-12 and check["transfer_mean"] <= 1e-12
    _, mask, K = view_depth(small, 2)
    assert mask[50, 55]  # 100.5 / 2 = 50.25, 110.5 / 2 = 55.25


def test_quick_run_has_both_parts(shared_data, tmp_path):
    if not (shared_data / colmap_scene.SCENE / colmap_scene.MODEL_FOLDER).is_dir():
        pytest.skip(f"{shared_data / colmap_scene.SCENE} is not in the shared data folder")
    out = tmp_path / "colmap_scene.md"
    assert colmap_scene.main(["--quick", "--out", str(out)]) == 0
    text = out.read_text()
    assert "`python -m bench.colmap_scene --quick --out" in text
    assert "## SfM-like inputs on RGB-D frames with ground truth" in text
    assert "## The real scene: leave-points-out accuracy" in text
    assert "## The real scene: multi-view consistency" in text
    assert "all ordered pairs (pooled)" in text and "wall time" in text
    assert "lands on its keypoint there with a mean error of" in text
