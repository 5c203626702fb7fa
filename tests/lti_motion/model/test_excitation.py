"""Tests of lti_motion.model.excitation: manoeuvres, run validation, excitation checks."""

import math

import numpy as np
import pytest

from lti_motion.exceptions import NonFiniteError, NotExcitedError, ShapeError
from lti_motion.model.excitation import (
    check_excitation,
    check_runs,
    excitation_condition_number,
    random_held_normal,
    rotation_in_place,
    step_sequence,
)

DT = 0.015


def test_step_sequence_phases_hold_one_motor_at_a_time():
    seq = step_sequence(amplitude_m_s=0.3, hold_s=0.6, rest_s=0.9, dt_s=DT)
    u = seq.cmd_m_s
    assert u.shape == (2 * (40 + 60), 2)
    assert [(s.start, s.stop) for s in seq.phases] == [(0, 40), (40, 100), (100, 140), (140, 200)]
    np.testing.assert_array_equal(u[seq.left_on], np.tile([0.3, 0.0], (40, 1)))
    np.testing.assert_array_equal(u[seq.left_off], 0.0)
    np.testing.assert_array_equal(u[seq.right_on], np.tile([0.0, 0.3], (40, 1)))
    np.testing.assert_array_equal(u[seq.right_off], 0.0)
    assert seq.amplitude_m_s == 0.3 and seq.dt_s == DT


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"amplitude_m_s": 0.0, "hold_s": 1.0, "rest_s": 1.0}, "amplitude_m_s"),
        ({"amplitude_m_s": 0.2, "hold_s": -1.0, "rest_s": 1.0}, "hold_s"),
        ({"amplitude_m_s": 0.2, "hold_s": 1.0, "rest_s": float("nan")}, "rest_s"),
    ],
)
def test_step_sequence_rejects_bad_parameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        step_sequence(dt_s=DT, **kwargs)


def test_random_held_normal_is_seeded_clipped_and_held():
    kw = {"n": 20000, "dt_s": DT, "std_m_s": 0.3, "hold_s": (0.1, 0.5), "max_m_s": 0.5}
    u1 = random_held_normal(rng=np.random.default_rng(5), **kw)
    u2 = random_held_normal(rng=np.random.default_rng(5), **kw)
    u3 = random_held_normal(rng=np.random.default_rng(6), **kw)
    np.testing.assert_array_equal(u1, u2)
    assert not np.array_equal(u1, u3)
    assert u1.shape == (20000, 2) and np.abs(u1).max() <= 0.5
    assert np.any(np.abs(u1) == 0.5)  # clipping happened at 0.3 std
    free = random_held_normal(rng=np.random.default_rng(5), **{**kw, "max_m_s": 10.0})
    for wheel in range(2):  # without clipping no two holds share a value
        change = np.flatnonzero(np.diff(free[:, wheel]) != 0) + 1
        holds = np.diff(change)
        assert holds.min() >= round(0.1 / DT) and holds.max() <= round(0.5 / DT)
    # independent wheels: little correlation, both excited
    assert abs(np.corrcoef(u1.T)[0, 1]) < 0.1
    assert np.all(u1.std(axis=0) > 0.2)


def test_random_held_normal_mean_and_validation(rng):
    u = random_held_normal(n=30000, dt_s=DT, rng=rng, std_m_s=0.05, mean_m_s=0.1)
    np.testing.assert_allclose(u.mean(axis=0), 0.1, atol=0.01)
    with pytest.raises(ValueError, match="hold_s"):
        random_held_normal(n=10, dt_s=DT, rng=rng, std_m_s=0.1, hold_s=(0.5, 0.1))
    with pytest.raises(ValueError, match="positive integer"):
        random_held_normal(n=0, dt_s=DT, rng=rng, std_m_s=0.1)


def test_rotation_in_place_covers_the_turns():
    u = rotation_in_place(turns=2, wheel_speed_m_s=0.1, wheel_base_m=0.235, dt_s=DT, margin=0.1)
    assert np.all(u == [-0.1, 0.1])
    yaw = len(u) * DT * (u[0, 1] - u[0, 0]) / 0.235  # w = (vR - vL) / b
    assert 2 * 2 * math.pi * 1.1 <= yaw < 2 * 2 * math.pi * 1.1 + 2 * 0.1 / 0.235 * DT
    with pytest.raises(ValueError, match="margin"):
        rotation_in_place(turns=1, wheel_speed_m_s=0.1, wheel_base_m=0.235, dt_s=DT, margin=-1)


def test_check_runs_names_mismatched_shapes():
    with pytest.raises(ShapeError, match=r"run 1: u has shape \(10, 2\) but y has shape \(9, 2\)"):
        check_runs([(np.zeros((5, 2)), np.zeros((5, 2))), (np.zeros((10, 2)), np.zeros((9, 2)))])
    with pytest.raises(ShapeError, match=r"expected y of shape \(n, 2\), got \(10, 3\)"):
        check_runs([(np.zeros((10, 2)), np.zeros((10, 3)))])
    with pytest.raises(ShapeError, match="wrap a single run"):
        check_runs((np.zeros((10, 2)), np.zeros((10, 2))))
    with pytest.raises(ShapeError, match="empty"):
        check_runs([])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_check_runs_names_the_non_finite_sample(bad):
    y = np.zeros((30, 2))
    y[17, 1] = bad
    with pytest.raises(NonFiniteError, match=r"run 0: y\[17, 1\] \(w\) is"):
        check_runs([(np.zeros((30, 2)), y)])
    with pytest.raises(ValueError):  # NonFiniteError is a ValueError
        check_runs([(y, np.zeros((30, 2)))])


def test_random_commands_are_exciting(rng):
    u = random_held_normal(n=5000, dt_s=DT, rng=rng, std_m_s=0.2)
    cond = check_excitation([u], n_lags=12)
    assert 1 < cond < 1e3
    assert excitation_condition_number([u[:2500], u[2500:]], n_lags=12) < 1e3


@pytest.mark.parametrize(
    "make, reason",
    [
        (lambda u: np.full_like(u, 0.2), "both wheels are constant"),
        (lambda u: np.column_stack([u[:, 0], np.zeros(len(u))]), "wheel R is constant"),
        (lambda u: np.column_stack([u[:, 0], 0.3 * np.ones(len(u))]), "R is constant"),
        (lambda u: np.column_stack([u[:, 0], u[:, 0]]), "collinear"),
        (lambda u: np.column_stack([u[:, 0], -u[:, 0]]), "collinear"),
    ],
)
def test_degenerate_commands_are_not_exciting(rng, make, reason):
    u = make(random_held_normal(n=2000, dt_s=DT, rng=rng, std_m_s=0.2))
    with pytest.raises(NotExcitedError, match=reason) as info:
        check_excitation([u], n_lags=6)
    msg = str(info.value)
    assert "condition number" in msg and "random_held_normal" in msg
    assert "drive both" in msg.lower()


def test_correlated_levels_keep_the_distribution_and_shrink_the_steps():
    from lti_motion.model.excitation import random_held_normal

    kw = {"n": 400_000, "dt_s": 0.015, "std_m_s": 0.1, "hold_s": (0.015, 0.015), "max_m_s": 10.0}
    white = random_held_normal(rng=np.random.default_rng(0), **kw)
    corr = random_held_normal(rng=np.random.default_rng(0), correlation=0.85, **kw)
    np.testing.assert_allclose(corr.std(axis=0), 0.1, rtol=0.03)
    np.testing.assert_allclose(corr.mean(axis=0), 0.0, atol=0.005)
    lag1 = np.corrcoef(corr[1:, 0], corr[:-1, 0])[0, 1]
    assert abs(lag1 - 0.85) < 0.01
    assert np.diff(corr, axis=0).std() < 0.6 * np.diff(white, axis=0).std()
    with pytest.raises(ValueError, match=r"correlation must be in \[0, 1\)"):
        random_held_normal(rng=np.random.default_rng(0), correlation=1.0, **kw)
