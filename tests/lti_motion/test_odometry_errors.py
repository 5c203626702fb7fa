"""lti_motion.odometry_errors and lti_motion.calibration.odometry_walk: encoder odometry's
error model (a random walk per metre of wheel travel, the intrinsics' covariance) checked
against seeded Monte Carlo and numerical derivatives, and measured back from a synthetic
calibration drive whose slip is known."""

from __future__ import annotations

import numpy as np
import pytest

from lti_motion.calibration.intrinsics_fit import calibrate_intrinsics
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import integrate_poses
from lti_motion.model.fir import FirFit
from lti_motion.model.motion_model import MotionModel
from lti_motion.odometry_errors import (
    OdometryErrors,
    intrinsics_sensitivities,
    wheel_walk_step_covariances,
)
from lti_motion.odometry_noise import OdometryNoise, grow_pose_covariances

K = OdometryIntrinsics(4.49e-4, 4.4455e-4, 0.236)
DT = 0.015


def _path(n: int = 300) -> tuple[np.ndarray, np.ndarray]:
    """Speeds of a straight run, a turn in place and an arc; and the poses."""
    speeds = np.concatenate([np.tile([0.3, 0.0], (n // 3, 1)), np.tile([0.0, 1.0], (n // 3, 1)),
                             np.tile([0.2, -0.6], (n - 2 * (n // 3), 1))])
    return speeds, integrate_poses(speeds, DT, initial_pose=np.zeros(3))


def _wheels(speeds: np.ndarray, b: float) -> np.ndarray:
    return np.column_stack([speeds[:, 0] - 0.5 * b * speeds[:, 1],
                            speeds[:, 0] + 0.5 * b * speeds[:, 1]]) * DT


def _speeds(wheels: np.ndarray, b: float) -> np.ndarray:
    return np.column_stack([wheels.sum(axis=1) / 2, (wheels[..., 1] - wheels[..., 0]) / b]) / DT


def test_the_random_walk_grows_as_independent_wheel_errors_do(rng):
    """eq. (1)-(2) grown with eq. 11's Jacobians against 4000 seeded paths whose wheels each
    err by N(0, k |s|) per step."""
    k_walk = 1e-5
    speeds, poses = _path()
    cov = grow_pose_covariances(poses, speeds, DT, wheel_walk_step_covariances(
        speeds, DT, wheel_base_m=K.wheel_base_m, wheel_variance_per_m=k_walk))[-1]
    wheels = _wheels(speeds, K.wheel_base_m)
    noisy = wheels + rng.standard_normal((4000, *wheels.shape)) * np.sqrt(k_walk * np.abs(wheels))
    noisy_speeds = np.stack([_speeds(w, K.wheel_base_m) for w in noisy])
    ends = integrate_poses(noisy_speeds, DT, initial_pose=np.zeros(3))[:, -1]
    sample = np.cov(ends.T)
    np.testing.assert_allclose(np.diag(sample), np.diag(cov), rtol=0.08)   # SE 2.2%
    d = np.sqrt(np.diag(cov))
    np.testing.assert_allclose(sample / np.outer(d, d), cov / np.outer(d, d), atol=0.05)


def test_the_intrinsics_sensitivities_match_a_numerical_derivative():
    speeds, poses = _path()
    counts = _wheels(speeds, K.wheel_base_m) / np.array([K.m_per_tick_left, K.m_per_tick_right])
    s = intrinsics_sensitivities(poses, speeds, DT, K)

    def end(p: np.ndarray) -> np.ndarray:
        k = OdometryIntrinsics(*p)
        return integrate_poses(k.body_motion(counts), 1.0, initial_pose=np.zeros(3))[-1]

    p0 = np.array(list(K.as_dict().values()))
    numeric = np.empty((3, 3))
    for j in range(3):
        h = np.zeros(3)
        h[j] = 1e-6 * p0[j]
        numeric[:, j] = (end(p0 + h) - end(p0 - h)) / (2 * h[j])
    np.testing.assert_allclose(s[-1], numeric, rtol=1e-4, atol=1e-6 * np.abs(numeric).max())
    np.testing.assert_array_equal(s[0], np.zeros((3, 3)))


def test_odometry_errors_refuse_what_is_not_a_variance():
    with pytest.raises(ValueError, match="wheel_variance_per_m must be a finite number >= 0"):
        OdometryErrors(-1e-6, np.eye(3) * 1e-12)
    with pytest.raises(ValueError, match=r"must be a finite \(3, 3\) covariance"):
        OdometryErrors(1e-6, np.eye(2))
    with pytest.raises(ValueError, match="positive semi-definite"):
        OdometryErrors(1e-6, -np.eye(3))


def _slipping_drive(rng, k_walk: float, seconds: float = 240.0):
    """Straight runs, turns both ways and arcs; each wheel's ground travel is its encoder
    travel plus N(0, k |s|) per period; counts, times, the true poses."""
    rates = [[450, 450], [-250, 250], [450, 450], [250, -250], [500, 300], [300, 500]]
    hold = [4.0, 3.0, 4.0, 3.0, 3.0, 3.0]
    reps = int(seconds // sum(hold))
    rate = np.repeat(np.asarray(rates * reps, float),
                     np.round(np.asarray(hold * reps) / DT).astype(int), axis=0)
    dn = rate * DT
    travel = dn * np.array([K.m_per_tick_left, K.m_per_tick_right])
    ground = travel + rng.standard_normal(travel.shape) * np.sqrt(k_walk * np.abs(travel))
    motion = np.column_stack([ground.sum(axis=1) / 2, (ground[:, 1] - ground[:, 0])
                              / K.wheel_base_m])
    poses = integrate_poses(motion, 1.0, initial_pose=np.zeros(3))
    ticks = np.round(np.vstack([[0.0, 0.0], np.cumsum(dn, axis=0)])).astype(np.int64)
    return np.arange(len(ticks)) * DT, ticks % 65536, poses


@pytest.mark.parametrize("k_walk", [2e-5, 5e-6])
def test_the_calibration_measures_the_walk_it_drove(rng, k_walk):
    t, ticks, poses = _slipping_drive(rng, k_walk)
    every = 7
    ref = poses[::every] + rng.standard_normal((len(poses[::every]), 3)) * [0.004, 0.004, 0.006]
    cal = calibrate_intrinsics(t, ticks, t[::every], ref, position_std_m=0.004,
                               heading_std_rad=0.006)
    e = cal.odometry_errors
    assert e is not None
    assert abs(e.wheel_variance_per_m / k_walk - 1) < 0.3, e.wheel_variance_per_m
    assert abs(e.wheel_variance_per_m - k_walk) < 4 * e.wheel_variance_std
    np.testing.assert_allclose(e.intrinsics_covariance, cal.covariance[:3, :3], rtol=1e-12)


def test_no_slip_measures_a_walk_far_below_a_slipping_one(rng):
    t, ticks, poses = _slipping_drive(rng, 0.0)
    every = 7
    ref = poses[::every] + rng.standard_normal((len(poses[::every]), 3)) * [0.004, 0.004, 0.006]
    cal = calibrate_intrinsics(t, ticks, t[::every], ref, position_std_m=0.004,
                               heading_std_rad=0.006)
    assert cal.odometry_errors.wheel_variance_per_m < 1e-6     # 5e-6 is measured above


def _model() -> MotionModel:
    fit = FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
                 residual_cov=np.array([[1e-4, 2e-5], [2e-5, 6e-3]]), n_samples=100,
                 source="steps")
    return MotionModel.from_fir(fit, dt_s=DT, wheel_base_m=0.235, m_per_tick=4.4e-4,
                                calibrated_at="2026-01-01T00:00:00+00:00")


def test_the_model_file_carries_the_errors_and_new_intrinsics_drop_old_ones(tmp_path):
    errors = OdometryErrors(2e-6, np.diag([6e-14, 6e-14, 3e-8]), 2e-7, "a test")
    m = _model().with_intrinsics(K, odometry_errors=errors)
    back = MotionModel.load(m.save(tmp_path / "m.json"))
    assert back.odometry_errors == errors
    assert back.with_intrinsics(K).odometry_errors is None
    assert MotionModel.load(_model().save(tmp_path / "old.json")).odometry_errors is None


def test_the_pose_grows_with_the_measured_errors_else_says_it_is_not_measured():
    errors = OdometryErrors(2e-6, np.diag([6e-14, 6e-14, 3e-8]), 2e-7, "a test")
    measured = OdometryNoise.from_model(_model().with_intrinsics(K, odometry_errors=errors))
    fallback = OdometryNoise.from_model(_model().with_intrinsics(K))
    assert measured.measured and not fallback.measured
    assert "not a measurement" in fallback.source and "a test" in measured.source
    speeds, poses = _path()
    got = measured.pose_covariances(poses, speeds, np.ones(len(speeds)))
    walk = grow_pose_covariances(poses, speeds, DT, wheel_walk_step_covariances(
        speeds, DT, wheel_base_m=K.wheel_base_m, wheel_variance_per_m=2e-6))
    s = intrinsics_sensitivities(poses, speeds, DT, K)
    want = walk + s @ errors.intrinsics_covariance @ np.swapaxes(s, 1, 2) + measured.pose_floor
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-15)
    assert np.all(np.linalg.eigvalsh(got) > 0)
