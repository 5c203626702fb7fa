"""Examples run as a user runs them, with short horizons (each is functions and a seeded main)."""




def test_calibrate_sim_writes_plots_and_model(tmp_path, capsys, load_example):
    example = load_example("calibrate_sim")
    assert example.main(["--out", str(tmp_path), "--excitation-s", "40"]) == 0
    for name in ("step_responses.png", "order_selection.png", "calibration_sequence.png",
                 "validation.png"):
        assert (tmp_path / name).stat().st_size > 10_000, name
    from lti_motion.model.motion_model import MotionModel

    model = MotionModel.load(tmp_path / "model_arx.json")
    assert model.kind == "arx" and model.m_per_tick > 0
    assert "free-run fit" in capsys.readouterr().out


def test_recalibration_alarm_raises_the_right_alarms_and_plots(tmp_path, capsys, load_example):
    example = load_example("recalibration_alarm")
    # a short form: 10 nominal drives for Phase I, the route cut at 40 s, faults earlier
    result = example.run(seed=0, spikes_at_s=5.0, carpet_at_s=10.0, payload_at_s=25.0,
                         max_s=40.0, nominal_runs=10, calibration_s=60.0, excitation_s=20.0,
                         validation_s=10.0, out=tmp_path)
    example.report(result, tmp_path)
    kinds = [(e.kind, e.t_s) for e in result.events]
    bursts = [t for k, t in kinds if k == "glitch_burst"]
    assert bursts and 5.0 <= bursts[0] <= 5.3, kinds            # the spikes, within 0.3 s
    assert all(5.0 <= t <= 7.0 for t in bursts), kinds          # no false burst elsewhere
    scale = [t for k, t in kinds if k == "scale_changed"]
    assert scale and all(t >= 10.0 for t in scale), kinds       # carpet, after its onset
    actions = {r.alarm.kind: r.action for r in result.records}
    assert actions["glitch_burst"] == "ignored"
    first_scale = next(r for r in result.records if r.alarm.kind == "scale_changed")
    assert first_scale.action in ("waiting", "adopted")
    for name in ("monitor.png", "fit.png"):
        assert (tmp_path / name).stat().st_size > 10_000, name
    out = capsys.readouterr().out
    assert "| t [s] | kind |" in out and "recalibration records" in out


def test_calibrate_from_bag_goes_through_the_guide(tmp_path, capsys, load_example):
    example = load_example("calibrate_from_bag")
    assert example.main(["--out", str(tmp_path), "--excitation-s", "40", "--drive-s",
                         "20"]) == 0
    out = capsys.readouterr().out
    assert "free-run fit" in out and "EKF, model and encoders: ATE rmse" in out
    bursts = [float(line.split("bag time ")[1].split(":")[0]) - 1_700_000_000
              for line in out.splitlines() if line.startswith("lti_motion/glitch_burst")]
    # the spikes start 14 s in (the monitor without a nominal fit may also cry wolf before)
    assert any(14.0 <= t <= 15.0 for t in bursts), out
    for name in ("fit.png", "trajectories.png"):
        assert (tmp_path / name).stat().st_size > 10_000, name
    assert (tmp_path / "estimates.bag").stat().st_size > 10_000
