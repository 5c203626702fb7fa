"""What both EKFs of the wing share: the gate, the update records and the landmark updates.

:class:`GatedUpdates` is a mixin over filterpy's ``ExtendedKalmanFilter``
(:class:`fusion.ekf.ModelEKF` and :class:`fusion.ekf.VelocityModelEKF` derive
from both). Every update goes through :meth:`GatedUpdates._gated`: the
normalised innovation squared (NIS) ``nu^T S^-1 nu`` against a chi-square
gate (Bar-Shalom, Li & Kirubarajan 2001, section 5.4.2), then a Joseph-form
update (eq. 5.2.3-18, :func:`fusion.ekf.joseph_covariance`), and
returns an :class:`UpdateRecord` that it also appends to ``records`` and
counts in ``stats``. Readings that are never compared (NaN, unknown landmark,
robot on the landmark) are records too (:meth:`GatedUpdates._skip`).

Landmarks: :meth:`GatedUpdates.update_landmark` looks the id up in the
filter's :class:`~fusion.landmark_map.LandmarkMap` and fuses ``(r, b)`` with
the measurement model of :mod:`fusion.range_bearing` on the state's pose (its
first three entries) and the sensor's mount on the robot
(:class:`fusion.sensor_pose.SensorPose`, default centred), with the
sighting's own full 2 x 2 covariance or the filter's
:class:`~fusion.noise.LandmarkNoise` at the predicted range;
:meth:`GatedUpdates.update_landmarks` fuses every row of a
:class:`~fusion.range_bearing.RangeBearing` (one frame's sightings).

References
----------
Y. Bar-Shalom, X. R. Li, T. Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, Wiley 2001, eq. 5.2.3-18 (Joseph form) and section
5.4.2 (NIS).
"""

from __future__ import annotations

import logging
import math
from collections import Counter, deque
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Literal

import numpy as np

from fusion.ekf.functions import (
    joseph_covariance,
    landmark_residual,
    landmark_terms,
)
from fusion.ekf.kernel import kernel_array, selector_update_kernel
from fusion.exceptions import (
    CovarianceNotPositiveDefiniteError,
    FilterOptionError,
    MeasurementShapeError,
    UnknownLandmarkError,
)
from fusion.landmark_map import LandmarkMap
from fusion.noise import LandmarkNoise, gate_threshold, inverse_covariance, nis
from fusion.range_bearing import MIN_RANGE_M, RangeBearing
from fusion.sensor_pose import SensorPose, as_sensor_pose

__all__ = ["FilterStats", "GatedUpdates", "UpdateKind", "UpdateReason", "UpdateRecord"]

_log = logging.getLogger(__name__)

UpdateKind = Literal["encoders", "landmark", "pose", "gyro"]
UpdateReason = Literal["fused", "forced", "gated", "non_finite", "unknown_landmark", "anchor",
                       "gap", "degenerate", "pending", "settling"]


@dataclass(frozen=True, slots=True)
class UpdateRecord:
    """What one update did: the figures a residual monitor reads.

    Attributes
    ----------
    kind : {"encoders", "landmark", "pose", "gyro"}
        The measurement.
    t_s : float
        Filter time of the update [s].
    innovation : ndarray, shape (m,)
        Measurement minus prediction (angles wrapped); NaN when the reading
        was not compared (``reason`` in non_finite, unknown_landmark, anchor,
        gap, degenerate). Read-only.
    innovation_cov : ndarray, shape (m, m)
        ``S = H P H^T + R`` (NaN when not compared). Read-only.
    nis : float
        ``nu^T S^-1 nu`` (NaN when not compared).
    accepted : bool
        Whether the reading was fused.
    reason : str
        ``"fused"``, ``"forced"`` (encoder counts outside the gate fused
        anyway: after ``reanchor_periods`` gated periods both wheels count
        steadily, so the model is what misses, e.g. a start from rest),
        ``"gated"`` (NIS outside the gate), ``"non_finite"``
        (NaN or inf in the reading), ``"unknown_landmark"``, ``"anchor"``
        (first encoder counts: a reference only), ``"gap"`` (counts right
        after others with no ``predict`` between, or more than
        ``max_periods`` periods after the last fused ones: the reference is
        renewed; for a gyro: a second reading after one :meth:`predict`, or a
        period without a reading, which restarts the window), ``"degenerate"``
        (robot on the landmark), ``"pending"`` (a gyro reading summed into
        its window, compared when the window closes), or ``"settling"`` (a
        gyro window in which the robot settled after a stop, not fused:
        :mod:`fusion.ekf.gyro`, *Settling after a stop*). An encoder
        reading after gated, NaN or lost ones spans all the periods since the
        last fused counts (its innovation is the summed speed residual).
    landmark_id : hashable or None
        The landmark, for ``kind="landmark"``.
    """

    kind: UpdateKind
    t_s: float
    innovation: np.ndarray
    innovation_cov: np.ndarray
    nis: float
    accepted: bool
    reason: UpdateReason
    landmark_id: Hashable | None = None


@dataclass(frozen=True)
class FilterStats:
    """Counts of updates by kind and reason (a snapshot).

    Attributes
    ----------
    counts : mapping of (kind, reason) to int
        How many updates of each kind ended each way.
    unknown_landmark_ids : tuple
        Ids seen that the map does not hold, in order of first sight.
    """

    counts: Mapping[tuple[str, str], int]
    unknown_landmark_ids: tuple[Hashable, ...]

    def count(self, kind: UpdateKind, reason: UpdateReason) -> int:
        """Updates of ``kind`` that ended with ``reason``."""
        return self.counts.get((kind, reason), 0)

    def rejected(self, kind: UpdateKind) -> int:
        """Readings of ``kind`` not fused, for any reason but ``"anchor"``."""
        return sum(c for (k, r), c in self.counts.items()
                   if k == kind and r not in ("fused", "anchor"))


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr.flags.writeable = False
    return arr


_NAN2 = _frozen(np.full(2, np.nan))
_NAN22 = _frozen(np.full((2, 2), np.nan))


class GatedUpdates:
    """The gate, the records and the landmark updates of a filterpy EKF (module notes).

    A mixin: a subclass of it and of ``filterpy.kalman.ExtendedKalmanFilter``
    calls :meth:`_init_updates` in its constructor and keeps ``x``, ``P``
    (filterpy's) and ``t_s`` (the filter time [s]) current. It sets
    filterpy's ``y``, ``S``, ``SI``, ``K``, ``z``, ``x_post`` and ``P_post``
    at every compared reading.

    Attributes
    ----------
    landmarks : LandmarkMap or None
        Known landmark positions, for :meth:`update_landmark`.
    landmark_noise : LandmarkNoise
        Range-bearing noise of sightings without a covariance of their own.
    unknown_landmarks : {"count", "raise"}
        What a sighting of an id not in the map does.
    gate_probability : float or None
        Chi-square gate of every update (``None``: fuse everything).
    records : collections.deque of UpdateRecord
        The latest records (``history`` of them).
    """

    x: np.ndarray
    P: np.ndarray
    t_s: float

    def _init_updates(self, *, gate_probability: float | None,
                      landmarks: LandmarkMap | Mapping[Hashable, tuple[float, float]] | None,
                      landmark_noise: LandmarkNoise | None,
                      unknown_landmarks: Literal["count", "raise"], history: int) -> None:
        """Set the gate, the map, the noise and the record keeping (constructor options)."""
        if unknown_landmarks not in ("count", "raise"):
            raise FilterOptionError(f"unknown_landmarks must be 'count' or 'raise', got "
                                    f"{unknown_landmarks!r}")
        if gate_probability is None:
            self._gates = {1: math.inf, 2: math.inf, 3: math.inf}
        elif not isinstance(gate_probability, (int, float)):
            raise FilterOptionError(f"gate probability must be a number in (0, 1) or None, got "
                                    f"{gate_probability!r}")
        else:
            self._gates = {d: gate_threshold(gate_probability, d) for d in (1, 2, 3)}
        self.gate_probability = gate_probability
        self.landmarks = (landmarks if isinstance(landmarks, LandmarkMap) or landmarks is None
                          else LandmarkMap(landmarks))
        self.landmark_noise = landmark_noise or LandmarkNoise()
        self.unknown_landmarks = unknown_landmarks
        self.records: deque[UpdateRecord] = deque(maxlen=max(0, int(history)))
        self._counts: Counter[tuple[str, str]] = Counter()
        self._unknown: dict[Hashable, None] = {}

    @property
    def stats(self) -> FilterStats:
        """Counts of fused and rejected readings so far."""
        return FilterStats(counts=MappingProxyType(dict(self._counts)),
                           unknown_landmark_ids=tuple(self._unknown))

    # -- landmarks -------------------------------------------------------------------------------
    def update_landmark(self, landmark_id: Hashable, range_bearing: np.ndarray, *,
                        cov: np.ndarray | None = None, t_s: float | None = None,
                        sensor_pose: SensorPose | Sequence[float] | None = None
                        ) -> UpdateRecord:
        """Fuse a range-bearing sighting of a landmark at a known position.

        Parameters
        ----------
        landmark_id : hashable
            Id in the filter's :class:`~fusion.landmark_map.LandmarkMap`.
        range_bearing : array_like, shape (2,)
            ``(r [m], b [rad])`` from the sensor, in its frame; the bearing
            residual is wrapped to ``(-pi, pi]``. NaN or inf: skipped and counted.
        cov : array_like, shape (2, 2), optional
            Covariance of ``(r [m], b [rad])``, symmetric positive definite,
            correlation included; default the filter's :attr:`landmark_noise`
            at the predicted range.
        t_s : float, optional
            Time for the record (default the filter time).
        sensor_pose : SensorPose or (x_m, y_m, yaw_rad), optional
            The sensor's mount on the robot (default the axle centre, facing
            the heading): the measurement model and its Jacobian are those of
            :func:`fusion.range_bearing.range_bearing_terms` for this mount.

        Returns
        -------
        UpdateRecord
            ``kind="landmark"``; ``reason`` ``"unknown_landmark"`` for an id
            not in the map, ``"degenerate"`` for a robot on the landmark.

        Raises
        ------
        MeasurementShapeError
            If the sighting is not (2,), ``cov`` not (2, 2) or ``sensor_pose``
            not three numbers.
        CovarianceNotPositiveDefiniteError
            If ``cov`` is not symmetric positive definite.
        NonFiniteInputError
            If ``sensor_pose`` is not finite.
        FilterOptionError
            If the filter has no landmark map.
        UnknownLandmarkError
            For an id not in the map, with ``unknown_landmarks="raise"``.
        """
        zmeas = np.asarray(range_bearing, dtype=float)
        if zmeas.shape != (2,):
            raise MeasurementShapeError(f"expected a range-bearing observation of shape (2,), "
                                        f"got {zmeas.shape}")
        if cov is not None:
            cov = _check_cov(cov)
        sensor = as_sensor_pose(sensor_pose)
        if self.landmarks is None:
            raise FilterOptionError("this filter has no landmark map; pass landmarks=...")
        t = self.t_s if t_s is None else float(t_s)
        if landmark_id not in self.landmarks:
            self._unknown.setdefault(landmark_id, None)
            if self.unknown_landmarks == "raise":
                self._counts["landmark", "unknown_landmark"] += 1
                self.landmarks.position(landmark_id)        # raises UnknownLandmarkError
                raise UnknownLandmarkError(landmark_id)     # pragma: no cover
            return self._skip("landmark", t, "unknown_landmark", 2, landmark_id)
        if not (math.isfinite(zmeas[0]) and math.isfinite(zmeas[1])):
            return self._skip("landmark", t, "non_finite", 2, landmark_id)
        lxy = self.landmarks.position(landmark_id)
        predicted, H = landmark_terms(self.x, lxy, sensor=sensor)
        if predicted[0] <= MIN_RANGE_M:                  # floored: the sensor on the landmark
            return self._skip("landmark", t, "degenerate", 2, landmark_id)
        R = self.landmark_noise.cov(predicted[0]) if cov is None else cov
        return self._gated("landmark", t, zmeas, landmark_residual(zmeas, predicted), H, R,
                           landmark_id)

    def update_landmarks(self, sightings: RangeBearing, *, t_s: float | None = None
                         ) -> list[UpdateRecord]:
        """Fuse every row of ``sightings`` in order (:meth:`update_landmark` each).

        Parameters
        ----------
        sightings : RangeBearing
            The sightings of the frame just predicted (their ``index`` is not
            read: select the frame's rows first, e.g. with
            :meth:`~fusion.range_bearing.RangeBearing.by_index`); rows without
            a covariance take the filter's :attr:`landmark_noise`; its
            ``sensor_pose`` is the mount of every row.
        t_s : float, optional
            Time for the records (default the filter time).

        Returns
        -------
        list of UpdateRecord
            One per row.

        Raises
        ------
        FilterOptionError, UnknownLandmarkError
            As :meth:`update_landmark`.
        """
        if not len(sightings):                   # most frames see no landmark
            return []
        mount = sightings.sensor_pose
        return [self.update_landmark(lid, z, cov=cov, t_s=t_s, sensor_pose=mount)
                for lid, z, cov in sightings]

    # -- the gate ------------------------------------------------------------------------------
    def _gated(self, kind: UpdateKind, t: float, zmeas: np.ndarray, innovation: np.ndarray,
               H: np.ndarray, R: np.ndarray, landmark_id: Hashable | None, *,
               PHt: np.ndarray | None = None, force: bool = False) -> UpdateRecord:
        """Gate on the NIS, then a Joseph-form update (Bar-Shalom et al. 2001, eq. 5.2.3-18);
        ``force`` fuses a reading outside the gate (reason ``"forced"``). ``PHt``, if given,
        is ``P H^T`` of a selector ``H`` on the last rows of the state."""
        P = self.P
        m = innovation.shape[0]
        if PHt is not None and m == 2:          # the speed state's reading: compiled
            record = self._gated_selector(kind, t, zmeas, innovation, R, landmark_id, force)
            if record is not None:
                return record
        if PHt is None:
            PHt = P @ H.T
            S = H @ PHt + R
        else:
            S = PHt[-m:] + R                     # H P H^T for a selector H on the last rows
        SI = inverse_covariance(S)
        value = nis(innovation, SI)
        inside = value <= self._gates[m]
        accepted = inside or force
        innovation.flags.writeable = False
        S.flags.writeable = False
        self.y, self.S, self.SI, self.z = innovation, S, SI, zmeas
        if accepted:
            K = PHt @ SI
            self.K = K
            self.x = self.x_post = self.x + K @ innovation
            self.P = self.P_post = joseph_covariance(P, K, H, R, PHt)
            self._log_likelihood = self._likelihood = self._mahalanobis = None
            reason: UpdateReason = "fused" if inside else "forced"
        else:
            self.K = np.zeros((len(self.x), m))
            self.x_post, self.P_post = self.x, P
            reason = "gated"
        record = UpdateRecord(kind, t, innovation, S, value, accepted, reason, landmark_id)
        self._counts[kind, reason] += 1
        self.records.append(record)
        return record

    def _gated_selector(self, kind: UpdateKind, t: float, zmeas: np.ndarray,
                        innovation: np.ndarray, R: np.ndarray, landmark_id: Hashable | None,
                        force: bool) -> UpdateRecord | None:
        """:meth:`_gated` for a 2-D reading of the last two states, in one compiled call
        (:func:`fusion.ekf.selector_update_kernel`); None if ``S`` has no positive
        determinant (the numpy path then decides)."""
        # innovation: a fresh float array; x, P, R: the filter's own (kernel_array copies
        # anything else a user assigned)
        ok, S, SI, value, accepted, K, x, P = selector_update_kernel(
            kernel_array(self.x), kernel_array(self.P), innovation, kernel_array(R),
            self._gates[2], bool(force))
        if not ok:
            return None
        innovation.flags.writeable = False
        S.flags.writeable = False
        self.y, self.S, self.SI, self.z = innovation, S, SI, zmeas
        self.K = K
        if accepted:
            self.x = self.x_post = x
            self.P = self.P_post = P
            self._log_likelihood = self._likelihood = self._mahalanobis = None
            reason: UpdateReason = "fused" if value <= self._gates[2] else "forced"
        else:
            self.x_post, self.P_post = self.x, self.P
            reason = "gated"
        record = UpdateRecord(kind, t, innovation, S, value, accepted, reason, landmark_id)
        self._counts[kind, reason] += 1
        self.records.append(record)
        return record

    def _skip(self, kind: UpdateKind, t: float, reason: UpdateReason, m: int,
              landmark_id: Hashable | None = None) -> UpdateRecord:
        """Record a reading that was not compared (NaN innovation, not accepted)."""
        nan_v = _NAN2 if m == 2 else _frozen(np.full(m, np.nan))
        nan_m = _NAN22 if m == 2 else _frozen(np.full((m, m), np.nan))
        record = UpdateRecord(kind, t, nan_v, nan_m, math.nan, False, reason, landmark_id)
        self._counts[kind, reason] += 1
        self.records.append(record)
        if reason not in ("anchor",):
            _log.debug("%s reading at t=%.3f s not fused: %s", kind, t, reason)
        return record


def _check_cov(cov: np.ndarray) -> np.ndarray:
    """A sighting's 2 x 2 covariance, checked: finite, symmetric positive definite."""
    R = np.asarray(cov, dtype=float)
    if R.shape != (2, 2):
        raise MeasurementShapeError(f"expected a range-bearing covariance of shape (2, 2), got "
                                    f"{R.shape}")
    (a, b), (c, d) = R.tolist()
    if not (math.isfinite(a + b + c + d) and a > 0 and a * d - b * c > 0
            and abs(b - c) <= 1e-9 * math.sqrt(abs(a * d))):
        raise CovarianceNotPositiveDefiniteError(
            f"a sighting's covariance must be finite, symmetric and positive definite, got "
            f"{R.tolist()}")
    return R
