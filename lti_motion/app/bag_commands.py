"""``lti-motion calibrate / replay / monitor --bag``: the commands on a recorded ROS bag.

A bag is read with :func:`drivers.bags.read_bag` (topics found by message type,
or named) and turned into a :class:`~lti_motion.recordings.FrameLog` by
:func:`drivers.bags.bag_to_log`, the one conversion; from there each command
runs as it does on a log (``docs/guide_ros_bags.md``):

- :func:`calibrate_from_bag`: the ARX model from the whole drive (commands
  against the wheel-angle speeds; the last 30 % held out to choose order and
  delay). A bag holds no rotation in place next to a wall, so the encoder scale
  is the nominal one, ``wheel_radius_m / ticks_per_rad``. A bag without
  ``JointState`` wheel angles but with ``nav_msgs/Odometry`` (a robot that
  publishes only its odometry, as ``diff_drive_controller`` does) is calibrated
  on the odometry's twist as body speeds instead (:func:`odometry_recording`,
  then :func:`lti_motion.calibration.calibrate_recording`, as ``calibrate --log``);
- :func:`replay_bag`: the estimators against the bag's reference poses
  (``PoseStamped``) if it has any; TUM files, plots, and with ``out_bag`` the EKF's
  estimates as ``nav_msgs/Odometry`` with covariance in a new bag;
- :func:`monitor_bag`: the EKF and the residual monitor over the recorded drive,
  alarms printed with their bag time, and with ``out_bag`` the estimates and the
  alarms (``diagnostic_msgs/DiagnosticArray``) in a new bag.

In replay and monitor, a bag's ``sensor_msgs/Imu`` yaw rate (found by type, or
``--imu-topic``) is put on the frames (:func:`drivers.bags.bag_to_log`) and
fused by the EKF as a gyro (:mod:`fusion.ekf.gyro`, :class:`~fusion.noise.GyroNoise`
defaults) with ``BagOptions(gyro=True)`` (``--gyro``); by default the Imu is not read
(opt-in: on a hard floor with the default scale priors the gyro can cost accuracy,
``docs/ekf.md``).

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np

from drivers.bags import (
    CREATE2_TICKS_PER_RAD,
    CREATE2_WHEEL_RADIUS_M,
    TOPIC_TYPES,
    BagAlarm,
    StampedSeries,
    bag_to_log,
    bag_topics,
    read_bag,
    write_estimates_bag,
)
from drivers.exceptions import BagError
from fusion.monitoring import AlarmEvent, FrameResult
from fusion.noise import GyroNoise
from lti_motion.app.monitor import format_alarm, monitor_frames
from lti_motion.app.replay import ReplayResult, run_replay, twist_counts
from lti_motion.app.replay_sources import source_from_frame_log, source_from_grid
from lti_motion.calibration import speeds_from_log
from lti_motion.exceptions import MissingEncoderScaleError
from lti_motion.model import MotionModel, fit_arx
from lti_motion.recordings import FrameLog, Recording, SensorFrame, median_period_s, on_grid

__all__ = ["BagOptions", "BagRun", "calibrate_from_bag", "load_bag_log", "monitor_bag",
           "odometry_recording", "plot_bag_fit", "replay_bag"]


@dataclass(frozen=True)
class BagOptions:
    """How to read a robot's drive from a bag (the ``--bag`` options).

    Attributes
    ----------
    topics : dict of str to str
        Topic per kind (``cmd``, ``wheels``, ``odom``, ``imu``, ``truth``), where
        the bag holds several of a kind.
    left_joint, right_joint : str
        Joint-name patterns (:func:`drivers.bags.read_bag`).
    truth_parent, truth_child : str or None
        Reference poses from tf: the transform of this child frame in this parent
        frame (:func:`drivers.bags.read_bag`); default ``None``: tf only when the
        bag has no ``PoseStamped`` topic, with the default frames.
    ticks_per_rad : float
        Encoder counts per wheel radian (default the Create 2's).
    wheel_radius_m : float
        Nominal wheel radius [m] (default the Create 2's 0.036).
    dt_s : float or None
        Sensor period [s]; default from the stamps (calibrate) or the model's.
    encoders : {"commanded", "quadrature"}
        How the wheel angles count (:func:`lti_motion.calibration.speeds_from_log`):
        ``"commanded"`` (default) for a Roomba / Create 2, whose encoders count in
        the commanded direction; ``"quadrature"`` for encoders that know which way
        the wheel turns (most ROS robots).
    max_wheel_m_s : float
        Wheel speeds above this are refused as impossible [m/s]
        (:func:`drivers.bags.bag_to_log`).
    gyro : bool
        Replay and monitor: read the bag's Imu yaw rate and fuse it (``--gyro``;
        default ``False``: the Imu is not read).
    """

    topics: dict = field(default_factory=dict)
    left_joint: str = r"left"
    right_joint: str = r"right"
    truth_parent: str | None = None
    truth_child: str | None = None
    ticks_per_rad: float = CREATE2_TICKS_PER_RAD
    wheel_radius_m: float = CREATE2_WHEEL_RADIUS_M
    dt_s: float | None = None
    encoders: Literal["commanded", "quadrature"] = "commanded"
    max_wheel_m_s: float = 20.0
    gyro: bool = False


def load_bag_log(path: str | os.PathLike, *, wheel_base_m: float,
                 options: BagOptions | None = None,
                 kinds: Sequence[str] = ("cmd", "wheels", "odom", "imu", "truth")) -> FrameLog:
    """The drive in a bag as a log (:func:`drivers.bags.read_bag`, then ``bag_to_log``);
    only the topics of ``kinds`` are read.

    Raises
    ------
    FileNotFoundError, BagError
        From the reader and the conversion.
    """
    opt = options or BagOptions()
    rec = read_bag(path, left_joint=opt.left_joint, right_joint=opt.right_joint, kinds=kinds,
                   truth_parent=opt.truth_parent, truth_child=opt.truth_child,
                   **{f"{kind}_topic": topic for kind, topic in opt.topics.items()})
    return bag_to_log(rec, wheel_base_m=wheel_base_m, ticks_per_rad=opt.ticks_per_rad,
                      wheel_radius_m=opt.wheel_radius_m, dt_s=opt.dt_s,
                      max_wheel_m_s=opt.max_wheel_m_s)


def calibrate_from_bag(path: str | os.PathLike, *, wheel_base_m: float,
                       options: BagOptions | None = None, floor: str | None = None,
                       validation: float = 0.3) -> tuple[MotionModel, FrameLog]:
    """Calibrate an ARX model on the drive recorded in a bag.

    Parameters
    ----------
    path : str or path-like
        The bag.
    wheel_base_m : float
        Nominal wheel base [m].
    options : BagOptions, optional
        Topics, joints, encoder and wheel (default: found by type, Create 2).
    floor : str, optional
        Floor name recorded in the model.
    validation : float
        Held-out tail that chooses order and delay (paper section III.C).

    Returns
    -------
    model : MotionModel
        ARX, wheel-servo DC gain (:class:`~lti_motion.calibration.CalibrationPlan`),
        ``m_per_tick`` the nominal scale.
    log : FrameLog
        The drive it was fitted on.

    Raises
    ------
    BagError
        For a bag without wheel angles or commands (and the reader's errors).
    CalibrationError
        If the drive does not excite the model enough.
    """
    opt = options or BagOptions()
    log = load_bag_log(path, wheel_base_m=wheel_base_m, options=opt, kinds=("cmd", "wheels"))
    if not log.meta["has_commands"]:
        raise BagError(f"{Path(path).name} has no geometry_msgs/Twist or TwistStamped "
                       "commands; calibration needs what was commanded (record /cmd_vel)")
    cmd_m_s, speeds = speeds_from_log(log, m_per_tick=log.meta["m_per_tick"],
                                      wheel_base_m=wheel_base_m, encoders=opt.encoders)
    model = fit_arx([(cmd_m_s, speeds)], dt_s=log.dt_s, wheel_base_m=wheel_base_m,
                    m_per_tick=log.meta["m_per_tick"], floor=floor, validation=validation,
                    dc_gain="wheel_servo")
    return model, log


def odometry_recording(path: str | os.PathLike, *, options: BagOptions | None = None,
                       reference: bool = False) -> Recording | None:
    """The drive as body speeds from the bag's ``nav_msgs/Odometry`` twist, for a bag that
    has no ``sensor_msgs/JointState`` wheel angles; ``None`` when it has them (or no
    Odometry: :func:`calibrate_from_bag` then says what is missing).

    The twist ``(linear.x [m/s], angular.z [rad/s])`` of each message is the robot's own
    estimate of its body speeds over the time since its last message
    (``diff_drive_controller``'s ``/odom``); the commands are the bag's Twist topic. Both
    keep their stamps; :func:`lti_motion.recordings.on_grid` puts them on the sensor
    period's grid, as for any recording. With ``reference`` (replay), the reference poses
    (``PoseStamped`` or tf) and, with ``options.gyro``, the Imu's yaw rate come along;
    ``meta["bag_start_ns"]`` is the bag's first stamp.

    Raises
    ------
    FileNotFoundError, BagError
        The reader's errors; a bag with odometry and no commands.
    """
    opt = options or BagOptions()
    types = bag_topics(path).values()
    if (opt.topics.get("wheels") or TOPIC_TYPES["wheels"][0] in types
            or not any(t in TOPIC_TYPES["odom"] for t in types)):
        return None
    kinds = ("cmd", "odom") + (("truth",) + (("imu",) if opt.gyro else ()) if reference else ())
    rec = read_bag(path, kinds=kinds, truth_parent=opt.truth_parent,
                   truth_child=opt.truth_child,
                   **{f"{kind}_topic": opt.topics.get(kind) for kind in kinds})
    if rec.cmd is None:
        raise BagError(f"{Path(path).name} has no geometry_msgs/Twist or TwistStamped "
                       "commands; calibration needs what was commanded (record /cmd_vel)")

    def seconds(series: StampedSeries) -> np.ndarray:
        return (series.t_ns - rec.start_ns) * 1e-9

    t_s = seconds(rec.odom)
    extra = {}
    if rec.truth is not None:
        extra.update(true_pose_t_s=seconds(rec.truth), true_pose=rec.truth.values)
    if rec.imu is not None:
        extra.update(yaw_rate_t_s=seconds(rec.imu), yaw_rate_rad_s=rec.imu.values[:, 0])
    return Recording.from_streams(
        wheel_t_s=t_s, body_speeds=rec.odom.values[:, 3:5],
        dt_s=opt.dt_s if opt.dt_s is not None else median_period_s(t_s),
        cmd_t_s=seconds(rec.cmd), cmd_body=rec.cmd.values, rates="since_last", **extra,
        meta={"source": "ROS bag", "bag": str(Path(path)), "bag_start_ns": int(rec.start_ns),
              "topics": {"cmd": rec.cmd.topic, "odom": rec.odom.topic}})


def plot_bag_fit(model: MotionModel, log: FrameLog, path: str | os.PathLike, *,
                 seconds: float = 30.0,
                 encoders: Literal["commanded", "quadrature"] = "commanded") -> np.ndarray:
    """Plot the measured speeds of a bag's drive against the model's free run; return the fit.

    Parameters
    ----------
    model : MotionModel
    log : FrameLog
        The drive (its ``meta["m_per_tick"]`` scales the counts).
    path : str or path-like
        The PNG written.
    seconds : float
        How much of the drive is drawn [s] (the fit covers all of it).
    encoders : {"commanded", "quadrature"}
        As for :class:`BagOptions`.

    Returns
    -------
    ndarray, shape (2,)
        Free-run fit percentage of (v, w) over the whole drive
        (:func:`lti_motion.metrics.fit_percent`).
    """
    from matplotlib.figure import Figure

    from lti_motion.metrics import fit_percent

    cmd_m_s, speeds = speeds_from_log(log, m_per_tick=model.m_per_tick,
                                      wheel_base_m=model.wheel_base_m, encoders=encoders)
    predicted = model.simulate(cmd_m_s)
    fit = np.asarray(fit_percent(speeds, predicted, axis=0))
    n = min(len(speeds), round(seconds / log.dt_s))
    t = np.arange(n) * log.dt_s
    fig = Figure(figsize=(10, 5))
    axes = fig.subplots(2, 1, sharex=True)
    for ax, j, unit in ((axes[0], 0, "v [m/s]"), (axes[1], 1, "w [rad/s]")):
        ax.plot(t, speeds[:n, j], lw=0.8, label="from the wheel angles")
        ax.plot(t, predicted[:n, j], lw=0.8, label=f"model, free run (fit {fit[j]:.1f} %)")
        ax.set(ylabel=unit)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[1].set(xlabel="time [s]")
    axes[0].set_title("Calibrated from the bag: measured speeds and the model's free run")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return fit


def _bag_ns(start_ns: int, t_s: np.ndarray | float) -> np.ndarray:
    """Bag times [ns] of times [s] from the bag's first stamp ``start_ns`` [ns]."""
    return start_ns + np.rint(np.asarray(t_s) * 1e9).astype(np.int64)


def _twist_log(path: str | os.PathLike, model: MotionModel,
               options: BagOptions | None) -> FrameLog | None:
    """For a bag with an odometry twist and no wheel angles: the drive as a log of the counts
    the twist stands for (:func:`~lti_motion.app.replay.twist_counts`, never wrapping) on
    the model's period; ``None`` for a bag with wheel angles.

    Raises
    ------
    MissingEncoderScaleError
        If the model has no encoder scale to count the twist's travel in.
    """
    opt = options or BagOptions()
    rec = odometry_recording(path, options=replace(opt, dt_s=opt.dt_s or model.dt_s),
                             reference=True)
    if rec is None:
        return None
    if model.encoder_intrinsics is None:
        raise MissingEncoderScaleError(
            f"{Path(path).name} has an odometry twist and no wheel angles; monitoring it "
            "needs a model with an encoder scale to count the twist's travel in, and this "
            "one has none: calibrate with the rotation in place or from wheel angles")
    grid = on_grid(rec, wheel_base_m=model.wheel_base_m, max_wheel_speed_m_s=opt.max_wheel_m_s)
    src = source_from_grid(grid, Path(path).name, dt_s=rec.dt_s)
    n = len(src)
    return FrameLog(t_s=src.t_s, ticks=twist_counts(src, model.encoder_intrinsics),
                    cmd_m_s=src.cmd_m_s, light_bump=np.zeros((n, 6), np.int64),
                    bumps=np.zeros((n, 2), bool), valid=src.valid, dt_s=rec.dt_s,
                    yaw_rate_rad_s=src.yaw_rate_rad_s,
                    meta={**rec.meta, "counter_bits": 64,
                          "lost_frames": int(np.count_nonzero(~src.valid))})


def _model_log(path: str | os.PathLike, model: MotionModel,
               options: BagOptions | None) -> FrameLog:
    """The bag's drive on the model's period (unless a period is given), with the Imu's yaw
    rate unless ``options.gyro`` is false."""
    opt = options or BagOptions()
    if opt.dt_s is None:
        opt = replace(opt, dt_s=model.dt_s)
    kinds = ("cmd", "wheels", "odom", "truth") + (("imu",) if opt.gyro else ())
    return load_bag_log(path, wheel_base_m=model.wheel_base_m, options=opt, kinds=kinds)


def replay_bag(path: str | os.PathLike, model: MotionModel, out_dir: str | os.PathLike, *,
               options: BagOptions | None = None, out_bag: str | os.PathLike | None = None,
               estimators: Sequence[str] | None = None, start_s: float = 0.0,
               duration_s: float | None = None, initial_pose: Sequence[float] | None = None,
               rpe_s: float = 1.0, print_fn: Callable[[str], object] = print) -> ReplayResult:
    """``lti-motion replay --bag``: :func:`~lti_motion.app.replay.run_replay` on a bag's drive.

    The reference poses, from a ``PoseStamped`` topic or tf (:mod:`drivers.bags.tf`), are the truth
    the metrics compare against (the estimators start at the first one and never
    read them after). With ``out_bag``, the ``ekf`` estimator's poses and
    covariances go into a new bag (:func:`drivers.bags.write_estimates_bag`).

    Raises
    ------
    FileNotFoundError, BagError, FileExistsError
        A missing or unusable bag; an existing ``out_bag`` (checked first).
    """
    if out_bag is not None and Path(out_bag).exists():
        raise FileExistsError(f"{out_bag} exists; lti-motion never overwrites a bag, give a "
                              "new name")
    opt = options or BagOptions()
    odometry = odometry_recording(path, options=replace(opt, dt_s=opt.dt_s or model.dt_s),
                                  reference=True)
    if odometry is not None:            # the robot's own odometry twist, no wheel angles
        grid = on_grid(odometry, wheel_base_m=model.wheel_base_m,
                       max_wheel_speed_m_s=opt.max_wheel_m_s)
        src = source_from_grid(grid, Path(path).name, dt_s=odometry.dt_s, start_s=start_s,
                               duration_s=duration_s)
        start_ns = odometry.meta["bag_start_ns"]
    else:
        log = _model_log(path, model, options)
        if "imu_noise" in log.meta:
            print_fn(log.meta["imu_noise"]["summary"])
        src = source_from_frame_log(log, Path(path).name, start_s=start_s,
                                    duration_s=duration_s)
        start_ns = log.meta["bag_start_ns"]
    result = run_replay(src, model, out_dir, estimators=estimators, initial_pose=initial_pose,
                        rpe_s=rpe_s, gyro=(options or BagOptions()).gyro, print_fn=print_fn)
    if out_bag is not None:
        name = "ekf" if "ekf" in result.pose_covs else next(iter(result.pose_covs), None)
        if name is None:
            raise BagError("--out-bag writes the EKF's estimates; run the ekf estimator")
        written = write_estimates_bag(out_bag, _bag_ns(start_ns, src.t_s),
                                      result.poses[name], result.pose_covs[name],
                                      speeds=result.speeds[name], twist_covs=model.R)
        print_fn(f"wrote the {name} estimates (nav_msgs/Odometry with covariance) to {written}")
    return result


@dataclass(frozen=True)
class BagRun:
    """What :func:`monitor_bag` found: the alarms with their bag times, and the estimates.

    Attributes
    ----------
    events : tuple of AlarmEvent
        The alarms (filter times from the first frame).
    alarm_ns : ndarray of int64
        Each alarm's bag time [ns].
    t_ns : ndarray of int64, shape (n,)
        Bag time of each frame [ns].
    poses : ndarray, shape (n, 3)
    pose_covs : ndarray, shape (n, 3, 3)
    out_bag : Path or None
        The bag written.
    """

    events: tuple[AlarmEvent, ...]
    alarm_ns: np.ndarray
    t_ns: np.ndarray
    poses: np.ndarray
    pose_covs: np.ndarray
    out_bag: Path | None = None


def _frames(log: FrameLog):
    yaw = log.yaw_rate_rad_s
    for k in range(len(log)):
        yield SensorFrame(t_s=float(log.t_s[k]), ticks=log.ticks[k],
                          light_bump=log.light_bump[k], bumps=log.bumps[k],
                          cmd_m_s=log.cmd_m_s[k], valid=bool(log.valid[k]),
                          yaw_rate_rad_s=None if yaw is None else float(yaw[k]))


def monitor_bag(path: str | os.PathLike, model: MotionModel, *,
                options: BagOptions | None = None, out_bag: str | os.PathLike | None = None,
                nominal=None, print_fn: Callable[[str], object] = print) -> BagRun:
    """``lti-motion monitor --bag``: the EKF and the residual monitor over a recorded drive.

    Each alarm is printed as the live monitor prints it
    (:func:`~lti_motion.app.monitor.format_alarm`, times from the first frame),
    followed by its bag time. With ``out_bag`` the estimates and the alarms go
    into a new bag.

    Parameters
    ----------
    path : str or path-like
        The bag.
    model : MotionModel
        The calibrated model of this robot (its period is the frames').
    options : BagOptions, optional
    out_bag : str or path-like, optional
        New bag for the estimates and alarms (refused if it exists).
    nominal : NominalFit, optional
        Phase I: dynamics tests on (:func:`~lti_motion.app.monitor.monitor_frames`).

    Raises
    ------
    FileNotFoundError, BagError, FileExistsError, MissingEncoderScaleError
    """
    if out_bag is not None and Path(out_bag).exists():
        raise FileExistsError(f"{out_bag} exists; lti-motion never overwrites a bag, give a "
                              "new name")
    log = _twist_log(path, model, options) or _model_log(path, model, options)
    n = len(log)
    poses, covs, speeds = np.zeros((n, 3)), np.zeros((n, 3, 3)), np.zeros((n, 2))
    step = iter(range(n))

    def keep(result: FrameResult, cov: np.ndarray) -> None:
        k = next(step)
        poses[k], covs[k], speeds[k] = result.pose, cov, result.speeds

    t0 = float(log.t_s[0])

    def line(text: str) -> None:
        print_fn(text)

    def on_alarm(event: AlarmEvent) -> None:
        ns = int(_bag_ns(log.meta["bag_start_ns"], t0 + event.t_s))
        print_fn(f"      bag time {ns // 10**9}.{ns % 10**9:09d}")

    print_fn(f"monitoring {Path(path).name}: {n} frames ({n * log.dt_s:.1f} s, "
             f"{log.meta['lost_frames']} lost), topics {log.meta['topics']}")
    gyro = None
    if log.yaw_rate_rad_s is not None:
        noise = log.meta["imu_noise"]
        density = noise["density_rad_s_sqrt_hz"]
        gyro = GyroNoise() if density is None else GyroNoise(noise_density_rad_s_sqrt_hz=density)
        print_fn(f"the EKF fuses the yaw rate of {log.meta['topics']['imu']} as a gyro: "
                 f"{noise['summary']}")
    run = monitor_frames(model, _frames(log), nominal=nominal, on_alarm_line=line,
                         on_alarm=on_alarm, on_step=keep, counter_bits=log.counter_bits,
                         gyro=gyro)
    for text in run.summary():
        print_fn(text)
    start_ns = log.meta["bag_start_ns"]
    alarm_ns = np.array([int(_bag_ns(start_ns, t0 + e.t_s)) for e in run.events], np.int64)
    t_ns = _bag_ns(start_ns, log.t_s)
    written = None
    if out_bag is not None:
        alarms = [BagAlarm(int(ns), f"lti_motion/{e.kind}", format_alarm(e),
                           (("test", e.test), ("statistic", f"{e.statistic:.6g}"),
                            ("threshold", f"{e.threshold:.6g}"), ("onset_s", f"{e.onset_s:.3f}")))
                  for e, ns in zip(run.events, alarm_ns, strict=True)]
        written = write_estimates_bag(out_bag, t_ns, poses, covs, speeds=speeds,
                                      twist_covs=model.R, alarms=alarms)
        print_fn(f"wrote the estimates and {len(alarms)} alarms to {written}")
    return BagRun(tuple(run.events), alarm_ns, t_ns, poses, covs, written)
