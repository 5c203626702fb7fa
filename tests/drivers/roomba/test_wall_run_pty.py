"""The wall run over a real pseudo-terminal: the manoeuvre through the pyserial driver
against the virtual Roomba (docs/intrinsics.md, on a robot). The estimate reads only the
driver's frames; the simulator's truth is rebuilt here, for scoring only, by running the
commands the emulator applied through a fresh simulator of the same seed."""

import math

import numpy as np
import pytest

from benchmarks.bench_intrinsics import straight_line_truth
from drivers.roomba.driver import Roomba, RoombaOptions
from drivers.roomba.oi import DEFAULT_STREAM_IDS
from drivers.roomba.virtual import VirtualRoomba, VirtualRoombaOptions
from drivers.sim.config import Room, get_preset
from drivers.sim.simulator import Simulator
from lti_motion.calibration.wall_run import calibrate_wall_run
from lti_motion.calibration.wall_run_drive import drive_wall_run, wall_passes
from lti_motion.exceptions import NoSignalError
from lti_motion.intrinsics import OdometryIntrinsics

SPEED = 10.0           # the emulator runs 10x faster than real time
PARAMS = get_preset("create2", wheel_diameter_errors=(0.01, 0.0), motor_balance=0.90)
NOMINAL = OdometryIntrinsics.symmetric(m_per_tick=PARAMS.m_per_tick,
                                       wheel_base_m=PARAMS.wheel_base_m)
SCENE = {"seed": 4, "floor": "tile", "room": Room.single_wall(),
         "initial_pose": (0.5, 0.5, -np.pi / 2 + 0.04)}


def _roomba(vr: VirtualRoomba, **options) -> Roomba:
    # a pty loses nothing: count frames (docs/driver.md, latency_tolerance_s=math.inf)
    return Roomba(vr.device_path,
                  options=RoombaOptions(clock_rate=SPEED, open_timeout_s=3.0,
                                        latency_tolerance_s=math.inf, write_timeout_s=2.0,
                                        **options))


def test_the_wall_run_over_the_serial_driver_finds_the_ratio():
    vr = VirtualRoomba(PARAMS, **SCENE, options=VirtualRoombaOptions(speed=SPEED))
    with vr, _roomba(vr) as robot:
        drive = drive_wall_run(robot, NOMINAL, run_m=1.0)
        counters = robot.counters
    assert drive.log.true_pose is None                 # the driver's frames carry no truth
    cal = calibrate_wall_run(wall_passes(drive, NOMINAL), NOMINAL, wall_side=drive.wall_side)
    # scoring only: the emulator's applied commands through the same simulator, bit for bit
    replay = Simulator(PARAMS, **SCENE).run(vr.applied_commands_m_s)
    left, right, _ = straight_line_truth(PARAMS, replay, replay.cmd_m_s)
    true_ratio = left / right
    assert counters.checksum_failures == 0 and counters.bytes_dropped == 0
    assert drive.wall_side == "left" and len(drive.runs) == 2
    assert true_ratio > 1.005                      # the larger left wheel shows (1.0086)
    assert cal.diameter_ratio == pytest.approx(true_ratio, rel=2e-3)   # the 0.2% goal
    assert abs(NOMINAL.diameter_ratio / true_ratio - 1) > 5e-3         # and it mattered
    assert [p.gap_start_m for p in wall_passes(drive, NOMINAL)] == pytest.approx(
        [0.04, 0.16], abs=0.01)


def test_a_stream_without_light_bumps_is_named():
    vr = VirtualRoomba(PARAMS, **SCENE, options=VirtualRoombaOptions(speed=SPEED))
    no_light = [i for i in DEFAULT_STREAM_IDS if not 46 <= i <= 51]
    with vr, _roomba(vr, stream_ids=no_light) as robot, pytest.raises(
            NoSignalError, match=r"no light-bump signals.*packets"):
        drive_wall_run(robot, NOMINAL, run_m=1.0)
