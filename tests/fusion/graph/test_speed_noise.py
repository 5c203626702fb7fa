"""Speed-error covariances for preintegration (fusion.graph.speed_noise), per-sample ones."""

import numpy as np
import pytest

from fusion.graph.preintegration import preintegrate, preintegrate_model
from fusion.graph.speed_noise import (
    filtered_speeds,
    long_run_contributions,
    long_run_covariance,
    model_speed_errors,
    slip_covariance,
    speed_covariance_from_data,
)
from lti_motion.exceptions import ShapeError
from lti_motion.model.fir import FirFit
from lti_motion.model.motion_model import MotionModel


def _ar1(rng, n, a, cov):
    w = rng.multivariate_normal(np.zeros(2), cov, size=n)
    x = np.zeros_like(w)
    for k in range(1, n):
        x[k] = a * x[k - 1] + w[k]
    return x


def test_long_run_covariance_of_white_noise_is_its_covariance(rng):
    cov = np.array([[2.0, 0.5], [0.5, 1.0]])
    e = rng.multivariate_normal(np.zeros(2), cov, size=100_000)
    # the estimator's relative spread is about sqrt(4 L / (3 n)) = 1.6% (Newey & West 1987)
    np.testing.assert_allclose(long_run_covariance(e, bandwidth=20), cov, atol=0.1)


def test_long_run_covariance_of_an_ar1_matches_its_spectral_density_at_zero(rng):
    """AR(1) x' = a x + w: Phi = cov(w) / (1 - a)^2 (Brockwell & Davis 1991, eq. 7.1.4)."""
    a, cov = 0.8, np.diag([1.0, 0.25])
    runs = [_ar1(rng, 20_000, a, cov) for _ in range(5)]
    phi = long_run_covariance(runs, bandwidth=400)
    np.testing.assert_allclose(np.diag(phi), np.diag(cov) / (1 - a) ** 2, rtol=0.1)
    # the plain second moment (bandwidth 0) is the stationary variance, far smaller
    np.testing.assert_allclose(np.diag(long_run_covariance(runs, bandwidth=0)),
                               np.diag(cov) / (1 - a * a), rtol=0.05)


def test_long_run_covariance_is_the_covariance_of_interval_sums(rng):
    """Bartlett with bandwidth L = overlapping batch means of L + 1 samples (Flegal & Jones)."""
    e = _ar1(rng, 30_000, 0.6, np.eye(2))
    lag = 49
    sums = np.lib.stride_tricks.sliding_window_view(e, lag + 1, axis=0).sum(axis=-1)
    obm = sums.T @ sums / len(sums) / (lag + 1)
    np.testing.assert_allclose(long_run_covariance(e, bandwidth=lag), obm, rtol=0.03, atol=0.03)


def test_long_run_covariance_refuses_bad_input():
    with pytest.raises(ShapeError, match=r"\(n, d\)"):
        long_run_covariance(np.zeros(10), bandwidth=2)
    with pytest.raises(ValueError, match="bandwidth"):
        long_run_covariance(np.zeros((10, 2)), bandwidth=-1)


@pytest.fixture
def static_model():
    """A static gain with white noise (no state): y = (v, w) of the commands + e."""
    taps = np.stack([[[0.5, 0.5], [-4.0, 4.0]]])
    return MotionModel.from_fir(FirFit(taps=taps, residual_cov=np.diag([1e-4, 4e-4]),
                                       n_samples=100, source="steps"), dt_s=0.015,
                                wheel_base_m=0.25, calibrated_at="2026-01-01T00:00:00+00:00")


def test_speed_covariance_from_data_measures_the_model_errors(static_model, rng):
    u = rng.uniform(-0.3, 0.3, (20_000, 2))
    y = static_model.simulate(u) + rng.multivariate_normal(np.zeros(2), np.diag([1e-4, 4e-4]),
                                                           size=len(u))
    err = model_speed_errors(static_model, [(u, y)])[0]
    np.testing.assert_allclose(err, y - static_model.simulate(u))
    phi = speed_covariance_from_data(static_model, [(u, y)], bandwidth_s=0.5)
    np.testing.assert_allclose(np.diag(phi), [1e-4, 4e-4], rtol=0.1)
    with pytest.raises(ValueError, match="mode"):
        model_speed_errors(static_model, [(u, y)], mode="magic")


def test_filtered_speeds_follow_the_encoders_with_slip_covariance(static_model, rng):
    u = rng.uniform(-0.3, 0.3, (500, 2))
    y = static_model.simulate(u) + 0.01 * rng.standard_normal((500, 2))
    post, cov = filtered_speeds(static_model, u, y)
    # R (1e-4, 4e-4) against an encoder noise of (1e-5, 1e-4) std: the posterior is the reading
    np.testing.assert_allclose(post, y, atol=1e-4)
    assert cov.shape == (500, 2, 2)
    np.testing.assert_allclose(cov - slip_covariance(post), np.broadcast_to(
        cov[0] - slip_covariance(post[:1])[0], cov.shape), atol=1e-15)
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_per_sample_speed_covariance_equals_a_constant_one(rng):
    speeds = np.column_stack([0.2 + 0.02 * rng.standard_normal(300), rng.standard_normal(300)])
    phi = np.array([[1e-4, 2e-5], [2e-5, 3e-3]])
    a = preintegrate(speeds, 0.015, keyframes=[0, 100, 300], speed_covariance=phi)
    b = preintegrate(speeds, 0.015, keyframes=[0, 100, 300],
                     speed_covariance=np.broadcast_to(phi, (300, 2, 2)))
    np.testing.assert_allclose(a.covariance, b.covariance, rtol=1e-12)
    with pytest.raises(ShapeError, match=r"\(300, 2, 2\)"):
        preintegrate(speeds, 0.015, keyframes=[0, 300], speed_covariance=np.zeros((3, 2, 2)))


def test_filtered_mode_needs_encoders(static_model):
    with pytest.raises(ValueError, match="measured_speeds"):
        preintegrate_model(static_model, np.zeros((10, 2)), keyframes=[0, 10], mode="filtered")


@pytest.mark.parametrize("n, lag", [(500, 0), (500, 7), (100, 300), (1, 3)])
def test_long_run_contributions_average_to_the_long_run_covariance(rng, n, lag):
    """Each lagged product of Newey-West split between its two samples (no edge loss)."""
    e = np.cumsum(rng.standard_normal((n, 2)), axis=0) * 0.1      # correlated errors
    h = long_run_contributions(e, bandwidth=lag)
    assert h.shape == (n, 2, 2)
    np.testing.assert_allclose(h, np.swapaxes(h, 1, 2))
    np.testing.assert_allclose(h.mean(axis=0), long_run_covariance(e, bandwidth=lag),
                               rtol=1e-10, atol=1e-14)
    with pytest.raises(ValueError, match="bandwidth"):
        long_run_contributions(e, bandwidth=-1)
