"""The real-data experiment: self-calibrated models against the raw commands on MRCLAM.

Calibrated on the first half of each robot's run, evaluated on the second half.
Measured (dt 0.1 s): ARX beats the raw commands by 12.8-42 points on v and by
20.6-55 points on w; the target on w is 30 points on every robot, missed by
robot 1 (+20.6: its raw w fit is already 43%). Dead reckoning over 30 s windows does not
reach the target 0.8 ratio (median ratios 0.88-1.42): docs/mrclam.md says why.

Landmark EKFs on the second half (lti_motion.app.mrclam_filters), the same
sightings, sighting noise and gate. With both filters' motion noise set by one rule (the
long-run covariance of each motion's speed error on the first half, as the factor graphs
use it): RMS 0.099-0.214 m (ARX model) and 0.125-0.223 m (raw commands), model / raw
0.80-0.96 (mean 0.89), the target 0.9 met on robots 2, 3 and 4. Under the earlier rule
(the model's own one-step noise against the commands' sample covariance) the ratios were
0.80-1.20 (mean 1.02). docs/mrclam.md.
"""

import numpy as np
import pytest

from drivers.datasets import CREATE1_WHEEL_BASE_M, load_mrclam, resample_robot
from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.model_ekf import ModelEKF
from fusion.ekf.velocity_ekf import VelocityModelEKF
from fusion.noise import LandmarkNoise
from fusion.range_bearing import range_bearing
from lti_motion.app.mrclam import WARMUP_S, evaluate_robot, split_halves
from lti_motion.app.mrclam_filters import (
    HELD_SCALES,
    NO_SLIP,
    evaluate_filters,
    output_error_model,
)
from lti_motion.app.mrclam_noise import speed_covariances
from lti_motion.kinematics import wheel_from_body
from lti_motion.model.fir import FirFit
from lti_motion.model.motion_model import MotionModel


@pytest.fixture(scope="module")
def dataset(mrclam_path):
    return load_mrclam(mrclam_path)


@pytest.fixture(scope="module")
def results(dataset):
    return {r: evaluate_robot(robot) for r, robot in dataset.robots.items()}


def test_arx_beats_raw_commands_on_every_robot_by_10_points_on_v_and_w(results):
    for r, res in results.items():
        gain = res.fit["arx"] - res.fit["raw"]
        assert np.all(gain >= 10.0), (r, res.fit)


def test_arx_beats_raw_commands_on_w_by_30_points_on_four_of_five_robots(results):
    gains = [res.fit["arx"][1] - res.fit["raw"][1] for res in results.values()]
    assert sum(g >= 30.0 for g in gains) >= 4, gains


def test_models_are_calibrated_on_the_first_half_only(results):
    for res in results.values():
        assert res.n_train_s > 300 and res.n_test_s > 300
        assert np.all(np.abs(res.arx.poles()) < 1.0)


@pytest.fixture(scope="module")
def filters(dataset, results):
    """Both EKFs under the long-run rule (the default)."""
    return {r: evaluate_filters(dataset.robots[r], dataset.landmarks, res.arx)
            for r, res in results.items()}


@pytest.fixture(scope="module")
def legacy(dataset, results):
    """Both EKFs under the earlier rule, kept for the record."""
    return {r: evaluate_filters(dataset.robots[r], dataset.landmarks, res.arx,
                                motion_noise="legacy")
            for r, res in results.items()}


def test_landmark_ekfs_hold_every_robot_within_25_cm_rms(filters, legacy):
    """Dead reckoning from the commands drifts by metres over a half run; landmarks bound it.

    Both filters get the same sightings under either rule.
    """
    for runs in (filters, legacy):
        for r, f in runs.items():
            assert max(f.rms_m.values()) < 0.25, (r, f.motion_noise, f.rms_m)
            seen = {name: f.fused[name] + f.gated[name] for name in ("model", "raw")}
            assert seen["model"] == seen["raw"] > 500, (r, f.motion_noise, seen)


def test_legacy_rule_fuses_most_sightings(legacy):
    for r, f in legacy.items():
        for name in ("model", "raw"):
            assert f.fused[name] >= 0.85 * (f.fused[name] + f.gated[name]), (r, name, f)


def test_both_filters_take_the_long_run_speed_covariance_of_the_first_half(dataset, results,
                                                                            filters):
    """One rule for both motions; the model's measured drift is the smaller on every robot."""
    warmup = round(WARMUP_S / 0.1)
    for r, f in filters.items():
        train, _ = split_halves(resample_robot(dataset.robots[r], dt_s=0.1),
                                min_samples=2 * warmup)
        want = speed_covariances(results[r].arx, train, warmup=warmup)
        for name in ("model", "raw"):
            np.testing.assert_allclose(f.speed_cov[name], want[name], rtol=1e-12)
        assert np.all(np.diag(want["model"]) < np.diag(want["raw"])), (r, want)


def test_model_driven_ekf_is_no_worse_than_raw_commands_and_better_on_average(filters, legacy):
    """The factor graph's claims (tests/lti_motion/app/test_mrclam_graph.py), now for the EKFs.

    Under the earlier rule they fail (robot 2 at 1.20, mean 1.02): the noise rule, not
    the filter, made the difference.
    """
    ratios = np.array([f.rms_m["model"] / f.rms_m["raw"] for f in filters.values()])
    assert np.all(ratios < 1.02), ratios
    assert ratios.mean() < 0.95, ratios
    old = np.array([f.rms_m["model"] / f.rms_m["raw"] for f in legacy.values()])
    assert not (np.all(old < 1.02) and old.mean() < 0.95), old


def test_sighting_noise_measured_on_the_first_half_is_plausible(filters):
    for r, f in filters.items():
        assert 0.03 < f.noise.range_std_m < 0.25, (r, f.noise)
        assert np.radians(0.2) < f.noise.bearing_std_rad < np.radians(1.5), (r, f.noise)


def test_bad_inputs_are_refused(dataset, results):
    robot, arx = dataset.robots[4], results[4].arx
    with pytest.raises(ValueError, match=r"calibrated at 0\.1 s"):
        evaluate_filters(robot, dataset.landmarks, arx, dt_s=0.2)
    with pytest.raises(ValueError, match="motion_noise must be"):
        evaluate_filters(robot, dataset.landmarks, arx, motion_noise="own")
    for bad in (np.eye(3), np.diag([1e-3, -1e-3]), np.array([[1e-3, 5e-4], [0.0, 1e-3]])):
        with pytest.raises(ValueError, match="speed_cov must"):
            output_error_model(arx, bad)


# -- the rule's mapping into ModelEKF, on synthetic data (no data set needed) ---------------

def _pass_through_model() -> MotionModel:
    """A model whose mean speeds are the commands (one FIR tap, body from wheel speeds),
    with coloured noise of its own: ``z' = 0.6 z + 0.5 e``, ``s = z + D u + e``."""
    b = CREATE1_WHEEL_BASE_M
    fit = FirFit(taps=np.array([[[0.5, 0.5], [-1 / b, 1 / b]]]), residual_cov=np.eye(2) * 1e-4,
                 n_samples=100, source="steps")
    model = MotionModel.from_fir(fit, dt_s=0.1, wheel_base_m=b,
                                 calibrated_at="2026-01-01T00:00:00+00:00")
    k = 0.5 * np.eye(2)
    return model.updated(A=0.6 * np.eye(2), B=np.zeros((2, 2)), C=np.eye(2), K=k,
                         Q=2.0 * k @ model.R @ k.T)


def test_output_error_model_keeps_the_free_run_and_takes_the_given_noise(results):
    arx = results[4].arx
    cov = np.array([[2e-3, 1e-4], [1e-4, 8e-3]])
    oe = output_error_model(arx, cov)
    u = np.random.default_rng(9).uniform(-0.1, 0.1, (200, 2))
    np.testing.assert_array_equal(oe.simulate(u), arx.simulate(u))
    np.testing.assert_array_equal(oe.R, cov)
    assert not np.any(oe.K) and np.all(oe.Q <= 1e-12)


def test_model_filter_under_the_rule_is_the_textbook_filter_for_a_pass_through_model():
    """Same speeds, same per-period speed covariance: same pose and covariance, to rounding.

    With its own noise (K != 0, slip, scale states) the model filter would differ.
    """
    model = _pass_through_model()
    cov = np.array([[2e-3, 1e-4], [1e-4, 8e-3]])
    noise = LandmarkNoise(range_std_frac=0.0, range_std_m=0.1, bearing_std_rad=0.01)
    pose0, landmark = np.array([0.5, -0.2, 0.3]), np.array([2.0, 1.0])
    rng = np.random.default_rng(3)
    filters = {
        "rule": ModelEKF(output_error_model(model, cov), initial_pose=pose0,
                         pose_std=(0.05, 0.05, 0.05), landmarks={7: landmark},
                         options=EKFOptions(slip=NO_SLIP, scales=HELD_SCALES,
                                            landmark_noise=noise, history=0)),
        "own": ModelEKF(model, initial_pose=pose0, pose_std=(0.05, 0.05, 0.05),
                        landmarks={7: landmark},
                        options=EKFOptions(landmark_noise=noise, history=0))}
    raw = VelocityModelEKF(dt_s=0.1, speed_cov=cov, initial_pose=pose0,
                           pose_std=(0.05, 0.05, 0.05), landmarks={7: landmark},
                           landmark_noise=noise)
    fused = 0
    for k in range(40):
        vw = np.array([0.08, 0.3 * np.sin(0.2 * k)])
        raw.predict(vw)
        for ekf in filters.values():
            ekf.predict(wheel_from_body(vw, wheel_base_m=CREATE1_WHEEL_BASE_M))
        if k % 5 == 4:
            z = range_bearing(raw.x, landmark) + rng.normal(0.0, [0.05, 0.005])
            fused += raw.update_landmark(7, z).accepted
            for ekf in filters.values():
                ekf.update_landmark(7, z)
    assert fused == 8
    np.testing.assert_allclose(filters["rule"].x[:3], raw.x, atol=1e-12)
    # all that differs is output_error_model's Q jitter (1e-12) against entries of 1e-3
    np.testing.assert_allclose(filters["rule"].P[:3, :3], raw.P, rtol=1e-7, atol=0.0)
    assert np.abs(filters["own"].P[:3, :3] - raw.P).max() > 1e-4
