"""Odometry intrinsics from runs localised only at their start and end (a robot seen now
and then): 20 simulated runs, end poses with 5 mm and 0.5 deg noise."""

import numpy as np
import pytest

from lti_motion.calibration import calibrate_intrinsics, calibrate_intrinsics_runs
from lti_motion.exceptions import PoseReferenceError, UnidentifiableError
from tests.lti_motion.calibration.test_intrinsics_fit import TRUE, _drive

NOISE = np.array([0.005, 0.005, np.deg2rad(0.5)])


def _runs(rng, n=20):
    """``n`` runs of straight stretches, turns in place both ways and arcs; the counts,
    the noisy start and end poses and each run's whole turns (known to who drove it)."""
    ticks, start, end, turns = [], [], [], []
    for _ in range(n):
        rates, seconds = [], []
        for _ in range(4):
            w = rng.choice([-250, 250])
            rates += [[450, 450], [-w, w], list(rng.choice([[500, 300], [300, 500]]))]
            seconds += [rng.uniform(2, 4), rng.uniform(1, 4), rng.uniform(1, 3)]
        _, counts, poses = _drive(rates, seconds)
        p0 = poses[0] + rng.standard_normal(3) * NOISE
        p1 = poses[-1] + rng.standard_normal(3) * NOISE
        seen = np.angle(np.exp(1j * (p1[2] - p0[2])))
        turns.append(int(np.round((poses[-1, 2] - poses[0, 2] - seen) / (2 * np.pi))))
        ticks.append(counts)
        start.append(p0)
        end.append(p1)
    return ticks, np.array(start), np.array(end), turns


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_twenty_runs_give_the_ratio_and_the_base(seed):
    ticks, start, end, turns = _runs(np.random.default_rng(seed))
    cal = calibrate_intrinsics_runs(ticks, start, end, turns=turns)
    k = cal.intrinsics
    assert k.diameter_ratio == pytest.approx(TRUE.diameter_ratio, rel=1e-3)
    assert k.wheel_base_m == pytest.approx(TRUE.wheel_base_m, rel=3e-3)
    assert cal.n_intervals == 20 and cal.covariance.shape == (3, 3)
    assert abs(k.wheel_base_m - TRUE.wheel_base_m) < 3 * cal.std[2]


def test_start_and_end_poses_are_refused_as_a_trajectory_but_taken_as_runs(rng):
    ticks, start, end, turns = _runs(rng, n=3)
    t = np.arange(len(ticks[0])) * 0.015
    with pytest.raises(PoseReferenceError, match="overlap in 2 reference samples"):
        calibrate_intrinsics(t, ticks[0], t[[0, -1]], np.stack([start[0], end[0]]))
    cal = calibrate_intrinsics_runs(ticks, start, end, turns=turns, outlier_rounds=0)
    assert cal.n_intervals == 3


def test_too_few_runs_or_mismatched_poses_are_named(rng):
    ticks, start, end, _ = _runs(rng, n=2)
    with pytest.raises(UnidentifiableError, match="at least 2 runs"):
        calibrate_intrinsics_runs(ticks[:1], start[:1], end[:1])
    with pytest.raises(PoseReferenceError, match=r"shape \(2, 3\)"):
        calibrate_intrinsics_runs(ticks, start, end[:1])
    with pytest.raises(ValueError, match="one integer per run"):
        calibrate_intrinsics_runs(ticks, start, end, turns=[0])
