"""The gate, records and landmark updates both EKFs share (fusion.ekf.updates): one
update_landmark(id, (r, b), *, cov, t_s) on a LandmarkMap, the same records and counts for the
model filter and the velocity-model baseline, against a stock filterpy update."""

import math

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

from fusion.ekf import functions as ef
from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.model_ekf import ModelEKF
from fusion.ekf.velocity_ekf import VelocityModelEKF
from fusion.exceptions import (
    CovarianceNotPositiveDefiniteError,
    FilterOptionError,
    MeasurementShapeError,
    UnknownLandmarkError,
)
from fusion.noise import LandmarkNoise
from fusion.range_bearing import RangeBearing, range_bearing
from fusion.sensor_pose import SensorPose
from lti_motion.model.fir import FirFit
from lti_motion.model.motion_model import MotionModel

LANDMARKS = {1: (2.0, 1.0), 2: (-1.0, 3.0), "door": (3.0, -2.0)}
COV = np.array([[4e-3, 1.5e-4], [1.5e-4, 2e-4]])


@pytest.fixture(scope="module")
def model():
    return MotionModel.from_fir(
        FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
            residual_cov=np.eye(2) * 1e-4, n_samples=100, source="steps"),
        dt_s=0.015, wheel_base_m=0.25, m_per_tick=5e-4,
        calibrated_at="2026-01-01T00:00:00+00:00")


def _filters(model, **kwargs):
    """The model filter and the baseline, each a few periods into a drive."""
    mf = ModelEKF(model, initial_pose=(0.1, -0.2, 0.3), pose_std=(0.05, 0.05, 0.05),
                  landmarks=LANDMARKS, options=EKFOptions(**kwargs))
    vf = VelocityModelEKF(dt_s=0.1, speed_cov=np.diag([1e-3, 4e-3]),
                          initial_pose=(0.1, -0.2, 0.3), pose_std=(0.05, 0.05, 0.05),
                          landmarks=LANDMARKS, **kwargs)
    for _ in range(3):
        mf.predict(np.array([0.2, 0.25]))
        vf.predict(np.array([0.2, 0.1]))
    return mf, vf


@pytest.mark.parametrize("which", [0, 1])
def test_one_landmark_update_matches_the_kalman_equations(model, which):
    """Full covariance: S = H P H^T + R, K = P H^T S^-1, x += K nu, Joseph P."""
    ekf = _filters(model)[which]
    x, P = ekf.x.copy(), ekf.P.copy()
    lxy = np.array(LANDMARKS[2])
    z = range_bearing(x, lxy) + np.array([0.03, -0.01])
    rec = ekf.update_landmark(2, z, cov=COV, t_s=4.5)
    H = ef.landmark_jacobian(x, lxy)
    S = H @ P @ H.T + COV
    K = P @ H.T @ np.linalg.inv(S)
    nu = ef.landmark_residual(z, range_bearing(x, lxy))
    ikh = np.eye(len(x)) - K @ H
    assert rec.accepted and rec.reason == "fused" and rec.kind == "landmark"
    assert rec.landmark_id == 2 and rec.t_s == 4.5
    np.testing.assert_allclose(rec.innovation_cov, S, rtol=1e-12)
    assert rec.nis == pytest.approx(nu @ np.linalg.solve(S, nu), rel=1e-12)
    np.testing.assert_allclose(ekf.x, x + K @ nu, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(ekf.P, ikh @ P @ ikh.T + K @ COV @ K.T, rtol=1e-9, atol=1e-15)


MOUNT = SensorPose(0.22, -0.04, 0.3)


@pytest.mark.parametrize("which", [0, 1])
def test_a_mounted_sensor_update_matches_the_kalman_equations(model, which):
    """The sensor's mount in h and H (fusion.range_bearing eq. 1-2), full covariance."""
    ekf = _filters(model)[which]
    x, P = ekf.x.copy(), ekf.P.copy()
    lxy = np.array(LANDMARKS[1])
    z = range_bearing(x, lxy, sensor=MOUNT) + np.array([0.02, 0.015])
    rec = ekf.update_landmark(1, z, cov=COV, sensor_pose=MOUNT)
    H = ef.landmark_jacobian(x, lxy, sensor=MOUNT)
    num = np.zeros_like(H)
    for j in range(3):
        e = np.zeros(len(x))
        e[j] = 1e-6
        num[:, j] = ef.landmark_residual(range_bearing(x + e, lxy, sensor=MOUNT),
                                         range_bearing(x - e, lxy, sensor=MOUNT)) / 2e-6
    np.testing.assert_allclose(H, num, rtol=1e-6, atol=1e-9)
    S = H @ P @ H.T + COV
    K = P @ H.T @ np.linalg.inv(S)
    nu = ef.landmark_residual(z, range_bearing(x, lxy, sensor=MOUNT))
    assert rec.accepted
    np.testing.assert_allclose(rec.innovation, nu, rtol=1e-12)
    np.testing.assert_allclose(ekf.x, x + K @ nu, rtol=1e-12, atol=1e-15)
    ikh = np.eye(len(x)) - K @ H
    np.testing.assert_allclose(ekf.P, ikh @ P @ ikh.T + K @ COV @ K.T, rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("which", [0, 1])
def test_update_landmarks_takes_the_mount_the_sightings_carry(model, which):
    a, b, c = (_filters(model)[which] for _ in range(3))
    z = range_bearing(a.x, np.array(LANDMARKS[2]), sensor=MOUNT) + np.array([0.01, -0.01])
    a.update_landmarks(RangeBearing(0, [2], [z[0]], [z[1]], cov=[COV], sensor_pose=MOUNT))
    b.update_landmark(2, z, cov=COV, sensor_pose=MOUNT)
    c.update_landmarks(RangeBearing(0, [2], [z[0]], [z[1]], cov=[COV]))     # taken as centred
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.P, b.P)
    assert not np.allclose(a.x, c.x)


@pytest.mark.parametrize("which", [0, 1])
def test_no_covariance_means_the_filters_noise_at_the_predicted_range(model, which):
    a, b = _filters(model)[which], _filters(model)[which]
    z = range_bearing(a.x, np.array(LANDMARKS[1])) + np.array([0.02, 0.01])
    predicted_range = range_bearing(a.x, np.array(LANDMARKS[1]))[0]
    a.update_landmark(1, z)
    b.update_landmark(1, z, cov=b.landmark_noise.cov(predicted_range))
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.P, b.P)


def test_the_baseline_equals_a_stock_filterpy_update(model):
    """The shared update is the textbook one filterpy's ExtendedKalmanFilter.update runs."""
    _, ours = _filters(model, gate_probability=None)
    stock = ExtendedKalmanFilter(dim_x=3, dim_z=2)
    stock.x, stock.P = ours.x.copy(), ours.P.copy()
    lxy = np.array(LANDMARKS["door"])
    z = range_bearing(ours.x, lxy) + np.array([-0.05, 0.02])
    ours.update_landmark("door", z, cov=COV)
    stock.update(z, lambda x: ef.landmark_jacobian(x, lxy), lambda x: range_bearing(x, lxy),
                 R=COV, residual=ef.landmark_residual)
    np.testing.assert_allclose(ours.x, stock.x, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(ours.P, stock.P, rtol=1e-10, atol=1e-16)
    np.testing.assert_allclose(ours.y, stock.y, rtol=1e-13)


@pytest.mark.parametrize("which", [0, 1])
def test_update_landmarks_fuses_every_row_in_order(model, which):
    a, b = _filters(model)[which], _filters(model)[which]
    rows = RangeBearing(7, [1, 9, "door", 2], [2.0, 1.0, 3.4, 3.2], [0.2, 0.0, -1.2, 1.4],
                        cov=np.stack([COV, COV, 2 * COV, COV]))
    recs = a.update_landmarks(rows, t_s=1.0)
    for lid, z, cov in rows:
        b.update_landmark(lid, z, cov=cov, t_s=1.0)
    np.testing.assert_array_equal(a.x, b.x)
    assert [r.landmark_id for r in recs] == [1, 9, "door", 2]
    assert [r.reason for r in recs][1] == "unknown_landmark"
    assert a.stats.count("landmark", "unknown_landmark") == 1
    assert a.stats.unknown_landmark_ids == (9,)
    assert a.update_landmarks(RangeBearing.empty()) == []


@pytest.mark.parametrize("which", [0, 1])
def test_gate_unknown_ids_and_records_are_the_same_for_both_filters(model, which):
    ekf = _filters(model, history=5)[which]
    far = range_bearing(ekf.x, np.array(LANDMARKS[1])) + np.array([1.5, 0.8])
    rec = ekf.update_landmark(1, far)
    assert not rec.accepted and rec.reason == "gated" and rec.nis > 13.8
    assert ekf.update_landmark(1, np.array([np.nan, 0.1])).reason == "non_finite"
    assert ekf.stats.count("landmark", "gated") == 1 and ekf.stats.rejected("landmark") == 2
    assert len(ekf.records) == 2 and ekf.records[-1].reason == "non_finite"
    strict = _filters(model, unknown_landmarks="raise")[which]
    with pytest.raises(UnknownLandmarkError, match="landmark 42 is not in the map"):
        strict.update_landmark(42, np.array([1.0, 0.0]))


@pytest.mark.parametrize("which", [0, 1])
def test_bad_landmark_input(model, which):
    ekf = _filters(model)[which]
    with pytest.raises(MeasurementShapeError, match=r"shape \(2,\), got \(3,\)"):
        ekf.update_landmark(1, np.zeros(3))
    with pytest.raises(MeasurementShapeError, match=r"\(2, 2\), got \(3, 3\)"):
        ekf.update_landmark(1, np.array([1.0, 0.0]), cov=np.eye(3))
    with pytest.raises(CovarianceNotPositiveDefiniteError, match="positive definite"):
        ekf.update_landmark(1, np.array([1.0, 0.0]), cov=np.array([[1.0, 2.0], [2.0, 1.0]]))
    with pytest.raises(CovarianceNotPositiveDefiniteError, match="symmetric"):
        ekf.update_landmark(1, np.array([1.0, 0.0]), cov=np.array([[1.0, 0.1], [0.0, 1.0]]))
    with pytest.raises(FilterOptionError, match="unknown_landmarks"):
        VelocityModelEKF(dt_s=0.1, speed_cov=np.eye(2), unknown_landmarks="drop")
    with pytest.raises(FilterOptionError, match="no landmark map"):
        VelocityModelEKF(dt_s=0.1, speed_cov=np.eye(2)).update_landmark(1, np.ones(2))


def test_the_baseline_keeps_time_and_noise_defaults():
    ekf = VelocityModelEKF(dt_s=0.1, speed_cov=np.eye(2) * 1e-4, landmarks=LANDMARKS,
                           landmark_noise=LandmarkNoise(bearing_std_rad=0.02))
    for _ in range(4):
        ekf.predict(np.array([0.1, 0.0]))
    assert ekf.t_s == pytest.approx(0.4)
    rec = ekf.update_landmark(1, range_bearing(ekf.x, np.array(LANDMARKS[1])))
    assert rec.t_s == pytest.approx(0.4) and rec.nis == pytest.approx(0.0, abs=1e-20)
    assert rec.innovation_cov[1, 1] > 0.02 ** 2 and math.isfinite(rec.nis)


def test_the_baseline_takes_no_gate_and_refuses_impossible_options(model):
    """Issue 15 item 4: VelocityModelEKF(gate_probability=None) fuses everything, as ModelEKF
    does; impossible options are one-line FilterOptionErrors (ValueErrors)."""
    vf = VelocityModelEKF(dt_s=0.1, speed_cov=np.diag([1e-4, 1e-3]), landmarks=LANDMARKS,
                          gate_probability=None)
    mf = ModelEKF(model, landmarks=LANDMARKS, options=EKFOptions(gate_probability=None))
    for ekf in (vf, mf):
        ekf.predict(np.array([0.2, 0.2]) if ekf is mf else np.array([0.2, 0.0]))
        far = range_bearing(ekf.x, np.array(LANDMARKS[1])) + np.array([3.0, 1.0])
        rec = ekf.update_landmark(1, far)
        assert rec.accepted and rec.nis > 1e3 and rec.reason == "fused"
    ok = {"dt_s": 0.1, "speed_cov": np.diag([1e-4, 1e-3])}
    cases = [({"dt_s": -0.1}, "dt_s"), ({"dt_s": math.nan}, "dt_s"),
             ({"speed_cov": -np.eye(2)}, "negative noise"),
             ({"speed_cov": np.full((2, 2), np.nan)}, "finite"),
             ({"speed_cov": np.array([[1.0, 0.0], [0.5, 1.0]])}, "symmetric"),
             ({"pose_std": (0.01, -0.01, 0.01)}, "pose_std"),
             ({"gate_probability": 1.0}, "gate probability"),
             ({"gate_probability": "0.99"}, "gate probability")]
    for bad, match in cases:
        with pytest.raises(FilterOptionError, match=match) as info:
            VelocityModelEKF(**{**ok, **bad})
        assert isinstance(info.value, ValueError) and "\n" not in str(info.value)
    with pytest.raises(FilterOptionError, match="gate probability"):
        ModelEKF(model, options=EKFOptions(gate_probability="0.99"))
