"""Tests of lti_motion.model.arx on a known synthetic plant (no simulator needed).

The plant: each wheel's speed is a discrete second-order lag
``(b0 + b1 q^-1) / (1 + a1 q^-1 + a2 q^-2)`` (unit DC gain, poles
0.8 +- 0.15j left, 0.75 +- 0.2j right, right gain 0.95) of its command delayed
by 4 samples; ``v = (vR + vL) / 2``, ``w = (vR - vL) / 0.235``; white
measurement noise on ``v`` and ``w``. Its exact MIMO ARX form has order 2
and delay 4.
"""


import numpy as np
import pytest
from synthetic_plant import BASE, DELAY, commands, plant, wheel_filters

from lti_motion.exceptions import (
    CalibrationError,
    NonFiniteError,
    NotExcitedError,
    ShapeError,
    UnstableModelError,
)
from lti_motion.metrics import fit_percent
from lti_motion.model.arx import (
    RecursiveARX,
    arx_regression,
    arx_state_space,
    check_stable,
    estimate_arx,
    one_step_predictor,
    rls_update,
    select_arx,
)
from lti_motion.model.state_space import simulate_state_space


def true_arx():
    """The plant's exact MIMO ARX coefficients (order 2, delay 4)."""
    (bl, al), (br, ar) = wheel_filters()
    t = np.array([[0.5, 0.5], [-1 / BASE, 1 / BASE]])  # wheel -> body speeds
    a = np.array([t @ np.diag([-al[k], -ar[k]]) @ np.linalg.inv(t) for k in (1, 2)])
    b = np.array([t @ np.diag([bl[j], br[j]]) for j in (0, 1)])
    return a, b


@pytest.fixture(scope="module")
def noisy_runs():
    rng = np.random.default_rng(11)
    return [(u, plant(u, rng)) for u in (commands(rng, 4000), commands(rng, 4000))]


@pytest.fixture(scope="module")
def selection(noisy_runs):
    return select_arx(noisy_runs)


def test_regression_rows_follow_eq12_and_never_straddle_runs(rng):
    u1, u2 = commands(rng, 50), commands(rng, 30)
    y1, y2 = rng.normal(size=(50, 2)), rng.normal(size=(30, 2))
    phi, y = arx_regression([(u1, y1), (u2, y2)], na=2, nb=3, delay=1)
    start = max(2, 1 + 3 - 1)
    assert phi.shape == (50 - start + 30 - start, 2 * 3 + 2 * 2)
    n = 10  # row of sample n of run 0
    expect = np.concatenate([u1[n - 1], u1[n - 2], u1[n - 3], y1[n - 1], y1[n - 2]])
    np.testing.assert_array_equal(phi[n - start], expect)
    k = 50 - start  # first row of run 1 uses only run 1's samples
    np.testing.assert_array_equal(phi[k], np.concatenate([u2[2], u2[1], u2[0], y2[2], y2[1]]))
    np.testing.assert_array_equal(y[k], y2[start])


def test_noise_free_plant_is_recovered_exactly(rng):
    u = commands(rng, 3000)
    fit = estimate_arx([(u, plant(u))], na=2, delay=DELAY)
    a, b = true_arx()
    np.testing.assert_allclose(fit.a, a, atol=1e-8)
    np.testing.assert_allclose(fit.b, b, atol=1e-8)
    assert fit.rank == 8 and fit.residual_cov.max() < 1e-20
    assert np.max(np.abs(fit.poles())) < 0.85


def test_many_runs_equal_one_fit_on_their_rows(noisy_runs):
    both = estimate_arx(noisy_runs, na=3, delay=DELAY)
    phi, y = arx_regression(noisy_runs, na=3, nb=3, delay=DELAY)
    theta = np.linalg.lstsq(phi, y, rcond=None)[0]
    np.testing.assert_allclose(both.theta, theta, rtol=1e-9, atol=1e-11)
    resid = y - phi @ theta
    np.testing.assert_allclose(both.residual_cov, resid.T @ resid / (len(y) - 12), rtol=1e-9)
    assert both.n_rows == len(y)


def test_selection_recovers_the_delay_and_levels_off(selection):
    sel = selection
    assert sel.delay == DELAY
    assert sel.fit_percent.shape == (12, 9, 2) and sel.nrmse.shape == (12, 9)
    assert np.all(sel.validation_fit_percent >= 95.0)
    curve, best = sel.curve, sel.curve.min()
    i = int(np.flatnonzero(sel.orders == sel.order)[0])
    assert curve[i] <= best * (1 + sel.tolerance)  # within tolerance of the best ...
    assert i > 0 and curve[i - 1] > best * (1 + sel.tolerance)  # ... the first order that is
    assert sel.order < sel.orders.max()  # the curve levelled off inside the grid
    assert curve[0] > 2 * best  # order 1 cannot describe second-order wheels
    assert sel.stable[i, sel.delays.tolist().index(sel.delay)]


def test_selected_model_free_runs_on_fresh_data(selection):
    rng = np.random.default_rng(12)
    u = commands(rng, 5000)
    y = plant(u, rng)
    ss = selection.fit.state_space()
    y_free = simulate_state_space(ss.A, ss.B, ss.C, ss.D, u)[0]
    assert np.all(fit_percent(y, y_free) >= 95.0)


def test_realisation_reproduces_the_difference_equation(rng):
    a = rng.normal(size=(3, 2, 2)) * 0.2
    b = rng.normal(size=(2, 2, 2))
    ss = arx_state_space(a, b, delay=2)
    u = rng.normal(size=(60, 2))
    y = simulate_state_space(ss.A, ss.B, ss.C, ss.D, u)[0]
    for n in range(10, 60):  # eq. 1, noise-free, from rest
        expect = sum(a[k - 1] @ y[n - k] for k in (1, 2, 3)) + sum(
            b[j] @ u[n - 2 - j] for j in (0, 1))
        np.testing.assert_allclose(y[n], expect, atol=1e-12)
    # the predictor forgets its initial state: A - K C is nilpotent of index r
    pa = one_step_predictor(ss)[0]
    r = ss.A.shape[0] // 2
    assert np.abs(np.linalg.matrix_power(pa, r)).max() == 0.0


def test_unstable_fit_raises_with_pole_magnitudes(rng):
    u = commands(rng, 300)
    y = np.zeros((300, 2))
    for n in range(1, 300):
        y[n] = 1.02 * y[n - 1] + u[n - 1]
    with pytest.raises(UnstableModelError, match=r"pole magnitudes \[1\.02, 1\.02\]"):
        estimate_arx([(u, y)], na=1, delay=1)
    fit = estimate_arx([(u, y)], na=1, delay=1, require_stable=False)
    np.testing.assert_allclose(np.abs(fit.poles()), 1.02)
    check_stable(np.array([0.3, -0.99 + 0.1j]))  # |p| = 0.995 is stable


def test_bad_inputs_raise_clear_errors(rng, noisy_runs):
    u, y = noisy_runs[0]
    with pytest.raises(ShapeError, match=r"u has shape \(4000, 2\) but y has shape \(3999, 2\)"):
        estimate_arx([(u, y[:-1])], na=2)
    y_bad = y.copy()
    y_bad[123, 0] = np.nan
    with pytest.raises(NonFiniteError, match=r"y\[123, 0\] \(v\)"):
        select_arx([(u, y_bad)])
    with pytest.raises(CalibrationError, match="at least 31 samples"):  # 6 lags + 24 + 1
        estimate_arx([(u[:20], y[:20])], na=6, nb=6, delay=0)
    with pytest.raises(NotExcitedError,
                       match=r"both wheels are constant.*condition number .*Drive both wheels"):
        estimate_arx([(np.full_like(u, 0.2), y)], na=2)
    with pytest.raises(NotExcitedError, match="collinear"):
        select_arx([(np.column_stack([u[:, 0], u[:, 0]]), y)], orders=range(1, 4))
    with pytest.raises(NotExcitedError, match="wheel R is constant"):
        estimate_arx([(np.column_stack([u[:, 0], 0 * u[:, 0]]), y)], na=2)
    with pytest.raises(ValueError, match="validation"):
        select_arx(noisy_runs, validation=1.5)


def test_rls_matches_batch_with_lambda_one(noisy_runs):
    u, y = noisy_runs[0]
    na, nb, d = 3, 3, DELAY
    start = max(na, d + nb - 1)
    # leading rest: the RLS's zero history then equals the batch regression's rows
    u0 = np.vstack([np.zeros((start, 2)), u[:3000]])
    y0 = np.vstack([np.zeros((start, 2)), y[:3000]])
    batch = estimate_arx([(u0, y0)], na=na, nb=nb, delay=d)
    rls = RecursiveARX(na=na, nb=nb, delay=d, lam=1.0, p0=1e10)
    rls.update_many(u0[:1000], y0[:1000])
    for k in range(1000, 1010):  # single-sample updates use the same recursion
        rls.update(u0[k], y0[k])
    rls.update_many(u0[1010:], y0[1010:])
    np.testing.assert_allclose(rls.theta, batch.theta, rtol=0, atol=1e-6)
    np.testing.assert_allclose(rls.p, rls.p.T, rtol=0, atol=0)
    fit = rls.to_fit()  # a-priori errors include the start-up transient: a bit larger
    np.testing.assert_allclose(np.diag(fit.residual_cov), np.diag(batch.residual_cov), rtol=0.25)


def test_rls_with_forgetting_follows_a_parameter_change(rng):
    u = commands(rng, 6000)
    y = np.zeros((6000, 2))
    e = rng.normal(size=(6000, 2)) * 1e-3
    for n in range(1, 6000):
        pole = 0.5 if n < 3000 else 0.8  # the plant changes half-way
        y[n] = pole * y[n - 1] + 0.3 * u[n - 1] + e[n]
    forget, keep = (RecursiveARX(na=1, nb=1, delay=1, lam=lam) for lam in (0.99, 1.0))
    for rls in (forget, keep):
        rls.update_many(u, y)
    np.testing.assert_allclose(np.diag(forget.to_fit().a[0]), 0.8, atol=0.01)
    assert np.all(np.abs(np.diag(keep.to_fit().a[0]) - 0.8) > 0.05)
    theta, p = rls_update(forget.theta, forget.p, np.ones(4), np.zeros(2), lam=0.99)
    assert theta.shape == (4, 2) and np.allclose(p, p.T)


def test_rls_can_continue_a_batch_fit(noisy_runs):
    u, y = noisy_runs[1]
    batch = estimate_arx([(u[:2000], y[:2000])], na=2, delay=DELAY)
    rls = RecursiveARX.from_fit(batch, lam=1.0)
    pred = rls.update_many(u[2000:], y[2000:])
    assert np.all(fit_percent(y[2100:], pred[100:]) > 90)


@pytest.mark.parametrize(("na", "nb", "delay"), [(2, 3, 4), (9, 9, 4), (3, 2, 0)])
def test_rls_single_sample_update_equals_update_many(na, nb, delay):
    rng = np.random.default_rng(0)
    u, y = rng.normal(size=(300, 2)), rng.normal(size=(300, 2))
    one = RecursiveARX(na=na, nb=nb, delay=delay, lam=0.99)
    many = RecursiveARX(na=na, nb=nb, delay=delay, lam=0.99)
    pred_one = np.array([one.update(u[k], y[k]) for k in range(len(u))])
    np.testing.assert_array_equal(pred_one, many.update_many(u, y))
    np.testing.assert_array_equal(one.theta, many.theta)
    with pytest.raises(ShapeError, match=r"shape \(2,\)"):
        one.update(np.zeros(3), np.zeros(2))
    with pytest.raises(NonFiniteError, match="non-finite"):
        one.update(np.array([np.nan, 0.0]), np.zeros(2))
