"""The start test's evidence: a drive start from rest, its lag and its two catch-up windows.

A payload (+50%, the monitor benchmark's fault) shows only where the robot starts
from rest: under the motors' current limit the heavier robot is late in the
start (about 3 standard deviations of a start window's lag evidence), then its
speed loop makes up the lost travel in the next two windows (about 2 each,
measured on the route, ``docs/monitor.md``). Stops, turns and steady driving
show no shift. The lag test of :mod:`fusion.monitoring.dynamics` reads the first
part only; this module gathers the three windows of each start into one score.

**Event.** A *drive start* is a period whose wheel commands have one sign
(``u_l u_r > 0``: driving, not turning in place) after a period with both
commands zero. Its *anchor* is the window holding it when it falls in the
window's first half, else the next window, so that the anchor holds most of
the start's transient. Windows ``j`` (the anchor), ``j + 1`` and ``j + 2``
make the event; it is dropped when one of them is invalid, when another start
anchors in ``j + 1`` or ``j + 2``, or when the anchor carries less lag
information than :data:`MIN_START_INFORMATION`.

**Evidence.** With ``v = s_j`` the anchor's lag signature and ``e``, ``Sigma``
each window's error and covariance under the null (:mod:`fusion.monitoring.dynamics_null`,
eqs. 1-2), the projections on the start's direction::

    z_0 = -v^T Sigma_j^-1 e_j / sqrt(v^T Sigma_j^-1 v)                        (eq. 5)
    z_m = +v^T Sigma_{j+m}^-1 e_{j+m} / sqrt(v^T Sigma_{j+m}^-1 v),  m = 1, 2  (eq. 6)

are each N(0, 1) if the null holds (a fixed direction's projection of
``N(0, Sigma)``, whitened); ``z_0 > 0`` is a late start (the lag evidence of
:class:`~fusion.monitoring.WindowStatistics` normalised), ``z_m > 0`` a robot
ahead of the prediction along the start's direction (catching up). The
score::

    Z = (z_0 + z_1 + z_2 - sum_m mu_m) / sigma_Z                              (eq. 7)

with ``mu_m`` and ``sigma_Z`` the mean of each ``z_m`` and the standard
deviation of their sum on nominal starts (:func:`fit_start_null`; the null's
mean misfit along the catch-up direction and the windows' correlation are
taken from the data, a Phase-I estimate). The monitor runs a CUSUM of
``mu1 Z - mu1^2 / 2`` over events, the log-likelihood ratio of a mean shift of
``mu1`` standard deviations (Basseville & Nikiforov 1993, section 2.2).

**Threshold.** The nominal ``Z`` is near N(0, 1) but its tail is heavier
(``docs/monitor.md``), so the textbook threshold alarms too
often. :func:`start_threshold_from_maxima` sets it from nominal driving
instead: the per-run maxima of the CUSUM above their ``1 - tail_fraction``
quantile ``u`` are fitted with a generalised Pareto distribution (peaks over
threshold, Pickands 1975), whose return level for an exceedance probability
``p`` per run is (Coles 2001, eq. 4.13)::

    h = u + sigma / xi ((zeta_u / p)^xi - 1)     (xi != 0; u + sigma ln(zeta_u / p) at 0)

with ``zeta_u = tail_fraction`` and ``p = F / runs_per_hour``.

References
----------
Pickands, J. (1975). Statistical inference using extreme order statistics.
Annals of Statistics 3, 119-131.
Basseville, M., Nikiforov, I. (1993). Detection of Abrupt Changes, section 2.2.
Coles, S. (2001). An Introduction to Statistical Modeling of Extreme Values.
Springer, section 4.3, eq. 4.13.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.stats import genpareto

from fusion.exceptions import FilterOptionError, MeasurementShapeError

__all__ = [
    "MIN_START_INFORMATION",
    "START_WINDOWS",
    "StartNull",
    "StartTracker",
    "drive_start_anchors",
    "fit_start_null",
    "start_cusum_maxima",
    "start_evidence",
    "start_threshold_from_maxima",
]

#: Windows of one event: the anchor and two catch-up windows.
START_WINDOWS = 3

#: Lag information ``v^T Sigma^-1 v`` [1/period^2] the anchor needs (a one-period
#: late start moves it by at least one standard deviation).
MIN_START_INFORMATION = 1.0


@dataclass(frozen=True)
class StartNull:
    """Nominal distribution of the start score (module docstring, eq. 7).

    Attributes
    ----------
    mean : tuple of 3 float
        ``mu_m``, nominal mean of ``z_0, z_1, z_2``.
    std : float
        ``sigma_Z``, nominal standard deviation of ``z_0 + z_1 + z_2``.
    n_starts : int
        Nominal starts it was estimated on.
    """

    mean: tuple[float, float, float]
    std: float
    n_starts: int

    def score(self, z: np.ndarray) -> np.ndarray:
        """``Z`` (eq. 7) of evidence ``z``, ``(..., 3)``."""
        return (np.sum(z, axis=-1) - sum(self.mean)) / self.std


def inverse_quadratic(cov: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a^T Sigma^-1 b`` for symmetric 2 x 2 ``Sigma``, batched.

    The inverse in closed form, ``[[s11, -s01], [-s01, s00]] / (s00 s11 - s01^2)``
    (a batched ``numpy.linalg.solve`` of 2 x 2 systems costs several times more).

    Parameters
    ----------
    cov : ndarray, shape (..., 2, 2)
        Symmetric positive definite ``Sigma`` [ticks^2].
    a, b : ndarray, shape (..., 2)
        Vectors [ticks].

    Returns
    -------
    ndarray, shape (...)
    """
    s00, s01, s11 = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    return (s11 * a[..., 0] * b[..., 0] - s01 * (a[..., 0] * b[..., 1] + a[..., 1] * b[..., 0])
            + s00 * a[..., 1] * b[..., 1]) / (s00 * s11 - s01 * s01)


def _projection(e: np.ndarray, cov: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``v^T Sigma^-1 e / sqrt(v^T Sigma^-1 v)`` and ``v^T Sigma^-1 v`` (eqs. 5-6), batched."""
    info = inverse_quadratic(cov, v, v)
    z = inverse_quadratic(cov, v, e) / np.sqrt(np.where(info > 0, info, 1.0))
    return z, info


def drive_start_anchors(cmd_m_s: np.ndarray, *, window_periods: int) -> np.ndarray:
    """Anchor windows of drive starts from rest (module docstring), ``(..., n // H)`` bool.

    Parameters
    ----------
    cmd_m_s : ndarray, shape (..., n, 2)
        Wheel commands of periods ``0 .. n-1`` [m/s]; the robot is at rest
        before period 0.
    window_periods : int
        ``H``.

    Examples
    --------
    >>> u = np.zeros((90, 2)); u[20:] = 0.2          # a start in the first window's 2nd half
    >>> drive_start_anchors(u, window_periods=30).tolist()
    [False, True, False]
    """
    u = np.asarray(cmd_m_s, float)
    if u.ndim < 2 or u.shape[-1] != 2:
        raise MeasurementShapeError(f"expected commands of shape (..., n, 2), got {u.shape}")
    h = int(window_periods)
    rest = np.all(u == 0.0, axis=-1)
    before = np.concatenate([np.ones_like(rest[..., :1]), rest[..., :-1]], axis=-1)
    start = before & (u[..., 0] * u[..., 1] > 0.0)
    n_w = u.shape[-2] // h
    k = np.arange(u.shape[-2])
    anchor_of = k // h + (k % h >= h // 2)                          # the anchor window
    out = np.zeros((*u.shape[:-2], n_w + 1), bool)
    idx = np.nonzero(start)
    out[(*idx[:-1], anchor_of[idx[-1]])] = True
    return out[..., :n_w]


def start_evidence(error_ticks: np.ndarray, cov_ticks2: np.ndarray, signature_ticks: np.ndarray,
                   valid: np.ndarray, anchors: np.ndarray) -> np.ndarray:
    """``z_0, z_1, z_2`` (eqs. 5-6) of every event, at its anchor window (the batch form).

    Parameters
    ----------
    error_ticks : ndarray, shape (..., n_windows, 2)
        ``e`` of each window [ticks].
    cov_ticks2 : ndarray, shape (..., n_windows, 2, 2)
        ``Sigma`` of each window [ticks^2].
    signature_ticks : ndarray, shape (..., n_windows, 2)
        ``s`` of each window [ticks per period].
    valid, anchors : ndarray of bool, shape (..., n_windows)
        Windows that may be tested; anchor windows (:func:`drive_start_anchors`).

    Returns
    -------
    ndarray, shape (..., n_windows, 3)
        The evidence of the event anchored at each window; NaN where none
        (module docstring: dropped events included).
    """
    e, cov, s = (np.asarray(a, float) for a in (error_ticks, cov_ticks2, signature_ticks))
    ok, anc = np.asarray(valid, bool), np.asarray(anchors, bool)
    n_w = s.shape[-2]
    if anc.shape != s.shape[:-1] or ok.shape != anc.shape:
        raise MeasurementShapeError(f"expected valid and anchors of shape {s.shape[:-1]}, got "
                                    f"{ok.shape} and {anc.shape}")
    event = anc & ok
    z = np.full((*s.shape[:-1], START_WINDOWS), np.nan)
    for m in range(START_WINDOWS):
        if m:
            event[..., n_w - m:] = False
            event[..., :n_w - m] &= ok[..., m:] & ~anc[..., m:]
        zm, info = _projection(e[..., m:, :], cov[..., m:, :, :], s[..., :n_w - m, :])
        z[..., :n_w - m, m] = -zm if m == 0 else zm                 # eq. 5, eq. 6
        if m == 0:
            event &= info > MIN_START_INFORMATION
    return np.where(event[..., None], z, np.nan)


def fit_start_null(z: np.ndarray, *, min_starts: int = 10) -> StartNull | None:
    """Nominal ``mu_m`` and ``sigma_Z`` (eq. 7) from evidence rows ``(n, 3)`` (NaN rows ignored).

    Returns ``None`` with fewer than ``min_starts`` events (no start test).
    """
    z = np.asarray(z, float).reshape(-1, START_WINDOWS)
    z = z[np.all(np.isfinite(z), axis=1)]
    if len(z) < max(int(min_starts), 2):
        return None
    return StartNull(tuple(float(x) for x in z.mean(axis=0)), float(np.std(z.sum(axis=1),
                                                                        ddof=1)), len(z))


def start_cusum_maxima(scores: np.ndarray, *, shift_sigma: float) -> np.ndarray:
    """Per-run maximum of the start CUSUM (``g = max(0, g + mu1 Z - mu1^2 / 2)``, no restart).

    Parameters
    ----------
    scores : ndarray, shape (n_runs, n_windows)
        ``Z`` of the events (NaN: no event), in time order.
    shift_sigma : float
        ``mu1``.
    """
    sc = np.atleast_2d(np.asarray(scores, float))
    g = np.zeros(len(sc))
    peak = np.zeros(len(sc))
    for j in range(sc.shape[1]):
        col = sc[:, j]
        g = np.where(np.isfinite(col),
                     np.maximum(0.0, g + shift_sigma * col - 0.5 * shift_sigma ** 2), g)
        peak = np.maximum(peak, g)
    return peak


def start_threshold_from_maxima(run_maxima: ArrayLike, *, runs_per_hour: float,
                                false_alarms_per_hour: float, tail_fraction: float = 0.1
                                ) -> float:
    """Threshold of the start CUSUM from nominal per-run maxima (module docstring, Coles eq. 4.13).

    Parameters
    ----------
    run_maxima : array_like, shape (n_runs,)
        Maximum of the CUSUM over each nominal run (:func:`start_cusum_maxima`).
    runs_per_hour : float
        Runs an hour of driving (the runs' count over their driving time).
    false_alarms_per_hour : float
        ``F``.
    tail_fraction : float
        ``zeta_u``: share of the maxima above the Pareto fit's ``u``.

    Returns
    -------
    float
        ``h`` exceeded by a run's maximum with probability ``F / runs_per_hour``.

    Raises
    ------
    FilterOptionError
        With fewer than 20 maxima above ``u``, or a budget that is not in the
        fitted tail (``F / runs_per_hour >= tail_fraction``).

    Examples
    --------
    >>> m = np.random.default_rng(0).exponential(1.0, 20000)      # GPD with xi = 0 above any u
    >>> h = start_threshold_from_maxima(m, runs_per_hour=60.0, false_alarms_per_hour=0.06)
    >>> abs(h - math.log(1000.0)) < 0.3                            # P(M > h) = 1e-3
    True
    """
    m = np.asarray(run_maxima, float).ravel()
    p = false_alarms_per_hour / runs_per_hour if runs_per_hour > 0 else math.inf
    if not (0 < p < tail_fraction < 1):
        raise FilterOptionError(f"need 0 < F / runs_per_hour < tail_fraction < 1, got "
                                f"{p} and {tail_fraction}")
    u = float(np.quantile(m, 1.0 - tail_fraction))
    exc = m[m > u] - u
    if exc.size < 20:
        raise FilterOptionError(f"the Pareto tail needs at least 20 maxima above u = {u:.3g}, "
                                f"got {exc.size}; give it more nominal runs")
    xi, _, sigma = genpareto.fit(exc, floc=0.0)
    ratio = tail_fraction / p
    if abs(xi) < 1e-9:
        return float(u + sigma * math.log(ratio))
    return float(u + sigma / xi * (ratio ** xi - 1.0))              # Coles 2001, eq. 4.13


class StartTracker:
    """Streaming events of ``n_robots`` robots (module docstring; :func:`start_evidence` in steps).

    Call :meth:`period` with every period's commands before the window
    integrator steps, and :meth:`window` when a window closes.
    """

    def __init__(self, n_robots: int, *, window_periods: int) -> None:
        n = int(n_robots)
        self.window_periods = int(window_periods)
        self._rest = np.ones(n, bool)            # the previous period was at rest
        self._anchor = np.zeros((2, n), bool)    # a start anchors in this window, the next
        self._m = np.full(n, -1)                 # next window of the event in progress
        self._v = np.zeros((n, 2))
        self._z = np.zeros((n, START_WINDOWS))

    def period(self, cmd_m_s: np.ndarray, position: int) -> None:
        """Commands ``(n_robots, 2)`` [m/s] of the period at ``position`` in its window."""
        u = np.asarray(cmd_m_s, float)
        start = self._rest & (u[:, 0] * u[:, 1] > 0.0)
        self._anchor[int(position >= self.window_periods // 2)] |= start
        self._rest = np.all(u == 0.0, axis=1)

    def window(self, error_ticks: np.ndarray, cov_ticks2: np.ndarray,
               signature_ticks: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Close a window; returns ``(n_robots, 3)`` evidence of events completed (NaN: none)."""
        anchor = self._anchor[0].copy()
        self._anchor = np.stack([self._anchor[1], np.zeros_like(anchor)])
        busy = (self._m > 0) & ~anchor               # a new anchor drops the event in progress
        z, _ = _projection(error_ticks, cov_ticks2, self._v)
        keep = busy & valid
        self._z[keep, self._m[keep]] = z[keep]                       # eq. 6
        self._m = np.where(keep, self._m + 1, -1)
        z0, info = _projection(error_ticks, cov_ticks2, signature_ticks)
        new = anchor & valid & (info > MIN_START_INFORMATION)
        self._v[new] = signature_ticks[new]
        self._z[new, 0] = -z0[new]                                   # eq. 5
        self._m[new] = 1
        done = self._m == START_WINDOWS
        out = np.where(done[:, None], self._z, np.nan)
        self._m[done] = -1
        return out
