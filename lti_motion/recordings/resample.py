"""Any recording onto the model's grid: per-period wheel commands and body speeds.

The one code path from a :class:`~lti_motion.recordings.Recording` (any wheel
measurement kind, any command kind, streams at different rates) to what
calibration fits and what the EKF fuses.

Notes
-----
The grid is the robot's sensor periods, found from the wheel stream's stamps
by :func:`lti_motion.recordings.assign_periods` (a wheel frame with the stamp and
values of the one before is a duplicate and merged); period ``k`` ends at host time
``offset_s + period_s k`` on the latency-free envelope. The rule for every
measured stream:

1. Make it cumulative: counts are unwrapped (shortest signed step on a
   ``2**counter_bits`` ring) and scaled by ``m_per_tick``; angles are
   scaled by ``wheel_radius_m`` (unwrapped first when every angle lies in
   ``[-pi, pi]``, i.e. the source wraps them; otherwise taken as continuous,
   as ``JointState.position`` of a continuous joint is); speeds (wheel, body, IMU yaw
   rate) are integrated with the trapezoid rule over their own times, or, for a
   recording whose speeds are means since the previous frame (``Recording.rates ==
   "since_last"``, an odometry twist), each times the time since the previous frame
   (the backward rectangle, exact for such means).
2. Interpolate the cumulative value linearly at the period boundaries (wheel
   frames sit at the end of the period they were assigned to; other streams
   at their stamps), difference, and divide by the period: the mean rate over
   each period. Frames lost or marked invalid are skipped, so the next frame's
   counts span the gap and are spread evenly over the periods they cover
   (those periods are flagged ``measured = False``).

Commands are held (zero-order hold, as a robot holds its last command): the
command of period ``k`` is the last one stamped at or before the middle of the
period on the host's typical arrival line (the envelope time plus the median
latency of the wheel frames: commands and wheel frames are stamped by the same
host, and a frame typically arrives that much after its period ends), zero
before the first; a command stored per wheel frame belongs to the period that
frame closes, and a period with no frame takes the next frame's command.

The periods are assigned by the stamps alone (``periods_by="stamps"``), or
by the stamps and the wheels' cumulative travel (``"stamps_and_travel"``,
counts and wheel angles only): a frame that jitter put on a lost neighbour's
period moves back into its own where that evens the travel per period
(:func:`lti_motion.recordings.assign_periods`, ``travel``). ROS bags use the
latter (:func:`drivers.bags.read_bag`'s recordings, through
:func:`drivers.bags.bag_grid`).
A body twist becomes wheel speeds through the wheel base
(:func:`lti_motion.kinematics.wheel_from_body`).

With ``max_gap_s`` the IMU's mean rate is blank (NaN) over a period reaching across a
gap between two of its stamps longer than that, and a reference pose (read by
:func:`poses_at`) is blank outside the reference's span and across such gaps.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from lti_motion.exceptions import WheelSpeedError
from lti_motion.kinematics import body_from_wheel, wheel_from_body
from lti_motion.recordings.clocks import PeriodAssignment, assign_periods
from lti_motion.recordings.recording import Recording, Stream
from lti_motion.recordings.ticks import unfold_commanded_direction

__all__ = ["MAX_WHEEL_SPEED_M_S", "GridSignals", "commands_at", "frame_stamps", "on_grid",
           "poses_at", "wheel_periods"]

#: How wheel frames find their periods (module Notes).
PeriodsBy = Literal["stamps", "stamps_and_travel"]

#: Fastest wheel (or body) speed taken as physically possible by default [m/s].
MAX_WHEEL_SPEED_M_S = 5.0


@dataclass(frozen=True)
class GridSignals:
    """A recording on the model's grid, periods ``1 .. P`` (period 0 has no start).

    Attributes
    ----------
    t_s : ndarray, shape (P,)
        Host time of the end of each period [s].
    period_s : float
        The fitted sensor period [s] (host seconds).
    cmd_m_s : ndarray, shape (P, 2)
        Wheel commands (left, right) in effect for each period [m/s].
    speeds : ndarray, shape (P, 2)
        Mean body speeds (v [m/s], w [rad/s]) over each period.
    measured : ndarray of bool, shape (P,)
        ``False`` for periods inside a gap (speed spread from the next frame).
    yaw_rate_rad_s : ndarray, shape (P,), or None
        Mean IMU yaw rate over each period [rad/s]; NaN for a period reaching outside
        the IMU's first and last stamps.
    true_pose : ndarray, shape (P, 3), or None
        Ground-truth pose at the end of each period.
    assignment : PeriodAssignment
        The frames' periods and the clock counts (lost, late, merged, dropped).
    closed : ndarray of bool, shape (P + 1,)
        Whether a used wheel frame closed period ``k``, ``0 .. P`` (its reading
        arrived; a period not closed is inside a gap).
    """

    t_s: np.ndarray
    period_s: float
    cmd_m_s: np.ndarray
    speeds: np.ndarray
    measured: np.ndarray
    yaw_rate_rad_s: np.ndarray | None
    true_pose: np.ndarray | None
    assignment: PeriodAssignment
    closed: np.ndarray


def _count_steps(counts: np.ndarray, counter_bits: int | None) -> np.ndarray:
    """Steps between consecutive counts, unwrapped on a ``2**counter_bits`` ring."""
    steps = np.diff(counts.astype(np.int64), axis=0)
    if counter_bits is not None and counter_bits < 63:           # 63, 64: never wrap
        mod = 1 << counter_bits
        steps = (steps + mod // 2) % mod - mod // 2          # shortest signed step
    return steps


def _cumulative(rec: Recording, used: np.ndarray, t_used: np.ndarray, *,
                m_per_tick: float | np.ndarray | None, wheel_radius_m: float | None,
                encoders: str) -> np.ndarray:
    """Cumulative wheel travel [m] (or body travel [m, rad]) at the used frames."""
    v = rec.wheel.values[used]
    kind = rec.wheel_kind
    if kind == "counts":
        if m_per_tick is None:
            raise ValueError("counts need the encoder scale m_per_tick [m/tick]")
        steps = _count_steps(v, rec.counter_bits)
        if encoders == "commanded":
            steps = unfold_commanded_direction(steps)
        travel = np.vstack([np.zeros((1, 2)), np.cumsum(steps, axis=0) * m_per_tick])
        return travel
    if kind in ("wheel_angles_rad", "wheel_speeds_rad_s") and wheel_radius_m is None:
        raise ValueError(f"{kind} need the wheel radius wheel_radius_m [m]")
    if kind == "wheel_angles_rad":
        if np.all(np.abs(v) <= np.pi):        # wrapped to (-pi, pi]: unwrap
            v = np.unwrap(v, axis=0)
        if encoders == "commanded":           # angles counted in the commanded direction
            steps = unfold_commanded_direction(np.diff(v, axis=0))
            return np.vstack([np.zeros((1, 2)), np.cumsum(steps, axis=0)]) * wheel_radius_m
        return (v - v[0]) * wheel_radius_m
    rate = v * wheel_radius_m if kind == "wheel_speeds_rad_s" else v
    if rec.rates == "since_last":       # a mean since the previous frame: backward rectangle
        # over the message's own interval (its stamps), not the periods it was put on: a
        # twist of a 43.7 ms interval on a 33 ms grid would otherwise turn the robot too far
        inc = rate[1:] * np.diff(rec.wheel.t_s[used])[:, None]
    else:                               # readings at their stamps: trapezoid rule
        inc = 0.5 * (rate[1:] + rate[:-1]) * np.diff(t_used)[:, None]
    return np.vstack([np.zeros((1, 2)), np.cumsum(inc, axis=0)])


#: A clock line fitted through a stamp misses it by rounding: 1 us of tolerance [s].
_STAMP_TOL_S = 1e-6


def _integrate_at(stream: Stream, t_grid: np.ndarray, max_gap_s: float | None) -> np.ndarray:
    """Mean rate of a rate stream over each grid interval (trapezoid, then interpolate);
    NaN for an interval reaching outside the stream's first and last stamps (no reading,
    not a zero rate), or, with ``max_gap_s``, across a gap between two stamps longer than
    that."""
    t, v = stream.t_s, stream.values[:, 0]
    # the trapezoid rule's running integral (module Notes, step 1)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    at = np.interp(t_grid, t, cum)
    rate = np.diff(at) / np.diff(t_grid)
    if max_gap_s is None:
        rate[(t_grid[:-1] < t[0]) | (t_grid[1:] > t[-1])] = np.nan
        return rate
    if t.size < 2:
        return np.full(rate.size, np.nan)
    big = np.concatenate([[0], np.cumsum(np.diff(t) > max_gap_s)])   # gaps before stamp i
    first = np.clip(np.searchsorted(t, t_grid[:-1], "right") - 1, 0, t.size - 2)
    last = np.clip(np.searchsorted(t, t_grid[1:], "left") - 1, 0, t.size - 2)
    rate[(t_grid[:-1] < t[0] - _STAMP_TOL_S) | (t_grid[1:] > t[-1] + _STAMP_TOL_S)
         | (big[last + 1] > big[first])] = np.nan
    return rate


def frame_stamps(rec: Recording, a: PeriodAssignment) -> np.ndarray:
    """Host time of the end of each period ``0 .. P`` as the wheel stream stamps it [s]:
    the stamp of the wheel frame that closed the period, else (a lost frame) the host's
    typical arrival line (the clock line plus the frames' median latency).

    The time to read another stream of the same host at (a reference pose that belongs
    to its wheel frame).

    Parameters
    ----------
    rec : Recording
    a : PeriodAssignment
        From :func:`wheel_periods` of ``rec`` (``GridSignals.assignment``).

    Returns
    -------
    ndarray, shape (P + 1,)
    """
    c = a.clock
    at = c.times_s(np.arange(a.n_periods)) + c.latency_median_s
    kept = a.keep & rec.wheel_valid
    at[a.period[kept]] = rec.wheel.t_s[kept]
    return at


def poses_at(stream: Stream, t_s: np.ndarray, *, max_gap_s: float | None = None) -> np.ndarray:
    """Poses of a pose stream interpolated at times ``t_s`` (heading unwrapped first).

    Parameters
    ----------
    stream : Stream
        Poses (x [m], y [m], heading [rad]), shape ``(m, 3)``, e.g.
        :attr:`Recording.true_pose <lti_motion.recordings.Recording.true_pose>`.
    t_s : array_like, shape (p,)
        Times [s] on the stream's clock.
    max_gap_s : float, optional
        Blank (NaN) outside the stream's span and across a gap between two of its
        stamps longer than this [s]; ``None``: held at the ends, interpolated over
        any gap.

    Returns
    -------
    ndarray, shape (p, 3)

    Examples
    --------
    >>> ref = Stream(np.array([0.0, 1.0, 3.0]), np.array([[0, 0, 0], [1, 0, 0], [3, 0, 0.]]))
    >>> poses_at(ref, np.array([0.5, 2.0, 4.0]), max_gap_s=1.5)[:, 0].tolist()
    [0.5, nan, nan]
    """
    t_s = np.asarray(t_s, dtype=float)
    tr = stream.t_s
    pose = stream.values.astype(float).copy()
    pose[:, 2] = np.unwrap(pose[:, 2])
    out = np.stack([np.interp(t_s, tr, pose[:, j]) for j in range(3)], axis=1)
    if max_gap_s is not None:
        blank = (t_s < tr[0]) | (t_s > tr[-1])
        if tr.size > 1:
            j = np.clip(np.searchsorted(tr, t_s), 1, tr.size - 1)
            blank |= tr[j] - tr[j - 1] > max_gap_s
        out[blank] = np.nan
    return out


def _frame_travel(rec: Recording, encoders: str) -> np.ndarray | None:
    """Cumulative travel of each wheel frame in the stream's own unit, NaN where unusable;
    ``None`` for speeds (a speed has no travel to even)."""
    v = rec.wheel.values
    if rec.wheel_kind == "counts":
        steps = _count_steps(v, rec.counter_bits)
        if encoders == "commanded":           # the count's sign flips with the command
            steps = unfold_commanded_direction(steps)
        cum = np.vstack([np.zeros((1, 2)), np.cumsum(steps, axis=0, dtype=float)])
    elif rec.wheel_kind == "wheel_angles_rad":
        cum = np.unwrap(v, axis=0) if np.all(np.abs(v) <= np.pi) else v.astype(float)
    else:
        return None
    cum[~rec.wheel_valid] = np.nan
    return cum


def wheel_periods(rec: Recording, *, periods_by: PeriodsBy = "stamps",
                  encoders: Literal["quadrature", "commanded"] = "quadrature"
                  ) -> PeriodAssignment:
    """The sensor period of each wheel frame of a recording (module Notes).

    A frame with the stamp and values of the one before is a duplicate and
    merged; the periods come from :func:`lti_motion.recordings.assign_periods`,
    given the frames' cumulative travel when ``periods_by`` is
    ``"stamps_and_travel"`` (counts and wheel angles; speeds have none).
    Counts of ``encoders="commanded"`` (Roomba / Create 2) are unfolded
    (:func:`~lti_motion.recordings.unfold_commanded_direction`) before their
    travel is judged.

    Returns
    -------
    PeriodAssignment
    """
    t, v = rec.wheel.t_s, rec.wheel.values
    repeat = np.zeros(t.size, bool)     # a frame delivered twice: same stamp, same values
    repeat[1:] = (np.diff(t) == 0) & np.all(v[1:] == v[:-1], axis=1)
    travel = _frame_travel(rec, encoders) if periods_by == "stamps_and_travel" else None
    return assign_periods(t, dt_s=rec.dt_s, duplicate=repeat, travel=travel)


def _command_index(rec: Recording, a: PeriodAssignment, periods: np.ndarray) -> np.ndarray:
    """The index in ``rec.cmd`` of the command :func:`commands_at` holds in each period
    (0 where none was sent yet)."""
    if rec.cmd_per_frame:
        k = a.period[a.keep]
        return np.flatnonzero(a.keep)[np.minimum(np.searchsorted(k, periods), k.size - 1)]
    c = a.clock
    mid = c.times_s(periods) + c.latency_median_s - 0.5 * c.period_s
    return np.maximum(np.searchsorted(rec.cmd.t_s, mid, side="right") - 1, 0)


def commands_at(rec: Recording, a: PeriodAssignment, periods: np.ndarray) -> np.ndarray:
    """The commands in effect in the given periods by the hold rule of the module Notes.

    Parameters
    ----------
    rec : Recording
    a : PeriodAssignment
        From :func:`wheel_periods` of ``rec``.
    periods : array_like of int, shape (p,)
        Period indices (0 is the first kept wheel frame's).

    Returns
    -------
    ndarray, shape (p, 2)
        In the unit of ``rec.cmd_kind`` (wheel speeds [m/s] or a body twist).
    """
    periods = np.asarray(periods, dtype=np.int64)
    if rec.cmd_per_frame:
        k = a.period[a.keep]
        vals = rec.cmd.values[a.keep].astype(float)
        # each period takes the command of the first frame at or after it
        nxt = np.searchsorted(k, periods)
        return vals[np.minimum(nxt, k.size - 1)]
    c = a.clock
    mid = c.times_s(periods) + c.latency_median_s - 0.5 * c.period_s
    last = np.searchsorted(rec.cmd.t_s, mid, side="right") - 1
    out = rec.cmd.values[np.maximum(last, 0)].astype(float)
    out[last < 0] = 0.0
    return out


def _check_speed(name: str, wheel_m_s: np.ndarray, t_s: np.ndarray, limit: float,
                 sample: np.ndarray) -> None:
    """A :class:`WheelSpeedError` for the first period with a wheel over ``limit``;
    ``sample[k]`` is the index, in its stream, of the sample behind period ``k``."""
    bad = np.flatnonzero(np.any(np.abs(wheel_m_s) > limit, axis=1))
    if bad.size:
        k = int(bad[0])
        side = int(np.argmax(np.abs(wheel_m_s[k])))
        speed = float(np.abs(wheel_m_s[k, side]))
        raise WheelSpeedError(
            f"{name}: a wheel at {speed:.3g} m/s at t = {t_s[k]:.3f} s cannot be right "
            f"(limit {limit:g} m/s); check the field's unit and scale",
            field=name, side=side, sample=int(sample[k]), speed_m_s=speed, t_s=float(t_s[k]),
            limit_m_s=float(limit))


def _pose_at(rec: Recording, a: PeriodAssignment, t_grid: np.ndarray,
             max_gap_s: float | None) -> np.ndarray | None:
    if rec.true_pose is None:
        return None
    if np.array_equal(rec.true_pose.t_s, rec.wheel.t_s):      # one pose per wheel frame
        pose = rec.true_pose.values.astype(float).copy()
        pose[:, 2] = np.unwrap(pose[:, 2])
        k = a.period[a.keep].astype(float)
        grid = np.arange(1, t_grid.size, dtype=float)
        return np.stack([np.interp(grid, k, pose[a.keep, j]) for j in range(3)], axis=1)
    return poses_at(rec.true_pose, t_grid[1:], max_gap_s=max_gap_s)


def on_grid(rec: Recording, *, wheel_base_m: float,
            m_per_tick: float | np.ndarray | None = None,
            wheel_radius_m: float | None = None,
            encoders: Literal["quadrature", "commanded"] = "quadrature",
            max_wheel_speed_m_s: float = MAX_WHEEL_SPEED_M_S,
            periods_by: PeriodsBy = "stamps", max_gap_s: float | None = None) -> GridSignals:
    """Per-period wheel commands and body speeds of any recording (module Notes).

    Parameters
    ----------
    rec : Recording
        Any wheel and command kind.
    wheel_base_m : float
        Distance between the wheels' contact points [m].
    m_per_tick : float or ndarray of shape (2,), optional
        Encoder scale [m/tick] (paper eq. 13), or each wheel's (left, right)
        (:class:`lti_motion.intrinsics.OdometryIntrinsics`); needed for counts.
    wheel_radius_m : float, optional
        Wheel radius [m]; needed for wheel angles and speeds in rad/s.
    encoders : {"quadrature", "commanded"}
        ``"commanded"`` for counters that count in the commanded direction
        (Roomba / Create 2; :func:`~lti_motion.recordings.unfold_commanded_direction`),
        and wheel angles made from such counts.
    max_wheel_speed_m_s : float
        Fastest wheel speed that can be right [m/s]; faster is bad input.
    periods_by : {"stamps", "stamps_and_travel"}
        How wheel frames find their periods (module Notes, :func:`wheel_periods`).
    max_gap_s : float, optional
        The IMU's rate and the reference poses are blank across gaps in their stamps
        longer than this [s] (module Notes); ``None``: no gap rule.

    Returns
    -------
    GridSignals

    Raises
    ------
    ValueError
        If the scale a kind needs is missing, or fewer than 2 valid wheel frames
        remain; the message names the field.
    WheelSpeedError
        A ``ValueError``: a wheel (measured or commanded) exceeds
        ``max_wheel_speed_m_s``; the message names the field, and the error the
        wheel and the stream's sample behind it.

    Examples
    --------
    Wheel angles at 50 Hz of a robot driving straight at 0.2 m/s:

    >>> t = np.arange(50) * 0.02
    >>> rec = Recording.from_streams(wheel_t_s=t, wheel_angles_rad=np.outer(t, [5.0, 5.0]),
    ...                              cmd_wheel_m_s=np.full((50, 2), 0.2))
    >>> g = on_grid(rec, wheel_base_m=0.3, wheel_radius_m=0.04)
    >>> g.speeds.shape, np.allclose(g.speeds, [0.2, 0.0])
    ((49, 2), True)
    """
    v = rec.wheel.values
    a = wheel_periods(rec, periods_by=periods_by, encoders=encoders)
    n_periods = a.n_periods - 1
    t_grid = a.clock.times_s(np.arange(n_periods + 1))
    used = a.keep & rec.wheel_valid & np.all(np.isfinite(v), axis=1)   # NaN: did not arrive
    if used.sum() < 2:
        raise ValueError(f"{rec.wheel_kind}: fewer than 2 valid wheel frames")
    k_used = a.period[used].astype(float)
    travel = _cumulative(rec, used, a.clock.times_s(k_used), m_per_tick=m_per_tick,
                         wheel_radius_m=wheel_radius_m, encoders=encoders)
    grid = np.arange(n_periods + 1, dtype=float)
    cum = np.stack([np.interp(grid, k_used, travel[:, j]) for j in range(2)], axis=1)
    rate = np.diff(cum, axis=0) / a.clock.period_s
    if rec.wheel_kind == "body_speeds":
        speeds = rate
        wheel = wheel_from_body(rate, wheel_base_m=wheel_base_m)
    else:
        wheel, speeds = rate, body_from_wheel(rate, wheel_base_m=wheel_base_m)
    used_at = np.flatnonzero(used)       # the frame closing each period, or the next one's
    behind = used_at[np.minimum(np.searchsorted(k_used, grid[1:]), used_at.size - 1)]
    _check_speed(rec.wheel_kind, wheel, t_grid[1:], max_wheel_speed_m_s, behind)
    cmd = commands_at(rec, a, np.arange(1, n_periods + 1))
    if rec.cmd_kind == "cmd_body":
        cmd = wheel_from_body(cmd, wheel_base_m=wheel_base_m)
    _check_speed(rec.cmd_kind, cmd, t_grid[1:], max_wheel_speed_m_s,
                 _command_index(rec, a, np.arange(1, n_periods + 1)))
    closed = np.zeros(n_periods + 1, bool)
    closed[a.period[used]] = True
    measured = closed[1:] & closed[:-1]
    yaw = None if rec.yaw_rate is None else _integrate_at(rec.yaw_rate, t_grid, max_gap_s)
    return GridSignals(t_s=t_grid[1:], period_s=a.clock.period_s, cmd_m_s=cmd, speeds=speeds,
                       measured=measured, yaw_rate_rad_s=yaw,
                       true_pose=_pose_at(rec, a, t_grid, max_gap_s), assignment=a,
                       closed=closed)
