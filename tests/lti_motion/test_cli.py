"""The command line, run as a user runs it (short horizons)."""

import json

import pytest

from lti_motion.cli import build_parser, main


def test_demo_writes_report_metrics_and_plots(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--runs", "4", "--excitation-s", "60"]) == 0
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    closure = metrics["closure_offset_m"]
    assert {"odometry", "fir_sensorless", "arx_sensorless", "arx_hybrid", "ekf",
            "ekf_landmarks"} <= set(closure)
    for row in closure.values():
        assert row["n"] == 4 and row["mean"] > 0 and row["std"] >= 0
    for name in ("report.md", "closure.png", "trajectories.png", "order_selection.png"):
        assert (tmp_path / name).stat().st_size > 500, name
    out = capsys.readouterr().out
    assert "Table II" in out and "0.068" in out          # the paper's odometry row beside ours


def test_help_and_bad_choices(capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["demo", "--floor", "ice"])
    assert exc.value.code == 2
    assert "invalid choice: 'ice'" in capsys.readouterr().err


def test_calibrate_on_a_missing_port_names_it(capsys):
    assert main(["calibrate", "--port", "/dev/does-not-exist", "--yes"]) == 2
    assert "/dev/does-not-exist" in capsys.readouterr().err


def test_calibrate_sim_writes_models_and_plots(tmp_path, capsys):
    assert main(["calibrate", "--sim", "create2", "--excitation-s", "40",
                 "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "encoder scale" in out and "ARX" in out
    for name in ("model_arx.json", "model_fir.json", "order_selection.png"):
        assert (tmp_path / name).is_file()


def test_virtual_roomba_prints_its_device_path(capsys):
    assert main(["virtual-roomba", "--duration", "0.3"]) == 0
    out = capsys.readouterr().out
    assert "listening on /dev/pts/" in out and "stopped" in out
