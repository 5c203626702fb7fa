"""``lti-motion calibrate --log LOG --reference FILE.tum``: a recorded drive and a motion
capture give both wheels' scale; bad input is one line and exit 2."""

import itertools
import json

import numpy as np
import pytest

from drivers.sim.config import Room, get_preset
from drivers.sim.motion_capture import intrinsics_drive, motion_capture
from drivers.sim.simulator import Simulator
from lti_motion.app.cli import main
from lti_motion.recordings.logfile import save_log
from lti_motion.recordings.tum import write_tum


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    folder = tmp_path_factory.mktemp("intrinsics")
    params = get_preset("create2", wheel_diameter_errors=(0.01, 0.0))
    log = Simulator(params, seed=4, room=Room.empty(), initial_pose=(0, 0, 0)).run(
        intrinsics_drive(params.period_s, repeats=1))
    t, poses = motion_capture(log, rng=np.random.default_rng(4))
    return {"log": save_log(folder / "drive.npz", log),
            "ref": write_tum(folder / "mocap.tum", t, poses),
            "late": write_tum(folder / "late.tum", t + 1e4, poses),
            "straight": write_tum(folder / "straight.tum", t, np.zeros_like(poses)),
            "folder": folder, "params": params}


def test_writes_intrinsics_and_prints_them(drive, capsys):
    out = drive["folder"] / "out"
    code = main(["calibrate", "--log", str(drive["log"]), "--reference", str(drive["ref"]),
                 "--out", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "left wheel" in text and "wheel base" in text
    result = json.loads((out / "intrinsics.json").read_text())["intrinsics"]
    ratio = result["m_per_tick_left"] / result["m_per_tick_right"]
    assert ratio == pytest.approx(1.01, rel=2e-3)


@pytest.mark.parametrize(("extra", "message"), [
    (["--reference", "late"], "overlap"),
    (["--reference", "straight"], "no turns"),
    (["--reference", "missing"], "missing.tum"),
])
def test_bad_input_is_one_line_and_exit_2(drive, capsys, extra, message):
    args = ["calibrate", "--log", str(drive["log"]), "--out", str(drive["folder"] / "bad")]
    if extra:
        name = extra[1]
        path = drive.get(name, drive["folder"] / f"{name}.tum")
        args += ["--reference", str(path)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert "Error:" not in err and "PoseReferenceError" not in err


def test_a_reference_without_a_log_is_one_line_and_exit_2(drive, capsys):
    # --log alone is the offline model calibration; --reference needs the drive it refers to
    assert main(["calibrate", "--robot", "create2", "--reference", str(drive["folder"] / "x.tum"),
                 "--out", str(drive["folder"] / "bad")]) == 2
    err = capsys.readouterr().err
    assert "--reference goes with --log" in err and err.count("\n") == 1
    assert not (drive["folder"] / "bad").exists()


def test_into_model_writes_a_model_carrying_the_intrinsics(drive, tmp_path, capsys):
    from lti_motion.model.fir import FirFit
    from lti_motion.model.motion_model import MotionModel

    fit = FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
                 residual_cov=np.eye(2) * 1e-4, n_samples=100, source="steps")
    model = MotionModel.from_fir(fit, dt_s=0.015, wheel_base_m=0.235, m_per_tick=4.4e-4,
                                 calibrated_at="2026-01-01T00:00:00+00:00")
    path = model.save(tmp_path / "model.json")
    assert main(["calibrate", "--log", str(drive["log"]), "--reference", str(drive["ref"]),
                 "--into-model", str(path), "--out", str(tmp_path / "o")]) == 0
    loaded = MotionModel.load(tmp_path / "o" / "model_intrinsics.json")
    assert loaded.intrinsics is not None
    assert loaded.intrinsics.diameter_ratio == pytest.approx(1.01, rel=2e-3)
    assert loaded.m_per_tick == pytest.approx(loaded.intrinsics.m_per_tick)
    assert np.array_equal(loaded.A, model.A)
    # the outputs moved with the counts' meaning: the same counts are predicted
    T = loaded.intrinsics.jacobian() @ np.linalg.inv(model.encoder_intrinsics.jacobian())
    np.testing.assert_allclose(loaded.C, T @ model.C, rtol=1e-12, atol=1e-15)
    # the odometry's error, measured on the drive, goes with the intrinsics
    written = json.loads((tmp_path / "o" / "intrinsics.json").read_text())["odometry_errors"]
    assert loaded.odometry_errors is not None
    assert loaded.odometry_errors.wheel_variance_per_m == written["wheel_variance_per_m"]
    np.testing.assert_allclose(loaded.odometry_errors.intrinsics_covariance,
                               np.asarray(written["intrinsics_covariance"]), rtol=1e-12)
    capsys.readouterr()
    assert main(["calibrate", "--log", str(drive["log"]), "--reference", str(drive["ref"]),
                 "--into-model", str(tmp_path / "none.json"), "--out", str(tmp_path / "p")]) == 2
    assert "no model file" in capsys.readouterr().err


def test_reference_without_log_is_refused(capsys):
    assert main(["calibrate", "--robot", "create2", "--reference", "x.tum"]) == 2
    assert "--reference goes with --log" in capsys.readouterr().err


@pytest.mark.parametrize(("extra", "message"), [
    (["--reference-std", "-0.005", "0.5"], "--reference-std M must be a positive"),
    (["--outlier-rounds", "-1"], "--outlier-rounds must be an integer of at least 0"),
    (["--outlier-fraction", "0.7"], r"--outlier-fraction must be in (0, 0.5]"),
])
def test_bad_options_are_one_line_and_exit_2(drive, capsys, extra, message):
    args = ["calibrate", "--log", str(drive["log"]), "--reference", str(drive["ref"]),
            "--out", str(drive["folder"] / "bad"), *extra]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_the_command_line_and_the_api_give_the_same_result(drive):
    """One set of defaults: the command with no options and the API with none."""
    from lti_motion.calibration import calibrate_intrinsics
    from lti_motion.recordings import load_log, read_tum

    out = drive["folder"] / "same"
    assert main(["calibrate", "--log", str(drive["log"]), "--reference", str(drive["ref"]),
                 "--out", str(out)]) == 0
    log = load_log(drive["log"])
    cal = calibrate_intrinsics(log.t_s[log.valid], log.ticks[log.valid], *read_tum(drive["ref"]))
    written = json.loads((out / "intrinsics.json").read_text())
    assert written["intrinsics"] == cal.intrinsics.as_dict()
    assert written["intervals_rejected"] == cal.n_rejected


def test_runs_with_only_start_and_end_poses(drive, tmp_path, capsys):
    """The drive cut into 20 runs, each localised only at its ends by the motion capture
    (5 mm, 0.5 deg): ``--reference RUNS`` with the runs header."""
    from lti_motion.recordings import RUNS_HEADER, read_tum

    t, poses = read_tum(drive["ref"])
    heading = np.unwrap(poses[:, 2])
    edges = np.linspace(0, len(t) - 1, 21).astype(int)
    lines = [RUNS_HEADER]
    for a, b in itertools.pairwise(edges):
        seen = np.angle(np.exp(1j * (poses[b, 2] - poses[a, 2])))
        turns = int(np.round((heading[b] - heading[a] - seen) / (2 * np.pi)))
        lines.append(" ".join(f"{v:.6f}" for v in [t[a], t[b], *poses[a], *poses[b]])
                     + f" {turns}")
    runs = tmp_path / "runs.txt"
    runs.write_text("\n".join(lines) + "\n")
    assert main(["calibrate", "--log", str(drive["log"]), "--reference", str(runs),
                 "--out", str(tmp_path / "o")]) == 0
    written = json.loads((tmp_path / "o" / "intrinsics.json").read_text())
    k = written["intrinsics"]
    assert k["m_per_tick_left"] / k["m_per_tick_right"] == pytest.approx(1.01, rel=3e-3)
    assert written["intervals_used"] == 20
    capsys.readouterr()
    assert main(["calibrate", "--reference", str(runs), "--out", str(tmp_path / "p")]) == 2
    assert "goes with --log" in capsys.readouterr().err


def test_a_clock_offset_is_named_and_fixed_by_its_option(drive, capsys):
    assert main(["calibrate", "--log", str(drive["log"]), "--reference", str(drive["late"]),
                 "--out", str(drive["folder"] / "late")]) == 2
    assert "--reference-offset S" in capsys.readouterr().err
    assert main(["calibrate", "--log", str(drive["log"]), "--reference", str(drive["late"]),
                 "--reference-offset=-1e4", "--out", str(drive["folder"] / "late")]) == 0
