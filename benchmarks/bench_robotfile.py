"""Reading robot files: what the shipped presets cost on first use, and one user file.

``drivers.sim.config`` builds :data:`~drivers.sim.PRESETS` from the shipped robot
files the first time a preset is asked for (not at import: ``lti-motion --help`` reads
no file), so this is paid once by every program that simulates a preset.

Baseline: the presets as the code built them before they were files, two
``RobotParams`` constructions (one with eight fields overridden), in the same process.
"""

from __future__ import annotations

from benchmarks.harness import Figure, benchmark, median_seconds
from drivers.sim.config import RobotParams, load_robot
from drivers.sim.robot_file import preset_names


def _presets_from_files() -> dict[str, RobotParams]:
    return {name: load_robot(name) for name in preset_names()}


def _presets_in_code() -> dict[str, RobotParams]:
    return {"create2": RobotParams(),
            "paper": RobotParams(name="paper", period_s=0.018, wheel_base_m=0.33,
                                 wheel_diameter_m=0.068, mass_kg=3.8, yaw_inertia_kg_m2=0.07,
                                 delay_periods=4.5, settling_time_s=0.27)}


@benchmark("robotfile")
def robot_files() -> list[Figure]:
    t_files = median_seconds(_presets_from_files, repeat=51, warmup=3)
    t_code = median_seconds(_presets_in_code, repeat=51, warmup=3)
    t_one = median_seconds(lambda: load_robot("create2"), repeat=51, warmup=3)
    return [Figure("robotfile.presets_first_use_ms", 1e3 * t_files, "ms", target=10.0,
                   better="lower", baseline="the two presets built in code",
                   baseline_value=1e3 * t_code),
            Figure("robotfile.load_one_file_ms", 1e3 * t_one, "ms", target=5.0,
                   better="lower")]
