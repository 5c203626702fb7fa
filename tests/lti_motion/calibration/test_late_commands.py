"""Calibration when the robot applies commands later than the host planned them.

Over a serial link a host that answers late has its command applied one or more
periods later, and the frames record the command applied (packets 41/42). The step
phases must be found where the robot put them (before, the end-to-end calibration
over a pseudo-terminal failed on a loaded machine with "no step of wheel L at sample 0").
"""

from collections import deque

import numpy as np
import pytest

from drivers.sim.config import Room
from drivers.sim.simulator import Simulator
from lti_motion.calibration.manoeuvres import CalibrationPlan, calibrate, phases_as_applied
from lti_motion.exceptions import CalibrationError
from lti_motion.model.excitation import step_sequence


class LateRobot:
    """A simulator that applies each command ``lag`` periods after it was sent."""

    def __init__(self, sim: Simulator, lag: int) -> None:
        self.sim, self.dt_s = sim, sim.dt_s
        self._queue = deque([np.zeros(2)] * lag)

    def step(self, cmd_m_s):
        self._queue.append(np.asarray(cmd_m_s, dtype=float))
        return self.sim.step(self._queue.popleft())


def test_phases_follow_each_edge_to_where_it_was_applied():
    seq = step_sequence(amplitude_m_s=0.3, hold_s=0.3, rest_s=0.3, dt_s=0.015)
    recorded = seq.cmd_m_s.copy()
    on, off, r_on, r_off = seq.phases
    recorded[on.start:on.start + 2] = 0.0            # left on lands 2 late
    recorded[off.start:off.start + 1] = recorded[off.start - 1]     # left off 1 late
    got = phases_as_applied(seq, recorded, max_lag=5)
    assert got == (slice(on.start + 2, off.start + 1), slice(off.start + 1, r_on.start),
                   slice(r_on.start, r_off.start), r_off)
    assert phases_as_applied(seq, seq.cmd_m_s, max_lag=5) == seq.phases


def test_a_step_never_applied_is_a_calibration_error():
    seq = step_sequence(amplitude_m_s=0.3, hold_s=0.3, rest_s=0.3, dt_s=0.015)
    with pytest.raises(CalibrationError, match=r"did not apply the step command \[0.3, 0.0\]"):
        phases_as_applied(seq, np.zeros_like(seq.cmd_m_s), max_lag=5)


def test_calibration_through_a_late_link_finds_the_steps():
    lag = 2                                          # periods: a host answering 30 ms late
    plan = CalibrationPlan(seed=3, excitation_s=10.0)
    sims = [Simulator("create2", seed=1, room=Room.cluttered(),
                      initial_pose=Room.CALIBRATION_SPOT) for _ in range(2)]
    cals = []
    for sim, robot in ((sims[0], sims[0]), (sims[1], LateRobot(sims[1], lag))):
        cals.append(calibrate(robot, wheel_base_m=0.235, plan=plan, floor="hard",
                              before_stage=lambda s, sim=sim: s != "rotation"
                              and sim.place(Room.OPEN_FLOOR)))
    on_time, late = cals
    # the same robot, the same steps (shifted by the lag): the same FIR within noise
    np.testing.assert_allclose(late.fir.coefficients["taps"].sum(axis=0),
                               on_time.fir.coefficients["taps"].sum(axis=0),
                               rtol=0.05, atol=0.02)
    assert late.fir.orders["n_taps"] == pytest.approx(on_time.fir.orders["n_taps"], abs=3)


def test_each_driven_manoeuvre_starts_on_fresh_frames():
    """calibrate asks a serial robot to drop frames that waited unread before each
    manoeuvre it drives (none for a recorded one)."""
    calls = []

    class SerialLike(LateRobot):
        def discard_buffered(self):
            calls.append(True)
            return 0

    sim = Simulator("create2", seed=1, room=Room.cluttered(), initial_pose=Room.CALIBRATION_SPOT)
    plan = CalibrationPlan(seed=3, excitation_s=10.0)
    first = calibrate(sim, wheel_base_m=0.235, plan=plan)
    calibrate(SerialLike(sim, 0), wheel_base_m=0.235, plan=plan,
              recorded={"rotation": first.logs["rotation"]})
    assert len(calls) == 2                           # steps and excitation, not the rotation
