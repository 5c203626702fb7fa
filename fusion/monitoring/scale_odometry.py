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

References
----------
Larsen, T. D., Bak, M., Andersen, N. A., Ravn, O. (1998). Location
estimation for an autonomously guided vehicle using an augmented Kalman
filter to autocalibrate the odometry. FUSION 1998.
Thrun, S., Burgard, W., Fox, D. (2005). Probabilistic Robotics, table 7.2.
Bar-Shalom, Y., Li, X. R., Kirubarajan, T. (2001). Estimation with
Applications to Tracking and Navigation, eq. 5.2.3-18.
"""

from __future__ import annotations

import numpy as np

from fusion.noise import LandmarkNoise, SlipNoise
from fusion.range_bearing import range_bearing_terms
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import pose_step_terms, wrap_angle

__all__ = [
    "KAPPA",
    "KV",
    "KW",
    "N_STATE",
    "landmark_update",
    "odometry_predict",
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
    pred, H = range_bearing_batch(x, landmark_xy, sensor=sensor)
    nu = range_bearing - pred
    nu[:, 1] = wrap_angle(nu[:, 1])
    R = np.zeros((len(x), 2, 2))
    R[:, 0, 0] = np.maximum(noise.range_std_m, noise.range_std_frac * pred[:, 0]) ** 2
    R[:, 1, 1] = noise.bearing_std_rad ** 2                       # LandmarkNoise.cov
    if cov is not None:
        own = ~np.isnan(cov[:, 0, 0])
        R[own] = cov[own]
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
