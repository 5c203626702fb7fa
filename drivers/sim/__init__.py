"""The simulator wing: a non-linear physics simulator of a differential-drive robot.

- :mod:`drivers.sim.config`: robot parameters and presets, floors, rooms, faults;
- :mod:`drivers.sim.robot_file`: robot description files (TOML or JSON), read and checked;
- :mod:`drivers.sim.simulator`: :class:`Simulator`, one robot or many in lock step;
- :mod:`drivers.sim.kernel`: the compiled inner loop;
- :mod:`drivers.sim.calibration`: the simulated robot calibrated as a user calibrates
  a real one.

The names below load with their module on first use (:mod:`lti_motion.lazy`):
``drivers.sim.config`` (numpy only) does not load numba or the calibration.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from lti_motion.lazy import lazy_exports

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
    "load_robot",
]

__getattr__, __dir__ = lazy_exports(__name__, {
    "drivers.sim.calibration": ("calibrate_simulator",),
    "drivers.sim.config": ("FLOORS", "PRESETS", "Fault", "FloorMap", "RobotParams", "Room",
                           "get_preset", "load_robot"),
    "drivers.sim.simulator": ("Simulator", "ground_m_per_tick"),
}, __all__)

if TYPE_CHECKING:
    from drivers.sim.calibration import calibrate_simulator
    from drivers.sim.config import (
        FLOORS,
        PRESETS,
        Fault,
        FloorMap,
        RobotParams,
        Room,
        get_preset,
        load_robot,
    )
    from drivers.sim.simulator import Simulator, ground_m_per_tick
