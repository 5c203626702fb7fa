"""``lti-motion calibrate`` keeps what it drove, resumes, stops cleanly and refuses to save
an unhealthy model (docs/guide_calibrate_real_robot.md).

Ctrl-C runs on the virtual Roomba over a real pseudo-terminal (8x real time, stopped in
the first seconds); the link that dies and the unhealthy model on the simulator, whose
manoeuvres go through the same command handler.
"""

import numpy as np
import pytest

from drivers.roomba.oi import Opcode
from drivers.roomba.virtual import VirtualRoomba
from drivers.roomba.virtual_options import VirtualRoombaOptions
from drivers.sim.config import Room
from lti_motion.app.cli import main
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.logfile import load_log


def _one_error_line(err, command="calibrate"):
    lines = err.strip("\n").split("\n")
    assert len(lines) == 1 and lines[0].startswith(f"lti-motion {command}: "), err
    assert "Traceback" not in err
    return lines[0]


def test_an_unwritable_out_is_refused_before_driving(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    assert main(["calibrate", "--sim", "create2", "--out", str(blocker / "out")]) == 2
    captured = capsys.readouterr()
    line = _one_error_line(captured.err)
    assert f"cannot write to {blocker / 'out'}" in line and "--out" in line
    assert "calibrating" not in captured.out               # nothing driven


def test_an_unwritable_monitor_record_is_refused_before_driving(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    assert main(["monitor", "--sim", "create2", "--duration", "5", "--excitation-s", "20",
                 "--record", str(blocker / "drive.npz")]) == 2
    captured = capsys.readouterr()
    line = _one_error_line(captured.err, "monitor")
    assert "cannot write to" in line and "--record" in line
    assert "calibrating" not in captured.out


def test_a_dead_link_keeps_the_rotation_and_resume_drives_only_the_rest(tmp_path, capsys,
                                                                       monkeypatch):
    from drivers.exceptions import PortError
    from drivers.sim.simulator import Simulator

    run, calls = Simulator.run, []

    def link_dies_in_the_steps(self, cmd_m_s):
        calls.append(len(cmd_m_s))
        if len(calls) == 2:
            raise PortError("read from /dev/ttyUSB0 failed: [Errno 5] Input/output error")
        return run(self, cmd_m_s)

    out = tmp_path / "cal"
    argv = ["calibrate", "--sim", "create2", "--excitation-s", "20", "--out", str(out)]
    with monkeypatch.context() as m:
        m.setattr(Simulator, "run", link_dies_in_the_steps)
        assert main(argv) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert "Input/output error" in line
    assert f"kept log_rotation.npz in {out}: run again with --resume" in line
    rotation = load_log(out / "log_rotation.npz")
    assert not (out / "log_steps.npz").exists() and not (out / "model_arx.json").exists()

    assert main(argv) == 2                                 # a fresh run would mix two runs
    assert "give --resume" in _one_error_line(capsys.readouterr().err)

    calls.clear()
    with monkeypatch.context() as m:
        m.setattr(Simulator, "run", lambda self, c: calls.append(len(c)) or run(self, c))
        assert main([*argv, "--resume", "--accept-unhealthy"]) == 0
    printed = capsys.readouterr().out
    assert "resuming: rotation recorded" in printed
    assert "kept the steps drive" in printed and "kept the rotation drive" not in printed
    assert len(calls) == 2                                 # steps and excitation only
    np.testing.assert_array_equal(load_log(out / "log_rotation.npz").ticks, rotation.ticks)
    assert (out / "model_arx.json").is_file()


def test_ctrl_c_stops_the_wheels_and_says_what_was_kept(tmp_path, capsys, monkeypatch):
    import drivers.sim

    original = drivers.sim.print_progress

    def interrupted(stage, done, total):
        if done >= 200:                                  # 3 s into the rotation
            raise KeyboardInterrupt
        original(stage, done, total)

    monkeypatch.setattr(drivers.sim, "print_progress", interrupted)    # what the command reads
    out = tmp_path / "cal"
    with VirtualRoomba(seed=1, room=Room.cluttered(), initial_pose=Room.CALIBRATION_SPOT,
                       options=VirtualRoombaOptions(speed=8.0)) as vr:
        assert main(["calibrate", "--port", vr.device_path, "--clock-rate", "8", "--yes",
                     "--out", str(out)]) == 130
        vr.wait_until(lambda v: v.received[-1].opcode == Opcode.STOP, timeout_s=5.0)
        tail = [(c.opcode, c.data) for c in vr.received[-4:]]
    line = _one_error_line(capsys.readouterr().err)
    assert "stopped by Ctrl-C; the wheels were commanded to stop" in line
    assert "no manoeuvre was complete, nothing kept" in line
    assert tail == [(Opcode.DRIVE_DIRECT, bytes(4)), (Opcode.PAUSE_RESUME_STREAM, b"\x00"),
                    (Opcode.START, b""), (Opcode.STOP, b"")]   # wheels stopped, robot off
    assert not list(out.glob("log_*.npz"))


def test_ctrl_c_at_the_prompt_is_one_line(tmp_path, capsys, monkeypatch):
    def no_enter(prompt=""):
        raise KeyboardInterrupt

    monkeypatch.setattr("builtins.input", no_enter)
    with VirtualRoomba(seed=1, options=VirtualRoombaOptions(speed=8.0)) as vr:
        assert main(["calibrate", "--port", vr.device_path, "--clock-rate", "8",
                     "--out", str(tmp_path / "cal")]) == 130
    assert "stopped by Ctrl-C" in _one_error_line(capsys.readouterr().err)


def test_an_unhealthy_model_is_refused_then_saved_on_request_without_driving(tmp_path, capsys):
    out = tmp_path / "cal"
    # 20 s of excitation: held-out fit ~77 / 77 % on the simulator, below the healthy 85 %
    assert main(["calibrate", "--sim", "create2", "--excitation-s", "20",
                 "--out", str(out)]) == 2
    captured = capsys.readouterr()
    line = _one_error_line(captured.err)
    assert "the model is unhealthy and was not saved" in line and "below the healthy 85%" in line
    assert "--accept-unhealthy" in line
    assert not (out / "model_arx.json").exists()
    assert (out / "log_excitation.npz").is_file() and (out / "order_selection.png").is_file()
    assert (out / "calibration_sequence.png").is_file()     # 20 s (the minimum) plots whole

    assert main(["calibrate", "--sim", "create2", "--excitation-s", "20", "--out", str(out),
                 "--resume", "--accept-unhealthy"]) == 0
    printed = capsys.readouterr().out
    assert "resuming: rotation, steps, excitation recorded" in printed
    assert "kept the" not in printed                           # nothing driven again
    assert "saving an unhealthy model as --accept-unhealthy asks" in printed
    model = MotionModel.load(out / "model_arx.json")
    assert (model.robot.robot, model.robot.wheel_data, model.robot.encoders) == (
        "create2", "counts", "commanded")
    assert model.robot.m_per_tick == (model.m_per_tick,) * 2
    assert MotionModel.load(out / "model_fir.json").robot == model.robot
    fit_v, fit_w = model.diagnostics["validation_fit_v"], model.diagnostics["validation_fit_w"]
    assert f"held-out free-run fit v {fit_v:.1f}%, w {fit_w:.1f}%" in printed   # the stored fit
    assert min(fit_v, fit_w) < 85.0


@pytest.mark.parametrize("bad", ["--resume"])
def test_resume_with_logs_of_another_plan_names_the_mismatch(tmp_path, capsys, bad):
    out = tmp_path / "cal"
    assert main(["calibrate", "--sim", "create2", "--excitation-s", "20", "--out", str(out),
                 "--accept-unhealthy"]) == 0
    capsys.readouterr()
    assert main(["calibrate", "--sim", "create2", "--excitation-s", "40", "--out", str(out),
                 bad]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert "the recorded excitation has" in line and "this plan drives" in line


def test_a_drive_that_fails_its_analysis_is_set_aside_and_resume_drives_it_again(
        tmp_path, capsys, monkeypatch):
    import lti_motion.calibration.manoeuvres as manoeuvres
    from drivers.sim.simulator import Simulator
    from lti_motion.exceptions import CalibrationError

    def no_period(*args, **kwargs):           # what a rotation cut short by a busy host gives
        raise CalibrationError("no autocorrelation peak reaches 0.5 (best -0.14)")

    out = tmp_path / "cal"
    argv = ["calibrate", "--sim", "create2", "--excitation-s", "20", "--out", str(out)]
    with monkeypatch.context() as m:
        m.setattr(manoeuvres, "rotation_period_ticks", no_period)
        assert main(argv) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert "no autocorrelation peak" in line
    assert "the rotation drive failed its analysis and was set aside as " \
           "log_rotation.failed.npz (--resume drives it again)" in line
    assert "no manoeuvre was complete, nothing kept" in line
    assert (out / "log_rotation.failed.npz").is_file() and not (out / "log_rotation.npz").exists()

    run, calls = Simulator.run, []
    monkeypatch.setattr(Simulator, "run", lambda self, c: calls.append(len(c)) or run(self, c))
    assert main([*argv, "--resume", "--accept-unhealthy"]) == 0
    printed = capsys.readouterr().out
    assert "resuming" not in printed and "kept the rotation drive" in printed
    assert len(calls) == 3 and (out / "model_arx.json").is_file()


def test_a_link_that_dies_in_the_steps_sets_no_drive_aside(tmp_path, capsys, monkeypatch):
    from drivers.exceptions import PortError
    from drivers.sim.simulator import Simulator

    run, calls = Simulator.run, []

    def link_dies_in_the_steps(self, cmd_m_s):
        calls.append(len(cmd_m_s))
        if len(calls) == 2:
            raise PortError("read from /dev/ttyUSB0 failed: [Errno 5] Input/output error")
        return run(self, cmd_m_s)

    monkeypatch.setattr(Simulator, "run", link_dies_in_the_steps)
    out = tmp_path / "cal"
    assert main(["calibrate", "--sim", "create2", "--excitation-s", "20",
                 "--out", str(out)]) == 2
    assert "set aside" not in capsys.readouterr().err
    assert (out / "log_rotation.npz").is_file() and not list(out.glob("*.failed.npz"))
