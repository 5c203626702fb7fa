"""Speed-error covariances for preintegration, from data and from the encoders.

Preintegration (:mod:`fusion.graph.preintegration`) needs the per-sample covariance
``Phi`` of the speed errors such that ``N Phi`` is the covariance of their sum
over ``N`` samples. The model's own ``Phi``
(:func:`~fusion.graph.speed_error_covariance`) follows from its
noise model; on the simulator's driving it is optimistic (the linear model
misses traction limits and current saturation, and its ``R`` and ``Q`` come
from one-step residuals). This module measures ``Phi`` instead, and gives the
covariance of the encoder-filtered speeds:

- :func:`model_speed_errors`: the model's speed errors against the *encoder*
  speeds of recorded runs (its calibration or validation log; never a
  simulator's truth), sensor-less or one step ahead.
- :func:`long_run_covariance`: the long-run covariance (spectral density at
  frequency zero) of such errors, by the Newey-West (Bartlett-kernel)
  estimator, pooled over runs.
- :func:`long_run_contributions`: the same estimator split into one term per
  sample (their mean is :func:`long_run_covariance`), for a long-run
  covariance conditioned on the motion (:mod:`fusion.graph.transient_noise`).
- :func:`speed_covariance_from_data`: both together, the ``Phi`` to
  preintegrate with.
- :func:`filtered_speeds`: the model's Kalman-filtered (posterior) speeds
  given the encoder speeds, with the per-sample covariance of their error
  against the ground (encoder noise left after the update, plus wheel slip,
  :class:`~fusion.ekf.functions.SlipNoise`, the EKF's model): what
  ``mode="filtered"`` preintegrates.

Notes
-----
**Long-run covariance.** For a stationary error ``eps`` with autocovariance
``Gamma_tau = E[eps_{k+tau} eps_k^T]``, the sum of ``N`` samples has covariance
``sum_{|tau| < N} (N - |tau|) Gamma_tau``, which tends to ``N Phi`` with

.. math::

    \\Phi = \\sum_{\\tau=-\\infty}^{\\infty} \\Gamma_\\tau

(Brockwell & Davis 1991, section 7.1, theorem 7.1.1). The Newey-West
estimator (Newey & West 1987, eq. 2) with bandwidth ``L`` is

.. math::

    \\hat\\Phi_L = \\hat\\Gamma_0 + \\sum_{\\tau=1}^{L} \\Big(1 - \\frac{\\tau}{L+1}\\Big)
                 (\\hat\\Gamma_\\tau + \\hat\\Gamma_\\tau^T),

positive semi-definite by construction; with ``L + 1`` samples per block it
equals the overlapping-batch-means estimator (the covariance of sums over
``L + 1`` samples, divided by ``L + 1``; Flegal & Jones 2010, section 2), i.e.
the covariance of an *interval* of that length per sample. The errors are not
demeaned: a mean error is drift too, and the factor must cover it. ``L``
should exceed the correlation time of the errors; for the ARX models here
(poles of the free run up to about 0.98 per 15 ms) 5 s is the default.

References
----------
W. K. Newey, K. D. West, "A simple, positive semi-definite, heteroskedasticity
and autocorrelation consistent covariance matrix", Econometrica 55(3), 1987,
pp. 703-708, eq. 2.
P. J. Brockwell, R. A. Davis, *Time Series: Theory and Methods*, 2nd ed.,
Springer 1991, section 7.1 (the variance of a sample mean, eq. 7.1.2-7.1.4).
J. M. Flegal, G. L. Jones, "Batch means and spectral variance estimators in
Markov chain Monte Carlo", Annals of Statistics 38(2), 2010, pp. 1034-1070.
C. Forster et al., "On-Manifold Preintegration for Real-Time Visual-Inertial
Odometry", IEEE Trans. Robotics 33(1), 2017, eq. 35 (the covariance
propagated through preintegration, here per sample).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np

from fusion.noise import SlipNoise
from lti_motion.exceptions import NonFiniteError, ShapeError
from lti_motion.model.motion_model import MotionModel

__all__ = [
    "DEFAULT_BANDWIDTH_S",
    "DEFAULT_ENCODER_STD",
    "filtered_speeds",
    "long_run_contributions",
    "long_run_covariance",
    "model_speed_errors",
    "slip_covariance",
    "speed_covariance_from_data",
]

#: Default Newey-West bandwidth [s]: longer than the free-run errors' correlation time.
DEFAULT_BANDWIDTH_S = 5.0
#: Standard deviation of an encoder speed reading ``(v [m/s], w [rad/s])`` beyond the
#: model (the EKF's default ``encoder_std``, :class:`fusion.ekf.ModelEKF`).
DEFAULT_ENCODER_STD = (1e-5, 1e-4)

Runs = Sequence[tuple[np.ndarray, np.ndarray]]
ErrorMode = Literal["free_run", "one_step"]


def _check_pairs(runs: Runs) -> list[tuple[np.ndarray, np.ndarray]]:
    out = []
    for i, (u, y) in enumerate(runs):
        u, y = np.asarray(u, dtype=float), np.asarray(y, dtype=float)
        if u.ndim != 2 or u.shape[1] != 2 or y.shape != u.shape:
            raise ShapeError(f"run {i}: expected u and y of the same shape (n, 2), got "
                             f"{u.shape} and {y.shape}")
        if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
            raise NonFiniteError(f"run {i} holds NaN or infinite values; clean it first")
        out.append((u, y))
    if not out:
        raise ValueError("need at least one run (u, y)")
    return out


def model_speed_errors(model: MotionModel, runs: Runs, *, mode: ErrorMode = "free_run",
                       warmup: int = 0) -> list[np.ndarray]:
    """The model's speed errors against measured (encoder) speeds, per run.

    Parameters
    ----------
    model : MotionModel
        The calibrated model.
    runs : sequence of (u, y)
        Commands ``(L, R)`` [m/s] and encoder body speeds ``(v [m/s], w [rad/s])``,
        each of shape (n_i, 2) (:func:`lti_motion.calibration.speeds_from_log`
        on a calibration or validation log). Runs should start at rest (the
        model starts from a zero state).
    mode : {"free_run", "one_step"}
        Sensor-less speeds (:meth:`MotionModel.simulate`) or one step ahead
        (:meth:`MotionModel.predict_one_step`).
    warmup : int
        Leading samples of each run to drop.

    Returns
    -------
    list of ndarray, shape (n_i - warmup, 2)
        ``y - y_hat`` [m/s, rad/s].
    """
    errors = []
    for u, y in _check_pairs(runs):
        if mode == "free_run":
            y_hat = model.simulate(u)
        elif mode == "one_step":
            y_hat = model.predict_one_step(u, y)
        else:
            raise ValueError(f"mode must be 'free_run' or 'one_step', got {mode!r}")
        errors.append((y - y_hat)[int(warmup):])
    return errors


def long_run_covariance(errors: Sequence[np.ndarray] | np.ndarray, *, bandwidth: int
                        ) -> np.ndarray:
    """Newey-West (Bartlett) long-run covariance of vector errors, pooled over runs.

    Parameters
    ----------
    errors : ndarray, shape (n, d), or a sequence of them
        Error samples (one run, or several independent runs).
    bandwidth : int
        Lags ``L >= 0`` included (``0``: the plain second moment).

    Returns
    -------
    ndarray, shape (d, d)
        ``Gamma_0 + sum_{tau=1}^{L} (1 - tau / (L + 1)) (Gamma_tau + Gamma_tau^T)``
        with ``Gamma_tau = sum_runs sum_k e_{k+tau} e_k^T / sum_runs n`` (not
        demeaned); symmetric positive semi-definite (Newey & West 1987, eq. 2).

    Raises
    ------
    ShapeError, NonFiniteError, ValueError
        Malformed errors, a negative bandwidth, or no samples.

    Examples
    --------
    White noise: the long-run covariance is the variance.

    >>> e = np.random.default_rng(0).standard_normal((20000, 1))
    >>> round(float(long_run_covariance(e, bandwidth=10)[0, 0]), 1)
    1.0

    An AR(1) with coefficient 0.5 has ``Phi = 1 / (1 - 0.5)^2 = 4`` times its
    innovation variance:

    >>> w = np.random.default_rng(1).standard_normal(200000)
    >>> x = np.zeros_like(w)
    >>> for k in range(1, len(w)):
    ...     x[k] = 0.5 * x[k - 1] + w[k]
    >>> round(float(long_run_covariance(x[:, None], bandwidth=200)[0, 0]), 1)
    4.0
    """
    runs = [errors] if isinstance(errors, np.ndarray) else list(errors)
    runs = [np.asarray(e, dtype=float) for e in runs]
    if not runs or any(e.ndim != 2 for e in runs) or len({e.shape[1] for e in runs}) != 1:
        raise ShapeError(f"expected error arrays of shape (n, d), got "
                         f"{[e.shape for e in runs]}")
    if any(not np.all(np.isfinite(e)) for e in runs):
        raise NonFiniteError("errors hold NaN or infinite values")
    lag = int(bandwidth)
    if lag < 0:
        raise ValueError(f"bandwidth must be >= 0, got {bandwidth}")
    n_total = sum(len(e) for e in runs)
    if n_total == 0:
        raise ValueError("no error samples")
    d = runs[0].shape[1]
    gammas = np.zeros((lag + 1, d, d))
    for e in runs:
        n = len(e)
        if n == 0:
            continue
        # all lagged products at once through the FFT (Wiener-Khinchin), per channel pair
        size = 1 << int(np.ceil(np.log2(2 * n)))
        f = np.fft.rfft(e, n=size, axis=0)
        cross = np.fft.irfft(f[:, :, None] * np.conj(f[:, None, :]), n=size, axis=0)
        m = min(lag, n - 1)
        gammas[:m + 1] += cross[:m + 1]        # cross[tau] = sum_k e_{k+tau} e_k^T
    gammas /= n_total
    weights = 1.0 - np.arange(1, lag + 1) / (lag + 1.0)          # Bartlett kernel
    tail = np.einsum("t,tij->ij", weights, gammas[1:])
    phi = gammas[0] + tail + tail.T
    return 0.5 * (phi + phi.T)


def long_run_contributions(errors: np.ndarray, *, bandwidth: int) -> np.ndarray:
    """Per-sample terms of the Newey-West long-run covariance of one run.

    Parameters
    ----------
    errors : ndarray, shape (n, d)
        Error samples of one run.
    bandwidth : int
        Lags ``L >= 0`` included, as in :func:`long_run_covariance`.

    Returns
    -------
    ndarray, shape (n, d, d)
        ``h_k = (e_k s_k^T + s_k e_k^T) / 2`` with the Bartlett-weighted
        neighbourhood sum ``s_k = sum_{|tau| <= L} (1 - |tau| / (L + 1)) e_{k+tau}``
        (inside the run). Their mean over the run is exactly
        ``long_run_covariance(errors, bandwidth=L)``: every lagged product of the
        estimator (Newey & West 1987, eq. 2) is counted once, split between its two
        samples. A single ``h_k`` need not be positive semi-definite; what a
        regression of ``h_k`` on features of sample ``k`` estimates is the
        long-run covariance *conditioned* on those features.

    Raises
    ------
    ShapeError, NonFiniteError, ValueError
        Malformed or non-finite errors, or a negative bandwidth.

    Examples
    --------
    >>> e = np.random.default_rng(0).standard_normal((500, 2))
    >>> bool(np.allclose(long_run_contributions(e, bandwidth=7).mean(axis=0),
    ...                  long_run_covariance(e, bandwidth=7)))
    True
    """
    e = np.asarray(errors, dtype=float)
    if e.ndim != 2:
        raise ShapeError(f"expected errors of shape (n, d), got {e.shape}")
    if not np.all(np.isfinite(e)):
        raise NonFiniteError("errors hold NaN or infinite values")
    lag = int(bandwidth)
    if lag < 0:
        raise ValueError(f"bandwidth must be >= 0, got {bandwidth}")
    n = len(e)
    kernel = 1.0 - np.abs(np.arange(-lag, lag + 1)) / (lag + 1.0)          # Bartlett
    # s_k = sum_tau w_tau e_{k+tau}: a centred convolution, cut to the run (FFT for speed)
    size = 1 << int(np.ceil(np.log2(max(n + 2 * lag + 1, 2))))
    f = np.fft.rfft(e, n=size, axis=0) * np.fft.rfft(kernel, n=size)[:, None]
    s = np.fft.irfft(f, n=size, axis=0)[lag:lag + n]
    h = e[:, :, None] * s[:, None, :]
    return 0.5 * (h + np.swapaxes(h, 1, 2))


def speed_covariance_from_data(model: MotionModel, runs: Runs, *,
                               mode: ErrorMode = "free_run",
                               bandwidth_s: float = DEFAULT_BANDWIDTH_S,
                               warmup: int = 0) -> np.ndarray:
    """``Phi`` for :func:`~fusion.graph.preintegrate_model`, measured on data.

    Parameters
    ----------
    model : MotionModel
        The calibrated model.
    runs : sequence of (u, y)
        Commands and encoder speeds of the model's calibration or validation
        log(s), as in :func:`model_speed_errors`.
    mode : {"free_run", "one_step"}
        Which predictor's errors.
    bandwidth_s : float
        Newey-West bandwidth [s] (:data:`DEFAULT_BANDWIDTH_S`).
    warmup : int
        Leading samples of each run to drop.

    Returns
    -------
    ndarray, shape (2, 2)
        Long-run covariance [(m/s)^2, (rad/s)^2] per sample.

    Raises
    ------
    ValueError
        If ``bandwidth_s`` is not positive or the estimate is not positive
        definite (too little or constant data).
    """
    if not (np.isfinite(bandwidth_s) and bandwidth_s > 0):
        raise ValueError(f"bandwidth_s must be positive, got {bandwidth_s}")
    errors = model_speed_errors(model, runs, mode=mode, warmup=warmup)
    phi = long_run_covariance(errors, bandwidth=round(bandwidth_s / model.dt_s))
    if np.linalg.eigvalsh(phi).min() <= 0:
        raise ValueError(f"the long-run speed covariance from the data is not positive "
                         f"definite ({phi.tolist()}); give longer or more varied runs")
    return phi


def slip_covariance(speeds: np.ndarray, *, slip: SlipNoise | None = None) -> np.ndarray:
    """Per-sample covariance of ground minus encoder speeds (wheel slip), ``(n, 2, 2)``.

    ``diag(sigma_v^2, sigma_w^2)`` with :meth:`SlipNoise.stds` at each sample's
    speeds (the EKF's model, :mod:`fusion.ekf.functions`), vectorised.
    """
    sp = np.asarray(speeds, dtype=float)
    if sp.ndim != 2 or sp.shape[1] != 2:
        raise ShapeError(f"expected speeds of shape (n, 2), got {sp.shape}")
    s = slip or SlipNoise()
    av, aw = np.abs(sp[:, 0]), np.abs(sp[:, 1])
    out = np.zeros((len(sp), 2, 2))
    out[:, 0, 0] = (s.v_floor_m_s + s.v_frac * av) ** 2
    out[:, 1, 1] = (s.w_floor_rad_s + s.w_frac * aw + s.w_per_v_rad_m * av) ** 2
    return out


def filtered_speeds(model: MotionModel, cmd_m_s: np.ndarray, speeds: np.ndarray, *,
                    encoder_std: tuple[float, float] = DEFAULT_ENCODER_STD,
                    slip: SlipNoise | None = None,
                    z0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The model's Kalman-filtered speeds given the encoders, and their error covariance.

    Parameters
    ----------
    model : MotionModel
        The calibrated model (innovations form).
    cmd_m_s : array_like, shape (n, 2)
        Wheel commands [m/s].
    speeds : array_like, shape (n, 2)
        Encoder body speeds [m/s, rad/s].
    encoder_std : (float, float)
        Noise of a reading beyond the model's ``R`` (:data:`DEFAULT_ENCODER_STD`).
    slip : SlipNoise, optional
        Ground-versus-encoder speed noise (the EKF's default).
    z0 : array_like, optional
        Model state before sample 0 (zeros: at rest).

    Returns
    -------
    speeds : ndarray, shape (n, 2)
        Posterior speeds ``s+ = s- + W (y - s-)`` with the one-step prediction
        ``s- = y_hat[n | n-1]`` (covariance ``R``, innovations form),
        ``W = R (R + R_enc)^-1`` and ``R_enc = diag(encoder_std^2)``.
    covariance : ndarray, shape (n, 2, 2)
        ``(I - W) R`` (the posterior covariance, Simon 2006 eq. 5.19) plus
        :func:`slip_covariance` at the posterior speeds: the covariance of the
        posterior's error against the ground, per sample, white (slip is white
        in the EKF's model; the encoders' quantisation is a difference of
        rounding errors, whose sum over an interval does not grow).

    Notes
    -----
    This is the speed part of the EKF's encoder update
    (:mod:`fusion.ekf.functions`: after the update the speed state is the
    reading, up to ``R_enc``), so the smoother's motion factors carry the
    same information as the EKF's encoder updates.
    """
    cmd_m_s = np.asarray(cmd_m_s, dtype=float)
    y = np.asarray(speeds, dtype=float)
    prior = model.predict_one_step(cmd_m_s, y, z0=z0)
    r = np.asarray(model.R)
    r_enc = np.diag(np.square(np.asarray(encoder_std, dtype=float)))
    gain = np.linalg.solve((r + r_enc).T, r.T).T                      # R (R + R_enc)^-1
    post = prior + (y - prior) @ gain.T
    post_cov = (np.eye(2) - gain) @ r
    post_cov = 0.5 * (post_cov + post_cov.T)
    return post, post_cov + slip_covariance(post, slip=slip)
