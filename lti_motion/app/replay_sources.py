"""Recorded drives for ``lti-motion replay``: NPZ logs, recordings on the model's grid (a
ROS bag's) and MRCLAM robots as one source type.

See :mod:`lti_motion.app.replay` for what is read from each kind of
recording, and ``docs/replay.md``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Hashable
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType

import numpy as np

from drivers.datasets import MrclamDataset, MrclamRobot, load_mrclam
from drivers.exceptions import DatasetError
from fusion.landmark_map import LandmarkMap
from fusion.noise import LandmarkNoise
from fusion.range_bearing import RangeBearing
from lti_motion.exceptions import LogFileError, MissingEncoderScaleError, RobotMismatchError
from lti_motion.kinematics import wheel_from_body
from lti_motion.model import MotionModel
from lti_motion.recordings import (
    FrameLog,
    GridSignals,
    Recording,
    commands_at,
    frame_stamps,
    load_log,
    load_recording,
    poses_at,
    stream_clock,
)
from lti_motion.robot_description import PERIOD_TOLERANCE, WHEEL_DATA, RobotDescription

__all__ = [
    "ESTIMATORS",
    "MRCLAM_LANDMARK_NOISE",
    "ReplaySource",
    "fit_mrclam_model",
    "load_source",
    "source_from_frame_log",
    "source_from_grid",
    "source_from_log",
    "source_from_mrclam",
    "source_from_recording",
    "source_from_wheel_grid",
]

_log = logging.getLogger(__name__)

ESTIMATORS = MappingProxyType({
    "odometry": "encoder odometry",
    "commands": "commands at face value",
    "sensorless": "model, sensor-less",
    "ekf": "EKF, model and encoders",
    "ekf_landmarks": "EKF, model, encoders (if any), landmarks",
})

#: Sighting noise for MRCLAM: the spread of set 6's sightings against Vicon
#: (median range error 7-13 cm at 3.7 m, bearing 0.4-1.4 degrees; 90% within
#: 0.3 m and 2 degrees); the filter's chi-square gate rejects the outliers.
MRCLAM_LANDMARK_NOISE = LandmarkNoise(range_std_frac=0.05, range_std_m=0.05,
                                      bearing_std_rad=0.02)


@dataclass(frozen=True)
class ReplaySource:
    """One robot's recorded drive, as the estimators see it (plus the truth for metrics).

    Attributes
    ----------
    name : str
        What it is, for people (file name, or data set and robot).
    t_s : ndarray, shape (n,)
        Frame times [s].
    periods : ndarray of int, shape (n,)
        Sensor periods each frame closes (frame 0: 0; more than 1 after lost frames).
    cmd_m_s : ndarray, shape (n, 2)
        Wheel commands (left, right) of the periods each frame closes [m/s].
    valid : ndarray of bool, shape (n,)
        Frames whose sensor readings arrived (not a frame whose counts are NaN
        in the log: the next valid counts span the gap, as after a lost frame).
    dt_s : float
        Sensor period [s].
    ticks : ndarray of int64, shape (n, 2), or None
        Raw encoder counts; ``None`` for a data set without encoders.
    counter_bits : int
        Width of the counters [bits] (16: the Open Interface's; the log's
        :attr:`~lti_motion.recordings.FrameLog.counter_bits`).
    yaw_rate_rad_s : ndarray, shape (n,), or None
        A gyro's reading over the period each frame closes [rad/s] (the log's
        :attr:`~lti_motion.recordings.FrameLog.yaw_rate_rad_s`); ``None`` without a gyro.
    gyro_density_rad_s_sqrt_hz : float or None
        The gyro's white-noise density the recording states [rad/s/sqrt(Hz)] (a
        bag Imu's ``angular_velocity_covariance``, :mod:`drivers.bags.imu_noise`);
        ``None``: not stated.
    truth_label : str
        What the reference poses are, for people: ``"ground truth"`` (a simulator's, a
        data set's motion capture), or a bag's topic or tf frames and what they are
        (``"the robot's odometry (/odom, nav_msgs/Odometry, frame odom)"``).
    body_speeds : ndarray, shape (n, 2), or None
        Measured body speeds (v [m/s], w [rad/s]) of the period each frame closes, for a
        robot that records its own odometry's twist and no wheel readings
        (:func:`source_from_grid`); ``None`` otherwise.
    truth : ndarray, shape (n, 3), or None
        Reference poses (x [m], y [m], theta [rad]); NaN rows where none.
    sightings : RangeBearing
        Landmark observations, ``index`` = frame index (none: empty).
    landmarks : LandmarkMap or None
        Landmark positions, when the source has sightings.
    landmark_noise : LandmarkNoise or None
        Sighting noise for the filter (``None``: the filter's default).
    """

    name: str
    t_s: np.ndarray
    periods: np.ndarray
    cmd_m_s: np.ndarray
    valid: np.ndarray
    dt_s: float
    ticks: np.ndarray | None = None
    truth: np.ndarray | None = None
    sightings: RangeBearing = field(default_factory=RangeBearing.empty)
    landmarks: LandmarkMap | None = None
    landmark_noise: LandmarkNoise | None = None
    counter_bits: int = 16
    yaw_rate_rad_s: np.ndarray | None = None
    gyro_density_rad_s_sqrt_hz: float | None = None
    body_speeds: np.ndarray | None = None
    truth_label: str = "ground truth"

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def has_truth(self) -> bool:
        """Whether some frames have ground truth."""
        return self.truth is not None and bool(np.any(np.isfinite(self.truth[:, 0])))

    def label(self, name: str) -> str:
        """What estimator ``name`` is on this source, for tables and plots."""
        gyro = self.yaw_rate_rad_s is not None          # both EKFs fuse it
        wheels = {"encoder counts": "encoders", "odometry twist": "odometry twist",
                  None: None}[self.wheel_readings]
        if name == "ekf_landmarks":
            return ((f"EKF, model, {wheels}, landmarks" if wheels
                     else "EKF, model and landmarks") + (", gyro" if gyro else ""))
        if name == "ekf":
            return f"EKF, model, {wheels} and gyro" if gyro else f"EKF, model and {wheels}"
        if name == "odometry" and self.ticks is None:
            return "the robot's odometry (twist)"
        return ESTIMATORS[name]

    @property
    def wheel_readings(self) -> str | None:
        """What the source measured of the wheels: ``"encoder counts"``, ``"odometry
        twist"`` or ``None``."""
        return ("encoder counts" if self.ticks is not None else
                "odometry twist" if self.body_speeds is not None else None)

    def available(self) -> list[str]:
        """The estimators this source can feed."""
        names = ["commands", "sensorless"]
        if self.wheel_readings is not None:
            names = ["odometry", *names, "ekf"]
        if self.landmarks is not None and self.sightings:
            names.append("ekf_landmarks")
        return names


def _window(t_s: np.ndarray, start_s: float, duration_s: float | None) -> np.ndarray:
    rel = t_s - t_s[0]
    keep = rel >= start_s
    if duration_s is not None:
        keep &= rel <= start_s + duration_s
    if keep.sum() < 2:
        raise ValueError(f"--start-s {start_s:g} / --duration-s {duration_s} leave fewer than 2 "
                         f"frames of a {rel[-1]:.1f} s recording")
    return np.flatnonzero(keep)


def _periods(t_s: np.ndarray, dt_s: float) -> np.ndarray:
    try:
        k = np.rint((stream_clock(t_s, dt_s) - t_s[0]) / dt_s).astype(np.int64)
    except ValueError as exc:                 # host clock bursts: one period a frame
        _log.warning("frame times do not follow the %.3f s period (%s); one period per frame",
                     dt_s, exc)
        k = np.arange(len(t_s))
    return np.concatenate([[0], np.diff(k)])


def source_from_log(path: str | os.PathLike, *, robot: int | None = None, start_s: float = 0.0,
                    duration_s: float | None = None) -> ReplaySource:
    """Read an ``lti-motion-log`` file as a :class:`ReplaySource`.

    Parameters
    ----------
    path : str or path-like
        The ``.npz`` log.
    robot : int, optional
        Robot index of a batch log (default 0); only 0 (or None) for a single robot.
    start_s, duration_s : float
        The stretch to replay, from the first frame [s].

    Raises
    ------
    FileNotFoundError, LogFileError
        From :func:`lti_motion.recordings.load_log`.
    ValueError
        For a robot index out of range, an empty stretch, or two frames with
        the same time (the TUM files need increasing times).
    """
    log = load_log(path)
    name = Path(path).name
    if log.n_robots is None and robot not in (None, 0):
        raise ValueError(f"{name} holds one robot's drive; there is no robot {robot} (leave "
                         "out --robot)")
    if log.n_robots is not None:
        i = 0 if robot is None else robot
        if not 0 <= i < log.n_robots:
            raise ValueError(f"{name} holds robots 0-{log.n_robots - 1}; there is no robot {i}")
        log, name = log.robot(i), f"{name} robot {i}"
    return source_from_frame_log(log, name, start_s=start_s, duration_s=duration_s)


def source_from_frame_log(log: FrameLog, name: str, *, start_s: float = 0.0,
                          duration_s: float | None = None) -> ReplaySource:
    """One robot's :class:`FrameLog` (a loaded log, a ROS bag's drive) as a :class:`ReplaySource`.

    Parameters
    ----------
    log : FrameLog
        One robot's frames.
    name : str
        What it is, for people.
    start_s, duration_s : float
        The stretch to replay, from the first frame [s].

    Raises
    ------
    ValueError
        For an empty stretch, or two frames with the same time.
    """
    keep = _window(log.t_s, start_s, duration_s)
    repeat = np.flatnonzero(np.diff(log.t_s[keep]) <= 0)      # load_log refused earlier times
    if repeat.size:
        k = int(keep[repeat[0] + 1])
        raise ValueError(f"{name}: frame {k} has the time of frame {k - 1} (t_s = "
                         f"{log.t_s[k]:.6f} s); replay needs increasing frame times")
    meta = log.meta
    landmarks, sightings = None, RangeBearing.empty()
    if meta.get("landmarks") and meta.get("observations"):
        landmarks = LandmarkMap({_key(row[0]): (row[1], row[2]) for row in meta["landmarks"]})
        first = int(keep[0])
        rows = [(int(frame) - first, _key(key), r, b)
                for frame, key, r, b in meta["observations"]
                if 1 <= int(frame) - first < len(keep)]
        if rows:
            k, ids, r, b = zip(*rows, strict=True)
            sightings = RangeBearing(list(k), ids, r, b)
    periods = _periods(log.t_s[keep], log.dt_s)
    counted = np.all(np.isfinite(log.ticks[keep]), axis=-1)     # a NaN count: a lost reading
    if not counted.all():
        _log.warning("%s: %d frames have no encoder counts (NaN); replayed as lost frames",
                     name, int(np.count_nonzero(~counted)))
    return ReplaySource(name=name, t_s=log.t_s[keep], periods=periods,
                        cmd_m_s=log.cmd_m_s[keep], valid=log.valid[keep] & counted,
                        dt_s=log.dt_s,
                        ticks=np.where(counted[:, None], log.ticks[keep], 0).astype(np.int64),
                        truth=None if log.true_pose is None else log.true_pose[keep],
                        sightings=sightings, landmarks=landmarks,
                        counter_bits=log.counter_bits,
                        yaw_rate_rad_s=(None if log.yaw_rate_rad_s is None else np.where(
                            log.valid[keep], log.yaw_rate_rad_s[keep], np.nan)),
                        gyro_density_rad_s_sqrt_hz=(meta.get("imu_noise") or {}).get(
                            "density_rad_s_sqrt_hz"))


def source_from_grid(grid: GridSignals, name: str, *, dt_s: float, start_s: float = 0.0,
                     duration_s: float | None = None) -> ReplaySource:
    """A recording of body speeds on the model's grid (:func:`lti_motion.recordings.on_grid`)
    as a :class:`ReplaySource`: one frame per period, the measured body speeds in
    :attr:`ReplaySource.body_speeds`.

    For a robot that records its own odometry's twist and no wheel readings
    (``diff_drive_controller``'s ``/odom``). The first period's end is the first frame
    (the estimators' start); a period inside a gap of the odometry keeps the gap's
    mean speed and is marked not valid (the EKF does not fuse it, odometry integrates it).

    Parameters
    ----------
    grid : GridSignals
        The recording on the grid.
    name : str
        What it is, for people.
    dt_s : float
        The nominal sensor period the grid was built on [s] (the model's).
    start_s, duration_s : float
        The stretch to replay, from the first frame [s].

    Raises
    ------
    ValueError
        For an empty stretch.
    """
    keep = _window(grid.t_s, start_s, duration_s)
    periods = np.ones(len(keep), np.int64)
    periods[0] = 0
    truth = None if grid.true_pose is None else grid.true_pose[keep]
    yaw = None if grid.yaw_rate_rad_s is None else grid.yaw_rate_rad_s[keep]
    return ReplaySource(name=name, t_s=grid.t_s[keep], periods=periods,
                        cmd_m_s=grid.cmd_m_s[keep], valid=grid.measured[keep], dt_s=dt_s,
                        truth=truth, yaw_rate_rad_s=yaw, body_speeds=grid.speeds[keep])


def source_from_wheel_grid(rec: Recording, grid: GridSignals, name: str, *,
                           m_per_tick: tuple[float, float], wheel_base_m: float, dt_s: float,
                           origin_m: tuple[float, float] = (0.0, 0.0), start_s: float = 0.0,
                           duration_s: float | None = None,
                           max_gap_s: float | None = None) -> ReplaySource:
    """A recording of wheel measurements on the model's grid as a :class:`ReplaySource`
    of encoder counts: one frame per period ``0 .. P``, as the robot's own stream gives them.

    The wheels' travel over each period (the grid's body speeds through ``wheel_base_m``,
    times the fitted period), summed from frame 0 on from ``origin_m``, is counted in whole
    ticks of
    ``m_per_tick``, never wrapping (``counter_bits`` 64): what the EKF's encoder update
    reads, so a reading the gate rejects keeps its motion. Frame ``k`` closes period
    ``k``, is stamped on the host's typical arrival line (the clock line plus the
    frames' median latency) and is valid when a wheel frame closed the period
    (:attr:`GridSignals.closed <lti_motion.recordings.GridSignals.closed>`); its
    command is the period's. The reference poses are read at the stamp of the frame
    that closed each period, else on the arrival line (:func:`lti_motion.recordings.poses_at`);
    the yaw rate is the period's mean (NaN for frame 0, which closes no period).

    Parameters
    ----------
    rec : Recording
        The recording the grid was made from (for its reference and its stamps).
    grid : GridSignals
        ``rec`` on the grid (:func:`lti_motion.recordings.on_grid`), with
        ``wheel_base_m``.
    name : str
        What it is, for people.
    m_per_tick : tuple of 2 float
        Each wheel's scale of the counts [m/tick], in the metres of the grid: for wheel
        angles the radius the grid used over the encoder's ticks per radian, so the
        counts are the encoder's own and the model's encoder scale reads them.
    wheel_base_m : float
        The wheel base the grid was made with [m].
    dt_s : float
        The nominal sensor period [s] (the model's).
    origin_m : tuple of 2 float
        Each wheel's travel at frame 0 [m] (a wheel angle times the radius), so the
        counts round as the encoder's own would.
    start_s, duration_s : float
        The stretch to replay, from the first frame [s].
    max_gap_s : float, optional
        Reference poses blank across gaps in their stamps longer than this [s].

    Raises
    ------
    ValueError
        For an empty stretch.
    """
    a, clock = grid.assignment, grid.assignment.clock
    n = len(grid.t_s) + 1
    t = clock.times_s(np.arange(n)) + clock.latency_median_s           # arrival line
    wheel = wheel_from_body(grid.speeds, wheel_base_m=wheel_base_m) * grid.period_s
    travel = np.vstack([np.zeros((1, 2)), np.cumsum(wheel, axis=0)]) + np.asarray(origin_m)
    ticks = np.rint(travel / np.asarray(m_per_tick, dtype=float)).astype(np.int64)
    first = commands_at(rec, a, np.zeros(1, np.int64))
    if rec.cmd_kind == "cmd_body":
        first = wheel_from_body(first, wheel_base_m=wheel_base_m)
    cmd = np.vstack([first, grid.cmd_m_s])
    truth = None
    if rec.true_pose is not None:
        # a pose belongs to its frame's own stamp
        truth = poses_at(rec.true_pose, frame_stamps(rec, a), max_gap_s=max_gap_s)
    yaw = (None if grid.yaw_rate_rad_s is None
           else np.concatenate([[np.nan], grid.yaw_rate_rad_s]))
    keep = _window(t, start_s, duration_s)
    periods = np.ones(len(keep), np.int64)
    periods[0] = 0
    return ReplaySource(name=name, t_s=t[keep], periods=periods, cmd_m_s=cmd[keep],
                        valid=grid.closed[keep], dt_s=dt_s, ticks=ticks[keep],
                        truth=None if truth is None else truth[keep], counter_bits=64,
                        yaw_rate_rad_s=None if yaw is None else yaw[keep],
                        gyro_density_rad_s_sqrt_hz=rec.gyro_density_rad_s_sqrt_hz)


def _key(value: object) -> Hashable:
    """Landmark ids come back from JSON as numbers or strings; whole numbers become int."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value if isinstance(value, Hashable) else str(value)


def _mrclam_robot(path: str | os.PathLike, robot: int) -> tuple[MrclamDataset, MrclamRobot]:
    """The data set and one of its robots; :class:`DatasetError` naming the robots it holds."""
    dataset = load_mrclam(path)
    if robot not in dataset.robots:
        raise DatasetError(f"{Path(path).name} holds robots {sorted(dataset.robots)}; there is "
                           f"no robot {robot}")
    return dataset, dataset.robots[robot]


def source_from_mrclam(path: str | os.PathLike, *, robot: int, dt_s: float,
                       wheel_base_m: float, start_s: float = 0.0,
                       duration_s: float | None = None, max_gap_s: float = 0.25
                       ) -> ReplaySource:
    """One MRCLAM robot on a uniform grid of ``dt_s``, as a :class:`ReplaySource`.

    Parameters
    ----------
    path : str or path-like
        The data set folder (e.g. ``MRCLAM_Dataset6``).
    robot : int
        Robot number (1-5).
    dt_s : float
        Grid step [s]: the model's sample period.
    wheel_base_m : float
        Turns MRCLAM's body-speed commands (v, w) into wheel commands [m]:
        the model's wheel base, so it reads them as it was calibrated.
    start_s, duration_s : float
        The stretch to replay, from the start of the overlap of commands and truth [s].
    max_gap_s : float
        Ground truth is blank (NaN) across Vicon gaps longer than this [s].

    Raises
    ------
    DatasetError
        For a missing or malformed file, or a robot the data set does not hold.
    """
    dataset, rec = _mrclam_robot(path, robot)
    cmd, gt = rec.commands, rec.groundtruth
    t0, t1 = max(cmd[0, 0], gt[0, 0]), min(cmd[-1, 0], gt[-1, 0])
    grid = np.arange(t0, t1, dt_s)
    keep = _window(grid, start_s, duration_s)
    t = grid[keep]
    idx = np.clip(np.searchsorted(cmd[:, 0], t, side="right") - 1, 0, len(cmd) - 1)
    wheels = wheel_from_body(cmd[idx, 1:], wheel_base_m=wheel_base_m)
    truth = np.column_stack([np.interp(t, gt[:, 0], gt[:, 1]), np.interp(t, gt[:, 0], gt[:, 2]),
                             np.interp(t, gt[:, 0], np.unwrap(gt[:, 3]))])
    j = np.clip(np.searchsorted(gt[:, 0], t), 1, len(gt) - 1)
    truth[gt[j, 0] - gt[j - 1, 0] > max_gap_s] = np.nan          # inside a Vicon gap
    frame = np.rint((rec.sightings[:, 0] - t[0]) / dt_s).astype(np.int64)
    inside = (frame >= 1) & (frame < len(t))
    sightings = RangeBearing(frame[inside], rec.sightings[inside, 1].astype(np.int64),
                             rec.sightings[inside, 2], rec.sightings[inside, 3])
    landmarks = LandmarkMap({k: v[:2] for k, v in dataset.landmarks.items()})
    return ReplaySource(name=f"{Path(path).name} robot {robot}", t_s=t,
                        periods=np.concatenate([[0], np.ones(len(t) - 1, np.int64)]),
                        cmd_m_s=wheels, valid=np.ones(len(t), bool), dt_s=dt_s, truth=truth,
                        sightings=sightings, landmarks=landmarks,
                        landmark_noise=MRCLAM_LANDMARK_NOISE)


def fit_mrclam_model(path: str | os.PathLike, *, robot: int, dt_s: float = 0.1
                     ) -> tuple[MotionModel, float]:
    """Calibrate an ARX model of an MRCLAM robot on the first half of its run only.

    As the MRCLAM experiment does (:mod:`lti_motion.app.mrclam`):
    commands to the body speeds differentiated from Vicon, wheel base 0.258 m.
    Replay from the returned time on, so no figure is measured on data the
    model was fitted to.

    Returns
    -------
    model : MotionModel
        The ARX model (``m_per_tick`` None: MRCLAM has no encoders).
    second_half_s : float
        Start of the second half from the start of the replay grid
        (:func:`source_from_mrclam`'s ``start_s``) [s].

    Raises
    ------
    DatasetError
        For a missing or malformed file, or a robot the data set does not hold.
    """
    from drivers.datasets import CREATE1_WHEEL_BASE_M, resample_robot
    from lti_motion.app.mrclam import split_halves
    from lti_motion.model import fit_arx

    _, rec = _mrclam_robot(path, robot)
    segments = resample_robot(rec, dt_s=dt_s)
    train, _ = split_halves(segments, min_samples=round(2.0 / dt_s))
    runs = [(wheel_from_body(s.commands_vw, wheel_base_m=CREATE1_WHEEL_BASE_M), s.speeds_vw)
            for s in train]
    model = fit_arx(runs, dt_s=dt_s, wheel_base_m=CREATE1_WHEEL_BASE_M)
    t0 = max(rec.commands[0, 0], rec.groundtruth[0, 0])
    t_mid = 0.5 * (segments[0].t_s[0] + segments[-1].t_s[-1])
    return model, float(t_mid - t0)


def load_source(path: str | os.PathLike, model: MotionModel, *, robot: int | None = None,
                start_s: float = 0.0, duration_s: float | None = None) -> ReplaySource:
    """A log file or an MRCLAM folder (``robot`` 1-5, default 1), whichever ``path`` is.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If it is neither a log nor an MRCLAM folder (the message says what was expected).
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such log file or data set folder: {path}")
    if path.is_dir():
        if not (path / "Barcodes.dat").is_file():
            raise DatasetError(f"{path} is a folder but not an MRCLAM data set (no "
                               "Barcodes.dat); give an .npz log or an MRCLAM_Dataset folder")
        return source_from_mrclam(path, robot=1 if robot is None else robot, dt_s=model.dt_s,
                                  wheel_base_m=model.wheel_base_m, start_s=start_s,
                                  duration_s=duration_s)
    try:
        rec = load_recording(path)
    except LogFileError:                    # a batch of robots, or damage: said below
        rec = None
    if rec is not None and not _frames(rec):    # not Roomba frames: onto the model's grid
        if robot not in (None, 0):
            raise ValueError(f"{path.name} holds one robot's drive; there is no robot "
                             f"{robot} (leave out --robot)")
        return source_from_recording(rec, model, path.name, start_s=start_s,
                                     duration_s=duration_s)
    src = source_from_log(path, robot=robot, start_s=start_s, duration_s=duration_s)
    if model.robot is not None:             # Roomba / simulator frames: 16-bit-like counts
        model.robot.check(RobotDescription(
            wheel_data="counts", wheel_base_m=model.robot.wheel_base_m, dt_s=src.dt_s,
            encoders=model.robot.encoders,
            counter_bits=None if src.counter_bits >= 63 else src.counter_bits),
            mine=f"the model's robot ({model.robot.robot})", theirs=path.name)
    return src


def _frames(rec: Recording) -> bool:
    """Whether a recording is Roomba / simulator frames (:meth:`Recording.to_frame_log`)."""
    try:
        rec.to_frame_log()
    except ValueError:
        return False
    return True


def source_from_recording(rec: Recording, model: MotionModel, name: str, *,
                          start_s: float = 0.0, duration_s: float | None = None
                          ) -> ReplaySource:
    """A version-2 recording of any differential drive (wheel angles, wheel or body speeds,
    counts with stamped commands) as a :class:`ReplaySource` on the model's grid
    (:func:`lti_motion.recordings.on_grid`), its wheels counted in the model's encoder scale,
    as a bag's are (:mod:`lti_motion.app.bag_commands`).

    Raises
    ------
    RobotMismatchError
        A recording of another robot than the model's (period beyond
        :data:`~lti_motion.robot_description.PERIOD_TOLERANCE`; another kind of wheel data).
    ValueError
        Wheel angles or speeds [rad/s] and a model without a robot description giving the
        wheel radius; counts and a model without an encoder scale.
    """
    from lti_motion.recordings import on_grid

    robot = model.robot
    if abs(rec.dt_s - model.dt_s) > PERIOD_TOLERANCE * model.dt_s:
        raise RobotMismatchError(
            f"{name} has a sensor period of {rec.dt_s * 1e3:.4g} ms, the model "
            f"{model.dt_s * 1e3:.4g} ms (more than {PERIOD_TOLERANCE:.0%} apart): a model of "
            "another robot?")
    if robot is not None and robot.wheel_data != rec.wheel_kind and not (
            rec.wheel_kind == "body_speeds" or robot.wheel_data == "body_speeds"):
        raise RobotMismatchError(f"{name} has {WHEEL_DATA[rec.wheel_kind]}, the model's robot "
                                 f"({robot.robot}) {WHEEL_DATA[robot.wheel_data]}")
    rec = replace(rec, dt_s=model.dt_s)
    if rec.wheel_kind == "body_speeds":
        grid = on_grid(rec, wheel_base_m=model.wheel_base_m)
        return source_from_grid(grid, name, dt_s=model.dt_s, start_s=start_s,
                                duration_s=duration_s)
    scale = model.encoder_intrinsics
    if scale is None:
        raise MissingEncoderScaleError.needed_by(f"replaying the wheels of {name}")
    m_per_tick = (scale.m_per_tick_left, scale.m_per_tick_right)
    radius = None
    if rec.wheel_kind in ("wheel_angles_rad", "wheel_speeds_rad_s"):
        if robot is None or robot.wheel_radius_m is None:
            raise ValueError(f"{name} holds {WHEEL_DATA[rec.wheel_kind]} and the model holds "
                             "no wheel radius (a model file before version 3): calibrate it "
                             "on this robot with 'lti-motion calibrate --log --wheel-radius'")
        radius = sum(robot.wheel_radius_m) / 2
    grid = on_grid(rec, wheel_base_m=model.wheel_base_m,
                   m_per_tick=model.m_per_tick if rec.wheel_kind == "counts" else None,
                   wheel_radius_m=radius,
                   periods_by="stamps_and_travel" if rec.wheel_kind in (
                       "counts", "wheel_angles_rad") else "stamps")
    return source_from_wheel_grid(rec, grid, name, m_per_tick=m_per_tick,
                                  wheel_base_m=model.wheel_base_m, dt_s=model.dt_s,
                                  start_s=start_s, duration_s=duration_s)


