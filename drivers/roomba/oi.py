"""The iRobot Roomba / Create 2 Open Interface (OI) protocol as pure code.

Bytes in, values out, and back: opcodes, command encoders, packet decoding,
query-list replies, and an incremental stream-frame parser that resyncs on
corrupt data. Nothing here touches a port, a clock or a thread; the pyserial
driver and the virtual Roomba both build on these functions.

Section numbers ("spec §4.1") and gotchas ("G9") are those of the project's
Open Interface fact sheet, which restates the iRobot Create 2 Open Interface
Specification (August 2016) page by page: §1 the serial line (§1.3 baud rates,
§1.4 sleep, BRC wake and charging), §2 OI modes, §3 commands (§3.1 Drive, §3.2
Drive Direct, §3.3 bit fields, §3.4 Song), §4 sensor access (§4.1 the stream
frame, its resync and bandwidth), §5 the sensor packets (§5.1 groups), §6
distance and angle caveats (§6.1 firmware bugs, §6.2 non-quadrature encoders,
§6.3 firmware version and banners), §7 encoders to odometry (§7.1 constants,
§7.2 formulas), §8 an emulator on a pseudo-terminal (§8.1 byte 19 as XOFF,
§8.3 modem-line ioctls, §8.5 the emulator's checklist), §9 known gotchas G1-G21
(e.g. G3 the robot asleep or at the wrong baud, G7 Safe falling back to
Passive, G9 a stream too large for its period, G17 the FTDI latency timer).

The packet table, value codecs and byte layouts live in
:mod:`drivers.roomba.oi_packets`; their public names are re-exported here so callers
need one import.

Examples
--------
Drive the left wheel backward and the right wheel forward (right goes first
on the wire, spec §3.2):

>>> drive_direct(left_mm_s=-200, right_mm_s=200).hex(" ")
'91 00 c8 ff 38'

Parse iRobot's stream example (spec §4.1):

>>> StreamParser([29, 13]).feed(bytes([19, 5, 29, 2, 25, 13, 0, 163]))
[StreamFrame(ids=(29, 13), values=(537, 0))]
"""

from __future__ import annotations

import logging
import math
import struct
import types
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from enum import IntEnum
from numbers import Integral, Real

from drivers.exceptions import ProtocolError, StreamBandwidthError
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

__all__ = [
    "BAUD_RATES",
    "COMMAND_DATA_BYTES",
    "DEFAULT_BAUD_BPS",
    "DEFAULT_STREAM_IDS",
    "GROUPS",
    "MAX_WHEEL_SPEED_MM_S",
    "PACKETS",
    "STREAM_HEADER",
    "STREAM_PERIOD_S",
    "GroupSpec",
    "OIMode",
    "Opcode",
    "PacketLayout",
    "PacketSpec",
    "StreamFrame",
    "StreamParser",
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
    "lookup_packet",
    "pause_resume_stream",
    "query_list",
    "query_reply_size",
    "reset",
    "safe",
    "sensors",
    "start",
    "stop",
    "stream",
    "stream_budget_bytes",
    "stream_frame_size",
]

_log = logging.getLogger(__name__)

#: The robot sends one stream frame every 15 ms (spec §4, §4.1).
STREAM_PERIOD_S = 0.015
#: Default baud of the Roomba 500/600 and Create 2 (spec §1.3).
DEFAULT_BAUD_BPS = 115200
#: Wheel speed limit of Drive Direct, mm/s (spec §3.2).
MAX_WHEEL_SPEED_MM_S = 500
#: Baud rate of each Baud (129) code 0..11 (spec §1.3).
BAUD_RATES: tuple[int, ...] = (300, 600, 1200, 2400, 4800, 9600, 14400, 19200, 28800,
                               38400, 57600, 115200)
_BITS_PER_BYTE = 10  # 8N1: start + 8 data + stop bits (spec §4.1 "Bandwidth limit")

#: The sensor packets this project streams: bumps & wheel drops 7, wheel
#: overcurrents 14, battery voltage 22 / current 23 / charge 25 / capacity 26,
#: OI mode 35, requested right/left velocity 41/42, encoder counts 43/44, light
#: bumper 45, light bump signals 46-51, left/right motor currents 54/55 and
#: stasis 58. The frame is 61 bytes, within the 172.8-byte budget at 115200
#: baud (spec §4.1).
DEFAULT_STREAM_IDS: tuple[int, ...] = (7, 14, 22, 23, 25, 26, 35, 41, 42, 43, 44, 45,
                                       46, 47, 48, 49, 50, 51, 54, 55, 58)


class Opcode(IntEnum):
    """Open Interface command opcodes (spec §3).

    Examples
    --------
    >>> Opcode.DRIVE_DIRECT, int(Opcode.STOP)
    (<Opcode.DRIVE_DIRECT: 145>, 173)
    """

    RESET = 7
    START = 128
    BAUD = 129
    CONTROL = 130
    SAFE = 131
    FULL = 132
    POWER = 133
    SPOT = 134
    CLEAN = 135
    MAX = 136
    DRIVE = 137
    MOTORS = 138
    LEDS = 139
    SONG = 140
    PLAY = 141
    SENSORS = 142
    SEEK_DOCK = 143
    PWM_MOTORS = 144
    DRIVE_DIRECT = 145
    DRIVE_PWM = 146
    STREAM = 148
    QUERY_LIST = 149
    PAUSE_RESUME_STREAM = 150
    SCHEDULING_LEDS = 162
    DIGIT_LEDS_RAW = 163
    DIGIT_LEDS_ASCII = 164
    BUTTONS = 165
    SCHEDULE = 167
    SET_DAY_TIME = 168
    STOP = 173


class OIMode(IntEnum):
    """Values of sensor packet 35, the OI mode (spec §2)."""

    OFF = 0
    PASSIVE = 1
    SAFE = 2
    FULL = 3


#: Data bytes after each opcode (spec §3); ``None`` where the count is in the
#: command itself (Song: 2N+2, Stream and Query List: N+1).
COMMAND_DATA_BYTES: Mapping[Opcode, int | None] = types.MappingProxyType({
    Opcode.RESET: 0, Opcode.START: 0, Opcode.BAUD: 1, Opcode.CONTROL: 0, Opcode.SAFE: 0,
    Opcode.FULL: 0, Opcode.POWER: 0, Opcode.SPOT: 0, Opcode.CLEAN: 0, Opcode.MAX: 0,
    Opcode.DRIVE: 4, Opcode.MOTORS: 1, Opcode.LEDS: 3, Opcode.SONG: None, Opcode.PLAY: 1,
    Opcode.SENSORS: 1, Opcode.SEEK_DOCK: 0, Opcode.PWM_MOTORS: 3, Opcode.DRIVE_DIRECT: 4,
    Opcode.DRIVE_PWM: 4, Opcode.STREAM: None, Opcode.QUERY_LIST: None,
    Opcode.PAUSE_RESUME_STREAM: 1, Opcode.SCHEDULING_LEDS: 2, Opcode.DIGIT_LEDS_RAW: 4,
    Opcode.DIGIT_LEDS_ASCII: 4, Opcode.BUTTONS: 1, Opcode.SCHEDULE: 15,
    Opcode.SET_DAY_TIME: 3, Opcode.STOP: 0,
})


# --------------------------------------------------------------------------- commands


def start() -> bytes:
    """Start (128): enter Passive mode from any mode, Off included (spec §2, §3)."""
    return bytes((Opcode.START,))


def safe() -> bytes:
    """Safe (131): full control with the cliff, wheel-drop and charger safeties (spec §2)."""
    return bytes((Opcode.SAFE,))


def full() -> bytes:
    """Full (132): full control with the safeties disabled (spec §2)."""
    return bytes((Opcode.FULL,))


def stop() -> bytes:
    """Stop (173): stop all streams and put the OI in Off mode (spec §2, §3)."""
    return bytes((Opcode.STOP,))


def reset() -> bytes:
    """Reset (7): like pulling the battery; prints a boot banner, ends in Off (spec §6.3)."""
    return bytes((Opcode.RESET,))


def baud(baud_bps: int) -> bytes:
    """Baud (129): change the serial rate; wait 100 ms before sending at it (spec §1.3).

    Parameters
    ----------
    baud_bps : int
        One of :data:`BAUD_RATES`, bits per second.

    Raises
    ------
    ProtocolError
        If the rate has no baud code.

    Examples
    --------
    >>> list(baud(115200))
    [129, 11]
    """
    if isinstance(baud_bps, bool) or baud_bps not in BAUD_RATES:
        raise ProtocolError(f"baud rate {baud_bps!r} bps has no Baud (129) code; expected one "
                            f"of {BAUD_RATES} (spec §1.3)")
    return bytes((Opcode.BAUD, BAUD_RATES.index(baud_bps)))


def _wheel_speed_mm_s(name: str, value: float) -> int:
    """Validate one Drive Direct wheel speed and return it as an int (spec §3.2)."""
    if isinstance(value, bool) or not isinstance(value, Real):
        raise TypeError(f"{name} must be a real number of mm/s, got {type(value).__name__}")
    if not isinstance(value, Integral) and not math.isfinite(float(value)):
        raise ProtocolError(f"{name} = {value!r} mm/s is not finite; expected a number in "
                            f"[-{MAX_WHEEL_SPEED_MM_S}, {MAX_WHEEL_SPEED_MM_S}] mm/s (spec §3.2)")
    if not -MAX_WHEEL_SPEED_MM_S <= value <= MAX_WHEEL_SPEED_MM_S:
        raise ProtocolError(f"{name} = {value!r} mm/s is out of range [-{MAX_WHEEL_SPEED_MM_S}, "
                            f"{MAX_WHEEL_SPEED_MM_S}] mm/s (spec §3.2); clip it before sending")
    return int(value) if isinstance(value, Integral) else round(float(value))


def drive_direct(left_mm_s: float, right_mm_s: float) -> bytes:
    """Drive Direct (145): set each wheel's speed (spec §3.2).

    Parameters
    ----------
    left_mm_s, right_mm_s : int or float
        Wheel speeds, mm/s, each in [-500, 500]; positive drives forward.
        The range is checked on the value given, then floats are rounded to
        the nearest integer mm/s with :func:`round` (halves go to the even
        neighbour). The robot's speed controller works in steps of about
        28.5 mm/s anyway (spec §3.1).

    Returns
    -------
    bytes
        ``[145][right hi][right lo][left hi][left lo]``: the **right** wheel
        comes first on the wire, int16 big-endian.

    Raises
    ------
    ProtocolError
        If a speed is NaN, infinite or outside [-500, 500] mm/s; nothing is
        encoded.
    TypeError
        If a speed is not a real number (``bool`` included).

    Examples
    --------
    >>> list(drive_direct(left_mm_s=100, right_mm_s=-1))
    [145, 255, 255, 0, 100]
    >>> list(drive_direct(0.4, 2.5))
    [145, 0, 2, 0, 0]
    """
    left = _wheel_speed_mm_s("left_mm_s", left_mm_s)
    right = _wheel_speed_mm_s("right_mm_s", right_mm_s)
    return struct.pack(">Bhh", Opcode.DRIVE_DIRECT, right, left)


def sensors(packet_id: int) -> bytes:
    """Sensors (142): ask once for one packet or group (spec §4).

    The reply is the bare data bytes (:func:`data_size` of them): no header,
    no id, no checksum. Flush the input before sending.

    Raises
    ------
    UnknownPacketError
        If ``packet_id`` is not a packet or group.

    Examples
    --------
    >>> list(sensors(100))
    [142, 100]
    """
    (pid,) = PacketLayout.from_ids((packet_id,), what="Sensors (142)").ids
    return bytes((Opcode.SENSORS, pid))


def query_list(ids: Iterable[int]) -> bytes:
    """Query List (149): ask once for several packets (spec §4).

    The reply is the concatenated data bytes of each id in order
    (:func:`query_reply_size` of them), with no framing.

    Raises
    ------
    UnknownPacketError
        If an id is unknown.
    ProtocolError
        If there are not 1..255 ids.

    Examples
    --------
    >>> list(query_list([43, 44]))
    [149, 2, 43, 44]
    """
    out = PacketLayout.from_ids(ids, what="Query List (149)").ids
    return bytes((Opcode.QUERY_LIST, len(out), *out))


def stream(ids: Iterable[int]) -> bytes:
    """Stream (148): start a frame every 15 ms with these packets (spec §4.1).

    Check the frame fits the baud with :func:`check_stream_bandwidth` first.

    Raises
    ------
    UnknownPacketError
        If an id is unknown.
    ProtocolError
        If there are not 1..255 ids, or the frame's ``n`` exceeds 255.

    Examples
    --------
    >>> list(stream([7, 43, 44]))
    [148, 3, 7, 43, 44]
    """
    layout = PacketLayout.from_ids(ids, what="Stream (148)")
    layout.require_streamable()
    return bytes((Opcode.STREAM, len(layout.ids), *layout.ids))


def pause_resume_stream(*, resume: bool) -> bytes:
    """Pause/Resume Stream (150): 0 pauses and keeps the list, 1 resumes (spec §4).

    Examples
    --------
    >>> list(pause_resume_stream(resume=False))
    [150, 0]
    """
    if not isinstance(resume, bool):
        raise TypeError(f"resume must be a bool, got {type(resume).__name__}")
    return bytes((Opcode.PAUSE_RESUME_STREAM, 1 if resume else 0))


# ------------------------------------------------------------------- bandwidth (§4.1)


def stream_frame_size(ids: Iterable[int]) -> int:
    """Bytes of one stream frame for a request list: header, n, payload, checksum.

    Notes
    -----
    ``n = sum(1 + data_size(id))`` and the frame is ``n + 3`` bytes (spec §4.1).

    Examples
    --------
    >>> stream_frame_size([7, 43, 44]), stream_frame_size(DEFAULT_STREAM_IDS)
    (11, 61)
    """
    return PacketLayout.from_ids(ids, what="Stream (148)").frame_size


def stream_budget_bytes(baud_bps: float, *, period_s: float = STREAM_PERIOD_S) -> float:
    """Bytes the line carries in one stream period (spec §4.1 "Bandwidth limit").

    Parameters
    ----------
    baud_bps : float
        Serial rate, bits per second, > 0.
    period_s : float
        Stream period, s (15 ms on the robot).

    Returns
    -------
    float
        ``baud_bps / 10 * period_s``, bytes (8N1 takes 10 bits per byte).

    Raises
    ------
    ProtocolError
        If a rate or period is not a finite positive number.

    Examples
    --------
    >>> round(stream_budget_bytes(115200), 6), round(stream_budget_bytes(19200), 6)
    (172.8, 28.8)
    """
    for name, v in (("baud_bps", baud_bps), ("period_s", period_s)):
        if isinstance(v, bool) or not isinstance(v, Real) or not (math.isfinite(v) and v > 0):
            raise ProtocolError(f"{name} must be a finite positive number, got {v!r}")
    return baud_bps / _BITS_PER_BYTE * period_s


def check_stream_bandwidth(ids: Iterable[int], *, baud_bps: float = DEFAULT_BAUD_BPS) -> int:
    """Raise unless a stream frame fits in one 15 ms period at ``baud_bps`` (spec §4.1).

    Asking for more than fits makes the robot's stream "eventually become
    corrupted" (spec §4.1, §9 G9).

    Returns
    -------
    int
        The frame size, bytes.

    Raises
    ------
    StreamBandwidthError
        If ``stream_frame_size(ids) > stream_budget_bytes(baud_bps)``.

    Examples
    --------
    >>> check_stream_bandwidth([100])
    84
    >>> check_stream_bandwidth([100], baud_bps=19200)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    drivers.exceptions.StreamBandwidthError: stream frame of 84 bytes exceeds the 28.8-byte ...
    """
    size = stream_frame_size(ids)
    budget = stream_budget_bytes(baud_bps)
    if size > budget:
        raise StreamBandwidthError(
            f"stream frame of {size} bytes exceeds the {budget:.1f}-byte budget of one 15 ms "
            f"period at {baud_bps:g} baud (spec §4.1); request fewer packets or a faster baud")
    return size


def encode_stream_frame(ids: Iterable[int], values: Mapping[int, int]) -> bytes:
    """Encode one stream frame with its checksum: the inverse of :class:`StreamParser`.

    Parameters
    ----------
    ids : iterable of int
        The requested packet and group ids, in request order.
    values : mapping
        ``{packet_id: value}`` for every single packet (group members included).

    Returns
    -------
    bytes
        ``[19][n][id1][data1...]...[checksum]`` (spec §4.1).

    Raises
    ------
    ProtocolError
        If a value is missing or out of range, or ``n`` exceeds 255.

    Examples
    --------
    The second worked example of spec §4.1:

    >>> encode_stream_frame([7, 43, 44], {7: 1, 43: 1000, 44: 65530}).hex(" ")
    '13 08 07 01 2b 03 e8 2c ff fa a2'
    """
    return PacketLayout.from_ids(ids, what="Stream (148)").encode_frame(values)


# ----------------------------------------------------------------------- stream parser


@dataclass(frozen=True, slots=True)
class StreamFrame:
    """The decoded values of one valid stream frame.

    Attributes
    ----------
    ids : tuple of int
        Single packet ids, in wire order (requested groups expanded).
    values : tuple of int
        Decoded value of each id, aligned with ``ids``.

    Examples
    --------
    >>> f = StreamFrame(ids=(43, 44), values=(1000, 65530))
    >>> f[44], f.as_dict()
    (65530, {43: 1000, 44: 65530})
    """

    ids: tuple[int, ...]
    values: tuple[int, ...]

    def __getitem__(self, packet_id: int) -> int:
        """Value of ``packet_id`` (its first occurrence); ``KeyError`` if absent."""
        try:
            return self.values[self.ids.index(packet_id)]
        except ValueError:
            raise KeyError(packet_id) from None

    def as_dict(self) -> dict[int, int]:
        """``{packet_id: value}``; a repeated packet keeps its first value."""
        out: dict[int, int] = {}
        for pid, v in zip(self.ids, self.values, strict=True):
            out.setdefault(pid, v)
        return out


class StreamParser:
    """Incremental parser of Stream (148) frames with resync (spec §4.1).

    Parameters
    ----------
    ids : iterable of int
        The requested packet and group ids, exactly as sent with
        :func:`stream`; they fix the frame length and id pattern.

    Attributes
    ----------
    frames_ok : int
        Valid frames returned so far.
    bad_length : int
        Candidate headers rejected because ``n`` differed from the expected value.
    checksum_failures : int
        Candidates with the right ``n`` whose bytes did not sum to 0 mod 256.
    bad_id : int
        Candidates with a good checksum but ids out of the requested pattern.
    bytes_dropped : int
        Bytes discarded: skipped while searching for a header (ASCII banners,
        charger text, line noise) plus each rejected candidate header byte.
        At all times ``bytes fed == frames_ok * frame_size + bytes_dropped + buffered``.

    Notes
    -----
    The resync algorithm of spec §4.1: (1) find a 19; (2) reject it unless the
    next byte is the expected ``n``; (3) wait for ``n + 1`` more bytes and
    reject it unless the frame sums to 0 mod 256; (4) reject it unless the
    ids sit at their offsets in request order; (5) on any rejection drop only
    that candidate header byte and rescan from the next byte, since 19 can
    occur inside data and a real frame may start inside a rejected candidate.
    A byte is discarded only once every candidate covering it is decided, so
    the result does not depend on how the input is chunked, and a frame is
    never lost unless an earlier overlapping candidate passes all four checks.

    At most ``frame_size - 1`` bytes stay buffered between calls (a candidate
    waiting for the rest of its frame), so garbage cannot grow the buffer.

    Since the id list is fixed, a valid frame has a fixed length and layout:
    the ids are compared and the values unpacked with one precompiled
    :class:`struct.Struct` each, and :meth:`bytes.find` jumps between
    candidate headers.

    Examples
    --------
    The second worked example of spec §4.1, split across two reads and
    preceded by a boot banner:

    >>> p = StreamParser([7, 43, 44])
    >>> frame = bytes.fromhex("13 08 07 01 2b 03 e8 2c ff fa a2")
    >>> p.feed(b"Roomba by iRobot!\\r\\n" + frame[:4])
    []
    >>> p.feed(frame[4:])
    [StreamFrame(ids=(7, 43, 44), values=(1, 1000, 65530))]
    >>> p.frames_ok, p.bytes_dropped, p.buffered
    (1, 19, 0)
    """

    def __init__(self, ids: Iterable[int]) -> None:
        layout = PacketLayout.from_ids(ids, what="Stream (148)")
        layout.require_streamable()
        self.layout = layout
        self.frames_ok = 0
        self.bad_length = 0
        self.checksum_failures = 0
        self.bad_id = 0
        self.bytes_dropped = 0
        self._buf = bytearray()

    @property
    def ids(self) -> tuple[int, ...]:
        """The requested packet and group ids."""
        return self.layout.ids

    @property
    def frame_size(self) -> int:
        """Bytes of one valid frame, ``n + 3``."""
        return self.layout.frame_size

    @property
    def buffered(self) -> int:
        """Bytes held back for the next :meth:`feed` (a possible partial frame)."""
        return len(self._buf)

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[StreamFrame]:
        """Add received bytes and return the valid frames they complete, in order.

        Never raises on any byte content; invalid data only updates the counters.

        Parameters
        ----------
        chunk : bytes-like
            Bytes as read from the port, any length (empty included): any
            object with the buffer protocol (``bytes``, ``bytearray``,
            ``memoryview``, ``array.array``, a NumPy ``uint8`` array), read as
            its raw bytes in C order.

        Raises
        ------
        TypeError
            If ``chunk`` is not bytes-like (e.g. a list of ints or a ``str``).

        Returns
        -------
        list of StreamFrame
            Frames completed by this chunk, oldest first.
        """
        buf = self._buf
        view = memoryview(chunk)          # any buffer; a NumPy array would broadcast in +=
        buf += view.cast("B") if view.c_contiguous else view.tobytes()
        end = len(buf)
        layout = self.layout
        n = layout.n
        size = layout.frame_size
        ids_unpack = layout.frame_ids_struct.unpack_from
        values_unpack = layout.frame_values_struct.unpack_from
        expected_ids = layout.ids
        field_ids = layout.field_ids
        find = buf.find
        frames: list[StreamFrame] = []
        append = frames.append
        pos = dropped = bad_len = bad_sum = bad_id = 0
        while True:
            i = find(STREAM_HEADER, pos)  # step 1: next candidate header
            if i < 0:
                dropped += end - pos
                pos = end
                break
            dropped += i - pos
            pos = i
            if i + 1 >= end:
                break  # wait for n
            if buf[i + 1] != n:  # step 2
                bad_len += 1
            else:
                stop_ = i + size
                if stop_ > end:
                    break  # step 3: wait for n + 1 more bytes
                if sum(buf[i:stop_]) & 0xFF:
                    bad_sum += 1
                elif ids_unpack(buf, i) != expected_ids:  # step 4
                    bad_id += 1
                else:
                    append(StreamFrame(field_ids, values_unpack(buf, i)))
                    pos = stop_
                    continue
            dropped += 1  # step 5: drop only the candidate header byte
            pos = i + 1
        if pos:
            del buf[:pos]
        self.frames_ok += len(frames)
        self.bytes_dropped += dropped
        self.bad_length += bad_len
        self.checksum_failures += bad_sum
        self.bad_id += bad_id
        if bad_sum or bad_id:
            _log.debug("stream %s: rejected %d candidate(s) by checksum, %d by id pattern",
                       list(expected_ids), bad_sum, bad_id)
        return frames
