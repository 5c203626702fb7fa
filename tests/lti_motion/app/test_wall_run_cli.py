"""``lti-motion calibrate --sim ROBOT --wall-run``: the diameter ratio from straight runs
beside a wall, printed and written (and into a model file); every refusal is one line and
exit 2. The ratio is scored against the simulator's truth in
tests/drivers/roomba/test_wall_run_pty.py (the same manoeuvre through the serial driver)."""

import contextlib
import dataclasses
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest

import drivers.sim.calibration
from drivers.sim.config import Room, load_robot
from drivers.sim.simulator import Simulator
from lti_motion.app.cli import main
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.logfile import load_log

CREATE2 = Path(drivers.sim.calibration.__file__).parent / "robots" / "create2.toml"


@pytest.fixture(scope="module")
def lefty(tmp_path_factory) -> Path:
    """A robot file: the Create 2 with a left wheel 1% larger than the right."""
    text = CREATE2.read_text().replace("wheel_diameter_errors = [0.0003, -0.0003]",
                                       "wheel_diameter_errors = [0.01, 0.0]")
    assert "[0.01, 0.0]" in text
    path = tmp_path_factory.mktemp("robot") / "lefty.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def run(lefty, tmp_path_factory):
    """One wall run of 1 m runs on the simulator, starting from a model file's intrinsics."""
    from lti_motion.model.fir import FirFit

    folder = tmp_path_factory.mktemp("wall")
    fit = FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
                 residual_cov=np.eye(2) * 1e-4, n_samples=100, source="steps")
    model = MotionModel.from_fir(fit, dt_s=0.015, wheel_base_m=0.235,
                                 m_per_tick=load_robot(str(lefty)).m_per_tick,
                                 calibrated_at="2026-01-01T00:00:00+00:00").save(
        folder / "model.json")
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["calibrate", "--sim", str(lefty), "--wall-run", "--wall-run-m", "1",
                     "--floor", "tile", "--into-model", str(model), "--out",
                     str(folder / "out")])
    return {"code": code, "text": out.getvalue(), "out": folder / "out", "model": model}


def test_prints_the_ratio_and_each_run(run):
    assert run["code"] == 0
    text = run["text"]
    result = json.loads((run["out"] / "wall_run.json").read_text())
    ratio, std = map(float, re.search(r"left/right\s+([\d.]+) \+- ([\d.]+)", text).groups())
    assert ratio == pytest.approx(result["diameter_ratio"], abs=1e-5)
    assert std == pytest.approx(result["diameter_ratio_std"], abs=1e-5)
    assert 0 < std < 0.002
    assert 1.005 < ratio < 1.015                      # the 1% larger left wheel shows
    passes = re.findall(r"pass \d: (forward|backward) run of ([\d.]+) m from (\d+) mm", text)
    assert [p[0] for p in passes] == ["forward", "backward"]
    assert [float(p[1]) for p in passes] == pytest.approx([1.0, 1.0], abs=0.05)
    assert [int(p[2]) for p in passes] == pytest.approx([40, 160], abs=10)
    assert "wall on the robot's left" in text


def test_writes_the_drive_and_the_model_carrying_the_intrinsics(run):
    result = json.loads((run["out"] / "wall_run.json").read_text())
    start = MotionModel.load(run["model"]).encoder_intrinsics
    assert result["intrinsics_in_use"] == pytest.approx(start.as_dict())
    moved = MotionModel.load(run["out"] / "model_intrinsics.json").intrinsics
    assert moved.as_dict() == pytest.approx(result["intrinsics"])
    assert moved.diameter_ratio == pytest.approx(result["diameter_ratio"])
    assert len(load_log(run["out"] / "log_wall_run.npz").t_s) > 3000


def _refused(capsys, args, message) -> str:
    assert main(["calibrate", "--wall-run", *args]) == 2
    err = capsys.readouterr().err
    assert re.search(message, err), err
    assert err.count("\n") == 1 and "Error:" not in err
    return err


def test_a_run_too_short_is_refused_before_driving(lefty, tmp_path, capsys):
    _refused(capsys, ["--sim", str(lefty), "--wall-run-m", "0.5", "--out", str(tmp_path / "o")],
             r"--wall-run-m 0\.5 is too short: .* at least 0\.8 m")
    assert not (tmp_path / "o").exists()


def test_a_recorded_drive_is_not_a_wall_run(tmp_path, capsys):
    _refused(capsys, ["--log", str(tmp_path / "x.npz"), "--out", str(tmp_path / "o")],
             "--wall-run drives the robot: give --sim")


def test_no_wall_ahead(lefty, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(drivers.sim, "wall_run_simulator",
                        lambda robot, **_: Simulator(robot, room=Room.empty()))
    _refused(capsys, ["--sim", str(lefty), "--out", str(tmp_path)],
             r"no wall found: no bump within 1\.5 m .*facing a straight wall")


def test_turns_that_are_off_curve_into_the_wall_on_both_sides(lefty, tmp_path, capsys):
    scale = 1.25 * load_robot(str(lefty)).m_per_tick          # the robot under-turns by 20%
    _refused(capsys, ["--sim", str(lefty), "--wall-run-m", "1", "--m-per-tick", str(scale),
                      "--out", str(tmp_path)],
             "curved into the wall on both sides.*intrinsics in use: --m-per-tick.*--into-model")


class _NoLightBumps:
    """A robot whose stream lacks the light bumps: they read 0 (as the driver gives them)."""

    def __init__(self, sim: Simulator) -> None:
        self.sim, self.dt_s = sim, sim.dt_s

    def step(self, cmd_m_s):
        frame = self.sim.step(cmd_m_s)
        return dataclasses.replace(frame, light_bump=np.zeros_like(frame.light_bump))


def test_no_light_bump_signals(lefty, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(drivers.sim, "wall_run_simulator",
                        lambda robot, **_: _NoLightBumps(Simulator(
                            robot, room=Room.single_wall(), initial_pose=(0, 0.5, -np.pi / 2))))
    _refused(capsys, ["--sim", str(lefty), "--out", str(tmp_path)],
             r"no light-bump signals: .*packets \(46-51\)")


def test_port_drives_the_wall_run_on_a_virtual_roomba(lefty, tmp_path, capsys):
    """The user's path: --port through the serial driver (default link options) at 10x."""
    from drivers.roomba.virtual import VirtualRoomba

    with VirtualRoomba(load_robot(str(lefty)), seed=2, speed=10.0, floor="tile",
                       room=Room.single_wall(), initial_pose=(0.0, 0.5, -np.pi / 2)) as vr:
        code = main(["calibrate", "--port", vr.device_path, "--clock-rate", "10", "--yes",
                     "--robot", str(lefty), "--wall-run", "--wall-run-m", "1",
                     "--out", str(tmp_path)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert f"driving the wall run on {vr.device_path}" in text
    assert "intrinsics in use: the nominal ones of" in text
    ratio = json.loads((tmp_path / "wall_run.json").read_text())["diameter_ratio"]
    assert 1.005 < ratio < 1.015                      # the 1% larger left wheel shows


def _no_one_answers(prompt=""):
    raise EOFError                                   # standard input closed (a script, CI)


def test_a_missing_port_is_said_before_anyone_is_asked_to_place_the_robot(
        lefty, tmp_path, capsys, monkeypatch):
    asked = []
    monkeypatch.setattr("builtins.input", lambda prompt="": asked.append(prompt))
    _refused(capsys, ["--port", str(tmp_path / "no-such-tty"), "--robot", str(lefty),
                      "--out", str(tmp_path / "o")], "no-such-tty")
    assert asked == []
    assert "Put the robot" not in capsys.readouterr().out


def test_closed_standard_input_at_the_prompt_is_one_line_saying_give_yes(
        lefty, tmp_path, capsys, monkeypatch):
    from drivers.roomba.virtual import VirtualRoomba

    monkeypatch.setattr("builtins.input", _no_one_answers)
    with VirtualRoomba(load_robot(str(lefty)), seed=2, speed=10.0, room=Room.single_wall(),
                       initial_pose=(0.0, 0.5, -np.pi / 2)) as vr:
        _refused(capsys, ["--port", vr.device_path, "--clock-rate", "10", "--robot",
                          str(lefty), "--out", str(tmp_path)],
                 "standard input is closed.*give --yes")
