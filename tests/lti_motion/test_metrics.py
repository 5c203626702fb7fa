"""Tests of lti_motion.metrics against closed-form cases."""

from __future__ import annotations

import numpy as np
import pytest

from lti_motion.exceptions import NonFiniteError, ShapeError
from lti_motion.kinematics import integrate_poses
from lti_motion.metrics import (
    RelativePoseError,
    TrajectoryError,
    ate,
    ate_stats,
    closure_error,
    closure_offset_m,
    fit_percent,
    rpe,
)


def _se2(poses: np.ndarray, angle: float, shift: np.ndarray) -> np.ndarray:
    """Apply the rigid motion (rotation by angle, then shift) to poses (..., n, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    out = poses.copy()
    out[..., 0] = c * poses[..., 0] - s * poses[..., 1] + shift[0]
    out[..., 1] = s * poses[..., 0] + c * poses[..., 1] + shift[1]
    out[..., 2] = poses[..., 2] + angle
    return out


@pytest.fixture
def trajectory(rng) -> np.ndarray:
    speeds = np.column_stack([rng.uniform(0.1, 0.3, 400), rng.normal(0.0, 0.8, 400)])
    return integrate_poses(speeds, 0.05, initial_pose=[0.5, -0.2, 0.3])


# --- fit_percent -----------------------------------------------------------


def test_fit_perfect_and_mean_predictor(rng):
    y = rng.normal(size=(200, 2))
    np.testing.assert_allclose(fit_percent(y, y), [100.0, 100.0])
    np.testing.assert_allclose(
        fit_percent(y, np.broadcast_to(y.mean(axis=0), y.shape)), 0.0, atol=1e-12
    )


def test_fit_closed_form():
    # ||y - yhat|| = 1, ||y - mean|| = sqrt(5): fit = 100 (1 - 1/sqrt(5))
    y = np.array([0.0, 1.0, 2.0, 3.0])
    assert fit_percent(y, y + np.array([0.0, 0.0, 0.0, 1.0])) == pytest.approx(
        100 * (1 - 1 / np.sqrt(5))
    )
    # a prediction at twice the error of the mean predictor scores -100
    assert fit_percent(y, y - 2 * (y - y.mean())) == pytest.approx(-100.0)


def test_fit_per_channel_and_axis(rng):
    y = rng.normal(size=(100, 3))
    yhat = y + rng.normal(scale=[0.1, 0.5, 1.0], size=(100, 3))
    fits = fit_percent(y, yhat)
    assert fits.shape == (3,)
    assert fits[0] > fits[1] > fits[2]
    np.testing.assert_allclose(fit_percent(y.T, yhat.T, axis=1), fits)
    for c in range(3):
        assert fit_percent(y[:, c], yhat[:, c]) == pytest.approx(fits[c])


def test_fit_constant_output_raises():
    y = np.column_stack([np.linspace(0, 1, 10), np.full(10, 0.1)])
    with pytest.raises(ValueError, match=r"constant.*channel\(s\) \[1\]"):
        fit_percent(y, y)
    with pytest.raises(ValueError, match="constant"):
        fit_percent(np.zeros(5), np.ones(5))


def test_fit_shape_and_nan_errors():
    with pytest.raises(ShapeError, match=r"\(10, 2\) and \(10, 3\)"):
        fit_percent(np.zeros((10, 2)), np.zeros((10, 3)))
    y = np.linspace(0.0, 1.0, 5)
    with pytest.raises(NonFiniteError, match="y_pred"):
        fit_percent(y, np.where(y > 0.5, np.nan, y))


# --- closure ---------------------------------------------------------------


def test_closure_offset():
    assert closure_offset_m([1.0, 1.0], [4.0, 5.0]) == pytest.approx(5.0)
    batch = closure_offset_m(np.zeros((3, 2)), np.array([[1.0, 0.0], [0.0, 2.0], [3.0, 4.0]]))
    np.testing.assert_allclose(batch, [1.0, 2.0, 5.0])
    with pytest.raises(ShapeError, match=r"\(\.\.\., 2\)"):
        closure_offset_m([0.0, 0.0, 0.0], [1.0, 1.0, 0.0])
    with pytest.raises(NonFiniteError, match="end_xy"):
        closure_offset_m([0.0, 0.0], [np.nan, 1.0])


def test_closure_error_of_closed_and_open_routes():
    n = 400
    circle = integrate_poses(np.tile([0.2, 0.2 / 0.5], (n, 1)), 2 * np.pi * 0.5 / 0.2 / n)
    assert closure_error(circle) == pytest.approx(0.0, abs=1e-12)
    batch = np.stack([circle, circle + np.array([0.03, 0.04, 0.0])])
    batch[1, -1, :2] += [0.3, 0.4]
    np.testing.assert_allclose(closure_error(batch), [0.0, 0.5], atol=1e-12)
    with pytest.raises(ShapeError, match=r"\(\.\.\., n, 2\) or \(\.\.\., n, 3\)"):
        closure_error(np.zeros((5, 4)))


# --- ATE -------------------------------------------------------------------


def test_ate_zero_for_identical(trajectory):
    assert ate(trajectory, trajectory) == 0.0
    assert ate(trajectory, trajectory, align=True) == pytest.approx(0.0, abs=1e-12)


def test_ate_constant_offset(trajectory):
    shifted = trajectory + np.array([0.3, -0.4, 0.0])
    stats = ate_stats(trajectory, shifted)
    assert isinstance(stats, TrajectoryError)
    for value in (stats.rmse_m, stats.mean_m, stats.median_m, stats.max_m):
        assert value == pytest.approx(0.5, abs=1e-12)
    assert ate(trajectory[:, :2], shifted[:, :2]) == pytest.approx(0.5)


@pytest.mark.parametrize("angle", [0.0, 0.7, -2.5, np.pi])
def test_ate_rigid_motion_aligns_to_zero(trajectory, angle):
    moved = _se2(trajectory, angle, np.array([2.0, -1.0]))
    stats = ate_stats(trajectory, moved, align=True)
    assert stats.rmse_m == pytest.approx(0.0, abs=1e-10)
    # the alignment found undoes the motion
    assert np.cos(stats.rotation_rad + angle) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(
        _se2(moved, stats.rotation_rad, stats.translation_m)[:, :2], trajectory[:, :2], atol=1e-10
    )
    if angle != 0.0:
        assert ate(trajectory, moved) > 1.0  # without alignment the error is large


def test_ate_alignment_minimises_error(trajectory, rng):
    noisy = _se2(trajectory, 0.3, np.array([0.1, 0.2]))
    noisy[:, :2] += rng.normal(scale=0.05, size=(trajectory.shape[0], 2))
    stats = ate_stats(trajectory, noisy, align=True)
    # perturbing the optimal alignment only increases the error
    for d_angle, d_shift in [(1e-3, [0, 0]), (-1e-3, [0, 0]), (0, [1e-3, 0]), (0, [0, -1e-3])]:
        other = _se2(noisy, stats.rotation_rad + d_angle, stats.translation_m + d_shift)
        assert ate(trajectory, other) > stats.rmse_m
    assert stats.rmse_m == pytest.approx(0.05 * np.sqrt(2), rel=0.15)


def test_ate_batch(trajectory):
    batch_true = np.stack([trajectory, trajectory])
    batch_est = np.stack(
        [trajectory + np.array([0.1, 0.0, 0.0]), _se2(trajectory, 1.0, np.array([1.0, 1.0]))]
    )
    np.testing.assert_allclose(ate(batch_true, batch_est, align=True), [0.0, 0.0], atol=1e-10)
    np.testing.assert_allclose(ate(batch_true, batch_est)[0], 0.1)


def test_ate_errors(trajectory):
    with pytest.raises(ShapeError, match=r"\(401, 3\) and \(400, 3\)"):
        ate(trajectory, trajectory[:-1])
    with pytest.raises(ShapeError, match="at least 2 samples"):
        ate(trajectory[:1], trajectory[:1], align=True)
    bad = trajectory.copy()
    bad[7, 1] = np.nan
    with pytest.raises(NonFiniteError, match=r"est_poses.*\[7, 1\]"):
        ate(trajectory, bad)


# --- RPE -------------------------------------------------------------------


def test_rpe_invariant_to_rigid_motion(trajectory):
    moved = _se2(trajectory, 1.1, np.array([3.0, -2.0]))
    err = rpe(trajectory, moved, delta=10)
    assert isinstance(err, RelativePoseError)
    assert err.trans_rmse_m == pytest.approx(0.0, abs=1e-12)
    assert err.rot_rmse_rad == pytest.approx(0.0, abs=1e-12)
    assert err.n_pairs == trajectory.shape[0] - 10


def test_rpe_scale_error_on_straight_line():
    n = 11
    truth = np.column_stack([np.arange(n) * 0.1, np.zeros(n), np.zeros(n)])
    est = truth * [1.1, 1.0, 1.0]  # 10 % too long
    err = rpe(truth, est, delta=2)
    assert err.trans_rmse_m == pytest.approx(0.02)
    assert err.rot_rmse_rad == 0.0


def test_rpe_heading_offset_gives_lateral_error():
    # The estimate turns 0.1 rad left at the start, then drives 1 m per step
    truth = np.column_stack([np.arange(5.0), np.zeros(5), np.zeros(5)])
    est = integrate_poses(np.tile([1.0, 0.0], (4, 1)), 1.0, initial_pose=[0.0, 0.0, 0.1])
    err = rpe(truth, est, delta=1)
    assert err.rot_rmse_rad == pytest.approx(0.0, abs=1e-15)  # relative motions agree
    assert err.trans_rmse_m == pytest.approx(0.0, abs=1e-12)
    assert ate(truth, est) > 0.1  # but the absolute error grows


def test_rpe_wraps_rotation_error():
    truth = np.zeros((3, 3))
    est = np.zeros((3, 3))
    est[1:, 2] = 2 * np.pi - 0.1  # equivalent to -0.1 rad
    assert rpe(truth, est, delta=1).rot_rmse_rad == pytest.approx(0.1 / np.sqrt(2))


def test_rpe_errors(trajectory):
    with pytest.raises(ValueError, match="delta"):
        rpe(trajectory, trajectory, delta=0)
    with pytest.raises(ValueError, match="delta"):
        rpe(trajectory, trajectory, delta=trajectory.shape[0])
    with pytest.raises(ValueError, match="delta"):
        rpe(trajectory, trajectory, delta=1.5)
    with pytest.raises(ShapeError, match=r"\(\.\.\., n, 3\)"):
        rpe(trajectory[:, :2], trajectory[:, :2], delta=1)
