"""The command line, run as a user runs it (short horizons).

The paper: ``docs/architecture.md``, "The paper".
"""

import json
import tomllib

import numpy as np
import pytest

from drivers.roomba.virtual_options import VirtualRoombaOptions
from lti_motion.app.cli import build_parser, main


def test_demo_writes_report_metrics_and_plots(tmp_path, capsys):
    # the command's plumbing, two runs a row (the demo's accuracy: test_route, benchmarks)
    assert main(["demo", "--out", str(tmp_path), "--runs", "2", "--excitation-s", "60"]) == 0
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    closure = metrics["closure_offset_m"]
    assert {"odometry", "fir_sensorless", "arx_sensorless", "arx_hybrid", "ekf",
            "ekf_landmarks"} <= set(closure)
    for row in closure.values():
        assert row["n"] == 2 and row["mean"] > 0 and row["std"] >= 0
    for name in ("report.md", "closure.png", "trajectories.png", "order_selection.png"):
        assert (tmp_path / name).stat().st_size > 500, name
    out = capsys.readouterr().out
    assert "Table II" in out and "0.068" in out          # the paper's odometry row beside ours


def test_help_and_bad_choices(capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["demo", "--floor", "ice"])
    assert exc.value.code == 2
    assert "invalid choice: 'ice'" in capsys.readouterr().err


def _options(parser):
    """Every option of every sub-command: ``(sub-command, flag, action)``."""
    commands = next(a for a in parser._actions if a.dest == "command").choices
    for name, sub in commands.items():
        for action in sub._actions:
            for flag in action.option_strings:
                yield name, flag, action


def test_robot_option_takes_a_name_or_file_and_the_old_spellings_still_parse():
    from drivers.sim.config import FLOORS
    from drivers.sim.robot_file import preset_names

    seen = set()
    for command, flag, action in _options(build_parser()):
        if flag == "--robot" and command != "replay":
            assert action.choices is None and action.metavar == "NAME_OR_FILE", command
            assert "robot file" in action.help, command
            assert f"a preset ({', '.join(preset_names())})" in action.help, command
            seen.add(command)
        elif flag == "--floor" and action.choices is not None:
            assert list(action.choices) == list(FLOORS), (command, flag)
        elif flag == "--floor":                                  # a robot's floor: any name
            assert all(f in action.help for f in FLOORS), (command, flag)
    assert seen == {"demo", "calibrate", "monitor", "virtual-roomba", "export"}
    parse = build_parser().parse_args
    for old, new in ((["demo", "--preset", "paper"], ["demo", "--robot", "paper"]),
                     (["calibrate", "--sim", "paper"], ["calibrate", "--robot", "paper"]),
                     (["monitor", "--sim", "paper"], ["monitor", "--robot", "paper"]),
                     (["virtual-roomba", "--preset", "paper"],
                      ["virtual-roomba", "--robot", "paper"])):
        assert vars(parse(old)) == vars(parse(new)), old
    assert parse(["replay", "x.npz", "--robot", "3"]).robot == 3    # replay: a robot index


ROBOT_FILE_ERRORS = [
    ("ticks_per_rev = 508.8", "ticks_per_rev = -5",
     "[encoders] ticks_per_rev must be a positive number [ticks per wheel revolution], got -5"),
    ("wheel_diameter_m = 0.072", "", "[geometry] wheel_diameter_m [m] is missing"),
    ("mass_kg = 3.6", "mass_kg = 3.6\nmass_lb = 8", "[mass] unknown field 'mass_lb'"),
]


@pytest.mark.parametrize("command", [
    ["demo", "--runs", "2", "--out", "{out}"],
    ["calibrate", "--out", "{out}"],
    ["monitor", "--duration", "1"],
    ["virtual-roomba", "--duration", "0.3"],
], ids=lambda c: c[0])
@pytest.mark.parametrize("old, new, message", ROBOT_FILE_ERRORS, ids=["range", "missing",
                                                                      "unknown"])
def test_a_bad_robot_file_is_one_line_exit_2_and_nothing_written(command, old, new, message,
                                                                 tmp_path, capsys):
    from importlib import resources

    text = (resources.files("drivers.sim") / "robots" / "create2.toml").read_text()
    assert old in text
    robot = tmp_path / "my.toml"
    robot.write_text(text.replace(old, new))
    out = tmp_path / "out"
    argv = [a.format(out=out) for a in command]
    assert main([argv[0], "--robot", str(robot), *argv[1:]]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith(f"lti-motion {argv[0]}: error: robot file {robot}: {message}")
    assert captured.err.count("\n") == 1 and "Traceback" not in captured.err
    assert not out.exists() and captured.out == ""


def test_an_unknown_robot_name_says_what_to_give(capsys):
    assert main(["demo", "--robot", "roomba9000", "--out", "/nonexistent/x"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("lti-motion demo: error: unknown robot 'roomba9000': neither a "
                          "preset (create2, paper) nor a .toml or .json robot file")


def test_calibrate_on_a_missing_port_names_it(capsys):
    assert main(["calibrate", "--port", "/dev/does-not-exist", "--yes"]) == 2
    assert "/dev/does-not-exist" in capsys.readouterr().err


def test_calibrate_sim_writes_models_and_plots(tmp_path, capsys):
    from importlib import resources

    text = (resources.files("drivers.sim") / "robots" / "create2.toml").read_text()
    robot = tmp_path / "mybot.json"              # a robot file: the Create 2 on carpet, renamed
    doc = tomllib.loads(text.replace('name = "create2"', 'name = "mybot"'))
    doc["floor"] = {"default": "carpet"}
    robot.write_text(json.dumps(doc))
    assert main(["calibrate", "--robot", str(robot), "--excitation-s", "40",
                 "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "calibrating the simulated mybot robot on carpet floor" in out
    assert "encoder scale" in out and "ARX" in out
    assert json.loads((tmp_path / "model_arx.json").read_text())["floor"] == "carpet"
    for name in ("model_arx.json", "model_fir.json", "order_selection.png"):
        assert (tmp_path / name).is_file()
    from lti_motion.recordings.logfile import load_log

    for stage in ("rotation", "steps", "excitation"):          # the drives, replayable
        assert load_log(tmp_path / f"log_{stage}.npz").has_truth


def test_virtual_roomba_prints_its_device_path(capsys):
    assert main(["virtual-roomba", "--duration", "0.3"]) == 0
    out = capsys.readouterr().out
    assert "listening on /dev/pts/" in out and "stopped" in out


# -- replay and monitor ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def model_file(tmp_path_factory, short_arx_model):
    return str(short_arx_model(2).save(tmp_path_factory.mktemp("model") / "model_arx.json"))


def test_monitor_sim_prints_the_stuck_encoder_alarm_and_records_a_log(model_file, tmp_path,
                                                                      capsys):
    log = tmp_path / "drive.npz"
    assert main(["monitor", "--sim", "create2", "--model", model_file, "--duration", "12",
                 "--fault", "stuck-encoder", "--fault-at", "8", "--record", str(log)]) == 0
    out = capsys.readouterr().out
    alarms = [line for line in out.splitlines() if line.startswith("ALARM")]
    stuck = [line for line in alarms if "stuck_encoder" in line]
    assert stuck and "left wheel" in stuck[0] and "onset" in stuck[0]
    t_first = float(stuck[0].split("t=")[1].split()[0])
    assert 8.0 <= t_first <= 8.3
    assert "first stuck_encoder alarm at" in out and "alarms:" in out
    # the recorded drive replays, with the simulator's truth for the metrics
    assert main(["replay", str(log), "--model", model_file, "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    assert "ATE rmse [m]" in out and "encoder odometry" in out and "evo_ape tum" in out
    rows = (tmp_path / "r" / "ekf.tum").read_text().splitlines()
    assert len(rows) == 1 + round(12 / 0.015)            # header + one pose per frame


def test_monitor_sim_runs_the_dynamics_and_scale_tests_after_phase_one(model_file, capsys):
    assert main(["monitor", "--sim", "create2", "--model", model_file, "--duration", "40",
                 "--fault", "carpet", "--fault-at", "15", "--nominal-drives", "8"]) == 0
    out = capsys.readouterr().out
    assert "phase I: fitting the dynamics null and the encoder gate on 8 nominal drives" in out
    assert "dynamics CUSUM thresholds: lag" in out and "scale test on 4 landmarks" in out
    gate = float(out.split("glitch gate NIS ")[1].split()[0])
    assert gate > 55.3                                  # set from the nominal drives
    scale = [line for line in out.splitlines()
             if line.startswith("ALARM") and "scale_changed" in line]
    assert scale and "travel x" in scale[0], out
    t_first = float(scale[0].split("t=")[1].split()[0])
    assert 15.0 < t_first < 30.0, scale[0]
    assert "first scale_changed alarm at" in out


def test_monitor_port_drives_a_virtual_roomba(model_file, capsys):
    from drivers.roomba.virtual import VirtualRoomba

    with VirtualRoomba(seed=5, options=VirtualRoombaOptions(speed=10.0)) as vr:
        assert main(["monitor", "--port", vr.device_path, "--clock-rate", "10",
                     "--model", model_file, "--duration", "4"]) == 0
        driven = len(vr.applied_commands_m_s)
    out = capsys.readouterr().out
    assert f"driving the robot on {vr.device_path}" in out and "monitored" in out
    assert driven > 200                      # 4 s at 15 ms, robot time
    # a healthy drive: its start from rest (at 1 s) is no glitch burst, no dynamics change
    assert "ALARM" not in out and "alarms: 0 (none)" in out, out


def test_monitor_port_fits_phase_one_on_recorded_nominal_drives(model_file, tmp_path, capsys):
    from drivers.roomba.virtual import VirtualRoomba

    log = tmp_path / "nominal.npz"                # a nominal drive, recorded as on a robot
    assert main(["monitor", "--sim", "create2", "--model", model_file, "--duration", "60",
                 "--nominal-drives", "0", "--record", str(log), "--seed", "3"]) == 0
    assert "dynamics tests off" in capsys.readouterr().out
    with VirtualRoomba(seed=5, options=VirtualRoombaOptions(speed=10.0)) as vr:
        assert main(["monitor", "--port", vr.device_path, "--clock-rate", "10",
                     "--model", model_file, "--duration", "4", "--nominal", str(log)]) == 0
    out = capsys.readouterr().out
    assert "phase I: fitting the dynamics null and the encoder gate on 1 nominal drive" in out
    assert "null from 1 nominal drives, 1.0 min" in out and "monitored" in out


def test_replay_mrclam_fits_on_the_first_half_and_replays_the_second(mrclam_path, tmp_path,
                                                                     capsys):
    assert main(["replay", str(mrclam_path), "--robot", "3", "--fit-first-half",
                 "--duration-s", "60", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "first half" in out and "EKF, model and landmarks" in out
    for name in ("model_arx.json", "commands.tum", "sensorless.tum", "ekf_landmarks.tum",
                 "groundtruth.tum", "trajectories.png", "errors.png", "metrics.json"):
        assert (tmp_path / name).is_file(), name


@pytest.mark.parametrize("argv, message", [
    (["replay", "missing.npz", "--model", "{model}"], "no such log file"),
    (["replay", "{log}", "--model", "missing.json"], "no model file missing.json"),
    (["replay", "{log}", "--model", "{log}"], "is a NumPy .npz archive (a recorded log?), not a "),
    (["replay", "{log}"], "give --model FILE"),
    (["replay", "{log}", "--model", "{model}", "--estimators", "ekf_landmarks"],
     "needs landmark sightings"),
    (["monitor", "--port", "/dev/nope"], "needs --model FILE"),
    (["monitor", "--port", "/dev/does-not-exist", "--model", "{model}"], "/dev/does-not-exist"),
    (["monitor", "--port", "/dev/nope", "--fault", "spikes"], "needs --robot (the simulator)"),
    (["monitor", "--sim", "create2", "--nominal", "{log}"], "needs --port"),
])
def test_replay_and_monitor_errors_exit_2_without_traceback(argv, message, model_file, tmp_path,
                                                            capsys):
    from drivers.sim.simulator import Simulator
    from lti_motion.recordings.logfile import save_log

    log = save_log(tmp_path / "short.npz", Simulator("create2", seed=0).run(np.full((50, 2), 0.1)))
    argv = [a.format(model=model_file, log=log) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


@pytest.mark.parametrize(("argv", "advice"), [
    (["replay", "{log}", "--model", "{model}", "--estimators", "odometry"],
     "--estimators commands sensorless"),
    (["replay", "{log}", "--model", "{model}", "--estimators", "ekf"],
     "--estimators commands sensorless"),
    (["replay", "{log}", "--model", "{model}"], "--estimators commands sensorless"),
    (["monitor", "--sim", "create2", "--model", "{model}", "--duration", "1",
      "--nominal-drives", "0"], "leave out --model"),
    (["monitor", "--sim", "create2", "--model", "{model}", "--duration", "1"],
     "leave out --model"),
    (["monitor", "--port", "/dev/no-such-robot", "--model", "{model}"],
     "'lti-motion calibrate --port /dev/no-such-robot'"),
], ids=["replay-odometry", "replay-ekf", "replay-all", "monitor-sim", "monitor-sim-nominal",
        "monitor-port"])
def test_a_model_without_encoder_scale_is_one_line_in_the_commands_words(argv, advice,
                                                                          model_file,
                                                                          tmp_path, capsys):
    """Issue 15 item 5: every command path that needs the scale says, in its own options,
    what gives it; the monitor says so before it drives (or opens the port)."""
    from drivers.sim.simulator import Simulator
    from lti_motion.model.motion_model import MotionModel
    from lti_motion.recordings.logfile import save_log

    unscaled = MotionModel.load(model_file).updated(m_per_tick=None).save(
        tmp_path / "unscaled.json")
    log = save_log(tmp_path / "short.npz", Simulator("create2", seed=0).run(np.full((50, 2), 0.1)))
    argv = [a.format(model=unscaled, log=log) for a in argv]
    assert main([*argv, "--out", str(tmp_path / "out")] if argv[0] == "replay" else argv) == 2
    captured = capsys.readouterr()
    err = captured.err
    assert err.count("\n") == 1 and err.startswith(f"lti-motion {argv[0]}: error: the model ")
    assert "has no encoder scale" in err and "'lti-motion calibrate" in err and "--model" in err
    assert advice in err
    for internal in ("Error", "m_per_tick", "FilterModel", "ModelEKF", "lti_motion.",
                     "Traceback"):
        assert internal not in err, internal
    if argv[0] == "monitor":
        assert "phase I" not in captured.out          # no nominal drive before the error
    else:                                             # the advice works
        assert main([*argv[:4], "--estimators", "commands", "sensorless",
                     "--out", str(tmp_path / "out2")]) == 0


def test_the_demo_says_what_its_user_can_do_about_a_missing_scale(monkeypatch, tmp_path,
                                                                  capsys):
    """The demo calibrates its own model; should that give no scale, its user hears about
    the demo's options, not the library's."""
    import lti_motion.app.demo as demo
    from lti_motion.exceptions import MissingEncoderScaleError

    def unscaled(*args, **kwargs):
        raise MissingEncoderScaleError.needed_by("encoder odometry")

    monkeypatch.setattr(demo, "run_demo", unscaled)
    assert main(["demo", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("lti-motion demo: error: the demo's ")
    assert "--seed" in err and "'lti-motion calibrate --robot NAME_OR_FILE'" in err
    for internal in ("Error", "m_per_tick", "lti_motion.", "--model"):
        assert internal not in err, internal


def test_replay_mrclam_robot_that_does_not_exist(mrclam_path, model_file, capsys):
    assert main(["replay", str(mrclam_path), "--robot", "7", "--fit-first-half"]) == 2
    assert "there is no robot 7" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["replay", "monitor"])
def test_sub_command_help(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    assert "docs/" in capsys.readouterr().out


def test_ctrl_c_in_a_command_without_its_own_answer_is_one_line_and_exit_130(
        tmp_path, monkeypatch, capsys):
    import lti_motion.app.demo as demo

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(demo, "run_demo", interrupted)
    assert main(["demo", "--out", str(tmp_path)]) == 130
    err = capsys.readouterr().err.strip()
    assert err == "lti-motion demo: stopped by Ctrl-C"


def test_version_prints_the_installed_distributions_version(capsys):
    from importlib.metadata import version

    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out == f"lti-motion {version('lti-motion')}\n"
