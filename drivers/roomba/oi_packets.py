"""The Open Interface sensor packet table, packet groups and their byte layouts.

One frozen :class:`PacketSpec` per single sensor packet (ids 7-58) and one
:class:`GroupSpec` per packet group (ids 0-6, 100, 101, 106, 107), transcribed
from the project's Open Interface fact sheet (spec §5 and §5.1, listed in
:mod:`drivers.roomba.oi`, which in turn cite the iRobot Create 2 OI Specification pp. 23-32 and
the membership table p. 39). A group's size is *computed* from its members;
the test suite checks it against the sizes printed in spec §5.1.

Every multi-byte value is big-endian (spec §5). Two deliberate departures
from the printed "Type" column:

* packets 43 and 44 (encoder counts) are decoded as **unsigned** 16-bit
  modular counters 0..65535, because the project unwraps them with
  :func:`lti_motion.recordings.unwrap_ticks` (spec §7.2);
* packets 54-57 (motor currents) are decoded as signed int16, as the spec's
  header and range say, although its prose says "unsigned" (spec §5).

:class:`PacketLayout` turns a request list into precompiled :mod:`struct`
layouts for Sensors (142) / Query List (149) replies and Stream (148) frames
(spec §4, §4.1); the value codecs here are shared by the driver, the stream
parser in :mod:`drivers.roomba.oi` and the virtual Roomba.

This module holds no I/O and no mutable module-level state (the tables are
read-only mappings).
"""

from __future__ import annotations

import struct
import types
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from numbers import Integral, Real

from drivers.exceptions import ProtocolError, UnknownPacketError

__all__ = [
    "GROUPS",
    "PACKETS",
    "STREAM_HEADER",
    "GroupSpec",
    "PacketLayout",
    "PacketSpec",
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
]

#: First byte of every stream frame (spec §4.1).
STREAM_HEADER = 19


@dataclass(frozen=True, kw_only=True)
class PacketSpec:
    """One single sensor packet of the Open Interface (spec §5).

    Every field is keyword-only (``signed`` is a boolean, never positional).

    Parameters
    ----------
    id : int
        Packet id, 7..58.
    name : str
        Snake-case identifier, e.g. ``"left_encoder_counts"``.
    size : int
        Data bytes on the wire (1 or 2), big-endian.
    signed : bool
        Two's complement when true.
    unit : str
        Unit of the decoded value (``"mm/s"``, ``"mA"``, ``"ticks"``, ...),
        ``"bits"`` for bit fields, ``"enum"`` for coded states.
    description : str
        One line of meaning and range, from spec §5.

    Examples
    --------
    >>> PACKETS[43].size, PACKETS[43].signed, PACKETS[43].max_value
    (2, False, 65535)
    """

    id: int
    name: str
    size: int
    signed: bool
    unit: str
    description: str

    @property
    def min_value(self) -> int:
        """Smallest value the packet can carry (from size and signedness)."""
        return -(1 << (8 * self.size - 1)) if self.signed else 0

    @property
    def max_value(self) -> int:
        """Largest value the packet can carry (from size and signedness)."""
        bits = 8 * self.size - (1 if self.signed else 0)
        return (1 << bits) - 1

    @property
    def struct_code(self) -> str:
        """The :mod:`struct` code of the value (``b``, ``B``, ``h`` or ``H``)."""
        code = "b" if self.size == 1 else "h"
        return code if self.signed else code.upper()


@dataclass(frozen=True)
class GroupSpec:
    """One packet group: a group id standing for several packets (spec §5.1).

    Parameters
    ----------
    id : int
        Group id (0-6, 100, 101, 106, 107).
    name : str
        Short identifier.
    members : tuple of int
        Member packet ids, in wire order.

    Examples
    --------
    >>> GROUPS[107].members, GROUPS[107].size
    ((54, 55, 56, 57, 58), 9)
    """

    id: int
    name: str
    members: tuple[int, ...]

    @property
    def size(self) -> int:
        """Data bytes of the whole group: the sum of its members' sizes."""
        return sum(PACKETS[m].size for m in self.members)


def _p(pid: int, name: str, size: int, unit: str, description: str, *, signed: bool
       ) -> PacketSpec:
    return PacketSpec(id=pid, name=name, size=size, signed=signed, unit=unit,
                      description=description)


# Transcribed from spec §5 (SPEC pp. 23-32); see the module docstring for the
# two deliberate decoding choices (43/44 unsigned, 54-57 signed).
_PACKET_LIST: tuple[PacketSpec, ...] = (
    _p(7, "bumps_wheel_drops", 1, "bits",
       "bit0 bump right, bit1 bump left, bit2 wheel drop right, bit3 wheel drop left",
       signed=False),
    _p(8, "wall", 1, "bool", "deprecated; same as light bumper right", signed=False),
    _p(9, "cliff_left", 1, "bool", "cliff left, 0-1", signed=False),
    _p(10, "cliff_front_left", 1, "bool", "cliff front left, 0-1", signed=False),
    _p(11, "cliff_front_right", 1, "bool", "cliff front right, 0-1", signed=False),
    _p(12, "cliff_right", 1, "bool", "cliff right, 0-1", signed=False),
    _p(13, "virtual_wall", 1, "bool", "virtual wall seen, 0-1", signed=False),
    _p(14, "wheel_overcurrents", 1, "bits",
       "bit0 side brush, bit2 main brush, bit3 right wheel, bit4 left wheel", signed=False),
    _p(15, "dirt_detect", 1, "count", "dirt level 0-255", signed=False),
    _p(16, "unused_1", 1, "raw", "unused, always 0; sent inside groups 0, 1, 6", signed=False),
    _p(17, "ir_opcode_omni", 1, "enum", "IR character omni, 0 = nothing received", signed=False),
    _p(18, "buttons", 1, "bits", "button bits (spec §3.3)", signed=False),
    _p(19, "distance", 2, "mm", "distance since last read; firmware bug (spec §6.1)", signed=True),
    _p(20, "angle", 2, "deg",
       "angle since last read, CCW positive; firmware bug (spec §6.1)", signed=True),
    _p(21, "charging_state", 1, "enum",
       "0 not charging, 1 reconditioning, 2 full, 3 trickle, 4 waiting, 5 fault", signed=False),
    _p(22, "voltage", 2, "mV", "battery voltage", signed=False),
    _p(23, "current", 2, "mA", "battery current, negative = discharging", signed=True),
    _p(24, "temperature", 1, "degC", "battery temperature", signed=True),
    _p(25, "battery_charge", 2, "mAh", "battery charge", signed=False),
    _p(26, "battery_capacity", 2, "mAh", "battery capacity", signed=False),
    _p(27, "wall_signal", 2, "raw", "wall signal 0-1023; deprecated, use 51", signed=False),
    _p(28, "cliff_left_signal", 2, "raw", "cliff left signal 0-4095", signed=False),
    _p(29, "cliff_front_left_signal", 2, "raw", "cliff front left signal 0-4095", signed=False),
    _p(30, "cliff_front_right_signal", 2, "raw", "cliff front right signal 0-4095", signed=False),
    _p(31, "cliff_right_signal", 2, "raw", "cliff right signal 0-4095", signed=False),
    _p(32, "unused_2", 1, "raw", "unused (1 byte)", signed=False),
    _p(33, "unused_3", 2, "raw", "unused (2 bytes)", signed=False),
    _p(34, "charging_sources", 1, "bits", "bit0 internal charger, bit1 home base", signed=False),
    _p(35, "oi_mode", 1, "enum",
       "0 off, 1 passive, 2 safe, 3 full (off by one on some 600s, spec §9 G8)", signed=False),
    _p(36, "song_number", 1, "count", "selected song 0-4", signed=False),
    _p(37, "song_playing", 1, "bool", "song playing, 0-1", signed=False),
    _p(38, "number_of_stream_packets", 1, "count", "stream packets 0-108", signed=False),
    _p(39, "requested_velocity", 2, "mm/s", "last Drive (137) velocity, -500..500", signed=True),
    _p(40, "requested_radius", 2, "mm", "last Drive (137) radius", signed=True),
    _p(41, "requested_right_velocity", 2, "mm/s",
       "last Drive Direct (145) right velocity, -500..500", signed=True),
    _p(42, "requested_left_velocity", 2, "mm/s",
       "last Drive Direct (145) left velocity, -500..500", signed=True),
    _p(43, "left_encoder_counts", 2, "ticks",
       "cumulative left ticks, unsigned 16-bit modular counter (spec §7)", signed=False),
    _p(44, "right_encoder_counts", 2, "ticks",
       "cumulative right ticks, unsigned 16-bit modular counter (spec §7)", signed=False),
    _p(45, "light_bumper", 1, "bits",
       "bit0 L, bit1 FL, bit2 CL, bit3 CR, bit4 FR, bit5 R", signed=False),
    _p(46, "light_bump_left_signal", 2, "raw", "0-4095", signed=False),
    _p(47, "light_bump_front_left_signal", 2, "raw", "0-4095", signed=False),
    _p(48, "light_bump_center_left_signal", 2, "raw", "0-4095", signed=False),
    _p(49, "light_bump_center_right_signal", 2, "raw", "0-4095", signed=False),
    _p(50, "light_bump_front_right_signal", 2, "raw", "0-4095", signed=False),
    _p(51, "light_bump_right_signal", 2, "raw", "0-4095", signed=False),
    _p(52, "ir_opcode_left", 1, "enum", "IR character left", signed=False),
    _p(53, "ir_opcode_right", 1, "enum", "IR character right", signed=False),
    _p(54, "left_motor_current", 2, "mA", "left wheel motor current", signed=True),
    _p(55, "right_motor_current", 2, "mA", "right wheel motor current", signed=True),
    _p(56, "main_brush_motor_current", 2, "mA", "main brush motor current", signed=True),
    _p(57, "side_brush_motor_current", 2, "mA", "side brush motor current", signed=True),
    _p(58, "stasis", 1, "bits",
       "bit0 stasis toggling (forward progress), bit1 stasis disabled", signed=False),
)

#: Single packets by id (spec §5), read-only.
PACKETS: Mapping[int, PacketSpec] = types.MappingProxyType({p.id: p for p in _PACKET_LIST})


def _g(gid: int, name: str, first: int, last: int) -> GroupSpec:
    return GroupSpec(id=gid, name=name, members=tuple(range(first, last + 1)))


# Membership from spec §5.1 (SPEC p. 23, p. 37): every group is a contiguous id range.
_GROUP_LIST: tuple[GroupSpec, ...] = (
    _g(0, "group_0", 7, 26),
    _g(1, "group_1", 7, 16),
    _g(2, "group_2", 17, 20),
    _g(3, "group_3", 21, 26),
    _g(4, "group_4", 27, 34),
    _g(5, "group_5", 35, 42),
    _g(6, "group_6", 7, 42),
    _g(100, "group_100", 7, 58),
    _g(101, "group_101", 43, 58),
    _g(106, "group_106", 46, 51),
    _g(107, "group_107", 54, 58),
)

#: Packet groups by id (spec §5.1), read-only.
GROUPS: Mapping[int, GroupSpec] = types.MappingProxyType({g.id: g for g in _GROUP_LIST})


def _unknown(packet_id: object) -> UnknownPacketError:
    return UnknownPacketError(
        f"unknown sensor packet id {packet_id!r}: expected a packet 7..58 or a group "
        f"{sorted(GROUPS)} (spec §5, §5.1)"
    )


def is_group(packet_id: int) -> bool:
    """Whether ``packet_id`` is a packet group id (spec §5.1).

    Raises
    ------
    UnknownPacketError
        If ``packet_id`` is neither a packet nor a group.

    Examples
    --------
    >>> is_group(100), is_group(43)
    (True, False)
    """
    if isinstance(packet_id, bool) or not isinstance(packet_id, Integral):
        raise _unknown(packet_id)
    if packet_id in GROUPS:
        return True
    if packet_id in PACKETS:
        return False
    raise _unknown(packet_id)


def lookup_packet(packet_id: int) -> PacketSpec:
    """The :class:`PacketSpec` of a single packet id.

    Raises
    ------
    UnknownPacketError
        If ``packet_id`` is not a single packet 7..58 (a group id included).

    Examples
    --------
    >>> lookup_packet(22).unit
    'mV'
    """
    if is_group(packet_id):
        raise UnknownPacketError(
            f"id {packet_id} is a packet group (spec §5.1), not a single packet; "
            f"use expand_ids() for its members"
        )
    return PACKETS[packet_id]


def data_size(packet_id: int) -> int:
    """Data bytes of a packet or group, as sent by opcode 142 (spec §4, §5).

    Parameters
    ----------
    packet_id : int
        A packet (7..58) or group id.

    Returns
    -------
    int
        Bytes, without the id byte.

    Raises
    ------
    UnknownPacketError
        If the id is unknown.

    Examples
    --------
    >>> data_size(7), data_size(43), data_size(100)
    (1, 2, 80)
    """
    if is_group(packet_id):
        return GROUPS[packet_id].size
    return PACKETS[packet_id].size


def expand_ids(ids: Iterable[int]) -> tuple[int, ...]:
    """Replace each group id by its member packet ids, keeping wire order.

    Parameters
    ----------
    ids : iterable of int
        Packet and/or group ids.

    Returns
    -------
    tuple of int
        Single packet ids in the order their bytes appear on the wire.

    Raises
    ------
    UnknownPacketError
        If any id is unknown.

    Examples
    --------
    >>> expand_ids([7, 106, 58])
    (7, 46, 47, 48, 49, 50, 51, 58)
    """
    out: list[int] = []
    for pid in ids:
        if is_group(pid):
            out.extend(GROUPS[pid].members)
        else:
            out.append(pid)
    return tuple(out)


def _checked_ids(ids: Iterable[int], *, what: str) -> tuple[int, ...]:
    """Validate a request list of packet/group ids: known, 1..255 of them (spec §4)."""
    if isinstance(ids, (str, bytes, bytearray)) or not isinstance(ids, Iterable):
        raise TypeError(f"{what} ids must be an iterable of packet ids, got {ids!r}")
    out = tuple(ids)
    if not 1 <= len(out) <= 255:
        raise ProtocolError(f"{what} needs 1..255 packet ids (N is one byte, spec §4), "
                            f"got {len(out)}")
    for pid in out:
        is_group(pid)  # raises UnknownPacketError naming the id
    return tuple(int(pid) for pid in out)


# ----------------------------------------------------------------- values and layouts


def _checked_value(spec: PacketSpec, value: int) -> int:
    if isinstance(value, Integral):
        v = int(value)
        if spec.min_value <= v <= spec.max_value:
            return v
    elif not isinstance(value, Real):
        raise TypeError(f"packet {spec.id} ({spec.name}) value must be an int, "
                        f"got {type(value).__name__}")
    raise ProtocolError(f"packet {spec.id} ({spec.name}) value {value!r} is not an integer in "
                        f"[{spec.min_value}, {spec.max_value}] (spec §5)")


def encode_packet_value(packet_id: int, value: int) -> bytes:
    """The data bytes of one single packet's value, big-endian (spec §5).

    Raises
    ------
    UnknownPacketError
        If ``packet_id`` is not a single packet (groups included).
    ProtocolError
        If ``value`` is not an integer in the packet's range.

    Examples
    --------
    >>> encode_packet_value(23, -1).hex(), encode_packet_value(44, 65530).hex()
    ('ffff', 'fffa')
    """
    spec = lookup_packet(packet_id)
    return struct.pack(">" + spec.struct_code, _checked_value(spec, value))


def decode_packet_value(packet_id: int, data: bytes) -> int:
    """Decode one single packet's data bytes (big-endian, signedness per spec §5).

    Encoder counts 43/44 come out unsigned, 0..65535 (spec §7).

    Raises
    ------
    UnknownPacketError
        If ``packet_id`` is not a single packet.
    ProtocolError
        If ``len(data)`` differs from the packet's size.

    Examples
    --------
    >>> decode_packet_value(23, b"\\xff\\x38"), decode_packet_value(43, b"\\xff\\xfa")
    (-200, 65530)
    """
    spec = lookup_packet(packet_id)
    if len(data) != spec.size:
        raise ProtocolError(f"packet {spec.id} ({spec.name}) has {spec.size} data bytes, "
                            f"got {len(data)} (spec §5)")
    return struct.unpack(">" + spec.struct_code, data)[0]


def checksum(data: bytes) -> int:
    """Checksum byte making the 8-bit sum of a frame zero (spec §4.1).

    Parameters
    ----------
    data : bytes
        The frame without its checksum: header, n and payload.

    Examples
    --------
    >>> checksum(bytes([19, 5, 29, 2, 25, 13, 0]))
    163
    """
    return -sum(data) & 0xFF


@dataclass(frozen=True)
class PacketLayout:
    """Byte layout of a request list, shared by Query List replies and stream frames.

    Build it with :meth:`from_ids`; it precompiles :class:`struct.Struct`
    objects so that a whole reply or frame is packed or unpacked in one call.

    Attributes
    ----------
    ids : tuple of int
        The requested packet and group ids, in order.
    field_ids : tuple of int
        ``expand_ids(ids)``: one single packet id per decoded value.
    n : int
        The stream frame's ``n`` byte: ``sum(1 + data_size(id))`` (spec §4.1).
    frame_size : int
        Stream frame bytes, ``n + 3``.
    reply_size : int
        Query List (149) reply bytes, ``sum(data_size(id))`` (spec §4).
    reply_struct, payload_struct : struct.Struct
        Reply data; frame payload (ids and data) for packing.
    frame_values_struct, frame_ids_struct : struct.Struct
        Unpack a whole frame's values, or its id bytes, from the header offset.

    Examples
    --------
    >>> lay = PacketLayout.from_ids([7, 43, 44])
    >>> lay.n, lay.frame_size, lay.reply_size
    (8, 11, 5)
    """

    ids: tuple[int, ...]
    field_ids: tuple[int, ...]
    n: int
    frame_size: int
    reply_size: int
    reply_struct: struct.Struct = field(repr=False, compare=False)
    payload_struct: struct.Struct = field(repr=False, compare=False)
    frame_values_struct: struct.Struct = field(repr=False, compare=False)
    frame_ids_struct: struct.Struct = field(repr=False, compare=False)

    @classmethod
    def from_ids(cls, ids: Iterable[int], *, what: str = "request") -> PacketLayout:
        """Layout of ``ids`` (1..255 known packet or group ids).

        Parameters
        ----------
        ids : iterable of int
            Requested packet and group ids, in request order.
        what : str
            The command the ids are for, quoted in error messages.

        Raises
        ------
        UnknownPacketError
            If an id is unknown.
        ProtocolError
            If there are not 1..255 ids.
        """
        req = _checked_ids(ids, what=what)
        codes = ["".join(lookup_packet(m).struct_code for m in expand_ids((pid,)))
                 for pid in req]
        sizes = [data_size(pid) for pid in req]
        n = sum(1 + s for s in sizes)
        return cls(
            ids=req,
            field_ids=expand_ids(req),
            n=n,
            frame_size=n + 3,
            reply_size=sum(sizes),
            reply_struct=struct.Struct(">" + "".join(codes)),
            payload_struct=struct.Struct(">" + "".join("B" + c for c in codes)),
            # header and n skipped, each id byte skipped, checksum skipped
            frame_values_struct=struct.Struct(">2x" + "".join("x" + c for c in codes) + "x"),
            frame_ids_struct=struct.Struct(">2x" + "".join(f"B{s}x" for s in sizes) + "x"),
        )

    def require_streamable(self) -> None:
        """Raise :class:`ProtocolError` if ``n`` does not fit its one byte (spec §4.1)."""
        if self.n > 255:
            raise ProtocolError(f"stream frame n = {self.n} does not fit in one byte (<= 255, "
                                f"spec §4.1); request fewer packets")

    def _values(self, values: Mapping[int, int]) -> list[int]:
        out = []
        for pid in self.field_ids:
            try:
                v = values[pid]
            except KeyError:
                raise ProtocolError(f"no value given for packet {pid} "
                                    f"({PACKETS[pid].name})") from None
            out.append(_checked_value(PACKETS[pid], v))
        return out

    def encode_reply(self, values: Mapping[int, int]) -> bytes:
        """Query List (149) reply bytes: each field's data, no framing (spec §4).

        ``values`` maps single packet ids (group members included) to values.
        """
        return self.reply_struct.pack(*self._values(values))

    def decode_reply(self, data: bytes) -> dict[int, int]:
        """Decode Query List (149) or Sensors (142) reply bytes to ``{packet_id: value}``.

        A packet repeated in the request (e.g. 7 with group 0) keeps its first value.
        """
        if len(data) != self.reply_size:
            raise ProtocolError(
                f"reply to {list(self.ids)} must be {self.reply_size} bytes, got {len(data)} "
                f"(spec §4); flush the input before each query and treat short reads as errors")
        return _first_wins(self.field_ids, self.reply_struct.unpack(data))

    def encode_frame(self, values: Mapping[int, int]) -> bytes:
        """One stream frame ``[19][n][id1][data1]...[checksum]`` (spec §4.1)."""
        self.require_streamable()
        body = bytes((STREAM_HEADER, self.n)) + self.payload_struct.pack(
            *_interleave(self.ids, self._grouped(self._values(values))))
        return body + bytes((checksum(body),))

    def _grouped(self, flat: list[int]) -> list[list[int]]:
        out, k = [], 0
        for pid in self.ids:
            m = len(GROUPS[pid].members) if pid in GROUPS else 1
            out.append(flat[k:k + m])
            k += m
        return out


def _interleave(ids: tuple[int, ...], grouped: list[list[int]]) -> list[int]:
    out: list[int] = []
    for pid, vals in zip(ids, grouped, strict=True):
        out.append(pid)
        out.extend(vals)
    return out


def _first_wins(ids: tuple[int, ...], values: tuple[int, ...]) -> dict[int, int]:
    out: dict[int, int] = {}
    for pid, v in zip(ids, values, strict=True):
        out.setdefault(pid, v)
    return out


def query_reply_size(ids: Iterable[int]) -> int:
    """Bytes of the reply to Query List (149) for ``ids`` (spec §4).

    Examples
    --------
    >>> query_reply_size([7, 43, 44]), query_reply_size([100])
    (5, 80)
    """
    return PacketLayout.from_ids(ids, what="Query List (149)").reply_size


def decode_query_list_reply(ids: Iterable[int], data: bytes) -> dict[int, int]:
    """Decode the reply to Query List (149), or to Sensors (142) with one id (spec §4).

    Parameters
    ----------
    ids : iterable of int
        The requested packet and group ids, in request order.
    data : bytes
        Exactly :func:`query_reply_size` bytes.

    Returns
    -------
    dict
        ``{packet_id: value}`` for every single packet (groups expanded); a
        packet repeated in the request keeps its first value.

    Raises
    ------
    ProtocolError
        If ``len(data)`` is wrong (flush input before each query; spec §4, §9 G11).
    UnknownPacketError
        If an id is unknown.

    Examples
    --------
    >>> decode_query_list_reply([7, 43, 44], bytes([1, 3, 232, 255, 250]))
    {7: 1, 43: 1000, 44: 65530}
    """
    return PacketLayout.from_ids(ids, what="Query List (149)").decode_reply(data)


def encode_query_list_reply(ids: Iterable[int], values: Mapping[int, int]) -> bytes:
    """The robot's reply to Query List (149) or Sensors (142): the inverse of decoding.

    ``values`` maps single packet ids (group members included) to values.

    Raises
    ------
    ProtocolError
        If a value is missing or out of its packet's range.

    Examples
    --------
    >>> list(encode_query_list_reply([7, 43], {7: 1, 43: 1000}))
    [1, 3, 232]
    """
    return PacketLayout.from_ids(ids, what="Query List (149)").encode_reply(values)
