"""Dynamics-change test on integrated encoder residuals: free-run travel over a window.

Why not one-step innovations: one period of 15 ms holds about four encoder
ticks, so a one-step residual is dominated by tick quantisation, and a PID
speed loop hides a heavier or weaker robot in steady state. The difference
shows in the *travel* over a transient. Over a window of ``H`` periods this
module compares each wheel's measured count change with the travel the model
predicts when run free from the commands, started from the hybrid
predictor's state at the window start (the model's innovations form,
``z' = (A - K C) z + (B - K D) u + K y``, Ljung 1999 section 4.3). A count
difference carries at most about one tick of quantisation whatever ``H``,
while a 3-period delay at a 0.25 m/s step is about 25 ticks.

Null model (:class:`DynamicsNull`, fitted by maximum likelihood on nominal
driving with :func:`fit_dynamics_null`, commands and counts only): the window
residual ``r`` (2,) [ticks] of (left, right) is Gaussian with mean
``Phi beta`` (eq. 2: ``Phi`` holds, as wheel vectors, the accelerating,
decelerating and turning parts of ``s``, the driving and turning parts of
``p``, and of the two previous windows' signatures) and covariance (eq. 1,
each term split into its driving and turning parts)::

    Sigma = Sigma0 + sigma_lag^2 s s^T + sigma_gain^2 p p^T + sigma_tail^2 s_prev s_prev^T

where ``s`` is the window's lag signature (the change of predicted wheel
travel per period across the window [ticks per period of lag]: a response
late by ``theta`` periods moves ``r`` by ``-theta s``), ``p`` the predicted
travel [ticks] (a relative gain error moves ``r`` by ``g p``) and ``s_prev``
the previous window's signature (the tail of a transient). ``Sigma0`` is
quantisation and roughness; the other terms are what a linear model misses
at speed changes, in turns and after transients.

Test: the window statistic ``q = e^T Sigma^-1 e`` (``e`` the residual minus
its mean) is chi-square with 2 degrees of freedom under the null; a change of
dynamics inflates it. A CUSUM (Page 1954) on the log-likelihood ratio of a
covariance ``lambda^2 Sigma`` against ``Sigma`` (Basseville & Nikiforov 1993,
section 2.2, eq. 2.2.4 with a scalar covariance change)::

    llr = 0.5 (1 - 1 / lambda^2) min(q, q_clip) - ln(lambda^2)     (2 channels)
    g = max(0, g + llr);  alarm when g > h

``q`` is clipped (Huber) so one window cannot raise an alarm alone. Threshold
from the false-alarm budget: for a CUSUM of log-likelihood ratios the
in-control average run length is at least ``exp(h)`` samples (Lorden 1971,
theorem 2; Basseville & Nikiforov 1993, eq. 5.2.29), so with ``N_w`` windows
an hour and a budget of ``F`` false alarms an hour, ``h = ln(N_w / F)``:
``H = 30`` periods of 15 ms (8,000 windows an hour), ``F = 0.05``: ``h = 12.0``.
The default ``F`` is 20 times below the issue's 1 an hour because the nominal
``q`` is heavier-tailed than chi-square and its outliers come in short runs;
measured: 0.65 false alarms an hour over 10.8 h of nominal route driving
(``benchmarks/bench_monitor.py``, ``docs/monitor.md``).

References
----------
Page, E. S. (1954). Continuous inspection schemes. Biometrika 41, 100-115.
Lorden, G. (1971). Procedures for reacting to a change in distribution.
Annals of Mathematical Statistics 42, 1897-1908, theorem 2.
Basseville, M., Nikiforov, I. (1993). Detection of Abrupt Changes, sections
2.2 and 5.2.
Ljung, L. (1999). System Identification, 2nd ed., section 4.3.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from fusion.exceptions import FilterOptionError, MeasurementShapeError
from lti_motion.model import MotionModel

__all__ = [
    "DynamicsMonitor",
    "DynamicsNull",
    "WindowResiduals",
    "cusum_llr_threshold",
    "fit_dynamics_null",
    "integrated_residuals",
    "window_statistic",
]


@dataclass(frozen=True)
class WindowResiduals:
    """Integrated residuals of consecutive windows, each ``(..., n_windows, 2)`` [ticks].

    Attributes
    ----------
    residual_ticks : ndarray
        Measured minus predicted wheel travel (left, right).
    lag_signature_ticks : ndarray
        ``s``: change of the predicted wheel travel per period across the window.
    predicted_ticks : ndarray
        ``p``: predicted wheel travel.
    valid : ndarray of bool, shape (..., n_windows)
        Windows without missing or glitched periods.
    """

    residual_ticks: np.ndarray
    lag_signature_ticks: np.ndarray
    predicted_ticks: np.ndarray
    valid: np.ndarray

    @property
    def previous_signature_ticks(self) -> np.ndarray:
        """``s`` of the two windows before, ``(..., n_windows, 2, 2)`` (zeros before the first)."""
        s = self.lag_signature_ticks
        out = np.zeros((*s.shape[:-1], 2, 2))
        out[..., 1:, 0, :] = s[..., :-1, :]
        out[..., 2:, 1, :] = s[..., :-2, :]
        return out


@dataclass(frozen=True)
class DynamicsNull:
    """Nominal distribution of window residuals (module docstring, eq. 1).

    Attributes
    ----------
    window_periods : int
        ``H``, periods per window.
    lag_bias_periods : float
        Unused (0): the mean is ``mean_coefficients`` (kept for the record format).
    base_cov_ticks2 : ndarray, shape (2, 2)
        ``Sigma0`` [ticks^2].
    lag_std_periods, gain_std, tail_std_periods : tuple of 2 float
        ``sigma_lag`` (driving, turning) [periods], ``sigma_gain`` (driving,
        turning) [1], ``sigma_tail`` (one and two windows back) [periods].
    mean_coefficients : ndarray, shape (7,)
        Coefficients of the nominal mean residual on the regressors of eq. 2.
    n_windows : int
        Windows it was fitted on.
    """

    window_periods: int
    lag_bias_periods: float
    base_cov_ticks2: np.ndarray
    lag_std_periods: tuple[float, float]
    gain_std: tuple[float, float]
    tail_std_periods: tuple[float, float]
    mean_coefficients: np.ndarray
    n_windows: int = 0


def _wheel_matrix(wheel_base_m: float) -> np.ndarray:
    # wheel speeds (left, right) from body speeds (v, w): v -/+ w b / 2
    return np.array([[1.0, -0.5 * wheel_base_m], [1.0, 0.5 * wheel_base_m]])


def integrated_residuals(model: MotionModel, cmd_m_s: np.ndarray, tick_deltas: np.ndarray, *,
                         window_periods: int = 30, glitch_ticks: float = 25.0
                         ) -> WindowResiduals:
    """Window residuals of whole drives (the batch form of :class:`DynamicsMonitor`).

    Parameters
    ----------
    model : MotionModel
        Calibrated model with ``m_per_tick``.
    cmd_m_s : ndarray, shape (..., n, 2)
        Wheel commands of periods ``0 .. n-1`` [m/s].
    tick_deltas : ndarray, shape (..., n, 2)
        Count change of each period (unwrapped) [ticks]; NaN: missing.
    window_periods : int
        ``H``.
    glitch_ticks : float
        A period whose count change is farther than this from the one-step
        prediction makes its window invalid (a spike, not dynamics).

    Returns
    -------
    WindowResiduals
        ``n // H`` windows.
    """
    u = np.asarray(cmd_m_s, float)
    d = np.asarray(tick_deltas, float)
    if u.shape != d.shape or u.shape[-1] != 2:
        raise MeasurementShapeError(f"expected commands and tick deltas of one shape (..., n, 2),"
                                    f" got {u.shape} and {d.shape}")
    batch = u.shape[:-2]
    mon = DynamicsMonitor(model, None, n_robots=int(np.prod(batch, dtype=int)),
                          window_periods=window_periods, glitch_ticks=glitch_ticks)
    uu = u.reshape(-1, *u.shape[-2:])
    dd = d.reshape(-1, *d.shape[-2:])
    out = [mon._step(uu[:, k], dd[:, k]) for k in range(u.shape[-2])]
    wins = [w for w in out if w is not None]
    if not wins:
        empty = np.zeros((*batch, 0, 2))
        return WindowResiduals(empty, empty, empty, np.zeros((*batch, 0), bool))
    r, s, p, ok = (np.stack([w[i] for w in wins], axis=1) for i in range(4))
    n_w = len(wins)
    return WindowResiduals(r.reshape(*batch, n_w, 2), s.reshape(*batch, n_w, 2),
                           p.reshape(*batch, n_w, 2), ok.reshape(*batch, n_w))


def _outer(a: np.ndarray) -> np.ndarray:
    return a[..., :, None] * a[..., None, :]


def _split(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Common (driving) and differential (turning) parts of wheel vectors, ``a = c + d``."""
    mean = 0.5 * (a[..., :1] + a[..., 1:])
    return np.concatenate([mean, mean], axis=-1), a - np.concatenate([mean, mean], axis=-1)


def _features(s: np.ndarray, p: np.ndarray, s_prev: np.ndarray) -> np.ndarray:
    """Regressors of the nominal mean residual, ``(..., 2, 7)`` (module docstring, eq. 2)."""
    s_c, s_d = _split(s)
    p_c, p_d = _split(p)
    sp_c, sp_d = _split(s_prev[..., 0, :])
    sq_c, sq_d = _split(s_prev[..., 1, :])
    return np.stack([np.maximum(s_c, 0.0), np.minimum(s_c, 0.0), s_d, p_c, p_d, sp_c, sp_d,
                     sq_c, sq_d], axis=-1)


def _window_cov(params: tuple, s: np.ndarray, p: np.ndarray, s_prev: np.ndarray) -> np.ndarray:
    _, base, lag2, gain2, tail2 = params
    s_c, s_d = _split(s)
    p_c, p_d = _split(p)
    # eq. 1, each term split into its driving and turning parts
    return (base + lag2[0] * _outer(s_c) + lag2[1] * _outer(s_d) + gain2[0] * _outer(p_c)
            + gain2[1] * _outer(p_d) + tail2[0] * _outer(s_prev[..., 0, :])
            + tail2[1] * _outer(s_prev[..., 1, :]))


def _params(null: DynamicsNull) -> tuple:
    return (null.lag_bias_periods, null.base_cov_ticks2, np.square(null.lag_std_periods),
            np.square(null.gain_std), np.square(null.tail_std_periods))


def window_statistic(null: DynamicsNull, residual_ticks: np.ndarray,
                     lag_signature_ticks: np.ndarray, predicted_ticks: np.ndarray,
                     previous_signature_ticks: np.ndarray) -> np.ndarray:
    """``q = e^T Sigma^-1 e`` of each window (chi-square, 2 dof, under the null), ``(...)``."""
    params = _params(null)
    e = residual_ticks - _features(lag_signature_ticks, predicted_ticks,
                                   previous_signature_ticks) @ null.mean_coefficients
    cov = _window_cov(params, lag_signature_ticks, predicted_ticks, previous_signature_ticks)
    return np.einsum("...i,...i->...", e, np.linalg.solve(cov, e[..., None])[..., 0])


def fit_dynamics_null(model: MotionModel, runs: Sequence[tuple[np.ndarray, np.ndarray]], *,
                      window_periods: int = 30, skip_s: float = 3.0) -> DynamicsNull:
    """Fit :class:`DynamicsNull` by maximum likelihood on nominal drives.

    Parameters
    ----------
    model : MotionModel
        The model the monitor will use.
    runs : sequence of (cmd_m_s, tick_deltas)
        Nominal driving, each ``(n, 2)`` or a batch ``(N, n, 2)``: commands and
        encoder count changes only (what a robot reports).
    window_periods : int
        ``H``.
    skip_s : float
        Start of each run left out (the state of the predictor settles) [s].

    Returns
    -------
    DynamicsNull
    """
    rs, ss, ps, sps = [], [], [], []
    skip = math.ceil(skip_s / (model.dt_s * window_periods))
    for cmd, deltas in runs:
        w = integrated_residuals(model, cmd, deltas, window_periods=window_periods)
        ok = w.valid.copy()
        ok[..., :skip] = False
        for arr, acc in ((w.residual_ticks, rs), (w.lag_signature_ticks, ss),
                         (w.predicted_ticks, ps), (w.previous_signature_ticks, sps)):
            acc.append(arr[ok])
    r, s, p, sp = (np.concatenate(a) for a in (rs, ss, ps, sps))
    if len(r) < 50:
        raise FilterOptionError(f"fit_dynamics_null needs at least 50 windows, got {len(r)}; "
                                "give it more nominal driving")

    def unpack(x: np.ndarray) -> tuple:
        lower = np.array([[math.exp(x[1]), 0.0], [x[2], math.exp(x[3])]])
        return (x[0], lower @ lower.T, np.exp(2 * x[4:6]), np.exp(2 * x[6:8]),
                np.exp(2 * x[8:10]))

    phi = _features(s, p, sp)                                # (n, 2, 7)
    beta = np.linalg.lstsq(phi.reshape(-1, phi.shape[-1]), r.reshape(-1), rcond=None)[0]

    def nll(x: np.ndarray) -> float:
        params = unpack(x)
        e = r - phi @ beta
        cov = _window_cov(params, s, p, sp)
        q = np.einsum("ni,ni->n", e, np.linalg.solve(cov, e[..., None])[..., 0])
        return 0.5 * float(np.sum(q + np.linalg.slogdet(cov)[1]))

    x = np.array([0.0, 0.0, 0.0, 0.0, math.log(0.5), math.log(0.5), math.log(0.01),
                  math.log(0.01), math.log(0.3), math.log(0.1)])
    for _ in range(2):     # variance by maximum likelihood, then the mean by weighted LS
        x = minimize(nll, x, method="Powell", options={"maxiter": 20000, "xtol": 1e-4,
                                                       "ftol": 1e-6}).x
        w_half = np.linalg.cholesky(np.linalg.inv(_window_cov(unpack(x), s, p, sp)))
        wt = np.swapaxes(w_half, -1, -2)
        beta = np.linalg.lstsq((wt @ phi).reshape(-1, phi.shape[-1]),
                               (wt @ r[..., None]).reshape(-1), rcond=None)[0]
    x = minimize(nll, x, method="Powell", options={"maxiter": 20000, "xtol": 1e-4,
                                                   "ftol": 1e-6}).x
    lag, base, lag2, gain2, tail2 = unpack(x)
    return DynamicsNull(window_periods=int(window_periods), lag_bias_periods=float(lag),
                        base_cov_ticks2=base, lag_std_periods=tuple(np.sqrt(lag2).tolist()),
                        gain_std=tuple(np.sqrt(gain2).tolist()),
                        tail_std_periods=tuple(np.sqrt(tail2).tolist()), mean_coefficients=beta,
                        n_windows=len(r))


def cusum_llr_threshold(windows_per_hour: float, false_alarms_per_hour: float) -> float:
    """``h = ln(N_w / F)``: Lorden's bound ``ARL0 >= exp(h)`` meets ``F`` alarms an hour.

    Examples
    --------
    >>> round(cusum_llr_threshold(3600 / (30 * 0.015), 0.05), 2)
    11.98
    """
    return math.log(windows_per_hour / false_alarms_per_hour)


class DynamicsMonitor:
    """Streaming dynamics-change test for ``n_robots`` robots in lock step (module docstring).

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
    false_alarms_per_hour : float
        Budget of this test, per robot.
    variance_ratio : float
        ``lambda^2``, the covariance inflation the CUSUM is tuned to.
    clip : float
        ``q_clip``.
    glitch_ticks : float
        See :func:`integrated_residuals`.

    Attributes
    ----------
    threshold : float
        ``h``.
    statistic : ndarray, shape (n_robots,)
        Current CUSUM values ``g``.
    """

    def __init__(self, model: MotionModel, null: DynamicsNull | None, *, n_robots: int = 1,
                 window_periods: int = 30, false_alarms_per_hour: float = 0.05,
                 variance_ratio: float = 4.0, clip: float = 16.0,
                 glitch_ticks: float = 25.0) -> None:
        if model.m_per_tick is None:
            raise FilterOptionError("DynamicsMonitor needs a model with m_per_tick")
        if not (variance_ratio > 1 and clip > 0 and false_alarms_per_hour > 0 and n_robots >= 1):
            raise FilterOptionError(
                f"need variance_ratio > 1, clip > 0, false_alarms_per_hour > 0, n_robots >= 1; "
                f"got {variance_ratio}, {clip}, {false_alarms_per_hour}, {n_robots}")
        self.model, self.null = model, null
        self.window_periods = null.window_periods if null is not None else int(window_periods)
        self.variance_ratio, self.clip = float(variance_ratio), float(clip)
        self.glitch_ticks = float(glitch_ticks)
        windows_per_hour = 3600.0 / (model.dt_s * self.window_periods)
        self.threshold = cusum_llr_threshold(windows_per_hour, false_alarms_per_hour)
        n, nz = int(n_robots), model.n_states
        self._to_ticks = model.dt_s / model.m_per_tick * _wheel_matrix(model.wheel_base_m)
        # (v, w) from wheel ticks: mean over 2, difference over the wheel base
        self._from_ticks = (model.m_per_tick / model.dt_s) * np.array(
            [[0.5, 0.5], [-1.0 / model.wheel_base_m, 1.0 / model.wheel_base_m]])
        self._pa = model.A - model.K @ model.C
        self._pb = model.B - model.K @ model.D
        self._z = np.zeros((n, nz))
        self._zf = np.zeros((n, nz))
        self._acc = np.zeros((3, n, 2))          # measured, predicted [ticks], first prediction
        self._ok = np.ones(n, bool)
        self._h = 0
        self._y_last = np.zeros((n, 2))          # last predicted wheel travel a period [ticks]
        self._s_prev = np.zeros((n, 2, 2))
        self.statistic = np.zeros(n)
        self._left = np.zeros(n)                  # window start at which g last left zero
        self._t0 = 0.0
        self.last_q = np.full(n, math.nan)

    def _step(self, u: np.ndarray, d: np.ndarray) -> tuple | None:
        """One period for all robots; the window's (r, s, p, valid) when one closes."""
        m = self.model
        if self._h == 0:
            self._zf = self._z.copy()
        y_free = self._zf @ m.C.T + u @ m.D.T
        y_one = self._z @ m.C.T + u @ m.D.T
        p_ticks = y_free @ self._to_ticks.T
        if self._h == 0:
            self._acc[2] = self._y_last
        good = np.all(np.isfinite(d), axis=1)
        one_ticks = y_one @ self._to_ticks.T
        glitch = ~good | np.any(np.abs(np.where(good[:, None], d, 0.0) - one_ticks)
                                > self.glitch_ticks, axis=1)
        self._ok &= ~glitch
        d_use = np.where(glitch[:, None], one_ticks, d)         # keep the predictor sane
        self._acc[0] += d_use
        self._acc[1] += p_ticks
        y_meas = d_use @ self._from_ticks.T
        self._zf = self._zf @ m.A.T + u @ m.B.T
        self._z = self._z @ self._pa.T + u @ self._pb.T + y_meas @ m.K.T
        self._h += 1
        if self._h < self.window_periods:
            return None
        r = self._acc[0] - self._acc[1]
        s = p_ticks - self._acc[2]        # predicted travel per period, end minus before
        self._y_last = p_ticks
        out = (r, s, self._acc[1].copy(), self._ok.copy())
        self._acc[:2] = 0.0
        self._ok = np.ones_like(self._ok)
        self._h = 0
        return out

    def update(self, t_s: float, cmd_m_s: np.ndarray, tick_deltas: np.ndarray
               ) -> list[tuple[int, float, float, float]]:
        """Feed one period of every robot; returns alarms as ``(robot, g, h, onset_s)``.

        Parameters
        ----------
        t_s : float
            Time of the frame closing the period [s].
        cmd_m_s : ndarray, shape (n_robots, 2) or (2,)
            Commands in effect over the period [m/s].
        tick_deltas : ndarray, same shape
            Count changes over the period [ticks]; NaN: missing.
        """
        n = self._z.shape[0]
        u = np.asarray(cmd_m_s, float).reshape(n, 2)
        d = np.asarray(tick_deltas, float).reshape(n, 2)
        if self._h == 0:
            self._t0 = float(t_s) - self.model.dt_s
        win = self._step(u, d)
        if win is None or self.null is None:
            return []
        r, s, p, ok = win
        q = window_statistic(self.null, r, s, p, self._s_prev)
        self._s_prev = np.stack([s, self._s_prev[:, 0]], axis=1)
        self.last_q = np.where(ok, q, math.nan)
        lam2 = self.variance_ratio
        llr = 0.5 * (1.0 - 1.0 / lam2) * np.minimum(q, self.clip) - math.log(lam2)
        llr = np.where(ok, llr, 0.0)
        g_new = np.maximum(0.0, self.statistic + llr)      # Page 1954
        self._left = np.where((self.statistic == 0) & (g_new > 0), self._t0, self._left)
        self.statistic = g_new
        alarms = []
        for i in np.flatnonzero(g_new > self.threshold):
            alarms.append((int(i), float(g_new[i]), self.threshold, float(self._left[i])))
            self.statistic[i] = 0.0
        return alarms

    def reset(self, robots: Sequence[int] | None = None) -> None:
        """Restart the CUSUM of ``robots`` (all by default)."""
        idx = slice(None) if robots is None else np.asarray(robots, int)
        self.statistic[idx] = 0.0
