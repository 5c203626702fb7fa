"""Scale-change test from landmarks (docs/monitor.md: the floor turns to carpet).

Closed-form checks of the batched odometry filter (range-bearing model against
the scalar functions, the transition against a numerical Jacobian, the
log-likelihood against scipy), then the simulator: the closed
route with its landmarks at 2 Hz, seeded carpet runs, the same runs without
the fault, and one hour of nominal driving (the benchmark runs ten:
``benchmarks/bench_scale.py``, ``docs/monitor.md``), then bad input and the
:class:`~fusion.monitoring.ResidualMonitor` wiring.
"""

import math

import numpy as np
import pytest
from scipy.stats import multivariate_normal

# the route drives are the benchmark's own (pytest puts the project root on the path)
from benchmarks.bench_scale import (
    alarms,
    carpet_runs,
    route_drives,
    true_ratio,
)
from drivers.sim.config import get_preset
from fusion.exceptions import FilterOptionError, FusionError, MeasurementShapeError
from fusion.landmark_map import LandmarkMap
from fusion.monitoring.residual import MonitorOptions, ResidualMonitor
from fusion.monitoring.scale import ScaleMonitor, ScaleOptions
from fusion.monitoring.scale_odometry import (
    KAPPA,
    KV,
    KW,
    landmark_update,
    landmark_update_compiled,
    odometry_predict,
    odometry_predict_into,
    range_bearing_batch,
)
from fusion.noise import LandmarkNoise, SlipNoise
from fusion.range_bearing import (
    RangeBearing,
    range_bearing,
    range_bearing_jacobian,
    range_bearing_terms,
)
from fusion.sensor_pose import SensorPose
from lti_motion.app.route import ROUTE_LANDMARKS
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import pose_step

WHEEL_BASE_M = get_preset("create2").wheel_base_m
LANDMARKS = LandmarkMap({1: (2.0, 1.0), 2: (4.0, -1.0)})


@pytest.fixture(scope="module")
def m_per_tick(route_model):
    return route_model.m_per_tick


# -- the batched filter ----------------------------------------------------------------------
@pytest.mark.parametrize("pose, landmark", [
    ((0.0, 0.0, 0.0), (2.0, 0.0)),
    ((1.0, -0.5, 2.5), (-1.0, 3.7)),
    ((3.0, 2.0, -3.1), (4.0, -1.0)),          # bearing near the +-pi seam
    ((0.2, 0.1, 7.0), (0.2, 0.3)),             # heading beyond 2 pi, landmark close
])
def test_range_bearing_batch_agrees_with_the_scalar_functions(pose, landmark):
    x = np.array([[*pose, 0.01, -0.02, 0.03]])
    pred, H = range_bearing_batch(x, np.array([landmark]))
    np.testing.assert_allclose(pred[0], range_bearing(np.array(pose), np.array(landmark)),
                               atol=1e-12)
    np.testing.assert_allclose(H[0, :, :3], range_bearing_jacobian(np.array(pose),
                                                                   np.array(landmark)))
    assert np.all(H[0, :, 3:] == 0.0)


def test_range_bearing_batch_takes_one_sensor_mount_per_row(rng):
    """Rows of robots with different sensors: each row is the one model for its mount
    (fusion.range_bearing eq. 1-2), the pose Jacobian a numerical derivative's."""
    x = np.column_stack([rng.uniform(-2, 2, (6, 2)), rng.uniform(-3, 3, 6), np.zeros((6, 3))])
    lxy = rng.uniform(-5, 5, (6, 2))
    mounts = np.column_stack([rng.uniform(-0.3, 0.3, (6, 2)), rng.uniform(-1, 1, 6)])
    pred, H = range_bearing_batch(x, lxy, sensor=mounts)
    for i in range(6):
        z, h_pose, _ = range_bearing_terms(x[i], lxy[i], sensor=SensorPose(*mounts[i]))
        np.testing.assert_allclose(pred[i], z, atol=1e-12)
        np.testing.assert_allclose(H[i, :, :3], h_pose, atol=1e-12)
        num = np.stack([(range_bearing_batch(x[i:i + 1] + e, lxy[i:i + 1], sensor=mounts[i:i + 1])
                         [0][0] - range_bearing_batch(x[i:i + 1] - e, lxy[i:i + 1],
                                                      sensor=mounts[i:i + 1])[0][0]) / 2e-6
                        for e in 1e-6 * np.eye(6)], axis=1)
        np.testing.assert_allclose(H[i], num, rtol=1e-6, atol=1e-8)


def _mean_step(x, deltas, intrinsics):
    """Module eq. 1 written out per wheel: ``(ds, dtheta) = J (d_l, d_r)``."""
    ds = 0.5 * (intrinsics.m_per_tick_left * deltas[0] + intrinsics.m_per_tick_right * deltas[1])
    dth = (intrinsics.m_per_tick_right * deltas[1]
           - intrinsics.m_per_tick_left * deltas[0]) / intrinsics.wheel_base_m
    pose = pose_step(x[:3], (1.0 + x[KV]) * ds, (1.0 + x[KW]) * dth + x[KAPPA] * ds, 1.0)
    return np.concatenate([pose, x[3:]])


@pytest.mark.parametrize("deltas", [(8.0, 8.0), (-6.0, 6.0), (3.0, 11.0), (0.0, 0.0)])
def test_odometry_predict_mean_and_covariance_match_a_numerical_linearisation(deltas):
    """Without noise, ``P' = J P J^T`` with ``J`` the central-difference Jacobian of the
    mean step (eq. 1): straight, turning in place, an arc and at rest; unequal wheels."""
    intrinsics = OdometryIntrinsics(4.42e-4, 4.38e-4, WHEEL_BASE_M)
    x = np.array([[0.3, -0.2, 0.7, -0.03, 0.02, 0.015]])
    d = np.array([deltas])
    A = np.random.default_rng(3).standard_normal((6, 6)) * 0.01
    P = (A @ A.T + 1e-6 * np.eye(6))[None]
    quiet = SlipNoise(v_frac=0.0, w_frac=0.0, w_per_v_rad_m=0.0, v_floor_m_s=0.0,
                      w_floor_rad_s=0.0)
    x1, P1 = odometry_predict(x, P, d, intrinsics=intrinsics, dt_s=0.015, slip=quiet,
                              walk_var=np.zeros(3), missing_std=(0.5, 4.0))
    np.testing.assert_allclose(x1[0], _mean_step(x[0], d[0], intrinsics), atol=1e-15)
    eps = 1e-6
    J = np.stack([(_mean_step(x[0] + eps * e, d[0], intrinsics)
                   - _mean_step(x[0] - eps * e, d[0], intrinsics)) / (2 * eps)
                  for e in np.eye(6)], axis=1)
    np.testing.assert_allclose(P1[0], J @ P[0] @ J.T, rtol=1e-6, atol=1e-14)


def test_the_compiled_prediction_equals_the_numpy_reference(rng):
    """odometry_predict_into (numba) against odometry_predict, row by row: the states bit for
    bit, the covariances to rounding; straight, turning in place, a half turn in one period
    (the closed form of sin(h)/h), at rest and missing counts, unequal wheels."""
    n = 40
    intrinsics = OdometryIntrinsics(4.42e-4, 4.38e-4, WHEEL_BASE_M)
    x = np.column_stack([rng.normal(0.0, 2.0, (n, 3)), rng.normal(0.0, 0.03, (n, 3))])
    A = rng.standard_normal((n, 6, 6)) * 0.01
    P = A @ A.transpose(0, 2, 1) + 1e-6 * np.eye(6)
    P = 0.5 * (P + P.transpose(0, 2, 1))
    d = rng.normal(0.0, 10.0, (n, 2))
    d[:6] = [(8.0, 8.0), (-6.0, 6.0), (-600.0, 600.0), (0.0, 0.0), (np.nan, 5.0), (3.0, np.inf)]
    kw = dict(intrinsics=intrinsics, dt_s=0.015, slip=SlipNoise(),
              walk_var=np.array([1e-8, 2e-8, 3e-8]), missing_std=(0.5, 4.0))
    x_ref, P_ref = odometry_predict(x, P, d, **kw)
    x_out, P_out = np.empty_like(x), np.empty_like(P)
    odometry_predict_into(x, P, d, x_out, P_out, **kw)
    np.testing.assert_array_equal(x_out, x_ref)
    np.testing.assert_allclose(P_out, P_ref, rtol=1e-13, atol=1e-15 * np.abs(P_ref).max())
    assert np.all(P_out == P_out.transpose(0, 2, 1))
    # in blocks: 8 robots' counts for 5 rows each (a robot's shadows share its counts)
    x_ref, _ = odometry_predict(x, P, np.tile(d[:8], (5, 1)), **kw)
    odometry_predict_into(x, P, d[:8], x_out, P_out, **kw)
    np.testing.assert_array_equal(x_out, x_ref)
    with pytest.raises(MeasurementShapeError, match="dividing"):
        odometry_predict_into(x, P, d[:7], x_out, P_out, **kw)


def test_the_compiled_landmark_update_equals_the_numpy_reference(rng):
    """landmark_update_compiled against landmark_update: the same gate decisions, states,
    covariances and log-likelihoods to rounding; outliers gated, own covariances on some
    rows, sensors off the axle."""
    n = 30
    x = np.column_stack([rng.uniform(-2, 2, (n, 2)), rng.uniform(-3, 3, n),
                         rng.normal(0.0, 0.03, (n, 3))])
    A = rng.standard_normal((n, 6, 6)) * 0.02
    P = A @ A.transpose(0, 2, 1) + 1e-6 * np.eye(6)
    P = 0.5 * (P + P.transpose(0, 2, 1))
    lxy = rng.uniform(-5, 5, (n, 2))
    mounts = np.column_stack([rng.uniform(-0.3, 0.3, (n, 2)), rng.uniform(-1, 1, n)])
    z = range_bearing_batch(x, lxy, sensor=mounts)[0] + rng.normal(0.0, 1.0, (n, 2)) * [0.05, 0.02]
    z[::7] += 3.0                                            # outliers
    cov = np.full((n, 2, 2), np.nan)
    cov[::3] = np.array([[0.01, 0.001], [0.001, 0.002]])
    ref = landmark_update(x, P, lxy, z, LandmarkNoise(), 13.8, cov=cov, sensor=mounts)
    out = landmark_update_compiled(x, P, lxy, z, LandmarkNoise(), 13.8, cov=cov, sensor=mounts)
    np.testing.assert_array_equal(out[2], ref[2])
    assert 0 < ref[2].sum() < n
    np.testing.assert_allclose(out[0], ref[0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(out[1], ref[1], rtol=1e-12, atol=1e-14 * np.abs(ref[1]).max())
    np.testing.assert_allclose(out[3], ref[3], rtol=1e-12)
    assert np.all(out[1] == out[1].transpose(0, 2, 1))


def test_missing_counts_move_nothing_and_grow_the_pose_covariance():
    x, P = np.zeros((1, 6)), np.tile(np.eye(6) * 1e-6, (1, 1, 1))
    x1, P1 = odometry_predict(x, P, np.array([[np.nan, 5.0]]),
                              intrinsics=OdometryIntrinsics.symmetric(
                                  m_per_tick=4.4e-4, wheel_base_m=WHEEL_BASE_M),
                              dt_s=0.015, slip=SlipNoise(), walk_var=np.zeros(3),
                              missing_std=(0.5, 4.0))
    assert np.all(x1 == 0.0)
    assert P1[0, 0, 0] == pytest.approx(1e-6 + (0.5 * 0.015) ** 2)
    assert P1[0, 2, 2] == pytest.approx(1e-6 + (4.0 * 0.015) ** 2)


def test_landmark_update_likelihood_gate_and_covariance(rng):
    n = 6
    x = np.column_stack([rng.uniform(0, 3, (n, 2)), rng.uniform(-3, 3, n), np.zeros((n, 3))])
    A = rng.standard_normal((n, 6, 6)) * 0.02
    P = A @ A.transpose(0, 2, 1) + 1e-6 * np.eye(6)
    lxy = np.tile([-1.0, 3.7], (n, 1))
    noise = LandmarkNoise()
    pred, H = range_bearing_batch(x, lxy)
    z = pred + rng.normal(0.0, 0.05, (n, 2))
    z[0, 0] += 5.0                                   # an outlier: gated
    gate = 13.8
    x1, P1, ok, ll = landmark_update(x, P, lxy, z, noise, gate)
    assert not ok[0] and np.all(ok[1:])
    np.testing.assert_array_equal(x1[0], x[0])
    np.testing.assert_array_equal(P1[0], P[0])
    for i in range(1, n):
        S = H[i] @ P[i] @ H[i].T + noise.cov(pred[i, 0])
        ref = multivariate_normal(np.zeros(2), S).logpdf(z[i] - pred[i]) + math.log(2 * math.pi)
        assert ll[i] == pytest.approx(ref, rel=1e-9)
        assert np.allclose(P1[i], P1[i].T) and np.linalg.eigvalsh(P1[i]).min() > 0
        assert np.trace(P1[i]) < np.trace(P[i])
    # the outlier's NIS is clipped at the gate in the likelihood
    S0 = H[0] @ P[0] @ H[0].T + noise.cov(pred[0, 0])
    assert ll[0] == pytest.approx(-0.5 * (gate + np.linalg.slogdet(S0)[1]))


def test_threshold_follows_the_false_alarm_budget():
    # eq. 2: 1,800 shadow starts an hour, F = 0.1 -> h = ln(18,000)
    assert ScaleOptions().threshold == pytest.approx(math.log(18000.0))
    assert ScaleOptions(false_alarms_per_hour=1.0, restart_every_s=1.0).threshold == \
        pytest.approx(math.log(3600.0))


def _straight_drive(ratio_after, *, change_k=400, steps=1000, noise_rng=None, mount=None):
    """0.25 m/s along x past two landmarks; after ``change_k`` the ground travel is
    ``ratio_after`` times the encoders'. Sightings noise-free unless ``noise_rng``, from a
    sensor at ``mount`` (default centred) which they carry."""
    mon = ScaleMonitor(5e-4, WHEEL_BASE_M, LANDMARKS, initial_pose=(0.0, 0.0, 0.0))
    x_m, found = 0.0, []
    noise = LandmarkNoise()
    for k in range(1, steps):
        x_m += (1.0 if k < change_k else ratio_after) * 7.5 * 5e-4
        seen = RangeBearing.empty()
        if k % 8 == 0:
            j = 1 + k // 8 % 2
            rb = range_bearing(np.array([x_m, 0.0, 0.0]), LANDMARKS.position(j), sensor=mount)
            if noise_rng is not None:
                rb = rb + noise_rng.normal(0.0, 1.0, 2) * [0.02 * rb[0], noise.bearing_std_rad]
            seen = RangeBearing(k, [j], rb[:1], rb[1:], sensor_pose=mount)
        found += mon.update(0.015 * k, np.array([7.5, 7.5]), [seen])
    return mon, found


@pytest.mark.parametrize("ratio", [0.96, 1.04])
def test_a_scale_change_on_a_straight_line_is_found_with_its_size_and_onset(ratio, rng):
    mon, found = _straight_drive(ratio, noise_rng=rng)
    assert len(found) == 1
    a = found[0]
    # shadows start every 2 s: the onset estimate is within one start of the truth
    assert abs(a.onset_s - 6.0) <= 2.0 + 0.015
    assert 6.0 < a.t_s < 16.0                     # within the target's 10 s
    assert abs(a.scale_ratio - ratio) < 3.0 * a.scale_ratio_std
    assert a.scale_ratio_std < 0.01
    # the main filter went on from the alarm's estimate
    assert mon.scale_ratio[0] == pytest.approx(ratio, abs=0.01)


def test_no_change_no_alarm(rng):
    _, found = _straight_drive(1.0, noise_rng=rng)
    assert found == []


def test_a_sensor_ahead_of_the_axle_finds_the_change_as_a_centred_one(rng):
    mount = SensorPose(0.22, 0.0, 0.0)
    mon, found = _straight_drive(0.96, noise_rng=rng, mount=mount)
    assert len(found) == 1 and 6.0 < found[0].t_s < 16.0
    assert abs(found[0].scale_ratio - 0.96) < 3.0 * found[0].scale_ratio_std
    assert mon.counts["gated"] <= 2
    quiet, none = _straight_drive(1.0, noise_rng=rng, mount=mount)
    assert none == [] and quiet.counts["gated"] <= 2


# -- the simulator ---------------------------------------------------------------------------
def test_carpet_is_found_within_10_s_with_its_scale(m_per_tick):
    """8 route runs (seeds 300-307, onsets uniform in 15-40 s, seed 7): every run alarms
    after its onset, none before, median delay <= 10 s (the benchmark: 20 runs, 5.9 s)."""
    res = carpet_runs(m_per_tick, n=8)
    assert res.detected == 8
    assert res.false_before == 0
    assert np.median(res.delays_s) <= 10.0 and res.delays_s.max() <= 15.0
    # the monitor's own scale 10 s after the alarm is within 2% of the truth
    assert res.later_errors_pct.size >= 6 and np.all(res.later_errors_pct < 2.0)


def test_the_same_runs_without_the_fault_raise_nothing(m_per_tick):
    drives = route_drives(m_per_tick, range(300, 308))
    found, ratios = alarms(m_per_tick, drives)
    assert all(a == [] for a in found)
    # on the calibration's own floor the scale stays near what the truth says
    for i in range(8):
        assert ratios[i, -1] == pytest.approx(true_ratio(m_per_tick, drives, i, 5.0), abs=0.01)


def test_one_hour_of_nominal_driving_raises_at_most_one_alarm(m_per_tick):
    """60 runs of the route (seeds 2000-2059, about an hour of driving); the benchmark
    measured 1 alarm in 11.8 h, so 2 or more here would mean the design broke."""
    drives = route_drives(m_per_tick, range(2000, 2060))
    assert drives.driving_s.sum() > 0.9 * 3600.0
    found, _ = alarms(m_per_tick, drives)
    assert sum(len(a) for a in found) <= 1


# -- bad input -------------------------------------------------------------------------------
def test_bad_options_and_shapes_raise_clear_errors():
    with pytest.raises(FilterOptionError, match="restart_std"):
        ScaleOptions(restart_std=(0.0, 0.05))
    with pytest.raises(FilterOptionError, match="false_alarms_per_hour"):
        ScaleOptions(false_alarms_per_hour=0.0)
    with pytest.raises(FilterOptionError, match="m_per_tick"):
        ScaleMonitor(-1.0, WHEEL_BASE_M, LANDMARKS, initial_pose=(0, 0, 0))
    with pytest.raises(MeasurementShapeError, match="initial_pose"):
        ScaleMonitor(5e-4, WHEEL_BASE_M, LANDMARKS, initial_pose=(0, 0))
    with pytest.raises(FilterOptionError, match="pose_std"):
        ScaleMonitor(5e-4, WHEEL_BASE_M, LANDMARKS, initial_pose=(0, 0, 0), pose_std=(0, 1, 1))
    mon = ScaleMonitor(5e-4, WHEEL_BASE_M, LANDMARKS, initial_pose=np.zeros((2, 3)))
    with pytest.raises(MeasurementShapeError, match=r"tick deltas \(2, 2\)"):
        mon.update(0.015, np.zeros(2))
    with pytest.raises(MeasurementShapeError, match="observations for 2 robots"):
        mon.update(0.015, np.zeros((2, 2)), [RangeBearing.empty()])
    with pytest.raises(MeasurementShapeError, match=r"observations for 2 robots, got 3"):
        mon.update(0.03, np.zeros((2, 2)), [RangeBearing.empty()] * 3)
    with pytest.raises(FusionError, match="time order"):
        mon.update(0.01, np.zeros((2, 2)))


def test_missing_and_unknown_readings_are_counted_not_fused():
    mon = ScaleMonitor(5e-4, WHEEL_BASE_M, LANDMARKS, initial_pose=(0.0, 0.0, 0.0))
    mon.update(0.015, [np.nan, 3.0], [RangeBearing(1, [99, 99], [2.0, 2.5], [0.1, 0.2])])
    assert mon.counts == {"updates": 0, "gated": 0, "missing": 1, "unknown_landmark": 2}
    assert np.all(np.isfinite(mon.pose))
    with pytest.raises(FusionError, match="non-finite"):     # a NaN sighting is no sighting
        RangeBearing(1, [1], [np.nan], [0.1])


def test_a_sightings_own_covariance_replaces_the_sensor_noise(rng):
    """Rows with a covariance use it, rows of NaN (no covariance) the sensor's noise at the
    predicted range; the monitor passes a RangeBearing's covariances on."""
    n = 4
    x = np.column_stack([rng.uniform(0, 3, (n, 2)), rng.uniform(-3, 3, n), np.zeros((n, 3))])
    P = np.tile(np.eye(6) * 1e-3, (n, 1, 1))
    lxy = np.tile([-1.0, 3.7], (n, 1))
    noise = LandmarkNoise()
    pred, _ = range_bearing_batch(x, lxy)
    z = pred + 0.01
    own = np.stack([noise.cov(r) for r in pred[:, 0]])
    cov = own.copy()
    cov[1] = np.nan
    cov[2] *= 4.0
    plain = landmark_update(x, P, lxy, z, noise, 13.8)
    mixed = landmark_update(x, P, lxy, z, noise, 13.8, cov=cov)
    for j in (0, 1, 3):
        np.testing.assert_allclose(mixed[0][j], plain[0][j], rtol=1e-12, atol=1e-15)
    assert np.abs(mixed[0][2] - x[2]).max() < np.abs(plain[0][2] - x[2]).max()
    # through the monitor: a huge covariance leaves the pose where odometry put it
    mons = [ScaleMonitor(5e-4, WHEEL_BASE_M, LANDMARKS, initial_pose=(0.0, 0.0, 0.0))
            for _ in range(2)]
    seen = RangeBearing(1, [1], [2.3], [0.5])
    mons[0].update(0.015, [7.5, 7.5], [seen])
    mons[1].update(0.015, [7.5, 7.5], [RangeBearing(1, [1], [2.3], [0.5],
                                                    cov=[np.eye(2) * 1e6])])
    assert mons[0].counts["updates"] == mons[1].counts["updates"] == 1
    moved = [np.abs(m.pose[0, :2] - [7.5 * 5e-4, 0.0]).max() for m in mons]
    assert moved[1] < 1e-6 < moved[0]


# -- ResidualMonitor wiring ------------------------------------------------------------------
def test_residual_monitor_raises_scale_changed_with_the_new_scale(rng):
    scale = ScaleMonitor(5e-4, WHEEL_BASE_M, LANDMARKS, initial_pose=(0.0, 0.0, 0.0))
    events = []
    mon = ResidualMonitor(MonitorOptions(), scale=scale, on_alarm=events.append)
    x_m = 0.0
    for k in range(1, 1000):
        x_m += (1.0 if k < 400 else 0.96) * 7.5 * 5e-4
        seen = None
        if k % 8 == 0:
            j = 1 + k // 8 % 2
            r, b = range_bearing(np.array([x_m, 0.0, 0.0]), LANDMARKS.position(j))
            seen = RangeBearing(k, [j], [r], [b])
        mon.update_landmarks(0.015 * k, [7.5, 7.5], seen)
    assert [e.kind for e in events] == ["scale_changed"]
    e = events[0]
    assert e.test == "scale_glr" and e.statistic > e.threshold == scale.threshold
    assert e.scale.scale_ratio == pytest.approx(0.96, abs=0.01) and e.onset_s == 6.0
    # with the scale test given, biased landmark innovations no longer feed the generic
    # landmark NIS and CUSUM (the scale test replaces them)
    for k in range(400):
        mon.update_innovation(20.0 + 0.125 * k, np.array([0.05, 0.0]), np.eye(2) * 1e-3,
                              stream="landmark")
    assert len(mon.events) == 1


def test_residual_monitor_scale_wiring_errors():
    with pytest.raises(FilterOptionError, match="ScaleMonitor"):
        ResidualMonitor().update_landmarks(0.0, [0.0, 0.0])
    two = ScaleMonitor(5e-4, WHEEL_BASE_M, LANDMARKS, initial_pose=np.zeros((2, 3)))
    with pytest.raises(FilterOptionError, match="one robot"):
        ResidualMonitor(scale=two)
    mon = ResidualMonitor(scale=ScaleMonitor(5e-4, WHEEL_BASE_M, ROUTE_LANDMARKS,
                                             initial_pose=(0.0, 0.0, 0.0)))
    mon.update_landmarks(1.0, [1.0, 1.0])
    with pytest.raises(FusionError, match="time order"):
        mon.update_landmarks(0.5, [1.0, 1.0])
