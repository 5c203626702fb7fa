"""Speed-error covariance conditioned on the model's transients, measured on data.

The long-run covariance ``Phi`` of :func:`fusion.graph.speed_covariance_from_data`
is one matrix for all driving: an average. The errors of a linear motion model are not
homoscedastic. After a large command step the real wheels are held back by the motors'
current limit and the floor's traction (``docs/calibration.md``), and the model, whose
response does not depend on the step size, runs ahead of them. At a sharp turn one wheel
reverses and the integrated yaw error of a 0.5 s interval is several times its average.
An average ``Phi`` then makes the intervals at sharp turns over-confident and the straight
ones over-cautious (``docs/factor_graph.md`` has the measurements).

This module conditions ``Phi`` on a transient indicator that the model computes from the
commands alone: the mean squared **wheel tracking error** of the predicted speeds,

.. math::

    d_k = \\lVert u_k - M \\hat y_k \\rVert_2, \\qquad
    f_k = \\frac{1}{W} \\sum_{j=k-W+1}^{k} d_j^2 \\quad [\\mathrm{m^2/s^2}],

with ``u`` the wheel commands, ``y_hat = (v, w)`` the model's predicted body speeds,
``M`` the body-to-wheel map of the differential drive (``v -+ w b / 2``, the inverse of
``v = (L + R) / 2``, ``w = (R - L) / b`` in
:func:`lti_motion.recordings.body_speeds_from_ticks`) and ``W`` samples of
``window_s``. ``d`` is large while the model's wheels are still catching up with a command
step; the window covers the slower real transient. The per-sample long-run covariance of
the model's speed errors against the encoders is

.. math::

    \\Phi(f_k) = \\Phi_0 + f_k \\Phi_1, \\qquad \\Phi_0 \\succ 0, \\ \\Phi_1 \\succeq 0,

fitted by least squares of the per-sample Newey-West terms ``h_k``
(:func:`fusion.graph.long_run_contributions`, whose mean is the unconditional
estimate) on ``(1, f_k)``: a variance function estimated by regressing second moments on
a covariate (Carroll & Ruppert 1988, ch. 3), with Newey-West second moments. Least
squares with an intercept passes through the means, so averaged over the data it was
fitted on ``Phi(f)`` equals the unconditional ``Phi``; the fit only moves variance from
the steady samples to the transient ones.

The encoders cannot see the ground, so the calibration logs hold no trace of wheel slip.
:meth:`TransientSpeedCovariance.per_sample` adds it from a prior, the EKF's state-dependent
:class:`~fusion.ekf.functions.SlipNoise` (:func:`fusion.graph.slip_covariance`), as
``mode="filtered"`` does; the white pose noise of
:func:`~fusion.graph.preintegrate` then only needs to keep the sideways direction
positive definite (:data:`~fusion.graph.FILTERED_SLIP_DENSITY`).

References
----------
W. K. Newey, K. D. West, "A simple, positive semi-definite, heteroskedasticity and
autocorrelation consistent covariance matrix", Econometrica 55(3), 1987, pp. 703-708, eq. 2.
R. J. Carroll, D. Ruppert, *Transformation and Weighting in Regression*, Chapman and Hall,
1988, ch. 3 (estimation of variance functions).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion.exceptions import MeasurementShapeError, NonFiniteInputError
from fusion.graph.speed_noise import (
    DEFAULT_BANDWIDTH_S,
    ErrorMode,
    Runs,
    long_run_contributions,
    model_speed_errors,
    slip_covariance,
)
from fusion.noise import SlipNoise
from lti_motion.model.motion_model import MotionModel

__all__ = [
    "DEFAULT_SLIP",
    "DEFAULT_WINDOW_S",
    "TransientSpeedCovariance",
    "mean_squared_tracking_error",
    "transient_speed_covariance_from_data",
]

#: Default averaging window of the squared tracking error [s]: on the simulator's calibration
#: logs the fit explains the yaw-rate terms best at 0.15 s (0.075-0.5 s tried;
#: docs/factor_graph.md).
DEFAULT_WINDOW_S = 0.15
#: Default ground slip added per sample: the EKF's (frozen, shared safely).
DEFAULT_SLIP = SlipNoise()


def _window_samples(window_s: float, dt_s: float) -> int:
    if not (np.isfinite(window_s) and window_s > 0):
        raise ValueError(f"window_s must be positive and finite, got {window_s}")
    return max(1, round(window_s / dt_s))


def mean_squared_tracking_error(cmd_m_s: np.ndarray, speeds: np.ndarray, *, wheel_base_m: float,
                                window: int) -> np.ndarray:
    """Causal moving mean of the squared distance of predicted wheel speeds from commands.

    Parameters
    ----------
    cmd_m_s : array_like, shape (n, 2)
        Wheel commands ``(L, R)`` [m/s].
    speeds : array_like, shape (n, 2)
        The model's predicted body speeds ``(v [m/s], w [rad/s])`` for the same samples.
    wheel_base_m : float
        Distance between the wheels [m].
    window : int
        Samples averaged, ``W >= 1`` (fewer at the start of the run).

    Returns
    -------
    ndarray, shape (n,)
        ``f_k`` [m^2/s^2] (module notes): zero when the predicted wheels hold the commands.

    Raises
    ------
    MeasurementShapeError, NonFiniteInputError, ValueError
        Mismatched shapes, NaN or infinity, a non-positive window or wheel base.

    Examples
    --------
    A step of 0.3 m/s on the left wheel that the prediction has not followed yet:

    >>> u = np.array([[0.0, 0.0], [0.3, 0.0], [0.3, 0.0]])
    >>> e2 = mean_squared_tracking_error(u, np.zeros((3, 2)), wheel_base_m=0.235, window=2)
    >>> (e2.round(3) + 0.0).tolist()
    [0.0, 0.045, 0.09]
    """
    cmd_m_s = np.asarray(cmd_m_s, dtype=float)
    sp = np.asarray(speeds, dtype=float)
    if cmd_m_s.ndim != 2 or cmd_m_s.shape[1] != 2 or sp.shape != cmd_m_s.shape:
        raise MeasurementShapeError(f"expected u and speeds of the same shape (n, 2), got "
                                    f"{cmd_m_s.shape} and {sp.shape}")
    if not (np.all(np.isfinite(cmd_m_s)) and np.all(np.isfinite(sp))):
        raise NonFiniteInputError("u or speeds hold NaN or infinite values")
    if not (np.isfinite(wheel_base_m) and wheel_base_m > 0) or int(window) < 1:
        raise ValueError(f"need a positive wheel base and window, got {wheel_base_m} and {window}")
    half = 0.5 * wheel_base_m * sp[:, 1]                       # wheels: v -+ w b / 2
    d2 = (cmd_m_s[:, 0] - (sp[:, 0] - half)) ** 2 + (cmd_m_s[:, 1] - (sp[:, 0] + half)) ** 2
    c = np.concatenate([[0.0], np.cumsum(d2)])
    k = np.arange(1, len(d2) + 1)
    lo = np.maximum(k - int(window), 0)
    return (c[k] - c[lo]) / np.minimum(k, int(window))


@dataclass(frozen=True)
class TransientSpeedCovariance:
    """Per-sample speed covariance: ``Phi(f) = base + f per_squared_tracking`` plus slip.

    Attributes
    ----------
    base : ndarray, shape (2, 2)
        ``Phi_0`` [(m/s)^2, (rad/s)^2]: the long-run covariance of the model's speed
        errors against the encoders when its wheels hold the commands; positive definite.
    per_squared_tracking : ndarray, shape (2, 2)
        ``Phi_1`` [(m/s)^2, (rad/s)^2 per (m/s)^2]: added per unit of the mean
        squared tracking error ``f``; positive semi-definite.
    window_s : float
        Averaging window of ``f`` [s].
    mean_squared_tracking_m2_s2 : float
        Mean ``f`` on the data it was fitted on: :attr:`mean` is then the
        unconditional long-run covariance of that data.
    slip : SlipNoise or None
        Ground-versus-encoder speed noise added per sample
        (:func:`fusion.graph.slip_covariance`; default the EKF's
        :class:`~fusion.ekf.functions.SlipNoise`); ``None`` adds none.

    Raises
    ------
    MeasurementShapeError, NonFiniteInputError, ValueError
        Wrong shapes, NaN, ``base`` not positive definite or
        ``per_squared_tracking`` not positive semi-definite, a non-positive window.

    Examples
    --------
    >>> cov = TransientSpeedCovariance(base=np.diag([1e-4, 4e-3]),
    ...                                per_squared_tracking=np.diag([0.1, 5.0]), slip=None)
    >>> u, speeds = np.array([[0.2, 0.2], [0.0, 0.4]]), np.array([[0.2, 0.0], [0.2, 0.0]])
    >>> cov.per_sample(u, speeds, wheel_base_m=0.235, dt_s=0.015)[:, 1, 1].round(4).tolist()
    [0.004, 0.204]
    """

    base: np.ndarray
    per_squared_tracking: np.ndarray
    window_s: float = DEFAULT_WINDOW_S
    mean_squared_tracking_m2_s2: float = 0.0
    slip: SlipNoise | None = DEFAULT_SLIP

    def __post_init__(self) -> None:
        for name in ("base", "per_squared_tracking"):
            arr = np.array(getattr(self, name), dtype=float)
            if arr.shape != (2, 2):
                raise MeasurementShapeError(f"{name} must have shape (2, 2), got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise NonFiniteInputError(f"{name} holds NaN or infinite values")
            arr = 0.5 * (arr + arr.T)
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        if np.linalg.eigvalsh(self.base).min() <= 0:
            raise ValueError(f"base must be positive definite, got {self.base.tolist()}")
        if np.linalg.eigvalsh(self.per_squared_tracking).min() < -1e-12 * np.abs(
                self.per_squared_tracking).max():
            raise ValueError(f"per_squared_tracking must be positive semi-definite, got "
                             f"{self.per_squared_tracking.tolist()}")
        _window_samples(float(self.window_s), 1.0)
        object.__setattr__(self, "window_s", float(self.window_s))
        mean_f = float(self.mean_squared_tracking_m2_s2)
        if not (np.isfinite(mean_f) and mean_f >= 0):
            raise ValueError(f"mean_squared_tracking_m2_s2 must be >= 0, got {mean_f}")
        object.__setattr__(self, "mean_squared_tracking_m2_s2", mean_f)

    @property
    def mean(self) -> np.ndarray:
        """``Phi`` at the mean ``f`` of the fitting data (no slip), shape (2, 2)."""
        return self.base + self.mean_squared_tracking_m2_s2 * self.per_squared_tracking

    def per_sample(self, cmd_m_s: np.ndarray, speeds: np.ndarray, *, wheel_base_m: float,
                   dt_s: float) -> np.ndarray:
        """``Phi(f_k)`` plus the slip covariance for each sample, shape (n, 2, 2).

        Parameters
        ----------
        cmd_m_s : array_like, shape (n, 2)
            Wheel commands [m/s].
        speeds : array_like, shape (n, 2)
            The model's predicted body speeds for them (as in the fit: free run
            or one step ahead) [m/s, rad/s].
        wheel_base_m : float
            Wheel base [m].
        dt_s : float
            Sample period [s] (sets the window in samples).
        """
        f = mean_squared_tracking_error(cmd_m_s, speeds, wheel_base_m=wheel_base_m,
                                        window=_window_samples(self.window_s, dt_s))
        out = self.base + f[:, None, None] * self.per_squared_tracking
        if self.slip is not None:
            out = out + slip_covariance(speeds, slip=self.slip)
        return out


def _psd_part(m: np.ndarray) -> np.ndarray:
    """Nearest positive semi-definite matrix in the Frobenius norm (Higham 1988)."""
    w, v = np.linalg.eigh(0.5 * (m + m.T))
    return (v * np.maximum(w, 0.0)) @ v.T


def transient_speed_covariance_from_data(model: MotionModel, runs: Runs, *,
                                         mode: ErrorMode = "free_run",
                                         bandwidth_s: float = DEFAULT_BANDWIDTH_S,
                                         window_s: float = DEFAULT_WINDOW_S,
                                         warmup: int = 0,
                                         slip: SlipNoise | None = DEFAULT_SLIP,
                                         ) -> TransientSpeedCovariance:
    """Fit ``Phi(f) = Phi_0 + f Phi_1`` on recorded runs against the encoders (no truth).

    Parameters
    ----------
    model : MotionModel
        The calibrated model.
    runs : sequence of (u, y)
        Commands and *encoder* body speeds of the model's calibration logs
        (:func:`lti_motion.calibration.speeds_from_log`), each starting at rest.
    mode : {"free_run", "one_step"}
        Which predictor's errors and speeds (:func:`~fusion.graph.model_speed_errors`).
    bandwidth_s : float
        Newey-West bandwidth [s].
    window_s : float
        Averaging window of the squared tracking error [s].
    warmup : int
        Leading samples of each run to drop.
    slip : SlipNoise or None
        Ground slip to add per sample when the result is used
        (:attr:`TransientSpeedCovariance.slip`; ``None``: none).

    Returns
    -------
    TransientSpeedCovariance

    Raises
    ------
    ValueError
        A non-positive bandwidth or window, or data whose fitted ``Phi_0`` is not
        positive definite (too little or constant data).

    Notes
    -----
    Least squares of ``h_k`` (the three distinct entries) on ``(1, f_k)`` over all
    samples of all runs. If the slope matrix is not positive semi-definite it is
    replaced by its nearest positive semi-definite matrix and the intercept refitted
    to keep the mean: ``Phi_0 = mean(h) - mean(f) Phi_1``. Without any transient in
    the data (``f`` constant) ``Phi_1 = 0`` and ``Phi_0`` is the unconditional
    long-run covariance.
    """
    if not (np.isfinite(bandwidth_s) and bandwidth_s > 0):
        raise ValueError(f"bandwidth_s must be positive, got {bandwidth_s}")
    window = _window_samples(window_s, model.dt_s)
    errors = model_speed_errors(model, runs, mode=mode)           # validates the runs
    lag = round(bandwidth_s / model.dt_s)
    h_all, f_all = [], []
    for (u, y), e in zip(runs, errors, strict=True):
        speeds = np.asarray(y, dtype=float) - e                      # the prediction
        f = mean_squared_tracking_error(u, speeds, wheel_base_m=model.wheel_base_m,
                                        window=window)
        h_all.append(long_run_contributions(e, bandwidth=lag)[int(warmup):])
        f_all.append(f[int(warmup):])
    h, f = np.concatenate(h_all).reshape(-1, 4), np.concatenate(f_all)
    if len(f) < 2:
        raise ValueError("need at least two samples after the warm-up")
    h_mean, f_mean = h.mean(axis=0), float(f.mean())
    f_var = float(np.mean((f - f_mean) ** 2))
    slope = np.zeros(4) if f_var <= 1e-12 * max(f_mean * f_mean, 1e-12) else (
        (f - f_mean) @ (h - h_mean) / (len(f) * f_var))           # least squares, eq. form
    per_squared = _psd_part(slope.reshape(2, 2))
    base = (h_mean - f_mean * per_squared.ravel()).reshape(2, 2)
    if np.linalg.eigvalsh(0.5 * (base + base.T)).min() <= 0:
        raise ValueError(f"the fitted steady-state speed covariance is not positive definite "
                         f"({base.tolist()}); give longer or more varied runs")
    return TransientSpeedCovariance(base=base, per_squared_tracking=per_squared,
                                    window_s=window_s, mean_squared_tracking_m2_s2=f_mean,
                                    slip=slip)
