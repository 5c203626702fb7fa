"""Phase I (fusion.monitoring.phase_one): the encoder gate and the checks on nominal drives."""

import numpy as np
import pytest

from fusion.exceptions import FilterOptionError, MeasurementShapeError
from fusion.monitoring.phase_one import fit_nominal
from fusion.monitoring.residual import MonitorOptions, ResidualMonitor, design_thresholds
from lti_motion.model.fir import FirFit
from lti_motion.model.motion_model import MotionModel


@pytest.fixture(scope="module")
def model():
    return MotionModel.from_fir(
        FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
               residual_cov=np.eye(2) * 1e-4, n_samples=100, source="steps"),
        dt_s=0.015, wheel_base_m=0.25, m_per_tick=5e-4,
        calibrated_at="2026-01-01T00:00:00+00:00")


def test_encoder_gate_applies_to_the_encoder_stream_only():
    opt = MonitorOptions(encoder_gate_nis=5000.0)
    assert design_thresholds(opt).gate == 5000.0
    assert design_thresholds(opt).burst_rate_per_hour < 1e-300     # chi-square tail of 5000
    assert round(design_thresholds(opt, stream="landmark").gate, 1) == 55.3
    mon = ResidualMonitor(opt)
    assert mon.thresholds("encoders").gate == 5000.0
    assert round(mon.thresholds("landmark").gate, 1) == 55.3
    with pytest.raises(FilterOptionError, match="encoder_gate_nis"):
        MonitorOptions(encoder_gate_nis=-1.0)


def test_fit_nominal_rejects_bad_input(model):
    with pytest.raises(FilterOptionError, match="at least one"):
        fit_nominal(model, [])
    with pytest.raises(MeasurementShapeError, match=r"ticks \(n \+ 1, 2\)"):
        fit_nominal(model, [(np.zeros((10, 2)), np.zeros((10, 2)))])
    with pytest.raises(FilterOptionError, match="gate_factor"):
        fit_nominal(model, [(np.zeros((10, 2)), np.zeros((11, 2)))], gate_factor=0.5)




def test_fit_nominal_reports_each_drive_and_the_null_fit(model, caplog):
    import logging

    from drivers.sim.config import Room
    from drivers.sim.simulator import Simulator
    from lti_motion.app.monitor_setup import monitor_route

    drives = []
    for seed in (1, 2):
        sim = Simulator("create2", seed=seed, room=Room.empty(), initial_pose=(0.0, 0.0, 0.0))
        log = sim.run(monitor_route(40.0, dt_s=sim.dt_s, wheel_base_m=model.wheel_base_m,
                                    rng=np.random.default_rng(seed)))
        drives.append((log.cmd_m_s[1:], np.unwrap(log.ticks, period=65536, axis=0)))
    calls = []
    with caplog.at_level(logging.INFO, logger="fusion.monitoring.phase_one"):
        fit_nominal(model, drives, progress=lambda *a: calls.append(a))
    assert calls == [("encoder NIS", 1, 2), ("encoder NIS", 2, 2), ("dynamics null", 0, 1),
                     ("dynamics null", 1, 1)]
    assert "dynamics null fitted in" in caplog.text
