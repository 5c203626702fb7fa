"""Settings and results of the smoothers in :mod:`fusion.graph.smoother` (re-exported there).

:func:`calibration_intrinsics_estimate` turns a smoother's calibration ``(s, g, kappa)``
into the odometry intrinsics it implies, as the model EKF's scale errors ``(k_v, k_w,
kappa)`` are (:mod:`fusion.scale_errors`): ``k_v = s - 1``, ``k_w = g - 1``
(the speeds are ``(s v, g w + kappa v)``, the EKF's ``D_c s``), a shift, so the
covariance of ``(k_v, k_w, kappa)`` is the calibration's own.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from fusion.graph.factors import CONSTANT_SIGMA_M
from fusion.noise import LandmarkNoise, ScaleErrors
from fusion.scale_errors import MAX_RATIO_ERROR, IntrinsicsEstimate, intrinsics_estimate
from lti_motion.intrinsics import OdometryIntrinsics

__all__ = ["SmootherOptions", "SmootherResult", "calibration_intrinsics_estimate"]


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
        Use the calibration-aware motion factors and estimate ``(s, g)`` (and
        ``kappa`` when the three calibration tuples have three entries).
    calibration_prior : (float, float) or (float, float, float)
        Prior mean of ``(s, g)``, or of ``(s, g, kappa [rad/m])``: the curvature
        of a left/right wheel diameter ratio, true speeds ``(s v, g w + kappa v)``
        (:mod:`fusion.graph.preintegration`; ``s = 1 + k_v``, ``g = 1 + k_w`` of
        the model EKF). :meth:`with_curvature` adds ``kappa`` with the EKF's
        prior and walk. The motions must be preintegrated with a calibration of
        the same size (``calibration=options.calibration_prior``).
    calibration_prior_sigmas : (float, float) or (float, float, float)
        Prior standard deviations: wide (0.2) by default, the robot may have
        changed since calibration.
    calibration_walk_sigmas : (float, float) or (float, float, float)
        Random-walk diffusion [1/sqrt(s), 1/sqrt(s), rad/m/sqrt(s)]: ``1e-3``
        lets ``(s, g)`` move by ``1e-3 sqrt(60)``, about 0.8% (1 sigma), a
        minute; a larger value follows a floor change faster and forgets a
        constant scale faster (the trade-off is measured in ``docs/factor_graph.md``).
    curvature_bound_rad_per_m : float
        ``|kappa|`` beyond which the estimate is not a robot (the EKF's clip,
        :data:`fusion.scale_errors.MAX_RATIO_ERROR` over the wheel base, set by
        :meth:`with_curvature`). The graph cannot clip a variable, so it bounds
        what the smoother *uses* of its estimate: the calibration it
        linearises new intervals at (:class:`~fusion.graph.IncrementalSmoother`)
        is clipped to it; the estimate itself is the least-squares one, held
        near zero by its 1% prior (the bound is 10 prior sigmas away).
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
        map's accuracy. The default :data:`~fusion.graph.CONSTANT_SIGMA_M`
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
    curvature_bound_rad_per_m: float = math.inf

    def __post_init__(self) -> None:
        setf = object.__setattr__
        setf(self, "initial_pose_sigmas",
             _positive_tuple(self.initial_pose_sigmas, 3, "initial_pose_sigmas"))
        nc = len(self.calibration_prior)
        if nc not in (2, 3):
            raise ValueError(f"calibration_prior must be (s, g) or (s, g, kappa), got "
                             f"{self.calibration_prior!r}")
        prior = (*_positive_tuple(self.calibration_prior[:2], 2, "calibration_prior"),
                 *(float(k) for k in self.calibration_prior[2:]))
        if not np.all(np.isfinite(prior)):
            raise ValueError(f"calibration_prior must be finite, got {self.calibration_prior!r}")
        setf(self, "calibration_prior", prior)
        for name in ("calibration_prior_sigmas", "calibration_walk_sigmas"):
            setf(self, name, _positive_tuple(getattr(self, name), nc, name))
        bound = self.curvature_bound_rad_per_m
        if not bound > 0:
            raise ValueError(f"curvature_bound_rad_per_m must be positive, got {bound}")
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

    @property
    def n_calibration(self) -> int:
        """Size of the calibration variable: 2 for ``(s, g)``, 3 with ``kappa``."""
        return len(self.calibration_prior)

    def bounded_calibration(self, calibration: np.ndarray) -> np.ndarray:
        """``calibration`` with ``|kappa|`` clipped to :attr:`curvature_bound_rad_per_m`
        (the model EKF's clip, :mod:`fusion.ekf.resets`): what a smoother linearises new
        intervals at and dead-reckons with.

        Examples
        --------
        >>> opts = SmootherOptions().with_curvature(wheel_base_m=0.25)
        >>> opts.bounded_calibration([1.0, 1.0, -0.9]).tolist()
        [1.0, 1.0, -0.4]
        """
        cal = np.array(calibration, dtype=float)
        if len(cal) == 3:
            bound = self.curvature_bound_rad_per_m
            cal[2] = np.clip(cal[2], -bound, bound)
        return cal

    def with_curvature(self, *, wheel_base_m: float, scales: ScaleErrors | None = None
                       ) -> SmootherOptions:
        """These options with the curvature ``kappa`` [rad/m] estimated as well.

        ``kappa`` gets the model EKF's prior and walk (:class:`fusion.noise.ScaleErrors`:
        ``ratio_prior_std / b`` and ``ratio_walk_per_sqrt_s / b``, a 1% diameter ratio and
        0.1% in 100 s by default), a prior mean of 0, and the EKF's bound
        ``MAX_RATIO_ERROR / b`` (:mod:`fusion.ekf.resets`); ``(s, g)`` keep theirs.

        Parameters
        ----------
        wheel_base_m : float
            Wheel base ``b`` [m] of the intrinsics the encoder speeds are computed with.
        scales : ScaleErrors, optional
            The EKF's scale-error settings (default :class:`~fusion.noise.ScaleErrors()`).

        Returns
        -------
        SmootherOptions

        Raises
        ------
        ValueError
            For a non-positive wheel base.

        Examples
        --------
        >>> opts = SmootherOptions().with_curvature(wheel_base_m=0.235)
        >>> opts.n_calibration, round(opts.calibration_prior_sigmas[2], 4)
        (3, 0.0426)
        """
        b = float(wheel_base_m)
        if not (math.isfinite(b) and b > 0):
            raise ValueError(f"wheel_base_m must be positive, got {wheel_base_m}")
        sc = scales or ScaleErrors()
        return replace(self, calibration_prior=(*self.calibration_prior[:2], 0.0),
                       calibration_prior_sigmas=(*self.calibration_prior_sigmas[:2],
                                                 sc.prior_stds(b)[2]),
                       calibration_walk_sigmas=(*self.calibration_walk_sigmas[:2],
                                                sc.walk_rates(b)[2]),
                       curvature_bound_rad_per_m=MAX_RATIO_ERROR / b)


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
    calibrations : ndarray, shape (n, nc), or None
        ``(s, g)`` (``nc = 2``) or ``(s, g, kappa)`` (``nc = 3``) in force at each
        keyframe (``None`` without ``calibrate``).
    calibration_covariances : ndarray, shape (n, nc, nc), or None
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

    def intrinsics_estimate(self, intrinsics: OdometryIntrinsics, *, index: int = -1
                            ) -> IntrinsicsEstimate:
        """The intrinsics the calibration at keyframe ``index`` implies
        (:func:`calibration_intrinsics_estimate`; needs ``calibration_covariances``).

        Raises
        ------
        ValueError
            Without calibrations or their covariances (smooth with ``calibrate`` and
            ``covariances=True``), or if the estimate is not a possible robot.
        """
        if self.calibrations is None or self.calibration_covariances is None:
            raise ValueError("this result holds no calibrations with covariances; smooth with "
                             "SmootherOptions(calibrate=True) and covariances=True")
        return calibration_intrinsics_estimate(intrinsics, self.calibrations[index],
                                               self.calibration_covariances[index])


def calibration_intrinsics_estimate(intrinsics: OdometryIntrinsics, calibration: np.ndarray,
                                    covariance: np.ndarray, *, t_s: float = math.nan
                                    ) -> IntrinsicsEstimate:
    """The odometry intrinsics a smoother's calibration implies, with their spread.

    Parameters
    ----------
    intrinsics : OdometryIntrinsics
        The intrinsics the preintegrated encoder speeds were computed with.
    calibration : array_like, shape (2,) or (3,)
        ``(s, g)`` or ``(s, g, kappa [rad/m])``; without ``kappa`` it is taken as
        exactly 0 (no diameter-ratio information).
    covariance : array_like, shape (2, 2) or (3, 3)
        Its (marginal) covariance.
    t_s : float
        Time of the estimate [s], for the record.

    Returns
    -------
    IntrinsicsEstimate
        :func:`fusion.scale_errors.intrinsics_estimate` of the scale errors
        ``(s - 1, g - 1, kappa)`` (module notes): ``intrinsics.corrected(s - 1, g - 1,
        kappa)``, eq. 1 there.

    Raises
    ------
    ValueError
        For shapes that do not match, or an estimate that is not a possible robot.

    Examples
    --------
    >>> k = OdometryIntrinsics.symmetric(m_per_tick=4.4e-4, wheel_base_m=0.235)
    >>> est = calibration_intrinsics_estimate(k, [1.0, 1.0, -0.01 / 0.235],
    ...                                       np.diag([1e-6, 1e-6, 0.002 ** 2]))
    >>> round(est.intrinsics.diameter_ratio, 5), round(est.diameter_ratio_std, 6)
    (1.01005, 0.000475)
    """
    c = np.asarray(calibration, dtype=float).reshape(-1)
    cov = np.asarray(covariance, dtype=float)
    if c.shape not in ((2,), (3,)) or cov.shape != (len(c), len(c)):
        raise ValueError(f"expected a calibration (2,) or (3,) and its square covariance, got "
                         f"{c.shape} and {cov.shape}")
    errors = np.array([c[0] - 1.0, c[1] - 1.0, c[2] if len(c) == 3 else 0.0])
    full = np.zeros((3, 3))
    full[:len(c), :len(c)] = cov
    return intrinsics_estimate(intrinsics, errors, full, t_s=t_s)
