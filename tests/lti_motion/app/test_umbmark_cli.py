"""``lti-motion calibrate --umbmark --robot NAME``: UMBmark's bidirectional square on the
simulator, its end poses in a small runs file, the fit from them."""

import json

import pytest

from drivers.sim.config import get_preset
from lti_motion.app.cli import main
from lti_motion.recordings import read_end_pose_runs


def test_umbmark_writes_the_runs_and_fits_ratio_and_base(tmp_path, capsys):
    out = tmp_path / "umb"
    assert main(["calibrate", "--umbmark", "--robot", "create2", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "umbmark_runs.txt" in said and "--m-per-tick" in said
    runs = read_end_pose_runs(out / "umbmark_runs.txt")
    assert runs.turns.tolist() == [1] * 5 + [-1] * 5
    k = json.loads((out / "intrinsics.json").read_text())["intrinsics"]
    errors = get_preset("create2").wheel_diameter_errors     # left, right
    truth = (1 + errors[0]) / (1 + errors[1])
    assert k["m_per_tick_left"] / k["m_per_tick_right"] == pytest.approx(truth, rel=2e-4)
    assert k["wheel_base_m"] == pytest.approx(get_preset("create2").wheel_base_m, rel=1e-2)
    # the file refits on its own, as a user's measured one would
    assert main(["calibrate", "--log", str(out / "log_umbmark.npz"), "--reference",
                 str(out / "umbmark_runs.txt"), "--m-per-tick", "0.000444565",
                 "--out", str(tmp_path / "again")]) == 0


def test_umbmark_needs_the_simulator(tmp_path, capsys):
    assert main(["calibrate", "--umbmark", "--port", "/dev/null", "--out", str(tmp_path)]) == 2
    assert "--umbmark drives the simulator" in capsys.readouterr().err


def test_umbmark_benchmark_short_meets_the_targets():
    """``python -m benchmarks umbmark`` shortened: the asymmetric robot (left wheel 1%
    larger, right motor 10% weaker, tile), 4 m squares 3 each way, end poses measured with
    5 mm and 0.5 deg noise, seeds 0-1: ratio within 0.1%, wheel base within 0.3% of the
    simulator's straight-line truth (scoring only)."""
    from benchmarks.bench_intrinsics import asymmetric_robot
    from benchmarks.bench_umbmark import umbmark_errors

    e = umbmark_errors(asymmetric_robot(), [0, 1], side_m=4.0, runs=3)
    assert e.shape == (2, 4)
    assert abs(e[:, 0]).max() < 0.1                    # ratio against the straight-line truth
    assert abs(e[:, 2]).max() < 0.3                    # wheel base against the contact base
    # the 1% type B error is found: the ratio is 1.01 to within 0.1%, not 1
    assert abs(e[:, 1]).max() < 0.1
