"""The textbook baseline: a stock filterpy EKF with the velocity motion model.

What a robot builder without a calibrated model runs (robot_localization's
differential-drive mode works the same way): the commanded body speeds taken at
face value, integrated along the arc, with additive speed noise propagated into
the pose (Thrun, Burgard & Fox 2005, table 7.2, lines 3-7), and range-bearing
landmark updates (table 7.2, lines 10-21). It is the reference the model-driven
filter is measured against on real data (``lti_motion.app.mrclam``).

The arc and its Jacobians are :func:`lti_motion.kinematics.pose_step` and
:func:`lti_motion.kinematics.pose_step_jacobians` (chord form, eq. 11 of the
paper; the same exact arc as Thrun's table 5.3, without its ``1/w``
singularity); the measurement is :mod:`fusion.landmark_map`.
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from fusion.exceptions import MeasurementShapeError
from fusion.noise import LandmarkNoise, gate_threshold, nis
from fusion.range_bearing import range_bearing, range_bearing_jacobian, range_bearing_residual
from lti_motion.kinematics import pose_step, pose_step_jacobians

__all__ = ["VelocityModelEKF"]


class VelocityModelEKF(ExtendedKalmanFilter):
    """Stock filterpy EKF on ``(x [m], y [m], theta [rad])`` driven by commanded ``(v, w)``.

    Parameters
    ----------
    dt_s : float
        Period of :meth:`predict` [s].
    speed_cov : array_like, shape (2, 2)
        Covariance of the commanded speeds' error ``(v [m/s], w [rad/s])``
        per period (Thrun's ``M_t``, here constant).
    initial_pose : array_like, shape (3,)
    pose_std : tuple of float
        Initial standard deviations ``(x [m], y [m], theta [rad])``.
    landmark_noise : LandmarkNoise
        Range-bearing noise.
    gate_probability : float
        Chi-square gate of the landmark updates (2 degrees of freedom).
    """

    def __init__(self, *, dt_s: float, speed_cov: np.ndarray,
                 initial_pose: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0),
                 pose_std: tuple[float, float, float] = (0.01, 0.01, 0.01),
                 landmark_noise: LandmarkNoise | None = None,
                 gate_probability: float = 0.999) -> None:
        super().__init__(dim_x=3, dim_z=2, dim_u=2)
        m = np.asarray(speed_cov, float)
        if m.shape != (2, 2):
            raise MeasurementShapeError(f"speed_cov must be (2, 2), got {m.shape}")
        self.dt_s = float(dt_s)
        self.speed_cov = m
        self.x = np.array(initial_pose, float)
        self.P = np.diag(np.square(pose_std))
        self.landmark_noise = landmark_noise or LandmarkNoise()
        self.gate = gate_threshold(gate_probability, 2)
        self.fused = self.gated = 0

    def predict_x(self, u: np.ndarray = 0) -> None:
        """The arc of one period (filterpy's hook for a non-linear ``f``)."""
        self.x = pose_step(self.x, u[0], u[1], self.dt_s)

    def predict(self, u: np.ndarray = 0, B: None = None, F: None = None,
                Q: None = None) -> None:
        """One period with commanded ``u = (v [m/s], w [rad/s])``.

        ``F = d pose' / d pose`` and ``Q = V M V^T`` with ``V = d pose' / d (v, w)``
        (Thrun et al. 2005, table 7.2, lines 3-7).
        """
        f_pose, f_speed = pose_step_jacobians(self.x, u[0], u[1], self.dt_s)
        self.F = f_pose
        self.Q = f_speed @ self.speed_cov @ f_speed.T
        super().predict(u=u)

    def update_landmark(self, landmark_xy: np.ndarray, z: np.ndarray) -> bool:
        """Fuse one ``(range [m], bearing [rad])`` of a known landmark; ``False`` if gated."""
        R = self.landmark_noise.cov(float(z[0]))
        H = range_bearing_jacobian(self.x, landmark_xy)[:, :3]
        z = np.asarray(z, float)
        innovation = range_bearing_residual(z, range_bearing(self.x, landmark_xy))
        S = H @ self.P @ H.T + R
        if nis(innovation, np.linalg.inv(S)) > self.gate:
            self.gated += 1
            return False
        self.update(z, lambda x: range_bearing_jacobian(x, landmark_xy)[:, :3],
                    lambda x: range_bearing(x, landmark_xy), R=R,
                    residual=range_bearing_residual)
        self.fused += 1
        return True
