"""Offline intrinsics calibration (Censi et al. 2013): recovery on closed-form kinematic
drives, the sensor's pose, and the errors for references that cannot work."""

import numpy as np
import pytest

from lti_motion.calibration.intrinsics_fit import calibrate_intrinsics
from lti_motion.exceptions import CalibrationError, PoseReferenceError, UnidentifiableError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import integrate_poses

TRUE = OdometryIntrinsics(4.49e-4, 4.4455e-4, 0.236)   # left wheel 1% larger
DT = 0.015


def _drive(rates, seconds, k=TRUE):
    """Tick rates (ticks/s per wheel) held for ``seconds``; counts, times and true poses."""
    rate = np.repeat(np.asarray(rates, float), np.round(np.asarray(seconds) / DT).astype(int),
                     axis=0)
    cum = np.vstack([[0.0, 0.0], np.cumsum(rate * DT, axis=0)])
    ticks = np.round(cum).astype(np.int64)
    t = np.arange(len(ticks)) * DT
    poses = integrate_poses(k.body_motion(np.diff(cum, axis=0)), 1.0)
    return t, ticks % 65536, poses


def _compose(poses, offset):
    """World pose of a frame mounted at ``offset`` (x, y, theta) on the robot."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    return np.stack([poses[:, 0] + c * offset[0] - s * offset[1],
                     poses[:, 1] + s * offset[0] + c * offset[1], poses[:, 2] + offset[2]], 1)


RICH = ([[450, 450], [-250, 250], [450, 450], [250, -250], [500, 300], [300, 500]] * 3,
        [4.0, 3.0, 4.0, 3.0, 3.0, 3.0] * 3)


def _reference(rng, poses, t, *, std=(0.003, 0.0052), every=7):
    noise = rng.standard_normal((len(poses[::every]), 3)) * [std[0], std[0], std[1]]
    return t[::every], poses[::every] + noise


def test_recovers_both_wheels_and_the_base_within_its_covariance(rng):
    t, ticks, poses = _drive(*RICH)
    rt, rp = _reference(rng, poses, t)
    cal = calibrate_intrinsics(t, ticks, rt, rp, sensor_pose=False, position_std_m=0.003,
                               heading_std_rad=np.deg2rad(0.3))
    est = np.array(list(cal.intrinsics.as_dict().values()))
    truth = np.array(list(TRUE.as_dict().values()))
    rel = np.abs(est / truth - 1.0)
    assert np.all(rel < 2e-3), rel
    assert np.all(np.abs(est - truth) < 5.0 * cal.std), (est - truth) / cal.std
    assert cal.covariance.shape == (3, 3)
    np.testing.assert_allclose(cal.covariance, cal.covariance.T, rtol=1e-12)
    assert np.all(np.linalg.eigvalsh(cal.covariance) > 0)
    assert cal.report.turns_left > 0 and cal.report.turns_right > 0
    assert cal.report.straight_runs > 0 and cal.report.undetermined == ()


def test_noise_free_closed_form_is_exact_and_refinement_keeps_it():
    t, ticks, poses = _drive(*RICH)
    cal = calibrate_intrinsics(t, ticks, t[::5], poses[::5], sensor_pose=False)
    for est in (cal.closed_form, cal.intrinsics):
        for name, value in TRUE.as_dict().items():
            assert getattr(est, name) == pytest.approx(value, rel=2e-4), name


def test_recovers_the_pose_of_a_sensor_mounted_off_the_axle(rng):
    offset = np.array([0.08, -0.03, 0.3])
    t, ticks, poses = _drive(*RICH)
    rt, rp = _reference(rng, _compose(poses, offset), t, std=(0.001, np.deg2rad(0.1)))
    cal = calibrate_intrinsics(t, ticks, rt, rp, sensor_pose=True, position_std_m=0.001,
                               heading_std_rad=np.deg2rad(0.1))
    np.testing.assert_allclose(cal.sensor_pose, offset, atol=3e-3)
    assert cal.intrinsics.wheel_base_m == pytest.approx(TRUE.wheel_base_m, rel=3e-3)
    assert cal.covariance.shape == (6, 6)


def test_no_turns_is_unidentifiable_never_nan(rng):
    t, ticks, poses = _drive([[450, 450]], [20.0])
    rt, rp = _reference(rng, poses, t)
    with pytest.raises(UnidentifiableError, match="no turns"):
        calibrate_intrinsics(t, ticks, rt, rp)


def test_turns_one_way_only_without_straight_runs_is_unidentifiable(rng):
    t, ticks, poses = _drive([[-250, 250]], [30.0])
    rt, rp = _reference(rng, poses, t)
    with pytest.raises(UnidentifiableError, match="one proportion"):
        calibrate_intrinsics(t, ticks, rt, rp, sensor_pose=False)


def test_turns_one_way_with_straight_runs_works_and_says_so(rng):
    t, ticks, poses = _drive([[450, 450], [-250, 250]] * 4, [4.0, 3.0] * 4)
    rt, rp = _reference(rng, poses, t)
    cal = calibrate_intrinsics(t, ticks, rt, rp, sensor_pose=False, position_std_m=0.003,
                               heading_std_rad=np.deg2rad(0.3))
    assert any("counter-clockwise only" in note for note in cal.report.undetermined)
    assert cal.intrinsics.diameter_ratio == pytest.approx(TRUE.diameter_ratio, rel=3e-3)


def test_robot_standing_still_is_unidentifiable(rng):
    t = np.arange(200) * DT
    ticks = np.full((200, 2), 123)
    with pytest.raises(UnidentifiableError, match="did not move"):
        calibrate_intrinsics(t, ticks, t[::7], np.zeros((len(t[::7]), 3)))


def test_reference_without_time_overlap_is_named(rng):
    t, ticks, poses = _drive(*RICH)
    with pytest.raises(PoseReferenceError, match="overlap"):
        calibrate_intrinsics(t, ticks, t[::7] + 1000.0, poses[::7])


def test_non_finite_reference_pose_is_named(rng):
    t, ticks, poses = _drive(*RICH)
    rp = poses[::7].copy()
    rp[5, 1] = np.nan
    with pytest.raises(PoseReferenceError, match=r"NaN or infinite.*sample 5"):
        calibrate_intrinsics(t, ticks, t[::7], rp)


def test_reference_of_another_robot_is_rejected(rng):
    t, ticks, _ = _drive(*RICH)
    other = ([[300, 300], [250, -250], [500, 500], [-250, 250], [300, 500], [500, 300]] * 3,
             [3.0, 4.0, 3.0, 3.0, 4.0, 3.0] * 3)
    _, _, poses_b = _drive(*other)
    n = min(len(t), len(poses_b))
    rt, rp = _reference(rng, poses_b[:n], t[:n])
    with pytest.raises(PoseReferenceError, match="this robot's"):
        calibrate_intrinsics(t[:n], ticks[:n], rt, rp)


def test_errors_are_calibration_and_value_errors():
    assert issubclass(PoseReferenceError, CalibrationError)
    assert issubclass(UnidentifiableError, ValueError)


def test_turns_in_place_both_ways_cannot_separate_the_wheels(rng):
    t, ticks, poses = _drive([[-250, 250], [250, -250]] * 3, [3.0, 3.0] * 3)
    rt, rp = _reference(rng, poses, t)
    with pytest.raises(UnidentifiableError, match="one proportion"):
        calibrate_intrinsics(t, ticks, rt, rp, sensor_pose=False, interval_s=2.0)


def test_arcs_both_ways_without_straight_runs_work_and_say_so(rng):
    t, ticks, poses = _drive([[500, 300], [300, 500]] * 3, [3.0, 3.0] * 3)
    rt, rp = _reference(rng, poses, t)
    cal = calibrate_intrinsics(t, ticks, rt, rp, sensor_pose=False, interval_s=2.0,
                               position_std_m=0.003, heading_std_rad=0.0052)
    assert cal.report.turns_left > 0 and cal.report.turns_right > 0
    assert cal.report.straight_runs == 0
    assert any("no straight runs" in note for note in cal.report.undetermined)
    assert cal.intrinsics.diameter_ratio == pytest.approx(TRUE.diameter_ratio, rel=3e-3)
    # manoeuvres alternating as fast as the intervals: the message says what to change
    with pytest.raises(UnidentifiableError, match="shorter interval_s"):
        calibrate_intrinsics(t, ticks, rt, rp, sensor_pose=False, interval_s=6.0)


@pytest.mark.parametrize(("option", "value", "message"), [
    ("interval_s", 0.0, "interval_s must be a positive"),
    ("interval_s", -1.0, "interval_s must be a positive"),
    ("interval_s", float("nan"), "interval_s must be a positive"),
    ("overlap", 0, "overlap must be an integer of at least 1"),
    ("overlap", 2.5, "overlap must be an integer"),
    ("encoders", "foo", "encoders must be 'quadrature' or 'commanded'"),
    ("position_std_m", -0.005, "position_std_m must be a positive"),
    ("heading_std_rad", 0.0, "heading_std_rad must be a positive"),
    ("outlier_rounds", -1, "outlier_rounds must be an integer of at least 0"),
    ("outlier_fraction", 0.0, r"outlier_fraction must be in \(0, 0.5\]"),
    ("outlier_fraction", 0.6, r"outlier_fraction must be in \(0, 0.5\]"),
])
def test_every_option_is_validated_in_one_line(rng, option, value, message):
    t, ticks, poses = _drive(*RICH)
    rt, rp = _reference(rng, poses, t)
    with pytest.raises(ValueError, match=message) as info:
        calibrate_intrinsics(t, ticks, rt, rp, **{option: value})
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("sensor_pose", [True, False])
def test_turns_in_place_only_are_unidentifiable_with_the_default_options(rng, sensor_pose):
    t, ticks, poses = _drive([[-250, 250], [250, -250]] * 3, [3.0, 3.0] * 3)
    rt, rp = _reference(rng, poses, t)
    with pytest.raises(UnidentifiableError, match="one proportion"):
        calibrate_intrinsics(t, ticks, rt, rp, sensor_pose=sensor_pose)


def test_a_constant_arc_is_unidentifiable_and_does_not_blame_the_reference(rng):
    t, ticks, poses = _drive([[500, 300]], [40.0])
    rt, rp = _reference(rng, poses, t)
    for interval_s in (2.0, 6.0):
        with pytest.raises(UnidentifiableError, match="one proportion") as info:
            calibrate_intrinsics(t, ticks, rt, rp, interval_s=interval_s)
        assert "this robot's" not in str(info.value)


def test_outlying_reference_samples_are_rejected_and_counted(rng):
    """1% of the reference poses thrown 10 cm away: the four rounds reject the intervals
    they spoil, and the estimate and its covariance come from the rest. (The rule drops
    the intervals above the 99th percentile: under about 100 intervals it drops none.)"""
    t, ticks, poses = _drive(*RICH)
    rt, rp = _reference(rng, poses, t, std=(0.002, 0.003))
    bad = rng.choice(len(rp), size=len(rp) // 100, replace=False)
    rp = rp.copy()
    rp[bad, :2] += rng.choice([-0.1, 0.1], size=(len(bad), 2))
    clean = calibrate_intrinsics(t, ticks, rt, rp, sensor_pose=False, interval_s=0.2,
                                 overlap=1)
    raw = calibrate_intrinsics(t, ticks, rt, rp, sensor_pose=False, interval_s=0.2,
                               overlap=1, outlier_rounds=0)
    assert raw.n_rejected == 0 and clean.n_rejected > 0
    assert clean.n_intervals + clean.n_rejected == raw.n_intervals
    err = abs(clean.intrinsics.wheel_base_m / TRUE.wheel_base_m - 1.0)
    err_raw = abs(raw.intrinsics.wheel_base_m / TRUE.wheel_base_m - 1.0)
    assert err < 2e-3 and err < err_raw
    assert clean.std[2] < raw.std[2]


def test_a_slow_robot_has_straight_runs_in_its_own_terms(rng):
    """A robot ten times slower than a Create 2 (a Khepera's speeds): its straight runs
    and turns are judged against its own wheel increments."""
    slow = ([[r / 10 for r in rate] for rate in RICH[0]], RICH[1])
    k = OdometryIntrinsics(4.49e-4, 4.4455e-4, 0.088)
    t, ticks, poses = _drive(*slow, k=k)
    rt, rp = _reference(rng, poses, t, std=(0.0003, 0.001))
    cal = calibrate_intrinsics(t, ticks, rt, rp, sensor_pose=False)
    assert cal.report.straight_runs > 10 and cal.report.turns_left > 5
    assert cal.report.turns_right > 5 and cal.report.undetermined == ()


def test_ticks_in_a_finer_unit_give_the_same_physical_result(rng):
    t, ticks, poses = _drive(*RICH)
    rt, rp = _reference(rng, poses, t)
    fine = np.round(np.unwrap(ticks.astype(float), period=65536, axis=0) * 10).astype(np.int64)
    a = calibrate_intrinsics(t, ticks, rt, rp, sensor_pose=True)
    b = calibrate_intrinsics(t, fine % 65536, rt, rp, sensor_pose=True)
    ka, kb = a.intrinsics, b.intrinsics
    np.testing.assert_allclose([kb.m_per_tick_left * 10, kb.m_per_tick_right * 10,
                                kb.wheel_base_m], [ka.m_per_tick_left, ka.m_per_tick_right,
                                                   ka.wheel_base_m], rtol=1e-4)
    np.testing.assert_allclose(b.std[2:], a.std[2:], rtol=1e-2)


@pytest.mark.parametrize("offset", [(0.08, -0.03, 0.3), (0.1, 0.0, 0.0)])
def test_a_sensor_off_the_axle_fitted_as_the_axle_names_the_mount(rng, offset):
    t, ticks, poses = _drive(*RICH)
    rt, rp = _reference(rng, _compose(poses, np.array(offset)), t,
                        std=(0.001, np.deg2rad(0.1)))
    with pytest.raises(PoseReferenceError, match=r"sensor_pose=True; --sensor-pose") as info:
        calibrate_intrinsics(t, ticks, rt, rp, sensor_pose=False)
    assert "this robot's" not in str(info.value)
