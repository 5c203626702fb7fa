"""GTSAM factors for a preintegrated motion model, its calibration, and landmarks.

- :func:`motion_factor`: the plain factor, a native ``gtsam.BetweenFactorPose2``
  with the preintegrated relative pose and covariance
  (:mod:`fusion.graph.preintegration`): no Python runs at optimisation time.
- :func:`calibrated_motion_factor` and :func:`calibrated_motion_group_factor`
  (from :mod:`fusion.graph.calibrated_factors`, re-exported): ``gtsam.CustomFactor``
  on (poses, calibration ``c = (s, g)`` or ``(s, g, kappa)``) that correct the preintegrated pose to
  first order in ``c``, as IMU preintegration corrects for the bias (Forster et
  al. 2017, eq. 44), so a smoother with landmarks estimates the calibration
  online. :func:`calibration_walk_factor` lets ``c`` drift.
- :func:`range_bearing_factors`: one factor per row of a
  :class:`fusion.range_bearing.RangeBearing` (the package's one observation
  type, the EKFs' too; ``index`` = keyframe), each with a full Gaussian noise
  model from the row's 2 x 2 covariance (or the sensor's
  :class:`fusion.noise.LandmarkNoise` at the measured range), to a landmark
  variable (known landmarks carry a prior, or a tight one for a constant).
  A sensor at the axle centre gets the native ``gtsam.BearingRangeFactor2D``;
  a sensor mounted elsewhere (the sightings' ``sensor_pose``) a
  ``gtsam.CustomFactor`` (:func:`mounted_range_bearing_factor`) around the
  package's one measurement model,
  :func:`fusion.range_bearing.range_bearing_terms`: gtsam's Python API has
  no bearing-range factor with a body-to-sensor transform (only
  ``RangeFactorWithTransform2D``, range alone).
  The map is :class:`fusion.landmark_map.LandmarkMap`;
  :func:`predict_range_bearing` is the measurement model and
  :func:`observe_landmarks` a simulator of observations for experiments.

Variables: poses ``X(i)`` (``gtsam.Pose2``, ``wTb``: body in world), calibrations
``C(i)`` (``Point2`` holding ``(s, g)`` around ``(1, 1)``, or ``Point3`` holding
``(s, g, kappa)`` around ``(1, 1, 0)``), landmarks ``L(id)``
(``Point2`` in the world frame).

Range-bearing noise: gtsam's ``BearingRange`` measurement, and so its error
and noise model, is ordered ``(bearing, range)``, the reverse of the
package's ``z = (r, b)``; :func:`range_bearing_factors` reorders each
covariance. A diagonal one becomes ``noiseModel.Diagonal.Sigmas``; any other
``noiseModel.Gaussian.Covariance(cov, smart=False)``: the smart default takes
a covariance whose off-diagonal entries are below 1e-9 in absolute value for
diagonal (gtsam ``checkIfDiagonal``, ``linear/NoiseModel.cpp``), which would
drop the range-bearing correlation of a precise sensor (ArUco covariances are
about 1e-8).

Mounted-sensor Jacobians: gtsam perturbs a ``Pose2`` in its body frame,
``wTb Exp(xi)``, whose position moves by ``R(theta) xi_xy`` and heading by
``xi_theta`` at ``xi = 0``; the factor's pose Jacobian is eq. 2 of
:mod:`fusion.range_bearing` times ``blkdiag(R(theta), 1)``, the landmark's
eq. 3 (a ``Point2`` moves in the world frame); rows in gtsam's ``(bearing,
range)`` order.

References
----------
C. Forster, L. Carlone, F. Dellaert, D. Scaramuzza, "On-Manifold
Preintegration for Real-Time Visual-Inertial Odometry", IEEE Trans. Robotics
33(1), 2017, eq. 44-45 (first-order bias update of preintegrated measurements).
"""

from __future__ import annotations

import gtsam
import numpy as np
from gtsam.symbol_shorthand import C, L, X

from fusion.exceptions import LandmarkIdError, MeasurementShapeError
from fusion.graph.calibrated_factors import (
    calibrated_motion_error,
    calibrated_motion_factor,
    calibrated_motion_group_factor,
)
from fusion.graph.preintegration import Preintegrated
from fusion.landmark_map import LandmarkMap
from fusion.noise import LandmarkNoise
from fusion.range_bearing import RangeBearing, range_bearing, range_bearing_terms
from fusion.range_bearing import _wrap as _wrap_scalar
from fusion.sensor_pose import CENTRED, SensorPose, as_sensor_pose
from lti_motion.kinematics import wrap_angle

__all__ = [
    "CONSTANT_SIGMA_M",
    "calibrated_motion_error",
    "calibrated_motion_factor",
    "calibrated_motion_group_factor",
    "calibration_key",
    "calibration_walk_factor",
    "landmark_key",
    "motion_factor",
    "mounted_range_bearing_factor",
    "observe_landmarks",
    "pose_key",
    "predict_range_bearing",
    "range_bearing_factors",
]

#: Prior standard deviation [m] that stands for "constant" on a known landmark:
#: far below any measurement noise, yet a proper Gaussian, so iSAM2's Cholesky
#: factorisation stays well posed (a hard ``NonlinearEquality`` would not).
CONSTANT_SIGMA_M = 1e-6


def pose_key(i: int) -> int:
    """GTSAM key of keyframe pose ``i`` (``X(i)``)."""
    return X(int(i))


def calibration_key(i: int) -> int:
    """GTSAM key ``C(i)`` of the calibration ``(s, g)`` or ``(s, g, kappa)`` from keyframe ``i``."""
    return C(int(i))


def landmark_key(landmark_id: int) -> int:
    """GTSAM key of landmark ``landmark_id`` (``L(id)``)."""
    return L(int(landmark_id))


def motion_factor(pre: Preintegrated, k: int, *, key_i: int, key_j: int
                  ) -> gtsam.BetweenFactorPose2:
    """The plain preintegrated motion factor of interval ``k``: a native between-factor.

    Parameters
    ----------
    pre : Preintegrated
        Preintegrated intervals.
    k : int
        Which interval.
    key_i, key_j : int
        Keys of the poses at its start and end.

    Returns
    -------
    gtsam.BetweenFactorPose2
        Measured ``iTj = pre.delta_pose[k]``, Gaussian noise ``pre.covariance[k]``
        (gtsam's error ``Log(iTj^-1 wTi^-1 wTj)`` is in the same coordinates).
    """
    dx, dy, dth = pre.delta_pose[k]
    return gtsam.BetweenFactorPose2(key_i, key_j, gtsam.Pose2(dx, dy, dth),
                                    gtsam.noiseModel.Gaussian.Covariance(pre.covariance[k]))


def calibration_walk_factor(key_a: int, key_b: int, *, sigma_per_sqrt_s: np.ndarray,
                            duration_s: float
                            ) -> gtsam.BetweenFactorPoint2 | gtsam.BetweenFactorPoint3:
    """Random walk of the calibration between two keyframes.

    Parameters
    ----------
    key_a, key_b : int
        Calibration keys of consecutive keyframes.
    sigma_per_sqrt_s : array_like, shape (2,) or (3,)
        Diffusion of ``(s, g)`` [1/sqrt(s)], or of ``(s, g, kappa)``
        [1/sqrt(s), 1/sqrt(s), rad/m/sqrt(s)].
    duration_s : float
        Time between the keyframes [s].

    Returns
    -------
    gtsam.BetweenFactorPoint2 or gtsam.BetweenFactorPoint3
        ``c_b - c_a ~ N(0, diag(sigma^2) duration_s)``, on ``Point2`` or ``Point3``
        variables as ``sigma_per_sqrt_s`` has 2 or 3 entries.
    """
    sig = np.asarray(sigma_per_sqrt_s, dtype=float).reshape(-1) * np.sqrt(float(duration_s))
    between = gtsam.BetweenFactorPoint2 if len(sig) == 2 else gtsam.BetweenFactorPoint3
    return between(key_a, key_b, np.zeros(len(sig)), gtsam.noiseModel.Diagonal.Sigmas(sig))


def predict_range_bearing(wTb: np.ndarray, points_xy: np.ndarray, *,
                          sensor_pose: SensorPose | None = None
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Bearing and range of world points seen from body poses (the measurement model).

    Parameters
    ----------
    wTb : array_like, shape (..., 3)
        Poses ``(x [m], y [m], theta [rad])``.
    points_xy : array_like, shape (..., 2)
        World points [m], broadcast against the poses.
    sensor_pose : SensorPose, optional
        The sensor's mount on the robot (default centred).

    Returns
    -------
    bearing_rad, range_m : ndarray, shape (...)
        ``atan2`` of the point in the sensor frame, wrapped to (-pi, pi], and
        distance from the sensor: :func:`fusion.range_bearing.range_bearing`
        in gtsam's order.

    Examples
    --------
    >>> b, r = predict_range_bearing(np.array([0.0, 0.0, np.pi / 2]), np.array([0.0, 2.0]))
    >>> round(float(b), 12) + 0.0, round(float(r), 12)
    (0.0, 2.0)
    """
    z = range_bearing(wTb, points_xy, sensor=sensor_pose)
    return z[..., 1], z[..., 0]


def observe_landmarks(wTb: np.ndarray, landmarks: LandmarkMap, *, rng: np.random.Generator,
                      bearing_sigma_rad: float, range_sigma_m: float, max_range_m: float,
                      min_range_m: float = 0.2, field_of_view_rad: float = 2 * np.pi,
                      index: np.ndarray | None = None,
                      sensor_pose: SensorPose | None = None) -> RangeBearing:
    """Simulate range-bearing observations of a map from true poses.

    Parameters
    ----------
    wTb : array_like, shape (n, 3)
        True poses the robot observes from.
    landmarks : fusion.landmark_map.LandmarkMap
        The true landmark positions (integer ids).
    rng : numpy.random.Generator
        Source of the measurement noise (seed it).
    bearing_sigma_rad, range_sigma_m : float
        Standard deviations of the Gaussian noise added.
    max_range_m, min_range_m : float
        Landmarks further away, or closer (a camera cannot focus on, or
        fit in view, a marker under its nose), are not seen [m].
    field_of_view_rad : float
        Full angular width of the sensor, centred on the heading.
    index : array_like of int, shape (n,), optional
        Index recorded for each pose (default ``0 .. n-1``).
    sensor_pose : SensorPose, optional
        The sensor's mount on the robot (default centred): ranges, bearings
        and the field of view are the sensor's.

    Returns
    -------
    RangeBearing
        Every (pose, landmark) pair in view, ordered by pose, each with the
        covariance the noise was drawn with, ``diag(range_sigma_m^2,
        bearing_sigma_rad^2)``, and the sensor's mount.

    Raises
    ------
    MeasurementShapeError
        If ``index`` does not have one entry per pose.
    LandmarkIdError
        If a landmark id is not an integer (the graph keys them as ``L(id)``).
    """
    poses = np.asarray(wTb, dtype=float).reshape(-1, 3)
    idx = np.arange(len(poses)) if index is None else np.asarray(index).reshape(-1)
    if idx.shape != (len(poses),):
        raise MeasurementShapeError(f"index has shape {idx.shape}, expected ({len(poses)},)")
    ids = landmarks.integer_ids                      # raises for non-integer ids
    mount = as_sensor_pose(sensor_pose)
    bearing, rng_m = predict_range_bearing(poses[:, None, :], landmarks.xy_m[None, :, :],
                                           sensor_pose=mount)
    seen = ((rng_m <= max_range_m) & (rng_m >= min_range_m)
            & (np.abs(bearing) <= 0.5 * field_of_view_rad))
    rows, cols = np.nonzero(seen)
    noisy_b = wrap_angle(bearing[rows, cols] + bearing_sigma_rad * rng.standard_normal(rows.size))
    noisy_r = np.abs(rng_m[rows, cols] + range_sigma_m * rng.standard_normal(rows.size))
    cov = np.diag([range_sigma_m ** 2, bearing_sigma_rad ** 2])
    return RangeBearing(idx[rows], ids[cols], noisy_r, noisy_b,
                        cov=np.broadcast_to(cov, (rows.size, 2, 2)), sensor_pose=mount)


def _integer_ids(observations: RangeBearing) -> np.ndarray:
    """The ids as ``int64``, as gtsam keys landmarks (``L(id)``); :class:`LandmarkIdError` else."""
    ids = observations.landmark_id
    if ids.dtype != np.int64:
        bad = [i for i in ids.tolist()
               if isinstance(i, bool) or not isinstance(i, (int, np.integer))]
        raise LandmarkIdError(f"the factor graph keys landmarks by integer id (gtsam L(id)); "
                              f"got {bad[:5]!r}; number the landmarks first")
    return ids


def _noise_model(cov: np.ndarray, huber_k: float | None) -> gtsam.noiseModel.Base:
    """gtsam noise of one ``(range, bearing)`` covariance, reordered to gtsam's
    ``(bearing, range)``: ``Diagonal.Sigmas`` if diagonal, else a full ``Gaussian`` (module
    notes: never gtsam's smart diagonal test), in a Huber kernel if ``huber_k``."""
    br = np.asarray(cov, dtype=float)[::-1, ::-1]
    if br[0, 1] == 0.0 and br[1, 0] == 0.0:
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.sqrt(np.diag(br)))
    else:
        noise = gtsam.noiseModel.Gaussian.Covariance(np.ascontiguousarray(br), False)
    if huber_k is not None:
        noise = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(huber_k),
                                               noise)
    return noise


def mounted_range_bearing_factor(key_pose: int, key_landmark: int, range_m: float,
                                 bearing_rad: float, *, sensor_pose: SensorPose,
                                 noise: gtsam.noiseModel.Base) -> gtsam.CustomFactor:
    """A range-bearing factor from a sensor mounted off the axle centre (a ``CustomFactor``).

    Parameters
    ----------
    key_pose, key_landmark : int
        Keys of the robot pose (``Pose2``, axle centre) and the landmark (``Point2``).
    range_m, bearing_rad : float
        The sighting, from the sensor, in its frame.
    sensor_pose : SensorPose
        The sensor's mount on the robot.
    noise : gtsam.noiseModel.Base
        Noise of the error, ordered ``(bearing, range)`` as gtsam's own
        factor's (:func:`range_bearing_factors` builds it from a covariance).

    Returns
    -------
    gtsam.CustomFactor
        Unwhitened error ``(wrap(b_hat - b), r_hat - r)`` with ``(r_hat,
        b_hat)`` from :func:`fusion.range_bearing.range_bearing_terms` and
        its Jacobians in gtsam's tangent spaces (module notes); for a centred
        mount it equals ``gtsam.BearingRangeFactor2D``'s error.
    """
    mount = as_sensor_pose(sensor_pose)
    bearing, range_ = float(bearing_rad), float(range_m)
    key_pose, key_landmark = int(key_pose), int(key_landmark)

    def error(_: gtsam.CustomFactor, values: gtsam.Values,
              jacobians: list[np.ndarray] | None) -> np.ndarray:
        p = values.atPose2(key_pose)
        theta = p.theta()
        z, h_pose, h_landmark = range_bearing_terms(np.array([p.x(), p.y(), theta]),
                                                    values.atPoint2(key_landmark), sensor=mount)
        if jacobians is not None:
            c, s = np.cos(theta), np.sin(theta)
            body = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # d wTb Exp(xi)/d xi
            jacobians[0] = (h_pose @ body)[::-1]
            jacobians[1] = h_landmark[::-1]
        return np.array([_wrap_scalar(float(z[1]) - bearing), float(z[0]) - range_])

    return gtsam.CustomFactor(noise, [key_pose, key_landmark], error)


def range_bearing_factors(observations: RangeBearing, *, landmark_noise: LandmarkNoise,
                          huber_k: float | None = None) -> list[gtsam.NonlinearFactor]:
    """Range-bearing factors, one per row: pose ``X(index)`` to landmark ``L(id)``.

    Parameters
    ----------
    observations : RangeBearing
        ``index`` = keyframe of each row; integer landmark ids.
    landmark_noise : LandmarkNoise
        The sensor's noise, for rows without a covariance of their own: its
        covariance at the *measured* range (the EKF takes the predicted one).
    huber_k : float, optional
        Huber threshold of a robust kernel on every factor.

    Returns
    -------
    list of gtsam.BearingRangeFactor2D or gtsam.CustomFactor
        In row order: native factors for a sensor at the axle centre,
        :func:`mounted_range_bearing_factor` for the sightings'
        ``sensor_pose`` elsewhere. Each noise model is the row's covariance
        reordered to gtsam's ``(bearing, range)`` (module notes):
        ``Diagonal`` if diagonal, else a full ``Gaussian``; rows with the same
        covariance share one. :func:`predict_range_bearing` is the
        measurement model.

    Raises
    ------
    LandmarkIdError
        If an id is not an integer.

    Examples
    --------
    >>> obs = RangeBearing([2, 3], [7, 7], [1.5, 1.4], [0.1, 0.2],
    ...                    cov=[np.diag([1e-4, 4e-6]), [[1e-4, 1e-6], [1e-6, 4e-6]]])
    >>> f = range_bearing_factors(obs, landmark_noise=LandmarkNoise())
    >>> len(f), f[1].measured().range(), f[0].noiseModel().sigmas().tolist()   # (b, r)
    (2, 1.4, [0.002, 0.01])
    >>> np.allclose(f[1].noiseModel().covariance(), [[4e-6, 1e-6], [1e-6, 1e-4]], rtol=1e-12)
    True
    """
    ids = _integer_ids(observations)
    covs = observations.cov
    mount = observations.sensor_pose
    models: dict[bytes, gtsam.noiseModel.Base] = {}
    out = []
    for j, (i, lid, r, b) in enumerate(zip(observations.index.tolist(), ids.tolist(),
                                           observations.range_m.tolist(),
                                           observations.bearing_rad.tolist(), strict=True)):
        cov = landmark_noise.cov(r) if covs is None else covs[j]
        key = cov.tobytes()
        noise = models.get(key)
        if noise is None:
            noise = models[key] = _noise_model(cov, huber_k)
        if mount == CENTRED:
            out.append(gtsam.BearingRangeFactor2D(pose_key(i), landmark_key(lid), gtsam.Rot2(b),
                                                  r, noise))
        else:
            out.append(mounted_range_bearing_factor(pose_key(i), landmark_key(lid), r, b,
                                                    sensor_pose=mount, noise=noise))
    return out
