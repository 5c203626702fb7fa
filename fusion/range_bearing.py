"""Landmarks at known positions, seen as range and bearing from the robot.

A camera that detects fiducial markers (ArUco) or a laser that finds
reflectors reports, per detected landmark, its id, its distance ``r`` [m] and
its bearing ``b`` [rad] in the robot frame (counter-clockwise from the
heading). With the robot at pose ``(x, y, theta)`` and the landmark at
``(l_x, l_y)`` in the world frame,

.. math::

    r = \\sqrt{(l_x - x)^2 + (l_y - y)^2}, \\qquad
    b = \\operatorname{atan2}(l_y - y,\\, l_x - x) - \\theta,

with ``b`` wrapped to ``(-pi, pi]`` (Thrun, Burgard & Fox 2005, table 6.4 and
eq. 6.40). Residuals of bearings are wrapped too
(:func:`range_bearing_residual`), so a landmark seen just across the
``+-pi`` seam does not produce a residual of almost ``2 pi``.

This module holds the measurement model for one pose (the filter lifts it to
its state in :mod:`fusion.ekf.functions`) and the observation type. The map is
:class:`fusion.landmark_map.LandmarkMap`, the sensor's noise
:class:`fusion.noise.LandmarkNoise`.
"""

from __future__ import annotations

import math
from collections.abc import Hashable
from dataclasses import dataclass

import numpy as np

from fusion.exceptions import LandmarkGeometryError, MeasurementShapeError
from lti_motion.kinematics import wrap_angle

__all__ = [
    "MIN_RANGE_M",
    "Observations",
    "range_bearing",
    "range_bearing_jacobian",
    "range_bearing_residual",
]


#: Below this predicted range [m] the bearing is undefined (robot on the landmark).
MIN_RANGE_M = 1e-6


def _pose_xy_theta(pose: np.ndarray) -> tuple[float, float, float]:
    if len(pose) < 3:
        raise MeasurementShapeError(f"expected a pose (x, y, theta) of shape (3,), got "
                                    f"{np.shape(pose)}")
    return float(pose[0]), float(pose[1]), float(pose[2])


def range_bearing(pose: np.ndarray, landmark_xy: np.ndarray) -> np.ndarray:
    """Predicted range and bearing of a landmark from a pose.

    Parameters
    ----------
    pose : array_like, shape (3,)
        ``(x [m], y [m], theta [rad])``; longer vectors use their first three
        entries (a filter state whose pose comes first).
    landmark_xy : array_like, shape (2,)
        Landmark position [m].

    Returns
    -------
    ndarray, shape (2,)
        ``(r [m], b [rad])``, ``b`` in ``(-pi, pi]`` (module equations).

    Examples
    --------
    >>> rb = range_bearing(np.array([1.0, 1.0, np.pi / 2]), np.array([1.0, 3.0]))
    >>> (rb.round(12) + 0.0).tolist()
    [2.0, 0.0]
    """
    x, y, theta = _pose_xy_theta(pose)
    dx, dy = float(landmark_xy[0]) - x, float(landmark_xy[1]) - y
    return np.array([math.hypot(dx, dy), _wrap(math.atan2(dy, dx) - theta)])


def _wrap(a_rad: float) -> float:
    """Scalar :func:`lti_motion.kinematics.wrap_angle`: into ``(-pi, pi]``."""
    out = math.pi - (math.pi - a_rad) % (2.0 * math.pi)
    return out + 2.0 * math.pi if out <= -math.pi else out


def range_bearing_jacobian(pose: np.ndarray, landmark_xy: np.ndarray) -> np.ndarray:
    """Jacobian of :func:`range_bearing` with respect to the pose.

    Parameters
    ----------
    pose : array_like, shape (3,)
        ``(x [m], y [m], theta [rad])`` (first three entries of a longer state).
    landmark_xy : array_like, shape (2,)
        Landmark position [m].

    Returns
    -------
    ndarray, shape (2, 3)
        ``[[-dx/r, -dy/r, 0], [dy/r^2, -dx/r^2, -1]]`` with ``(dx, dy)`` the
        landmark minus the robot position (Thrun et al. 2005, table 7.2).

    Raises
    ------
    LandmarkGeometryError
        If the range is below :data:`MIN_RANGE_M` (the bearing is undefined).

    Examples
    --------
    >>> (range_bearing_jacobian(np.zeros(3), np.array([2.0, 0.0])).round(12) + 0.0).tolist()
    [[-1.0, 0.0, 0.0], [0.0, -0.5, -1.0]]
    """
    x, y, _ = _pose_xy_theta(pose)
    dx, dy = float(landmark_xy[0]) - x, float(landmark_xy[1]) - y
    q = dx * dx + dy * dy
    if q < MIN_RANGE_M * MIN_RANGE_M:
        raise LandmarkGeometryError(
            f"the robot at ({x:.6g}, {y:.6g}) stands on the landmark at ({x + dx:.6g}, "
            f"{y + dy:.6g}); the bearing is undefined there")
    r = math.sqrt(q)
    return np.array([[-dx / r, -dy / r, 0.0], [dy / q, -dx / q, -1.0]])


def range_bearing_residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a - b`` for range-bearing vectors, the bearing difference wrapped to ``(-pi, pi]``.

    Parameters
    ----------
    a, b : array_like, shape (..., 2)
        ``(r [m], b [rad])`` pairs.

    Returns
    -------
    ndarray, shape (..., 2)

    Examples
    --------
    >>> range_bearing_residual(np.array([2.0, 3.1]), np.array([1.5, -3.1])).round(6).tolist()
    [0.5, -0.083185]
    """
    d = np.subtract(a, b, dtype=float)
    d[..., 1] = wrap_angle(d[..., 1])
    return d


@dataclass(frozen=True)
class Observations:
    """Range-bearing observations of a drive, in frame order.

    Attributes
    ----------
    frame : ndarray of int, shape (m,)
        Index of the frame (sensor period) each observation belongs to.
    landmark_id : tuple, length m
        Landmark id of each observation.
    range_bearing : ndarray, shape (m, 2)
        ``(r [m], b [rad])``.
    """

    frame: np.ndarray
    landmark_id: tuple[Hashable, ...]
    range_bearing: np.ndarray

    def by_frame(self) -> dict[int, list[tuple[Hashable, np.ndarray]]]:
        """Observations grouped by frame: ``{frame: [(id, (r, b)), ...]}``."""
        out: dict[int, list[tuple[Hashable, np.ndarray]]] = {}
        for k, key, rb in zip(self.frame.tolist(), self.landmark_id, self.range_bearing,
                              strict=True):
            out.setdefault(k, []).append((key, rb))
        return out
