"""``lti-motion calibrate --wall-run``: the wheels' diameter ratio without any reference,
from straight runs beside a wall, on the simulator (``--sim``) or a Roomba (``--port``).

The manoeuvre is :func:`lti_motion.calibration.drive_wall_run` (the same code on both),
the estimate :func:`lti_motion.calibration.calibrate_wall_run`. The drive is kept as
``OUT/log_wall_run.npz``, the result written as ``OUT/wall_run.json`` (and, with
``--into-model``, a copy of the model carrying the intrinsics) and summarised on the
terminal. The simulator's truth is never read.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from drivers.sim import RobotParams
    from lti_motion.calibration import WallRunCalibration, WallRunDrive
    from lti_motion.intrinsics import OdometryIntrinsics

__all__ = ["add_wall_run_arguments", "run_wall_run"]

#: Exit code after Ctrl-C (128 + SIGINT, the shell's convention).
EXIT_INTERRUPTED = 130


def add_wall_run_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of the wall run on ``lti-motion calibrate``."""
    parser.add_argument("--wall-run", action="store_true",
                        help="with --sim or --port: drive straight runs beside a wall and "
                             "calibrate the wheels' diameter ratio without any reference "
                             "(docs/intrinsics.md); starts from --into-model's intrinsics, "
                             "else the nominal ones")
    parser.add_argument("--wall-run-m", type=float, default=2.0, metavar="M",
                        help="with --wall-run: length of each straight run [m] (default 2, "
                             "at least 0.8)")


def _intrinsics_in_use(args: argparse.Namespace, described: RobotParams | None
                       ) -> tuple[OdometryIntrinsics, str]:
    """The intrinsics the wall run starts from, and where they come from: the model of
    ``--into-model`` (e.g. the rotation manoeuvre's scale), else the robot's nominal ones."""
    from lti_motion.app.calibrate_run import nominal_wheel_base_m
    from lti_motion.intrinsics import OdometryIntrinsics
    from lti_motion.model import MotionModel

    if args.into_model:
        if not Path(args.into_model).is_file():
            raise FileNotFoundError(f"no model file {args.into_model}")
        known = MotionModel.load(args.into_model).encoder_intrinsics
        if known is not None:
            return known, f"those of {args.into_model}"
    if args.m_per_tick is not None:
        scale, source = args.m_per_tick, "--m-per-tick"
    elif described is not None:
        scale, source = described.m_per_tick, f"the nominal ones of {args.sim}"
    else:
        from drivers.sim import get_preset

        scale, source = get_preset("create2").m_per_tick, "a Create 2's nominal ones"
    return (OdometryIntrinsics.symmetric(m_per_tick=scale,
                                         wheel_base_m=nominal_wheel_base_m(args, described)),
            source)


def _check(args: argparse.Namespace) -> None:
    """Refuse, before anything is driven, what cannot give a wall run."""
    from lti_motion.calibration import MIN_RUN_M

    if args.log or args.bag:
        raise ValueError("--wall-run drives the robot: give --sim NAME_OR_FILE or --port DEV, "
                         "not --log or --bag")
    if not (args.sim or args.port):
        raise ValueError("--wall-run needs a robot to drive: --sim NAME_OR_FILE or --port DEV")
    if not args.wall_run_m >= MIN_RUN_M:
        raise ValueError(f"--wall-run-m {args.wall_run_m:g} is too short: the fit needs "
                         f"straight runs of at least {MIN_RUN_M:g} m (default 2)")


def _drive(args: argparse.Namespace, known: OdometryIntrinsics, described: RobotParams | None
           ) -> WallRunDrive:
    """The manoeuvre on the simulator or on the robot at ``--port``."""
    from lti_motion.calibration import drive_wall_run

    if described is not None and not args.port:
        from drivers.sim import wall_run_simulator

        print(f"wall run of the simulated {described.name} robot, 0.5 m in front of a wall "
              f"(seed {args.seed})")
        sim = wall_run_simulator(described, seed=args.seed, floor=args.floor)
        return drive_wall_run(sim, known, run_m=args.wall_run_m)
    from drivers.roomba import Roomba
    from lti_motion.app.prompts import wait_until_placed

    # the port is opened first: a missing robot is said before anyone is asked to place it
    with Roomba(args.port, baud=args.baud, clock_rate=args.clock_rate) as robot:
        print(f"next: the wall run. Put the robot on hard floor facing a straight, plain wall "
              f"0.2-1.5 m ahead, with {args.wall_run_m + 0.5:g} m clear along the wall on "
              "both sides of it.")
        if not args.yes:
            wait_until_placed()
        print(f"driving the wall run on {args.port} at {args.baud} baud")
        return drive_wall_run(robot, known, run_m=args.wall_run_m)


def _summary(cal: WallRunCalibration, drive: WallRunDrive, known: OdometryIntrinsics,
             source: str) -> list[str]:
    import numpy as np

    from lti_motion.calibration import run_path, wall_passes

    over = (" (its first run curved towards the wall on its left)"
            if drive.wall_side == "right" else "")
    lines = [f"wall on the robot's {drive.wall_side}{over}; intrinsics in use: {source} "
             f"(left/right {known.diameter_ratio:.5f})"]
    for i, wp in enumerate(wall_passes(drive, known)):
        travel = run_path(wp.ticks, known)[0][-1]
        lines.append(f"pass {i + 1}: {'forward' if travel > 0 else 'backward'} run of "
                     f"{abs(travel):.2f} m from {wp.gap_start_m * 1e3:.0f} mm off the wall, "
                     f"heading {np.rad2deg(cal.heading_rad[i]):+.2f} deg, curvature "
                     f"{cal.pass_kappa_rad_per_m[i]:+.5f} rad/m")
    k = cal.intrinsics
    lines += [
        f"curvature    {cal.kappa_rad_per_m:+.5f} rad/m +- {cal.kappa_std_rad_per_m:.5f}",
        f"left/right   {cal.diameter_ratio:.5f} +- {cal.diameter_ratio_std:.5f}",
        f"left wheel   {k.m_per_tick_left * 1e3:.5f} mm/tick",
        f"right wheel  {k.m_per_tick_right * 1e3:.5f} mm/tick",
        f"residual     {cal.residual_rms_m * 1e3:.1f} mm RMS",
    ]
    return lines + [f"note: {note}" for note in cal.notes]


def run_wall_run(args: argparse.Namespace) -> int:
    """Handler of ``lti-motion calibrate --wall-run``; returns the exit code.

    Raises
    ------
    ValueError
        Options that cannot give a wall run, and the manoeuvre's and the estimate's errors
        (:class:`~lti_motion.exceptions.WallRunError`, ``NoSignalError``,
        ``UnidentifiableError``, ...); the CLI prints them as one line and exits with 2.
    OSError
        An output folder that cannot be written, a model file that cannot be read.
    """
    import sys

    from drivers.sim import load_robot
    from lti_motion.app.calibrate_run import check_writable_folder
    from lti_motion.app.intrinsics_cli import write_into_model
    from lti_motion.calibration import calibrate_wall_run, wall_passes
    from lti_motion.exceptions import CurvedIntoWallError
    from lti_motion.persistence import atomic_write
    from lti_motion.recordings import save_log

    _check(args)
    out = Path(args.out)
    check_writable_folder(out)
    described = load_robot(args.sim) if args.sim else None
    known, source = _intrinsics_in_use(args, described)
    try:
        drive = _drive(args, known, described)
    except CurvedIntoWallError as exc:
        if args.into_model:
            raise
        raise CurvedIntoWallError(
            f"{exc} (intrinsics in use: {source}; 'lti-motion calibrate' measures the scale "
            "on the floor: give the model_arx.json it writes with --into-model)") from exc
    except KeyboardInterrupt:
        print("\nlti-motion calibrate: stopped by Ctrl-C; the wheels were commanded to stop; "
              "nothing kept", file=sys.stderr)
        return EXIT_INTERRUPTED
    written = [save_log(out / "log_wall_run.npz", drive.log)]
    try:
        cal = calibrate_wall_run(wall_passes(drive, known), known, wall_side=drive.wall_side)
    except ValueError as exc:
        raise type(exc)(f"{exc} (the drive is kept in {written[0]})") from exc
    result = {"intrinsics": cal.intrinsics.as_dict(), "diameter_ratio": cal.diameter_ratio,
              "diameter_ratio_std": cal.diameter_ratio_std,
              "kappa_rad_per_m": cal.kappa_rad_per_m,
              "kappa_std_rad_per_m": cal.kappa_std_rad_per_m,
              "pass_kappa_rad_per_m": list(cal.pass_kappa_rad_per_m),
              "heading_rad": list(cal.heading_rad), "wall_side": drive.wall_side,
              "intrinsics_in_use": known.as_dict(), "notes": list(cal.notes)}
    path = out / "wall_run.json"
    with atomic_write(path, text=True) as fh:       # never half-written
        fh.write(json.dumps(result, indent=2) + "\n")
    written.append(path)
    if args.into_model:
        written.append(write_into_model(args.into_model, cal.intrinsics, out))
    for line in _summary(cal, drive, known, source):
        print(line)
    print(f"wrote {', '.join(str(p) for p in written)}")
    return 0
