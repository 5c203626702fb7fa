"""One recording type for any differential-drive robot.

A :class:`Recording` holds what a drive of any differential-drive robot
leaves behind, each signal as a *stream* with its own host timestamps:

- commands, as wheel speeds (left, right) [m/s] or as a body twist
  (v [m/s], w [rad/s]) (e.g. ROS ``/cmd_vel``), either stamped when sent or
  one per wheel frame;
- wheel measurements, exactly one kind of: raw counts of any counter width
  (wrapping or not), wheel angles [rad] (e.g. ``JointState.position``),
  wheel speeds [rad/s] or [m/s], or body speeds (v, w) from the robot's own
  odometry;
- optional: a yaw rate from an IMU [rad/s] (with the gyro's noise density when the
  source states it), a ground-truth pose, landmark sightings with the sensor's pose
  on the robot;
- where it came from (:class:`RecordingSource`): a ROS bag's path, the clock epoch
  of its times, the topic of each stream, the wheels' joint names and the frames of
  a reference taken from tf.

The wheel stream sets the model's grid: its frames are assigned to the robot's
sensor periods by :func:`lti_motion.recordings.assign_periods`, and
:func:`lti_motion.recordings.on_grid` turns every stream into per-period
commands and body speeds, the inputs of calibration and what the EKF fuses.
A :class:`~lti_motion.recordings.FrameLog` (the Roomba / simulator frames)
converts with :meth:`Recording.from_frame_log`.

Units are SI: seconds, metres, radians.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Literal

import numpy as np

from lti_motion.exceptions import ShapeError
from lti_motion.recordings.frames import FrameLog

__all__ = ["COMMAND_KINDS", "STREAMS", "WHEEL_KINDS", "Recording", "RecordingSource", "Stream"]

#: The kinds of wheel measurement, and the unit of their two columns.
WHEEL_KINDS = MappingProxyType({
    "counts": "ticks (left, right)",
    "wheel_angles_rad": "rad (left, right)",
    "wheel_speeds_rad_s": "rad/s (left, right)",
    "wheel_speeds_m_s": "m/s (left, right)",
    "body_speeds": "(v [m/s], w [rad/s])",
})
#: The kinds of command, and the unit of their two columns.
COMMAND_KINDS = MappingProxyType({
    "cmd_wheel_m_s": "m/s (left, right)",
    "cmd_body": "(v [m/s], w [rad/s])",
})

#: The streams of a recording, as :attr:`RecordingSource.topics` names them.
STREAMS = ("wheel", "cmd", "yaw_rate", "true_pose", "sightings")

WheelKind = Literal["counts", "wheel_angles_rad", "wheel_speeds_rad_s", "wheel_speeds_m_s",
                    "body_speeds"]
CommandKind = Literal["cmd_wheel_m_s", "cmd_body"]


@dataclass(frozen=True)
class Stream:
    """One timestamped signal.

    Attributes
    ----------
    t_s : ndarray, shape (m,)
        Host timestamps [s], never decreasing.
    values : ndarray, shape (m, c)
        One row per timestamp, in the unit of the stream's kind.
    """

    t_s: np.ndarray
    values: np.ndarray


@dataclass(frozen=True)
class RecordingSource:
    """Where a recording came from, for people and for times outside the recording.

    Attributes
    ----------
    path : str
        The file or folder read (a ROS bag).
    kind : str
        What it is, e.g. ``"ROS bag"``.
    start_ns : int
        Unix time [ns] of the recording's time 0: a time ``t_s`` of any stream is
        ``start_ns + t_s * 1e9`` on the source's clock (a bag's first stamp).
    topics : Mapping of str to str
        The topic (or channel) each stream of :data:`STREAMS` was read from; a
        stream not listed was not recorded (a ``cmd`` missing: the recording's
        commands are zeros standing in for none).
    wheel_names : tuple of str
        The (left, right) joints of the wheel stream, ``()`` when not named.
    truth_frames : tuple of str
        The (parent, child) frames of a reference taken from tf, else ``()``.

    Examples
    --------
    >>> src = RecordingSource(path="drive.bag", kind="ROS bag", start_ns=10**18,
    ...                       topics={"wheel": "/joint_states", "cmd": "/cmd_vel"})
    >>> src.has("cmd"), src.has("true_pose"), src.topics["wheel"]
    (True, False, '/joint_states')
    """

    path: str
    kind: str
    start_ns: int = 0
    topics: Mapping[str, str] = field(default_factory=dict)
    wheel_names: tuple[str, ...] = ()
    truth_frames: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        unknown = set(self.topics) - set(STREAMS)
        if unknown:
            raise ValueError(f"RecordingSource.topics: unknown streams {sorted(unknown)}; "
                             f"known: {', '.join(STREAMS)}")
        if len(self.wheel_names) not in (0, 2) or len(self.truth_frames) not in (0, 2):
            raise ValueError("RecordingSource: wheel_names and truth_frames are pairs (left, "
                             f"right), (parent, child) or empty, got {self.wheel_names} and "
                             f"{self.truth_frames}")
        object.__setattr__(self, "topics", MappingProxyType(dict(self.topics)))
        object.__setattr__(self, "start_ns", int(self.start_ns))

    def has(self, stream: str) -> bool:
        """Whether the source recorded ``stream`` (one of :data:`STREAMS`)."""
        return stream in self.topics


def _stream(name: str, t_s: object, values: object, columns: int) -> Stream:
    """A checked stream: finite increasing stamps, numeric values of the right width."""
    t = np.asarray(t_s, dtype=float)
    v = np.asarray(values)
    if v.dtype.kind not in "iuf" and v.size:
        raise ValueError(f"{name} must hold numbers, got {v.dtype}")
    v = v.astype(np.int64 if v.dtype.kind in "iu" else float)
    if columns == 1 and v.ndim == 1:
        v = v[:, None]
    if t.ndim != 1 or v.shape != (t.size, columns):
        raise ShapeError(f"{name} must have shape ({t.size}, {columns}) to match its "
                         f"{t.size} timestamps, got {v.shape}")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise ValueError(f"{name}: timestamp {int(bad[0])} is not finite ({t[bad[0]]})")
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        k = int(back[0]) + 1
        raise ValueError(f"{name}: timestamps go backwards at sample {k} ({t[k]:.6f} s after "
                         f"{t[k - 1]:.6f} s)")
    return Stream(t_s=t, values=v)


def _one_of(name: str, given: dict[str, object]) -> tuple[str, object]:
    chosen = [(k, v) for k, v in given.items() if v is not None]
    if len(chosen) != 1:
        raise ValueError(f"give exactly one {name} ({', '.join(given)}), got "
                         f"{[k for k, _ in chosen] or 'none'}")
    return chosen[0]


@dataclass(frozen=True)
class Recording:
    """A drive of any differential-drive robot, one stream per signal.

    Build it with :meth:`from_streams` (any robot, e.g. a ROS bag's topics)
    or :meth:`from_frame_log` (Roomba, simulator); turn it into the model's
    per-period signals with :func:`lti_motion.recordings.on_grid`.

    Attributes
    ----------
    dt_s : float
        Nominal sensor period of the wheel stream [s] (the model's period).
    wheel : Stream
        Wheel measurements, shape ``(n, 2)``, of kind ``wheel_kind``.
    wheel_kind : str
        One of :data:`WHEEL_KINDS`.
    wheel_valid : ndarray of bool, shape (n,)
        ``False`` for a wheel frame lost on the way (its values are ignored;
        the next valid frame's values span the gap).
    cmd : Stream
        Commands, shape ``(m, 2)``, of kind ``cmd_kind``.
    cmd_kind : str
        One of :data:`COMMAND_KINDS`.
    cmd_per_frame : bool
        ``True`` when ``cmd`` holds one command per wheel frame, in effect
        for the period that frame closes (``cmd.t_s`` is then ``wheel.t_s``).
    counter_bits : int or None
        Width of a wrapping counter (16 for a Roomba); ``None`` when counts
        do not wrap. Used only for ``wheel_kind == "counts"``.
    yaw_rate : Stream or None
        IMU yaw rate, shape ``(m, 1)`` [rad/s].
    true_pose : Stream or None
        Ground truth (x [m], y [m], heading [rad]), shape ``(m, 3)``.
    sightings : Stream or None
        Landmark sightings (id, range [m], bearing [rad]), shape ``(m, 3)``,
        measured by a sensor at ``sensor_pose`` on the robot.
    sensor_pose : tuple of 3 float
        Sightings' sensor pose on the robot (x [m] forward, y [m] left,
        heading [rad]).
    light_bump, bumps : ndarray or None
        Roomba only, optional: light-bump signals ``(n, 6)`` and bumper flags
        ``(n, 2)`` of each wheel frame.
    meta : dict
        Free-form JSON-serialisable description.
    rates : {"samples", "since_last"}
        For wheel speeds and body speeds: ``"samples"``, readings of the rate at their
        stamps (a wheel-speed sensor); ``"since_last"``, each the mean rate over the
        time since the previous frame (an odometry twist, as ``diff_drive_controller``
        publishes it: travel over the update interval divided by it).
    gyro_density_rad_s_sqrt_hz : float or None
        The white-noise density of ``yaw_rate`` the source states
        [rad/s/sqrt(Hz)] (a ROS Imu's ``angular_velocity_covariance``); ``None``:
        not stated.
    source : RecordingSource or None
        Where the recording came from (``None``: not said).
    """

    dt_s: float
    wheel: Stream
    wheel_kind: WheelKind
    wheel_valid: np.ndarray
    cmd: Stream
    cmd_kind: CommandKind
    cmd_per_frame: bool = False
    counter_bits: int | None = None
    yaw_rate: Stream | None = None
    true_pose: Stream | None = None
    sightings: Stream | None = None
    sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    light_bump: np.ndarray | None = None
    bumps: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    rates: Literal["samples", "since_last"] = "samples"
    gyro_density_rad_s_sqrt_hz: float | None = None
    source: RecordingSource | None = None

    def __len__(self) -> int:
        """Number of wheel frames."""
        return self.wheel.t_s.size

    @classmethod
    def from_streams(
        cls, *, wheel_t_s: np.ndarray, dt_s: float | None = None,
        counts: np.ndarray | None = None, counter_bits: int | None = None,
        wheel_angles_rad: np.ndarray | None = None,
        wheel_speeds_rad_s: np.ndarray | None = None,
        wheel_speeds_m_s: np.ndarray | None = None, body_speeds: np.ndarray | None = None,
        valid: np.ndarray | None = None, cmd_t_s: np.ndarray | None = None,
        cmd_wheel_m_s: np.ndarray | None = None, cmd_body: np.ndarray | None = None,
        yaw_rate_t_s: np.ndarray | None = None, yaw_rate_rad_s: np.ndarray | None = None,
        true_pose_t_s: np.ndarray | None = None, true_pose: np.ndarray | None = None,
        sightings_t_s: np.ndarray | None = None, sightings: np.ndarray | None = None,
        sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0), meta: dict | None = None,
        rates: Literal["samples", "since_last"] = "samples",
        gyro_density_rad_s_sqrt_hz: float | None = None,
        source: RecordingSource | None = None,
    ) -> Recording:
        """A recording from timestamped arrays, one wheel kind and one command kind.

        Parameters
        ----------
        wheel_t_s : array_like, shape (n,)
            Host stamps of the wheel measurements [s], never decreasing.
        dt_s : float, optional
            Nominal sensor period [s]; by default the median stamp interval.
        counts, wheel_angles_rad, wheel_speeds_rad_s, wheel_speeds_m_s, body_speeds : \
array_like, shape (n, 2)
            Exactly one: raw counts [ticks], wheel angles [rad], wheel speeds
            [rad/s] or [m/s] (left, right), or body speeds (v [m/s], w [rad/s]).
        counter_bits : int, optional
            Width of a wrapping counter (``counts`` only); ``None``: no wrap.
        valid : array_like of bool, shape (n,), optional
            ``False`` for wheel frames to ignore (lost on the way). A frame
            whose values are not finite (NaN: the reading did not arrive) is
            ignored the same way.
        cmd_t_s : array_like, shape (m,), optional
            Stamps of the commands when they were sent [s]; ``None``: one
            command per wheel frame, in effect for the period it closes.
        cmd_wheel_m_s, cmd_body : array_like, shape (m, 2)
            Exactly one: wheel commands (left, right) [m/s] or a body twist
            (v [m/s], w [rad/s]).
        yaw_rate_t_s, yaw_rate_rad_s : array_like, shape (m,), optional
            IMU yaw rate and its stamps.
        true_pose_t_s, true_pose : array_like, shapes (m,) and (m, 3), optional
            Ground truth (x [m], y [m], heading [rad]) and its stamps.
        sightings_t_s, sightings : array_like, shapes (m,) and (m, 3), optional
            Landmark sightings (id, range [m], bearing [rad]) and their stamps.
        sensor_pose : tuple of 3 float
            The sighting sensor's pose on the robot (x [m], y [m], heading [rad]).
        meta : dict, optional
            Free-form JSON-serialisable description.
        rates : {"samples", "since_last"}
            What a speed kind's values are (:attr:`rates`; default readings at their
            stamps).
        gyro_density_rad_s_sqrt_hz : float, optional
            The yaw rate's white-noise density [rad/s/sqrt(Hz)], when the source
            states it (needs ``yaw_rate_rad_s``).
        source : RecordingSource, optional
            Where the recording came from.

        Returns
        -------
        Recording

        Raises
        ------
        ValueError
            If not exactly one wheel kind or command kind is given, a stamp
            is not finite or goes backwards, or a command is not finite (the
            message names the stream),
            or ``counter_bits`` is not 1..64, or a gyro density is given without a
            yaw rate or is not a non-negative number.
        ShapeError
            If an array's shape does not match its stamps.

        Examples
        --------
        A robot reporting wheel angles at 50 Hz, driven by /cmd_vel at 10 Hz:

        >>> t = np.arange(100) * 0.02
        >>> rec = Recording.from_streams(
        ...     wheel_t_s=t, wheel_angles_rad=np.outer(t, [5.0, 5.0]),
        ...     cmd_t_s=t[::5], cmd_body=np.tile([0.1, 0.0], (20, 1)))
        >>> rec.wheel_kind, rec.cmd_kind, len(rec), round(rec.dt_s, 6)
        ('wheel_angles_rad', 'cmd_body', 100, 0.02)
        """
        kind, values = _one_of("wheel measurement", {
            "counts": counts, "wheel_angles_rad": wheel_angles_rad,
            "wheel_speeds_rad_s": wheel_speeds_rad_s, "wheel_speeds_m_s": wheel_speeds_m_s,
            "body_speeds": body_speeds})
        wheel = _stream(kind, wheel_t_s, values, 2)
        if wheel.t_s.size < 2:
            raise ValueError(f"{kind}: a recording needs at least 2 wheel frames, got "
                             f"{wheel.t_s.size}")
        if kind == "counts" and counter_bits is not None and not 1 <= counter_bits <= 64:
            raise ValueError(f"counter_bits must be 1..64 (16 for a Roomba), got {counter_bits}")
        period = float(np.median(np.diff(wheel.t_s))) if dt_s is None else float(dt_s)
        if not (np.isfinite(period) and period > 0):
            raise ValueError(f"dt_s must be a positive sensor period in s, got {period}")
        cmd_kind, cmd_values = _one_of("command", {"cmd_wheel_m_s": cmd_wheel_m_s,
                                                   "cmd_body": cmd_body})
        cmd = _stream(cmd_kind, wheel.t_s if cmd_t_s is None else cmd_t_s, cmd_values, 2)
        bad = np.flatnonzero(~np.all(np.isfinite(cmd.values), axis=1))
        if bad.size:
            raise ValueError(f"{cmd_kind}: command {int(bad[0])} is not finite "
                             f"({cmd.values[bad[0]].tolist()})")
        if rates not in ("samples", "since_last"):
            raise ValueError(f"rates must be 'samples' or 'since_last', got {rates!r}")
        ok = np.ones(wheel.t_s.size, bool) if valid is None else np.asarray(valid, bool)
        if ok.shape != wheel.t_s.shape:
            raise ShapeError(f"valid must have shape {wheel.t_s.shape}, got {ok.shape}")
        optional = {}
        for name, t_opt, v_opt, cols in (("yaw_rate", yaw_rate_t_s, yaw_rate_rad_s, 1),
                                         ("true_pose", true_pose_t_s, true_pose, 3),
                                         ("sightings", sightings_t_s, sightings, 3)):
            if (t_opt is None) != (v_opt is None):
                raise ValueError(f"{name} needs both its stamps and its values")
            optional[name] = None if v_opt is None else _stream(name, t_opt, v_opt, cols)
        if gyro_density_rad_s_sqrt_hz is not None:
            density = float(gyro_density_rad_s_sqrt_hz)
            if optional["yaw_rate"] is None or not (math.isfinite(density) and density >= 0):
                raise ValueError("gyro_density_rad_s_sqrt_hz needs a yaw rate and must be a "
                                 f"number >= 0 [rad/s/sqrt(Hz)], got {density!r}")
            gyro_density_rad_s_sqrt_hz = density
        if source is not None and not isinstance(source, RecordingSource):
            raise TypeError(f"source must be a RecordingSource, got {type(source).__name__}")
        return cls(dt_s=period, wheel=wheel, wheel_kind=kind, wheel_valid=ok, cmd=cmd,
                   cmd_kind=cmd_kind, cmd_per_frame=cmd_t_s is None,
                   counter_bits=counter_bits if kind == "counts" else None,
                   sensor_pose=tuple(float(x) for x in sensor_pose), meta=dict(meta or {}),
                   rates=rates, gyro_density_rad_s_sqrt_hz=gyro_density_rad_s_sqrt_hz,
                   source=source, **optional)

    @classmethod
    def from_frame_log(cls, log: FrameLog) -> Recording:
        """The recording of a single-robot :class:`~lti_motion.recordings.FrameLog`.

        Counts wrap at ``2**log.counter_bits`` (16 bits unless the log's
        ``meta["counter_bits"]`` says otherwise; 63, 64: they never wrap), commands
        one per frame, ``valid`` kept, simulator ground truth (pose) kept when
        present, a gyro's yaw rate (``log.yaw_rate_rad_s``) as the ``yaw_rate``
        stream of the valid frames, stamped half a period before the frame (the
        reading is the period's mean).

        Raises
        ------
        ValueError
            For a batch log (use ``log.robot(i)``) or stamps that go backwards.
        """
        if log.n_robots is not None:
            raise ValueError("Recording.from_frame_log needs a single-robot log; use "
                             "log.robot(i) first")
        truth = {} if log.true_pose is None else {"true_pose_t_s": log.t_s,
                                                  "true_pose": log.true_pose}
        if log.yaw_rate_rad_s is not None:     # a gyro: the period's mean, stamped mid-period
            ok = log.valid & np.isfinite(log.yaw_rate_rad_s)
            truth.update(yaw_rate_t_s=log.t_s[ok] - 0.5 * log.dt_s,
                         yaw_rate_rad_s=log.yaw_rate_rad_s[ok])
        bits = log.counter_bits
        rec = cls.from_streams(wheel_t_s=log.t_s, dt_s=log.dt_s, counts=log.ticks,
                               counter_bits=None if bits >= 63 else bits, valid=log.valid,
                               cmd_wheel_m_s=log.cmd_m_s,
                               meta=dict(log.meta), **truth)
        return replace(rec, light_bump=log.light_bump, bumps=log.bumps)

    def to_frame_log(self) -> FrameLog:
        """The :class:`~lti_motion.recordings.FrameLog` of a Roomba-like recording.

        Needs 16-bit counts and one wheel command per frame; missing light
        bumps and bumpers become zeros; ground truth is left out (a FrameLog's
        truth also needs the true body speeds).

        Raises
        ------
        ValueError
            If the recording holds another wheel or command kind.
        """
        if (self.wheel_kind != "counts" or self.counter_bits != 16 or not self.cmd_per_frame
                or self.cmd_kind != "cmd_wheel_m_s"):
            raise ValueError(f"only a recording of 16-bit counts with one wheel command per "
                             f"frame is a FrameLog; this one holds {self.wheel_kind} and "
                             f"{self.cmd_kind}")
        n = len(self)
        return FrameLog(
            t_s=self.wheel.t_s, ticks=self.wheel.values, cmd_m_s=self.cmd.values,
            light_bump=(np.zeros((n, 6), np.int64) if self.light_bump is None
                        else self.light_bump),
            bumps=np.zeros((n, 2), bool) if self.bumps is None else self.bumps,
            valid=self.wheel_valid, dt_s=self.dt_s, meta=dict(self.meta))
