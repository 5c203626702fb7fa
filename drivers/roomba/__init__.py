"""The Roomba wing: the iRobot Roomba / Create 2 over its serial Open Interface.

- :mod:`drivers.roomba.oi`, :mod:`drivers.roomba.oi_packets`: the protocol as pure
  functions (commands, packets, the stream parser);
- :mod:`drivers.roomba.driver`: :class:`Roomba`, the pyserial robot, with its options
  (:class:`RoombaOptions`, :mod:`drivers.roomba.roomba_options`);
- :mod:`drivers.roomba.virtual`: :class:`VirtualRoomba` (its options:
  :class:`VirtualRoombaOptions`, :mod:`drivers.roomba.virtual_options`), the simulator behind the
  protocol on a pseudo-terminal;
- :mod:`drivers.roomba.stream_clock`: sensor-period time from host arrival times.

The names below load with their module on first use (:mod:`lti_motion.lazy`), so
importing the door costs nothing until a name is read.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from lti_motion.lazy import lazy_exports

__all__ = [
    "BAUD_RATES",
    "COMMAND_DATA_BYTES",
    "DEFAULT_BANNER",
    "DEFAULT_BAUD_BPS",
    "DEFAULT_CHARGER_TEXT",
    "DEFAULT_STREAM_IDS",
    "GROUPS",
    "MAX_WHEEL_SPEED_MM_S",
    "PACKETS",
    "SERIAL_LATENCY_TOLERANCE_S",
    "STREAM_HEADER",
    "STREAM_PERIOD_S",
    "EmulatorStats",
    "GroupSpec",
    "LinkCounters",
    "OIMode",
    "Opcode",
    "PacketLayout",
    "PacketSpec",
    "ReceivedCommand",
    "Roomba",
    "RoombaOptions",
    "StreamClock",
    "StreamFrame",
    "StreamParser",
    "VirtualRoomba",
    "VirtualRoombaOptions",
    "baud",
    "check_stream_bandwidth",
    "checksum",
    "data_size",
    "decode_packet_value",
    "decode_query_list_reply",
    "drive_direct",
    "encode_packet_value",
    "encode_query_list_reply",
    "encode_stream_frame",
    "expand_ids",
    "full",
    "is_group",
    "is_pseudo_terminal",
    "lookup_packet",
    "pause_resume_stream",
    "query_list",
    "query_reply_size",
    "reset",
    "safe",
    "sensors",
    "serve",
    "start",
    "stop",
    "stream",
    "stream_budget_bytes",
    "stream_frame_size",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "drivers.roomba.driver": (
            "LinkCounters",
            "Roomba",
            "is_pseudo_terminal",
        ),
        "drivers.roomba.oi": (
            "BAUD_RATES",
            "COMMAND_DATA_BYTES",
            "DEFAULT_BAUD_BPS",
            "DEFAULT_STREAM_IDS",
            "MAX_WHEEL_SPEED_MM_S",
            "OIMode",
            "Opcode",
            "STREAM_PERIOD_S",
            "StreamFrame",
            "StreamParser",
            "baud",
            "check_stream_bandwidth",
            "drive_direct",
            "encode_stream_frame",
            "full",
            "pause_resume_stream",
            "query_list",
            "reset",
            "safe",
            "sensors",
            "start",
            "stop",
            "stream",
            "stream_budget_bytes",
            "stream_frame_size",
        ),
        "drivers.roomba.oi_packets": (
            "GROUPS",
            "GroupSpec",
            "PACKETS",
            "PacketLayout",
            "PacketSpec",
            "STREAM_HEADER",
            "checksum",
            "data_size",
            "decode_packet_value",
            "decode_query_list_reply",
            "encode_packet_value",
            "encode_query_list_reply",
            "expand_ids",
            "is_group",
            "lookup_packet",
            "query_reply_size",
        ),
        "drivers.roomba.roomba_options": (
            "RoombaOptions",
            "SERIAL_LATENCY_TOLERANCE_S",
        ),
        "drivers.roomba.stream_clock": ("StreamClock",),
        "drivers.roomba.virtual": (
            "EmulatorStats",
            "ReceivedCommand",
            "VirtualRoomba",
            "serve",
        ),
        "drivers.roomba.virtual_options": (
            "DEFAULT_BANNER",
            "DEFAULT_CHARGER_TEXT",
            "VirtualRoombaOptions",
        ),
    },
    __all__,
)

if TYPE_CHECKING:
    from drivers.roomba.driver import LinkCounters, Roomba, is_pseudo_terminal
    from drivers.roomba.oi import (
        BAUD_RATES,
        COMMAND_DATA_BYTES,
        DEFAULT_BAUD_BPS,
        DEFAULT_STREAM_IDS,
        MAX_WHEEL_SPEED_MM_S,
        STREAM_PERIOD_S,
        OIMode,
        Opcode,
        StreamFrame,
        StreamParser,
        baud,
        check_stream_bandwidth,
        drive_direct,
        encode_stream_frame,
        full,
        pause_resume_stream,
        query_list,
        reset,
        safe,
        sensors,
        start,
        stop,
        stream,
        stream_budget_bytes,
        stream_frame_size,
    )
    from drivers.roomba.oi_packets import (
        GROUPS,
        PACKETS,
        STREAM_HEADER,
        GroupSpec,
        PacketLayout,
        PacketSpec,
        checksum,
        data_size,
        decode_packet_value,
        decode_query_list_reply,
        encode_packet_value,
        encode_query_list_reply,
        expand_ids,
        is_group,
        lookup_packet,
        query_reply_size,
    )
    from drivers.roomba.roomba_options import SERIAL_LATENCY_TOLERANCE_S, RoombaOptions
    from drivers.roomba.stream_clock import StreamClock
    from drivers.roomba.virtual import EmulatorStats, ReceivedCommand, VirtualRoomba, serve
    from drivers.roomba.virtual_options import (
        DEFAULT_BANNER,
        DEFAULT_CHARGER_TEXT,
        VirtualRoombaOptions,
    )
