"""Clocks across a bag's topics: header stamps against the bag's receive times, one time base.

A robot stamps its messages with its own clock; the commanding PC stamps (or, for a bare
``geometry_msgs/Twist``, only receives) the commands with another; the recorder stamps
every message with its receive time. When the robot's clock and the PC's disagree, the
header stamps put the wheels' motion before the commands that caused it, and the model
fitted on them is wrong without a word. :func:`clock_check` measures, per topic, the
median of ``header stamp - receive time`` (a topic without header stamps: 0, its stamps
*are* its receive times), and the lag from the commands to the wheels' motion under both
time bases (:func:`command_lag_s`); :func:`choose_time_base` picks the one the drive is
read on (``"auto"``: the header stamps unless the topics' offsets disagree by more than
one wheel period, then the receive times, one clock for every topic).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from drivers.bags.topics import StampedSeries

__all__ = ["MAX_LAG_S", "STAMP_CHOICES", "ClockCheck", "choose_time_base", "command_lag_s"]

#: The time bases a drive can be read on (``--stamps``).
STAMP_CHOICES = ("auto", "header", "receive")
#: The command-to-motion lags tried, either way [s].
MAX_LAG_S = 2.0

Stamps = Literal["auto", "header", "receive"]


@dataclass(frozen=True)
class ClockCheck:
    """What the clocks of a bag's topics say, and the time base chosen.

    Attributes
    ----------
    offsets_s : Mapping of str to float
        Per topic read, the median of header stamp minus receive time [s] (0 for a
        topic without header stamps).
    spread_s : float
        The commands' offset minus the wheels' (or the wheels' alone), as a magnitude [s]:
        what the choice rests on.
    period_s : float
        The wheel stream's median period [s] (receive times), the tolerance.
    lag_s : Mapping of str to float or None
        The lag from the commands to the wheels' motion [s] under ``"header"`` and
        ``"receive"`` stamps (:func:`command_lag_s`; ``None``: no motion to time; empty:
        no commands).
    requested, chosen : str
        The ``stamps`` asked for and the time base used.
    """

    offsets_s: Mapping[str, float]
    spread_s: float
    period_s: float
    lag_s: Mapping[str, float | None]
    requested: str
    chosen: str

    @property
    def disagree(self) -> bool:
        """Whether the commands' and the wheels' clocks disagree by more than one period."""
        return self.spread_s > self.period_s

    def lines(self) -> list[str]:
        """The check as printable lines."""
        offsets = ", ".join(f"{t} {1e3 * o:+.1f} ms" for t, o in self.offsets_s.items())
        lags = ", ".join(f"{base} {'not found' if lag is None else f'{1e3 * lag:+.0f} ms'}"
                         for base, lag in self.lag_s.items())
        out = [f"clocks: header stamp - receive time per topic: {offsets}; "
               + (f"lag from commands to wheel motion: {lags}" if self.lag_s else
                  "no commands to time the wheels against")]
        if self.disagree:
            out.append(f"clocks: the commands' and the wheels' clocks disagree by "
                       f"{self.spread_s:.3f} s, more than "
                       f"a period ({1e3 * self.period_s:.1f} ms): the robot's clock and the "
                       "commanding PC's are offset")
        why = {"auto": " (auto: " + ("the header stamps disagree, the receive times are one "
                                     "clock)" if self.chosen == "receive" else
                                     "the header stamps agree)"),
               "header": " (--stamps header)", "receive": " (--stamps receive)"}
        out.append(f"stamps: {self.chosen} times for every topic{why[self.requested]}")
        return out

    def as_meta(self) -> dict:
        """The check as a recording's ``meta["clocks"]`` (plain types)."""
        return {"offsets_s": dict(self.offsets_s), "spread_s": self.spread_s,
                "period_s": self.period_s, "lag_s": dict(self.lag_s),
                "requested": self.requested, "chosen": self.chosen, "lines": self.lines()}


def _rates(t_ns: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mid-interval times [s] and finite-difference rates of ``values`` per second."""
    t = t_ns * 1e-9
    dt = np.diff(t)
    keep = dt > 0
    rates = np.diff(values, axis=0)[keep] / dt[keep, None]
    return (0.5 * (t[1:] + t[:-1]))[keep], rates


def command_lag_s(cmd: StampedSeries, wheels: StampedSeries, *, body_speeds: bool,
                  period_s: float, max_lag_s: float = MAX_LAG_S) -> float | None:
    """The lag from the commands to the wheels' motion [s] on the series' own stamps.

    The commanded ``(v, w)`` (held between messages) and the measured motion (the wheel
    angles' rates as their sum and difference, or an odometry twist's ``(v, w)``) on one
    grid of ``period_s``, each channel's mean removed and scaled to unit variance; the lag
    is the shift, within ``+-max_lag_s``, that maximises the sum of the two channels'
    cross-correlations (Bendat and Piersol 2010, section 5.1.2: the peak of the
    cross-correlation of an input and a delayed output is at the delay). Negative: the
    wheels move before they are commanded, which no robot does.

    Parameters
    ----------
    cmd : StampedSeries
        Commands, columns ``(v [m/s], w [rad/s])``.
    wheels : StampedSeries
        Wheel angles ``(left, right)`` [rad], or odometry (its columns 3 and 4: v, w).
    body_speeds : bool
        ``wheels`` is odometry.
    period_s : float
        The grid period [s].
    max_lag_s : float
        The largest lag tried either way [s].

    Returns
    -------
    float or None
        The lag [s]; ``None`` when a channel is constant over the overlap.

    References
    ----------
    J. S. Bendat and A. G. Piersol, *Random Data*, 4th ed., Wiley, 2010, section 5.1.2.
    """
    if len(cmd) < 2 or len(wheels) < 3:
        return None
    if body_speeds:
        t_y, y = wheels.t_ns[1:] * 1e-9, wheels.values[1:, 3:5]
    else:
        t_y, rates = _rates(wheels.t_ns, wheels.values[:, :2])
        y = np.column_stack([rates.sum(axis=1), rates[:, 1] - rates[:, 0]])
    t0 = max(cmd.t_ns[0] * 1e-9, t_y[0])
    t1 = min(cmd.t_ns[-1] * 1e-9, t_y[-1])
    if t1 - t0 < 4 * max_lag_s:
        return None
    grid = np.arange(t0, t1, period_s)
    held = np.searchsorted(cmd.t_ns * 1e-9, grid, side="right") - 1
    u = cmd.values[np.clip(held, 0, len(cmd) - 1)]
    yg = np.column_stack([np.interp(grid, t_y, y[:, j]) for j in range(2)])
    m = round(max_lag_s / period_s)
    total = np.zeros(2 * m + 1)
    used = 0
    for j in range(2):
        a, b = u[:, j] - u[:, j].mean(), yg[:, j] - yg[:, j].mean()
        if not (a.std() > 0 and b.std() > 0):
            continue
        a, b = a / a.std(), b / b.std()
        n = len(a)
        total += [np.dot(a[max(0, -k):n - max(0, k)], b[max(0, k):n - max(0, -k)]) / n
                  for k in range(-m, m + 1)]
        used += 1
    if not used:
        return None
    return float((int(np.argmax(total)) - m) * period_s)


def _offset_s(series: StampedSeries) -> float:
    if series.recv_ns is None or not series.header:
        return 0.0
    return float(np.median(series.t_ns - series.recv_ns) * 1e-9)


def _on_receive(series: StampedSeries) -> StampedSeries:
    if series.recv_ns is None or not series.header:
        return series
    return replace(series, t_ns=series.recv_ns)


def choose_time_base(series: Mapping[str, StampedSeries | None], *,
                     stamps: Stamps = "auto") -> tuple[dict[str, StampedSeries | None],
                                                       ClockCheck]:
    """The series on one time base, and the check that chose it.

    Parameters
    ----------
    series : Mapping of str to StampedSeries or None
        The kinds read (``cmd``, ``wheels``, ``odom``, ``imu``, ``truth``), each with
        its receive times (``recv_ns``); a ``truth`` from tf keeps its header stamps.
    stamps : {"auto", "header", "receive"}
        ``"auto"``: header stamps unless the offsets (header minus receive) of the
        commands and the wheels disagree by more than one wheel period (the other topics
        follow the choice: it does not depend on which of them were read).

    Returns
    -------
    dict of str to StampedSeries or None
        The series, on receive times where chosen.
    ClockCheck

    Raises
    ------
    ValueError
        For an unknown ``stamps``.
    """
    if stamps not in STAMP_CHOICES:
        raise ValueError(f"stamps must be one of {', '.join(STAMP_CHOICES)}, got {stamps!r}")
    present = {k: s for k, s in series.items() if s is not None and s.recv_ns is not None}
    offsets = {s.topic: _offset_s(s) for s in present.values()}
    wheels = series.get("wheels") or series.get("odom")
    # the choice rests on the commands and the wheels alone, whose lag the model learns: an
    # Imu or a reference read or not (replay reads them, calibrate does not) must not move it
    timing = [_offset_s(s) for s in (series.get("cmd"), wheels)
              if s is not None and s.recv_ns is not None]
    spread = max(timing) - min(timing) if timing else 0.0
    body = series.get("wheels") is None
    period = (float(np.median(np.diff(wheels.recv_ns))) * 1e-9
              if wheels is not None and wheels.recv_ns is not None and len(wheels) > 1 else 0.0)
    lag: dict[str, float | None] = {}
    cmd = series.get("cmd")
    if cmd is not None and wheels is not None and period > 0:
        lag["header"] = command_lag_s(cmd, wheels, body_speeds=body, period_s=period)
        lag["receive"] = command_lag_s(_on_receive(cmd), _on_receive(wheels),
                                       body_speeds=body, period_s=period)
    chosen = stamps if stamps != "auto" else ("receive" if spread > period > 0 else "header")
    out = dict(series)
    if chosen == "receive":
        out = {k: None if s is None else _on_receive(s) for k, s in series.items()}
    return out, ClockCheck(offsets_s=offsets, spread_s=spread, period_s=period, lag_s=lag,
                           requested=stamps, chosen=chosen)
