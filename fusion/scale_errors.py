"""What the model filters' scale errors mean: the intrinsics they imply, and their bounds.

The scale-error states are shared by the model EKF (:mod:`fusion.ekf`) and the smoother
(:mod:`fusion.graph`), so their meaning lives in the base of the package.

**The intrinsics they imply.**

:class:`fusion.ekf.ModelEKF` carries the scale errors ``c = (k_v, k_w, kappa)``
of the ground motion against the motion its encoder intrinsics compute from the
counts (:mod:`fusion.ekf.functions`, *Pose noise*). The intrinsics they imply
are :meth:`lti_motion.intrinsics.OdometryIntrinsics.corrected`::

    b'   = b (1 + k_v) / (1 + k_w)
    m_L' = m_L (1 + k_v - kappa b' / 2)
    m_R' = m_R (1 + k_v + kappa b' / 2)                                   (eq. 1)

with ``m_L, m_R`` [m/tick] and ``b`` [m] the intrinsics in use. Their covariance
is the first-order propagation ``J P_cc J^T`` of the scale errors' block of the
filter's covariance (Bar-Shalom, Li & Kirubarajan 2001, section 1.4.15), with
``J = d(m_L', m_R', b') / d(k_v, k_w, kappa)`` (eq. 2, written out in
:func:`corrected_jacobian`); the diameter ratio ``m_L' / m_R'`` has the standard
deviation ``sqrt(g P_cc g^T)``, ``g = (J_0 / m_R' - m_L' J_1 / m_R'^2)``
(eq. 3, ``J_i`` the rows of ``J``).

References
----------
Y. Bar-Shalom, X. R. Li, T. Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, Wiley 2001, section 1.4.15 (propagation of a
covariance through a function).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lti_motion.intrinsics import OdometryIntrinsics

__all__ = ["MAX_RATIO_ERROR", "MAX_SCALE_ERROR", "IntrinsicsEstimate", "corrected_jacobian",
           "intrinsics_estimate"]

#: Largest physically possible relative scale error ``|k_v|``, ``|k_w|``: a ground speed
#: between half and one and a half times the encoder speed (:mod:`fusion.ekf.resets`).
MAX_SCALE_ERROR = 0.5

#: Largest physically possible relative difference of the wheels' diameters, which bounds
#: ``|kappa| <= MAX_RATIO_ERROR / b`` (:mod:`fusion.ekf.resets`).
MAX_RATIO_ERROR = 0.1


@dataclass(frozen=True)
class IntrinsicsEstimate:
    """What the filter's scale errors say of the robot's odometry intrinsics.

    Attributes
    ----------
    intrinsics : OdometryIntrinsics
        The corrected intrinsics (eq. 1).
    scale_errors : tuple of 3 float
        ``(k_v, k_w, kappa [rad/m])`` they come from.
    covariance : ndarray, shape (3, 3)
        Of ``(m_per_tick_left [m/tick], m_per_tick_right [m/tick], wheel_base_m [m])``
        (eq. 2).
    diameter_ratio_std : float
        Standard deviation of ``intrinsics.diameter_ratio`` (left over right, eq. 3).
    t_s : float
        Filter time of the estimate [s].
    """

    intrinsics: OdometryIntrinsics
    scale_errors: tuple[float, float, float]
    covariance: np.ndarray
    diameter_ratio_std: float
    t_s: float

    @property
    def std(self) -> np.ndarray:
        """Standard deviations of ``(m_per_tick_left, m_per_tick_right, wheel_base_m)``, (3,)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))


def corrected_jacobian(intrinsics: OdometryIntrinsics, k_v: float, k_w: float,
                       kappa_rad_per_m: float) -> np.ndarray:
    """``J = d(m_L', m_R', b') / d(k_v, k_w, kappa)`` of eq. 1, shape (3, 3).

    With ``s = 1 + k_w``, ``db'/dk_v = b / s`` and ``db'/dk_w = -b' / s``, so
    ``dm_L'/dk_v = m_L (1 - kappa b / (2 s))``, ``dm_L'/dk_w = m_L kappa b' / (2 s)``,
    ``dm_L'/dkappa = -m_L b' / 2``, and the right wheel's with the sign of
    ``kappa`` flipped.

    Examples
    --------
    >>> k = OdometryIntrinsics.symmetric(m_per_tick=1e-3, wheel_base_m=0.2)
    >>> ((corrected_jacobian(k, 0.0, 0.0, 0.0) * [[1e3], [1e3], [1.0]]).round(6) + 0.0).tolist()
    [[1.0, 0.0, -0.1], [1.0, 0.0, 0.1], [0.2, -0.2, 0.0]]
    """
    m_l, m_r, b = intrinsics.m_per_tick_left, intrinsics.m_per_tick_right, intrinsics.wheel_base_m
    s = 1.0 + k_w
    b_new = b * (1.0 + k_v) / s
    db_v, db_w = b / s, -b_new / s
    half = 0.5 * kappa_rad_per_m
    return np.array([
        [m_l * (1.0 - half * db_v), -m_l * half * db_w, -m_l * 0.5 * b_new],
        [m_r * (1.0 + half * db_v), m_r * half * db_w, m_r * 0.5 * b_new],
        [db_v, db_w, 0.0],
    ])


def intrinsics_estimate(intrinsics: OdometryIntrinsics, scale_errors: np.ndarray,
                        scale_cov: np.ndarray, *, t_s: float = math.nan) -> IntrinsicsEstimate:
    """The intrinsics ``intrinsics.corrected(*scale_errors)`` and their spread (module notes).

    Parameters
    ----------
    intrinsics : OdometryIntrinsics
        The encoder intrinsics the filter maps counts with.
    scale_errors : array_like, shape (3,)
        ``(k_v, k_w, kappa [rad/m])``.
    scale_cov : array_like, shape (3, 3)
        Their covariance (the filter's ``P[SCALES, SCALES]``).
    t_s : float
        Time of the estimate [s], for the record.

    Returns
    -------
    IntrinsicsEstimate

    Raises
    ------
    ValueError
        If the scale errors give a non-positive scale or wheel base, or the shapes
        are wrong.

    Examples
    --------
    >>> k = OdometryIntrinsics.symmetric(m_per_tick=4.4e-4, wheel_base_m=0.235)
    >>> est = intrinsics_estimate(k, [0.0, 0.0, -0.01 / 0.235], np.diag([0, 0, 0.002 ** 2]))
    >>> round(est.intrinsics.diameter_ratio, 5), round(est.diameter_ratio_std, 6)
    (1.01005, 0.000475)
    """
    c = np.asarray(scale_errors, dtype=float)
    P = np.asarray(scale_cov, dtype=float)
    if c.shape != (3,) or P.shape != (3, 3):
        raise ValueError(f"expected scale errors (3,) and their covariance (3, 3), got {c.shape} "
                         f"and {P.shape}")
    k_v, k_w, kappa = c.tolist()
    new = intrinsics.corrected(k_v, k_w, kappa)
    J = corrected_jacobian(intrinsics, k_v, k_w, kappa)          # eq. 2
    cov = J @ P @ J.T
    m_l, m_r = new.m_per_tick_left, new.m_per_tick_right
    g = J[0] / m_r - (m_l / (m_r * m_r)) * J[1]                   # eq. 3
    return IntrinsicsEstimate(new, (k_v, k_w, kappa), 0.5 * (cov + cov.T),
                              math.sqrt(max(float(g @ P @ g), 0.0)), float(t_s))
