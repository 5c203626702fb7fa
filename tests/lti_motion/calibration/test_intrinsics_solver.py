"""The outlier rule of the intrinsics calibration on residuals of known noise
(:func:`lti_motion.calibration.intrinsics_solver.trim`)."""

import numpy as np

from lti_motion.calibration.intrinsics_solver import trim

POSITION_STD = 0.005 * np.sqrt(2)     # two poses' position noise per axis [m]
HEADING_STD = np.deg2rad(0.5)         # one pose's heading noise [rad]


def _pose_reference_residuals(rng, n=4000):
    """Residuals of a clean pose reference: half the intervals turns in place (no
    displacement), half runs 1.2 m straight, whose start heading's error adds
    ``HEADING_STD * 1.2 m`` across the displacement."""
    straight = np.arange(n) % 2 == 1
    travel = np.zeros((n, 2))
    travel[straight, 0] = 1.2
    across_std = np.hypot(POSITION_STD, HEADING_STD * travel[:, 0])
    r = np.stack([rng.standard_normal(n) * POSITION_STD, rng.standard_normal(n) * across_std,
                  rng.standard_normal(n) * HEADING_STD * np.sqrt(2)], axis=1)
    return r, travel, straight


def test_each_interval_is_judged_against_its_own_noise(rng):
    r, travel, straight = _pose_reference_residuals(rng)
    one_scale = ~trim(r, 0.01)
    own = ~trim(r, 0.01, travel=travel)
    # one scale for all: the long intervals' Gaussian tails look like outliers (the
    # rotation residual's 0.27% tail comes from both kinds)
    assert one_scale.sum() > 0.01 * len(r) and straight[one_scale].mean() > 0.8
    # against their own noise: about the 0.27% tail of each of the two residuals, from
    # either kind of interval
    assert own.sum() < 0.01 * len(r)
    assert 0.2 < straight[own].mean() < 0.8


def test_a_gross_error_is_still_rejected_against_its_own_noise(rng):
    r, travel, _ = _pose_reference_residuals(rng)
    bad = np.arange(0, 400, 20)                # 0.5% of the intervals, 0.1 m off
    r[bad, 1] += 0.1
    own = ~trim(r, 0.01, travel=travel)
    assert own[bad].all()
