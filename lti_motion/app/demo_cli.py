"""The options of ``lti-motion demo`` (the run itself: :mod:`lti_motion.app.demo`).

Light on purpose: ``lti-motion --help`` builds every sub-command's parser, and this
module imports no numerical machinery.
"""

from __future__ import annotations

import argparse

from lti_motion.app.robot_options import FLOOR_HELP, FLOOR_NAMES, ROBOT_HELP

__all__ = ["DESCRIPTION", "HELP", "add_arguments"]

#: One line in ``lti-motion --help``.
HELP = "run the main job on the simulator"
#: The head of ``lti-motion demo --help``.
DESCRIPTION = ("Calibrate the simulated robot as the paper does, "
               "then drive the paper's closed route with every "
               "estimator; writes report.md, metrics.json and plots.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``lti-motion demo``."""
    parser.add_argument("--out", default="out/demo", help="report folder (default: out/demo)")
    parser.add_argument("--seed", type=int, default=0, help="simulator seed (default: 0)")
    parser.add_argument("--robot", "--preset", dest="preset", default="create2",
                        metavar="NAME_OR_FILE", help=f"{ROBOT_HELP} (default: create2)")
    parser.add_argument("--floor", choices=FLOOR_NAMES, help=FLOOR_HELP)
    parser.add_argument("--runs", type=int, default=30, help="route runs per estimator (30)")
    parser.add_argument("--excitation-s", type=float, default=180.0,
                        help="length of the calibration's random excitation [s] (180)")
