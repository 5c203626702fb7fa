"""Where data comes from: the physics simulator, the Roomba Open Interface, logs."""

from drivers.exceptions import SimulatorError
from drivers.sim import Simulator, ground_m_per_tick
from drivers.sim_config import FLOORS, PRESETS, Fault, FloorMap, RobotParams, Room, get_preset

__all__ = [
    "FLOORS",
    "PRESETS",
    "Fault",
    "FloorMap",
    "RobotParams",
    "Room",
    "Simulator",
    "SimulatorError",
    "get_preset",
    "ground_m_per_tick",
]
