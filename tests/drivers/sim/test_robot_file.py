"""Robot description files: the shipped presets, the schema, and one-line errors per field."""

import json
import re
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from drivers.exceptions import RobotFileError, SimulatorError
from drivers.sim.config import PRESETS, Fault, FaultKind, FloorMap, RobotParams, load_robot
from drivers.sim.robot_file import FAULT_FIELDS, SCHEMA, preset_names
from drivers.sim.simulator import Simulator

ROOT = Path(__file__).resolve().parents[3]

#: The presets as the code defined them before they became files (config.py at 5ea4b37):
#: ``create2`` was RobotParams' defaults, ``paper`` these overrides of them.
FORMER_PRESETS = {
    "create2": RobotParams(),
    "paper": RobotParams(name="paper", period_s=0.018, wheel_base_m=0.33,
                         wheel_diameter_m=0.068, mass_kg=3.8, yaw_inertia_kg_m2=0.07,
                         delay_periods=4.5, settling_time_s=0.27),
}

MINIMAL = """\
name = "mybot"
period_s = 0.02
[geometry]
wheel_base_m = 0.3
wheel_diameter_m = 0.07
[encoders]
ticks_per_rev = 1000
[delay]
delay_periods = 3
[mass]
mass_kg = 4.5
"""


def _write(tmp_path, text, name="my.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_shipped_files_reproduce_the_former_presets_exactly():
    assert preset_names() == ("create2", "paper")
    for name, former in FORMER_PRESETS.items():
        entry = resources.files("drivers.sim") / "robots" / f"{name}.toml"
        assert entry.is_file(), name                       # found as package data
        assert load_robot(name) == former, name            # every field, bit for bit
        assert PRESETS[name] == former, name
    assert PRESETS["create2"].ir_angles_rad == FORMER_PRESETS["create2"].ir_angles_rad


def test_pyproject_ships_the_robot_files_as_package_data():
    doc = tomllib.loads((ROOT / "pyproject.toml").read_text())
    patterns = doc["tool"]["setuptools"]["package-data"]["drivers.sim"]
    shipped = sorted(p.name for p in (ROOT / "drivers/sim/robots").glob("*.toml"))
    matched = sorted({p.name for pat in patterns for p in (ROOT / "drivers/sim").glob(pat)})
    assert matched == shipped == ["create2.toml", "paper.toml"]


def test_a_minimal_file_takes_the_create2_values_for_the_rest(tmp_path):
    robot = load_robot(_write(tmp_path, MINIMAL))
    assert (robot.name, robot.period_s, robot.wheel_base_m, robot.ticks_per_rev,
            robot.delay_periods, robot.mass_kg) == ("mybot", 0.02, 0.3, 1000.0, 3.0, 4.5)
    assert robot.replace(name="create2", period_s=0.015, wheel_base_m=0.235,
                         wheel_diameter_m=0.072, ticks_per_rev=508.8, delay_periods=4.0,
                         mass_kg=3.6) == RobotParams()
    assert robot.floor == "hard" and robot.faults == ()


@pytest.mark.parametrize("bits", [10, 24, 32, 64])
def test_counters_of_any_width_wrap_in_the_simulator_and_unwrap_in_the_odometry(tmp_path, bits):
    """A 10-bit counter wraps every 1024 ticks (0.22 m of a 0.07 m wheel at 1000 ticks per
    turn): the drive's speeds are those of the same drive with 16-bit counters."""
    from drivers.sim.simulator import Simulator
    from lti_motion.calibration.manoeuvres import speeds_from_log
    from lti_motion.recordings.ticks import unwrap_ticks

    text = _replace(MINIMAL, "ticks_per_rev = 1000", f"ticks_per_rev = 1000\ncounter_bits = {bits}")
    robot = load_robot(_write(tmp_path, text))
    assert robot.counter_bits == bits
    cmd = np.tile([[0.3, 0.25]], (300, 1))
    wide = Simulator(robot, seed=4).run(cmd)
    narrow = Simulator(robot.replace(counter_bits=16), seed=4).run(cmd)
    assert wide.counter_bits == bits and narrow.counter_bits == 16
    if bits < 63:
        assert wide.ticks.min() >= 0 and wide.ticks.max() < 2**bits
    np.testing.assert_array_equal(unwrap_ticks(wide.ticks, counter_bits=bits),
                                  unwrap_ticks(narrow.ticks))
    if bits == 10:
        assert np.any(np.diff(wide.ticks[:, 0]) < 0)              # it wrapped
    scale = {"m_per_tick": robot.m_per_tick, "wheel_base_m": robot.wheel_base_m}
    for a, b in zip(speeds_from_log(wide, **scale), speeds_from_log(narrow, **scale),
                    strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_real_robots_file_needs_no_simulator_field(tmp_path):
    from drivers.sim.robot_file import robot_geometry

    text = _replace(_replace(MINIMAL, "[delay]\ndelay_periods = 3\n", ""),
                    "[mass]\nmass_kg = 4.5\n", "")
    text = _replace(text, "ticks_per_rev = 1000", 'ticks_per_rev = 4096\nkind = "quadrature"')
    g = robot_geometry(_write(tmp_path, text))
    assert (g.name, g.period_s, g.wheel_base_m, g.wheel_radius_m) == ("mybot", 0.02, 0.3, 0.035)
    assert (g.ticks_per_rev, g.encoders, g.counter_bits) == (4096, "quadrature", None)
    # the simulator still runs it, on the create2 values for what the file leaves out
    params = load_robot(_write(tmp_path, text, "real.toml"))
    assert (params.mass_kg, params.delay_periods) == (RobotParams().mass_kg,
                                                      RobotParams().delay_periods)


def test_json_and_toml_of_the_same_robot_agree(tmp_path):
    doc = tomllib.loads(MINIMAL)
    doc["floor"] = {"default": "carpet"}
    from_json = load_robot(_write(tmp_path, json.dumps(doc), "my.json"))
    from_toml = load_robot(_write(tmp_path, MINIMAL + '[floor]\ndefault = "carpet"\n'))
    assert from_json == from_toml and from_json.floor == "carpet"


FAULTY = MINIMAL + """\
[floor]
default = "tile"
[[floor.regions]]
xmin_m = 0.0
xmax_m = 1.0
ymin_m = -1.0
ymax_m = 1.0
floor = "carpet"
[[faults]]
kind = "stuck_encoder"
t_s = 0.5
wheel = "left"
[[faults]]
kind = "payload"
t_s = 1.0
duration_s = 2.0
payload_kg = 1.5
"""


def test_floor_map_and_faults_reach_the_simulator(tmp_path):
    robot = load_robot(_write(tmp_path, FAULTY))
    assert robot.floor == FloorMap("tile", ((0.0, 1.0, -1.0, 1.0, "carpet"),))
    assert robot.faults == (Fault("stuck_encoder", t_s=0.5, wheel="left"),
                            Fault("payload", t_s=1.0, duration_s=2.0, payload_kg=1.5))
    sim = Simulator(robot, seed=3)
    assert sim.floor_map == robot.floor and sim.faults == robot.faults
    log = sim.run(np.full((100, 2), 0.2))                     # 2 s at 0.2 m/s
    after = log.t_s > 0.6
    assert np.ptp(log.ticks[after, 0]) == 0                   # the left count froze
    assert np.ptp(log.ticks[after, 1]) > 100                  # the right one did not
    assert Simulator(robot, floor="hard").floor_map == FloorMap("hard")   # a run may override


def test_a_batch_keeps_each_robots_faults_on_that_robot(tmp_path):
    faulty = load_robot(_write(tmp_path, FAULTY))
    healthy = faulty.replace(faults=())
    sim = Simulator([healthy, faulty], seed=[1, 2])
    assert [f.robots for f in sim.faults] == [(1,), (1,)]
    with pytest.raises(SimulatorError, match="one floor"):
        Simulator([healthy, healthy.replace(floor="hard")], seed=[1, 2])


def test_the_schema_page_names_every_field_and_fault_parameter():
    page = (ROOT / "docs/robot_file.md").read_text()
    for section, fields in SCHEMA.items():
        if section:
            assert f"[{section}]" in page, section
        for f in fields:
            assert f"`{f.key}`" in page, f.key
    for kind, keys in FAULT_FIELDS.items():
        assert f'`"{kind}"`' in page, kind
        for key in keys:
            assert f"`{key}`" in page, key
    assert set(FAULT_FIELDS) == set(FaultKind.__args__)


def _replace(text, old, new):
    assert old in text
    return text.replace(old, new)


BAD = [
    (lambda t: _replace(t, "ticks_per_rev = 1000", "ticks_per_rev = -5"),
     "robot file {path}: [encoders] ticks_per_rev must be a positive number "
     "[ticks per wheel revolution], got -5"),
    (lambda t: _replace(t, "ticks_per_rev = 1000", 'ticks_per_rev = "many"'),
     "[encoders] ticks_per_rev must be a positive number [ticks per wheel revolution], "
     "got 'many'"),
    (lambda t: _replace(t, "ticks_per_rev = 1000", "tick_per_rev = 1000"),
     "[encoders] unknown field 'tick_per_rev' (did you mean ticks_per_rev?); known: "
     "ticks_per_rev, counter_bits, kind"),
    (lambda t: _replace(t, "ticks_per_rev = 1000\n", ""),
     "[encoders] ticks_per_rev [ticks per wheel revolution] is missing"),
    (lambda t: t + "[motors]\nmotor_kv = 3.0\n",
     "[motors] unknown field 'motor_kv' (did you mean motor_k?); known: max_speed_m_s,"),
    (lambda t: _replace(t, "mass_kg = 4.5", "mass_kg = 4.5\nweight_kg = 1"),
     "[mass] unknown field 'weight_kg'"),
    (lambda t: t + "[wheels]\nsize = 1\n", "unknown field or section 'wheels'"),
    (lambda t: _replace(t, 'name = "mybot"\n', ""), "robot file {path}: name is missing"),
    (lambda t: _replace(t, "wheel_diameter_m = 0.07\n", ""),
     "[geometry] wheel_diameter_m [m] is missing"),
    (lambda t: _replace(t, "ticks_per_rev = 1000", 'ticks_per_rev = 1000\nkind = "hall"'),
     "[encoders] kind must be \"commanded\""),
    (lambda t: _replace(t, "period_s = 0.02", "period_s = true"),
     "period_s must be a positive number [s], got True"),
    (lambda t: _replace(t, "delay_periods = 3", "delay_periods = 40"),
     "[delay] delay_periods must be a number within 0 .. 30 [sensor periods], got 40"),
    (lambda t: _replace(t, "delay_periods = 3", "delay_periods = 0.2\ndelay_jitter_periods = 1"),
     "delay_periods must exceed half of delay_jitter_periods"),
    (lambda t: t + "[geometry.x]\n", "[geometry] unknown field 'x'"),
    (lambda t: t + "[encoders.more]\n", "[encoders] unknown field 'more'"),
    (lambda t: _replace(t, "ticks_per_rev = 1000", "ticks_per_rev = 1000\ncounter_bits = 12.5"),
     "[encoders] counter_bits must be a whole number of bits from 8 to 64 (16 for the Open "
     "Interface's counters; 63 and 64 never wrap), got 12.5"),
    (lambda t: _replace(t, "ticks_per_rev = 1000", "ticks_per_rev = 1000\ncounter_bits = 4"),
     "[encoders] counter_bits must be a whole number of bits from 8 to 64"),
    (lambda t: t + "[light_bumps]\nir_angles_deg = [1, 2]\n",
     "[light_bumps] ir_angles_deg must be a list of 6 numbers [degrees], got [1, 2]"),
    (lambda t: t + '[floor]\ndefault = "ice"\n', "[floor] unknown floor 'ice'"),
    (lambda t: t + '[[faults]]\nkind = "meteor"\nt_s = 1\n',
     "[[faults]] #1 kind must be one of floor, payload,"),
    (lambda t: t + '[[faults]]\nkind = "motor"\nt_s = 1\nweakening = 1.5\n',
     "[[faults]] #1 weakening must be a number within 0 .. 1, 1 excluded"),
    (lambda t: t + '[[faults]]\nkind = "motor"\nt_s = 1\nprobability = 0.5\n',
     "[[faults]] #1 unknown field 'probability' for a motor fault; known: kind, t_s,"),
    (lambda t: t + '[[faults]]\nkind = "stall"\n', "[[faults]] #1 t_s is missing"),
    (lambda t: t + '[[faults]]\nkind = "stall"\nt_s = 1\nwheel = "middle"\n',
     "[[faults]] #1 wheel must be"),
    (lambda t: t + "[[floor.regions]]\nxmin_m = 0\n", "[[floor.regions]] #1 xmax_m is missing"),
    (lambda t: "faults = 3\n" + t, "faults must be a list of tables ([[faults]]), got 3"),
    (lambda t: t + "[floor]\nregions = [1]\n", "[[floor.regions]] #1 must be a table, got 1"),
    (lambda t: t + '[floor]\nregions = "all"\n',
     "[floor] regions must be a list of tables ([[floor.regions]]), got 'all'"),
    (lambda t: _replace(t, 'name = "mybot"', 'name = "mybot"\nname = "again"'),
     "robot file {path}: not valid TOML:"),
]


@pytest.mark.parametrize("edit, message", BAD, ids=[m[:40] for _, m in BAD])
def test_bad_robot_files_are_one_line_naming_the_field(edit, message, tmp_path):
    path = _write(tmp_path, edit(MINIMAL))
    with pytest.raises(RobotFileError) as exc:
        load_robot(path)
    text = str(exc.value)
    assert message.format(path=path) in text
    assert text.startswith(f"robot file {path}: ") and "\n" not in text.strip()


@pytest.mark.parametrize("source, error, message", [
    ("roomba9000", RobotFileError,
     "unknown robot 'roomba9000': neither a preset (create2, paper) nor a .toml or .json"),
    ("no/such/robot.toml", FileNotFoundError, "robot file no/such/robot.toml: no such file"),
    ("robot.yaml", RobotFileError, "give a .toml or .json robot file"),
])
def test_unknown_names_and_files_say_what_to_give(source, error, message, tmp_path):
    if source.endswith(".yaml"):
        source = str(_write(tmp_path, MINIMAL, source))
    with pytest.raises(error, match=re.escape(message)):
        load_robot(source)
