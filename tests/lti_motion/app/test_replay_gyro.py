"""`lti-motion replay` fuses a log's gyro (docs/ekf.md): saved, loaded and fused in the EKFs."""

import numpy as np
import pytest

from drivers.sim.config import Fault, Room, get_preset
from drivers.sim.simulator import Simulator
from lti_motion.app.replay import estimate, run_replay
from lti_motion.app.replay_sources import source_from_log
from lti_motion.kinematics import wrap_angle
from lti_motion.recordings.logfile import load_log, save_log


@pytest.fixture(scope="module")
def model(short_arx_model):
    return short_arx_model(4)


def test_a_carpet_drive_with_a_gyro_replays_with_a_better_heading(model, tmp_path):
    """20 s of curves on carpet (ground turns ~5% short), 5 s at rest first, 5% of frames
    lost: the log keeps the readings, and the EKF that fuses them ends with a third of the
    heading error of odometry."""
    robot = get_preset("create2").replace(floor="carpet", gyro_noise_density_rad_s_sqrt_hz=0.005,
                                          gyro_bias_rad_s=0.006)
    sim = Simulator(robot, seed=21, room=Room.empty(), initial_pose=(0.0, 0.0, 0.0),
                    faults=[Fault("lost_frames", t_s=6.0, probability=0.05)])
    k = np.arange(round(20.0 / sim.dt_s))
    turn = 0.06 * np.sin(k * sim.dt_s * 2 * np.pi / 10.0)
    cmd = np.concatenate([np.zeros((round(5.0 / sim.dt_s), 2)),
                          np.stack([0.2 - turn, 0.2 + turn], axis=1)])
    log = sim.run(cmd)
    path = save_log(tmp_path / "gyro.npz", log)
    np.testing.assert_array_equal(load_log(path).yaw_rate_rad_s, log.yaw_rate_rad_s)
    src = source_from_log(path)
    assert np.isnan(src.yaw_rate_rad_s[~src.valid]).all()
    poses, extra = estimate(src, model, ["odometry", "ekf"])
    assert extra["ekf"]["gyro_windows_fused"] >= 20
    assert extra["ekf"]["gyro_windows_gated"] <= 1
    err = {name: abs(float(wrap_angle(p[-1, 2] - src.truth[-1, 2]))) for name, p in poses.items()}
    assert err["ekf"] < err["odometry"] / 3, err
    plain = source_from_log(save_log(tmp_path / "plain.npz",
                                     Simulator("create2", seed=21).run(cmd[:100])))
    assert plain.yaw_rate_rad_s is None
    assert "gyro_windows_fused" not in estimate(plain, model, ["ekf"])[1]["ekf"]


def test_replay_fuses_a_logs_gyro_only_when_asked(model, tmp_path):
    """``run_replay`` (``lti-motion replay LOG``) leaves a log's gyro out unless ``gyro=True``
    (``--gyro``), and says the recording has one."""
    robot = get_preset("create2").replace(gyro_noise_density_rad_s_sqrt_hz=0.005)
    path = save_log(tmp_path / "g.npz", Simulator(robot, seed=5).run(np.full((300, 2), 0.1)))
    for gyro in (False, True):
        lines = []
        result = run_replay(path, model, tmp_path / f"out{gyro}", estimators=["ekf"],
                            gyro=gyro, print_fn=lines.append)
        assert ("gyro_windows_fused" in result.metrics["ekf"]) == gyro
        assert ("the recording has gyro readings; --gyro fuses them" in lines) != gyro
