"""Recording frames from drivers and replaying log files."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drivers.logs import Recorder, replay
from drivers.roomba.driver import Roomba
from drivers.roomba.roomba_options import RoombaOptions
from drivers.roomba.virtual import VirtualRoomba
from drivers.roomba.virtual_options import VirtualRoombaOptions
from drivers.sim.config import Fault
from drivers.sim.simulator import Simulator
from lti_motion.exceptions import LogFileError
from lti_motion.recordings.frames import SensorFrame
from lti_motion.recordings.logfile import load_log


def test_round_trip_through_save_and_load_keeps_every_field(tmp_path, rng):
    sim = Simulator("create2", seed=3, faults=[Fault("lost_frames", t_s=0.0, probability=0.2)])
    rec = Recorder(meta={"source": "sim"})
    cmds = rng.uniform(-0.3, 0.3, (120, 2)).round(3)
    rec.extend(sim.step(c) for c in cmds)
    path = rec.save(tmp_path / "drive.npz")
    log, ref = load_log(path), Simulator("create2", seed=3,
                                         faults=[Fault("lost_frames", t_s=0.0,
                                                       probability=0.2)]).run(cmds)
    for name in ("t_s", "ticks", "light_bump", "bumps", "cmd_m_s", "valid", "true_pose"):
        assert np.array_equal(getattr(log, name), getattr(ref, name)), name
    assert log.meta["source"] == "sim" and log.meta["n_frames"] == 120 and log.dt_s == 0.015
    frames = list(replay(path))
    assert len(frames) == int(ref.valid.sum()) < 120             # lost frames are skipped
    assert all(np.array_equal(f.ticks, t) for f, t in zip(frames, ref.ticks[ref.valid],
                                                          strict=True))


def test_recording_a_driver_keeps_the_oi_mode(tmp_path):
    rec = Recorder()
    options = RoombaOptions(clock_rate=5.0, stall_periods=100)
    with VirtualRoomba(seed=5, options=VirtualRoombaOptions(speed=5.0)) as vr, \
            Roomba(vr.device_path, options=options) as robot:
        for _ in range(30):
            rec.add(robot.step([0.1, -0.1]))
    path = rec.save(tmp_path / "robot.npz", dt_s=robot.dt_s)
    frames = list(replay(path))
    assert len(frames) == 30 and {f.oi_mode for f in frames} == {2}
    assert all(np.array_equal(a.ticks, b.ticks) and a.t_s == b.t_s
               for a, b in zip(frames, rec.frames, strict=True))
    assert not load_log(path).has_truth


def test_bad_input():
    rec = Recorder()
    with pytest.raises(ValueError, match="no frames"):
        rec.to_log()
    with pytest.raises(TypeError, match="SensorFrame"):
        rec.add({"ticks": [0, 0]})
    batch = Simulator("create2", n_robots=2).step(np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        rec.add(batch)
    with pytest.raises(ValueError, match="dt_s"):
        Recorder(dt_s=0.0)


def test_replay_of_a_damaged_file_raises(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a log")
    with pytest.raises(LogFileError):
        list(replay(bad))
    with pytest.raises(FileNotFoundError):
        list(replay(tmp_path / "missing.npz"))


def test_to_log_uses_the_given_period():
    f = SensorFrame(t_s=0.0, ticks=np.zeros(2, np.int64), light_bump=np.zeros(6, np.int64),
                    bumps=np.zeros(2, bool), cmd_m_s=np.zeros(2))
    rec = Recorder(dt_s=0.02)
    rec.extend([f, dataclasses.replace(f, t_s=0.02, valid=False)])
    log = rec.to_log(0.018)
    assert log.dt_s == 0.018 and log.valid.tolist() == [True, False] and len(rec) == 2
