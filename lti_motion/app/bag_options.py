"""The options of ``--bag`` (a recorded ROS bag) on ``calibrate``, ``replay`` and ``monitor``.

Only the argument definitions, light so that ``lti-motion --help`` loads no bag reader;
the bag commands (:mod:`lti_motion.app.bag_commands`) read what they parse.
"""

from __future__ import annotations

import argparse

__all__ = ["add_bag_options"]


def add_bag_options(parser: argparse.ArgumentParser, *, shared_with_log: bool = False) -> None:
    """The options of --bag: topics where a bag holds several of a kind, joints, encoder.

    ``shared_with_log``: ``calibrate`` already has ``--wheel-radius`` and ``--encoders`` (for
    ``--log``); they mean the same for a bag and are not added twice."""
    group = parser.add_argument_group(
        "ROS bag (--bag)", "topics are found by message type when the bag has one of each")
    for kind, what in (("cmd", "Twist or TwistStamped commands"),
                       ("wheels", "JointState wheel angles"),
                       ("odom", "Odometry (its twist, where the bag has no wheel angles)"),
                       ("imu", "Imu"),
                       ("truth", "reference poses: PoseStamped (found by type), "
                                 "PoseWithCovarianceStamped or nav_msgs/Odometry (named)")):
        group.add_argument(f"--{kind}-topic", metavar="TOPIC", help=f"the {what} topic")
    group.add_argument("--truth-parent", metavar="FRAME",
                       help="reference poses from tf: the parent frame (default the first "
                            "of world, map, odom with the child frame)")
    group.add_argument("--truth-child", metavar="FRAME",
                       help="reference poses from tf: the robot's frame (default base_link, "
                            "else base_footprint)")
    group.add_argument("--left-joint", default="left", metavar="PATTERN",
                       help="left wheel joint: its name or a pattern (default 'left')")
    group.add_argument("--right-joint", default="right", metavar="PATTERN",
                       help="right wheel joint: its name or a pattern (default 'right')")
    group.add_argument("--ticks-per-rad", type=float, default=None,
                       help="encoder counts per wheel radian: with the wheel radius, the "
                            "encoder scale the model keeps (default: calibrate --robot's "
                            "description, else 10000, the angles' own resolution; replay and "
                            "monitor: the model's robot's)")
    if not shared_with_log:
        group.add_argument("--wheel-radius", type=float, default=None,
                           help="nominal wheel radius [m] (default the model's robot's)")
        group.add_argument("--encoders", choices=["commanded", "quadrature"],
                           default=None,
                           help="commanded: the angles count in the commanded direction "
                                "(Roomba, Create 2); quadrature: they know the way the wheel "
                                "turns (default)")
    group.add_argument("--max-wheel-speed", type=float, default=None, metavar="M_S",
                       help="refuse wheel speeds above this as impossible [m/s] (default 20 for a "
                            "bag; calibrate --log: 5)")
    group.add_argument("--stamps", choices=["auto", "header", "receive"], default="auto",
                       help="time base of every topic: the messages' header stamps, the "
                            "bag's receive times, or auto (default): the header stamps unless "
                            "the topics' clocks disagree by more than a period; printed")
    group.add_argument("--dt", type=float, default=None,
                       help="sensor period [s] (default: calibrate from the wheel stamps, "
                            "replay and monitor the model's); calibrate refuses one more "
                            "than 10%% from the wheel stamps' own period")
