"""The textbook baseline: a stock filterpy EKF with the velocity motion model.

What a robot builder without a calibrated model runs (robot_localization's
differential-drive mode works the same way): the commanded body speeds taken at
face value, integrated along the arc, with additive speed noise propagated into
the pose (Thrun, Burgard & Fox 2005, table 7.2, lines 3-7), and range-bearing
landmark updates (table 7.2, lines 10-21). It is the reference the model-driven
filter is measured against on real data (``lti_motion.app.mrclam``).

The arc and its Jacobians are those of :func:`lti_motion.kinematics.pose_step` and
:func:`lti_motion.kinematics.pose_step_jacobians`, in scalar arithmetic (chord form, eq. 11 of the
paper; the same exact arc as Thrun's table 5.3, without its ``1/w``
singularity); the measurement is :mod:`fusion.range_bearing`. The landmark
updates, their gate and their records are the model filter's
(:class:`fusion.ekf.GatedUpdates`): the same ``update_landmark(id,
(r, b))`` and ``update_landmarks(sightings)`` on a
:class:`~fusion.landmark_map.LandmarkMap`, the same
:class:`~fusion.ekf.UpdateRecord` and ``stats``.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Mapping
from typing import Literal

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from fusion.ekf.updates import GatedUpdates
from fusion.exceptions import FilterOptionError, MeasurementShapeError
from fusion.landmark_map import LandmarkMap
from fusion.noise import LandmarkNoise
from lti_motion.exceptions import NonFiniteError
from lti_motion.kinematics import pose_step, sinc_and_derivative

__all__ = ["VelocityModelEKF"]


class VelocityModelEKF(GatedUpdates, ExtendedKalmanFilter):
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
    landmarks : LandmarkMap or mapping, optional
        Known landmark positions, for :meth:`update_landmark` and
        :meth:`update_landmarks`.
    landmark_noise : LandmarkNoise, optional
        Range-bearing noise of sightings without a covariance of their own
        (default 2% of range, 1 degree), at the predicted range.
    gate_probability : float or None
        Chi-square gate of the landmark updates (2 degrees of freedom);
        ``None`` fuses everything.
    unknown_landmarks : {"count", "raise"}
        What a sighting of an id not in the map does.
    history : int
        How many update records :attr:`records` keeps (0: none).

    Raises
    ------
    MeasurementShapeError
        If ``speed_cov`` is not (2, 2).
    FilterOptionError
        For an impossible option: ``dt_s`` not positive, ``speed_cov`` not
        finite, symmetric and positive semi-definite (a negative noise),
        ``pose_std`` not three positive numbers, a gate probability outside
        (0, 1) (``None`` fuses everything) or an unknown ``unknown_landmarks``.

    Examples
    --------
    >>> ekf = VelocityModelEKF(dt_s=0.1, speed_cov=np.diag([1e-4, 1e-3]),
    ...                        landmarks={7: (2.0, 0.0)})
    >>> ekf.predict(np.array([0.5, 0.0]))
    >>> rec = ekf.update_landmark(7, np.array([1.96, 0.0]))
    >>> rec.accepted, round(rec.t_s, 3), (ekf.x.round(4) + 0.0).tolist()
    (True, 0.1, [0.0494, 0.0, 0.0])
    """

    def __init__(self, *, dt_s: float, speed_cov: np.ndarray,
                 initial_pose: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0),
                 pose_std: tuple[float, float, float] = (0.01, 0.01, 0.01),
                 landmarks: LandmarkMap | Mapping[Hashable, tuple[float, float]] | None = None,
                 landmark_noise: LandmarkNoise | None = None,
                 gate_probability: float | None = 0.999,
                 unknown_landmarks: Literal["count", "raise"] = "count",
                 history: int = 10_000) -> None:
        super().__init__(dim_x=3, dim_z=2, dim_u=2)
        m = np.asarray(speed_cov, float)
        if m.shape != (2, 2):
            raise MeasurementShapeError(f"speed_cov must be (2, 2), got {m.shape}")
        if not (isinstance(dt_s, (int, float)) and math.isfinite(dt_s) and dt_s > 0):
            raise FilterOptionError(f"dt_s must be a positive number of seconds, got {dt_s!r}")
        if not (np.all(np.isfinite(m)) and np.allclose(m, m.T)
                and np.linalg.eigvalsh(0.5 * (m + m.T)).min() >= 0):
            raise FilterOptionError(f"speed_cov must be finite, symmetric and positive "
                                    f"semi-definite (no negative noise), got {m.tolist()}")
        std = np.asarray(pose_std, float)
        if std.shape != (3,) or not (np.all(np.isfinite(std)) and np.all(std > 0)):
            raise FilterOptionError(f"pose_std must be three positive numbers, got {pose_std}")
        self._init_updates(gate_probability=gate_probability, landmarks=landmarks,
                           landmark_noise=landmark_noise, unknown_landmarks=unknown_landmarks,
                           history=history)
        self.dt_s = float(dt_s)
        self.t_s = 0.0
        self.speed_cov = m
        self.x = np.array(initial_pose, float)
        self.P = np.diag(np.square(std))

    def predict_x(self, speeds: np.ndarray = 0) -> None:
        """The arc of one period (filterpy's hook for a non-linear ``f``)."""
        self.x = pose_step(self.x, speeds[0], speeds[1], self.dt_s)

    def predict(self, speeds: np.ndarray = 0, B: None = None, F: None = None,
                Q: None = None) -> None:
        """One period at body speeds ``speeds = (v [m/s], w [rad/s])``; adds ``dt_s`` to ``t_s``.

        ``F = d pose' / d pose`` and ``Q = V M V^T`` with ``V = d pose' / d (v, w)``
        (Thrun et al. 2005, table 7.2, lines 3-7), then filterpy's ``P = F P F^T + Q`` and
        its prior copies. The arc (paper eq. 11, chord form: ``h = w dt / 2``,
        ``c = v dt sin(h) / h``, ``x' = x + c cos(theta + h)``, ``y' = y + c sin(theta +
        h)``, ``theta' = theta + 2 h``) and its Jacobians are those of
        :func:`lti_motion.kinematics.pose_step_jacobians`, in scalar arithmetic (it runs
        at every period).

        Raises
        ------
        lti_motion.exceptions.NonFiniteError
            If a speed is not finite (as :func:`~lti_motion.kinematics.pose_step`).
        """
        v, w = float(speeds[0]), float(speeds[1])
        if not (math.isfinite(v) and math.isfinite(w)):
            raise NonFiniteError(f"body speeds must be finite, got {[v, w]}")
        px, py, theta = self.x.tolist()
        dt = self.dt_s
        h = 0.5 * w * dt
        sinc, dsinc = sinc_and_derivative(h)
        cm, sm = math.cos(theta + h), math.sin(theta + h)
        chord = v * dt * sinc
        k = 0.5 * v * dt * dt
        self.F = np.array(((1.0, 0.0, -chord * sm), (0.0, 1.0, chord * cm), (0.0, 0.0, 1.0)))
        f_speed = np.array(((dt * sinc * cm, k * (dsinc * cm - sinc * sm)),
                            (dt * sinc * sm, k * (dsinc * sm + sinc * cm)),
                            (0.0, dt)))
        self.Q = f_speed @ self.speed_cov @ f_speed.T
        self.x = np.array((px + chord * cm, py + chord * sm, theta + 2.0 * h))
        self.P = self.F @ self.P @ self.F.T + self.Q
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()     # as filterpy's predict
        self.t_s += self.dt_s
