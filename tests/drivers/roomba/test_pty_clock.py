"""On a pseudo-terminal, frames that arrive late are late, not lost (issue 28, item 1).

A busy host starves the virtual Roomba's thread: it falls behind its schedule and
catches up with a burst of frames (``drivers/roomba/virtual.py``). Every frame still
arrives; a stream clock that took the burst's wall-time lateness, scaled by the clock
rate, for lost periods would cut a manoeuvre short. On a pseudo-terminal the frames
are counted; the emulator's own stalls are found with a tolerance given
(``test_driver.py``, a 40 ms gap at 10x).
"""

import math
import time

import numpy as np

from drivers.roomba.driver import Roomba, is_pseudo_terminal
from drivers.roomba.roomba_options import SERIAL_LATENCY_TOLERANCE_S, RoombaOptions
from drivers.roomba.virtual import VirtualRoomba
from drivers.roomba.virtual_options import VirtualRoombaOptions


def test_the_tolerance_is_chosen_by_the_link(tmp_path):
    with VirtualRoomba(seed=1, options=VirtualRoombaOptions(speed=10.0)) as vr:
        assert is_pseudo_terminal(vr.device_path)
        assert Roomba(vr.device_path).latency_tolerance_s == math.inf        # counted
        given = RoombaOptions(latency_tolerance_s=0.05)
        assert Roomba(vr.device_path, options=given).latency_tolerance_s == 0.05
    plain = tmp_path / "not-a-tty"
    plain.write_text("")
    assert not is_pseudo_terminal(str(plain)) and not is_pseudo_terminal("/dev/nope")
    serial = Roomba(str(plain), options=RoombaOptions(clock_rate=10.0))
    assert serial.latency_tolerance_s == SERIAL_LATENCY_TOLERANCE_S     # robot time there


def test_a_starved_emulator_loses_no_period(monkeypatch):
    tick, ticks = VirtualRoomba._tick, []

    def starved_now_and_then(self):
        ticks.append(1)
        if len(ticks) % 150 == 0:
            time.sleep(0.025)              # the scheduler gives the thread no CPU for 25 ms
        tick(self)

    monkeypatch.setattr(VirtualRoomba, "_tick", starved_now_and_then)
    with VirtualRoomba(seed=1, options=VirtualRoombaOptions(speed=10.0)) as vr, \
            Roomba(vr.device_path, options=RoombaOptions(clock_rate=10.0,
                                                      open_timeout_s=5.0)) as robot:
        frames = [robot.step((0.1, 0.1)) for _ in range(1000)]
        skipped = robot.counters.periods_skipped
    t_s = np.array([f.t_s for f in frames])
    assert skipped == 0
    np.testing.assert_allclose(np.diff(t_s), robot.dt_s)   # one period per frame


def test_catch_up_drops_the_frames_a_host_left_waiting():
    with VirtualRoomba(seed=1, options=VirtualRoombaOptions(speed=10.0)) as vr, \
            Roomba(vr.device_path, options=RoombaOptions(clock_rate=10.0,
                                                      open_timeout_s=5.0)) as robot:
        time.sleep(0.5)                       # a library loading: 333 periods at 10x
        k_before = robot.counters.frames
        dropped = robot.catch_up()
        frames = [robot.step((0.1, 0.1)) for _ in range(40)]
    assert dropped >= 250 and robot.counters.frames >= k_before + dropped
    # the commands act within a few periods, not after the 333 stale frames
    assert any(np.allclose(f.cmd_m_s, 0.1) for f in frames)
    t_s = np.array([f.t_s for f in frames])
    assert t_s[0] >= 250 * robot.dt_s                 # the dropped frames' periods counted
