"""Dynamics-change tests on integrated encoder residuals: lag, start and covariance CUSUMs.

The window residuals and their nominal distribution are in
:mod:`fusion.monitoring.dynamics_null` (free-run travel over windows of ``H`` periods;
``e = r - Phi beta ~ N(0, Sigma)`` under the null, its statistic ``q``, the
lag evidence ``a`` and information ``b``). Three one-sided CUSUMs (Page 1954)
run on each robot's windows; an alarm is raised when one crosses its
threshold, and all restart. Windows in the first ``null.skip_windows`` after
the monitor starts are not tested (the null was fitted without them).

**Lag test.** The dynamics faults of ``docs/monitor.md`` act mostly as extra lag: a payload
accelerates more slowly under the motors' current limit, a weakened motor
likewise at high demand, and a command delay is a lag. A response late by
``theta`` periods shifts ``e`` by ``-theta s`` (``s`` the window's lag
signature), so under the alternative ``a ~ N(theta b, b)``. The
log-likelihood ratio of a lag ``theta1`` against none, for a change in the
mean along a known direction (Basseville & Nikiforov 1993, section 7.2.1,
eq. 7.2.8 with a one-dimensional direction)::

    llr_lag = theta1 a - theta1^2 b / 2                                   (eq. 3)

A window without a transient has ``b ~ 0`` and leaves the CUSUM where it
is; only speed changes and turns move it. ``theta1`` = 1 period by default:
the smallest lag worth an alarm (a payload of +50% lags by about one period
in each start, a 3-period delay by three).

Threshold from the false-alarm budget ``F_lag``: under the null the
increments are Gaussian, ``N(-mu^2 / 2, mu^2)`` with ``mu = theta1 sqrt(b)``,
so the CUSUM is a normal-mean CUSUM with reference ``k = mu / 2`` and
threshold ``h / mu`` in standard units; Siegmund's approximation of its
in-control run length (Siegmund 1985, eq. 2.56; Basseville & Nikiforov 1993,
eq. 5.2.44) is solved for ``h`` (:func:`lag_cusum_threshold`) with ``mu`` from
the median information of the null's informative windows (``b > 1``) and the
run length counted in informative windows, ``N_inf / F_lag`` with ``N_inf``
the informative windows an hour. Lorden's bound ``h = ln(N / F)`` would hold
too but counts every window, most of which carry no lag information, and is
needlessly high. On the route the nominal ``a / sqrt(b)`` of informative windows
is close to N(0, 1), with misfit at a few manoeuvres (``docs/monitor.md``).

**Covariance test** (kept from the first design, catches faults that are not
a lag, e.g. a weakened motor's overshoot): the log-likelihood ratio of a
covariance ``lambda^2 Sigma`` against ``Sigma`` (Basseville & Nikiforov 1993,
section 2.2, eq. 2.2.4 with a scalar covariance change)::

    llr_cov = 0.5 (1 - 1 / lambda^2) min(q, q_clip) - ln(lambda^2)        (eq. 4)

``q`` clipped (Huber) so one window cannot raise an alarm alone; threshold
``h = ln(N_w / F_cov)`` (Lorden 1971, theorem 2: ``ARL0 >= exp(h)``),
``N_w`` = 8,000 windows an hour of 0.45 s, ``F_cov = 0.05``: ``h = 12.0``.

**Start test** (:mod:`fusion.monitoring.dynamics_start`): a payload shows only at a
drive start from rest, late in the start window and catching up in the next
two. Each start's three windows give a score ``Z`` (eq. 7 there, near N(0, 1)
under the null); a CUSUM over starts of ``mu1 Z - mu1^2 / 2`` with
``mu1 = 3`` (one start's worth of evidence), threshold set from nominal
driving (peaks over threshold,
:func:`~fusion.monitoring.start_threshold_from_maxima`):
:data:`START_THRESHOLD` = 7.16 for ``F_start = 0.1`` an hour, fitted on 10.8 h
of route driving (seeds 5000-5649, ``python -m benchmarks monitor_threshold``).
It is a property of the null and the route: refit it for other driving.

**Onset.** An alarm is dated by the posterior change time of the tripping test's
increments since the previous alarm, with an interval
(:mod:`fusion.monitoring.change_time`); the window at which the CUSUM last left
zero is kept as :attr:`DynamicsAlarm.cusum_onset_s`.

Budget: ``F_lag + F_start + F_cov = 0.25 + 0.1 + 0.05 = 0.4`` false alarms an
hour by design, against a target of 1; the rates measured on nominal driving
(``python -m benchmarks monitor``) are in ``docs/monitor.md``.

References
----------
Page, E. S. (1954). Continuous inspection schemes. Biometrika 41, 100-115.
Lorden, G. (1971). Procedures for reacting to a change in distribution.
Annals of Mathematical Statistics 42, 1897-1908, theorem 2.
Siegmund, D. (1985). Sequential Analysis. Springer, eq. 2.56.
Basseville, M., Nikiforov, I. (1993). Detection of Abrupt Changes, sections
2.2, 5.2 and 7.2.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fusion.exceptions import FilterOptionError
from fusion.monitoring.change_time import ChangeTimeRule, ChangeTimeTracker
from fusion.monitoring.cusum import cusum_llr_threshold, lag_cusum_threshold
from fusion.monitoring.dynamics_null import (
    DynamicsNull,
    WindowIntegrator,
    WindowResiduals,
    WindowStatistics,
    _error_and_cov,
    _statistics,
    fit_dynamics_null,
    integrated_residuals,
    window_statistics,
)
from fusion.monitoring.dynamics_start import (
    START_WINDOWS,
    StartTracker,
    drive_start_anchors,
    start_evidence,
)
from lti_motion.model.motion_model import MotionModel

__all__ = [
    "START_THRESHOLD",
    "DynamicsAlarm",
    "DynamicsMonitor",
    "DynamicsNull",
    "WindowResiduals",
    "WindowStatistics",
    "fit_dynamics_null",
    "integrated_residuals",
    "start_scores",
    "window_statistics",
]

#: Threshold [nats] of the start CUSUM (``mu1 = 3``) for 0.1 false alarms an hour,
#: from the per-run maxima on 10.8 h of nominal route driving, seeds 5000-5649
#: (module docstring; ``python -m benchmarks monitor_threshold`` recomputes it).
START_THRESHOLD = 7.16






@dataclass(frozen=True)
class DynamicsAlarm:
    """One alarm of :class:`DynamicsMonitor`.

    Attributes
    ----------
    robot : int
        Index of the robot.
    test : {"lag", "start", "covariance"}
        The CUSUM that crossed.
    statistic, threshold : float
        Its value and threshold [nats].
    onset_s : float
        The posterior change time (:mod:`fusion.monitoring.change_time`): the
        median of the change window given the tripping test's evidence over
        the windows since the previous alarm [s].
    lag_periods : float
        Least-squares lag since the lag CUSUM last left zero, ``sum a / sum b``
        [periods] (NaN without lag information).
    lag_std_periods : float
        Its standard deviation ``1 / sqrt(sum b)`` [periods] (``a ~ N(theta b, b)``,
        module docstring); NaN without lag information. A window without a
        transient carries ``b ~ 0``: after such windows only, the lag is
        meaningless (its deviation is huge).
    onset_lo_s, onset_hi_s : float
        The change time's interval at its rule's level [s].
    cusum_onset_s : float
        Start of the window at which the tripping CUSUM last left zero (for
        the start test: the anchor window of that start) [s]: the first
        design's onset, often long before the change.
    """

    robot: int
    test: str
    statistic: float
    threshold: float
    onset_s: float
    lag_periods: float
    lag_std_periods: float = math.nan
    onset_lo_s: float = math.nan
    onset_hi_s: float = math.nan
    cusum_onset_s: float = math.nan


class DynamicsMonitor:
    """Streaming dynamics-change tests for ``n_robots`` robots in lock step (module docstring).

    Parameters
    ----------
    model : MotionModel
        Calibrated model with ``m_per_tick``.
    null : DynamicsNull or None
        Nominal window distribution (:func:`fit_dynamics_null`); ``None``
        computes window residuals only (no test).
    n_robots : int
        Robots fed together.
    window_periods : int
        ``H`` (taken from ``null`` when given).
    lag_periods : float
        ``theta1`` of the lag test [periods].
    lag_false_alarms_per_hour, covariance_false_alarms_per_hour : float
        Budgets of the lag and covariance tests, per robot.
    start_shift_sigma : float
        ``mu1`` of the start test [standard deviations of ``Z``].
    start_threshold : float
        ``h`` of the start test [nats] (:data:`START_THRESHOLD`; the test is
        off when the null has no start distribution).
    variance_ratio : float
        ``lambda^2`` of the covariance test.
    clip : float
        ``q_clip``.
    glitch_ticks : float
        See :class:`fusion.monitoring.WindowIntegrator`.
    change_time : ChangeTimeRule, optional
        How an alarm's onset is dated (:mod:`fusion.monitoring.change_time`).

    Attributes
    ----------
    lag_threshold, covariance_threshold, start_threshold : float
        ``h`` of the three tests [nats].
    statistic : ndarray, shape (n_robots, 2)
        Current CUSUM values ``g`` (lag, covariance).
    start_statistic : ndarray, shape (n_robots,)
        Current value of the start CUSUM.
    alarms : list of DynamicsAlarm
        Every alarm raised.
    """

    def __init__(self, model: MotionModel, null: DynamicsNull | None, *, n_robots: int = 1,
                 window_periods: int = 30, lag_periods: float = 1.0,
                 lag_false_alarms_per_hour: float = 0.25,
                 covariance_false_alarms_per_hour: float = 0.05, variance_ratio: float = 4.0,
                 clip: float = 16.0, glitch_ticks: float = 25.0, start_shift_sigma: float = 3.0,
                 start_threshold: float = START_THRESHOLD,
                 change_time: ChangeTimeRule | None = None) -> None:
        if not (variance_ratio > 1 and clip > 0 and lag_periods > 0):
            raise FilterOptionError(f"need variance_ratio > 1, clip > 0, lag_periods > 0; got "
                                    f"{variance_ratio}, {clip}, {lag_periods}")
        if not (start_shift_sigma > 0 and start_threshold > 0):
            raise FilterOptionError(f"need start_shift_sigma > 0 and start_threshold > 0; got "
                                    f"{start_shift_sigma} and {start_threshold}")
        self.model, self.null = model, null
        self.window_periods = null.window_periods if null is not None else int(window_periods)
        self._integ = WindowIntegrator(model, n_robots=n_robots,
                                       window_periods=self.window_periods,
                                       glitch_ticks=glitch_ticks)
        self.variance_ratio, self.clip, self.lag_periods = (float(variance_ratio), float(clip),
                                                            float(lag_periods))
        windows_per_hour = 3600.0 / (model.dt_s * self.window_periods)
        self.covariance_threshold = cusum_llr_threshold(windows_per_hour,
                                                        covariance_false_alarms_per_hour)
        self.lag_threshold = math.inf
        if null is not None and null.informative_fraction > 0:
            self.lag_threshold = lag_cusum_threshold(
                null.informative_fraction * windows_per_hour, lag_false_alarms_per_hour,
                shift_sigma=self.lag_periods * math.sqrt(null.lag_information_median))
        self.start_shift_sigma = float(start_shift_sigma)
        self.start_threshold = (float(start_threshold) if null is not None and null.start
                                is not None else math.inf)
        n = int(n_robots)
        self._start = StartTracker(n, window_periods=self.window_periods)
        self._change = ChangeTimeTracker(n, 3, window_s=self.window_periods * model.dt_s,
                                         rule=change_time)
        self._s_prev = np.zeros((n, 2, 2))
        self._g = np.zeros((n, 3))                 # CUSUMs: lag, covariance, start
        self._left = np.zeros((n, 3))              # window start at which g last left zero
        self._ab = np.zeros((n, 2))                # sum of a, b since the lag CUSUM left zero
        self._t0 = 0.0
        self._n_windows = 0
        self.last_q = np.full(n, math.nan)
        self.alarms: list[DynamicsAlarm] = []

    @property
    def statistic(self) -> np.ndarray:
        """Current lag and covariance CUSUMs, ``(n_robots, 2)`` (a view)."""
        return self._g[:, :2]

    @property
    def start_statistic(self) -> np.ndarray:
        """Current start CUSUM, ``(n_robots,)`` (a view)."""
        return self._g[:, 2]

    @property
    def threshold(self) -> float:
        """``h`` of the covariance test (the first design's name)."""
        return self.covariance_threshold

    def _llr(self, st: WindowStatistics, ok: np.ndarray, score: np.ndarray) -> np.ndarray:
        th = self.lag_periods
        lam2 = self.variance_ratio
        mu = self.start_shift_sigma
        llr = np.stack([th * st.lag_evidence - 0.5 * th * th * st.lag_information,    # eq. 3
                        0.5 * (1.0 - 1.0 / lam2) * np.minimum(st.q, self.clip)        # eq. 4
                        - math.log(lam2)], axis=1)
        llr = np.where(ok[:, None], llr, 0.0)
        start = np.where(np.isfinite(score), mu * score - 0.5 * mu * mu, 0.0)    # B&N 2.2
        return np.concatenate([llr, start[:, None]], axis=1)

    def update(self, t_s: float, cmd_m_s: np.ndarray, tick_deltas: np.ndarray
               ) -> list[DynamicsAlarm]:
        """Feed one period of every robot; returns the alarms it raised (also appended to
        :attr:`alarms`).

        Parameters
        ----------
        t_s : float
            Time of the frame closing the period [s].
        cmd_m_s : ndarray, shape (n_robots, 2) or (2,)
            Commands in effect over the period [m/s].
        tick_deltas : ndarray, same shape
            Count changes over the period [ticks]; NaN: missing.
        """
        n = self.statistic.shape[0]
        u = np.asarray(cmd_m_s, float).reshape(n, 2)
        d = np.asarray(tick_deltas, float).reshape(n, 2)
        if self._integ.at_window_start:
            self._t0 = float(t_s) - self.model.dt_s
        self._start.period(u, self._integ.period_in_window)
        win = self._integ.step(u, d)
        if win is None or self.null is None:
            return []
        r, s, p, ok = win
        self._n_windows += 1
        ok = ok & (self._n_windows > self.null.skip_windows)
        e, cov = _error_and_cov(self.null, r, s, p, self._s_prev)
        st = _statistics(e, cov, s)
        self._s_prev = np.stack([s, self._s_prev[:, 0]], axis=1)
        self.last_q = np.where(ok, st.q, math.nan)
        z = self._start.window(e, cov, s, ok)
        score = (self.null.start.score(z) if self.null.start is not None
                 else np.full(len(z), math.nan))
        llr = self._llr(st, ok, score)
        self._change.push(self._t0, llr)
        g_new = np.maximum(0.0, self._g + llr)                               # Page 1954
        span = (START_WINDOWS - 1) * self.window_periods * self.model.dt_s
        onset = np.array([self._t0, self._t0, self._t0 - span])          # start: its anchor
        self._left = np.where((self._g == 0) & (g_new > 0), onset, self._left)
        restart = (self._g[:, 0] == 0) & (g_new[:, 0] > 0)
        self._ab = np.where(restart[:, None], 0.0, self._ab)
        self._ab += np.where(ok[:, None], np.stack([st.lag_evidence, st.lag_information], 1),
                             0.0)
        self._g = g_new
        thresholds = np.array([self.lag_threshold, self.covariance_threshold,
                               self.start_threshold])
        out = []
        for i in np.flatnonzero(np.any(g_new > thresholds, axis=1)):
            j = int(np.argmax(g_new[i] - thresholds))
            info = self._ab[i, 1]
            lag, lag_std = ((self._ab[i, 0] / info, 1.0 / math.sqrt(info)) if info > 0
                            else (math.nan, math.nan))
            when = self._change.estimate(int(i), j)
            # a start's score closes its third window: the start began two windows earlier
            back = span if j == 2 else 0.0
            alarm = DynamicsAlarm(int(i), ("lag", "covariance", "start")[j], float(g_new[i, j]),
                                  float(thresholds[j]), when.onset_s - back, float(lag),
                                  float(lag_std), when.lo_s - back, when.hi_s,
                                  float(self._left[i, j]))
            self._change.reset(int(i))
            self.alarms.append(alarm)
            out.append(alarm)
            self._g[i] = 0.0
            self._ab[i] = 0.0
        return out

    def reset(self, robots: Sequence[int] | None = None) -> None:
        """Restart the CUSUMs of ``robots`` (all by default)."""
        idx = slice(None) if robots is None else np.asarray(robots, int)
        self._g[idx] = 0.0
        self._ab[idx] = 0.0
        for i in np.arange(self._g.shape[0])[idx]:
            self._change.reset(int(i))


def start_scores(null: DynamicsNull, windows: WindowResiduals, cmd_m_s: np.ndarray
                 ) -> np.ndarray:
    """Start scores ``Z`` of whole drives, at the window closing each event (the batch form).

    What :class:`DynamicsMonitor`'s start test adds up: ``Z``
    (:mod:`fusion.monitoring.dynamics_start`, eq. 7) at the third window of each event,
    NaN elsewhere; the first ``null.skip_windows`` windows are not tested.

    Parameters
    ----------
    null : DynamicsNull
        Nominal distribution, with ``start``.
    windows : WindowResiduals
        Windows of :func:`integrated_residuals` of the same drives.
    cmd_m_s : ndarray, shape (..., n, 2)
        The drives' commands [m/s].

    Returns
    -------
    ndarray, shape (..., n_windows)

    Raises
    ------
    FilterOptionError
        If the null has no start distribution.
    """
    if null.start is None:
        raise FilterOptionError("the null has no start distribution (fewer than 10 drive "
                                "starts in its nominal driving)")
    s = windows.lag_signature_ticks
    e, cov = _error_and_cov(null, windows.residual_ticks, s, windows.predicted_ticks,
                            windows.previous_signature_ticks)
    ok = windows.valid.copy()
    ok[..., :null.skip_windows] = False
    anchors = drive_start_anchors(cmd_m_s, window_periods=null.window_periods)
    z = null.start.score(start_evidence(e, cov, s, ok, anchors))
    out = np.full_like(z, np.nan)
    out[..., START_WINDOWS - 1:] = z[..., :z.shape[-1] - START_WINDOWS + 1]
    return out
