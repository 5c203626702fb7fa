"""OdometryIntrinsics: validation, the symmetric constructor, and odometry with per-wheel scales."""

import numpy as np
import pytest

from lti_motion.exceptions import ShapeError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import body_from_wheel
from lti_motion.recordings.ticks import body_speeds_from_ticks


@pytest.mark.parametrize("field", ["m_per_tick_left", "m_per_tick_right", "wheel_base_m"])
@pytest.mark.parametrize("bad", [0.0, -1e-4, np.nan, np.inf])
def test_rejects_non_positive_or_non_finite(field, bad):
    values = {"m_per_tick_left": 4e-4, "m_per_tick_right": 4e-4, "wheel_base_m": 0.235}
    values[field] = bad
    with pytest.raises(ValueError, match=field):
        OdometryIntrinsics(**values)


def test_symmetric_matches_one_scale():
    k = OdometryIntrinsics.symmetric(m_per_tick=4.4e-4, wheel_base_m=0.235)
    assert k.m_per_tick_left == k.m_per_tick_right == k.m_per_tick == 4.4e-4
    assert k.diameter_ratio == 1.0


def test_body_motion_is_body_from_wheel_of_each_wheels_travel(rng):
    k = OdometryIntrinsics(4.5e-4, 4.3e-4, 0.24)
    dn = rng.integers(-300, 300, size=(50, 2))
    travel = dn * [4.5e-4, 4.3e-4]
    np.testing.assert_allclose(k.body_motion(dn), body_from_wheel(travel, wheel_base_m=0.24),
                               rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(k.wheel_travel_m(dn), travel, rtol=1e-12)
    with pytest.raises(ShapeError, match=r"\(\.\.\., 2\)"):
        k.body_motion(np.zeros((4, 3)))


def test_body_speeds_from_ticks_takes_intrinsics_and_keeps_old_signature(rng):
    ticks = np.cumsum(rng.integers(0, 40, size=(30, 2)), axis=0) % 65536
    t = np.arange(30) * 0.015
    old = body_speeds_from_ticks(ticks, t, m_per_tick=4.4e-4, wheel_base_m=0.235)
    new = body_speeds_from_ticks(
        ticks, t, intrinsics=OdometryIntrinsics.symmetric(m_per_tick=4.4e-4, wheel_base_m=0.235))
    np.testing.assert_array_equal(old, new)
    uneven = body_speeds_from_ticks(ticks, t, intrinsics=OdometryIntrinsics(4.4e-4, 4.0e-4, 0.235))
    d = np.diff(ticks, axis=0) * [4.4e-4, 4.0e-4] / 0.015
    np.testing.assert_allclose(uneven, body_from_wheel(d, wheel_base_m=0.235), rtol=1e-12)


def test_body_speeds_from_ticks_scale_given_twice_or_never():
    ticks, t = np.zeros((3, 2), int), np.arange(3.0)
    with pytest.raises(ValueError, match="not both"):
        body_speeds_from_ticks(ticks, t, m_per_tick=1e-3, wheel_base_m=0.2,
                               intrinsics=OdometryIntrinsics(1e-3, 1e-3, 0.2))
    with pytest.raises(ValueError, match="give the encoder scale"):
        body_speeds_from_ticks(ticks, t, m_per_tick=1e-3)


def test_scale_errors_round_trip_and_match_the_ground_motion():
    """corrected() and scale_errors_to() invert each other, and the errors they give
    reproduce the new intrinsics' body motion from the old one (module docstring)."""
    rng = np.random.default_rng(4)
    for _ in range(50):
        old = OdometryIntrinsics(*rng.uniform(3e-4, 6e-4, 2), rng.uniform(0.15, 0.5))
        new = OdometryIntrinsics(old.m_per_tick_left * rng.uniform(0.95, 1.05),
                                 old.m_per_tick_right * rng.uniform(0.95, 1.05),
                                 old.wheel_base_m * rng.uniform(0.95, 1.05))
        k_v, k_w, kappa = old.scale_errors_to(new)
        back = old.corrected(k_v, k_w, kappa)
        np.testing.assert_allclose([back.m_per_tick_left, back.m_per_tick_right,
                                    back.wheel_base_m],
                                   [new.m_per_tick_left, new.m_per_tick_right,
                                    new.wheel_base_m], rtol=1e-12)
        ticks = rng.integers(-500, 500, size=2)
        ds, dth = old.body_motion(ticks)
        b_new = new.wheel_base_m
        expected = [(1 + k_v) * ds + kappa * b_new * old.wheel_base_m * dth / 4,
                    (1 + k_w) * dth + kappa * ds]
        np.testing.assert_allclose(new.body_motion(ticks), expected, rtol=1e-10, atol=1e-15)


def test_corrected_refuses_impossible_errors():
    k = OdometryIntrinsics.symmetric(m_per_tick=4e-4, wheel_base_m=0.2)
    with pytest.raises(ValueError, match="m_per_tick_left"):
        k.corrected(-1.5, 0.0, 0.0)
