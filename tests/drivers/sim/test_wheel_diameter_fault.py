"""The ``wheel_diameter`` fault: one wheel's true diameter changes during a drive.

Closed form (``lti_motion.intrinsics``, module docstring): with the encoders still
counting rotation, a straight run of equal counts curves at ``kappa = (rho_R - rho_L) / b``,
so a left wheel ``1 + delta`` times larger curves at ``-delta / b`` [rad/m], a right one
at ``+delta / b``.
"""

import numpy as np
import pytest

from drivers.exceptions import SimulatorError
from drivers.sim.config import Fault, Room, get_preset
from drivers.sim.simulator import Simulator
from lti_motion.recordings.ticks import unwrap_ticks

PARAMS = get_preset("create2")
ONSET_S = 3.0


def _curvature_rad_per_m(log, k0, k1):
    """Ground heading change not explained by the counts, per metre driven, frames k0..k1.

    The counts are converted with the robot's own (pre-fault) true wheel scales and wheel
    base, so a healthy robot gives about 0."""
    p = PARAMS
    pose = log.true_pose[k0:k1 + 1]
    travel_m = float(np.sum(np.hypot(*np.diff(pose[:, :2], axis=0).T)))
    dn = unwrap_ticks(log.ticks)[k1] - unwrap_ticks(log.ticks)[k0]
    k_l, k_r = (p.m_per_tick * (1.0 + e) for e in p.wheel_diameter_errors)
    counted_rad = (k_r * dn[1] - k_l * dn[0]) / p.true_wheel_base_m
    return (pose[-1, 2] - pose[0, 2] - counted_rad) / travel_m


def _straight(faults, n=1200, seed=3):
    cmd = np.zeros((n, 2))
    cmd[10:] = 0.25
    return Simulator(PARAMS, seed=seed, floor="hard", room=Room.empty(), faults=faults).run(cmd)


@pytest.mark.parametrize(("wheel", "delta", "sign"),
                         [("left", 0.005, -1.0), ("left", -0.005, -1.0), ("right", 0.005, 1.0)])
def test_one_wheels_diameter_change_curves_a_straight_run_at_delta_over_b(wheel, delta, sign):
    log = _straight([Fault("wheel_diameter", t_s=ONSET_S, wheel=wheel, diameter_change=delta)])
    after = _curvature_rad_per_m(log, round(6.0 / PARAMS.period_s), len(log.t_s) - 1)
    expected = sign * delta / PARAMS.true_wheel_base_m                 # 0.0213 rad/m
    assert after == pytest.approx(expected, rel=0.05)
    # before the onset it drives exactly as the healthy robot of the same seed
    k_onset = round(ONSET_S / PARAMS.period_s)
    healthy = _straight([])
    np.testing.assert_array_equal(log.true_pose[:k_onset], healthy.true_pose[:k_onset])
    assert abs(_curvature_rad_per_m(healthy, 400, len(log.t_s) - 1)) < 0.01 * abs(expected)
    # both encoders still count alike: the firmware servos rotation, not ground speed
    dn = np.diff(unwrap_ticks(log.ticks)[[400, -1]], axis=0)[0]
    assert abs(dn[0] - dn[1]) <= 0.002 * dn.mean()


def test_both_wheels_change_scales_travel_without_curving():
    healthy = _straight([])
    both = _straight([Fault("wheel_diameter", t_s=0.0, wheel="both", diameter_change=0.01)])
    k0, k1 = round(2.0 / PARAMS.period_s), len(healthy.t_s) - 1
    assert abs(_curvature_rad_per_m(both, k0, k1)) < 1e-3
    travel = [np.hypot(*(log.true_pose[k1, :2] - log.true_pose[k0, :2]))
              for log in (healthy, both)]
    assert travel[1] / travel[0] == pytest.approx(1.01, abs=0.002)


def test_a_diameter_change_beyond_20_percent_is_refused():
    with pytest.raises(SimulatorError, match=r"diameter_change must be within -0\.2 \.\. 0\.2"):
        Fault("wheel_diameter", t_s=1.0, wheel="left", diameter_change=0.3)
