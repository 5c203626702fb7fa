"""Configuration of the physics simulator: robot presets, floors, rooms and faults.

Everything here is plain data; :mod:`drivers.sim.simulator` turns it into the arrays the
compiled kernel (:mod:`drivers.sim.kernel`) integrates.

A robot is described by a robot file (``docs/robot_file.md``; read and checked by
:mod:`drivers.sim.robot_file`); :func:`load_robot` makes its :class:`RobotParams`. The
presets are the shipped files ``drivers/sim/robots/create2.toml`` and ``paper.toml``.
The numbers of the ``create2`` preset (also :class:`RobotParams`' defaults) come from
the Create 2 Open Interface specification (wheel base 235 mm, wheel diameter 72 mm,
508.8 ticks per wheel revolution, 500 mm/s top speed, 15 ms sensor period;
spec §4 and §7 in :mod:`drivers.roomba.oi`) and from plausible values for a 3.6 kg robot whose
wheel motors are current limited. The ``paper`` preset is the paper's Roomba 560:
18 ms sensor period, a wheel base of 0.33 m as the paper states (paper section III.A,
eq. 13) and a longer command delay; a step settles within 15 samples (paper
Fig. 6).

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import dataclasses
import functools
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Literal

import numpy as np

from drivers.exceptions import RobotFileError, SimulatorError

__all__ = [
    "FLOORS",
    "PRESETS",
    "Fault",
    "Floor",
    "FloorMap",
    "RobotParams",
    "Room",
    "floor_name",
    "get_floor",
    "get_preset",
    "load_robot",
]


@dataclass(frozen=True)
class Floor:
    """Ground contact of one surface.

    Attributes
    ----------
    name : str
        Surface name.
    friction : float
        Peak traction coefficient mu (traction limit = mu * normal force).
    slip_ratio : float
        Slip ratio at which traction reaches tanh(1) = 76% of its limit;
        larger means a softer contact that creeps more under load.
    rolling_resistance : float
        Rolling-resistance coefficient (force = c * normal force) of tyres and caster.
    compression : float
        Tyre compression: the effective rolling radius is ``r (1 - compression)``,
        so ground travel per encoder tick drops by this fraction.
    roughness_n : float
        Standard deviation of the random force per wheel the surface applies,
        held over one sensor period [N].
    scrub : float
        Tyre twisting resistance when turning (torque = scrub * weight * b / 2).
    """

    name: str
    friction: float
    slip_ratio: float
    rolling_resistance: float
    compression: float
    roughness_n: float
    scrub: float


#: The floors by name (read-only).
FLOORS: Mapping[str, Floor] = MappingProxyType({
    f.name: f
    for f in (
        Floor("hard", friction=0.9, slip_ratio=0.08, rolling_resistance=0.015,
              compression=0.0, roughness_n=0.05, scrub=0.005),
        Floor("tile", friction=0.45, slip_ratio=0.08, rolling_resistance=0.012,
              compression=0.0, roughness_n=0.05, scrub=0.004),
        Floor("carpet", friction=0.8, slip_ratio=0.15, rolling_resistance=0.05,
              compression=0.03, roughness_n=0.3, scrub=0.012),
    )
})


def get_floor(name: str) -> Floor:
    """The floor called ``name``.

    Raises
    ------
    SimulatorError
        If there is no such floor; the message lists the known ones.
    """
    try:
        return FLOORS[name]
    except (KeyError, TypeError):
        raise SimulatorError(f"unknown floor {name!r}; known floors: {sorted(FLOORS)}") from None


@dataclass(frozen=True)
class FloorMap:
    """Floors by region: a default surface and axis-aligned rectangles over it.

    Attributes
    ----------
    default : str
        Floor everywhere no rectangle covers.
    regions : tuple of (xmin_m, xmax_m, ymin_m, ymax_m, floor)
        Later rectangles win where they overlap.
    """

    default: str = "hard"
    regions: tuple[tuple[float, float, float, float, str], ...] = ()

    def __post_init__(self) -> None:
        get_floor(self.default)
        for reg in self.regions:
            if len(reg) != 5 or not (reg[0] < reg[1] and reg[2] < reg[3]):
                raise SimulatorError(
                    f"floor region must be (xmin, xmax, ymin, ymax, floor) with xmin < xmax "
                    f"and ymin < ymax, got {reg!r}"
                )
            get_floor(reg[4])


def floor_name(floor: str | FloorMap) -> str:
    """The name a floor is recorded under: its own, or a floor map's default surface."""
    return floor.default if isinstance(floor, FloorMap) else floor


@dataclass(frozen=True)
class Room:
    """Walls and boxes as line segments the light-bump sensors see and the bumper hits.

    Attributes
    ----------
    segments : ndarray, shape (S, 5)
        Rows ``(x1, y1, x2, y2, reflectivity)`` in metres; reflectivity scales
        the IR signal (1 = white wall).
    """

    segments: np.ndarray

    def __post_init__(self) -> None:
        seg = np.asarray(self.segments, dtype=float).reshape(-1, 5)
        if not np.all(np.isfinite(seg)):
            raise SimulatorError("room segments must be finite")
        object.__setattr__(self, "segments", seg)

    @staticmethod
    def _rect(x0: float, y0: float, x1: float, y1: float, refl: float) -> list[list[float]]:
        return [[x0, y0, x1, y0, refl], [x1, y0, x1, y1, refl],
                [x1, y1, x0, y1, refl], [x0, y1, x0, y0, refl]]

    @classmethod
    def empty(cls) -> Room:
        """No walls at all (the IR signals see nothing)."""
        return cls(np.zeros((0, 5)))

    @classmethod
    def box(cls, width_m: float = 5.0, depth_m: float = 5.0) -> Room:
        """A bare rectangular room ``[0, width] x [0, depth]``."""
        return cls(np.array(cls._rect(0.0, 0.0, width_m, depth_m, 1.0)))

    @classmethod
    def single_wall(cls, *, y_m: float = 0.0, length_m: float = 10.0) -> Room:
        """One straight wall along ``y = y_m`` centred on ``x = 0``."""
        return cls(np.array([[-length_m / 2, y_m, length_m / 2, y_m, 1.0]]))

    @classmethod
    def cluttered(cls) -> Room:
        """A 5 m x 5 m room with a few boxes and furniture of mixed colour.

        A good spot to rotate for the encoder scale is :attr:`CALIBRATION_SPOT`:
        several surfaces lie within half a metre of it.
        """
        seg = cls._rect(0.0, 0.0, 5.0, 5.0, 1.0)
        seg += cls._rect(0.35, 0.95, 0.75, 1.35, 0.6)      # dark box
        seg += cls._rect(1.1, 0.25, 1.6, 0.55, 1.2)        # white box
        seg += cls._rect(3.6, 3.5, 4.4, 4.1, 0.8)          # armchair
        seg += [[2.0, 5.0, 3.0, 4.4, 0.9]]                 # slanted shelf
        return cls(np.array(seg))

    #: Pose (x m, y m, heading rad) near the boxes of :meth:`cluttered`.
    CALIBRATION_SPOT = (0.95, 0.85, 0.0)

    #: Open floor outside the 5 m rooms: nothing within 25 m, for the steps and the
    #: random excitation of a calibration (:meth:`drivers.sim.Simulator.place`).
    OPEN_FLOOR = (30.0, 30.0, 0.0)


@dataclass(frozen=True)
class RobotParams:
    """Physical parameters of one simulated robot.

    All SI: metres, kilograms, seconds, volts, amperes; wheel quantities are
    expressed at the wheel rim (force in N, speed in m/s), so the motor's
    gearbox and wheel radius are folded into ``motor_k``.

    Attributes
    ----------
    name : str
        Preset name.
    period_s : float
        Sensor period: one frame every ``period_s`` [s].
    wheel_base_m, wheel_diameter_m : float
        Nominal axle length and wheel diameter [m], as the spec states them
        (what a user knows before calibrating).
    wheel_base_error : float
        Relative error of the nominal wheel base: the wheels' contact points
        are ``wheel_base_m (1 + wheel_base_error)`` apart.
    wheel_diameter_errors : tuple of 2 float
        Relative errors of the nominal diameter of the (left, right) wheel
        (tyre wear, manufacturing); the firmware does not know them. Unequal
        diameters make the robot curve while both encoders agree (Borenstein's
        UMBmark "type B" error). The default +-0.03% is set so that encoder
        odometry on the closed route reproduces the offset the paper measured on
        its real Roomba (6.8 cm, Table II): reality is the reference.
    ticks_per_rev : float
        Encoder counts per wheel revolution.
    counter_bits : int
        Width of the encoder counters, 8 .. 64: counts wrap at
        ``2**counter_bits`` (16: the Open Interface's); 63 and 64 never wrap
        in a drive (held as a signed 64-bit count).
    max_speed_m_s : float
        Largest wheel-speed command accepted [m/s].
    mass_kg, payload_kg : float
        Robot mass and extra payload [kg].
    yaw_inertia_kg_m2 : float
        Yaw moment of inertia of the empty robot [kg m^2].
    payload_radius_m : float
        Radius of gyration of the payload about the centre [m].
    drive_weight_fraction : float
        Fraction of the weight carried by the two drive wheels (the rest on the caster).
    caster_offset_m : float
        Distance of the front caster ahead of the wheel axle [m].
    wheel_mass_kg : float
        Rotor and wheel inertia reflected to the rim, ``J / r^2`` [kg].
    motor_k : float
        Motor constant at the rim: back-EMF [V per m/s] and force per current [N/A].
    motor_resistance_ohm, current_limit_a, supply_v : float
        Armature resistance, driver current limit, and the voltage the PWM can apply.
    gear_viscous_n_s_m, gear_coulomb_n : float
        Gearbox friction at the rim: viscous [N per m/s] and Coulomb [N].
    motor_balance : float
        Right motor constant relative to the left (unit-to-unit variation).
    pid_kp, pid_ki, pid_kd, pid_kff : float
        Speed-loop gains: proportional [V per m/s], integral [V per m],
        derivative on measurement [V s per m], feed-forward [V per m/s].
    speed_filter_s : float
        Time constant of the firmware's wheel-speed measurement filter [s].
    delay_periods, delay_jitter_periods : float
        Transport delay of commands, and the full width of its uniform jitter,
        in sensor periods.
    latency_s, latency_jitter_s : float
        Mean and standard deviation of the host-side timestamp latency [s].
    internal_step_s : float
        Controller step (the mechanics is sub-stepped four times finer) [s].
    robot_radius_m, ir_radius_m : float
        Body radius (bumper) and radius at which the light-bump sensors sit [m].
    ir_angles_rad : tuple of 6 float
        Light-bump sensor directions relative to the heading, packet order
        left .. right [rad].
    ir_reference_m : float
        Distance at which a white wall saturates the IR signal; the signal
        falls as the inverse square beyond it [m].
    ir_noise : float
        Standard deviation of the IR signal noise [counts].
    settling_time_s : float
        Documented time from a step command to within 2% of the final speed [s].
    floor : str or FloorMap
        The floor the robot drives on unless a simulation names another.
    faults : tuple of Fault
        Changes scheduled in every simulation of this robot (times from its start).
    gyro_noise_density_rad_s_sqrt_hz : float or None
        A yaw-rate gyro's white-noise density [rad/s/sqrt(Hz)] (MEMS: about 0.005);
        ``None`` (the default): the robot has no gyro. Its frame reading is the true
        body yaw rate averaged over the period, plus ``gyro_bias_rad_s``, plus white
        noise of standard deviation ``density / sqrt(period_s)`` (the period's mean of
        the white rate noise).
    gyro_bias_rad_s : float
        The gyro's constant bias [rad/s] (MEMS: up to about 0.01); needs a gyro.
    """

    name: str = "create2"
    period_s: float = 0.015
    wheel_base_m: float = 0.235
    wheel_diameter_m: float = 0.072
    wheel_base_error: float = 0.004
    wheel_diameter_errors: tuple[float, float] = (0.0003, -0.0003)
    ticks_per_rev: float = 508.8
    counter_bits: int = 16
    max_speed_m_s: float = 0.5
    mass_kg: float = 3.6
    payload_kg: float = 0.0
    yaw_inertia_kg_m2: float = 0.055
    payload_radius_m: float = 0.08
    drive_weight_fraction: float = 0.85
    caster_offset_m: float = 0.13
    wheel_mass_kg: float = 0.4
    motor_k: float = 18.0
    motor_resistance_ohm: float = 2.0
    current_limit_a: float = 0.45
    supply_v: float = 14.4
    gear_viscous_n_s_m: float = 0.5
    gear_coulomb_n: float = 0.3
    motor_balance: float = 0.98
    pid_kp: float = 60.0
    pid_ki: float = 100.0
    pid_kd: float = 0.0
    pid_kff: float = 18.0
    speed_filter_s: float = 0.006
    delay_periods: float = 4.0
    delay_jitter_periods: float = 1.0
    latency_s: float = 0.002
    latency_jitter_s: float = 0.001
    internal_step_s: float = 0.001
    robot_radius_m: float = 0.17
    ir_radius_m: float = 0.16
    ir_angles_rad: tuple[float, ...] = tuple(
        np.deg2rad([65.0, 38.0, 13.0, -13.0, -38.0, -65.0]).tolist()
    )
    ir_reference_m: float = 0.04
    ir_noise: float = 3.0
    settling_time_s: float = 0.25
    floor: str | FloorMap = "hard"
    faults: tuple[Fault, ...] = ()
    gyro_noise_density_rad_s_sqrt_hz: float | None = None
    gyro_bias_rad_s: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.floor, FloorMap):
            get_floor(self.floor)
        object.__setattr__(self, "faults", tuple(self.faults))
        if not all(isinstance(f, Fault) for f in self.faults):
            raise SimulatorError(f"RobotParams.faults must hold Fault objects, got {self.faults}")
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float) and not np.isfinite(value):
                raise SimulatorError(f"RobotParams.{f.name} must be finite, got {value}")
        positive = ("period_s", "wheel_base_m", "wheel_diameter_m", "ticks_per_rev",
                    "max_speed_m_s", "mass_kg", "yaw_inertia_kg_m2", "wheel_mass_kg",
                    "motor_k", "motor_resistance_ohm", "current_limit_a", "supply_v",
                    "internal_step_s", "speed_filter_s")
        for name in positive:
            if getattr(self, name) <= 0:
                raise SimulatorError(
                    f"RobotParams.{name} must be positive, got {getattr(self, name)}")
        if isinstance(self.counter_bits, bool) or self.counter_bits not in range(8, 65):
            raise SimulatorError(f"RobotParams.counter_bits must be a whole number of bits "
                                 f"from 8 to 64 (16 for a Roomba), got {self.counter_bits!r}")
        if self.payload_kg < 0:
            raise SimulatorError(f"RobotParams.payload_kg must be >= 0, got {self.payload_kg}")
        density = self.gyro_noise_density_rad_s_sqrt_hz
        if density is not None and not (np.isfinite(density) and density >= 0):
            raise SimulatorError(f"RobotParams.gyro_noise_density_rad_s_sqrt_hz must be >= 0 "
                                 f"[rad/s/sqrt(Hz)] or None (no gyro), got {density}")
        if density is None and self.gyro_bias_rad_s != 0.0:
            raise SimulatorError(f"RobotParams.gyro_bias_rad_s ({self.gyro_bias_rad_s}) needs "
                                 f"a gyro: give gyro_noise_density_rad_s_sqrt_hz too")
        if len(self.wheel_diameter_errors) != 2 or max(map(abs, self.wheel_diameter_errors)) > 0.2:
            raise SimulatorError(
                f"wheel_diameter_errors needs (left, right) within +-20%, "
                f"got {self.wheel_diameter_errors}")
        if len(self.ir_angles_rad) != 6:
            raise SimulatorError(f"ir_angles_rad needs 6 angles, got {len(self.ir_angles_rad)}")
        if self.delay_periods - self.delay_jitter_periods / 2 < 0:
            raise SimulatorError("delay_periods must exceed half of delay_jitter_periods")
        if self.internal_step_s > self.period_s:
            raise SimulatorError(
                f"internal_step_s ({self.internal_step_s}) must not exceed period_s "
                f"({self.period_s})"
            )

    @property
    def m_per_tick(self) -> float:
        """Nominal wheel travel per encoder tick, ``pi D / ticks_per_rev`` [m] (the spec value)."""
        return float(np.pi * self.wheel_diameter_m / self.ticks_per_rev)

    @property
    def true_wheel_base_m(self) -> float:
        """Distance between the wheels' contact points [m] (simulator truth)."""
        return self.wheel_base_m * (1.0 + self.wheel_base_error)

    def replace(self, **changes: object) -> RobotParams:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)


FaultKind = Literal[
    "floor", "payload", "motor", "delay", "encoder_spikes", "stuck_encoder", "stall",
    "lost_frames", "wheel_diameter",
]


@dataclass(frozen=True)
class Fault:
    """A change scheduled at a time during a simulation.

    Attributes
    ----------
    kind : str
        ``"floor"`` (``floor``: new surface everywhere), ``"payload"``
        (``payload_kg``: new payload), ``"motor"`` (``weakening``: fraction of
        motor constant lost, ``wheel``), ``"delay"`` (``extra_periods``: added
        transport delay), ``"encoder_spikes"`` (``rate_hz`` of spikes,
        ``magnitude_ticks``, ``wheel``), ``"stuck_encoder"`` (``wheel``: its
        count freezes), ``"stall"`` (``wheel``: blocked by an obstacle),
        ``"lost_frames"`` (``probability`` of losing each frame),
        ``"wheel_diameter"`` (``diameter_change``: the ``wheel``'s true diameter
        scaled by ``1 + diameter_change``, e.g. 0.005 for hair wound on it; its
        encoder still counts its rotation, so the robot curves on equal counts,
        at ``-diameter_change / b`` [rad/m] for the left wheel).
    t_s : float
        Onset [s] from the start of the simulation.
    duration_s : float
        How long it lasts [s]; ``inf`` means until the end.
    robots : tuple of int or None
        Robots of a batch it applies to; ``None`` means all.
    floor, payload_kg, weakening, extra_periods, rate_hz, magnitude_ticks, probability
        Parameters of the kinds above.
    diameter_change : float
        Relative change of the wheel's diameter (``"wheel_diameter"``), within +-0.2.
    wheel : {"left", "right", "both"}
        The wheel a wheel fault hits.
    """

    kind: FaultKind
    t_s: float
    duration_s: float = float("inf")
    robots: tuple[int, ...] | None = None
    floor: str = "carpet"
    payload_kg: float = 0.0
    weakening: float = 0.2
    extra_periods: float = 3.0
    rate_hz: float = 2.0
    magnitude_ticks: float = 150.0
    probability: float = 0.5
    diameter_change: float = 0.005
    wheel: Literal["left", "right", "both"] = "both"
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        kinds = FaultKind.__args__
        if self.kind not in kinds:
            raise SimulatorError(f"unknown fault kind {self.kind!r}; known kinds: {list(kinds)}")
        if not np.isfinite(self.t_s) or self.t_s < 0:
            raise SimulatorError(f"fault onset t_s must be finite and >= 0, got {self.t_s}")
        if not self.duration_s > 0:
            raise SimulatorError(f"fault duration_s must be > 0, got {self.duration_s}")
        if self.wheel not in ("left", "right", "both"):
            raise SimulatorError(
                f"fault wheel must be 'left', 'right' or 'both', got {self.wheel!r}")
        if self.kind == "floor":
            get_floor(self.floor)
        if self.kind == "payload" and self.payload_kg < 0:
            raise SimulatorError(f"payload_kg must be >= 0, got {self.payload_kg}")
        if self.kind == "motor" and not 0 <= self.weakening < 1:
            raise SimulatorError(f"motor weakening must be in [0, 1), got {self.weakening}")
        if self.kind == "lost_frames" and not 0 <= self.probability <= 1:
            raise SimulatorError(
                f"lost-frame probability must be in [0, 1], got {self.probability}")
        if self.kind == "wheel_diameter" and not abs(self.diameter_change) <= 0.2:
            raise SimulatorError(f"wheel diameter_change must be within -0.2 .. 0.2, got "
                                 f"{self.diameter_change}")

    @property
    def wheels(self) -> tuple[int, ...]:
        """Wheel indices (0 left, 1 right) this fault hits."""
        return {"left": (0,), "right": (1,), "both": (0, 1)}[self.wheel]


def load_robot(name_or_path: str | os.PathLike[str]) -> RobotParams:
    """The robot a robot file describes, or a shipped preset by name.

    Parameters
    ----------
    name_or_path : str or path
        A preset name (``"create2"``, ``"paper"``) or a ``.toml`` / ``.json`` robot file
        (``docs/robot_file.md``).

    Raises
    ------
    RobotFileError
        A file that cannot describe a robot: one line naming the file and the field.
    FileNotFoundError
        No such file.

    Examples
    --------
    >>> load_robot("paper").period_s
    0.018
    """
    # the reader (tomllib, importlib.resources) loads with the first robot, not with
    # this module: the command line's start-up imports this module for its floor names
    from drivers.sim.robot_file import read_robot_file

    spec = read_robot_file(name_or_path)
    try:
        floor = (FloorMap(spec.floor_default, spec.floor_regions) if spec.floor_regions
                 else get_floor(spec.floor_default).name)
    except SimulatorError as exc:
        raise RobotFileError(f"{spec.source}: [floor] {exc}") from None
    faults = []
    for i, args in enumerate(spec.faults, start=1):
        try:
            faults.append(Fault(**args))
        except SimulatorError as exc:
            raise RobotFileError(f"{spec.source}: [[faults]] #{i} {exc}") from None
    try:
        return RobotParams(**spec.params, floor=floor, faults=tuple(faults))
    except SimulatorError as exc:
        raise RobotFileError(f"{spec.source}: {exc}") from None


@functools.cache
def _shipped_presets() -> Mapping[str, RobotParams]:
    from drivers.sim.robot_file import preset_names

    return MappingProxyType({name: load_robot(name) for name in preset_names()})


def __getattr__(name: str) -> object:
    """``PRESETS``, read from the shipped robot files on first use (PEP 562)."""
    if name == "PRESETS":
        return _shipped_presets()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


if TYPE_CHECKING:
    #: The robot presets by name, read from the shipped robot files on first use
    #: (read-only: :func:`get_preset` with overrides makes a variant).
    PRESETS: Mapping[str, RobotParams]


def get_preset(name: str, **overrides: object) -> RobotParams:
    """A preset's parameters, optionally with fields overridden.

    Raises
    ------
    SimulatorError
        If there is no such preset; the message lists the known ones.
    """
    presets = _shipped_presets()
    try:
        base = presets[name]
    except (KeyError, TypeError):
        raise SimulatorError(f"unknown preset {name!r}; known presets: {sorted(presets)}") from None
    return base.replace(**overrides) if overrides else base
