"""Tests of lti_motion.model.fir and lti_motion.model.fir_steps: FIR from steps and by least
squares, state-space simulation.

The synthetic plant is the one of test_arx.py (second-order wheels, 4-sample
delay, v = (vR + vL) / 2, w = (vR - vL) / 0.235, white noise on v and w).

The paper: ``docs/architecture.md``, "The paper".
"""
import numpy as np
import pytest
from synthetic_plant import BASE, DELAY, DT, plant

from lti_motion.exceptions import CalibrationError, ShapeError
from lti_motion.kinematics import body_from_wheel, wheel_from_body
from lti_motion.metrics import fit_percent
from lti_motion.model.excitation import random_held_normal, step_sequence
from lti_motion.model.fir import estimate_fir, fir_state_space
from lti_motion.model.fir_steps import fir_from_steps
from lti_motion.model.state_space import (
    markov_parameters,
    simulate_state_space,
    simulate_state_space_loop,
)


def true_impulse_response(n):
    """taps[i, out, in] of the plant."""
    taps = np.empty((n, 2, 2))
    for wheel in range(2):
        u = np.zeros((n, 2))
        u[0, wheel] = 1.0
        taps[:, :, wheel] = plant(u)
    return taps


SEQ = step_sequence(amplitude_m_s=0.3, hold_s=1.0, rest_s=1.0, dt_s=DT)


def test_noise_free_steps_give_the_true_impulse_response():
    y = plant(SEQ.cmd_m_s)
    fit = fir_from_steps(SEQ.cmd_m_s, y, phases=SEQ)
    truth = true_impulse_response(80)
    # exact up to the not-quite-settled level before each falling edge (0.83^66 ~ 5e-6)
    np.testing.assert_allclose(fit.taps, truth[: fit.n_taps], atol=2e-5)
    np.testing.assert_allclose(fit.taps[:DELAY], 0.0, atol=2e-5)  # the transport delay
    # the length is where all four step responses stay within 5 % of their peak of
    # their final value, plus the margin
    step = np.cumsum(truth, axis=0)
    last = max(np.flatnonzero(np.abs(step[:, o, i] - step[-1, o, i])
                              > 0.05 * np.abs(step[:, o, i]).max())[-1]
               for o in range(2) for i in range(2))
    assert fit.n_taps == last + 1 + 2
    assert fit.source == "steps" and fit.step_responses.shape == (67, 2, 2)
    np.testing.assert_allclose(fit.step_responses[-1], truth.sum(axis=0), atol=2e-5)


def test_noisy_steps_give_a_fir_that_free_runs_above_90_percent(rng):
    u, y = SEQ.cmd_m_s, plant(SEQ.cmd_m_s, rng)
    both = fir_from_steps(u, y, phases=SEQ)
    rising = fir_from_steps(u, y, phases=SEQ, edges="rising", max_taps=both.n_taps)
    assert 10 <= both.n_taps <= 30
    u_val = random_held_normal(n=5000, dt_s=DT, rng=rng, std_m_s=0.2)
    y_val = plant(u_val, rng)
    fits = {}
    for name, fit in (("both", both), ("rising", rising)):
        ss = fir_state_space(fit.taps)
        fits[name] = fit_percent(y_val, simulate_state_space(ss.A, ss.B, ss.C, ss.D, u_val)[0])
    assert np.all(fits["both"] >= 90.0)
    truth = true_impulse_response(both.n_taps)
    err_both = np.abs(both.taps - truth).mean()
    err_rising = np.abs(rising.taps - truth[: rising.n_taps]).mean()
    assert err_both < err_rising  # averaging the edges halves the noise variance


def test_steps_that_do_not_match_the_phases_raise():
    u = SEQ.cmd_m_s.copy()
    y = plant(u)
    with pytest.raises(CalibrationError, match="no step of wheel R"):
        fir_from_steps(u, y, phases=(SEQ.left_on, SEQ.left_off, SEQ.left_off, SEQ.right_off))
    u[10, 1] = 0.1
    with pytest.raises(CalibrationError, match="change inside the phase"):
        fir_from_steps(u, y, phases=SEQ)
    with pytest.raises(CalibrationError, match="do not fit"):
        fir_from_steps(u[:100], y[:100], phases=SEQ)
    with pytest.raises(ShapeError, match="four slices"):
        fir_from_steps(u, y, phases=SEQ.phases[:3])


def test_least_squares_fir_on_random_data(rng):
    u = random_held_normal(n=6000, dt_s=DT, rng=rng, std_m_s=0.2)
    fit = estimate_fir([(u, plant(u))], n_taps=36, delay=DELAY)
    truth = true_impulse_response(fit.n_taps)
    # only the truncated tail differs: the last tap absorbs it
    scale = np.abs(truth).max(axis=0)
    np.testing.assert_allclose(fit.taps[:-1] / scale, truth[:-1] / scale, atol=1e-3)
    np.testing.assert_allclose(fit.taps[-1] / scale, truth[-1] / scale, atol=1e-2)
    assert fit.source == "lstsq" and fit.n_taps == 40 and np.all(fit.taps[:DELAY] == 0)
    with pytest.raises(CalibrationError, match="at least"):
        estimate_fir([(u[:50], plant(u[:50]))], n_taps=36)


def test_fir_realisation_has_the_taps_as_markov_parameters(rng):
    taps = rng.normal(size=(7, 2, 2))
    ss = fir_state_space(taps)
    np.testing.assert_allclose(markov_parameters(ss.A, ss.B, ss.C, ss.D, 10)[:7], taps,
                               atol=1e-15)
    np.testing.assert_array_equal(markov_parameters(ss.A, ss.B, ss.C, ss.D, 10)[7:], 0.0)
    u = rng.normal(size=(50, 2))
    direct = sum(np.einsum("oi,ni->no", taps[i], np.vstack([np.zeros((i, 2)), u[: 50 - i]]))
                 for i in range(7))
    np.testing.assert_allclose(simulate_state_space(*ss[:4], u)[0], direct, atol=1e-12)


@pytest.mark.parametrize("nz", [1, 6, 24])
@pytest.mark.parametrize("n", [1, 5, 127, 128, 129, 700])
@pytest.mark.parametrize("batch", [(), (3,)])
def test_block_simulation_equals_the_plain_recursion(rng, nz, n, batch):
    a = rng.normal(size=(nz, nz))
    a *= 0.97 / np.abs(np.linalg.eigvals(a)).max()
    b, c, d = rng.normal(size=(nz, 2)), rng.normal(size=(2, nz)), rng.normal(size=(2, 2))
    u = rng.normal(size=(*batch, n, 2))
    z0 = rng.normal(size=(*batch, nz))
    y_fast, z_fast = simulate_state_space(a, b, c, d, u, z0=z0)
    y_ref, z_ref = simulate_state_space_loop(a, b, c, d, u, z0=z0)
    np.testing.assert_allclose(y_fast, y_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(z_fast, z_ref, rtol=0, atol=1e-9)


def test_simulation_checks_shapes(rng):
    a, b, c, d = np.eye(2) * 0.5, np.ones((2, 2)), np.ones((2, 2)), np.zeros((2, 2))
    with pytest.raises(ShapeError, match=r"u of shape \(\.\.\., n, 2\)"):
        simulate_state_space(a, b, c, d, np.zeros((5, 3)))
    with pytest.raises(ShapeError, match="z0"):
        simulate_state_space(a, b, c, d, np.zeros((5, 2)), z0=np.zeros(3))
    y, z = simulate_state_space(a, b, c, d, np.zeros((0, 2)))
    assert y.shape == (0, 2) and z.shape == (2,)


# --- the steady-state gain of the FIR from steps (lti_motion.model.fir_steps, dc_gain) ---------

TICK_M = 0.00044  # encoder resolution [m per tick], as a Roomba's


def servo_plant(u, rng, *, gain=0.99):
    """A wheel-servoed robot: both wheels reach ``gain`` times their command (the plant's
    right wheel, gain 0.95, is given its command / 0.95), and the body speeds come from
    quantised encoder counts, one count in 10 per period at 0.3 m/s."""
    y = plant(u * np.array([1.0, 1.0 / 0.95])) * gain
    wheels = wheel_from_body(y, wheel_base_m=BASE)
    counts = np.floor((np.cumsum(wheels * DT, axis=0) + rng.uniform(0, TICK_M, 2)) / TICK_M)
    speeds = np.diff(counts, axis=0, prepend=counts[:1]) * TICK_M / DT
    return body_from_wheel(speeds, wheel_base_m=BASE)


def _free_run(fit, u):
    ss = fir_state_space(fit.taps)
    return simulate_state_space(ss.A, ss.B, ss.C, ss.D, u)[0]


@pytest.mark.parametrize("dc_gain", ["settled", "wheel_servo"])
def test_noise_free_steps_keep_the_transient_and_hold_the_settled_level(dc_gain):
    y = plant(SEQ.cmd_m_s)
    free = fir_from_steps(SEQ.cmd_m_s, y, phases=SEQ)
    fit = fir_from_steps(SEQ.cmd_m_s, y, phases=SEQ, dc_gain=dc_gain, wheel_base_m=BASE)
    assert fit.n_taps == free.n_taps
    step = np.cumsum(fit.taps, axis=0)
    peak = np.abs(free.step_responses).max(axis=0)
    # the level is averaged from twice the settling length on, where the plant's transient
    # is down to the band squared (0.25 % of the peak) and decaying: 0.1 % of the peak
    level = np.cumsum(true_impulse_response(200), axis=0)[-1]    # wheels 1.0 and 0.95
    if dc_gain == "wheel_servo":   # the nearest c M: c the mean wheel gain, 0.975
        level = 0.975 * np.array([[0.5, 0.5], [-1 / BASE, 1 / BASE]])
    np.testing.assert_array_less(np.abs(step[-1] - level), 1e-3 * peak)
    # before it has settled, the step response is the measured one (edges measured from
    # the settled part of the phase before them: a shift of 0.1 % of the peak at most)
    settled = np.flatnonzero(np.any(np.abs(fit.taps) > 1e-15, axis=(1, 2)))[-1]
    shift = np.abs(step[:settled] - free.step_responses[:settled])
    assert np.all(shift < 1e-3 * peak), shift.max(axis=0) / peak
    assert np.all(np.abs(step[:DELAY]) < 1e-3 * peak)                 # the transport delay


def test_wheel_servo_restriction_holds_exactly_straight_commands_give_no_yaw(rng):
    u = SEQ.cmd_m_s
    fit = fir_from_steps(u, servo_plant(u, rng), phases=SEQ, dc_gain="wheel_servo",
                         wheel_base_m=BASE)
    g = fit.taps.sum(axis=0)
    c = g[0, 0] * 2.0
    np.testing.assert_allclose(g, c * np.array([[0.5, 0.5], [-1 / BASE, 1 / BASE]]),
                               rtol=0, atol=1e-12)
    assert c == pytest.approx(0.99, abs=0.01)
    straight = _free_run(fit, np.full((300, 2), 0.2))
    assert abs(straight[-1, 1]) < 1e-12 and straight[-1, 0] == pytest.approx(0.2 * c, rel=1e-12)
    turn = _free_run(fit, np.tile([-0.1, 0.1], (300, 1)))
    assert abs(turn[-1, 0]) < 1e-12


def test_settled_level_and_servo_gain_beat_one_quantised_sample():
    """Over 20 step calibrations of a quantised servo plant, the paper's one-sample DC
    gain has a straight-line yaw bias of centiradians per second; the settled mean shrinks
    it, the wheel-servo restriction removes it; the held-out free-run fit is not worse."""
    u, straight = SEQ.cmd_m_s, np.array([0.25, 0.25])
    yaw = {k: [] for k in ("free", "settled", "wheel_servo")}
    fits = {k: [] for k in yaw}
    for seed in range(20):
        rng = np.random.default_rng(seed)
        y = servo_plant(u, rng)
        u_val = random_held_normal(n=4000, dt_s=DT, rng=rng, std_m_s=0.2, hold_s=(0.5, 2.0))
        y_val = servo_plant(u_val, rng)
        for k in yaw:
            fit = fir_from_steps(u, y, phases=SEQ, dc_gain=k, wheel_base_m=BASE)
            yaw[k].append(abs(fit.taps.sum(axis=0)[1] @ straight))
            fits[k].append(fit_percent(y_val, _free_run(fit, u_val)))
    rms = {k: np.sqrt(np.mean(np.square(v))) for k, v in yaw.items()}
    assert rms["free"] > 0.01                      # rad/s: ruins a route (docs/route.md)
    assert rms["settled"] < 0.25 * rms["free"]
    assert rms["wheel_servo"] < 1e-12
    mean_fit = {k: np.mean(v, axis=0) for k, v in fits.items()}
    assert np.all(mean_fit["wheel_servo"] >= mean_fit["free"]), mean_fit


def test_quantised_plateaus_settle():
    """Quantised counts leave most of a plateau on one level (median absolute deviation
    zero): the settling band then uses the standard deviation, not 5 % of the peak only."""
    u = SEQ.cmd_m_s
    fit = fir_from_steps(u, servo_plant(u, np.random.default_rng(0)), phases=SEQ,
                         edges="rising")
    assert fit.n_taps <= 25


def test_bad_dc_gain_options_raise():
    u, y = SEQ.cmd_m_s, plant(SEQ.cmd_m_s)
    with pytest.raises(ValueError, match="dc_gain must be one of"):
        fir_from_steps(u, y, phases=SEQ, dc_gain="servo")
    with pytest.raises(ValueError, match="needs wheel_base_m"):
        fir_from_steps(u, y, phases=SEQ, dc_gain="wheel_servo")
    with pytest.raises(ValueError, match="wheel_base_m must be a positive"):
        fir_from_steps(u, y, phases=SEQ, dc_gain="wheel_servo", wheel_base_m=-0.2)
    with pytest.raises(ValueError, match="edges must be"):
        fir_from_steps(u, y, phases=SEQ, edges="falling")
    # a response still moving at the end of its phase has no settled level to measure
    late = y + 1e-6 * np.random.default_rng(0).normal(size=y.shape)
    for phase in (SEQ.left_on, SEQ.right_on):
        late[phase.stop - 1] += 0.5
    with pytest.raises(CalibrationError, match="not settled"):
        fir_from_steps(u, late, phases=SEQ, dc_gain="settled", edges="rising")
