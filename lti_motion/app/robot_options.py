"""The words of ``--robot`` and ``--floor``, shared by the sub-commands that simulate.

Light on purpose: the argument definitions of every sub-command import it, and
``lti-motion --help`` loads them all.
"""

from __future__ import annotations

from drivers.sim import FLOORS

__all__ = ["FLOOR_HELP", "FLOOR_NAMES", "ROBOT_HELP"]

#: The simulator's floors, the choices of --floor.
FLOOR_NAMES = tuple(FLOORS)
#: --robot of demo, calibrate, monitor and virtual-roomba (old spellings --preset, --sim
#: kept as aliases, same dest); replay's --robot is a robot index (docs/robot_file.md).
#: The preset names are written out, not read from the robot files, so that start-up
#: reads no file (tests/lti_motion/app/test_cli.py checks they are all named).
ROBOT_HELP = ("the simulated robot: a preset (create2, paper) or a robot file "
              "(.toml or .json, docs/robot_file.md)")
FLOOR_HELP = "simulated floor (default: the robot's)"
