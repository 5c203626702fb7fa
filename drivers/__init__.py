"""Where data comes from, as wings: the simulator and the Roomba; logs and data sets.

- :mod:`drivers.sim`: the physics simulator of a differential-drive robot (the
  embedded default), its configuration and compiled kernel;
- :mod:`drivers.roomba`: the Roomba / Create 2 Open Interface, the pyserial robot,
  the virtual Roomba on a pseudo-terminal, the stream clock;
- :mod:`drivers.logs`, :mod:`drivers.datasets`: recorded logs and public data sets;
- :mod:`drivers.bags.reader`, :mod:`drivers.bags.topics`, :mod:`drivers.bags.writer`: ROS bags in
  and out (``rosbags``).

Importing this package loads only its exceptions; each wing loads what it needs.
"""

from drivers.exceptions import (
    BagError,
    DatasetError,
    PortError,
    ProtocolError,
    SimulatorError,
    StreamStalledError,
)

__all__ = ["BagError", "DatasetError", "PortError", "ProtocolError", "SimulatorError",
           "StreamStalledError"]
