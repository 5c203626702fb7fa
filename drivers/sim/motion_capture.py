"""A simulated motion-capture system and the intrinsics calibration drive.

Motion capture is an external sensor: it sees the robot's true pose, with noise,
at its own rate. Like the landmark sensor of the route evaluation, it is the
physical world's side and reads the simulator's truth; the estimators that use
its output never do.
"""

from __future__ import annotations

import numpy as np

from drivers.exceptions import SimulatorError
from lti_motion.kinematics import wheel_from_body
from lti_motion.recordings.frames import FrameLog

__all__ = ["intrinsics_drive", "motion_capture"]


def motion_capture(log: FrameLog, *, rng: np.random.Generator, rate_hz: float = 10.0,
                   position_std_m: float = 0.005,
                   heading_std_rad: float = float(np.deg2rad(0.5))
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Noisy poses of the wheel axle's centre at ``rate_hz``, stamped on the frames' clock.

    Parameters
    ----------
    log : FrameLog
        One robot's frames with the simulator's truth (``true_pose``), shape (n, ...).
    rng : numpy.random.Generator
        Source of the measurement noise.
    rate_hz : float
        Capture rate [Hz]; every ``round(1 / (rate_hz dt))``-th frame.
    position_std_m, heading_std_rad : float
        White noise on each coordinate [m] and on the heading [rad].

    Returns
    -------
    t_s : ndarray, shape (m,)
        Capture times [s] (the sensor periods' ends, ``(k + 1) dt`` from the log's start).
    poses : ndarray, shape (m, 3)
        ``(x [m], y [m], theta [rad])``.

    Raises
    ------
    SimulatorError
        If the log has no truth or holds several robots.
    """
    if log.true_pose is None or np.ndim(log.t_s) != 1:
        raise SimulatorError("motion_capture needs one robot's FrameLog with its true poses")
    stride = max(1, round(1.0 / (rate_hz * log.dt_s)))
    idx = np.arange(0, len(log.t_s), stride)
    t = (idx + 1) * log.dt_s + (log.t_s[0] - log.dt_s)
    noise = rng.standard_normal((len(idx), 3)) * [position_std_m, position_std_m,
                                                  heading_std_rad]
    return t, log.true_pose[idx] + noise


def intrinsics_drive(dt_s: float, *, speed_m_s: float = 0.2, run_m: float = 2.0,
                     turn_rad_s: float = 0.5, accel_m_s2: float = 0.1,
                     wheel_base_m: float = 0.235, repeats: int = 2) -> np.ndarray:
    """Wheel commands of a calibration drive: straight runs and turns both ways.

    Per repeat: a run ahead, a half turn counter-clockwise, a run back, a half turn
    clockwise; each manoeuvre ramps its wheel speeds up and down at ``accel_m_s2``
    (sudden steps make the wheels slip, which no intrinsic explains) and is followed
    by 0.5 s at rest. The robot stays within ``run_m`` of its start.

    Parameters
    ----------
    dt_s : float
        Sensor period [s].
    speed_m_s, run_m : float
        Straight-run speed [m/s] and length [m].
    turn_rad_s : float
        Yaw rate of the turns in place [rad/s].
    accel_m_s2 : float
        Wheel-speed ramp [m/s^2].
    wheel_base_m : float
        Nominal wheel base [m], to turn body speeds into wheel commands.
    repeats : int
        Number of repeats.

    Returns
    -------
    ndarray, shape (n, 2)
        ``(left, right)`` wheel-speed commands [m/s], one per period.
    """
    def move(v: float, w: float, distance: float) -> np.ndarray:
        peak = abs(v) + 0.5 * abs(w) * wheel_base_m          # fastest wheel [m/s]
        ramp = peak / accel_m_s2
        cruise = max(distance / max(abs(v), abs(w)) - ramp, 0.0)
        t = np.arange(round((2 * ramp + cruise) / dt_s)) * dt_s
        profile = np.clip(np.minimum(t, 2 * ramp + cruise - t) / ramp, 0.0, 1.0)
        body = np.outer(profile, [v, w])
        return wheel_from_body(body, wheel_base_m=wheel_base_m)

    if min(dt_s, speed_m_s, run_m, turn_rad_s, accel_m_s2, wheel_base_m) <= 0 or repeats < 1:
        raise SimulatorError("intrinsics_drive needs positive speeds, lengths and period, "
                             "and repeats >= 1")
    rest = np.zeros((round(0.5 / dt_s), 2))
    parts = [rest]
    for _ in range(repeats):
        parts += [move(speed_m_s, 0.0, run_m), rest, move(0.0, turn_rad_s, np.pi), rest,
                  move(speed_m_s, 0.0, run_m), rest, move(0.0, -turn_rad_s, np.pi), rest]
    return np.vstack(parts)
