"""Tests of lti_motion.calibration.encoder_scale on synthetic rotation-in-place recordings.

The generator below stands in for the physics simulator: a Create 2-like robot
turns in place at a varying speed inside a room of axis-aligned walls and
boxes; six light-bump sensors on the bumper look out at +-65, +-40 and +-12
degrees from forward; each reads ``f(range, incidence)``, decreasing with
range and saturating at 4095, blurred over a beam of a few degrees, with noise
and an ambient offset; the encoders count each wheel's travel in whole ticks on
16-bit counters that wrap.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest

from lti_motion.calibration.encoder_scale import (
    RotationPeriod,
    encoder_scale_m_per_tick,
    rotation_period_ticks,
)
from lti_motion.exceptions import (
    CalibrationError,
    CalibrationNonFiniteError,
    CalibrationShapeError,
    NonFiniteError,
    NoSignalError,
    NotPeriodicError,
    ShapeError,
)
from lti_motion.recordings.ticks import unwrap_ticks

WHEEL_BASE_M = 0.235  # Create 2
M_PER_TICK = np.pi * 0.072 / 508.8  # 72 mm wheels, 508.8 ticks per revolution
SENSOR_ANGLES_RAD = np.deg2rad([65.0, 40.0, 12.0, -12.0, -40.0, -65.0])  # packets 46..51
MOUNT_RADIUS_M = 0.16
BEAM_OFFSETS_RAD = np.deg2rad([-8.0, -4.0, 0.0, 4.0, 8.0])
BEAM_WEIGHTS = np.exp(-0.5 * np.array([-2.0, -1.0, 0.0, 1.0, 2.0]) ** 2)
SATURATION_RANGE_M = 0.1  # a white wall at 0.1 m reads 4095


@dataclass(frozen=True)
class Scene:
    """A room ``(x0, y0, x1, y1)`` [m] with boxes inside and the robot's turning centre."""

    room: tuple[float, float, float, float]
    centre: tuple[float, float]
    boxes: list[tuple[float, float, float, float]] = field(default_factory=list)


def _ray_range(origin: np.ndarray, direction: np.ndarray, scene: Scene):
    """Range [m] to the nearest surface along each ray, and the incidence cosine there."""
    ox, oy = origin[:, 0], origin[:, 1]
    dx, dy = direction[:, 0], direction[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_x, inv_y = 1.0 / dx, 1.0 / dy
        x0, y0, x1, y1 = scene.room  # from inside the room: the exit distance
        tx = np.where(dx > 0, (x1 - ox) * inv_x, (x0 - ox) * inv_x)
        ty = np.where(dy > 0, (y1 - oy) * inv_y, (y0 - oy) * inv_y)
        best = np.minimum(tx, ty)
        cos_inc = np.where(tx < ty, np.abs(dx), np.abs(dy))
        for bx0, by0, bx1, by1 in scene.boxes:  # slab method
            ax, bx = (bx0 - ox) * inv_x, (bx1 - ox) * inv_x
            ay, by = (by0 - oy) * inv_y, (by1 - oy) * inv_y
            near_x, near_y = np.minimum(ax, bx), np.minimum(ay, by)
            near = np.maximum(near_x, near_y)
            far = np.minimum(np.maximum(ax, bx), np.maximum(ay, by))
            hit = (near <= far) & (near > 0) & (near < best)
            best = np.where(hit, near, best)
            cos_inc = np.where(hit, np.where(near_x > near_y, np.abs(dx), np.abs(dy)), cos_inc)
    return best, cos_inc


def light_bumps(xy: np.ndarray, heading: np.ndarray, scene: Scene, rng, *, noise: float):
    """Six IR readings (n, 6) in 0..4095 for robot positions (n, 2) and headings (n,)."""
    out = np.zeros((heading.size, 6))
    for c, beta in enumerate(SENSOR_ANGLES_RAD):
        mount = heading + beta
        origin = xy + MOUNT_RADIUS_M * np.column_stack([np.cos(mount), np.sin(mount)])
        for offset, weight in zip(BEAM_OFFSETS_RAD, BEAM_WEIGHTS, strict=True):
            ray = mount + offset
            r, cos_inc = _ray_range(origin, np.column_stack([np.cos(ray), np.sin(ray)]), scene)
            out[:, c] += weight * cos_inc * (SATURATION_RANGE_M / np.maximum(r, 1e-3)) ** 2
    counts = 4095.0 * out / BEAM_WEIGHTS.sum() + 2.0 + rng.normal(0.0, noise, out.shape)
    return np.clip(np.round(counts), 0, 4095).astype(np.int64)


@dataclass(frozen=True)
class Recording:
    light_bump: np.ndarray  # (n, 6) counts
    tick_diff: np.ndarray  # (n,) unwrapped right - left ticks
    wheel_steps: np.ndarray  # (n - 1, 2) ticks per frame
    period_ticks: float  # the truth: 2 pi b / scale
    m_per_tick: float


def rotate_in_place(
    rng,
    scene: Scene,
    *,
    turns: float,
    m_per_tick: float = M_PER_TICK,
    ccw: bool = True,
    noise: float = 3.0,
    drift_m_per_turn: float = 0.001,
) -> Recording:
    """Frames every ~15 ms of a rotation in place at a varying speed, standstill at both ends."""
    w_mean = rng.uniform(1.5, 4.0)  # 6 to 16 ticks per wheel and frame on average
    phase = rng.uniform(0.0, 2 * np.pi)
    total = 2 * np.pi * turns
    rates = [0.0] * int(rng.integers(3, 8))
    dts = [0.015] * len(rates)
    angle = t = 0.0
    while angle < total:
        dt = 0.015 + rng.normal(0.0, 0.001)
        ramp = min(1.0, t / 0.4, max(0.05, (total - angle) / 0.6))
        rate = ramp * w_mean * (1.0 + 0.35 * np.sin(2 * np.pi * t / 2.3 + phase))
        rates.append(rate)
        dts.append(dt)
        angle += rate * dt
        t += dt
    n_stop = int(rng.integers(3, 8))
    rates, dts = np.array(rates + [0.0] * n_stop), np.array(dts + [0.015] * n_stop)
    turned = np.cumsum(rates * dts)
    sign = 1.0 if ccw else -1.0
    heading = rng.uniform(0.0, 2 * np.pi) + sign * turned
    drift = rng.uniform(0.0, 2 * np.pi)
    xy = np.asarray(scene.centre) + np.outer(
        drift_m_per_turn * turned / (2 * np.pi), [np.cos(drift), np.sin(drift)]
    )
    ir = light_bumps(xy, heading, scene, rng, noise=noise)
    arc = 0.5 * WHEEL_BASE_M * turned  # each wheel's travel [m]
    start, frac = rng.integers(60000, 65536, size=2), rng.uniform(0.0, 1.0, size=2)
    raw_left = (start[0] + np.floor(-sign * arc / m_per_tick + frac[0]).astype(np.int64)) % 65536
    raw_right = (start[1] + np.floor(sign * arc / m_per_tick + frac[1]).astype(np.int64)) % 65536
    left, right = unwrap_ticks(raw_left), unwrap_ticks(raw_right)
    return Recording(
        light_bump=ir,
        tick_diff=right - left,
        wheel_steps=np.abs(np.diff(np.column_stack([left, right]), axis=0)),
        period_ticks=2 * np.pi * WHEEL_BASE_M / m_per_tick,
        m_per_tick=m_per_tick,
    )


def cluttered_room(rng) -> Scene:
    """Robot near a corner of a small room with three boxes around it at 0.35-0.6 m."""
    room = (0.0, 0.0, rng.uniform(1.6, 2.4), rng.uniform(1.4, 2.0))
    centre = (rng.uniform(0.35, 0.55), rng.uniform(0.35, 0.55))
    boxes = []
    for _ in range(3):
        bearing, dist = rng.uniform(0.0, 2 * np.pi), rng.uniform(0.35, 0.6)
        cx, cy = centre[0] + dist * np.cos(bearing), centre[1] + dist * np.sin(bearing)
        hw, hh = rng.uniform(0.02, 0.15, size=2)
        boxes.append((cx - hw, cy - hh, cx + hw, cy + hh))
    return Scene(room=room, centre=centre, boxes=boxes)


def single_wall(rng) -> Scene:
    """One wall at 0.25-0.4 m; the others 3.6 m or more away (out of range)."""
    return Scene(room=(0.0, 0.0, 8.0, 8.0), centre=(rng.uniform(0.25, 0.4), 4.0))


def _relative_error(result: RotationPeriod, rec: Recording) -> float:
    return result.period_ticks / rec.period_ticks - 1.0


def _random_recording(seed: int, scene_factory, **kwargs) -> Recording:
    rng = np.random.default_rng(seed)
    scene = scene_factory(rng)
    kwargs.setdefault("turns", rng.uniform(2.1, 3.0))
    kwargs.setdefault("m_per_tick", M_PER_TICK * rng.uniform(0.95, 1.05))  # floor-dependent
    return rotate_in_place(rng, scene, ccw=bool(seed % 2), **kwargs)


# --- the synthetic data is what the module docstring describes ---------------


def test_generator_is_realistic():
    rec = _random_recording(3, single_wall)
    moving = rec.wheel_steps[rec.wheel_steps.sum(axis=1) > 0]
    assert 5 <= np.median(moving) <= 30  # ticks per wheel per frame
    assert np.ptp(moving) >= 8  # the rotation speed varies
    assert rec.light_bump.dtype == np.int64
    assert rec.light_bump.min() >= 0 and rec.light_bump.max() <= 4095
    room = _random_recording(5, cluttered_room)
    assert np.all(np.ptp(room.light_bump, axis=0) > 100)  # every channel sees something


# --- precision ----------------------------------------------------------------


@pytest.mark.parametrize("scene_factory", [cluttered_room, single_wall])
def test_period_within_0p2_percent_over_seeds(scene_factory):
    errors = []
    for seed in range(24):
        rec = _random_recording(seed, scene_factory)
        result = rotation_period_ticks(rec.light_bump, rec.tick_diff)
        errors.append(_relative_error(result, rec))
        assert result.confidence > 0.8
        assert result.n_turns == pytest.approx(
            (rec.tick_diff.max() - rec.tick_diff.min()) / rec.period_ticks, rel=0.01
        )
    errors = np.array(errors)
    assert np.max(np.abs(errors)) < 2e-3
    assert np.sqrt(np.mean(errors**2)) < 1e-3  # aim: 0.1 % RMS


def test_single_wall_uses_peak_detector():
    rec = _random_recording(4, single_wall)
    result = rotation_period_ticks(rec.light_bump, rec.tick_diff)
    assert result.method == "peaks"
    assert result.channels == (0, 1, 2, 3, 4, 5)
    assert abs(_relative_error(result, rec)) < 2e-4


@pytest.mark.parametrize("method", ["autocorr", "peaks"])
def test_explicit_methods_on_single_wall(method):
    rec = _random_recording(6, single_wall)
    result = rotation_period_ticks(rec.light_bump, rec.tick_diff, method=method)
    assert result.method == method
    assert abs(_relative_error(result, rec)) < 5e-4


def test_saturated_close_wall():
    rng = np.random.default_rng(10)
    rec = rotate_in_place(rng, Scene(room=(0.0, 0.0, 8.0, 8.0), centre=(0.21, 4.0)), turns=2.3)
    saturated = np.mean(rec.light_bump == 4095)
    assert saturated > 0.02  # flat tops on every bump
    result = rotation_period_ticks(rec.light_bump, rec.tick_diff)
    assert abs(_relative_error(result, rec)) < 5e-4


def test_clockwise_rotation_and_noise_free():
    rng = np.random.default_rng(11)
    rec = rotate_in_place(rng, cluttered_room(rng), turns=2.6, ccw=False, noise=0.0)
    assert rec.tick_diff[-1] < 0
    result = rotation_period_ticks(rec.light_bump, rec.tick_diff)
    assert abs(_relative_error(result, rec)) < 1e-3


def test_encoder_scale_recovers_simulated_scale():
    rec = _random_recording(21, cluttered_room, m_per_tick=M_PER_TICK * 1.03)
    period = rotation_period_ticks(rec.light_bump, rec.tick_diff).period_ticks
    scale = encoder_scale_m_per_tick(period, wheel_base_m=WHEEL_BASE_M)
    assert scale == pytest.approx(rec.m_per_tick, rel=2e-3)


def test_eq13_algebra_one_exact_turn():
    # one turn in place: each wheel travels pi b, right forwards and left backwards
    right_ticks = np.pi * WHEEL_BASE_M / M_PER_TICK
    left_ticks = -right_ticks
    scale = encoder_scale_m_per_tick(right_ticks - left_ticks, wheel_base_m=WHEEL_BASE_M)
    assert scale == pytest.approx(M_PER_TICK, rel=1e-15)
    assert right_ticks - left_ticks == pytest.approx(3321.33, abs=0.01)  # Create 2 numbers


def test_off_centre_corridor_is_not_half_a_turn():
    # two walls, 0.3 m and 0.45 m away: two bumps per turn, of different heights
    rng = np.random.default_rng(8)
    scene = Scene(room=(0.0, 0.0, 20.0, 0.75), centre=(10.0, 0.3))
    rec = rotate_in_place(rng, scene, turns=2.5)
    result = rotation_period_ticks(rec.light_bump, rec.tick_diff)
    assert abs(_relative_error(result, rec)) < 2e-3


def test_period_range_resolves_symmetric_corridor():
    # centred between identical walls the signal repeats every half turn; a
    # datasheet range for the period picks the full turn
    rng = np.random.default_rng(9)
    scene = Scene(room=(0.0, 0.0, 20.0, 0.7), centre=(10.0, 0.35))
    rec = rotate_in_place(rng, scene, turns=2.5, drift_m_per_turn=0.0)
    half = rotation_period_ticks(rec.light_bump, rec.tick_diff, method="autocorr")
    assert half.period_ticks == pytest.approx(rec.period_ticks / 2, rel=2e-3)
    nominal = 2 * np.pi * WHEEL_BASE_M / M_PER_TICK
    full = rotation_period_ticks(
        rec.light_bump, rec.tick_diff, period_range_ticks=(0.7 * nominal, 1.3 * nominal)
    )
    assert abs(_relative_error(full, rec)) < 2e-3


def test_peak_detector_resolves_ambiguous_autocorrelation():
    # a strong signal that repeats every half turn (a symmetric corridor seen by one
    # channel) next to two small bumps once per turn: the autocorrelation alone
    # picks the half turn, the bumps settle it
    rng = np.random.default_rng(15)
    period = 3321.3
    d = np.cumsum(np.r_[0, rng.integers(10, 60, 320)])
    angle = 2 * np.pi * d / period

    def bump(phase):
        return 200.0 * np.exp(-0.5 * (np.angle(np.exp(1j * (angle - phase))) / 0.15) ** 2)

    sig = np.column_stack([bump(0.3), bump(1.0), 1500.0 + 1400.0 * np.cos(2 * angle)])
    sig = np.round(sig + rng.normal(0.0, 3.0, sig.shape))
    alone = rotation_period_ticks(sig, d, method="autocorr")
    assert alone.period_ticks == pytest.approx(period / 2, rel=1e-3)
    result = rotation_period_ticks(sig, d)
    assert result.method == "peaks"
    assert result.channels == (0, 1)
    assert result.period_ticks == pytest.approx(period, rel=1e-3)


def test_single_channel_input():
    rec = _random_recording(12, single_wall)
    result = rotation_period_ticks(rec.light_bump[:, 2], rec.tick_diff)
    assert result.channels == (0,)
    assert abs(_relative_error(result, rec)) < 1e-3


# --- errors -------------------------------------------------------------------


@pytest.mark.parametrize("scene_factory", [cluttered_room, single_wall])
def test_fewer_than_two_turns_is_rejected(scene_factory):
    rec = _random_recording(13, scene_factory, turns=1.7)
    with pytest.raises(NotPeriodicError, match="two full turns"):
        rotation_period_ticks(rec.light_bump, rec.tick_diff)


def test_nothing_in_range():
    rng = np.random.default_rng(14)
    rec = rotate_in_place(rng, Scene(room=(0.0, 0.0, 10.0, 10.0), centre=(5.0, 5.0)), turns=2.5)
    with pytest.raises(NoSignalError, match="nothing was within sensor range"):
        rotation_period_ticks(rec.light_bump, rec.tick_diff)


def test_not_rotating():
    with pytest.raises(NotPeriodicError, match="did not rotate"):
        rotation_period_ticks(np.full((50, 6), 100), np.full(50, 7))


def test_aperiodic_signal_is_rejected(rng):
    tick_diff = np.cumsum(rng.integers(10, 60, 600))
    walk = np.clip(np.cumsum(rng.normal(0.0, 30.0, (600, 6)), axis=0) + 1000, 0, 4095)
    with pytest.raises(NotPeriodicError, match="rotate at least two full turns"):
        rotation_period_ticks(walk, tick_diff, method="autocorr")
    with pytest.raises(NotPeriodicError):
        rotation_period_ticks(rng.normal(500.0, 50.0, (600, 6)), tick_diff)


def test_shape_and_nan_errors():
    ir, d = np.zeros((10, 6)), np.arange(10)
    with pytest.raises(CalibrationShapeError, match=r"\(10, 6\) and \(9,\)") as info:
        rotation_period_ticks(ir, d[:-1])
    assert isinstance(info.value, ShapeError) and isinstance(info.value, CalibrationError)
    bad = ir.copy()
    bad[4, 2] = np.nan
    with pytest.raises(CalibrationNonFiniteError, match=r"signals.*\[4, 2\]") as info:
        rotation_period_ticks(bad, d)
    assert isinstance(info.value, NonFiniteError) and isinstance(info.value, CalibrationError)
    with pytest.raises(ValueError, match="method"):
        rotation_period_ticks(ir, d, method="fft")
    with pytest.raises(ValueError, match="grid_step_ticks"):
        rotation_period_ticks(ir, d, grid_step_ticks=0.0)
    with pytest.raises(ValueError, match="period_range_ticks"):
        rotation_period_ticks(ir, d, period_range_ticks=(4000.0, 3000.0))


@pytest.mark.parametrize(("period", "base"), [(0.0, 0.235), (-3.0, 0.235), (3321.0, np.nan)])
def test_encoder_scale_rejects_bad_input(period, base):
    with pytest.raises(ValueError, match="positive and finite"):
        encoder_scale_m_per_tick(period, wheel_base_m=base)
