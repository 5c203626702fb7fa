"""The Roomba wing: the iRobot Roomba / Create 2 over its serial Open Interface.

- :mod:`drivers.roomba.oi`, :mod:`drivers.roomba.oi_packets`: the protocol as pure
  functions (commands, packets, the stream parser);
- :mod:`drivers.roomba.driver`: :class:`Roomba`, the pyserial robot;
- :mod:`drivers.roomba.virtual`: :class:`VirtualRoomba`, the simulator behind the
  protocol on a pseudo-terminal;
- :mod:`drivers.roomba.stream_clock`: sensor-period time from host arrival times.
"""

from drivers.roomba.driver import LinkCounters, Roomba
from drivers.roomba.stream_clock import StreamClock
from drivers.roomba.virtual import VirtualRoomba, serve

__all__ = ["LinkCounters", "Roomba", "StreamClock", "VirtualRoomba", "serve"]
