"""Synthetic drives for the preintegration, factor and smoother tests (tests/fusion/graph)."""

import gtsam
import numpy as np

from fusion.graph.factors import calibration_key, pose_key
from fusion.landmark_map import LandmarkMap
from fusion.range_bearing import RangeBearing

DT = 0.015                                        # sensor period [s]
PHI = np.array([[1e-4, 2e-5], [2e-5, 5e-3]])      # speed covariance [(m/s)^2, (rad/s)^2]


def speeds(rng: np.random.Generator, n: int, *, turn: float = 0.8) -> np.ndarray:
    """``(n, 2)`` body speeds ``(v [m/s], w [rad/s])``: 0.2 m/s with noise, a turn of
    amplitude ``turn`` [rad/s] with a 4.4 s period, plus noise."""
    t = np.arange(n) * DT
    return np.column_stack([0.2 + 0.05 * rng.standard_normal(n),
                            turn * np.sin(t / 0.7) + 0.2 * rng.standard_normal(n)])


def ring_sightings(truth: np.ndarray) -> tuple[RangeBearing, LandmarkMap]:
    """Noise-free range-bearing sightings of 8 landmarks on a 3 m ring from every pose of
    ``truth`` ``(n, 3)`` [m, m, rad], with a 1e-4 covariance; and the ring."""
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    lm = LandmarkMap.from_arrays(np.arange(8), np.column_stack([3 * np.cos(angles),
                                                                3 * np.sin(angles)]))
    d = lm.xy_m[None, :, :] - truth[:, None, :2]
    bearing = np.arctan2(d[..., 1], d[..., 0]) - truth[:, 2:3]
    index = np.repeat(np.arange(len(truth)), 8)
    obs = RangeBearing(index, np.tile(np.arange(8), len(truth)),
                       np.hypot(d[..., 0], d[..., 1]).ravel(),
                       np.arctan2(np.sin(bearing), np.cos(bearing)).ravel(),
                       cov=np.broadcast_to(np.eye(2) * 1e-4, (len(index), 2, 2)))
    return obs, lm


def group_values(pre, rng: np.random.Generator, cal) -> gtsam.Values:
    """Values for a group factor over every interval of ``pre``: poses where the
    preintegrated motions put them, each off by a small random offset, and ``cal`` under
    ``calibration_key(0)``."""
    values = gtsam.Values()
    pose = gtsam.Pose2(*rng.uniform(-2, 2, 3))
    for i in range(len(pre.delta_pose) + 1):
        values.insert(pose_key(i), pose)
        if i < len(pre.delta_pose):
            pose = pose.compose(gtsam.Pose2(*pre.delta_pose[i])).compose(
                gtsam.Pose2(*(0.05 * rng.standard_normal(3))))
    values.insert(calibration_key(0), np.asarray(cal, dtype=float))
    return values


def factor_values(pre, k: int, rng: np.random.Generator, *, cal) -> gtsam.Values:
    """Values for a calibrated motion factor of interval ``k`` of ``pre``: a random first
    pose, the second where the preintegrated motion puts it plus a small offset, and the
    calibration ``cal`` under ``calibration_key(0)``."""
    wTi = gtsam.Pose2(*rng.uniform(-2, 2, 3))
    wTj = wTi.compose(gtsam.Pose2(*pre.delta_pose[k])).compose(
        gtsam.Pose2(*(0.05 * rng.standard_normal(3))))
    values = gtsam.Values()
    values.insert(pose_key(0), wTi)
    values.insert(pose_key(1), wTj)
    values.insert(calibration_key(0), np.asarray(cal, dtype=float))
    return values


def feed_online(sm, pre, obs: RangeBearing, *, after_update=None):
    """Feed an incremental smoother keyframe by keyframe as a robot would: the motion
    closing keyframe ``k``, its sightings (``obs.index == k``), an update; then
    ``after_update(k)`` if given. Returns the smoother."""
    for k in range(len(pre) + 1):
        if k > 0:
            sm.add_motion(pre[k - 1])
        sm.add_observations(obs.select(obs.index == k))
        sm.update()
        if after_update is not None:
            after_update(k)
    return sm
