"""Stalled wheel or stuck encoder (``fusion.monitoring.wheel_check``): the rule on made-up
currents, then the simulator's blocked wheel and stuck encoder through ``MonitoredFilter``."""

import math

import numpy as np
import pytest

from drivers.sim.config import Fault, Room
from drivers.sim.simulator import Simulator
from fusion.exceptions import FilterOptionError, MeasurementShapeError
from fusion.monitoring.monitored_filter import MonitoredFilter
from fusion.monitoring.wheel_check import WheelCheck, WheelCheckOptions
from lti_motion.app.monitor_setup import monitor_route
from lti_motion.recordings.frames import SensorFrame

MOVING, FLAT_LEFT = np.array([False, False]), np.array([True, False])


def _drive(wc, n=30, current=0.03):
    for _ in range(n):
        wc.update(MOVING, np.array([7.0, 7.0]), np.array([current, current]))


def test_a_normal_current_while_the_count_stands_is_the_encoder_at_once():
    wc = WheelCheck()
    _drive(wc)
    wc.update(FLAT_LEFT, np.array([0.0, 7.0]), np.array([0.031, 0.03]))
    v = wc.verdict(0)
    assert (v.kind, v.evidence) == ("stuck_encoder", "current")
    assert v.min_current_a == pytest.approx(0.031) and v.reference_current_a == pytest.approx(0.03)


def test_a_high_current_is_a_stall_only_once_it_outlasts_a_start():
    wc = WheelCheck()
    _drive(wc)
    for k in range(WheelCheckOptions().decide_periods):
        assert wc.verdict(0) is None or k == 0          # waits while the current stays high
        wc.update(FLAT_LEFT, np.array([0.0, 7.0]), np.array([0.45, 0.03]))
    assert wc.verdict(0).kind == "stalled_wheel"
    # a start's few periods at the limit, then the running current: the encoder
    wc = WheelCheck()
    _drive(wc)
    for current in (0.45, 0.45, 0.45, 0.04):
        wc.update(FLAT_LEFT, np.array([0.0, 7.0]), np.array([current, 0.03]))
    assert wc.verdict(0).kind == "stuck_encoder"


def test_the_overcurrent_flag_decides_and_no_currents_leave_the_old_call():
    wc = WheelCheck()
    wc.update(FLAT_LEFT, np.array([0.0, 7.0]), np.array([0.2, 0.03]), np.array([True, False]))
    assert (wc.verdict(0).kind, wc.verdict(0).evidence) == ("stalled_wheel", "overcurrent")
    wc = WheelCheck()                                  # no running current yet, no flag: wait
    wc.update(FLAT_LEFT, np.array([0.0, 7.0]), np.array([0.2, 0.03]))
    assert wc.verdict(0) is None
    wc.update(FLAT_LEFT, np.array([0.0, 7.0]))
    assert (wc.verdict(0).kind, wc.verdict(0).evidence) == ("stuck_encoder", "no currents")
    assert math.isnan(wc.verdict(0).min_current_a)


def test_bad_input_is_a_clear_error():
    with pytest.raises(FilterOptionError, match="current_ratio"):
        WheelCheckOptions(current_ratio=0.5)
    with pytest.raises(MeasurementShapeError, match="motor_current_a must have shape"):
        WheelCheck().update(MOVING, np.zeros(2), np.zeros(3))


# -- on the simulator ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def model(short_arx_model):
    return short_arx_model(2)


SEEDS = (11, 12, 13, 14)


def _alarms(model, kind, *, currents=True):
    """Each seed's first wheel alarm after a 2 s fault on the left wheel at 8 s."""
    sim = Simulator("create2", seed=list(SEEDS), room=Room.empty(),
                    initial_pose=np.zeros((len(SEEDS), 3)),
                    faults=[Fault(kind, t_s=8.0, duration_s=2.0, wheel="left")])
    cmds = np.stack([monitor_route(11.0, dt_s=sim.dt_s, wheel_base_m=model.wheel_base_m,
                                   rng=np.random.default_rng(s)) for s in SEEDS])
    log = sim.run(cmds)
    out = []
    for i in range(len(SEEDS)):
        r = log.robot(i)
        mf = MonitoredFilter(model)
        for k in range(len(r)):
            # with currents the simulator's frame, else one of a robot that reports none
            mf.step(r.frame(k) if currents
                    else SensorFrame.of_counts(r.t_s[k], r.ticks[k], r.cmd_m_s[k]))
        wheel = [e for e in mf.events if e.test == "stuck"]
        out.append(wheel[0] if wheel else None)
    return out


def test_a_blocked_wheel_is_a_stalled_wheel_and_a_frozen_count_a_stuck_encoder(model):
    for e in _alarms(model, "stall"):
        assert e is not None and (e.kind, e.channel) == ("stalled_wheel", 0), e
        assert 8.0 <= e.t_s <= 8.3 and e.onset_s <= 8.0 + 0.03
    for e in _alarms(model, "stuck_encoder"):
        assert e is not None and (e.kind, e.channel) == ("stuck_encoder", 0), e
        assert 8.0 <= e.t_s <= 8.1
    # a robot that reports no currents: a blocked wheel cannot be told from the encoder
    assert {e.kind for e in _alarms(model, "stall", currents=False)} == {"stuck_encoder"}


def test_the_simulated_motor_draws_its_limit_when_blocked_and_flags_it():
    sim = Simulator("create2", seed=3, room=Room.empty(), initial_pose=(0.0, 0.0, 0.0),
                    faults=[Fault("stall", t_s=2.0, duration_s=1.0, wheel="right")])
    log = sim.run(np.full((267, 2), 0.2))               # 4 s at 0.2 m/s
    limit = sim.params[0].current_limit_a
    k0, k1 = round(2.0 / sim.dt_s), round(3.0 / sim.dt_s)
    running = np.abs(log.motor_current_a[100:k0])
    assert np.all(running < 0.25 * limit)               # driving: well below the limit
    assert np.allclose(np.abs(log.motor_current_a[k0 + 1:k1 - 1, 1]), limit)
    assert np.all(np.abs(log.motor_current_a[k0:k1, 0]) < 0.25 * limit)   # the other wheel
    # the overcurrent flag once the current has held the limit for OVERCURRENT_S
    from drivers.sim.kernel import OVERCURRENT_S
    flagged = np.flatnonzero(log.wheel_overcurrent[:, 1])
    assert flagged.size and flagged.min() * sim.dt_s == pytest.approx(2.0 + OVERCURRENT_S,
                                                                      abs=2 * sim.dt_s)
    # it clears once the freed wheel's current leaves the limit (its speed loop wound up)
    assert flagged.max() < k1 + 10 and not log.wheel_overcurrent[:, 0].any()
