"""The simulator's yaw-rate gyro: a sensor with bias and white noise, off by default."""

import numpy as np
import pytest

from drivers.exceptions import RobotFileError, SimulatorError
from drivers.sim.config import get_preset, load_robot
from drivers.sim.simulator import Simulator
from lti_motion.recordings.frames import FrameLog
from lti_motion.recordings.recording import Recording

DENSITY = 0.005         # rad/s/sqrt(Hz), a MEMS gyro
BIAS = 0.008            # rad/s

FIELDS = ("t_s", "ticks", "light_bump", "bumps", "cmd_m_s", "valid", "true_pose",
          "true_body_m_s", "motor_current_a", "wheel_overcurrent")


def _commands(n: int, seed: int) -> np.ndarray:
    """Smooth random wheel commands, positive, shape (n, 2)."""
    rng = np.random.default_rng(seed)
    steps = rng.uniform(0.05, 0.3, (n // 100 + 1, 2))
    return np.repeat(steps, 100, axis=0)[:n]


@pytest.fixture(scope="module")
def gyro_robot():
    return get_preset("create2").replace(gyro_noise_density_rad_s_sqrt_hz=DENSITY,
                                         gyro_bias_rad_s=BIAS)


def test_no_gyro_by_default_and_the_gyro_changes_no_other_output(gyro_robot):
    cmd = _commands(1500, 5)
    plain = Simulator("create2", seed=11).run(cmd)
    with_gyro = Simulator(gyro_robot, seed=11).run(cmd)
    assert plain.yaw_rate_rad_s is None
    assert with_gyro.yaw_rate_rad_s.shape == (1500,)
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(plain, name), getattr(with_gyro, name), name)


def test_reading_is_the_period_mean_yaw_rate_plus_bias_plus_white_noise(gyro_robot):
    dt = gyro_robot.period_s
    log = Simulator(gyro_robot, seed=12, initial_pose=(2.5, 2.5, 3.0)).run(_commands(8000, 6))
    heading = np.unwrap(np.concatenate([[3.0], log.true_pose[:, 2]]))
    err = log.yaw_rate_rad_s - np.diff(heading) / dt
    std = DENSITY / np.sqrt(dt)
    # 8000 draws: the mean within 4 standard errors, the spread within 5%
    assert abs(err.mean() - BIAS) < 4 * std / np.sqrt(err.size)
    assert abs(err.std() / std - 1.0) < 0.05
    assert abs(np.corrcoef(err[1:], err[:-1])[0, 1]) < 0.05       # white


def test_step_and_run_and_batches_give_the_same_readings(gyro_robot):
    cmd = _commands(300, 7)
    whole = Simulator(gyro_robot, seed=13).run(cmd)
    sim = Simulator(gyro_robot, seed=13)
    stepped = FrameLog.from_frames([sim.step(c) for c in cmd], dt_s=gyro_robot.period_s)
    np.testing.assert_array_equal(stepped.yaw_rate_rad_s, whole.yaw_rate_rad_s)
    batch = Simulator([gyro_robot, get_preset("create2")], seed=[13, 14]).run(
        np.stack([cmd, cmd]))
    np.testing.assert_array_equal(batch.yaw_rate_rad_s[0], whole.yaw_rate_rad_s)
    assert np.all(np.isnan(batch.yaw_rate_rad_s[1]))
    assert batch.robot(0).window(10, 20).yaw_rate_rad_s.shape == (10,)


def test_robot_file_gyro_section(tmp_path):
    base = get_preset("create2")
    text = f"""\
name = "gyrobot"
period_s = {base.period_s}
[geometry]
wheel_base_m = {base.wheel_base_m}
wheel_diameter_m = {base.wheel_diameter_m}
[encoders]
ticks_per_rev = {base.ticks_per_rev}
[delay]
delay_periods = {base.delay_periods}
[mass]
mass_kg = {base.mass_kg}
"""
    path = tmp_path / "gyrobot.toml"
    path.write_text(text)
    assert load_robot(path).gyro_noise_density_rad_s_sqrt_hz is None
    path.write_text(text + "[gyro]\ngyro_noise_density_rad_s_sqrt_hz = 0.005\n"
                    "gyro_bias_rad_s = -0.01\n")
    robot = load_robot(path)
    assert (robot.gyro_noise_density_rad_s_sqrt_hz, robot.gyro_bias_rad_s) == (0.005, -0.01)
    path.write_text(text + "[gyro]\ngyro_noise_density_rad_s_sqrt_hz = -1\n")
    with pytest.raises(RobotFileError, match=r"\[gyro\] gyro_noise_density_rad_s_sqrt_hz must"):
        load_robot(path)
    path.write_text(text + "[gyro]\ngyro_bias_rad_s = 0.01\n")
    with pytest.raises(RobotFileError, match="needs a gyro"):
        load_robot(path)


def test_bias_without_a_gyro_is_refused():
    with pytest.raises(SimulatorError, match="needs a gyro"):
        get_preset("create2").replace(gyro_bias_rad_s=0.01)


def test_the_recording_carries_the_gyro(gyro_robot):
    log = Simulator(gyro_robot, seed=15).run(_commands(200, 8))
    rec = Recording.from_frame_log(log)
    np.testing.assert_array_equal(rec.yaw_rate.values[:, 0], log.yaw_rate_rad_s)
    np.testing.assert_allclose(rec.yaw_rate.t_s, log.t_s - 0.5 * log.dt_s)
    assert Recording.from_frame_log(Simulator("create2", seed=15).run(
        _commands(20, 8))).yaw_rate is None
