"""Each estimator asks for what it needs: a bag without commands (the Jackal's odometry and
Imu) replays the odometry, and what needs the commands is refused naming itself and the
missing topic, one line, exit 2."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from lti_motion.app.cli import main


@pytest.fixture(scope="module")
def jackal() -> Path:
    """``LTI_MOTION_DATA/real/jackal_odom_imu.bag``; absent data fails under CI and skips
    elsewhere, as the other real-data fixtures (tests/conftest.py)."""
    env = os.environ.get("LTI_MOTION_DATA")
    base = Path(env) if env else Path(__file__).resolve().parents[4] / "shared" / "data"
    path = base / "real" / "jackal_odom_imu.bag"
    if not path.is_file():
        if os.environ.get("CI"):
            pytest.fail("real bags not found: set LTI_MOTION_DATA to the shared data folder")
        pytest.skip("real bags not found (set LTI_MOTION_DATA)")
    return path


@pytest.fixture
def model_file(tiny_model, tmp_path) -> Path:
    """A model at the Jackal bag's own 20 ms period (another period is refused first)."""
    return tiny_model.updated(dt_s=0.02).save(tmp_path / "model.json")


def test_the_odometry_replays_without_commands(jackal, model_file, tmp_path, capsys):
    out = tmp_path / "replay"
    assert main(["replay", "--bag", str(jackal), "--model", str(model_file),
                 "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert ("jackal_odom_imu.bag has no commands: replaying only the estimators that need "
            "none (odometry)") in said
    assert "no commands to time the wheels against" in said
    assert {p.name for p in out.iterdir()} >= {"odometry.tum"}
    assert not (out / "ekf.tum").exists() and not (out / "commands.tum").exists()
    tum = np.loadtxt(out / "odometry.tum")
    assert len(tum) > 1000 and np.all(np.isfinite(tum))


@pytest.mark.parametrize(("argv", "words"), [
    (["replay", "--estimators", "odometry", "ekf"], ("estimator 'ekf' needs the commands",
                                                     "estimators that need none: odometry")),
    (["replay", "--estimators", "sensorless"], ("estimator 'sensorless' needs the commands",)),
    (["replay", "--gyro"], ("--gyro fuses the Imu in estimator 'ekf'",)),
    (["monitor"], ("monitor --bag needs the commands",)),
])
def test_what_needs_the_commands_is_refused_by_name(jackal, model_file, tmp_path, capsys,
                                                    argv, words):
    extra = ["--out", str(tmp_path / "o")] if argv[0] == "replay" else []
    assert main([argv[0], "--bag", str(jackal), "--model", str(model_file), *extra,
                 *argv[1:]]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    for word in (*words, "jackal_odom_imu.bag", "/jackal_velocity_controller/odom"):
        assert word in err, err
