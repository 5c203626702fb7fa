"""The route's smoother with the curvature kappa: it learns a diameter ratio from landmarks
(docs/intrinsics.md, "Online, in the smoother") and hands it over as the EKF does."""

import numpy as np
import pytest

from drivers.sim.calibration import calibrate_simulator
from drivers.sim.config import get_preset
from fusion.graph.smoother import SmootherOptions
from lti_motion.app.route import ROUTE_LANDMARKS, drive_route
from lti_motion.app.route_smoother import ROUTE_SMOOTHER_OPTIONS, SmootherEstimator
from lti_motion.calibration.manoeuvres import CalibrationPlan
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.recordings.frames import SensorFrame

#: Issue 17's robot: left wheel 1% larger, right motor 10% weaker (benchmarks/bench_intrinsics)
ASYMMETRIC = get_preset("create2", wheel_diameter_errors=(0.01, 0.0), motor_balance=0.90)


@pytest.fixture(scope="module")
def model():
    return calibrate_simulator(ASYMMETRIC, seed=0, floor="tile",
                               plan=CalibrationPlan(seed=2, excitation_s=60.0)).arx


def test_the_smoother_learns_the_diameter_ratio_on_the_route(model):
    """Truth: 1.0097-1.0098 over a straight-line drive on tile (docs/intrinsics.md); the
    benchmark's 30 seeds end within 0.10% of it. Without kappa the ratio stays 1."""
    opts = ROUTE_SMOOTHER_OPTIONS.with_curvature(wheel_base_m=model.wheel_base_m)
    est = SmootherEstimator(model, landmarks=ROUTE_LANDMARKS, options=opts)
    res = drive_route(ASYMMETRIC, est, seeds=[3, 4], floor="tile", landmarks=ROUTE_LANDMARKS)
    assert res.finished.all()
    learned = est.intrinsics_estimates()
    for e in learned:
        assert e.intrinsics.diameter_ratio == pytest.approx(1.0097, abs=0.002)
        assert 1e-4 < e.diameter_ratio_std < 2e-3
        assert abs(e.scale_errors[2]) < opts.curvature_bound_rad_per_m
    plain = SmootherEstimator(model, landmarks=ROUTE_LANDMARKS)
    drive_route(ASYMMETRIC, plain, seeds=[3], floor="tile", landmarks=ROUTE_LANDMARKS, max_s=5.0)
    assert plain.intrinsics_estimates()[0].intrinsics.diameter_ratio == pytest.approx(
        1.0, abs=1e-12)
    # the write-back: a model with the learned intrinsics maps counts through them
    written = model.with_intrinsics(learned[0].intrinsics)
    assert written.intrinsics.diameter_ratio == pytest.approx(
        learned[0].intrinsics.diameter_ratio)


def _drive(model, options=None):
    est = SmootherEstimator(model, keyframe_s=0.06, options=options)
    est.reset(1, np.zeros((1, 3)))
    for k in range(11):
        frame = SensorFrame(t_s=0.015 * k, ticks=np.array([[3 * k, 4 * k]]),
                            light_bump=np.zeros((1, 6), int), bumps=np.zeros((1, 2), bool),
                            cmd_m_s=np.full((1, 2), 0.2))
        pose = est.step(frame, np.full((1, 2), 0.2))
    return pose, est


def test_a_model_with_intrinsics_is_read_through_them(model):
    symmetric = OdometryIntrinsics.symmetric(m_per_tick=model.m_per_tick,
                                             wheel_base_m=model.wheel_base_m)
    plain, _ = _drive(model)
    same, _ = _drive(model.updated(intrinsics=symmetric))
    np.testing.assert_allclose(same, plain, atol=1e-12)
    skew, _ = _drive(model.updated(intrinsics=OdometryIntrinsics(
        1.02 * model.m_per_tick, model.m_per_tick, model.wheel_base_m)))
    assert np.abs(skew - plain).max() > 1e-4


def test_intrinsics_estimates_need_a_started_calibrating_smoother(model):
    est = SmootherEstimator(model)
    with pytest.raises(RuntimeError, match="reset"):
        est.intrinsics_estimates()
    _, est = _drive(model, SmootherOptions(calibrate=False))
    with pytest.raises(ValueError, match="calibrate=False"):
        est.intrinsics_estimates()
