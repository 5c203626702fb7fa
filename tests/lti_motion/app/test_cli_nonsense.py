"""Nonsense on the command line is refused before anything runs.

Each case was accepted silently before (ignored, exit 0, or a failure deep inside after
minutes of work); now: one line naming the option, exit 2, no output folder written.
"""

import numpy as np
import pytest

from drivers.sim.simulator import Simulator
from lti_motion.app.cli import main
from lti_motion.recordings.logfile import save_log


@pytest.fixture(scope="module")
def files(tmp_path_factory, tiny_model):
    folder = tmp_path_factory.mktemp("nonsense")
    model = tiny_model
    log = Simulator("create2", seed=0).run(np.full((200, 2), 0.1))
    return {"model": str(model.save(folder / "model.json")),
            "log": str(save_log(folder / "one_robot.npz", log))}


CASES = [
    (["calibrate", "--sim", "create2", "--wheel-base", "-0.2"],
     "--wheel-base is for --port, --log and --bag; the simulated create2 has its own (0.235 m)"),
    (["calibrate", "--sim", "create2", "--wheel-base", "0.235"], "--wheel-base is for --port"),
    (["calibrate", "--port", "/dev/nonexistent-roomba", "--wheel-base", "-0.2"],
     "--wheel-base must be a positive number, got -0.2"),
    (["calibrate", "--port", "/dev/nonexistent-roomba", "--baud", "12345"],
     "--baud 12345 is not a rate the Open Interface speaks: give one of"),
    (["monitor", "--port", "/dev/nonexistent-roomba", "--model", "{model}", "--baud", "7"],
     "--baud 7 is not a rate the Open Interface speaks"),
    (["calibrate", "--bag", "{log}", "--left-joint", "(["],
     "--left-joint '([' is not a valid joint name pattern (a regular expression)"),
    (["replay", "--bag", "{log}", "--model", "{model}", "--right-joint", "*"],
     "--right-joint '*' is not a valid joint name pattern"),
    (["calibrate", "--port", "/dev/nonexistent-roomba", "--clock-rate", "0"],
     "--clock-rate must be a positive number, got 0"),
    (["calibrate", "--sim", "create2", "--excitation-s", "1"],
     "--excitation-s must be a finite number of seconds, at least 20"),
    (["demo", "--excitation-s", "1"], "--excitation-s must be a finite number of seconds, at "
     "least 20"),
    (["calibrate", "--sim", "create2", "--excitation-s", "inf"],
     "30%), got inf"),
    (["calibrate", "--sim", "create2", "--into-model", "{model}"],
     "--into-model writes the intrinsics that --reference or --wall-run calibrates"),
    (["demo", "--runs", "0"], "--runs must be 1 or more, got 0"),
    (["monitor", "--sim", "create2", "--model", "{model}", "--duration", "-3"],
     "--duration must be a positive number, got -3"),
    (["monitor", "--sim", "create2", "--model", "{model}", "--duration", "10", "--fault",
      "spikes", "--fault-at", "12"], "--fault-at 12 s is outside the drive"),
    (["monitor", "--sim", "create2", "--model", "{model}", "--fault-at", "-1", "--fault",
      "spikes"], "--fault-at -1 s is outside the drive"),
    (["monitor", "--sim", "create2", "--model", "{model}", "--fault-at", "3"],
     "--fault-at is the onset of --fault; give --fault too"),
    (["monitor", "--sim", "create2", "--model", "{model}", "--nominal-drives", "-1"],
     "--nominal-drives must be 0 or more"),
    (["replay", "{log}", "--model", "{model}", "--robot", "9"],
     "one_robot.npz holds one robot's drive; there is no robot 9"),
    (["replay", "{log}", "--model", "{model}", "--rpe-s", "0"],
     "--rpe-s must be a positive number, got 0"),
    (["replay", "{log}", "--model", "{model}", "--start-s", "-5"],
     "--start-s must be 0 or more, got -5"),
    (["virtual-roomba", "--speed", "-1"], "--speed must be a positive number, got -1"),
]


@pytest.mark.parametrize("argv, message", CASES, ids=[" ".join(c[0][:1] + c[0][-2:])
                                                       for c in CASES])
def test_nonsense_is_one_line_and_exit_2(argv, message, files, tmp_path, capsys):
    out = tmp_path / "out"
    argv = [a.format(**files) for a in argv]
    if argv[0] in ("calibrate", "demo", "replay"):
        argv += ["--out", str(out)]
    assert main(argv) == 2
    captured = capsys.readouterr()
    err = captured.err
    assert err.count("\n") == 1 and err.startswith(f"lti-motion {argv[0]}: error: "), err
    assert message in err, err
    assert "Traceback" not in err and "Error" not in err
    assert not out.exists()                              # refused before any work


def test_a_failed_port_leaves_no_empty_out_folder_behind(tmp_path, capsys):
    out = tmp_path / "never-written"
    assert main(["calibrate", "--port", str(tmp_path / "no-such-tty"), "--out", str(out)]) == 2
    assert "nothing kept" in capsys.readouterr().err
    assert not out.exists()


def test_a_failed_port_leaves_an_existing_out_folder_alone(tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    assert main(["calibrate", "--port", str(tmp_path / "no-such-tty"), "--out", str(out)]) == 2
    assert out.is_dir()
