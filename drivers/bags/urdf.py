"""A robot's nominal wheels from its URDF: the two wheel joints, their separation and radius.

Read with the standard library (``xml.etree.ElementTree``), the way ROS 1's
``diff_drive_controller`` reads the robot description when ``wheel_separation`` or
``wheel_radius`` is not given (ros_controllers 0.21.2, ``diff_drive_controller.cpp``,
``setOdomParamsFromUrdf``): the separation is the distance between the two wheel joints'
origins (each relative to its parent link, so both wheels should hang from the same link),
the radius is the left wheel link's collision cylinder's (or sphere's) radius.

A wheel joint is a ``continuous`` (or ``revolute``) joint whose child link has a cylinder
or a sphere (collision first, else visual); the left one has ``left`` in its name, the right
one ``right``, unless the joint names are given.

The text may come from a file (:func:`read_urdf_wheels`) or from a bag's own
``/robot_description`` topic (``std_msgs/String``, latched by ``robot_state_publisher``;
:func:`read_bag_urdf`, then :func:`urdf_wheels`).
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from drivers.bags.messages import is_mcap, open_bag, raw_messages
from drivers.exceptions import BagError

__all__ = ["ROBOT_DESCRIPTION_TOPIC", "UrdfWheels", "read_bag_urdf", "read_urdf_wheels",
           "urdf_wheels"]

#: Where ``robot_state_publisher`` publishes the URDF (``std_msgs/String``).
ROBOT_DESCRIPTION_TOPIC = "/robot_description"


@dataclass(frozen=True)
class UrdfWheels:
    """The wheel joints a URDF describes.

    Attributes
    ----------
    left_joint, right_joint : str
        Joint names (``diff_drive_controller``'s ``left_wheel_names`` / ``left_wheel``).
    wheel_separation_m : float
        Distance between the joints' origins [m].
    wheel_radius_m : float
        The left wheel link's cylinder (or sphere) radius [m].
    """

    left_joint: str
    right_joint: str
    wheel_separation_m: float
    wheel_radius_m: float


def _radius(link: ET.Element | None) -> float | None:
    if link is None:
        return None
    for part in ("collision", "visual"):
        for element in link.findall(part):
            for shape in ("cylinder", "sphere"):
                geometry = element.find(f"geometry/{shape}")
                if geometry is not None and geometry.get("radius") is not None:
                    return float(geometry.get("radius"))
    return None


def _origin(joint: ET.Element) -> tuple[float, float, float]:
    origin = joint.find("origin")
    xyz = "0 0 0" if origin is None else origin.get("xyz", "0 0 0")
    values = [float(v) for v in xyz.split()]
    if len(values) != 3:
        raise ValueError(f"joint {joint.get('name')!r}: origin xyz {xyz!r} is not three numbers")
    return values[0], values[1], values[2]


def read_urdf_wheels(path: str | os.PathLike, *, left_joint: str | None = None,
                     right_joint: str | None = None) -> UrdfWheels:
    """The two wheel joints of a URDF file, their separation and radius (module docstring).

    Parameters
    ----------
    path : str or path-like
        The URDF (plain XML; run xacro first).
    left_joint, right_joint : str, optional
        The wheel joints' names, when their names do not say left and right.

    Returns
    -------
    UrdfWheels

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    ValueError
        If the file is not XML, or it has no wheel joints (or not one per side).

    Examples
    --------
    >>> import tempfile
    >>> text = '''<robot name="r">
    ...   <link name="base_link"/>
    ...   <link name="wl"><collision><geometry><cylinder radius="0.05" length="0.02"/>
    ...   </geometry></collision></link>
    ...   <link name="wr"><collision><geometry><cylinder radius="0.05" length="0.02"/>
    ...   </geometry></collision></link>
    ...   <joint name="left_wheel_joint" type="continuous"><parent link="base_link"/>
    ...     <child link="wl"/><origin xyz="0 0.15 0"/></joint>
    ...   <joint name="right_wheel_joint" type="continuous"><parent link="base_link"/>
    ...     <child link="wr"/><origin xyz="0 -0.15 0"/></joint>
    ... </robot>'''
    >>> with tempfile.NamedTemporaryFile("w", suffix=".urdf", delete=False) as f:
    ...     _ = f.write(text)
    >>> wheels = read_urdf_wheels(f.name)
    >>> wheels.left_joint, wheels.right_joint, wheels.wheel_separation_m, wheels.wheel_radius_m
    ('left_wheel_joint', 'right_wheel_joint', 0.3, 0.05)
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no URDF file {path}")
    return urdf_wheels(path.read_text(encoding="utf-8", errors="replace"),
                       source=f"URDF {path}", left_joint=left_joint, right_joint=right_joint)


def urdf_wheels(text: str, *, source: str = "the URDF", left_joint: str | None = None,
                right_joint: str | None = None) -> UrdfWheels:
    """The two wheel joints of a URDF's text, their separation and radius (module docstring).

    Parameters
    ----------
    text : str
        The URDF (plain XML; run xacro first).
    source : str
        What it is, for the messages (``"URDF robot.urdf"``, ``"the bag's /robot_description"``).
    left_joint, right_joint : str, optional
        The wheel joints' names, when their names do not say left and right.

    Returns
    -------
    UrdfWheels

    Raises
    ------
    ValueError
        If the text is not XML, or it has no wheel joints (or not one per side).
    """
    path = source
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ValueError(f"{path} is not XML ({exc}); give the expanded URDF "
                         "(xacro file.xacro > file.urdf)") from None
    links = {link.get("name"): link for link in root.iter("link")}
    wheels = {}
    for joint in root.iter("joint"):
        if joint.get("type") not in ("continuous", "revolute"):
            continue
        child = joint.find("child")
        radius = _radius(links.get(None if child is None else child.get("link")))
        if radius is not None:
            wheels[joint.get("name")] = (joint, radius)
    named = {"left": left_joint, "right": right_joint}
    chosen = {}
    for side, name in named.items():
        if name is not None:
            if name not in wheels:
                raise ValueError(f"{path} has no wheel joint {name!r} (a continuous joint "
                                 f"whose child link has a cylinder or sphere); wheel joints: "
                                 f"{sorted(wheels) or 'none'}")
            chosen[side] = name
            continue
        found = [n for n in wheels if side in n.lower()]
        if len(found) != 1:
            raise ValueError(f"{path} has no wheel joints to use: {len(found)} {side} "
                             f"ones among {sorted(wheels) or 'none'} (a continuous joint whose "
                             "child link has a cylinder or sphere, with 'left' / 'right' in its "
                             "name); name them with --left-joint and --right-joint")
        chosen[side] = found[0]
    (left, radius), (right, _) = wheels[chosen["left"]], wheels[chosen["right"]]
    separation = math.dist(_origin(left), _origin(right))
    if not (separation > 0 and radius > 0):
        raise ValueError(f"{path}: wheel separation {separation:g} m and radius "
                         f"{radius:g} m must be positive")
    return UrdfWheels(chosen["left"], chosen["right"], round(separation, 12), radius)


def read_bag_urdf(path: str | os.PathLike, *, topic: str = ROBOT_DESCRIPTION_TOPIC
                  ) -> str | None:
    """The URDF a bag recorded on ``topic`` (``std_msgs/String``; its last message), or None.

    Raises
    ------
    FileNotFoundError, BagError
        No such bag, not a bag, or ``topic`` of another type.
    """
    with open_bag(path) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            return None
        if conns[0].msgtype != "std_msgs/msg/String":
            raise BagError(f"topic {topic} holds {conns[0].msgtype}, not the URDF as a "
                           "std_msgs/String")
        _, raws = raw_messages(reader, conns, mcap=is_mcap(path))[topic]
        if not raws:
            return None
        store = reader.typestore
        decode = store.deserialize_cdr if reader.is2 else store.deserialize_ros1
        return str(decode(raws[-1], "std_msgs/msg/String").data)
