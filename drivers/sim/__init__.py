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
    "FAULT_FIELDS",
    "FLOORS",
    "N_NOISE",
    "N_PARAMS",
    "N_PERIOD",
    "N_STATE",
    "OVERCURRENT_S",
    "PRESETS",
    "QUEUE_LEN",
    "SCHEMA",
    "Fault",
    "Field",
    "Floor",
    "FloorMap",
    "RobotGeometry",
    "RobotParams",
    "RobotSpec",
    "Room",
    "Simulator",
    "calibrate_simulator",
    "floor_name",
    "get_floor",
    "get_preset",
    "ground_m_per_tick",
    "intrinsics_drive",
    "load_robot",
    "preset_names",
    "print_progress",
    "read_robot_file",
    "robot_geometry",
    "robot_source",
    "run_periods",
    "summarize",
    "wall_run_simulator",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "drivers.sim.calibration": (
            "calibrate_simulator",
            "print_progress",
            "summarize",
            "wall_run_simulator",
        ),
        "drivers.sim.config": (
            "FLOORS",
            "Fault",
            "Floor",
            "FloorMap",
            "PRESETS",
            "RobotParams",
            "Room",
            "floor_name",
            "get_floor",
            "get_preset",
            "load_robot",
        ),
        "drivers.sim.kernel": (
            "N_NOISE",
            "N_PARAMS",
            "N_PERIOD",
            "N_STATE",
            "OVERCURRENT_S",
            "QUEUE_LEN",
            "run_periods",
        ),
        "drivers.sim.motion_capture": ("intrinsics_drive",),
        "drivers.sim.robot_file": (
            "FAULT_FIELDS",
            "Field",
            "RobotGeometry",
            "RobotSpec",
            "SCHEMA",
            "preset_names",
            "read_robot_file",
            "robot_geometry",
            "robot_source",
        ),
        "drivers.sim.simulator": (
            "Simulator",
            "ground_m_per_tick",
        ),
    },
    __all__,
)

if TYPE_CHECKING:
    from drivers.sim.calibration import (
        calibrate_simulator,
        print_progress,
        summarize,
        wall_run_simulator,
    )
    from drivers.sim.config import (
        FLOORS,
        PRESETS,
        Fault,
        Floor,
        FloorMap,
        RobotParams,
        Room,
        floor_name,
        get_floor,
        get_preset,
        load_robot,
    )
    from drivers.sim.kernel import (
        N_NOISE,
        N_PARAMS,
        N_PERIOD,
        N_STATE,
        OVERCURRENT_S,
        QUEUE_LEN,
        run_periods,
    )
    from drivers.sim.motion_capture import intrinsics_drive
    from drivers.sim.robot_file import (
        FAULT_FIELDS,
        SCHEMA,
        Field,
        RobotGeometry,
        RobotSpec,
        preset_names,
        read_robot_file,
        robot_geometry,
        robot_source,
    )
    from drivers.sim.simulator import Simulator, ground_m_per_tick
