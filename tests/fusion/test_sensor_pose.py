"""The sensor's mount on the robot (fusion.sensor_pose) and the one range-bearing measurement
model with its Jacobians (fusion.range_bearing.range_bearing_terms): closed-form references,
numerical derivatives, and the mount carried by every RangeBearing operation."""

import math

import numpy as np
import pytest

from fusion.exceptions import LandmarkGeometryError, MeasurementShapeError, NonFiniteInputError
from fusion.range_bearing import (
    RangeBearing,
    range_bearing,
    range_bearing_jacobian,
    range_bearing_terms,
)
from fusion.sensor_pose import CENTRED, SensorPose, as_sensor_pose
from lti_motion.kinematics import wrap_angle

MOUNTS = [CENTRED, SensorPose(0.22, 0.0, 0.0), SensorPose(0.15, -0.05, 0.0),
          SensorPose(-0.1, 0.08, 0.6), SensorPose(0.0, 0.0, -math.pi / 2)]


def _numerical(f, x, eps=1e-6):
    cols = []
    for e in np.eye(len(x)):
        d = f(x + eps * e) - f(x - eps * e)
        d[1] = wrap_angle(d[1])
        cols.append(d / (2 * eps))
    return np.stack(cols, axis=1)


@pytest.mark.parametrize("mount", MOUNTS, ids=repr)
def test_jacobians_match_numerical_derivatives(mount):
    rng = np.random.default_rng(11)
    for _ in range(50):
        pose = np.array([*rng.uniform(-3, 3, 2), rng.uniform(-math.pi, math.pi)])
        lxy = pose[:2] + rng.uniform(0.5, 4.0) * np.array(
            [math.cos(a := rng.uniform(-math.pi, math.pi)), math.sin(a)])
        _, H_pose, H_landmark = range_bearing_terms(pose, lxy, sensor=mount)
        num_pose = _numerical(lambda p, lxy=lxy: range_bearing(p, lxy, sensor=mount), pose)
        num_lm = _numerical(lambda lm, pose=pose: range_bearing(pose, lm, sensor=mount), lxy)
        np.testing.assert_allclose(H_pose, num_pose, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(H_landmark, num_lm, rtol=1e-6, atol=1e-8)
        np.testing.assert_array_equal(range_bearing_jacobian(pose, lxy, sensor=mount), H_pose)


@pytest.mark.parametrize("mount", MOUNTS, ids=repr)
def test_a_mounted_sensor_sees_what_a_robot_at_its_pose_would(mount):
    """Closed form: the sensor is a robot at (x, y) + R(theta) s, heading theta + yaw."""
    rng = np.random.default_rng(3)
    poses = np.column_stack([rng.uniform(-3, 3, (40, 2)), rng.uniform(-4, 4, 40)])
    lxy = rng.uniform(-5, 5, (40, 2))
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    sensor = np.column_stack([poses[:, 0] + c * mount.x_m - s * mount.y_m,
                              poses[:, 1] + s * mount.x_m + c * mount.y_m,
                              poses[:, 2] + mount.yaw_rad])
    d = lxy - sensor[:, :2]
    expected = np.column_stack([np.hypot(d[:, 0], d[:, 1]),
                                wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - sensor[:, 2])])
    got = range_bearing(poses, lxy, sensor=mount)        # batched
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(range_bearing(sensor, lxy), expected, rtol=1e-12, atol=1e-12)


def test_the_centred_jacobian_is_the_textbook_one():
    pose, lxy = np.array([1.0, -0.5, 0.4]), np.array([3.0, 1.0])
    dx, dy = 2.0, 1.5
    q = dx * dx + dy * dy
    r = math.sqrt(q)
    np.testing.assert_allclose(range_bearing_jacobian(pose, lxy),
                               [[-dx / r, -dy / r, 0.0], [dy / q, -dx / q, -1.0]], rtol=1e-12)


def test_a_sensor_on_the_landmark_is_refused_not_a_nan():
    pose, mount = np.array([1.0, 1.0, math.pi / 2]), SensorPose(0.2, 0.0, 0.0)
    with pytest.raises(LandmarkGeometryError, match="stands on a landmark"):
        range_bearing_jacobian(pose, np.array([1.0, 1.2]), sensor=mount)
    z = range_bearing(pose, np.array([1.0, 1.2]), sensor=mount)
    assert np.all(np.isfinite(z)) and z[0] > 0
    range_bearing_jacobian(pose, np.array([1.0, 1.2]))   # the axle centre is 0.2 m away


@pytest.mark.parametrize(("value", "error", "match"), [
    ((0.1, 0.0), MeasurementShapeError, "three numbers"),
    ("front", MeasurementShapeError, "three numbers"),
    ((0.1, math.nan, 0.0), NonFiniteInputError, "y_m must be finite"),
])
def test_bad_mounts_name_the_problem(value, error, match):
    with pytest.raises(error, match=match):
        as_sensor_pose(value)
    with pytest.raises(error, match=match):
        RangeBearing(0, [1], [1.0], [0.0], sensor_pose=value)


def test_every_operation_keeps_the_mount():
    mount = SensorPose(0.15, 0.0, 0.0)
    obs = RangeBearing([2, 1, 2], [4, 5, 6], [1.0, 2.0, 3.0], [0.1, 0.2, 0.3],
                       sensor_pose=(0.15, 0.0, 0.0))
    assert obs.sensor_pose == mount and RangeBearing(0, [1], [1.0], [0.0]).sensor_pose is CENTRED
    assert obs.select([0]).sensor_pose == mount
    assert obs.with_index(7).sensor_pose == mount
    assert all(g.sensor_pose == mount for g in obs.by_index().values())
    both = RangeBearing.concatenate([obs.select([0]), obs.select([1, 2])])
    assert both == obs
    assert obs != RangeBearing([2, 1, 2], [4, 5, 6], [1.0, 2.0, 3.0], [0.1, 0.2, 0.3])
    with pytest.raises(MeasurementShapeError, match="different mount poses"):
        RangeBearing.concatenate([obs, RangeBearing(3, [1], [1.0], [0.0])])
