"""Settings and results of the smoothers in :mod:`fusion.graph.smoother` (re-exported there)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from fusion.graph.factors import CONSTANT_SIGMA_M
from fusion.noise import LandmarkNoise

__all__ = ["SmootherOptions", "SmootherResult"]


def _positive_tuple(value: Sequence[float], n: int, name: str) -> tuple[float, ...]:
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"{name} must be {n} positive numbers, got {value!r}")
    return tuple(float(a) for a in arr)


@dataclass(frozen=True)
class SmootherOptions:
    """How the graph is built and solved.

    Attributes
    ----------
    initial_pose_sigmas : (float, float, float)
        Prior standard deviations on the first pose (x [m], y [m], theta [rad]).
    calibrate : bool
        Use the calibration-aware motion factors and estimate ``(s, g)``.
    calibration_prior : (float, float)
        Prior mean of ``(s, g)``.
    calibration_prior_sigmas : (float, float)
        Prior standard deviations of ``(s, g)``: wide (0.2) by default, the
        robot may have changed since calibration.
    calibration_walk_sigmas : (float, float)
        Random-walk diffusion of ``(s, g)`` [1/sqrt(s)]: ``1e-3`` lets them
        move by ``1e-3 sqrt(60)``, about 0.8% (1 sigma), a minute; a larger
        value follows a floor change faster and forgets a constant scale
        faster (the trade-off is measured in ``docs/factor_graph.md``).
    calibration_every : int
        Consecutive keyframe intervals that share one calibration variable
        (at 0.5 s keyframes, 10 means a new calibration every 5 s, far
        shorter than a floor or load change lasts). The intervals of one
        calibration variable enter the graph as one
        :func:`~fusion.graph.factors.calibrated_motion_group_factor`; in
        :class:`~fusion.graph.IncrementalSmoother` the newest, not yet
        complete, group enters as native between-factors at the current
        calibration estimate until it completes (docs/factor_graph.md).
    relinearize_threshold : float
        iSAM2 relinearises a pose or landmark whose update exceeds this
        (tangent units, m and rad); calibrations never need it (the factor
        is linear in them). GTSAM's default; 0.01 gave the same accuracy on
        the acceptance runs at up to 1.6x the time.
    relinearize_skip : int
        iSAM2 checks for relinearisation every this many updates.
    landmark_huber_k : float or None
        Huber threshold (in standard deviations of the whitened error) of a
        robust kernel on the range-bearing factors (``gtsam.noiseModel.Robust``
        with ``mEstimator.Huber``; Huber 1964): beyond ``k`` sigma a detection
        weighs as if its error grew linearly, not quadratically, so outliers
        (the EKF gates them) cannot drag the path. ``None``: plain Gaussian.
        The kernel's weights follow the linearisation point, so use it with a
        small ``relinearize_threshold`` (1e-3 with ``relinearize_skip=1``).
    landmark_noise : LandmarkNoise
        The range-bearing sensor's noise, for sightings without a covariance
        of their own (:class:`fusion.range_bearing.RangeBearing` rows with
        ``cov=None``), taken at the *measured* range: the graph builds each
        factor before it predicts one (the EKFs take the predicted range).
        Default 2% of range (5 mm floor) and 1 degree, as the EKFs'.
    landmark_sigma_m : float
        Standard deviation [m] of the prior that holds each known landmark
        (:class:`fusion.landmark_map.LandmarkMap`) at its mapped position: the
        map's accuracy. The default :data:`~fusion.graph.factors.CONSTANT_SIGMA_M`
        (1e-6 m) stands for "exactly known".
    reinitialize_every : int
        Every this many updates, the newest pose and calibration are read
        back from iSAM2 to start the next keyframes from (in between, new
        poses start from dead reckoning off the last read-back). Reading an
        estimate back solves the Bayes tree; doing it at every update
        doubles the cost of a long smoothing run (benchmark ``graph``).

    Raises
    ------
    ValueError
        For a non-positive sigma, threshold or count, or a ``landmark_noise`` that
        is not a :class:`fusion.noise.LandmarkNoise`.
    """

    initial_pose_sigmas: tuple[float, float, float] = (1e-3, 1e-3, 1e-3)
    calibrate: bool = True
    calibration_prior: tuple[float, float] = (1.0, 1.0)
    calibration_prior_sigmas: tuple[float, float] = (0.2, 0.2)
    calibration_walk_sigmas: tuple[float, float] = (1e-3, 1e-3)
    calibration_every: int = 10
    relinearize_threshold: float = 0.1
    relinearize_skip: int = 10
    landmark_huber_k: float | None = None
    landmark_noise: LandmarkNoise = field(default_factory=LandmarkNoise)
    landmark_sigma_m: float = CONSTANT_SIGMA_M
    reinitialize_every: int = 10

    def __post_init__(self) -> None:
        setf = object.__setattr__
        setf(self, "initial_pose_sigmas",
             _positive_tuple(self.initial_pose_sigmas, 3, "initial_pose_sigmas"))
        setf(self, "calibration_prior",
             _positive_tuple(self.calibration_prior, 2, "calibration_prior"))
        for name in ("calibration_prior_sigmas", "calibration_walk_sigmas"):
            setf(self, name, _positive_tuple(getattr(self, name), 2, name))
        for name in ("calibration_every", "relinearize_skip", "reinitialize_every"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        k = self.landmark_huber_k
        if k is not None and not (np.isfinite(k) and k > 0):
            raise ValueError(f"landmark_huber_k must be positive or None, got {k}")
        if not isinstance(self.landmark_noise, LandmarkNoise):
            raise ValueError(f"landmark_noise must be a LandmarkNoise, got "
                             f"{type(self.landmark_noise).__name__}")
        for name in ("relinearize_threshold", "landmark_sigma_m"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive, got {value}")


@dataclass(frozen=True, eq=False)
class SmootherResult:
    """The smoothed estimate at the keyframes.

    Attributes
    ----------
    keyframes : ndarray of int, shape (n,)
        Sample index of each keyframe pose.
    poses : ndarray, shape (n, 3)
        ``wTb`` per keyframe ``(x [m], y [m], theta [rad])``, theta in (-pi, pi].
    pose_covariances : ndarray, shape (n, 3, 3), or None
        Marginal covariances in gtsam ``Pose2`` local coordinates (body frame).
    calibrations : ndarray, shape (n, 2), or None
        ``(s, g)`` in force at each keyframe (``None`` without ``calibrate``).
    calibration_covariances : ndarray, shape (n, 2, 2), or None
        Their marginal covariances.
    landmark_ids : ndarray of int, shape (k,)
        Landmarks in the graph.
    landmarks_xy : ndarray, shape (k, 2)
        Their estimated positions [m].
    """

    keyframes: np.ndarray
    poses: np.ndarray
    pose_covariances: np.ndarray | None
    calibrations: np.ndarray | None
    calibration_covariances: np.ndarray | None
    landmark_ids: np.ndarray
    landmarks_xy: np.ndarray
