"""Synthetic range-bearing sightings drawn from known poses, for simulation and tests."""

from __future__ import annotations

import math

import numpy as np

from fusion.exceptions import FilterOptionError, MeasurementShapeError
from fusion.landmark_map import LandmarkMap
from fusion.noise import LandmarkNoise
from fusion.range_bearing import RangeBearing, range_bearing
from fusion.sensor_pose import SensorPose, as_sensor_pose
from lti_motion.kinematics import wrap_angle

__all__ = [
    "synthetic_observations",
]


def synthetic_observations(
    poses: np.ndarray,
    landmarks: LandmarkMap,
    *,
    dt_s: float,
    rng: np.random.Generator,
    rate_hz: float = 2.0,
    noise: LandmarkNoise | None = None,
    max_range_m: float = math.inf,
    sensor_pose: SensorPose | None = None,
) -> RangeBearing:
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
        Landmarks farther than this (from the sensor) are not seen.
    sensor_pose : SensorPose, optional
        Where the sensor sits on the robot (default the axle centre): ranges
        and bearings are drawn from the sensor's true position and axis
        (:func:`fusion.range_bearing.range_bearing`, eq. 1), and the result
        carries the mount.

    Returns
    -------
    RangeBearing
        ``index`` = frame, in frame order (frame 0 is never observed: the
        filter starts there), without covariances: the estimator's own
        :class:`LandmarkNoise` applies; ``sensor_pose`` the mount.

    Raises
    ------
    MeasurementShapeError
        If ``poses`` is not ``(n, 3)`` or ``sensor_pose`` not three numbers.
    FilterOptionError
        If ``rate_hz`` or ``dt_s`` is not positive.
    """
    poses = np.asarray(poses, dtype=float)
    if poses.ndim != 2 or poses.shape[1] != 3:
        raise MeasurementShapeError(f"expected poses of shape (n, 3), got {poses.shape}")
    if not (rate_hz > 0 and dt_s > 0):
        raise FilterOptionError(f"rate_hz and dt_s must be positive, got {rate_hz}, {dt_s}")
    noise = noise or LandmarkNoise()
    mount = as_sensor_pose(sensor_pose)
    stride = max(1, round(1.0 / (rate_hz * dt_s)))
    ids = landmarks.ids
    frames, keys, values = [], [], []
    k_all = np.arange(1, len(poses))
    for j, key in enumerate(ids):
        offset = j * stride // max(1, len(ids))
        ks = k_all[(k_all + offset) % stride == 0]
        r, b = range_bearing(poses[ks], landmarks.position(key), sensor=mount).T
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
    return RangeBearing(frame[order], [keys[i] for i in order], rb[order, 0], rb[order, 1],
                        sensor_pose=mount)
