"""Real clocks: the robot's sensor period, offset and drift from host timestamps.

A robot samples its sensors every period ``T`` of its own clock; the host
stamps each frame when it arrives, later by a latency that is never negative
and jitters by milliseconds (USB serial adapters deliver in bursts, a busy
host schedules late). Frames get lost, delivered twice or late, and the
robot's clock drifts against the host's by tens of ppm. This module recovers,
without raising on any of that:

- the clock line ``t = offset_s + period_s k`` (host seconds of the sensor
  period ``k``), fitted to the *lower envelope* of the stamps, since latency is
  one-sided: a least-squares line through the earliest arrivals
  (:func:`fit_clock`);
- the sensor period each frame belongs to, strictly increasing along the
  frames (:func:`assign_periods`), with counts of what was merged, dropped,
  pulled back and lost.

Notes
-----
Assignment rule. With the envelope line, frame ``i`` cannot have been sampled
after period ``u_i = floor((t_i - offset_s) / period_s + 1/4)`` (latency >= 0;
the quarter period absorbs the envelope's own error). Frames arrive in the
order they were sampled, so frame ``i``'s period is at most one less than
frame ``i + 1``'s: ``k_i = min(u_i, k_{i+1} - 1)``, the latest period
consistent with every later frame (a backward running minimum). A frame that
arrived more than a period late is pulled back by the on-time frame after it;
a gap in ``k`` is a lost frame. Frames the caller marks as duplicates (same
stamp and payload as the one before) are merged; frames whose stamp is not
finite are dropped. The period is found by fitting on a growing prefix (64 frames,
then doubling), so a drift of 100 ppm over hours never accumulates into a
wrong period count. The fitted period replaces the nominal one only where
they differ by more than three standard errors of the fit (a short record
cannot resolve a drift: 100 frames with 1 ms of jitter leave 200 ppm of
uncertainty); under 64 frames only the offset is fitted.

References
----------
.. [1] Olson, E. "A passive solution to the sensor synchronization problem",
   IROS 2010, section III: the minimum of (host - sensor) time differences as
   the latency-free envelope.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

__all__ = ["ClockFit", "PeriodAssignment", "assign_periods", "fit_clock"]

_log = logging.getLogger(__name__)

#: Fraction of a period by which a stamp may fall below the envelope line.
_ENVELOPE_SLACK = 0.25
#: Fraction of the residuals, lowest first, the envelope line is fitted to.
_ENVELOPE_FRACTION = 0.3
#: Size of the first prefix the period is fitted on [frames].
_FIRST_PREFIX = 64


@dataclass(frozen=True)
class ClockFit:
    """The robot's sensor clock as seen from the host.

    Attributes
    ----------
    period_s : float
        Sensor period in host seconds (the nominal period times ``rate``).
    offset_s : float
        Host time of period 0 on the latency-free envelope [s].
    rate : float
        ``period_s / nominal period``; ``(rate - 1) * 1e6`` is the drift [ppm].
    latency_median_s : float
        Median arrival latency above the envelope [s].
    """

    period_s: float
    offset_s: float
    rate: float
    latency_median_s: float

    @property
    def drift_ppm(self) -> float:
        """Drift of the robot's clock against the host's [ppm] (positive: robot slow)."""
        return (self.rate - 1.0) * 1e6

    def times_s(self, k: np.ndarray) -> np.ndarray:
        """Host time [s] of the sensor periods ``k`` on the envelope line."""
        return self.offset_s + self.period_s * np.asarray(k, dtype=float)


@dataclass(frozen=True)
class PeriodAssignment:
    """Which sensor period each frame closes.

    Attributes
    ----------
    period : ndarray of int64, shape (n,)
        Period index of each frame (0 for the first kept frame), strictly
        increasing over kept frames; -1 for a frame merged or dropped.
    keep : ndarray of bool, shape (n,)
        Frames that close a period.
    clock : ClockFit
        The fitted clock.
    n_merged : int
        Frames merged into the one before (duplicates).
    n_dropped : int
        Frames dropped (stamp not finite).
    n_late : int
        Frames that arrived more than a period late, pulled back to their period.
    n_missing : int
        Periods between the first and last kept frame with no frame (lost).
    """

    period: np.ndarray
    keep: np.ndarray
    clock: ClockFit
    n_merged: int
    n_dropped: int
    n_late: int
    n_missing: int

    @property
    def n_periods(self) -> int:
        """Periods from the first kept frame to the last, both included."""
        kept = self.period[self.keep]
        return int(kept[-1] + 1) if kept.size else 0

    def summary(self) -> str:
        """One line: period, drift and the frame counts."""
        c = self.clock
        return (f"sensor period {c.period_s * 1e3:.4f} ms ({c.drift_ppm:+.0f} ppm against "
                f"the nominal {c.period_s / c.rate * 1e3:.4f} ms), "
                f"median latency {c.latency_median_s * 1e3:.1f} ms; {self.n_missing} periods "
                f"lost, {self.n_late} frames late, {self.n_merged} merged, "
                f"{self.n_dropped} dropped")


def _envelope_line(k: np.ndarray, t: np.ndarray, nominal: float
                   ) -> tuple[float, float, np.ndarray]:
    """Least-squares line through the lowest residuals, then lowered onto the envelope.

    The slope stays ``nominal`` unless the fitted one differs from it by more
    than three standard errors (a short record cannot resolve a drift).
    """
    k = k.astype(float)
    period, offset = np.polyfit(k, t, 1)
    low = np.ones(k.size, bool)
    for _ in range(3):                        # reweight: keep the earliest arrivals
        r = t - (offset + period * k)
        sub = r <= np.quantile(r, _ENVELOPE_FRACTION)
        if sub.sum() < 3 or np.ptp(k[sub]) == 0:
            break
        low = sub
        period, offset = np.polyfit(k[low], t[low], 1)
    r_low = t[low] - (offset + period * k[low])
    # standard error of an LS slope: s / (sqrt(m) std(k)), Montgomery 2012 eq. 2.10
    se = float(np.std(r_low) / (np.sqrt(low.sum()) * max(np.std(k[low]), 1e-12)))
    if abs(period - nominal) <= 3.0 * se:
        period, offset = nominal, float(np.mean(t[low] - nominal * k[low]))
    r = t - (offset + period * k)
    floor = np.quantile(r, 0.01) if r.size >= 100 else r.min()
    return float(period), float(offset + floor), r - floor


def _monotone_periods(t: np.ndarray, period_s: float, offset_s: float) -> np.ndarray:
    """Latest strictly increasing periods no later than each stamp allows (module Notes)."""
    upper = np.floor((t - offset_s) / period_s + _ENVELOPE_SLACK).astype(np.int64)
    idx = np.arange(t.size, dtype=np.int64)
    # k_i = min_{j >= i} (u_j - (j - i)): a backward running minimum of u_j - j
    return idx + np.minimum.accumulate((upper - idx)[::-1])[::-1]


def fit_clock(t_s: np.ndarray, *, dt_s: float | None = None) -> tuple[ClockFit, np.ndarray]:
    """Fit the sensor clock line to increasing host stamps of consecutive frames.

    Parameters
    ----------
    t_s : array_like, shape (n,)
        Host stamps [s], finite and never decreasing, no two equal
        (:func:`assign_periods` cleans raw stamps first).
    dt_s : float, optional
        Nominal sensor period [s]; by default the median frame interval.

    Returns
    -------
    clock : ClockFit
    period : ndarray of int64, shape (n,)
        Strictly increasing period of each frame, the first 0.

    Raises
    ------
    ValueError
        If fewer than 2 stamps are given or ``dt_s`` is not positive.
    """
    t = np.asarray(t_s, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"a clock fit needs at least 2 frame times, got shape {t.shape}")
    nominal = float(np.median(np.diff(t))) if dt_s is None else float(dt_s)
    if not (np.isfinite(nominal) and nominal > 0):
        raise ValueError(f"the sensor period must be a positive number of seconds, got {dt_s}")
    n = min(_FIRST_PREFIX, t.size)
    # a lower bound of the envelope: lost frames only make t_i - T i larger, latency too
    period, offset = nominal, float(np.min(t[:n] - nominal * np.arange(n)))
    while t.size >= _FIRST_PREFIX:
        for _ in range(2):                    # assignment and line, to their fixed point
            k = _monotone_periods(t[:n], period, offset)
            period, offset, _ = _envelope_line(k, t[:n], nominal)
        if n == t.size:
            break
        n = min(2 * n, t.size)
    k = _monotone_periods(t, period, offset)
    if t.size >= _FIRST_PREFIX:
        period, offset, latency = _envelope_line(k, t, nominal)
    else:                                     # too few frames to beat the nominal period
        latency = t - period * k
        offset = float(latency.min())
        latency = latency - offset
    k = _monotone_periods(t, period, offset)
    offset += period * k[0]
    k = k - k[0]
    clock = ClockFit(period_s=period, offset_s=offset, rate=period / nominal,
                     latency_median_s=float(np.median(latency)))
    return clock, k


def assign_periods(t_s: np.ndarray, *, dt_s: float | None = None,
                   duplicate: np.ndarray | None = None) -> PeriodAssignment:
    """Assign frames to the robot's sensor periods; never raises on jitter, gaps or repeats.

    Parameters
    ----------
    t_s : array_like, shape (n,)
        Host stamps of the frames in arrival order [s]. Stamps that are not
        finite are dropped; equal stamps (a burst delivery) are fine. Stamps
        that go backwards are bad input.
    dt_s : float, optional
        Nominal sensor period [s]; by default the median frame interval.
    duplicate : array_like of bool, shape (n,), optional
        Frames known to repeat the one before (same stamp and payload):
        merged into it.

    Returns
    -------
    PeriodAssignment

    Raises
    ------
    ValueError
        If a finite stamp is earlier than a finite stamp before it, or fewer
        than 2 distinct finite stamps remain.

    Examples
    --------
    Frames every 15 ms with up to 9 ms latency, the 4th lost and the 6th
    arriving 20 ms late (after the 7th would have, were the 7th not later):

    >>> t = np.array([0.002, 0.016, 0.031, 0.062, 0.097, 0.1, 0.121])
    >>> a = assign_periods(t, dt_s=0.015)
    >>> a.period.tolist(), a.n_missing, a.n_late
    ([0, 1, 2, 4, 5, 6, 8], 2, 1)
    """
    t = np.asarray(t_s, dtype=float).ravel()
    finite = np.isfinite(t)
    back = np.flatnonzero(np.diff(t[finite]) < 0)
    if back.size:
        i = int(np.flatnonzero(finite)[back[0] + 1])
        raise ValueError(f"frame times go backwards at frame {i}: {t[i]:.6f} s after "
                         f"{t[finite][back[0]]:.6f} s")
    dup = np.zeros(t.size, bool) if duplicate is None else np.asarray(duplicate, bool).ravel()
    if dup.shape != t.shape:
        raise ValueError(f"duplicate must have shape {t.shape}, got {dup.shape}")
    keep = finite & ~dup
    if keep.sum() < 2:
        raise ValueError(f"at least 2 distinct finite frame times are needed, got {keep.sum()}")
    clock, k = fit_clock(t[keep], dt_s=dt_s)
    period = np.full(t.size, -1, dtype=np.int64)
    period[keep] = k
    upper = np.floor((t[keep] - clock.offset_s) / clock.period_s + _ENVELOPE_SLACK)
    n_late = int(np.sum(upper > k))
    n_missing = int(k[-1] + 1 - k.size)
    out = PeriodAssignment(period=period, keep=keep, clock=clock,
                           n_merged=int((dup & finite).sum()),
                           n_dropped=int((~finite).sum()), n_late=n_late, n_missing=n_missing)
    if out.n_merged or out.n_dropped:
        _log.info("clock: %s", out.summary())
    return out
