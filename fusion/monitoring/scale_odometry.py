"""Landmark-aided encoder odometry with scale states, as pure functions batched over filters.

The filter of :mod:`fusion.monitoring.scale`: per row ``i`` of a batch (robots,
and alternative hypotheses of the same robot) an extended Kalman filter with
state::

    x = (x, y, theta, k_v, k_w, kappa)

the pose (m, m, rad; heading continuous), the relative scale errors of the
ground travel and turn against the encoders' (odometry auto-calibration,
Larsen et al. 1998; the scale states of :mod:`fusion.ekf.functions`) and the
curvature ``kappa`` [rad/m] a straight run of equal counts drives (one wheel's
scale against the other's: :mod:`lti_motion.intrinsics`, "Scale errors"). One
period with count changes ``(d_l, d_r)`` [ticks], converted by the odometry
intrinsics in use (``J`` of :meth:`~lti_motion.intrinsics.OdometryIntrinsics.jacobian`)::

    (ds, dtheta) = J (d_l, d_r)
    g = ((1 + k_v) ds, (1 + k_w) dtheta + kappa ds) + eta                   (eq. 1)
    pose' = pose_step(pose, g)                                             (paper eq. 11)
    k' = k + w,  w ~ N(0, diag(q_c))

(eq. 1 is the intrinsics module's ``(ds_g, dtheta_g)`` with the second-order
``kappa b' b dtheta / 4`` term of the travel dropped: 0.3 mm per radian turned
at a 0.5% wheel ratio.) ``eta`` is the slip noise
(:class:`~fusion.ekf.functions.SlipNoise`, per period). With ``F_p``, ``F_s`` the
Jacobians of the pose step with respect to the pose and to ``g``
(:func:`lti_motion.kinematics.pose_step_jacobians`) and ``F_s = (f_v, f_w)`` by column::

    F = [[F_p, f_v ds, f_w dtheta, f_w ds],     Q = [[F_s diag(sigma^2) F_s^T, 0],
         [0,   I                          ]]          [0,                       diag(q_c)]]

Landmark sightings ``(r, b)`` update the pose with the range-bearing model
from the sensor's mount on the robot (:func:`fusion.range_bearing.range_bearing_terms`,
eq. 1-2, the EKFs' one copy; Thrun, Burgard & Fox 2005, table 7.2), gated on
the NIS, in Joseph form (Bar-Shalom et al. 2001, eq. 5.2.3-18), with each
sighting's own covariance or the sensor's :class:`~fusion.noise.LandmarkNoise`
at the predicted range.

:func:`odometry_predict` and :func:`landmark_update` are the numpy
references; :func:`odometry_predict_into` and :func:`landmark_update_compiled`
evaluate the same expressions compiled (numba, row by row, as
:mod:`fusion.ekf.kernel`; the measurement model and the innovations stay
:func:`landmark_update`'s own): :class:`~fusion.monitoring.ScaleMonitor`
runs them every period, and numpy's per-call overhead on a few small arrays
cost many times the arithmetic. They agree with the references to rounding
(sums in another order, covariances computed on their lower triangle and
mirrored, ``S`` inverted in closed form; ``tests/fusion/monitoring/test_scale.py``).

References
----------
The paper: ``docs/architecture.md``, "The paper".
Larsen, T. D., Bak, M., Andersen, N. A., Ravn, O. (1998). Location
estimation for an autonomously guided vehicle using an augmented Kalman
filter to autocalibrate the odometry. FUSION 1998.
Thrun, S., Burgard, W., Fox, D. (2005). Probabilistic Robotics, table 7.2.
Bar-Shalom, Y., Li, X. R., Kirubarajan, T. (2001). Estimation with
Applications to Tracking and Navigation, eq. 5.2.3-18.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from fusion.exceptions import MeasurementShapeError
from fusion.noise import LandmarkNoise, SlipNoise
from fusion.range_bearing import range_bearing_terms
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import _DSINC_SERIES, _SERIES_BELOW, pose_step_terms, wrap_angle

__all__ = [
    "KAPPA",
    "KV",
    "KW",
    "N_STATE",
    "landmark_update",
    "landmark_update_compiled",
    "odometry_predict",
    "odometry_predict_into",
    "range_bearing_batch",
]

#: State indices of the scale errors ``k_v`` (travel), ``k_w`` (turn) and the
#: curvature error ``kappa`` [rad/m]; the state's length.
KV, KW, KAPPA, N_STATE = 3, 4, 5, 6


def odometry_predict(x: np.ndarray, P: np.ndarray, tick_deltas: np.ndarray, *,
                     intrinsics: OdometryIntrinsics, dt_s: float, slip: SlipNoise,
                     walk_var: np.ndarray, missing_std: tuple[float, float]
                     ) -> tuple[np.ndarray, np.ndarray]:
    """One period of encoder travel for every row (module eq. 1, paper eq. 11).

    Parameters
    ----------
    x : ndarray, shape (n, 6)
        States.
    P : ndarray, shape (n, 6, 6)
        Covariances.
    tick_deltas : ndarray, shape (n, 2)
        Count changes of (left, right) [ticks]; a row with NaN is a period of
        unknown travel: no motion, with speed noise ``missing_std``.
    intrinsics : OdometryIntrinsics
        Each wheel's scale [m/tick] and the wheel base [m] the counts are converted with.
    dt_s : float
        Period [s].
    slip : SlipNoise
        Ground-versus-encoder speed noise.
    walk_var : ndarray, shape (3,)
        Random-walk variances of ``(k_v, k_w, kappa)`` per period.
    missing_std : tuple of 2 float
        Speed and turn-rate standard deviations of a missing period [m/s, rad/s].

    Returns
    -------
    x, P : ndarray
        The predicted states and covariances (new arrays).
    """
    missing = ~np.isfinite(tick_deltas).all(axis=1)
    d = np.where(missing[:, None], 0.0, tick_deltas)
    ds, dth = intrinsics.body_motion(d).T                         # [m], [rad]
    gs, gth = (1.0 + x[:, KV]) * ds, (1.0 + x[:, KW]) * dth + x[:, KAPPA] * ds   # eq. 1
    pose_next, f_pose, f_speed = pose_step_terms(x[:, :3], gs, gth, 1.0)
    x_new = x.copy()
    x_new[:, :3] = pose_next
    F = np.zeros_like(P)
    F[:, :3, :3] = f_pose
    F[:, :3, KV] = f_speed[:, :, 0] * ds[:, None]                 # d pose / d k_v
    F[:, :3, KW] = f_speed[:, :, 1] * dth[:, None]
    F[:, :3, KAPPA] = f_speed[:, :, 1] * ds[:, None]
    F[:, KV, KV] = F[:, KW, KW] = F[:, KAPPA, KAPPA] = 1.0
    sv, sw = slip.stds(ds / dt_s, dth / dt_s)                     # [m/s], [rad/s]
    sv = np.where(missing, missing_std[0], sv) * dt_s
    sw = np.where(missing, missing_std[1], sw) * dt_s
    f_noise = f_speed * np.stack([sv, sw], axis=1)[:, None, :]
    P_new = F @ P @ F.transpose(0, 2, 1)
    P_new[:, :3, :3] += f_noise @ f_noise.transpose(0, 2, 1)
    P_new[:, KV, KV] += walk_var[0]
    P_new[:, KW, KW] += walk_var[1]
    P_new[:, KAPPA, KAPPA] += walk_var[2]
    return x_new, 0.5 * (P_new + P_new.transpose(0, 2, 1))


def odometry_predict_into(x: np.ndarray, P: np.ndarray, tick_deltas: np.ndarray,
                          x_out: np.ndarray, P_out: np.ndarray, *,
                          intrinsics: OdometryIntrinsics, dt_s: float, slip: SlipNoise,
                          walk_var: np.ndarray, missing_std: tuple[float, float]) -> None:
    """:func:`odometry_predict`, compiled, written into ``x_out`` and ``P_out``.

    Parameters
    ----------
    x, P
        As :func:`odometry_predict`: C-contiguous float64 arrays, shapes
        (n, 6) and (n, 6, 6).
    tick_deltas : ndarray, shape (m, 2)
        Count changes as :func:`odometry_predict`'s, C-contiguous float64, for
        a batch in blocks of ``m`` rows (``n`` a multiple of ``m``): row ``r``
        takes row ``r % m`` (a robot's shadows share its counts; ``m = n``:
        one per row).
    x_out, P_out : ndarray, shapes (n, 6) and (n, 6, 6)
        C-contiguous float64 buffers that receive the predicted states and
        covariances (not ``x`` or ``P`` themselves).
    intrinsics, dt_s, slip, walk_var, missing_std
        As :func:`odometry_predict`.

    Raises
    ------
    MeasurementShapeError
        If ``tick_deltas`` is not (m, 2) with ``m`` dividing the batch.

    Notes
    -----
    Equal to :func:`odometry_predict` (of the deltas repeated to ``n`` rows) to
    rounding (module notes).
    """
    m = len(tick_deltas)
    if tick_deltas.ndim != 2 or tick_deltas.shape[1] != 2 or m == 0 or len(x) % m:
        raise MeasurementShapeError(f"expected tick deltas (m, 2) with m dividing the {len(x)} "
                                    f"rows, got {tick_deltas.shape}")
    constants = np.array((dt_s, slip.v_floor_m_s, slip.v_frac, slip.w_floor_rad_s, slip.w_frac,
                          slip.w_per_v_rad_m, missing_std[0], missing_std[1], *walk_var))
    _predict_kernel(x, P, tick_deltas, intrinsics.jacobian(), constants, x_out, P_out)


@njit(cache=True)
def _sinc_terms(h):
    """``sin(h) / h`` as ``np.sinc(h / pi)`` evaluates it, and its derivative as
    :func:`lti_motion.kinematics._sinc_half_derivative` (series below ``|h| = 0.25``)."""
    y = math.pi * (h * (1.0 / math.pi))
    value = math.sin(y) / y if y != 0.0 else 1.0
    if abs(h) < _SERIES_BELOW:
        series = 0.0
        for i in range(len(_DSINC_SERIES) - 1, -1, -1):
            series = series * (h * h) + _DSINC_SERIES[i]
        return value, series * h
    return value, (h * math.cos(h) - math.sin(h)) / (h * h)


@njit(cache=True)
def _predict_kernel(x, P, tick_deltas, J, constants, x_out, P_out):
    """Rows of :func:`odometry_predict`: eq. 1, paper eq. 11 (chord form), ``F``, ``Q``,
    ``F P F^T + Q`` on the lower triangle, mirrored. ``constants``: ``dt_s``, the
    :class:`~fusion.noise.SlipNoise` figures, ``missing_std``, ``walk_var``."""
    dt = constants[0]
    F = np.zeros((N_STATE, N_STATE))
    fp = np.empty((N_STATE, N_STATE))
    n_deltas = tick_deltas.shape[0]
    for r in range(x.shape[0]):
        d0, d1 = tick_deltas[r % n_deltas, 0], tick_deltas[r % n_deltas, 1]
        missing = not (math.isfinite(d0) and math.isfinite(d1))
        if missing:
            d0, d1 = 0.0, 0.0
        ds, dth = d0 * J[0, 0] + d1 * J[0, 1], d0 * J[1, 0] + d1 * J[1, 1]   # [m], [rad]
        gs = (1.0 + x[r, KV]) * ds                                       # eq. 1
        gth = (1.0 + x[r, KW]) * dth + x[r, KAPPA] * ds
        half = 0.5 * gth
        s, dsinc = _sinc_terms(half)
        mid = x[r, 2] + half
        cm, sm = math.cos(mid), math.sin(mid)
        chord = gs * s
        x_out[r, 0] = x[r, 0] + chord * cm                               # paper eq. 11
        x_out[r, 1] = x[r, 1] + chord * sm
        x_out[r, 2] = x[r, 2] + gth
        for i in range(3, N_STATE):
            x_out[r, i] = x[r, i]
        k = 0.5 * gs
        fv0, fv1 = s * cm, s * sm                                        # F_s = (f_v, f_w)
        fw0, fw1 = k * (dsinc * cm - s * sm), k * (dsinc * sm + s * cm)
        F[0, 0], F[0, 2], F[1, 1], F[1, 2], F[2, 2] = 1.0, -chord * sm, 1.0, chord * cm, 1.0
        F[0, KV], F[0, KW], F[0, KAPPA] = fv0 * ds, fw0 * dth, fw0 * ds
        F[1, KV], F[1, KW], F[1, KAPPA] = fv1 * ds, fw1 * dth, fw1 * ds
        F[2, KW], F[2, KAPPA] = dth, ds
        F[KV, KV] = F[KW, KW] = F[KAPPA, KAPPA] = 1.0
        av = abs(ds / dt)                                                # SlipNoise.stds
        sv = constants[1] + constants[2] * av
        sw = constants[3] + constants[4] * abs(dth / dt) + constants[5] * av
        if missing:
            sv, sw = constants[6], constants[7]
        sv, sw = sv * dt, sw * dt
        g = ((fv0 * sv, fw0 * sw), (fv1 * sv, fw1 * sw), (0.0, sw))      # F_s diag(sigma)
        for i in range(N_STATE):                                         # F P
            for j in range(N_STATE):
                acc = 0.0
                for m in range(N_STATE):
                    f = F[i, m]
                    if f != 0.0:
                        acc += f * P[r, m, j]
                fp[i, j] = acc
        for i in range(N_STATE):                          # F (F P)^T + Q, lower triangle
            for j in range(i + 1):
                acc = 0.0
                for m in range(N_STATE):
                    f = F[i, m]
                    if f != 0.0:
                        acc += f * fp[j, m]
                if i < 3:
                    acc += g[i][0] * g[j][0] + g[i][1] * g[j][1]
                elif i == j:
                    acc += constants[5 + i]                              # walk_var
                P_out[r, i, j] = acc
                P_out[r, j, i] = acc


def range_bearing_batch(x: np.ndarray, landmark_xy: np.ndarray, *,
                        sensor: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~fusion.range_bearing.range_bearing_terms` on the states, batched over rows.

    Parameters
    ----------
    x : ndarray, shape (n, >= 3)
        States, the pose first.
    landmark_xy : ndarray, shape (n, 2)
        Landmark of each row [m].
    sensor : ndarray, shape (n, 3) or (3,), optional
        Each row's sensor mount ``(x_m, y_m, yaw_rad)`` on the robot, or one
        for all (:class:`fusion.sensor_pose.SensorPose` too); default centred.

    Returns
    -------
    pred : ndarray, shape (n, 2)
        ``(r [m], b [rad])``, ``b`` wrapped.
    H : ndarray, shape (n, 2, 6)
        Pose columns: :mod:`fusion.range_bearing` eq. 2 (for a centred
        sensor ``[[-dx/r, -dy/r, 0], [dy/r^2, -dx/r^2, -1]]``, Thrun et al.
        2005, table 7.2), zeros for the scales. Ranges are floored at
        :data:`~fusion.range_bearing.MIN_RANGE_M`.

    Examples
    --------
    >>> pred, H = range_bearing_batch(np.zeros((1, 6)), np.array([[2.0, 0.0]]))
    >>> (pred.round(12) + 0.0).tolist(), (H[0, :, :3].round(12) + 0.0).tolist()
    ([[2.0, 0.0]], [[-1.0, 0.0, 0.0], [0.0, -0.5, -1.0]])
    """
    pred, h_pose, _ = range_bearing_terms(x[:, :3], landmark_xy, sensor=sensor)
    H = np.zeros((len(x), 2, N_STATE))
    H[:, :, :3] = h_pose
    return pred, H


def landmark_update(x: np.ndarray, P: np.ndarray, landmark_xy: np.ndarray,
                    range_bearing: np.ndarray, noise: LandmarkNoise, gate: float, *,
                    cov: np.ndarray | None = None, sensor: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Range-bearing updates of every row, gated on the NIS, Joseph form.

    Parameters
    ----------
    x, P : ndarray, shapes (n, 6) and (n, 6, 6)
        States and covariances.
    landmark_xy : ndarray, shape (n, 2)
        The sighted landmark of each row [m].
    range_bearing : ndarray, shape (n, 2)
        Sightings ``(r [m], b [rad])``.
    noise : LandmarkNoise
        The sensor's noise, at each row's predicted range.
    gate : float
        NIS gate: rows with ``nu^T S^-1 nu`` above it are not fused.
    cov : ndarray, shape (n, 2, 2), optional
        A sighting's own full covariance of ``(r [m], b [rad])`` per row,
        replacing ``noise``; rows of NaN take ``noise``.
    sensor : ndarray, shape (n, 3) or (3,), optional
        The sensor's mount ``(x_m, y_m, yaw_rad)`` per row or for all
        (:func:`range_bearing_batch`); default centred.

    Returns
    -------
    x, P : ndarray
        Updated states and covariances (new arrays; gated rows unchanged).
    accepted : ndarray of bool, shape (n,)
    log_likelihood : ndarray, shape (n,)
        ``-0.5 (min(nis, gate) + ln det S)``: ``ln N(nu; 0, S)`` without the
        ``2 pi`` constant, the NIS clipped at the gate.
    """
    nu, H, R = _innovations(x, landmark_xy, range_bearing, noise, cov, sensor)
    PHt = P @ H.transpose(0, 2, 1)
    S = H @ PHt + R
    Si = np.linalg.inv(S)
    nis = np.einsum("ni,nij,nj->n", nu, Si, nu)
    ok = nis <= gate
    K = PHt @ Si
    IKH = np.eye(N_STATE) - K @ H
    P_post = IKH @ P @ IKH.transpose(0, 2, 1) + K @ R @ K.transpose(0, 2, 1)  # eq. 5.2.3-18
    x_new, P_new = x.copy(), P.copy()
    x_new[ok] = x[ok] + np.einsum("nij,nj->ni", K[ok], nu[ok])
    P_new[ok] = 0.5 * (P_post[ok] + P_post[ok].transpose(0, 2, 1))
    return x_new, P_new, ok, -0.5 * (np.minimum(nis, gate) + np.linalg.slogdet(S)[1])


def landmark_update_compiled(x: np.ndarray, P: np.ndarray, landmark_xy: np.ndarray,
                             range_bearing: np.ndarray, noise: LandmarkNoise, gate: float, *,
                             cov: np.ndarray | None = None, sensor: np.ndarray | None = None
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`landmark_update` with the update itself compiled (numba, row by row).

    The measurement model, the innovations and ``R`` are :func:`landmark_update`'s
    own; ``S``, its closed-form 2 x 2 inverse and ``ln det S``, the gain and the
    Joseph form (Bar-Shalom et al. 2001, eq. 5.2.3-18, by associativity as
    :func:`fusion.ekf.selector_update_kernel`) run compiled. Parameters
    and returns as :func:`landmark_update`, to which it is equal to rounding.
    """
    nu, H, R = _innovations(x, landmark_xy, range_bearing, noise, cov, sensor)
    x_new, P_new = np.empty_like(x), np.empty_like(P)
    ok, ll = np.empty(len(x), dtype=bool), np.empty(len(x))
    _update_kernel(np.ascontiguousarray(x), np.ascontiguousarray(P), np.ascontiguousarray(H),
                   nu, R, float(gate), x_new, P_new, ok, ll)
    return x_new, P_new, ok, ll


def _innovations(x: np.ndarray, landmark_xy: np.ndarray, range_bearing: np.ndarray,
                 noise: LandmarkNoise, cov: np.ndarray | None, sensor: np.ndarray | None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The innovations ``nu`` (n, 2) (bearing wrapped), ``H`` (n, 2, 6) and ``R`` (n, 2, 2)
    of :func:`landmark_update`."""
    pred, H = range_bearing_batch(x, landmark_xy, sensor=sensor)
    nu = range_bearing - pred
    nu[:, 1] = wrap_angle(nu[:, 1])
    R = np.zeros((len(x), 2, 2))
    R[:, 0, 0] = np.maximum(noise.range_std_m, noise.range_std_frac * pred[:, 0]) ** 2
    R[:, 1, 1] = noise.bearing_std_rad ** 2                       # LandmarkNoise.cov
    if cov is not None:
        own = ~np.isnan(cov[:, 0, 0])
        R[own] = cov[own]
    return nu, H, R


@njit(cache=True)
def _update_kernel(x, P, H, nu, R, gate, x_out, P_out, ok, ll):
    """Rows of :func:`landmark_update` from ``nu``, ``H``, ``R``: writes the outputs."""
    n = x.shape[1]
    pht, K, mh, kr = np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 2))
    hph = np.empty((2, 2))
    for r in range(x.shape[0]):
        for i in range(n):                                  # P H^T
            for a in range(2):
                acc = 0.0
                for j in range(n):
                    acc += P[r, i, j] * H[r, a, j]
                pht[i, a] = acc
        for a in range(2):                                  # H P H^T
            for b in range(2):
                acc = 0.0
                for j in range(n):
                    acc += H[r, a, j] * pht[j, b]
                hph[a, b] = acc
        s00, s01 = hph[0, 0] + R[r, 0, 0], hph[0, 1] + R[r, 0, 1]     # S (eq. 5.2.3-9)
        s10, s11 = hph[1, 0] + R[r, 1, 0], hph[1, 1] + R[r, 1, 1]
        det = s00 * s11 - s01 * s10
        f = 1.0 / det                                       # closed-form 2 x 2 inverse
        si00, si01, si10, si11 = s11 * f, -s01 * f, -s10 * f, s00 * f
        n0, n1 = nu[r, 0], nu[r, 1]
        nis = si00 * n0 * n0 + (si01 + si10) * n0 * n1 + si11 * n1 * n1
        ll[r] = -0.5 * (min(nis, gate) + math.log(abs(det)))
        ok[r] = nis <= gate
        if not ok[r]:                                       # gated: the row as it was
            for i in range(n):
                x_out[r, i] = x[r, i]
                for j in range(n):
                    P_out[r, i, j] = P[r, i, j]
            continue
        for i in range(n):                      # K = P H^T S^-1, x + K nu, M H^T, K R
            k0 = pht[i, 0] * si00 + pht[i, 1] * si10
            k1 = pht[i, 0] * si01 + pht[i, 1] * si11
            K[i, 0], K[i, 1] = k0, k1
            x_out[r, i] = x[r, i] + (k0 * n0 + k1 * n1)
            mh[i, 0] = pht[i, 0] - (k0 * hph[0, 0] + k1 * hph[1, 0])
            mh[i, 1] = pht[i, 1] - (k0 * hph[0, 1] + k1 * hph[1, 1])
            kr[i, 0] = k0 * R[r, 0, 0] + k1 * R[r, 1, 0]
            kr[i, 1] = k0 * R[r, 0, 1] + k1 * R[r, 1, 1]
        for i in range(n):              # M - (M H^T) K^T + (K R) K^T (5.2.3-18), with
            for j in range(i + 1):      # M = P - K (P H^T)^T; symmetric: lower triangle
                mij = P[r, i, j] - (K[i, 0] * pht[j, 0] + K[i, 1] * pht[j, 1])
                v = ((mij - (mh[i, 0] * K[j, 0] + mh[i, 1] * K[j, 1]))
                     + (kr[i, 0] * K[j, 0] + kr[i, 1] * K[j, 1]))
                P_out[r, i, j] = v
                P_out[r, j, i] = v
