"""Sensor frames: the one data type every driver produces and every estimator reads.

A *frame* is what a differential-drive robot reports once per sensor period:
a timestamp, the raw left and right encoder counts, the six light-bump IR
signals, the bump flags, and the wheel-speed commands that were actually sent.
The simulator adds its ground truth (pose and body speeds); a real robot leaves
those fields ``None``.

Two containers share the same field names:

- :class:`SensorFrame`: one period of one robot (what a driver yields);
- :class:`FrameLog`: a columnar record of many periods, with time along
  axis 0, or of ``N`` robots in lock step, with robots along axis 0 and time
  along axis 1 (what the batch simulator returns).

Units are SI: seconds, metres per second, radians. Encoder counts are the
robot's raw unsigned 16-bit values (``0..65535``) and wrap (another width in
``meta["counter_bits"]``, :attr:`FrameLog.counter_bits`); unwrap them with
:func:`lti_motion.recordings.unwrap_ticks`.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, fields
from types import MappingProxyType

import numpy as np

from lti_motion.exceptions import ShapeError

__all__ = ["N_LIGHT_BUMPS", "FrameLog", "SensorFrame"]

#: Light-bump sensors of a Roomba 600 / Create 2, in packet order 46-51:
#: left, front-left, centre-left, centre-right, front-right, right.
N_LIGHT_BUMPS = 6


@dataclass(frozen=True)
class SensorFrame:
    """One sensor period of one robot.

    For a batch of ``N`` simulated robots every array field gains a leading
    robot axis (``t_s`` becomes shape ``(N,)``).

    Attributes
    ----------
    t_s : float
        Timestamp of the frame [s] (host clock for a real robot; includes
        jitter in the simulator).
    ticks : ndarray of int64, shape (2,)
        Raw encoder counts (left, right) as the robot reports them, unsigned
        16-bit modular values in ``0..65535`` [ticks].
    light_bump : ndarray of int64, shape (6,)
        Light-bump IR signals, ``0..4095``, larger when a surface is nearer.
    bumps : ndarray of bool, shape (2,)
        Bumper flags (left, right).
    cmd_m_s : ndarray of float, shape (2,)
        Wheel-speed commands (left, right) in effect when the frame was taken,
        as sent by the host [m/s].
    oi_mode : int or None
        Open Interface mode (0 off, 1 passive, 2 safe, 3 full) when known.
    valid : bool or ndarray of bool
        ``False`` for a frame the simulator lost on the way (a batch frame
        holds one flag per robot); a driver only yields frames it received.
    true_pose : ndarray, shape (3,), or None
        Simulator only: true pose (x [m], y [m], heading [rad]).
    true_body_m_s : ndarray, shape (2,), or None
        Simulator only: true body speeds (v [m/s], w [rad/s]).
    motor_current_a : ndarray, shape (2,), or None
        Wheel motor currents (left, right) [A], where the robot reports them
        (Open Interface packets 54-55, the simulator); ``None`` otherwise.
    wheel_overcurrent : ndarray of bool, shape (2,), or None
        Wheel overcurrent flags (left, right) where the robot reports them
        (Open Interface packet 14, the simulator); ``None`` otherwise.
    yaw_rate_rad_s : float or None
        A yaw-rate gyro's reading over the period [rad/s] (a simulated robot
        with a gyro: bias and noise included, NaN for a robot of a batch
        without one); ``None`` without a gyro.
    """

    t_s: float
    ticks: np.ndarray
    light_bump: np.ndarray
    bumps: np.ndarray
    cmd_m_s: np.ndarray
    oi_mode: int | None = None
    valid: bool | np.ndarray = True
    true_pose: np.ndarray | None = None
    true_body_m_s: np.ndarray | None = None
    motor_current_a: np.ndarray | None = None
    wheel_overcurrent: np.ndarray | None = None
    yaw_rate_rad_s: float | np.ndarray | None = None

    @classmethod
    def of_counts(cls, t_s: float, ticks: np.ndarray, cmd_m_s: np.ndarray, *,
                  valid: bool = True, motor_current_a: np.ndarray | None = None,
                  wheel_overcurrent: np.ndarray | None = None,
                  yaw_rate_rad_s: float | None = None) -> SensorFrame:
        """A frame of what a recording's row holds: counts, commands and the optional wheel
        and gyro readings, without light bumps or bumpers.

        For a filter fed from a recording or a test (the light bumps read zero, nothing
        near; the bumpers are released).

        Parameters
        ----------
        t_s : float
            Timestamp [s].
        ticks : array_like of int, shape (2,)
            Raw encoder counts (left, right) [ticks].
        cmd_m_s : array_like, shape (2,)
            Wheel-speed commands (left, right) of the period the frame closes [m/s].
        valid, motor_current_a, wheel_overcurrent, yaw_rate_rad_s
            As the attributes of the same names.

        Examples
        --------
        >>> frame = SensorFrame.of_counts(0.015, np.array([6, 6]), np.array([0.2, 0.2]))
        >>> frame.light_bump.tolist(), frame.bumps.tolist(), frame.valid
        ([0, 0, 0, 0, 0, 0], [False, False], True)
        """
        return cls(t_s=t_s, ticks=ticks, light_bump=np.zeros(N_LIGHT_BUMPS, np.int64),
                   bumps=np.zeros(2, bool), cmd_m_s=cmd_m_s, valid=valid,
                   motor_current_a=motor_current_a, wheel_overcurrent=wheel_overcurrent,
                   yaw_rate_rad_s=yaw_rate_rad_s)


_PER_SAMPLE = MappingProxyType({
    "t_s": (),
    "ticks": (2,),
    "light_bump": (N_LIGHT_BUMPS,),
    "bumps": (2,),
    "cmd_m_s": (2,),
    "valid": (),
    "true_pose": (3,),
    "true_body_m_s": (2,),
    "motor_current_a": (2,),
    "wheel_overcurrent": (2,),
    "yaw_rate_rad_s": (),
})


@dataclass(frozen=True)
class FrameLog:
    """A columnar record of sensor frames.

    Every array has shape ``(n, ...)`` for one robot, or ``(N, n, ...)`` for
    ``N`` robots stepped in lock step; the trailing shape of each field is that
    of :class:`SensorFrame`.

    Attributes
    ----------
    t_s : ndarray, shape (n,) or (N, n)
        Frame timestamps [s].
    ticks : ndarray of int64, shape (..., n, 2)
        Raw unsigned 16-bit encoder counts (left, right) [ticks].
    light_bump : ndarray of int64, shape (..., n, 6)
        Light-bump IR signals, ``0..4095``.
    bumps : ndarray of bool, shape (..., n, 2)
        Bumper flags (left, right).
    cmd_m_s : ndarray, shape (..., n, 2)
        Wheel-speed commands (left, right) sent for each period [m/s].
    valid : ndarray of bool, shape (..., n)
        ``False`` where the frame was lost on the way (the simulator's
        lost-frame fault); the next valid frame's counts include the motion.
    dt_s : float
        Nominal sensor period [s].
    true_pose, true_body_m_s : ndarray or None
        Simulator ground truth, shapes ``(..., n, 3)`` and ``(..., n, 2)``.
    meta : dict
        Free-form description (preset, floor, seed, ...), JSON-serialisable.
    motor_current_a, wheel_overcurrent : ndarray or None
        Optional: wheel motor currents [A] and overcurrent flags (bool), shape
        ``(..., n, 2)``, where the robot reports them (:class:`SensorFrame`).
    yaw_rate_rad_s : ndarray or None
        Optional: a yaw-rate gyro's reading per period [rad/s], shape ``(..., n)``
        (:class:`SensorFrame`).
    """

    t_s: np.ndarray
    ticks: np.ndarray
    light_bump: np.ndarray
    bumps: np.ndarray
    cmd_m_s: np.ndarray
    valid: np.ndarray
    dt_s: float
    true_pose: np.ndarray | None = None
    true_body_m_s: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    motor_current_a: np.ndarray | None = None
    wheel_overcurrent: np.ndarray | None = None
    yaw_rate_rad_s: np.ndarray | None = None

    def __post_init__(self) -> None:
        lead = np.shape(self.t_s)
        if len(lead) not in (1, 2):
            raise ShapeError(f"FrameLog.t_s must have shape (n,) or (N, n), got {lead}")
        for name, tail in _PER_SAMPLE.items():
            value = getattr(self, name)
            if value is None:
                continue
            if np.shape(value) != lead + tail:
                raise ShapeError(
                    f"FrameLog.{name} must have shape {lead + tail}, got {np.shape(value)}"
                )
        if not (np.isfinite(self.dt_s) and self.dt_s > 0):
            raise ValueError(f"FrameLog.dt_s must be a positive period in s, got {self.dt_s}")

    @property
    def n_robots(self) -> int | None:
        """Number of robots for a batch log, ``None`` for a single robot."""
        return self.t_s.shape[0] if self.t_s.ndim == 2 else None

    def __len__(self) -> int:
        """Number of frames (periods) per robot."""
        return self.t_s.shape[-1]

    @property
    def counter_bits(self) -> int:
        """Width of the encoder counters [bits]: ``meta["counter_bits"]`` (per robot when
        a list, as the batch simulator gives it), 16 (the Open Interface's) when absent;
        63 and 64 never wrap."""
        bits = self.meta.get("counter_bits", 16)
        if isinstance(bits, list | tuple):
            bits = bits[self.meta.get("robot", 0)] if self.n_robots is None else bits[0]
        return int(bits)

    @property
    def has_truth(self) -> bool:
        """Whether the log carries simulator ground truth."""
        return self.true_pose is not None

    def robot(self, i: int) -> FrameLog:
        """The log of robot ``i`` of a batch log.

        Raises
        ------
        ValueError
            If the log holds a single robot.
        """
        if self.n_robots is None:
            raise ValueError("FrameLog.robot(i) needs a batch log; this log holds one robot")
        kw = {f.name: getattr(self, f.name) for f in fields(self)}
        for name in _PER_SAMPLE:
            if kw[name] is not None:
                kw[name] = kw[name][i]
        kw["meta"] = {**self.meta, "robot": i}
        return FrameLog(**kw)

    def window(self, start: int, stop: int | None = None) -> FrameLog:
        """Frames ``start:stop`` along the time axis, as a new log."""
        axis_slice = (slice(None),) * (self.t_s.ndim - 1) + (slice(start, stop),)
        kw = {f.name: getattr(self, f.name) for f in fields(self)}
        for name in _PER_SAMPLE:
            if kw[name] is not None:
                kw[name] = kw[name][axis_slice]
        return FrameLog(**kw)

    def frames(self) -> Iterator[SensorFrame]:
        """Iterate over the valid frames of a single-robot log."""
        if self.n_robots is not None:
            raise ValueError("FrameLog.frames() needs a single-robot log; use robot(i) first")
        for k in np.flatnonzero(self.valid):
            yield self.frame(k)

    def frame(self, k: int, *, truth: bool = True) -> SensorFrame:
        """Frame ``k`` of a single-robot log, lost or not (its ``valid`` says which).

        Parameters
        ----------
        k : int
            Index along the time axis.
        truth : bool
            Whether the frame carries the simulator's truth (``true_pose``,
            ``true_body_m_s``) when the log has it; false gives what a robot
            reports.

        Raises
        ------
        ValueError
            If the log holds a batch of robots.
        """
        if self.n_robots is not None:
            raise ValueError("FrameLog.frame(k) needs a single-robot log; use robot(i) first")
        return SensorFrame(
            t_s=float(self.t_s[k]),
            ticks=self.ticks[k],
            light_bump=self.light_bump[k],
            bumps=self.bumps[k],
            cmd_m_s=self.cmd_m_s[k],
            valid=bool(self.valid[k]),
            true_pose=self.true_pose[k] if truth and self.true_pose is not None else None,
            true_body_m_s=(self.true_body_m_s[k] if truth and self.true_body_m_s is not None
                           else None),
            motor_current_a=(None if self.motor_current_a is None
                             else self.motor_current_a[k]),
            wheel_overcurrent=(None if self.wheel_overcurrent is None
                               else self.wheel_overcurrent[k]),
            yaw_rate_rad_s=(None if self.yaw_rate_rad_s is None
                            else float(self.yaw_rate_rad_s[k])),
        )

    @classmethod
    def from_frames(
        cls, frames: Iterable[SensorFrame], *, dt_s: float, meta: dict | None = None
    ) -> FrameLog:
        """Stack single frames (e.g. from a driver) into a log.

        Raises
        ------
        ValueError
            If ``frames`` is empty.
        """
        frames = list(frames)
        if not frames:
            raise ValueError("FrameLog.from_frames needs at least one frame")
        truth = all(f.true_pose is not None for f in frames)
        current = all(f.motor_current_a is not None for f in frames)
        overcurrent = all(f.wheel_overcurrent is not None for f in frames)
        gyro = all(f.yaw_rate_rad_s is not None for f in frames)
        return cls(
            t_s=np.array([f.t_s for f in frames], dtype=float),
            ticks=np.array([f.ticks for f in frames], dtype=np.int64),
            light_bump=np.array([f.light_bump for f in frames], dtype=np.int64),
            bumps=np.array([f.bumps for f in frames], dtype=bool),
            cmd_m_s=np.array([f.cmd_m_s for f in frames], dtype=float),
            valid=np.array([bool(np.all(f.valid)) for f in frames], dtype=bool),
            dt_s=dt_s,
            true_pose=np.array([f.true_pose for f in frames]) if truth else None,
            true_body_m_s=np.array([f.true_body_m_s for f in frames]) if truth else None,
            meta=dict(meta or {}),
            motor_current_a=(np.array([f.motor_current_a for f in frames], dtype=float)
                             if current else None),
            wheel_overcurrent=(np.array([f.wheel_overcurrent for f in frames], dtype=bool)
                               if overcurrent else None),
            yaw_rate_rad_s=(np.array([f.yaw_rate_rad_s for f in frames], dtype=float)
                            if gyro else None),
        )
