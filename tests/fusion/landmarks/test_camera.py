"""Tests of fusion.landmarks.camera: intrinsics checks, the camera mount frames, the renderer."""

from __future__ import annotations

import math
import re

import cv2
import numpy as np
import pytest

from fusion.exceptions import CameraOptionError, CameraShapeError
from fusion.landmarks.camera import (
    OPTICAL_TO_ROBOT,
    CameraIntrinsics,
    CameraMount,
    SyntheticCamera,
    check_camera_matrix,
    check_dist_coeffs,
    world_T_camera,
)
from fusion.landmarks.marker_map import MarkerLandmark, MarkerMap
from lti_motion.exceptions import ShapeError

K500 = CameraIntrinsics.pinhole(fx_px=500.0)


def _facing_origin(marker_id: int, x: float, y: float, z: float = 0.2,
                   turn_rad: float = 0.0) -> MarkerLandmark:
    """A marker at (x, y, z) whose face looks at the world origin, turned by ``turn_rad``."""
    return MarkerLandmark(marker_id, x, y, z_m=z, yaw_rad=math.atan2(-y, -x) + turn_rad)


# --- intrinsics ---------------------------------------------------------------------------

@pytest.mark.parametrize("bad_shape", [(2, 2), (3,), (3, 4), (9,), (1, 3, 3)])
def test_camera_matrix_of_wrong_shape_names_both_shapes(bad_shape):
    with pytest.raises(CameraShapeError, match=r"\(3, 3\).*" + re.escape(str(bad_shape))):
        check_camera_matrix(np.ones(bad_shape))


@pytest.mark.parametrize("k", [
    [[-500.0, 0, 320], [0, 500, 240], [0, 0, 1]],
    [[500.0, 0, 320], [0, 500, 240], [0, 0, 2]],
    [[500.0, 0, 320], [0, np.nan, 240], [0, 0, 1]],
])
def test_camera_matrix_with_bad_values_is_an_option_error(k):
    with pytest.raises(CameraOptionError, match="K must be"):
        check_camera_matrix(k)


@pytest.mark.parametrize("bad", [np.zeros(3), np.zeros(6), np.zeros((2, 5))])
def test_distortion_of_wrong_length(bad):
    with pytest.raises(CameraShapeError, match=r"length \(0, 4, 5, 8, 12, 14\)"):
        check_dist_coeffs(bad)


def test_errors_are_value_errors_and_shape_errors():
    assert issubclass(CameraShapeError, ValueError) and issubclass(CameraShapeError, ShapeError)
    assert issubclass(CameraOptionError, ValueError)


def test_distortion_accepts_row_and_column_vectors():
    assert check_dist_coeffs(np.zeros((1, 5))).shape == (5,)
    assert check_dist_coeffs(np.zeros((4, 1))).shape == (4,)
    assert check_dist_coeffs(None).shape == (0,)


def test_intrinsics_compare_by_value():
    assert CameraIntrinsics.pinhole(fx_px=500.0) == K500
    assert CameraIntrinsics.pinhole(fx_px=501.0) != K500
    assert CameraIntrinsics.pinhole(fx_px=500.0, dist_coeffs=np.full(5, 0.01)) != K500


def test_intrinsics_reject_a_bad_size():
    with pytest.raises(CameraOptionError, match="width_px"):
        CameraIntrinsics(np.eye(3), 0, 480)


def test_project_matches_opencv_with_distortion(rng):
    cam = CameraIntrinsics.pinhole(fx_px=480.0, fy_px=470.0, cx_px=330.0, cy_px=235.0,
                                   dist_coeffs=np.array([-0.2, 0.05, 1e-3, -2e-3, 0.0]))
    pts = np.column_stack([rng.uniform(-0.5, 0.5, (20, 2)), rng.uniform(1.0, 3.0, 20)])
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.camera_matrix, cam.dist_coeffs)
    np.testing.assert_allclose(cam.project(pts), ref.reshape(-1, 2), atol=1e-9)
    plain = CameraIntrinsics.pinhole(fx_px=480.0)
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), plain.camera_matrix, None)
    np.testing.assert_allclose(plain.project(pts), ref.reshape(-1, 2), atol=1e-9)


# --- mount and frames ---------------------------------------------------------------------

@pytest.mark.parametrize("yaw, pitch", [(0.0, 0.0), (0.4, 0.0), (-0.3, 0.2), (2.0, -0.5)])
def test_mount_rotation_is_a_rotation(yaw, pitch):
    r = CameraMount(yaw_rad=yaw, pitch_rad=pitch).robot_R_camera()
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)


def test_mount_angles_turn_the_optical_axis_the_documented_way():
    assert np.allclose(OPTICAL_TO_ROBOT @ [0, 0, 1], [1, 0, 0])      # optical z = forward
    assert np.allclose(OPTICAL_TO_ROBOT @ [1, 0, 0], [0, -1, 0])     # optical x = right
    left = CameraMount(yaw_rad=0.3).robot_R_camera()[:, 2]
    down = CameraMount(pitch_rad=0.3).robot_R_camera()[:, 2]
    assert left[1] > 0 and math.atan2(left[1], left[0]) == pytest.approx(0.3)
    assert down[2] < 0 and math.asin(-down[2]) == pytest.approx(0.3)


def test_world_T_camera_for_a_turned_robot():
    r, t = world_T_camera(CameraMount(x_m=0.1, z_m=0.2), np.array([1.0, 2.0, math.pi / 2]))
    np.testing.assert_allclose(t, [1.0, 2.1, 0.2], atol=1e-12)
    np.testing.assert_allclose(r[:, 2], [0.0, 1.0, 0.0], atol=1e-12)   # looks along world +y
    np.testing.assert_allclose(r[:, 1], [0.0, 0.0, -1.0], atol=1e-12)  # image down = world down


def test_world_T_camera_checks_the_pose():
    with pytest.raises(CameraShapeError, match=r"\(3,\).*\(2,\)"):
        world_T_camera(CameraMount(), np.zeros(2))
    with pytest.raises(CameraOptionError, match="finite"):
        world_T_camera(CameraMount(), np.array([0.0, np.inf, 0.0]))


# --- renderer -----------------------------------------------------------------------------

def test_render_is_seeded_and_of_the_camera_size():
    mm = MarkerMap([_facing_origin(1, 2.0, 0.0)])
    cam = SyntheticCamera(CameraIntrinsics.pinhole(fx_px=400.0, width_px=320, height_px=240))
    a = cam.render(mm, np.zeros(3), np.random.default_rng(5))
    b = cam.render(mm, np.zeros(3), np.random.default_rng(5))
    c = cam.render(mm, np.zeros(3), np.random.default_rng(6))
    assert a.shape == (240, 320) and a.dtype == np.uint8
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_rendered_edges_sit_on_the_true_projection():
    """Without blur and noise a pixel's grey is the area it sees: the edge is in place."""
    mm = MarkerMap([MarkerLandmark(3, 1.0, 0.0, z_m=0.2, yaw_rad=math.pi)], marker_size_m=0.15)
    cam = SyntheticCamera(K500, mount=CameraMount(x_m=0.0), blur_sigma_px=0.0,
                          noise_sigma_grey=0.0, supersample=4)
    img = cam.render(mm, np.zeros(3), np.random.default_rng(0)).astype(float)
    corners = cam.visible_corners_px(mm, np.zeros(3))[3]
    left = corners[0, 0]                              # the black square's left edge [px]
    col = round(left)                                 # the pixel the edge crosses
    row = round(corners[0, 1]) + 3                    # a row through the black border
    black_fraction = (col + 0.5) - left
    expected = cam.white_grey + black_fraction * (cam.black_grey - cam.white_grey)
    assert img[row, col] == pytest.approx(expected, abs=1.0)     # 1 grey level ~ 0.005 px


def test_image_noise_is_white_gaussian_of_the_given_sigma():
    """Noise by inversion of a 16-bit quantile table (module docstring). On a blank image
    the difference to the noiseless render is ``rint(g + n) - rint(g)`` for the background
    grey ``g``: its distribution matches the same difference with ``Generator.normal`` draws
    and fractions of ``g`` spread over [0, 1) (the background is a vertical gradient), and
    neighbours along a row are uncorrelated once the row's own rounding is taken out."""
    sigma = 2.5
    quiet = SyntheticCamera(K500, noise_sigma_grey=0.0)
    noisy = SyntheticCamera(K500, noise_sigma_grey=sigma)
    blank = MarkerMap([])
    base = quiet.render(blank, np.zeros(3), np.random.default_rng(0)).astype(float)
    d = np.concatenate([(noisy.render(blank, np.zeros(3), np.random.default_rng(seed))
                         - base).ravel() for seed in range(4)])      # 1.2 million pixels
    rng = np.random.default_rng(99)
    g = rng.uniform(0.0, 1.0, d.size)
    ref = np.rint(g + rng.normal(0.0, sigma, d.size)) - np.rint(g)
    assert abs(d.mean()) < 0.01
    assert d.std() == pytest.approx(ref.std(), rel=0.005)            # sqrt(sigma^2 + 1/6)
    values = np.arange(-15, 16)
    p_d = np.array([np.mean(d == v) for v in values])
    p_ref = np.array([np.mean(ref == v) for v in values])
    assert np.max(np.abs(p_d - p_ref)) < 0.002, np.round(p_d - p_ref, 4)
    assert np.mean(np.abs(d) >= 3 * sigma) == pytest.approx(np.mean(np.abs(ref) >= 3 * sigma),
                                                            rel=0.1)  # the tails
    img = d[: base.size].reshape(base.shape)
    img = img - img.mean(axis=1, keepdims=True)     # rint(g) - g is the same along a row
    assert abs(np.corrcoef(img[:, :-1].ravel(), img[:, 1:].ravel())[0, 1]) < 0.01


def test_back_facing_and_behind_markers_are_not_drawn():
    cam = SyntheticCamera(K500, noise_sigma_grey=0.0)
    empty = cam.render(MarkerMap([]), np.zeros(3), np.random.default_rng(0))
    back = MarkerLandmark(1, 2.0, 0.0, yaw_rad=0.0)        # its face looks away from the robot
    behind = MarkerLandmark(2, -2.0, 0.0, yaw_rad=0.0)     # faces the robot, behind the camera
    mm = MarkerMap([back, behind])
    assert np.array_equal(cam.render(mm, np.zeros(3), np.random.default_rng(0)), empty)
    assert cam.visible_corners_px(mm, np.zeros(3)) == {}


def test_a_marker_half_out_of_the_image_is_clipped():
    mm = MarkerMap([_facing_origin(4, 1.0, 0.64, z=0.2)])       # about at the left image edge
    cam = SyntheticCamera(K500, noise_sigma_grey=0.0)
    img = cam.render(mm, np.zeros(3), np.random.default_rng(0))
    assert img[:, :5].min() < 60                                # part of it is in the image
    assert cam.visible_corners_px(mm, np.zeros(3)) == {}        # but not all of it


def test_a_nearer_marker_hides_a_farther_one():
    near, far = _facing_origin(1, 1.0, 0.0), _facing_origin(2, 2.5, 0.0)
    cam = SyntheticCamera(K500, noise_sigma_grey=0.0)
    both = cam.render(MarkerMap([far, near]), np.zeros(3), np.random.default_rng(0))
    alone = cam.render(MarkerMap([near]), np.zeros(3), np.random.default_rng(0))
    assert np.array_equal(both, alone)


def test_rendering_with_distortion_moves_the_marker_where_projection_says(rng):
    dist = np.array([-0.25, 0.08, 0.0, 0.0, 0.0])
    intr = CameraIntrinsics.pinhole(fx_px=500.0, dist_coeffs=dist)
    mm = MarkerMap([_facing_origin(7, 1.2, 0.55)])
    cam = SyntheticCamera(intr, noise_sigma_grey=0.0, blur_sigma_px=0.0)
    img = cam.render(mm, np.zeros(3), rng)
    truth = cam.visible_corners_px(mm, np.zeros(3))[7]
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    corners, ids, _ = det.detectMarkers(img)
    assert ids is not None and ids.ravel().tolist() == [7]
    np.testing.assert_allclose(corners[0].reshape(4, 2), truth, atol=1.0)


@pytest.mark.parametrize("option", [{"blur_sigma_px": -1.0}, {"noise_sigma_grey": np.nan},
                                    {"supersample": 0}, {"near_m": 0.0}, {"white_grey": 300.0}])
def test_bad_render_options(option):
    with pytest.raises(CameraOptionError):
        SyntheticCamera(K500, **option)

