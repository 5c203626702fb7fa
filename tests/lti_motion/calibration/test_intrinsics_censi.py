"""The intrinsics calibration on Censi et al.'s own data (IEEE T-RO 29(2), 2013): a Khepera
III with a laser scanner off its axle, configurations ``lstraight`` (A) and ``l90`` (B),
each whole run and its three subsets, raw (no hand cleaning), through the command line with
its defaults plus ``--sensor-pose``; the authors' published results (``X_results.json``,
their solver with four outlier rounds) are the reference values."""

import json

import numpy as np
import pytest

from lti_motion.app.cli import main
from lti_motion.calibration import calibrate_intrinsics, calibrate_intrinsics_intervals
from lti_motion.recordings import read_motion_intervals

RUNS = [f"{c}{s}" for c in ("lstraight", "l90") for s in ("", "_0", "_1", "_2")]
#: The Khepera III's encoders: 2764.8 ticks per wheel revolution (data README).
COUNTS_PER_RAD = 2764.8 / (2 * np.pi)


def _series(samples, counts_per_rad):
    """The samples as the project's time series: clock = cumulative intervals, integer
    counts of the integrated wheel angles, the sensor's motions composed into a path."""
    t = np.concatenate([[0.0], np.cumsum(samples.duration_s)])
    angle = np.vstack([[0.0, 0.0], np.cumsum(samples.wheel_rad, axis=0)])
    poses = np.zeros((len(t), 3))
    for k, (x, y, th) in enumerate(samples.sensor_motion):
        c, s = np.cos(poses[k, 2]), np.sin(poses[k, 2])
        poses[k + 1] = [poses[k, 0] + c * x - s * y, poses[k, 1] + s * x + c * y,
                        poses[k, 2] + th]
    return t, np.round(angle * counts_per_rad).astype(np.int64), poses


@pytest.mark.parametrize("run", RUNS)
def test_cli_defaults_on_raw_samples_match_the_authors(censi_path, tmp_path, capsys, run):
    assert main(["calibrate", "--reference", str(censi_path / f"{run}.tuple"), "--sensor-pose",
                 "--out", str(tmp_path)]) == 0
    assert "rejected as outliers" in capsys.readouterr().out
    got = json.loads((tmp_path / "intrinsics.json").read_text())
    ref = json.loads((censi_path / f"{run}_results.json").read_text())
    k = got["intrinsics"]
    assert k["wheel_base_m"] == pytest.approx(ref["axle"], rel=3e-3)
    assert got["diameters_m"]["left"] == pytest.approx(ref["l_diam"], rel=3e-3)
    assert got["diameters_m"]["right"] == pytest.approx(ref["r_diam"], rel=3e-3)
    x, y, th = got["sensor_pose"]
    assert abs(np.rad2deg(th - ref["l_theta"])) < 0.5
    assert abs(x - ref["l_x"]) < 2e-3 and abs(y - ref["l_y"]) < 2e-3
    assert got["intervals_rejected"] > 0
    assert got["intervals_used"] + got["intervals_rejected"] == len(
        read_motion_intervals(censi_path / f"{run}.tuple").duration_s)


@pytest.mark.parametrize(("config", "upper"), [("lstraight", 2.0), ("l90", None)])
def test_reported_std_covers_the_subsets_spread(censi_path, config, upper):
    """The subsets' mean reported standard deviation over their spread, per parameter:
    never below 1/2 (overconfident); for lstraight also below 2 (measured 0.73-1.26). On
    l90 (turns in place) the reported values are 1.95-3.8 times the spread for five of the
    six parameters (docs/intrinsics.md: missed; with three subsets the spread itself is
    uncertain by about a factor of two), so only the lower bound is held there."""
    est, std = [], []
    for i in range(3):
        s = read_motion_intervals(censi_path / f"{config}_{i}.tuple")
        cal = calibrate_intrinsics_intervals(s.wheel_rad, s.sensor_motion, sensor_pose=True)
        est.append([*cal.intrinsics.as_dict().values(), *cal.sensor_pose])
        std.append(cal.std)
    ratio = np.mean(std, axis=0) / np.std(est, axis=0, ddof=1)
    assert np.all(ratio > 0.5), ratio                      # never overconfident by 2x
    if upper is not None:
        assert np.all(ratio < upper), ratio


def test_counts_in_any_unit_give_the_same_physical_result(censi_path):
    s = read_motion_intervals(censi_path / "l90_2.tuple")
    base = calibrate_intrinsics_intervals(s.wheel_rad, s.sensor_motion, sensor_pose=True)
    for factor in (10.0, 0.1):
        cal = calibrate_intrinsics_intervals(s.wheel_rad * factor, s.sensor_motion,
                                             sensor_pose=True)
        k, k0 = cal.intrinsics, base.intrinsics
        np.testing.assert_allclose([k.m_per_tick_left * factor, k.m_per_tick_right * factor,
                                    k.wheel_base_m], [k0.m_per_tick_left, k0.m_per_tick_right,
                                                      k0.wheel_base_m], rtol=1e-4)
        np.testing.assert_allclose(cal.sensor_pose, base.sensor_pose, atol=1e-6)
        np.testing.assert_allclose(cal.std[2:], base.std[2:], rtol=1e-3)


def test_time_series_in_ten_times_finer_ticks_gives_the_same_result(censi_path):
    """Integer counts: 10x finer ticks change nothing but rounding (the refinement's steps
    are relative; before, a fixed absolute step moved the axle by 0.8%)."""
    s = read_motion_intervals(censi_path / "lstraight_1.tuple")
    out = []
    for cpr in (COUNTS_PER_RAD, 10 * COUNTS_PER_RAD):
        t, ticks, poses = _series(s, cpr)
        cal = calibrate_intrinsics(t, ticks, t, poses, sensor_pose=True)
        k = cal.intrinsics
        out.append([k.m_per_tick_left * cpr, k.m_per_tick_right * cpr, k.wheel_base_m,
                    cal.std[2]])
    np.testing.assert_allclose(out[1], out[0], rtol=1e-4)


def test_khepera_straight_runs_count_in_its_own_terms(censi_path):
    s = read_motion_intervals(censi_path / "lstraight_0.tuple")
    report = calibrate_intrinsics_intervals(s.wheel_rad, s.sensor_motion,
                                            sensor_pose=True).report
    assert report.straight_runs > 300 and report.turns_left > 300 and report.turns_right > 300
    s = read_motion_intervals(censi_path / "l90_0.tuple")
    report = calibrate_intrinsics_intervals(s.wheel_rad, s.sensor_motion,
                                            sensor_pose=True).report
    assert report.straight_runs == 0 and report.arcs == 0
    assert any("turns in place only" in note for note in report.undetermined)


def test_without_the_sensor_mount_the_message_names_it(censi_path, tmp_path, capsys):
    assert main(["calibrate", "--reference", str(censi_path / "l90_0.tuple"),
                 "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "--sensor-pose" in err and err.count("\n") == 1


def test_time_series_of_wheel_angles_in_any_unit_gives_the_same_result(censi_path):
    """Float counts (wheel angles, never wrapping): radians, and 10x finer and coarser
    units, equal within 0.01% (no rounding involved)."""
    s = read_motion_intervals(censi_path / "l90_1.tuple")
    t, _, poses = _series(s, 1.0)
    angle = np.vstack([[0.0, 0.0], np.cumsum(s.wheel_rad, axis=0)])
    out = []
    for unit in (1.0, 10.0, 0.1):
        cal = calibrate_intrinsics(t, angle * unit, t, poses, sensor_pose=True)
        k = cal.intrinsics
        out.append([k.m_per_tick_left * unit, k.m_per_tick_right * unit, k.wheel_base_m,
                    *cal.sensor_pose])
    np.testing.assert_allclose(out[1], out[0], rtol=1e-4, atol=1e-7)
    np.testing.assert_allclose(out[2], out[0], rtol=1e-4, atol=1e-7)
