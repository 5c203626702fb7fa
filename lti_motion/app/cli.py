"""The ``lti-motion`` command line (the application layer: wires core, drivers and fusion).

Sub-commands
------------
demo
    Calibrate on the simulator as the paper does, then its route evaluation
    (Table II) for every estimator; writes a report folder.
calibrate
    Run the calibration manoeuvres on the simulator or a real robot, fit the
    encoder scale, FIR and ARX models, save them and their plots; or, with
    ``--log``, fit the ARX model offline on any recorded drive.
    ``--log LOG --reference FILE.tum``, both wheels' scale and the wheel base of a
    recorded drive against a pose reference (``docs/intrinsics.md``). With
    ``--wall-run``, the wheels' diameter ratio from straight runs beside a wall.
replay
    Run the estimators on a recorded log or an MRCLAM robot; ATE / RPE where
    there is ground truth, TUM trajectories for ``evo``, plots.
monitor
    Drive the simulator or a robot (or listen), run the EKF with the residual
    monitor, print alarms as they happen and a summary.
virtual-roomba
    A simulated Roomba behind the Open Interface on a pseudo-terminal.
export
    Write a calibrated model as ROS parameters: ``diff_drive_controller``'s multipliers
    and covariances, robot_localization's and fuse's process noise
    (``docs/guide_ros_config.md``).

This module and the experiment runners are the only part of ``lti_motion``
allowed to import ``drivers`` and ``fusion`` (docs/architecture.md, Layout and layers).

Each sub-command's options are added by its own light module (``demo_cli``,
``calibrate_cli``, ``replay_cli``, ``monitor_cli``, ``virtual_roomba_cli``; with
``robot_options`` and ``bag_options`` that several share); this module creates the
sub-parsers and dispatches. Each sub-command imports its machinery inside its handler, so
``lti-motion --help`` and a mistyped option cost only the parser (and numpy, for the
simulator's floor names; robot files are read when a sub-command names a robot).

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import re
import sys
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

# The command's numpy runs OpenBLAS on one thread unless the user set OPENBLAS_NUM_THREADS
# (numpy reads it once, when it loads: here, before the first import that loads it). The
# library's matrices are small; more threads only spin (measured: the demo 126 -> 105 s wall
# on a loaded 2-core machine). The library itself sets nothing: a program that loads numpy
# before this module keeps its own setting.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from drivers.sim import load_robot
from lti_motion.app import (
    calibrate_cli,
    demo_cli,
    export_cli,
    monitor_cli,
    replay_cli,
    virtual_roomba_cli,
)
from lti_motion.exceptions import MissingEncoderScaleError

__all__ = ["main"]



def _cmd_calibrate_log(args: argparse.Namespace) -> int:
    """``calibrate --log FILE``: the ARX model from any recorded drive (docs/calibration.md)."""
    from lti_motion.app.calibrate_log import LogRobot, run_calibrate_log
    from lti_motion.app.calibrate_run import nominal_wheel_base_m
    from lti_motion.app.recorded_health import HeldOut

    described = load_robot(args.sim) if args.sim else None
    if args.m_per_tick is not None or args.wheel_radius is not None:
        source = "the robot description on the command line (--m-per-tick / --wheel-radius)"
    elif described is not None:
        source = f"the nominal {described.name} description (--robot)"
    else:
        source = "the robot description (none given)"
    robot = LogRobot(
        name=described.name if described is not None else None,
        wheel_base_m=nominal_wheel_base_m(args, described),
        m_per_tick=args.m_per_tick if args.m_per_tick is not None
        else (described.m_per_tick if described else None),
        wheel_radius_m=args.wheel_radius if args.wheel_radius is not None
        else (described.wheel_diameter_m / 2 if described else None),
        source=source)
    print(f"calibrating from the recording {args.log}")
    _, lines = run_calibrate_log(args.log, robot, out=Path(args.out), floor=args.floor,
                                 held_out=HeldOut(args.start_s, args.duration_s),
                                 accept_unhealthy=args.accept_unhealthy,
                                 max_wheel_speed_m_s=args.max_wheel_speed, dt_s=args.dt)
    for line in lines:
        print(line)
    return 0


def _bag_options(args: argparse.Namespace):
    from lti_motion.app.bag_commands import BagOptions

    topics = {kind: getattr(args, f"{kind}_topic") for kind in
              ("cmd", "wheels", "odom", "imu", "truth") if getattr(args, f"{kind}_topic")}
    for name in ("ticks_per_rad", "wheel_radius", "dt", "max_wheel_speed"):
        value = getattr(args, name)
        if value is not None and not value > 0:
            raise ValueError(f"--{name.replace('_', '-')} must be positive, got {value:g}")
    ticks_per_rad, wheel_radius_m = args.ticks_per_rad, args.wheel_radius
    sources = {k: f"--{flag}" for k, flag, v in (
        ("ticks_per_rad", "ticks-per-rad", ticks_per_rad),
        ("wheel_radius_m", "wheel-radius", wheel_radius_m)) if v is not None}
    described = _robot_file(args)
    if described is not None:                       # a robot file: its description
        from drivers.sim import robot_geometry

        g = robot_geometry(described)
        if ticks_per_rad is None:
            ticks_per_rad, sources["ticks_per_rad"] = g.ticks_per_rad, f"the {g.source}"
        if wheel_radius_m is None:
            wheel_radius_m, sources["wheel_radius_m"] = g.wheel_radius_m, f"the {g.source}"
    extra = {k: v for k, v in (("ticks_per_rad", ticks_per_rad),
                               ("wheel_radius_m", wheel_radius_m), ("dt_s", args.dt),
                               ("max_wheel_m_s", args.max_wheel_speed))
             if v is not None}
    gyro = getattr(args, "gyro", False)                  # replay and monitor only
    if args.imu_topic and hasattr(args, "gyro") and not gyro:
        raise ValueError("--imu-topic chooses the Imu that --gyro fuses; add --gyro")
    return BagOptions(topics=topics, left_joint=args.left_joint, right_joint=args.right_joint,
                      truth_parent=args.truth_parent, truth_child=args.truth_child,
                      encoders=args.encoders, gyro=gyro, sources=sources, stamps=args.stamps,
                      **extra)


def _robot_file(args: argparse.Namespace) -> str | None:
    """The robot file (or preset) a command names: calibrate's --robot, replay's --robot
    NAME_OR_FILE (a number there is an MRCLAM robot or a batch log's index)."""
    if getattr(args, "sim", None):
        return args.sim
    robot = getattr(args, "robot", None)
    return robot if isinstance(robot, str) else None


def _cmd_calibrate_bag(args: argparse.Namespace) -> int:
    from lti_motion.app.bag_commands import (
        calibrate_from_bag,
        check_commands,
        load_bag_recording,
        plot_bag_fit,
        reading_lines,
    )
    from lti_motion.app.bag_robot import bag_geometry
    from lti_motion.app.plots import plot_order_selection
    from lti_motion.app.recorded_health import (
        HeldOut,
        held_out_line,
        recorded_problems,
        refuse_unhealthy,
    )

    out = Path(args.out)
    options = _bag_options(args)
    rec = load_bag_recording(args.bag, options=options, imu=False, truth=False)
    check_commands(args.bag, rec)
    angles = rec.wheel_kind == "wheel_angles_rad"
    geometry = bag_geometry(args, angles=angles)
    for line in geometry.lines(angles=angles):
        print(line)
    options = replace(options, wheel_radius_m=geometry.wheel_radius_m,
                      ticks_per_rad=geometry.ticks_per_rad, encoders=geometry.encoders)
    cal, rec = calibrate_from_bag(args.bag, wheel_base_m=geometry.wheel_base_m,
                                  options=options, floor=args.floor, recording=rec,
                                  robot_name=geometry.robot, sources=geometry.sources,
                                  held_out=HeldOut(args.start_s, args.duration_s))
    model, grid = cal.model, cal.grid
    if rec.wheel_kind == "body_speeds":           # no wheel angles: the robot's own odometry
        print(f"calibrating from {args.bag}: no sensor_msgs/JointState wheel angles; the "
              f"nav_msgs/Odometry twist on {rec.source.topics['wheel']} as body speeds")
    lost = int((~grid.closed).sum())              # periods no wheel message closed
    print(f"calibrated from {args.bag}: {len(grid.closed)} frames of {model.dt_s * 1e3:g} ms "
          f"({lost} lost), topics {dict(rec.source.topics)}")
    from lti_motion.persistence import atomic_write

    scale = ("none needed (body speeds)" if cal.m_per_tick is None else
             f"{cal.m_per_tick:.6g} m/tick (nominal: wheel radius / ticks per radian)")
    lines = [*reading_lines(rec), *cal.report.lines(), f"encoder scale {scale}"]
    if cal.widened:
        lines.append(f"search widened: {cal.widened}")
    lines += [held_out_line(cal), f"robot description kept in the model: {model.robot.describe()}"]
    for line in lines:
        print(line)
    out.mkdir(parents=True, exist_ok=True)
    with atomic_write(out / "excitation.txt", text=True) as fh:
        fh.write("\n".join(lines) + "\n")
    refuse_unhealthy(recorded_problems(cal), accept_unhealthy=args.accept_unhealthy)
    path = model.save(out / "model_arx.json")
    plot_order_selection(model, out / "order_selection.png")
    fit = plot_bag_fit(model, grid, out / "bag_fit.png")
    print(f"free-run fit on the whole drive (fitted and held-out parts): v {fit[0]:.1f} %, "
          f"w {fit[1]:.1f} %")
    print(f"wrote {path}, {out / 'order_selection.png'}, {out / 'bag_fit.png'} and "
          f"{out / 'excitation.txt'}")
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    if args.wall_run:                               # the diameter ratio beside a wall
        from lti_motion.app.wall_run_cli import run_wall_run

        return run_wall_run(args)
    if args.bag:
        return _cmd_calibrate_bag(args)
    if args.umbmark:                                # UMBmark's square both ways, simulated
        from lti_motion.app.umbmark_cli import run_umbmark

        return run_umbmark(args)
    if args.reference:                              # odometry intrinsics against a reference
        from lti_motion.app.intrinsics_cli import run_intrinsics_calibration

        return run_intrinsics_calibration(args)
    if args.log:
        return _cmd_calibrate_log(args)
    from lti_motion.app.calibrate_run import run_calibrate

    return run_calibrate(args)


def _load_model(path: str):
    from lti_motion.model import MotionModel

    if not Path(path).is_file():
        raise FileNotFoundError(f"no model file {path}; make one with 'lti-motion calibrate'")
    return MotionModel.load(path)


def _cmd_replay_bag(args: argparse.Namespace) -> int:
    from lti_motion.app.bag_commands import replay_bag

    if args.source is not None:
        raise ValueError("give either a log / data set or --bag, not both")
    if args.model is None:
        raise ValueError("replay --bag needs --model FILE (from 'lti-motion calibrate --bag')")
    replay_bag(args.bag, _load_model(args.model), args.out, options=_bag_options(args),
               out_bag=args.out_bag, estimators=args.estimators, start_s=args.start_s,
               duration_s=args.duration_s, initial_pose=args.initial_pose, rpe_s=args.rpe_s)
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    if args.bag:
        return _cmd_replay_bag(args)
    if args.out_bag:
        raise ValueError("--out-bag writes the estimates of a --bag replay; give --bag")
    if args.source is None:
        raise ValueError("give a log (.npz) or an MRCLAM data set folder, or --bag BAG")
    from lti_motion.app.replay import fit_mrclam_model, run_replay

    start_s = args.start_s
    if args.model is not None:
        model = _load_model(args.model)
    elif args.fit_first_half:
        if not Path(args.source).is_dir():
            raise ValueError("--fit-first-half works on an MRCLAM data set folder; for a log "
                             "give --model FILE")
        robot = 1 if args.robot is None else args.robot
        model, half_s = fit_mrclam_model(args.source, robot=robot)
        start_s = max(start_s, half_s)
        Path(args.out).mkdir(parents=True, exist_ok=True)
        print(f"calibrated an ARX model of robot {robot} on the first half of its run: "
              f"order {model.orders['na']}, delay {model.orders['delay']}; saved to "
              f"{model.save(Path(args.out) / 'model_arx.json')}; replaying from "
              f"{start_s:.1f} s (the second half)")
    else:
        raise ValueError("give --model FILE (from 'lti-motion calibrate'), or "
                         "--fit-first-half for an MRCLAM data set")
    run_replay(args.source, model, args.out, estimators=args.estimators, robot=args.robot,
               start_s=start_s, duration_s=args.duration_s, initial_pose=args.initial_pose,
               rpe_s=args.rpe_s, gyro=args.gyro)
    return 0


def _cmd_monitor_bag(args: argparse.Namespace) -> int:
    from lti_motion.app.bag_commands import monitor_bag
    from lti_motion.app.monitor_setup import nominal_from_logs

    if args.fault or args.listen or args.record:
        raise ValueError("--fault, --listen and --record drive a robot; --bag reads a "
                         "recorded drive")
    if args.model is None:
        raise ValueError("monitor --bag needs --model FILE (from 'lti-motion calibrate --bag')")
    model = _load_model(args.model)
    nominal = nominal_from_logs(model, args.nominal) if args.nominal else None
    monitor_bag(args.bag, model, options=_bag_options(args), out_bag=args.out_bag,
                nominal=nominal)
    return 0


def _cmd_monitor(args: argparse.Namespace) -> int:
    if args.bag:
        return _cmd_monitor_bag(args)
    if args.out_bag:
        raise ValueError("--out-bag writes what monitor --bag found; give --bag")
    from lti_motion.app import monitor as live_monitor
    from lti_motion.app.progress import StatusLine

    if args.fault and not args.sim:
        raise ValueError("--fault injects a simulator fault; it needs --robot (the simulator)")
    if args.listen and args.sim:
        raise ValueError("--listen reads a robot's stream; it needs --port")
    if args.gyro and not args.sim:
        raise ValueError("--gyro fuses a robot file's [gyro] or a bag's Imu; a Roomba's "
                         "stream has no gyro")
    if args.nominal and args.sim:
        raise ValueError("--nominal reads logs of a robot's nominal drives; it needs --port "
                         "(--robot drives --nominal-drives itself)")
    robot = load_robot(args.sim) if args.sim else None
    if args.model is not None:
        model = _load_model(args.model)
        if model.m_per_tick is None:          # before any drive: nothing driven, nothing lost
            raise MissingEncoderScaleError.needed_by("the monitor")
    elif args.sim:
        from drivers.sim import calibrate_simulator, print_progress
        from lti_motion.calibration import CalibrationPlan

        print(f"no --model: calibrating the simulated {robot.name} robot first "
              f"({args.excitation_s:g} s of excitation, seed {args.seed})")
        model = calibrate_simulator(robot, seed=args.seed, floor=args.floor,
                                    plan=CalibrationPlan(seed=args.seed,
                                                         excitation_s=args.excitation_s),
                                    progress=print_progress).arx
    else:
        raise ValueError("monitor --port needs --model FILE: calibrate the robot first with "
                         f"'lti-motion calibrate --port {args.port}'")
    if args.sim:
        run = live_monitor.run_on_simulator(model, robot=robot, duration_s=args.duration,
                                            seed=args.seed, floor=args.floor, fault=args.fault,
                                            fault_at_s=args.fault_at, record=args.record,
                                            nominal_drives=args.nominal_drives, gyro=args.gyro,
                                            progress=StatusLine().phase_one)
    else:
        from drivers.exceptions import PassiveModeError

        _check_port_robot(model, args.port)
        try:
            run = live_monitor.run_on_port(model, args.port, duration_s=args.duration,
                                           baud=args.baud, clock_rate=args.clock_rate,
                                           listen=args.listen, seed=args.seed,
                                           record=args.record, nominal_logs=args.nominal or (),
                                           progress=StatusLine().phase_one)
        except PassiveModeError as exc:
            raise OSError(str(exc)) from exc
    return EXIT_INTERRUPTED if run.interrupted else 0     # Ctrl-C: the drive kept, still 130


def _check_port_robot(model, port: str) -> None:
    """``monitor --port``: a Roomba streams raw 16-bit counts, counted in the commanded
    direction, every 15 ms; a model of another robot is refused in one line."""
    if model.robot is None:                 # a model file before version 3: nothing to check
        return
    from drivers.roomba import STREAM_PERIOD_S
    from lti_motion.robot_description import RobotDescription

    roomba = RobotDescription(wheel_data="counts", wheel_base_m=model.robot.wheel_base_m,
                              dt_s=STREAM_PERIOD_S, encoders="commanded", counter_bits=16)
    model.robot.check(roomba, mine=f"the model's robot ({model.robot.robot})",
                      theirs=f"the Roomba on {port}")


def _cmd_virtual_roomba(args: argparse.Namespace) -> int:
    from drivers.roomba import serve

    try:
        serve(preset=load_robot(args.preset), seed=args.seed, speed=args.speed, floor=args.floor,
              duration_s=args.duration)
    except KeyboardInterrupt:
        print("\nvirtual Roomba stopped")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from lti_motion.app.demo import run_demo
    from lti_motion.app.progress import StatusLine

    status = StatusLine()            # the route's progress; the printed lines unchanged
    run_demo(Path(args.out), seed=args.seed, robot=load_robot(args.preset), floor=args.floor,
             runs=args.runs, excitation_s=args.excitation_s, print_fn=status.print,
             progress=status.route)
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from lti_motion.app.ros_config import export_text

    if args.to not in export_cli.TARGET_NAMES:       # before reading anything: one line
        raise ValueError(f"unknown --to {args.to!r}; give one of "
                         f"{', '.join(export_cli.TARGET_NAMES)}")
    model = _load_model(args.model)
    text = export_text(model, args.to, nominal=_nominal(args, model.robot),
                       model_name=args.model,
                       publish_rate_hz=args.publish_rate, frequency_hz=args.frequency,
                       node=args.node)
    if model.odometry_errors is None:                # one line, beside the file's comment
        print(f"note: {args.model} carries no measured odometry error; the pose covariances "
              "stand on the model's output noise, an upper bound (calibrate the intrinsics "
              "against a pose reference to measure it: docs/guide_ros_config.md)",
              file=sys.stderr)
    if args.out:
        from lti_motion.persistence import atomic_write

        out = Path(args.out)
        if out.parent and not out.parent.is_dir():
            raise FileNotFoundError(f"--out {out}: no folder {out.parent}")
        with atomic_write(out, text=True) as f:
            f.write(text)
        print(f"wrote {args.to} parameters to {args.out}")
    else:
        print(text, end="")
    return 0


def _nominal(args: argparse.Namespace, robot=None):
    """``export``: the nominal geometry from the flags, over a URDF, over a robot file, over
    the model's robot (``robot``, :attr:`MotionModel.robot`)."""
    from lti_motion.app.ros_config import CREATE2_TICKS_PER_REV, Nominal

    radius = separation = left = right = None
    sources, ticks, ticks_source = [], CREATE2_TICKS_PER_REV, (
        f"{CREATE2_TICKS_PER_REV:g}, the Create 2's (default; --ticks-per-rev)")
    if robot is not None and robot.wheel_radius_m is not None:   # the model's own robot
        radius, separation = sum(robot.wheel_radius_m) / 2, robot.wheel_base_m
        sources.append(f"the model's robot ({robot.robot})")
        if robot.ticks_per_rev is not None:
            ticks = robot.ticks_per_rev
            ticks_source = f"{ticks:g}, the model's robot's"
    if (args.left_joint or args.right_joint) and not args.urdf:
        raise ValueError("--left-joint and --right-joint name the wheel joints of --urdf; "
                         "give --urdf FILE")
    if args.robot:
        described = load_robot(args.robot)
        radius, separation = described.wheel_diameter_m / 2, described.wheel_base_m
        ticks, ticks_source = (described.ticks_per_rev,
                               f"{described.ticks_per_rev:g}, {described.name}'s")
        sources = [f"the robot file {args.robot}"]          # over the model's robot
    if args.urdf:
        from drivers.bags import read_urdf_wheels

        wheels = read_urdf_wheels(args.urdf, left_joint=args.left_joint,
                                  right_joint=args.right_joint)
        radius, separation = wheels.wheel_radius_m, wheels.wheel_separation_m
        left, right = wheels.left_joint, wheels.right_joint
        sources = [*(s for s in sources if not s.startswith("the model's robot")),
                   f"the URDF {args.urdf} (joints {left}, {right})"]
    if args.wheel_radius is not None:
        radius = args.wheel_radius
        sources.append("--wheel-radius")
    if args.wheel_separation is not None:
        separation = args.wheel_separation
        sources.append("--wheel-separation")
    if args.ticks_per_rev is not None:
        ticks, ticks_source = args.ticks_per_rev, f"{args.ticks_per_rev:g} (--ticks-per-rev)"
    return Nominal(wheel_radius_m=radius, wheel_separation_m=separation, ticks_per_rev=ticks,
                   left_joint=left, right_joint=right,
                   source=", ".join(sources) or "none given (absolute values)",
                   ticks_source=ticks_source)


#: The sub-commands, in the order ``lti-motion --help`` lists them: the name, the light
#: module that adds its options (``HELP``, ``DESCRIPTION``, ``add_arguments``), the handler.
_SUB_COMMANDS = (
    ("demo", demo_cli, _cmd_demo),
    ("calibrate", calibrate_cli, _cmd_calibrate),
    ("replay", replay_cli, _cmd_replay),
    ("monitor", monitor_cli, _cmd_monitor),
    ("virtual-roomba", virtual_roomba_cli, _cmd_virtual_roomba),
    ("export", export_cli, _cmd_export),
)


#: Exit status of a command stopped by Ctrl-C (128 + SIGINT, as a shell reports it).
EXIT_INTERRUPTED = 130


class _Version(argparse.Action):
    """``--version``: the installed distribution's version, looked up only when asked."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: object) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS,
                         help=kwargs.get("help"))

    def __call__(self, parser: argparse.ArgumentParser, *_: object) -> None:
        from importlib.metadata import version

        print(f"lti-motion {version('lti-motion')}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``lti-motion``: one sub-parser per sub-command, whose options
    its own light module adds (``SUB_cli.add_arguments``), and the handler it dispatches to."""
    parser = argparse.ArgumentParser(
        prog="lti-motion",
        description="Self-calibrating LTI motion models for differential-drive robots.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    parser.add_argument("--version", action=_Version, help="print the installed version and exit")
    sub = parser.add_subparsers(dest="command", required=True)
    for name, options, handler in _SUB_COMMANDS:
        command = sub.add_parser(name, help=options.HELP, description=options.DESCRIPTION)
        options.add_arguments(command)
        command.set_defaults(func=handler)
    return parser


#: Shortest random excitation a calibration accepts [s]: the ARX order and delay are chosen
#: on its held-out last 30%, and the calibration-sequence plot shows its first 20 s.
MIN_EXCITATION_S = 20.0

#: Longest random excitation [s]: an hour of driving (the commands are made before the
#: drive; 1e9 s asked numpy for 993 GiB).
MAX_EXCITATION_S = 3600.0

#: Longest ``monitor`` drive [s]: a day (its route is made before the drive).
MAX_MONITOR_S = 86400.0

#: The driver's references to the Open Interface spec and its gotchas ("(spec §1.3, G3,
#: G15)"): the library's readers have them (drivers/roomba/oi.py); a command-line user
#: gets the advice around them.
_SPEC_REFERENCE = re.compile(r"\s*\((?:spec )?§[^)]*\)|\s*\(G\d+(?:, G\d+)*\)"
                             r"|;\s*spec §[^)]*(?=\))")


def _one_line(exc: BaseException) -> str:
    """An error as the command line prints it: one line, without the spec references."""
    return _SPEC_REFERENCE.sub("", " ".join(str(exc).split()))


def _check_args(args: argparse.Namespace) -> None:
    """Refuse options that make no sense, before anything runs (cases: test_cli_nonsense.py).

    Raises
    ------
    ValueError
        One line in the command's words, naming the option and its value.
    """
    def positive(option: str, value: float | None) -> None:
        if value is not None and not (math.isfinite(value) and value > 0):
            raise ValueError(f"{option} must be a positive number, got {value:g}")

    _check_link_and_joints(args)
    excitation_s = getattr(args, "excitation_s", None)
    if excitation_s is not None and not (math.isfinite(excitation_s)
                                         and excitation_s >= MIN_EXCITATION_S):
        raise ValueError(f"--excitation-s must be a finite number of seconds, at least "
                         f"{MIN_EXCITATION_S:g} (the model's order is chosen on its last 30%), "
                         f"got {excitation_s:g}")
    if excitation_s is not None and excitation_s > MAX_EXCITATION_S:
        raise ValueError(f"--excitation-s {excitation_s:g} s is more driving than a "
                         f"calibration needs: give at most {MAX_EXCITATION_S:g} s (an hour; "
                         "180 s is the default)")
    seed = getattr(args, "seed", None)
    if seed is not None and seed < 0:
        raise ValueError(f"--seed must be a whole number of 0 or more, got {seed}")
    if args.command == "calibrate":
        _check_calibrate_args(args, positive)
    elif args.command == "monitor":
        positive("--duration", args.duration)
        if args.duration > MAX_MONITOR_S:
            raise ValueError(f"--duration {args.duration:g} s is longer than a monitor drive "
                             f"can be: give at most {MAX_MONITOR_S:g} s (a day)")
        positive("--clock-rate", args.clock_rate)
        if args.fault_at is not None and args.fault is None:
            raise ValueError("--fault-at is the onset of --fault; give --fault too")
        if args.fault_at is not None and not 0 <= args.fault_at < args.duration:
            raise ValueError(f"--fault-at {args.fault_at:g} s is outside the drive: give a "
                             f"time from 0 to before --duration ({args.duration:g} s)")
        if args.nominal_drives < 0:
            raise ValueError(f"--nominal-drives must be 0 or more, got {args.nominal_drives}")
        if args.record:
            _check_record_path(Path(args.record))
    elif args.command == "replay":
        positive("--rpe-s", args.rpe_s)
        positive("--duration-s", args.duration_s)
        if not (math.isfinite(args.start_s) and args.start_s >= 0):
            raise ValueError(f"--start-s must be 0 or more, got {args.start_s:g}")
        if isinstance(args.robot, str) and not args.bag:
            raise ValueError(f"--robot {args.robot} describes the robot of a --bag's wheel "
                             "angles; a log's counts are read with the model's encoder scale "
                             "(give a robot number for an MRCLAM run or a batch log)")
        if isinstance(args.robot, int) and args.robot < 0:
            raise ValueError(f"--robot must be 0 or more, got {args.robot}")
    elif args.command == "demo" and args.runs < 1:
        raise ValueError(f"--runs must be 1 or more, got {args.runs}")
    elif args.command == "virtual-roomba":
        positive("--speed", args.speed)
        positive("--duration", args.duration)


def _check_link_and_joints(args: argparse.Namespace) -> None:
    """A serial rate the robot speaks; wheel-joint patterns that are regular expressions."""
    if getattr(args, "port", None) and getattr(args, "baud", None) is not None:
        from drivers.roomba import BAUD_RATES

        if args.baud not in BAUD_RATES:
            raise ValueError(f"--baud {args.baud} is not a rate the Open Interface speaks: "
                             f"give one of {', '.join(map(str, BAUD_RATES))} (a Create 2 "
                             "talks at 115200 unless it was told otherwise)")
    for option in ("left_joint", "right_joint"):
        pattern = getattr(args, option, None)
        if pattern is not None:
            try:
                re.compile(pattern)
            except re.error as exc:
                raise ValueError(f"--{option.replace('_', '-')} {pattern!r} is not a valid "
                                 f"joint name pattern (a regular expression): {exc}; give the "
                                 "joint's name") from None


def _check_calibrate_args(args: argparse.Namespace, positive: Callable) -> None:
    """``calibrate``: one place to drive; --wheel-base only for a robot or a recording (the
    simulator has its description's)."""
    alone = bool(args.reference) and not (args.sim or args.port or args.log or args.bag)
    if not (args.sim or args.port or args.log or args.bag or alone):
        raise ValueError("give --robot NAME_OR_FILE (the simulator), --port DEVICE (a robot), "
                         "--log FILE or --bag PATH (a recorded drive)")
    if args.reference and (args.sim or args.port or args.bag):
        raise ValueError("--reference goes with --log LOG.npz (a recorded drive), or alone "
                         "with interval samples")
    if args.into_model and not (args.reference or args.wall_run):
        raise ValueError("--into-model writes the intrinsics that --reference or --wall-run "
                         "calibrates into a copy of a model: give one of them")
    described = load_robot(args.sim) if args.sim else None    # a bad robot file: one line
    recorded = args.log or args.bag
    if described and not (args.port or recorded) and args.wheel_base is not None:
        raise ValueError(f"--wheel-base is for --port, --log and --bag; the simulated "
                         f"{args.sim} has its own ({described.wheel_base_m:g} m)")
    positive("--wheel-base", args.wheel_base)
    positive("--clock-rate", args.clock_rate)
    positive("--max-wheel-speed", args.max_wheel_speed)
    positive("--duration-s", args.duration_s)
    if args.start_s is not None and not (math.isfinite(args.start_s) and args.start_s >= 0):
        raise ValueError(f"--start-s must be 0 or more, got {args.start_s:g}")


def _check_record_path(path: Path) -> None:
    """``monitor --record``: a file name in a folder that can be written, before driving."""
    from lti_motion.app.calibrate_run import check_writable_folder

    if path.is_dir():
        raise ValueError(f"--record {path} is a folder; give a file name, e.g. drive.npz")
    check_writable_folder(path.parent, option="--record")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``lti-motion`` console script."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        _check_args(args)
        return args.func(args)
    except MissingEncoderScaleError:
        print(f"lti-motion {args.command}: error: {_no_encoder_scale(args)}", file=sys.stderr)
        return 2
    except (ValueError, OSError) as exc:                # the README promises one line
        print(f"lti-motion {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        # sub-commands that drive a robot or keep a recording answer Ctrl-C themselves (what
        # was kept, the wheels stopped); every other one stops here, in one line
        print(f"\nlti-motion {args.command}: stopped by Ctrl-C", file=sys.stderr)
        return EXIT_INTERRUPTED


def _no_encoder_scale(args: argparse.Namespace) -> str:
    """What a command-line user can do about a model without an encoder scale, in the words
    and options of the command they ran."""
    if args.command == "demo":
        return ("the demo's calibration of the simulated robot measured no encoder scale, "
                "which turns encoder counts into distances (its rotation in place found no "
                "period); run it again with another --seed or --robot, or look at the "
                "rotation's plots from 'lti-motion calibrate --robot NAME_OR_FILE'")
    model = getattr(args, "model", None)
    what = f"the model {model}" if model else "the model"
    port = getattr(args, "port", None)
    calibrate = f"'lti-motion calibrate --port {port}'" if port else "'lti-motion calibrate'"
    tail = ""
    if args.command == "replay":
        tail = ("; or replay only the estimators that need no encoder counts: "
                "--estimators commands sensorless")
    elif getattr(args, "sim", None):
        tail = "; or leave out --model: --robot then calibrates the simulated robot first"
    elif args.command == "monitor" and getattr(args, "bag", None):
        tail = ("; a bag's odometry twist is monitored in the model's encoder ticks, and a "
                "model calibrated on the twist alone has none: calibrate from wheel angles "
                "or on the robot")
    return (f"{what} has no encoder scale, which turns encoder counts into distances; "
            f"calibrate the robot with {calibrate} (its rotation in place measures "
            f"the scale) and give the model_arx.json it writes with --model{tail}")

if __name__ == "__main__":
    raise SystemExit(main())
