"""A yaw-rate gyro in the model EKF: the window measurement, its Jacobian, the clone,
the records, and what it does on the simulator (fusion.ekf.gyro)."""

import numpy as np
import pytest
from synthetic_ekf_model import numerical_jacobian

from drivers.sim.config import Fault, Room, get_preset
from drivers.sim.simulator import Simulator
from fusion.ekf import functions as ef
from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.gyro import (
    clone_heading,
    gyro_cov,
    gyro_jacobian,
    gyro_measurement,
    heading_quantization_var,
)
from fusion.ekf.model_ekf import ModelEKF
from fusion.exceptions import FilterOptionError, MeasurementShapeError
from fusion.noise import GyroNoise
from lti_motion.kinematics import wrap_angle

START = (2.5, 1.3, 0.0)


@pytest.fixture(scope="module")
def fm(model):
    return ef.FilterModel(model, gyro=GyroNoise())


@pytest.fixture()
def rng():
    return np.random.default_rng(41)


def _state(fm, rng):
    x = ef.initial_state(fm, (1.0, 2.0, 0.7), z=0.05 * rng.standard_normal(fm.nz))
    x[ef.SCALES] = (0.004, -0.003, 0.03)
    x[ef.GYRO_BIAS], x[ef.HEADING_CLONE] = 0.007, 0.55
    x[fm.speed_slice] = (0.2, 0.4)
    return x


def test_layout_with_a_gyro(model, fm):
    plain = ef.FilterModel(model)
    assert (fm.n, fm.z0, plain.n, plain.z0) == (plain.n + 2, 8, model.n_states + 8, 6)
    assert fm.model_slice == slice(8, 8 + model.n_states)
    x = ef.initial_state(fm, START)
    assert x[ef.HEADING_CLONE] == START[2] and x[ef.GYRO_BIAS] == 0.0
    P = ef.initial_covariance(fm, pose_std=(0.01, 0.01, 0.02))
    assert P[ef.HEADING_CLONE, ef.HEADING_CLONE] == P[2, ef.HEADING_CLONE] == pytest.approx(4e-4)
    assert P[ef.GYRO_BIAS, ef.GYRO_BIAS] == pytest.approx(GyroNoise().bias_prior_std_rad_s ** 2)
    assert np.linalg.eigvalsh(P).min() >= -1e-15


@pytest.mark.parametrize("window_s", [0.015, 0.5, 2.0])
def test_the_gyro_jacobian_matches_a_numerical_derivative(fm, rng, window_s):
    x = _state(fm, rng)
    num = numerical_jacobian(lambda xx: gyro_measurement(xx, fm, window_s), x)
    np.testing.assert_allclose(gyro_jacobian(x, fm, window_s), num, atol=1e-9)
    assert gyro_measurement(x, fm, window_s)[0] == pytest.approx(
        0.7 - 0.55 + window_s * 0.007)


@pytest.mark.parametrize("accumulate", [False, True])
def test_F_with_a_gyro_matches_a_numerical_derivative(fm, rng, accumulate):
    x = _state(fm, rng)
    u = np.array([0.25, 0.15])
    num = numerical_jacobian(lambda xx: ef.predict_terms(xx, u, fm, accumulate=accumulate)[0],
                              x)
    np.testing.assert_allclose(ef.predict_terms(x, u, fm, accumulate=accumulate)[1], num,
                               atol=1e-8)


def test_without_gyro_readings_the_filter_is_the_plain_one(model, fm, rng):
    """The two gyro states change nothing else: same x and P on the common states."""
    plain = ModelEKF(model, initial_ticks=(0, 0))
    with_gyro = ModelEKF(model, initial_ticks=(0, 0), options=EKFOptions(gyro=GyroNoise()))
    keep = np.r_[0:6, 8:with_gyro.fm.n]
    ticks = np.zeros(2)
    for k in range(300):
        u = np.array([0.2 + 0.05 * np.sin(k / 20), 0.2 + 0.05 * np.cos(k / 30)])
        ticks = ticks + np.round(u * 0.015 / 4.4e-4 + rng.normal(0, 0.5, 2))
        for f in (plain, with_gyro):
            f.predict(u)
            f.update_encoders(ticks.astype(np.int64) % 65536)
    np.testing.assert_allclose(with_gyro.x[keep], plain.x, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(with_gyro.P[np.ix_(keep, keep)], plain.P, rtol=1e-9, atol=1e-16)


def test_clone_copies_the_heading_and_keeps_P_psd(fm, rng):
    x = _state(fm, rng)
    a = rng.standard_normal((fm.n, fm.n))
    P = a @ a.T
    x2, P2 = clone_heading(x, P)
    c = ef.HEADING_CLONE
    assert x2[c] == x[2] and x[c] == 0.55                 # input untouched
    np.testing.assert_array_equal(P2[c], P2[2])
    np.testing.assert_array_equal(P2[:, c], P2[:, 2])
    assert np.linalg.eigvalsh(P2).min() > -1e-9 * np.abs(P2).max()
    # after the clone, theta - theta_c has no variance
    h = gyro_jacobian(x2, fm, 0.0)
    assert (h @ P2 @ h.T)[0, 0] == pytest.approx(0.0, abs=1e-9)


def test_noise_of_the_window(model, fm):
    i = model.encoder_intrinsics
    q = heading_quantization_var(fm)
    assert q == pytest.approx((i.m_per_tick_left ** 2 + i.m_per_tick_right ** 2)
                              / (12 * i.wheel_base_m ** 2))
    assert gyro_cov(fm, 0.5)[0, 0] == pytest.approx(0.005 ** 2 * 0.5 + 2 * q)
    with pytest.raises(FilterOptionError, match="no gyro"):
        gyro_cov(ef.FilterModel(model), 0.5)


def test_gyro_noise_options():
    assert GyroNoise().std_rad_s(0.015) == pytest.approx(0.005 / np.sqrt(0.015))
    for bad in ({"noise_density_rad_s_sqrt_hz": 0.0}, {"bias_walk_rad_s_per_sqrt_s": -1.0},
                {"window_s": 0.0}, {"max_bias_rad_s": 0.02}):
        with pytest.raises(FilterOptionError, match="GyroNoise"):
            GyroNoise(**bad)


def _drive(ekf, n, *, rate):
    """n periods straight at 0.2 m/s (ticks consistent), gyro reading ``rate``."""
    recs = []
    for k in range(1, n + 1):
        ekf.predict(np.array([0.2, 0.2]))
        ekf.update_encoders(np.array([k * 7, k * 7]))
        recs.append(ekf.update_gyro(rate))
    return recs


def test_readings_fill_a_window_then_fuse(model):
    ekf = ModelEKF(model, initial_ticks=(0, 0), options=EKFOptions(gyro=GyroNoise(window_s=0.15)))
    periods = round(0.15 / model.dt_s)
    recs = _drive(ekf, 2 * periods, rate=0.0)
    reasons = [r.reason for r in recs]
    assert reasons == (["pending"] * (periods - 1) + ["fused"]) * 2
    assert all(r.kind == "gyro" for r in recs)
    assert recs[periods - 1].innovation.shape == (1,)
    assert ekf.stats.count("gyro", "pending") == 2 * (periods - 1)
    assert ekf.x[ef.HEADING_CLONE] == ekf.x[2]       # a new window started


def test_nan_gap_and_errors(model):
    ekf = ModelEKF(model, initial_ticks=(0, 0), options=EKFOptions(gyro=GyroNoise(window_s=0.15)))
    _drive(ekf, 3, rate=0.0)
    assert ekf.update_gyro(0.0).reason == "gap"              # no predict between
    ekf.predict(np.array([0.2, 0.2]))
    assert ekf.update_gyro(np.nan).reason == "non_finite"    # drops the window
    ekf.predict(np.array([0.2, 0.2]))
    assert ekf.update_gyro(0.0).reason == "pending"          # the new window's first
    ekf.predict(np.array([0.2, 0.2]))
    ekf.predict(np.array([0.2, 0.2]))                        # a period without a reading
    assert ekf.update_gyro(0.0).reason == "gap"              # restarts the window
    ekf.predict(np.array([0.2, 0.2]))
    assert ekf.update_gyro(0.0).reason == "pending"
    with pytest.raises(MeasurementShapeError, match="one yaw rate"):
        ekf.update_gyro([0.1, 0.2])
    with pytest.raises(FilterOptionError, match="no gyro"):
        ModelEKF(model).update_gyro(0.1)


def test_the_bias_estimate_is_clipped(model):
    gyro = GyroNoise(window_s=0.03, bias_prior_std_rad_s=0.01, max_bias_rad_s=0.03)
    ekf = ModelEKF(model, initial_ticks=(0, 0),
                   options=EKFOptions(gyro=gyro, gate_probability=None))
    recs = _drive(ekf, 400, rate=1.0)          # a rate no encoder sees: bias takes part
    assert sum(r.reason == "fused" for r in recs) == 200
    assert abs(ekf.gyro_bias) == pytest.approx(0.03)
    assert np.isnan(ModelEKF(model).gyro_bias)


# -- on the simulator ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sim_model(ekf_example_model):
    return ekf_example_model


def _run(model, log, gyro):
    ekf = ModelEKF(model, initial_pose=START, pose_std=(0.005,) * 3, initial_ticks=log.ticks[0],
                   options=EKFOptions(gyro=gyro, history=0))
    err, var = np.empty(len(log.t_s)), np.empty(len(log.t_s))
    err[0], var[0] = 0.0, ekf.P[2, 2]
    for k in range(1, len(log.t_s)):
        ekf.predict(log.cmd_m_s[k])
        ekf.update_encoders(log.ticks[k])
        if gyro is not None:
            ekf.update_gyro(log.yaw_rate_rad_s[k])
        err[k], var[k] = wrap_angle(log.true_pose[k, 2] - ekf.x[2]), ekf.P[2, 2]
    return ekf, err, var


def _robot(floor, bias):
    return get_preset("create2").replace(gyro_noise_density_rad_s_sqrt_hz=0.005,
                                         gyro_bias_rad_s=bias, floor=floor)


def test_at_rest_the_filter_learns_the_bias(sim_model):
    """10 s at rest: the reading is the bias; 0.005 rad/s/sqrt(Hz) leaves 0.0016 rad/s."""
    for seed in (1, 2):
        log = Simulator(_robot("hard", 0.008), seed=seed, initial_pose=START,
                        room=Room.box(5.0, 5.0)).run(np.zeros((667, 2)))
        ekf, err, _ = _run(sim_model, log, GyroNoise())
        sd = np.sqrt(ekf.P[ef.GYRO_BIAS, ef.GYRO_BIAS])
        assert 0.001 < sd < 0.0025
        assert abs(ekf.gyro_bias - 0.008) < 3 * sd
        assert abs(err[-1]) < 1e-3                   # at rest the heading stays put


def test_on_carpet_the_gyro_corrects_the_turn_shortfall(sim_model, load_example):
    """Carpet: ground turns ~5% short of the encoders. 20 s of the route, 3 robots, a
    0.008 rad/s bias: the gyro filter's heading error is a fraction of encoders-only's,
    and within 3 of its own standard deviations."""
    example = load_example("ekf_plugin")
    sim = Simulator(_robot("carpet", 0.008), n_robots=3, seed=60, room=Room.box(5.0, 5.0),
                    initial_pose=START)
    logs = example.drive_route(sim, duration_s=20.0, rng=np.random.default_rng(60))
    for i in range(3):
        log = logs.robot(i)
        _, e_enc, _ = _run(sim_model, log, None)
        _, e_gyro, var = _run(sim_model, log, GyroNoise())
        assert abs(e_gyro[-1]) < 0.5 * abs(e_enc[-1]), i
        assert np.all(np.abs(e_gyro) <= 3 * np.sqrt(var)), i


def test_a_wheel_diameter_fault_is_seen_by_the_gyro(sim_model, load_example):
    """A 0.5% larger left wheel (kappa ~ -0.021 rad/m), 10 s at rest first (the bias
    learned there: at a steady speed a bias and ``kappa v`` look alike to the gyro): the
    gyro filter's final heading error is below half of encoders-only's on each of 3
    robots over 30 s."""
    example = load_example("ekf_plugin")
    sim = Simulator(_robot("hard", 0.0), n_robots=3, seed=70, room=Room.box(5.0, 5.0),
                    initial_pose=START,
                    faults=[Fault("wheel_diameter", t_s=0.0, diameter_change=0.005,
                                  wheel="left")])
    logs = example.drive_route(sim, duration_s=30.0, rng=np.random.default_rng(70),
                               rest_s=10.0)
    for i in range(3):
        log = logs.robot(i)
        _, e_enc, _ = _run(sim_model, log, None)
        _, e_gyro, _ = _run(sim_model, log, GyroNoise())
        assert abs(e_gyro[-1]) < 0.5 * abs(e_enc[-1]), i
