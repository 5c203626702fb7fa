"""The wall run (docs/intrinsics.md, "Without a reference"): closed-form synthetic passes,
the mirror-pair square-up, and every error path."""

from __future__ import annotations

import numpy as np
import pytest

from lti_motion.calibration.wall_run import (
    WallPass,
    calibrate_wall_run,
    mirror_heading_rad,
    run_path,
)
from lti_motion.exceptions import (
    CalibrationError,
    CalibrationShapeError,
    NoSignalError,
    SaturatedSignalError,
    UnidentifiableError,
)
from lti_motion.intrinsics import OdometryIntrinsics

K = 4.4e-4                      # m/tick
B = 0.235                       # m
NOMINAL = OdometryIntrinsics.symmetric(m_per_tick=K, wheel_base_m=B)
RADIUS = 0.17                   # the bumper's radius: unknown to the estimate
A, C = 4095 * 0.9 * 0.04 ** 2, 0.14     # inverse-square law S = A / (g - C)^2


@pytest.fixture
def rng():
    return np.random.default_rng(20261202)


def synthetic_pass(true: OdometryIntrinsics, *, backoff_m: float, direction: int,
                   theta0_rad: float = 0.0, run_m: float = 2.0, side: str = "left",
                   noise_counts: float = 0.0, rng=None, left_over_right: float = 1.0
                   ) -> WallPass:
    """A run of (nearly) equal counts along a wall at y = 0, the robot's true path from the
    true intrinsics (exact dead reckoning), the signal the inverse-square law of the gap."""
    n = 600
    steps = np.linspace(0.0, run_m / K, n)
    counts = np.round(np.outer(steps, [1.0, left_over_right])).astype(np.int64) * direction
    x, y = run_path(counts, true)
    sign = 1.0 if side == "left" else -1.0
    gap = RADIUS + backoff_m - sign * (y + theta0_rad * x)     # small start heading
    signal = A / (gap - C) ** 2
    if noise_counts:
        signal = signal + noise_counts * rng.standard_normal(n)
    return WallPass(ticks=counts % 65536, signal=np.round(signal), gap_start_m=backoff_m)


def kappa_of(true: OdometryIntrinsics) -> float:
    return NOMINAL.scale_errors_to(true)[2]


TRUE_CASES = [  # (left m/tick, right m/tick) with the mean K: the type B error both ways,
    (1.005 * K, 0.995 * K),     # and none (a travel-scale error k_v would bias kappa by a
    (0.9975 * K, 1.0025 * K),   # relative 2 k_v: second order, see docs/intrinsics.md)
    (K, K),
]


@pytest.mark.parametrize(("k_left", "k_right"), TRUE_CASES)
@pytest.mark.parametrize("side", ["left", "right"])
def test_noise_free_passes_give_the_true_ratio(k_left, k_right, side):
    true = OdometryIntrinsics(k_left, k_right, B)
    passes = [synthetic_pass(true, backoff_m=0.06, direction=1, theta0_rad=0.01, side=side),
              synthetic_pass(true, backoff_m=0.16, direction=-1, theta0_rad=-0.01, side=side)]
    cal = calibrate_wall_run(passes, NOMINAL, wall_side=side)
    assert cal.kappa_rad_per_m == pytest.approx(kappa_of(true), abs=2e-4)
    assert cal.diameter_ratio == pytest.approx(true.diameter_ratio, rel=5e-5)
    assert cal.intrinsics.m_per_tick == pytest.approx(K, rel=1e-9)    # travel scale kept
    np.testing.assert_allclose(cal.heading_rad, [0.01, -0.01], atol=2e-3)
    assert cal.law_slope_per_m == pytest.approx(1.0 / np.sqrt(A), rel=1e-3)


def test_counts_that_differ_are_explained_by_the_intrinsics_in_use():
    """Unequal counts curve the encoders' own path; only the rest is kappa."""
    true = OdometryIntrinsics(1.004 * K, 0.996 * K, B)
    passes = [synthetic_pass(true, backoff_m=0.06, direction=1, left_over_right=1.004),
              synthetic_pass(true, backoff_m=0.16, direction=-1, left_over_right=0.997)]
    cal = calibrate_wall_run(passes, NOMINAL)
    assert cal.diameter_ratio == pytest.approx(true.diameter_ratio, rel=5e-5)


def test_noisy_signal_error_and_reported_spread(rng):
    """With 3 counts of noise the ratio stays within 0.05%, and the reported standard
    deviation matches the spread over 30 seeded realisations within a factor 1.6."""
    true = OdometryIntrinsics(1.01 * K, K, B)
    kappas, stds = [], []
    for _ in range(30):
        passes = [synthetic_pass(true, backoff_m=0.06, direction=1, noise_counts=3.0,
                                 rng=rng),
                  synthetic_pass(true, backoff_m=0.16, direction=-1, noise_counts=3.0,
                                 rng=rng)]
        cal = calibrate_wall_run(passes, NOMINAL)
        assert abs(cal.diameter_ratio / true.diameter_ratio - 1.0) < 5e-4
        kappas.append(cal.kappa_rad_per_m)
        stds.append(cal.kappa_std_rad_per_m)
    ratio = np.mean(stds) / np.std(kappas)
    assert 1 / 1.6 < ratio < 1.6


@pytest.mark.parametrize("start", [NOMINAL, OdometryIntrinsics(0.99 * K, K, 1.02 * B)])
def test_ratio_std_is_the_propagated_curvature_std(start, rng):
    """``diameter_ratio_std`` against a central difference of the ratio in ``kappa``."""
    true = OdometryIntrinsics(1.01 * K, K, B)
    passes = [synthetic_pass(true, backoff_m=0.06, direction=1, noise_counts=3.0, rng=rng),
              synthetic_pass(true, backoff_m=0.16, direction=-1, noise_counts=3.0, rng=rng)]
    cal = calibrate_wall_run(passes, start)
    h = 1e-6
    slope = (start.corrected(0, 0, cal.kappa_rad_per_m + h).diameter_ratio
             - start.corrected(0, 0, cal.kappa_rad_per_m - h).diameter_ratio) / (2 * h)
    assert cal.diameter_ratio_std == pytest.approx(abs(slope) * cal.kappa_std_rad_per_m,
                                                   rel=1e-6)
    assert cal.diameter_ratio_std > 0


def test_one_direction_only_is_noted():
    true = OdometryIntrinsics(1.005 * K, 0.995 * K, B)
    passes = [synthetic_pass(true, backoff_m=0.06, direction=1),
              synthetic_pass(true, backoff_m=0.16, direction=1)]
    cal = calibrate_wall_run(passes, NOMINAL)
    assert any("one direction" in note for note in cal.notes)
    assert cal.diameter_ratio == pytest.approx(true.diameter_ratio, rel=5e-5)


def test_run_path_is_an_arc_for_unequal_wheels():
    k = OdometryIntrinsics(K, 1.02 * K, B)
    counts = np.outer(np.arange(0, 4001, 10), [1, 1])
    x, y = run_path(counts, k)
    s = 4000 * k.m_per_tick
    curvature = (k.m_per_tick_right - k.m_per_tick_left) / (B * k.m_per_tick)
    assert x[-1] == pytest.approx(np.sin(curvature * s) / curvature, rel=1e-6)
    assert y[-1] == pytest.approx((1 - np.cos(curvature * s)) / curvature, rel=1e-5)


def _good_passes():
    true = OdometryIntrinsics(1.01 * K, K, B)
    return [synthetic_pass(true, backoff_m=0.06, direction=1),
            synthetic_pass(true, backoff_m=0.16, direction=-1)]


def test_one_pass_is_not_enough():
    with pytest.raises(UnidentifiableError, match="two passes"):
        calibrate_wall_run(_good_passes()[:1], NOMINAL)


def test_alike_backoffs_cannot_fix_the_law():
    passes = _good_passes()
    passes[1] = WallPass(passes[1].ticks, passes[1].signal, gap_start_m=0.07)
    with pytest.raises(UnidentifiableError, match="back off by distances"):
        calibrate_wall_run(passes, NOMINAL)


def test_a_short_run_is_refused():
    true = OdometryIntrinsics(1.01 * K, K, B)
    passes = [synthetic_pass(true, backoff_m=0.06, direction=1, run_m=0.5),
              synthetic_pass(true, backoff_m=0.16, direction=-1)]
    with pytest.raises(UnidentifiableError, match=r"pass 1 runs 0\.50 m"):
        calibrate_wall_run(passes, NOMINAL)


def test_no_wall_seen():
    passes = _good_passes()
    passes[1] = WallPass(passes[1].ticks, np.zeros(len(passes[1].signal)), 0.16)
    with pytest.raises(NoSignalError, match=r"pass 2: .* no wall seen"):
        calibrate_wall_run(passes, NOMINAL)


def test_saturated_signal():
    passes = _good_passes()
    passes[0] = WallPass(passes[0].ticks, np.full(len(passes[0].signal), 4095), 0.06)
    with pytest.raises(SaturatedSignalError, match=r"pass 1: .* saturated"):
        calibrate_wall_run(passes, NOMINAL)


def test_a_signal_that_does_not_fall_with_the_gap():
    passes = _good_passes()
    flat = [WallPass(p.ticks, 500.0 + 0.0 * p.signal, p.gap_start_m) for p in passes]
    with pytest.raises(UnidentifiableError):
        calibrate_wall_run(flat, NOMINAL)


def test_shapes_and_sides_are_checked():
    with pytest.raises(CalibrationShapeError, match=r"\(n, 2\)"):
        WallPass(np.zeros((5, 3)), np.zeros(5), 0.1)
    with pytest.raises(CalibrationShapeError, match="finite"):
        WallPass(np.zeros((2, 2)), np.array([1.0, np.nan]), 0.1)
    with pytest.raises(ValueError, match="wall_side"):
        calibrate_wall_run(_good_passes(), NOMINAL, wall_side="up")
    assert issubclass(SaturatedSignalError, CalibrationError)
    assert issubclass(SaturatedSignalError, ValueError)


def _lobe(angle_rad):
    """A sensor's signal ``angle_rad`` off square to a wall: falls both ways."""
    return 2000.0 * np.cos(angle_rad) ** 3 / (1.0 + 2.0 * angle_rad ** 2)


@pytest.mark.parametrize(("square", "gain", "mount"), [(0.0, 1.0, 0.23), (0.08, 0.7, 0.23),
                                                       (-0.12, 1.3, 0.4)])
def test_mirror_heading_finds_the_square(square, gain, mount, rng):
    phi = np.concatenate([np.linspace(0.0, 0.5, 200), np.linspace(0.5, -0.5, 400),
                          np.linspace(-0.5, 0.0, 200)])
    left = _lobe(phi - square + mount) + 3.0 * rng.standard_normal(len(phi))
    right = gain * _lobe(phi - square - mount) + 3.0 * rng.standard_normal(len(phi))
    assert mirror_heading_rad(phi, left, right) == pytest.approx(square, abs=0.004)


def test_mirror_heading_needs_a_wide_enough_scan():
    phi = np.linspace(-0.2, 0.2, 100)
    with pytest.raises(UnidentifiableError, match="turn at least"):
        mirror_heading_rad(phi, _lobe(phi + 0.2), _lobe(phi - 0.2))
