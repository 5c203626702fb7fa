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
its state in :mod:`fusion.ekf_functions`), a landmark map type
(:class:`LandmarkMap`), the sensor's noise model (:class:`LandmarkNoise`), and
:func:`synthetic_observations`, which draws noisy observations from given
poses for simulation and testing.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType

import numpy as np

from fusion.exceptions import (
    FilterOptionError,
    LandmarkGeometryError,
    LandmarkIdError,
    MeasurementShapeError,
    UnknownLandmarkError,
)
from lti_motion.kinematics import wrap_angle

__all__ = [
    "MIN_RANGE_M",
    "LandmarkMap",
    "LandmarkNoise",
    "Observations",
    "range_bearing",
    "range_bearing_jacobian",
    "range_bearing_residual",
    "synthetic_observations",
]

#: Below this predicted range [m] the bearing is undefined (robot on the landmark).
MIN_RANGE_M = 1e-6


@dataclass(frozen=True)
class LandmarkMap:
    """Landmark positions by id: ``id -> (x [m], y [m])`` in the world frame.

    The one map type of the package: the EKF looks positions up by id
    (:meth:`position`), the factor graph (:mod:`fusion.smoother`,
    :func:`fusion.factors.observe_landmarks`) uses the vectorised view
    :attr:`integer_ids` and :attr:`xy_m`, computed once and cached.

    Parameters
    ----------
    positions : mapping of hashable to (x, y)
        Known landmarks; ids are any hashable values (ints, marker names). The
        factor graph keys landmarks by integer (gtsam ``L(id)``), so it needs
        integer ids.

    Raises
    ------
    MeasurementShapeError
        If a position is not two numbers.
    FilterOptionError
        If a position is not finite.

    Examples
    --------
    >>> lm = LandmarkMap({1: (0.5, 0.5), "door": (4.5, 0.5)})
    >>> lm.position("door").tolist(), 7 in lm, lm.unknown([1, 7, 8])
    ([4.5, 0.5], False, (7, 8))
    >>> grid = LandmarkMap.from_arrays([3, 5], [[0.0, 1.0], [2.0, 1.0]])
    >>> grid.integer_ids.tolist(), grid.xy_m[1].tolist(), grid.position(5).tolist()
    ([3, 5], [2.0, 1.0], [2.0, 1.0])
    """

    positions: Mapping[Hashable, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        table = {}
        for key, xy in dict(self.positions).items():
            arr = np.array(xy, dtype=float)
            if arr.shape != (2,):
                raise MeasurementShapeError(
                    f"landmark {key!r} needs a position (x, y) of shape (2,), got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise FilterOptionError(f"landmark {key!r} has a non-finite position {arr}")
            arr.flags.writeable = False
            table[key] = arr
        object.__setattr__(self, "positions", MappingProxyType(table))

    def __contains__(self, landmark_id: object) -> bool:
        return landmark_id in self.positions

    def __len__(self) -> int:
        return len(self.positions)

    @classmethod
    def from_arrays(cls, ids: Iterable[int], xy_m: np.ndarray) -> LandmarkMap:
        """A map from integer ids and their positions, row by row.

        Parameters
        ----------
        ids : array_like of int, shape (k,)
            Distinct landmark ids (e.g. ArUco marker ids).
        xy_m : array_like, shape (k, 2)
            Positions in the world frame [m].

        Raises
        ------
        MeasurementShapeError
            If ``xy_m`` is not ``(k, 2)``.
        LandmarkIdError
            If an id repeats or is not an integer.
        FilterOptionError
            If a position is not finite.
        """
        id_list = list(np.asarray(ids).reshape(-1).tolist())
        xy = np.asarray(xy_m, dtype=float)
        if xy.shape != (len(id_list), 2):
            raise MeasurementShapeError(f"expected xy_m of shape ({len(id_list)}, 2) for "
                                        f"{len(id_list)} ids, got {xy.shape}")
        _check_integer_ids(id_list)
        if len(set(id_list)) != len(id_list):
            repeated = sorted({i for i in id_list if id_list.count(i) > 1})
            raise LandmarkIdError(f"landmark ids must be distinct; repeated: {repeated}")
        return cls(dict(zip(id_list, xy, strict=True)))

    @property
    def ids(self) -> tuple[Hashable, ...]:
        """The known ids, in insertion order."""
        return tuple(self.positions)

    @cached_property
    def integer_ids(self) -> np.ndarray:
        """The ids as a read-only ``int64`` array, shape (k,), in :attr:`ids` order.

        Raises
        ------
        LandmarkIdError
            If an id is not an integer (the factor graph keys landmarks as ``L(id)``).
        """
        ids = list(self.positions)
        _check_integer_ids(ids)
        out = np.array(ids, dtype=np.int64).reshape(-1)
        out.flags.writeable = False
        return out

    @cached_property
    def xy_m(self) -> np.ndarray:
        """The positions as a read-only array [m], shape (k, 2), in :attr:`ids` order."""
        out = np.array(list(self.positions.values()), dtype=float).reshape(-1, 2)
        out.flags.writeable = False
        return out

    def position(self, landmark_id: Hashable) -> np.ndarray:
        """Position ``(x, y)`` [m] of a landmark (read-only array).

        Raises
        ------
        UnknownLandmarkError
            If the id is not in the map; the message lists some known ids.
        """
        try:
            return self.positions[landmark_id]
        except (KeyError, TypeError):
            known = list(self.positions)[:10]
            raise UnknownLandmarkError(
                f"landmark {landmark_id!r} is not in the map (known ids: {known}"
                f"{' ...' if len(self.positions) > 10 else ''}); add it to the LandmarkMap "
                "or drop the observation") from None

    def unknown(self, landmark_ids: Iterable[Hashable]) -> tuple[Hashable, ...]:
        """The ids among ``landmark_ids`` that the map does not hold, in order, without repeats."""
        seen: dict[Hashable, None] = {}
        for key in landmark_ids:
            if key not in self.positions:
                seen.setdefault(key, None)
        return tuple(seen)


def _check_integer_ids(ids: list[Hashable]) -> None:
    bad = [i for i in ids if isinstance(i, bool) or not isinstance(i, (int, np.integer))]
    if bad:
        raise LandmarkIdError(
            f"the factor graph keys landmarks by integer id (gtsam L(id)); got {bad[:5]!r}; "
            "number the landmarks (e.g. by marker id)")


@dataclass(frozen=True)
class LandmarkNoise:
    """Standard deviations of a range-bearing sensor.

    Attributes
    ----------
    range_std_frac : float
        Range noise as a fraction of the range (0.02 = 2%).
    range_std_m : float
        Floor of the range noise [m]; the standard deviation is
        ``max(range_std_m, range_std_frac * r)``.
    bearing_std_rad : float
        Bearing noise [rad].

    Raises
    ------
    FilterOptionError
        If a value is negative or not finite, or the range noise is zero.

    Examples
    --------
    >>> LandmarkNoise(range_std_frac=0.02, bearing_std_rad=0.01).cov(2.0).round(8).tolist()
    [[0.0016, 0.0], [0.0, 0.0001]]
    """

    range_std_frac: float = 0.02
    range_std_m: float = 0.005
    bearing_std_rad: float = math.radians(1.0)

    def __post_init__(self) -> None:
        values = (self.range_std_frac, self.range_std_m, self.bearing_std_rad)
        if not all(math.isfinite(v) and v >= 0 for v in values):
            raise FilterOptionError(f"LandmarkNoise needs finite, non-negative values, got {self}")
        if self.range_std_m == 0 and self.range_std_frac == 0:
            raise FilterOptionError("LandmarkNoise needs range_std_m > 0 or range_std_frac > 0")
        if self.bearing_std_rad == 0:
            raise FilterOptionError("LandmarkNoise needs bearing_std_rad > 0")

    def cov(self, range_m: float) -> np.ndarray:
        """Measurement covariance ``diag(sigma_r^2, sigma_b^2)`` at a range [m, rad]^2, (2, 2)."""
        sr = max(self.range_std_m, self.range_std_frac * abs(range_m))
        return np.array([[sr * sr, 0.0], [0.0, self.bearing_std_rad ** 2]])


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
    >>> range_bearing(np.array([1.0, 1.0, np.pi / 2]), np.array([1.0, 3.0])).round(12).tolist()
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
    >>> range_bearing_jacobian(np.zeros(3), np.array([2.0, 0.0])).tolist()
    [[-1.0, -0.0, 0.0], [0.0, -0.5, -1.0]]
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


def synthetic_observations(
    poses: np.ndarray,
    landmarks: LandmarkMap,
    *,
    dt_s: float,
    rng: np.random.Generator,
    rate_hz: float = 2.0,
    noise: LandmarkNoise | None = None,
    max_range_m: float = math.inf,
) -> Observations:
    """Noisy range-bearing observations of every landmark from a sequence of poses.

    For simulation: give it the simulator's *true* poses; the filter then sees
    only the noisy observations.

    Parameters
    ----------
    poses : ndarray, shape (n, 3)
        Pose at each frame ``(x [m], y [m], theta [rad])``.
    landmarks : LandmarkMap
        The landmarks to observe.
    dt_s : float
        Frame period [s].
    rng : numpy.random.Generator
        Source of the noise (seeded by the caller).
    rate_hz : float
        Observations per second of each landmark; landmark ``j`` is seen on
        frames ``k`` with ``(k + j * stride // n_landmarks) % stride == 0``,
        ``stride = round(1 / (rate_hz dt_s))``, so the landmarks take turns.
    noise : LandmarkNoise, optional
        Noise standard deviations; default 2% of the range (with a 5 mm
        floor) and 1 degree.
    max_range_m : float
        Landmarks farther than this are not seen.

    Returns
    -------
    Observations
        In frame order; frame 0 is never observed (the filter starts there).

    Raises
    ------
    MeasurementShapeError
        If ``poses`` is not ``(n, 3)``.
    FilterOptionError
        If ``rate_hz`` or ``dt_s`` is not positive.
    """
    poses = np.asarray(poses, dtype=float)
    if poses.ndim != 2 or poses.shape[1] != 3:
        raise MeasurementShapeError(f"expected poses of shape (n, 3), got {poses.shape}")
    if not (rate_hz > 0 and dt_s > 0):
        raise FilterOptionError(f"rate_hz and dt_s must be positive, got {rate_hz}, {dt_s}")
    noise = noise or LandmarkNoise()
    stride = max(1, round(1.0 / (rate_hz * dt_s)))
    ids = landmarks.ids
    frames, keys, values = [], [], []
    k_all = np.arange(1, len(poses))
    for j, key in enumerate(ids):
        offset = j * stride // max(1, len(ids))
        ks = k_all[(k_all + offset) % stride == 0]
        lxy = landmarks.position(key)
        d = lxy[None, :] - poses[ks, :2]
        r = np.hypot(d[:, 0], d[:, 1])
        b = np.arctan2(d[:, 1], d[:, 0]) - poses[ks, 2]
        sr = np.maximum(noise.range_std_m, noise.range_std_frac * r)
        r_obs = r + sr * rng.standard_normal(len(ks))
        b_obs = wrap_angle(b + noise.bearing_std_rad * rng.standard_normal(len(ks)))
        seen = r <= max_range_m
        frames.append(ks[seen])
        keys.extend([key] * int(seen.sum()))
        values.append(np.stack([r_obs, b_obs], axis=1)[seen])
    frame = np.concatenate(frames) if frames else np.zeros(0, int)
    rb = np.concatenate(values) if values else np.zeros((0, 2))
    order = np.argsort(frame, kind="stable")
    return Observations(frame=frame[order], landmark_id=tuple(keys[i] for i in order),
                        range_bearing=rb[order])
