"""The recorded-log format: round trip, atomic write, damaged and foreign files."""

import json

import numpy as np
import pytest

from drivers.sim.simulator import Simulator
from lti_motion.exceptions import LogFileError
from lti_motion.logfile import LOG_VERSION, load_log, save_log


@pytest.fixture
def sim_log():
    return Simulator("create2", seed=2).run(np.full((60, 2), 0.2))


def test_round_trip_is_exact(tmp_path, sim_log):
    path = save_log(tmp_path / "drive.npz", sim_log)
    again = load_log(path)
    for name in ("t_s", "ticks", "light_bump", "bumps", "cmd_m_s", "valid", "true_pose",
                 "true_body_m_s"):
        np.testing.assert_array_equal(getattr(again, name), getattr(sim_log, name))
    assert again.dt_s == sim_log.dt_s and again.meta == json.loads(json.dumps(sim_log.meta))
    assert [p.name for p in tmp_path.iterdir()] == ["drive.npz"]     # no temporary left


def test_damaged_foreign_and_future_files_raise(tmp_path, sim_log):
    path = save_log(tmp_path / "drive.npz", sim_log)
    truncated = tmp_path / "cut.npz"
    truncated.write_bytes(path.read_bytes()[:200])
    with pytest.raises(LogFileError, match="damaged or not a log file"):
        load_log(truncated)
    foreign = tmp_path / "other.npz"
    np.savez(foreign, header=np.array(json.dumps({"format": "something-else"})))
    with pytest.raises(LogFileError, match="is not an lti-motion-log file"):
        load_log(foreign)
    future = tmp_path / "future.npz"
    np.savez(future, header=np.array(json.dumps({"format": "lti-motion-log",
                                                 "version": LOG_VERSION + 1})))
    with pytest.raises(LogFileError, match=f"version {LOG_VERSION + 1}"):
        load_log(future)
    with pytest.raises(FileNotFoundError):
        load_log(tmp_path / "missing.npz")
