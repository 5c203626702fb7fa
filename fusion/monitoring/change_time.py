"""When did the dynamics change? A posterior change time with a stated interval.

The dynamics CUSUMs (:mod:`fusion.monitoring.dynamics`) date an alarm to the
window at which the tripping statistic last left zero: the maximum-likelihood
change time for a known post-change distribution (Basseville & Nikiforov
1993, section 2.6: ``argmax_tau S_tau``, with ``S_tau`` the log-likelihood
ratio summed from window ``tau`` to now). Alone it states no uncertainty, and
under the null the CUSUM wanders above zero for long stretches, so that date
can precede the change by many seconds (10.8 s on the monitor's drives,
``docs/monitor.md``). This module states the uncertainty: with a uniform prior
over the windows since the previous alarm, the posterior of the change
window (Smith 1975) is::

    p(tau) ~ exp(kappa S_tau),   S_tau = sum_{j >= tau} l_j                 (eq. 1)

with ``l_j`` the tripping test's log-likelihood-ratio increment of window ``j``
(eqs. 3 and 4 of :mod:`fusion.monitoring.dynamics`, or the start test's) and
``kappa = 1`` for the exact likelihood. The nominal windows' tails are heavier
than the tests' Gaussian model (``docs/monitor.md``), which makes ``kappa = 1``
overconfident; ``kappa < 1`` tempers the likelihood. The estimate is the
posterior median window's start; the interval at ``level`` is one-sided, from
the start of the ``1 - level`` quantile's window to the end of the alarm's
window (a change that raised the alarm began before it). Windows without
evidence (``l_j = 0``: no transient) leave the posterior flat across them: the
data cannot date a change there more finely, and the interval says so.

The rule's two settings (``kappa`` and ``level``) were chosen on one block of
simulated faults and reported on another (``python -m benchmarks monitor_onset``,
``docs/monitor.md``).

References
----------
Basseville, M., Nikiforov, I. (1993). Detection of Abrupt Changes, section 2.6.
Smith, A. F. M. (1975). A Bayesian approach to inference about a change-point in
a sequence of random variables. Biometrika 62, 407-416.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusion.exceptions import FilterOptionError, MeasurementShapeError

__all__ = ["ChangeTime", "ChangeTimeRule", "ChangeTimeTracker", "change_time",
           "change_time_posterior"]


@dataclass(frozen=True)
class ChangeTimeRule:
    """Settings of the posterior change time (module docstring).

    Attributes
    ----------
    temperature : float
        ``kappa`` of eq. 1 (1: the tests' likelihood as it is).
    level : float
        Probability of the stated interval.
    max_windows : int
        Windows kept since the previous alarm (older ones are dropped: the
        change is then dated no earlier than the oldest kept).
    """

    temperature: float = 1.0
    level: float = 0.9
    max_windows: int = 400

    def __post_init__(self) -> None:
        bad = [name for name, ok in (("temperature", self.temperature > 0),
                                     ("level", 0.0 < self.level < 1.0),
                                     ("max_windows", self.max_windows >= 1)) if not ok]
        if bad:
            raise FilterOptionError(f"ChangeTimeRule out of range: {', '.join(bad)}")


@dataclass(frozen=True)
class ChangeTime:
    """A dated change.

    Attributes
    ----------
    onset_s : float
        Start of the posterior median's window [s].
    lo_s, hi_s : float
        The interval at the rule's level [s]: from the start of the ``1 - level``
        quantile's window to the end of the last window (the alarm's).
    """

    onset_s: float
    lo_s: float
    hi_s: float


def change_time_posterior(llr: np.ndarray, *, temperature: float = 1.0) -> np.ndarray:
    """Posterior probability of a change at each window (eq. 1, uniform prior), shape (m,).

    Parameters
    ----------
    llr : array_like, shape (m,)
        The test's log-likelihood-ratio increments ``l_j`` of the windows, in time
        order (0 for windows without a test) [nats].
    temperature : float
        ``kappa``.

    Raises
    ------
    MeasurementShapeError
        If ``llr`` is not a non-empty 1-d array of finite values.

    Examples
    --------
    >>> llr = np.r_[np.full(5, -1.0), np.full(5, 2.0)]     # the change at window 5
    >>> int(np.argmax(change_time_posterior(llr)))
    5
    """
    lv = np.asarray(llr, dtype=float)
    if lv.ndim != 1 or lv.size == 0 or not np.all(np.isfinite(lv)):
        raise MeasurementShapeError(f"expected a non-empty 1-d array of finite increments, got "
                                    f"shape {lv.shape}")
    log_p = float(temperature) * np.cumsum(lv[::-1])[::-1]      # kappa S_tau
    w = np.exp(log_p - log_p.max())
    return w / w.sum()


def change_time(t0_s: np.ndarray, llr: np.ndarray, *, window_s: float,
                rule: ChangeTimeRule | None = None) -> ChangeTime:
    """The posterior change time of windows starting at ``t0_s`` [s] (module docstring).

    Parameters
    ----------
    t0_s : array_like, shape (m,)
        Start of each window [s].
    llr : array_like, shape (m,)
        As for :func:`change_time_posterior` [nats].
    window_s : float
        Window length [s].
    rule : ChangeTimeRule, optional

    Examples
    --------
    >>> llr = np.r_[np.full(20, -1.0), np.full(5, 3.0)]
    >>> when = change_time(0.45 * np.arange(25), llr, window_s=0.45)
    >>> round(when.onset_s, 2), round(when.lo_s, 2), round(when.hi_s, 2)
    (9.0, 8.1, 11.25)
    """
    rule = rule or ChangeTimeRule()
    t0 = np.asarray(t0_s, dtype=float)
    p = change_time_posterior(llr, temperature=rule.temperature)
    if t0.shape != p.shape:
        raise MeasurementShapeError(f"t0_s must have shape {p.shape}, got {t0.shape}")
    cdf = np.cumsum(p)

    def at(q: float) -> int:
        return int(min(np.searchsorted(cdf, q * cdf[-1]), len(cdf) - 1))

    return ChangeTime(float(t0[at(0.5)]), float(t0[at(1.0 - rule.level)]),
                      float(t0[-1] + window_s))


class ChangeTimeTracker:
    """Per-robot window history since each robot's last alarm, for :func:`change_time`.

    Parameters
    ----------
    n_robots : int
    n_tests : int
        Log-likelihood-ratio increments kept per window (one per test).
    window_s : float
        Window length [s].
    rule : ChangeTimeRule, optional
    """

    def __init__(self, n_robots: int, n_tests: int, *, window_s: float,
                 rule: ChangeTimeRule | None = None) -> None:
        self.rule = rule or ChangeTimeRule()
        self.window_s = float(window_s)
        m = self.rule.max_windows
        self._t0 = np.zeros((int(n_robots), m))               # a ring per robot
        self._llr = np.zeros((int(n_robots), m, int(n_tests)))
        self._count = np.zeros(int(n_robots), dtype=int)

    def push(self, t0_s: float, llr: np.ndarray) -> None:
        """Record one window of every robot: its start [s] and increments ``(n_robots,
        n_tests)`` [nats] (0 for windows not tested)."""
        slot = self._count % self.rule.max_windows
        rows = np.arange(len(self._count))
        self._t0[rows, slot] = float(t0_s)
        self._llr[rows, slot] = np.asarray(llr, dtype=float)
        self._count += 1

    def estimate(self, robot: int, test: int) -> ChangeTime:
        """The change time of ``robot`` by test column ``test``, over its windows since its
        last reset (NaN without any)."""
        n, m = int(self._count[robot]), self.rule.max_windows
        if n == 0:
            return ChangeTime(math.nan, math.nan, math.nan)
        order = np.arange(n - min(n, m), n) % m
        return change_time(self._t0[robot, order], self._llr[robot, order, test],
                           window_s=self.window_s, rule=self.rule)

    def reset(self, robot: int) -> None:
        """Forget ``robot``'s windows (after its alarm)."""
        self._count[robot] = 0
