"""Tests of fusion.landmarks.aruco and fusion.landmarks.marker_map: accuracy and covariance on
rendered images, the covariance against numerical derivatives, bad input, map files, unknown
ids."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from fusion.exceptions import (
    CameraOptionError,
    CameraShapeError,
    ImageDtypeError,
    ImageShapeError,
    MarkerMapError,
    MarkerPoseError,
    UnknownLandmarkError,
)
from fusion.landmarks.aruco import (
    CornerNoise,
    MarkerDetector,
    correct_edge_bias,
    detect_markers,
    detection_diagnostics,
    observation_from_corners,
    observations_from_pose,
)
from fusion.landmarks.camera import CameraIntrinsics, CameraMount, SyntheticCamera
from fusion.landmarks.marker_map import MarkerLandmark, MarkerMap, load_marker_map, save_marker_map
from fusion.range_bearing import RangeBearing, range_bearing
from fusion.sensor_pose import SensorPose

K500 = CameraIntrinsics.pinhole(fx_px=500.0)           # 640 x 480, centred, no distortion
MOUNT = CameraMount(x_m=0.1, z_m=0.2)                  # 0.1 m forward, 0.2 m up, looking forward
SIZE_M = 0.15
CHI2_2_954 = 6.18                                      # chi-square, 2 dof, 95.4% ("2 sigma")
N_IMAGES = 120                                         # two markers each: ~240 detections
SCENE_SEED = 20261123
NO_BIAS = CornerNoise(edge_bias_px=0.0, edge_bias_at_20px=0.0)   # for exact corners


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _true_range_bearing(pose: np.ndarray, m: MarkerLandmark,
                        mount: CameraMount = MOUNT) -> tuple[float, float]:
    """Range and bearing of a marker centre from the camera: from the map, the rendering pose
    and the camera's mount only (the camera's foot at pose + R(theta) (x_m, y_m), its axis
    at theta + yaw_rad)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    cam_x = pose[0] + c * mount.x_m - s * mount.y_m
    cam_y = pose[1] + s * mount.x_m + c * mount.y_m
    dx, dy = m.x_m - cam_x, m.y_m - cam_y
    return math.hypot(dx, dy), _wrap(math.atan2(dy, dx) - pose[2] - mount.yaw_rad)


def _random_scene(rng: np.random.Generator) -> tuple[np.ndarray, MarkerMap]:
    """A random robot pose and two markers 1-3 m away, one left and one right of the
    heading, up to 25 deg off it, turned up to 50 deg away from facing the robot."""
    pose = np.array([rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-math.pi, math.pi)])
    markers = []
    for k, (lo, hi) in enumerate([(-25.0, -8.0), (8.0, 25.0)]):
        r, b = rng.uniform(1.0, 3.0), math.radians(rng.uniform(lo, hi))
        x, y = pose[0] + r * math.cos(pose[2] + b), pose[1] + r * math.sin(pose[2] + b)
        facing_robot = math.atan2(pose[1] - y, pose[0] - x)
        markers.append(MarkerLandmark(10 * k + int(rng.integers(0, 10)), x, y,
                                      z_m=rng.uniform(0.1, 0.35),
                                      yaw_rad=facing_robot + math.radians(rng.uniform(-50, 50))))
    return pose, MarkerMap(markers, marker_size_m=SIZE_M)


@pytest.fixture(scope="module")
def rendered() -> dict:
    """Detections on N_IMAGES rendered scenes: errors against the truth, and raw corners."""
    rng = np.random.default_rng(SCENE_SEED)
    cam = SyntheticCamera(K500, mount=MOUNT, blur_sigma_px=0.8, noise_sigma_grey=2.5)
    detector = MarkerDetector(K500, SIZE_M, mount=MOUNT)
    errors, d2, sd, visible, corners, unknown = [], [], [], 0, [], 0
    for _ in range(N_IMAGES):
        pose, mm = _random_scene(rng)
        visible += len(cam.visible_corners_px(mm, pose))
        image = cam.render(mm, pose, rng)
        known, unknown_ids = mm.split_known(detector.detect(image))
        unknown += len(unknown_ids)
        for marker_id, z, cov in known:
            r, b = _true_range_bearing(pose, mm.marker(marker_id))
            e = np.array([z[0] - r, _wrap(z[1] - b)])
            errors.append([e[0] / r, e[1]])
            d2.append(e @ np.linalg.solve(cov, e))
            sd.append(np.sqrt(np.diag(cov)) * [1.0 / r, 1.0])
        ids, raw = detector.detect_corners(image)
        corners += [(_true_range_bearing(pose, mm.marker(i)), c)
                    for i, c in zip(ids, raw, strict=True) if i in mm]
    return {"rel_err": np.array(errors), "d2": np.array(d2), "sd_rel": np.array(sd),
            "visible": visible, "corners": corners, "unknown": unknown}


# --- acceptance on rendered images --------------------------------------------------------

def test_enough_detections_and_almost_all_visible_markers_found(rendered):
    """Markers whose quiet zone reaches within 3 px of the image border may be missed
    (OpenCV's ``minDistanceToBorder``); misread ids would show as unknown."""
    n = len(rendered["d2"])
    assert n >= 200
    assert 0.95 * rendered["visible"] <= n <= rendered["visible"]
    assert rendered["unknown"] == 0


def test_median_range_and_bearing_errors(rendered):
    rel_range, bearing = np.abs(rendered["rel_err"]).T
    assert np.median(rel_range) <= 0.02                # target: at most 2%
    assert np.median(bearing) <= math.radians(1.0)     # target: at most 1 degree
    # What we measure, with margin (docs/aruco.md): 0.1-0.2% and a few thousandths of a degree.
    assert np.median(rel_range) < 0.004 and np.median(bearing) < math.radians(0.02)


def test_covariance_covers_the_error_at_two_sigma(rendered):
    """Mahalanobis distance^2 below chi2(2, 0.954); the per-component 2-sigma test too."""
    assert np.mean(rendered["d2"] < CHI2_2_954) >= 0.90
    per_component = np.all(np.abs(rendered["rel_err"]) < 2 * rendered["sd_rel"], axis=1)
    assert np.mean(per_component) >= 0.90


def test_covariance_is_not_hugely_conservative(rendered):
    """Mean NEES of a consistent 2-D estimate is 2; the defaults buy margin, not a blanket."""
    assert 0.3 < np.mean(rendered["d2"]) < 4.0


def test_without_the_edge_bias_correction_range_is_long_but_within_the_issue(rendered):
    noise = CornerNoise(edge_bias_px=0.0, edge_bias_at_20px=0.0, edge_bias_sigma_px=0.0)
    rel = np.array([observation_from_corners(0, c, K500, marker_size_m=SIZE_M, mount=MOUNT,
                                             noise=noise).range_m[0] / r - 1.0
                    for (r, _), c in rendered["corners"]])
    assert 0.002 < np.mean(rel) < 0.02                # cornerSubPix pulls corners inward
    assert np.median(np.abs(rel)) <= 0.02


# --- covariance model against numerical derivatives --------------------------------------

GEOMETRIES = [  # range [m], bearing [rad], turn away from facing the camera [rad], height [m]
    (1.0, -0.4, 0.0, 0.2),       # head-on: rotation vector far from the singular pi
    (1.6, 0.0, 0.0, 0.2),        # exactly head-on, on the axis
    (2.0, 0.3, 0.7, 0.3),
    (3.0, 0.1, -0.85, 0.1),
    (1.5, -0.2, 0.3, 0.25),
]


def _marker_xy(r, b, mount=MOUNT):
    """Where a marker at range r and bearing b from the camera is, the robot at the origin."""
    return (mount.x_m + r * math.cos(mount.yaw_rad + b),
            mount.y_m + r * math.sin(mount.yaw_rad + b))


def _exact_corners(r, b, turn, z, mount=MOUNT, intr=K500):
    m = MarkerLandmark(1, *_marker_xy(r, b, mount), z_m=z,
                       yaw_rad=mount.yaw_rad + b + math.pi + turn)
    cam = SyntheticCamera(intr, mount=mount)
    return cam.visible_corners_px(MarkerMap([m], marker_size_m=SIZE_M), np.zeros(3))[1]


def _rb(corners):
    o = observation_from_corners(1, corners, K500, marker_size_m=SIZE_M, mount=MOUNT, noise=NO_BIAS)
    return np.array([o.range_m[0], o.bearing_rad[0]])


@pytest.mark.parametrize("r, b, turn, z", GEOMETRIES)
def test_exact_corners_give_the_exact_range_bearing_and_obliquity(r, b, turn, z):
    c = _exact_corners(r, b, turn, z)
    o = observation_from_corners(1, c, K500, marker_size_m=SIZE_M, mount=MOUNT,
                                 noise=NO_BIAS)
    _, obliquity_rad = detection_diagnostics(c, K500, marker_size_m=SIZE_M, mount=MOUNT,
                                             noise=NO_BIAS)
    assert o.range_m[0] == pytest.approx(r, abs=1e-9)
    assert o.bearing_rad[0] == pytest.approx(b, abs=1e-9)
    assert o.sensor_pose == MOUNT.sensor_pose()
    cam_xy = np.array([MOUNT.x_m, 0.0])
    marker_xy = np.array(_marker_xy(r, b))
    to_cam = cam_xy - marker_xy
    to_cam3 = np.append(to_cam, MOUNT.z_m - z)
    normal = np.array([math.cos(b + math.pi + turn), math.sin(b + math.pi + turn), 0.0])
    expected = math.acos(min(1.0, normal @ to_cam3 / np.linalg.norm(to_cam3)))
    assert obliquity_rad == pytest.approx(expected, abs=1e-6)


@pytest.mark.parametrize("r, b, turn, z", GEOMETRIES)
def test_covariance_matches_numerical_propagation_through_solvepnp(r, b, turn, z):
    """Sigma = sn^2 J J^T + sb^2 g g^T with J = d(r, b)/d(corners) and g = d(r, b)/d(edge bias)
    by central differences of the whole estimator (solvePnP IPPE_SQUARE + LM refinement)."""
    c = _exact_corners(r, b, turn, z)
    h = 1e-3
    jac = np.empty((2, 8))
    for k in range(8):
        dc = np.zeros(8)
        dc[k] = h
        jac[:, k] = (_rb(c + dc.reshape(4, 2)) - _rb(c - dc.reshape(4, 2))) / (2 * h)
    g = (_rb(correct_edge_bias(c, h)) - _rb(correct_edge_bias(c, -h))) / (2 * h)
    noise = CornerNoise(sigma_px=0.3, sigma_at_20px=0.0, edge_bias_px=0.0,
                        edge_bias_at_20px=0.0, edge_bias_sigma_px=0.2)
    numeric = 0.3 ** 2 * jac @ jac.T + 0.2 ** 2 * np.outer(g, g)
    o = observation_from_corners(1, c, K500, marker_size_m=SIZE_M, mount=MOUNT, noise=noise)
    scale = np.sqrt(np.outer(np.diag(numeric), np.diag(numeric)))
    np.testing.assert_allclose(o.cov[0] / scale, numeric / scale, atol=0.02)


def test_an_exactly_symmetric_view_still_gives_a_pose():
    """OpenCV's IPPE_SQUARE returns NaN for these corners (head-on, symmetric about the
    image row through the principal point); the general IPPE fallback solves them."""
    raw = np.array([[221.21523696611615, 197.24727198810476],
                    [305.5341623937994, 197.94837001479485],
                    [305.5341623937994, 281.0516299852051],
                    [221.21523696611615, 281.7527280118952]])
    o = observation_from_corners(1, raw, K500, marker_size_m=SIZE_M, mount=MOUNT)
    # the marker 1.0 m from the axle centre, 0.1 rad left (from the camera 0.1 m ahead)
    x = MOUNT.x_m + o.range_m[0] * math.cos(o.bearing_rad[0])
    y = o.range_m[0] * math.sin(o.bearing_rad[0])
    assert math.hypot(x, y) == pytest.approx(1.0, abs=0.01) and abs(math.atan2(y, x) - 0.1) < 1e-3


def test_covariance_grows_with_range_and_obliquity():
    def sd_range(r, turn):
        c = _exact_corners(r, 0.1, turn, 0.2)
        o = observation_from_corners(1, c, K500, marker_size_m=SIZE_M, mount=MOUNT)
        return math.sqrt(o.cov[0, 0, 0])
    assert sd_range(1.0, 0.0) < sd_range(2.0, 0.0) < sd_range(3.0, 0.0)
    assert sd_range(2.0, 0.0) < sd_range(2.0, 0.87)


@pytest.mark.parametrize("r, b, turn, z", GEOMETRIES)
def test_covariance_is_symmetric_positive_definite_and_read_only(r, b, turn, z):
    o = observation_from_corners(1, _exact_corners(r, b, turn, z), K500, marker_size_m=SIZE_M,
                                 mount=MOUNT, index=4)
    assert len(o) == 1 and o.index.tolist() == [4] and o.landmark_id.tolist() == [1]
    assert np.array_equal(o.cov[0], o.cov[0].T)
    assert np.all(np.linalg.eigvalsh(o.cov[0]) > 0)
    with pytest.raises(ValueError, match="read-only"):
        o.cov[0, 0, 0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.range_m = np.ones(1)  # type: ignore[misc]


def test_edge_bias_correction_is_linear_and_invertible(rng):
    c = _exact_corners(2.0, 0.3, 0.7, 0.3) + rng.normal(0.0, 0.2, (4, 2))
    one = correct_edge_bias(c, 1.0) - c
    np.testing.assert_allclose(correct_edge_bias(c, 0.3) - c, 0.3 * one, atol=1e-9)
    np.testing.assert_allclose(correct_edge_bias(correct_edge_bias(c, 0.3), -0.3), c, atol=1e-9)


def test_a_mount_yaw_turns_the_bearing():
    """A camera yawed 0.3 rad left, 0.15 m ahead, sees a marker 0.3 rad left of the robot's
    heading (from the camera) at the image centre: bearing 0 in its own frame, and its
    mount carried, through which the measurement model puts the marker back."""
    mount = CameraMount(x_m=0.15, y_m=0.05, z_m=0.2, yaw_rad=0.3, pitch_rad=0.1)
    m = MarkerLandmark(1, *_marker_xy(2.0, 0.0, mount), z_m=0.2 + 2.0 * math.tan(-0.1),
                       yaw_rad=0.3 + math.pi)
    c = SyntheticCamera(K500, mount=mount).visible_corners_px(
        MarkerMap([m], marker_size_m=SIZE_M), np.zeros(3))[1]
    assert np.allclose(c.mean(axis=0), K500.camera_matrix[:2, 2], atol=1.0)   # image centre
    o = observation_from_corners(1, c, K500, marker_size_m=SIZE_M, mount=mount,
                                 noise=NO_BIAS)
    assert o.bearing_rad[0] == pytest.approx(0.0, abs=1e-9)
    assert o.range_m[0] == pytest.approx(2.0, abs=1e-9)
    assert o.sensor_pose == SensorPose(0.15, 0.05, 0.3)
    np.testing.assert_allclose(
        range_bearing(np.zeros(3), np.array([m.x_m, m.y_m]), sensor=o.sensor_pose),
        [o.range_m[0], o.bearing_rad[0]], atol=1e-9)


# --- distortion ---------------------------------------------------------------------------

def test_detection_through_lens_distortion_is_accurate():
    intr = CameraIntrinsics.pinhole(fx_px=500.0, dist_coeffs=np.array([-0.2, 0.05, 0, 0, 0]))
    cam = SyntheticCamera(intr, mount=MOUNT)
    rng = np.random.default_rng(8)
    detector = MarkerDetector(intr, SIZE_M, mount=MOUNT)
    rel, bear = [], []
    for _ in range(6):
        pose, mm = _random_scene(rng)
        for marker_id, z, _ in observations_from_pose(cam, mm, pose, rng, detector=detector):
            r, b = _true_range_bearing(pose, mm.marker(marker_id))
            rel.append(abs(z[0] / r - 1.0))
            bear.append(abs(_wrap(z[1] - b)))
    assert len(rel) >= 10
    assert np.median(rel) < 0.01 and np.median(bear) < math.radians(0.1)


# --- bad input ----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def detector() -> MarkerDetector:
    return MarkerDetector(K500, SIZE_M, mount=MOUNT)


@pytest.mark.parametrize("image", [
    np.zeros((480, 640), np.uint8),                    # black
    np.full((480, 640), 128, np.uint8),                # uniform grey
    np.full((480, 640, 3), 200, np.uint8),             # uniform BGR
    np.zeros((0, 0), np.uint8),                        # no pixels
    np.zeros((0, 640, 3), np.uint8),
])
def test_empty_images_give_no_detections(detector, image):
    assert len(detector.detect(image)) == 0


@pytest.mark.parametrize("dtype", [np.float64, np.int32, np.uint16, bool])
def test_an_image_of_the_wrong_dtype(detector, dtype):
    with pytest.raises(ImageDtypeError, match=f"uint8.*{np.dtype(dtype)}"):
        detector.detect(np.zeros((480, 640), dtype))


@pytest.mark.parametrize("shape", [(640,), (480, 640, 4), (480, 640, 2), (1, 480, 640, 3)])
def test_an_image_of_the_wrong_shape(detector, shape):
    with pytest.raises(ImageShapeError, match=r"\(H, W\).*" + str(shape[-1])):
        detector.detect(np.zeros(shape, np.uint8))


def test_an_image_of_another_size_than_the_intrinsics(detector):
    with pytest.raises(ImageShapeError, match=r"\(240, 320\).*\(480, 640\)"):
        detector.detect(np.zeros((240, 320), np.uint8))


def test_not_an_array(detector):
    with pytest.raises(ImageDtypeError, match="list"):
        detector.detect([[0, 0], [0, 0]])


def test_input_errors_are_value_errors():
    for cls in (ImageDtypeError, ImageShapeError, CameraShapeError, CameraOptionError,
                MarkerMapError):
        assert issubclass(cls, ValueError)


@pytest.mark.parametrize("k, match", [(np.eye(2), r"\(3, 3\), got \(2, 2\)"),
                                      (np.ones(9), r"\(3, 3\), got \(9,\)")])
def test_intrinsics_of_the_wrong_shape(k, match):
    with pytest.raises(CameraShapeError, match=match):
        detect_markers(np.zeros((480, 640), np.uint8), k, None, marker_size_m=SIZE_M)


def test_distortion_of_the_wrong_shape():
    with pytest.raises(CameraShapeError, match=r"got shape \(3,\)"):
        detect_markers(np.zeros((480, 640), np.uint8), K500.camera_matrix, np.zeros(3),
                       marker_size_m=SIZE_M)


def test_corners_of_the_wrong_shape():
    with pytest.raises(ImageShapeError, match=r"\(4, 2\), got \(3, 2\)"):
        observation_from_corners(0, np.zeros((3, 2)), K500, marker_size_m=SIZE_M, mount=MOUNT)


@pytest.mark.parametrize("corners", [
    np.zeros((4, 2)),                                                  # all in one point
    np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [30.0, 0.0]]),     # collinear
    np.array([[0.0, 10.0], [10.0, 10.0], [10.0, 0.0], [0.0, 0.0]]) + 300.0,   # mirror order
])
def test_degenerate_corners_raise_a_pose_error(corners):
    with pytest.raises(MarkerPoseError):
        observation_from_corners(0, corners, K500, marker_size_m=SIZE_M, mount=MOUNT)


@pytest.mark.parametrize("kwargs, error", [
    ({"marker_size_m": 0.0}, CameraOptionError),
    ({"marker_size_m": SIZE_M, "corner_refinement": "best"}, CameraOptionError),
    ({"marker_size_m": SIZE_M, "dictionary": "DICT_9X9_7"}, MarkerMapError),
])
def test_bad_detector_options(kwargs, error):
    with pytest.raises(error):
        MarkerDetector(K500, **kwargs)


@pytest.mark.parametrize("kwargs", [{"sigma_px": 0.0}, {"edge_bias_px": -0.1},
                                    {"edge_bias_sigma_px": np.nan}])
def test_bad_corner_noise(kwargs):
    with pytest.raises(CameraOptionError, match="CornerNoise"):
        CornerNoise(**kwargs)


# --- the one-call path, colour images, unknown ids ----------------------------------------

def test_observations_from_pose_is_seeded_and_matches_the_detector():
    pose, mm = _random_scene(np.random.default_rng(3))
    cam = SyntheticCamera(K500, mount=MOUNT)
    a = observations_from_pose(cam, mm, pose, np.random.default_rng(9))
    b = observations_from_pose(cam, mm, pose, np.random.default_rng(9))
    image = cam.render(mm, pose, np.random.default_rng(9))
    c = detect_markers(image, K500.camera_matrix, None, marker_size_m=SIZE_M, mount=MOUNT)
    assert isinstance(a, RangeBearing) and len(a) == 2 and a.cov.shape == (2, 2, 2)
    assert a == b == c
    assert a.select([0]) != a.select([1])
    d = detect_markers(image, K500.camera_matrix, None, marker_size_m=SIZE_M, mount=MOUNT,
                       index=31)
    assert d.index.tolist() == [31, 31] and d.with_index(0) == a


def test_grey_bgr_and_single_channel_images_agree(detector):
    pose, mm = _random_scene(np.random.default_rng(4))
    grey = SyntheticCamera(K500, mount=MOUNT).render(mm, pose, np.random.default_rng(1))
    outs = [detector.detect(im) for im in (grey, grey[:, :, None], np.dstack([grey] * 3))]
    assert len(outs[0]) == 2
    assert outs[0] == outs[1] == outs[2]


def test_unknown_ids_in_detections_are_reported():
    mm = MarkerMap([MarkerLandmark(4, 2.0, 0.4, yaw_rad=math.pi),
                    MarkerLandmark(9, 2.5, -0.6, yaw_rad=math.pi - 0.5)], marker_size_m=SIZE_M)
    seen = observations_from_pose(SyntheticCamera(K500, mount=MOUNT), mm, np.zeros(3),
                                  np.random.default_rng(2))
    assert sorted(seen.landmark_id.tolist()) == [4, 9]
    smaller = MarkerMap([mm.marker(9)], marker_size_m=SIZE_M)
    known, unknown = smaller.split_known(RangeBearing.concatenate([seen, seen]))
    assert unknown == (4,)
    assert known.landmark_id.tolist() == [9, 9] and known.cov.shape == (2, 2, 2)
    with pytest.raises(UnknownLandmarkError, match="marker 4 is not in the map"):
        smaller.marker(4)


# --- map files ----------------------------------------------------------------------------

def test_map_round_trip_through_json(tmp_path):
    _, mm = _random_scene(np.random.default_rng(6))
    path = tmp_path / "markers.json"
    save_marker_map(mm, path)
    back = load_marker_map(path)
    assert back == mm and back.ids == mm.ids
    assert json.loads(path.read_text())["format"] == "lti-motion-marker-map"
    lm = back.to_landmark_map()
    assert lm.position(mm.ids[0]).tolist() == mm.markers[0].position_xy_m.tolist()


def test_hand_written_map_with_defaults(tmp_path):
    path = tmp_path / "m.json"
    path.write_text('{"format": "lti-motion-marker-map", "version": 1, "marker_size_m": 0.1,'
                    ' "markers": [{"id": 2, "x_m": 1, "y_m": -1}]}')
    mm = load_marker_map(path)
    assert mm.dictionary == "DICT_4X4_50" and mm.marker(2).z_m == 0.3 and len(mm) == 1


@pytest.mark.parametrize("text, match", [
    ("not json", "not valid JSON"),
    ('{"format": "other", "version": 1}', "expected format"),
    ('{"format": "lti-motion-marker-map", "version": 1, "marker_size_m": 0.1, "markers": '
     '[{"id": 1, "x_m": 0, "y_m": 0}, {"id": 1, "x_m": 1, "y_m": 0}]}', "twice"),
    ('{"format": "lti-motion-marker-map", "version": 1, "marker_size_m": 0.1, "markers": '
     '[{"id": 50, "x_m": 0, "y_m": 0}]}', "outside DICT_4X4_50"),
    ('{"format": "lti-motion-marker-map", "version": 1, "markers": []}', "marker_size_m"),
    ('{"format": "lti-motion-marker-map", "version": 1, "marker_size_m": 0.1, "markers": '
     '[{"id": 1, "x_m": "a", "y_m": 0}]}', r"markers\[0\]"),
])
def test_malformed_map_files(tmp_path, text, match):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(MarkerMapError, match=match):
        load_marker_map(path)
