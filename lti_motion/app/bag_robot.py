"""``calibrate --bag``: the robot's geometry, from the flags, a robot file or the bag's URDF.

Nothing is assumed: a bag's wheel angles become travel only with the robot's wheel radius
and wheel base, which come, in this order of precedence, from

1. the flags (``--wheel-radius``, ``--wheel-base``, ``--ticks-per-rad``, ``--encoders``);
2. a robot file (``--robot FILE``, ``docs/robot_file.md``: geometry, encoders and period
   are all a real robot's file needs);
3. the bag's own ``/robot_description`` (the URDF ``robot_state_publisher`` latches: the
   wheel joints' cylinder radius and their separation, :mod:`drivers.bags.urdf`).

Without a wheel base (and a radius, for wheel angles) the command stops with one line
saying what to give. Each number's source is printed and kept in the model's robot
description (:class:`~lti_motion.robot_description.RobotDescription`).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["BagGeometry", "bag_geometry"]


@dataclass(frozen=True)
class BagGeometry:
    """The robot's numbers for ``calibrate --bag`` and where each came from [m, counts/rad].

    Attributes
    ----------
    wheel_base_m : float
    wheel_radius_m : float or None
        ``None`` only for a bag without wheel angles (the robot's odometry twist).
    ticks_per_rad : float or None
        ``None``: the angles are counted in
        :data:`~lti_motion.robot_description.ANGLE_COUNTS_PER_RAD`.
    encoders : {"commanded", "quadrature"} or None
        ``None``: quadrature (the default for sensor_msgs/JointState angles).
    robot : str or None
        The robot's name (a robot file's).
    sources : dict of str to str
        Per number, where it came from.
    """

    wheel_base_m: float
    wheel_radius_m: float | None
    ticks_per_rad: float | None = None
    encoders: str | None = None
    robot: str | None = None
    sources: dict = field(default_factory=dict)

    def lines(self, *, angles: bool) -> list[str]:
        """What ``calibrate`` prints: each number with its source."""
        from lti_motion.robot_description import ANGLE_COUNTS_PER_RAD

        out = [f"wheel base {self.wheel_base_m:g} m from {self.sources['wheel_base_m']}"]
        if angles:
            out.append(f"wheel radius {self.wheel_radius_m:g} m from "
                       f"{self.sources['wheel_radius_m']}")
            if self.ticks_per_rad is None:
                out.append(f"counts per radian {ANGLE_COUNTS_PER_RAD:g}: the angles' own "
                           "resolution (no encoder resolution given; --ticks-per-rad or a "
                           "robot file's ticks_per_rev for the encoder's)")
            else:
                out.append(f"counts per radian {self.ticks_per_rad:g} from "
                           f"{self.sources['ticks_per_rad']}")
            if self.encoders is None:
                out.append("encoders quadrature: JointState angles know the way the wheel "
                           "turns (default; --encoders commanded for a Create 2's)")
            else:
                out.append(f"encoders {self.encoders} from {self.sources['encoders']}")
        return out


def bag_geometry(args: argparse.Namespace, *, angles: bool) -> BagGeometry:
    """The geometry ``calibrate --bag`` fits with: flags over a robot file over the bag's URDF.

    Parameters
    ----------
    args : argparse.Namespace
        ``calibrate``'s: ``bag``, ``sim`` (``--robot``), ``wheel_radius``, ``wheel_base``,
        ``ticks_per_rad``, ``encoders``.
    angles : bool
        The bag's wheels are angles (a radius is then needed), else the robot's odometry.

    Raises
    ------
    ValueError
        One line naming what to give when the wheel base (or, for angles, the radius) has
        no source; a bad robot file or URDF (one line).
    """
    from drivers.bags import read_bag_urdf, urdf_wheels

    values: dict[str, object] = {}
    sources: dict[str, str] = {}
    robot = None

    def put(key: str, value: object, source: str) -> None:
        if value is not None:
            values[key], sources[key] = value, source

    text = read_bag_urdf(args.bag)
    if text is not None:
        where = "the bag's /robot_description"
        wheels = urdf_wheels(text, source=where)
        joints = f"{where} (joints {wheels.left_joint}, {wheels.right_joint})"
        put("wheel_base_m", wheels.wheel_separation_m, joints)
        put("wheel_radius_m", wheels.wheel_radius_m, joints)
    if args.sim:
        from drivers.sim import robot_geometry

        g = robot_geometry(args.sim)
        robot = g.name
        for key, value in (("wheel_base_m", g.wheel_base_m),
                           ("wheel_radius_m", g.wheel_radius_m),
                           ("ticks_per_rad", g.ticks_per_rad), ("encoders", g.encoders)):
            put(key, value, f"the {g.source} (--robot)")
    for key, flag in (("wheel_base_m", "wheel_base"), ("wheel_radius_m", "wheel_radius"),
                      ("ticks_per_rad", "ticks_per_rad"), ("encoders", "encoders")):
        put(key, getattr(args, flag, None), f"--{flag.replace('_', '-')}")
    needed = ["wheel_base_m"] + (["wheel_radius_m"] if angles else [])
    missing = [k for k in needed if k not in values]
    if missing:
        what = ("wheel angles" if angles else "the robot's odometry twist")
        flags = " and ".join(f"--{k[:-2].replace('_', '-')} M" for k in missing)
        raise ValueError(
            f"{Path(args.bag).name} holds {what} and nothing gives the robot's "
            f"{' and '.join(k[:-2].replace('_', ' ') for k in missing)}: give {flags} "
            "(metres), or --robot FILE (docs/robot_file.md), or record the URDF on "
            "/robot_description")
    return BagGeometry(wheel_base_m=float(values["wheel_base_m"]),
                       wheel_radius_m=(float(values["wheel_radius_m"])
                                       if "wheel_radius_m" in values else None),
                       ticks_per_rad=values.get("ticks_per_rad"),
                       encoders=values.get("encoders"), robot=robot, sources=sources)
