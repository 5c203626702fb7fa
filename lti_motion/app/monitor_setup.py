"""The monitor's drive and its Phase I, as ``lti-motion monitor`` runs them.

- :func:`monitor_route`: the monitor's drive (rest, then rounded-rectangle laps);
- :func:`nominal_on_simulator`, :func:`nominal_from_logs`: Phase I
  (:func:`fusion.monitoring.fit_nominal`) on simulated nominal drives of the
  same route, or on logs the command recorded on the robot's nominal drives;
- the simulated landmark sensor of ``lti-motion monitor --sim``
  (:data:`MONITOR_LANDMARKS`, :func:`sightings`): it reads the simulator's true
  pose, as a camera sees the world; the monitor sees only its noisy output.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from fusion.landmark_map import LandmarkMap
from fusion.monitoring import NominalFit, fit_nominal
from fusion.noise import LandmarkNoise
from fusion.range_bearing import RangeBearing, range_bearing
from lti_motion.kinematics import wheel_from_body, wrap_angle
from lti_motion.model import MotionModel
from lti_motion.recordings import unwrap_ticks

if TYPE_CHECKING:
    from drivers.sim import FloorMap, RobotParams
    from lti_motion.recordings import FrameLog

__all__ = ["MONITOR_LANDMARKS", "monitor_route", "nominal_from_logs", "nominal_on_simulator",
           "sightings"]

#: Four landmarks around the monitor's rounded rectangle (x in -0.4..1.6 m, y in 0..2 m).
MONITOR_LANDMARKS = LandmarkMap({1: (-1.5, -1.0), 2: (2.7, -1.0), 3: (2.7, 3.0),
                                 4: (-1.5, 3.0)})


def monitor_route(duration_s: float, *, dt_s: float, wheel_base_m: float,
                  rng: np.random.Generator, rest_s: float = 1.0, side_m: float = 1.2,
                  radius_m: float = 0.4, speeds_m_s: tuple[float, float] = (0.12, 0.3)
                  ) -> np.ndarray:
    """Wheel commands ``(n, 2)`` [m/s] of the monitor's drive: rest, then rounded-rectangle laps.

    Each straight is driven at a speed drawn uniformly from ``speeds_m_s``; each
    corner is a quarter arc of ``radius_m`` at 0.15 m/s. Open loop: the path
    drifts as the robot does.
    """
    n = round(duration_s / dt_s)
    rows = [np.zeros((round(rest_s / dt_s), 2))]
    total = len(rows[0])
    while total < n:
        v = rng.uniform(*speeds_m_s)
        straight = np.tile([v, 0.0], (max(1, round(side_m / v / dt_s)), 1))
        v_arc = 0.15
        arc = np.tile([v_arc, v_arc / radius_m],
                      (max(1, round(0.5 * math.pi * radius_m / v_arc / dt_s)), 1))
        for body in (straight, arc):
            rows.append(wheel_from_body(body, wheel_base_m=wheel_base_m))
            total += len(body)
    return np.concatenate(rows)[:n]


def sightings(true_pose: np.ndarray, k: int, rng: np.random.Generator, *,
              landmarks: LandmarkMap = MONITOR_LANDMARKS, rate_hz: float = 2.0,
              dt_s: float = 0.015, noise: LandmarkNoise | None = None) -> RangeBearing:
    """The simulated landmark sensor at frame ``k``: each landmark at ``rate_hz``, in turn.

    Reads the true pose (the world's side); returns the frame's sightings (``index`` =
    ``k``, no covariance) with range noise ``max(range_std_m, range_std_frac r)`` and
    bearing noise ``bearing_std_rad`` (default 2% of range, 1 degree).
    """
    noise = noise or LandmarkNoise()
    stride = max(1, round(1.0 / (rate_hz * dt_s)))
    ids = landmarks.ids
    rows = []
    for j, landmark_id in enumerate(ids):
        if (k + j * stride // len(ids)) % stride:
            continue
        r, b = range_bearing(np.asarray(true_pose, float), landmarks.position(landmark_id))
        sr = max(noise.range_std_m, noise.range_std_frac * r)
        rows.append((landmark_id, r + sr * rng.standard_normal(),
                     wrap_angle(b + noise.bearing_std_rad * rng.standard_normal())))
    return RangeBearing(k, *zip(*rows, strict=True)) if rows else RangeBearing.empty()


def nominal_on_simulator(model: MotionModel, *, robot: RobotParams | str = "create2",
                         n_drives: int = 20, duration_s: float = 30.0, seed: int = 0,
                         floor: str | FloorMap | None = None,
                         progress: Callable[[str, int, int], None] | None = None) -> NominalFit:
    """Phase I on the simulator: ``n_drives`` nominal drives of :func:`monitor_route`.

    Seeds ``seed + 1000 .. seed + 1000 + n_drives - 1`` (route and simulator), no
    fault (the robot's own faults are left out), all in one batch, on ``floor``
    (default the robot's); ``robot`` is parameters, a preset name or a robot file.
    Commands and counts only go to :func:`~lti_motion.app.monitor_setup.fit_nominal`,
    which reports its steps to ``progress`` (``fit_nominal``'s).
    """
    from drivers.sim import Room, Simulator, load_robot

    params = load_robot(robot) if isinstance(robot, str) else robot
    seeds = [seed + 1000 + i for i in range(n_drives)]
    sim = Simulator(params.replace(faults=()), seed=seeds, floor=floor, room=Room.empty(),
                    initial_pose=np.zeros((n_drives, 3)))
    cmds = np.stack([monitor_route(duration_s, dt_s=sim.dt_s, wheel_base_m=model.wheel_base_m,
                                   rng=np.random.default_rng(s)) for s in seeds])
    log = sim.run(cmds)
    drives = [(r.cmd_m_s[1:], _unwrapped(r)) for r in (log.robot(i) for i in range(n_drives))]
    return fit_nominal(model, drives, progress=progress)


def nominal_from_logs(model: MotionModel, paths: Sequence[str], *,
                      progress: Callable[[str, int, int], None] | None = None) -> NominalFit:
    """Phase I from logs of nominal drives (``lti-motion monitor --record`` on the robot);
    ``progress`` as for :func:`~fusion.monitoring.fit_nominal`."""
    from lti_motion.recordings import load_log

    drives = []
    for path in paths:
        log = load_log(path)
        drives.append((log.cmd_m_s[1:], _unwrapped(log)))
    return fit_nominal(model, drives, progress=progress)


def _unwrapped(log: FrameLog) -> np.ndarray:
    """A drive's counts unwrapped from their ``2**counter_bits`` ring: ``fit_nominal``
    differences them on the 16-bit ring, exact for steps below 2**15 ticks."""
    return unwrap_ticks(log.ticks, counter_bits=log.counter_bits)
