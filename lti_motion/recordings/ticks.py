"""Encoder counts to wheel and body speeds.

The Roomba / Create 2 reports each wheel's encoder as an unsigned 16-bit
counter that wraps (Open Interface packets 43 and 44). The counts
are unwrapped with the shortest signed step on the 16-bit ring, which is
correct in both directions as long as fewer than 32768 ticks (14.5 m of
wheel travel) pass between two frames.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from lti_motion.exceptions import ShapeError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import body_from_wheel
from lti_motion.recordings.clocks import assign_periods

__all__ = [
    "TICK_MODULUS",
    "body_speeds_from_ticks",
    "stream_clock",
    "tick_deltas",
    "tick_step",
    "unfold_commanded_direction",
    "unwrap_ticks",
]

#: Encoder counters are 16-bit: they wrap at 65536 ticks.
TICK_MODULUS = 1 << 16


def tick_deltas(ticks: np.ndarray, *, axis: int = 0, counter_bits: int = 16) -> np.ndarray:
    """Signed tick increments between consecutive raw counts.

    Parameters
    ----------
    ticks : array_like of int
        Raw counts (any integer values; taken modulo ``2**counter_bits``).
    axis : int
        The time axis.
    counter_bits : int
        Width of the counters (16: the Open Interface's); 63 or 64: they never
        wrap (signed 64-bit counts, plain differences).

    Returns
    -------
    ndarray of int64
        One element fewer than ``ticks`` along ``axis``:
        ``((c - p + 32768) mod 65536) - 32768`` (spec §7.2, :mod:`drivers.roomba.oi`), on a
        ``2**counter_bits`` ring in general: the shortest signed step.

    Examples
    --------
    >>> tick_deltas(np.array([65530, 5, 65530])).tolist()
    [11, -11]
    >>> tick_deltas(np.array([2**24 - 6, 5]), counter_bits=24).tolist()
    [11]
    """
    return _ring_step(np.diff(np.asarray(ticks, dtype=np.int64), axis=axis), counter_bits)


def tick_step(prev: np.ndarray, now: np.ndarray, *, counter_bits: int = 16) -> np.ndarray:
    """Signed tick increments from the raw counts ``prev`` to ``now``, elementwise.

    :func:`tick_deltas` of the two rows ``[prev, now]``, without stacking them
    (per-period callers).

    Examples
    --------
    >>> tick_step(np.array([65530, 5]), np.array([5, 65530])).tolist()
    [11, -11]
    """
    return _ring_step(np.asarray(now, dtype=np.int64) - np.asarray(prev, dtype=np.int64),
                      counter_bits)


def _ring_step(diff: np.ndarray, counter_bits: int) -> np.ndarray:
    """``((diff + half) mod 2**bits) - half`` (spec §7.2): the shortest signed step
    on the counters' ring; plain differences from 63 bits (counters that never wrap)."""
    if counter_bits >= 63:
        return diff
    modulus = 1 << counter_bits
    half = modulus // 2
    return (diff + half) % modulus - half


def unwrap_ticks(ticks: np.ndarray, *, axis: int = 0, counter_bits: int = 16) -> np.ndarray:
    """Unwrap raw counts into a continuous count starting at the first sample.

    Parameters
    ----------
    ticks : array_like of int
        Raw counts; the first sample along ``axis`` is the origin.
    axis : int
        The time axis.
    counter_bits : int
        Width of the counters (16: the Open Interface's; :func:`tick_deltas`).

    Returns
    -------
    ndarray of int64
        Same shape as ``ticks``; the first sample along ``axis`` is 0.

    Examples
    --------
    >>> unwrap_ticks(np.array([65534, 65535, 0, 1, 0, 65535])).tolist()
    [0, 1, 2, 3, 2, 1]
    """
    ticks = np.asarray(ticks, dtype=np.int64)
    steps = tick_deltas(ticks, axis=axis, counter_bits=counter_bits)
    zero_shape = list(ticks.shape)
    zero_shape[axis] = 1
    return np.cumsum(np.concatenate([np.zeros(zero_shape, np.int64), steps], axis=axis), axis=axis)


def body_speeds_from_ticks(
    ticks: np.ndarray,
    t_s: np.ndarray,
    *,
    m_per_tick: float | None = None,
    wheel_base_m: float | None = None,
    intrinsics: OdometryIntrinsics | None = None,
    encoders: Literal["quadrature", "commanded"] = "quadrature",
) -> np.ndarray:
    """Body speeds (v, w) over each frame interval from raw encoder counts.

    Parameters
    ----------
    ticks : ndarray of int, shape (n, 2)
        Raw counts (left, right) of consecutive frames.
    t_s : ndarray, shape (n,)
        Frame timestamps [s].
    m_per_tick : float, optional
        Encoder scale of both wheels [m/tick] (paper eq. 13); with ``wheel_base_m``,
        or give ``intrinsics`` instead.
    wheel_base_m : float, optional
        Distance between the wheels' contact points [m].
    intrinsics : OdometryIntrinsics, optional
        Each wheel's scale and the wheel base (unequal wheels); excludes the two above.
    encoders : {"quadrature", "commanded"}
        ``"commanded"`` for encoders that count in the commanded direction
        (Roomba / Create 2): the sign around reversals is restored with
        :func:`unfold_commanded_direction`.

    Returns
    -------
    ndarray, shape (n - 1, 2)
        ``v = (vR + vL) / 2`` [m/s] and ``w = (vR - vL) / b`` [rad/s] over
        each interval (paper section II.B, Fig. 1).

    Raises
    ------
    ShapeError
        If the shapes do not match.
    ValueError
        If timestamps do not increase, ``wheel_base_m`` is not positive, or the
        scales are given both ways or not at all.

    Examples
    --------
    >>> k = OdometryIntrinsics(1e-3, 1e-3, 0.25)
    >>> body_speeds_from_ticks(np.array([[0, 0], [10, 30]]), np.array([0.0, 0.1]),
    ...                        intrinsics=k).round(9).tolist()
    [[0.2, 0.8]]
    """
    if intrinsics is None:
        if m_per_tick is None or wheel_base_m is None:
            raise ValueError("give the encoder scale: m_per_tick and wheel_base_m, or intrinsics")
        intrinsics = OdometryIntrinsics.symmetric(m_per_tick=m_per_tick,
                                                  wheel_base_m=wheel_base_m)
    elif m_per_tick is not None or wheel_base_m is not None:
        raise ValueError("give either intrinsics or m_per_tick and wheel_base_m, not both")
    ticks = np.asarray(ticks)
    t_s = np.asarray(t_s, dtype=float)
    if ticks.ndim != 2 or ticks.shape[1] != 2 or t_s.shape != (ticks.shape[0],):
        raise ShapeError(
            f"expected ticks of shape (n, 2) and t_s of shape (n,), got {ticks.shape} "
            f"and {t_s.shape}"
        )
    dt = np.diff(t_s)
    if np.any(dt <= 0):
        raise ValueError(f"timestamps must increase; first bad step at index {np.argmin(dt)}")
    deltas = tick_deltas(ticks, axis=0)
    if encoders == "commanded":
        deltas = unfold_commanded_direction(deltas)
    elif encoders != "quadrature":
        raise ValueError(f"encoders must be 'quadrature' or 'commanded', got {encoders!r}")
    scale = np.array([intrinsics.m_per_tick_left, intrinsics.m_per_tick_right])
    wheel = deltas * (scale / dt[:, None])         # the same rounding as one m_per_tick
    return body_from_wheel(wheel, wheel_base_m=intrinsics.wheel_base_m)


def stream_clock(t_s: np.ndarray, dt_s: float) -> np.ndarray:
    """Timestamps on the robot's own sensor clock, recovered from jittered host times.

    The robot samples its encoders every period; the host stamps each frame
    on arrival, with latency jitter of a millisecond or more (USB serial
    adapters deliver in bursts). Differencing counts over host times turns
    that jitter into speed noise proportional to speed (1 ms of jitter on a
    15 ms period is 7% of the speed). This returns the time of each frame's
    sensor period on the clock line fitted to the stamps' latency-free
    envelope (:func:`lti_motion.recordings.assign_periods`: sensor period, offset
    and drift; frames assigned to periods monotonically), so gaps from lost
    frames are kept and jitter, drift and late frames never raise.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Host timestamps [s], never decreasing.
    dt_s : float
        The robot's nominal sensor period [s].

    Returns
    -------
    ndarray, shape (n,)
        Increasing; a frame whose stamp is not finite gets the time of the
        next frame.

    Raises
    ------
    ValueError
        If the stamps go backwards or fewer than 2 are distinct.

    Examples
    --------
    >>> t = stream_clock(np.array([0.0021, 0.0158, 0.0312, 0.0611]), 0.015)
    >>> np.round(np.diff(t) / 0.015, 3).tolist()
    [1.0, 1.0, 2.0]
    """
    a = assign_periods(t_s, dt_s=dt_s)
    k = a.period.copy()
    kept = np.flatnonzero(a.keep)
    nxt = kept[np.minimum(np.searchsorted(kept, np.arange(k.size)), kept.size - 1)]
    k[~a.keep] = a.period[nxt[~a.keep]]
    return a.clock.times_s(k)


def unfold_commanded_direction(deltas: np.ndarray, *, window: int = 12) -> np.ndarray:
    """Restore the sign of tick increments from encoders that count in the commanded direction.

    The Roomba's encoders are not quadrature: they count in the direction the
    firmware is commanding, not the direction the wheel turns (spec §6.2,
    :mod:`drivers.roomba.oi`). When a command reverses a wheel, the count runs backwards while the
    wheel is still rolling the old way and slowing down. The true wheel speed
    is continuous through zero, so after each flip of the count direction the
    sign is put back until the count rate reaches its minimum (the wheel
    stops), searched over the next ``window`` frames and never past the next
    flip.

    Parameters
    ----------
    deltas : ndarray of int or float, shape (n,) or (n, k)
        Tick increments per frame (from :func:`tick_deltas`), or wheel-angle increments
        [rad] made from such counts, one column per wheel.
    window : int
        Frames after a flip within which the wheel must stop (about 180 ms at
        15 ms; a wheel at 0.5 m/s stops in about 130 ms under the current limit).

    Returns
    -------
    ndarray of int64 (float for float increments)
        Same shape; increments with the wheel's true direction of rotation.

    Examples
    --------
    A wheel at +8 ticks per frame commanded to reverse: the count turns negative
    at once (-5, -2) while the wheel slows, then goes on in the new direction.

    >>> unfold_commanded_direction(np.array([8, 8, -5, -2, -1, -4, -8])).tolist()
    [8, 8, 5, 2, -1, -4, -8]
    """
    deltas = np.asarray(deltas)
    deltas = deltas.astype(float if deltas.dtype.kind == "f" else np.int64)
    if deltas.ndim == 1:
        return unfold_commanded_direction(deltas[:, None], window=window)[:, 0]
    out = deltas.copy()
    for col in range(deltas.shape[1]):
        d = deltas[:, col]
        moving = np.flatnonzero(d)
        if moving.size < 2:
            continue
        sign = np.sign(d[moving])
        flips = moving[1:][sign[1:] != sign[:-1]]
        for i, k in enumerate(flips):
            end = min(k + window, flips[i + 1] if i + 1 < len(flips) else len(d))
            if end - k < 2:
                continue
            # the flip frame itself mixes both directions: look for the stop after it, the
            # first smallest increment (float increments equal but for rounding tie)
            mag = np.abs(d[k + 1:end])
            stop = k + 1 + int(np.flatnonzero(mag <= mag.min() * (1.0 + 1e-9))[0])
            if stop > k + 1:                     # still slowing down: it rolled the old way
                out[k:stop, col] = -d[k:stop]
    return out
