"""Stalled wheel or stuck encoder: what the motor currents say while an encoder count stands.

The stuck check (:meth:`~fusion.monitoring.ResidualMonitor.update_counts`) sees a
wheel's count stay flat while the command and the model say the wheel turns. Two
faults look the same to the encoders: the encoder stopped counting while its wheel
turns (``"stuck_encoder"``), or the wheel itself stopped, blocked by an obstacle
(``"stalled_wheel"``). The wheel's motor tells them apart. A DC motor with a
negligible armature inductance draws ``i = (V - k omega) / R`` (Franklin, Powell &
Emami-Naeini, *Feedback Control of Dynamic Systems*, section 2.3): while the wheel
turns at the commanded speed the back-EMF ``k omega`` nearly cancels the drive
voltage and the current carries only the friction and acceleration load; a blocked
wheel has no back-EMF, its speed loop raises the voltage, and the current climbs to
the driver's limit and stays there. The Open Interface reports each wheel motor's
current (packets 54/55) and sets an overcurrent flag (packet 14).

**Rule**, per wheel, over the flat stretch (the periods the stuck check counted):

1. an overcurrent flag in the stretch: ``"stalled_wheel"``;
2. else, with currents, the smallest ``|i|`` of the stretch against
   ``current_ratio`` times the wheel's running current ``i_ref`` (the median
   ``|i|`` over the last ``history`` periods in which that wheel's count moved):
   below it, ``"stuck_encoder"`` at once (the smallest current of a stretch can
   only fall); at or above it, ``"stalled_wheel"`` once the stretch holds
   ``decide_periods`` periods. The smallest, because a start from rest holds a
   healthy motor at its limit for up to 6 periods on the simulator, while a
   blocked wheel stays there as long as it is blocked;
3. without a running current yet (fewer than ``min_history`` moving periods),
   only the overcurrent flag decides: ``"stuck_encoder"`` after
   ``overcurrent_wait_periods`` flat periods without one;
4. without currents (a robot that reports none): ``"stuck_encoder"`` at once,
   as before this check, with :attr:`WheelVerdict.evidence` ``"no currents"``.

Measured on the simulator (``docs/monitor.md``): a blocked wheel holds 0.45 A (the
limit) from its first period; healthy driving has a median of 0.03 A and at most 6
periods at or above 0.1 A; a stuck encoder's motor keeps its running current.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Literal

import numpy as np

from fusion.exceptions import FilterOptionError, MeasurementShapeError

__all__ = ["WheelCheck", "WheelCheckOptions", "WheelVerdict"]

WheelFault = Literal["stalled_wheel", "stuck_encoder"]


@dataclass(frozen=True)
class WheelCheckOptions:
    """Settings of :class:`WheelCheck` (module rule).

    Attributes
    ----------
    current_ratio : float
        A flat stretch whose smallest current is at least this many times the
        running current is a stalled wheel.
    decide_periods : int
        Flat periods before a high current is called a stall (longer than a
        start from rest holds a healthy motor at its limit).
    history : int
        Moving periods in the running current's median.
    min_history : int
        Moving periods needed before the running current is used.
    overcurrent_wait_periods : int
        Without a running current: flat periods to wait for an overcurrent flag.
    """

    current_ratio: float = 4.0
    decide_periods: int = 10
    history: int = 200
    min_history: int = 20
    overcurrent_wait_periods: int = 40

    def __post_init__(self) -> None:
        bad = [name for name, ok in (("current_ratio", self.current_ratio > 1.0),
                                     ("decide_periods", self.decide_periods >= 1),
                                     ("history", self.history >= 1),
                                     ("min_history", 1 <= self.min_history <= self.history),
                                     ("overcurrent_wait_periods",
                                      self.overcurrent_wait_periods >= 1)) if not ok]
        if bad:
            raise FilterOptionError(f"WheelCheckOptions out of range: {', '.join(bad)}")


@dataclass(frozen=True)
class WheelVerdict:
    """What the motor said about a wheel whose count stood.

    Attributes
    ----------
    kind : {"stalled_wheel", "stuck_encoder"}
        The fault.
    wheel : int
        0 left, 1 right.
    evidence : str
        ``"overcurrent"``, ``"current"`` or ``"no currents"``.
    min_current_a : float
        Smallest ``|i|`` of the flat stretch [A] (NaN without currents).
    reference_current_a : float
        The running current ``i_ref`` [A] (NaN when unknown).
    """

    kind: WheelFault
    wheel: int
    evidence: str
    min_current_a: float = math.nan
    reference_current_a: float = math.nan


class WheelCheck:
    """Running motor-current evidence of two wheels (module rule).

    Parameters
    ----------
    options : WheelCheckOptions, optional

    Examples
    --------
    >>> wc = WheelCheck()
    >>> for _ in range(30):                      # driving: counts move, 30 mA each
    ...     wc.update(np.array([False, False]), np.array([7.0, 7.0]), np.array([0.03, 0.03]))
    >>> for _ in range(10):                      # the left count stands at 450 mA
    ...     wc.update(np.array([True, False]), np.array([0.0, 7.0]), np.array([0.45, 0.03]))
    >>> wc.verdict(0).kind, wc.verdict(0).evidence
    ('stalled_wheel', 'current')
    """

    def __init__(self, options: WheelCheckOptions | None = None) -> None:
        self.options = options or WheelCheckOptions()
        self._history = (deque(maxlen=self.options.history),
                         deque(maxlen=self.options.history))
        self._n = np.zeros(2, dtype=int)             # flat periods with currents
        self._min = np.full(2, math.inf)
        self._over = np.zeros(2, dtype=bool)
        self._reported = False

    def update(self, flat: np.ndarray, tick_deltas: np.ndarray,
               motor_current_a: np.ndarray | None = None,
               wheel_overcurrent: np.ndarray | None = None) -> None:
        """Take one period: which wheels' counts stood (as the stuck check counts them),
        the count changes [ticks], the motor currents [A] and overcurrent flags.

        Raises
        ------
        MeasurementShapeError
            If a given array is not of shape (2,).
        """
        flat = np.asarray(flat, dtype=bool)
        d = np.asarray(tick_deltas, dtype=float)
        cur = None if motor_current_a is None else np.abs(np.asarray(motor_current_a, float))
        over = (np.zeros(2, dtype=bool) if wheel_overcurrent is None
                else np.asarray(wheel_overcurrent, dtype=bool))
        for name, a in (("flat", flat), ("tick_deltas", d), ("motor_current_a", cur),
                        ("wheel_overcurrent", over)):
            if a is not None and a.shape != (2,):
                raise MeasurementShapeError(f"{name} must have shape (2,), got {a.shape}")
        self._reported = cur is not None and bool(np.all(np.isfinite(cur)))
        if not self._reported:
            self._n[:] = 0
            self._min[:] = math.inf
            self._over[:] = False
            return
        for w in range(2):
            if flat[w]:
                self._n[w] += 1
                self._min[w] = min(self._min[w], cur[w])
                self._over[w] |= bool(over[w])
                continue
            self._n[w], self._min[w], self._over[w] = 0, math.inf, False
            if d[w] != 0:
                self._history[w].append(cur[w])

    def reference_current_a(self, wheel: int) -> float:
        """The running current ``i_ref`` of ``wheel`` [A]; NaN before ``min_history``."""
        h = self._history[wheel]
        return float(np.median(h)) if len(h) >= self.options.min_history else math.nan

    def verdict(self, wheel: int) -> WheelVerdict | None:
        """Stalled wheel or stuck encoder for ``wheel``'s current flat stretch; None: wait."""
        opt = self.options
        if not self._reported:
            return WheelVerdict("stuck_encoder", wheel, "no currents")
        low, ref = float(self._min[wheel]), self.reference_current_a(wheel)
        if self._over[wheel]:
            return WheelVerdict("stalled_wheel", wheel, "overcurrent", low, ref)
        if math.isnan(ref):
            if self._n[wheel] >= opt.overcurrent_wait_periods:
                return WheelVerdict("stuck_encoder", wheel, "current", low, ref)
            return None
        if low < opt.current_ratio * ref:
            return WheelVerdict("stuck_encoder", wheel, "current", low, ref)
        if self._n[wheel] >= opt.decide_periods:
            return WheelVerdict("stalled_wheel", wheel, "current", low, ref)
        return None
