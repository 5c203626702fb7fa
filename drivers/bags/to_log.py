"""A bag's drive as a :class:`~lti_motion.recordings.FrameLog`: the one conversion,
:func:`bag_to_log`.

The rule (``docs/guide_ros_bags.md``): the bag's topics become a
:class:`~lti_motion.recordings.Recording` (wheel angles, body-twist commands,
each with its own stamps) and go the way of every recording
(:mod:`lti_motion.recordings.resample`, :mod:`lti_motion.recordings.clocks`):

- the frames are the wheel-angle messages, each assigned to a sensor period by
  :func:`lti_motion.recordings.wheel_periods` with ``periods_by="stamps_and_travel"``
  (the clock line fitted to the stamps, drift included; a message that jitter put
  on a lost neighbour's period goes back to its own where that evens the wheel
  travel). The log's period ``dt_s`` is the fitted one as a robot is configured
  (:func:`lti_motion.recordings.snap_period_s`: a whole 0.1 ms or a whole rate in Hz),
  or the one given. Frame ``k`` is stamped with period ``k``'s time on the host's
  typical arrival line (envelope plus median latency). A period without a message
  is a lost frame (``valid`` false) whose angles are interpolated linearly between
  its neighbours, so the next counts span the gap;
- the counts are the angles times ``ticks_per_rad``, rounded, on the 16-bit ring
  (:mod:`lti_motion.recordings.ticks`); the encoder scale is then
  ``wheel_radius_m / ticks_per_rad`` (``meta["m_per_tick"]``);
- frame ``k`` closes period ``k``; its command is the one in effect in that
  period (:func:`lti_motion.recordings.commands_at`: the last command stamped at or
  before the period's middle, zero before the first), turned into wheel commands
  through ``wheel_base_m`` (:func:`lti_motion.kinematics.wheel_from_body`);
- reference poses (``truth``) are interpolated onto the frames (a received frame
  at its own stamp), blank (NaN) outside their span and across gaps longer than
  ``max_gap_s``;
- an IMU's yaw rate (``sensor_msgs/Imu`` ``angular_velocity.z``, any rate) becomes
  each frame's ``yaw_rate_rad_s``, the mean rate over the period the frame closes,
  by the rule of :mod:`lti_motion.recordings.resample` for a rate stream: integrated with the
  trapezoid rule over the Imu's own stamps, the integral interpolated linearly at
  the period boundaries (the fitted clock line, :meth:`ClockFit.times_s
  <lti_motion.recordings.clocks.ClockFit.times_s>` of ``k - 1`` and ``k``), differenced and
  divided by the period. An Imu faster than the wheels is averaged over each period,
  a slower one interpolated linearly between its messages. A period reaching
  outside the Imu's messages, or over a gap between two of them longer than
  ``max_gap_s``, has no reading (NaN: the EKF starts a new gyro window). Messages whose
  ``angular_velocity_covariance[0]`` is -1 have no rate and are left out; the yaw
  rate's noise the covariance gives (:mod:`drivers.bags.imu_noise`) goes into
  ``meta["imu_noise"]``.

Times in the log count from the bag's first stamp (``meta["bag_start_ns"]``).
"""

from __future__ import annotations

import math

import numpy as np

from drivers.bags.imu_noise import imu_rate_noise, with_rate_data
from drivers.bags.reader import BagRecording, StampedSeries
from drivers.exceptions import BagError
from lti_motion.kinematics import wheel_from_body
from lti_motion.recordings.clocks import median_period_s, snap_period_s
from lti_motion.recordings.frames import N_LIGHT_BUMPS, FrameLog
from lti_motion.recordings.recording import Recording
from lti_motion.recordings.resample import commands_at, wheel_periods
from lti_motion.recordings.ticks import TICK_MODULUS

__all__ = ["CREATE2_TICKS_PER_RAD", "CREATE2_WHEEL_RADIUS_M", "bag_to_log"]

#: The Create 2's encoder: 508.8 counts per wheel turn (OI spec, packet 43).
CREATE2_TICKS_PER_RAD = 508.8 / (2.0 * math.pi)
#: The Create 2's nominal wheel radius [m] (72 mm diameter, OI spec).
CREATE2_WHEEL_RADIUS_M = 0.036


def _seconds(series: StampedSeries, start_ns: int) -> np.ndarray:
    return (series.t_ns - start_ns) * 1e-9


def _check_speed(what: str, topic: str, speed_m_s: np.ndarray, limit_m_s: float,
                 message: np.ndarray) -> None:
    """A one-line error for the first speed over the limit; ``message`` numbers each speed's
    message in the topic."""
    fast = np.flatnonzero(np.abs(speed_m_s) > limit_m_s)
    if fast.size:
        j = int(fast[0])
        i = int(message[j])
        raise BagError(f"topic {topic}: the {what} moves at {abs(speed_m_s[j]):.3g} m/s at "
                       f"message {i}, more than {limit_m_s:g} m/s: wrong joint, units, "
                       "wheel radius or stamps")


def bag_to_log(rec: BagRecording, *, wheel_base_m: float,
               ticks_per_rad: float = CREATE2_TICKS_PER_RAD,
               wheel_radius_m: float = CREATE2_WHEEL_RADIUS_M, dt_s: float | None = None,
               max_wheel_m_s: float = 20.0, max_gap_s: float = 0.25) -> FrameLog:
    """The drive in a bag as a :class:`FrameLog`, by the rule of the module docstring.

    Parameters
    ----------
    rec : BagRecording
        From :func:`drivers.bags.read_bag`; needs wheel angles.
    wheel_base_m : float
        Turns the body-speed commands into wheel commands [m].
    ticks_per_rad : float
        Encoder counts per wheel radian (default the Create 2's, 80.98).
    wheel_radius_m : float
        Nominal wheel radius [m] (default the Create 2's, 0.036).
    dt_s : float, optional
        Sensor period [s]; default from the wheel messages' stamps (module docstring).
    max_wheel_m_s : float
        A wheel or wheel command faster than this [m/s] is refused as impossible
        (default 20 m/s: far beyond any robot this library models, while encoder
        glitches of several hundred ticks still pass, for the monitor to find).
    max_gap_s : float
        Reference poses and the Imu's yaw rate are blank across gaps longer than
        this [s].

    Returns
    -------
    FrameLog
        One robot (``yaw_rate_rad_s`` when the recording has an Imu); ``meta``
        holds ``m_per_tick``, ``ticks_per_rad``, ``bag_start_ns``, the topics and
        joints used, ``has_commands``, ``lost_frames``, ``clock`` (the period
        assignment's summary line) and, with an Imu, ``imu_noise`` (its yaw-rate
        ``variance_rad2_s2`` or ``None`` if unknown, ``period_s``,
        ``density_rad_s_sqrt_hz``, message counts known / unknown / without a rate,
        and a ``summary`` line; :mod:`drivers.bags.imu_noise`).

    Raises
    ------
    BagError
        No wheel angles (the bag's topics listed); fewer than 2 messages; stamps
        all equal and no ``dt_s``; a wheel or command faster than ``max_wheel_m_s``;
        an Imu none of whose messages has an angular velocity.
        (A non-finite Imu value or Imu stamps going backwards are refused by
        :func:`drivers.bags.read_bag`.)
    ValueError
        For a non-positive ``wheel_base_m``, ``ticks_per_rad`` or ``wheel_radius_m``.
    """
    for name, value in (("wheel_base_m", wheel_base_m), ("ticks_per_rad", ticks_per_rad),
                        ("wheel_radius_m", wheel_radius_m)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be positive, got {value!r}")
    if rec.wheels is None:
        listing = ", ".join(f"{t} ({m})" for t, m in sorted(rec.topics.items()))
        raise BagError(f"{rec.path.name} has no sensor_msgs/JointState wheel angles; it has "
                       f"{listing or 'no topics'}")
    wheels = rec.wheels
    t = _seconds(wheels, rec.start_ns)
    if len(t) < 2:
        raise BagError(f"topic {wheels.topic} has {len(t)} message; a drive needs at least 2")
    if dt_s is not None and not (math.isfinite(dt_s) and dt_s > 0):
        raise BagError(f"the sensor period must be positive, got {dt_s!r} s")
    if dt_s is None and not np.any(np.diff(t) > 0):
        raise BagError(f"topic {wheels.topic}: no sensor period in its stamps (all equal); "
                       "give the period with --dt")
    cmd = {"cmd_body": np.zeros((len(t), 2))}            # none recorded: zero, per frame
    if rec.cmd is not None:
        cmd = {"cmd_t_s": _seconds(rec.cmd, rec.start_ns), "cmd_body": rec.cmd.values}
    track = Recording.from_streams(wheel_t_s=t, wheel_angles_rad=wheels.values,
                                   dt_s=median_period_s(t) if dt_s is None else dt_s, **cmd)
    a = wheel_periods(track, periods_by="stamps_and_travel")
    got = np.flatnonzero(a.keep)                  # messages that close a period
    k, angles = a.period[got], wheels.values[got]
    clock = a.clock
    # over the periods between messages, not the jittered stamps
    speed = np.diff(angles, axis=0) / (np.diff(k) * clock.period_s)[:, None] * wheel_radius_m
    for side in (0, 1):
        _check_speed(f"{rec.joints[side]} wheel", wheels.topic, speed[:, side], max_wheel_m_s,
                     got[1:])
    n = int(k[-1]) + 1
    grid = np.arange(n)
    full = np.column_stack([np.interp(grid, k, angles[:, s]) for s in (0, 1)])
    ticks = np.mod(np.rint(full * ticks_per_rad).astype(np.int64), TICK_MODULUS)
    valid = np.zeros(n, bool)
    valid[k] = True
    t_s = clock.times_s(grid) + clock.latency_median_s        # typical arrival line
    wheel_cmd = wheel_from_body(commands_at(track, a, grid), wheel_base_m=wheel_base_m)
    if rec.cmd is not None:
        sent = wheel_from_body(rec.cmd.values, wheel_base_m=wheel_base_m)
        for side in (0, 1):
            _check_speed(("left", "right")[side] + " wheel command", rec.cmd.topic,
                         sent[:, side], max_wheel_m_s, np.arange(1, len(sent) + 1))
    at_s = t_s.copy()
    at_s[k] = t[got]                         # a pose belongs to its frame's own stamp
    truth = None if rec.truth is None else _reference(rec.truth, rec.start_ns, at_s, max_gap_s)
    yaw, imu_noise = None, None
    if rec.imu is not None:
        noise = imu_rate_noise(rec.imu)
        imu_noise = {"variance_rad2_s2": noise.variance_rad2_s2, "period_s": noise.period_s,
                     "density_rad_s_sqrt_hz": noise.density_rad_s_sqrt_hz,
                     "messages": [noise.n_known, noise.n_unknown, noise.n_no_data],
                     "summary": noise.describe(rec.imu.topic)}
        yaw = _mean_rate(with_rate_data(rec.imu), rec.start_ns,
                         clock.times_s(np.arange(-1, n)), max_gap_s)
    dt_s = snap_period_s(clock.period_s) if dt_s is None else float(dt_s)
    meta = {"source": "ROS bag", "bag": str(rec.path), "bag_start_ns": int(rec.start_ns),
            "ticks_per_rad": float(ticks_per_rad), "wheel_radius_m": float(wheel_radius_m),
            "m_per_tick": float(wheel_radius_m / ticks_per_rad),
            "topics": {kind: getattr(rec, kind).topic for kind in
                       ("cmd", "wheels", "odom", "imu", "truth")
                       if getattr(rec, kind) is not None},
            "joints": list(rec.joints), "has_commands": rec.cmd is not None,
            "lost_frames": int(n - len(k)), "clock": a.summary(),
            **({} if imu_noise is None else {"imu_noise": imu_noise})}
    return FrameLog(t_s=t_s, ticks=ticks, light_bump=np.zeros((n, N_LIGHT_BUMPS), np.int64),
                    bumps=np.zeros((n, 2), bool), cmd_m_s=wheel_cmd, valid=valid, dt_s=dt_s,
                    true_pose=truth, yaw_rate_rad_s=yaw, meta=meta)


def _mean_rate(rate: StampedSeries, start_ns: int, bounds_s: np.ndarray,
               max_gap_s: float) -> np.ndarray:
    """Mean of a rate stream over each interval between ``bounds_s`` (module docstring);
    NaN for an interval reaching outside the stream or over a gap longer than ``max_gap_s``."""
    t, v = _seconds(rate, start_ns), rate.values[:, 0]
    # the trapezoid rule's running integral (resample.py, module Notes step 1)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    out = np.diff(np.interp(bounds_s, t, cum)) / np.diff(bounds_s)
    if len(t) < 2:
        return np.full(len(out), np.nan)
    big = np.concatenate([[0], np.cumsum(np.diff(t) > max_gap_s)])   # gaps before message i
    first = np.clip(np.searchsorted(t, bounds_s[:-1], "right") - 1, 0, len(t) - 2)
    last = np.clip(np.searchsorted(t, bounds_s[1:], "left") - 1, 0, len(t) - 2)
    tol = 1e-6                # 1 us: a clock line fitted through a stamp misses it by rounding
    out[(bounds_s[:-1] < t[0] - tol) | (bounds_s[1:] > t[-1] + tol)
        | (big[last + 1] > big[first])] = np.nan
    return out


def _reference(truth: StampedSeries, start_ns: int, t_s: np.ndarray,
               max_gap_s: float) -> np.ndarray:
    """Reference poses interpolated at ``t_s``; NaN outside their span and across gaps."""
    tr = _seconds(truth, start_ns)
    out = np.column_stack([np.interp(t_s, tr, truth.values[:, j]) for j in range(3)])
    j = np.clip(np.searchsorted(tr, t_s), 1, max(len(tr) - 1, 1))
    blank = (t_s < tr[0]) | (t_s > tr[-1])
    if len(tr) > 1:
        blank |= tr[j] - tr[j - 1] > max_gap_s
    out[blank] = np.nan
    return out
