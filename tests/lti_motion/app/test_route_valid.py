"""The route's estimators honour ``valid``: a lost frame's counts are never read, the next
valid frame's counts span the gap (docs/architecture.md, The flow of one frame)."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.ekf.model_ekf import ModelEKF
from lti_motion.app.route import ArxHybrid, EkfEstimator, Odometry
from lti_motion.kinematics import body_from_wheel_matrix
from lti_motion.model.arx import estimate_arx
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.frames import SensorFrame

DT_S, B_M, M_PER_TICK, N = 0.015, 0.235, 1e-4, 200
WHEEL_M_S = np.array([0.18, 0.22])


@pytest.fixture(scope="module")
def model():
    """A first-order ARX model of a wheel servo, fitted on seeded synthetic data."""
    rng = np.random.default_rng(3)
    u = np.repeat(rng.normal(0.0, 0.2, (300, 2)), 20, axis=0)
    m = body_from_wheel_matrix(B_M)
    y = np.zeros_like(u)
    for k in range(1, len(u)):
        y[k] = 0.8 * y[k - 1] + 0.2 * m @ u[k - 1] + rng.normal(0.0, 1e-3, 2)
    fit = estimate_arx([(u, y)], na=1, nb=1, delay=1)
    return MotionModel.from_arx(fit, dt_s=DT_S, wheel_base_m=B_M, m_per_tick=M_PER_TICK)


def _frames(*, lost: slice, flag: bool):
    """Two robots driving the same arc; robot 1's frames ``lost`` hold garbage counts,
    marked invalid when ``flag``."""
    k = np.arange(N)[:, None, None]
    ticks = np.round(k * WHEEL_M_S * DT_S / M_PER_TICK).astype(np.int64).repeat(2, axis=1)
    ticks[lost, 1] = [[12345, 3000], [30000, 45000], [5000, 9000]]     # garbled counts
    valid = np.ones((N, 2), bool)
    valid[lost, 1] = not flag
    return [SensorFrame(t_s=i * DT_S, ticks=ticks[i] % 65536, light_bump=np.zeros((2, 6)),
                        bumps=np.zeros((2, 2), bool), cmd_m_s=np.tile(WHEEL_M_S, (2, 1)),
                        valid=valid[i]) for i in range(N)]


def _final(estimator, frames):
    estimator.reset(2, np.zeros((2, 3)))
    for f in frames:
        pose = estimator.step(f, f.cmd_m_s)
    return np.array(pose)


@pytest.mark.parametrize("make", [
    lambda m: Odometry(m_per_tick=M_PER_TICK, wheel_base_m=B_M),
    ArxHybrid,
], ids=["odometry", "arx_hybrid"])
def test_lost_frames_are_skipped_not_read(model, make):
    honoured = _final(make(model), _frames(lost=slice(60, 63), flag=True))
    np.testing.assert_allclose(honoured[1], honoured[0], atol=2e-3)
    # the same garbage counts, not flagged, do move the estimate: the test can fail
    misread = _final(make(model), _frames(lost=slice(60, 63), flag=False))
    assert np.max(np.abs(misread[1] - misread[0])) > 0.05


def test_the_ekf_never_fuses_a_lost_frame(model, monkeypatch):
    fused = []
    original = ModelEKF.update_encoders

    def spy(self, ticks, **kw):
        fused.append(np.array(ticks))
        return original(self, ticks, **kw)

    monkeypatch.setattr(ModelEKF, "update_encoders", spy)
    honoured = _final(EkfEstimator(model), _frames(lost=slice(60, 63), flag=True))
    np.testing.assert_allclose(honoured[1], honoured[0], atol=2e-3)
    assert len(fused) == 2 * (N - 1) - 3
    assert not any(np.array_equal(t, [12345, 3000]) for t in fused)
    fused.clear()
    _final(EkfEstimator(model), _frames(lost=slice(60, 63), flag=False))
    assert any(np.array_equal(t, [12345, 3000]) for t in fused)
