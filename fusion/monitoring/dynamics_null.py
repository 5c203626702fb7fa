"""Integrated encoder residuals over windows, and their nominal distribution (the null).

Why not one-step innovations: one period of 15 ms holds about four encoder
ticks, so a one-step residual is dominated by tick quantisation, and a PID
speed loop hides a heavier or weaker robot in steady state. The difference
shows in the *travel* over a transient. Over a window of ``H`` periods,
:class:`WindowIntegrator` compares each wheel's measured count change with the
travel the model predicts when run free from the commands, started from the
hybrid predictor's state at the window start (the model's innovations form,
``z' = (A - K C) z + (B - K D) u + K y``, Ljung 1999 section 4.3). A count
difference carries at most about one tick of quantisation whatever ``H``,
while a 3-period delay at a 0.25 m/s step is about 25 ticks.

Null model (:class:`DynamicsNull`, fitted by maximum likelihood on nominal
driving with :func:`fit_dynamics_null`, commands and counts only): the window
residual ``r`` (2,) [ticks] of (left, right) is Gaussian with mean
``Phi beta`` and covariance ``Sigma``::

    Phi   = [c(s)+, c(s)-, d(s)+, d(s)-, c(p), d(p), c(s1), d(s1), c(s2), d(s2)]   (eq. 2)
    Sigma = Sigma0 + sum_j v_j phi_j phi_j^T + w+ diag(s+ * s+) + w- diag(s- * s-)   (eq. 1)

where ``s`` is the window's lag signature (the change of predicted wheel
travel per period across the window [ticks per period of lag]: a response
late by ``theta`` periods moves ``r`` by ``-theta s``), ``p`` the predicted
travel [ticks] (a relative gain error moves ``r`` by ``g p``), ``s1, s2`` the
signatures of the previous two windows (the tail of a transient); ``c(.)``
and ``d(.)`` the common (driving) and differential (turning) parts of a wheel
vector, ``x+`` and ``x-`` a part where the speed magnitude grows
(``x p > 0``: starting, speeding up) or shrinks (slowing down, stopping);
``phi_j`` the columns of ``Phi``. ``Sigma0`` is quantisation and roughness,
the ``v_j`` terms what a linear model misses at speed changes, in turns and
after transients, and ``w+, w-`` (per wheel, ``s+ / s-`` taken wheel by
wheel) each wheel's own lag spread, which makes the two wheels of a start
from rest disagree. Speeding up and slowing down are separated because the
motors' current limit makes them differ while the model is linear.

Window statistics (:func:`window_statistics`), with ``e = r - Phi beta``:

- ``q = e^T Sigma^-1 e``, chi-square with 2 degrees of freedom under the null;
- the lag evidence ``a = -s^T Sigma^-1 e`` and information
  ``b = s^T Sigma^-1 s``: under the null ``a ~ N(0, b)``; a response late by
  ``theta`` periods gives ``a ~ N(theta b, b)``, the least-squares lag being
  ``a / b`` (Basseville & Nikiforov 1993, section 7.2.1, a change in the mean
  along a known direction).

References
----------
Ljung, L. (1999). System Identification, 2nd ed., section 4.3.
Basseville, M., Nikiforov, I. (1993). Detection of Abrupt Changes: Theory and
Application. Prentice Hall, section 7.2.1.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import minimize

from fusion.exceptions import FilterOptionError, MeasurementShapeError
from fusion.monitoring.dynamics_start import (
    StartNull,
    drive_start_anchors,
    fit_start_null,
    inverse_quadratic,
    start_evidence,
)
from lti_motion.exceptions import MissingEncoderScaleError
from lti_motion.kinematics import body_from_wheel_matrix, wheel_from_body_matrix
from lti_motion.model.motion_model import MotionModel

__all__ = [
    "DynamicsNull",
    "WindowIntegrator",
    "WindowResiduals",
    "WindowStatistics",
    "fit_dynamics_null",
    "integrated_residuals",
    "window_statistics",
]

#: Names of the columns of ``Phi`` (module docstring, eq. 2), the order of
#: :attr:`DynamicsNull.mean_coefficients` and :attr:`DynamicsNull.term_std`.
TERMS = ("drive_up", "drive_down", "turn_up", "turn_down", "gain_drive", "gain_turn",
         "tail1_drive", "tail1_turn", "tail2_drive", "tail2_turn")

#: Lag information [1/period^2] above which a window counts as informative
#: (a one-period lag moves it by at least one standard deviation).
INFORMATIVE_B = 1.0


@dataclass(frozen=True)
class WindowResiduals:
    """Integrated residuals of consecutive windows, each ``(..., n_windows, 2)`` [ticks].

    Attributes
    ----------
    residual_ticks : ndarray
        ``r``: measured minus predicted wheel travel (left, right).
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
class WindowStatistics:
    """Test statistics of windows (module docstring), each ``(..., n_windows)``.

    Attributes
    ----------
    q : ndarray
        ``e^T Sigma^-1 e`` (chi-square, 2 dof, under the null).
    lag_evidence : ndarray
        ``a = -s^T Sigma^-1 e`` [1/period].
    lag_information : ndarray
        ``b = s^T Sigma^-1 s`` [1/period^2].
    """

    q: np.ndarray
    lag_evidence: np.ndarray
    lag_information: np.ndarray


@dataclass(frozen=True)
class DynamicsNull:
    """Nominal distribution of window residuals (module docstring, eqs. 1-2).

    Attributes
    ----------
    window_periods : int
        ``H``, periods per window.
    base_cov_ticks2 : ndarray, shape (2, 2)
        ``Sigma0`` [ticks^2].
    term_std : ndarray, shape (10,)
        ``sqrt(v_j)`` of the columns :data:`TERMS` (lag terms [periods],
        gain terms [1]).
    wheel_lag_std_periods : tuple of 2 float
        ``sqrt(w+), sqrt(w-)`` [periods].
    mean_coefficients : ndarray, shape (10,)
        ``beta`` on the columns :data:`TERMS`.
    n_windows : int
        Windows it was fitted on.
    informative_fraction : float
        Share of those windows with lag information ``b`` above
        :data:`INFORMATIVE_B` (for the lag test's threshold).
    lag_information_median : float
        Median ``b`` of the informative windows [1/period^2].
    start : StartNull or None
        Nominal distribution of the start score
        (:mod:`fusion.monitoring.dynamics_start`, eq. 7); ``None``: too few starts.
    skip_windows : int
        Windows at the start of each run left out of the fit; the monitor
        leaves out as many after it starts.
    """

    window_periods: int
    base_cov_ticks2: np.ndarray
    term_std: np.ndarray
    wheel_lag_std_periods: tuple[float, float]
    mean_coefficients: np.ndarray
    n_windows: int = 0
    informative_fraction: float = 0.0
    lag_information_median: float = 0.0
    start: StartNull | None = None
    skip_windows: int = 0


class WindowIntegrator:
    """Window residuals of ``n_robots`` robots fed one period at a time (module docstring).

    Parameters
    ----------
    model : MotionModel
        Calibrated model with ``m_per_tick``.
    n_robots : int
        Robots fed together.
    window_periods : int
        ``H``.
    glitch_ticks : float
        A period whose count change is farther than this from the one-step
        prediction makes its window invalid (a spike, not dynamics); the
        predictor is fed the prediction instead.
    """

    def __init__(self, model: MotionModel, *, n_robots: int = 1, window_periods: int = 30,
                 glitch_ticks: float = 25.0) -> None:
        if model.m_per_tick is None:
            raise MissingEncoderScaleError.needed_by("the dynamics tests' integrated residuals")
        if not (window_periods >= 2 and n_robots >= 1 and glitch_ticks > 0):
            raise FilterOptionError(f"need window_periods >= 2, n_robots >= 1, glitch_ticks > 0;"
                                    f" got {window_periods}, {n_robots}, {glitch_ticks}")
        self.model = model
        self.window_periods = int(window_periods)
        self.glitch_ticks = float(glitch_ticks)
        n, nz = int(n_robots), model.n_states
        self._to_ticks = model.dt_s / model.m_per_tick * wheel_from_body_matrix(model.wheel_base_m)
        self._from_ticks = (model.m_per_tick / model.dt_s) * body_from_wheel_matrix(
            model.wheel_base_m)
        self._pa = model.A - model.K @ model.C
        self._pb = model.B - model.K @ model.D
        self._z = np.zeros((n, nz))
        self._zf = np.zeros((n, nz))
        self._acc = np.zeros((2, n, 2))          # measured, predicted travel [ticks]
        self._ok = np.ones(n, bool)
        self._h = 0
        self._y_last = np.zeros((n, 2))          # last predicted wheel travel a period [ticks]
        self._s_start = np.zeros((n, 2))

    @property
    def n_robots(self) -> int:
        """Robots fed together."""
        return self._z.shape[0]

    @property
    def at_window_start(self) -> bool:
        """Whether the next period opens a window."""
        return self._h == 0

    @property
    def period_in_window(self) -> int:
        """Position ``0 .. H-1`` of the next period in its window."""
        return self._h

    def step(self, cmd_m_s: np.ndarray, tick_deltas: np.ndarray) -> tuple | None:
        """One period of all robots, ``(n_robots, 2)`` each [m/s], [ticks].

        Returns
        -------
        tuple of (r, s, p, valid) or None
            The window's residual, signature, predicted travel (each
            ``(n_robots, 2)`` [ticks]) and validity when the period closes a
            window.
        """
        m = self.model
        u, d = cmd_m_s, tick_deltas
        if self._h == 0:
            self._zf = self._z.copy()
            self._s_start = self._y_last.copy()
        c = m.offset_speeds                      # affine offset: the linear part runs on y - c
        feedthrough = u @ m.D.T
        y_free = self._zf @ m.C.T + feedthrough + c
        y_one = self._z @ m.C.T + feedthrough + c
        p_ticks = y_free @ self._to_ticks.T
        self._y_last = p_ticks
        good = np.isfinite(d).all(axis=1)
        one_ticks = y_one @ self._to_ticks.T
        glitch = ~good | (np.abs(np.where(good[:, None], d, 0.0) - one_ticks)
                          > self.glitch_ticks).any(axis=1)
        self._ok &= ~glitch
        d_use = np.where(glitch[:, None], one_ticks, d)         # keep the predictor sane
        self._acc[0] += d_use
        self._acc[1] += p_ticks
        y_meas = d_use @ self._from_ticks.T
        self._zf = self._zf @ m.A.T + u @ m.B.T
        self._z = self._z @ self._pa.T + u @ self._pb.T + (y_meas - c) @ m.K.T
        self._h += 1
        if self._h < self.window_periods:
            return None
        out = (self._acc[0] - self._acc[1], p_ticks - self._s_start, self._acc[1].copy(),
               self._ok.copy())
        self._acc[:] = 0.0
        self._ok = np.ones_like(self._ok)
        self._h = 0
        return out


def integrated_residuals(model: MotionModel, cmd_m_s: np.ndarray, tick_deltas: np.ndarray, *,
                         window_periods: int = 30, glitch_ticks: float = 25.0
                         ) -> WindowResiduals:
    """Window residuals of whole drives (the batch form of :class:`WindowIntegrator`).

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
        See :class:`WindowIntegrator`.

    Returns
    -------
    WindowResiduals
        ``n // H`` windows.

    Raises
    ------
    MeasurementShapeError
        If commands and count changes differ in shape or are not pairs.
    """
    u = np.asarray(cmd_m_s, float)
    d = np.asarray(tick_deltas, float)
    if u.shape != d.shape or u.ndim < 2 or u.shape[-1] != 2:
        raise MeasurementShapeError(f"expected commands and tick deltas of one shape (..., n, 2),"
                                    f" got {u.shape} and {d.shape}")
    batch = u.shape[:-2]
    integ = WindowIntegrator(model, n_robots=int(np.prod(batch, dtype=int)),
                             window_periods=window_periods, glitch_ticks=glitch_ticks)
    uu = u.reshape(-1, *u.shape[-2:])
    dd = d.reshape(-1, *d.shape[-2:])
    wins = [w for w in (integ.step(uu[:, k], dd[:, k]) for k in range(u.shape[-2]))
            if w is not None]
    n_w = len(wins)
    if not wins:
        empty = np.zeros((*batch, 0, 2))
        return WindowResiduals(empty, empty, empty, np.zeros((*batch, 0), bool))
    r, s, p, ok = (np.stack([w[i] for w in wins], axis=1) for i in range(4))
    return WindowResiduals(r.reshape(*batch, n_w, 2), s.reshape(*batch, n_w, 2),
                           p.reshape(*batch, n_w, 2), ok.reshape(*batch, n_w))


def _split(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Common (driving) and differential (turning) parts of wheel vectors, ``a = c + d``."""
    mean = np.repeat(0.5 * (a[..., :1] + a[..., 1:]), 2, axis=-1)
    return mean, a - mean


def _up_down(a: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a`` where the speed magnitude grows (``a p > 0``: speeding up), and the rest."""
    up = a * p > 0.0
    return np.where(up, a, 0.0), np.where(up, 0.0, a)


def _columns(s: np.ndarray, p: np.ndarray, s_prev: np.ndarray) -> np.ndarray:
    """``Phi``, ``(..., 2, 10)`` (module docstring, eq. 2; column names :data:`TERMS`)."""
    s_c, s_d = _split(s)
    p_c, p_d = _split(p)
    s1_c, s1_d = _split(s_prev[..., 0, :])
    s2_c, s2_d = _split(s_prev[..., 1, :])
    return np.stack([*_up_down(s_c, p_c), *_up_down(s_d, p_d), p_c, p_d, s1_c, s1_d, s2_c,
                     s2_d], axis=-1)


def _covariance(base: np.ndarray, term_var: np.ndarray, wheel_var: np.ndarray, phi: np.ndarray,
                s: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``Sigma`` of each window, ``(..., 2, 2)`` (module docstring, eq. 1)."""
    cov = base + np.einsum("...ij,j,...kj->...ik", phi, term_var, phi)
    s_up, s_dn = _up_down(s, p)                       # per wheel
    diag = wheel_var[0] * s_up ** 2 + wheel_var[1] * s_dn ** 2
    return cov + diag[..., :, None] * np.eye(2)


def _error_and_cov(null: DynamicsNull, r: np.ndarray, s: np.ndarray, p: np.ndarray,
                   s_prev: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    phi = _columns(s, p, s_prev)
    cov = _covariance(null.base_cov_ticks2, np.square(null.term_std),
                      np.square(null.wheel_lag_std_periods), phi, s, p)
    return r - phi @ null.mean_coefficients, cov


def _statistics(e: np.ndarray, cov: np.ndarray, s: np.ndarray) -> WindowStatistics:
    return WindowStatistics(inverse_quadratic(cov, e, e), -inverse_quadratic(cov, s, e),
                            inverse_quadratic(cov, s, s))


def window_statistics(null: DynamicsNull, windows: WindowResiduals) -> WindowStatistics:
    """``q``, lag evidence and lag information of each window (module docstring).

    Parameters
    ----------
    null : DynamicsNull
        Nominal distribution.
    windows : WindowResiduals
        Windows of :func:`integrated_residuals`.

    Returns
    -------
    WindowStatistics
    """
    s = windows.lag_signature_ticks
    e, cov = _error_and_cov(null, windows.residual_ticks, s, windows.predicted_ticks,
                            windows.previous_signature_ticks)
    return _statistics(e, cov, s)


def fit_dynamics_null(model: MotionModel, runs: Sequence[tuple[np.ndarray, np.ndarray]], *,
                      window_periods: int = 30, skip_s: float = 3.0) -> DynamicsNull:
    """Fit :class:`DynamicsNull` by maximum likelihood on nominal drives.

    The mean by weighted least squares and the covariance parameters by
    minimising the Gaussian negative log-likelihood (Powell), alternated;
    then the start score's nominal mean and spread on the drive starts of the
    same windows (:func:`fusion.monitoring.fit_start_null`, eq. 7).

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

    Raises
    ------
    FilterOptionError
        With fewer than 100 usable windows.
    """
    parts: list[list[np.ndarray]] = [[], [], [], []]
    skip = math.ceil(skip_s / (model.dt_s * window_periods))
    kept = []
    for cmd, deltas in runs:
        w = integrated_residuals(model, cmd, deltas, window_periods=window_periods)
        ok = w.valid.copy()
        ok[..., :skip] = False
        kept.append((w, ok, drive_start_anchors(cmd, window_periods=window_periods)))
        for acc, arr in zip(parts, (w.residual_ticks, w.lag_signature_ticks, w.predicted_ticks,
                                    w.previous_signature_ticks), strict=True):
            acc.append(arr[ok])
    r, s, p, s_prev = (np.concatenate(a) for a in parts)
    if len(r) < 100:
        raise FilterOptionError(f"fit_dynamics_null needs at least 100 windows, got {len(r)}; "
                                "give it more nominal driving")
    phi = _columns(s, p, s_prev)                                    # (n, 2, 10)
    n_terms = phi.shape[-1]

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        lower = np.array([[math.exp(x[0]), 0.0], [x[1], math.exp(x[2])]])
        return lower @ lower.T, np.exp(2.0 * x[3:3 + n_terms]), np.exp(2.0 * x[3 + n_terms:])

    # Sigma's three entries are linear in the variances: their coefficients once, here, as
    # one (3 n, 10) matrix (one matrix-vector product per call, not n small ones)
    pairs = np.stack([phi[:, 0] * phi[:, 0], phi[:, 0] * phi[:, 1], phi[:, 1] * phi[:, 1]],
                     axis=1).reshape(-1, n_terms)                    # (3 n, 10)
    s_up, s_dn = (np.square(a) for a in _up_down(s, p))

    def nll(x: np.ndarray, e: np.ndarray) -> float:
        """Gaussian negative log-likelihood of the errors ``e``, up to a constant."""
        base, term_var, wheel_var = unpack(x)
        c = (pairs @ term_var).reshape(-1, 3)
        wheels = wheel_var[0] * s_up + wheel_var[1] * s_dn
        s00, s01 = base[0, 0] + c[:, 0] + wheels[:, 0], base[0, 1] + c[:, 1]
        s11 = base[1, 1] + c[:, 2] + wheels[:, 1]
        det = s00 * s11 - s01 * s01
        q = (s11 * e[:, 0] ** 2 - 2.0 * s01 * e[:, 0] * e[:, 1] + s00 * e[:, 1] ** 2) / det
        return 0.5 * float(np.sum(q + np.log(np.abs(det))))

    beta = np.linalg.lstsq(phi.reshape(-1, n_terms), r.reshape(-1), rcond=None)[0]
    x = np.concatenate([[0.0, 0.0, 0.0], np.full(n_terms + 2, math.log(0.1))])
    # log standard deviations bounded so that every Sigma stays positive definite
    bounds = [(-6.0, 3.0), (-5.0, 5.0), (-6.0, 3.0)] + [(-20.0, 3.0)] * (len(x) - 3)
    opts = {"maxiter": 30000, "xtol": 1e-4, "ftol": 1e-6}
    for _ in range(2):     # variance by maximum likelihood, then the mean by weighted LS
        x = minimize(nll, x, args=(r - phi @ beta,), method="Powell", bounds=bounds,
                     options=opts).x
        w_half = np.linalg.cholesky(np.linalg.inv(_covariance(*unpack(x), phi, s, p)))
        wt = np.swapaxes(w_half, -1, -2)
        beta = np.linalg.lstsq((wt @ phi).reshape(-1, n_terms),
                               (wt @ r[..., None]).reshape(-1), rcond=None)[0]
    x = minimize(nll, x, args=(r - phi @ beta,), method="Powell", bounds=bounds,
                 options=opts).x
    base, term_var, wheel_var = unpack(x)
    b = _statistics(r - phi @ beta, _covariance(base, term_var, wheel_var, phi, s, p),
                    s).lag_information
    informative = b > INFORMATIVE_B
    null = DynamicsNull(window_periods=int(window_periods), base_cov_ticks2=base,
                        term_std=np.sqrt(term_var),
                        wheel_lag_std_periods=(float(math.sqrt(wheel_var[0])),
                                               float(math.sqrt(wheel_var[1]))),
                        mean_coefficients=beta, n_windows=len(r),
                        informative_fraction=float(np.mean(informative)),
                        lag_information_median=float(np.median(b[informative]))
                        if informative.any() else 0.0, skip_windows=skip)
    z = [start_evidence(*_error_and_cov(null, w.residual_ticks, w.lag_signature_ticks,
                                        w.predicted_ticks, w.previous_signature_ticks),
                        w.lag_signature_ticks, ok, anchors).reshape(-1, 3)
         for w, ok, anchors in kept]
    return replace(null, start=fit_start_null(np.concatenate(z)))
