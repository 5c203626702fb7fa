"""Tests of lti_motion.kinematics: closed-form motions, invariants, Jacobians."""

from __future__ import annotations

import numpy as np
import pytest

from lti_motion.exceptions import NonFiniteError, ShapeError
from lti_motion.kinematics import (
    body_from_wheel,
    integrate_poses,
    pose_step,
    pose_step_jacobians,
    pose_step_terms,
    wheel_from_body,
    wrap_angle,
)
from lti_motion.recordings.ticks import body_speeds_from_ticks


def _step_sequentially(
    speeds: np.ndarray, dt_s: np.ndarray | float, start: np.ndarray
) -> np.ndarray:
    dt = np.broadcast_to(dt_s, speeds.shape[:-1])
    poses = [np.asarray(start, dtype=float)]
    for k in range(speeds.shape[0]):
        poses.append(pose_step(poses[-1], speeds[k, 0], speeds[k, 1], dt[k]))
    return np.array(poses)


def _numerical_jacobians(pose, v, w, dt, eps=1e-6):
    """Central differences of pose_step in (x, y, theta) and (v, w)."""
    f_pose = np.empty((3, 3))
    for j in range(3):
        d = np.zeros(3)
        d[j] = eps
        f_pose[:, j] = (pose_step(pose + d, v, w, dt) - pose_step(pose - d, v, w, dt)) / (2 * eps)
    f_speed = np.empty((3, 2))
    f_speed[:, 0] = (pose_step(pose, v + eps, w, dt) - pose_step(pose, v - eps, w, dt)) / (2 * eps)
    f_speed[:, 1] = (pose_step(pose, v, w + eps, dt) - pose_step(pose, v, w - eps, dt)) / (2 * eps)
    return f_pose, f_speed


@pytest.mark.parametrize(
    ("angle", "expected"),
    [
        (0.0, 0.0),
        (np.pi, np.pi),
        (-np.pi, np.pi),
        (3 * np.pi, np.pi),
        (2 * np.pi, 0.0),
        (-0.5, -0.5),
        (7.0, 7.0 - 2 * np.pi),
        (-1e-17, -1e-17),
    ],
)
def test_wrap_angle_range(angle, expected):
    assert wrap_angle(angle) == pytest.approx(expected, abs=1e-15)


def test_wrap_angle_is_half_open(rng):
    a = wrap_angle(rng.uniform(-50, 50, 10_000))
    assert np.all(a > -np.pi) and np.all(a <= np.pi)


def test_wheel_body_round_trip(rng):
    wheel = rng.normal(0.0, 0.3, (4, 5, 2))
    body = body_from_wheel(wheel, wheel_base_m=0.235)
    np.testing.assert_allclose(wheel_from_body(body, wheel_base_m=0.235), wheel, atol=1e-15)
    # pure spin: wheels opposite -> v = 0, w = 2 v_wheel / b
    np.testing.assert_allclose(
        body_from_wheel([-0.1, 0.1], wheel_base_m=0.2), [0.0, 1.0], atol=1e-15
    )


@pytest.mark.parametrize("bad", [0.0, -0.3, np.nan])
def test_wheel_base_must_be_positive(bad):
    with pytest.raises(ValueError, match="wheel_base_m"):
        body_from_wheel([0.1, 0.2], wheel_base_m=bad)
    with pytest.raises(ValueError, match="wheel_base_m"):
        wheel_from_body([0.1, 0.2], wheel_base_m=bad)


def test_wheel_body_shape_errors():
    with pytest.raises(ShapeError, match=r"\(\.\.\., 2\).*\(4, 3\)"):
        body_from_wheel(np.zeros((4, 3)), wheel_base_m=0.2)
    with pytest.raises(ShapeError, match=r"got \(3,\)"):
        wheel_from_body(np.zeros(3), wheel_base_m=0.2)


def test_odometry_uses_kinematics():
    ticks = np.array([[0, 0], [10, 30], [65530, 50]])  # left wraps backwards
    t_s = np.array([0.0, 0.1, 0.2])
    body = body_speeds_from_ticks(ticks, t_s, m_per_tick=1e-3, wheel_base_m=0.2)
    wheel = np.array([[0.1, 0.3], [-0.16, 0.2]])
    np.testing.assert_allclose(body, body_from_wheel(wheel, wheel_base_m=0.2), atol=1e-12)


def test_straight_line():
    pose = pose_step(np.array([1.0, 2.0, np.pi / 6]), 0.5, 0.0, 2.0)
    np.testing.assert_allclose(pose, [1.0 + np.cos(np.pi / 6), 2.0 + 0.5, np.pi / 6], atol=1e-15)


def test_constant_turn_full_circle_returns_to_start():
    n = 1000
    radius, v = 0.7, 0.3
    w = v / radius
    dt = 2 * np.pi / w / n
    start = np.array([0.4, -1.2, 2.0])
    poses = integrate_poses(np.tile([v, w], (n, 1)), dt, initial_pose=start)
    np.testing.assert_allclose(poses[-1, :2], start[:2], rtol=0.0, atol=1e-12)
    assert poses[-1, 2] == pytest.approx(start[2] + 2 * np.pi, abs=1e-12)
    # every pose lies on the circle of radius v / w around the centre
    centre = start[:2] + radius * np.array([-np.sin(start[2]), np.cos(start[2])])
    np.testing.assert_allclose(np.linalg.norm(poses[:, :2] - centre, axis=1), radius, atol=1e-12)


def test_single_step_matches_paper_eq11_arc_branch():
    x, y, th, v, w, dt = 0.3, -0.2, 0.8, 0.4, 1.3, 0.7
    expected = [
        x + v / w * (np.sin(th + w * dt) - np.sin(th)),
        y - v / w * (np.cos(th + w * dt) - np.cos(th)),
        th + w * dt,
    ]
    np.testing.assert_allclose(pose_step([x, y, th], v, w, dt), expected, atol=1e-15)


def test_pure_rotation_keeps_position():
    poses = integrate_poses(np.tile([0.0, 2.0], (50, 1)), 0.1, initial_pose=[1.0, 2.0, 0.0])
    np.testing.assert_array_equal(poses[:, :2], np.tile([1.0, 2.0], (51, 1)))
    assert poses[-1, 2] == pytest.approx(10.0, abs=1e-12)


def test_heading_is_not_wrapped():
    poses = integrate_poses(np.tile([0.0, 1.0], (10, 1)), 1.0)
    assert poses[-1, 2] == pytest.approx(10.0)
    assert wrap_angle(poses[-1, 2]) == pytest.approx(10.0 - 4 * np.pi)


def test_w_zero_and_tiny_w_agree():
    pose = np.array([0.1, 0.2, 0.3])
    straight = pose_step(pose, 0.5, 0.0, 0.02)
    for w in (1e-12, -1e-12):
        np.testing.assert_allclose(pose_step(pose, 0.5, w, 0.02), straight, rtol=0.0, atol=1e-12)
    j0 = pose_step_jacobians(pose, 0.5, 0.0, 0.02)
    j1 = pose_step_jacobians(pose, 0.5, 1e-12, 0.02)
    for a, b in zip(j0, j1, strict=True):
        np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12)


def test_integrate_matches_repeated_pose_step(rng):
    n = 500
    speeds = np.column_stack([rng.normal(0.2, 0.1, n), rng.normal(0.0, 1.0, n)])
    speeds[::7, 1] = 0.0  # exact straight segments mixed in
    dt = rng.uniform(0.012, 0.018, n)  # jittered frame times
    start = np.array([0.5, -0.3, 1.0])
    np.testing.assert_allclose(
        integrate_poses(speeds, dt, initial_pose=start),
        _step_sequentially(speeds, dt, start),
        rtol=0.0,
        atol=1e-12,
    )


def test_integrate_broadcasts_over_batch(rng):
    speeds = rng.normal(0.0, 0.5, (3, 4, 20, 2))
    starts = rng.normal(0.0, 1.0, (4, 3))  # broadcast over the first batch axis
    poses = integrate_poses(speeds, 0.015, initial_pose=starts)
    assert poses.shape == (3, 4, 21, 3)
    for i in range(3):
        for j in range(4):
            np.testing.assert_allclose(
                poses[i, j], _step_sequentially(speeds[i, j], 0.015, starts[j]), atol=1e-12
            )
    # one speed sequence, several step lengths
    per_dt = integrate_poses(speeds[0, 0], np.array([[0.01], [0.02]]))
    assert per_dt.shape == (2, 21, 3)
    np.testing.assert_allclose(per_dt[1], integrate_poses(speeds[0, 0], 0.02), atol=1e-15)


def test_pose_step_broadcasts(rng):
    poses = rng.normal(size=(5, 3))
    v = rng.normal(size=5)
    out = pose_step(poses, v, 0.4, 0.1)
    assert out.shape == (5, 3)
    for k in range(5):
        np.testing.assert_array_equal(out[k], pose_step(poses[k], v[k], 0.4, 0.1))
    assert pose_step(np.zeros(3), np.ones((2, 4)), 0.0, 1.0).shape == (2, 4, 3)


def test_pose_step_without_broadcasting_equals_the_broadcast_path(rng):
    """Inputs of the pose's batch shape skip the broadcasting (the per-step case); the
    same numbers broadcast from other shapes give the same poses bit for bit."""
    poses = rng.normal(size=(6, 3))
    v, w = rng.normal(size=6), rng.normal(size=6)
    w[0] = 0.0
    direct = pose_step(poses, v, w, 0.015)
    np.testing.assert_array_equal(direct, pose_step(poses[None], v[None], w, 0.015)[0])
    every = pose_step(poses, v[:, None], w[:, None], np.full((1, 1), 0.015))  # (6, 6, 3)
    np.testing.assert_array_equal(direct, every[np.arange(6), np.arange(6)])
    with pytest.raises(ShapeError, match="do not broadcast"):
        pose_step(poses, v[:4], w, 0.015)


def test_integrate_empty_sequence():
    poses = integrate_poses(np.zeros((0, 2)), 0.1, initial_pose=[1.0, 2.0, 3.0])
    np.testing.assert_array_equal(poses, [[1.0, 2.0, 3.0]])


@pytest.mark.parametrize(
    ("v", "w", "dt"),
    [
        (0.3, 0.0, 0.1),
        (0.3, 1e-9, 0.1),
        (-0.2, -3e-4, 0.5),
        (0.3, 4.9, 0.1),  # h = w dt / 2 just below the series switch at 0.25
        (0.3, 5.1, 0.1),  # just above
        (0.5, 2.0, 1.0),
        (0.0, 1.5, 0.2),
        (0.4, -30.0, 0.2),
    ],
)
def test_jacobians_match_central_differences(v, w, dt):
    pose = np.array([0.2, -0.7, 2.5])
    f_pose, f_speed = pose_step_jacobians(pose, v, w, dt)
    n_pose, n_speed = _numerical_jacobians(pose, v, w, dt)
    np.testing.assert_allclose(f_pose, n_pose, rtol=0.0, atol=1e-8)
    np.testing.assert_allclose(f_speed, n_speed, rtol=0.0, atol=1e-8)


def test_jacobians_continuous_across_zero_yaw_rate():
    ws = np.linspace(-1e-3, 1e-3, 2001)
    ws = np.concatenate([ws, [4.99999999, 5.00000001]])  # around the series switch, dt = 0.1
    _, f_speed = pose_step_jacobians(np.array([0.0, 0.0, 0.7]), 0.4, ws, 0.1)
    dwd = f_speed[:, :2, 1]
    # smooth: successive differences stay at the size of the step times the curvature
    assert np.max(np.abs(np.diff(dwd[:2001], axis=0))) < 1e-8
    assert np.max(np.abs(dwd[-1] - dwd[-2])) < 1e-8


def test_jacobians_batch_shapes(rng):
    f_pose, f_speed = pose_step_jacobians(rng.normal(size=(2, 3, 3)), rng.normal(size=3), 0.2, 0.1)
    assert f_pose.shape == (2, 3, 3, 3)
    assert f_speed.shape == (2, 3, 3, 2)


@pytest.mark.parametrize("dt", [1.0, 0.015, np.array([0.01, 0.02, 0.5])])
def test_pose_step_terms_are_pose_step_and_jacobians_bit_for_bit(rng, dt):
    # straight runs, turns on the series and on the closed-form branch, a batch broadcast
    pose = rng.normal(size=(4, 3, 3)) * (1.0, 1.0, 3.0)
    v = rng.normal(size=3) * 0.3
    w = np.array([0.0, rng.normal() * 0.05, rng.normal() * 4.0])
    nxt, f_pose, f_speed = pose_step_terms(pose, v, w, dt)
    ref_pose, ref_speed = pose_step_jacobians(pose, v, w, dt)
    assert np.array_equal(nxt, pose_step(pose, v, w, dt))
    assert np.array_equal(f_pose, ref_pose) and np.array_equal(f_speed, ref_speed)
    with pytest.raises(NonFiniteError, match="v_m_s"):
        pose_step_terms(np.zeros(3), np.inf, 0.0, 0.1)


def test_pose_shape_and_value_errors():
    with pytest.raises(ShapeError, match=r"\(\.\.\., 3\).*\(2,\)"):
        pose_step(np.zeros(2), 1.0, 0.0, 0.1)
    with pytest.raises(ShapeError, match="do not broadcast"):
        pose_step(np.zeros((4, 3)), np.ones(3), 0.0, 0.1)
    with pytest.raises(NonFiniteError, match="w_rad_s"):
        pose_step(np.zeros(3), 1.0, np.nan, 0.1)
    with pytest.raises(ShapeError, match=r"\(\.\.\., n, 2\)"):
        integrate_poses(np.zeros(5), 0.1)
    with pytest.raises(ShapeError, match="do not broadcast"):
        integrate_poses(np.zeros((5, 2)), np.ones(4))
    with pytest.raises(ShapeError, match="initial_pose"):
        integrate_poses(np.zeros((5, 2)), 0.1, initial_pose=np.zeros(2))
    with pytest.raises(NonFiniteError, match="speeds"):
        integrate_poses(np.array([[0.1, np.inf]]), 0.1)
