"""The monitor's drive, its Phase I on the simulator and its simulated landmark sensor
(``lti_motion.app.monitor_setup``)."""

import numpy as np
import pytest

from fusion.monitoring.phase_one import encoder_nis
from lti_motion.app import monitor_setup as ms


@pytest.fixture(scope="module")
def model(short_arx_model):
    return short_arx_model(2)


def test_gate_sits_between_a_start_from_rest_and_a_spike(model):
    fit = ms.nominal_on_simulator(model, n_drives=3, duration_s=20.0, seed=4)
    assert fit.n_drives == 3
    assert fit.duration_s == pytest.approx(3 * (round(20.0 / model.dt_s) - 1) * model.dt_s)
    # the model misses the start from rest beyond the chi-square gate; the rule is 10 x that
    assert fit.max_nominal_nis > 55.3
    assert fit.encoder_gate_nis == pytest.approx(10.0 * fit.max_nominal_nis)
    assert fit.options(model.dt_s).encoder_gate_nis == fit.encoder_gate_nis
    # a 150-tick spike on a fresh drive is far above it
    from drivers.sim.config import Fault, Room
    from drivers.sim.simulator import Simulator

    sim = Simulator("create2", seed=9, room=Room.empty(), initial_pose=(0.0, 0.0, 0.0),
                    faults=[Fault("encoder_spikes", t_s=10.0, duration_s=1.0, rate_hz=20.0)])
    log = sim.run(ms.monitor_route(15.0, dt_s=model.dt_s, wheel_base_m=model.wheel_base_m,
                                   rng=np.random.default_rng(9)))
    nis = encoder_nis(model, log.cmd_m_s[1:], log.ticks)
    k = round(10.0 / model.dt_s) - 5                    # a few frames before the onset
    assert np.nanmax(nis[:k]) < fit.encoder_gate_nis < np.nanmax(nis[k:])


def test_simulated_sensor_sees_each_landmark_at_2_hz():
    rng = np.random.default_rng(1)
    seen = [ms.sightings(np.array([0.5, 1.0, 0.3]), k, rng) for k in range(round(2.0 / 0.015))]
    assert all(len(frame) == 0 or frame.index.tolist() == [k] * len(frame)
               for k, frame in enumerate(seen))
    ids = [lid for frame in seen for lid, _, _ in frame]
    assert sorted(set(ids)) == [1, 2, 3, 4]
    assert all(ids.count(i) in (4, 5) for i in range(1, 5))          # 2 Hz over 2 s
    r = np.hypot(-1.5 - 0.5, -1.0 - 1.0)
    ranges = [rb[0] for frame in seen for lid, rb, _ in frame if lid == 1]
    assert np.allclose(ranges, r, rtol=0.1)


def test_a_robot_with_12_bit_counters_is_monitored_as_its_16_bit_twin(model, tmp_path):
    """Phase I and the monitored drive on a robot whose counters wrap every 4,096 ticks give
    the alarms, counts and final pose of the same robot with 16-bit counters; the recorded
    drive says its width, and a Phase I from that log matches the simulator's."""
    from drivers.sim.config import load_robot
    from lti_motion.app.monitor import run_on_simulator
    from lti_motion.recordings.logfile import load_log

    runs = {}
    for bits in (16, 12):
        params = load_robot("create2").replace(counter_bits=bits)
        runs[bits] = run_on_simulator(model, robot=params, duration_s=20.0, seed=3,
                                      fault="delay", fault_at_s=8.0, nominal_drives=3,
                                      record=str(tmp_path / f"drive{bits}.npz"),
                                      print_fn=lambda _line: None)
    narrow = load_log(tmp_path / "drive12.npz")
    assert narrow.counter_bits == 12 and narrow.ticks.max() < 4096
    assert np.any(np.abs(np.diff(narrow.ticks, axis=0)) > 2048)          # it wraps
    wide, thin = runs[16], runs[12]
    assert [(e.kind, e.t_s) for e in thin.events] == [(e.kind, e.t_s) for e in wide.events]
    assert thin.counts == wide.counts and thin.encoders_gated == wide.encoders_gated
    np.testing.assert_allclose(thin.final_pose, wide.final_pose, rtol=0, atol=1e-9)
    fit_log = ms.nominal_from_logs(model, [str(tmp_path / "drive12.npz")] * 3)  # 100 windows
    fit_twin = ms.nominal_from_logs(model, [str(tmp_path / "drive16.npz")] * 3)
    assert fit_log.max_nominal_nis == pytest.approx(fit_twin.max_nominal_nis, rel=1e-12)
