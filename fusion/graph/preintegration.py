"""Preintegration of a motion model's body speeds between keyframes, in SE(2).

Between two keyframes ``i`` and ``j`` a factor graph needs one relative pose
``iTj`` (frame ``j`` expressed in frame ``i``) with its covariance, not the
hundreds of speed samples in between. As IMU preintegration does for
gyroscope and accelerometer samples (Forster et al. 2017), this module sums
the model's predicted speeds ``(v, w)`` into that relative pose once, with

- the covariance of its error in the tangent space at ``iTj`` (gtsam's
  ``Pose2`` local coordinates ``(x, y, theta)`` in frame ``j``), propagated
  from the model's own speed-error covariance through the kinematics
  Jacobians (:func:`lti_motion.kinematics.pose_step_jacobians`), and
- the first-order derivative of ``iTj`` with respect to the calibration
  ``c = (s, g)``: a scale ``s`` on the linear speed and a gain ``g`` on the
  yaw rate (true speeds ``(s v, g w)``), or ``c = (s, g, kappa)`` with a
  curvature ``kappa`` [rad/m] as well (true speeds ``(s v, g w + kappa v)``:
  the model EKF's ``D_c`` with ``s = 1 + k_v``, ``g = 1 + k_w``, a left/right
  wheel diameter ratio; :mod:`fusion.ekf.functions`, *Pose noise*), so a
  smoother can correct the relative pose for a new calibration without
  integrating again.

Everything is vectorised over all samples of all intervals at once: headings
and positions by cumulative sums, per-interval sums by ``np.add.reduceat``.

Notes
-----
**Which covariance.** The speed errors of an LTI predictor are correlated in
time. In the innovations form ``z' = A z + B u + K e``, ``y = C z + D u + e``
(:class:`~lti_motion.model.MotionModel`) the free-run (sensor-less) speed
error is ``eps[n] = C x[n] + e[n]`` with ``x' = A x + w``, ``cov(w) = Q``,
``E[w e^T] = K R``. Its autocovariance is

.. math::

    \\Gamma_0 = C P C^T + R, \\qquad
    \\Gamma_\\tau = C A^{\\tau-1} (A P C^T + K R) \\quad (\\tau \\ge 1),

with ``P = A P A^T + Q`` the stationary state-error covariance (the limit of
:meth:`~lti_motion.model.MotionModel.output_error_covariance`). A chain of
independent between-factors cannot hold correlations *across* intervals, so
each interval gets the *long-run* covariance (the spectral density at zero
frequency, Newey & West 1987)

.. math::

    \\Phi = \\sum_{\\tau=-\\infty}^{\\infty} \\Gamma_\\tau
          = \\Gamma_0 + \\Sigma_1 + \\Sigma_1^T, \\qquad
    \\Sigma_1 = C (I - A)^{-1} (A P C^T + K R),

per sample, as if the errors were white with covariance ``Phi``. The summed
error over ``N`` samples then has covariance ``N Phi`` (plus edge terms that
vanish relative to it when ``N`` exceeds the correlation time), so the
covariance of a *chain* of intervals grows as the true one does, whatever
the keyframe spacing. Using ``Gamma_0`` alone would treat correlated errors
as white and make long chains over-confident. With encoders
(``mode="one_step"``) the errors of the one-step predictor are the
innovations ``e``, white by construction: ``Phi = R``. ``Phi`` may also vary
per sample (shape ``(n, 2, 2)``): :mod:`fusion.graph.transient_noise` measures it
as a function of the model's wheel tracking error, larger in the transients
after command steps that a linear model cannot follow.

The relative-pose error is, to first order, ``delta = sum_k G_k eps_k``
with ``G_k = T (F_speed,k + [J (p_j - p_{k+1}) dt_k; 0] e_w^T)``: the
kinematics Jacobian of step ``k`` plus the lever arm by which a yaw-rate
error at step ``k`` swings the rest of the interval (``J`` is the rotation by
90 degrees, ``T = diag(R_j^T, 1)`` takes frame-``i`` errors to the local
coordinates at ``j``). So ``cov = sum_k G_k D_c Phi D_c^T G_k^T`` with
``D_c = [[s, 0], [kappa, g]]`` (``diag(s, g)`` without ``kappa``), and the
calibration Jacobian is ``sum_k G_k D_s,k`` with ``D_s = d(true speeds)/dc =
[[v, 0, 0], [0, w, v]]`` at the encoder/model speeds ``(v, w)`` (its first two
columns without ``kappa``; the EKF's ``D_s``, :mod:`fusion.ekf.functions`).

References
----------
The paper: ``docs/architecture.md``, "The paper".
C. Forster, L. Carlone, F. Dellaert, D. Scaramuzza, "On-Manifold
Preintegration for Real-Time Visual-Inertial Odometry", IEEE Trans.
Robotics 33(1), 2017, pp. 1-21: sections V-VI (preintegrated measurements,
eq. 33-35; first-order bias correction, eq. 44).
W. K. Newey, K. D. West, "A simple, positive semi-definite,
heteroskedasticity and autocorrelation consistent covariance matrix",
Econometrica 55(3), 1987, pp. 703-708.
L. Ljung, *System Identification*, 2nd ed., 1999, section 4.3 (innovations form).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.linalg

from fusion.exceptions import (
    EmptyIntervalError,
    GraphInputError,
    KeyframeOrderError,
    MeasurementShapeError,
    NonFiniteInputError,
)
from fusion.graph.speed_noise import filtered_speeds
from fusion.graph.transient_noise import TransientSpeedCovariance
from lti_motion.kinematics import pose_step_jacobians
from lti_motion.model.motion_model import MotionModel

__all__ = [
    "FILTERED_SLIP_DENSITY",
    "SLIP_DENSITY",
    "Preintegrated",
    "SpeedMode",
    "compose_motions",
    "fit_calibration",
    "preintegrate",
    "preintegrate_model",
    "relative_pose_errors",
    "speed_error_covariance",
]

#: Default :func:`preintegrate` ``slip_density``: 1 mm and 1 mrad per square-root second.
SLIP_DENSITY = (1e-6, 1e-6, 1e-6)
#: :func:`preintegrate_model`'s ``slip_density`` in ``mode="filtered"`` and with a
#: :class:`~fusion.graph.TransientSpeedCovariance`: 0.1 mm and 0.1 mrad per
#: square-root second (slip along the track and in heading is in the per-sample
#: covariance there; this keeps the sideways direction positive definite).
FILTERED_SLIP_DENSITY = (1e-8, 1e-8, 1e-8)
#: Where the speeds come from: commands only, the one-step predictor with encoders, or
#: the model's Kalman-filtered (posterior) speeds given the encoders.
SpeedMode = Literal["free_run", "one_step", "filtered"]











_FIELDS = ("keyframes", "duration_s", "delta_pose", "covariance", "calibration_jacobian",
           "calibration")


@dataclass(frozen=True, eq=False)
class Preintegrated:
    """Relative motions between consecutive keyframes, preintegrated (``m`` intervals).

    Attributes
    ----------
    keyframes : ndarray of int, shape (m + 1,)
        Sample indices of the keyframes: interval ``k`` holds samples
        ``keyframes[k] .. keyframes[k + 1] - 1``, and keyframe ``k`` is the
        pose before sample ``keyframes[k]``.
    duration_s : ndarray, shape (m,)
        Length of each interval [s].
    delta_pose : ndarray, shape (m, 3)
        ``iTj`` as ``(x [m], y [m], theta [rad])``: keyframe ``k + 1`` in the
        frame of keyframe ``k``; ``theta`` is the turned angle (not wrapped).
    covariance : ndarray, shape (m, 3, 3)
        Covariance of ``Log(iTj_hat^-1 iTj_true)`` (gtsam ``Pose2`` local
        coordinates at ``iTj``: ``(x, y)`` in frame ``j`` [m^2], ``theta`` [rad^2]).
    calibration_jacobian : ndarray, shape (m, 3, nc)
        ``d Log(iTj_hat^-1 iTj(c)) / d c`` at ``c = calibration``, columns for
        the scale ``s`` of ``v``, the gain ``g`` of ``w`` and, with ``nc = 3``,
        the curvature ``kappa`` [rad/m].
    calibration : ndarray, shape (nc,)
        The calibration ``(s, g)`` or ``(s, g, kappa)`` the speeds were integrated with.
    """

    keyframes: np.ndarray
    duration_s: np.ndarray
    delta_pose: np.ndarray
    covariance: np.ndarray
    calibration_jacobian: np.ndarray
    calibration: np.ndarray

    def __post_init__(self) -> None:
        for name in _FIELDS:
            arr = np.array(getattr(self, name))
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    def __len__(self) -> int:
        return len(self.delta_pose)

    def __getitem__(self, index: int | slice) -> Preintegrated:
        """Consecutive intervals as their own :class:`Preintegrated` (int or step-1 slice)."""
        rng = range(len(self))[index]
        if isinstance(rng, int):
            rng = range(rng, rng + 1)
        if rng.step != 1 or len(rng) == 0:
            raise IndexError(f"need a non-empty slice with step 1, got {index!r}")
        sl = slice(rng.start, rng.stop)
        # read-only views of arrays __post_init__ already made: no copies, no checks
        return Preintegrated._of_views(self.keyframes[rng.start:rng.stop + 1],
                                       self.duration_s[sl], self.delta_pose[sl],
                                       self.covariance[sl], self.calibration_jacobian[sl],
                                       self.calibration)

    @classmethod
    def _of_views(cls, *arrays: np.ndarray) -> Preintegrated:
        """An instance of read-only arrays (views of another instance's), in field order."""
        out = object.__new__(cls)
        for name, arr in zip(_FIELDS, arrays, strict=True):
            object.__setattr__(out, name, arr)
        return out


def _scaled_speed_covariance(phi_cov: np.ndarray, cal: np.ndarray
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Entries ``(p, q, r)`` of ``D_c Phi D_c^T``, ``D_c = [[s, 0], [kappa, g]]`` (module notes)."""
    s, g = cal[0], cal[1]
    kappa = cal[2] if len(cal) == 3 else 0.0
    p0, q0, r0 = phi_cov[..., 0, 0], phi_cov[..., 0, 1], phi_cov[..., 1, 1]
    if kappa == 0.0:
        return s * s * p0, s * g * q0, g * g * r0                 # diag(c) Phi diag(c)
    return (s * s * p0, s * (kappa * p0 + g * q0),
            kappa * kappa * p0 + 2.0 * kappa * g * q0 + g * g * r0)


def speed_error_covariance(model: MotionModel, *, mode: SpeedMode = "free_run") -> np.ndarray:
    """Long-run covariance ``Phi`` of a model's per-sample speed errors.

    Parameters
    ----------
    model : MotionModel
        The calibrated model.
    mode : {"free_run", "one_step"}
        ``"free_run"``: speeds from commands only (:meth:`MotionModel.simulate`);
        ``"one_step"``: the one-step predictor with encoder speeds
        (:meth:`MotionModel.predict_one_step`).

    Returns
    -------
    ndarray, shape (2, 2)
        ``Phi`` [(m/s)^2, (rad/s)^2]: ``sum_k eps_k`` over ``N`` samples has
        covariance about ``N Phi``.

    Notes
    -----
    Free run: ``Phi = Gamma_0 + Sigma_1 + Sigma_1^T`` with the stationary
    ``P`` from the discrete Lyapunov equation ``P = A P A^T + Q`` (module
    notes). One step: ``Phi = R`` (innovations are white; Ljung 1999, 4.3).

    Examples
    --------
    A static gain with white output noise (no state): ``Phi = R``.

    >>> from lti_motion.model.fir import FirFit
    >>> m = MotionModel.from_fir(FirFit(taps=np.stack([np.eye(2)]), residual_cov=np.eye(2) * 1e-4,
    ...     n_samples=100, source="steps"), dt_s=0.015, wheel_base_m=0.235,
    ...     calibrated_at="2026-01-01T00:00:00+00:00")
    >>> bool(np.allclose(speed_error_covariance(m), np.eye(2) * 1e-4))
    True
    """
    if mode == "one_step":
        return np.array(model.R)
    if mode != "free_run":
        raise GraphInputError(f"mode must be 'free_run' or 'one_step', got {mode!r}")
    a, c = model.A, model.C
    if model.n_states == 0:
        return np.array(model.R)
    p = scipy.linalg.solve_discrete_lyapunov(a, model.Q)     # P = A P A^T + Q
    gamma0 = c @ p @ c.T + model.R
    sigma1 = c @ np.linalg.solve(np.eye(model.n_states) - a, a @ p @ c.T + model.S)
    phi = gamma0 + sigma1 + sigma1.T                          # Newey & West 1987
    phi = 0.5 * (phi + phi.T)
    if np.linalg.eigvalsh(phi).min() <= 0:   # cannot happen for a valid model; never return junk
        raise ValueError(f"long-run speed covariance is not positive definite: {phi.tolist()}")
    return phi


def _check_keyframes(keyframes: np.ndarray, n: int) -> np.ndarray:
    kf = np.asarray(keyframes)
    if kf.ndim != 1 or kf.size < 2:
        raise MeasurementShapeError(f"expected keyframes of shape (m + 1,) with m >= 1, got "
                                    f"{kf.shape}")
    if not np.issubdtype(kf.dtype, np.integer):
        if not (np.all(np.isfinite(kf)) and np.array_equal(kf, np.round(kf))):
            raise GraphInputError(f"keyframes must be integer sample indices, got {kf[:5]}...")
        kf = kf.astype(np.int64)
    steps = np.diff(kf)
    if np.any(steps < 0):
        bad = int(np.argmax(steps < 0))
        raise KeyframeOrderError(
            f"keyframes must increase: keyframes[{bad + 1}] = {kf[bad + 1]} comes after "
            f"keyframes[{bad}] = {kf[bad]}; sort them")
    if np.any(steps == 0):
        bad = int(np.argmax(steps == 0))
        raise EmptyIntervalError(
            f"the interval between keyframes {bad} and {bad + 1} (sample {kf[bad]}) holds no "
            "samples; drop the repeated keyframe")
    if kf[0] < 0 or kf[-1] > n:
        raise GraphInputError(f"keyframes must lie in [0, {n}] for {n} speed samples, got "
                              f"{kf[0]} .. {kf[-1]}")
    return kf.astype(np.int64)


def preintegrate(speeds: np.ndarray, dt_s: float | np.ndarray, *, keyframes: np.ndarray,
                 speed_covariance: np.ndarray,
                 calibration: tuple[float, ...] | np.ndarray = (1.0, 1.0),
                 slip_density: tuple[float, float, float] | np.ndarray = SLIP_DENSITY,
                 ) -> Preintegrated:
    """Preintegrate body speeds between consecutive keyframes.

    Parameters
    ----------
    speeds : array_like, shape (n, 2)
        Predicted body speeds ``(v [m/s], w [rad/s])``, sample ``k`` held
        over ``[t_k, t_k + dt_k)``.
    dt_s : float or array_like, shape (n,)
        Sample period(s) [s].
    keyframes : array_like of int, shape (m + 1,)
        Strictly increasing sample indices in ``[0, n]``.
    speed_covariance : array_like, shape (2, 2) or (n, 2, 2)
        Per-sample (long-run) covariance ``Phi`` of the speed errors
        (:func:`speed_error_covariance`), one for all samples or one per sample.
    calibration : (float, float) or (float, float, float)
        ``(s, g)``: the speeds integrated are ``(s v, g w)``; the errors
        scale with them (``diag(c) Phi diag(c)``). ``(s, g, kappa)``: the
        speeds are ``(s v, g w + kappa v)`` (``kappa`` [rad/m]), the errors
        ``D_c Phi D_c^T`` (module notes), and the Jacobian has a third column.
    slip_density : (float, float, float)
        White pose noise outside the speed model (sideways slip and scrub,
        floor roughness), ``(x [m^2/s], y [m^2/s], theta [rad^2/s])`` in the
        body frame, added as ``diag(slip_density) * duration``
        (:data:`SLIP_DENSITY`). It also keeps the covariance positive
        definite: the kinematics alone give no sideways error at rest
        (the robot is non-holonomic), a singular covariance.

    Returns
    -------
    Preintegrated

    Raises
    ------
    MeasurementShapeError, NonFiniteInputError
        Malformed or non-finite arrays (also ``lti_motion``'s ``ShapeError`` and
        ``NonFiniteError``).
    KeyframeOrderError, EmptyIntervalError, GraphInputError
        Keyframes out of order, repeated, or outside the samples.

    Notes
    -----
    Mean: the chord form of paper eq. 11 with headings relative to keyframe
    ``i``, summed per interval. Covariance and calibration Jacobian: module
    notes (Forster et al. 2017, eq. 35 and 44, in SE(2)).

    Examples
    --------
    A quarter circle of radius 1 m in one interval:

    >>> pre = preintegrate(np.tile([np.pi / 2, np.pi / 2], (100, 1)), 0.01,
    ...                    keyframes=[0, 100], speed_covariance=np.eye(2) * 1e-4)
    >>> pre.delta_pose.round(9).tolist()
    [[1.0, 1.0, 1.570796327]]
    """
    sp = np.asarray(speeds, dtype=float)
    if sp.ndim != 2 or sp.shape[1] != 2:
        raise MeasurementShapeError(f"expected speeds of shape (n, 2) (v, w), got {sp.shape}")
    n = len(sp)
    kf = _check_keyframes(keyframes, n)
    dt = np.broadcast_to(np.asarray(dt_s, dtype=float), (n,)) if np.ndim(dt_s) == 0 else (
        np.asarray(dt_s, dtype=float))
    if dt.shape != (n,):
        raise MeasurementShapeError(f"expected dt_s a number or of shape ({n},), got {dt.shape}")
    phi_cov = np.asarray(speed_covariance, dtype=float)
    if phi_cov.shape not in ((2, 2), (n, 2, 2)):
        raise MeasurementShapeError(f"expected speed_covariance of shape (2, 2) or ({n}, 2, 2), "
                                    f"got {phi_cov.shape}")
    slip = np.asarray(slip_density, dtype=float)
    if slip.shape != (3,) or not np.all(slip >= 0):
        raise GraphInputError(f"slip_density must be three non-negative densities, got "
                              f"{slip_density}")
    cal = np.asarray(calibration, dtype=float)
    if cal.shape not in ((2,), (3,)):
        raise MeasurementShapeError(f"expected calibration (s, g) or (s, g, kappa) of shape (2,) "
                                    f"or (3,), got {cal.shape}")
    lo, hi = int(kf[0]), int(kf[-1])
    sp, dt = sp[lo:hi], dt[lo:hi]
    if phi_cov.ndim == 3:
        phi_cov = phi_cov[lo:hi]
    for name, arr in (("speeds", sp), ("dt_s", dt), ("speed_covariance", phi_cov),
                      ("calibration", cal)):
        if not np.all(np.isfinite(arr)):
            raise NonFiniteInputError(f"{name} holds NaN or infinite values; clean the input first")
    if np.any(dt <= 0):
        raise GraphInputError(f"dt_s must be positive, got min {dt.min()}")

    starts = kf[:-1] - lo                       # interval starts within the used samples
    lengths = np.diff(kf)
    seg = np.repeat(np.arange(len(starts)), lengths)
    v_raw, w_raw = sp[:, 0], sp[:, 1]
    kappa = float(cal[2]) if len(cal) == 3 else 0.0
    v, w = cal[0] * v_raw, cal[1] * w_raw + kappa * v_raw          # D_c (module notes)

    # headings relative to keyframe i at the start of each sample: exclusive cumsum per interval
    phi = w * dt
    excl = np.cumsum(phi) - phi
    theta = excl - excl[starts][seg]
    zeros = np.zeros_like(theta)
    _, f_speed = pose_step_jacobians(np.stack([zeros, zeros, theta], axis=-1), v, w, dt)
    # the chord of each step (paper eq. 11) is dx/dv * v: F_speed[:, :2, 0] = dt S(h) (cos, sin)(m)
    a, c = f_speed[:, 0, 0], f_speed[:, 1, 0]                    # d(x, y)/dv, frame i
    chord_x, chord_y = a * v, c * v
    sums = np.add.reduceat(np.stack([chord_x, chord_y, phi, dt], axis=-1), starts, axis=0)
    d_x, d_y, d_theta, duration = sums.T                          # p_j in frame i, turn, time
    incl_x, incl_y = np.cumsum(chord_x), np.cumsum(chord_y)
    rem_x = d_x[seg] - (incl_x - (incl_x - chord_x)[starts][seg])  # p_j - p_{k+1}, frame i
    rem_y = d_y[seg] - (incl_y - (incl_y - chord_y)[starts][seg])
    # d(x, y)/dw: the step's own chord plus the lever arm J (p_j - p_{k+1}) dt
    b = f_speed[:, 0, 1] - rem_y * dt
    d = f_speed[:, 1, 1] + rem_x * dt
    # G Phi G^T with G = [[a, b], [c, d], [0, dt]], six distinct entries per sample
    p, q, r = _scaled_speed_covariance(phi_cov, cal)
    ga, gb, gc, gd = p * a + q * b, q * a + r * b, p * c + q * d, q * c + r * d
    columns = [ga * a + gb * b, ga * c + gb * d, gb * dt, gc * c + gd * d, gd * dt,
               r * dt * dt, a * v_raw, b * w_raw, c * v_raw, d * w_raw, dt * w_raw]
    if len(cal) == 3:                  # d/dkappa: the yaw-rate column G e_w times v (D_s)
        columns += [b * v_raw, d * v_raw, dt * v_raw]
    acc = np.add.reduceat(np.stack(columns, axis=-1), starts, axis=0)
    cov_i = acc[:, [0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(-1, 3, 3)
    jac_i = np.zeros((len(starts), 3, len(cal)))
    jac_i[:, 0, 0], jac_i[:, 0, 1], jac_i[:, 1, 0], jac_i[:, 1, 1], jac_i[:, 2, 1] = acc[:, 6:11].T
    if len(cal) == 3:
        jac_i[:, 0, 2], jac_i[:, 1, 2], jac_i[:, 2, 2] = acc[:, 11:].T

    cs, sn = np.cos(d_theta), np.sin(d_theta)
    t = np.zeros((len(starts), 3, 3))                             # diag(R_j^T, 1)
    t[:, 0, 0], t[:, 0, 1], t[:, 1, 0], t[:, 1, 1], t[:, 2, 2] = cs, sn, -sn, cs, 1.0
    cov = t @ cov_i @ np.swapaxes(t, 1, 2)
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    cov += duration[:, None, None] * np.diag(slip)
    return Preintegrated(
        keyframes=kf, duration_s=duration,
        delta_pose=np.column_stack([d_x, d_y, d_theta]), covariance=cov,
        calibration_jacobian=t @ jac_i, calibration=cal,
    )


def preintegrate_model(model: MotionModel, cmd_m_s: np.ndarray, *, keyframes: np.ndarray,
                       mode: SpeedMode = "free_run", measured_speeds: np.ndarray | None = None,
                       z0: np.ndarray | None = None, covariance_scale: float = 1.0,
                       speed_covariance: np.ndarray | TransientSpeedCovariance | None = None,
                       calibration: tuple[float, ...] | np.ndarray = (1.0, 1.0),
                       slip_density: tuple[float, float, float] | np.ndarray | None = None,
                       ) -> Preintegrated:
    """Predict speeds with a model, then preintegrate them between keyframes.

    Parameters
    ----------
    model : MotionModel
        The calibrated model (``dt_s`` is its sample period).
    cmd_m_s : array_like, shape (n, 2)
        Wheel commands ``(L, R)`` [m/s], one per sample.
    keyframes : array_like of int, shape (m + 1,)
        Strictly increasing sample indices in ``[0, n]``.
    mode : {"free_run", "one_step", "filtered"}
        Sensor-less (:meth:`MotionModel.simulate`), one step ahead with the
        encoders (:meth:`MotionModel.predict_one_step`), or the model's
        Kalman-filtered speeds given the encoders
        (:func:`fusion.graph.filtered_speeds`, with their per-sample
        error covariance, slip included). The last two need ``measured_speeds``.
    measured_speeds : array_like, shape (n, 2), optional
        Encoder body speeds, for ``mode="one_step"`` and ``"filtered"``.
    z0 : array_like, shape (nz,), optional
        Model state before sample 0 (zeros: at rest).
    covariance_scale : float
        Factor on the speed covariance; 1 (the default) trusts it.
    speed_covariance : array_like or TransientSpeedCovariance, optional
        The speed covariance to use instead of the model's own
        (:func:`speed_error_covariance`): shape (2, 2) or (n, 2, 2), e.g.
        measured on the calibration log
        (:func:`fusion.graph.speed_covariance_from_data`); or a
        :class:`fusion.graph.TransientSpeedCovariance`, evaluated
        per sample at the commands and the predicted speeds (larger during
        the model's transients).
    calibration : (float, float) or (float, float, float)
        Linearisation point ``(s, g)`` or ``(s, g, kappa)`` (:func:`preintegrate`).
    slip_density : (float, float, float), optional
        Pose noise outside the model, as in :func:`preintegrate`; default
        :data:`SLIP_DENSITY`, or :data:`FILTERED_SLIP_DENSITY` when the per-sample
        covariance already holds the ground slip (``"filtered"``, or a
        ``TransientSpeedCovariance`` with ``slip``).

    Returns
    -------
    Preintegrated

    Raises
    ------
    GraphInputError
        For an unknown mode, a missing ``measured_speeds``, a non-positive
        ``covariance_scale``; and as :func:`preintegrate`.
    """
    if mode in ("one_step", "filtered") and measured_speeds is None:
        raise GraphInputError(f"mode={mode!r} needs measured_speeds (encoder body speeds, "
                              "shape (n, 2))")
    if mode == "free_run":
        speeds = model.simulate(cmd_m_s, z0=z0)
        phi = speed_error_covariance(model, mode=mode)
    elif mode == "one_step":
        speeds = model.predict_one_step(cmd_m_s, measured_speeds, z0=z0)
        phi = speed_error_covariance(model, mode=mode)
    elif mode == "filtered":
        speeds, phi = filtered_speeds(model, cmd_m_s, measured_speeds, z0=z0)
    else:
        raise GraphInputError(f"mode must be 'free_run', 'one_step' or 'filtered', got {mode!r}")
    scale = float(covariance_scale)
    if not (np.isfinite(scale) and scale > 0):
        raise GraphInputError(f"covariance_scale must be positive and finite, got "
                              f"{covariance_scale}")
    if isinstance(speed_covariance, TransientSpeedCovariance):
        phi = speed_covariance.per_sample(cmd_m_s, speeds, wheel_base_m=model.wheel_base_m,
                                          dt_s=model.dt_s)
    elif speed_covariance is not None:
        phi = np.asarray(speed_covariance, dtype=float)
    if slip_density is None:
        with_slip = mode == "filtered" or (isinstance(speed_covariance, TransientSpeedCovariance)
                                           and speed_covariance.slip is not None)
        slip_density = FILTERED_SLIP_DENSITY if with_slip else SLIP_DENSITY
    return preintegrate(speeds, model.dt_s, keyframes=keyframes, speed_covariance=scale * phi,
                        calibration=calibration, slip_density=slip_density)


def compose_motions(delta_pose: np.ndarray, *, initial_pose: np.ndarray) -> np.ndarray:
    """Chain relative poses into absolute ones (dead reckoning through keyframes).

    Parameters
    ----------
    delta_pose : array_like, shape (m, 3)
        Relative poses ``iTj`` (e.g. :attr:`Preintegrated.delta_pose`).
    initial_pose : array_like, shape (3,)
        ``wTb`` of the first keyframe ``(x [m], y [m], theta [rad])``.

    Returns
    -------
    ndarray, shape (m + 1, 3)
        ``wT0, wT0 iT1, ...``; headings continuous (not wrapped).

    Examples
    --------
    >>> poses = compose_motions(np.array([[1.0, 0.0, np.pi / 2]] * 2), initial_pose=np.zeros(3))
    >>> (poses.round(9) + 0.0).tolist()
    [[0.0, 0.0, 0.0], [1.0, 0.0, 1.570796327], [1.0, 1.0, 3.141592654]]
    """
    d = np.asarray(delta_pose, dtype=float)
    start = np.asarray(initial_pose, dtype=float)
    if d.ndim != 2 or d.shape[1] != 3 or start.shape != (3,):
        raise MeasurementShapeError(f"expected delta_pose (m, 3) and initial_pose (3,), got "
                                    f"{d.shape} and "
                         f"{start.shape}")
    theta = start[2] + np.concatenate([[0.0], np.cumsum(d[:, 2])])
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    steps = np.column_stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]])
    xy = start[:2] + np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
    return np.column_stack([xy, theta])


def _se2_log(x: np.ndarray, y: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Logmap of SE(2) poses ``(x, y, theta)`` (gtsam ``Pose2.Logmap``), vectorised, (k, 3)."""
    th = np.arctan2(np.sin(theta), np.cos(theta))
    half = 0.5 * th
    # V(theta)^-1 = (h / tan h) I + h J^T with h = theta / 2 (Murray, Li & Sastry 1994, 2.3)
    a = np.where(np.abs(half) < 1e-8, 1.0 - half * half / 3.0,
                 half * np.cos(half) / np.where(half == 0, 1.0, np.sin(half)))
    return np.column_stack([a * x + half * y, -half * x + a * y, th])


def relative_pose_errors(pre: Preintegrated, poses: np.ndarray) -> np.ndarray:
    """Errors of the preintegrated relative poses against reference keyframe poses.

    Parameters
    ----------
    pre : Preintegrated
        ``m`` intervals.
    poses : array_like, shape (m + 1, 3)
        Reference ``wTb`` at the keyframes (ground truth, motion capture).

    Returns
    -------
    ndarray, shape (m, 3)
        ``Log(iTj_hat^-1 wTi^-1 wTj)`` per interval, the motion factor's error
        at the reference poses (gtsam ``Pose2`` local coordinates).
    """
    ref = np.asarray(poses, dtype=float)
    if ref.shape != (len(pre) + 1, 3):
        raise MeasurementShapeError(f"expected poses of shape ({len(pre) + 1}, 3), got "
                                    f"{ref.shape}")
    c, s = np.cos(ref[:-1, 2]), np.sin(ref[:-1, 2])
    dx, dy = ref[1:, 0] - ref[:-1, 0], ref[1:, 1] - ref[:-1, 1]
    bx, by = c * dx + s * dy, -s * dx + c * dy                    # wTi^-1 wTj
    m = pre.delta_pose
    cm, sm = np.cos(m[:, 2]), np.sin(m[:, 2])
    ex, ey = bx - m[:, 0], by - m[:, 1]
    return _se2_log(cm * ex + sm * ey, -sm * ex + cm * ey, ref[1:, 2] - ref[:-1, 2] - m[:, 2])


def fit_calibration(pre: Preintegrated, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The constant calibration ``(s, g)`` or ``(s, g, kappa)`` best explaining reference poses.

    Parameters
    ----------
    pre : Preintegrated
        ``m`` intervals, with calibration Jacobians and covariances.
    poses : array_like, shape (m + 1, 3)
        Reference ``wTb`` at the keyframes.

    Returns
    -------
    calibration : ndarray, shape (nc,)
        Weighted least squares ``c = c_bar + (sum J^T W J)^-1 sum J^T W r`` with
        ``r`` from :func:`relative_pose_errors` and ``W`` the inverse
        interval covariances: what a calibration-aware graph with perfectly
        known poses would estimate (one Gauss-Newton step, exact in ``s``).
    covariance : ndarray, shape (nc, nc)
        ``(sum J^T W J)^-1``.
    """
    r = relative_pose_errors(pre, poses)
    w = np.linalg.inv(pre.covariance)
    jt_w = np.swapaxes(pre.calibration_jacobian, 1, 2) @ w
    info = np.einsum("kij,kjl->il", jt_w, pre.calibration_jacobian)
    cov = np.linalg.inv(info)
    return pre.calibration + cov @ np.einsum("kij,kj->i", jt_w, r), cov
