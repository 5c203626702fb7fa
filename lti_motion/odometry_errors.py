"""How wrong encoder odometry gets along a path: the error model a calibration measures.

Dead reckoning from wheel encoders is wrong for two reasons (Borenstein & Feng 1996;
Kelly 2004): *systematic* errors, the intrinsics' own error left after calibration, the
same at every step; and *non-systematic* ones, slip and uneven floor, fresh at every step.
Both are measured where there is a pose reference, in the intrinsics calibration
(:mod:`lti_motion.calibration.odometry_walk`), and carried with the model
(:attr:`lti_motion.model.MotionModel.odometry_errors`); the model's output noise ``R``
is *not* this error (it is the model's one-step prediction error of speeds the encoders
measure exactly, which holds speed changes the model did not predict).

**Non-systematic: a random walk per metre of wheel travel.** Chong & Kleeman (1997,
eq. 4) take each wheel's travel error over a step as independent, of variance
proportional to the distance it rolled:

.. math::  \\sigma_L^2 = k\\,|\\Delta s_L|, \\qquad \\sigma_R^2 = k\\,|\\Delta s_R|    (1)

with one ``k`` [m^2/m] for both wheels. Through ``ds = (s_L + s_R) / 2``, ``dtheta =
(s_R - s_L) / b`` the step's ``(ds, dtheta)`` covariance is

.. math::  \\Sigma = \\begin{pmatrix} (|s_L| + |s_R|)/4 & (|s_R| - |s_L|)/(2b) \\\\
           (|s_R| - |s_L|)/(2b) & (|s_L| + |s_R|)/b^2 \\end{pmatrix} k                (2)

and it is grown along the path with paper eq. 11's Jacobians
(:func:`lti_motion.odometry_noise.grow_pose_covariances`; Chong & Kleeman eq. 8-9).

**Systematic: the intrinsics' covariance.** A pose integrated with intrinsics ``p = (k_L,
k_R, b)`` that are off by ``dp`` is off by ``S_n dp``, the sensitivities accumulated
along the path

.. math::  S_{n+1} = F_n S_n + G_n\\, \\partial(v, w)/\\partial p                       (3)

(``F, G`` the step's Jacobians, paper eq. 11; Kelly 2004, sec. 3, the linearised
propagation of a systematic error), so it carries ``S_n \\Sigma_p S_n^T`` with
``\\Sigma_p`` the calibration's covariance of ``p``. It grows with the distance (not its
square root) and correlates every pose of a path.

What neither represents: slip that depends on the manoeuvre (a turn faster than the
calibration drive's scrubs more), which the calibration absorbs into its effective
intrinsics for its own manoeuvres only (``docs/guide_ros_config.md``).

References
----------
J. Borenstein, L. Feng, "Measurement and correction of systematic odometry errors in
mobile robots", IEEE T-RA 12(6):869-880, 1996 (systematic and non-systematic errors).
K. S. Chong, L. Kleeman, "Accurate odometry and error modelling for a mobile robot",
ICRA 1997, pp. 2783-2788, eq. 4 (variance proportional to each wheel's travel), 8-9.
A. Kelly, "Linearized error propagation in odometry", IJRR 23(2):179-218, 2004, sec. 3.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lti_motion.exceptions import ShapeError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import pose_step_jacobians

__all__ = ["OdometryErrors", "intrinsics_sensitivities", "wheel_walk_step_covariances"]


@dataclass(frozen=True)
class OdometryErrors:
    """Encoder odometry's error model, as measured by an intrinsics calibration.

    Attributes
    ----------
    wheel_variance_per_m : float
        ``k`` of eq. (1): each wheel's travel variance per metre it rolls [m^2/m]
        (0 when the calibration saw no growth above its reference's noise).
    intrinsics_covariance : ndarray, shape (3, 3)
        Covariance of the calibrated ``(k_L [m/tick], k_R [m/tick], b [m])``.
    wheel_variance_std : float
        Standard error of ``k`` [m^2/m] from the fit.
    source : str
        Where the numbers were measured, for people.

    Raises
    ------
    ValueError
        A negative or non-finite variance, a covariance that is not (3, 3), symmetric and
        positive semi-definite.

    Examples
    --------
    >>> e = OdometryErrors(1e-6, np.diag([1e-14, 1e-14, 1e-8]), 2e-7, "test")
    >>> OdometryErrors.from_dict(e.as_dict()) == e
    True
    """

    wheel_variance_per_m: float
    intrinsics_covariance: np.ndarray
    wheel_variance_std: float = 0.0
    source: str = ""

    def __post_init__(self) -> None:
        setf = object.__setattr__
        for name in ("wheel_variance_per_m", "wheel_variance_std"):
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"OdometryErrors.{name} must be a finite number >= 0, got "
                                 f"{value}")
            setf(self, name, value)
        cov = np.array(self.intrinsics_covariance, dtype=float)
        if cov.shape != (3, 3) or not np.all(np.isfinite(cov)):
            raise ValueError(f"OdometryErrors.intrinsics_covariance must be a finite (3, 3) "
                             f"covariance of (k_L, k_R, b), got shape {cov.shape}")
        cov = 0.5 * (cov + cov.T)
        if np.min(np.linalg.eigvalsh(cov)) < -1e-12 * max(np.max(np.abs(cov)), 1e-300):
            raise ValueError("OdometryErrors.intrinsics_covariance must be positive "
                             "semi-definite")
        cov.flags.writeable = False
        setf(self, "intrinsics_covariance", cov)
        setf(self, "source", str(self.source))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, OdometryErrors):
            return NotImplemented
        return (self.wheel_variance_per_m == other.wheel_variance_per_m
                and self.wheel_variance_std == other.wheel_variance_std
                and self.source == other.source
                and np.array_equal(self.intrinsics_covariance, other.intrinsics_covariance))

    __hash__ = None  # type: ignore[assignment]

    def as_dict(self) -> dict:
        """The numbers by name (for model files)."""
        return {"wheel_variance_per_m": self.wheel_variance_per_m,
                "wheel_variance_std": self.wheel_variance_std,
                "intrinsics_covariance": self.intrinsics_covariance.tolist(),
                "source": self.source}

    @classmethod
    def from_dict(cls, doc: dict) -> OdometryErrors:
        """The inverse of :meth:`as_dict`."""
        return cls(float(doc["wheel_variance_per_m"]), np.asarray(doc["intrinsics_covariance"]),
                   float(doc.get("wheel_variance_std", 0.0)), str(doc.get("source", "")))


def wheel_walk_step_covariances(speeds: np.ndarray, dt_s: np.ndarray | float, *,
                                wheel_base_m: float, wheel_variance_per_m: float) -> np.ndarray:
    """Eq. (2) per step, as the covariance of the step's mean speeds ``(v, w)``.

    Parameters
    ----------
    speeds : ndarray, shape (n, 2)
        ``(v [m/s], w [rad/s])`` of each step.
    dt_s : float or ndarray, shape (n,)
        Each step's length [s].
    wheel_base_m : float
        ``b`` [m].
    wheel_variance_per_m : float
        ``k`` [m^2/m].

    Returns
    -------
    ndarray, shape (n, 2, 2)
        ``Sigma / dt^2`` [(m/s)^2, (rad/s)^2]: what
        :func:`lti_motion.odometry_noise.grow_pose_covariances` takes.

    Examples
    --------
    A metre straight in one second: each wheel 1 m, ``var(ds) = k / 2``:

    >>> c = wheel_walk_step_covariances(np.array([[1.0, 0.0]]), 1.0, wheel_base_m=0.2,
    ...                                 wheel_variance_per_m=1e-4)
    >>> (c[0].round(8) + 0.0).tolist()
    [[5e-05, 0.0], [0.0, 0.005]]
    """
    speeds = np.asarray(speeds, dtype=float)
    if speeds.ndim != 2 or speeds.shape[1] != 2:
        raise ShapeError(f"expected speeds of shape (n, 2) (v, w), got {speeds.shape}")
    dt = np.broadcast_to(np.asarray(dt_s, dtype=float), (len(speeds),))
    b = float(wheel_base_m)
    s_l = np.abs((speeds[:, 0] - 0.5 * b * speeds[:, 1]) * dt)      # wheel travel [m]
    s_r = np.abs((speeds[:, 0] + 0.5 * b * speeds[:, 1]) * dt)
    out = np.empty((len(speeds), 2, 2))
    out[:, 0, 0] = 0.25 * (s_l + s_r)                                # eq. (2)
    out[:, 0, 1] = out[:, 1, 0] = 0.5 * (s_r - s_l) / b
    out[:, 1, 1] = (s_l + s_r) / b**2
    return out * (float(wheel_variance_per_m) / dt**2)[:, None, None]


def intrinsics_sensitivities(poses: np.ndarray, speeds: np.ndarray, dt_s: np.ndarray | float,
                             intrinsics: OdometryIntrinsics) -> np.ndarray:
    """``S_n = d pose_n / d (k_L, k_R, b)`` along a dead-reckoned path, eq. (3).

    Parameters
    ----------
    poses : ndarray, shape (n, 3)
        The poses; pose ``k + 1`` follows pose ``k`` by ``speeds[k]`` over ``dt_s``.
    speeds : ndarray, shape (n - 1, 2)
        ``(v [m/s], w [rad/s])`` of each step, computed with ``intrinsics``.
    dt_s : float or ndarray, shape (n - 1,)
        Each step's length [s].
    intrinsics : OdometryIntrinsics
        The intrinsics the speeds were computed with.

    Returns
    -------
    ndarray, shape (n, 3, 3)
        ``S_0 = 0`` (the start is given).

    Notes
    -----
    With wheel travels ``s = k n`` fixed by the counts ``n``: ``v = (k_L n_L + k_R n_R) /
    (2 dt)``, ``w = (k_R n_R - k_L n_L) / (b dt)``, so ``dv/dk_L = s_L / (2 k_L dt)``,
    ``dw/dk_L = -s_L / (k_L b dt)``, ``dv/dk_R = s_R / (2 k_R dt)``, ``dw/dk_R = s_R /
    (k_R b dt)``, ``dw/db = -w / b``.

    Examples
    --------
    Two metres straight: ``dx/dk_L = dx/dk_R = n / 2 = 1 / (2 k)`` per metre, each:

    >>> k = OdometryIntrinsics.symmetric(m_per_tick=1e-3, wheel_base_m=0.2)
    >>> poses = np.column_stack([np.linspace(0, 2, 3), np.zeros(3), np.zeros(3)])
    >>> s = intrinsics_sensitivities(poses, np.tile([1.0, 0.0], (2, 1)), 1.0, k)
    >>> (s[-1, 0].round(6) + 0.0).tolist()
    [1000.0, 1000.0, 0.0]
    """
    poses = np.asarray(poses, dtype=float)
    speeds = np.asarray(speeds, dtype=float)
    n = len(poses)
    if poses.ndim != 2 or poses.shape[1] != 3 or speeds.shape != (n - 1, 2):
        raise ShapeError(f"expected poses (n, 3) and speeds (n - 1, 2), got {poses.shape} "
                         f"and {speeds.shape}")
    dt = np.broadcast_to(np.asarray(dt_s, dtype=float), (n - 1,))
    out = np.zeros((n, 3, 3))
    if n == 1:
        return out
    kl, kr, b = intrinsics.m_per_tick_left, intrinsics.m_per_tick_right, intrinsics.wheel_base_m
    v, w = speeds[:, 0], speeds[:, 1]
    s_l, s_r = (v - 0.5 * b * w) * dt, (v + 0.5 * b * w) * dt       # wheel travel [m]
    d = np.zeros((n - 1, 2, 3))                                       # d (v, w) / d p
    d[:, 0, 0] = s_l / (2 * kl * dt)
    d[:, 0, 1] = s_r / (2 * kr * dt)
    d[:, 1, 0] = -s_l / (kl * b * dt)
    d[:, 1, 1] = s_r / (kr * b * dt)
    d[:, 1, 2] = -w / b
    f_pose, f_speed = pose_step_jacobians(poses[:-1], v, w, dt)
    added = f_speed @ d                                               # G dvw/dp, all at once
    s = out[0]
    for k in range(n - 1):                                            # eq. (3), sequential
        s = f_pose[k] @ s + added[k]
        out[k + 1] = s
    return out
