"""ROS bags in, the raw layer: the topics of a recorded drive found by type, decoded into
stamped arrays, one :class:`StampedSeries` per topic.

This is what :func:`drivers.bags.read_bag` reads the bag with before it makes the
drive one :class:`~lti_motion.recordings.Recording`; use that, not this, for a drive.

Reads ROS 1 ``.bag`` files and ROS 2 bags (a folder with ``metadata.yaml`` and a
``.db3`` or ``.mcap`` file; the ``.db3`` / ``.mcap`` file itself is accepted too)
with ``rosbags``, without a ROS install.

What is read (:data:`TOPIC_TYPES`), each topic found by its message type when the
bag holds one topic of that kind, or named by the caller when it holds several:

- ``cmd``: ``geometry_msgs/Twist`` or ``TwistStamped`` body-speed commands
  (``linear.x`` [m/s], ``angular.z`` [rad/s]);
- ``wheels``: ``sensor_msgs/JointState`` wheel angles [rad], the left and the right
  joint found by name (:data:`LEFT_JOINT`, :data:`RIGHT_JOINT`: a name holding
  ``left`` / ``right``, as ``wheel_left_joint`` of the TurtleBot and Create
  descriptions or ``left_wheel_joint`` of diff_drive_controller's examples);
- ``odom``: ``nav_msgs/Odometry`` (pose x, y, yaw; twist v, w);
- ``imu``: ``sensor_msgs/Imu`` (yaw rate, and element 0 and ``zz`` of its
  ``angular_velocity_covariance``: :mod:`drivers.bags.imu_noise`);
- ``truth``: ``geometry_msgs/PoseStamped`` reference poses (motion capture), found by
  type; named with ``truth_topic``, also ``PoseWithCovarianceStamped`` (``/amcl_pose``)
  and ``nav_msgs/Odometry`` (its pose; a simulator's true pose, or the robot's own
  odometry); or, when the bag has no such topic or a tf frame pair is named, the
  transform of the robot's frame in ``tf2_msgs/TFMessage`` topics (``/tf``,
  ``/tf_static``; :mod:`drivers.bags.tf`).

Each message is stamped with its header stamp when it has one, else with the time
the bag received it.

Examples
--------
>>> import tempfile, pathlib
>>> from drivers.bags.writer import write_drive_bag
>>> from drivers.sim.simulator import Simulator
>>> log = Simulator("create2", seed=0).run(np.full((50, 2), 0.2))
>>> path = write_drive_bag(pathlib.Path(tempfile.mkdtemp()) / "drive.bag", log)
>>> found = read_topics(path)
>>> found.wheels.topic, found.cmd.topic, len(found.wheels)
('/joint_states', '/cmd_vel', 50)
"""

from __future__ import annotations

import logging
import os
import re
import struct
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.serde import SerdeError

from drivers.bags.fields import decode_fields
from drivers.bags.messages import is_mcap, open_bag, raw_messages
from drivers.bags.tf import TF_TYPE, tf_truth
from drivers.exceptions import BagError

__all__ = [
    "LEFT_JOINT",
    "RIGHT_JOINT",
    "TOPIC_OPTIONS",
    "TOPIC_TYPES",
    "BagTopics",
    "StampedSeries",
    "bag_topics",
    "read_topics",
]

_log = logging.getLogger(__name__)

#: Message types accepted for each kind of topic.
TOPIC_TYPES: Mapping[str, tuple[str, ...]] = MappingProxyType({
    "cmd": ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped"),
    "wheels": ("sensor_msgs/msg/JointState",),
    "odom": ("nav_msgs/msg/Odometry",),
    "imu": ("sensor_msgs/msg/Imu",),
    "truth": ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped",
              "nav_msgs/msg/Odometry"),
})
#: The reference types found by type alone (the others only when named: a bag's
#: ``/odom`` is the robot's odometry, not a reference, unless the user says so).
_TRUTH_BY_TYPE = ("geometry_msgs/msg/PoseStamped",)
#: The command-line option that names each kind's topic (for the messages).
TOPIC_OPTIONS: Mapping[str, str] = MappingProxyType({
    "cmd": "--cmd-topic", "wheels": "--wheels-topic", "odom": "--odom-topic",
    "imu": "--imu-topic", "truth": "--truth-topic"})
#: Default joint-name patterns (regular expressions, case-insensitive, searched).
LEFT_JOINT = r"left"
RIGHT_JOINT = r"right"

_STAMP = ("header.stamp.sec", "header.stamp.nanosec")
_POSE = ("position.x", "position.y", "orientation.x", "orientation.y", "orientation.z",
         "orientation.w")
#: Field paths per message type (after the header stamp, when there is one).
_FIELDS: Mapping[str, tuple[str, ...]] = MappingProxyType({
    "geometry_msgs/msg/Twist": ("linear.x", "angular.z"),
    "geometry_msgs/msg/TwistStamped": ("twist.linear.x", "twist.angular.z"),
    "nav_msgs/msg/Odometry": (*(f"pose.pose.{p}" for p in _POSE), "twist.twist.linear.x",
                              "twist.twist.angular.z"),
    "sensor_msgs/msg/Imu": ("angular_velocity.z", "angular_velocity_covariance[0]",
                            "angular_velocity_covariance[8]"),
    "geometry_msgs/msg/PoseStamped": tuple(f"pose.{p}" for p in _POSE),
    "geometry_msgs/msg/PoseWithCovarianceStamped": tuple(f"pose.pose.{p}" for p in _POSE),
})
#: What each kind's ``values`` columns hold, for people.
COLUMNS: Mapping[str, tuple[str, ...]] = MappingProxyType({
    "cmd": ("v [m/s]", "w [rad/s]"),
    "wheels": ("left [rad]", "right [rad]"),
    "odom": ("x [m]", "y [m]", "theta [rad]", "v [m/s]", "w [rad/s]"),
    "imu": ("w [rad/s]", "angular_velocity_covariance[0]", "yaw-rate variance [rad^2/s^2]"),
    "truth": ("x [m]", "y [m]", "theta [rad]"),
})


@dataclass(frozen=True)
class StampedSeries:
    """The messages of one topic as numbers.

    Attributes
    ----------
    topic, msgtype : str
        Where they came from.
    t_ns : ndarray of int64, shape (n,)
        Stamps [ns] (header stamp, else receive time), non-decreasing.
    values : ndarray, shape (n, k)
        The kind's columns (:data:`COLUMNS`), SI units; headings unwrapped.
    frames : tuple of str
        The first message's ``header.frame_id`` (and an Odometry's ``child_frame_id``)
        for reference poses, else ``()``.
    recv_ns : ndarray of int64, shape (n,), or None
        The times the bag received the messages [ns] (``None``: not known, e.g. tf
        poses gathered from several messages).
    header : bool
        Whether ``t_ns`` are the messages' header stamps (else the receive times).
    """

    topic: str
    msgtype: str
    t_ns: np.ndarray
    values: np.ndarray
    frames: tuple[str, ...] = ()
    recv_ns: np.ndarray | None = None
    header: bool = False

    def __len__(self) -> int:
        return len(self.t_ns)


@dataclass(frozen=True)
class BagTopics:
    """The raw series of a drive's topics found in a bag (not a recording: the reader's
    input to :func:`drivers.bags.read_bag`).

    Attributes
    ----------
    path : Path
        The bag.
    topics : Mapping of str to str
        Every topic of the bag and its message type.
    start_ns : int
        The bag's first stamp [ns] (times elsewhere count from it).
    cmd, wheels, odom, imu, truth : StampedSeries or None
        The kinds of :data:`TOPIC_TYPES` found (``None``: the bag has none).
    joints : tuple of str
        The (left, right) joint names used, ``()`` without wheels.
    truth_frames : tuple of str
        The tf (parent, child) frames of ``truth`` when it came from tf, else ``()``.
    """

    path: Path
    topics: Mapping[str, str]
    start_ns: int
    cmd: StampedSeries | None = None
    wheels: StampedSeries | None = None
    odom: StampedSeries | None = None
    imu: StampedSeries | None = None
    truth: StampedSeries | None = None
    joints: tuple[str, ...] = ()
    truth_frames: tuple[str, ...] = ()


def _listing(topics: Mapping[str, str]) -> str:
    return ", ".join(f"{t} ({m})" for t, m in sorted(topics.items())) or "no topics"


def bag_topics(path: str | os.PathLike) -> dict[str, str]:
    """Every topic of a bag and its message type (``pkg/msg/Type``).

    Raises
    ------
    FileNotFoundError
        If there is no such file or folder.
    BagError
        If it is not a readable bag.
    """
    with open_bag(path) as reader:
        return {c.topic: c.msgtype for c in reader.connections}


def _choose(kind: str, topics: Mapping[str, str], counts: Mapping[str, int],
            chosen: str | None) -> str | None:
    """The topic of one kind: the one named, else the only one of its types."""
    types = TOPIC_TYPES[kind]
    what = " or ".join(t.replace("/msg/", "/") for t in types)
    if chosen is not None:
        if chosen not in topics:
            raise BagError(f"the bag has no topic {chosen}; it has {_listing(topics)}")
        if topics[chosen] not in types:
            raise BagError(f"topic {chosen} holds {topics[chosen]}, but {TOPIC_OPTIONS[kind]} "
                           f"needs {what}")
        return chosen
    if kind == "truth":
        types = _TRUTH_BY_TYPE
    found = sorted(t for t, m in topics.items() if m in types and counts.get(t, 0))
    if len(found) > 1:
        raise BagError(f"the bag has {len(found)} {what} topics ({', '.join(found)}); choose "
                       f"one with {TOPIC_OPTIONS[kind]}")
    return found[0] if found else None


def _joint_index(names: list[str], pattern: str, side: str, topic: str) -> int:
    hits = [i for i, n in enumerate(names) if re.search(pattern, n, re.IGNORECASE)]
    if len(hits) != 1:
        raise BagError(f"topic {topic}: {len(hits)} joints match the {side} wheel pattern "
                       f"{pattern!r} among {names}; name the {side} joint with "
                       f"--{side}-joint")
    return hits[0]


def _yaw(q: np.ndarray) -> np.ndarray:
    """Yaw of quaternions (x, y, z, w) [rad], unwrapped along time."""
    x, y, z, w = q.T
    return np.unwrap(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def _planar(data: np.ndarray) -> np.ndarray:
    """Columns (x, y, qx, qy, qz, qw, ...) as (x, y, yaw, ...)."""
    return np.column_stack([data[:, :2], _yaw(data[:, 2:6]), data[:, 6:]])


def _series(kind: str, topic: str, msgtype: str, recv_ns: np.ndarray, raws: Sequence[bytes],
            reader: AnyReader, joints: tuple[str, str]) -> tuple[StampedSeries, tuple[str, ...]]:
    store = reader.typestore
    if reader.is2:
        def deserialize(raw: bytes) -> object:
            return store.deserialize_cdr(raw, msgtype)

        def serialize(msg: object) -> bytes:
            return store.serialize_cdr(msg, msgtype)
    else:
        def deserialize(raw: bytes) -> object:
            return store.deserialize_ros1(raw, msgtype)

        def serialize(msg: object) -> bytes:
            return store.serialize_ros1(msg, msgtype)
    stamped = msgtype != "geometry_msgs/msg/Twist"
    names: tuple[str, ...] = ()
    if kind == "wheels":
        first = list(deserialize(raws[0]).name)
        names = (first[_joint_index(first, joints[0], "left", topic)],
                 first[_joint_index(first, joints[1], "right", topic)])

        def paths_of(msg: object) -> tuple[str, ...]:
            now = list(msg.name)
            if not set(names) <= set(now):
                raise BagError(f"topic {topic}: a message lacks joint {names[0]} or "
                               f"{names[1]} (it has {now})")
            return (*_STAMP, f"position[{now.index(names[0])}]",
                    f"position[{now.index(names[1])}]")
        paths = paths_of(deserialize(raws[0]))
    else:
        paths_of = None
        paths = (*_STAMP, *_FIELDS[msgtype]) if stamped else _FIELDS[msgtype]
    if stamped and not reader.is2:            # ROS 1 headers count: read the count too
        seq = ("header.seq",)
        inner = paths_of
        paths_of = None if inner is None else (lambda msg: (*seq, *inner(msg)))
        paths = (*seq, *paths)
    try:
        data = decode_fields(raws, paths, deserialize=deserialize, serialize=serialize,
                             paths_of=paths_of)
    except IndexError as exc:
        raise BagError(f"topic {topic}: a message is missing a field ({exc})") from exc
    except (SerdeError, struct.error, UnicodeDecodeError) as exc:
        raise BagError(f"topic {topic}: a message cannot be decoded as {msgtype} ({exc}): the "
                       "bag is damaged or its message definition is not the one written") from exc
    if stamped and not reader.is2:
        data = data[:, 1:]
    header = stamped
    if stamped:
        t_ns = data[:, 0].astype(np.int64) * 1_000_000_000 + data[:, 1].astype(np.int64)
        data = data[:, 2:]
        if not np.any(t_ns):                  # header never filled in: the bag's times
            t_ns, header = recv_ns, False
    else:
        t_ns = recv_ns
    frames: tuple[str, ...] = ()
    if kind in ("odom", "truth"):
        data = _planar(data)
    frames: tuple[str, ...] = ()
    if kind == "truth":
        data = data[:, :3]                    # an Odometry's pose only
        first = deserialize(raws[0])
        frames = (str(first.header.frame_id),
                  *((str(first.child_frame_id),) if hasattr(first, "child_frame_id") else ()))
    return StampedSeries(topic, msgtype, t_ns, data, frames,
                         recv_ns=np.asarray(recv_ns, np.int64), header=header), names


def read_topics(path: str | os.PathLike, *, cmd_topic: str | None = None,
                wheels_topic: str | None = None, odom_topic: str | None = None,
                imu_topic: str | None = None, truth_topic: str | None = None,
                left_joint: str = LEFT_JOINT, right_joint: str = RIGHT_JOINT,
                truth_parent: str | None = None, truth_child: str | None = None,
                kinds: Collection[str] = tuple(TOPIC_TYPES),
                odom_without_wheels: bool = False) -> BagTopics:
    """Find a drive's topics in a bag and decode them.

    Parameters
    ----------
    path : str or path-like
        ROS 1 ``.bag`` file, or ROS 2 bag folder (or its ``.db3`` / ``.mcap`` file).
    cmd_topic, wheels_topic, odom_topic, imu_topic, truth_topic : str, optional
        The topic of each kind (:data:`TOPIC_TYPES`); needed only where the bag
        holds several of that kind. Without one, a kind the bag lacks is ``None``.
    left_joint, right_joint : str
        Regular expressions (case-insensitive, searched) that pick exactly one
        joint each from the first ``JointState`` message, or the joints' names.
    truth_parent, truth_child : str, optional
        Take the reference poses from tf: the transform of frame ``truth_child``
        in frame ``truth_parent`` (:mod:`drivers.bags.tf`; either left out is
        tried from its defaults). Without either, tf is read only when the bag
        has no ``PoseStamped`` topic, and its default pair used when present.
    kinds : collection of str
        The kinds to read (default all); the others stay ``None`` and unread
        (calibration needs only ``cmd`` and ``wheels``).
    odom_without_wheels : bool
        Read ``odom`` only when the bag has no wheels topic to read (and none is
        named): the odometry then stands in for the wheels.

    Returns
    -------
    BagTopics
        Stamps and values checked: finite, stamps never going backwards.

    Raises
    ------
    FileNotFoundError
        If there is no such bag.
    BagError
        A ``ValueError``: not a bag; a named topic missing or of the wrong type;
        several topics of a kind and none named; a named topic empty; joints not
        found; a tf frame pair named and absent (the pairs found listed), or named
        in a bag without tf, or named with ``truth_topic``; stamps going backwards;
        a value not finite. The message names the topic (and lists the bag's
        topics where that helps).
    """
    chosen = {"cmd": cmd_topic, "wheels": wheels_topic, "odom": odom_topic,
              "imu": imu_topic, "truth": truth_topic}
    with open_bag(path) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        counts: dict[str, int] = {}
        for c in reader.connections:
            counts[c.topic] = counts.get(c.topic, 0) + c.msgcount
        unknown = set(kinds) - set(TOPIC_TYPES)
        if unknown:
            raise ValueError(f"unknown kinds {sorted(unknown)}; known: {', '.join(TOPIC_TYPES)}")
        picked = {kind: _choose(kind, topics, counts, chosen[kind]) for kind in TOPIC_TYPES
                  if kind in kinds and not (kind == "odom" and odom_without_wheels)}
        if odom_without_wheels and "odom" in kinds and picked.get("wheels") is None:
            picked["odom"] = _choose("odom", topics, counts, chosen["odom"])
        for kind, topic in picked.items():
            if topic is not None and not counts.get(topic):
                raise BagError(f"topic {topic} is empty: no messages to read as {kind}")
        tf = _tf_topics(topics, counts, kinds, picked, truth_topic, truth_parent, truth_child)
        wanted = {t: k for k, t in picked.items() if t is not None}
        found, names = {}, ()
        conns = [c for c in reader.connections if c.topic in wanted or c.topic in tf]
        got_raw = raw_messages(reader, conns, mcap=is_mcap(path))
        for topic, kind in wanted.items():
            recv, raws = got_raw[topic]
            series, got = _series(kind, topic, topics[topic], recv, raws, reader,
                                  (left_joint, right_joint))
            _check(series)
            found[kind] = series
            names = got or names
        frames: tuple[str, ...] = ()
        if tf:
            parts = [(t, *got_raw[t]) for t in tf]
            series = _tf_series(reader, [t for t, r, _ in parts for _ in r],
                                np.concatenate([r for _, r, _ in parts]),
                                [raw for _, _, raws in parts for raw in raws],
                                truth_parent, truth_child)
            if series is not None:
                (series, frames) = series
                _check(series)
                found["truth"] = series
    firsts = [int(s.t_ns[0]) for s in found.values()]
    start_ns = min(firsts) if firsts else 0
    _log.info("read %s: %s", path, ", ".join(f"{k} {s.topic} ({len(s)})"
                                             for k, s in found.items()))
    return BagTopics(path=Path(path), topics=MappingProxyType(topics), start_ns=start_ns,
                     joints=names, truth_frames=frames, **found)


def _tf_topics(topics: Mapping[str, str], counts: Mapping[str, int], kinds: Collection[str],
               picked: dict[str, str | None], truth_topic: str | None,
               truth_parent: str | None, truth_child: str | None) -> list[str]:
    """The tf topics to read for the reference poses (``[]``: none); a named frame pair
    replaces a ``PoseStamped`` topic found by type (``picked`` updated)."""
    named = truth_parent is not None or truth_child is not None
    if named and truth_topic is not None:
        raise BagError("give --truth-topic (PoseStamped) or --truth-parent / --truth-child "
                       "(tf), not both")
    if "truth" not in kinds or truth_topic is not None or (picked.get("truth") and not named):
        return []
    tf = sorted(t for t, m in topics.items() if m == TF_TYPE and counts.get(t))
    if named and not tf:
        raise BagError("--truth-parent / --truth-child read tf, but the bag has no "
                       f"tf2_msgs/TFMessage topic; it has {_listing(topics)}")
    if tf:
        picked["truth"] = None
    return tf


def _tf_series(reader: AnyReader, topics: Sequence[str], recv_ns: np.ndarray,
               raws: Sequence[bytes], parent: str | None, child: str | None
               ) -> tuple[StampedSeries, tuple[str, str]] | None:
    """The reference poses in tf messages (:func:`drivers.bags.tf_truth`), or None."""
    store = reader.typestore
    decode = store.deserialize_cdr if reader.is2 else store.deserialize_ros1
    msgs = [decode(raw, TF_TYPE) for raw in raws]
    got = tf_truth(msgs, recv_ns, topics, parent=parent, child=child)
    if got is None:
        _log.info("tf holds none of the default reference frame pairs; no reference poses")
        return None
    t_ns, rows, pair, where = got
    return StampedSeries(", ".join(where), TF_TYPE, t_ns, _planar(rows)), pair


def _check(series: StampedSeries) -> None:
    """Finite values and stamps that never go backwards, or a one-line :class:`BagError`."""
    back = np.flatnonzero(np.diff(series.t_ns) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise BagError(f"topic {series.topic}: stamps go backwards at message {i} "
                       f"({(series.t_ns[i - 1] - series.t_ns[i]) / 1e9:.6f} s before the one "
                       "ahead of it); record with header stamps from one clock")
    bad = np.argwhere(~np.isfinite(series.values))
    if bad.size:
        i, j = (int(v) for v in bad[0])
        raise BagError(f"topic {series.topic}: message {i} has a {series.values[i, j]} in its "
                       f"{_column(series, j)}")


def _column(series: StampedSeries, j: int) -> str:
    for kind, types in TOPIC_TYPES.items():
        if series.msgtype in (*types, *((TF_TYPE,) if kind == "truth" else ())):
            return COLUMNS[kind][j]
    return f"column {j}"
