"""Robot description files: one schema, read from TOML or JSON and checked field by field.

A robot file describes one simulated robot: its sensor period, geometry, encoders,
command delay, mass and payload, motors, speed controller, light-bump sensors, floor
(or floor map) and scheduled faults. ``docs/robot_file.md`` documents every field, its
unit and its default; :data:`SCHEMA` is that table in code. The shipped presets are
such files (``drivers/sim/robots/create2.toml``, ``paper.toml``), read through
:mod:`importlib.resources` so that an installed package finds them.

This module reads and checks the file; :func:`drivers.sim.load_robot` turns
the result into :class:`~drivers.sim.RobotParams` (whose own checks, such as
the delay against its jitter, then run with the file's name in the message). Every
error is one line that names the file, the section and the field::

    robot file my.toml: [encoders] ticks_per_rev must be a positive number
    [ticks per wheel revolution], got -5
"""

from __future__ import annotations

import math
import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import NamedTuple

import numpy as np

from drivers.exceptions import RobotFileError

__all__ = ["FAULT_FIELDS", "SCHEMA", "Field", "RobotGeometry", "RobotSpec", "preset_names",
           "read_robot_file", "robot_geometry", "robot_source"]


class Field(NamedTuple):
    """One field of the schema.

    Attributes
    ----------
    key : str
        Name in the file; also the :class:`~drivers.sim.RobotParams` field, except
        ``ir_angles_deg`` (radians in ``ir_angles_rad``).
    check : str
        ``"positive"``, ``"nonnegative"``, ``"real"``, ``"fraction"`` (0 < x <= 1),
        ``"error"`` (|x| <= 0.2), ``"delay"`` (0 .. 30), ``"weakening"`` (0 <= x < 1),
        ``"probability"`` (0 .. 1), ``"pair_error"`` (two errors), ``"six_angles"``,
        ``"counter_bits"`` (8 .. 64), ``"wheel"``, ``"text"``, ``"encoder_kind"``
        (``"commanded"`` or ``"quadrature"``).
    unit : str
        Unit as the messages and the schema page state it.
    required : bool
        Whether a file must give it: what a real robot has (name, period, geometry,
        encoders). The others default to the ``create2`` value when the simulator runs
        the robot; a real robot's file may leave every simulator field out.
    """

    key: str
    check: str
    unit: str
    required: bool = False


_S, _M, _KG = "s", "m", "kg"

#: The schema: section ("" for the top level) -> its fields (read-only).
SCHEMA: Mapping[str, tuple[Field, ...]] = MappingProxyType({
    "": (Field("name", "text", "", True), Field("period_s", "positive", _S, True)),
    "geometry": (Field("wheel_base_m", "positive", _M, True),
                 Field("wheel_diameter_m", "positive", _M, True),
                 Field("wheel_base_error", "error", "fraction"),
                 Field("wheel_diameter_errors", "pair_error", "fraction"),
                 Field("robot_radius_m", "positive", _M),
                 Field("caster_offset_m", "nonnegative", _M)),
    "encoders": (Field("ticks_per_rev", "positive", "ticks per wheel revolution", True),
                 Field("counter_bits", "counter_bits", "bits"),
                 Field("kind", "encoder_kind", "")),
    "delay": (Field("delay_periods", "delay", "sensor periods"),
              Field("delay_jitter_periods", "delay", "sensor periods"),
              Field("latency_s", "nonnegative", _S),
              Field("latency_jitter_s", "nonnegative", _S)),
    "mass": (Field("mass_kg", "positive", _KG),
             Field("payload_kg", "nonnegative", _KG),
             Field("yaw_inertia_kg_m2", "positive", "kg m^2"),
             Field("payload_radius_m", "nonnegative", _M),
             Field("drive_weight_fraction", "fraction", "fraction"),
             Field("wheel_mass_kg", "positive", _KG)),
    "motors": (Field("max_speed_m_s", "positive", "m/s"),
               Field("motor_k", "positive", "V s/m = N/A"),
               Field("motor_resistance_ohm", "positive", "ohm"),
               Field("current_limit_a", "positive", "A"),
               Field("supply_v", "positive", "V"),
               Field("gear_viscous_n_s_m", "nonnegative", "N s/m"),
               Field("gear_coulomb_n", "nonnegative", "N"),
               Field("motor_balance", "positive", "ratio")),
    "controller": (Field("pid_kp", "nonnegative", "V s/m"),
                   Field("pid_ki", "nonnegative", "V/m"),
                   Field("pid_kd", "nonnegative", "V s^2/m"),
                   Field("pid_kff", "nonnegative", "V s/m"),
                   Field("speed_filter_s", "positive", _S),
                   Field("internal_step_s", "positive", _S),
                   Field("settling_time_s", "nonnegative", _S)),
    "light_bumps": (Field("ir_radius_m", "nonnegative", _M),
                    Field("ir_angles_deg", "six_angles", "degrees"),
                    Field("ir_reference_m", "positive", _M),
                    Field("ir_noise", "nonnegative", "counts")),
    "floor": (Field("default", "text", "floor name"),),
    "gyro": (Field("gyro_noise_density_rad_s_sqrt_hz", "nonnegative", "rad/s/sqrt(Hz)"),
             Field("gyro_bias_rad_s", "real", "rad/s")),
})

#: Keys of a ``[[faults]]`` entry besides ``kind``, ``t_s`` and ``duration_s``, by kind
#: (the parameters :class:`~drivers.sim.Fault` reads for that kind).
FAULT_FIELDS: Mapping[str, tuple[str, ...]] = MappingProxyType({
    "floor": ("floor",), "payload": ("payload_kg",), "motor": ("weakening", "wheel"),
    "delay": ("extra_periods",), "encoder_spikes": ("rate_hz", "magnitude_ticks", "wheel"),
    "stuck_encoder": ("wheel",), "stall": ("wheel",), "lost_frames": ("probability",),
    "wheel_diameter": ("diameter_change", "wheel"),
})

#: How each fault parameter is checked, and its unit.
_FAULT_CHECKS = MappingProxyType({
    "floor": Field("floor", "text", "floor name"), "wheel": Field("wheel", "wheel", ""),
    "payload_kg": Field("payload_kg", "nonnegative", _KG),
    "weakening": Field("weakening", "weakening", "fraction of the motor constant lost"),
    "extra_periods": Field("extra_periods", "delay", "sensor periods"),
    "rate_hz": Field("rate_hz", "nonnegative", "Hz"),
    "magnitude_ticks": Field("magnitude_ticks", "nonnegative", "ticks"),
    "probability": Field("probability", "probability", ""),
    "diameter_change": Field("diameter_change", "error", "fraction of the diameter"),
})

_REGION_KEYS = ("xmin_m", "xmax_m", "ymin_m", "ymax_m", "floor")
_TABLES = ("floor", "faults")       # sections that hold more than fields
_CHECKS = MappingProxyType({
    "positive": ("a positive number", lambda x: x > 0),
    "nonnegative": ("a number >= 0", lambda x: x >= 0),
    "real": ("a finite number", lambda x: True),
    "fraction": ("a number in (0, 1]", lambda x: 0 < x <= 1),
    "error": ("a number within -0.2 .. 0.2", lambda x: abs(x) <= 0.2),
    # the kernel queues 32 commands (drivers.sim.kernel.QUEUE_LEN)
    "delay": ("a number within 0 .. 30", lambda x: 0 <= x <= 30),
    "weakening": ("a number within 0 .. 1, 1 excluded", lambda x: 0 <= x < 1),
    "probability": ("a number within 0 .. 1", lambda x: 0 <= x <= 1),
})


@dataclass(frozen=True)
class RobotSpec:
    """A robot file, read and checked, before it becomes ``RobotParams``.

    Attributes
    ----------
    source : str
        Where it came from, as messages name it (``robot file PATH`` or ``preset NAME``).
    params : dict
        :class:`~drivers.sim.RobotParams` keyword arguments (SI, radians).
    floor_default : str
        Floor everywhere no region covers.
    floor_regions : tuple of (xmin_m, xmax_m, ymin_m, ymax_m, floor)
        Floor-map rectangles; empty for one floor everywhere.
    faults : tuple of dict
        :class:`~drivers.sim.Fault` keyword arguments, in file order.
    encoders : {"commanded", "quadrature"} or None
        ``[encoders] kind``: how the wheel counts count (``None``: the file does not say).
    """

    source: str
    params: dict = field(default_factory=dict)
    floor_default: str = "hard"
    floor_regions: tuple[tuple[float, float, float, float, str], ...] = ()
    faults: tuple[dict, ...] = ()
    encoders: str | None = None


@dataclass(frozen=True)
class RobotGeometry:
    """What a robot file says about a real robot: geometry, encoders and rate [m, s].

    Attributes
    ----------
    name : str
    source : str
        ``robot file PATH`` or ``preset NAME``.
    period_s : float
        Sensor period [s].
    wheel_base_m : float
        Nominal wheel base [m].
    wheel_radius_m : float
        Nominal wheel radius, half ``wheel_diameter_m`` [m].
    ticks_per_rev : float
        Encoder counts per wheel revolution.
    counter_bits : int or None
        Counter width, when the file gives it.
    encoders : {"commanded", "quadrature"} or None
        How the counts count, when the file says.
    """

    name: str
    source: str
    period_s: float
    wheel_base_m: float
    wheel_radius_m: float
    ticks_per_rev: float
    counter_bits: int | None = None
    encoders: str | None = None

    @property
    def ticks_per_rad(self) -> float:
        """Encoder counts per wheel radian, ``ticks_per_rev / (2 pi)``."""
        return self.ticks_per_rev / (2 * math.pi)


def _robots_dir():
    return resources.files("drivers.sim") / "robots"


def preset_names() -> tuple[str, ...]:
    """Names of the shipped robot files (``drivers/sim/robots/*.toml``), sorted."""
    return tuple(sorted(p.name[:-5] for p in _robots_dir().iterdir()
                        if p.name.endswith(".toml")))


def robot_source(name_or_path: str | os.PathLike[str]) -> tuple[str, str, str]:
    """Resolve a preset name or a file path to ``(source label, format, text)``.

    A string without a path separator and without a ``.toml`` / ``.json`` suffix is a
    preset name; anything else is a file.

    Raises
    ------
    RobotFileError
        Unknown preset name, unsupported suffix.
    FileNotFoundError
        No such file.
    """
    text = os.fspath(name_or_path)
    is_path = isinstance(name_or_path, os.PathLike) or os.sep in text or "/" in text \
        or text.endswith((".toml", ".json"))
    if not is_path:
        entry = _robots_dir() / f"{text}.toml"
        if not text or not entry.is_file():
            raise RobotFileError(
                f"unknown robot {text!r}: neither a preset ({', '.join(preset_names())}) nor "
                "a .toml or .json robot file")
        return f"preset {text}", "toml", entry.read_text(encoding="utf-8")
    path = Path(text)
    label = f"robot file {text}"
    if path.suffix not in (".toml", ".json"):
        raise RobotFileError(f"{label}: give a .toml or .json robot file (docs/robot_file.md)")
    if not path.is_file():
        raise FileNotFoundError(f"{label}: no such file")
    try:
        return label, path.suffix[1:], path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise RobotFileError(f"{label}: not a text file") from None


def _number(value: object, where: str, unit: str, check: str) -> float:
    what, ok = _CHECKS[check]
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or not ok(value):
        raise RobotFileError(f"{where} must be {what}{f' [{unit}]' if unit else ''}, "
                             f"got {value!r}")
    return float(value)


def _value(spec: Field, value: object, where: str) -> tuple[str, object]:
    """The RobotParams keyword and value of one field, checked."""
    if spec.check == "text":
        if not isinstance(value, str) or not value.strip():
            raise RobotFileError(f"{where} must be a non-empty string, got {value!r}")
        return spec.key, value
    if spec.check == "wheel":
        if value not in ("left", "right", "both"):
            raise RobotFileError(f"{where} must be \"left\", \"right\" or \"both\", "
                                 f"got {value!r}")
        return spec.key, value
    if spec.check == "encoder_kind":
        if value not in ("commanded", "quadrature"):
            raise RobotFileError(f"{where} must be \"commanded\" (the counts follow the "
                                 f"command's sign, a Roomba) or \"quadrature\", got {value!r}")
        return spec.key, value
    if spec.check == "counter_bits":
        if not isinstance(value, int) or isinstance(value, bool) or not 8 <= value <= 64:
            raise RobotFileError(f"{where} must be a whole number of bits from 8 to 64 (16 "
                                 f"for the Open Interface's counters; 63 and 64 never wrap), "
                                 f"got {value!r}")
        return spec.key, value
    if spec.check in ("pair_error", "six_angles"):
        n = 2 if spec.check == "pair_error" else 6
        if not isinstance(value, list) or len(value) != n:
            raise RobotFileError(f"{where} must be a list of {n} numbers [{spec.unit}], "
                                 f"got {value!r}")
        check = "error" if n == 2 else "real"
        items = [_number(v, f"{where}[{i}]", spec.unit, check) for i, v in enumerate(value)]
        if n == 2:
            return spec.key, tuple(items)
        return "ir_angles_rad", tuple(np.deg2rad(items).tolist())
    return spec.key, _number(value, where, spec.unit, spec.check)


def _section(doc: Mapping, section: str, label: str) -> dict:
    """Check one section's keys and values; RobotParams keywords out."""
    where = f"{label}: [{section}] " if section else f"{label}: "
    fields = {f.key: f for f in SCHEMA[section]}
    extra = {"floor": ("regions",)}.get(section, ())
    table = doc if section == "" else doc.get(section, {})
    if not isinstance(table, Mapping):
        raise RobotFileError(f"{label}: [{section}] must be a table of fields, got {table!r}")
    skip = set(SCHEMA) | set(_TABLES) if section == "" else set(extra)
    for key in table:
        if key not in fields and key not in skip:
            known = [*fields, *extra] if section else [
                *fields, *(f"[{s}]" for s in SCHEMA if s), "[[faults]]"]
            what = "field" if section else "field or section"
            import difflib  # only for a message: not at every start-up

            close = difflib.get_close_matches(key, [k.strip("[]") for k in known], n=1)
            hint = f" (did you mean {close[0]}?)" if close else ""
            raise RobotFileError(f"{where}unknown {what} {key!r}{hint}; known: "
                                 f"{', '.join(known)}")
    for f in fields.values():
        if f.required and f.key not in table:
            unit = f" [{f.unit}]" if f.unit else ""
            raise RobotFileError(f"{where}{f.key}{unit} is missing (docs/robot_file.md)")
    return dict(_value(fields[k], table[k], f"{where}{k}") for k in fields if k in table)


def _tables(value: object, label: str, *, name: str, array: str) -> list[tuple[str, Mapping]]:
    """The tables of an array of tables (``[[array]]``), each with its place for messages."""
    if not isinstance(value, list):
        raise RobotFileError(f"{label}: {name} must be a list of tables ([[{array}]]), "
                             f"got {value!r}")
    out = []
    for i, entry in enumerate(value, start=1):
        where = f"{label}: [[{array}]] #{i} "
        if not isinstance(entry, Mapping):
            raise RobotFileError(f"{where}must be a table, got {entry!r}")
        out.append((where, entry))
    return out


def _regions(doc: Mapping, label: str) -> tuple[tuple[float, float, float, float, str], ...]:
    out = []
    for where, reg in _tables(doc.get("floor", {}).get("regions", []), label,
                              name="[floor] regions", array="floor.regions"):
        for key in reg:
            if key not in _REGION_KEYS:
                raise RobotFileError(f"{where}unknown field {key!r}; known: "
                                     f"{', '.join(_REGION_KEYS)}")
        for key in _REGION_KEYS:
            if key not in reg:
                raise RobotFileError(f"{where}{key} is missing")
        box = [_number(reg[k], f"{where}{k}", "m", "real") for k in _REGION_KEYS[:4]]
        floor = _value(Field("floor", "text", ""), reg["floor"], f"{where}floor")[1]
        out.append((*box, floor))
    return tuple(out)


def _faults(doc: Mapping, label: str) -> tuple[dict, ...]:
    out = []
    for where, entry in _tables(doc.get("faults", []), label, name="faults", array="faults"):
        for key in ("kind", "t_s"):
            if key not in entry:
                raise RobotFileError(f"{where}{key} is missing")
        kind = entry["kind"]
        if kind not in FAULT_FIELDS:
            raise RobotFileError(f"{where}kind must be one of {', '.join(FAULT_FIELDS)}, "
                                 f"got {kind!r}")
        allowed = ("kind", "t_s", "duration_s", *FAULT_FIELDS[kind])
        for key in entry:
            if key not in allowed:
                raise RobotFileError(f"{where}unknown field {key!r} for a {kind} fault; "
                                     f"known: {', '.join(allowed)}")
        args: dict[str, object] = {"kind": kind}
        args["t_s"] = _number(entry["t_s"], f"{where}t_s", "s", "nonnegative")
        if "duration_s" in entry:
            args["duration_s"] = _number(entry["duration_s"], f"{where}duration_s", "s",
                                         "positive")
        for key in FAULT_FIELDS[kind]:
            if key in entry:
                args[key] = _value(_FAULT_CHECKS[key], entry[key], f"{where}{key}")[1]
        out.append(args)
    return tuple(out)


def read_robot_file(name_or_path: str | os.PathLike[str]) -> RobotSpec:
    """Read and check a robot file (or a shipped preset by name).

    Parameters
    ----------
    name_or_path : str or path
        A preset name (``"create2"``, ``"paper"``) or a ``.toml`` / ``.json`` file.

    Returns
    -------
    RobotSpec
        The checked fields; :func:`drivers.sim.load_robot` builds the robot.

    Raises
    ------
    RobotFileError
        Unparsable file, unknown or missing section or field, wrong type, out of range:
        one line naming the file, the section and the field.
    FileNotFoundError
        No such file.
    """
    import json  # the shipped presets are TOML: not at every start-up

    label, fmt, text = robot_source(name_or_path)
    try:
        doc = tomllib.loads(text) if fmt == "toml" else json.loads(text)
    except ValueError as exc:        # TOMLDecodeError and JSONDecodeError are ValueErrors
        raise RobotFileError(f"{label}: not valid {fmt.upper()}: {exc}") from None
    if not isinstance(doc, Mapping):
        raise RobotFileError(f"{label}: must hold a table of sections, got {doc!r}")
    params: dict[str, object] = {}
    for section in SCHEMA:
        params.update(_section(doc, section, label))
    floor_default = params.pop("default", "hard")
    encoders = params.pop("kind", None)
    return RobotSpec(source=label, params=params, floor_default=floor_default,
                     floor_regions=_regions(doc, label), faults=_faults(doc, label),
                     encoders=encoders)


def robot_geometry(name_or_path: str | os.PathLike[str]) -> RobotGeometry:
    """A robot file's (or preset's) geometry, encoders and period: what a real robot has.

    A real robot's file needs only its name, ``period_s``, ``[geometry] wheel_base_m`` and
    ``wheel_diameter_m`` and ``[encoders] ticks_per_rev`` (``counter_bits`` and ``kind``
    when known); the simulator's fields may be left out.

    Raises
    ------
    RobotFileError, FileNotFoundError
        As :func:`read_robot_file`.

    Examples
    --------
    >>> g = robot_geometry("create2")
    >>> g.wheel_radius_m, g.wheel_base_m, g.encoders, g.counter_bits
    (0.036, 0.235, 'commanded', 16)
    """
    spec = read_robot_file(name_or_path)
    p = spec.params
    return RobotGeometry(name=str(p["name"]), source=spec.source, period_s=float(p["period_s"]),
                         wheel_base_m=float(p["wheel_base_m"]),
                         wheel_radius_m=float(p["wheel_diameter_m"]) / 2,
                         ticks_per_rev=float(p["ticks_per_rev"]),
                         counter_bits=int(p["counter_bits"]) if "counter_bits" in p else None,
                         encoders=spec.encoders)
