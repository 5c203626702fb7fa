"""Exceptions of the drivers package.

Each subclasses the matching builtin so callers may catch either.
"""

from __future__ import annotations

__all__ = [
    "ChecksumError",
    "DatasetError",
    "PassiveModeError",
    "PortError",
    "ProtocolError",
    "SimulatorError",
    "StreamBandwidthError",
    "StreamStalledError",
    "UnknownPacketError",
]


class SimulatorError(ValueError):
    """Bad input to the simulator (shape, NaN, unknown preset or floor, ...)."""


class ProtocolError(ValueError):
    """Bytes or values that break the Roomba Open Interface protocol."""


class ChecksumError(ProtocolError):
    """A stream frame whose bytes do not sum to zero modulo 256."""


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
