"""The paper's evaluation (Fig. 2, Table II): a closed route of checkpoints, driven on each
estimator's own position, many robots in lock step.

The robot follows numbered checkpoints with a stop-turn-drive follower that steers on
the estimator's pose, never on the truth; at the last checkpoint (the start) it stops
where it *believes* it started. The closure offset is the true distance between the
true start and the true stop (paper section II.D). Thirty seeded runs per estimator.

An *estimator* here is anything with ``reset(n_robots, initial_pose)`` and
``step(frame, cmd, observations) -> poses (N, 3)``: it sees the frame the robot reports
(encoder counts, timestamps), the command just executed, and the landmark sensor's noisy
range-bearing observations (one :class:`fusion.range_bearing.RangeBearing` per robot,
``index`` = the period), never the simulator's truth.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from drivers.sim import FloorMap, RobotParams, Room, Simulator
from fusion.ekf import EKFOptions, ModelEKF
from fusion.landmark_map import LandmarkMap
from fusion.noise import LandmarkNoise
from fusion.range_bearing import RangeBearing, range_bearing
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import body_from_wheel, pose_step, wheel_from_body, wrap_angle
from lti_motion.model import MotionModel
from lti_motion.recordings import SensorFrame, tick_deltas, tick_step

__all__ = [
    "ROUTE_LANDMARKS",
    "ROUTE_M",
    "ArxHybrid",
    "EkfEstimator",
    "Estimator",
    "Odometry",
    "RecordingOdometry",
    "RouteResult",
    "SensorLess",
    "drive_route",
]

_log = logging.getLogger(__name__)

#: Checkpoints (x m, y m) of the closed route, starting and ending at the first;
#: 10.3 m in all (the paper's route is "about 10 m"; its geometry is not given).
ROUTE_M = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 2.0], [1.5, 2.7], [0.0, 2.0], [0.0, 0.0]])
ROUTE_M.flags.writeable = False

#: Four landmarks around the route, in a 5 m x 5 m room.
ROUTE_LANDMARKS = LandmarkMap({1: (-1.0, -1.0), 2: (4.0, -1.0), 3: (4.0, 3.7), 4: (-1.0, 3.7)})


class Estimator(Protocol):
    """A pose estimator driven in lock step with ``N`` robots."""

    def reset(self, n_robots: int, initial_pose: np.ndarray) -> None:
        """Start ``n_robots`` estimates at ``initial_pose`` (N, 3)."""

    def step(self, frame: SensorFrame, cmd_m_s: np.ndarray,
             observations: Sequence[RangeBearing] | None = None) -> np.ndarray:
        """Take the frame closing the period of ``cmd_m_s`` (N, 2), and the landmark
        observations of that period if any (one per robot); return poses (N, 3)."""


def _valid(frame: SensorFrame, n_robots: int) -> np.ndarray:
    """The frame's ``valid`` flag per robot: a lost frame's counts are never read."""
    valid = np.asarray(frame.valid, bool)
    return valid if valid.shape == (n_robots,) else np.broadcast_to(valid, (n_robots,))


class Odometry:
    """Encoder odometry: wheel ticks times the encoder scale, integrated with eq. 11.

    Parameters
    ----------
    m_per_tick : float, optional
        Encoder scale of both wheels [m/tick] (calibrated by rotation, or nominal).
    wheel_base_m : float, optional
        Nominal wheel base [m].
    intrinsics : OdometryIntrinsics, optional
        Each wheel's scale and the wheel base (:mod:`lti_motion.calibration.intrinsics_fit`),
        instead of the two above.
    """

    def __init__(self, *, m_per_tick: float | None = None, wheel_base_m: float | None = None,
                 intrinsics: OdometryIntrinsics | None = None) -> None:
        if intrinsics is None:
            if m_per_tick is None or wheel_base_m is None:
                raise ValueError("Odometry needs m_per_tick and wheel_base_m, or intrinsics")
            intrinsics = OdometryIntrinsics.symmetric(m_per_tick=m_per_tick,
                                                      wheel_base_m=wheel_base_m)
        self.intrinsics = intrinsics
        self.m_per_tick = intrinsics.m_per_tick
        self.wheel_base_m = intrinsics.wheel_base_m

    def reset(self, n_robots: int, initial_pose: np.ndarray) -> None:
        self.pose = np.array(initial_pose, dtype=float).reshape(n_robots, 3)
        self._ticks = np.zeros((n_robots, 2), np.int64)
        self._anchored = np.zeros(n_robots, bool)

    def step(self, frame: SensorFrame, cmd_m_s: np.ndarray,
             observations: Sequence[RangeBearing] | None = None) -> np.ndarray:
        ticks = np.asarray(frame.ticks, np.int64).reshape(self._ticks.shape)
        valid = _valid(frame, len(ticks))
        # a lost frame is skipped: the next valid frame's counts span the gap
        use = valid & self._anchored
        d = self.intrinsics.wheel_travel_m(tick_step(self._ticks, ticks))
        d[~use] = 0.0
        self._ticks = np.where(valid[:, None], ticks, self._ticks)
        self._anchored |= valid
        # displacement [m] and turn [rad] over the period(s) since the last valid frame
        v, w = body_from_wheel(d, wheel_base_m=self.wheel_base_m).T
        self.pose = pose_step(self.pose, v, w, 1.0)
        return self.pose


class RecordingOdometry(Odometry):
    """Encoder odometry that keeps what the robot reported: commands, counts, sightings.

    For experiments that replay a route's drives through other code (monitors, Phase I):
    after :func:`drive_route`, ``cmd``, ``ticks`` and ``sightings`` hold one entry per
    period, and :meth:`tick_deltas` the unwrapped count changes.
    """

    def reset(self, n_robots: int, initial_pose: np.ndarray) -> None:
        super().reset(n_robots, initial_pose)
        self.cmd: list[np.ndarray] = []
        self.ticks: list[np.ndarray] = []
        self.sightings: list = []

    def step(self, frame, cmd_m_s, observations=None):
        self.cmd.append(np.array(cmd_m_s, float))
        self.ticks.append(np.asarray(frame.ticks, np.int64))
        self.sightings.append(observations)
        return super().step(frame, cmd_m_s, observations)

    def tick_deltas(self) -> np.ndarray:
        """Count changes of periods 1..n, unwrapped, ``(N, n, 2)`` [ticks]."""
        return tick_deltas(np.stack(self.ticks, axis=1), axis=1).astype(float)


class SensorLess:
    """The model run open loop from the commands alone (paper: simulation mode)."""

    def __init__(self, model: MotionModel) -> None:
        self.model = model

    def reset(self, n_robots: int, initial_pose: np.ndarray) -> None:
        self.pose = np.array(initial_pose, dtype=float).reshape(n_robots, 3)
        self.z = np.zeros((n_robots, self.model.A.shape[0]))

    def step(self, frame: SensorFrame, cmd_m_s: np.ndarray,
             observations: Sequence[RangeBearing] | None = None) -> np.ndarray:
        m = self.model
        y = self.z @ m.C.T + cmd_m_s @ m.D.T             # predicted (v, w) over the period
        self.z = self.z @ m.A.T + cmd_m_s @ m.B.T
        self.pose = pose_step(self.pose, y[:, 0], y[:, 1], m.dt_s)
        return self.pose


class ArxHybrid:
    """The paper's filter mode: one-step prediction from measured past outputs.

    The model's predictor form (innovations form, Ljung 1999 sec. 4.3):
    ``z' = (A - K C) z + (B - K D) u + K y_meas``, ``y_hat = C z + D u``; the
    predicted speeds are integrated into the pose, so a single faulty encoder
    reading moves the estimate only through the gain ``K``.
    """

    def __init__(self, model: MotionModel) -> None:
        self.model = model
        m = model
        self._a = m.A - m.K @ m.C
        self._b = m.B - m.K @ m.D

    def reset(self, n_robots: int, initial_pose: np.ndarray) -> None:
        self.pose = np.array(initial_pose, dtype=float).reshape(n_robots, 3)
        self.z = np.zeros((n_robots, self.model.A.shape[0]))
        self._ticks = np.zeros((n_robots, 2), np.int64)
        self._since = np.zeros(n_robots)         # periods since the last valid frame, 0: none

    def step(self, frame: SensorFrame, cmd_m_s: np.ndarray,
             observations: Sequence[RangeBearing] | None = None) -> np.ndarray:
        m = self.model
        ticks = np.asarray(frame.ticks, np.int64).reshape(self._ticks.shape)
        valid = _valid(frame, len(ticks))
        y_hat = self.z @ m.C.T + cmd_m_s @ m.D.T
        self._since[self._since > 0] += 1
        use = valid & (self._since > 0)
        # over a gap of lost frames: the mean speed since the last valid frame
        step = tick_step(self._ticks, ticks)
        if m.intrinsics is None:
            d, base = step * (m.m_per_tick / m.dt_s), m.wheel_base_m
        else:                                   # each wheel's own scale
            d, base = m.intrinsics.wheel_travel_m(step) / m.dt_s, m.intrinsics.wheel_base_m
        d /= np.maximum(self._since - 1, 1)[:, None]
        y_meas = np.where(use[:, None], body_from_wheel(d, wheel_base_m=base), y_hat)
        self._ticks = np.where(valid[:, None], ticks, self._ticks)
        self._since[valid] = 1
        self.z = self.z @ self._a.T + cmd_m_s @ self._b.T + y_meas @ m.K.T
        self.pose = pose_step(self.pose, y_hat[:, 0], y_hat[:, 1], m.dt_s)
        return self.pose


class EkfEstimator:
    """One :class:`fusion.ekf.ModelEKF` per robot: the model and the encoders, and
    landmarks when a map is given (the filter gates and counts faulty readings)."""

    def __init__(self, model: MotionModel, *, landmarks: LandmarkMap | None = None,
                 landmark_noise: LandmarkNoise | None = None) -> None:
        self.model = model
        self.landmarks = landmarks
        self.landmark_noise = landmark_noise

    def reset(self, n_robots: int, initial_pose: np.ndarray) -> None:
        self.pose = np.array(initial_pose, dtype=float).reshape(n_robots, 3)
        self.filters: list[ModelEKF] | None = None

    def step(self, frame: SensorFrame, cmd_m_s: np.ndarray,
             observations: Sequence[RangeBearing] | None = None) -> np.ndarray:
        ticks = np.asarray(frame.ticks, np.int64).reshape(len(self.pose), 2)
        valid = _valid(frame, len(ticks))
        if self.filters is None:            # the first frame anchors the encoder counts
            self.filters = [
                ModelEKF(self.model, initial_pose=pose, pose_std=(0.005, 0.005, 0.005),
                         initial_ticks=t if ok else None, landmarks=self.landmarks,
                         options=EKFOptions(landmark_noise=self.landmark_noise, history=0))
                for pose, t, ok in zip(self.pose, ticks, valid, strict=True)]
            return self.pose
        for i, ekf in enumerate(self.filters):
            ekf.predict(cmd_m_s[i])
            if valid[i]:                    # a lost frame's counts are never read
                ekf.update_encoders(ticks[i])
            if observations is not None and self.landmarks is not None:
                ekf.update_landmarks(observations[i])
            self.pose[i] = ekf.x[:3]
        return self.pose


def _observe(landmarks: LandmarkMap, true_poses: np.ndarray, k: int, *, stride: int,
             noise: LandmarkNoise, rng: np.random.Generator) -> list[RangeBearing]:
    """The landmark sensor of period ``k``, one :class:`RangeBearing` per robot (``index``
    = ``k``): each landmark seen once per ``stride`` periods, the landmarks taking turns,
    with noise (the physical world's side: it reads the truth)."""
    rows: list[list[tuple[int, float, float]]] = [[] for _ in true_poses]
    ids = landmarks.ids
    for j, landmark_id in enumerate(ids):
        if (k + j * stride // len(ids)) % stride:
            continue
        xy = landmarks.position(landmark_id)
        for i, pose in enumerate(true_poses):
            r, b = range_bearing(pose, xy)
            sr = max(noise.range_std_m, noise.range_std_frac * r)
            rows[i].append((landmark_id, r + sr * rng.standard_normal(),
                            wrap_angle(b + noise.bearing_std_rad * rng.standard_normal())))
    return [RangeBearing(k, *zip(*seen, strict=True)) if seen else RangeBearing.empty()
            for seen in rows]


@dataclass(frozen=True)
class RouteResult:
    """One estimator's runs of the route.

    Attributes
    ----------
    closure_offset_m : ndarray, shape (N,)
        True distance between start and stop, per run [m] (paper Table II).
    true_poses, est_poses : ndarray, shape (N, n, 3)
        Trajectories, the truth and the estimate the robot steered on.
    finished : ndarray of bool, shape (N,)
        Runs that reached the last checkpoint before the time limit.
    """

    closure_offset_m: np.ndarray
    true_poses: np.ndarray
    est_poses: np.ndarray
    finished: np.ndarray
    extra: dict = field(default_factory=dict)


def _follower(est: np.ndarray, target_idx: np.ndarray, phase: np.ndarray, *,
              cruise_m_s: float, turn_rad_s: float, wheel_base_m: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stop-turn-drive towards the next checkpoint, on the estimated pose.

    Returns the wheel commands (N, 2) [m/s], the estimated distance to the
    checkpoint [m] and the estimated heading error towards it [rad].
    """
    goal = ROUTE_M[np.minimum(target_idx, len(ROUTE_M) - 1)]
    delta = goal - est[:, :2]
    dist = np.hypot(delta[:, 0], delta[:, 1])
    err = wrap_angle(np.arctan2(delta[:, 1], delta[:, 0]) - est[:, 2])
    # per robot by phase: at rest (0, 3), turn in place (1), drive (2); np.where on whole
    # arrays, np.minimum(np.maximum()) for np.clip (the same values, less call overhead)
    driving = phase == 2
    slow = np.minimum(np.maximum(dist / 0.3, 0.25), 1.0)   # slow down near the checkpoint
    body = np.zeros((len(est), 2))
    body[:, 0] = np.where(driving, cruise_m_s * slow * np.maximum(0.0, np.cos(err)), 0.0)
    body[:, 1] = np.where(phase == 1, np.minimum(np.maximum(2.0 * err, -turn_rad_s), turn_rad_s),
                          np.where(driving, np.minimum(np.maximum(1.5 * err, -0.5), 0.5), 0.0))
    return wheel_from_body(body, wheel_base_m=wheel_base_m), dist, err


def drive_route(params: RobotParams, estimator: Estimator, *, seeds: Sequence[int],
                floor: str | FloorMap | None = None, cruise_m_s: float = 0.25,
                turn_rad_s: float = 1.0,
                reach_m: float = 0.03, max_s: float = 150.0, faults: Sequence = (),
                landmarks: LandmarkMap | None = None, landmark_noise: LandmarkNoise | None = None,
                landmark_rate_hz: float = 2.0,
                progress: Callable[[float, int, int], None] | None = None) -> RouteResult:
    """Drive the closed route once per seed, all robots in lock step.

    The follower per robot: *stop* (0.4 s at rest), *turn* in place until the
    estimated heading error is below 0.03 rad, *stop*, *drive* until the estimated
    distance to the checkpoint is below ``reach_m``; then the next checkpoint. At
    the last checkpoint the robot stops for good. ``floor`` defaults to the robot's
    (:attr:`~drivers.sim.RobotParams.floor`); the robot's own faults happen too.
    ``progress``, if given, is called every 200 periods and at the end as
    ``progress(t_s, home, n)``: the route time driven [s] (at most ``max_s``), the
    robots home and the robots (an estimator that is slow per step, the iSAM2
    smoother, takes minutes of wall time for the route).
    """
    n = len(seeds)
    dt = params.period_s
    heading0 = 0.0
    initial_pose = np.tile([*ROUTE_M[0], heading0], (n, 1))
    sim = Simulator(params, seed=list(seeds), floor=floor, room=Room.empty(),
                    initial_pose=initial_pose, faults=faults)
    estimator.reset(n, initial_pose)
    noise = landmark_noise or LandmarkNoise()
    stride = max(1, round(1.0 / (landmark_rate_hz * dt)))
    sensor_rng = np.random.default_rng([int(x) for x in seeds] + [0x5E45])
    est = initial_pose.copy()
    target = np.ones(n, int)           # index of the checkpoint being approached
    phase = np.zeros(n, int)           # 0 stop, 1 turn, 2 drive, 3 done
    hold = np.full(n, round(0.4 / dt))  # periods left in a stop
    after_stop = np.ones(n, int)       # the phase a stop leads to
    n_max = round(max_s / dt)
    true_log, est_log = [], []
    for k in range(n_max):
        cmd, dist, err = _follower(est, target, phase, cruise_m_s=cruise_m_s,
                                   turn_rad_s=turn_rad_s, wheel_base_m=params.wheel_base_m)
        cmd = np.minimum(np.maximum(cmd, -params.max_speed_m_s), params.max_speed_m_s)
        cmd[(phase == 0) | (phase == 3)] = 0.0
        frame = sim.step(cmd)
        # the estimator gets what a robot reports: the simulator's truth is stripped
        seen = replace(frame, true_pose=None, true_body_m_s=None)
        obs = None if landmarks is None else _observe(landmarks, frame.true_pose, k + 1,
                                                      stride=stride, noise=noise,
                                                      rng=sensor_rng)
        est = estimator.step(seen, np.rint(cmd * 1000.0) / 1000.0, obs)   # whole mm/s
        true_log.append(frame.true_pose)
        est_log.append(est.copy())
        # phase transitions, on the estimate only
        hold = np.maximum(hold - 1, 0)
        stop_done = (phase == 0) & (hold == 0)
        if stop_done.any():         # most periods change no phase: skip the updates
            phase = np.where(stop_done, np.where(target >= len(ROUTE_M), 3, after_stop), phase)
        turned = (phase == 1) & (np.abs(err) < 0.03)
        arrived = (phase == 2) & (dist < reach_m)
        if (turned | arrived).any():
            target = np.where(arrived, target + 1, target)
            after_stop = np.where(turned, 2, np.where(arrived, 1, after_stop))
            hold = np.where(turned | arrived, round(0.4 / dt), hold)
            phase = np.where(turned | arrived, 0, phase)
        if progress is not None and k % 200 == 0:
            progress((k + 1) * dt, int((phase == 3).sum()), n)
        if (phase == 3).all():
            break
    if progress is not None:
        progress(len(true_log) * dt, int((phase == 3).sum()), n)
    true = np.stack(true_log, axis=1)
    est_all = np.stack(est_log, axis=1)
    offset = np.linalg.norm(true[:, -1, :2] - ROUTE_M[0], axis=1)
    return RouteResult(closure_offset_m=offset, true_poses=true, est_poses=est_all,
                       finished=phase == 3)
