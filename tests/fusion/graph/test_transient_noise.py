"""The speed covariance conditioned on the model's transients (fusion.graph.transient_noise)."""

import numpy as np
import pytest

from fusion.exceptions import FusionError
from fusion.graph.preintegration import FILTERED_SLIP_DENSITY, preintegrate, preintegrate_model
from fusion.graph.speed_noise import long_run_covariance, model_speed_errors, slip_covariance
from fusion.graph.transient_noise import (
    TransientSpeedCovariance,
    mean_squared_tracking_error,
    transient_speed_covariance_from_data,
)
from fusion.noise import SlipNoise
from lti_motion.exceptions import NonFiniteError, ShapeError
from lti_motion.model.fir import FirFit
from lti_motion.model.motion_model import MotionModel

DT = 0.015
WHEEL_BASE_M = 0.25
#: Wheels to body speeds of a differential drive: v = (L + R) / 2, w = (R - L) / b.
WHEELS_TO_BODY = np.array([[0.5, 0.5], [-1.0 / WHEEL_BASE_M, 1.0 / WHEEL_BASE_M]])


@pytest.fixture
def lagging_model():
    """An FIR that reaches the commanded wheel speeds in three samples (a transient)."""
    taps = np.stack([c * WHEELS_TO_BODY for c in (0.2, 0.3, 0.5)])
    return MotionModel.from_fir(FirFit(taps=taps, residual_cov=np.diag([1e-4, 4e-4]),
                                       n_samples=100, source="steps"), dt_s=DT,
                                wheel_base_m=WHEEL_BASE_M,
                                calibrated_at="2026-01-01T00:00:00+00:00")


def _held_commands(rng, n, hold):
    levels = rng.uniform(-0.3, 0.3, (n // hold + 1, 2))
    return np.repeat(levels, hold, axis=0)[:n]


def test_tracking_error_is_zero_when_the_prediction_holds_the_commands():
    """Straight line and constant-turn arc: predicted wheels equal the commands."""
    body = np.array([[0.2, 0.0], [0.15, 0.8], [0.0, -1.2]])
    for v, w in body:
        speeds = np.tile([v, w], (40, 1))
        u = speeds @ np.linalg.inv(WHEELS_TO_BODY).T           # wheels for (v, w)
        f = mean_squared_tracking_error(u, speeds, wheel_base_m=WHEEL_BASE_M, window=10)
        np.testing.assert_allclose(f, 0.0, atol=1e-28)


def test_tracking_error_is_the_causal_window_mean_of_the_squared_distance():
    u = np.zeros((6, 2))
    u[2:] = [0.3, -0.1]                                          # a step at sample 2
    f = mean_squared_tracking_error(u, np.zeros((6, 2)), wheel_base_m=WHEEL_BASE_M, window=3)
    d2 = 0.3 ** 2 + 0.1 ** 2
    np.testing.assert_allclose(f, [0, 0, d2 / 3, 2 * d2 / 3, d2, d2], rtol=1e-12)


def test_fit_recovers_a_known_variance_function(lagging_model, rng):
    """White errors with variance a + b f: the fit returns a and b (and is mean-preserving)."""
    u = _held_commands(rng, 200_000, hold=20)
    y_hat = lagging_model.simulate(u)
    f = mean_squared_tracking_error(u, y_hat, wheel_base_m=WHEEL_BASE_M, window=10)
    a, b = np.array([1e-4, 4e-3]), np.array([0.05, 2.0])
    y = y_hat + np.sqrt(a + f[:, None] * b) * rng.standard_normal(u.shape)
    cov = transient_speed_covariance_from_data(lagging_model, [(u, y)], bandwidth_s=DT,
                                               window_s=10 * DT)
    # spread over generator seeds 1-3 and this one: base within 4%, slope within 2%
    np.testing.assert_allclose(np.diag(cov.base), a, rtol=0.08)
    np.testing.assert_allclose(np.diag(cov.per_squared_tracking), b, rtol=0.05)
    # least squares with an intercept: the mean is the unconditional Newey-West estimate
    errors = model_speed_errors(lagging_model, [(u, y)])
    np.testing.assert_allclose(cov.mean, long_run_covariance(errors, bandwidth=1), rtol=1e-9)


def test_without_transients_the_fit_is_the_unconditional_covariance(rng):
    """A static gain reaches every command at once: f = 0, so Phi_1 = 0."""
    taps = np.stack([WHEELS_TO_BODY])
    model = MotionModel.from_fir(FirFit(taps=taps, residual_cov=np.eye(2) * 1e-4,
                                        n_samples=100, source="steps"), dt_s=DT,
                                 wheel_base_m=WHEEL_BASE_M,
                                 calibrated_at="2026-01-01T00:00:00+00:00")
    u = _held_commands(rng, 5000, hold=20)
    y = model.simulate(u) + 0.01 * rng.standard_normal(u.shape)
    cov = transient_speed_covariance_from_data(model, [(u, y)], bandwidth_s=0.3)
    np.testing.assert_allclose(cov.per_squared_tracking, 0.0, atol=1e-12)
    errors = model_speed_errors(model, [(u, y)])
    np.testing.assert_allclose(cov.base, long_run_covariance(errors, bandwidth=20), rtol=1e-9)


def test_per_sample_covariance_adds_the_slip_and_stays_positive_definite(lagging_model, rng):
    u = _held_commands(rng, 400, hold=30)
    speeds = lagging_model.simulate(u)
    cov = TransientSpeedCovariance(base=[[1e-4, 1e-5], [1e-5, 4e-3]],
                                   per_squared_tracking=[[0.05, 0.01], [0.01, 2.0]])
    no_slip = TransientSpeedCovariance(base=cov.base, per_squared_tracking=cov.per_squared_tracking,
                                       slip=None)
    kw = {"wheel_base_m": WHEEL_BASE_M, "dt_s": DT}
    added = cov.per_sample(u, speeds, **kw) - no_slip.per_sample(u, speeds, **kw)
    np.testing.assert_allclose(added, slip_covariance(speeds, slip=SlipNoise()), atol=1e-18)
    phi = cov.per_sample(u, speeds, **kw)
    np.testing.assert_allclose(phi, np.swapaxes(phi, 1, 2))
    assert np.linalg.eigvalsh(phi).min() > 0
    # larger right after each command step than where the wheels hold the commands
    f = mean_squared_tracking_error(u, speeds, wheel_base_m=WHEEL_BASE_M, window=10)
    assert phi[f > 0.01, 1, 1].min() > phi[f == 0, 1, 1].max()


def test_preintegrate_model_evaluates_the_transient_covariance_per_sample(lagging_model, rng):
    """The adapter equals preintegrating with the explicit per-sample covariance."""
    u = _held_commands(rng, 300, hold=25)
    cov = TransientSpeedCovariance(base=np.diag([1e-4, 4e-3]), per_squared_tracking=np.diag(
        [0.05, 2.0]))
    pre = preintegrate_model(lagging_model, u, keyframes=[0, 100, 300], speed_covariance=cov)
    speeds = lagging_model.simulate(u)
    ref = preintegrate(speeds, DT, keyframes=[0, 100, 300],
                       speed_covariance=cov.per_sample(u, speeds, wheel_base_m=WHEEL_BASE_M,
                                                       dt_s=DT),
                       slip_density=FILTERED_SLIP_DENSITY)
    np.testing.assert_allclose(pre.covariance, ref.covariance, rtol=1e-12)
    np.testing.assert_allclose(pre.delta_pose, ref.delta_pose, rtol=1e-12)


@pytest.mark.parametrize("kwargs, error, match", [
    ({"base": np.eye(3)}, ShapeError, r"base must have shape \(2, 2\)"),
    ({"base": np.diag([1e-4, -1e-3])}, ValueError, "positive definite"),
    ({"per_squared_tracking": np.diag([1.0, -1.0])}, ValueError, "semi-definite"),
    ({"per_squared_tracking": np.diag([np.nan, 1.0])}, NonFiniteError, "NaN"),
    ({"window_s": 0.0}, ValueError, "window_s"),
])
def test_bad_transient_covariances_are_refused(kwargs, error, match):
    args = {"base": np.diag([1e-4, 4e-3]), "per_squared_tracking": np.diag([0.05, 2.0]),
            **kwargs}
    with pytest.raises(error, match=match):
        TransientSpeedCovariance(**args)


def test_bad_fit_input_is_refused(lagging_model):
    u = np.zeros((100, 2))
    with pytest.raises(ShapeError, match=r"\(n, 2\)"):
        transient_speed_covariance_from_data(lagging_model, [(u, np.zeros((99, 2)))])
    with pytest.raises(ValueError, match="bandwidth_s"):
        transient_speed_covariance_from_data(lagging_model, [(u, u)], bandwidth_s=0.0)
    with pytest.raises(ValueError, match="not positive definite"):      # errors all zero
        transient_speed_covariance_from_data(lagging_model, [(u, lagging_model.simulate(u))])
    with pytest.raises(FusionError, match="same shape"):
        mean_squared_tracking_error(u, np.zeros((100, 3)), wheel_base_m=0.25, window=3)
