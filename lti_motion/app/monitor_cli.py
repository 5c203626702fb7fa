"""The options of ``lti-motion monitor`` (the run itself: :mod:`lti_motion.app.monitor` and,
with ``--bag``, :mod:`lti_motion.app.bag_commands`).

Light on purpose: ``lti-motion --help`` builds every sub-command's parser, and this
module imports no numerical machinery.
"""

from __future__ import annotations

import argparse

from lti_motion.app.bag_options import add_bag_options
from lti_motion.app.robot_options import FLOOR_HELP, FLOOR_NAMES, ROBOT_HELP

__all__ = ["DESCRIPTION", "HELP", "add_arguments"]

#: One line in ``lti-motion --help``.
HELP = "drive (or listen), run the EKF and the residual monitor, print alarms"
#: The head of ``lti-motion monitor --help``.
DESCRIPTION = ("Drives a rounded-rectangle route with speed changes (the simulator or a "
               "robot; --listen only reads a robot), runs the model's EKF on the encoders "
               "with the residual monitor (gate and glitch bursts, stuck encoder, dynamics "
               "tests after a Phase-I fit on nominal drives, and on the simulator the "
               "landmark "
               "scale test), and prints each alarm as it is raised (time, "
               "kind, test, statistic > threshold, onset) and a summary. Without --model, "
               "--robot calibrates the simulated robot first; --port needs --model. See "
               "docs/guide_alarms.md.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``lti-motion monitor``: where to drive (one of --robot, --port,
    --bag), the monitor's, and those of ``--bag``."""
    mwhere = parser.add_mutually_exclusive_group(required=True)
    mwhere.add_argument("--robot", "--sim", dest="sim", metavar="NAME_OR_FILE",
                        help=f"monitor {ROBOT_HELP}")
    mwhere.add_argument("--port", help="serial device of a Roomba / Create 2")
    mwhere.add_argument("--bag", help="a recorded ROS bag: monitor its drive, alarms with bag "
                                      "time (needs --model)")
    parser.add_argument("--out-bag", metavar="NEW_BAG",
                        help="--bag: write the estimates (nav_msgs/Odometry with covariance) and "
                             "the alarms (diagnostic_msgs/DiagnosticArray) into this new bag")
    parser.add_argument("--model", help="model file (model_arx.json from 'lti-motion calibrate')")
    parser.add_argument("--duration", type=float, default=30.0,
                        help="robot seconds to drive or listen (default 30)")
    parser.add_argument("--fault", choices=["stuck-encoder", "stall", "spikes", "payload", "motor",
                                            "delay", "carpet", "wheel-drift"],
                        help="--robot only: inject this simulator fault (stall: the left wheel "
                             "blocked for 2 s; wheel-drift: the left wheel's diameter +0.5%%)")
    parser.add_argument("--nominal-drives", type=int, default=20,
                        help="--robot: nominal drives of the same length first, for the dynamics "
                             "null and the encoder gate (default 20; 0: dynamics tests off)")
    parser.add_argument("--nominal", nargs="+", metavar="LOG.npz",
                        help="--port: logs of nominal drives (--record) for the dynamics null and "
                             "the encoder gate (without: dynamics tests off)")
    parser.add_argument("--fault-at", type=float, default=None,
                        help="onset of --fault [s] (default: half the duration)")
    parser.add_argument("--seed", type=int, default=0, help="simulator and route seed (default 0)")
    parser.add_argument("--floor", choices=FLOOR_NAMES, help=FLOOR_HELP)
    parser.add_argument("--excitation-s", type=float, default=60.0,
                        help="--robot without --model: calibration excitation [s] (default 60)")
    parser.add_argument("--baud", type=int, default=115200, help="baud rate (default 115200)")
    parser.add_argument("--clock-rate", type=float, default=1.0,
                        help="robot seconds per wall second (the --speed of a virtual Roomba)")
    parser.add_argument("--listen", action="store_true",
                        help="--port only: send no wheel command, only read the stream")
    parser.add_argument("--record", metavar="FILE.npz",
                        help="also write the frames as a log that 'lti-motion replay' reads")
    parser.add_argument("--gyro", action="store_true",
                        help="the EKF fuses the robot file's [gyro] or the bag's Imu yaw rate "
                             "(bias estimated; it helps where the wheels slip, and can cost on a "
                             "hard floor: docs/ekf.md)")
    add_bag_options(parser)
