"""The wall-run manoeuvre on any robot: straight runs beside a wall, each started a measured
distance from it (the estimator is :mod:`lti_motion.calibration.wall_run`).

The robot is anything calibration drives (:class:`lti_motion.calibration.Robot`: a sensor
period ``dt_s`` and ``step(cmd_m_s) -> SensorFrame``), the simulator and the serial driver
alike; this module only duck-types it. The robot drives alone: the manoeuvre reads only its
encoder counts, bump flags and light-bump signals (never a simulator's truth).

Per pass it drives at the wall until the bumper touches, backs off a chosen distance
(measured by the encoders), scans the wall to square up to it, turns a quarter turn so the
wall is on its left, and drives a straight run of equal wheel commands beside it; the first
pass forwards, the second backwards (so the same side sensor watches the wall) from a larger
distance. Between the passes it turns back to the wall and touches it again. A robot that
curves towards the wall (its side signal climbs past ``2.5`` times its start) stops the run
and starts over with the wall on its right: both passes curve the same way against the wall,
so on that side they curve away from it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lti_motion.calibration.manoeuvres import Robot
from lti_motion.calibration.manoeuvres import drive as drive_commands
from lti_motion.calibration.wall_run import WallPass, mirror_heading_rad
from lti_motion.exceptions import CurvedIntoWallError, NoSignalError, WallRunError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import wheel_from_body
from lti_motion.recordings.frames import FrameLog
from lti_motion.recordings.ticks import tick_deltas, unwrap_ticks

__all__ = ["WallRunDrive", "drive_wall_run", "wall_passes"]

#: Light-bump channels (OI packets 46-51: left, front left, centre left, centre right,
#: front right, right).
LEFT_SENSOR, CENTRE_LEFT, CENTRE_RIGHT, RIGHT_SENSOR = 0, 2, 3, 5
#: A run stops when its side signal exceeds this multiple of its start (or 3500 counts).
STOP_RISE = 2.5


@dataclass(frozen=True)
class WallRunDrive:
    """What :func:`drive_wall_run` recorded.

    Attributes
    ----------
    log : FrameLog
        Every frame of the manoeuvre (on a simulator with its truth, for scoring only).
    backoff : tuple of slice
        Frames of each pass's back-off from the wall (from the robot standing pressed
        against it to the end of the back-off).
    runs : tuple of slice
        Frames of each pass's straight run beside the wall.
    directions : tuple of int
        +1 for a forward run, -1 for a backward one.
    wall_side : {"left", "right"}
        The side the wall was on during the runs.
    sensor : int
        The light-bump channel that watched it (0 left, 5 right).
    """

    log: FrameLog
    backoff: tuple[slice, ...]
    runs: tuple[slice, ...]
    directions: tuple[int, ...]
    wall_side: str = "left"
    sensor: int = LEFT_SENSOR


def _move(v_m_s: float, w_rad_s: float, amount: float, *, dt_s: float, accel_m_s2: float,
          wheel_base_m: float) -> np.ndarray:
    """Ramped wheel commands for ``amount`` metres (``w = 0``) or radians (``v = 0``)."""
    if w_rad_s == 0.0:          # a run too short to reach the speed: v^2 / a = amount
        v_m_s = float(np.sign(v_m_s)) * min(abs(v_m_s), float(np.sqrt(amount * accel_m_s2)))
    peak = abs(v_m_s) + 0.5 * abs(w_rad_s) * wheel_base_m          # fastest wheel [m/s]
    ramp = peak / accel_m_s2
    cruise = max(amount / max(abs(v_m_s), abs(w_rad_s)) - ramp, 0.0)
    t = np.arange(round((2 * ramp + cruise) / dt_s)) * dt_s
    profile = np.clip(np.minimum(t, 2 * ramp + cruise - t) / ramp, 0.0, 1.0)
    return wheel_from_body(np.outer(profile, [v_m_s, w_rad_s]), wheel_base_m=wheel_base_m)


def _concat(logs: list[FrameLog]) -> FrameLog:
    def cat(name: str) -> np.ndarray | None:
        parts = [getattr(lg, name) for lg in logs]
        return None if any(p is None for p in parts) else np.concatenate(parts)

    return FrameLog(t_s=cat("t_s"), ticks=cat("ticks"), light_bump=cat("light_bump"),
                    bumps=cat("bumps"), cmd_m_s=cat("cmd_m_s"), valid=cat("valid"),
                    dt_s=logs[0].dt_s, true_pose=cat("true_pose"),
                    true_body_m_s=cat("true_body_m_s"), meta=dict(logs[0].meta),
                    motor_current_a=cat("motor_current_a"),
                    wheel_overcurrent=cat("wheel_overcurrent"))


def _fresh(robot: Robot) -> None:
    """Drop frames that queued unread while the host computed (the serial driver's
    ``discard_buffered``; a simulator has none): the next command answers a fresh frame."""
    if hasattr(robot, "discard_buffered"):
        robot.discard_buffered()


def _run(robot: Robot, cmd_m_s: np.ndarray) -> FrameLog:
    """One open-loop segment: the commands, one per sensor period (a simulator's ``run``)."""
    _fresh(robot)
    return drive_commands(robot, cmd_m_s)


def _until_bump(robot: Robot, speed_m_s: float, *, accel_m_s2: float,
                max_travel_m: float) -> FrameLog:
    """Drive ahead with equal wheel commands until a bump flag is set, then stop."""
    dt = robot.dt_s
    _fresh(robot)
    n_max = round((max_travel_m / speed_m_s + speed_m_s / accel_m_s2) / dt)
    frames = []
    for k in range(n_max):
        v = min(speed_m_s, accel_m_s2 * k * dt)
        frames.append(robot.step([v, v]))
        if np.any(frames[-1].bumps):
            return FrameLog.from_frames(frames, dt_s=dt)
    raise WallRunError(f"no wall found: no bump within {max_travel_m} m of driving ahead; "
                       "start the wall run facing a straight wall closer than that")


def _turn_to(robot: Robot, target_rad: float, heading_rad: float, *,
             intrinsics: OdometryIntrinsics, opts: dict, rate_rad_s: float) -> list[FrameLog]:
    """Turn in place from encoder heading ``heading_rad`` to ``target_rad``: one ramped turn,
    then one slow correction of what the encoders say is left."""
    logs = []
    rest = np.zeros((round(0.5 / robot.dt_s), 2))
    for rate in (rate_rad_s, 0.1):
        left = target_rad - heading_rad
        if abs(left) < 0.002:
            break
        logs.append(_run(robot, np.vstack([_move(0.0, np.sign(left) * rate, abs(left), **opts),
                                       rest])))
        heading_rad += float(intrinsics.body_motion(tick_deltas(logs[-1].ticks)).sum(0)[1])
    return logs


def _square_up(robot: Robot, *, intrinsics: OdometryIntrinsics, opts: dict,
               scan_rad: float, rate_rad_s: float, side: float) -> list[FrameLog]:
    """Scan the wall in front (turn +-``scan_rad``), find its square with the centre-left
    and centre-right light bumps (:func:`~lti_motion.calibration.mirror_heading_rad`) and turn
    a quarter turn from it, clockwise (``side`` +1: the wall on the left) or not (-1)."""
    rest = np.zeros((round(0.5 / robot.dt_s), 2))
    cmd = np.vstack([_move(0.0, rate_rad_s, scan_rad, **opts), rest,
                     _move(0.0, -rate_rad_s, 2 * scan_rad, **opts), rest,
                     _move(0.0, rate_rad_s, scan_rad, **opts), rest])
    scan = _run(robot, cmd)
    if not np.any(scan.light_bump):
        raise NoSignalError("no light-bump signals: every light bump read 0 while the robot "
                            "scanned the wall a few cm away; stream the light-bump packets "
                            "(46-51) or use a robot that has them")
    turn = intrinsics.body_motion(tick_deltas(scan.ticks))[:, 1]
    heading = np.concatenate([[0.0], np.cumsum(turn)])[1:]
    square = mirror_heading_rad(heading, scan.light_bump[:, CENTRE_LEFT],
                                scan.light_bump[:, CENTRE_RIGHT])
    return [scan, *_turn_to(robot, square - side * np.pi / 2, float(heading[-1]),
                            intrinsics=intrinsics, opts=opts, rate_rad_s=rate_rad_s)]


def _guarded_run(robot: Robot, cmd: np.ndarray, sensor: int, *, accel_m_s2: float
                 ) -> tuple[FrameLog, bool]:
    """Drive ``cmd`` (a straight run) frame by frame; stop, ramping down, if a bump comes or
    the side signal climbs past :data:`STOP_RISE` times its start. Whether it stopped."""
    frames, start = [], None
    _fresh(robot)
    for k, c in enumerate(cmd):
        frames.append(robot.step(c))
        signal = float(frames[-1].light_bump[sensor])
        start = signal if k == 0 else start
        if np.any(frames[-1].bumps) or signal > min(STOP_RISE * max(start, 20.0), 3500.0):
            v = c[0]
            for step in np.arange(abs(v), 0.0, -accel_m_s2 * 2 * robot.dt_s)[1:]:
                frames.append(robot.step(np.full(2, np.sign(v) * step)))
            frames.extend(robot.step(np.zeros(2)) for _ in range(round(0.5 / robot.dt_s)))
            return FrameLog.from_frames(frames, dt_s=robot.dt_s), True
    return FrameLog.from_frames(frames, dt_s=robot.dt_s), False


def drive_wall_run(robot: Robot, intrinsics: OdometryIntrinsics, *, run_m: float = 2.0,
                   speed_m_s: float = 0.2, backoff_m: tuple[float, float] = (0.04, 0.16),
                   approach_m_s: float = 0.1, turn_rad_s: float = 0.5,
                   accel_m_s2: float = 0.1, scan_rad: float = 0.5,
                   max_approach_m: float = 1.5) -> WallRunDrive:
    """Drive the wall run on one robot that starts facing a wall.

    Per pass: drive at the wall until a bump, back off ``backoff_m[i]``, scan the wall
    to square up to it, turn a quarter turn clockwise (wall on the left) and drive a
    straight run of equal wheel commands, forwards in the first pass and backwards in
    the second. Between the passes the robot turns back to the wall. A run whose side
    signal climbs past :data:`STOP_RISE` times its start (the robot curves towards the
    wall) stops, and the manoeuvre starts over with the wall on the right.

    Parameters
    ----------
    robot : Robot
        The serial driver or a simulator of one robot (no batch), standing in front of a
        straight wall, facing it. Frames that queue while the host computes between the
        segments are dropped (its ``discard_buffered``, when it has one).
    intrinsics : OdometryIntrinsics
        The robot's intrinsics in use (nominal or rotation-calibrated), for its turns.
    run_m : float
        Length of each straight run [m].
    speed_m_s, approach_m_s : float
        Run speed and the speed of driving at the wall [m/s].
    backoff_m : tuple of 2 float
        Distance each pass backs off from the wall before its run [m]; the two must differ.
    turn_rad_s, accel_m_s2 : float
        Yaw rate of the turns [rad/s] and the wheel-speed ramp [m/s^2].
    scan_rad : float
        How far the square-up scan turns each way [rad].
    max_approach_m : float
        Give up when no bump comes within this distance [m].

    Returns
    -------
    WallRunDrive

    Raises
    ------
    WallRunError
        A batch simulator, bad sizes, or no wall within ``max_approach_m``.
    CurvedIntoWallError
        Runs that came at the wall on both sides (a ``WallRunError``).
    NoSignalError
        Light bumps that all read 0 while the robot scans the wall a few cm away (a stream
        without them).
    """
    if getattr(robot, "batch", False):
        raise WallRunError("drive_wall_run drives one robot; got a batch simulator")
    if min(run_m, speed_m_s, approach_m_s, turn_rad_s, accel_m_s2, scan_rad,
           *backoff_m) <= 0 or len(backoff_m) != 2:
        raise WallRunError("drive_wall_run needs positive sizes and speeds and two "
                           f"back-off distances, got backoff_m={backoff_m}")
    opts = dict(dt_s=robot.dt_s, accel_m_s2=accel_m_s2, wheel_base_m=intrinsics.wheel_base_m)
    rest = np.zeros((round(0.5 / robot.dt_s), 2))
    logs: list[FrameLog] = [_run(robot, rest)]

    def mark(new: list[FrameLog]) -> slice:
        start = sum(len(lg.t_s) for lg in logs)
        logs.extend(new)
        return slice(start, start + sum(len(lg.t_s) for lg in new))

    facing_wall = True
    for side, sensor in ((1.0, LEFT_SENSOR), (-1.0, RIGHT_SENSOR)):
        backoff, runs = [], []
        for back, direction in zip(backoff_m, (1, -1), strict=True):
            if not facing_wall:
                mark([_run(robot, np.vstack([_move(0.0, side * turn_rad_s, np.pi / 2, **opts),
                                         rest]))])
            mark([_until_bump(robot, approach_m_s, accel_m_s2=accel_m_s2,
                              max_travel_m=max_approach_m), _run(robot, rest)])
            backoff.append(mark([_run(robot, np.vstack([_move(-approach_m_s, 0.0, back, **opts),
                                                    rest]))]))
            mark(_square_up(robot, intrinsics=intrinsics, opts=opts, scan_rad=scan_rad,
                            rate_rad_s=0.3, side=side))
            cmd = np.vstack([_move(direction * speed_m_s, 0.0, run_m, **opts), rest])
            log, stopped = _guarded_run(robot, cmd, sensor, accel_m_s2=accel_m_s2)
            runs.append(mark([log]))
            facing_wall = False
            if stopped:
                break
        else:
            return WallRunDrive(log=_concat(logs), backoff=tuple(backoff), runs=tuple(runs),
                                directions=(1, -1), wall_side="left" if side > 0 else "right",
                                sensor=sensor)
        # the robot came at the wall: start over with the wall on the other side
        mark([_run(robot, np.vstack([_move(0.0, side * turn_rad_s, np.pi / 2, **opts), rest]))])
        facing_wall = True
    raise CurvedIntoWallError("the robot curved into the wall on both sides: its quarter "
                              "turns are off; calibrate the encoder scale on this floor first "
                              "(the rotation manoeuvre) and start the wall run from it")


def wall_passes(drive: WallRunDrive, intrinsics: OdometryIntrinsics) -> list[WallPass]:
    """The passes :func:`lti_motion.calibration.calibrate_wall_run` takes (with
    ``wall_side=drive.wall_side``), from the robot's own signals: each run's counts and
    side-sensor signal, and the back-off measured by the encoders with ``intrinsics`` (the
    robot's current ones)."""
    log = drive.log
    passes = []
    for back, run in zip(drive.backoff, drive.runs, strict=True):
        counts = unwrap_ticks(log.ticks[back])
        travel = intrinsics.wheel_travel_m(counts[-1] - counts[0]).mean()
        passes.append(WallPass(ticks=log.ticks[run], signal=log.light_bump[run, drive.sensor],
                               gap_start_m=-float(travel)))
    return passes
