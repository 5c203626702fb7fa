"""The wall run driven on the simulator: the robot finds its wheels' diameter ratio alone
(scored here against the simulator's truth, which the estimate never reads)."""

import dataclasses

import numpy as np
import pytest

from drivers.sim.config import Room, get_preset
from drivers.sim.simulator import Simulator
from lti_motion.calibration.wall_run import calibrate_wall_run
from lti_motion.calibration.wall_run_drive import drive_wall_run, wall_passes
from lti_motion.exceptions import WallRunError
from lti_motion.intrinsics import OdometryIntrinsics

PARAMS = get_preset("create2", wheel_diameter_errors=(0.01, 0.0), motor_balance=0.90)
NOMINAL = OdometryIntrinsics.symmetric(m_per_tick=PARAMS.m_per_tick,
                                       wheel_base_m=PARAMS.wheel_base_m)


def _true_ratio(drive) -> float:
    """Truth for scoring: each wheel's ground travel per tick over the first run's cruise."""
    run = drive.runs[0]
    v, w = drive.log.true_body_m_s[run].T
    cruise = np.abs(drive.log.cmd_m_s[run, 0] - 0.2) < 1e-9
    b = PARAMS.true_wheel_base_m
    travel = np.stack([v - 0.5 * b * w, v + 0.5 * b * w], 1)[cruise].sum(0)
    ticks = np.diff(drive.log.ticks[run], axis=0)[cruise[1:]].sum(0)
    return float((travel[0] / ticks[0]) / (travel[1] / ticks[1]))


def test_the_asymmetric_robot_finds_its_ratio_beside_a_wall():
    sim = Simulator(PARAMS, seed=4, floor="tile", room=Room.single_wall(),
                    initial_pose=(0.5, 0.5, -np.pi / 2 + 0.04))
    drive = drive_wall_run(sim, NOMINAL)
    blind = dataclasses.replace(drive, log=dataclasses.replace(drive.log, true_pose=None,
                                                               true_body_m_s=None))
    cal = calibrate_wall_run(wall_passes(blind, NOMINAL), NOMINAL, wall_side=drive.wall_side)
    assert drive.wall_side == "left"          # it curves away from a wall on its left
    true_ratio = _true_ratio(drive)
    assert true_ratio == pytest.approx(1.0095, abs=0.001)           # what is measured
    assert cal.diameter_ratio == pytest.approx(true_ratio, rel=2e-3)   # the 0.2% goal
    assert abs(NOMINAL.diameter_ratio / true_ratio - 1) > 5e-3          # and it mattered
    np.testing.assert_allclose(cal.heading_rad, 0.0, atol=0.02)       # squared up
    assert [p.gap_start_m for p in wall_passes(drive, NOMINAL)] == pytest.approx(
        [0.04, 0.16], abs=0.01)


def test_a_robot_curving_towards_the_wall_goes_over_to_the_other_side():
    mirrored = PARAMS.replace(wheel_diameter_errors=(0.0, 0.01))
    sim = Simulator(mirrored, seed=5, floor="tile", room=Room.single_wall(),
                    initial_pose=(0.5, 0.5, -np.pi / 2))
    drive = drive_wall_run(sim, NOMINAL)
    assert drive.wall_side == "right" and drive.sensor == 5
    assert len(drive.runs) == 2
    gaps = [drive.log.true_pose[run, 1] for run in drive.runs]        # scoring only
    assert min(g.min() for g in gaps) > 0.19                            # never touched
    cal = calibrate_wall_run(wall_passes(drive, NOMINAL), NOMINAL, wall_side="right")
    assert _true_ratio(drive) == pytest.approx(1 / 1.0095, abs=0.001)
    assert cal.diameter_ratio == pytest.approx(_true_ratio(drive), rel=2e-3)


def test_no_wall_ahead_is_an_error():
    sim = Simulator(PARAMS, seed=0, room=Room.empty(), initial_pose=(0, 0, 0))
    with pytest.raises(WallRunError, match=r"no wall found: no bump within 0\.3 m"):
        drive_wall_run(sim, NOMINAL, max_approach_m=0.3)


def test_bad_arguments():
    with pytest.raises(WallRunError, match="one robot"):
        drive_wall_run(Simulator(PARAMS, n_robots=2), NOMINAL)
    with pytest.raises(WallRunError, match="back-off"):
        drive_wall_run(Simulator(PARAMS), NOMINAL, backoff_m=(0.1, -0.1))
