"""Examples run as a user runs them, with short horizons (STYLE rule 15)."""




def test_calibrate_sim_writes_plots_and_model(tmp_path, capsys, load_example):
    example = load_example("calibrate_sim")
    assert example.main(["--out", str(tmp_path), "--excitation-s", "40"]) == 0
    for name in ("step_responses.png", "order_selection.png", "calibration_sequence.png",
                 "validation.png"):
        assert (tmp_path / name).stat().st_size > 10_000, name
    from lti_motion.model import MotionModel

    model = MotionModel.load(tmp_path / "model_arx.json")
    assert model.kind == "arx" and model.m_per_tick > 0
    assert "free-run fit" in capsys.readouterr().out
