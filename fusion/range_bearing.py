"""Landmarks at known positions, seen as range and bearing from a sensor on the robot.

A camera that detects fiducial markers (ArUco) or a laser that finds
reflectors reports, per detected landmark, its id, its distance ``r`` [m] and
its bearing ``b`` [rad] in the sensor frame (counter-clockwise from the
sensor's axis). The sensor sits on the robot at the planar mount pose
``(s_x, s_y, s_psi)`` (:class:`fusion.sensor_pose.SensorPose`; default the
axle centre facing the heading). With the robot at pose ``(x, y, theta)``,
the sensor at ``p_s = (x, y) + R(theta) (s_x, s_y)`` and the landmark at
``(l_x, l_y)`` in the world frame, ``(d_x, d_y) = (l_x, l_y) - p_s`` and
``q = d_x^2 + d_y^2``:

.. math::

    r = \\sqrt{q}, \\qquad
    b = \\operatorname{atan2}(d_y,\\, d_x) - \\theta - s_\\psi,            \\qquad (1)

with ``b`` wrapped to ``(-pi, pi]`` (Thrun, Burgard & Fox 2005, table 6.4 and
eq. 6.40, the sensor displaced as in their sec. 6.6.1). By the chain rule,
with ``(o_x, o_y) = R(theta) (s_x, s_y)`` (``d p_s / d theta = (-o_y, o_x)``),

.. math::

    \\frac{\\partial (r, b)}{\\partial (x, y, \\theta)} =
    \\begin{bmatrix} -d_x/r & -d_y/r & (d_x o_y - d_y o_x)/r \\\\
                    d_y/q & -d_x/q & -(d_x o_x + d_y o_y)/q - 1 \\end{bmatrix},  \\qquad (2)

    \\frac{\\partial (r, b)}{\\partial (l_x, l_y)} =
    \\begin{bmatrix} d_x/r & d_y/r \\\\ -d_y/q & d_x/q \\end{bmatrix},        \\qquad (3)

which for a centred sensor are Thrun et al.'s table 7.2. One function,
:func:`range_bearing_terms`, evaluates (1)-(3), batched; both EKFs (through
:mod:`fusion.ekf.functions`), the factor graph's mounted-sensor factor
(:mod:`fusion.graph.factors`) and the scale test
(:mod:`fusion.monitoring.scale_odometry`) call it. Residuals of bearings are
wrapped too (:func:`range_bearing_residual`), so a landmark seen just across
the ``+-pi`` seam does not produce a residual of almost ``2 pi``.

The one observation type is :class:`RangeBearing`: sightings as columns
(index, id, range, bearing and an optional full 2 x 2 covariance per row)
and the mount of the sensor that took them, which every estimator, detector
and simulated sensor of the package reads or writes. The map is
:class:`fusion.landmark_map.LandmarkMap`, the sensor's noise
:class:`fusion.noise.LandmarkNoise`.

References
----------
S. Thrun, W. Burgard, D. Fox, *Probabilistic Robotics*, MIT Press 2005,
table 6.4, eq. 6.40, sec. 6.6.1 and table 7.2.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Iterator, Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import NamedTuple

import numpy as np

from fusion.exceptions import (
    CovarianceNotPositiveDefiniteError,
    LandmarkGeometryError,
    LandmarkIdError,
    MeasurementShapeError,
    NonFiniteInputError,
)
from fusion.sensor_pose import CENTRED, SensorPose, as_sensor_pose
from lti_motion.kinematics import wrap_angle

__all__ = [
    "MIN_RANGE_M",
    "RangeBearing",
    "range_bearing",
    "range_bearing_jacobian",
    "range_bearing_residual",
    "range_bearing_terms",
]


#: Below this predicted range [m] the bearing is undefined (robot on the landmark).
MIN_RANGE_M = 1e-6
_MIN_Q = MIN_RANGE_M * MIN_RANGE_M


def _pose_array(pose: np.ndarray) -> np.ndarray:
    p = np.asarray(pose, dtype=float)
    if p.ndim == 0 or p.shape[-1] < 3:
        raise MeasurementShapeError(f"expected a pose (x, y, theta) of shape (3,), got "
                                    f"{np.shape(pose)}")
    return p


def range_bearing_terms(pose: np.ndarray, landmark_xy: np.ndarray, *,
                        sensor: SensorPose | np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The measurement model and both its Jacobians, batched: the package's one copy.

    Parameters
    ----------
    pose : array_like, shape (..., >= 3)
        Robot poses ``(x [m], y [m], theta [rad])`` of the axle centre; longer
        vectors use their first three entries (a filter state whose pose
        comes first).
    landmark_xy : array_like, shape (..., 2)
        Landmark positions [m], broadcast against the poses.
    sensor : SensorPose or array_like of shape (..., 3), optional
        The sensor's mount on the robot (default centred); an array holds
        one ``(x_m, y_m, yaw_rad)`` per row, broadcast against the poses (a
        batch of robots with different sensors).

    Returns
    -------
    z : ndarray, shape (..., 2)
        ``(r [m], b [rad])`` from the sensor (module notes), ``b`` in
        ``(-pi, pi]``; ranges floored at :data:`MIN_RANGE_M`.
    H_pose : ndarray, shape (..., 2, 3)
        ``dz / d(x, y, theta)`` (module notes, eq. 2).
    H_landmark : ndarray, shape (..., 2, 2)
        ``dz / d(l_x, l_y)`` (module notes, eq. 3).

    Examples
    --------
    A sensor 0.2 m ahead of the axle sees a landmark 2 m ahead of the axle at 1.8 m:

    >>> z, Hp, Hl = range_bearing_terms(np.zeros(3), np.array([2.0, 0.0]),
    ...                                 sensor=SensorPose(0.2, 0.0, 0.0))
    >>> (z.round(12) + 0.0).tolist(), (Hp.round(6) + 0.0).tolist()
    ([1.8, 0.0], [[-1.0, 0.0, 0.0], [0.0, -0.555556, -1.111111]])
    """
    p = _pose_array(pose)
    lxy = np.asarray(landmark_xy, dtype=float)
    sx, sy, syaw = _mount_columns(sensor)
    if p.ndim == 1 and lxy.shape == (2,) and isinstance(sx, float):     # one sighting
        px, py, theta = p[:3].tolist()
        lx, ly = lxy.tolist()
        r, b, h, g = _terms(px, py, theta, lx, ly, sx, sy, syaw, math)
        return (np.array([r, _wrap(b)]), np.array(h).reshape(2, 3), np.array(g).reshape(2, 2))
    r, b, h, g = _terms(p[..., 0], p[..., 1], p[..., 2], lxy[..., 0], lxy[..., 1], sx, sy, syaw,
                        _NUMPY)
    return (np.stack([r, wrap_angle(b)], axis=-1),
            np.stack(np.broadcast_arrays(*h), axis=-1).reshape((*np.shape(r), 2, 3)),
            np.stack(np.broadcast_arrays(*g), axis=-1).reshape((*np.shape(r), 2, 2)))


class _Functions(NamedTuple):
    cos: Callable
    sin: Callable
    sqrt: Callable
    atan2: Callable


_NUMPY = _Functions(np.cos, np.sin, np.sqrt, np.arctan2)


_FA = float | np.ndarray     # a float, or an array of them (broadcast)


def _terms(px: _FA, py: _FA, theta: _FA, lx: _FA, ly: _FA, sx: _FA, sy: _FA, syaw: _FA,
           f: _Functions | ModuleType) -> tuple[_FA, _FA, tuple[_FA, ...], tuple[_FA, ...]]:
    """Eq. 1-3 once, on floats (``f = math``) or arrays (``f = _NUMPY``): the range, the
    unwrapped bearing, the six pose-Jacobian entries and the four landmark ones, row-major."""
    c, sn = f.cos(theta), f.sin(theta)
    ox, oy = c * sx - sn * sy, sn * sx + c * sy                  # R(theta) (s_x, s_y)
    dx, dy = lx - px - ox, ly - py - oy
    q = dx * dx + dy * dy
    q = q + (q < _MIN_Q) * (_MIN_Q - q)                          # floored at MIN_RANGE_M^2
    r = f.sqrt(q)
    b = f.atan2(dy, dx) - theta - syaw                                               # eq. 1
    h = (-dx / r, -dy / r, (dx * oy - dy * ox) / r,
         dy / q, -dx / q, -(dx * ox + dy * oy) / q - 1.0)                            # eq. 2
    g = (dx / r, dy / r, -dy / q, dx / q)                                            # eq. 3
    return r, b, h, g


def _wrap(a_rad: float) -> float:
    """Scalar :func:`lti_motion.kinematics.wrap_angle`: into ``(-pi, pi]``."""
    out = math.pi - (math.pi - a_rad) % (2.0 * math.pi)
    return out + 2.0 * math.pi if out <= -math.pi else out


def _mount_columns(sensor: SensorPose | np.ndarray | None
                   ) -> tuple[float | np.ndarray, float | np.ndarray, float | np.ndarray]:
    """``(s_x, s_y, s_psi)`` of one mount (floats) or of one mount per row (arrays)."""
    if sensor is None or isinstance(sensor, SensorPose):
        s = as_sensor_pose(sensor)
        return s.x_m, s.y_m, s.yaw_rad
    arr = np.asarray(sensor, dtype=float)
    if arr.ndim < 2:
        s = as_sensor_pose(arr)
        return s.x_m, s.y_m, s.yaw_rad
    if arr.shape[-1] != 3:
        raise MeasurementShapeError(f"expected sensor mounts of shape (..., 3) (x_m, y_m, "
                                    f"yaw_rad), got {arr.shape}")
    if not np.isfinite(arr).all():
        raise NonFiniteInputError("sensor mounts must be finite")
    return arr[..., 0], arr[..., 1], arr[..., 2]


def range_bearing(pose: np.ndarray, landmark_xy: np.ndarray, *,
                  sensor: SensorPose | None = None) -> np.ndarray:
    """Predicted range and bearing of a landmark from a pose.

    Parameters
    ----------
    pose : array_like, shape (..., >= 3)
        ``(x [m], y [m], theta [rad])`` of the axle centre; longer vectors use
        their first three entries (a filter state whose pose comes first).
    landmark_xy : array_like, shape (..., 2)
        Landmark position [m].
    sensor : SensorPose, optional
        The sensor's mount on the robot (default centred).

    Returns
    -------
    ndarray, shape (..., 2)
        ``(r [m], b [rad])`` from the sensor, ``b`` in ``(-pi, pi]`` (module
        notes, eq. 1); :func:`range_bearing_terms` without the Jacobians.

    Examples
    --------
    >>> rb = range_bearing(np.array([1.0, 1.0, np.pi / 2]), np.array([1.0, 3.0]))
    >>> (rb.round(12) + 0.0).tolist()
    [2.0, 0.0]
    """
    return range_bearing_terms(pose, landmark_xy, sensor=sensor)[0]


def range_bearing_jacobian(pose: np.ndarray, landmark_xy: np.ndarray, *,
                           sensor: SensorPose | None = None) -> np.ndarray:
    """Jacobian of :func:`range_bearing` with respect to the robot pose.

    Parameters
    ----------
    pose : array_like, shape (..., >= 3)
        ``(x [m], y [m], theta [rad])`` (first three entries of a longer state).
    landmark_xy : array_like, shape (..., 2)
        Landmark position [m].
    sensor : SensorPose, optional
        The sensor's mount on the robot (default centred).

    Returns
    -------
    ndarray, shape (..., 2, 3)
        Module notes, eq. 2; for a centred sensor ``[[-dx/r, -dy/r, 0],
        [dy/r^2, -dx/r^2, -1]]`` with ``(dx, dy)`` the landmark minus the
        robot position (Thrun et al. 2005, table 7.2).

    Raises
    ------
    LandmarkGeometryError
        If a range is below :data:`MIN_RANGE_M` (the bearing is undefined).

    Examples
    --------
    >>> (range_bearing_jacobian(np.zeros(3), np.array([2.0, 0.0])).round(12) + 0.0).tolist()
    [[-1.0, 0.0, 0.0], [0.0, -0.5, -1.0]]
    """
    z, h_pose, _ = range_bearing_terms(pose, landmark_xy, sensor=sensor)
    if np.any(z[..., 0] <= MIN_RANGE_M):                         # floored: on the landmark
        at = np.broadcast_to(landmark_xy, z.shape)[z[..., 0] <= MIN_RANGE_M].reshape(-1, 2)[0]
        raise LandmarkGeometryError(
            f"the sensor stands on a landmark (at ({at[0]:.6g}, {at[1]:.6g})); the bearing "
            f"is undefined there")
    return h_pose


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



@dataclass(frozen=True, eq=False)
class RangeBearing:
    """Range-bearing sightings of landmarks, one row each: the package's one observation type.

    The EKFs (:meth:`fusion.ekf.ModelEKF.update_landmarks`), the factor graph
    (:meth:`fusion.graph.IncrementalSmoother.add_observations`), the scale test
    (:meth:`fusion.monitoring.ScaleMonitor.update`), the ArUco detector
    (:meth:`fusion.landmarks.MarkerDetector.detect`) and the synthetic sensors
    all read or write this type. Columns of ``k`` rows, validated at
    construction and read-only.

    Parameters
    ----------
    index : int or array_like of int, shape (k,)
        What each row belongs to: the frame (sensor period) it was seen at, or,
        for the smoother, the keyframe. One int stands for every row.
    landmark_id : array_like, shape (k,)
        Landmark ids: any hashable values for the EKFs; integers where the
        factor graph keys landmarks as ``L(id)``. Stored as ``int64`` when all
        are integers, else as an object array.
    range_m : array_like, shape (k,)
        Measured distance [m], positive.
    bearing_rad : array_like, shape (k,)
        Measured bearing in the robot frame, counter-clockwise from the
        heading [rad].
    cov : array_like, shape (k, 2, 2), optional
        Covariance of each row's ``(range [m], bearing [rad])``, symmetric
        positive definite, correlation included. ``None``: the estimator's own
        :class:`fusion.noise.LandmarkNoise` applies.
    sensor_pose : SensorPose or (x_m, y_m, yaw_rad), optional
        Where the sensor that took the rows sits on the robot
        (:class:`fusion.sensor_pose.SensorPose`); ranges and bearings are
        from it (module notes, eq. 1). Default: the axle centre, facing the
        heading.

    Raises
    ------
    MeasurementShapeError
        If a column does not have ``k`` rows, ``cov`` is not ``(k, 2, 2)`` or
        ``index`` does not hold integers.
    NonFiniteInputError
        If a range, bearing or covariance holds NaN or infinity.
    LandmarkGeometryError
        If a range is not positive.
    LandmarkIdError
        If an id is not hashable.
    CovarianceNotPositiveDefiniteError
        If a covariance is not symmetric positive definite.

    Notes
    -----
    The covariance is the sensor's, in the order of the measurement vector
    ``z = (r, b)``; gtsam's ``BearingRange`` measurement runs the other way,
    ``(b, r)``, and :func:`fusion.graph.range_bearing_factors`
    reorders it.

    Examples
    --------
    Two frames of sightings, grouped for a filter loop:

    >>> obs = RangeBearing([3, 3, 5], [7, 9, 7], [2.0, 1.5, 1.8], [0.1, -0.4, 0.2])
    >>> len(obs), obs.landmark_id.dtype, sorted(obs.by_index())
    (3, dtype('int64'), [3, 5])
    >>> [(lid, z.tolist(), cov) for lid, z, cov in obs.by_index()[3]]
    [(7, [2.0, 0.1], None), (9, [1.5, -0.4], None)]

    Ids may be any hashable values, and each row may carry its own covariance:

    >>> one = RangeBearing(4, ["door"], [2.0], [0.3], cov=[[[4e-4, 1e-5], [1e-5, 1e-4]]])
    >>> one.index.tolist(), one.cov.shape
    ([4], (1, 2, 2))

    A camera 0.15 m ahead of the axle:

    >>> RangeBearing(0, [7], [2.0], [0.1], sensor_pose=(0.15, 0.0, 0.0)).sensor_pose
    SensorPose(x_m=0.15, y_m=0.0, yaw_rad=0.0)
    """

    index: np.ndarray
    landmark_id: np.ndarray
    range_m: np.ndarray
    bearing_rad: np.ndarray
    cov: np.ndarray | None = None
    sensor_pose: SensorPose = CENTRED

    def __post_init__(self) -> None:
        range_m = _column(self.range_m, "range_m")
        k = len(range_m)
        bearing = _column(self.bearing_rad, "bearing_rad", k)
        index = _index_column(self.index, k)
        ids = _id_column(self.landmark_id, k)
        if (range_m <= 0).any():
            row = int(np.argmax(range_m <= 0))
            raise LandmarkGeometryError(
                f"RangeBearing.range_m must be positive (a distance [m]); row {row} holds "
                f"{range_m[row]}")
        cov = None if self.cov is None else _cov_column(self.cov, k)
        for name, arr in (("index", index), ("landmark_id", ids), ("range_m", range_m),
                          ("bearing_rad", bearing), ("cov", cov)):
            if arr is not None:
                arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "sensor_pose", as_sensor_pose(self.sensor_pose))

    @classmethod
    def _trusted(cls, index: np.ndarray, landmark_id: np.ndarray, range_m: np.ndarray,
                 bearing_rad: np.ndarray, cov: np.ndarray | None,
                 sensor_pose: SensorPose = CENTRED) -> RangeBearing:
        """Rows of an already validated value (a selection): no checks, columns read-only."""
        out = object.__new__(cls)
        object.__setattr__(out, "sensor_pose", sensor_pose)
        for name, arr in (("index", index), ("landmark_id", landmark_id), ("range_m", range_m),
                          ("bearing_rad", bearing_rad), ("cov", cov)):
            if arr is not None and arr.flags.writeable:
                arr.flags.writeable = False
            object.__setattr__(out, name, arr)
        return out

    @classmethod
    def empty(cls) -> RangeBearing:
        """No sightings (shared: the value is immutable).

        Examples
        --------
        >>> len(RangeBearing.empty()), RangeBearing.empty() is RangeBearing.empty()
        (0, True)
        """
        return _EMPTY

    @classmethod
    def concatenate(cls, parts: Sequence[RangeBearing]) -> RangeBearing:
        """The rows of ``parts``, in order.

        Covariances are kept if every part has them; a mix of parts with and
        without, or parts from sensors at different mount poses, raises
        :class:`~fusion.exceptions.MeasurementShapeError`.

        Examples
        --------
        >>> a = RangeBearing(1, [7], [2.0], [0.1])
        >>> RangeBearing.concatenate([a, RangeBearing(2, ["door"], [1.0], [0.0])]).landmark_id
        array([7, 'door'], dtype=object)
        """
        parts = [p for p in parts if len(p)]
        if not parts:
            return _EMPTY
        if len(parts) == 1:
            return parts[0]
        with_cov = [p.cov is not None for p in parts]
        if any(with_cov) and not all(with_cov):
            raise MeasurementShapeError("cannot concatenate sightings with and without "
                                        "covariances; give every part a cov, or none")
        mounts = {p.sensor_pose for p in parts}
        if len(mounts) > 1:
            raise MeasurementShapeError(f"cannot concatenate sightings of sensors at different "
                                        f"mount poses ({sorted(mounts, key=repr)}); keep one "
                                        f"RangeBearing per sensor")
        ids = [p.landmark_id for p in parts]
        if any(i.dtype != np.int64 for i in ids):
            ids = [i.astype(object) for i in ids]
        return cls._trusted(np.concatenate([p.index for p in parts]), np.concatenate(ids),
                            np.concatenate([p.range_m for p in parts]),
                            np.concatenate([p.bearing_rad for p in parts]),
                            np.concatenate([p.cov for p in parts]) if all(with_cov) else None,
                            parts[0].sensor_pose)

    def __len__(self) -> int:
        return len(self.range_m)

    def __iter__(self) -> Iterator[tuple[Hashable, np.ndarray, np.ndarray | None]]:
        """Rows as ``(landmark_id, z = (r [m], b [rad]) (2,), cov (2, 2) or None)``."""
        covs = self.cov if self.cov is not None else [None] * len(self)
        for lid, r, b, c in zip(self.landmark_id.tolist(), self.range_m.tolist(),
                                self.bearing_rad.tolist(), covs, strict=True):
            yield lid, np.array((r, b)), c

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RangeBearing):
            return NotImplemented
        if (self.cov is None) != (other.cov is None) or self.sensor_pose != other.sensor_pose:
            return False
        return all(np.array_equal(getattr(self, n), getattr(other, n))
                   for n in ("index", "landmark_id", "range_m", "bearing_rad", "cov"))

    __hash__ = None  # type: ignore[assignment]  # holds arrays

    def select(self, rows: np.ndarray | slice) -> RangeBearing:
        """The rows ``rows`` picks (a boolean mask, integer positions or a slice)."""
        return RangeBearing._trusted(self.index[rows], self.landmark_id[rows],
                                     self.range_m[rows], self.bearing_rad[rows],
                                     None if self.cov is None else self.cov[rows],
                                     self.sensor_pose)

    def with_index(self, index: np.ndarray | int) -> RangeBearing:
        """The same sightings attached to other indices (frames to keyframes, say).

        Raises
        ------
        MeasurementShapeError
            If ``index`` is not one integer or ``k`` of them.
        """
        return RangeBearing._trusted(_index_column(index, len(self)), self.landmark_id,
                                     self.range_m, self.bearing_rad, self.cov, self.sensor_pose)

    def by_index(self) -> dict[int, RangeBearing]:
        """The rows grouped by index, ``{index: rows}``, indices ascending, rows in order.

        Group once before a filter loop and look each frame up in the result;
        selecting one frame's rows from the whole drive at every frame would
        scan all rows each time.
        """
        if not len(self):
            return {}
        order = np.argsort(self.index, kind="stable")
        keys, starts = np.unique(self.index[order], return_index=True)
        bounds = [*starts.tolist(), len(order)]
        return {key: self.select(order[bounds[j]:bounds[j + 1]])
                for j, key in enumerate(keys.tolist())}


def _column(values: object, name: str, k: int | None = None) -> np.ndarray:
    arr = np.array(values, dtype=float)
    if arr.ndim != 1 or (k is not None and len(arr) != k):
        raise MeasurementShapeError(f"RangeBearing.{name} has shape {arr.shape}, expected "
                                    f"({'k' if k is None else k},): one value per row")
    if not np.isfinite(arr).all():
        row = int(np.argmin(np.isfinite(arr)))
        raise NonFiniteInputError(f"RangeBearing.{name} holds a non-finite value ({arr[row]}) "
                                  f"in row {row}; drop the sighting instead")
    return arr


def _index_column(values: object, k: int) -> np.ndarray:
    arr = np.asarray(values)
    if arr.ndim == 0:
        arr = np.full(k, arr, dtype=arr.dtype)
    if arr.size == 0:
        arr = np.zeros(0, np.int64)
    if arr.dtype.kind not in "iu":
        raise MeasurementShapeError(f"RangeBearing.index must hold integers (frame or keyframe "
                                    f"numbers), got dtype {arr.dtype}")
    if arr.shape != (k,):
        raise MeasurementShapeError(f"RangeBearing.index has shape {arr.shape}, expected ({k},) "
                                    "or one int for every row")
    return arr.astype(np.int64)


def _id_column(values: object, k: int) -> np.ndarray:
    if isinstance(values, np.ndarray) and values.dtype.kind in "iu":
        arr = values.astype(np.int64)
    else:
        items = values.tolist() if isinstance(values, np.ndarray) else list(values)
        if all(isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))
               for v in items):
            arr = np.array(items, dtype=np.int64).reshape(-1)
        else:
            bad = [v for v in items if not isinstance(v, Hashable)]
            if bad:
                raise LandmarkIdError(f"landmark ids must be hashable, got {bad[0]!r}")
            arr = np.empty(len(items), dtype=object)
            for j, v in enumerate(items):
                arr[j] = v
    if arr.shape != (k,):
        raise MeasurementShapeError(f"RangeBearing.landmark_id has shape {arr.shape}, expected "
                                    f"({k},): one id per row")
    return arr


def _cov_column(values: object, k: int) -> np.ndarray:
    cov = np.array(values, dtype=float)
    if cov.shape != (k, 2, 2):
        raise MeasurementShapeError(f"RangeBearing.cov has shape {cov.shape}, expected "
                                    f"({k}, 2, 2): one (range, bearing) covariance per row")
    if not np.isfinite(cov).all():
        row = int(np.argmin(np.isfinite(cov).all(axis=(1, 2))))
        raise NonFiniteInputError(f"RangeBearing.cov holds a non-finite value in row {row}")
    flat = cov.reshape(k, 4)
    a, b, c, d = flat.T
    ad = a * d
    bad = (abs(b - c) > 1e-9 * np.sqrt(abs(ad))) | ~(a > 0) | ~(ad - b * c > 0)
    if bad.any():
        row = int(np.argmax(bad))
        raise CovarianceNotPositiveDefiniteError(
            f"RangeBearing.cov must be symmetric positive definite; row {row} is "
            f"{cov[row].tolist()}")
    return cov


_EMPTY = RangeBearing(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
