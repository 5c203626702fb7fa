"""Real clocks: the robot's sensor period, offset and drift from host timestamps.

A robot samples its sensors every period ``T`` of its own clock; the host
stamps each frame when it arrives, later by a latency that is never negative
and jitters by milliseconds (USB serial adapters deliver in bursts, a busy
host schedules late). Frames get lost, delivered twice or late, and the
robot's clock drifts against the host's by tens of ppm. This module recovers,
without raising on any of that:

- the clock line ``t = offset_s + period_s k`` (host seconds of the sensor
  period ``k``) on the *lower envelope* of the stamps, the latency-free
  arrival (:func:`fit_clock`);
- the sensor period each frame belongs to, strictly increasing along the
  frames (:func:`assign_periods`), with counts of what was merged, dropped,
  late, lost and moved.

Notes
-----
Assignment rule. Frames arrive in the order they were sampled, so frame ``i``
closes period ``k_i = i + g_i``, where ``g_i``, the frames lost before it, never
decreases. With the clock line through the median stamp, ``g`` is the
nondecreasing staircase nearest (least squares) to ``(t_i - offset) / period
- i``: an isotonic regression (pool adjacent violators, Barlow et al. 1972,
section 1.2, [2]_), rounded to whole periods. A frame that arrived late is pulled
back by the on-time frames around it (their violations pool); a step in ``g``
is a lost frame. This holds for latency with a hard floor (a serial link:
most frames at the floor, a tail of late ones) and for jitter on both sides
of its mean (a bag's host stamps) alike; a frame is misnumbered only where
it strays half a period from the typical arrival beside a lost frame, whose
period it then takes. Given the frames' cumulative *travel* (wheel angles,
unwrapped counts), such a frame is moved into the free period beside it when
that makes the travel per period at least twice as even (the sum over the
columns of the change of travel per period over the frame before and the one
after, which a robot's inertia keeps small: a misplaced frame shows as one
period of double travel and one of none), where its stamp lies at most three
quarters of a period before the period's time on the typical arrival line
(envelope plus median latency) and at most two periods after it. Frames the
caller marks as duplicates (same stamp and payload as the one before) are
merged; frames whose stamp is not finite are dropped.

Clock line. The period is the slope of a least-squares line through the
numbered stamps (stamps more than five MADs off it left out), or of the
earliest 30 % of them where the two agree within three standard errors (a
hard latency floor makes the earliest arrivals the sharpest, [1]_). It is
found on a growing prefix (64 frames, the offset alone first, then
doubling), so a drift of 100 ppm over hours never accumulates into a wrong
period count. The fitted period replaces the nominal one only where they
differ by more than three standard errors of the fit (a short record cannot
resolve a drift: 100 frames with 1 ms of jitter leave 200 ppm of
uncertainty); under 64 frames only the offset is fitted. The envelope lies
at the 1 % quantile of the residuals (the lowest under 100 frames).

References
----------
.. [1] Olson, E. "A passive solution to the sensor synchronization problem",
   IROS 2010, section III: the minimum of (host - sensor) time differences as
   the latency-free envelope.
.. [2] Barlow, R. E., Bartholomew, D. J., Bremner, J. M., Brunk, H. D.
   "Statistical inference under order restrictions", Wiley 1972, section 1.2:
   the pool-adjacent-violators algorithm.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.optimize import isotonic_regression

__all__ = ["ClockFit", "PeriodAssignment", "assign_periods", "fit_clock", "median_period_s",
           "snap_period_s"]

_log = logging.getLogger(__name__)

#: A frame later than (1 - this) periods above the envelope counts as late.
_ENVELOPE_SLACK = 0.25
#: Fraction of the residuals, lowest first, the envelope's slope is fitted to.
_ENVELOPE_FRACTION = 0.3
#: Residuals further than this many (scaled) MADs from their median are left out of the line.
_OUTLIER_MADS = 5.0
#: Size of the first prefix the period is fitted on [frames].
_FIRST_PREFIX = 64
#: A move into a free period must make the travel per period this much more even.
_EVEN_GAIN = 2.0
#: Latest a frame may arrive after the period it is moved into, on the typical arrival
#: line [periods].
_MAX_LATENCY_PERIODS = 2.0
#: Earliest a frame may arrive before the period it is moved into, on that line [periods].
_MAX_EARLY_PERIODS = 0.75


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
        Frames that arrived later than three quarters of a period after their
        period's envelope time (they would have been taken for the next period).
    n_missing : int
        Periods between the first and last kept frame with no frame (lost).
    n_moved : int
        Frames moved into a free period beside them by their travel
        (module Notes; 0 without ``travel``).
    """

    period: np.ndarray
    keep: np.ndarray
    clock: ClockFit
    n_merged: int
    n_dropped: int
    n_late: int
    n_missing: int
    n_moved: int = 0

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
                f"{self.n_dropped} dropped, {self.n_moved} moved by their travel")


def _line(k: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    """Least-squares slope and intercept of ``t`` against ``k`` (centred normal equations)."""
    k_mean, t_mean = k.mean(), t.mean()
    dk = k - k_mean
    slope = float(np.sum(dk * (t - t_mean)) / np.sum(dk * dk))
    return slope, float(t_mean - slope * k_mean)


def _clock_line(k: np.ndarray, t: np.ndarray, nominal: float) -> tuple[float, float]:
    """Least-squares line ``t = offset + period k``, stamps far off it left out.

    Stamps more than :data:`_OUTLIER_MADS` scaled median absolute deviations
    from the median residual (a misnumbered frame, a burst) are left out of
    the fit. The slope of the earliest :data:`_ENVELOPE_FRACTION` of the
    arrivals replaces it where the two agree within three standard errors
    (latency with a hard floor: the earliest arrivals scatter least, Olson
    2010 section III). The slope stays ``nominal`` unless the fitted one
    differs from it by more than three standard errors (a short record cannot
    resolve a drift). The offset is the median line's, the centre the frames are
    numbered around (module Notes).
    """
    k = k.astype(float)
    period, offset = _line(k, t)
    for _ in range(2):
        r = t - (offset + period * k)
        mid = np.median(r)
        spread = 1.4826 * float(np.median(np.abs(r - mid)))      # MAD as a std
        inlier = np.abs(r - mid) <= _OUTLIER_MADS * max(spread, 1e-12)
        if inlier.sum() < 3 or np.ptp(k[inlier]) == 0:
            break
        period, offset = _line(k[inlier], t[inlier])
    r = t[inlier] - (offset + period * k[inlier])
    # standard error of an LS slope: s / (sqrt(n) std(k)), Montgomery 2012 eq. 2.10
    se = float(np.std(r) / (np.sqrt(r.size) * max(float(np.std(k[inlier])), 1e-12)))
    low = r <= np.quantile(r, _ENVELOPE_FRACTION)     # the earliest arrivals
    if low.sum() >= 3 and np.ptp(k[inlier][low]) > 0:
        envelope = _line(k[inlier][low], t[inlier][low])[0]
        if abs(envelope - period) <= 3.0 * se:        # a hard latency floor: sharper
            period = envelope
    if abs(period - nominal) <= 3.0 * se:
        period = nominal
    return float(period), float(np.median(t - period * k))


def _isotonic_periods(t: np.ndarray, period_s: float, offset_s: float) -> np.ndarray:
    """Strictly increasing periods nearest the stamps (module Notes): ``k_i = i + g_i``
    with ``g`` the frames lost before frame ``i``, a nondecreasing staircase."""
    idx = np.arange(t.size, dtype=np.int64)
    y = (t - offset_s) / period_s - idx
    g = isotonic_regression(y).x              # pool adjacent violators, L2
    return idx + np.rint(g).astype(np.int64)


def _unevenness(travel: np.ndarray, i: np.ndarray, k_prev: np.ndarray, k_i: np.ndarray,
                k_next: np.ndarray) -> np.ndarray:
    """Change of travel per period over the frames before and after frames ``i`` on periods
    ``k_i``, summed over the columns (module Notes)."""
    before = (travel[i] - travel[i - 1]) / (k_i - k_prev)[:, None]
    after = (travel[i + 1] - travel[i]) / (k_next - k_i)[:, None]
    return np.abs(after - before).sum(axis=1)


def _even_travel(k: np.ndarray, x: np.ndarray, travel: np.ndarray) -> tuple[np.ndarray, int]:
    """Frames beside a free period moved into it where their travel says so (module Notes).

    ``k`` are the frames' periods, ``x`` their stamps in periods on the
    typical arrival line (envelope plus median latency), ``travel`` their
    cumulative travel, shape (n, c) (a row with a NaN is never moved nor
    judged by). The candidates are screened at once, then moved one by one,
    each checked again against its neighbours' periods as they then are.
    """
    k = k.copy()
    gaps = np.diff(k) >= 2
    cand = np.flatnonzero(gaps[:-1] | gaps[1:]) + 1           # beside a free period
    moved = 0
    if not cand.size:
        return k, moved

    def better(i: np.ndarray, new: np.ndarray) -> np.ndarray:
        prev, nxt = k[i - 1], k[i + 1]
        ok = (prev < new) & (new < nxt) & (x[i] - new > -_MAX_EARLY_PERIODS) & (
            x[i] - new < _MAX_LATENCY_PERIODS)
        with np.errstate(invalid="ignore", divide="ignore"):
            now = _unevenness(travel, i, prev, k[i], nxt)
            then = _unevenness(travel, i, prev, np.where(ok, new, k[i]), nxt)
        return ok & (_EVEN_GAIN * then < now)

    screened = cand[better(cand, k[cand] - 1) | better(cand, k[cand] + 1)]
    for i in screened:                         # few: one at a time, neighbours as they are
        one = np.array([i])
        for new in (k[i] - 1, k[i] + 1):
            if better(one, np.array([new]))[0]:
                k[i] = new
                moved += 1
                break
    return k, moved


def median_period_s(t_s: np.ndarray) -> float:
    """The median interval of increasing stamps, lost frames and bursts aside [s].

    The median of the positive intervals, then the median of those between
    half and 1.5 times it (a lost frame's double interval and a burst's
    short one left out).

    Raises
    ------
    ValueError
        If no two stamps differ.

    Examples
    --------
    >>> median_period_s(np.array([0.0, 0.02, 0.04, 0.08, 0.1, 0.1]))
    0.02
    """
    steps = np.diff(np.asarray(t_s, dtype=float))
    steps = steps[steps > 0]
    if not steps.size:
        raise ValueError("no sensor period in the stamps: no two of them differ")
    rough = float(np.median(steps))
    return float(np.median(steps[(steps > 0.5 * rough) & (steps < 1.5 * rough)]))


def snap_period_s(period_s: float, *, rel_tol: float = 1e-3) -> float:
    """A fitted period as the nominal one a robot is configured with [s].

    A whole 0.1 ms (15 ms) or a whole rate in Hz (30 Hz: 33.33 ms) within
    ``rel_tol``, else the period rounded to 0.1 us. A clock drift of 100 ppm
    is well inside the default 0.1 %.

    Examples
    --------
    >>> snap_period_s(0.0200013), round(snap_period_s(0.033339), 9), snap_period_s(0.0173456)
    (0.02, 0.033333333, 0.0173456)
    """
    for nominal in (round(period_s, 4), 1.0 / round(1.0 / period_s)):
        if abs(nominal - period_s) <= rel_tol * period_s:
            return float(nominal)
    return round(float(period_s), 7)


def fit_clock(t_s: np.ndarray, *, dt_s: float | None = None) -> tuple[ClockFit, np.ndarray]:
    """Fit the sensor clock line to increasing host stamps of consecutive frames.

    Parameters
    ----------
    t_s : array_like, shape (n,)
        Host stamps [s], finite and never decreasing, no two equal
        (:func:`assign_periods` cleans raw stamps first).
    dt_s : float, optional
        Nominal sensor period [s]; by default :func:`median_period_s`.

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
    nominal = median_period_s(t) if dt_s is None else float(dt_s)
    if not (np.isfinite(nominal) and nominal > 0):
        raise ValueError(f"the sensor period must be a positive number of seconds, got {dt_s}")
    n = min(_FIRST_PREFIX, t.size)
    period = nominal
    offset = float(np.median(t[:n] - nominal * np.arange(n)))
    for _ in range(3):                        # the offset first, on the nominal period
        k = _isotonic_periods(t[:n], period, offset)
        offset = float(np.median(t[:n] - period * k))
    while t.size >= _FIRST_PREFIX:
        k_before = None
        for _ in range(3):                    # assignment and line, to their fixed point
            k = _isotonic_periods(t[:n], period, offset)
            if k_before is not None and np.array_equal(k, k_before):
                break
            period, offset = _clock_line(k, t[:n], nominal)
            k_before = k
        if n == t.size:
            break
        n = min(2 * n, t.size)
    k = _isotonic_periods(t, period, offset)
    r = t - (offset + period * k)
    floor = float(np.quantile(r, 0.01) if r.size >= 100 else r.min())
    latency = r - floor                       # above the latency-free envelope
    offset += floor + period * k[0]
    k = k - k[0]
    clock = ClockFit(period_s=period, offset_s=offset, rate=period / nominal,
                     latency_median_s=float(np.median(latency)))
    return clock, k


def assign_periods(t_s: np.ndarray, *, dt_s: float | None = None,
                   duplicate: np.ndarray | None = None,
                   travel: np.ndarray | None = None) -> PeriodAssignment:
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
    travel : array_like, shape (n, c), optional
        Cumulative travel of each frame (wheel angles [rad], unwrapped counts;
        NaN for a frame whose reading is unusable): a frame beside a free
        period moves into it where that evens the travel per period (module
        Notes). Without it the stamps alone decide.

    Returns
    -------
    PeriodAssignment

    Raises
    ------
    ValueError
        If a finite stamp is earlier than a finite stamp before it, fewer
        than 2 distinct finite stamps remain, or ``travel`` has not one row
        per frame.

    Examples
    --------
    Frames every 15 ms with 1-2 ms latency, the 4th lost, the 6th arriving
    20 ms late together with the 7th (a burst), the 9th lost:

    >>> t = np.array([0.002, 0.016, 0.031, 0.062, 0.095, 0.095, 0.106, 0.122, 0.152])
    >>> a = assign_periods(t, dt_s=0.015)
    >>> a.period.tolist(), a.n_missing, a.n_late
    ([0, 1, 2, 4, 5, 6, 7, 8, 10], 2, 1)
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
    x = (t[keep] - clock.offset_s) / clock.period_s
    typical = x - clock.latency_median_s / clock.period_s     # on the typical arrival line
    moved = 0
    if travel is not None:
        cum = np.asarray(travel, dtype=float)
        cum = cum[:, None] if cum.ndim == 1 else cum
        if cum.shape[0] != t.size:
            raise ValueError(f"travel must have {t.size} rows, one per frame, got "
                             f"{cum.shape[0]}")
        if k.size >= 3:
            k, moved = _even_travel(k, typical, cum[keep])
    period = np.full(t.size, -1, dtype=np.int64)
    period[keep] = k
    n_late = int(np.sum(np.floor(x + _ENVELOPE_SLACK) > k))
    n_missing = int(k[-1] + 1 - k.size)
    out = PeriodAssignment(period=period, keep=keep, clock=clock,
                           n_merged=int((dup & finite).sum()),
                           n_dropped=int((~finite).sum()), n_late=n_late, n_missing=n_missing,
                           n_moved=moved)
    if out.n_merged or out.n_dropped:
        _log.info("clock: %s", out.summary())
    return out
