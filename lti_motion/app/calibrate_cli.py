"""The options of ``lti-motion calibrate`` (the runs: :mod:`lti_motion.app.calibrate_run`,
:mod:`lti_motion.app.calibrate_log`, :mod:`lti_motion.app.intrinsics_cli`,
:mod:`lti_motion.app.umbmark_cli`,
:mod:`lti_motion.app.wall_run_cli` and, with ``--bag``, :mod:`lti_motion.app.bag_commands`).

Light on purpose: ``lti-motion --help`` builds every sub-command's parser, and this
module imports no numerical machinery.
"""

from __future__ import annotations

import argparse

from lti_motion.app.bag_options import add_bag_options
from lti_motion.app.intrinsics_cli import add_intrinsics_arguments
from lti_motion.app.robot_options import FLOOR_NAMES, ROBOT_HELP
from lti_motion.app.umbmark_cli import add_umbmark_arguments
from lti_motion.app.wall_run_cli import add_wall_run_arguments

__all__ = ["DESCRIPTION", "HELP", "add_arguments"]

#: One line in ``lti-motion --help``.
HELP = "calibrate the encoder scale, FIR and ARX models by driving"
#: The head of ``lti-motion calibrate --help``.
DESCRIPTION = ("Runs the paper's manoeuvres (rotation in place, one-motor steps, "
               "random excitation) on the simulator or a robot, keeps each drive as "
               "log_<manoeuvre>.npz as it ends (--resume goes on from them), fits the "
               "models, writes plots, and model_arx.json and model_fir.json when the "
               "model is healthy; or fits the ARX model offline from a recorded drive "
               "(--log). See docs/guide_calibrate_real_robot.md.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``lti-motion calibrate``: where to drive or what was recorded, the
    robot's description, the intrinsics and wall-run options, and those of ``--bag``."""
    parser.add_argument("--robot", "--sim", dest="sim", metavar="NAME_OR_FILE",
                        help=f"calibrate {ROBOT_HELP}; with --port or --log, the robot's "
                             "description (wheel base; with --log also its encoder scale and "
                             "wheel radius)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--port", help="serial device of a Roomba / Create 2, e.g. /dev/ttyUSB0")
    where.add_argument("--log", metavar="FILE",
                       help="calibrate the ARX model offline from a recorded drive of any "
                            "differential drive (.npz, docs/log_format.md); prints an "
                            "excitation report; the encoder scale then comes from "
                            "--m-per-tick, --wheel-radius or --robot; with --reference, both "
                            "wheels' scale and the wheel base instead (docs/intrinsics.md)")
    parser.add_argument("--m-per-tick", type=float, default=None,
                        help="with --log: encoder scale [m/tick] from the robot description")
    parser.add_argument("--wheel-radius", type=float, default=None,
                        help="with --log or --bag: wheel radius [m] for wheel angles or speeds "
                             "in rad/s (default: the --robot description's; --bag: else the "
                             "bag's /robot_description; none assumed)")
    where.add_argument("--bag", help="a recorded ROS bag (ROS 1 .bag, or a ROS 2 folder with a "
                                     ".db3 or .mcap file): fit the ARX model on its drive "
                                     "(docs/guide_ros_bags.md)")
    add_intrinsics_arguments(parser)
    add_wall_run_arguments(parser)
    add_umbmark_arguments(parser)
    parser.add_argument("--baud", type=int, default=115200, help="baud rate (default 115200)")
    parser.add_argument("--clock-rate", type=float, default=1.0,
                        help="robot seconds per wall second: 1 for a real robot, the --speed "
                             "of a faster virtual Roomba")
    parser.add_argument("--wheel-base", type=float, default=None,
                        help="nominal wheel base [m] (default: the --robot description's; "
                             "--bag: else the bag's /robot_description, none assumed; else "
                             "0.235, the Create 2)")
    parser.add_argument("--floor", help="floor name recorded in the model (default: hard, or "
                        f"the robot's) and simulated with --robot: {', '.join(FLOOR_NAMES)}")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random excitation")
    parser.add_argument("--excitation-s", type=float, default=180.0,
                        help="length of the random excitation [s] (default 180)")
    parser.add_argument("--out", default="out/calibration", help="output folder")
    parser.add_argument("--yes", action="store_true",
                        help="do not wait for Enter between manoeuvres (robot already placed)")
    parser.add_argument("--resume", action="store_true",
                        help="use the drives an earlier, stopped run kept in --out "
                             "(log_<manoeuvre>.npz) and drive only the rest")
    parser.add_argument("--accept-unhealthy", action="store_true",
                        help="save the model even if its held-out fit is below the healthy 85%% "
                             "(docs/guide_calibrate_real_robot.md), or, with --log or --bag, "
                             "its order or delay is at the top of the widened search range")
    parser.add_argument("--start-s", type=float, default=None,
                        help="with --log or --bag: start of the time span held out of the fit "
                             "[s from the drive's start] (default: the last 20%% of the drive)")
    parser.add_argument("--duration-s", type=float, default=None,
                        help="with --log or --bag: length of the held-out span [s] (default: "
                             "to the end of the drive)")
    add_bag_options(parser, shared_with_log=True)
