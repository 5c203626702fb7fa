"""The options of ``lti-motion replay`` (the run itself: :mod:`lti_motion.app.replay` and,
with ``--bag``, :mod:`lti_motion.app.bag_commands`).

Light on purpose: ``lti-motion --help`` builds every sub-command's parser, and this
module imports no numerical machinery.
"""

from __future__ import annotations

import argparse

from lti_motion.app.bag_options import add_bag_options

__all__ = ["DESCRIPTION", "HELP", "add_arguments"]

#: One line in ``lti-motion --help``.
HELP = "run the estimators on a recorded log or an MRCLAM robot"
#: The head of ``lti-motion replay --help``.
DESCRIPTION = ("Runs the estimators (encoder odometry, commands, the model sensor-less, "
               "the model's EKF with encoders, and with landmarks where there are "
               "sightings) on an lti-motion log (.npz, docs/log_format.md) or an MRCLAM "
               "data set folder; prints ATE / RPE where there is ground truth; writes one "
               "TUM trajectory per estimator (and groundtruth.tum) for evo, "
               "metrics.json and plots. See docs/replay.md.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``lti-motion replay``, and those of ``--bag``."""
    parser.add_argument("source", metavar="LOG_OR_DATASET", nargs="?",
                        help="an .npz log, or an MRCLAM_Dataset folder (or give --bag)")
    parser.add_argument("--bag", help="a recorded ROS bag instead (docs/guide_ros_bags.md)")
    parser.add_argument("--out-bag", metavar="NEW_BAG",
                        help="--bag: also write the EKF's estimates (nav_msgs/Odometry with "
                             "covariance) into this new bag (.bag: ROS 1; else a ROS 2 folder)")
    parser.add_argument("--model", help="model file from 'lti-motion calibrate' (model_arx.json)")
    parser.add_argument("--fit-first-half", action="store_true",
                        help="MRCLAM only, instead of --model: fit an ARX model on the first half "
                             "of the robot's run and replay the second half")
    parser.add_argument("--robot", type=_robot, default=None, metavar="N_OR_FILE",
                        help="MRCLAM robot number 1-5 (default 1), or robot index of a batch log "
                             "(default 0); with --bag, a robot file or preset whose wheel "
                             "radius and ticks per revolution read the wheel angles, over the "
                             "model's robot (docs/robot_file.md)")
    parser.add_argument("--out", default="out/replay", help="output folder (default out/replay)")
    parser.add_argument("--estimators", nargs="+", metavar="NAME",
                        choices=["odometry", "commands", "sensorless", "ekf", "ekf_landmarks"],
                        help="which to run: odometry commands sensorless ekf ekf_landmarks "
                             "(default: every one the recording can feed)")
    parser.add_argument("--start-s", type=float, default=0.0,
                        help="skip this much of the recording [s] (default 0)")
    parser.add_argument("--duration-s", type=float, default=None,
                        help="replay only this long [s] (default: to the end)")
    parser.add_argument("--initial-pose", type=float, nargs=3, metavar=("X", "Y", "THETA"),
                        help="start pose [m m rad] (default: the first ground-truth pose, "
                             "else 0 0 0)")
    parser.add_argument("--rpe-s", type=float, default=1.0, help="RPE step [s] (default 1)")
    parser.add_argument("--gyro", action="store_true",
                        help="the EKF fuses the log's gyro or the bag's Imu yaw rate (bias "
                             "estimated; it helps where the wheels slip, and can cost on a hard "
                             "floor: docs/ekf.md)")
    add_bag_options(parser)


def _robot(text: str) -> int | str:
    """``--robot``: a whole number (an MRCLAM robot, a batch log's index), else a robot file
    or preset name."""
    try:
        return int(text)
    except ValueError:
        return text
