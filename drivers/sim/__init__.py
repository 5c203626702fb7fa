"""The simulator wing: a non-linear physics simulator of a differential-drive robot.

- :mod:`drivers.sim.config`: robot parameters and presets, floors, rooms, faults;
- :mod:`drivers.sim.simulator`: :class:`Simulator`, one robot or many in lock step;
- :mod:`drivers.sim.kernel`: the compiled inner loop;
- :mod:`drivers.sim.calibration`: the simulated robot calibrated as a user calibrates
  a real one.
"""

from drivers.sim.calibration import calibrate_simulator
from drivers.sim.config import FLOORS, PRESETS, Fault, FloorMap, RobotParams, Room, get_preset
from drivers.sim.simulator import Simulator, ground_m_per_tick

__all__ = [
    "FLOORS",
    "PRESETS",
    "Fault",
    "FloorMap",
    "RobotParams",
    "Room",
    "Simulator",
    "calibrate_simulator",
    "get_preset",
    "ground_m_per_tick",
]
