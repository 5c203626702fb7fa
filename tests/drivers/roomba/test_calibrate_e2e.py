"""End to end over a real pseudo-terminal: the calibration manoeuvres through the real
pyserial driver against the virtual Roomba, compared with calibrating the simulator
directly (target: "a calibrated model whose fit matches calibrating on the
simulator directly, within 1 point")."""

import math

import numpy as np
import pytest

from drivers.roomba.driver import Roomba
from drivers.roomba.roomba_options import RoombaOptions
from drivers.roomba.virtual import VirtualRoomba
from drivers.roomba.virtual_options import VirtualRoombaOptions
from drivers.sim.config import Room
from drivers.sim.simulator import Simulator
from lti_motion.calibration.manoeuvres import CalibrationPlan, calibrate, speeds_from_log
from lti_motion.model.excitation import random_held_normal

SPEED = 20.0          # the emulator runs 20x faster than real time
PLAN = CalibrationPlan(seed=3)


def _validation(cal):
    rng = np.random.default_rng(11)
    cmds = np.stack([np.concatenate([np.zeros((60, 2)), random_held_normal(
        n=round(90 / 0.015), dt_s=0.015, rng=rng, std_m_s=PLAN.excitation_std_m_s,
        hold_s=PLAN.hold_s, correlation=PLAN.excitation_correlation)]) for _ in range(3)])
    logs = Simulator("create2", n_robots=3, seed=42, room=Room.empty()).run(cmds)
    runs = [speeds_from_log(logs.robot(i), m_per_tick=cal.m_per_tick, wheel_base_m=0.235)
            for i in range(3)]
    return np.mean([cal.arx.fit_percent([r]) for r in runs], axis=0)


@pytest.fixture(scope="module")
def both():
    direct_sim = Simulator("create2", seed=1, room=Room.cluttered(),
                           initial_pose=Room.CALIBRATION_SPOT)
    direct = calibrate(direct_sim, wheel_base_m=0.235, plan=PLAN, floor="hard",
                       before_stage=lambda s: s != "rotation" and direct_sim.place(Room.OPEN_FLOOR))
    vr = VirtualRoomba("create2", seed=1, room=Room.cluttered(), initial_pose=Room.CALIBRATION_SPOT,
                       options=VirtualRoombaOptions(speed=SPEED))
    # the stall window is the driver's wall-time floor (0.3 s): at 20x, 5 periods are 3.75 ms.
    # A pty loses nothing, and the emulator's thread, held off by a loaded host, sends frames
    # late and slips its schedule (overruns), which a robot's clock never does: the driver
    # counts frames (latency_tolerance_s=inf). With 0.6 s, 295 periods were taken for lost on
    # a quiet machine and 726 on a loaded one, and the fit fell 1.2 and 2.4 points below
    # the direct calibration's (5,124 and 76 points with another test run beside it).
    with vr, Roomba(vr.device_path,
                    options=RoombaOptions(clock_rate=SPEED, open_timeout_s=3.0,
                                          latency_tolerance_s=math.inf,
                                          write_timeout_s=2.0)) as robot:
        over_pty = calibrate(robot, wheel_base_m=0.235, plan=PLAN, floor="hard",
                             before_stage=lambda s: s != "rotation" and vr.place(Room.OPEN_FLOOR))
        counters = robot.counters
    return direct, over_pty, counters


def test_fit_through_the_driver_matches_the_direct_calibration_within_1_point(both):
    direct, over_pty, _ = both
    fit_direct, fit_pty = _validation(direct), _validation(over_pty)
    assert np.all(fit_pty >= 90.0), fit_pty
    np.testing.assert_allclose(fit_pty, fit_direct, atol=1.0)
    assert abs(over_pty.m_per_tick / direct.m_per_tick - 1.0) < 0.002
    assert over_pty.arx.orders["delay"] == pytest.approx(direct.arx.orders["delay"], abs=1)


def test_no_frames_lost_during_calibration(both):
    """A pty loses no bytes: every frame arrives whole. (The stream clock's timestamps are
    not the measure: a host stalled for tens of ms makes it infer skipped periods.)"""
    _, over_pty, counters = both
    assert counters.checksum_failures == 0 and counters.bytes_dropped == 0
    assert counters.bad_length == 0 and counters.stalls == 0
    for log in over_pty.logs.values():
        assert log.valid.all()
        assert np.all(np.diff(log.t_s) > 0)
