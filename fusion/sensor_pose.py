"""Where a range-bearing sensor sits on the robot: its planar mount pose.

A camera or a laser is rarely at the axle centre, the point whose pose
``(x, y, theta)`` the estimators carry. :class:`SensorPose` holds the
sensor's origin ``(x_m, y_m)`` in the robot frame (x forward, y left, at the
axle centre) and the direction ``yaw_rad`` its bearings are measured from
(counter-clockwise from the robot's heading). With the robot at
``(x, y, theta)`` the sensor is at

.. math::

    p_s = \\begin{bmatrix} x \\\\ y \\end{bmatrix}
          + R(\\theta) \\begin{bmatrix} s_x \\\\ s_y \\end{bmatrix},
    \\qquad \\theta_s = \\theta + s_\\psi,

the composition of two planar poses (Thrun, Burgard & Fox 2005, sec. 6.6.1;
a ``wTb * bTs`` of ``gtsam.Pose2``). The measurement model that uses it is
:func:`fusion.range_bearing.range_bearing`; a
:class:`fusion.range_bearing.RangeBearing` carries the mount of the sensor
that saw its rows (default :data:`CENTRED`).

References
----------
S. Thrun, W. Burgard, D. Fox, *Probabilistic Robotics*, MIT Press 2005,
sec. 6.6.1 (feature-based measurements, sensor mounted off the robot centre).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fusion.exceptions import MeasurementShapeError, NonFiniteInputError

__all__ = ["CENTRED", "SensorPose", "as_sensor_pose"]


@dataclass(frozen=True)
class SensorPose:
    """The planar pose of a range-bearing sensor in the robot frame.

    Parameters
    ----------
    x_m : float
        Sensor origin ahead of the axle centre [m].
    y_m : float
        Sensor origin left of the axle centre [m].
    yaw_rad : float
        Direction bearings are measured from, counter-clockwise from the
        robot's heading [rad].

    Raises
    ------
    NonFiniteInputError
        If a value is NaN or infinite.

    Examples
    --------
    >>> cam = SensorPose(0.15, 0.0, 0.0)
    >>> cam.is_centred, SensorPose().is_centred
    (False, True)
    >>> (cam.world_xy(np.array([1.0, 2.0, np.pi / 2])).round(12) + 0.0).tolist()
    [1.0, 2.15]
    """

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x_m", "y_m", "yaw_rad"):
            value = float(getattr(self, name))
            if not math.isfinite(value):
                raise NonFiniteInputError(f"SensorPose.{name} must be finite, got {value}")
            object.__setattr__(self, name, value)

    @property
    def is_centred(self) -> bool:
        """Whether the sensor sits at the axle centre, facing the heading (all zero)."""
        return self.x_m == 0.0 and self.y_m == 0.0 and self.yaw_rad == 0.0

    def world_xy(self, pose: np.ndarray) -> np.ndarray:
        """The sensor's position in the world for robot poses (module equation).

        Parameters
        ----------
        pose : array_like, shape (..., >= 3)
            Robot poses ``(x [m], y [m], theta [rad])`` (the first three entries).

        Returns
        -------
        ndarray, shape (..., 2)
            ``(x, y) + R(theta) (x_m, y_m)`` [m].
        """
        p = np.asarray(pose, dtype=float)
        c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
        return np.stack([p[..., 0] + c * self.x_m - s * self.y_m,
                         p[..., 1] + s * self.x_m + c * self.y_m], axis=-1)


#: The sensor at the axle centre, facing the heading: the default of every sighting.
CENTRED = SensorPose()


def as_sensor_pose(value: SensorPose | Sequence[float] | None) -> SensorPose:
    """A :class:`SensorPose` from itself, ``None`` (:data:`CENTRED`) or ``(x_m, y_m, yaw_rad)``.

    Raises
    ------
    MeasurementShapeError
        If ``value`` is neither a SensorPose nor three numbers.
    NonFiniteInputError
        If a value is not finite.

    Examples
    --------
    >>> as_sensor_pose((0.2, 0.0, 0.0))
    SensorPose(x_m=0.2, y_m=0.0, yaw_rad=0.0)
    >>> as_sensor_pose(None) is CENTRED
    True
    """
    if value is None:
        return CENTRED
    if isinstance(value, SensorPose):
        return value
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.shape != (3,):
        raise MeasurementShapeError(
            f"a sensor pose is SensorPose(x_m, y_m, yaw_rad) or three numbers, got {value!r}")
    return SensorPose(*arr.tolist())
