"""Exceptions of the drivers package.

Each subclasses the matching builtin so callers may catch either.

A stream frame whose checksum fails is not an error: the stream parser drops it,
resynchronises and counts it (:attr:`drivers.roomba.StreamParser.checksum_failures`,
``Roomba.counters``), since a few corrupt frames are normal on a serial link (spec G10).
The Sensors (142) and Query List (149) replies carry no checksum (spec §4); a reply of
the wrong length raises :class:`ProtocolError`.
"""

from __future__ import annotations

__all__ = [
    "BagError",
    "DatasetError",
    "PassiveModeError",
    "PortError",
    "ProtocolError",
    "RobotFileError",
    "SimulatorError",
    "StreamBandwidthError",
    "StreamStalledError",
    "UnknownPacketError",
]


class SimulatorError(ValueError):
    """Bad input to the simulator (shape, NaN, unknown preset or floor, ...)."""


class RobotFileError(SimulatorError):
    """A robot description file (or preset name) that cannot describe a robot: unparsable,
    an unknown or missing field, a wrong type or a value out of range. The message names
    the file, the section and the field on one line."""


class ProtocolError(ValueError):
    """Bytes or values that break the Roomba Open Interface protocol."""


class PortError(OSError):
    """A serial port that does not exist, is busy, or went away; names the port."""


class StreamStalledError(TimeoutError):
    """No sensor frame arrived within the allowed number of periods."""


class PassiveModeError(RuntimeError):
    """The robot fell back to passive mode (wheel drop, cliff, charger)."""


class UnknownPacketError(ProtocolError):
    """A sensor packet or group id that the Open Interface does not define (spec §5)."""


class StreamBandwidthError(ProtocolError):
    """A stream request whose frame does not fit in one 15 ms period at the baud (spec §4.1)."""


class DatasetError(ValueError):
    """A dataset folder that is missing files or holds malformed ones."""


class BagError(ValueError):
    """A ROS bag that cannot give what was asked: no usable topic, a wrong message type, an
    empty topic, stamps going backwards, impossible values; the message names the topic."""
