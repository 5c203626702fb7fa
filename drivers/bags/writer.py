"""ROS bags out: estimates, alarms and simulated drives, written with ``rosbags``' own messages.

The format follows the path: a name ending in ``.bag`` is a ROS 1 bag; anything
else a ROS 2 bag folder, in MCAP (default) or SQLite 3 (``.db3``) storage. Messages
are built from ``rosbags``' typestore classes (ROS 1 Noetic, ROS 2 Humble) and
serialized by it; no byte is laid out here.

Nothing is half-written: a bag is written under a temporary name in its folder and
renamed into place when complete; an existing path is refused.

- :func:`write_estimates_bag`: poses with covariance as ``nav_msgs/Odometry``,
  alarms as ``diagnostic_msgs/DiagnosticArray``;
- :func:`write_drive_bag`: a :class:`~lti_motion.recordings.FrameLog` (a simulator
  drive) as a robot running ROS would record it: ``/cmd_vel`` (``Twist``),
  ``/joint_states`` (wheel angles from the counts), ``/odom`` (encoder odometry)
  and, with simulator truth, ``/ground_truth`` (``PoseStamped``) or, with
  ``truth="tf"``, ``/tf`` (``tf2_msgs/TFMessage``: ``world -> base_link``) and a
  static ``base_link -> base_laser`` mount on ``/tf_static``, or with
  ``truth="tf_chain"`` the same poses as a chain: ``map -> odom`` on ``/tf`` every
  tenth frame (a localiser's correction drifting at a constant rate: 20 mm/s in x,
  -10 mm/s in y, 0.01 rad/s in yaw), ``odom -> base_footprint`` on ``/tf`` per frame
  (the pose in ``odom`` that makes the chain the truth) and a static
  ``base_footprint -> base_link`` mount 0.05 m up on ``/tf_static``; and, when the
  drive has a yaw-rate gyro (``log.yaw_rate_rad_s``), ``/imu/data``
  (``sensor_msgs/Imu``: the yaw rate and its variance, orientation and acceleration
  marked absent, REP 145).

No ``Odometry`` written here holds a zero variance (robot_localization replaces one with
a warning): the estimates' twist carries the model's output noise, or "unknown"
(:data:`UNESTIMATED_VARIANCE`) when none is given; the drive's ``/odom`` its
:class:`~lti_motion.odometry_noise.OdometryNoise` (the twist's, and the pose's grown along
the path); every variance is at least :data:`~lti_motion.odometry_noise.VARIANCE_FLOOR`.
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
import shutil
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from drivers.bags.reader import CREATE2_TICKS_PER_RAD, CREATE2_WHEEL_RADIUS_M
from drivers.exceptions import BagError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import body_from_wheel, integrate_poses
from lti_motion.odometry_noise import VARIANCE_FLOOR, OdometryNoise
from lti_motion.recordings.frames import FrameLog
from lti_motion.recordings.ticks import tick_deltas, unwrap_ticks

__all__ = ["BagAlarm", "write_drive_bag", "write_estimates_bag"]

Storage = Literal["mcap", "sqlite3"]
#: Variance written for the Odometry entries the planar filter does not estimate
#: (z, roll, pitch and their rates) [m^2, rad^2]: "unknown", as robot_localization reads it.
UNESTIMATED_VARIANCE = 1e6


@dataclass(frozen=True)
class BagAlarm:
    """One alarm as it goes into a ``DiagnosticStatus``.

    Attributes
    ----------
    t_ns : int
        Bag time of the alarm [ns].
    name : str
        What fired (e.g. ``"lti_motion/dynamics_changed"``).
    message : str
        One line for people.
    values : tuple of (str, str)
        Key-value pairs (statistic, threshold, onset, ...).
    """

    t_ns: int
    name: str
    message: str
    values: tuple[tuple[str, str], ...] = ()


@functools.cache
def _typestore(ros1: bool) -> Typestore:
    """The distro's typestore (ROS 1 Noetic or ROS 2 Humble), one per process: ``rosbags``
    generates a message type's serializers once per store, which was most of the time of
    writing a short bag. Bags only add ``tf2_msgs/msg/TFMessage`` to it, always the same."""
    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)


class _Bag:
    """An open bag: typestore, connections, one serializer, by format."""

    def __init__(self, writer: Writer1 | Writer2, ros1: bool) -> None:
        self.writer, self.ros1 = writer, ros1
        self.store = _typestore(ros1)
        self.types = self.store.types
        self.conns: dict[str, object] = {}
        self.seq = 0

    def topic(self, name: str, msgtype: str) -> None:
        self.conns[name] = (self.writer.add_connection(name, msgtype, typestore=self.store),
                            msgtype)

    def write(self, topic: str, t_ns: int, msg: object) -> None:
        conn, msgtype = self.conns[topic]
        data = (self.store.serialize_ros1(msg, msgtype) if self.ros1
                else self.store.serialize_cdr(msg, msgtype))
        self.writer.write(conn, int(t_ns), data)

    def header(self, t_ns: int, frame_id: str) -> object:
        stamp = self.types["builtin_interfaces/msg/Time"](sec=int(t_ns // 1_000_000_000),
                                                          nanosec=int(t_ns % 1_000_000_000))
        self.seq += 1
        extra = {"seq": self.seq} if self.ros1 else {}
        return self.types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id, **extra)

    def vector3(self, x: float = 0.0, y: float = 0.0, z: float = 0.0) -> object:
        return self.types["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))

    def pose(self, x: float, y: float, theta: float) -> object:
        t = self.types
        return t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
            orientation=t["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=math.sin(theta / 2.0), w=math.cos(theta / 2.0)))

    def twist(self, v: float, w: float) -> object:
        return self.types["geometry_msgs/msg/Twist"](linear=self.vector3(v),
                                                     angular=self.vector3(z=w))


@contextlib.contextmanager
def _open_bag(path: str | os.PathLike, storage: Storage) -> Iterator[_Bag]:
    """Write a bag under a temporary name next to ``path``; rename it into place on success."""
    path = Path(path)
    if path.exists():
        raise FileExistsError(f"{path} exists; lti-motion never overwrites a bag, give a new "
                              "name")
    if storage not in ("mcap", "sqlite3"):
        raise ValueError(f"storage must be 'mcap' or 'sqlite3', got {storage!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent))
    try:
        ros1 = path.suffix == ".bag"
        inner = tmp / path.name
        if ros1:
            writer = Writer1(inner)
        else:
            plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
            writer = Writer2(inner, version=9, storage_plugin=plugin)
        writer.open()
        try:
            yield _Bag(writer, ros1)
        finally:
            writer.close()
        os.replace(inner, path)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _covariance6(cov: np.ndarray, keep: tuple[int, ...] = (0, 1, 5)) -> np.ndarray:
    """A planar covariance in ROS's 6x6, row-major: the pose's ``(x, y, theta)`` into
    ``(x, y, z, roll, pitch, yaw)``, or with ``keep=(0, 5)`` a twist's ``(v, w)`` into
    ``(vx, vy, vz, wx, wy, wz)``; the rest :data:`UNESTIMATED_VARIANCE`, no variance below
    :data:`~lti_motion.odometry_noise.VARIANCE_FLOOR`."""
    out = np.diag(np.full(6, UNESTIMATED_VARIANCE))
    idx = list(keep)
    out[np.ix_(idx, idx)] = 0.5 * (cov + cov.T)
    out[idx, idx] = np.maximum(out[idx, idx], VARIANCE_FLOOR)
    return out.ravel()


def write_estimates_bag(path: str | os.PathLike, t_ns: np.ndarray, poses: np.ndarray,
                        pose_covs: np.ndarray, *, speeds: np.ndarray | None = None,
                        twist_covs: np.ndarray | None = None,
                        alarms: Sequence[BagAlarm] = (), odom_topic: str = "/lti_motion/odom",
                        alarm_topic: str = "/diagnostics", frame_id: str = "odom",
                        child_frame_id: str = "base_link", storage: Storage = "mcap") -> Path:
    """Write estimated poses (and alarms) into a new bag.

    Parameters
    ----------
    path : str or path-like
        New bag: ``*.bag`` for ROS 1, else a ROS 2 bag folder.
    t_ns : array_like of int, shape (n,)
        Bag times of the estimates [ns].
    poses : ndarray, shape (n, 3)
        ``(x [m], y [m], theta [rad])`` in ``frame_id``.
    pose_covs : ndarray, shape (n, 3, 3)
        Their covariances [m^2, m rad, rad^2] (the EKF's pose block); the other
        entries of the 6x6 get :data:`UNESTIMATED_VARIANCE`.
    speeds : ndarray, shape (n, 2), optional
        Body speeds ``(v [m/s], w [rad/s])`` for the twist (zeros without).
    twist_covs : ndarray, shape (2, 2) or (n, 2, 2), optional
        Their covariance [(m/s)^2, (rad/s)^2], e.g. the model's output noise ``R``;
        without, the twist's variances are :data:`UNESTIMATED_VARIANCE` ("unknown").
    alarms : sequence of BagAlarm
        One ``DiagnosticArray`` (level ERROR) each, at its own time.
    odom_topic, alarm_topic, frame_id, child_frame_id : str
        Names in the bag.
    storage : {"mcap", "sqlite3"}
        ROS 2 storage.

    Returns
    -------
    Path
        The bag written.

    Raises
    ------
    FileExistsError
        If ``path`` exists.
    BagError
        If the shapes disagree or a value is not finite (nothing is written).
    """
    t_ns = np.asarray(t_ns, dtype=np.int64)
    poses, pose_covs = np.asarray(poses, float), np.asarray(pose_covs, float)
    n = len(t_ns)
    speeds = np.zeros((n, 2)) if speeds is None else np.asarray(speeds, float)
    twist_covs = (np.diag([UNESTIMATED_VARIANCE] * 2) if twist_covs is None
                  else np.asarray(twist_covs, float))
    twist_covs = np.broadcast_to(twist_covs, (n, 2, 2)) if twist_covs.shape == (2, 2) \
        else twist_covs
    if poses.shape != (n, 3) or pose_covs.shape != (n, 3, 3) or speeds.shape != (n, 2) \
            or twist_covs.shape != (n, 2, 2):
        raise BagError(f"estimates need poses (n, 3), covariances (n, 3, 3), speeds (n, 2) and "
                       f"twist covariances (2, 2) or (n, 2, 2) for n = {n} stamps; got "
                       f"{poses.shape}, {pose_covs.shape}, {speeds.shape}, {twist_covs.shape}")
    for name, value in (("poses", poses), ("covariances", pose_covs), ("speeds", speeds),
                        ("twist covariances", twist_covs)):
        if not np.all(np.isfinite(value)):
            raise BagError(f"the estimates' {name} hold a NaN or infinite value; nothing written")
    with _open_bag(path, storage) as bag:
        t = bag.types
        bag.topic(odom_topic, "nav_msgs/msg/Odometry")
        if alarms:
            bag.topic(alarm_topic, "diagnostic_msgs/msg/DiagnosticArray")
        pending = sorted(alarms, key=lambda a: a.t_ns)
        for i in range(n):
            while pending and pending[0].t_ns <= t_ns[i]:
                _write_alarm(bag, alarm_topic, pending.pop(0), frame_id)
            msg = t["nav_msgs/msg/Odometry"](
                header=bag.header(t_ns[i], frame_id), child_frame_id=child_frame_id,
                pose=t["geometry_msgs/msg/PoseWithCovariance"](
                    pose=bag.pose(*poses[i]), covariance=_covariance6(pose_covs[i])),
                twist=t["geometry_msgs/msg/TwistWithCovariance"](
                    twist=bag.twist(*speeds[i]), covariance=_covariance6(twist_covs[i], (0, 5))))
            bag.write(odom_topic, t_ns[i], msg)
        for alarm in pending:
            _write_alarm(bag, alarm_topic, alarm, frame_id)
    return Path(path)


def _write_alarm(bag: _Bag, topic: str, alarm: BagAlarm, frame_id: str) -> None:
    t = bag.types
    status_type = t["diagnostic_msgs/msg/DiagnosticStatus"]
    status = status_type(level=int(status_type.ERROR), name=alarm.name, message=alarm.message,
                         hardware_id="lti_motion",
                         values=[t["diagnostic_msgs/msg/KeyValue"](key=k, value=v)
                                 for k, v in alarm.values])
    bag.write(topic, alarm.t_ns, t["diagnostic_msgs/msg/DiagnosticArray"](
        header=bag.header(alarm.t_ns, frame_id), status=[status]))


def _imu_message(bag: _Bag, t_ns: int, yaw_rate_rad_s: float, yaw_rate_var: float,
                frame_id: str = "base_link") -> object:
    """A ``sensor_msgs/Imu`` holding only a yaw rate, as REP 145 asks of a partial IMU.

    ``angular_velocity.z`` is the reading and its variance is
    ``angular_velocity_covariance[8]`` (row-major 3x3; 0 for "unknown", as the
    message definition reads an all-zero matrix); the roll and pitch rates, not
    measured, get :data:`UNESTIMATED_VARIANCE`. Orientation and linear acceleration
    are not given: element 0 of their covariances is -1 (the message definition,
    REP 145 section "Data Sources").
    """
    t = bag.types
    unknown = np.zeros(9)
    unknown[0] = -1.0
    rate_cov = np.diag([UNESTIMATED_VARIANCE, UNESTIMATED_VARIANCE, 0.0]).ravel()
    rate_cov[8] = yaw_rate_var
    return t["sensor_msgs/msg/Imu"](
        header=bag.header(t_ns, frame_id),
        orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=unknown.copy(), angular_velocity=bag.vector3(z=yaw_rate_rad_s),
        angular_velocity_covariance=rate_cov, linear_acceleration=bag.vector3(),
        linear_acceleration_covariance=unknown.copy())


def write_drive_bag(path: str | os.PathLike, log: FrameLog, *, start_ns: int = 1_700_000_000
                    * 1_000_000_000, ticks_per_rad: float = CREATE2_TICKS_PER_RAD,
                    wheel_radius_m: float = CREATE2_WHEEL_RADIUS_M, wheel_base_m: float = 0.235,
                    joints: tuple[str, str] = ("wheel_left_joint", "wheel_right_joint"),
                    storage: Storage = "mcap",
                    truth: Literal["pose", "tf", "tf_chain"] = "pose",
                    gyro_noise_density_rad_s_sqrt_hz: float | None = None,
                    imu_topic: str = "/imu/data", joint_states: bool = True,
                    odom_noise: OdometryNoise | None = None,
                    header_offsets_s: Mapping[str, float] | None = None,
                    odom_twist_replaced: Mapping[int, tuple[float, float]] | None = None
                    ) -> Path:
    """Write a single-robot drive as ROS would record it (module docstring).

    Lost frames (``valid`` false) are left out, as they never arrived. The
    command of frame ``k`` (period ``k``) is stamped at the start of its period
    on the robot's clock, ``t_s[k] - dt_s``; wheel angles are the unwrapped
    counts over ``ticks_per_rad``, stamped with the frame times. ``/odom`` holds
    the encoder odometry, as ``diff_drive_controller`` publishes it: the pose
    integrated from the wheel travel and the twist, the body speeds over the
    interval since the last received frame's stamp (its travel over ``now - last``, as
    ``diff_drive_controller`` divides by its own clock; over the nominal periods where two
    frames share a stamp), with the covariances of ``odom_noise``: the
    twist's its speed covariance over those periods, the pose's grown along the path
    (:meth:`~lti_motion.odometry_noise.OdometryNoise.pose_covariances`). A gyro's
    reading of frame ``k`` (the mean yaw rate over period ``k``) goes on
    ``imu_topic`` stamped mid-period, ``t_s[k] - dt_s / 2``, as
    :meth:`lti_motion.recordings.Recording.from_frame_log` stamps it; a
    received frame's NaN reading is left out too.

    Parameters
    ----------
    path : str or path-like
        New bag (``*.bag``: ROS 1; else a ROS 2 folder).
    log : FrameLog
        One robot's frames (the simulator's, or a recorded log).
    start_ns : int
        Bag time of ``t_s = 0`` [ns].
    ticks_per_rad, wheel_radius_m, wheel_base_m : float
        The robot's encoder, wheel radius [m] and wheel base [m].
    joints : tuple of 2 str
        The (left, right) joint names.
    storage : {"mcap", "sqlite3"}
        ROS 2 storage.
    truth : {"pose", "tf", "tf_chain"}
        How the simulator's poses go in: a ``PoseStamped`` topic, tf directly, or
        tf as a chain ``map -> odom -> base_footprint -> base_link`` (module
        docstring).
    gyro_noise_density_rad_s_sqrt_hz : float, optional
        The gyro's white-noise density [rad/s/sqrt(Hz)]; the Imu's yaw-rate
        variance is then ``density^2 / dt_s`` (a period's mean of white rate noise,
        Woodman 2007, section 3.2.1), else 0 ("unknown").
    imu_topic : str
        Where the gyro goes (with a gyro in the drive).
    joint_states : bool
        Write the wheel angles on ``/joint_states``; ``False`` leaves them out, as
        from a robot that publishes only its odometry.
    odom_noise : OdometryNoise, optional
        The odometry's noise, e.g. ``OdometryNoise.from_model(model)``; default
        :meth:`~lti_motion.odometry_noise.OdometryNoise.from_encoders` of the nominal
        encoders (the counts' rounding, grown as if it accumulated: an upper bound).
    header_offsets_s : Mapping of str to float, optional
        Per topic, seconds added to its messages' header stamps and not to the times
        the bag records them at: a publisher whose clock runs ahead of (positive) or
        behind the recorder's, e.g. ``{"/joint_states": 0.8, "/odom": 0.8}`` for a
        robot 0.8 s ahead of the PC that sends ``/cmd_vel`` (a bare ``Twist``: no
        header to shift).
    odom_twist_replaced : Mapping of int to (float, float), optional
        ``/odom`` message index -> the ``(v [m/s], w [rad/s])`` its twist holds
        instead: a driver's glitch, e.g. a heading that wrapped by 2 pi within one
        message interval (the pose is left as integrated).

    Returns
    -------
    Path
        The bag written.

    Raises
    ------
    FileExistsError
        If ``path`` exists.
    ValueError
        For an unknown ``truth``, a batch log, or a negative or non-finite noise
        density (nothing is written).

    References
    ----------
    REP 145, "Conventions for IMU sensor drivers"; ``sensor_msgs/msg/Imu``.
    O. J. Woodman, "An introduction to inertial navigation", UCAM-CL-TR-696, 2007.
    """
    if truth not in ("pose", "tf", "tf_chain"):
        raise ValueError(f"truth must be 'pose', 'tf' or 'tf_chain', got {truth!r}")
    if log.n_robots is not None:
        raise ValueError("write_drive_bag writes one robot; pass log.robot(i)")
    density = gyro_noise_density_rad_s_sqrt_hz
    if density is not None and not (math.isfinite(density) and density >= 0):
        raise ValueError(f"gyro_noise_density_rad_s_sqrt_hz must be >= 0, got {density!r}")
    rows = np.flatnonzero(log.valid)
    t_ns = start_ns + np.rint(log.t_s * 1e9).astype(np.int64)
    angles = unwrap_ticks(log.ticks, axis=0, counter_bits=log.counter_bits) / ticks_per_rad
    cmd_vw = body_from_wheel(log.cmd_m_s, wheel_base_m=wheel_base_m)
    cmd_ns = t_ns - round(log.dt_s * 1e9)
    travel = tick_deltas(log.ticks[rows], axis=0, counter_bits=log.counter_bits) * (
        wheel_radius_m / ticks_per_rad)
    body_m = body_from_wheel(travel, wheel_base_m=wheel_base_m)
    odom = integrate_poses(body_m, 1.0)
    twist = np.zeros((len(rows), 2))            # (v [m/s], w [rad/s]) since the last frame
    spans = np.diff(rows)                        # periods since the last received frame
    interval_s = np.diff(log.t_s[rows])          # over its own stamps' interval; two frames
    interval_s = np.where(interval_s > 0, interval_s, spans * log.dt_s)   # on one stamp: periods
    twist[1:] = body_m / interval_s[:, None]
    written_twist = twist.copy()
    for j, vw in (odom_twist_replaced or {}).items():
        written_twist[j] = vw
    shifts = {topic: round(offset * 1e9) for topic, offset in (header_offsets_s or {}).items()}
    if odom_noise is None:
        k = wheel_radius_m / ticks_per_rad
        odom_noise = OdometryNoise.from_encoders(
            OdometryIntrinsics.symmetric(m_per_tick=k, wheel_base_m=wheel_base_m), log.dt_s)
    odom_pose_covs = odom_noise.pose_covariances(odom, twist[1:], spans)
    odom_twist_covs = np.concatenate([odom_noise.speed_cov[None],
                                      odom_noise.speed_cov[None] / spans[:, None, None]])
    with _open_bag(path, storage) as bag:
        t, out = bag.types, []
        for topic, msgtype in (("/cmd_vel", "geometry_msgs/msg/Twist"),
                               ("/joint_states", "sensor_msgs/msg/JointState"),
                               ("/odom", "nav_msgs/msg/Odometry")):
            if joint_states or topic != "/joint_states":
                bag.topic(topic, msgtype)
        if log.true_pose is not None and truth == "pose":
            bag.topic("/ground_truth", "geometry_msgs/msg/PoseStamped")
        elif log.true_pose is not None:
            out.extend(_tf_truth(bag, t_ns[rows], log.true_pose[rows],
                                 chain=truth == "tf_chain"))
        out += [(cmd_ns[k], "/cmd_vel", bag.twist(*cmd_vw[k]))    # sent, lost frame or not
                for k in range(1, len(log))]
        empty = np.zeros(0)
        for j, k in enumerate(rows):
            if joint_states:
                out.append((t_ns[k], "/joint_states", t["sensor_msgs/msg/JointState"](
                    header=bag.header(t_ns[k], "base_link"), name=list(joints),
                    position=angles[k].copy(), velocity=empty, effort=empty)))
            out.append((t_ns[k], "/odom", t["nav_msgs/msg/Odometry"](
                header=bag.header(t_ns[k], "odom"), child_frame_id="base_link",
                pose=t["geometry_msgs/msg/PoseWithCovariance"](
                    pose=bag.pose(*odom[j]), covariance=_covariance6(odom_pose_covs[j])),
                twist=t["geometry_msgs/msg/TwistWithCovariance"](
                    twist=bag.twist(*written_twist[j]),
                    covariance=_covariance6(odom_twist_covs[j], (0, 5))))))
            if log.true_pose is not None and truth == "pose":
                out.append((t_ns[k], "/ground_truth", t["geometry_msgs/msg/PoseStamped"](
                    header=bag.header(t_ns[k], "world"), pose=bag.pose(*log.true_pose[k]))))
        out += _gyro_messages(bag, log, t_ns, imu_topic, gyro_noise_density_rad_s_sqrt_hz)
        out.sort(key=lambda item: item[0])        # in time order, as a recorder writes
        for stamp, topic, msg in out:
            if shifts.get(topic) and hasattr(msg, "header"):   # the publisher's own clock
                own = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                msg = replace(msg, header=bag.header(own + shifts[topic], msg.header.frame_id))
            bag.write(topic, stamp, msg)
    return Path(path)


def _gyro_messages(bag: _Bag, log: FrameLog, t_ns: np.ndarray, topic: str,
                   density: float | None) -> list[tuple[int, str, object]]:
    """The gyro's readings of the received frames as Imu messages, stamped mid-period."""
    if log.yaw_rate_rad_s is None:
        return []
    var = 0.0 if density is None else density**2 / log.dt_s      # Woodman 2007, 3.2.1
    bag.topic(topic, "sensor_msgs/msg/Imu")
    stamps = t_ns - round(0.5 * log.dt_s * 1e9)
    rows = np.flatnonzero(log.valid & np.isfinite(log.yaw_rate_rad_s))
    return [(int(stamps[k]), topic, _imu_message(bag, int(stamps[k]),
                                                float(log.yaw_rate_rad_s[k]), var))
            for k in rows]


def _tf_truth(bag: _Bag, t_ns: np.ndarray, poses: np.ndarray, *, chain: bool
              ) -> list[tuple[int, str, object]]:
    """The poses on ``/tf`` (directly or as a chain) and static mounts on ``/tf_static``."""
    if "tf2_msgs/msg/TFMessage" not in bag.types:          # ROS 1 Noetic's store lacks it
        bag.store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                              "tf2_msgs/msg/TFMessage"))
        bag.types = bag.store.types
    t = bag.types
    for topic in ("/tf", "/tf_static"):
        bag.topic(topic, "tf2_msgs/msg/TFMessage")

    def transform(stamp: int, parent: str, child: str, x: float, y: float, theta: float,
                  z: float = 0.0) -> object:
        pose = bag.pose(x, y, theta)
        return t["geometry_msgs/msg/TransformStamped"](
            header=bag.header(stamp, parent), child_frame_id=child,
            transform=t["geometry_msgs/msg/Transform"](
                translation=bag.vector3(pose.position.x, pose.position.y, z),
                rotation=pose.orientation))

    def message(*transforms: object) -> object:
        return t["tf2_msgs/msg/TFMessage"](transforms=list(transforms))

    first = int(t_ns[0])
    if not chain:
        mount = transform(first, "base_link", "base_laser", 0.1, 0.0, 0.0)
        return [(first, "/tf_static", message(mount))] + [
            (int(stamp), "/tf", message(transform(int(stamp), "world", "base_link", *pose)))
            for stamp, pose in zip(t_ns, poses, strict=True)]
    mount = transform(first, "base_footprint", "base_link", 0.0, 0.0, 0.0, z=0.05)
    out = [(first, "/tf_static", message(mount))]
    elapsed_s = (t_ns - first) * 1e-9
    drift = np.column_stack([0.02 * elapsed_s, -0.01 * elapsed_s, 0.01 * elapsed_s])
    for j in sorted({*range(0, len(t_ns), 10), len(t_ns) - 1}):
        out.append((int(t_ns[j]), "/tf", message(transform(int(t_ns[j]), "map", "odom",
                                                           *drift[j]))))
    # odom_T_base = (map_T_odom)^-1 map_T_base, in the plane
    c, s = np.cos(drift[:, 2]), np.sin(drift[:, 2])
    dx, dy = poses[:, 0] - drift[:, 0], poses[:, 1] - drift[:, 1]
    in_odom = np.column_stack([c * dx + s * dy, -s * dx + c * dy, poses[:, 2] - drift[:, 2]])
    out += [(int(stamp), "/tf", message(transform(int(stamp), "odom", "base_footprint", *p)))
            for stamp, p in zip(t_ns, in_odom, strict=True)]
    return out
