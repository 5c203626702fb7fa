"""``lti-motion calibrate --log``: offline calibration from any recording, and its refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest

from drivers.sim.config import get_preset
from drivers.sim.simulator import Simulator
from lti_motion.app.cli import main
from lti_motion.model.excitation import random_held_normal
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.logfile import save_log, save_recording
from lti_motion.recordings.recording import Recording
from lti_motion.recordings.ticks import unwrap_ticks

PARAMS = get_preset("create2")


@pytest.fixture(scope="module")
def drive():
    """45 s of held random commands between two 1 s rests, on the simulator (seed 4)."""
    dt = PARAMS.period_s
    cmd = random_held_normal(n=round(45 / dt), dt_s=dt, rng=np.random.default_rng(4),
                             std_m_s=0.2, mean_m_s=0.0, hold_s=(0.5, 2.0), correlation=0.85)
    rest = np.zeros((round(1 / dt), 2))
    return Simulator(PARAMS, seed=4).run(np.concatenate([rest, cmd, rest]))


def _angles(log):
    """The same drive as a JointState robot would record it: wheel angles, stamped commands."""
    angles = unwrap_ticks(log.ticks) * PARAMS.m_per_tick / (PARAMS.wheel_diameter_m / 2)
    return Recording.from_streams(wheel_t_s=log.t_s, dt_s=log.dt_s, wheel_angles_rad=angles,
                                  cmd_t_s=log.t_s - log.dt_s, cmd_wheel_m_s=log.cmd_m_s)


def test_a_roomba_log_and_a_wheel_angle_recording_both_calibrate(drive, tmp_path, capsys):
    v1 = save_log(tmp_path / "v1.npz", drive)
    assert main(["calibrate", "--accept-unhealthy", "--log", str(v1), "--robot", "create2",
                 "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert "condition of the regression" in out and "at rest" in out
    assert "NOT measured" in out and "encoder scale" in out
    model_a = MotionModel.load(tmp_path / "a" / "model_arx.json")
    assert model_a.m_per_tick == pytest.approx(PARAMS.m_per_tick)
    robot = model_a.robot                       # the robot travels with the model
    assert (robot.robot, robot.wheel_data, robot.encoders, robot.counter_bits) == (
        "create2", "counts", "commanded", 16)
    assert robot.m_per_tick == pytest.approx((PARAMS.m_per_tick,) * 2)
    assert robot.wheel_base_m == 0.235 and robot.dt_s == model_a.dt_s

    v2 = save_recording(tmp_path / "v2.npz", _angles(drive))
    assert main(["calibrate", "--accept-unhealthy", "--log", str(v2), "--wheel-radius",
                 str(PARAMS.wheel_diameter_m / 2), "--out", str(tmp_path / "b")]) == 0
    model_b = MotionModel.load(tmp_path / "b" / "model_arx.json")
    assert model_b.m_per_tick == pytest.approx(PARAMS.wheel_diameter_m / 2 / 1e4)
    assert model_b.robot.wheel_data == "wheel_angles_rad"
    assert model_b.robot.wheel_radius_m == (PARAMS.wheel_diameter_m / 2,) * 2
    fits = [float(line.split("v ")[-1].split("%")[0])
            for line in capsys.readouterr().out.splitlines() if "free-run fit" in line]
    assert fits and fits[0] > 70.0, fits

    # replay reads both versions: the wheel angles with the radius the model carries give
    # the encoder odometry of the Roomba frames (the same drive; the recording of angles
    # holds no truth: the path lengths compared)
    ates = {}
    for name, log, model in (("v1", v1, "a"), ("v2", v2, "b")):
        assert main(["replay", str(log), "--model", str(tmp_path / model / "model_arx.json"),
                     "--estimators", "odometry", "--out", str(tmp_path / f"r{name}")]) == 0
        ates[name] = json.loads((tmp_path / f"r{name}" / "metrics.json").read_text())[
            "metrics"]["odometry"]["path_m"]
    assert ates["v2"] == pytest.approx(ates["v1"], rel=0.01), ates
    # a model of counts replaying wheel angles: another robot's data, one line
    capsys.readouterr()
    assert main(["replay", str(v2), "--model", str(tmp_path / "a" / "model_arx.json"),
                 "--out", str(tmp_path / "rx")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "v2.npz has wheel angles [rad]" in err
    assert "the model's robot (create2) raw encoder counts" in err


def test_a_straight_drive_is_refused_with_the_reason_and_nothing_written(drive, tmp_path,
                                                                         capsys):
    straight = Simulator(PARAMS, seed=5).run(np.repeat(drive.cmd_m_s.mean(axis=1)[:, None],
                                                       2, axis=1))
    path = save_log(tmp_path / "straight.npz", straight)
    assert main(["calibrate", "--log", str(path), "--robot", "create2",
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "yaw dynamics are not identified" in err
    assert not (tmp_path / "o").exists()


def test_counts_without_a_scale_and_an_impossible_wheel_speed_exit_2(drive, tmp_path, capsys):
    path = save_log(tmp_path / "v1.npz", drive)
    assert main(["calibrate", "--log", str(path), "--out", str(tmp_path / "o")]) == 2
    assert "--m-per-tick" in capsys.readouterr().err
    rec = _angles(drive)
    fast = rec.wheel.values.copy()
    fast[500:, 1] += 100.0 * PARAMS.period_s / (PARAMS.wheel_diameter_m / 2)
    bad = Recording.from_streams(wheel_t_s=rec.wheel.t_s, wheel_angles_rad=fast,
                                 cmd_t_s=rec.cmd.t_s, cmd_wheel_m_s=rec.cmd.values)
    path = save_recording(tmp_path / "fast.npz", bad)
    assert main(["calibrate", "--log", str(path), "--wheel-radius", "0.036",
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "wheel_angles_rad: a wheel at 100 m/s" in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_a_recording_with_a_rotation_in_place_measures_the_scale(tmp_path, capsys):
    from drivers.sim.config import Room
    from drivers.sim.simulator import ground_m_per_tick
    from lti_motion.model.excitation import rotation_in_place
    from lti_motion.recordings.frames import FrameLog

    params = PARAMS.replace(wheel_diameter_errors=(0.03, 0.03))   # 3% off the description
    dt = params.period_s
    rest = np.zeros((round(1 / dt), 2))
    sim = Simulator(params, seed=6, room=Room.cluttered(), initial_pose=Room.CALIBRATION_SPOT)
    turn = sim.run(np.concatenate([rest, rotation_in_place(
        turns=3.0, wheel_speed_m_s=0.15, wheel_base_m=PARAMS.wheel_base_m, dt_s=dt), rest]))
    sim.place(Room.OPEN_FLOOR)
    cmd = random_held_normal(n=round(40 / dt), dt_s=dt, rng=np.random.default_rng(6),
                             std_m_s=0.2, mean_m_s=0.0, hold_s=(0.5, 2.0), correlation=0.85)
    drive = sim.run(np.concatenate([rest, cmd, rest]))
    both = FrameLog(**{name: np.concatenate([getattr(turn, name), getattr(drive, name)])
                       for name in ("t_s", "ticks", "light_bump", "bumps", "cmd_m_s",
                                    "valid")}, dt_s=dt)
    path = save_log(tmp_path / "both.npz", both)
    assert main(["calibrate", "--accept-unhealthy", "--log", str(path),
                 "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "measured by the rotation in place" in out and "NOT measured" not in out
    model = MotionModel.load(tmp_path / "o" / "model_arx.json")
    truth = ground_m_per_tick(params, "hard")
    assert model.m_per_tick == pytest.approx(truth, rel=0.01)
    assert abs(PARAMS.m_per_tick / truth - 1) > 0.025          # the description is not
    # the same drive without its rotation: the scale must come from the description
    path = save_log(tmp_path / "drive.npz", drive)
    assert main(["calibrate", "--log", str(path), "--out", str(tmp_path / "p")]) == 2
    assert "no rotation in place" in capsys.readouterr().err
