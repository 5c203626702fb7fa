"""ROS bags in: a recorded drive as one :class:`~lti_motion.recordings.Recording`.

:func:`read_bag` finds the drive's topics by message type (or as named;
:mod:`drivers.bags.topics`) and gives them to the recording as they are, each
stream with its own stamps, in seconds from the bag's first stamp
(:attr:`RecordingSource.start_ns <lti_motion.recordings.RecordingSource.start_ns>`):

- the wheels: ``sensor_msgs/JointState`` angles of the left and right joint, as
  ``wheel_angles_rad``; a bag without them but with ``nav_msgs/Odometry`` gives the
  odometry's twist (``linear.x``, ``angular.z``) as ``body_speeds``, each the mean
  since the robot's previous message (``rates="since_last"``, as
  ``diff_drive_controller`` publishes it), a twist inconsistent with its neighbours
  left out and reported (:mod:`drivers.bags.twist_checks`, ``meta["twist_outliers"]``);
- the commands: the ``Twist`` / ``TwistStamped`` body speeds as ``cmd_body``
  (a bag without any: zeros, and the source lists no ``cmd`` topic);
- an Imu's yaw rate (its messages with an angular velocity;
  :mod:`drivers.bags.imu_noise`) with the noise density its covariance states;
- the reference poses (``PoseStamped`` or tf) as ``true_pose``.

:func:`bag_grid` puts the recording on the model's grid, the one path of every
recording (:func:`lti_motion.recordings.on_grid`), with the rule for bags: periods
from the stamps and the wheel travel (a message that jitter put on a lost neighbour's
period goes back to its own), the Imu and the reference blank across gaps longer than
``max_gap_s``, and an impossible wheel speed a one-line :class:`BagError` naming the
topic, the joint and the message.

Examples
--------
>>> import tempfile, pathlib
>>> from drivers.bags.writer import write_drive_bag
>>> from drivers.sim.simulator import Simulator
>>> log = Simulator("create2", seed=0).run(np.full((50, 2), 0.2))
>>> path = write_drive_bag(pathlib.Path(tempfile.mkdtemp()) / "drive.bag", log)
>>> rec = read_bag(path)
>>> rec.wheel_kind, rec.source.topics["wheel"], rec.source.topics["cmd"], len(rec)
('wheel_angles_rad', '/joint_states', '/cmd_vel', 50)
>>> grid = bag_grid(rec, wheel_base_m=0.235, wheel_radius_m=CREATE2_WHEEL_RADIUS_M)
>>> len(grid.closed), bool(np.allclose(grid.speeds[20:, 0], 0.2, atol=0.01))
(50, True)
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import replace
from pathlib import Path
from typing import Literal

import numpy as np

from drivers.bags.clocks import Stamps, choose_time_base
from drivers.bags.imu_noise import imu_rate_noise, with_rate_data
from drivers.bags.integrity import check_bag
from drivers.bags.topics import (
    LEFT_JOINT,
    RIGHT_JOINT,
    TOPIC_OPTIONS,
    TOPIC_TYPES,
    StampedSeries,
    read_topics,
)
from drivers.bags.twist_checks import drop_twist_outliers
from drivers.exceptions import BagError
from lti_motion.exceptions import WheelSpeedError
from lti_motion.recordings.clocks import median_period_s
from lti_motion.recordings.recording import Recording, RecordingSource
from lti_motion.recordings.resample import GridSignals, on_grid

__all__ = [
    "CREATE2_TICKS_PER_RAD",
    "CREATE2_WHEEL_RADIUS_M",
    "LEFT_JOINT",
    "MAX_GAP_S",
    "MAX_WHEEL_M_S",
    "RIGHT_JOINT",
    "TOPIC_OPTIONS",
    "TOPIC_TYPES",
    "bag_grid",
    "read_bag",
]

_log = logging.getLogger(__name__)

#: The Create 2's encoder: 508.8 counts per wheel turn (OI spec, packet 43) [ticks/rad].
CREATE2_TICKS_PER_RAD = 508.8 / (2.0 * math.pi)
#: The Create 2's nominal wheel radius [m] (72 mm diameter, OI spec).
CREATE2_WHEEL_RADIUS_M = 0.036
#: A wheel or wheel command faster than this is refused as impossible [m/s]: far beyond
#: any robot this library models, while encoder glitches of several hundred ticks still
#: pass, for the monitor to find.
MAX_WHEEL_M_S = 20.0
#: The Imu's yaw rate and the reference poses are blank across gaps longer than this [s].
MAX_GAP_S = 0.25


def _listing(topics) -> str:
    return ", ".join(f"{t} ({m})" for t, m in sorted(topics.items())) or "no topics"


def read_bag(path: str | os.PathLike, *, cmd_topic: str | None = None,
             wheels_topic: str | None = None, odom_topic: str | None = None,
             imu_topic: str | None = None, truth_topic: str | None = None,
             left_joint: str = LEFT_JOINT, right_joint: str = RIGHT_JOINT,
             truth_parent: str | None = None, truth_child: str | None = None,
             imu: bool = True, truth: bool = True, dt_s: float | None = None,
             stamps: Stamps = "auto", twist_outliers: Literal["drop", "keep"] = "drop"
             ) -> Recording:
    """The drive recorded in a bag, by the rule of the module docstring.

    The bag is opened once; only the topics needed are decoded.

    Parameters
    ----------
    path : str or path-like
        ROS 1 ``.bag`` file, or ROS 2 bag folder (or its ``.db3`` / ``.mcap`` file).
    cmd_topic, wheels_topic, odom_topic, imu_topic, truth_topic : str, optional
        The topic of each kind (:data:`TOPIC_TYPES`); needed only where the bag
        holds several of that kind. ``odom`` is read only without wheel angles.
    left_joint, right_joint : str
        Regular expressions (case-insensitive, searched) that pick exactly one
        joint each from the first ``JointState`` message, or the joints' names.
    truth_parent, truth_child : str, optional
        Reference poses from tf (:func:`drivers.bags.topics.read_topics`).
    imu, truth : bool
        Whether to read the Imu's yaw rate and the reference poses (calibration
        needs neither).
    dt_s : float, optional
        The nominal sensor period [s] (the wheel stream's); default the median
        interval of its stamps.
    stamps : {"auto", "header", "receive"}
        The time base of every topic (:func:`drivers.bags.choose_time_base`): the
        messages' header stamps, the bag's receive times, or (default) the header
        stamps unless the topics' clocks disagree by more than a wheel period. The
        check is in ``meta["clocks"]`` (its ``lines`` to print).
    twist_outliers : {"drop", "keep"}
        An odometry twist read as the wheels (no wheel angles): its messages
        inconsistent with their neighbours (:func:`drivers.bags.twist_outliers`) are
        left out (default), or kept and only reported (the monitor, whose tests look
        for such glitches); either way ``meta["twist_outliers"]`` lists them.

    Returns
    -------
    Recording
        Wheel angles [rad] (or the odometry twist), body-twist commands, with
        ``source`` (the bag, its first stamp, the topic of each stream, the joints,
        the tf frames) and, with an Imu, ``gyro_density_rad_s_sqrt_hz`` and
        ``meta["imu_noise"]`` (its summary line and message counts).

    Raises
    ------
    FileNotFoundError
        If there is no such bag.
    BagError
        A ``ValueError``: every error of :func:`drivers.bags.topics.read_topics`; no
        wheel angles nor odometry (the bag's topics listed); fewer than 2 wheel
        messages; stamps all equal and no ``dt_s``; a non-positive ``dt_s``; an Imu
        none of whose messages has an angular velocity; a damaged MCAP file
        (:func:`drivers.bags.check_bag`).
    """
    if dt_s is not None and not (math.isfinite(dt_s) and dt_s > 0):
        raise BagError(f"the sensor period must be positive, got {dt_s!r} s")
    check_bag(path)                 # a damaged file refused before any number is read
    kinds = ("cmd", "wheels", "odom") + (("imu",) if imu else ()) + (("truth",) if truth else ())
    found = read_topics(path, cmd_topic=cmd_topic, wheels_topic=wheels_topic,
                        odom_topic=odom_topic, imu_topic=imu_topic, truth_topic=truth_topic,
                        left_joint=left_joint, right_joint=right_joint,
                        truth_parent=truth_parent, truth_child=truth_child, kinds=kinds,
                        odom_without_wheels=True)
    kinds_read = {k: getattr(found, k) for k in ("cmd", "wheels", "odom", "imu", "truth")}
    on_base, clocks = choose_time_base(kinds_read, stamps=stamps)
    firsts = [int(s.t_ns[0]) for s in on_base.values() if s is not None and len(s)]
    found = replace(found, **on_base, start_ns=min(firsts) if firsts else found.start_ns)
    wheels = found.wheels if found.wheels is not None else found.odom
    outliers = None
    if found.wheels is None and wheels is not None:      # a driver's twist: a measurement
        kept, outliers = drop_twist_outliers(wheels, found.start_ns)
        wheels = kept if twist_outliers == "drop" else wheels
    if wheels is None:
        raise BagError(f"{Path(path).name} has no sensor_msgs/JointState wheel angles (nor a "
                       f"nav_msgs/Odometry twist); it has {_listing(found.topics)}")

    def seconds(series: StampedSeries) -> np.ndarray:
        return (series.t_ns - found.start_ns) * 1e-9

    t = seconds(wheels)
    if len(t) < 2:
        raise BagError(f"topic {wheels.topic} has {len(t)} message; a drive needs at least 2")
    if dt_s is None and not np.any(np.diff(t) > 0):
        raise BagError(f"topic {wheels.topic}: no sensor period in its stamps (all equal); "
                       "give the period with --dt")
    streams: dict = {"wheel": wheels.topic}
    if found.wheels is not None:
        wheel = {"wheel_angles_rad": wheels.values}
    else:                                   # the robot's own odometry: its twist
        wheel = {"body_speeds": wheels.values[:, 3:5], "rates": "since_last"}
    if found.cmd is not None:
        cmd = {"cmd_t_s": seconds(found.cmd), "cmd_body": found.cmd.values}
        streams["cmd"] = found.cmd.topic
    else:                                   # none recorded: zero, per frame
        cmd = {"cmd_body": np.zeros((len(t), 2))}
    extra, meta = {}, {"clocks": clocks.as_meta()}
    if outliers is not None:
        dropped = twist_outliers == "drop"
        meta["twist_outliers"] = {"topic": outliers.topic, "index": outliers.index.tolist(),
                                  "t_s": outliers.t_s.tolist(), "left_out": dropped,
                                  "lines": outliers.lines(left_out=dropped)}
    if found.truth is not None:
        extra.update(true_pose_t_s=seconds(found.truth), true_pose=found.truth.values)
        streams["true_pose"] = found.truth.topic
        meta["reference"] = {"topic": found.truth.topic, "type": found.truth.msgtype,
                             "frames": list(found.truth_frames or found.truth.frames)}
    if found.imu is not None:
        noise = imu_rate_noise(found.imu)
        rated = with_rate_data(found.imu)
        extra.update(yaw_rate_t_s=seconds(rated), yaw_rate_rad_s=rated.values[:, 0],
                     gyro_density_rad_s_sqrt_hz=noise.density_rad_s_sqrt_hz)
        streams["yaw_rate"] = found.imu.topic
        meta["imu_noise"] = {"variance_rad2_s2": noise.variance_rad2_s2,
                             "period_s": noise.period_s,
                             "messages": [noise.n_known, noise.n_unknown, noise.n_no_data],
                             "summary": noise.describe(found.imu.topic)}
    source = RecordingSource(path=str(path), kind="ROS bag", start_ns=found.start_ns,
                             topics=streams, wheel_names=found.joints,
                             truth_frames=found.truth_frames)
    rec = Recording.from_streams(wheel_t_s=t, dt_s=median_period_s(t) if dt_s is None else dt_s,
                                 **wheel, **cmd, **extra, source=source, meta=meta)
    _log.info("read %s: %d wheel messages on %s", path, len(rec), wheels.topic)
    return rec


def bag_grid(rec: Recording, *, wheel_base_m: float, wheel_radius_m: float | None = None,
             encoders: Literal["commanded", "quadrature"] = "quadrature",
             max_wheel_m_s: float = MAX_WHEEL_M_S, max_gap_s: float = MAX_GAP_S) -> GridSignals:
    """A bag's recording on the model's grid (:func:`lti_motion.recordings.on_grid`).

    Wheel angles find their periods by their stamps and travel
    (``periods_by="stamps_and_travel"``); the Imu's rate and the reference poses are
    blank across gaps longer than ``max_gap_s``.

    Parameters
    ----------
    rec : Recording
        From :func:`read_bag`.
    wheel_base_m : float
        Turns the body-twist commands into wheel commands [m].
    wheel_radius_m : float, optional
        Wheel radius [m]; needed for wheel angles.
    encoders : {"commanded", "quadrature"}
        How the wheel angles count (:func:`lti_motion.recordings.on_grid`).
    max_wheel_m_s : float
        A wheel or wheel command faster than this [m/s] is refused as impossible.
    max_gap_s : float
        Gaps in the Imu's and the reference's stamps longer than this [s] leave them
        blank.

    Returns
    -------
    GridSignals

    Raises
    ------
    BagError
        A wheel or wheel command faster than ``max_wheel_m_s``, naming the topic, the
        joint and the message; fewer than 2 wheel messages usable.
    ValueError
        For a non-positive ``wheel_base_m`` or ``wheel_radius_m``.
    """
    for name, value in (("wheel_base_m", wheel_base_m), ("wheel_radius_m", wheel_radius_m)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be positive, got {value!r}")
    angles = rec.wheel_kind in ("counts", "wheel_angles_rad")
    try:
        return on_grid(rec, wheel_base_m=wheel_base_m, wheel_radius_m=wheel_radius_m,
                       encoders=encoders, max_wheel_speed_m_s=max_wheel_m_s,
                       periods_by="stamps_and_travel" if angles else "stamps",
                       max_gap_s=max_gap_s)
    except WheelSpeedError as exc:
        raise BagError(_speed_message(rec, exc)) from exc
    except ValueError as exc:
        if rec.source is None:
            raise
        raise BagError(f"topic {rec.source.topics.get('wheel')}: {exc}") from exc


def _speed_message(rec: Recording, exc: WheelSpeedError) -> str:
    """One line naming the topic, the wheel (its joint) and the message of an impossible
    speed."""
    side = ("left", "right")[exc.side]
    src = rec.source
    if exc.field == rec.cmd_kind:
        topic = src.topics.get("cmd", "(no commands)") if src else rec.cmd_kind
        what, message = f"{side} wheel command", exc.sample + 1
    else:
        topic = src.topics.get("wheel", rec.wheel_kind) if src else rec.wheel_kind
        names = src.wheel_names if src else ()
        what = f"{names[exc.side] if names else side} wheel"
        message = exc.sample
    return (f"topic {topic}: the {what} moves at {exc.speed_m_s:.3g} m/s at message "
            f"{message} (t = {exc.t_s:.3f} s), more than {exc.limit_m_s:g} m/s "
            "(--max-wheel-speed): wrong joint, units, wheel radius or stamps")

