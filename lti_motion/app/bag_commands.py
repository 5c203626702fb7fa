"""``lti-motion calibrate / replay / monitor --bag``: the commands on a recorded ROS bag.

A bag is read once with :func:`drivers.bags.read_bag` (topics found by message type,
or named) into one :class:`~lti_motion.recordings.Recording`: wheel angles as
angles, the twist commands as a twist, the robot's odometry twist as body speeds
when it has no wheel angles. :func:`drivers.bags.bag_grid` puts it on the model's
grid once (:func:`lti_motion.recordings.on_grid`, the one path of every recording),
and each command runs on that grid (``docs/guide_ros_bags.md``):

- :func:`calibrate_from_bag`: the ARX model from the whole drive through
  :func:`lti_motion.calibration.calibrate_recording`, as ``calibrate --log`` (the
  excitation report; the last 30 % held out to choose order and delay). A bag holds
  no rotation in place next to a wall, so the encoder scale of wheel angles is the
  nominal one, ``wheel_radius_m / ticks_per_rad``, kept in the model
  (:attr:`OfflineCalibration.m_per_tick
  <lti_motion.calibration.OfflineCalibration.m_per_tick>`); a robot's odometry twist
  needs none;
- :func:`replay_bag`: the estimators against the bag's reference poses
  (``PoseStamped`` or tf) if it has any; TUM files, plots, and with ``out_bag`` the
  EKF's estimates as ``nav_msgs/Odometry`` with covariance in a new bag;
- :func:`monitor_bag`: the EKF and the residual monitor over the recorded drive,
  alarms printed with their bag time, and with ``out_bag`` the estimates and the
  alarms (``diagnostic_msgs/DiagnosticArray``) in a new bag.

In replay and monitor the wheels' travel on the grid is counted in the encoder's ticks
(``ticks_per_rad``; :func:`~lti_motion.app.replay_sources.source_from_wheel_grid`), what
the model's encoder scale reads (a twist: in the model's ticks,
:func:`~lti_motion.app.replay.twist_counts`), and a bag's ``sensor_msgs/Imu`` yaw
rate (found by type, or ``--imu-topic``), the mean over each period, is fused by the
EKF as a gyro (:mod:`fusion.ekf.gyro`, :class:`~fusion.noise.GyroNoise` defaults or
the density the Imu states) with ``BagOptions(gyro=True)`` (``--gyro``); by default
the Imu is not read (opt-in: on a hard floor with the default scale priors the gyro
can cost accuracy, ``docs/ekf.md``).

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np

from drivers.bags import (
    CREATE2_TICKS_PER_RAD,
    CREATE2_WHEEL_RADIUS_M,
    MAX_GAP_S,
    MAX_WHEEL_M_S,
    BagAlarm,
    bag_grid,
    read_bag,
    read_bag_urdf,
    urdf_wheels,
    write_estimates_bag,
)
from drivers.exceptions import BagError
from fusion.monitoring import AlarmEvent, FrameResult
from fusion.noise import GyroNoise
from lti_motion.app.monitor import format_alarm, monitor_frames
from lti_motion.app.recorded_health import HeldOut, check_period, held_out_span
from lti_motion.app.replay import ReplayResult, run_replay, twist_counts
from lti_motion.app.replay_sources import (
    ReplaySource,
    source_from_grid,
    source_from_wheel_grid,
)
from lti_motion.calibration import OfflineCalibration, calibrate_recording
from lti_motion.exceptions import MissingEncoderScaleError, RobotMismatchError
from lti_motion.model import MotionModel
from lti_motion.recordings import (
    GridSignals,
    Recording,
    SensorFrame,
    median_period_s,
    snap_period_s,
)
from lti_motion.robot_description import (
    ANGLE_COUNTS_PER_RAD,
    PERIOD_TOLERANCE,
    RobotDescription,
)

__all__ = ["NEED_COMMANDS", "BagOptions", "BagRun", "calibrate_from_bag", "check_commands",
           "load_bag_recording", "monitor_bag", "plot_bag_fit", "reading_lines",
           "reference_label", "replay_bag", "replay_source"]


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
    ticks_per_rad : float or None
        Encoder counts per wheel radian. ``None``: replay and monitor take the model's
        robot's (:attr:`MotionModel.robot <lti_motion.model.MotionModel.robot>`);
        calibration counts the angles in :data:`~lti_motion.robot_description.ANGLE_COUNTS_PER_RAD`.
    wheel_radius_m : float or None
        Nominal wheel radius [m]. ``None``: replay and monitor take the model's robot's;
        calibration on wheel angles refuses to guess one.
    dt_s : float or None
        Sensor period [s]; default from the stamps (checked against the model's in replay
        and monitor).
    encoders : {"commanded", "quadrature"} or None
        How the wheel angles count, for calibration (:func:`lti_motion.recordings.on_grid`):
        ``"commanded"`` for a Roomba / Create 2, whose encoders count in the commanded
        direction; ``"quadrature"`` (``None``: the default) for encoders that know which
        way the wheel turns (most ROS robots).
    max_wheel_m_s : float
        Wheel speeds above this are refused as impossible [m/s]
        (:func:`drivers.bags.bag_grid`).
    gyro : bool
        Replay and monitor: read the bag's Imu yaw rate and fuse it (``--gyro``;
        default ``False``: the Imu is not read).
    sources : dict of str to str
        Where ``ticks_per_rad``, ``wheel_radius_m`` and ``encoders`` came from, for the
        output (``{"wheel_radius_m": "--wheel-radius"}``).
    stamps : {"auto", "header", "receive"}
        The time base of every topic (``--stamps``, :func:`drivers.bags.choose_time_base`).
    """

    topics: dict = field(default_factory=dict)
    left_joint: str = r"left"
    right_joint: str = r"right"
    truth_parent: str | None = None
    truth_child: str | None = None
    ticks_per_rad: float | None = None
    wheel_radius_m: float | None = None
    dt_s: float | None = None
    encoders: Literal["commanded", "quadrature"] | None = None
    max_wheel_m_s: float = MAX_WHEEL_M_S
    gyro: bool = False
    sources: dict = field(default_factory=dict)
    stamps: Literal["auto", "header", "receive"] = "auto"

    @property
    def m_per_tick(self) -> float | None:
        """The nominal encoder scale of the wheel angles, ``wheel_radius_m / ticks_per_rad``
        [m/tick] (``ticks_per_rad`` defaulting to
        :data:`~lti_motion.robot_description.ANGLE_COUNTS_PER_RAD`), or ``None`` without a
        radius."""
        if self.wheel_radius_m is None:
            return None
        return self.wheel_radius_m / (self.ticks_per_rad or ANGLE_COUNTS_PER_RAD)


def load_bag_recording(path: str | os.PathLike, *, options: BagOptions | None = None,
                       imu: bool = True, truth: bool = True, dt_s: float | None = None,
                       twist_outliers: Literal["drop", "keep"] = "drop") -> Recording:
    """The drive in a bag as one recording (:func:`drivers.bags.read_bag` with the
    options' topics and joints); the Imu and the reference read only when asked.

    Raises
    ------
    FileNotFoundError, BagError
        From the reader.
    """
    opt = options or BagOptions()
    return read_bag(path, left_joint=opt.left_joint, right_joint=opt.right_joint,
                    truth_parent=opt.truth_parent, truth_child=opt.truth_child, imu=imu,
                    truth=truth, dt_s=opt.dt_s if dt_s is None else dt_s, stamps=opt.stamps,
                    twist_outliers=twist_outliers,
                    **{f"{kind}_topic": topic for kind, topic in opt.topics.items()})


def reading_lines(rec: Recording) -> list[str]:
    """What reading the bag found, to print: its clocks and time base
    (:func:`drivers.bags.choose_time_base`), and the odometry twists left out
    (:func:`drivers.bags.drop_twist_outliers`)."""
    return [*rec.meta.get("clocks", {}).get("lines", []),
            *rec.meta.get("twist_outliers", {}).get("lines", [])]


def _grid(rec: Recording, *, wheel_base_m: float, options: BagOptions,
          encoders: Literal["commanded", "quadrature"]) -> GridSignals:
    angles = rec.wheel_kind == "wheel_angles_rad"
    return bag_grid(rec, wheel_base_m=wheel_base_m,
                    wheel_radius_m=options.wheel_radius_m if angles else None,
                    encoders=encoders, max_wheel_m_s=options.max_wheel_m_s)


def check_commands(path: str | os.PathLike, rec: Recording) -> None:
    """Calibration needs what was commanded.

    Raises
    ------
    BagError
        One line, when the bag's drive has no commands.
    """
    if not rec.source.has("cmd"):
        raise BagError(f"{Path(path).name} has no geometry_msgs/Twist or TwistStamped "
                       "commands; calibration needs what was commanded (record /cmd_vel)")


def calibrate_from_bag(path: str | os.PathLike, *, wheel_base_m: float,
                       options: BagOptions | None = None, floor: str | None = None,
                       validation: float = 0.3, recording: Recording | None = None,
                       robot_name: str | None = None,
                       sources: Mapping[str, str] | None = None,
                       held_out: HeldOut | None = None
                       ) -> tuple[OfflineCalibration, Recording]:
    """Calibrate an ARX model on the drive recorded in a bag.

    The bag is read once, put on the grid once (:func:`drivers.bags.bag_grid`), and
    fitted through :func:`lti_motion.calibration.calibrate_recording`, as any recording.
    The model carries the robot it was fitted on
    (:class:`~lti_motion.robot_description.RobotDescription`: the wheel data, the
    encoders, counts per radian, the wheel radius, the wheel base and the period), which
    ``replay --bag`` and ``monitor --bag`` then read the bag with.

    Parameters
    ----------
    path : str or path-like
        The bag.
    wheel_base_m : float
        Nominal wheel base [m].
    options : BagOptions, optional
        Topics, joints, encoders and wheel radius: wheel angles need
        ``options.wheel_radius_m`` (counted in ``ticks_per_rad``, default
        :data:`~lti_motion.robot_description.ANGLE_COUNTS_PER_RAD`; encoders default
        ``"quadrature"``).
    floor : str, optional
        Floor name recorded in the model.
    validation : float
        Held-out tail that chooses order and delay (paper section III.C).
    recording : Recording, optional
        The bag's drive already read (:func:`load_bag_recording`), not read again.
    robot_name : str, optional
        The robot's name, kept in the model's robot description.
    sources : mapping of str to str, optional
        Where each number came from (``{"wheel_radius_m": "--wheel-radius"}``), kept too.
    held_out : HeldOut, optional
        The time span kept out of the fit, on which the model is measured
        (:func:`lti_motion.app.recorded_health.held_out_span`; default the last 20%).

    Returns
    -------
    calibration : OfflineCalibration
        The ARX model (wheel-servo DC gain; period the fitted one as the robot is
        configured, :func:`lti_motion.recordings.snap_period_s`, or ``options.dt_s``;
        its ``robot`` set), the excitation report, the grid it was fitted on, and the
        encoder scale ``m_per_tick``: the nominal ``wheel_radius_m / ticks_per_rad`` for
        wheel angles, ``None`` for an odometry twist.
    recording : Recording
        The drive as read.

    Raises
    ------
    BagError
        For a bag without wheel angles (nor odometry) or without commands, or wheel
        angles without a wheel radius (and the reader's errors).
    ValueError
        A ``options.dt_s`` further than 10 % from the wheel stamps' own period
        (:func:`lti_motion.app.recorded_health.check_period`); a held-out span outside
        the drive.
    NotExcitedError
        If the drive cannot identify the model (the reasons given).
    """
    opt = options or BagOptions()
    rec = recording if recording is not None else load_bag_recording(
        path, options=opt, imu=False, truth=False)
    check_commands(path, rec)
    t = rec.wheel.t_s
    check_period(opt.dt_s, median_period_s(t),
                 f"the median interval of the stamps on {rec.source.topics['wheel']}")
    angles = rec.wheel_kind == "wheel_angles_rad"
    if angles and opt.wheel_radius_m is None:
        raise BagError(f"{Path(path).name} holds wheel angles and no wheel radius was given: "
                       "give --wheel-radius M (or BagOptions(wheel_radius_m=...))")
    encoders = opt.encoders or "quadrature"
    ticks = opt.ticks_per_rad or ANGLE_COUNTS_PER_RAD
    grid = _grid(rec, wheel_base_m=wheel_base_m, options=opt, encoders=encoders)
    cal = calibrate_recording(
        rec, wheel_base_m=wheel_base_m, grid=grid, validation=validation, floor=floor,
        m_per_tick=opt.m_per_tick if angles else None,
        wheel_radius_m=opt.wheel_radius_m if angles else None, encoders=encoders,
        scale_from=("the nominal wheel radius / ticks per radian" if angles
                    else "the robot's odometry (body speeds)"),
        dt_s=snap_period_s(grid.period_s) if opt.dt_s is None else opt.dt_s,
        held_out_s=held_out_span(held_out or HeldOut(), float(t[-1] - t[0])))
    robot = RobotDescription(
        wheel_data=rec.wheel_kind, wheel_base_m=wheel_base_m, dt_s=cal.model.dt_s,
        encoders=encoders, ticks_per_rad=ticks if angles else None,
        wheel_radius_m=opt.wheel_radius_m if angles else None,
        robot=robot_name or Path(path).name, sources=dict(sources or {}))
    return replace(cal, model=cal.model.updated(robot=robot)), rec


def plot_bag_fit(model: MotionModel, grid: GridSignals, path: str | os.PathLike, *,
                 seconds: float = 30.0) -> np.ndarray:
    """Plot the measured speeds of a bag's drive against the model's free run; return the fit.

    Parameters
    ----------
    model : MotionModel
    grid : GridSignals
        The drive on the model's grid (:attr:`OfflineCalibration.grid
        <lti_motion.calibration.OfflineCalibration.grid>`, the one it was fitted on).
    path : str or path-like
        The PNG written.
    seconds : float
        How much of the drive is drawn [s] (the fit covers all of it).

    Returns
    -------
    ndarray, shape (2,)
        Free-run fit percentage of (v, w) over the whole drive
        (:func:`lti_motion.metrics.fit_percent`).
    """
    from matplotlib.figure import Figure

    from lti_motion.metrics import fit_percent

    cmd_m_s, speeds = grid.cmd_m_s, grid.speeds
    predicted = model.simulate(cmd_m_s)
    fit = np.asarray(fit_percent(speeds, predicted, axis=0))
    n = min(len(speeds), round(seconds / grid.period_s))
    t = np.arange(n) * grid.period_s
    fig = Figure(figsize=(10, 5))
    axes = fig.subplots(2, 1, sharex=True)
    for ax, j, unit in ((axes[0], 0, "v [m/s]"), (axes[1], 1, "w [rad/s]")):
        ax.plot(t, speeds[:n, j], lw=0.8, label="measured")
        ax.plot(t, predicted[:n, j], lw=0.8, label=f"model, free run (fit {fit[j]:.1f} %)")
        ax.set(ylabel=unit)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[1].set(xlabel="time [s]")
    axes[0].set_title("Calibrated from the bag: measured speeds and the model's free run")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return fit


def reference_label(rec: Recording) -> str:
    """What a bag's reference poses are, named by topic or tf frames: a robot's own odometry
    (a ``nav_msgs/Odometry`` topic, or frame ``odom``) is "the robot's odometry", never
    ground truth; a ``PoseWithCovarianceStamped`` a pose estimate (e.g. ``/amcl_pose``).

    Examples
    --------
    >>> from lti_motion.recordings import Recording
    >>> rec = Recording.from_streams(wheel_t_s=[0.0, 0.1], wheel_angles_rad=[[0, 0], [1, 1]],
    ...     cmd_body=[[0, 0], [0, 0]], meta={"reference": {"topic": "/odom",
    ...     "type": "nav_msgs/msg/Odometry", "frames": ["odom", "base_footprint"]}})
    >>> reference_label(rec)
    "the robot's odometry (/odom, nav_msgs/Odometry, odom -> base_footprint)"
    """
    ref = rec.meta.get("reference")
    if not ref:
        return "the reference poses"
    kind, frames = ref["type"].replace("/msg/", "/"), list(ref.get("frames") or ())
    pair = " -> ".join(f for f in frames if f) or "no frame named"
    where = (f"tf {pair}" if kind == "tf2_msgs/TFMessage" else f"{ref['topic']}, {kind}, {pair}")
    if kind == "nav_msgs/Odometry" or (frames and frames[0].lstrip("/") == "odom"):
        return f"the robot's odometry ({where})"
    if kind == "geometry_msgs/PoseWithCovarianceStamped":
        return f"the pose estimate ({where})"
    return f"the reference poses ({where})"


def _bag_ns(start_ns: int, t_s: np.ndarray | float) -> np.ndarray:
    """Bag times [ns] of times [s] from the bag's first stamp ``start_ns`` [ns]."""
    return start_ns + np.rint(np.asarray(t_s) * 1e9).astype(np.int64)


def _bag_robot(path: str | os.PathLike, model: MotionModel, opt: BagOptions, rec: Recording,
               print_fn: Callable[[str], object]) -> tuple[float | None, float | None]:
    """The wheel radius [m] and counts per radian the bag's wheel angles are read with: the
    flags' (or a robot file's), else the model's robot's; the bag checked against the
    model's robot (wheel data, period, and the geometry of its own ``/robot_description``)
    in one line naming both values, :class:`~lti_motion.exceptions.RobotMismatchError`."""
    name, robot = Path(path).name, model.robot
    if _off(rec.dt_s, model.dt_s) > PERIOD_TOLERANCE:
        raise RobotMismatchError(
            f"{name} has a sensor period of {rec.dt_s * 1e3:.4g} ms, the model "
            f"{model.dt_s * 1e3:.4g} ms (more than {PERIOD_TOLERANCE:.0%} apart): a model of "
            f"another robot? (--dt {model.dt_s:.6g} resamples the bag to the model's period)")
    angles = rec.wheel_kind == "wheel_angles_rad"
    given = {k: v for k, v in (("wheel_radius_m", opt.wheel_radius_m),
                               ("ticks_per_rad", opt.ticks_per_rad)) if v is not None}
    if robot is None:
        radius = given.get("wheel_radius_m", CREATE2_WHEEL_RADIUS_M)
        ticks = given.get("ticks_per_rad", CREATE2_TICKS_PER_RAD)
        if angles and len(given) < 2:
            print_fn(f"the model holds no robot description (a model file before version 3): "
                     f"the wheel angles are read with wheel radius {radius:g} m and "
                     f"{ticks:g} counts/rad ({'the Create 2s' if not given else 'given'} "
                     "values; --wheel-radius and --ticks-per-rad for another robot, or "
                     "recalibrate)")
        return radius, ticks
    urdf = read_bag_urdf(path)
    # the bag's wheel data are read whatever they are (a twist as the counts of the model's
    # scale): its period and its own geometry are checked
    bag = RobotDescription(wheel_data=robot.wheel_data, wheel_base_m=robot.wheel_base_m,
                           dt_s=rec.dt_s, encoders=robot.encoders,
                           wheel_radius_m=robot.wheel_radius_m)
    theirs = name
    if urdf is not None:
        wheels = urdf_wheels(urdf, source=f"{name}'s /robot_description")
        bag = replace(bag, wheel_base_m=wheels.wheel_separation_m,
                      wheel_radius_m=(wheels.wheel_radius_m,) * 2)
        theirs = f"{name}'s /robot_description"
    robot.check(bag, mine=f"the model's robot ({robot.robot})", theirs=theirs)
    radius = (robot.wheel_radius_m[0] + robot.wheel_radius_m[1]) / 2 if robot.wheel_radius_m \
        else None
    ticks = robot.ticks_per_rad
    print_fn(f"robot: {robot.describe()} (the model's)")
    for key, value in given.items():
        mine = radius if key == "wheel_radius_m" else ticks
        what = "wheel radius" if key == "wheel_radius_m" else "counts per radian"
        print_fn(f"{what} {value:g} from {opt.sources.get(key, 'the options')}, over the "
                 f"model's robot's {mine:g}" if mine is not None else
                 f"{what} {value:g} from {opt.sources.get(key, 'the options')}")
    radius = given.get("wheel_radius_m", radius)
    ticks = given.get("ticks_per_rad", ticks)
    return radius, ticks


def _off(a: float, b: float) -> float:
    return abs(a - b) / b


def _model_source(path: str | os.PathLike, model: MotionModel, options: BagOptions | None,
                  *, start_s: float = 0.0, duration_s: float | None = None,
                  print_fn: Callable[[str], object] = print,
                  twist_outliers: Literal["drop", "keep"] = "drop"
                  ) -> tuple[Recording, GridSignals, ReplaySource]:
    """The bag's drive read once, checked against the model's robot, on the model's grid
    once (with the Imu's yaw rate when ``options.gyro``), as the estimators' source: wheel
    angles as the encoder's counts (the angles times counts per radian, which the model's
    encoder scale turns into metres), a twist as body speeds."""
    opt = options or BagOptions()
    rec = load_bag_recording(path, options=opt, imu=opt.gyro, truth=True, dt_s=opt.dt_s,
                             twist_outliers=twist_outliers)
    radius, ticks = _bag_robot(path, model, opt, rec, print_fn)
    rec = replace(rec, dt_s=model.dt_s)
    opt = replace(opt, wheel_radius_m=radius, ticks_per_rad=ticks)
    # the counts go to the EKF as the robot's stream gives them: no unfolding
    grid = _grid(rec, wheel_base_m=model.wheel_base_m, options=opt, encoders="quadrature")
    name = Path(path).name
    if rec.wheel_kind == "body_speeds":          # the robot's own odometry twist
        src = source_from_grid(grid, name, dt_s=rec.dt_s, start_s=start_s,
                               duration_s=duration_s)
    else:                   # the encoder's own counts: the angles times ticks per radian
        first = np.flatnonzero(grid.assignment.keep & rec.wheel_valid)[0]
        src = source_from_wheel_grid(rec, grid, name, m_per_tick=(opt.m_per_tick,) * 2,
                                     wheel_base_m=model.wheel_base_m, dt_s=rec.dt_s,
                                     origin_m=tuple(rec.wheel.values[first] * opt.wheel_radius_m),
                                     start_s=start_s, duration_s=duration_s,
                                     max_gap_s=MAX_GAP_S)
    return rec, grid, src


def replay_source(path: str | os.PathLike, model: MotionModel, *,
                  options: BagOptions | None = None, start_s: float = 0.0,
                  duration_s: float | None = None,
                  print_fn: Callable[[str], object] | None = None
                  ) -> tuple[Recording, ReplaySource]:
    """The bag's drive as :func:`replay_bag` replays it: read once, checked against the
    model's robot, on the model's grid once, the estimators' source (a lost frame's yaw
    rate NaN: a new gyro window). ``print_fn`` receives the robot used (default: nothing
    printed).

    Raises
    ------
    FileNotFoundError, BagError
        From the reader and the grid.
    RobotMismatchError
        A bag of another robot than the model's (its period, wheel data or the geometry
        of its ``/robot_description``), both values named.
    """
    rec, _, src = _model_source(path, model, options, start_s=start_s, duration_s=duration_s,
                                print_fn=print_fn or (lambda _line: None))
    if src.yaw_rate_rad_s is not None:
        src = replace(src, yaw_rate_rad_s=np.where(src.valid, src.yaw_rate_rad_s, np.nan))
    return rec, src


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
    rec, src = replay_source(path, model, options=opt, start_s=start_s, duration_s=duration_s,
                             print_fn=print_fn)
    for line in reading_lines(rec):
        print_fn(line)
    if src.has_truth and initial_pose is None and not np.all(np.isfinite(src.truth[0])):
        late = float(src.t_s[np.flatnonzero(np.isfinite(src.truth[:, 0]))[0]] - src.t_s[0])
        print_fn(f"{reference_label(rec)} starts {late:.3f} s after the first wheel frame: "
                 "replaying from its first pose")
        rec, src = replay_source(path, model, options=opt, start_s=start_s + late,
                                 duration_s=None if duration_s is None else duration_s - late)
    if src.has_truth:
        src = replace(src, truth_label=reference_label(rec))
    if not rec.source.has("cmd"):
        estimators = _without_commands(path, src.available(), estimators, gyro=opt.gyro)
        print_fn(f"{Path(path).name} has no commands: replaying only the estimators that need "
                 f"none ({', '.join(estimators)})")
    if "imu_noise" in rec.meta:
        print_fn(rec.meta["imu_noise"]["summary"])
    result = run_replay(src, model, out_dir, estimators=estimators, initial_pose=initial_pose,
                        rpe_s=rpe_s, gyro=opt.gyro, print_fn=print_fn)
    if out_bag is not None:
        name = "ekf" if "ekf" in result.pose_covs else next(iter(result.pose_covs), None)
        if name is None:
            raise BagError("--out-bag writes the EKF's estimates; run the ekf estimator")
        frames = list((rec.meta.get("reference") or {}).get("frames") or ())
        frame_id = frames[0] if src.has_truth and frames and frames[0] else "odom"
        written = write_estimates_bag(out_bag, _bag_ns(rec.source.start_ns, src.t_s),
                                      result.poses[name], result.pose_covs[name],
                                      speeds=result.speeds[name], twist_covs=model.R,
                                      frame_id=frame_id)
        print_fn(f"wrote the {name} estimates (nav_msgs/Odometry with covariance, frame "
                 f"{frame_id}{', the reference' + chr(39) + 's' if src.has_truth else ''}) to "
                 f"{written}")
    return result


#: The estimators that predict from what was commanded (:data:`~lti_motion.app.replay.ESTIMATORS`).
NEED_COMMANDS = ("commands", "sensorless", "ekf", "ekf_landmarks")
_NO_COMMANDS = "the commands, a geometry_msgs/Twist or TwistStamped topic (e.g. /cmd_vel)"


def _bag_listing(path: str | os.PathLike) -> str:
    from drivers.bags import bag_topics

    return ", ".join(f"{t} ({m})" for t, m in sorted(bag_topics(path).items()))


def _without_commands(path: str | os.PathLike, available: Sequence[str],
                      asked: Sequence[str] | None, *, gyro: bool) -> list[str]:
    """The estimators to replay on a bag without commands: those asked for (or available)
    that need none; one that needs them is refused, naming it and the missing topic."""
    name = Path(path).name
    for est in asked or ():
        if est in NEED_COMMANDS:
            raise BagError(f"estimator {est!r} needs {_NO_COMMANDS}, which {name} does not "
                           f"have (it has {_bag_listing(path)}); estimators that need none: "
                           f"{', '.join(n for n in available if n not in NEED_COMMANDS)}")
    if gyro:
        raise BagError(f"--gyro fuses the Imu in estimator 'ekf', which needs {_NO_COMMANDS}; "
                       f"{name} has none (it has {_bag_listing(path)}): leave out --gyro")
    names = [n for n in (asked or available) if n not in NEED_COMMANDS]
    if not names:
        raise BagError(f"{name} has no commands and nothing an estimator without them reads "
                       f"(wheel angles or an odometry twist); it has {_bag_listing(path)}")
    return names


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


def _frames(src: ReplaySource, ticks: np.ndarray,
            yaw: np.ndarray | None) -> Iterator[SensorFrame]:
    """The source's frames as a robot's stream gives them (no light bumps, no bumpers)."""
    no_bumps, no_light = np.zeros(2, bool), np.zeros(6, np.int64)
    for k in range(len(src)):
        yield SensorFrame(t_s=float(src.t_s[k]), ticks=ticks[k], light_bump=no_light,
                          bumps=no_bumps, cmd_m_s=src.cmd_m_s[k], valid=bool(src.valid[k]),
                          yaw_rate_rad_s=None if yaw is None else float(yaw[k]))


def monitor_bag(path: str | os.PathLike, model: MotionModel, *,
                options: BagOptions | None = None, out_bag: str | os.PathLike | None = None,
                nominal=None, print_fn: Callable[[str], object] = print) -> BagRun:
    """``lti-motion monitor --bag``: the EKF and the residual monitor over a recorded drive.

    Each alarm is printed as the live monitor prints it
    (:func:`~lti_motion.app.monitor.format_alarm`, times from the first frame),
    followed by its bag time. With ``out_bag`` the estimates and the alarms go
    into a new bag. The wheels' travel goes in as the encoder's counts (a twist's as the
    counts of the model's scale, :func:`~lti_motion.app.replay.twist_counts`).

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
    rec, _, src = _model_source(path, model, options, print_fn=print_fn, twist_outliers="keep")
    if not rec.source.has("cmd"):
        raise BagError(f"monitor --bag needs {_NO_COMMANDS}: each of its tests compares the "
                       "wheels with the model's prediction from what was commanded, and "
                       f"{Path(path).name} has none (it has {_bag_listing(path)}); 'replay "
                       "--bag --estimators odometry' runs without them")
    if src.ticks is not None:
        ticks, yaw = src.ticks, src.yaw_rate_rad_s
    else:                                        # a twist: the counts it stands for
        if model.encoder_intrinsics is None:
            raise MissingEncoderScaleError(
                f"{Path(path).name} has an odometry twist and no wheel angles; monitoring it "
                "needs a model with an encoder scale to count the twist's travel in, and "
                "this one has none: calibrate with the rotation in place or from wheel angles")
        ticks, yaw = twist_counts(src, model.encoder_intrinsics), src.yaw_rate_rad_s
    n = len(src)
    poses, covs, speeds = np.zeros((n, 3)), np.zeros((n, 3, 3)), np.zeros((n, 2))
    step = iter(range(n))

    def keep(result: FrameResult, cov: np.ndarray) -> None:
        k = next(step)
        poses[k], covs[k], speeds[k] = result.pose, cov, result.speeds

    t0 = float(src.t_s[0])
    start_ns = rec.source.start_ns

    def on_alarm(event: AlarmEvent) -> None:
        ns = int(_bag_ns(start_ns, t0 + event.t_s))
        print_fn(f"      bag time {ns // 10**9}.{ns % 10**9:09d}")

    lost = int(np.count_nonzero(~src.valid))
    print_fn(f"monitoring {Path(path).name}: {n} frames ({n * src.dt_s:.1f} s, {lost} lost), "
             f"topics {dict(rec.source.topics)}")
    for line in reading_lines(rec):
        print_fn(line)
    gyro = None
    if yaw is not None:
        density = rec.gyro_density_rad_s_sqrt_hz
        gyro = GyroNoise() if density is None else GyroNoise(noise_density_rad_s_sqrt_hz=density)
        print_fn(f"the EKF fuses the yaw rate of {rec.source.topics['yaw_rate']} as a gyro: "
                 f"{rec.meta['imu_noise']['summary']}")
    run = monitor_frames(model, _frames(src, ticks, yaw), nominal=nominal,
                         on_alarm_line=print_fn, on_alarm=on_alarm, on_step=keep,
                         counter_bits=64, gyro=gyro)
    for text in run.summary():
        print_fn(text)
    alarm_ns = np.array([int(_bag_ns(start_ns, t0 + e.t_s)) for e in run.events], np.int64)
    t_ns = _bag_ns(start_ns, src.t_s)
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
