"""The synthetic speed response the model-EKF tests fit their model to (so the filter's
model is exact): a second-order ARX response (v, w) with unit steady-state gains and white
noise, driven by held forward wheel commands."""

import numpy as np

from lti_motion.model.arx import estimate_arx
from lti_motion.model.motion_model import MotionModel

DT, B = 0.015, 0.235
M_PER_TICK = 2e-5    # fine counts: quantisation far below the synthetic model's noise
R_TRUE = np.diag([1e-4, 6e-3])


def held_commands(rng, n, *, mean=0.2, std=0.08):
    """Positive wheel commands held 0.3-1 s (forward driving, as the routes)."""
    out, k = np.empty((n, 2)), 0
    while k < n:
        hold = int(rng.integers(20, 67))
        out[k:k + hold] = np.clip(mean + std * rng.standard_normal(2), 0.02, 0.45)
        k += hold
    return out


def arx_data(rng, n):
    """A second-order speed response (v, w) with unit steady-state gains, plus white noise."""
    a1, a2 = np.diag([0.9, 0.85]), np.diag([-0.2, -0.15])
    g = np.array([[0.5, 0.5], [-1.0 / B, 1.0 / B]])
    b0 = g * np.array([[0.3], [0.3]])
    u = held_commands(rng, n)
    y = np.zeros((n, 2))
    e = rng.multivariate_normal(np.zeros(2), R_TRUE, n)
    for k in range(2, n):
        y[k] = a1 @ y[k - 1] + a2 @ y[k - 2] + b0 @ u[k - 1] + e[k]
    return u, y


def fitted_model() -> MotionModel:
    """A fitted ARX model, q_scale 1.3 (so Q > K R K^T), D = 0, K != 0, nz = 4."""
    u, y = arx_data(np.random.default_rng(1), 6000)
    fit = estimate_arx([(u, y)], na=2, nb=1, delay=1)
    return MotionModel.from_arx(fit, dt_s=DT, wheel_base_m=B, m_per_tick=M_PER_TICK,
                                q_scale=1.3, calibrated_at="2026-01-01T00:00:00+00:00")


def numerical_jacobian(f, x, eps=1e-6):
    """Central differences of ``f`` at ``x``, one column per state (the check every analytic
    Jacobian of the filters gets)."""
    cols = [(f(x + eps * e) - f(x - eps * e)) / (2 * eps) for e in np.eye(len(x))]
    return np.stack(cols, axis=1)
