"""No ``nav_msgs/Odometry`` the project writes holds a zero variance: the drive bags'
``/odom`` (dead reckoning, its pose covariance grown along the path) and the estimates of
``replay --bag --out-bag`` and ``monitor --bag --out-bag`` (the twist's the model's output
noise, the pose's the filter's)."""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from drivers.bags.writer import UNESTIMATED_VARIANCE, write_drive_bag, write_estimates_bag
from drivers.sim.simulator import Simulator
from lti_motion.app.cli import main
from lti_motion.model.excitation import random_held_normal
from lti_motion.model.motion_model import MotionModel
from lti_motion.odometry_noise import OdometryNoise

START_NS = 1_760_000_000 * 1_000_000_000


def _odometry(path) -> list:
    with AnyReader([path]) as reader:
        return [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                if c.msgtype == "nav_msgs/msg/Odometry"]


def _diagonals(msgs) -> tuple[np.ndarray, np.ndarray]:
    pose = np.array([np.diag(m.pose.covariance.reshape(6, 6)) for m in msgs])
    twist = np.array([np.diag(m.twist.covariance.reshape(6, 6)) for m in msgs])
    return pose, twist


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """A 45 s excitation of the create2 simulator, as a ROS 2 bag, and a model of it."""
    folder = tmp_path_factory.mktemp("cov")
    cmd = random_held_normal(n=3000, dt_s=0.015, rng=np.random.default_rng(5), std_m_s=0.2,
                             mean_m_s=0.05, hold_s=(0.5, 2.0), correlation=0.85)
    log = Simulator("create2", seed=21).run(cmd)
    bag = write_drive_bag(folder / "drive", log, start_ns=START_NS)
    out = folder / "cal"
    assert main(["calibrate", "--accept-unhealthy", "--bag", str(bag), "--robot", "create2",
                 "--out", str(out)]) == 0
    return {"folder": folder, "log": log, "bag": bag, "model": out / "model_arx.json"}


def test_the_drive_bags_odometry_grows_its_pose_covariance_and_has_no_zero(drive):
    msgs = _odometry(drive["bag"])
    pose, twist = _diagonals(msgs)
    assert np.all(pose > 0) and np.all(twist > 0)
    assert np.all(np.diff(pose[:, 5]) > 0)              # the heading's grows every period
    assert pose[-1, 0] + pose[-1, 1] > 100 * (pose[1, 0] + pose[1, 1])
    assert np.all(pose[:, [2, 3, 4]] == UNESTIMATED_VARIANCE)


def test_a_model_noise_gives_the_drive_bags_twist_its_output_noise(drive, tmp_path):
    model = MotionModel.load(drive["model"])
    noise = OdometryNoise.from_model(model)
    path = write_drive_bag(tmp_path / "with_model.bag", drive["log"], start_ns=START_NS,
                           odom_noise=noise)
    _, twist = _diagonals(_odometry(path))
    spans = np.diff(np.flatnonzero(drive["log"].valid))
    np.testing.assert_allclose(twist[1:, 0], model.R[0, 0] / spans, rtol=1e-12)
    np.testing.assert_allclose(twist[1:, 5], model.R[1, 1] / spans, rtol=1e-12)


def test_estimates_without_twist_noise_say_unknown_not_zero(tmp_path):
    n = 5
    path = write_estimates_bag(tmp_path / "est.bag", START_NS + np.arange(n) * 10**7,
                               np.zeros((n, 3)), np.zeros((n, 3, 3)))
    pose, twist = _diagonals(_odometry(path))
    assert np.all(pose > 0)                              # floored, never 0
    assert np.all(twist == UNESTIMATED_VARIANCE)


@pytest.mark.parametrize("command", ["replay", "monitor"])
def test_out_bag_estimates_carry_the_model_noise_and_the_filters_pose(drive, command, tmp_path):
    model = MotionModel.load(drive["model"])
    est = tmp_path / "est"
    argv = [command, "--bag", str(drive["bag"]), "--model", str(drive["model"]),
            "--out-bag", str(est)]
    if command == "replay":
        argv += ["--out", str(tmp_path / "replay")]
    assert main(argv) == 0
    msgs = _odometry(est)
    pose, twist = _diagonals(msgs)
    assert np.all(pose > 0) and np.all(twist > 0)
    np.testing.assert_allclose(twist[:, 0], model.R[0, 0], rtol=1e-12)
    np.testing.assert_allclose(twist[:, 5], model.R[1, 1], rtol=1e-12)
    speeds = np.array([[m.twist.twist.linear.x, m.twist.twist.angular.z] for m in msgs])
    assert np.abs(speeds[:, 0]).max() > 0.05               # the filter's speeds, not zeros
