"""The options of ``lti-motion virtual-roomba`` (the Roomba itself:
:func:`drivers.roomba.virtual.serve`).

Light on purpose: ``lti-motion --help`` builds every sub-command's parser, and this
module imports no numerical machinery.
"""

from __future__ import annotations

import argparse

from lti_motion.app.robot_options import FLOOR_HELP, FLOOR_NAMES, ROBOT_HELP

__all__ = ["DESCRIPTION", "HELP", "add_arguments"]

#: One line in ``lti-motion --help``.
HELP = "a simulated Roomba on a pseudo-terminal"
#: The head of ``lti-motion virtual-roomba --help``.
DESCRIPTION = ("Starts the simulator behind the Roomba Open Interface on a "
               "pseudo-terminal and prints its device path; connect with "
               "'lti-motion calibrate --port PATH'. Ctrl-C stops it.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``lti-motion virtual-roomba``."""
    parser.add_argument("--robot", "--preset", dest="preset", default="create2",
                        metavar="NAME_OR_FILE", help=f"{ROBOT_HELP} (default: create2)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--speed", type=float, default=1.0,
                        help="simulated seconds per wall-clock second (default 1: real time)")
    parser.add_argument("--floor", choices=FLOOR_NAMES, help=FLOOR_HELP)
    parser.add_argument("--duration", type=float, default=None,
                        help="stop after this many wall-clock seconds (default: run until Ctrl-C)")
