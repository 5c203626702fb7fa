"""Ctrl-C in the sub-commands: one line, exit 130, the partial drive kept where a drive is
recorded, and no file half-written (issue 28, item 2).

The interrupt is raised where a person's Ctrl-C lands: inside the drive (the simulator's
or the driver's step), or while the outputs are written.
"""

import pytest

from drivers.roomba.virtual import VirtualRoomba
from drivers.roomba.virtual_options import VirtualRoombaOptions
from lti_motion.app.cli import main
from lti_motion.recordings.logfile import load_log


@pytest.fixture
def model_file(tmp_path, tiny_model):
    return str(tiny_model.save(tmp_path / "model_arx.json"))


def test_ctrl_c_in_monitor_robot_keeps_the_partial_drive_and_exits_130(model_file, tmp_path,
                                                                       monkeypatch, capsys):
    from drivers.sim.simulator import Simulator

    run, calls = Simulator.run, []

    def interrupted_in_the_third_second(self, cmd_m_s):
        calls.append(len(cmd_m_s))
        if len(calls) == 3:
            raise KeyboardInterrupt
        return run(self, cmd_m_s)

    monkeypatch.setattr(Simulator, "run", interrupted_in_the_third_second)
    log = tmp_path / "drive.npz"
    assert main(["monitor", "--robot", "create2", "--model", model_file, "--duration", "10",
                 "--nominal-drives", "0", "--record", str(log)]) == 130
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    assert "stopped by Ctrl-C after" in captured.out and "monitored" in captured.out
    kept = load_log(log)                                 # the two blocks driven before it
    assert len(kept.ticks) == calls[0] + calls[1]


def test_ctrl_c_in_monitor_port_exits_130_and_keeps_the_drive(model_file, tmp_path,
                                                             monkeypatch, capsys):
    from drivers.roomba.driver import Roomba

    step, steps = Roomba.step, []

    def interrupted_after_100_periods(self, cmd):
        steps.append(cmd)
        if len(steps) > 100:
            raise KeyboardInterrupt
        return step(self, cmd)

    monkeypatch.setattr(Roomba, "step", interrupted_after_100_periods)
    log = tmp_path / "drive.npz"
    with VirtualRoomba(seed=5, options=VirtualRoombaOptions(speed=10.0)) as vr:
        assert main(["monitor", "--port", vr.device_path, "--clock-rate", "10",
                     "--model", model_file, "--duration", "10", "--record", str(log)]) == 130
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    assert "stopped by Ctrl-C after 100 frames" in captured.out
    assert len(load_log(log).ticks) == 100


def test_ctrl_c_while_the_demo_draws_leaves_no_truncated_plot(tmp_path, monkeypatch, capsys):
    from matplotlib.figure import Figure

    def interrupted_halfway(self, fname, **kwargs):     # a Ctrl-C while the PNG is written
        if hasattr(fname, "write"):
            fname.write(b"\x89PNG\r\n\x1a\n half an image")
        else:
            with open(fname, "wb") as f:
                f.write(b"\x89PNG\r\n\x1a\n half an image")
        raise KeyboardInterrupt

    monkeypatch.setattr(Figure, "savefig", interrupted_halfway)
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--runs", "1", "--excitation-s", "20"]) == 130
    assert capsys.readouterr().err.strip() == "lti-motion demo: stopped by Ctrl-C"
    assert sorted(p.name for p in out.iterdir()) == ["model_arx.json"]    # whole, saved before
