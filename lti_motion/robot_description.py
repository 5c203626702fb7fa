"""The robot a model was calibrated on: how its recording's wheel data became wheel travel.

A :class:`~lti_motion.model.MotionModel` predicts body speeds from commands, and an
estimator turns a recording's wheel data into travel with the model's encoder scale.
That scale means something only with the robot it came from: how the wheels were
measured (raw counts, joint angles, the robot's own odometry twist), how the encoders
count (in the commanded direction, like a Roomba's, or in quadrature), the counts per
wheel radian, each wheel's radius and metres per count, the wheel base, the counter's
width and the sensor period. :class:`RobotDescription` holds these numbers and where
each came from; it is saved in the model's file (:mod:`lti_motion.model.motion_model`,
version 3), and a recording replayed with the model is checked against it
(:meth:`RobotDescription.disagreement`) instead of being read with another robot's
numbers.

For wheel angles ``phi`` [rad] the travel of a wheel is ``r * phi`` and its count
``n = phi * ticks_per_rad``, so ``m_per_tick = r / ticks_per_rad``; for raw counts the
travel is ``m_per_tick * n`` (paper eq. 13 for the scale's measurement).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Literal

from lti_motion.exceptions import RobotMismatchError

__all__ = ["ANGLE_COUNTS_PER_RAD", "GEOMETRY_TOLERANCE", "PERIOD_TOLERANCE", "WHEEL_DATA",
           "RobotDescription"]

#: Counts per radian that wheel angles are counted in when no encoder resolution is given
#: (``--ticks-per-rad``): 1e-4 rad a count, finer than any wheel encoder (a 4096-count
#: encoder's is 1.5e-3 rad), so the count adds no rounding to the angles a recording holds;
#: the model's encoder scale is then ``wheel_radius_m / ANGLE_COUNTS_PER_RAD``.
ANGLE_COUNTS_PER_RAD = 1e4

#: Relative tolerance between two sensor periods (a recording's and a model's): 5 %,
#: wider than a real clock's drift (a Roomba's 15 ms runs 1 % off nominal) and far below
#: the rate of another robot (15 ms against 33 ms is 120 %).
PERIOD_TOLERANCE = 0.05
#: Relative tolerance between two geometries (wheel radius, wheel base, metres per count):
#: 2 %, wider than a URDF's rounding (0.033 of 0.0330) and a worn tyre, below any other robot
#: (a Create 2's 0.036 m radius against a TurtleBot3's 0.033 m is 9 % off).
GEOMETRY_TOLERANCE = 0.02

#: How a recording's wheel data can arrive, and what it is (the wheel kinds of
#: :data:`lti_motion.recordings.WHEEL_KINDS`).
WHEEL_DATA = MappingProxyType({
    "counts": "raw encoder counts",
    "wheel_angles_rad": "wheel angles [rad] (e.g. sensor_msgs/JointState)",
    "wheel_speeds_rad_s": "wheel speeds [rad/s]",
    "wheel_speeds_m_s": "wheel speeds [m/s]",
    "body_speeds": "the robot's odometry twist (v, w)",
})

WheelData = Literal["counts", "wheel_angles_rad", "wheel_speeds_rad_s", "wheel_speeds_m_s",
                    "body_speeds"]
EncoderKind = Literal["commanded", "quadrature"]


def _positive(name: str, value: object) -> float:
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"RobotDescription.{name} must be a number, got {value!r}") from None
    if not (math.isfinite(number) and number > 0):
        raise ValueError(f"RobotDescription.{name} must be positive and finite, got {number}")
    return number


def _pair(name: str, value: object) -> tuple[float, float] | None:
    """``None``, one number for both wheels, or (left, right)."""
    if value is None:
        return None
    if isinstance(value, (int, float)):
        value = (value, value)
    try:
        left, right = value  # type: ignore[misc]
    except (TypeError, ValueError):
        raise ValueError(f"RobotDescription.{name} must be one number or (left, right), got "
                         f"{value!r}") from None
    return _positive(name, left), _positive(name, right)


def _off(a: float, b: float) -> float:
    """Relative difference of two positive numbers, against the second."""
    return abs(a - b) / b


@dataclass(frozen=True)
class RobotDescription:
    """The robot a recording came from, as its wheel data became wheel travel [m, s, rad].

    Attributes
    ----------
    wheel_data : {"counts", "wheel_angles_rad", "wheel_speeds_rad_s", "wheel_speeds_m_s", \
"body_speeds"}
        What the recording measured at the wheels (:data:`WHEEL_DATA`).
    wheel_base_m : float
        Distance between the wheels' contact points [m].
    dt_s : float
        Sensor period the model runs at [s].
    encoders : {"commanded", "quadrature"}
        How the wheel data counts: ``"commanded"`` in the commanded direction (a Roomba
        or Create 2), ``"quadrature"`` knowing which way the wheel turns (most ROS robots).
    ticks_per_rad : float or None
        Encoder counts per wheel radian (``ticks_per_rev / (2 pi)``); ``None`` when the
        wheel data are not counts nor angles, or not known.
    wheel_radius_m : tuple of float or None
        Each wheel's radius (left, right) [m]; one number is taken for both.
    m_per_tick : tuple of float or None
        Each wheel's travel per count (left, right) [m/tick]; for wheel angles
        ``wheel_radius_m / ticks_per_rad``.
    counter_bits : int or None
        Width of the wheel counters (16 for a Roomba; ``None``: they do not wrap).
    robot : str or None
        The robot's name (a robot file's, a URDF's, the bag's).
    sources : mapping of str to str
        Where each number came from (``{"wheel_radius_m": "--wheel-radius", ...}``).

    Raises
    ------
    ValueError
        On a non-positive or non-finite number, an unknown wheel data or encoder kind,
        or a counter width outside 1..64.

    Examples
    --------
    >>> robot = RobotDescription(wheel_data="wheel_angles_rad", wheel_base_m=0.287,
    ...                          dt_s=1 / 30, encoders="quadrature", ticks_per_rad=651.9,
    ...                          wheel_radius_m=0.033, robot="turtlebot3_waffle")
    >>> robot.wheel_radius_m, round(robot.m_per_tick[0], 9)
    ((0.033, 0.033), 5.0621e-05)
    >>> RobotDescription.from_dict(robot.as_dict()) == robot
    True
    """

    wheel_data: WheelData
    wheel_base_m: float
    dt_s: float
    encoders: EncoderKind = "quadrature"
    ticks_per_rad: float | None = None
    wheel_radius_m: tuple[float, float] | None = None
    m_per_tick: tuple[float, float] | None = None
    counter_bits: int | None = None
    robot: str | None = None
    sources: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        setf = object.__setattr__
        if self.wheel_data not in WHEEL_DATA:
            raise ValueError(f"RobotDescription.wheel_data must be one of {list(WHEEL_DATA)}, "
                             f"got {self.wheel_data!r}")
        if self.encoders not in ("commanded", "quadrature"):
            raise ValueError(f"RobotDescription.encoders must be 'commanded' or 'quadrature', "
                             f"got {self.encoders!r}")
        setf(self, "wheel_base_m", _positive("wheel_base_m", self.wheel_base_m))
        setf(self, "dt_s", _positive("dt_s", self.dt_s))
        if self.ticks_per_rad is not None:
            setf(self, "ticks_per_rad", _positive("ticks_per_rad", self.ticks_per_rad))
        setf(self, "wheel_radius_m", _pair("wheel_radius_m", self.wheel_radius_m))
        m_per_tick = _pair("m_per_tick", self.m_per_tick)
        if m_per_tick is None and self.wheel_radius_m is not None and self.ticks_per_rad:
            m_per_tick = tuple(r / self.ticks_per_rad for r in self.wheel_radius_m)
        setf(self, "m_per_tick", m_per_tick)
        if self.counter_bits is not None:
            if isinstance(self.counter_bits, bool) or not 1 <= int(self.counter_bits) <= 64:
                raise ValueError(f"RobotDescription.counter_bits must be 1..64 or None, got "
                                 f"{self.counter_bits!r}")
            setf(self, "counter_bits", int(self.counter_bits))
        setf(self, "sources", MappingProxyType({str(k): str(v)
                                                for k, v in dict(self.sources).items()}))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RobotDescription):
            return NotImplemented
        return self.as_dict() == other.as_dict()

    def __hash__(self) -> int:
        return hash(tuple(sorted((k, str(v)) for k, v in self.as_dict().items())))

    @property
    def ticks_per_rev(self) -> float | None:
        """Encoder counts per wheel revolution, ``2 pi ticks_per_rad``, or ``None``."""
        return None if self.ticks_per_rad is None else 2 * math.pi * self.ticks_per_rad

    def as_dict(self) -> dict[str, Any]:
        """The description as JSON-ready values (:meth:`from_dict` reads them back)."""
        return {"wheel_data": self.wheel_data, "wheel_base_m": self.wheel_base_m,
                "dt_s": self.dt_s, "encoders": self.encoders,
                "ticks_per_rad": self.ticks_per_rad,
                "wheel_radius_m": None if self.wheel_radius_m is None
                else list(self.wheel_radius_m),
                "m_per_tick": None if self.m_per_tick is None else list(self.m_per_tick),
                "counter_bits": self.counter_bits, "robot": self.robot,
                "sources": dict(self.sources)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RobotDescription:
        """Inverse of :meth:`as_dict`.

        Raises
        ------
        ValueError
            On unknown or missing keys, or invalid values.
        """
        if not isinstance(data, Mapping):
            raise ValueError(f"a robot description must be a mapping, got {type(data).__name__}")
        known = set(cls.__dataclass_fields__)
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"a robot description has unknown keys {sorted(unknown)}")
        try:
            return cls(**data)
        except TypeError as exc:
            raise ValueError(f"a robot description is incomplete ({exc})") from None

    def describe(self) -> str:
        """One line for people: the robot, its wheel data, geometry, encoders and period."""
        parts = [f"{self.robot or 'unnamed robot'}: {WHEEL_DATA[self.wheel_data]}"]
        if self.wheel_radius_m is not None:
            parts.append("wheel radius " + _fmt_pair(self.wheel_radius_m, "m"))
        parts.append(f"wheel base {self.wheel_base_m:g} m")
        if self.wheel_data in ("counts", "wheel_angles_rad"):
            parts.append(f"{self.encoders} encoders")
            if self.ticks_per_rad is not None:
                parts.append(f"{self.ticks_per_rad:g} counts/rad")
            if self.m_per_tick is not None:
                parts.append(_fmt_pair(self.m_per_tick, "m/count"))
        if self.counter_bits is not None:
            parts.append(f"{self.counter_bits}-bit counters")
        parts.append(f"period {self.dt_s * 1e3:g} ms")
        return ", ".join(parts)

    def disagreement(self, other: RobotDescription, *, mine: str = "the model",
                     theirs: str = "the recording",
                     period_tolerance: float = PERIOD_TOLERANCE,
                     geometry_tolerance: float = GEOMETRY_TOLERANCE) -> str | None:
        """The first way ``other`` (a recording's robot) disagrees with this one, or ``None``.

        Compared: the wheel data, the encoder kind (counts and angles only), the period
        (relative ``period_tolerance``), the wheel base, each wheel's radius and metres per
        count (relative ``geometry_tolerance``), where both sides state them.

        Parameters
        ----------
        other : RobotDescription
        mine, theirs : str
            What each side is, for the message.
        period_tolerance, geometry_tolerance : float
            Relative tolerances (:data:`PERIOD_TOLERANCE`, :data:`GEOMETRY_TOLERANCE`).

        Returns
        -------
        str or None
            One line naming both values, or ``None`` when they agree.

        Examples
        --------
        >>> model = RobotDescription(wheel_data="wheel_angles_rad", wheel_base_m=0.287,
        ...                          dt_s=1 / 30, wheel_radius_m=0.033)
        >>> bag = RobotDescription(wheel_data="wheel_angles_rad", wheel_base_m=0.287,
        ...                        dt_s=0.015, wheel_radius_m=0.033)
        >>> model.disagreement(bag)
        'the recording has a sensor period of 15 ms, the model 33.3333 ms (more than 5% apart)'
        """
        if self.wheel_data != other.wheel_data:
            return (f"{theirs} has {WHEEL_DATA[other.wheel_data]}, {mine} "
                    f"{WHEEL_DATA[self.wheel_data]}")
        if (self.wheel_data in ("counts", "wheel_angles_rad")
                and self.encoders != other.encoders):
            return f"{theirs} has {other.encoders} encoders, {mine} {self.encoders} ones"
        if _off(other.dt_s, self.dt_s) > period_tolerance:
            return (f"{theirs} has a sensor period of {other.dt_s * 1e3:g} ms, {mine} "
                    f"{self.dt_s * 1e3:g} ms (more than {period_tolerance:.0%} apart)")
        pct = f"more than {geometry_tolerance:.0%} apart"
        if _off(other.wheel_base_m, self.wheel_base_m) > geometry_tolerance:
            return (f"{theirs} has a wheel base of {other.wheel_base_m:g} m, {mine} "
                    f"{self.wheel_base_m:g} m ({pct})")
        for name, what, unit in (("wheel_radius_m", "a wheel radius", "m"),
                                 ("m_per_tick", "an encoder scale", "m/count")):
            a, b = getattr(self, name), getattr(other, name)
            if a is not None and b is not None and any(
                    _off(y, x) > geometry_tolerance for x, y in zip(a, b, strict=True)):
                return (f"{theirs} has {what} of {_fmt_pair(b, unit)}, {mine} "
                        f"{_fmt_pair(a, unit)} ({pct})")
        if (self.counter_bits is not None and other.counter_bits is not None
                and self.counter_bits != other.counter_bits):
            return (f"{theirs} has {other.counter_bits}-bit counters, {mine} "
                    f"{self.counter_bits}-bit ones")
        return None

    def check(self, other: RobotDescription, **kwargs: Any) -> None:
        """:meth:`disagreement`, raised.

        Raises
        ------
        RobotMismatchError
            A ``ValueError`` with the one line of :meth:`disagreement`.
        """
        found = self.disagreement(other, **kwargs)
        if found is not None:
            raise RobotMismatchError(found)


def _fmt_pair(pair: tuple[float, float], unit: str) -> str:
    left, right = pair
    return f"{left:g} {unit}" if left == right else f"{left:g} / {right:g} {unit} (left / right)"
