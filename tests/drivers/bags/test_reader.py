"""ROS bags in and out (drivers.bags.reader, drivers.bags.topics, drivers.bags.writer).

Every bag here is written in a tmp_path with rosbags from a short simulator
drive (or from the MRCLAM files), in the three formats: ROS 1 ``.bag``, ROS 2
SQLite 3 (``.db3``) and ROS 2 MCAP.
"""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from drivers.bags.fields import decode_fields
from drivers.bags.reader import CREATE2_TICKS_PER_RAD, CREATE2_WHEEL_RADIUS_M, bag_grid, read_bag
from drivers.bags.topics import bag_topics, read_topics
from drivers.bags.writer import BagAlarm, write_drive_bag, write_estimates_bag
from drivers.exceptions import BagError
from drivers.sim.config import Fault
from drivers.sim.simulator import Simulator
from lti_motion.kinematics import body_from_wheel
from lti_motion.model.excitation import random_held_normal
from lti_motion.recordings.clocks import snap_period_s
from lti_motion.recordings.ticks import tick_deltas

FORMATS = [("drive.bag", "mcap"), ("drive_db3", "sqlite3"), ("drive_mcap", "mcap")]
START_NS = 1_700_000_000 * 1_000_000_000


@pytest.fixture(scope="module")
def drive():
    """4 s of random wheel commands on the create2 simulator, 10% of frames lost."""
    rng = np.random.default_rng(7)
    cmd = random_held_normal(n=270, dt_s=0.015, rng=rng, std_m_s=0.2, mean_m_s=0.1,
                             hold_s=(0.3, 0.8), correlation=0.5)
    sim = Simulator("create2", seed=3,
                    faults=[Fault("lost_frames", t_s=0.5, probability=0.1)])
    return sim.run(cmd)


@pytest.fixture(params=FORMATS, ids=["ros1", "db3", "mcap"])
def bag(request, tmp_path, drive):
    name, storage = request.param
    return write_drive_bag(tmp_path / name, drive, storage=storage, start_ns=START_NS)


def _speeds_of(drive, periods):
    """The body speeds of a drive's counts over the periods between its valid frames
    (the closing frame's counts span a gap), each period of a gap the gap's mean."""
    ok = np.flatnonzero(drive.valid)
    d = tick_deltas(drive.ticks[ok], axis=0) / CREATE2_TICKS_PER_RAD * CREATE2_WHEEL_RADIUS_M
    span = np.diff(ok)
    wheel = np.repeat(d / (span[:, None] * periods), span, axis=0)
    return body_from_wheel(wheel, wheel_base_m=0.235)


def test_the_drive_comes_back_frame_for_frame(bag, drive):
    found = read_topics(bag)
    assert {k: getattr(found, k).topic for k in ("cmd", "wheels", "odom", "truth")} == {
        "cmd": "/cmd_vel", "wheels": "/joint_states", "odom": "/odom", "truth": "/ground_truth"}
    assert found.imu is None and found.joints == ("wheel_left_joint", "wheel_right_joint")
    rec = read_bag(bag)
    assert rec.wheel_kind == "wheel_angles_rad" and rec.cmd_kind == "cmd_body"
    assert dict(rec.source.topics) == {"wheel": "/joint_states", "cmd": "/cmd_vel",
                                       "true_pose": "/ground_truth"}
    assert rec.source.wheel_names == ("wheel_left_joint", "wheel_right_joint")
    assert rec.yaw_rate is None and len(rec) == int(np.count_nonzero(drive.valid))
    # the angles as written, never quantised: the counts over ticks per radian
    ok = drive.valid
    np.testing.assert_allclose(rec.wheel.values * CREATE2_TICKS_PER_RAD,
                               np.unwrap(drive.ticks[ok].astype(float), period=65536, axis=0),
                               atol=1e-6)
    grid = bag_grid(rec, wheel_base_m=0.235, wheel_radius_m=CREATE2_WHEEL_RADIUS_M)
    assert grid.period_s == pytest.approx(0.015, rel=1e-3)
    assert len(grid.closed) == len(drive)                      # the last frame is valid
    np.testing.assert_array_equal(grid.closed, drive.valid)
    assert np.count_nonzero(~grid.closed) == int(np.count_nonzero(~drive.valid)) > 5
    # every period's speeds: the counts' travel over the periods between valid frames
    np.testing.assert_allclose(grid.speeds, _speeds_of(drive, grid.period_s), atol=1e-9)
    np.testing.assert_allclose(grid.cmd_m_s, drive.cmd_m_s[1:], atol=1e-12)
    np.testing.assert_allclose(grid.true_pose[ok[1:]], drive.true_pose[1:][ok[1:]], atol=1e-9)
    # period 0 on the bag's clock: the grid's phase from all stamps, within their 1 ms jitter
    clock = grid.assignment.clock
    first_ns = rec.source.start_ns + (clock.times_s(0) + clock.latency_median_s) * 1e9
    assert abs(first_ns - (START_NS + drive.t_s[0] * 1e9)) < 3e6


def test_vectorised_and_per_message_decoding_agree(bag):
    with AnyReader([bag]) as reader:
        conn = next(c for c in reader.connections if c.topic == "/odom")
        raws = [raw for _, _, raw in reader.messages(connections=[conn])]
        store, msgtype = reader.typestore, conn.msgtype
        if reader.is2:
            de, ser = (lambda b: store.deserialize_cdr(b, msgtype),
                       lambda m: store.serialize_cdr(m, msgtype))
        else:
            de, ser = (lambda b: store.deserialize_ros1(b, msgtype),
                       lambda m: store.serialize_ros1(m, msgtype))
    paths = ("header.stamp.sec", "header.stamp.nanosec", "pose.pose.position.x",
             "pose.pose.orientation.z")
    fast = decode_fields(raws, paths, deserialize=de, serialize=ser)
    slow = decode_fields(raws, paths, deserialize=de, serialize=ser, vectorise=False)
    np.testing.assert_array_equal(fast, slow)
    assert np.ptp(fast[:, 2]) > 0.1                             # it moved


def test_estimates_and_alarms_round_trip(tmp_path, rng):
    n = 40
    t_ns = START_NS + np.arange(n) * 15_000_000
    poses = np.column_stack([np.linspace(0, 1, n), rng.normal(size=n) * 0.01,
                             np.linspace(0, 3.5, n)])
    a = rng.normal(size=(n, 3, 3)) * 0.01
    covs = a @ a.transpose(0, 2, 1)
    alarm = BagAlarm(int(t_ns[10]) + 1, "lti_motion/stuck_encoder", "left wheel stuck",
                     (("statistic", "12.5"), ("threshold", "8.0")))
    for name in ("est.bag", "est_mcap"):
        path = write_estimates_bag(tmp_path / name, t_ns, poses, covs, alarms=[alarm])
        with AnyReader([path]) as reader:
            odom, diag = [], []
            for conn, stamp, raw in reader.messages():
                msg = reader.deserialize(raw, conn.msgtype)
                (odom if conn.topic == "/lti_motion/odom" else diag).append((stamp, msg))
        assert len(odom) == n and len(diag) == 1
        cov6 = odom[7][1].pose.covariance.reshape(6, 6)
        np.testing.assert_allclose(cov6[np.ix_([0, 1, 5], [0, 1, 5])], covs[7], atol=1e-15)
        assert cov6[2, 2] == cov6[3, 3] == 1e6
        yaw = 2 * np.arctan2(odom[7][1].pose.pose.orientation.z,
                             odom[7][1].pose.pose.orientation.w)
        assert yaw == pytest.approx(poses[7, 2])
        stamp, msg = diag[0]
        assert stamp == alarm.t_ns and msg.status[0].name == "lti_motion/stuck_encoder"
        assert [(v.key, v.value) for v in msg.status[0].values] == list(alarm.values)
        # the estimates read back as a bag: the Odometry topic found by type
        assert read_topics(path).odom.values[7, 2] == pytest.approx(poses[7, 2])
        assert read_bag(path).wheel_kind == "body_speeds"      # its twist: no wheel angles


def test_nothing_is_overwritten_or_half_written(tmp_path, drive):
    path = write_drive_bag(tmp_path / "a.bag", drive)
    before = path.read_bytes()
    with pytest.raises(FileExistsError, match="never overwrites"):
        write_drive_bag(path, drive)
    assert path.read_bytes() == before
    bad = np.zeros((3, 3, 3))
    bad[1, 0, 0] = np.nan
    with pytest.raises(BagError, match="NaN"):
        write_estimates_bag(tmp_path / "est", np.arange(3), np.zeros((3, 3)), bad)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bag"]


# -- reference poses from tf -------------------------------------------------------------------
@pytest.mark.parametrize(("name", "storage"), FORMATS, ids=["ros1", "db3", "mcap"])
def test_reference_poses_from_tf_equal_the_truth_written(tmp_path, drive, name, storage):
    path = write_drive_bag(tmp_path / name, drive, storage=storage, start_ns=START_NS,
                           truth="tf")
    assert "/ground_truth" not in bag_topics(path)
    found = read_topics(path)             # no PoseStamped topic: tf, with its default frames
    assert found.truth.topic == "/tf" and found.truth_frames == ("world", "base_link")
    ok = drive.valid
    np.testing.assert_array_equal(found.truth.t_ns, START_NS + np.rint(drive.t_s[ok] * 1e9))
    np.testing.assert_allclose(found.truth.values, drive.true_pose[ok], atol=1e-9)
    rec = read_bag(path)
    assert rec.source.topics["true_pose"] == "/tf"
    assert rec.source.truth_frames == ("world", "base_link")
    np.testing.assert_allclose(rec.true_pose.values, drive.true_pose[ok], atol=1e-9)
    grid = bag_grid(rec, wheel_base_m=0.235, wheel_radius_m=CREATE2_WHEEL_RADIUS_M)
    np.testing.assert_allclose(grid.true_pose[ok[1:]], drive.true_pose[1:][ok[1:]], atol=1e-9)


def _transform(t, t_ns, parent, child, x, yaw):
    stamp = t["builtin_interfaces/msg/Time"](sec=int(t_ns // 10**9), nanosec=int(t_ns % 10**9))
    return t["geometry_msgs/msg/TransformStamped"](
        header=t["std_msgs/msg/Header"](stamp=stamp, frame_id=parent), child_frame_id=child,
        transform=t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=x, y=0.0, z=0.0),
            rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=np.sin(yaw / 2),
                                                       w=np.cos(yaw / 2))))


def test_tf_frames_by_default_or_named_and_a_missing_pair(tmp_path):
    """/tf holds odom -> base_link (x = i) and /world -> base_link (x = 10 i); a
    PoseStamped topic is there too."""
    t = get_typestore(Stores.ROS2_HUMBLE).types
    msgs = []
    for i in range(5):
        t_ns = 10**9 + i * 20_000_000
        msgs.append(("/tf", "tf2_msgs/msg/TFMessage", t_ns, t["tf2_msgs/msg/TFMessage"](
            transforms=[_transform(t, t_ns, "odom", "base_link", float(i), 0.1 * i),
                        _transform(t, t_ns, "/world", "base_link", 10.0 * i, -0.1 * i)])))
        tf = _transform(t, t_ns, "w", "", 0.0, 0.0)
        msgs.append(("/mocap", "geometry_msgs/msg/PoseStamped", t_ns, t[
            "geometry_msgs/msg/PoseStamped"](header=tf.header, pose=t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                orientation=tf.transform.rotation))))
    path, _ = _raw_bag(tmp_path / "tf", msgs, ros1=False)
    assert read_topics(path).truth.topic == "/mocap"              # PoseStamped first
    rec = read_topics(path, truth_child="base_link")              # named: tf, world preferred
    assert rec.truth_frames == ("world", "base_link")
    np.testing.assert_allclose(rec.truth.values, np.column_stack(
        [10.0 * np.arange(5), np.zeros(5), -0.1 * np.arange(5)]), atol=1e-12)
    odom = read_topics(path, truth_parent="odom").truth.values
    np.testing.assert_allclose(odom[:, [0, 2]], np.column_stack([np.arange(5), 0.1 * np.arange(5)]),
                               atol=1e-12)
    with pytest.raises(BagError, match=r"no transform map -> base_footprint \(no frame map "
                                       r"nor base_footprint in it\); it has "
                                       r"odom -> base_link, world -> base_link \(choose"):
        read_topics(path, truth_parent="map", truth_child="base_footprint")
    with pytest.raises(BagError, match=r"--truth-topic .* not both"):
        read_topics(path, truth_topic="/mocap", truth_parent="odom")


@pytest.mark.parametrize(("name", "storage"), FORMATS, ids=["ros1", "db3", "mcap"])
def test_a_tf_chain_is_composed_into_the_truth_written(tmp_path, drive, name, storage):
    """map -> odom (every 10th frame, interpolated between), odom -> base_footprint (per
    frame), base_footprint -> base_link (static, 5 cm up): composed, the simulator's poses."""
    path = write_drive_bag(tmp_path / name, drive, storage=storage, start_ns=START_NS,
                           truth="tf_chain")
    rec = read_topics(path)               # defaults: world absent, map -> base_link chained
    assert rec.truth_frames == ("map", "base_link")
    assert rec.truth.topic == "/tf, /tf_static"
    ok = drive.valid
    np.testing.assert_array_equal(rec.truth.t_ns, START_NS + np.rint(drive.t_s[ok] * 1e9))
    np.testing.assert_allclose(rec.truth.values, drive.true_pose[ok], atol=1e-9)
    # the chain walked up: base_link in base_footprint's parent, odom, at the start
    # (where map and odom coincide) is the truth; later it is off by the drift
    odom = read_topics(path, truth_parent="odom").truth
    assert read_topics(path, truth_parent="odom").truth_frames == ("odom", "base_link")
    np.testing.assert_allclose(odom.values[0], drive.true_pose[ok][0], atol=1e-9)
    assert np.max(np.abs(odom.values[:, 2] - drive.true_pose[ok][:, 2])) > 0.03
    # and down: map in base_link, the inverse of the truth
    inv = read_topics(path, truth_parent="base_link", truth_child="map").truth.values
    x, y, th = drive.true_pose[ok].T
    np.testing.assert_allclose(inv[:, 0], -(np.cos(th) * x + np.sin(th) * y), atol=1e-9)
    np.testing.assert_allclose(np.cos(inv[:, 2] + th), 1.0, atol=1e-9)


def test_a_static_mount_composes_and_a_missing_link_is_named(tmp_path, drive):
    path = write_drive_bag(tmp_path / "mount.bag", drive, truth="tf")
    laser = read_bag(path, truth_parent="world", truth_child="base_laser").true_pose.values
    x, y, th = drive.true_pose[drive.valid].T        # the laser 0.1 m ahead of base_link
    np.testing.assert_allclose(laser, np.column_stack(
        [x + 0.1 * np.cos(th), y + 0.1 * np.sin(th), th]), atol=1e-9)
    t = get_typestore(Stores.ROS2_HUMBLE).types
    msgs = [("/tf", "tf2_msgs/msg/TFMessage", 10**9 + i * 20_000_000, t[
        "tf2_msgs/msg/TFMessage"](transforms=[
            _transform(t, 10**9 + i * 20_000_000, "odom", "base_link", 0.1 * i, 0.0),
            _transform(t, 10**9 + i * 20_000_000, "map", "marker", 1.0, 0.0)]))
        for i in range(5)]
    two, _ = _raw_bag(tmp_path / "two_trees", msgs, ros1=False)
    with pytest.raises(BagError, match=r"no transform map -> base_link \(no chain: map's "
                                       r"transforms lead up to map, base_link's to odom; the "
                                       r"link map -> odom is missing\); it has map -> marker, "
                                       r"odom -> base_link"):
        read_bag(two, truth_parent="map", truth_child="base_link")


def test_tf_named_in_a_bag_without_tf(bag):
    with pytest.raises(BagError, match=r"the bag has no tf2_msgs/TFMessage topic; it has "
                                       r"/cmd_vel"):
        read_bag(bag, truth_child="base_link")


# -- bad input -----------------------------------------------------------------------------
def _raw_bag(path, messages, *, ros1=True):
    """A bag written with rosbags alone: ``messages`` is [(topic, msgtype, t_ns, msg)]."""
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    writer = Writer1(path) if ros1 else Writer2(path, version=9,
                                                storage_plugin=StoragePlugin.MCAP)
    with writer:
        conns = {}
        for topic, msgtype, t_ns, msg in messages:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            if msg is not None:
                data = (store.serialize_ros1(msg, msgtype) if ros1
                        else store.serialize_cdr(msg, msgtype))
                writer.write(conns[topic], t_ns, data)
    return path, store


def _joint_state(store, t_ns, left, right, names=("wheel_left_joint", "wheel_right_joint")):
    t = store.types
    header = t["std_msgs/msg/Header"](
        seq=0, stamp=t["builtin_interfaces/msg/Time"](sec=int(t_ns // 10**9),
                                                      nanosec=int(t_ns % 10**9)),
        frame_id="")
    return t["sensor_msgs/msg/JointState"](header=header, name=list(names),
                                           position=np.array([left, right], float),
                                           velocity=np.zeros(0), effort=np.zeros(0))


def _joints_bag(tmp_path, stamps_ns, angles, **kw):
    """JointState messages received every 20 ms, with the header stamps given."""
    store = get_typestore(Stores.ROS1_NOETIC)
    msgs = [("/joint_states", "sensor_msgs/msg/JointState", 10**9 + i * 20_000_000,
             _joint_state(store, int(s), *a, **kw))
            for i, (s, a) in enumerate(zip(stamps_ns, angles, strict=True))]
    return _raw_bag(tmp_path / "j.bag", msgs)[0]


def test_a_bag_without_wheels_names_what_it_has(tmp_path):
    """Odometry alone stands in for the wheels (its twist); without it too, the error
    names what is missing and lists what the bag has."""
    path = write_estimates_bag(tmp_path / "est.bag", np.arange(3), np.zeros((3, 3)),
                               np.zeros((3, 3, 3)))
    rec = read_bag(path)
    assert rec.wheel_kind == "body_speeds" and rec.rates == "since_last"
    assert dict(rec.source.topics) == {"wheel": "/lti_motion/odom"}     # no commands
    store = get_typestore(Stores.ROS1_NOETIC)
    t = store.types
    twist = t["geometry_msgs/msg/Twist"](linear=t["geometry_msgs/msg/Vector3"](x=0.1, y=0.0,
                                                                            z=0.0),
                                         angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0,
                                                                             z=0.0))
    cmd_only, _ = _raw_bag(tmp_path / "cmd.bag", [("/cmd_vel", "geometry_msgs/msg/Twist",
                                                   10**9 + i * 10**8, twist) for i in range(3)])
    with pytest.raises(BagError, match=r"^cmd.bag has no sensor_msgs/JointState wheel angles "
                                       r"\(nor a nav_msgs/Odometry twist\); it has /cmd_vel "
                                       r"\(geometry_msgs/msg/Twist\)$"):
        read_bag(cmd_only)


def test_a_topic_of_the_wrong_type_or_missing(bag):
    with pytest.raises(BagError, match=r"topic /odom holds nav_msgs/msg/Odometry, but "
                                       r"--cmd-topic needs geometry_msgs/Twist"):
        read_bag(bag, cmd_topic="/odom")
    with pytest.raises(BagError, match=r"no topic /wheels; it has /cmd_vel \(geometry"):
        read_bag(bag, wheels_topic="/wheels")


def test_several_topics_of_a_kind_need_a_choice(tmp_path):
    store = get_typestore(Stores.ROS1_NOETIC)
    msgs = [(topic, "sensor_msgs/msg/JointState", 10**9 + i, _joint_state(store, 10**9 + i,
                                                                        0.0, 0.0))
            for i, topic in enumerate(["/a/joint_states", "/b/joint_states"])]
    path, _ = _raw_bag(tmp_path / "two.bag", msgs)
    with pytest.raises(BagError, match=r"2 sensor_msgs/JointState topics \(/a/joint_states, "
                                       r"/b/joint_states\); choose one with --wheels-topic"):
        read_bag(path)
    assert read_topics(path, wheels_topic="/b/joint_states").wheels.topic == "/b/joint_states"
    with pytest.raises(BagError, match=r"^topic /b/joint_states has 1 message; a drive needs "
                                       r"at least 2$"):
        read_bag(path, wheels_topic="/b/joint_states")


def test_an_empty_topic(tmp_path):
    path, _ = _raw_bag(tmp_path / "e.bag", [("/joint_states", "sensor_msgs/msg/JointState",
                                             0, None)])
    assert bag_topics(path) == {"/joint_states": "sensor_msgs/msg/JointState"}
    with pytest.raises(BagError, match="topic /joint_states is empty"):
        read_bag(path, wheels_topic="/joint_states")


def test_stamps_going_backwards(tmp_path):
    stamps = 10**9 + np.array([0, 20, 40, 30, 60]) * 1_000_000
    path = _joints_bag(tmp_path, stamps, np.zeros((5, 2)))
    with pytest.raises(BagError, match=r"topic /joint_states: stamps go backwards at message 3"):
        read_bag(path)


def test_a_wheel_at_100_m_s(tmp_path):
    stamps = 10**9 + np.arange(5) * 20_000_000
    angles = np.zeros((5, 2))
    angles[3:, 1] = 100.0 * 0.02 / 0.036                     # 100 m/s for one period
    path = _joints_bag(tmp_path, stamps, angles)
    with pytest.raises(BagError, match=r"^topic /joint_states: the wheel_right_joint wheel "
                                       r"moves at 100 m/s at message 3 \(t = 0.060 s\), "
                                       r"more than 20 m/s \(--max-wheel-speed\)"):
        bag_grid(read_bag(path), wheel_base_m=0.235, wheel_radius_m=CREATE2_WHEEL_RADIUS_M)
    # a command as impossible: the topic, the wheel and the message
    store = get_typestore(Stores.ROS1_NOETIC)
    t = store.types
    msgs = [("/joint_states", "sensor_msgs/msg/JointState", int(s),
             _joint_state(store, int(s), 0.0, 0.0)) for s in stamps]
    msgs.insert(2, ("/cmd_vel", "geometry_msgs/msg/Twist", int(stamps[1]) + 1,
                    t["geometry_msgs/msg/Twist"](
                        linear=t["geometry_msgs/msg/Vector3"](x=30.0, y=0.0, z=0.0),
                        angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0))))
    fast, _ = _raw_bag(tmp_path / "fast_cmd.bag", msgs)
    with pytest.raises(BagError, match=r"^topic /cmd_vel: the left wheel command moves at "
                                       r"30 m/s at message 1 \(t = \S+ s\), more than 20 m/s"):
        bag_grid(read_bag(fast), wheel_base_m=0.235, wheel_radius_m=CREATE2_WHEEL_RADIUS_M)


def test_joints_found_by_name_or_named(tmp_path):
    stamps = 10**9 + np.arange(4) * 20_000_000
    angles = np.column_stack([np.arange(4) * 0.1, np.arange(4) * 0.2])
    path = _joints_bag(tmp_path, stamps, angles, names=("right_wheel", "left_wheel"))
    rec = read_bag(path)
    np.testing.assert_array_equal(rec.wheel.values, angles[:, ::-1])      # swapped by name
    assert rec.source.wheel_names == ("left_wheel", "right_wheel")
    other = _joints_bag(tmp_path / "..", stamps, angles, names=("j1", "j2"))
    with pytest.raises(BagError, match=r"0 joints match the left wheel pattern 'left' among "
                                       r"\['j1', 'j2'\]; name the left joint with --left-joint"):
        read_bag(other)
    assert read_bag(other, left_joint="j2", right_joint="j1").source.wheel_names == ("j2", "j1")


def test_not_a_bag(tmp_path):
    (tmp_path / "x.txt").write_text("hello")
    with pytest.raises(BagError, match="is not a bag"):
        read_bag(tmp_path / "x.txt")
    (tmp_path / "y.bag").write_bytes(b"#ROSBAG V2.0\nbroken")
    with pytest.raises(BagError, match="cannot read"):
        read_bag(tmp_path / "y.bag")
    with pytest.raises(FileNotFoundError, match="no such bag"):
        read_bag(tmp_path / "none.bag")


# -- a bag made from the MRCLAM data ---------------------------------------------------------
def test_a_bag_from_mrclam(tmp_path, mrclam_path):
    from drivers.datasets import load_mrclam

    robot = load_mrclam(mrclam_path).robots[1]
    cmd, gt = robot.commands[:3000], robot.groundtruth[:3000]
    store = get_typestore(Stores.ROS2_HUMBLE)
    t = store.types

    def stamp(s):
        ns = round(s * 1e9)
        return t["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)

    msgs = [("/cmd_vel", "geometry_msgs/msg/Twist", round(s * 1e9), t["geometry_msgs/msg/Twist"](
        linear=t["geometry_msgs/msg/Vector3"](x=v, y=0.0, z=0.0),
        angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=w))) for s, v, w in cmd]
    msgs += [("/vicon/pose", "geometry_msgs/msg/PoseStamped", round(s * 1e9),
              t["geometry_msgs/msg/PoseStamped"](
                  header=t["std_msgs/msg/Header"](stamp=stamp(s), frame_id="world"),
                  pose=t["geometry_msgs/msg/Pose"](
                      position=t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                      orientation=t["geometry_msgs/msg/Quaternion"](
                          x=0.0, y=0.0, z=np.sin(th / 2), w=np.cos(th / 2)))))
             for s, x, y, th in gt]
    msgs.sort(key=lambda m: m[2])
    path, _ = _raw_bag(tmp_path / "mrclam", msgs, ros1=False)
    rec = read_topics(path)
    assert rec.wheels is None and rec.truth.topic == "/vicon/pose"
    np.testing.assert_allclose(rec.cmd.values, cmd[:, 1:])
    np.testing.assert_allclose(rec.cmd.t_ns, np.round(cmd[:, 0] * 1e9))
    np.testing.assert_allclose(rec.truth.values[:, :2], gt[:, 1:3], atol=1e-12)
    np.testing.assert_allclose(rec.truth.values[:, 2], np.unwrap(gt[:, 3]), atol=1e-9)
    with pytest.raises(BagError, match="no sensor_msgs/JointState wheel angles"):
        read_bag(path)


def test_4_ms_of_host_jitter_at_50_hz(tmp_path):
    """Stamps jittered by 4 ms (standard deviation) on a 20 ms period: some messages land
    nearer a neighbour's period; each frame still finds its own period."""
    import dataclasses

    from drivers.sim.config import PRESETS

    params = dataclasses.replace(PRESETS["create2"], period_s=0.02, latency_jitter_s=0.004)
    cmd = np.full((1500, 2), 0.15)
    drive = Simulator(params, seed=5, faults=[Fault("lost_frames", t_s=0.1,
                                                    probability=0.02)]).run(cmd)
    t = drive.t_s[drive.valid]
    assert np.any(np.diff(np.rint((t - t[0]) / 0.02)) < 1)       # two nearest the same period
    grid = bag_grid(read_bag(write_drive_bag(tmp_path / "j.bag", drive)), wheel_base_m=0.235,
                    wheel_radius_m=CREATE2_WHEEL_RADIUS_M)
    assert snap_period_s(grid.period_s) == 0.02 and len(grid.closed) == len(drive)
    np.testing.assert_array_equal(grid.closed, drive.valid)
    np.testing.assert_allclose(grid.speeds, _speeds_of(drive, grid.period_s), atol=1e-9)


def test_a_message_jittered_onto_a_lost_neighbours_period_goes_back(tmp_path):
    """Message 6 of a steady drive is 12 ms early and message 5 never came: the stamp alone
    puts message 6 on period 5; the even wheel travel puts it back on period 6."""
    periods = np.delete(np.arange(200), 5)
    stamps = 10**9 + periods * 20_000_000
    stamps[5] -= 12_000_000                                    # period 6, stamped early
    angles = np.column_stack([periods * 0.05, periods * 0.06])   # steady: 2.5, 3 rad/s
    grid = bag_grid(read_bag(_joints_bag(tmp_path, stamps, angles)), wheel_base_m=0.235,
                    wheel_radius_m=CREATE2_WHEEL_RADIUS_M)
    assert len(grid.closed) == 200 and snap_period_s(grid.period_s) == 0.02
    np.testing.assert_array_equal(np.flatnonzero(~grid.closed), [5])
    np.testing.assert_array_equal(grid.assignment.period, periods)
    # steady: every period's wheel travel the same, the gap's two periods included
    wheel = np.column_stack([grid.speeds[:, 0] - grid.speeds[:, 1] * 0.235 / 2,
                             grid.speeds[:, 0] + grid.speeds[:, 1] * 0.235 / 2])
    np.testing.assert_allclose(wheel * grid.period_s, np.tile(
        [0.05 * CREATE2_WHEEL_RADIUS_M, 0.06 * CREATE2_WHEEL_RADIUS_M], (199, 1)), rtol=1e-6)
