"""An Imu's ``angular_velocity_covariance`` as the gyro's noise (drivers.bags.imu_noise): the
REP 145 conventions (all zeros unknown, element 0 of -1 no data), the conversion to a
noise density through the Imu's period, and the bags the tests write."""

from __future__ import annotations

import math

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.typesys import Stores, get_typestore

from drivers.bags.imu_noise import imu_rate_noise, with_rate_data
from drivers.bags.reader import CREATE2_WHEEL_RADIUS_M, bag_grid, read_bag
from drivers.bags.topics import StampedSeries, read_topics
from drivers.bags.writer import write_drive_bag
from drivers.exceptions import BagError
from drivers.sim.config import Room, get_preset
from drivers.sim.simulator import Simulator

DENSITY = 0.005                                  # rad/s/sqrt(Hz)


def _series(cov0, zz, period_ns=10_000_000):
    n = len(cov0)
    values = np.column_stack([np.full(n, 0.1), cov0, zz]).astype(float)
    return StampedSeries("/imu", "sensor_msgs/msg/Imu", np.arange(n, dtype=np.int64)
                         * period_ns, values)


def test_a_stated_variance_becomes_a_density_through_the_period():
    """sigma^2 = 0.0025 rad^2/s^2 per message at 100 Hz: q = sqrt(sigma^2 tau) = 0.005."""
    noise = imu_rate_noise(_series([1e6] * 5, [0.0025] * 5))
    assert noise.variance_rad2_s2 == 0.0025 and noise.period_s == pytest.approx(0.01)
    assert noise.density_rad_s_sqrt_hz == pytest.approx(0.005)
    assert (noise.n_known, noise.n_unknown, noise.n_no_data) == (5, 0, 0)
    assert "zz 0.0025 rad^2/s^2 at 100 Hz" in noise.describe("/imu")
    # the same noise at 400 Hz states a 4 times larger variance per message
    fast = imu_rate_noise(_series([0.0] * 5, [0.01] * 5, period_ns=2_500_000))
    assert fast.density_rad_s_sqrt_hz == pytest.approx(0.005)


def test_all_zero_is_unknown():
    noise = imu_rate_noise(_series([0.0] * 4, [0.0] * 4))
    assert noise.variance_rad2_s2 is None and noise.density_rad_s_sqrt_hz is None
    assert noise.n_unknown == 4
    assert "no yaw-rate covariance (all zeros: unknown)" in noise.describe("/imu")


def test_minus_one_is_no_data():
    """Element 0 of -1: the message has no rate; it is dropped, its neighbours kept; a topic
    of such messages only cannot be a gyro."""
    imu = _series([1e6, -1.0, 1e6, 1e6], [0.0025, 0.0, 0.0025, 0.0025])
    kept = with_rate_data(imu)
    np.testing.assert_array_equal(kept.t_ns, imu.t_ns[[0, 2, 3]])
    noise = imu_rate_noise(imu)
    assert (noise.n_known, noise.n_unknown, noise.n_no_data) == (3, 0, 1)
    assert with_rate_data(_series([0.0, 0.0], [0.0, 0.0])).t_ns.size == 2
    with pytest.raises(BagError, match=r"^topic /imu: every message's angular_velocity_"
                                       r"covariance\[0\] is -1 \(no angular velocity\)"):
        imu_rate_noise(_series([-1.0] * 3, [0.0] * 3))


def test_the_median_of_the_known_variances_and_a_negative_one():
    noise = imu_rate_noise(_series([0.0] * 5, [0.0, 0.001, 0.002, 0.004, 0.0]))
    assert noise.variance_rad2_s2 == 0.002 and noise.n_unknown == 2
    with pytest.raises(BagError, match=r"zz is -0\.001, a variance must not be negative"):
        imu_rate_noise(_series([0.0] * 3, [0.001, -0.001, 0.001]))


# -- through bags ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def drive():
    robot = get_preset("create2").replace(gyro_noise_density_rad_s_sqrt_hz=DENSITY,
                                          gyro_bias_rad_s=0.004)
    sim = Simulator(robot, seed=5, room=Room.empty(), initial_pose=(0.0, 0.0, 0.0))
    return sim.run(np.tile([0.15, 0.2], (200, 1)))


@pytest.mark.parametrize(("name", "storage"), [("d.bag", "mcap"), ("d_db3", "sqlite3"),
                                               ("d_mcap", "mcap")], ids=["ros1", "db3", "mcap"])
def test_the_writers_covariance_comes_back_as_the_density(tmp_path, drive, name, storage):
    """The bag writer states density^2 / dt per message (REP 145); read back through the
    Imu's stamps (jittered host times, median spacing dt within 1%) it is the density."""
    bag = write_drive_bag(tmp_path / name, drive, storage=storage,
                          gyro_noise_density_rad_s_sqrt_hz=DENSITY)
    found = read_topics(bag)
    np.testing.assert_allclose(found.imu.values[:, 2], DENSITY ** 2 / drive.dt_s)
    rec = read_bag(bag, dt_s=drive.dt_s)
    assert rec.gyro_density_rad_s_sqrt_hz == pytest.approx(DENSITY, rel=0.01)
    assert rec.meta["imu_noise"]["messages"] == [len(found.imu), 0, 0]


def test_a_bag_without_a_covariance_is_unknown(tmp_path, drive):
    """Written without a density the zz entry is 0: unknown, the default noise is used."""
    rec = read_bag(write_drive_bag(tmp_path / "u.bag", drive,
                                   gyro_noise_density_rad_s_sqrt_hz=None))
    assert rec.meta["imu_noise"]["variance_rad2_s2"] is None
    assert rec.gyro_density_rad_s_sqrt_hz is None and rec.yaw_rate is not None


def _raw_bag(path, store, wheels_ns, imu_ns, cov0):
    t = store.types
    vec = t["geometry_msgs/msg/Vector3"]

    def header(t_ns):
        return t["std_msgs/msg/Header"](seq=0, stamp=t["builtin_interfaces/msg/Time"](
            sec=int(t_ns // 10**9), nanosec=int(t_ns % 10**9)), frame_id="base_link")

    with Writer1(path) as writer:
        joints = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState",
                                       typestore=store)
        imu = writer.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=store)
        for i, t_ns in enumerate(wheels_ns):
            msg = t["sensor_msgs/msg/JointState"](
                header=header(t_ns), name=["wheel_left_joint", "wheel_right_joint"],
                position=np.array([0.01 * i, 0.01 * i]), velocity=np.zeros(0),
                effort=np.zeros(0))
            writer.write(joints, int(t_ns), store.serialize_ros1(msg, msg.__msgtype__))
        for t_ns, c0 in zip(imu_ns, cov0, strict=True):
            cov = np.zeros(9)
            cov[0], cov[8] = c0, (0.0 if c0 == -1.0 else 0.0004)
            msg = t["sensor_msgs/msg/Imu"](
                header=header(t_ns), orientation=t["geometry_msgs/msg/Quaternion"](
                    x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=np.zeros(9),
                angular_velocity=vec(x=0.0, y=0.0, z=0.3 if c0 != -1.0 else 99.0),
                angular_velocity_covariance=cov, linear_acceleration=vec(x=0.0, y=0.0, z=0.0),
                linear_acceleration_covariance=np.zeros(9))
            writer.write(imu, int(t_ns), store.serialize_ros1(msg, msg.__msgtype__))
    return path


def test_messages_without_a_rate_are_left_out_of_the_yaw_rate(tmp_path):
    """A 100 Hz Imu under 50 Hz wheels whose every 5th message says -1 (with a wild 99 rad/s
    in its rate): the frames' yaw rate is the other messages' 0.3 rad/s; the noise is the
    zz of those, 0.0004 rad^2/s^2 at 100 Hz: q = 0.002 rad/s/sqrt(Hz)."""
    store = get_typestore(Stores.ROS1_NOETIC)
    wheels_ns = 10**9 + np.arange(100) * 20_000_000
    imu_ns = 10**9 + np.arange(200) * 10_000_000
    cov0 = [-1.0 if i % 5 == 2 else 1e6 for i in range(200)]
    rec = read_bag(_raw_bag(tmp_path / "m.bag", store, wheels_ns, imu_ns, cov0))
    grid = bag_grid(rec, wheel_base_m=0.235, wheel_radius_m=CREATE2_WHEEL_RADIUS_M)
    y = grid.yaw_rate_rad_s[np.isfinite(grid.yaw_rate_rad_s)]
    assert y.size > 90
    np.testing.assert_allclose(y, 0.3, rtol=1e-9)
    assert rec.meta["imu_noise"]["messages"] == [160, 0, 40]
    assert len(rec.yaw_rate.t_s) == 160
    assert rec.gyro_density_rad_s_sqrt_hz == pytest.approx(math.sqrt(0.0004 * 0.01))


def test_an_imu_without_any_rate_is_refused(tmp_path):
    store = get_typestore(Stores.ROS1_NOETIC)
    path = _raw_bag(tmp_path / "n.bag", store, 10**9 + np.arange(20) * 20_000_000,
                    10**9 + np.arange(20) * 20_000_000, [-1.0] * 20)
    with pytest.raises(BagError, match=r"^topic /imu: every message's angular_velocity_"
                                       r"covariance\[0\] is -1"):
        read_bag(path)


@pytest.mark.parametrize("command", ["replay", "monitor"])
def test_the_cli_refuses_an_imu_without_rate_with_gyro(tmp_path, capsys, ekf_example_model,
                                                      command):
    """``--gyro`` on a bag whose Imu has no angular velocity: one line, exit 2, nothing
    written; without ``--gyro`` the Imu is not read (the bag has no commands: replay runs
    the odometry, monitor refuses)."""
    from lti_motion.app.cli import main

    store = get_typestore(Stores.ROS1_NOETIC)
    bag = _raw_bag(tmp_path / "n.bag", store, 10**9 + np.arange(100) * 20_000_000,
                   10**9 + np.arange(100) * 20_000_000, [-1.0] * 100)
    model = ekf_example_model.save(tmp_path / "model_arx.json")
    # the bag's 20 ms resampled to the model's 15 ms, as asked (--dt)
    argv = [command, "--bag", str(bag), "--model", str(model), "--dt", "0.015"]
    if command == "replay":
        argv += ["--out", str(tmp_path / "out")]
    assert main([*argv, "--gyro"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "angular_velocity_covariance[0] is -1" in err, err
    assert not (tmp_path / "out").exists()
    if command == "replay":           # the bag has no commands: the odometry replays alone
        assert main(argv) == 0, capsys.readouterr().err
    else:                             # every test of the monitor predicts from the commands
        assert main(argv) == 2
        assert "monitor --bag needs the commands" in capsys.readouterr().err
