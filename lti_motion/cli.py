"""The ``lti-motion`` command line (the application layer: wires core, drivers and fusion).

Sub-commands
------------
demo
    Calibrate on the simulator as the paper does, then its route evaluation
    (Table II) for every estimator; writes a report folder.
calibrate
    Run the calibration manoeuvres on the simulator or a real robot, fit the
    encoder scale, FIR and ARX models, save them and their plots.
virtual-roomba
    A simulated Roomba behind the Open Interface on a pseudo-terminal.

This module and the experiment runners are the only part of ``lti_motion``
allowed to import ``drivers`` and ``fusion`` (ARCHITECTURE.md, Layout).
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

__all__ = ["main"]


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from lti_motion.calibration import CalibrationPlan, calibrate
    from lti_motion.experiments.plots import plot_calibration
    from lti_motion.experiments.sim_calibration import (
        calibrate_simulator,
        print_progress,
        summarize,
    )

    plan = CalibrationPlan(seed=args.seed, excitation_s=args.excitation_s)
    out = Path(args.out)
    if args.sim:
        print(f"calibrating the simulated {args.sim} robot on {args.floor} floor "
              f"(seed {args.seed})")
        cal = calibrate_simulator(args.sim, seed=args.seed, floor=args.floor, plan=plan,
                                  progress=print_progress)
    else:
        from drivers.roomba import Roomba

        def before_stage(stage: str) -> None:
            where = {"rotation": "beside a wall or furniture (within 30 cm), room to turn",
                     "steps": "on open floor, 2 m clear all round",
                     "excitation": "on open floor, 2 m clear all round"}[stage]
            print(f"next: {stage}. Put the robot {where}.")
            if not args.yes:
                input("press Enter when it is there (Ctrl-C stops the robot) ")

        print(f"calibrating the robot on {args.port} at {args.baud} baud")
        with Roomba(args.port, baud=args.baud, clock_rate=args.clock_rate) as robot:
            cal = calibrate(robot, wheel_base_m=args.wheel_base, plan=plan, floor=args.floor,
                            progress=print_progress, before_stage=before_stage)
    out.mkdir(parents=True, exist_ok=True)
    cal.arx.save(out / "model_arx.json")
    cal.fir.save(out / "model_fir.json")
    plots = plot_calibration(cal, out)
    for line in summarize(cal):
        print(line)
    print(f"wrote {out / 'model_arx.json'}, {out / 'model_fir.json'} and "
          f"{', '.join(p.name for p in plots)}")
    return 0


def _cmd_virtual_roomba(args: argparse.Namespace) -> int:
    from drivers.virtual_roomba import serve

    try:
        serve(preset=args.preset, seed=args.seed, speed=args.speed, floor=args.floor,
              duration_s=args.duration)
    except KeyboardInterrupt:
        print("\nvirtual Roomba stopped")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from lti_motion.experiments.demo import run_demo

    run_demo(Path(args.out), seed=args.seed, preset=args.preset, floor=args.floor,
             runs=args.runs, excitation_s=args.excitation_s)
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``lti-motion``."""
    parser = argparse.ArgumentParser(
        prog="lti-motion",
        description="Self-calibrating LTI motion models for differential-drive robots.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="run the main job on the simulator",
                          description="Calibrate the simulated robot as the paper does, "
                                      "then drive the paper's closed route with every "
                                      "estimator; writes report.md, metrics.json and plots.")
    demo.add_argument("--out", default="out/demo", help="report folder (default: out/demo)")
    demo.add_argument("--seed", type=int, default=0, help="simulator seed (default: 0)")
    demo.add_argument("--preset", default="create2", choices=["create2", "paper"],
                      help="robot preset (default: create2)")
    demo.add_argument("--floor", default="hard", choices=["hard", "tile", "carpet"],
                      help="floor (default: hard)")
    demo.add_argument("--runs", type=int, default=30, help="route runs per estimator (30)")
    demo.add_argument("--excitation-s", type=float, default=180.0,
                      help="length of the calibration's random excitation [s] (180)")
    demo.set_defaults(func=_cmd_demo)

    cal = sub.add_parser(
        "calibrate", help="calibrate the encoder scale, FIR and ARX models by driving",
        description="Runs the paper's manoeuvres (rotation in place, one-motor steps, "
                    "random excitation) on the simulator or a robot, fits the models, and "
                    "writes model_arx.json, model_fir.json and plots.")
    where = cal.add_mutually_exclusive_group(required=True)
    where.add_argument("--sim", choices=["create2", "paper"], help="calibrate the simulator")
    where.add_argument("--port", help="serial device of a Roomba / Create 2, e.g. /dev/ttyUSB0")
    cal.add_argument("--baud", type=int, default=115200, help="baud rate (default 115200)")
    cal.add_argument("--clock-rate", type=float, default=1.0,
                     help="robot seconds per wall second: 1 for a real robot, the --speed "
                          "of a faster virtual Roomba")
    cal.add_argument("--wheel-base", type=float, default=0.235,
                     help="nominal wheel base [m] (default 0.235, the Create 2)")
    cal.add_argument("--floor", default="hard", help="floor name recorded in the model "
                     "(and simulated with --sim: hard, tile, carpet)")
    cal.add_argument("--seed", type=int, default=0, help="seed of the random excitation")
    cal.add_argument("--excitation-s", type=float, default=180.0,
                     help="length of the random excitation [s] (default 180)")
    cal.add_argument("--out", default="out/calibration", help="output folder")
    cal.add_argument("--yes", action="store_true",
                     help="do not wait for Enter between manoeuvres (robot already placed)")
    cal.set_defaults(func=_cmd_calibrate)

    vr = sub.add_parser(
        "virtual-roomba", help="a simulated Roomba on a pseudo-terminal",
        description="Starts the simulator behind the Roomba Open Interface on a "
                    "pseudo-terminal and prints its device path; connect with "
                    "'lti-motion calibrate --port PATH'. Ctrl-C stops it.")
    vr.add_argument("--preset", default="create2", choices=["create2", "paper"])
    vr.add_argument("--seed", type=int, default=0)
    vr.add_argument("--speed", type=float, default=1.0,
                    help="simulated seconds per wall-clock second (default 1: real time)")
    vr.add_argument("--floor", default="hard", choices=["hard", "tile", "carpet"])
    vr.add_argument("--duration", type=float, default=None,
                    help="stop after this many wall-clock seconds (default: run until Ctrl-C)")
    vr.set_defaults(func=_cmd_virtual_roomba)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``lti-motion`` console script."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except (ValueError, OSError) as exc:
        print(f"lti-motion {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
