"""``lti-motion calibrate --umbmark --robot NAME``: UMBmark's bidirectional square as a
procedure, on the simulator.

Borenstein and Feng's benchmark drives a square of side ``L`` counter-clockwise and
clockwise, several times each, and measures where the robot ends. Here each square is one
run of :func:`lti_motion.calibration.calibrate_intrinsics_runs`: its counts from the log
and its start and end pose from a small file (the runs format of
:func:`lti_motion.recordings.read_end_pose_runs`, one square a line, ``turns`` +1 or -1).
The simulated drive writes that file itself with the simulator's true poses plus a
measurement's noise (5 mm, 0.5 deg), then fits it as ``calibrate --log
OUT/log_umbmark.npz --reference OUT/umbmark_runs.txt`` does; on a robot, drive the squares,
measure the poses and write the file by hand, then run that command.

The squares turn the robot one way in one half and the other way in the other, so the
two wheels' scales separate (the reason UMBmark is bidirectional: Borenstein & Feng 1996,
sec. 3, type A and type B errors).

References
----------
J. Borenstein, L. Feng, "Measurement and correction of systematic odometry errors in
mobile robots", IEEE T-RA 12(6):869-880, 1996.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

    from drivers.sim import RobotParams
    from lti_motion.recordings import EndPoseRuns, FrameLog

__all__ = ["add_umbmark_arguments", "run_umbmark", "simulate_umbmark", "umbmark_squares"]

#: Speeds and ramps of the squares (gentle: slip is no intrinsic).
_SPEED_M_S = 0.2
_TURN_RAD_S = 0.5
_ACCEL_M_S2 = 0.1
#: Noise of the simulated measurement of each start and end pose [m], [rad].
_MEASURE_STD = (0.005, 0.0087)


def add_umbmark_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``calibrate --umbmark``."""
    parser.add_argument("--umbmark", action="store_true",
                        help="with --robot: drive UMBmark's square both ways on the simulator, "
                             "write OUT/log_umbmark.npz and the squares' start and end poses "
                             "OUT/umbmark_runs.txt, and fit both wheels' scale and the wheel "
                             "base from them (docs/intrinsics.md)")
    parser.add_argument("--umbmark-side", type=float, default=1.0, metavar="M",
                        help="side of the square [m] (default 1)")
    parser.add_argument("--umbmark-runs", type=int, default=5, metavar="N",
                        help="squares each way (default 5)")


def _square(dt_s: float, wheel_base_m: float, side_m: float, direction: int):
    """Wheel commands [m/s] of one square (4 sides, 4 quarter turns ``direction`` +1
    counter-clockwise, -1 clockwise), each manoeuvre ramped and followed by 0.5 s rest."""
    import numpy as np

    from lti_motion.kinematics import wheel_from_body

    def move(v: float, w: float, distance: float) -> np.ndarray:
        peak = abs(v) + 0.5 * abs(w) * wheel_base_m
        ramp = peak / _ACCEL_M_S2
        cruise = max(distance / max(abs(v), abs(w)) - ramp, 0.0)
        t = np.arange(round((2 * ramp + cruise) / dt_s)) * dt_s
        profile = np.clip(np.minimum(t, 2 * ramp + cruise - t) / ramp, 0.0, 1.0)
        return wheel_from_body(np.outer(profile, [v, w]), wheel_base_m=wheel_base_m)

    rest = np.zeros((round(0.5 / dt_s), 2))
    parts = []
    for _ in range(4):
        parts += [move(_SPEED_M_S, 0.0, side_m), rest,
                  move(0.0, direction * _TURN_RAD_S, np.pi / 2), rest]
    return np.concatenate(parts)


def umbmark_squares(dt_s: float, wheel_base_m: float, *, side_m: float, runs: int
                    ) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Wheel commands of UMBmark's bidirectional square: ``runs`` squares counter-clockwise,
    then ``runs`` clockwise (Borenstein & Feng 1996, sec. 3).

    Parameters
    ----------
    dt_s : float
        Command period [s].
    wheel_base_m : float
        The nominal wheel base the commands are computed with [m].
    side_m : float
        Side of the square [m] (Borenstein and Feng: 4 m).
    runs : int
        Squares each way (Borenstein and Feng: 5).

    Returns
    -------
    commands : ndarray, shape (n, 2)
        Wheel speeds ``(left, right)`` [m/s], one row a period: each square four sides at
        0.2 m/s and four quarter turns in place at 0.5 rad/s, every manoeuvre ramped at
        0.1 m/s^2 and followed by 0.5 s at rest.
    bounds : ndarray of int, shape (2 runs + 1,)
        The command row at which each square starts, and the end.
    directions : list of int
        +1 (counter-clockwise) or -1 (clockwise), one per square.
    """
    import numpy as np

    directions = [1] * runs + [-1] * runs
    squares = [_square(dt_s, wheel_base_m, side_m, d) for d in directions]
    bounds = np.concatenate([[0], np.cumsum([len(s) for s in squares])])
    return np.concatenate(squares), bounds, directions


def simulate_umbmark(params: RobotParams, *, side_m: float, runs: int, seed: int,
                     floor: str | None = None,
                     measure_std: tuple[float, float] = _MEASURE_STD
                     ) -> tuple[FrameLog, EndPoseRuns]:
    """Drive UMBmark's squares on the simulator and measure where each starts and ends.

    The measurement is the physical world's side of the procedure (a tape measure): the
    simulator's true pose at each square's first and last frame plus Gaussian noise of
    ``measure_std`` ``(position [m], heading [rad])``; the calibration sees only the
    counts and these poses.

    Parameters
    ----------
    params : drivers.sim.RobotParams
        The simulated robot.
    side_m, runs
        As :func:`umbmark_squares`.
    seed : int
        The simulator's seed; the measurement noise is drawn from ``[seed, 0x0B]``.
    floor : str, optional
        The simulated floor (default the robot's).
    measure_std : tuple of 2 float
        Standard deviation of a measured position [m] (each axis) and heading [rad].

    Returns
    -------
    log : lti_motion.recordings.FrameLog
        The drive.
    runs : lti_motion.recordings.EndPoseRuns
        Each square's start and end frame times [s], measured poses and whole ``turns``
        (+1 counter-clockwise, -1 clockwise), as the runs file holds them.
    """
    import numpy as np

    from drivers.sim import Room, Simulator
    from lti_motion.recordings import EndPoseRuns

    cmd, bounds, directions = umbmark_squares(params.period_s, params.wheel_base_m,
                                              side_m=side_m, runs=runs)
    sim = Simulator(params, seed=seed, floor=floor, room=Room.empty(),
                    initial_pose=(0.0, 0.0, 0.0))
    log = sim.run(cmd)
    rng = np.random.default_rng([seed, 0x0B])
    std = np.array([measure_std[0], measure_std[0], measure_std[1]])
    ends = np.minimum(bounds, len(log.t_s) - 1)
    measured = log.true_pose[ends] + rng.standard_normal((len(ends), 3)) * std
    # the headings show the net turn modulo a turn; a square turns one whole turn
    seen = np.angle(np.exp(1j * np.diff(measured[:, 2])))
    turns = np.round((2 * np.pi * np.array(directions) - seen) / (2 * np.pi)).astype(int)
    return log, EndPoseRuns(times_s=np.stack([log.t_s[ends[:-1]], log.t_s[ends[1:]]], 1),
                            start_poses=measured[:-1], end_poses=measured[1:], turns=turns)


def _runs_text(runs: EndPoseRuns) -> str:
    """The runs file (:data:`lti_motion.recordings.RUNS_HEADER`, one run a line)."""
    from lti_motion.recordings import RUNS_HEADER

    lines = [RUNS_HEADER]
    for (t0, t1), p0, p1, turns in zip(runs.times_s, runs.start_poses, runs.end_poses,
                                       runs.turns, strict=True):
        lines.append(" ".join(f"{v:.6f}" for v in (t0, t1, *p0, *p1)) + f" {int(turns)}")
    return "\n".join(lines) + "\n"


def run_umbmark(args: argparse.Namespace) -> int:
    """Handler of ``lti-motion calibrate --umbmark``; returns the exit code.

    Raises
    ------
    ValueError
        No simulated robot, or options out of range (one line, exit 2).
    """
    import numpy as np

    from drivers.sim import load_robot
    from lti_motion.app.calibrate_run import check_writable_folder
    from lti_motion.app.intrinsics_cli import run_intrinsics_calibration
    from lti_motion.recordings import save_log

    if not args.sim or args.port or args.log or args.bag:
        raise ValueError("--umbmark drives the simulator: give --robot NAME_OR_FILE (on a "
                         "robot, drive the squares, write the runs file and give it with "
                         "--log LOG --reference RUNS)")
    if not (np.isfinite(args.umbmark_side) and args.umbmark_side > 0):
        raise ValueError(f"--umbmark-side must be a positive length [m], got "
                         f"{args.umbmark_side:g}")
    if args.umbmark_runs < 2:
        raise ValueError(f"--umbmark-runs must be at least 2 squares each way, got "
                         f"{args.umbmark_runs}")
    out = Path(args.out)
    check_writable_folder(out)
    params = load_robot(args.sim)
    print(f"UMBmark: {args.umbmark_runs} squares of {args.umbmark_side:g} m counter-clockwise, "
          f"then clockwise, simulated {params.name} robot (seed {args.seed})")
    log, runs = simulate_umbmark(params, side_m=args.umbmark_side, runs=args.umbmark_runs,
                                 seed=args.seed, floor=args.floor)
    out.mkdir(parents=True, exist_ok=True)
    log_path = save_log(out / "log_umbmark.npz", log)
    runs_path = out / "umbmark_runs.txt"
    runs_path.write_text(_runs_text(runs))
    print(f"wrote {log_path} and {runs_path} (poses measured with 5 mm, 0.5 deg noise)")
    # the squares end where they start: their travel cannot give the scale, so the
    # wheels' mean scale is the description's and the fit gives the ratio and the base
    if args.m_per_tick is None:
        args.m_per_tick = params.m_per_tick
    print(f"wheels' mean scale held at {args.m_per_tick * 1e3:.5f} mm/tick (--m-per-tick, "
          f"default the {params.name} description's); refit after editing: lti-motion "
          f"calibrate --log {log_path} --reference {runs_path} --m-per-tick "
          f"{args.m_per_tick:.9g}")
    args.log, args.reference = str(log_path), str(runs_path)
    return run_intrinsics_calibration(args)
