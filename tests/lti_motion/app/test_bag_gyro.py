"""A bag's Imu yaw rate in ``lti-motion replay / monitor --bag``, and a gyro in the monitor.

The drive: the create2 simulator on carpet (the ground turns ~5% short of what the
wheels say) with a gyro (0.005 rad/s/sqrt(Hz), bias 0.006 rad/s), 5 s at rest, then 20 s
of curves that keep turning left (0.34 rad/s on average), 5% of frames lost after 6 s,
written to a ROS 1 bag with ``/imu/data``.

Measured before choosing the assertions (drive seeds 21-30, 10 runs, the ARX model of
``calibrate_simulator("create2", seed=4)`` on 40 s of excitation; final heading error
of the replayed ``ekf``): without the Imu 0.358 (sd 0.001) rad, with it 0.051 (sd 0.032)
rad, the ratio 0.04-0.29 (worst seed 26); the same logs replayed in memory (the
simulator's own readings, no bag) 0.052 (sd 0.031) rad, within 0.0053 rad of the bag's
on every run. Command: ``docs/replay.md``, "A ROS bag's Imu".
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import drivers.sim
from benchmarks.bench_bag_gyro import DENSITY, carpet_drive
from drivers.bags.writer import write_drive_bag
from fusion.ekf.ekf_options import EKFOptions
from fusion.exceptions import FilterOptionError
from fusion.monitoring.monitored_filter import MonitoredFilter
from fusion.noise import GyroNoise
from lti_motion.app.bag_commands import BagOptions, monitor_bag, replay_bag
from lti_motion.app.cli import main
from lti_motion.app.replay import estimate
from lti_motion.app.replay_sources import source_from_frame_log
from lti_motion.kinematics import wrap_angle
from lti_motion.recordings.frames import SensorFrame


@pytest.fixture(scope="module")
def model(short_arx_model):
    return short_arx_model(4)


@pytest.fixture(scope="module")
def model_file(model, tmp_path_factory):
    return model.save(tmp_path_factory.mktemp("model") / "model_arx.json")


@pytest.fixture(scope="module")
def carpet(tmp_path_factory):
    """The module docstring's drive, seed 21, and its bag."""
    log = carpet_drive(21)
    bag = write_drive_bag(tmp_path_factory.mktemp("bags") / "carpet.bag", log,
                          gyro_noise_density_rad_s_sqrt_hz=DENSITY)
    return log, bag


def _heading_error(poses: np.ndarray, truth: np.ndarray) -> float:
    return abs(float(wrap_angle(poses[-1, 2] - truth[-1, 2])))


def test_replay_bag_fuses_the_imu_with_gyro_and_leaves_it_out_by_default(carpet, model,
                                                                          tmp_path):
    """With the Imu the EKF ends under a third of its encoders-only heading error (measured:
    0.04-0.29 of it over 10 seeds, 0.043 on this one) and within 0.01 rad of the same drive
    replayed from memory (measured: within 0.0053 on every seed)."""
    log, bag = carpet
    lines = []
    err = {}
    for name, options in (("gyro", BagOptions(gyro=True)), ("plain", None)):
        result = replay_bag(bag, model, tmp_path / name, options=options,
                            estimators=["ekf"], print_fn=lines.append)
        gyro = name == "gyro"
        err[name] = _heading_error(result.poses["ekf"], result.source.truth)
        assert ("gyro_windows_fused" in result.metrics["ekf"]) == gyro
    assert err["gyro"] < err["plain"] / 3, err
    said = "\n".join(lines)
    assert re.search(r"EKF, model, encoders and gyro: .*; gyro: \d+ windows fused, \d+ gated",
                     said), said
    assert "EKF, model and encoders: " in said          # the default replay's label
    # the Imu's covariance (density^2 / dt, written by the bag writer) is the gyro's noise
    assert re.search(r"/imu/data's angular_velocity_covariance zz 0\.00167 rad\^2/s\^2 at "
                     r"6\d\.\d+ Hz: gyro noise density 0\.005 rad/s/sqrt\(Hz\)", said), said
    assert "gyro noise density 0.005 rad/s/sqrt(Hz), the recording's" in said
    memory = source_from_frame_log(log, "memory")
    poses, extra = estimate(memory, model, ["ekf"])
    assert abs(err["gyro"] - _heading_error(poses["ekf"], memory.truth)) < 0.01
    assert extra["ekf"]["gyro_windows_fused"] >= 20


def test_monitor_bag_fuses_the_imu(carpet, model):
    """The monitor's EKF with the bag's Imu ends closer in heading than without it, by the
    same margin as replay (the same filter), and says so."""
    log, bag = carpet
    err, said = {}, {}
    for name, gyro in (("gyro", True), ("plain", False)):
        lines = []
        run = monitor_bag(bag, model, options=BagOptions(gyro=gyro), print_fn=lines.append)
        err[name] = _heading_error(run.poses, log.true_pose)
        said[name] = "\n".join(lines)
    assert err["gyro"] < err["plain"] / 3, err
    assert "fuses the yaw rate of /imu/data as a gyro: /imu/data's angular_velocity_" \
        "covariance zz 0.00167" in said["gyro"]
    assert int(re.search(r"^gyro: (\d+) windows fused", said["gyro"], re.M)[1]) >= 20
    assert "gyro" not in said["plain"]


@pytest.mark.parametrize(("extra", "message"), [
    (["--imu-topic", "/odom", "--gyro"],
     "topic /odom holds nav_msgs/msg/Odometry, but --imu-topic needs sensor_msgs/Imu"),
    (["--imu-topic", "/imu/data"], "--imu-topic chooses the Imu that --gyro fuses; add --gyro"),
])
@pytest.mark.parametrize("command", ["replay", "monitor"])
def test_imu_options_given_wrong_are_one_line_and_exit_2(carpet, model_file, tmp_path, capsys,
                                                         command, extra, message):
    argv = [command, "--bag", str(carpet[1]), "--model", str(model_file), *extra]
    if command == "replay":
        argv += ["--out", str(tmp_path / "out")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and "Traceback" not in err, err


def test_monitored_filter_estimates_a_gyro_bias_at_rest(tiny_model, rng):
    """10 s at rest with a gyro reading 0.008 rad/s plus its white noise (0.041 rad/s a
    period), frames 300-309 lost (their readings too): the bias state ends within 0.003
    rad/s of 0.008 (two of its standard deviations, 0.0016 over 10 s at 0.005
    rad/s/sqrt(Hz)) and the heading stays within 0.005 rad of 0 (the encoders say: no
    turn). Without ``EKFOptions(gyro=)`` a frame with a reading is refused."""
    mf = MonitoredFilter(tiny_model, ekf_options=EKFOptions(history=0, gyro=GyroNoise()))
    readings = 0.008 + 0.005 / np.sqrt(tiny_model.dt_s) * rng.standard_normal(667)
    for k, y in enumerate(readings):
        mf.step(SensorFrame.of_counts(k * tiny_model.dt_s, np.array([100, 200]), np.zeros(2),
                                      valid=not 300 <= k < 310, yaw_rate_rad_s=float(y)))
    assert abs(mf.ekf.gyro_bias - 0.008) < 0.003, mf.ekf.gyro_bias
    assert abs(mf.ekf.pose[2]) < 0.005
    assert mf.ekf.stats.count("gyro", "non_finite") == 10       # the lost frames
    assert mf.ekf.stats.count("gyro", "fused") > 0
    with pytest.raises(FilterOptionError,
                       match=r"has no gyro; give ekf_options=EKFOptions\(gyro=GyroNoise"):
        MonitoredFilter(tiny_model).step(SensorFrame.of_counts(0.0, np.array([0, 0]), np.zeros(2),
                                                               yaw_rate_rad_s=0.0))


def test_monitor_sim_with_a_robot_file_that_has_a_gyro(model_file, tmp_path, capsys):
    """``lti-motion monitor --robot FILE --gyro`` with a ``[gyro]``: the EKF fuses it (8 s
    drive, no Phase I); without ``--gyro`` it is left out and a line says how to fuse it;
    ``--gyro`` for a robot without one or with ``--port`` is a one-line error."""
    robot = tmp_path / "gyro_robot.toml"
    preset = Path(drivers.sim.__file__).parent / "robots" / "create2.toml"
    robot.write_text(preset.read_text() + "\n[gyro]\ngyro_noise_density_rad_s_sqrt_hz = 0.005\n"
                     "gyro_bias_rad_s = 0.004\n")
    argv = ["monitor", "--robot", str(robot), "--model", str(model_file), "--duration", "8",
            "--nominal-drives", "0"]
    assert main([*argv, "--gyro"]) == 0
    out = capsys.readouterr().out
    assert ("the robot has a gyro: the EKF fuses its yaw rate (bias estimated; noise density "
            "0.005 rad/s/sqrt(Hz), the robot file's)") in out
    assert int(re.search(r"^gyro: (\d+) windows fused", out, re.M)[1]) >= 10, out
    assert main([*argv, "--duration", "1"]) == 0
    out = capsys.readouterr().out
    assert "the robot has a gyro; --gyro fuses its yaw rate" in out and "windows fused" not in out
    for where, message in ((["--robot", "create2"], "--gyro: the robot create2 has no gyro"),
                           (["--port", "/dev/null"], "a Roomba's stream has no gyro")):
        assert main(["monitor", *where, "--model", str(model_file), "--gyro"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err, err
