"""What encoder odometry and its speeds are worth: covariances from a model's noise.

A calibrated :class:`~lti_motion.model.MotionModel` knows how well it predicts the
encoder body speeds one period ahead: ``R``, the covariance of its one-step residuals
``e`` [(m/s)^2, (rad/s)^2] at its period ``dt``. Odometry publishers and state estimators
want other forms of the same knowledge; this module derives them, once, for the ROS
exports and the bags the project writes.

**A speed averaged over another period.** White speed noise of covariance ``R`` per
period ``dt`` has the density ``R dt``; its mean over a period ``T`` has

.. math::  \\Sigma_T = R \\, dt / T                                          (1)

(Woodman 2007, section 3.2.1, for a gyro's rate noise; the same for any white rate).

**The encoders' rounding.** A count is the wheel angle rounded to a whole tick, an error
uniform over one tick (variance ``1/12`` tick^2, Widrow & Kollar 2008, ch. 4); a period's
count change is the difference of two such errors (``1/6`` tick^2). Through the
intrinsics' ``J`` (:meth:`~lti_motion.intrinsics.OdometryIntrinsics.jacobian`) the speeds
carry

.. math::  R_q = J \\,\\mathrm{diag}(1/6, 1/6)\\, J^T / dt^2                  (2)

On a Create 2 (0.44 mm/tick, 15 ms) that is most of a model's ``R`` (84-88% of its
variances on the simulated robot of ``benchmarks/bench_ros_config.py``). It does not
accumulate: the rounding errors of a path's increments cancel but for the last one, so a
dead-reckoned pose carries it once, not once per period.

**Growth along a path.** A pose integrated from speeds with errors of covariance ``S``
per period (paper eq. 11, :func:`~lti_motion.kinematics.pose_step_jacobians`) has

.. math::  P_{k+1} = F_k P_k F_k^T + G_k S G_k^T                             (3)

(Thrun, Burgard & Fox 2005, section 5.4 and table 3.3). What it grows with depends on
what was measured. A model whose intrinsics were calibrated against a pose reference
carries encoder odometry's own error model (:mod:`lti_motion.odometry_errors`: a random
walk per metre of wheel travel, Chong & Kleeman 1997, and the intrinsics' covariance
propagated along the path, Kelly 2004), and :meth:`OdometryNoise.from_model` grows with
that. Without it, the growth falls back on ``S = R - R_q`` (eigenvalues clipped at
:data:`VARIANCE_FLOOR`): the part of the model's residuals that is not rounding, which
still holds speed changes the model did not predict (the encoders measure them
exactly), an upper bound that looks like no measurement of slip and is labelled so
(:attr:`OdometryNoise.measured` False). Either adds the last count's rounding on top.

**The model's speed error over a filter's period.** A filter that predicts ``N = T /
dt`` model periods ahead from a known state has the speed error covariance
``S_N = C P_N C^T + R`` (:meth:`~lti_motion.model.MotionModel.output_error_covariance`,
``P_{h+1} = A P_h A^T + Q``): :func:`speed_error_over` (robot_localization's and fuse's
process noise, ``lti_motion.app.ros_config``).

References
----------
O. J. Woodman, "An introduction to inertial navigation", UCAM-CL-TR-696, 2007, sec. 3.2.1.
B. Widrow, I. Kollar, *Quantization Noise*, Cambridge University Press 2008, ch. 4.
S. Thrun, W. Burgard, D. Fox, *Probabilistic Robotics*, MIT Press 2005, sec. 5.4.
L. Ljung, *System Identification*, 2nd ed., Prentice Hall 1999, sec. 4.3 (innovations form).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lti_motion.exceptions import MissingEncoderScaleError, ShapeError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import pose_step_jacobians
from lti_motion.odometry_errors import intrinsics_sensitivities, wheel_walk_step_covariances

__all__ = [
    "VARIANCE_FLOOR",
    "OdometryNoise",
    "averaged_covariance",
    "grow_pose_covariances",
    "rounding_pose_covariance",
    "rounding_speed_covariance",
    "speed_error_over",
]

#: The smallest variance any covariance here holds [(m/s)^2, (rad/s)^2, m^2, rad^2]: a
#: standard deviation of 1e-6, far below an encoder's resolution, so nothing is ever 0
#: (robot_localization replaces a zero variance with a warning).
VARIANCE_FLOOR = 1e-12


def _covariance2(cov: np.ndarray, name: str) -> np.ndarray:
    cov = np.asarray(cov, dtype=float)
    if cov.shape != (2, 2):
        raise ShapeError(f"{name} must be a (2, 2) covariance of (v, w), got shape {cov.shape}")
    if not np.all(np.isfinite(cov)):
        raise ValueError(f"{name} holds NaN or infinite values")
    return 0.5 * (cov + cov.T)


def _positive(value: float, name: str) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive number, got {value}")
    return value


def _clip_psd(cov: np.ndarray) -> np.ndarray:
    """``cov`` with its eigenvalues raised to :data:`VARIANCE_FLOOR` (symmetric)."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    out = (v * np.maximum(w, VARIANCE_FLOOR)) @ v.T
    return 0.5 * (out + out.T)


def averaged_covariance(speed_cov: np.ndarray, *, dt_s: float, period_s: float) -> np.ndarray:
    """Covariance of white speed noise averaged over ``period_s``, eq. (1).

    Parameters
    ----------
    speed_cov : ndarray, shape (2, 2)
        Covariance of ``(v [m/s], w [rad/s])`` per period ``dt_s``, e.g. ``MotionModel.R``.
    dt_s, period_s : float
        The period of ``speed_cov`` and the averaging period [s].

    Returns
    -------
    ndarray, shape (2, 2)
        ``speed_cov dt_s / period_s``.

    Examples
    --------
    >>> averaged_covariance(np.eye(2) * 1e-4, dt_s=0.015, period_s=0.03).diagonal().tolist()
    [5e-05, 5e-05]
    """
    cov = _covariance2(speed_cov, "speed_cov")
    return cov * (_positive(dt_s, "dt_s") / _positive(period_s, "period_s"))


def rounding_speed_covariance(intrinsics: OdometryIntrinsics, dt_s: float) -> np.ndarray:
    """The speeds' covariance from the counts' rounding over one period, eq. (2).

    Parameters
    ----------
    intrinsics : OdometryIntrinsics
        Each wheel's m/tick and the wheel base.
    dt_s : float
        The period of one count change [s].

    Returns
    -------
    ndarray, shape (2, 2)
        ``J diag(1/6, 1/6) J^T / dt^2`` [(m/s)^2, (rad/s)^2].

    Examples
    --------
    >>> k = OdometryIntrinsics.symmetric(m_per_tick=1e-3, wheel_base_m=0.2)
    >>> ((rounding_speed_covariance(k, 0.01) * 6).round(12) + 0.0).tolist()
    [[0.005, 0.0], [0.0, 0.5]]
    """
    j = intrinsics.jacobian()
    return j @ j.T / (6.0 * _positive(dt_s, "dt_s") ** 2)


def rounding_pose_covariance(intrinsics: OdometryIntrinsics) -> np.ndarray:
    """What the last counts' rounding (``1/12`` tick^2 each) leaves in a pose, (3, 3).

    The travel's variance goes on both ``x`` and ``y`` (the heading is not known here, so
    either axis may hold all of it); the heading's on ``theta``.

    Examples
    --------
    >>> k = OdometryIntrinsics.symmetric(m_per_tick=1e-3, wheel_base_m=0.2)
    >>> (rounding_pose_covariance(k).diagonal() * 12).round(12).tolist()
    [5e-07, 5e-07, 5e-05]
    """
    st = intrinsics.jacobian() @ intrinsics.jacobian().T / 12.0     # (travel, turn)
    return np.diag([st[0, 0], st[0, 0], st[1, 1]])


def grow_pose_covariances(poses: np.ndarray, speeds: np.ndarray, dt_s: float,
                          growth_cov: np.ndarray, *,
                          initial_cov: np.ndarray | None = None) -> np.ndarray:
    """Covariances of poses integrated from speeds with white errors, eq. (3).

    Parameters
    ----------
    poses : ndarray, shape (n, 3)
        The poses ``(x [m], y [m], theta [rad])``; pose ``k + 1`` follows pose ``k`` by
        ``speeds[k]`` held for ``dt_s``.
    speeds : ndarray, shape (n - 1, 2)
        ``(v [m/s], w [rad/s])`` of each step.
    dt_s : float or ndarray, shape (n - 1,)
        Each step's length [s].
    growth_cov : ndarray, shape (2, 2) or (n - 1, 2, 2)
        The speed errors' covariance, the same for every step or one per step.
    initial_cov : ndarray, shape (3, 3), optional
        Covariance of ``poses[0]`` (zeros).

    Returns
    -------
    ndarray, shape (n, 3, 3)

    Examples
    --------
    A straight metre in ten steps: the travel's variance adds up, ``10 (0.1)^2 1e-4``:

    >>> poses = np.column_stack([np.linspace(0, 1, 11), np.zeros(11), np.zeros(11)])
    >>> p = grow_pose_covariances(poses, np.tile([1.0, 0.0], (10, 1)), 0.1, np.eye(2) * 1e-4)
    >>> float(p[-1, 0, 0].round(12))
    1e-05
    """
    poses = np.asarray(poses, dtype=float)
    speeds = np.asarray(speeds, dtype=float)
    n = len(poses)
    if poses.ndim != 2 or poses.shape[1] != 3 or speeds.shape != (n - 1, 2):
        raise ShapeError(f"expected poses (n, 3) and speeds (n - 1, 2), got {poses.shape} "
                         f"and {speeds.shape}")
    s = np.asarray(growth_cov, dtype=float)
    if s.shape not in ((2, 2), (n - 1, 2, 2)) or not np.all(np.isfinite(s)):
        raise ShapeError(f"growth_cov must be a finite (2, 2) or (n - 1, 2, 2) covariance for "
                         f"n = {n} poses, got shape {s.shape}")
    out = np.empty((n, 3, 3))
    out[0] = np.zeros((3, 3)) if initial_cov is None else np.asarray(initial_cov, float)
    if n == 1:
        return out
    f_pose, f_speed = pose_step_jacobians(poses[:-1], speeds[:, 0], speeds[:, 1], dt_s)
    added = f_speed @ s @ np.swapaxes(f_speed, 1, 2)           # G S G^T, every step at once
    p = out[0]
    for k in range(n - 1):                                     # eq. (3), sequential
        p = f_pose[k] @ p @ f_pose[k].T + added[k]
        out[k + 1] = p
    return 0.5 * (out + np.swapaxes(out, 1, 2))


def speed_error_over(model, period_s: float) -> np.ndarray:
    """The model's speed error covariance ``N = period_s / dt`` periods after a known state.

    ``S_N = C P_N C^T + R`` with ``P_0 = 0``, ``P_{h+1} = A P_h A^T + Q``
    (:meth:`~lti_motion.model.MotionModel.output_error_covariance`); ``N`` at least 1.

    Parameters
    ----------
    model : MotionModel
    period_s : float
        A filter's period [s].

    Returns
    -------
    ndarray, shape (2, 2)
        [(m/s)^2, (rad/s)^2].
    """
    n = max(1, round(_positive(period_s, "period_s") / model.dt_s))
    return model.output_error_covariance(n + 1)[n]


@dataclass(frozen=True)
class OdometryNoise:
    """The noise of encoder odometry: its speeds' covariance, and how its pose grows.

    Attributes
    ----------
    speed_cov : ndarray, shape (2, 2)
        Covariance of one period's speeds ``(v [m/s], w [rad/s])`` (a twist's).
    growth_cov : ndarray, shape (2, 2)
        The share of it that accumulates in a dead-reckoned pose, per period (eq. 3).
    pose_floor : ndarray, shape (3, 3)
        Added to every pose covariance once (the last counts' rounding).
    dt_s : float
        The period [s].
    source : str
        Where the numbers came from, for people.
    wheel_variance_per_m : float
        Each wheel's travel variance per metre rolled [m^2/m], grown along the path on
        top of ``growth_cov`` (:func:`lti_motion.odometry_errors.
        wheel_walk_step_covariances`); 0: none.
    intrinsics : OdometryIntrinsics or None
        The intrinsics the odometry uses, with ``intrinsics_covariance``.
    intrinsics_covariance : ndarray, shape (3, 3), or None
        Their covariance: the systematic error carried along the path
        (:func:`lti_motion.odometry_errors.intrinsics_sensitivities`); None: none.
    measured : bool
        The pose growth is encoder odometry's error measured against a reference (True),
        or a stand-in for it (False).
    """

    speed_cov: np.ndarray
    growth_cov: np.ndarray
    pose_floor: np.ndarray
    dt_s: float
    source: str
    wheel_variance_per_m: float = 0.0
    intrinsics: OdometryIntrinsics | None = None
    intrinsics_covariance: np.ndarray | None = None
    measured: bool = False

    def __post_init__(self) -> None:
        setf = object.__setattr__
        setf(self, "speed_cov", _clip_psd(_covariance2(self.speed_cov, "speed_cov")))
        setf(self, "growth_cov", _clip_psd(_covariance2(self.growth_cov, "growth_cov")))
        floor = np.asarray(self.pose_floor, dtype=float)
        if floor.shape != (3, 3) or not np.all(np.isfinite(floor)):
            raise ShapeError(f"pose_floor must be a finite (3, 3) covariance, got {floor.shape}")
        setf(self, "pose_floor", floor + VARIANCE_FLOOR * np.eye(3))
        setf(self, "dt_s", _positive(self.dt_s, "dt_s"))
        k = float(self.wheel_variance_per_m)
        if not (np.isfinite(k) and k >= 0):
            raise ValueError(f"wheel_variance_per_m must be a finite number >= 0, got {k}")
        setf(self, "wheel_variance_per_m", k)
        if self.intrinsics_covariance is not None:
            cov = np.asarray(self.intrinsics_covariance, dtype=float)
            if cov.shape != (3, 3) or self.intrinsics is None:
                raise ShapeError("intrinsics_covariance must be (3, 3) and come with the "
                                 f"intrinsics, got shape {cov.shape}")
            setf(self, "intrinsics_covariance", 0.5 * (cov + cov.T))

    @classmethod
    def from_model(cls, model) -> OdometryNoise:
        """The model's output noise ``R`` for the speeds; the pose grown with the model's
        measured odometry errors (:attr:`~lti_motion.model.MotionModel.odometry_errors`)
        when it has them, else with ``R - R_q`` (module docstring, ``measured`` False); the
        last counts' rounding on top.

        Raises
        ------
        MissingEncoderScaleError
            If the model has no encoder scale (the rounding needs it).
        """
        k = model.encoder_intrinsics
        if k is None:
            raise MissingEncoderScaleError.needed_by("the odometry's covariances")
        rq = rounding_speed_covariance(k, model.dt_s)
        errors = getattr(model, "odometry_errors", None)
        if errors is not None:
            return cls(model.R, np.zeros((2, 2)), rounding_pose_covariance(k), model.dt_s,
                       f"the model's output noise R (speeds); encoder odometry's random walk "
                       f"({errors.wheel_variance_per_m:.3g} m^2 per metre of wheel travel) "
                       f"and its intrinsics' covariance, measured by the {errors.source} "
                       "(pose growth)",
                       wheel_variance_per_m=errors.wheel_variance_per_m, intrinsics=k,
                       intrinsics_covariance=errors.intrinsics_covariance, measured=True)
        return cls(model.R, model.R - rq, rounding_pose_covariance(k), model.dt_s,
                   "the model's output noise R (speeds); R less the counts' rounding (growth: "
                   "not a measurement of the odometry's error, an upper bound)")

    @classmethod
    def from_encoders(cls, intrinsics: OdometryIntrinsics, dt_s: float) -> OdometryNoise:
        """Without a model: the counts' rounding for the speeds, and grown as if it
        accumulated (an upper bound standing in for the slip nothing here measures)."""
        rq = rounding_speed_covariance(intrinsics, dt_s)
        return cls(rq, rq, rounding_pose_covariance(intrinsics), dt_s,
                   "the counts' rounding (no model: grown as if it accumulated)")

    def twist_covariance(self, period_s: float) -> np.ndarray:
        """The speeds averaged over ``period_s`` (eq. 1), (2, 2)."""
        return _clip_psd(averaged_covariance(self.speed_cov, dt_s=self.dt_s, period_s=period_s))

    def pose_covariances(self, poses: np.ndarray, speeds: np.ndarray, periods: np.ndarray
                         ) -> np.ndarray:
        """Covariances of dead-reckoned ``poses`` (n, 3), eq. (3) plus the floor.

        ``speeds[k]`` (n - 1, 2) led from pose ``k`` to ``k + 1`` over ``periods[k]`` whole
        periods (more than one after lost frames): the growth scales with the periods.
        """
        periods = np.asarray(periods, dtype=float)
        speeds = np.asarray(speeds, dtype=float)
        dt = periods * self.dt_s
        # a step of m periods holds their mean speed: its error is S / m, over m dt
        per_step = self.growth_cov[None] / periods[:, None, None]
        if self.wheel_variance_per_m > 0 and self.intrinsics is not None:
            per_step = per_step + wheel_walk_step_covariances(
                speeds, dt, wheel_base_m=self.intrinsics.wheel_base_m,
                wheel_variance_per_m=self.wheel_variance_per_m)
        growth = grow_pose_covariances(poses, speeds, dt, per_step)
        if self.intrinsics_covariance is not None:
            s = intrinsics_sensitivities(poses, speeds, dt, self.intrinsics)
            growth = growth + s @ self.intrinsics_covariance @ np.swapaxes(s, 1, 2)
        return growth + self.pose_floor

