"""Filters that cannot run away (fusion.ekf.resets): the scale-error states stay physical, an
implausible scale or a diverged filter is reset and counted, the covariance stays PSD.

The reproduction runs on the simulator: a robot at rest whose odometry reads -0.022 m/s (an
encoder bias at rest), then a drive, with dense landmarks; the filter fuses the odometry as
speeds (a speeds-only recording) and the landmarks. Before the bounds its scale states left
any plausible range and its pose followed the biased odometry while it gated the landmarks.
"""

import math

import numpy as np
import pytest

from benchmarks.bench_bounds import BIAS_M_S, LANDMARKS, START, biased_drive
from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.functions import SCALES
from fusion.ekf.model_ekf import ModelEKF
from fusion.ekf.resets import (
    MAX_RATIO_ERROR,
    MAX_SCALE_ERROR,
    DivergenceWatch,
    ScaleBound,
    discrepancy,
    reset_scales,
    scale_statistic,
    widen_pose,
)
from fusion.exceptions import FilterOptionError
from fusion.noise import ScaleErrors
from fusion.range_bearing import RangeBearing, range_bearing
from lti_motion.kinematics import integrate_poses
from lti_motion.model.fir import FirFit
from lti_motion.model.motion_model import MotionModel

# the scenario, shared with `python -m benchmarks bounds`: START, the four corner
# LANDMARKS, BIAS_M_S = -0.022 m/s (what the odometry reads while the robot stands still)


@pytest.fixture(scope="module")
def small_model():
    return MotionModel.from_fir(
        FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
               residual_cov=np.eye(2) * 1e-4, n_samples=100, source="steps"),
        dt_s=0.015, wheel_base_m=0.25, m_per_tick=5e-4,
        calibrated_at="2026-01-01T00:00:00+00:00")


def _is_psd(P):
    return np.allclose(P, P.T) and np.linalg.eigvalsh(0.5 * (P + P.T)).min() > -1e-12


# -- the pure functions -----------------------------------------------------------------------
def test_the_bound_is_the_chi_square_quantile_of_the_prior_spread():
    b = ScaleBound.from_scales(ScaleErrors(prior_std=(0.01, 0.02), walk_per_sqrt_s=(1e-3, 0.0),
                                           ratio_prior_std=0.005, ratio_walk_per_sqrt_s=2e-4),
                               wheel_base_m=0.25)
    # chi2(3) tail: erfc(sqrt(x/2)) + sqrt(2x/pi) exp(-x/2)
    x = b.threshold
    tail = math.erfc(math.sqrt(x / 2)) + math.sqrt(2 * x / math.pi) * math.exp(-x / 2)
    assert tail == pytest.approx(1e-6, rel=1e-6)
    # kappa's prior is the ratio's over the wheel base: 0.005 / 0.25 = 0.02 rad/m
    assert b.prior_var[2] == pytest.approx(0.02 ** 2)
    assert b.max_kappa_rad_per_m == pytest.approx(0.1 / 0.25)
    assert scale_statistic(0.01, 0.02, 0.02, b, 0.0) == pytest.approx(3.0)
    # the walk widens the spread with time: 100 s add (1e-3)^2 * 100 = 1e-4 to k_v's variance
    # and (2e-4 / 0.25)^2 * 100 = 6.4e-5 to kappa's
    assert scale_statistic(0.01, 0.0, 0.0, b, 100.0) == pytest.approx(0.5)
    assert scale_statistic(0.0, 0.0, 0.02, b, 100.0) == pytest.approx(4e-4 / (4e-4 + 6.4e-5))


@pytest.mark.parametrize("bad", [None, 0.0, 1.0, 1.5, math.nan])
def test_scale_errors_refuse_an_impossible_plausibility_probability(bad):
    with pytest.raises(FilterOptionError, match="plausible_probability"):
        ScaleErrors(plausible_probability=bad)


@pytest.mark.parametrize("scales", [ScaleErrors(prior_std=(0.1, 0.01)),
                                    ScaleErrors(ratio_prior_std=0.02)])
def test_a_prior_too_wide_for_the_physical_bound_is_refused(small_model, scales):
    """5.5 sigma of a 10% prior reach |k| = 0.5; of a 2% ratio prior a 10% ratio."""
    with pytest.raises(FilterOptionError, match="physical bounds"):
        ModelEKF(small_model, options=EKFOptions(scales=scales))


def test_reset_puts_the_scales_back_at_their_prior_and_keeps_P_psd(rng):
    n = 12
    a = rng.standard_normal((n, n))
    P = a @ a.T + 1e-3 * np.eye(n)
    x = rng.standard_normal(n)
    b = ScaleBound.from_scales(ScaleErrors(prior_std=(0.01, 0.02)), wheel_base_m=0.25)
    x2, P2 = reset_scales(x, P, b)
    c = [3, 4, 5]
    assert np.all(x2[SCALES] == 0) and np.all(np.delete(x2, c) == np.delete(x, c))
    assert np.allclose(P2[SCALES, SCALES], np.diag([1e-4, 4e-4, 0.04 ** 2]))
    assert np.all(P2[SCALES, :3] == 0) and np.all(P2[6:, SCALES] == 0)
    rest = np.delete(np.delete(P, c, 0), c, 1)
    assert np.array_equal(np.delete(np.delete(P2, c, 0), c, 1), rest)
    assert _is_psd(P2)
    W = widen_pose(P2, position_m=0.5, heading_rad=0.1)
    assert np.allclose(np.diag(W - P2)[:3], [0.25, 0.25, 0.01]) and _is_psd(W)


def test_widening_brings_the_rejected_sighting_back_inside_the_gate():
    P = np.diag([1e-6, 1e-6, 1e-6])
    pose, lxy = np.array([1.0, 0.5, 0.3]), np.array([4.0, 2.0])
    z = range_bearing(pose + np.array([0.4, -0.3, 0.05]), lxy)        # the pose is 0.5 m off
    predicted = range_bearing(pose, lxy)
    nu = z - predicted
    e, b = discrepancy(nu, float(predicted[0]))
    from fusion.ekf.functions import landmark_jacobian
    H = landmark_jacobian(pose, lxy)
    R = np.diag([0.02 ** 2, 0.01 ** 2])
    nis = lambda Pm: float(nu @ np.linalg.solve(H @ Pm @ H.T + R, nu))   # noqa: E731
    assert nis(P) > 100 and nis(widen_pose(P, position_m=e, heading_rad=b)) < 3.0


def test_divergence_needs_a_run_of_gated_readings_of_two_landmarks():
    w = DivergenceWatch(5)
    assert not any(w.observe(False, 7) for _ in range(50))       # one landmark: a map error
    assert not w.observe(True, 7) and w.in_a_row == 0
    assert [w.observe(False, k % 2) for k in range(5)] == [False] * 4 + [True]
    assert not DivergenceWatch(None).observe(False, 1)
    with pytest.raises(FilterOptionError, match="diverged_after"):
        DivergenceWatch(0)


# -- the filter -------------------------------------------------------------------------------
def test_an_implausible_scale_is_reset_counted_and_logged(small_model, caplog):
    ekf = ModelEKF(small_model, landmarks=LANDMARKS, initial_pose=START)
    ekf.predict(np.zeros(2))
    x = ekf.x.copy()
    x[SCALES] = (-0.9, 0.0, 0.0)         # what a bias at rest drove the filter to
    ekf.x = x
    with caplog.at_level("WARNING", logger="fusion.ekf.model_ekf"):
        rec = ekf.update_speeds(np.zeros(2))
    assert rec.accepted and ekf.n_resets == 1
    reset = ekf.resets[-1]
    assert reset.cause == "scale_implausible" and reset.scale_errors[0] == pytest.approx(-0.9)
    assert reset.statistic > reset.threshold
    assert np.all(ekf.scale_errors == 0) and _is_psd(ekf.P)
    assert np.allclose(ekf.P[SCALES, SCALES], np.diag([1e-4, 1e-4, (0.01 / 0.25) ** 2]))
    assert "filter reset" in caplog.text


def test_a_wide_prior_is_clipped_to_the_physical_bound(small_model):
    scales = ScaleErrors(prior_std=(0.05, 0.05), plausible_probability=0.9)
    ekf = ModelEKF(small_model, options=EKFOptions(scales=scales))
    ekf.predict(np.zeros(2))
    x = ekf.x.copy()
    x[SCALES] = (0.6, 0.0, -0.5)         # kappa -0.5 rad/m: a ratio 12.5% off at b = 0.25 m
    ekf.x = x
    ekf._scales_since_s = -1e12          # a spread so wide the test cannot fire: the clip acts
    ekf.update_speeds(np.zeros(2))
    assert ekf.scale_errors[0] == MAX_SCALE_ERROR and ekf.n_resets == 0
    assert ekf.scale_errors[2] == pytest.approx(-MAX_RATIO_ERROR / 0.25)


# -- the reproduction on the simulator ----------------------------------------------------------
def _filter(model, log, speeds, sightings):
    ekf = ModelEKF(model, initial_pose=START, pose_std=(0.005,) * 3, landmarks=LANDMARKS,
                   options=EKFOptions(history=0))
    by_frame, none = sightings.by_index(), RangeBearing.empty()
    poses = np.empty((len(log.t_s), 3))
    poses[0] = ekf.pose
    bound = ekf.scale_bound
    d2 = np.zeros(len(log.t_s))
    for k in range(1, len(log.t_s)):
        ekf.predict(log.cmd_m_s[k])
        ekf.update_speeds(speeds[k - 1])
        ekf.update_landmarks(by_frame.get(k, none))
        poses[k] = ekf.pose
        # against the loosest spread (the walk's since the start: resets only shorten it)
        d2[k] = scale_statistic(*ekf.scale_errors.tolist(), bound, ekf.t_s)
    return ekf, poses, d2


def _ate(log, poses):
    return float(np.sqrt(np.mean(np.sum((poses[:, :2] - log.true_pose[:, :2]) ** 2, axis=1))))


@pytest.fixture(scope="module")
def example(load_example):
    return load_example("ekf_plugin")


@pytest.mark.parametrize("seed", [100, 101])
def test_an_encoder_bias_at_rest_with_dense_landmarks_does_not_run_the_filter_away(
        example, route_model, seed):
    log, speeds, sightings = biased_drive(example, route_model, seed=seed, rest_s=30.0,
                                           bias_m_s=BIAS_M_S)
    ekf, poses, d2 = _filter(route_model, log, speeds, sightings)
    odometry = integrate_poses(speeds, log.dt_s, initial_pose=START)
    # the scale states stay within their plausibility bound at every frame
    assert d2.max() <= ScaleBound.from_scales(ScaleErrors(),
                                              wheel_base_m=route_model.wheel_base_m).threshold
    assert ekf.n_resets >= 1
    # and the landmarks keep the pose: far better than the biased dead reckoning
    assert _ate(log, poses) < 0.4 * _ate(log, odometry)
    assert ekf.stats.count("landmark", "gated") < 0.25 * len(sightings)


def test_without_the_bias_the_filter_never_resets(example, route_model):
    log, speeds, sightings = biased_drive(example, route_model, seed=100, rest_s=30.0,
                                           bias_m_s=0.0)
    ekf, poses, _ = _filter(route_model, log, speeds, sightings)
    assert ekf.n_resets == 0 and _ate(log, poses) < 0.02


def test_pose_fixes_that_stay_outside_the_gate_mean_divergence_too(small_model):
    """A filter sure of a pose 1 m off rejects pose fixes; after diverged_after of them in a
    row it resets and widens its pose covariance, and the next fix is fused."""
    ekf = ModelEKF(small_model, pose_std=(0.001,) * 3, options=EKFOptions(diverged_after=5))
    cov = np.diag([1e-4, 1e-4, 1e-4])
    fix = np.array([1.0, 0.0, 0.0])
    for _ in range(5):
        ekf.predict(np.zeros(2))
        assert not ekf.update_pose(fix, cov).accepted
    assert ekf.n_resets == 1 and ekf.resets[0].cause == "diverged" and _is_psd(ekf.P)
    ekf.predict(np.zeros(2))
    assert ekf.update_pose(fix, cov).accepted and ekf.pose[0] > 0.9
