"""lti_motion.odometry_noise: covariances from a model's noise, checked against closed forms,
numerical propagation and seeded Monte Carlo."""

from __future__ import annotations

import numpy as np
import pytest

from lti_motion.exceptions import MissingEncoderScaleError, ShapeError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import integrate_poses
from lti_motion.model.fir import FirFit
from lti_motion.model.motion_model import MotionModel
from lti_motion.odometry_noise import (
    VARIANCE_FLOOR,
    OdometryNoise,
    averaged_covariance,
    grow_pose_covariances,
    rounding_speed_covariance,
    speed_error_over,
)

K = OdometryIntrinsics(4.5e-4, 4.4e-4, 0.235)


def assert_same_covariance(sample: np.ndarray, expected: np.ndarray, *, rel: float,
                           corr: float) -> None:
    """Variances within ``rel`` and correlations within ``corr`` of ``expected`` (sampled
    covariances: an off-diagonal's error scales with the diagonals, not with itself)."""
    d = np.sqrt(np.diag(expected))
    np.testing.assert_allclose(np.diag(sample), np.diag(expected), rtol=rel)
    np.testing.assert_allclose(sample / np.outer(d, d), expected / np.outer(d, d), atol=corr)


def _model(m_per_tick: float | None = 4.4e-4) -> MotionModel:
    fit = FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
                 residual_cov=np.array([[1e-4, 2e-5], [2e-5, 6e-3]]), n_samples=100,
                 source="steps")
    return MotionModel.from_fir(fit, dt_s=0.015, wheel_base_m=0.235, m_per_tick=m_per_tick,
                                calibrated_at="2026-01-01T00:00:00+00:00")


def test_white_noise_averaged_over_n_periods_has_a_nth_of_the_variance(rng):
    cov = np.array([[4e-4, 1e-4], [1e-4, 9e-3]])
    got = averaged_covariance(cov, dt_s=0.01, period_s=0.05)
    samples = rng.multivariate_normal(np.zeros(2), cov, size=(40_000, 5)).mean(axis=1)
    assert_same_covariance(np.cov(samples.T), got, rel=0.03, corr=0.02)   # SE 0.7%, 0.005
    np.testing.assert_allclose(got, cov / 5)


def test_rounding_covariance_matches_rounded_wheel_angles(rng):
    """Counts are angles rounded to whole ticks; the speeds from their differences carry
    J diag(1/6, 1/6) J^T / dt^2 (eq. 2)."""
    dt = 0.015
    angle = np.cumsum(rng.uniform(5.0, 40.0, size=(50_000, 2)), axis=0)   # ticks, real
    counts = np.rint(angle)
    err = np.diff(counts, axis=0) - np.diff(angle, axis=0)
    speeds_err = K.body_motion(err) / dt
    assert_same_covariance(np.cov(speeds_err.T), rounding_speed_covariance(K, dt), rel=0.03,
                           corr=0.02)


def test_growth_matches_monte_carlo_along_an_arc(rng):
    """eq. 3 against 4000 seeded integrations of noisy speeds on a constant-turn arc."""
    n, dt = 200, 0.02
    speeds = np.tile([0.3, 0.5], (n, 1))
    poses = integrate_poses(speeds, dt, initial_pose=np.zeros(3))
    cov = np.array([[2e-4, 3e-5], [3e-5, 4e-3]])
    p = grow_pose_covariances(poses, speeds, dt, cov)
    noisy = speeds + rng.multivariate_normal(np.zeros(2), cov, size=(4000, n))
    ends = integrate_poses(noisy, dt, initial_pose=np.zeros(3))[:, -1]
    assert_same_covariance(np.cov(ends.T), p[-1], rel=0.08, corr=0.05)     # SE 2%, 0.016
    assert np.all(np.linalg.eigvalsh(p[3:]) > 0)       # positive definite from the 3rd step
    assert np.all(np.linalg.eigvalsh(p) >= -1e-18)     # semi-definite before (rank 2 noise)
    np.testing.assert_array_equal(p, np.swapaxes(p, 1, 2))


def test_a_straight_line_grows_the_travel_linearly_and_the_side_cubically():
    n, dt, v = 100, 0.01, 1.0
    speeds = np.tile([v, 0.0], (n, 1))
    poses = integrate_poses(speeds, dt, initial_pose=np.zeros(3))
    s_v, s_w = 1e-4, 1e-3
    p = grow_pose_covariances(poses, speeds, dt, np.diag([s_v, s_w]))[-1]
    t = n * dt
    assert p[0, 0] == pytest.approx(n * dt**2 * s_v)
    assert p[2, 2] == pytest.approx(n * dt**2 * s_w)
    # lateral: sum over steps of (v t_k)^2 s_w dt^2, about v^2 s_w dt t^3 / 3
    assert p[1, 1] == pytest.approx(v**2 * s_w * dt * t**3 / 3, rel=0.03)


def test_a_span_of_m_periods_adds_m_periods_of_noise():
    noise = OdometryNoise(np.eye(2) * 1e-4, np.eye(2) * 1e-4, np.zeros((3, 3)), 0.01, "test")
    speeds = np.array([[0.2, 0.0]])
    poses = integrate_poses(speeds, 0.03, initial_pose=np.zeros(3))
    one_span = noise.pose_covariances(poses, speeds, np.array([3]))[-1]
    speeds3 = np.tile([0.2, 0.0], (3, 1))
    poses3 = integrate_poses(speeds3, 0.01, initial_pose=np.zeros(3))
    three = noise.pose_covariances(poses3, speeds3, np.ones(3))[-1]
    assert one_span[0, 0] == pytest.approx(three[0, 0])


def test_from_model_grows_with_r_less_the_rounding_and_never_holds_a_zero_variance():
    model = _model()
    noise = OdometryNoise.from_model(model)
    k = model.encoder_intrinsics
    np.testing.assert_allclose(noise.speed_cov, model.R)
    expected = model.R - rounding_speed_covariance(k, model.dt_s)
    w = np.linalg.eigvalsh(expected)
    if w.min() > VARIANCE_FLOOR:
        np.testing.assert_allclose(noise.growth_cov, expected, rtol=1e-9)
    assert np.all(np.linalg.eigvalsh(noise.growth_cov) >= 0.999 * VARIANCE_FLOOR)
    poses = np.zeros((1, 3))
    assert np.all(np.diag(noise.pose_covariances(poses, np.zeros((0, 2)), np.zeros(0))[0]) > 0)
    assert np.all(np.diag(noise.twist_covariance(0.02)) > 0)


def test_the_growth_is_never_below_zero_when_the_rounding_exceeds_r():
    model = _model(m_per_tick=5e-3)              # coarse encoders: rounding above R
    noise = OdometryNoise.from_model(model)
    assert np.all(np.linalg.eigvalsh(noise.growth_cov) > 0)


def test_speed_error_over_one_period_is_c_q_ct_plus_r_and_grows_with_the_period():
    model = _model()
    one = model.C @ model.Q @ model.C.T + model.R
    np.testing.assert_allclose(speed_error_over(model, model.dt_s), one, rtol=1e-12)
    assert speed_error_over(model, 0.1)[1, 1] >= speed_error_over(model, 0.015)[1, 1]


def test_bad_input_raises_specific_errors():
    with pytest.raises(ShapeError, match=r"\(2, 2\)"):
        averaged_covariance(np.eye(3), dt_s=0.01, period_s=0.02)
    with pytest.raises(ValueError, match="period_s must be a positive number"):
        averaged_covariance(np.eye(2), dt_s=0.01, period_s=0.0)
    with pytest.raises(ShapeError, match="speeds"):
        grow_pose_covariances(np.zeros((3, 3)), np.zeros((3, 2)), 0.01, np.eye(2))
    with pytest.raises(MissingEncoderScaleError, match="odometry's covariances"):
        OdometryNoise.from_model(_model(m_per_tick=None))
