"""The robot description a model carries: validation, round trip, and the one-line checks."""

import math

import pytest

from lti_motion.exceptions import RobotMismatchError
from lti_motion.robot_description import (
    GEOMETRY_TOLERANCE,
    PERIOD_TOLERANCE,
    RobotDescription,
)

WAFFLE = RobotDescription(wheel_data="wheel_angles_rad", wheel_base_m=0.287, dt_s=1 / 30,
                          encoders="quadrature", ticks_per_rad=4096 / (2 * math.pi),
                          wheel_radius_m=0.033, robot="turtlebot3_waffle")


def test_round_trip_and_derived_scale():
    again = RobotDescription.from_dict(WAFFLE.as_dict())
    assert again == WAFFLE and hash(again) == hash(WAFFLE)
    assert WAFFLE.ticks_per_rev == pytest.approx(4096)
    assert WAFFLE.m_per_tick == pytest.approx((0.033 * 2 * math.pi / 4096,) * 2)


@pytest.mark.parametrize(("change", "match"), [
    ({"wheel_base_m": 0.0}, "wheel_base_m must be positive"),
    ({"dt_s": math.nan}, "dt_s must be positive"),
    ({"wheel_radius_m": (0.033, -1)}, "wheel_radius_m must be positive"),
    ({"wheel_radius_m": (1, 2, 3)}, r"one number or \(left, right\)"),
    ({"encoders": "hall"}, "encoders must be"),
    ({"wheel_data": "pulses"}, "wheel_data must be one of"),
    ({"counter_bits": 65}, "counter_bits must be 1..64"),
])
def test_invalid_descriptions_are_refused(change, match):
    with pytest.raises(ValueError, match=match):
        RobotDescription(**{**WAFFLE.as_dict(), **change})


def test_unknown_keys_are_refused():
    with pytest.raises(ValueError, match=r"unknown keys \['mass_kg'\]"):
        RobotDescription.from_dict({**WAFFLE.as_dict(), "mass_kg": 1.8})


@pytest.mark.parametrize(("change", "match"), [
    ({"dt_s": 0.015}, r"sensor period of 15 ms, the model 33.3333 ms"),
    ({"wheel_base_m": 0.235}, r"wheel base of 0.235 m, the model 0.287 m"),
    ({"wheel_radius_m": 0.036}, r"wheel radius of 0.036 m, the model 0.033 m"),
    ({"encoders": "commanded"}, "commanded encoders, the model quadrature ones"),
    ({"wheel_data": "body_speeds"}, "odometry twist"),
])
def test_a_recording_of_another_robot_is_refused_in_one_line(change, match):
    other = RobotDescription(**{**WAFFLE.as_dict(), **change})
    with pytest.raises(RobotMismatchError, match=match) as info:
        WAFFLE.check(other)
    assert "\n" not in str(info.value)


def test_within_the_tolerances_it_agrees():
    near = RobotDescription(**{**WAFFLE.as_dict(),
                               "dt_s": WAFFLE.dt_s * (1 + 0.9 * PERIOD_TOLERANCE),
                               "wheel_base_m": 0.287 * (1 - 0.9 * GEOMETRY_TOLERANCE)})
    assert WAFFLE.disagreement(near) is None
