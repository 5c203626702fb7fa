"""Examples run as a user runs them, with short horizons (STYLE rule 15)."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _load(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "examples" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_calibrate_sim_writes_plots_and_model(tmp_path, capsys):
    example = _load("calibrate_sim")
    assert example.main(["--out", str(tmp_path), "--excitation-s", "40"]) == 0
    for name in ("step_responses.png", "order_selection.png", "calibration_sequence.png",
                 "validation.png"):
        assert (tmp_path / name).stat().st_size > 10_000, name
    from lti_motion.model import MotionModel

    model = MotionModel.load(tmp_path / "model_arx.json")
    assert model.kind == "arx" and model.m_per_tick > 0
    assert "free-run fit" in capsys.readouterr().out
