"""The options of ``lti-motion export`` (the parameters themselves:
:mod:`lti_motion.app.ros_config`; a URDF's wheels: :mod:`drivers.bags.urdf`).

Light on purpose: ``lti-motion --help`` builds every sub-command's parser, and this
module imports no numerical machinery.
"""

from __future__ import annotations

import argparse

from lti_motion.app.robot_options import ROBOT_HELP

__all__ = ["DESCRIPTION", "HELP", "TARGET_NAMES", "add_arguments"]

#: One line in ``lti-motion --help``.
HELP = "write the calibration as ROS parameters (diff_drive_controller, robot_localization, fuse)"
#: The head of ``lti-motion export --help``.
DESCRIPTION = ("Writes a calibrated model as the parameters a ROS stack takes: "
               "diff_drive_controller's wheel radius and separation multipliers and "
               "covariance diagonals (ROS 2, or ROS 1 with diff_drive_controller_ros1), "
               "robot_localization's process noise, fuse's Unicycle2D process noise; each "
               "number with a comment that says where it came from. See "
               "docs/guide_ros_config.md.")
#: What --to takes (checked by the handler, so a wrong one is one line).
TARGET_NAMES = ("diff_drive_controller", "diff_drive_controller_ros1", "robot_localization",
                "fuse")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``lti-motion export``."""
    parser.add_argument("--model", required=True, metavar="FILE",
                        help="the model file (model_intrinsics.json for diff_drive_controller: "
                             "a model with odometry intrinsics, docs/intrinsics.md)")
    parser.add_argument("--to", required=True, metavar="TARGET",
                        help=f"what to write: {', '.join(TARGET_NAMES)}")
    parser.add_argument("--out", metavar="FILE", help="write here (default: stdout)")
    nominal = parser.add_argument_group("the nominal geometry (diff_drive_controller; without "
                                        "one, absolute values)")
    nominal.add_argument("--wheel-radius", type=float, metavar="M",
                         help="nominal wheel radius [m] (over --robot and --urdf)")
    nominal.add_argument("--wheel-separation", type=float, metavar="M",
                         help="nominal wheel separation [m] (over --robot and --urdf)")
    nominal.add_argument("--robot", metavar="NAME_OR_FILE",
                         help=f"{ROBOT_HELP}: its wheel diameter, wheel base and ticks per "
                              "revolution")
    nominal.add_argument("--urdf", metavar="FILE",
                         help="the robot's URDF: its wheel joints, their separation and the "
                              "wheels' cylinder radius")
    nominal.add_argument("--left-joint", metavar="NAME",
                         help="--urdf: the left wheel joint, when its name does not say left")
    nominal.add_argument("--right-joint", metavar="NAME",
                         help="--urdf: the right wheel joint, when its name does not say right")
    nominal.add_argument("--ticks-per-rev", type=float, metavar="N",
                         help="encoder counts per wheel revolution the hardware interface "
                              "divides by (default: --robot's, else 508.8, the Create 2's)")
    parser.add_argument("--publish-rate", type=float, default=50.0, metavar="HZ",
                        help="the odometry's publish rate [Hz] (diff_drive_controller's "
                             "publish_rate; default 50, its default)")
    parser.add_argument("--frequency", type=float, default=30.0, metavar="HZ",
                        help="the filter's rate [Hz] for robot_localization and fuse (default "
                             "30, robot_localization's default)")
    parser.add_argument("--node", metavar="NAME",
                        help="the node / controller name at the top of the file (default: "
                             "diff_drive_controller, ekf_filter_node, state_estimator)")
