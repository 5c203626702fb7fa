"""The model-based EKF: maths against references, filterpy parity, bad input, invariants.

Unit tests on a small synthetic ARX model (known, fast); the Monte Carlo acceptance
runs on the simulator are in ``test_ekf_montecarlo.py``.
"""
import dataclasses
import math
import re

import numba
import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
from scipy.stats import chi2
from synthetic_ekf_model import (
    DT,
    M_PER_TICK,
    B,
    arx_data,
    held_commands,
    numerical_jacobian,
)

from fusion.ekf import functions as ef
from fusion.ekf import kernel
from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.model_ekf import ModelEKF
from fusion.ekf.updates import UpdateRecord
from fusion.exceptions import (
    FilterOptionError,
    MeasurementShapeError,
    NonFiniteInputError,
    UnknownLandmarkError,
)
from fusion.landmark_map import LandmarkMap
from fusion.landmarks.synthetic import synthetic_observations
from fusion.noise import LandmarkNoise, inverse_covariance
from fusion.range_bearing import range_bearing, range_bearing_jacobian, range_bearing_residual
from lti_motion.exceptions import ShapeError
from lti_motion.kinematics import (
    body_from_wheel,
    integrate_poses,
    pose_step,
    pose_step_jacobians,
    wrap_angle,
)
from lti_motion.model.arx import estimate_arx
from lti_motion.model.motion_model import MotionModel

LANDMARKS = LandmarkMap({0: (0.5, 0.5), 1: (4.5, 0.5), 2: (4.5, 4.5), 3: (0.5, 4.5)})


@pytest.fixture(scope="module")
def fm(model):
    return ef.FilterModel(model)


def _state(fm, rng, *, w=0.4):
    x = ef.initial_state(fm, (1.0, 2.0, 0.7), z=0.05 * rng.standard_normal(fm.nz))
    x[ef.SCALES] = (0.004, -0.003, 0.03)        # kappa 0.03 rad/m: a 0.7% diameter ratio
    x[fm.speed_slice] = (0.2, w)
    return x


# -- prediction -----------------------------------------------------------------------------------
def test_layout_and_shapes(model, fm):
    assert fm.n == model.n_states + 8 and fm.nz == model.n_states
    assert np.any(model.K != 0) and model.q_scale > 1
    x = ef.initial_state(fm, (0.0, 0.0, 0.0))
    x_next, F, Q = ef.predict_terms(x, np.array([0.2, 0.2]), fm)
    assert x_next.shape == (fm.n,) and F.shape == Q.shape == (fm.n, fm.n)


@pytest.mark.parametrize("w", [0.0, 1e-9, 0.4, -2.5, 12.0])
@pytest.mark.parametrize("accumulate", [False, True])
def test_transition_jacobian_matches_a_numerical_derivative(fm, rng, w, accumulate):
    u = np.array([0.15, 0.3])
    x = _state(fm, rng)
    # put the speed C z + D u near w by choosing z's first block
    x[ef.SCALES.stop:ef.SCALES.stop + 2] = (0.2, w)

    def f(xx):
        return ef.predict_terms(xx, u, fm, accumulate=accumulate)[0]

    F = ef.predict_terms(x, u, fm, accumulate=accumulate)[1]
    # a step of 1e-5: central differences err by ~eps^2 f''' ~ 1e-11 here, while 1e-7 left
    # rounding errors of ~1e-16 |x| / eps ~ 2e-9 in the pose rows (|x| ~ 2 m)
    np.testing.assert_allclose(F, numerical_jacobian(f, x, eps=1e-5), rtol=1e-6, atol=1e-9)


def test_pose_step_and_its_jacobians_agree_with_kinematics(fm, rng):
    for _ in range(20):
        x = _state(fm, rng)
        x[ef.SCALES] = 0.0
        u = rng.uniform(0.0, 0.4, 2)
        x_next, F, _ = ef.predict_terms(x, u, fm)
        v, w = fm.model.C @ x[fm.model_slice] + fm.model.D @ u
        np.testing.assert_allclose(x_next[:3], pose_step(x[:3], v, w, DT), rtol=1e-13, atol=1e-15)
        f_pose, f_speed = pose_step_jacobians(x[:3], v, w, DT)
        np.testing.assert_allclose(F[:3, :3], f_pose, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(F[:3, fm.model_slice], f_speed @ fm.model.C, rtol=1e-12,
                                   atol=1e-15)


def test_process_noise_is_the_documented_sum_and_carries_the_correlation(model, fm, rng):
    """Q = G R G^T + F_s R_slip F_s^T + blkdiag(0, walk, Q - K R K^T, 0), built densely here."""
    x, u = _state(fm, rng), np.array([0.2, 0.25])
    Q = ef.predict_terms(x, u, fm)[2]
    v, w = model.C @ x[fm.model_slice] + model.D @ u
    kv, kw, kappa = x[ef.SCALES]
    assert kappa != 0
    d_c = np.array([[1 + kv, 0.0], [kappa, 1 + kw]])          # g = D_c s
    f_s = pose_step_jacobians(x[:3], *(d_c @ [v, w]), DT)[1]
    G = np.vstack([f_s @ d_c, np.zeros((3, 2)), model.K, np.eye(2)])
    sv, sw = fm.slip.stds(v, w)
    want = G @ model.R @ G.T
    want[:3, :3] += f_s @ np.diag([sv ** 2, sw ** 2]) @ f_s.T
    want[3:6, 3:6] += np.diag(np.square(fm.scale_walk)) * DT
    zs = fm.model_slice
    want[zs, zs] += model.Q - model.K @ model.R @ model.K.T
    np.testing.assert_allclose(Q, want, rtol=1e-10, atol=1e-18)
    # E[w_z e^T] = K R = MotionModel.S, E[w_s e^T] = R
    np.testing.assert_allclose(Q[zs, fm.speed_slice], model.S, rtol=1e-12)
    np.testing.assert_allclose(Q[fm.speed_slice, fm.speed_slice], model.R, rtol=1e-12)
    assert np.linalg.eigvalsh(Q).min() > -1e-15


def test_predict_sets_filterpys_F_and_Q_for_this_step(model, fm):
    """The subclass double-buffers F and Q: every step's matrices are the functions' ones."""
    ekf = ModelEKF(model, initial_pose=(0.0, 0.0, 0.3))
    for k in range(5):
        u = np.array([0.1 + 0.05 * k, 0.3])
        x_before = ekf.x
        ekf.predict(u)
        _, F, Q = ef.predict_terms(x_before, u, fm)
        np.testing.assert_array_equal(ekf.F, F)
        np.testing.assert_array_equal(ekf.Q, Q)
        np.testing.assert_array_equal(ekf.x_prior, ekf.x)


# -- the correlated noise, on data from the model itself ------------------------------------------
def _from_the_model(model, rng, n):
    """Commands and speeds generated by the innovations form, model error included."""
    u = held_commands(rng, n)
    extra = model.Q - model.K @ model.R @ model.K.T
    z = np.zeros(model.n_states)
    y = np.empty((n, 2))
    for k in range(n):
        e = rng.multivariate_normal(np.zeros(2), model.R)
        y[k] = model.C @ z + model.D @ u[k] + e
        z = model.A @ z + model.B @ u[k] + model.K @ e + rng.multivariate_normal(
            np.zeros(model.n_states), extra)
    return u, y


def test_encoder_nis_is_chi_square_on_data_from_the_model(model, rng):
    u, y = _from_the_model(model, rng, 6000)
    ekf = ModelEKF(model, options=EKFOptions(gate_probability=None))
    nis = []
    for k in range(len(u)):
        ekf.predict(u[k])
        nis.append(ekf.update_speeds(y[k]).nis)
    lo, hi = chi2.ppf([0.005, 0.995], 2 * len(nis)) / len(nis)
    assert lo <= np.mean(nis) <= hi, np.mean(nis)


def test_speed_state_is_the_reading_and_the_model_state_the_one_step_predictor(rng):
    """With q_scale 1 the fused filter *is* MotionModel's predictor; the pose is odometry."""
    u, y = arx_data(np.random.default_rng(5), 3000)
    fit = estimate_arx([(u, y)], na=2, nb=1, delay=1)
    model = MotionModel.from_arx(fit, dt_s=DT, wheel_base_m=B, m_per_tick=M_PER_TICK,
                                 calibrated_at="2026-01-01T00:00:00+00:00")
    ekf = ModelEKF(model, options=EKFOptions(gate_probability=None), initial_pose=(0.0, 0.0, 0.0))
    priors, poses = [], []
    for k in range(len(u)):
        ekf.predict(u[k])
        priors.append(ekf.speeds)
        ekf.update_speeds(y[k])
        np.testing.assert_allclose(ekf.speeds, y[k], atol=1e-6)
        poses.append(ekf.pose)
    np.testing.assert_allclose(np.array(priors)[50:], model.predict_one_step(u, y)[50:],
                               atol=2e-4)
    odometry = integrate_poses(y, DT)[1:]
    np.testing.assert_allclose(np.array(poses), odometry, atol=1e-5)


def test_pose_nees_is_consistent_when_the_world_follows_the_filters_model(model, fm):
    """Truth drawn from the filter's own noise model (scales, slip, landmarks): NEES ~ chi2(3)."""
    n_runs, n_steps = 20, 800
    nees = []
    for r in range(n_runs):
        rng = np.random.default_rng(100 + r)
        u, y = _from_the_model(model, rng, n_steps)
        scales = rng.normal(0.0, fm.scales.prior_std)
        start = np.array([2.0, 1.5, 0.2])
        pose, truth = start + 0.005 * rng.standard_normal(3), []
        for k in range(n_steps):
            sv, sw = fm.slip.stds(*y[k])
            g = (1 + scales) * y[k] + rng.normal(0.0, (sv, sw))
            pose = pose_step(pose, g[0], g[1], DT)
            truth.append(pose)
            scales = scales + rng.normal(0.0, fm.scales.walk_per_sqrt_s) * math.sqrt(DT)
        truth = np.array(truth)
        obs = synthetic_observations(np.vstack([start, truth]), LANDMARKS, dt_s=DT, rng=rng)
        by_frame = obs.by_index()
        ekf = ModelEKF(model, initial_pose=start, pose_std=(0.005, 0.005, 0.005),
                       landmarks=LANDMARKS, options=EKFOptions(gate_probability=None))
        err = []
        for k in range(n_steps):
            ekf.predict(u[k])
            ekf.update_speeds(y[k])
            if k + 1 in by_frame:
                ekf.update_landmarks(by_frame[k + 1])
            e = truth[k] - ekf.pose
            e[2] = wrap_angle(e[2])
            err.append(e @ np.linalg.solve(ekf.pose_cov, e))
        nees.append(np.mean(err))
    lo, hi = chi2.ppf([0.005, 0.995], 3 * n_runs) / n_runs
    assert lo <= np.mean(nees) <= hi, np.mean(nees)


# -- filterpy parity ------------------------------------------------------------------------------
class _Stock(ExtendedKalmanFilter):
    """A stock filterpy EKF; only predict_x, filterpy's documented hook, is overridden."""

    def predict_x(self, u=0):
        self.x = ef.state_transition(self.x, u, self.fm)


def test_subclass_and_stock_filterpy_ekf_on_the_plain_functions_agree_step_by_step(model, fm):
    rng = np.random.default_rng(3)
    u, y = _from_the_model(model, rng, 600)
    pose0 = np.array([1.0, 1.0, 0.3])
    truth = integrate_poses(y, DT, initial_pose=pose0)
    obs = synthetic_observations(truth, LANDMARKS, dt_s=DT, rng=rng, rate_hz=4.0).by_index()
    ours = ModelEKF(model, initial_pose=pose0, landmarks=LANDMARKS,
                    options=EKFOptions(gate_probability=None))
    stock = _Stock(dim_x=fm.n, dim_z=2, dim_u=2)
    stock.fm = fm
    stock.x, stock.P = ef.initial_state(fm, pose0), ef.initial_covariance(fm)
    noise = LandmarkNoise()
    for k in range(len(u)):
        ours.predict(u[k])
        _, stock.F, stock.Q = ef.predict_terms(stock.x, u[k], fm)
        stock.predict(u[k])
        ours.update_speeds(y[k])
        stock.update(y[k], ef.encoder_jacobian, ef.encoder_measurement, R=fm.encoder_cov,
                     args=(fm,), hx_args=(fm,))
        for key, rb, _ in obs.get(k + 1, ()):
            ours.update_landmark(key, rb)
            lxy = LANDMARKS.position(key)
            r = noise.cov(ef.landmark_measurement(stock.x, lxy)[0])
            stock.update(rb, ef.landmark_jacobian, ef.landmark_measurement, R=r, args=(lxy,),
                         hx_args=(lxy,), residual=ef.landmark_residual)
        np.testing.assert_allclose(ours.x, stock.x, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(ours.P, stock.P, rtol=1e-7, atol=1e-15)
        np.testing.assert_allclose(ours.SI, np.linalg.inv(ours.S), rtol=1e-10)
    assert ours.stats.count("landmark", "fused") > 50


def test_encoder_counts_and_speeds_give_the_same_filter(model):
    rng = np.random.default_rng(4)
    u, y = _from_the_model(model, rng, 400)
    wheel = np.stack([y[:, 0] - 0.5 * B * y[:, 1], y[:, 0] + 0.5 * B * y[:, 1]], axis=1)
    counts = np.vstack([[0, 0], np.round(np.cumsum(wheel * DT / M_PER_TICK, 0))])
    ticks = (counts + np.array([65000, 100])).astype(np.int64) % 65536    # both roll over
    inc = np.diff(counts, axis=0)
    y_q = body_from_wheel(inc, wheel_base_m=B) * (M_PER_TICK / DT)
    a = ModelEKF(model, initial_ticks=ticks[0], options=EKFOptions(gate_probability=None))
    b = ModelEKF(model, options=EKFOptions(gate_probability=None))
    for k in range(len(u)):
        a.predict(u[k])
        b.predict(u[k])
        ra, rb = a.update_encoders(ticks[k + 1]), b.update_speeds(y_q[k])
        assert ra.accepted == rb.accepted
        np.testing.assert_allclose(a.x, b.x, rtol=1e-9, atol=1e-12)


def test_a_stock_ukf_runs_on_the_plain_functions(model, fm):
    rng = np.random.default_rng(6)
    u, y = _from_the_model(model, rng, 300)
    points = MerweScaledSigmaPoints(fm.n, alpha=0.3, beta=2.0, kappa=0.0)
    ukf = UnscentedKalmanFilter(fm.n, 2, DT, hx=lambda x: ef.encoder_measurement(x, fm),
                                fx=lambda x, dt, u: ef.state_transition(x, u, fm),
                                points=points, residual_x=ef.state_residual,
                                x_mean_fn=ef.state_mean)
    ukf.x, ukf.P = ef.initial_state(fm, (0.0, 0.0, 3.1)), ef.initial_covariance(fm)
    ekf = ModelEKF(model, initial_pose=(0.0, 0.0, 3.1),
                   options=EKFOptions(gate_probability=None, encoder_std=(1e-3, 1e-2)))
    for k in range(len(u)):
        ukf.Q = ef.process_noise(ukf.x, u[k], fm)
        ukf.predict(u=u[k])
        ukf.update(y[k], R=np.diag([1e-3, 1e-2]) ** 2)
        ekf.predict(u[k])
        ekf.update_speeds(y[k])
    assert np.hypot(*(ukf.x[:2] - ekf.pose[:2])) < 2e-3
    assert abs(wrap_angle(ukf.x[2] - ekf.pose[2])) < 2e-3


# -- gating, faults, bad input --------------------------------------------------------------------
def _ticks_for(model, rng, n):
    """Commands and clean raw counts of a drive that follows the model's own speeds."""
    u, y = _from_the_model(model, rng, n)
    wheel = np.stack([y[:, 0] - 0.5 * B * y[:, 1], y[:, 0] + 0.5 * B * y[:, 1]], axis=1)
    counts = np.vstack([[0, 0], np.round(np.cumsum(wheel * DT / M_PER_TICK, 0))])
    return u, counts.astype(np.int64)


def _run_encoders(model, u, ticks):
    """A ModelEKF through the commands and counts: the filter and its encoder records."""
    ekf = ModelEKF(model, initial_ticks=ticks[0])
    recs = []
    for k in range(len(u)):
        ekf.predict(u[k])
        recs.append(ekf.update_encoders(ticks[k + 1] % 65536))
    return ekf, recs


def test_a_spike_is_rejected_counted_and_its_period_recovered_at_the_next_frame(model, rng):
    u, clean = _ticks_for(model, rng, 300)
    spiked = clean.copy()
    spiked[150, 1] += 4000                              # one frame of the right wheel
    runs = {name: _run_encoders(model, u, ticks)
            for name, ticks in (("clean", clean), ("spiked", spiked))}
    ekf, recs = runs["spiked"]
    assert recs[149].reason == "gated" and recs[149].nis > 1e3
    assert recs[150].accepted                    # counts against the last fused frame: clean
    assert ekf.stats.count("encoders", "gated") == runs["clean"][0].stats.count(
        "encoders", "gated") + 1
    np.testing.assert_allclose(ekf.pose, runs["clean"][0].pose, atol=5e-4)


def test_a_stuck_encoder_is_gated_and_the_filter_recovers_after_it(model, rng):
    u, clean = _ticks_for(model, rng, 600)
    stuck = clean.copy()
    stuck[200:260, 0] = clean[200, 0]                   # left counts freeze for 0.9 s ...
    stuck[260:, 0] -= clean[259, 0] - clean[200, 0]     # ... and resume without the lost ticks
    runs = {name: _run_encoders(model, u, ticks)
            for name, ticks in (("clean", clean), ("stuck", stuck))}
    ekf, recs = runs["stuck"]
    assert sum(r.accepted for r in recs[205:258]) <= 2, "a frozen wheel's readings are gated"
    assert sum(r.accepted for r in recs[300:]) >= 295, "and fused again once it turns"
    y = np.array([ef.encoder_speeds(stuck[k:k + 2], ekf.fm) for k in range(len(u))])
    odometry = integrate_poses(y, DT)[-1]
    error = np.hypot(*(ekf.pose[:2] - runs["clean"][0].pose[:2]))
    assert error < 0.05 and error < 0.25 * np.hypot(*(odometry[:2] - runs["clean"][0].pose[:2]))


def test_nan_readings_are_skipped_counted_and_leave_the_state_alone(model, rng):
    u, ticks = _ticks_for(model, rng, 40)
    ekf = ModelEKF(model, initial_ticks=ticks[0], landmarks=LANDMARKS)
    for k in range(20):
        ekf.predict(u[k])
        ekf.update_encoders(ticks[k + 1])
    ekf.predict(u[20])
    x, P = ekf.x.copy(), ekf.P.copy()
    recs = [ekf.update_encoders(np.array([np.nan, 3.0])),
            ekf.update_landmark(0, np.array([np.nan, 0.1])),
            ekf.update_pose(np.array([np.inf, 0.0, 0.0]), np.eye(3)),
            ekf.update_landmark(1, np.array([2.0, np.nan]))]
    np.testing.assert_array_equal(ekf.x, x)
    np.testing.assert_array_equal(ekf.P, P)
    assert [r.reason for r in recs] == ["non_finite"] * 4 and not any(r.accepted for r in recs)
    assert all(np.isnan(r.nis) for r in recs)
    assert ekf.stats.count("encoders", "non_finite") == 1
    assert ekf.stats.count("landmark", "non_finite") == 2
    ekf.predict(u[21])                                  # the next counts span two periods
    assert ekf.update_encoders(ticks[22]).accepted
    assert np.all(np.isfinite(ekf.x)) and np.all(np.isfinite(ekf.P))


def test_lost_frames_are_bridged_by_the_counts(model, rng):
    u, ticks = _ticks_for(model, rng, 200)
    full = ModelEKF(model, initial_ticks=ticks[0])
    lossy = ModelEKF(model, initial_ticks=ticks[0])
    for k in range(len(u)):
        full.predict(u[k])
        full.update_encoders(ticks[k + 1])
        lossy.predict(u[k])
        if k % 10 not in (3, 4, 5):                     # three frames of every ten are lost
            lossy.update_encoders(ticks[k + 1])
    assert lossy.stats.count("encoders", "fused") >= 138
    np.testing.assert_allclose(lossy.pose, full.pose, atol=2e-3)


def test_rollover_of_the_16_bit_counters_is_seamless(fm):
    y = ef.encoder_speeds(np.array([[65530, 3], [2, 65531]]), fm)   # +8 left, -8 right
    np.testing.assert_allclose(y, [0.0, -16 * M_PER_TICK / DT / B])


def test_wrong_shapes_raise_clear_errors(model):
    ekf = ModelEKF(model, landmarks=LANDMARKS)
    cases = [
        (lambda: ekf.predict(np.zeros(3)), r"u of shape \(2,\)"),
        (lambda: ekf.update_encoders(np.zeros(3, int)), r"counts of shape \(2,\)"),
        (lambda: ModelEKF(model).update_speeds(np.zeros((2, 1))), r"shape \(2,\)"),
        (lambda: ekf.update_landmark(0, np.zeros(3)), r"observation of shape \(2,\)"),
        (lambda: ekf.update_pose(np.zeros(3), np.eye(2)), r"covariance \(3, 3\)"),
        (lambda: ef.predict_terms(np.zeros(4), np.zeros(2), ekf.fm), r"state of shape"),
    ]
    for call, match in cases:
        with pytest.raises(MeasurementShapeError, match=match):
            call()
    assert issubclass(MeasurementShapeError, ShapeError)
    with pytest.raises(NonFiniteInputError, match="finite"):
        ekf.predict(np.array([np.nan, 0.1]))
    with pytest.raises(FilterOptionError, match="symmetric positive definite"):
        ekf.update_pose(np.zeros(3), -np.eye(3))
    with pytest.raises(FilterOptionError, match="no landmark map"):
        ModelEKF(model).update_landmark(0, np.array([1.0, 0.0]))
    with pytest.raises(FilterOptionError, match="gate probability"):
        ModelEKF(model, options=EKFOptions(gate_probability=1.5))
    with pytest.raises(NotImplementedError, match="predict"):
        ekf.predict_update(np.zeros(2), None, None)


def test_unknown_landmarks_are_counted_or_raise_as_asked(model):
    ekf = ModelEKF(model, landmarks=LANDMARKS)
    ekf.predict(np.zeros(2))
    rec = ekf.update_landmark("door", np.array([1.0, 0.0]))
    assert rec.reason == "unknown_landmark" and not rec.accepted
    ekf.update_landmark(42, np.array([1.0, 0.0]))
    ekf.update_landmark("door", np.array([1.0, 0.0]))
    stats = ekf.stats
    assert stats.unknown_landmark_ids == ("door", 42)
    assert stats.count("landmark", "unknown_landmark") == 3
    strict = ModelEKF(model, landmarks=LANDMARKS, options=EKFOptions(unknown_landmarks="raise"))
    with pytest.raises(UnknownLandmarkError, match="'door' is not in the map"):
        strict.update_landmark("door", np.array([1.0, 0.0]))
    assert LANDMARKS.unknown([0, "door", 7, "door"]) == ("door", 7)


# -- landmarks and pose fixes ---------------------------------------------------------------------
def test_range_bearing_and_its_jacobian(rng):
    assert range_bearing(np.array([1.0, 1.0, 0.0]), np.array([4.0, 5.0])).tolist() == \
        pytest.approx([5.0, math.atan2(4.0, 3.0)])
    for _ in range(20):
        pose, lxy = rng.uniform(-3, 3, 3), rng.uniform(-3, 3, 2)
        num = numerical_jacobian(lambda p, lxy=lxy: range_bearing(p, lxy), pose, eps=1e-7)
        np.testing.assert_allclose(range_bearing_jacobian(pose, lxy), num, rtol=1e-6,
                                   atol=1e-8)


def test_bearing_residuals_wrap_across_the_seam(model):
    # a landmark straight behind the robot: predicted bearing +-pi
    d = range_bearing_residual(np.array([2.0, -math.pi + 0.01]), np.array([2.0, math.pi - 0.01]))
    assert d[1] == pytest.approx(0.02)
    ekf = ModelEKF(model, initial_pose=(2.5, 0.5, 0.0), landmarks={"behind": (0.5, 0.5)},
                   pose_std=(0.01, 0.01, 0.01))
    ekf.predict(np.zeros(2))
    rec = ekf.update_landmark("behind", np.array([2.0, -math.pi + 0.005]))
    assert rec.accepted and abs(rec.innovation[1]) < 0.01
    assert abs(wrap_angle(ekf.pose[2])) < 0.01


def test_a_pose_fix_pulls_the_estimate_and_wraps_the_heading(model):
    ekf = ModelEKF(model, initial_pose=(0.0, 0.0, math.pi - 0.01), pose_std=(0.1, 0.1, 0.1))
    ekf.predict(np.zeros(2))
    rec = ekf.update_pose(np.array([0.05, -0.05, -math.pi + 0.01]), np.eye(3) * 1e-4)
    assert rec.kind == "pose" and rec.accepted and rec.innovation[2] == pytest.approx(0.02)
    assert ekf.pose[:2] == pytest.approx([0.05, -0.05], abs=2e-3)
    assert wrap_angle(ekf.pose[2] - (-math.pi + 0.01)) == pytest.approx(0.0, abs=1e-3)
    far = ekf.update_pose(np.array([3.0, 0.0, 0.0]), np.eye(3) * 1e-4)
    assert far.reason == "gated" and far.nis > 1e4


def test_records_are_small_frozen_and_read_only(model):
    ekf = ModelEKF(model, initial_ticks=(0, 0), options=EKFOptions(history=3))
    ekf.predict(np.zeros(2))
    rec = ekf.update_encoders(np.array([0, 0]))
    assert isinstance(rec, UpdateRecord)
    assert {f.name for f in dataclasses.fields(rec)} >= {
        "innovation", "innovation_cov", "nis", "accepted", "kind", "t_s"}
    assert rec.t_s == pytest.approx(DT) and rec.kind == "encoders"
    with pytest.raises(dataclasses.FrozenInstanceError):
        rec.accepted = False
    with pytest.raises(ValueError, match="read-only"):
        rec.innovation[0] = 1.0
    np.testing.assert_allclose(rec.innovation_cov, ekf.S)
    assert rec.nis == pytest.approx(rec.innovation @ np.linalg.solve(ekf.S, rec.innovation))
    for _ in range(5):
        ekf.predict(np.zeros(2))
        ekf.update_encoders(np.array([0, 0]))
    assert len(ekf.records) == 3 and ekf.records[-1].t_s == pytest.approx(6 * DT)


def test_update_speeds_refuses_to_mix_with_counts(model):
    ekf = ModelEKF(model, initial_ticks=(0, 0))
    with pytest.raises(FilterOptionError, match="update_encoders"):
        ekf.update_speeds(np.zeros(2))


# -- covariance invariants ------------------------------------------------------------------------
# The EKF's own compiled step (fusion.ekf.kernel): F P F^T + Q and the encoder update.
@numba.njit(cache=True)
def _encoder_periods(P, k0, n_steps, Fs, Qs, R_enc, force):
    """Periods ``k0 .. k0 + n_steps - 1``: the kernel's propagation and encoder update (with
    ``force`` every reading fused; an argument, so the kernel keeps its one signature)."""
    x, innovation = np.zeros(P.shape[0]), np.zeros(2)
    for k in range(k0, k0 + n_steps):
        j = k % Fs.shape[0]
        P = kernel._propagate(P, Fs[j], Qs[j])
        P = kernel.selector_update_kernel(x, P, innovation, R_enc, 0.0, force)[7]
    return P


def _landmark_update(P, H, R):
    """The filter's numpy landmark update (GatedUpdates._gated): Joseph form, eq. 5.2.3-18."""
    PHt = P @ H.T
    K = PHt @ inverse_covariance(H @ PHt + R)
    return ef.joseph_covariance(P, K, H, R, PHt)


def test_covariance_stays_symmetric_positive_definite_over_a_million_steps(model, fm):
    """10^6 periods of propagate + encoder update (+ a landmark every 16th), Joseph form,
    through the filter's own code: the compiled kernels of the EKF step and its numpy
    landmark update.

    Jacobians and noise come from predict_terms along a drive (cycled).
    """
    rng = np.random.default_rng(7)
    u, y = _from_the_model(model, rng, 1000)
    x = ef.initial_state(fm, (2.5, 1.0, 0.0))
    Fs, Qs, Hs = [], [], []
    for k in range(len(u)):
        x, F, Q = ef.predict_terms(x, u[k], fm)
        x[fm.speed_slice] = y[k]
        Fs.append(F.copy())
        Qs.append(Q.copy())
        Hs.append(ef.landmark_jacobian(x, LANDMARKS.position(k % 4)))
    Fs, Qs, R_enc = np.array(Fs), np.array(Qs), np.array(fm.encoder_cov)
    R_lm = LandmarkNoise().cov(2.5)
    P, snaps = ef.initial_covariance(fm), []
    for k0 in range(0, 1_000_000, 16):
        P = _encoder_periods(P, k0, 16, Fs, Qs, R_enc, True)
        P = _landmark_update(P, Hs[k0 % len(Hs)], R_lm)
        if k0 % 5120 == 0:
            snaps.append(P)
    snaps = np.array([*snaps, P])
    assert np.all(np.isfinite(snaps))
    scale = np.abs(snaps).max(axis=(1, 2))
    assert np.max(np.abs(snaps - snaps.transpose(0, 2, 1)).max(axis=(1, 2)) / scale) < 1e-12
    d = np.sqrt(np.diagonal(snaps, axis1=1, axis2=2))
    correlation = snaps / (d[:, :, None] * d[:, None, :])
    assert np.linalg.eigvalsh(correlation).min() > 0.0
    np.linalg.cholesky(snaps)


def test_predict_and_update_keep_P_symmetric_positive_definite(model, rng):
    u, ticks = _ticks_for(model, rng, 500)
    ekf = ModelEKF(model, initial_ticks=ticks[0], landmarks=LANDMARKS, initial_pose=(2.0, 2.0, 0))
    for k in range(len(u)):
        ekf.predict(u[k])
        ekf.update_encoders(ticks[k + 1])
        if k % 20 == 0:
            ekf.update_landmark(k % 4, range_bearing(ekf.pose, LANDMARKS.position(k % 4)))
        np.testing.assert_allclose(ekf.P, ekf.P.T, rtol=0, atol=1e-14 * np.abs(ekf.P).max())
        np.linalg.cholesky(ekf.P)


# -- the example ----------------------------------------------------------------------------------
def test_example_runs_with_a_short_horizon(tmp_path, capsys, load_example):
    example = load_example("ekf_plugin")
    assert example.main(["--out", str(tmp_path), "--duration-s", "10", "--short"]) == 0
    png = tmp_path / "ekf_plugin.png"
    assert png.exists() and png.stat().st_size > 10_000
    assert "position RMS error EKF" in capsys.readouterr().out


def test_a_models_offset_reaches_the_speed_state_and_the_pose(model, rng):
    """Sensor-less, the filter's speeds are the model's free run, affine offset included."""
    shifted = model.updated(offset_speeds=[0.01, -0.02])
    u = held_commands(rng, 200)
    ekf = ModelEKF(shifted, initial_pose=(0.0, 0.0, 0.0))
    speeds = []
    for k in range(len(u)):
        speeds.append(ekf.speeds)
        ekf.predict(u[k])
    want = shifted.simulate(u[:-1])
    np.testing.assert_allclose(np.array(speeds)[1:], want, atol=1e-12)
    np.testing.assert_allclose(speeds[0], [0.01, -0.02], atol=1e-15)
    np.testing.assert_allclose(ekf.pose, shifted.predict_poses(u)[-1], atol=1e-9)


# -- counter width ---------------------------------------------------------------------------------
@pytest.mark.parametrize("bits", [12, 24, 32, 64])
def test_counters_of_any_width_wrap_where_they_wrap(model, rng, bits):
    """The same drive with counts offset to just below the ring's top (so they wrap on the
    way) gives the same estimate as with the plain counts, for any counter width; a 16-bit
    filter reading 12-bit counts takes their wrap for a jump of 4,096 ticks and rejects it
    (wider counters read as 16-bit would pass: 2**16 divides their ring)."""
    u, ticks = _ticks_for(model, rng, 300)
    ticks = np.asarray(ticks, np.int64)
    top = (1 << 62) if bits >= 63 else 1 << bits
    wrapped = (ticks + top - 40) % top if bits < 63 else ticks + top - 40

    def run(counts, counter_bits):
        ekf = ModelEKF(model, initial_ticks=counts[0],
                       options=EKFOptions(counter_bits=counter_bits))
        accepted = []
        for k in range(len(u)):
            ekf.predict(u[k])
            accepted.append(ekf.update_encoders(counts[k + 1]).accepted)
        return ekf.x.copy(), np.array(accepted)

    x_plain, ok_plain = run(ticks, bits)
    x_wrapped, ok_wrapped = run(wrapped, bits)
    assert ok_plain.all() and ok_wrapped.all()
    np.testing.assert_allclose(x_wrapped, x_plain, rtol=0, atol=1e-12)
    if bits == 12:
        _, ok16 = run(wrapped, 16)
        assert not ok16.all()


def test_counter_width_out_of_range_is_refused(model):
    with pytest.raises(FilterOptionError, match=r"counter_bits must be an int in 8\.\.64"):
        ModelEKF(model, options=EKFOptions(counter_bits=7))


@pytest.mark.parametrize("history", [-1, 2.5, None])
def test_a_history_that_is_not_a_count_is_refused(history):
    with pytest.raises(FilterOptionError, match=r"history must be an int of 0 or more .*"
                                                rf"got {re.escape(repr(history))}"):
        EKFOptions(history=history)


def test_a_model_files_path_is_refused_with_how_to_load_it(tmp_path):
    from fusion.exceptions import NotAModelError

    path = str(tmp_path / "model_arx.json")
    with pytest.raises(NotAModelError, match=r"got a str .*MotionModel\.load") as err:
        ModelEKF(path)
    assert isinstance(err.value, TypeError) and "\n" not in str(err.value)
    with pytest.raises(NotAModelError, match=r"got a dict$"):
        ModelEKF({"na": 2})
