"""The simulated motion capture and the intrinsics drive: the calibration recovers the
simulator's wheel diameter ratio and wheel base (scored here against its truth)."""

import numpy as np
import pytest

from drivers.exceptions import SimulatorError
from drivers.sim.config import Room, get_preset
from drivers.sim.motion_capture import intrinsics_drive, motion_capture
from drivers.sim.simulator import Simulator
from lti_motion.calibration.intrinsics_fit import calibrate_intrinsics


def test_calibration_recovers_the_asymmetric_robot_on_tile():
    params = get_preset("create2", wheel_diameter_errors=(0.01, 0.0), motor_balance=0.90)
    cmd = intrinsics_drive(params.period_s, repeats=2)
    sim = Simulator(params, seed=3, floor="tile", room=Room.empty(), initial_pose=(0, 0, 0))
    log = sim.run(cmd)
    t_ref, poses = motion_capture(log, rng=np.random.default_rng(3))
    cal = calibrate_intrinsics(log.t_s, log.ticks, t_ref, poses, sensor_pose=False,
                               encoders="commanded", heading_std_rad=np.deg2rad(0.5))
    k = cal.intrinsics
    true_ratio = (1.01 / 1.0)
    assert k.diameter_ratio == pytest.approx(true_ratio, rel=1e-3)
    # the tyres slip by about 0.25% at cruise on tile, so the geometric scale is an upper bound
    assert k.m_per_tick_left == pytest.approx(params.m_per_tick * 1.01, rel=6e-3)
    assert k.wheel_base_m == pytest.approx(params.true_wheel_base_m, rel=5e-3)


def test_motion_capture_is_noisy_truth_at_its_rate():
    sim = Simulator("create2", seed=0, room=Room.empty())
    log = sim.run(np.full((200, 2), 0.2))
    t, poses = motion_capture(log, rng=np.random.default_rng(0), rate_hz=10.0)
    stride = round(1 / (10.0 * log.dt_s))
    assert len(t) == len(range(0, 200, stride))
    err = poses - log.true_pose[::stride]
    assert 0.001 < np.std(err[:, 0]) < 0.01
    with pytest.raises(SimulatorError, match="true poses"):
        motion_capture(log.__class__(**{**log.__dict__, "true_pose": None}),
                       rng=np.random.default_rng(0))


def test_intrinsics_drive_turns_both_ways_and_rejects_nonsense():
    cmd = intrinsics_drive(0.015, repeats=1)
    diff = cmd[:, 1] - cmd[:, 0]
    assert diff.max() > 0.1 and diff.min() < -0.1
    assert np.all(np.abs(cmd) <= 0.5)
    with pytest.raises(SimulatorError, match="positive"):
        intrinsics_drive(0.015, speed_m_s=-0.1)
