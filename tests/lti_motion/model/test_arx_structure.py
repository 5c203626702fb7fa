"""Steady-state gain of ARX fits and least squares restricted to it
(lti_motion.model.arx_structure)."""
import dataclasses

import numpy as np
import pytest
from synthetic_plant import BASE, DELAY, commands, plant

from lti_motion.exceptions import CalibrationError, ShapeError
from lti_motion.kinematics import body_from_wheel_matrix
from lti_motion.model.arx import arx_regression, estimate_arx, free_run_errors
from lti_motion.model.arx_structure import (
    dc_gain,
    nearest_servo_gain,
    output_scales,
    restrict_dc_gain,
    scale_outputs,
    servo_dc_gain,
)
from lti_motion.model.state_space import simulate_state_space

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


# --- output scales refined on the output error -------------------------------------------------

def test_scaled_outputs_are_the_scaled_simulation_with_the_same_poles(runs, free):
    s = np.array([0.97, 1.04])
    scaled = scale_outputs(free, s)
    u = runs[0][0][:800]
    ss0, ss1 = free.state_space(), scaled.state_space()
    y0 = simulate_state_space(ss0.A, ss0.B, ss0.C, ss0.D, u)[0]
    y1 = simulate_state_space(ss1.A, ss1.B, ss1.C, ss1.D, u)[0]
    np.testing.assert_allclose(y1, y0 * s, atol=1e-12)
    np.testing.assert_allclose(np.sort_complex(scaled.poles()), np.sort_complex(free.poles()),
                               atol=1e-10)
    np.testing.assert_allclose(dc_gain(scaled), np.diag(s) @ dc_gain(free), atol=1e-12)
    np.testing.assert_allclose(scaled.residual_cov, free.residual_cov * np.outer(s, s))
    # the information matrix is that of the scaled regressors (one lag of y scaled by s)
    phi, _ = arx_regression([(u, y0)], na=free.na, nb=free.nb, delay=free.delay)
    phi1, _ = arx_regression([(u, y0 * s)], na=free.na, nb=free.nb, delay=free.delay)
    t = np.concatenate([np.ones(2 * free.nb), np.tile(s, free.na)])
    np.testing.assert_allclose(phi1, phi * t, atol=1e-12)
    np.testing.assert_allclose(np.linalg.inv(scale_outputs(free, s).information_inv)[:4, :4],
                               (np.linalg.inv(free.information_inv) * np.outer(t, t))[:4, :4],
                               rtol=1e-8)


def test_output_scales_move_a_noise_biased_gain_towards_the_plants():
    # white output noise biases least-squares ARX (an equation-error fit, Ljung 1999,
    # section 7.3): its gain is 3-4% off here; the output-error scales bring it within 2%,
    # from a start further off still (3% high on v, 2% low on w)
    truth = body_from_wheel_matrix(BASE) @ np.diag([1.0, 0.95])
    rng = np.random.default_rng(11)
    u = commands(rng, 8000)
    y = plant(u, rng)
    fit = estimate_arx([(u, y)], na=ORDER, delay=DELAY)
    ls_error = np.abs(dc_gain(fit) / truth - 1).max()
    wrong = scale_outputs(fit, [1.03, 0.98])
    s = output_scales(wrong, [(u, y)], warmup=ORDER + DELAY, horizons=(1, 67, 200, 667))
    error = np.abs(dc_gain(scale_outputs(wrong, s)) / truth - 1).max()
    assert ls_error > 0.03
    assert error < 0.02 and error < ls_error / 2


def test_output_scales_minimise_the_prefiltered_criterion(runs, free):
    rng = np.random.default_rng(5)
    u = commands(rng, 5000)
    y = plant(u, rng)
    horizons, warm = (1, 67, 667), ORDER + DELAY
    s = output_scales(free, [(u, y)], warmup=warm, horizons=horizons)
    e0 = free_run_errors(free.state_space(), [(u, y)], warmup=warm)[0]
    yy, ys = y[warm:], y[warm:] - e0

    def cost(scales):
        total = np.zeros(2)
        for h in horizons:
            k = np.ones(h)
            f = [np.column_stack([np.convolve(x[:, i], k, "valid") for i in range(2)])
                 for x in (yy, ys, e0)]
            total += np.sum((f[0] - scales * f[1]) ** 2, axis=0) / (len(f[2])
                                                                    * np.mean(f[2] ** 2, axis=0))
        return total

    best = cost(s)
    for ds in (1e-3, -1e-3):
        assert np.all(cost(s + ds) > best)


def test_output_scales_refuse_runs_shorter_than_the_warm_up(free):
    u = np.zeros((5, 2))
    with pytest.raises(CalibrationError, match="no run is longer than the 8-sample warm-up"):
        output_scales(free, [(u, u)], warmup=8, horizons=(1,))


def test_scale_outputs_refuses_bad_scales(free):
    with pytest.raises(ValueError, match="scales must be two positive numbers"):
        scale_outputs(free, [1.0, -1.0])


def test_fit_arx_with_output_scales_keeps_the_servo_structure():
    from lti_motion.model.motion_model import fit_arx
    rng = np.random.default_rng(12)
    u = commands(rng, 8000)
    y = plant(u, rng)
    m = fit_arx([(u, y)], dt_s=0.015, wheel_base_m=BASE, orders=[2], delays=[DELAY],
                dc_gain="wheel_servo", output_scale_horizons_s=(1.0, 3.0, 10.0))
    d = m.diagnostics
    assert abs(d["output_scale_v"] - 1.0) < 0.05 and abs(d["output_scale_w"] - 1.0) < 0.05
    g = m.D + m.C @ np.linalg.solve(np.eye(len(m.A)) - m.A, m.B)
    # straight commands (L = R) give no steady yaw rate; the gain is diag(s) c M
    assert abs(g[1] @ [1.0, 1.0]) < 1e-10
    s = np.array([d["output_scale_v"], d["output_scale_w"]])
    np.testing.assert_allclose(g, np.diag(s) @ body_from_wheel_matrix(BASE) * d["dc_gain_scale"],
                               atol=1e-9)
