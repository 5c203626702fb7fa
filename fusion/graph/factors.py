"""GTSAM factors for a preintegrated motion model, its calibration, and landmarks.

- :func:`motion_factor`: the plain factor, a native ``gtsam.BetweenFactorPose2``
  with the preintegrated relative pose and covariance
  (:mod:`fusion.graph.preintegration`): no Python runs at optimisation time.
- :func:`calibrated_motion_factor` and :func:`calibrated_motion_group_factor`
  (from :mod:`fusion.graph.calibrated_factors`, re-exported): ``gtsam.CustomFactor``
  on (poses, calibration ``c = (s, g)``) that correct the preintegrated pose to
  first order in ``c``, as IMU preintegration corrects for the bias (Forster et
  al. 2017, eq. 44), so a smoother with landmarks estimates the calibration
  online. :func:`calibration_walk_factor` lets ``c`` drift.
- :func:`range_bearing_factor`: a native ``gtsam.BearingRangeFactor2D`` to a
  landmark variable (known landmarks carry a prior, or a tight one for a
  constant). :class:`RangeBearing` holds observations for the graph (one
  noise level per set; :meth:`RangeBearing.from_observations` converts the
  EKF's :class:`fusion.landmark_map.Observations`), the map is
  :class:`fusion.landmark_map.LandmarkMap`; :func:`predict_range_bearing` is the
  measurement model and :func:`observe_landmarks` a simulator of observations
  for experiments.

Variables: poses ``X(i)`` (``gtsam.Pose2``, ``wTb``: body in world), calibrations
``C(i)`` (``Point2`` holding ``(s, g)`` around ``(1, 1)``), landmarks ``L(id)``
(``Point2`` in the world frame).

References
----------
C. Forster, L. Carlone, F. Dellaert, D. Scaramuzza, "On-Manifold
Preintegration for Real-Time Visual-Inertial Odometry", IEEE Trans. Robotics
33(1), 2017, eq. 44-45 (first-order bias update of preintegrated measurements).
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
from gtsam.symbol_shorthand import C, L, X

from fusion.exceptions import (
    GraphInputError,
    LandmarkIdError,
    MeasurementShapeError,
    NonFiniteInputError,
)
from fusion.graph.calibrated_factors import (
    calibrated_motion_error,
    calibrated_motion_factor,
    calibrated_motion_group_factor,
)
from fusion.graph.preintegration import Preintegrated
from fusion.landmark_map import LandmarkMap
from fusion.range_bearing import Observations
from lti_motion.kinematics import wrap_angle

__all__ = [
    "CONSTANT_SIGMA_M",
    "RangeBearing",
    "calibrated_motion_error",
    "calibrated_motion_factor",
    "calibrated_motion_group_factor",
    "calibration_key",
    "calibration_walk_factor",
    "landmark_key",
    "motion_factor",
    "observe_landmarks",
    "pose_key",
    "predict_range_bearing",
    "range_bearing_factor",
]

#: Prior standard deviation [m] that stands for "constant" on a known landmark:
#: far below any measurement noise, yet a proper Gaussian, so iSAM2's Cholesky
#: factorisation stays well posed (a hard ``NonlinearEquality`` would not).
CONSTANT_SIGMA_M = 1e-6


def pose_key(i: int) -> int:
    """GTSAM key of keyframe pose ``i`` (``X(i)``)."""
    return X(int(i))


def calibration_key(i: int) -> int:
    """GTSAM key of the calibration ``(s, g)`` in force from keyframe ``i`` (``C(i)``)."""
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
                            duration_s: float) -> gtsam.BetweenFactorPoint2:
    """Random walk of the calibration between two keyframes.

    Parameters
    ----------
    key_a, key_b : int
        Calibration keys of consecutive keyframes.
    sigma_per_sqrt_s : array_like, shape (2,)
        Diffusion of ``(s, g)`` [1/sqrt(s)].
    duration_s : float
        Time between the keyframes [s].

    Returns
    -------
    gtsam.BetweenFactorPoint2
        ``c_b - c_a ~ N(0, diag(sigma^2) duration_s)``.
    """
    sig = np.asarray(sigma_per_sqrt_s, dtype=float) * np.sqrt(float(duration_s))
    return gtsam.BetweenFactorPoint2(key_a, key_b, np.zeros(2),
                                     gtsam.noiseModel.Diagonal.Sigmas(sig))


@dataclass(frozen=True, eq=False)
class RangeBearing:
    """Range-bearing observations of landmarks, one row each.

    Attributes
    ----------
    pose_index : ndarray of int, shape (k,)
        The pose each was taken from: a keyframe index for
        :class:`~fusion.graph.IncrementalSmoother`, a frame index for the
        log-level helpers of :mod:`fusion.graph.smoother`.
    landmark_id : ndarray of int, shape (k,)
        Which landmark.
    bearing_rad : ndarray, shape (k,)
        Bearing in the body frame, counter-clockwise from the heading [rad].
    range_m : ndarray, shape (k,)
        Distance [m].
    bearing_sigma_rad, range_sigma_m : float
        Measurement standard deviations.
    """

    pose_index: np.ndarray
    landmark_id: np.ndarray
    bearing_rad: np.ndarray
    range_m: np.ndarray
    bearing_sigma_rad: float
    range_sigma_m: float

    def __post_init__(self) -> None:
        cols = {"pose_index": np.asarray(self.pose_index).astype(np.int64).reshape(-1),
                "landmark_id": np.asarray(self.landmark_id).astype(np.int64).reshape(-1),
                "bearing_rad": np.asarray(self.bearing_rad, dtype=float).reshape(-1),
                "range_m": np.asarray(self.range_m, dtype=float).reshape(-1)}
        k = len(cols["pose_index"])
        for name, arr in cols.items():
            if arr.shape != (k,):
                raise MeasurementShapeError(f"RangeBearing.{name} has shape {arr.shape}, "
                                            f"expected ({k},)")
            if not np.all(np.isfinite(arr)):
                raise NonFiniteInputError(f"RangeBearing.{name} holds NaN or infinite values")
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        if np.any(cols["range_m"] <= 0):
            raise GraphInputError("ranges must be positive")
        for name in ("bearing_sigma_rad", "range_sigma_m"):
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value > 0):
                raise GraphInputError(f"RangeBearing.{name} must be positive, got {value}")
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.pose_index)

    def select(self, mask: np.ndarray) -> RangeBearing:
        """The rows where ``mask`` (boolean or index array) holds."""
        return RangeBearing(self.pose_index[mask], self.landmark_id[mask], self.bearing_rad[mask],
                            self.range_m[mask], self.bearing_sigma_rad, self.range_sigma_m)

    def with_pose_index(self, pose_index: np.ndarray) -> RangeBearing:
        """The same observations attached to other pose indices."""
        return RangeBearing(pose_index, self.landmark_id, self.bearing_rad, self.range_m,
                            self.bearing_sigma_rad, self.range_sigma_m)

    @classmethod
    def from_observations(cls, observations: Observations, *, bearing_sigma_rad: float,
                          range_sigma_m: float) -> RangeBearing:
        """The EKF's :class:`fusion.landmark_map.Observations` as graph observations.

        Parameters
        ----------
        observations : Observations
            ``pose_index`` becomes their ``frame``; ids must be integers.
        bearing_sigma_rad, range_sigma_m : float
            The noise the graph gives every row (``Observations`` carry none; a
            :class:`fusion.landmark_map.LandmarkNoise` with a range fraction has no
            single range sigma, so choose one).

        Raises
        ------
        LandmarkIdError
            If an id is not an integer.
        ValueError
            If a range or a sigma is not positive.

        Examples
        --------
        >>> from fusion.range_bearing import Observations
        >>> obs = Observations(np.array([3]), (7,), np.array([[2.0, 0.1]]))
        >>> rb = RangeBearing.from_observations(obs, bearing_sigma_rad=0.02, range_sigma_m=0.05)
        >>> rb.pose_index.tolist(), rb.landmark_id.tolist(), rb.range_m.tolist()
        ([3], [7], [2.0])
        >>> rb.to_observations().range_bearing.tolist()
        [[2.0, 0.1]]
        """
        bad = [i for i in observations.landmark_id
               if isinstance(i, bool) or not isinstance(i, (int, np.integer))]
        if bad:
            raise LandmarkIdError(f"the factor graph keys landmarks by integer id; got "
                                  f"{bad[:5]!r}; number the landmarks first")
        rb = np.asarray(observations.range_bearing, dtype=float).reshape(-1, 2)
        return cls(observations.frame, np.array(observations.landmark_id, dtype=np.int64),
                   rb[:, 1], rb[:, 0], bearing_sigma_rad, range_sigma_m)

    def to_observations(self) -> Observations:
        """These rows as :class:`fusion.landmark_map.Observations` (``frame`` = ``pose_index``)."""
        return Observations(frame=self.pose_index.copy(),
                            landmark_id=tuple(self.landmark_id.tolist()),
                            range_bearing=np.column_stack([self.range_m, self.bearing_rad]))


def predict_range_bearing(wTb: np.ndarray, points_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bearing and range of world points seen from body poses (the measurement model).

    Parameters
    ----------
    wTb : array_like, shape (..., 3)
        Poses ``(x [m], y [m], theta [rad])``.
    points_xy : array_like, shape (..., 2)
        World points [m], broadcast against the poses.

    Returns
    -------
    bearing_rad, range_m : ndarray, shape (...)
        ``atan2`` of the point in the body frame, wrapped to (-pi, pi], and distance.

    Examples
    --------
    >>> b, r = predict_range_bearing(np.array([0.0, 0.0, np.pi / 2]), np.array([0.0, 2.0]))
    >>> round(float(b), 12) + 0.0, round(float(r), 12)
    (0.0, 2.0)
    """
    pose = np.asarray(wTb, dtype=float)
    pts = np.asarray(points_xy, dtype=float)
    dx, dy = pts[..., 0] - pose[..., 0], pts[..., 1] - pose[..., 1]
    return wrap_angle(np.arctan2(dy, dx) - pose[..., 2]), np.hypot(dx, dy)


def observe_landmarks(wTb: np.ndarray, landmarks: LandmarkMap, *, rng: np.random.Generator,
                      bearing_sigma_rad: float, range_sigma_m: float, max_range_m: float,
                      min_range_m: float = 0.2, field_of_view_rad: float = 2 * np.pi,
                      pose_index: np.ndarray | None = None) -> RangeBearing:
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
    pose_index : array_like of int, shape (n,), optional
        Index recorded for each pose (default ``0 .. n-1``).

    Returns
    -------
    RangeBearing
        Every (pose, landmark) pair in view, ordered by pose.
    """
    poses = np.asarray(wTb, dtype=float).reshape(-1, 3)
    idx = np.arange(len(poses)) if pose_index is None else np.asarray(pose_index).reshape(-1)
    if idx.shape != (len(poses),):
        raise MeasurementShapeError(f"pose_index has shape {idx.shape}, expected "
                                    f"({len(poses)},)")
    ids = landmarks.integer_ids                      # raises for non-integer ids
    bearing, rng_m = predict_range_bearing(poses[:, None, :], landmarks.xy_m[None, :, :])
    seen = ((rng_m <= max_range_m) & (rng_m >= min_range_m)
            & (np.abs(bearing) <= 0.5 * field_of_view_rad))
    rows, cols = np.nonzero(seen)
    noisy_b = wrap_angle(bearing[rows, cols] + bearing_sigma_rad * rng.standard_normal(rows.size))
    noisy_r = np.abs(rng_m[rows, cols] + range_sigma_m * rng.standard_normal(rows.size))
    return RangeBearing(idx[rows], ids[cols], noisy_b, noisy_r,
                        bearing_sigma_rad, range_sigma_m)


def range_bearing_factor(bearing_rad: float, range_m: float, *, key_pose: int,
                         key_landmark: int, noise: gtsam.noiseModel.Base
                         ) -> gtsam.BearingRangeFactor2D:
    """A native range-bearing factor between a pose and a landmark variable.

    Parameters
    ----------
    bearing_rad, range_m : float
        The measurement (:func:`predict_range_bearing` is its model).
    key_pose, key_landmark : int
        Keys of the ``Pose2`` (``wTb``) and the ``Point2`` (world frame).
    noise : gtsam.noiseModel.Base
        Two-dimensional (bearing [rad], range [m]) noise model.

    Returns
    -------
    gtsam.BearingRangeFactor2D
    """
    return gtsam.BearingRangeFactor2D(key_pose, key_landmark, gtsam.Rot2(float(bearing_rad)),
                                      float(range_m), noise)
