"""The gyro's zero-angular-rate update at rest (fusion.ekf.gyro, "At rest"): the
measurement and its Jacobian, when the rest test fires and what cannot fool it."""

import numpy as np
import pytest
from synthetic_ekf_model import numerical_jacobian

from drivers.sim.config import Room, get_preset
from drivers.sim.simulator import Simulator
from fusion.ekf import functions as ef
from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.gyro import rest_cov, rest_jacobian, rest_measurement
from fusion.ekf.model_ekf import ModelEKF
from fusion.exceptions import FilterOptionError
from fusion.noise import GyroNoise

WINDOW_S = 0.15


@pytest.fixture(scope="module")
def fm(model):
    return ef.FilterModel(model, gyro=GyroNoise())


@pytest.fixture()
def rng():
    return np.random.default_rng(43)


@pytest.mark.parametrize("window_s", [0.015, 0.5, 2.0])
def test_the_rest_jacobian_matches_a_numerical_derivative(fm, rng, window_s):
    x = ef.initial_state(fm, (1.0, 2.0, 0.7), z=0.05 * rng.standard_normal(fm.nz))
    x[ef.GYRO_BIAS], x[ef.HEADING_CLONE] = 0.007, 0.55
    num = numerical_jacobian(lambda xx: rest_measurement(xx, fm, window_s), x)
    np.testing.assert_allclose(rest_jacobian(x, fm, window_s), num, atol=1e-9)
    assert rest_measurement(x, fm, window_s)[0] == pytest.approx(window_s * 0.007)
    # no heading difference and no encoder rounding: the white rate noise over T only
    assert rest_cov(fm, window_s)[0, 0] == pytest.approx(0.005 ** 2 * window_s)


def test_the_rest_functions_need_a_gyro(model):
    plain = ef.FilterModel(model)
    for f in (rest_measurement, rest_jacobian):
        with pytest.raises(FilterOptionError, match="no gyro"):
            f(np.zeros(plain.n), plain, 0.5)
    with pytest.raises(FilterOptionError, match="settling"):
        GyroNoise(rest_settle_s=-0.1)


def _ekf(model, **gyro):
    return ModelEKF(model, initial_ticks=(100, 200),
                    options=EKFOptions(gyro=GyroNoise(window_s=WINDOW_S, rest_settle_s=WINDOW_S,
                                                      **gyro)))


def _periods(model, seconds):
    return round(seconds / model.dt_s)


def _step(ekf, cmd, ticks, rate):
    ekf.predict(np.asarray(cmd, dtype=float))
    ekf.update_encoders(np.asarray(ticks))
    return ekf.update_gyro(rate)


def test_fires_at_rest_after_the_settling_time(model, rng):
    """Still from the start: the first window is inside the settling time (a heading
    update), every later one a rest update whose innovation is the sum minus ``T b``."""
    ekf = _ekf(model)
    n = _periods(model, WINDOW_S)
    b0 = ekf.gyro_bias
    recs = [_step(ekf, (0, 0), (100, 200), 0.008 + 0.04 * rng.standard_normal())
            for _ in range(5 * n)]
    closed = [r for r in recs if r.reason != "pending"]
    assert [r.reason for r in closed] == ["fused"] * 5
    assert ekf.n_rest_updates == 4
    assert abs(ekf.gyro_bias - 0.008) < abs(b0 - 0.008)
    # without the rest update every window is the heading update
    plain = _ekf(model, rest_update=False)
    for _ in range(5 * n):
        _step(plain, (0, 0), (100, 200), 0.008)
    assert plain.n_rest_updates == 0 and plain.stats.count("gyro", "fused") == 5


def test_the_rest_update_measures_the_bias_alone(model):
    """At rest the innovation of a rest window is ``sum(y) dt - T b``, its ``H`` the bias."""
    ekf = _ekf(model)
    n = _periods(model, WINDOW_S)
    for _ in range(2 * n):                      # settle, then one full window pending
        _step(ekf, (0, 0), (100, 200), 0.0)
    b = ekf.gyro_bias
    for _ in range(n - 1):
        _step(ekf, (0, 0), (100, 200), 0.01)
    ekf.predict(np.zeros(2))
    ekf.update_encoders(np.array([100, 200]))
    x_before, P = ekf.x.copy(), ekf.P.copy()
    rec = ekf.update_gyro(0.01)
    assert ekf.n_rest_updates == 2
    T = n * model.dt_s
    assert rec.innovation[0] == pytest.approx(T * (0.01 - b))
    # the Kalman update with H = T at the bias: x += P[:, b] T / S * innovation
    S = T * T * P[ef.GYRO_BIAS, ef.GYRO_BIAS] + 0.005 ** 2 * T
    assert rec.innovation_cov[0, 0] == pytest.approx(S)
    np.testing.assert_allclose(ekf.x[:ef.HEADING_CLONE] - x_before[:ef.HEADING_CLONE],
                               P[:ef.HEADING_CLONE, ef.GYRO_BIAS] * T / S * rec.innovation[0],
                               rtol=1e-9, atol=1e-15)


def test_never_while_moving(model):
    """Wheels turning, or commands non-zero: heading updates only."""
    ekf = _ekf(model)
    n = _periods(model, WINDOW_S)
    for k in range(1, 6 * n + 1):
        _step(ekf, (0.2, 0.2), (100 + 7 * k, 200 + 7 * k), 0.0)
    assert ekf.n_rest_updates == 0 and ekf.stats.count("gyro", "fused") == 6


def test_a_stuck_encoder_on_a_turning_robot_is_not_rest(model):
    """Both counters frozen while the robot is commanded to turn: not still (commands)."""
    ekf = _ekf(model)
    for _ in range(6 * _periods(model, WINDOW_S)):
        _step(ekf, (-0.1, 0.1), (100, 200), 0.85)
    assert ekf.n_rest_updates == 0


def test_pushed_with_zero_commands_is_not_rest(model):
    """Commands zero but the wheels turning (pushed, or coasting): not still."""
    ekf = _ekf(model)
    for k in range(1, 6 * _periods(model, WINDOW_S) + 1):
        _step(ekf, (0, 0), (100 + 3 * k, 200 - 3 * k), 0.3)
    assert ekf.n_rest_updates == 0


def test_coasting_with_stuck_encoders_waits_for_the_settling_time(model):
    """Commands just went to zero and the counters are frozen: the robot may still roll.
    The first still window settles the stop (dropped, ``"settling"``); a rest update needs
    the settling time before its window (the second is one); without dropping the settling
    window it is a heading update."""
    for drop, expected in ((True, (["settling", "fused", "fused"], [0, 1, 2])),
                           (False, (["fused", "fused", "fused"], [0, 1, 2]))):
        ekf = _ekf(model, drop_settling=drop)
        n = _periods(model, WINDOW_S)
        for k in range(1, 3 * n + 1):
            _step(ekf, (0.2, 0.2), (100 + 7 * k, 200 + 7 * k), 0.0)
        frozen = (100 + 21 * n, 200 + 21 * n)
        reasons, rest = [], []
        for _ in range(3):
            recs = [_step(ekf, (0, 0), frozen, 0.0) for _ in range(n)]
            reasons.append(recs[-1].reason)
            rest.append(ekf.n_rest_updates)
        assert (reasons, rest) == expected, drop


def test_windows_settling_after_a_stop_are_dropped(model):
    """Stopped, the wheels count on (braking, creeping) for 2.5 windows: the windows
    overlapping the stop and the settling are dropped (``"settling"``) until a whole
    window stood still; the same counts with non-zero commands are fused; a filter that
    starts with zero commands and creeping counts (carpet at rest) is settled."""
    n = _periods(model, WINDOW_S)
    ekf = _ekf(model)
    k, reasons = 0, []
    for _ in range(2 * n):                                      # driving
        k += 7
        reasons.append(_step(ekf, (0.2, 0.2), (100 + k, 200 + k), 0.0).reason)
    for i in range(6 * n):                                      # stopped: creep 2.5 windows
        k += 1 if i < 2.5 * n and i % 3 == 0 else 0
        reasons.append(_step(ekf, (0, 0), (100 + k, 200 + k), 0.0).reason)
    closed = [r for r in reasons if r != "pending"]
    assert closed == ["fused", "fused", "settling", "settling", "settling", "settling",
                      "fused", "fused"], closed
    assert ekf.stats.count("gyro", "settling") == 4
    # a start with zero commands and creeping counts: never settling
    ekf = _ekf(model)
    recs = [_step(ekf, (0, 0), (100 + i // 7, 200 + i // 7), 0.0) for i in range(4 * n)]
    assert [r.reason for r in recs if r.reason != "pending"] == ["fused"] * 4


def test_a_lost_frame_breaks_the_rest(model):
    ekf = _ekf(model)
    n = _periods(model, WINDOW_S)
    for _ in range(2 * n):
        _step(ekf, (0, 0), (100, 200), 0.0)
    assert ekf.n_rest_updates == 1
    for i in range(n):                      # a lost frame inside this window: not still
        _step(ekf, (0, 0), (np.nan, np.nan) if i == 3 else (100.0, 200.0), 0.0)
    assert ekf.n_rest_updates == 1
    for _ in range(2 * n):                  # settle again: the second window is a rest one
        _step(ekf, (0, 0), (100, 200), 0.0)
    assert ekf.n_rest_updates == 2


def test_turned_by_hand_with_still_wheels_is_gated(model):
    """Counts and commands say still, the gyro reads a turn: the rest update's innovation
    is outside its 1-degree-of-freedom gate (0.5 rad/s over 0.15 s against 0.002 rad)."""
    ekf = _ekf(model)
    n = _periods(model, WINDOW_S)
    for _ in range(2 * n):
        _step(ekf, (0, 0), (100, 200), 0.0)
    bias = ekf.gyro_bias
    recs = [_step(ekf, (0, 0), (100, 200), 0.5) for _ in range(n)]
    assert recs[-1].reason == "gated" and ekf.gyro_bias == bias


def test_on_the_simulator_at_rest(ekf_example_model):
    """10 s at rest on the simulator (bias 0.008 rad/s, 0.005 rad/s/sqrt(Hz)): rest updates
    in the windows in which the counts stood still (from the third on); the bias within 3
    of its standard deviations, which is at most the white noise's over the rest time,
    ``density / sqrt(T)`` (+5% for the first window and the prior)."""
    robot = get_preset("create2").replace(gyro_noise_density_rad_s_sqrt_hz=0.005,
                                          gyro_bias_rad_s=0.008)
    for seed in (3, 4):
        log = Simulator(robot, seed=seed, room=Room.box(5.0, 5.0),
                        initial_pose=(2.5, 1.3, 0.0)).run(np.zeros((667, 2)))
        ekf = ModelEKF(ekf_example_model, initial_pose=(2.5, 1.3, 0.0),
                       initial_ticks=log.ticks[0], options=EKFOptions(gyro=GyroNoise(), history=0))
        for k in range(1, len(log.t_s)):
            ekf.predict(log.cmd_m_s[k])
            ekf.update_encoders(log.ticks[k])
            ekf.update_gyro(log.yaw_rate_rad_s[k])
        # 20 windows of 33 periods, each a rest update when its periods and the 34 of the
        # settling time before it kept their counts (the simulator's encoders spike now
        # and then, at rest too: such a window and the settling after it are not still)
        still = np.all(np.diff(log.ticks, axis=0) == 0, axis=1)       # period k + 1
        expected = sum(bool(33 * j >= 67 and np.all(still[33 * j - 67:33 * j]))
                       for j in range(1, 21))
        assert expected >= 14
        assert (ekf.n_rest_updates, ekf.stats.count("gyro", "fused")) == (expected, 20)
        sd = np.sqrt(ekf.P[ef.GYRO_BIAS, ef.GYRO_BIAS])
        assert sd < 1.05 * 0.005 / np.sqrt(666 * log.dt_s)
        assert abs(ekf.gyro_bias - 0.008) < 3 * sd
