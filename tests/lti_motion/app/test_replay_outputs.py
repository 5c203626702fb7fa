"""``lti-motion replay``'s output folder holds only this run's files, each written whole
(issue 28, item 4; ``docs/replay.md``, Files)."""

import errno

import numpy as np
import pytest

from drivers.sim.config import Room
from drivers.sim.simulator import Simulator
from lti_motion.app.cli import main
from lti_motion.app.monitor import monitor_route
from lti_motion.recordings.logfile import save_log


@pytest.fixture
def paths(tmp_path, tiny_model):
    sim = Simulator("create2", seed=3, room=Room.empty(), initial_pose=(0.0, 0.0, 0.0))
    log = sim.run(monitor_route(5.0, dt_s=sim.dt_s, wheel_base_m=tiny_model.wheel_base_m,
                                rng=np.random.default_rng(3)))
    return (str(save_log(tmp_path / "drive.npz", log)),
            str(tiny_model.save(tmp_path / "model_arx.json")), tmp_path / "out")


def test_a_second_run_leaves_none_of_the_first_runs_files(paths, capsys):
    log, model, out = paths
    assert main(["replay", log, "--model", model, "--out", str(out)]) == 0
    assert (out / "ekf.tum").is_file() and (out / "odometry.tum").is_file()
    (out / "notes.txt").write_text("mine")                   # not a replay output: kept
    assert main(["replay", log, "--model", model, "--out", str(out),
                 "--estimators", "commands"]) == 0
    left = sorted(p.name for p in out.iterdir())
    assert left == ["commands.tum", "errors.png", "groundtruth.tum", "metrics.json",
                    "notes.txt", "trajectories.png"]


def test_a_full_disk_names_the_file_and_leaves_no_truncated_one(paths, capsys, monkeypatch):
    import lti_motion.recordings.tum as tum

    log, model, out = paths
    savetxt, calls = np.savetxt, []

    def disk_fills_halfway(f, rows, **kwargs):
        calls.append(f)
        if len(calls) == 2:                           # ekf.tum, after odometry.tum
            savetxt(f, rows[: len(rows) // 2], **kwargs)
            raise OSError(errno.ENOSPC, "No space left on device")
        savetxt(f, rows, **kwargs)

    monkeypatch.setattr(tum.np, "savetxt", disk_fills_halfway)
    assert main(["replay", log, "--model", model, "--out", str(out),
                 "--estimators", "odometry", "ekf"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    assert f"could not write {out / 'ekf.tum'}: No space left on device" in err
    assert list(out.iterdir()) == []              # no truncated file, no half set, no temp


def test_ctrl_c_while_writing_is_one_line_exit_130_and_no_half_set(paths, capsys, monkeypatch):
    import lti_motion.app.replay_plots as plots

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    log, model, out = paths
    monkeypatch.setattr(plots, "plot_trajectories", interrupted)
    assert main(["replay", log, "--model", model, "--out", str(out)]) == 130
    assert capsys.readouterr().err.strip() == "lti-motion replay: stopped by Ctrl-C"
    assert list(out.iterdir()) == []
