"""The dynamics tests' window integrator honours a model's affine speed offset."""

import numpy as np

from fusion.monitoring.dynamics_null import integrated_residuals
from lti_motion.kinematics import wheel_from_body_matrix
from lti_motion.model.arx import estimate_arx
from lti_motion.model.motion_model import MotionModel

DT, B, M_PER_TICK = 0.015, 0.235, 4.5e-4
OFFSET = np.array([0.01, -0.05])


def _model():
    rng = np.random.default_rng(3)
    u = np.repeat(rng.normal(0.2, 0.1, size=(100, 2)), 30, axis=0)
    y = np.zeros((len(u), 2))
    g = np.array([[0.5, 0.5], [-1.0 / B, 1.0 / B]])
    for k in range(1, len(u)):
        y[k] = 0.7 * y[k - 1] + 0.3 * g @ u[k - 1] + rng.normal(0, [1e-3, 1e-2])
    fit = estimate_arx([(u, y)], na=1, delay=1)
    return MotionModel.from_arx(fit, dt_s=DT, wheel_base_m=B, m_per_tick=M_PER_TICK,
                                calibrated_at="2026-12-01T00:00:00+00:00"), u


def _ticks(y):
    return y @ (DT / M_PER_TICK * wheel_from_body_matrix(B)).T


def test_a_shifted_model_on_shifted_data_gives_the_unshifted_residuals():
    model, u = _model()
    rng = np.random.default_rng(4)
    y = model.simulate(u) + rng.normal(0, [2e-3, 2e-2], size=u.shape)
    shifted = model.updated(offset_speeds=OFFSET)
    plain = integrated_residuals(model, u, _ticks(y))
    both = integrated_residuals(shifted, u, _ticks(y + OFFSET))
    np.testing.assert_allclose(both.residual_ticks, plain.residual_ticks, atol=1e-8)
    np.testing.assert_allclose(both.predicted_ticks, plain.predicted_ticks + _ticks(OFFSET) * 30,
                               atol=1e-8)
    ignored = integrated_residuals(model, u, _ticks(y + OFFSET))       # the offset unmodelled
    assert np.abs(ignored.residual_ticks - plain.residual_ticks).max() > 1.0   # ticks
