"""The command line's messages in its own words (issue 28, item 6): odd option values are
one line naming the option, and the driver's references to the Open Interface spec stay
out of what a command-line user reads."""

import re

import pytest

from lti_motion.app.cli import main


def _one_line(err, command):
    lines = err.strip("\n").split("\n")
    assert len(lines) == 1 and lines[0].startswith(f"lti-motion {command}: error: "), err
    return lines[0]


@pytest.mark.parametrize("argv, expected", [
    (["calibrate", "--robot", "create2", "--excitation-s", "1e9"],
     "--excitation-s 1e+09 s is more driving than a calibration needs: give at most 3600 s"),
    (["demo", "--excitation-s", "1e7"], "give at most 3600 s"),
    (["calibrate", "--robot", "create2", "--seed", "-1"],
     "--seed must be a whole number of 0 or more, got -1"),
    (["virtual-roomba", "--seed", "-1", "--duration", "0.2"], "--seed must be"),
    (["monitor", "--robot", "create2", "--seed", "-3"], "--seed must be"),
    (["monitor", "--robot", "create2", "--duration", "1e9"],
     "--duration 1e+09 s is longer than a monitor drive can be: give at most 86400 s"),
])
def test_odd_values_are_one_line_naming_the_option(argv, expected, tmp_path, capsys):
    assert main([*argv, *(["--out", str(tmp_path / "o")] if argv[0] in ("calibrate", "demo")
                         else [])]) == 2
    captured = capsys.readouterr()
    assert expected in _one_line(captured.err, argv[0])
    assert "calibrating" not in captured.out                # refused before anything runs


def test_a_silent_port_is_told_in_the_commands_words(tmp_path, capsys, monkeypatch):
    from drivers.exceptions import StreamStalledError
    from drivers.roomba.driver import Roomba

    def silent(self):
        raise StreamStalledError(
            f"no valid stream frame from {self.port} at 115200 baud within 1 s of requesting "
            "the stream (0 bytes skipped). Check that the robot is switched on and awake "
            "(press Clean), the cable (TX/RX, ground), and the baud rate: 115200 for a "
            "Create 2 / Roomba 500-600, 57600 for a Create 1 (spec §1.3, G3, G15)")

    monkeypatch.setattr(Roomba, "open", silent)
    assert main(["calibrate", "--port", "/dev/ttyUSB0", "--yes",
                 "--out", str(tmp_path / "cal")]) == 2
    line = _one_line(capsys.readouterr().err, "calibrate")
    assert "57600 for a Create 1;" in line or line.rstrip().endswith("57600 for a Create 1"), line
    assert "spec" not in line and "G15" not in line and "§" not in line


def test_a_dynamics_test_phase_one_could_not_set_up_is_called_off_not_inf():
    import math
    from types import SimpleNamespace

    from lti_motion.app.monitor import _test_lines

    dyn = SimpleNamespace(lag_threshold=math.inf, covariance_threshold=21.3,
                          start_threshold=math.inf)
    mon = SimpleNamespace(thresholds=lambda: SimpleNamespace(gate=300.0), dynamics=dyn)
    nominal = SimpleNamespace(max_nominal_nis=30.0, n_drives=20, duration_s=600.0)
    (line,) = _test_lines(mon, nominal, None)
    assert not re.search(r"\binf\b", line)
    assert "lag off (no window of the nominal drives carried lag information)" in line
    assert "start off (the nominal drives gave no start-from-rest null)" in line


def test_monitor_names_the_robot_files_own_faults(tiny_model):
    from drivers.sim.config import Fault, get_preset
    from lti_motion.app.monitor import run_on_simulator

    robot = get_preset("create2").replace(
        name="my_robot", faults=(Fault("payload", t_s=2.0, payload_kg=3.0),
                                 Fault("stall", t_s=9.0)))        # after the drive: not named
    lines = []
    run_on_simulator(tiny_model, robot=robot, duration_s=4.0, nominal_drives=0,
                     landmarks=False, print_fn=lines.append)
    assert ("the robot my_robot has faults of its own in this drive (its file's [[faults]], "
            "left out of Phase I): payload at 2 s") in lines
