"""The robot travels with its model: ``calibrate --bag`` assumes no geometry, writes the robot
into the model, and ``replay --bag`` reads the bag with it, refusing another robot's bag in
one line (issue 29, items 1, 2 and 4)."""

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

from drivers.bags.writer import write_drive_bag
from drivers.sim.simulator import Simulator
from lti_motion.app.cli import main
from lti_motion.model import MotionModel
from lti_motion.model.excitation import random_held_normal
from tests.conftest import data_dir

URDF = """<robot name="{name}">
  <link name="base_footprint"/>
  <link name="wl"><collision><geometry><cylinder radius="{r}" length="0.02"/></geometry>
  </collision></link>
  <link name="wr"><collision><geometry><cylinder radius="{r}" length="0.02"/></geometry>
  </collision></link>
  <joint name="wheel_left_joint" type="continuous"><parent link="base_footprint"/>
    <child link="wl"/><origin xyz="0 {half} 0.03"/></joint>
  <joint name="wheel_right_joint" type="continuous"><parent link="base_footprint"/>
    <child link="wr"/><origin xyz="0 -{half} 0.03"/></joint>
</robot>"""


def _one_line_exit_2(argv, capsys, *needles):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    for needle in needles:
        assert needle in err, err
    return err


def _with_urdf(src: Path, out: Path, urdf: str) -> Path:
    """A copy of the ROS 1 bag ``src`` with the URDF latched on /robot_description."""
    store = get_typestore(Stores.ROS1_NOETIC)
    with AnyReader([src]) as reader, Writer(out) as writer:
        conns = {c.topic: writer.add_connection(c.topic, c.msgtype, typestore=reader.typestore)
                 for c in reader.connections}
        desc = writer.add_connection("/robot_description", "std_msgs/msg/String",
                                     typestore=store)
        first = True
        for c, t, raw in reader.messages():
            if first:
                msg = store.types["std_msgs/msg/String"](data=urdf)
                writer.write(desc, t, store.serialize_ros1(msg, "std_msgs/msg/String"))
                first = False
            writer.write(conns[c.topic], t, raw)
    return out


@pytest.fixture(scope="module")
def sim_bag(tmp_path_factory):
    """A 45 s excitation of the simulated Create 2, as a ROS 1 bag (wheel angles, /cmd_vel,
    the true pose on /ground_truth)."""
    cmd = random_held_normal(n=3000, dt_s=0.015, rng=np.random.default_rng(3), std_m_s=0.2,
                             mean_m_s=0.05, hold_s=(0.5, 2.0), correlation=0.85)
    log = Simulator("create2", seed=31).run(cmd)
    return write_drive_bag(tmp_path_factory.mktemp("robot") / "drive.bag", log)


def test_calibrate_bag_without_geometry_is_one_line_saying_what_to_give(sim_bag, tmp_path,
                                                                         capsys):
    _one_line_exit_2(["calibrate", "--accept-unhealthy", "--bag", str(sim_bag),
                      "--out", str(tmp_path)], capsys,
                     "nothing gives the robot's wheel base and wheel radius",
                     "--wheel-base M and --wheel-radius M", "--robot FILE",
                     "/robot_description")
    assert not (tmp_path / "model_arx.json").exists()


def test_the_model_carries_the_robot_and_replay_reads_the_bag_with_it(sim_bag, tmp_path,
                                                                      capsys):
    out = tmp_path / "cal"
    assert main(["calibrate", "--accept-unhealthy", "--bag", str(sim_bag),
                 "--robot", "create2", "--out",
                 str(out)]) == 0
    said = capsys.readouterr().out
    assert "wheel radius 0.036 m from the preset create2 (--robot)" in said
    assert "encoders commanded from the preset create2 (--robot)" in said
    model = MotionModel.load(out / "model_arx.json")
    robot = model.robot
    assert (robot.robot, robot.wheel_data, robot.encoders) == ("create2", "wheel_angles_rad",
                                                               "commanded")
    assert robot.wheel_radius_m == (0.036, 0.036) and robot.wheel_base_m == 0.235
    assert robot.ticks_per_rad == pytest.approx(508.8 / (2 * math.pi))
    assert robot.dt_s == model.dt_s == 0.015
    assert robot.sources["wheel_radius_m"] == "the preset create2 (--robot)"
    # replay without any flag: the model's robot; the same as the flags would give
    metrics = {}
    for name, extra in (("model", []), ("flags", ["--wheel-radius", "0.036",
                                                   "--ticks-per-rad", str(508.8 / 2 / math.pi)])):
        assert main(["replay", "--bag", str(sim_bag), "--model", str(out / "model_arx.json"),
                     "--estimators", "odometry", "--out", str(tmp_path / name), *extra]) == 0
        metrics[name] = json.loads((tmp_path / name / "metrics.json").read_text())["metrics"]
    said = capsys.readouterr().out
    assert "robot: create2: wheel angles" in said and "(the model's)" in said
    assert "wheel radius 0.036 from --wheel-radius, over the model's robot's 0.036" in said
    assert metrics["model"]["odometry"]["ate_rmse_m"] == pytest.approx(
        metrics["flags"]["odometry"]["ate_rmse_m"], rel=1e-9)
    # a robot file with only what a real robot has overrides the model's counts per radian
    # (the model's encoder scale turns counts into metres), and says so
    real = tmp_path / "real.toml"
    real.write_text('name = "fine"\nperiod_s = 0.015\n[geometry]\nwheel_base_m = 0.235\n'
                    'wheel_diameter_m = 0.072\n[encoders]\nticks_per_rev = 559.68\n'
                    'kind = "commanded"\n')
    assert main(["replay", "--bag", str(sim_bag), "--model", str(out / "model_arx.json"),
                 "--estimators", "odometry", "--robot", str(real),
                 "--out", str(tmp_path / "file")]) == 0
    said = capsys.readouterr().out
    assert (f"counts per radian 89.0758 from the robot file {real}, over the model's robot's "
            "80.978") in said
    path = json.loads((tmp_path / "file" / "metrics.json").read_text())["metrics"]
    assert path["odometry"]["path_m"] == pytest.approx(
        metrics["model"]["odometry"]["path_m"] * 1.1, rel=1e-3)


def test_the_bags_urdf_gives_the_geometry_and_refuses_another_robots_model(sim_bag, tmp_path,
                                                                          capsys):
    ros1 = write_drive_bag(tmp_path / "drive.bag", Simulator("create2", seed=32).run(
        random_held_normal(n=3000, dt_s=0.015, rng=np.random.default_rng(4), std_m_s=0.2,
                           mean_m_s=0.05, hold_s=(0.5, 2.0), correlation=0.85)))
    urdf_bag = _with_urdf(Path(ros1), tmp_path / "with_urdf.bag",
                          URDF.format(name="create", r=0.036, half=0.1175))
    out = tmp_path / "cal"
    assert main(["calibrate", "--accept-unhealthy", "--bag", str(urdf_bag),
                 "--encoders", "commanded",
                 "--out", str(out)]) == 0
    said = capsys.readouterr().out
    src = "the bag's /robot_description (joints wheel_left_joint, wheel_right_joint)"
    assert f"wheel base 0.235 m from {src}" in said
    assert f"wheel radius 0.036 m from {src}" in said
    assert "counts per radian 10000: the angles' own resolution" in said
    model = out / "model_arx.json"
    assert MotionModel.load(model).robot.sources["wheel_base_m"] == src
    # the same drive, its URDF another robot's (a TurtleBot3 Waffle's): refused, both named
    waffle = _with_urdf(Path(ros1), tmp_path / "waffle.bag",
                        URDF.format(name="waffle", r=0.033, half=0.1435))
    _one_line_exit_2(["replay", "--bag", str(waffle), "--model", str(model),
                      "--out", str(tmp_path / "r")], capsys,
                     "waffle.bag's /robot_description has a wheel base of 0.287 m, the model's "
                     "robot (with_urdf.bag) 0.235 m (more than 2% apart)")


def test_a_bag_at_another_period_than_the_model_is_refused(sim_bag, tmp_path, capsys):
    """A model of a robot at 33 ms (calibrate refuses to fit at a --dt so far from the bag's
    own period, so the model is this bag's with the other robot's period)."""
    import dataclasses

    out = tmp_path / "cal"
    assert main(["calibrate", "--accept-unhealthy", "--bag", str(sim_bag), "--robot",
                 "create2", "--out", str(out)]) == 0
    capsys.readouterr()
    model = MotionModel.load(out / "model_arx.json")
    other = model.updated(dt_s=0.033, robot=dataclasses.replace(model.robot, dt_s=0.033))
    path = other.save(tmp_path / "other.json")
    for command in ("replay", "monitor"):
        _one_line_exit_2([command, "--bag", str(sim_bag), "--model", str(path),
                          *(["--out", str(tmp_path / "r")] if command == "replay" else [])],
                         capsys, "drive.bag has a sensor period of 14.98 ms, the model 33 ms "
                                 "(more than 5% apart)")


def _turtlebot() -> Path:
    base = data_dir()
    path = None if base is None else base / "real" / "turtlebot3_gazebo.bag"
    if path is None or not path.is_file():
        if os.environ.get("CI"):
            pytest.fail("turtlebot3_gazebo.bag not found: set LTI_MOTION_DATA")
        pytest.skip("turtlebot3_gazebo.bag not found (set LTI_MOTION_DATA)")
    return path


def _independent_odometry(bag: Path, *, radius_m: float, separation_m: float):
    """The wheel angles integrated here, with rosbags alone (midpoint heading), from the
    first /odom pose; and /odom at the wheel stamps."""
    t, angles, odom_t, odom = [], [], [], []
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic in ("/joint_states", "/odom")]
        for c, _, raw in reader.messages(connections=conns):
            m = reader.deserialize(raw, c.msgtype)
            stamp = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
            if c.topic == "/joint_states":
                names = list(m.name)
                t.append(stamp)
                angles.append([m.position[names.index("wheel_left_joint")],
                               m.position[names.index("wheel_right_joint")]])
            else:
                q = m.pose.pose.orientation
                odom_t.append(stamp)
                odom.append([m.pose.pose.position.x, m.pose.pose.position.y,
                             math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y ** 2
                                                                           + q.z ** 2))])
    t, angles, odom_t, odom = map(np.asarray, (t, angles, odom_t, odom))
    odom[:, 2] = np.unwrap(odom[:, 2])
    truth = np.column_stack([np.interp(t, odom_t, odom[:, k]) for k in range(3)])
    step = np.diff(angles, axis=0) * radius_m
    ds, dth = step.mean(axis=1), (step[:, 1] - step[:, 0]) / separation_m
    poses = np.zeros((len(t), 3))
    poses[0] = truth[0]
    for k in range(len(ds)):
        heading = poses[k, 2] + dth[k] / 2
        poses[k + 1] = poses[k] + (ds[k] * math.cos(heading), ds[k] * math.sin(heading), dth[k])
    return t, poses, truth, float(np.abs(ds).sum())


def test_turtlebot3_calibrates_only_with_its_geometry_and_replays_as_its_wheels_say(tmp_path,
                                                                                   capsys):
    """Issue 29's check on the Gazebo TurtleBot3 Waffle bag: no geometry, one line; with it,
    ``replay --truth-topic /odom`` without geometry flags gives the encoder odometry of an
    independent integration of the wheel angles (radius 0.033 m, separation 0.287 m) to
    1 % (measured: 0.9 mm at most over a 25.0 m path, ATE 2.0364 against 2.0368 m)."""
    bag = _turtlebot()
    _one_line_exit_2(["calibrate", "--accept-unhealthy", "--bag", str(bag),
                      "--out", str(tmp_path / "no")], capsys,
                     "turtlebot3_gazebo.bag holds wheel angles and nothing gives")
    out = tmp_path / "cal"
    assert main(["calibrate", "--accept-unhealthy", "--bag", str(bag),
                 "--wheel-radius", "0.033", "--wheel-base",
                 "0.287", "--ticks-per-rad", str(4096 / (2 * math.pi)), "--encoders",
                 "quadrature", "--out", str(out)]) == 0
    capsys.readouterr()
    replay = tmp_path / "replay"
    assert main(["replay", "--bag", str(bag), "--model", str(out / "model_arx.json"),
                 "--truth-topic", "/odom", "--estimators", "odometry", "--out",
                 str(replay)]) == 0
    said = capsys.readouterr().out
    label = "the robot's odometry (/odom, nav_msgs/Odometry, odom -> base_footprint)"
    assert f"reference: {label}" in said and "ground truth" not in said
    assert f"estimators start at the first pose of {label}" in said
    t, poses, truth, path_m = _independent_odometry(bag, radius_m=0.033, separation_m=0.287)
    tum = np.loadtxt(replay / "odometry.tum")
    at = tum[:, 0] - tum[0, 0] + t[0]                   # TUM times count from the first frame
    ours = np.column_stack([np.interp(at, t, poses[:, k]) for k in range(2)])
    gap = np.linalg.norm(tum[:, 1:3] - ours, axis=1)
    assert gap.max() < 0.01 * path_m, (gap.max(), path_m)
    metrics = json.loads((replay / "metrics.json").read_text())["metrics"]["odometry"]
    independent_ate = float(np.sqrt(np.mean(np.sum((poses[:, :2] - truth[:, :2]) ** 2, 1))))
    assert metrics["ate_rmse_m"] == pytest.approx(independent_ate, rel=0.01)
    assert metrics["path_m"] == pytest.approx(path_m, rel=0.01)


def test_monitor_port_refuses_a_model_of_another_robot_before_opening_it(tmp_path, capsys,
                                                                         short_arx_model):
    from lti_motion.robot_description import RobotDescription

    model = short_arx_model(4)
    waffle = RobotDescription(wheel_data="wheel_angles_rad", wheel_base_m=0.287,
                              dt_s=model.dt_s, wheel_radius_m=0.033, robot="waffle")
    path = model.updated(robot=waffle).save(tmp_path / "waffle.json")
    _one_line_exit_2(["monitor", "--port", "/dev/does-not-exist", "--model", str(path)], capsys,
                     "the Roomba on /dev/does-not-exist has raw encoder counts, the model's "
                     "robot (waffle) wheel angles [rad]")


def _as_amcl(src: Path, out: Path, *, late_s: float) -> Path:
    """A copy of the ROS 1 bag ``src`` whose /ground_truth (PoseStamped, frame world) is
    /amcl_pose (PoseWithCovarianceStamped, frame map), starting ``late_s`` after the rest."""
    store = get_typestore(Stores.ROS1_NOETIC)
    pwcs = "geometry_msgs/msg/PoseWithCovarianceStamped"
    with AnyReader([src]) as reader, Writer(out) as writer:
        conns = {c.topic: writer.add_connection(c.topic, c.msgtype, typestore=reader.typestore)
                 for c in reader.connections if c.topic != "/ground_truth"}
        amcl = writer.add_connection("/amcl_pose", pwcs, typestore=store)
        start = None
        for c, t, raw in reader.messages():
            start = t if start is None else start
            if c.topic != "/ground_truth":
                writer.write(conns[c.topic], t, raw)
            elif t >= start + late_s * 1e9:
                pose = reader.deserialize(raw, c.msgtype)
                header = store.types["std_msgs/msg/Header"](seq=0, stamp=pose.header.stamp,
                                                            frame_id="map")
                msg = store.types[pwcs](header=header, pose=store.types[
                    "geometry_msgs/msg/PoseWithCovariance"](pose=pose.pose,
                                                            covariance=np.zeros(36)))
                writer.write(amcl, t, store.serialize_ros1(msg, pwcs))
    return out


def test_any_reference_is_named_started_from_and_the_estimates_written_in_its_frame(
        sim_bag, tmp_path, capsys):
    """``PoseWithCovarianceStamped`` on /amcl_pose (frame map), starting 0.5 s after the
    wheels: named for what it is, the replay starts at its first pose (said so), the metrics
    match the PoseStamped reference replayed from the same time, and ``--out-bag`` writes
    the estimates in frame map."""
    out = tmp_path / "cal"
    assert main(["calibrate", "--accept-unhealthy", "--bag", str(sim_bag),
                 "--robot", "create2", "--out",
                 str(out)]) == 0
    model = str(out / "model_arx.json")
    amcl = _as_amcl(sim_bag, tmp_path / "amcl.bag", late_s=0.5)
    capsys.readouterr()
    assert main(["replay", "--bag", str(amcl), "--model", model, "--truth-topic", "/amcl_pose",
                 "--estimators", "odometry", "ekf", "--out", str(tmp_path / "a"),
                 "--out-bag", str(tmp_path / "est.bag")]) == 0
    said = capsys.readouterr().out
    label = "the pose estimate (/amcl_pose, geometry_msgs/PoseWithCovarianceStamped, map)"
    assert f"reference: {label}" in said and "ground truth" not in said
    assert f"{label} starts 0.5" in said and "replaying from its first pose" in said
    assert f"estimators start at the first pose of {label}" in said
    assert "frame map, the reference's" in said
    with AnyReader([tmp_path / "est.bag"]) as reader:
        conn = next(c for c in reader.connections if c.msgtype == "nav_msgs/msg/Odometry")
        first = reader.deserialize(next(reader.messages(connections=[conn]))[2], conn.msgtype)
    assert first.header.frame_id == "map"
    late = json.loads((tmp_path / "a" / "metrics.json").read_text())["metrics"]
    # the same drive against its PoseStamped truth, replayed from 0.5 s on
    assert main(["replay", "--bag", str(sim_bag), "--model", model, "--estimators", "odometry",
                 "ekf", "--start-s", "0.5", "--out", str(tmp_path / "p")]) == 0
    said = capsys.readouterr().out
    assert "reference: the reference poses (/ground_truth, geometry_msgs/PoseStamped, world)" \
        in said
    pose = json.loads((tmp_path / "p" / "metrics.json").read_text())["metrics"]
    for name in ("odometry", "ekf"):
        assert late[name]["ate_rmse_m"] == pytest.approx(pose[name]["ate_rmse_m"], rel=0.1,
                                                         abs=0.005), (name, late, pose)


def test_replay_refuses_a_roomba_log_with_a_model_of_wheel_angles(tmp_path, capsys,
                                                                   short_arx_model):
    from lti_motion.recordings.logfile import save_log
    from lti_motion.robot_description import RobotDescription

    model = short_arx_model(4)
    log = Simulator("create2", seed=5).run(np.full((200, 2), 0.2))
    path = save_log(tmp_path / "roomba.npz", log)
    waffle = RobotDescription(wheel_data="wheel_angles_rad", wheel_base_m=model.wheel_base_m,
                              dt_s=model.dt_s, wheel_radius_m=0.033, robot="waffle")
    other = model.updated(robot=waffle).save(tmp_path / "waffle.json")
    _one_line_exit_2(["replay", str(path), "--model", str(other), "--out", str(tmp_path / "r")],
                     capsys, "roomba.npz has raw encoder counts, the model's robot (waffle) "
                             "wheel angles [rad]")
    create2 = RobotDescription(wheel_data="counts", wheel_base_m=model.wheel_base_m,
                               dt_s=model.dt_s, encoders="commanded", counter_bits=16,
                               robot="create2")
    same = model.updated(robot=create2).save(tmp_path / "create2.json")
    assert main(["replay", str(path), "--model", str(same), "--estimators", "odometry",
                 "--out", str(tmp_path / "ok")]) == 0


def test_a_tf_reference_in_frame_odom_is_the_robots_odometry():
    from lti_motion.app.bag_commands import reference_label
    from lti_motion.recordings import Recording

    def label(ref):
        return reference_label(Recording.from_streams(
            wheel_t_s=[0.0, 0.1], wheel_angles_rad=[[0, 0], [1, 1]], cmd_body=[[0, 0], [0, 0]],
            meta={"reference": ref}))

    tf = "tf2_msgs/msg/TFMessage"
    assert label({"topic": "/tf", "type": tf, "frames": ["odom", "base_footprint"]}) == \
        "the robot's odometry (tf odom -> base_footprint)"
    assert label({"topic": "/tf", "type": tf, "frames": ["world", "base_link"]}) == \
        "the reference poses (tf world -> base_link)"
    assert label({"topic": "/vicon", "type": "geometry_msgs/msg/PoseStamped",
                  "frames": ["world"]}) == \
        "the reference poses (/vicon, geometry_msgs/PoseStamped, world)"
