"""Steady-state gain of ARX fits and least squares restricted to it (lti_motion.arx_structure)."""
import dataclasses

import numpy as np
import pytest
from synthetic_plant import BASE, DELAY, commands, plant

from lti_motion.arx import arx_regression, estimate_arx
from lti_motion.arx_structure import (
    dc_gain,
    nearest_servo_gain,
    restrict_dc_gain,
    servo_dc_gain,
)
from lti_motion.exceptions import ShapeError
from lti_motion.kinematics import body_from_wheel_matrix

ORDER = 2


@pytest.fixture(scope="module")
def runs():
    rng = np.random.default_rng(3)
    u = commands(rng, 6000)
    return [(u, plant(u) + 1e-4 * rng.normal(size=u.shape))]


@pytest.fixture(scope="module")
def free(runs):
    return estimate_arx(runs, na=ORDER, delay=DELAY)


def _rss(fit, runs):
    phi, y = arx_regression(runs, na=fit.na, nb=fit.nb, delay=fit.delay)
    e = y - phi @ fit.theta
    return e.T @ e


def test_free_fit_finds_the_plants_gain(free):
    # wheel gains 1.0 (left) and 0.95 (right): G = M diag(1, 0.95)
    truth = body_from_wheel_matrix(BASE) @ np.diag([1.0, 0.95])
    np.testing.assert_allclose(dc_gain(free), truth, atol=0.01)


def test_restricted_fit_has_the_required_gain_and_is_least_squares_under_it(runs, free):
    truth = body_from_wheel_matrix(BASE) @ np.diag([1.0, 0.95])
    fit = restrict_dc_gain(free, truth)
    np.testing.assert_allclose(dc_gain(fit), truth, atol=1e-10)
    rss_free, rss_r = _rss(free, runs), _rss(fit, runs)
    assert np.all(np.diag(rss_r) >= np.diag(rss_free))
    # the stated RSS growth (Greene eq. 5-26) matches the regression's
    dof = free.n_rows - free.rank + 2
    np.testing.assert_allclose(np.diag(fit.residual_cov) * dof,
                               np.diag(free.residual_cov) * dof + np.diag(rss_r - rss_free),
                               rtol=1e-3)
    # any other parameters with the same gain fit worse: step along the restriction's null space
    c = np.concatenate([np.tile(np.eye(2), fit.nb), np.tile(truth.T, fit.na)], axis=1)
    null = np.linalg.svd(c)[2][2:].T
    rng = np.random.default_rng(0)
    for _ in range(5):
        step = null @ rng.normal(size=(null.shape[1], 2)) * 1e-3
        theta = fit.theta + step
        nb = fit.nb
        moved = dataclasses.replace(
            fit, b=theta[: 2 * nb].reshape(nb, 2, 2).transpose(0, 2, 1),
            a=theta[2 * nb:].reshape(fit.na, 2, 2).transpose(0, 2, 1))
        np.testing.assert_allclose(dc_gain(moved), truth, atol=1e-9)
        assert np.trace(_rss(moved, runs)) > np.trace(rss_r)
    eig = np.linalg.eigvalsh(fit.information_inv)
    assert eig.min() > -1e-9 * eig.max()


def test_servo_gain_is_one_scale_times_the_wheel_matrix(free):
    gain, c = servo_dc_gain(free, wheel_base_m=BASE)
    assert c == pytest.approx(0.975, abs=1e-3)    # mean of the wheel gains 1.0 and 0.95
    np.testing.assert_allclose(gain, c * body_from_wheel_matrix(BASE))
    # straight-line yaw rate per m/s of forward command is zero
    assert abs(gain[1].sum()) < 1e-12


def test_nearest_servo_gain_is_the_least_squares_projection_in_wheel_coordinates(rng, free):
    g = body_from_wheel_matrix(BASE) @ rng.normal(1.0, 0.05, size=(2, 2))
    gain, c = nearest_servo_gain(g, wheel_base_m=BASE)
    m = body_from_wheel_matrix(BASE)
    np.testing.assert_allclose(gain, c * m, rtol=0, atol=1e-15)
    wheel = np.linalg.solve(m, g)
    assert c == pytest.approx(np.trace(wheel) / 2, rel=1e-12)
    for other in c + np.array([-1e-3, -1e-6, 1e-6, 1e-3]):   # any other scale is farther
        assert np.linalg.norm(wheel - other * np.eye(2)) > np.linalg.norm(wheel - c * np.eye(2))
    # the ARX form is the same function of the fit's DC gain
    np.testing.assert_allclose(servo_dc_gain(free, wheel_base_m=BASE)[0],
                               nearest_servo_gain(dc_gain(free), wheel_base_m=BASE)[0])


def test_bad_gain_shape_and_wheel_base(free):
    with pytest.raises(ShapeError, match=r"got \(2, 3\)"):
        nearest_servo_gain(np.ones((2, 3)), wheel_base_m=BASE)
    with pytest.raises(ValueError, match="wheel_base_m"):
        nearest_servo_gain(np.eye(2), wheel_base_m=float("nan"))
    with pytest.raises(ShapeError, match=r"\(2, 2\)"):
        restrict_dc_gain(free, np.eye(3))
    with pytest.raises(ValueError, match="wheel_base_m"):
        body_from_wheel_matrix(0.0)
