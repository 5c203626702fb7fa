"""A simulated gyro through ROS bags: written as ``sensor_msgs/Imu``, read back onto the frames.

The drive is the simulator's with a gyro (carpet, bias 0.006 rad/s, 5% of frames
lost), written in the three formats; the bad-input bags are written with rosbags
alone.
"""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.typesys import Stores, get_typestore

from benchmarks.bench_bag_gyro import DENSITY, carpet_drive
from drivers.bags.reader import CREATE2_WHEEL_RADIUS_M, bag_grid, read_bag
from drivers.bags.topics import read_topics
from drivers.bags.writer import UNESTIMATED_VARIANCE, write_drive_bag
from drivers.exceptions import BagError
from drivers.sim.simulator import Simulator

FORMATS = [("drive.bag", "mcap"), ("drive_db3", "sqlite3"), ("drive_mcap", "mcap")]
START_NS = 1_700_000_000 * 1_000_000_000


def _frames(path, dt_s=None):
    """The bag's drive on the grid as frames ``0 .. P`` (frame ``k`` closes period ``k``),
    stamped on the host's arrival line: (times [s], yaw rate [rad/s] or None, recording)."""
    rec = read_bag(path, dt_s=dt_s)
    grid = bag_grid(rec, wheel_base_m=0.235, wheel_radius_m=CREATE2_WHEEL_RADIUS_M)
    clock = grid.assignment.clock
    t = clock.times_s(np.arange(len(grid.closed))) + clock.latency_median_s
    yaw = (None if grid.yaw_rate_rad_s is None
           else np.concatenate([[np.nan], grid.yaw_rate_rad_s]))
    return t, yaw, rec


@pytest.fixture(scope="module")
def drive():
    """4 s of curves on carpet with a gyro, 5% of frames lost after 1 s."""
    return carpet_drive(21, rest_s=0.0, curves_s=4.0, wave_s=2.0, lost_from_s=1.0)


@pytest.mark.parametrize(("name", "storage"), FORMATS, ids=["ros1", "db3", "mcap"])
def test_the_gyro_is_written_as_imu_and_comes_back_on_the_frames(tmp_path, drive, name,
                                                                   storage):
    """Each received frame's reading is one Imu message stamped mid-period, its variance
    density^2 / dt, orientation and acceleration marked absent (-1); read back, the readings
    are exact, and the frames' yaw rates (resampled by the trapezoid rule) differ from the
    simulator's by the averaging of neighbouring readings only: mean under 1 mrad/s (the
    bias is 6 mrad/s), sd under the reading noise's 0.041 rad/s."""
    path = write_drive_bag(tmp_path / name, drive, storage=storage, start_ns=START_NS,
                           gyro_noise_density_rad_s_sqrt_hz=DENSITY)
    rec = read_topics(path)
    ok = drive.valid & np.isfinite(drive.yaw_rate_rad_s)
    assert rec.imu.topic == "/imu/data" and rec.imu.msgtype == "sensor_msgs/msg/Imu"
    np.testing.assert_array_equal(rec.imu.values[:, 0], drive.yaw_rate_rad_s[ok])
    expected_ns = START_NS + np.rint(drive.t_s[ok] * 1e9).astype(np.int64) - 7_500_000
    np.testing.assert_array_equal(rec.imu.t_ns, expected_ns)
    with AnyReader([path]) as reader:
        conn = next(c for c in reader.connections if c.topic == "/imu/data")
        msg = reader.deserialize(next(reader.messages([conn]))[2], conn.msgtype)
    assert msg.orientation_covariance[0] == -1 and msg.linear_acceleration_covariance[0] == -1
    np.testing.assert_allclose(msg.angular_velocity_covariance,
                               [UNESTIMATED_VARIANCE, 0, 0, 0, UNESTIMATED_VARIANCE, 0, 0, 0,
                                DENSITY**2 / drive.dt_s])
    _, yaw, rec = _frames(path, dt_s=drive.dt_s)
    assert rec.source.topics["yaw_rate"] == "/imu/data"
    assert rec.gyro_density_rad_s_sqrt_hz == pytest.approx(DENSITY, rel=0.01)
    assert len(yaw) == len(drive)
    got = np.isfinite(yaw)
    assert not got[0] and got[1:-1].all()          # period 0 starts before the first reading
    diff = yaw[got & ok] - drive.yaw_rate_rad_s[got & ok]
    assert abs(diff.mean()) < 1e-3 and diff.std() < 0.041, (diff.mean(), diff.std())


def test_without_a_gyro_no_imu_is_written(tmp_path):
    log = Simulator("create2", seed=1).run(np.full((40, 2), 0.1))
    path = write_drive_bag(tmp_path / "plain.bag", log)
    rec = read_topics(path)
    assert rec.imu is None and "/imu/data" not in rec.topics
    _, yaw, rec = _frames(path)
    assert yaw is None and rec.yaw_rate is None and not rec.source.has("yaw_rate")


def test_a_slower_imu_with_a_gap(tmp_path):
    """A 20 Hz Imu under 50 Hz wheels: a constant 0.3 rad/s comes back on every period
    inside its span; periods outside it, or over its 0.5 s gap (> max_gap_s 0.25 s), have
    none."""
    store = get_typestore(Stores.ROS1_NOETIC)
    wheels_ns = 10**9 + np.arange(100) * 20_000_000
    imu_ns = 10**9 + np.concatenate([np.arange(3, 20), np.arange(31, 38)]) * 50_000_000
    msgs = [("/joint_states", "sensor_msgs/msg/JointState", int(t),
             _joint_state(store, t, 0.01 * i)) for i, t in enumerate(wheels_ns)]
    msgs += [("/imu", "sensor_msgs/msg/Imu", int(t), _imu(store, t, 0.3)) for t in imu_ns]
    t, y, rec = _frames(_raw_bag(tmp_path / "slow.bag", msgs))
    assert rec.dt_s == pytest.approx(0.02)
    inside = np.isfinite(y)
    np.testing.assert_allclose(y[inside], 0.3, rtol=1e-9)
    t = t + rec.source.start_ns * 1e-9
    span = (t - 0.02 > imu_ns[0] * 1e-9) & (t < imu_ns[-1] * 1e-9)
    gap = (t > imu_ns[16] * 1e-9) & (t - 0.02 < imu_ns[17] * 1e-9)
    assert inside.sum() == (span & ~gap).sum() > 50
    assert not inside[~span].any() and not inside[gap].any()


def test_a_faster_imu_is_averaged_over_each_period(tmp_path):
    """A 200 Hz Imu of w(t) = 0.5 sin(pi t) under 50 Hz wheels: each frame's yaw rate is the
    mean of w over its 20 ms period, (0.5 / pi) (cos pi t0 - cos pi t1) / 0.02, within the
    trapezoid rule's error bound on 5 ms steps, h^2 / 12 max|w''| = 1.028e-5 rad/s (the
    periods' ends fall on Imu stamps: no interpolation error)."""
    store = get_typestore(Stores.ROS1_NOETIC)
    wheels_ns = 10**9 + np.arange(100) * 20_000_000
    imu_ns = 10**9 + np.arange(400) * 5_000_000
    msgs = [("/joint_states", "sensor_msgs/msg/JointState", int(t),
             _joint_state(store, t, 0.01 * i)) for i, t in enumerate(wheels_ns)]
    msgs += [("/imu", "sensor_msgs/msg/Imu", int(t),
              _imu(store, t, 0.5 * np.sin(np.pi * (t - 10**9) * 1e-9))) for t in imu_ns]
    t, yaw, rec = _frames(_raw_bag(tmp_path / "fast.bag", msgs))
    t1 = t + (rec.source.start_ns - 10**9) * 1e-9        # from the first stamp
    t0 = t1 - 0.02
    expected = 0.5 / np.pi * (np.cos(np.pi * t0) - np.cos(np.pi * t1)) / 0.02
    got = np.isfinite(yaw)
    assert got[1:].all() and not got[0]
    np.testing.assert_allclose(yaw[1:], expected[1:], atol=1.03e-5)


# -- bad input: the reader's one-line errors -----------------------------------------------
def _raw_bag(path, messages):
    """A ROS 1 bag written with rosbags alone: ``messages`` is [(topic, msgtype, t_ns, msg)]."""
    store = get_typestore(Stores.ROS1_NOETIC)
    with Writer1(path) as writer:
        conns = {}
        for topic, msgtype, t_ns, msg in messages:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], t_ns, store.serialize_ros1(msg, msgtype))
    return path


def _header(store, t_ns):
    t = store.types
    return t["std_msgs/msg/Header"](
        seq=0, stamp=t["builtin_interfaces/msg/Time"](sec=int(t_ns // 10**9),
                                                      nanosec=int(t_ns % 10**9)),
        frame_id="base_link")


def _joint_state(store, t_ns, angle):
    return store.types["sensor_msgs/msg/JointState"](
        header=_header(store, t_ns), name=["wheel_left_joint", "wheel_right_joint"],
        position=np.array([angle, angle]), velocity=np.zeros(0), effort=np.zeros(0))


def _imu(store, t_ns, yaw_rate):
    t = store.types
    absent = np.zeros(9)
    absent[0] = -1.0
    vec = t["geometry_msgs/msg/Vector3"]
    return t["sensor_msgs/msg/Imu"](
        header=_header(store, t_ns),
        orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=absent, angular_velocity=vec(x=0.0, y=0.0, z=float(yaw_rate)),
        angular_velocity_covariance=np.zeros(9), linear_acceleration=vec(x=0.0, y=0.0, z=0.0),
        linear_acceleration_covariance=absent.copy())


def _imu_bag(tmp_path, stamps_ns, rates):
    store = get_typestore(Stores.ROS1_NOETIC)
    msgs = [("/joint_states", "sensor_msgs/msg/JointState", 10**9 + i * 20_000_000,
             _joint_state(store, 10**9 + i * 20_000_000, 0.01 * i)) for i in range(10)]
    msgs += [("/imu", "sensor_msgs/msg/Imu", 10**9 + i * 20_000_000, _imu(store, int(s), r))
             for i, (s, r) in enumerate(zip(stamps_ns, rates, strict=True))]
    return _raw_bag(tmp_path / "imu.bag", msgs)


def test_an_imu_reading_that_is_nan(tmp_path):
    path = _imu_bag(tmp_path, 10**9 + np.arange(5) * 20_000_000, [0.1, 0.1, np.nan, 0.1, 0.1])
    with pytest.raises(BagError, match=r"^topic /imu: message 2 has a nan in its w \[rad/s\]$"):
        read_bag(path)


def test_imu_stamps_going_backwards(tmp_path):
    path = _imu_bag(tmp_path, 10**9 + np.array([0, 20, 40, 30, 60]) * 1_000_000, [0.1] * 5)
    with pytest.raises(BagError, match=r"^topic /imu: stamps go backwards at message 3 "
                                       r"\(0\.010000 s before the one ahead of it\)"):
        read_bag(path)


def test_an_imu_topic_of_the_wrong_type(tmp_path, drive):
    path = write_drive_bag(tmp_path / "d.bag", drive, gyro_noise_density_rad_s_sqrt_hz=DENSITY)
    with pytest.raises(BagError, match=r"^topic /odom holds nav_msgs/msg/Odometry, but "
                                       r"--imu-topic needs sensor_msgs/Imu$"):
        read_bag(path, imu_topic="/odom")


def test_a_negative_noise_density_is_refused(tmp_path, drive):
    with pytest.raises(ValueError, match="gyro_noise_density_rad_s_sqrt_hz must be >= 0"):
        write_drive_bag(tmp_path / "n.bag", drive, gyro_noise_density_rad_s_sqrt_hz=-1.0)
    assert not list(tmp_path.iterdir())
