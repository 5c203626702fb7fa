"""A bag's drive as a :class:`~lti_motion.frames.FrameLog`: the one conversion, :func:`bag_to_log`.

The rule (``docs/guide_ros_bags.md``):

- the frames are the wheel-angle messages, put on a uniform grid of the sensor
  period ``dt_s`` (default: the median interval between them, refined as the
  slope of their stamps against their period numbers, snapped to a whole 0.1 ms
  or a whole rate in Hz within 0.1 %): frame
  ``k`` is the message ``rint((t - t_0) / dt_s) = k``, stamped ``t_0 + k dt_s``, with
  ``t_0`` the grid's phase from all the stamps (their circular mean), as
  :func:`lti_motion.odometry.stream_clock` times a jittered host stream; where
  jitter puts two messages on one period, a run of them beside it moves by one period
  into the period a misrounded stamp left free. A period without a message is a lost frame
  (``valid`` false) whose angles are interpolated linearly between its
  neighbours, so the next counts span the gap;
- the counts are the angles times ``ticks_per_rad``, rounded, on the 16-bit ring
  (:mod:`lti_motion.odometry`); the encoder scale is then
  ``wheel_radius_m / ticks_per_rad`` (``meta["m_per_tick"]``);
- frame ``k`` closes period ``k``; its command is the last command stamped at
  or before the middle of that period, ``t_k - dt_s / 2`` (zero before the first),
  turned into wheel commands through ``wheel_base_m``
  (:func:`lti_motion.kinematics.wheel_from_body`);
- reference poses (``truth``) are interpolated onto the frames, blank (NaN)
  outside their span and across gaps longer than ``max_gap_s``.

Times in the log count from the bag's first stamp (``meta["bag_start_ns"]``).
"""

from __future__ import annotations

import math

import numpy as np

from drivers.bags import BagRecording, StampedSeries
from drivers.exceptions import BagError
from lti_motion.frames import N_LIGHT_BUMPS, FrameLog
from lti_motion.kinematics import wheel_from_body
from lti_motion.odometry import TICK_MODULUS

__all__ = ["CREATE2_TICKS_PER_RAD", "CREATE2_WHEEL_RADIUS_M", "bag_to_log"]

#: Longest run of messages moved by one period to separate two on one period.
_MAX_SHIFT = 50

#: The Create 2's encoder: 508.8 counts per wheel turn (OI spec, packet 43).
CREATE2_TICKS_PER_RAD = 508.8 / (2.0 * math.pi)
#: The Create 2's nominal wheel radius [m] (72 mm diameter, OI spec).
CREATE2_WHEEL_RADIUS_M = 0.036


def _seconds(series: StampedSeries, start_ns: int) -> np.ndarray:
    return (series.t_ns - start_ns) * 1e-9


def _grid(rec: BagRecording, dt_s: float | None
          ) -> tuple[np.ndarray, float, np.ndarray, float]:
    """Frame index of each wheel message, the period, the message times and the time of
    frame 0 [s]."""
    wheels = rec.wheels
    t = _seconds(wheels, rec.start_ns)
    if len(t) < 2:
        raise BagError(f"topic {wheels.topic} has {len(t)} message; a drive needs at least 2")
    if dt_s is None:
        dt_s = _period(t, wheels.topic)
    if not (math.isfinite(dt_s) and dt_s > 0):
        raise BagError(f"the sensor period must be positive, got {dt_s!r} s")
    k, origin = _periods(t, dt_s, wheels.topic)
    return k, dt_s, t, origin


def _numbers(t: np.ndarray, dt_s: float) -> tuple[np.ndarray, float]:
    """The nearest period numbers of stamps on a grid of ``dt_s`` whose phase is the stamps'
    circular mean (not the first stamp's, which has its own jitter), and the grid's time 0."""
    x = (t - t[0]) / dt_s
    phase = float(np.angle(np.mean(np.exp(2j * np.pi * x))) / (2.0 * np.pi))
    k = np.rint(x - phase).astype(np.int64)
    return k - k[0], float(t[0] + (phase + k[0]) * dt_s)


def _periods(t: np.ndarray, dt_s: float, topic: str) -> tuple[np.ndarray, float]:
    """Period number of each message (:func:`_numbers`), and the time of period 0 [s].

    Where jitter rounds two messages onto one period, a run of messages beside them
    moves by one period into the free period nearest (at most :data:`_MAX_SHIFT`
    messages away), on the side where the moved stamps end up closest to their periods
    (least squares): the slot a misrounded stamp left empty."""
    k, origin = _numbers(t, dt_s)
    x = (t - origin) / dt_s
    n = len(k)
    for i in np.flatnonzero(np.diff(k) < 1):
        if k[i + 1] > k[i]:                        # an earlier repair separated them
            continue
        lo = i
        while lo > 0 and k[lo - 1] == k[lo] - 1 and i - lo < _MAX_SHIFT:
            lo -= 1
        hi = i + 1
        while hi < n - 1 and k[hi + 1] == k[hi] + 1 and hi - i < _MAX_SHIFT:
            hi += 1
        down_ok = lo == 0 or k[lo - 1] < k[lo] - 1
        up_ok = hi == n - 1 or k[hi + 1] > k[hi] + 1
        left, right = slice(lo, i + 1), slice(i + 1, hi + 1)
        cost_down = np.sum((x[left] - k[left] + 1) ** 2 - (x[left] - k[left]) ** 2)
        cost_up = np.sum((x[right] - k[right] - 1) ** 2 - (x[right] - k[right]) ** 2)
        if down_ok and (not up_ok or cost_down <= cost_up):
            k[left] -= 1
        elif up_ok:
            k[right] += 1
    same = np.flatnonzero(np.diff(k) < 1)
    if same.size:
        i = int(same[0])
        raise BagError(f"topic {topic}: messages {i} and {i + 1} fall in the same "
                       f"{dt_s * 1e3:g} ms period (stamps {t[i]:.4f} s and {t[i + 1]:.4f} s): "
                       "stamps jitter by a period or more, or the period is wrong (--dt)")
    return k - k[0], origin + k[0] * dt_s


def _beside_gaps(k: np.ndarray, x: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Messages beside a one-period gap, moved into it where the wheels say so.

    Jitter can round a message onto the period of a lost neighbour, leaving its own
    free: no collision shows it. For a message with a free period on one side and a
    stamp within a period of it, the period is the one that makes the wheels' travel
    per period most even over the message before and the one after (the sum over both
    wheels of the change of travel per period, which a robot's inertia keeps small:
    a misplaced message shows as one period of double travel then one of none)."""
    k = k.copy()
    gaps = np.diff(k) >= 2
    for i in np.flatnonzero(gaps[:-1] | gaps[1:]) + 1:        # beside a free period
        for step in (-1, 1):
            new = k[i] + step
            if not (k[i - 1] < new < k[i + 1]) or abs(x[i] - new) >= 0.75:
                continue
            cost = []
            for ki in (k[i], new):
                before = (angles[i] - angles[i - 1]) / (ki - k[i - 1])
                after = (angles[i + 1] - angles[i]) / (k[i + 1] - ki)
                cost.append(float(np.abs(after - before).sum()))
            if cost[1] < 0.5 * cost[0]:
                k[i] = new
    return k


def _period(t: np.ndarray, topic: str) -> float:
    """The sensor period of jittered stamps [s]: the median of the intervals between half
    and 1.5 times the median interval (one period each, lost frames aside), then refined
    as the least-squares slope of the stamps against their period numbers over the first
    64, 128, 256, ... messages (each fit good enough to number the next stretch); snapped
    to a whole 0.1 ms or a whole rate in Hz within 0.1 %, else rounded to 0.1 us."""
    steps = np.diff(t)
    if not np.any(steps > 0):
        raise BagError(f"topic {topic}: no sensor period in its stamps (all equal); give the "
                       "period with --dt")
    rough = float(np.median(steps[steps > 0]))
    dt_s = float(np.median(steps[(steps > 0.5 * rough) & (steps < 1.5 * rough)]))
    m = min(64, len(t))
    while True:
        k, _ = _numbers(t[:m], dt_s)
        if k[-1] >= 2:
            dt_s = float(np.polyfit(k, t[:m], 1)[0])
        if m == len(t):
            break
        m = min(2 * m, len(t))
    for nominal in (round(dt_s, 4), 1.0 / round(1.0 / dt_s)):     # 15 ms, 50 Hz, 30 Hz
        if abs(nominal - dt_s) <= 1e-3 * dt_s:
            return nominal
    return round(dt_s, 7)


def _check_speed(what: str, topic: str, speed_m_s: np.ndarray, limit_m_s: float) -> None:
    fast = np.flatnonzero(np.abs(speed_m_s) > limit_m_s)
    if fast.size:
        i = int(fast[0])
        raise BagError(f"topic {topic}: the {what} moves at {abs(speed_m_s[i]):.3g} m/s at "
                       f"message {i + 1}, more than {limit_m_s:g} m/s: wrong joint, units, "
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
        Reference poses are blank across gaps longer than this [s].

    Returns
    -------
    FrameLog
        One robot; ``meta`` holds ``m_per_tick``, ``ticks_per_rad``,
        ``bag_start_ns``, the topics and joints used, ``has_commands``.

    Raises
    ------
    BagError
        No wheel angles (the bag's topics listed); fewer than 2 messages; two
        messages in one period; a wheel or command faster than ``max_wheel_m_s``.
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
    k, dt_s, t, origin = _grid(rec, dt_s)
    angles = rec.wheels.values
    k = _beside_gaps(k, (t - origin) / dt_s, angles)
    # over the periods between messages, not the jittered stamps
    speed = np.diff(angles, axis=0) / (np.diff(k) * dt_s)[:, None] * wheel_radius_m
    for side in (0, 1):
        _check_speed(f"{rec.joints[side]} wheel", rec.wheels.topic, speed[:, side],
                     max_wheel_m_s)
    n = int(k[-1]) + 1
    grid = np.arange(n)
    full = np.column_stack([np.interp(grid, k, angles[:, s]) for s in (0, 1)])
    ticks = np.mod(np.rint(full * ticks_per_rad).astype(np.int64), TICK_MODULUS)
    valid = np.zeros(n, bool)
    valid[k] = True
    t_s = origin + grid * dt_s
    cmd = np.zeros((n, 2))
    if rec.cmd is not None:
        tc = _seconds(rec.cmd, rec.start_ns)
        wheels_cmd = wheel_from_body(rec.cmd.values, wheel_base_m=wheel_base_m)
        for side in (0, 1):
            _check_speed(("left", "right")[side] + " wheel command", rec.cmd.topic,
                         wheels_cmd[:, side], max_wheel_m_s)
        last = np.searchsorted(tc, t_s - 0.5 * dt_s, side="right") - 1
        cmd = np.where(last[:, None] >= 0, wheels_cmd[np.maximum(last, 0)], 0.0)
    at_s = t_s.copy()
    at_s[k] = t                              # a pose belongs to its frame's own stamp
    truth = None if rec.truth is None else _reference(rec.truth, rec.start_ns, at_s, max_gap_s)
    meta = {"source": "ROS bag", "bag": str(rec.path), "bag_start_ns": int(rec.start_ns),
            "ticks_per_rad": float(ticks_per_rad), "wheel_radius_m": float(wheel_radius_m),
            "m_per_tick": float(wheel_radius_m / ticks_per_rad),
            "topics": {kind: getattr(rec, kind).topic for kind in
                       ("cmd", "wheels", "odom", "imu", "truth")
                       if getattr(rec, kind) is not None},
            "joints": list(rec.joints), "has_commands": rec.cmd is not None,
            "lost_frames": int(n - len(k))}
    return FrameLog(t_s=t_s, ticks=ticks, light_bump=np.zeros((n, N_LIGHT_BUMPS), np.int64),
                    bumps=np.zeros((n, 2), bool), cmd_m_s=cmd, valid=valid, dt_s=dt_s,
                    true_pose=truth, meta=meta)


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
