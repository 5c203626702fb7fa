"""Example-based tests of the Open Interface protocol layer (drivers.roomba.oi and oi_packets).

Reference values are labelled with their source: "spec §N" is the project's
Open Interface fact sheet, whose sections :mod:`drivers.roomba.oi` lists.
"""

from __future__ import annotations

import array
import logging
import math

import numpy as np
import pytest

from drivers.exceptions import (
    ProtocolError,
    StreamBandwidthError,
    UnknownPacketError,
)
from drivers.roomba.oi import (
    BAUD_RATES,
    COMMAND_DATA_BYTES,
    DEFAULT_STREAM_IDS,
    GROUPS,
    PACKETS,
    Opcode,
    PacketLayout,
    PacketSpec,
    StreamFrame,
    StreamParser,
    baud,
    check_stream_bandwidth,
    checksum,
    data_size,
    decode_packet_value,
    decode_query_list_reply,
    drive_direct,
    encode_packet_value,
    encode_query_list_reply,
    encode_stream_frame,
    expand_ids,
    full,
    is_group,
    lookup_packet,
    pause_resume_stream,
    query_list,
    query_reply_size,
    reset,
    safe,
    sensors,
    start,
    stop,
    stream,
    stream_budget_bytes,
    stream_frame_size,
)
from lti_motion.recordings.ticks import unwrap_ticks

# Unknown ids: holes in the id space of spec §5 / §5.1.
UNKNOWN_IDS = [59, 60, 99, 102, 105, 108, 127, 255]

# Spec §4.1, iRobot's example: request [148][2][29][13].
SPEC_FRAME_1 = bytes([19, 5, 29, 2, 25, 13, 0, 163])
# Spec §4.1, second worked example: request [148][3][7][43][44].
SPEC_FRAME_2 = bytes.fromhex("13 08 07 01 2B 03 E8 2C FF FA A2")


def random_values(rng: np.random.Generator, ids: tuple[int, ...]) -> dict[int, int]:
    """Uniform random value for every single packet of ``ids`` over its full range."""
    return {pid: int(rng.integers(PACKETS[pid].min_value, PACKETS[pid].max_value + 1))
            for pid in expand_ids(ids)}


# ------------------------------------------------------------------ opcodes and table


# spec §3 opcode table
SPEC_OPCODES = {
    "RESET": 7, "START": 128, "BAUD": 129, "CONTROL": 130, "SAFE": 131, "FULL": 132,
    "POWER": 133, "SPOT": 134, "CLEAN": 135, "MAX": 136, "DRIVE": 137, "MOTORS": 138,
    "LEDS": 139, "SONG": 140, "PLAY": 141, "SENSORS": 142, "SEEK_DOCK": 143,
    "PWM_MOTORS": 144, "DRIVE_DIRECT": 145, "DRIVE_PWM": 146, "STREAM": 148,
    "QUERY_LIST": 149, "PAUSE_RESUME_STREAM": 150, "SCHEDULING_LEDS": 162,
    "DIGIT_LEDS_RAW": 163, "DIGIT_LEDS_ASCII": 164, "BUTTONS": 165, "SCHEDULE": 167,
    "SET_DAY_TIME": 168, "STOP": 173,
}


@pytest.mark.parametrize(("name", "value"), sorted(SPEC_OPCODES.items()))
def test_opcode_values_match_spec(name: str, value: int) -> None:
    assert Opcode[name] == value


def test_every_opcode_has_a_data_byte_count() -> None:
    assert set(COMMAND_DATA_BYTES) == set(Opcode)
    # spec §3 "Data bytes" column, spot checks
    assert COMMAND_DATA_BYTES[Opcode.DRIVE_DIRECT] == 4
    assert COMMAND_DATA_BYTES[Opcode.SCHEDULE] == 15
    assert COMMAND_DATA_BYTES[Opcode.STREAM] is None


# spec §5: two-byte packets and signed packets (43/44 deliberately unsigned, 54-57 int16)
TWO_BYTE_IDS = {19, 20, 22, 23, 25, 26, 27, 28, 29, 30, 31, 33, 39, 40, 41, 42, 43, 44,
                46, 47, 48, 49, 50, 51, 54, 55, 56, 57}
SIGNED_IDS = {19, 20, 23, 24, 39, 40, 41, 42, 54, 55, 56, 57}


@pytest.mark.parametrize("pid", range(7, 59))
def test_packet_table_matches_spec(pid: int) -> None:
    spec = PACKETS[pid]
    assert spec.id == pid
    assert spec.size == (2 if pid in TWO_BYTE_IDS else 1)
    assert spec.signed == (pid in SIGNED_IDS)
    assert spec.name.isidentifier() and spec.unit and spec.description


def test_a_packet_spec_takes_its_fields_by_keyword_only() -> None:
    # a boolean is never positional: the signedness cannot slide into another slot
    with pytest.raises(TypeError, match="positional"):
        PacketSpec(7, "bumps_wheel_drops", 1, False, "bits", "bumps")  # type: ignore[misc]
    spec = PACKETS[19]
    assert PacketSpec(id=19, name=spec.name, size=2, signed=True, unit=spec.unit,
                      description=spec.description) == spec


def test_packet_table_has_exactly_7_to_58() -> None:
    assert sorted(PACKETS) == list(range(7, 59))


def test_encoder_counts_are_unsigned_and_motor_currents_int16() -> None:
    assert (PACKETS[43].min_value, PACKETS[43].max_value) == (0, 65535)
    assert (PACKETS[44].min_value, PACKETS[44].max_value) == (0, 65535)
    for pid in (54, 55, 56, 57):
        assert (PACKETS[pid].min_value, PACKETS[pid].max_value) == (-32768, 32767)


# spec §5.1 "Bytes" column
SPEC_GROUP_SIZES = {0: 26, 1: 10, 2: 6, 3: 10, 4: 14, 5: 12, 6: 52, 100: 80, 101: 28,
                    106: 12, 107: 9}


@pytest.mark.parametrize(("gid", "size"), sorted(SPEC_GROUP_SIZES.items()))
def test_group_sizes_computed_from_members_match_spec(gid: int, size: int) -> None:
    assert GROUPS[gid].size == size
    assert data_size(gid) == size
    assert query_reply_size([gid]) == size
    assert is_group(gid)


def test_groups_are_exactly_the_spec_groups() -> None:
    assert sorted(GROUPS) == sorted(SPEC_GROUP_SIZES)


# spec §5.1, byte offsets inside group 100 (first byte of each packet)
GROUP_100_OFFSETS = {7: 0, 8: 1, 14: 7, 17: 10, 19: 12, 21: 16, 24: 21, 27: 26, 32: 36,
                     33: 37, 34: 39, 35: 40, 39: 44, 43: 52, 44: 54, 45: 56, 46: 57,
                     52: 69, 53: 70, 54: 71, 58: 79}


def test_group_100_byte_offsets_match_spec() -> None:
    offsets, k = {}, 0
    for pid in GROUPS[100].members:
        offsets[pid] = k
        k += PACKETS[pid].size
    assert {pid: offsets[pid] for pid in GROUP_100_OFFSETS} == GROUP_100_OFFSETS


@pytest.mark.parametrize("bad", [*UNKNOWN_IDS, -1, 256])
def test_unknown_ids_are_named_in_the_error(bad: int) -> None:
    pattern = rf"unknown sensor packet id {bad}\b"
    for fn in (data_size, is_group, sensors, lookup_packet):
        with pytest.raises(UnknownPacketError, match=pattern):
            fn(bad)
    for fn in (query_list, stream, stream_frame_size, query_reply_size, StreamParser):
        with pytest.raises(UnknownPacketError, match=pattern):
            fn([7, bad])
    with pytest.raises(UnknownPacketError, match=pattern):
        decode_packet_value(bad, b"\x00")


def test_unknown_packet_error_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="unknown sensor packet id 59"):
        stream([59])


def test_bool_and_non_integer_ids_are_rejected() -> None:
    with pytest.raises(UnknownPacketError, match="True"):
        sensors(True)
    with pytest.raises(UnknownPacketError, match=r"id 7\.0"):
        query_list([7.0])
    with pytest.raises(TypeError, match="iterable of packet ids"):
        stream(b"\x07")


def test_group_is_not_a_single_packet() -> None:
    with pytest.raises(UnknownPacketError, match="100 is a packet group"):
        lookup_packet(100)
    with pytest.raises(UnknownPacketError, match="100 is a packet group"):
        encode_packet_value(100, 0)


# ------------------------------------------------------------------------- commands


def test_mode_commands() -> None:
    assert (start(), safe(), full(), stop(), reset()) == (b"\x80", b"\x83", b"\x84",
                                                          b"\xad", b"\x07")


@pytest.mark.parametrize(("left", "right", "wire"), [
    # [145][right hi][right lo][left hi][left lo], int16 big-endian (spec §3.2)
    (0, 0, [145, 0, 0, 0, 0]),
    (100, 200, [145, 0, 200, 0, 100]),
    (-200, 200, [145, 0, 200, 255, 56]),
    (500, -500, [145, 254, 12, 1, 244]),
    (-1, 1, [145, 0, 1, 255, 255]),
])
def test_drive_direct_puts_right_wheel_first(left: int, right: int, wire: list[int]) -> None:
    assert list(drive_direct(left, right)) == wire
    assert list(drive_direct(left_mm_s=left, right_mm_s=right)) == wire


def test_drive_direct_rounds_floats_and_accepts_numpy_scalars() -> None:
    assert drive_direct(99.6, -0.4) == drive_direct(100, 0)
    assert drive_direct(0.5, 1.5) == drive_direct(0, 2)  # round(): halves to even
    assert drive_direct(np.float64(499.9), np.int16(-3)) == drive_direct(500, -3)


@pytest.mark.parametrize(("kwargs", "pattern"), [
    ({"left_mm_s": 501, "right_mm_s": 0}, r"left_mm_s = 501 mm/s is out of range \[-500, 500\]"),
    ({"left_mm_s": 0, "right_mm_s": -500.5},
     r"right_mm_s = -500.5 mm/s is out of range \[-500, 500\]"),
    ({"left_mm_s": math.nan, "right_mm_s": 0}, r"left_mm_s = nan mm/s is not finite"),
    ({"left_mm_s": 0, "right_mm_s": -math.inf}, r"right_mm_s = -inf mm/s is not finite"),
    ({"left_mm_s": 0, "right_mm_s": 10**6}, r"right_mm_s = 1000000 mm/s is out of range"),
])
def test_drive_direct_range_errors(kwargs: dict, pattern: str) -> None:
    with pytest.raises(ProtocolError, match=pattern):
        drive_direct(**kwargs)


@pytest.mark.parametrize("bad", [True, "100", None])
def test_drive_direct_rejects_non_numbers(bad: object) -> None:
    with pytest.raises(TypeError, match="left_mm_s must be a real number"):
        drive_direct(bad, 0)


def test_sensor_request_commands() -> None:
    assert list(sensors(35)) == [142, 35]
    assert list(sensors(0)) == [142, 0]
    assert list(query_list([43, 44, 7])) == [149, 3, 43, 44, 7]
    assert list(stream(DEFAULT_STREAM_IDS)) == [148, len(DEFAULT_STREAM_IDS),
                                                *DEFAULT_STREAM_IDS]
    assert list(stream([np.int64(100)])) == [148, 1, 100]
    assert list(pause_resume_stream(resume=True)) == [150, 1]
    assert list(pause_resume_stream(resume=False)) == [150, 0]


def test_pause_resume_needs_a_bool() -> None:
    with pytest.raises(TypeError, match="resume must be a bool, got int"):
        pause_resume_stream(resume=1)


def test_request_length_limits() -> None:
    with pytest.raises(ProtocolError, match=r"needs 1..255 packet ids .* got 0"):
        stream([])
    with pytest.raises(ProtocolError, match=r"needs 1..255 packet ids .* got 256"):
        query_list([7] * 256)
    # 4 x group 100 is n = 4 * 81 = 324 > 255 (spec §4.1: n is one byte)
    with pytest.raises(ProtocolError, match="n = 324 does not fit in one byte"):
        stream([100] * 4)
    with pytest.raises(ProtocolError, match="n = 324"):
        StreamParser([100] * 4)
    assert query_reply_size([100] * 4) == 320  # fine for a query


@pytest.mark.parametrize(("code", "rate"), list(enumerate(BAUD_RATES)))
def test_baud_codes(code: int, rate: int) -> None:
    assert list(baud(rate)) == [129, code]


def test_baud_rejects_unknown_rate() -> None:
    with pytest.raises(ProtocolError, match="baud rate 9601 bps has no Baud"):
        baud(9601)


# ------------------------------------------------------------------------ bandwidth


def test_stream_budget_matches_spec() -> None:
    # spec §4.1 "Bandwidth limit": 172.8, 86.4 and 28.8 bytes per 15 ms
    assert stream_budget_bytes(115200) == pytest.approx(172.8)
    assert stream_budget_bytes(57600) == pytest.approx(86.4)
    assert stream_budget_bytes(19200) == pytest.approx(28.8)


def test_frame_sizes() -> None:
    assert stream_frame_size([29, 13]) == len(SPEC_FRAME_1)
    assert stream_frame_size([7, 43, 44]) == len(SPEC_FRAME_2)
    assert stream_frame_size([100]) == 84  # spec §4.1: "group 100 ... 84-byte frame"


def test_default_stream_fits_at_115200_only() -> None:
    size = check_stream_bandwidth(DEFAULT_STREAM_IDS)
    assert size == stream_frame_size(DEFAULT_STREAM_IDS) <= 172.8
    assert check_stream_bandwidth(DEFAULT_STREAM_IDS, baud_bps=57600) == size
    with pytest.raises(StreamBandwidthError, match=r"61 bytes exceeds the 28.8-byte budget"):
        check_stream_bandwidth(DEFAULT_STREAM_IDS, baud_bps=19200)


def test_bandwidth_boundary() -> None:
    # 28 bytes fit in the 28.8-byte budget at 19200 baud; 29 do not.
    ids_28 = [106, 22, 23, 25, 26]  # n = 13 + 4 * 3 = 25 -> 28 bytes
    assert stream_frame_size(ids_28) == 28
    ids_29 = [106, 22, 23, 25, 7, 45]  # n = 13 + 3 * 3 + 2 * 2 = 26 -> 29 bytes
    assert stream_frame_size(ids_29) == 29
    assert check_stream_bandwidth(ids_28, baud_bps=19200) == 28
    with pytest.raises(StreamBandwidthError, match="29 bytes"):
        check_stream_bandwidth(ids_29, baud_bps=19200)


@pytest.mark.parametrize("bad", [0, -115200, math.nan, math.inf, True])
def test_bandwidth_rejects_bad_baud(bad: float) -> None:
    with pytest.raises(ProtocolError, match="baud_bps must be a finite positive number"):
        check_stream_bandwidth([7], baud_bps=bad)


# ------------------------------------------------------------------- value codecs


@pytest.mark.parametrize("pid", range(7, 59))
def test_packet_value_round_trip_at_extremes(pid: int) -> None:
    spec = PACKETS[pid]
    for v in (spec.min_value, 0, 1, spec.max_value):
        data = encode_packet_value(pid, v)
        assert len(data) == spec.size
        assert decode_packet_value(pid, data) == v


def test_packet_decoding_is_big_endian_and_signed_per_table() -> None:
    assert decode_packet_value(22, b"\x3a\x98") == 15000  # mV
    assert decode_packet_value(23, b"\xfc\x18") == -1000  # mA, negative = discharging
    assert decode_packet_value(24, b"\xff") == -1  # degC, signed byte
    assert decode_packet_value(43, b"\xff\xff") == 65535  # modular counter, not -1
    assert decode_packet_value(54, b"\xff\x9c") == -100  # int16 motor current


def test_packet_codec_errors() -> None:
    with pytest.raises(ProtocolError, match=r"packet 43 .* has 2 data bytes, got 3"):
        decode_packet_value(43, b"\x00\x00\x00")
    with pytest.raises(ProtocolError, match=r"value 65536 is not an integer in \[0, 65535\]"):
        encode_packet_value(43, 65536)
    with pytest.raises(ProtocolError, match=r"value -1 is not an integer in \[0, 65535\]"):
        encode_packet_value(44, -1)
    with pytest.raises(ProtocolError, match=r"value 1.5 is not an integer"):
        encode_packet_value(7, 1.5)
    with pytest.raises(TypeError, match="must be an int, got str"):
        encode_packet_value(7, "1")


def test_checksum_of_spec_examples() -> None:
    assert checksum(SPEC_FRAME_1[:-1]) == SPEC_FRAME_1[-1] == 163
    assert checksum(SPEC_FRAME_2[:-1]) == SPEC_FRAME_2[-1] == 0xA2
    assert sum(SPEC_FRAME_1) % 256 == sum(SPEC_FRAME_2) % 256 == 0


def test_query_list_reply_round_trip(rng: np.random.Generator) -> None:
    ids = (7, 100, 43, 106)
    values = random_values(rng, ids)
    data = encode_query_list_reply(ids, values)
    assert len(data) == query_reply_size(ids) == 1 + 80 + 2 + 12
    assert decode_query_list_reply(ids, data) == values


def test_sensors_reply_of_a_group() -> None:
    data = bytes(range(12))  # group 106: light bump signals 46..51, u16 each
    assert decode_query_list_reply([106], data) == {46: 0x0001, 47: 0x0203, 48: 0x0405,
                                                    49: 0x0607, 50: 0x0809, 51: 0x0A0B}


def test_query_reply_with_a_repeated_packet_keeps_the_first_value() -> None:
    data = bytes([5]) + bytes(range(10))  # 7, then group 1 = packets 7..16 (1 byte each)
    decoded = decode_query_list_reply([7, 1], data)
    assert decoded[7] == 5 and decoded[8] == 1 and decoded[16] == 9


def test_query_reply_wrong_length_says_to_flush() -> None:
    with pytest.raises(ProtocolError, match=r"must be 5 bytes, got 4 .* flush the input"):
        decode_query_list_reply([7, 43, 44], b"\x00" * 4)


def test_encoding_needs_every_value() -> None:
    with pytest.raises(ProtocolError, match=r"no value given for packet 44"):
        encode_stream_frame([7, 43, 44], {7: 0, 43: 0})


# ------------------------------------------------------------- stream frames (§4.1)


def test_spec_example_1_encode_and_parse() -> None:
    # The spec writes the cliff signal as "0x0225 = 549", but the frame's bytes are
    # decimal (they must be: with 0x25 the frame would not sum to 0 mod 256), so the
    # signal is 2 * 256 + 25 = 537. The byte list and its checksum are authoritative.
    assert encode_stream_frame([29, 13], {29: 537, 13: 0}) == SPEC_FRAME_1
    assert StreamParser([29, 13]).feed(SPEC_FRAME_1) == [
        StreamFrame(ids=(29, 13), values=(537, 0))]


def test_spec_example_2_encode_and_parse() -> None:
    assert encode_stream_frame([7, 43, 44], {7: 1, 43: 1000, 44: 65530}) == SPEC_FRAME_2
    (frame,) = StreamParser([7, 43, 44]).feed(SPEC_FRAME_2)
    assert frame.as_dict() == {7: 1, 43: 1000, 44: 65530}
    assert frame[7] & 0b0001  # right bumper pressed


def test_default_stream_round_trip_random_values(rng: np.random.Generator) -> None:
    parser = StreamParser(DEFAULT_STREAM_IDS)
    sent = [random_values(rng, DEFAULT_STREAM_IDS) for _ in range(200)]
    data = b"".join(encode_stream_frame(DEFAULT_STREAM_IDS, v) for v in sent)
    got = parser.feed(data)
    assert [f.as_dict() for f in got] == sent
    assert parser.frames_ok == 200 and parser.bytes_dropped == 0 and parser.buffered == 0


@pytest.mark.parametrize("pid", sorted(set(DEFAULT_STREAM_IDS)))
def test_default_stream_round_trip_extremes_of_each_packet(pid: int) -> None:
    base = dict.fromkeys(expand_ids(DEFAULT_STREAM_IDS), 0)
    for v in (PACKETS[pid].min_value, PACKETS[pid].max_value):
        values = {**base, pid: v}
        (frame,) = StreamParser(DEFAULT_STREAM_IDS).feed(
            encode_stream_frame(DEFAULT_STREAM_IDS, values))
        assert frame[pid] == v


def test_groups_in_a_stream_round_trip(rng: np.random.Generator) -> None:
    ids = (7, 106, 100, 107)
    values = random_values(rng, ids)
    data = encode_stream_frame(ids, values)
    assert len(data) == stream_frame_size(ids) == 3 + 2 + 13 + 81 + 10
    (frame,) = StreamParser(ids).feed(data)
    assert frame.ids == expand_ids(ids)
    assert frame.as_dict() == values


def test_stream_frame_lookup() -> None:
    frame = StreamFrame(ids=(7, 43, 7), values=(1, 2, 3))
    assert frame[7] == 1 and frame.as_dict() == {7: 1, 43: 2}
    with pytest.raises(KeyError):
        frame[44]


def test_banner_charger_text_and_split_frames() -> None:
    # spec §6.3 / §9 G21: ASCII noise before and between frames
    banner = b"r3-robot/tags/release-stm32-3.7.7:6913\r\nRoomba by iRobot!\r\n"
    charger = b"bat:   min 0  sec 13  mV 15902  mA 1203  tenths-deg-C 262\r\n"
    data = banner + SPEC_FRAME_2 + charger + SPEC_FRAME_2
    parser = StreamParser([7, 43, 44])
    frames = []
    for k in range(0, len(data), 7):
        frames += parser.feed(data[k:k + 7])
    assert len(frames) == 2 and frames[0] == frames[1]
    assert parser.frames_ok == 2
    assert parser.bytes_dropped == len(banner) + len(charger)
    assert parser.buffered == 0


def _strided(data: bytes) -> np.ndarray:
    """The bytes as every other element of a larger array: not contiguous."""
    big = np.zeros(2 * len(data), np.uint8)
    big[::2] = np.frombuffer(data, np.uint8)
    return big[::2]


BYTES_LIKE = {
    "bytes": bytes,
    "bytearray": bytearray,
    "memoryview": memoryview,
    "array.array": lambda b: array.array("B", b),
    "numpy uint8": lambda b: np.frombuffer(b, np.uint8),
    "numpy 2-D": lambda b: np.frombuffer(b, np.uint8).reshape(1, -1),
    "numpy strided": _strided,
}


@pytest.mark.parametrize("kind", BYTES_LIKE)
def test_feed_takes_any_bytes_like_chunk(kind: str) -> None:
    data = b"Roomba by iRobot!\r\n" + SPEC_FRAME_2 + SPEC_FRAME_2[:5]
    parser = StreamParser([7, 43, 44])
    frames = []
    for k in range(0, len(data), 7):
        frames += parser.feed(BYTES_LIKE[kind](data[k:k + 7]))
    assert frames == [StreamFrame(ids=(7, 43, 44), values=(1, 1000, 65530))]
    assert parser.bytes_dropped == 19 and parser.buffered == 5


def test_feed_refuses_what_is_not_bytes_like() -> None:
    with pytest.raises(TypeError):
        StreamParser([7, 43, 44]).feed([19, 8, 7])


def test_frame_starting_inside_a_rejected_candidate() -> None:
    # "19 8" looks like a header with the right n; its window covers the real frame's
    # first 9 bytes and fails the checksum; dropping only the 19 lets the scan find
    # the real frame two bytes later (spec §4.1 step 5).
    data = bytes([19, 8]) + SPEC_FRAME_2
    parser = StreamParser([7, 43, 44])
    assert parser.feed(data) == [StreamFrame(ids=(7, 43, 44), values=(1, 1000, 65530))]
    assert parser.checksum_failures == 1 and parser.bytes_dropped == 2


def test_wrong_n_is_counted_as_bad_length() -> None:
    parser = StreamParser([7, 43, 44])
    assert len(parser.feed(bytes([19, 19]) + SPEC_FRAME_2)) == 1
    # the first 19 sees n = 19, the second sees n = 19 (the real header); both
    # differ from the expected n = 8
    assert parser.bad_length == 2
    assert parser.bytes_dropped == 2


def test_good_checksum_wrong_ids_is_counted_as_bad_id() -> None:
    body = bytearray(SPEC_FRAME_2[:-1])
    body[4] = 42  # id 43 -> 42; n and lengths unchanged
    frame = bytes(body) + bytes((checksum(body),))
    parser = StreamParser([7, 43, 44])
    assert parser.feed(frame) == []
    assert (parser.bad_id, parser.checksum_failures, parser.bad_length) == (1, 0, 0)
    # the candidate header is dropped, then the rest (no other 19) while scanning
    assert parser.bytes_dropped == len(frame) and parser.buffered == 0


def test_checksum_failure_is_counted_and_logged(caplog: pytest.LogCaptureFixture) -> None:
    bad = bytearray(SPEC_FRAME_2)
    bad[3] ^= 0x04
    parser = StreamParser([7, 43, 44])
    with caplog.at_level(logging.DEBUG, logger="drivers.roomba.oi"):
        got = parser.feed(bytes(bad) + SPEC_FRAME_2)
    assert got == [StreamFrame(ids=(7, 43, 44), values=(1, 1000, 65530))]
    assert parser.checksum_failures == 1
    assert parser.bytes_dropped == len(SPEC_FRAME_2)
    assert "rejected 1 candidate(s) by checksum" in caplog.text


def test_garbage_does_not_grow_the_buffer(rng: np.random.Generator) -> None:
    parser = StreamParser(DEFAULT_STREAM_IDS)
    fed = 0
    for _ in range(200):
        chunk = rng.integers(0, 256, size=int(rng.integers(1, 2000)), dtype=np.uint8).tobytes()
        parser.feed(chunk)
        fed += len(chunk)
        assert parser.buffered < parser.frame_size
    # byte accounting (StreamParser docstring)
    assert fed == parser.frames_ok * parser.frame_size + parser.bytes_dropped + parser.buffered
    # header-heavy garbage: every byte a candidate header
    parser.feed(bytes([19]) * 10_000)
    assert parser.buffered < parser.frame_size
    assert parser.bad_length >= 9_990


def test_single_byte_corruption_exhaustive(rng: np.random.Generator) -> None:
    """Every byte of the middle frame, eight masks each: the other two frames survive."""
    sent = [random_values(rng, DEFAULT_STREAM_IDS) for _ in range(3)]
    frames = [encode_stream_frame(DEFAULT_STREAM_IDS, v) for v in sent]
    size = len(frames[0])
    for offset in range(size):
        for mask in (0x01, 0x02, 0x04, 0x08, 0x10, 0x20, 0x40, 0x80, 0xFF, 19 ^ frames[1][offset]):
            if mask == 0:
                continue
            middle = bytearray(frames[1])
            middle[offset] ^= mask
            parser = StreamParser(DEFAULT_STREAM_IDS)
            got = [f.as_dict() for f in parser.feed(frames[0] + bytes(middle) + frames[2])]
            assert got == [sent[0], sent[2]], (offset, mask)


def test_constructor_rejects_bad_ids() -> None:
    with pytest.raises(ProtocolError, match=r"needs 1\.\.255 packet ids"):
        StreamParser([])
    with pytest.raises(TypeError, match="iterable of packet ids"):
        StreamParser(7)


def test_feed_accepts_bytes_like() -> None:
    parser = StreamParser([7, 43, 44])
    assert len(parser.feed(bytearray(SPEC_FRAME_2))) == 1
    assert len(parser.feed(memoryview(SPEC_FRAME_2))) == 1
    assert parser.feed(b"") == []


def test_layout_structs_agree_with_the_table() -> None:
    layout = PacketLayout.from_ids(DEFAULT_STREAM_IDS)
    assert layout.frame_values_struct.size == layout.frame_size
    assert layout.frame_ids_struct.size == layout.frame_size
    assert layout.payload_struct.size == layout.n
    assert layout.reply_struct.size == layout.reply_size == layout.n - len(DEFAULT_STREAM_IDS)


# ---------------------------------------------------------- encoder rollover (§7.2)


def test_encoder_rollover_both_directions_decodes_and_unwraps() -> None:
    ids = (43, 44)
    steps = np.arange(12)
    left_true = 65530 + 3 * steps  # forward through 65535 -> 0
    right_true = 5 - 3 * steps  # backward through 0 -> 65535
    data = b"".join(
        encode_stream_frame(ids, {43: int(lt) % 65536, 44: int(rt) % 65536})
        for lt, rt in zip(left_true, right_true, strict=True))
    frames = StreamParser(ids).feed(data)
    raw = np.array([f.values for f in frames])
    assert raw.min() >= 0 and raw.max() <= 65535  # modular counters, never negative
    assert raw[:, 0].tolist() == [int(v) % 65536 for v in left_true]
    assert 0 in raw[:, 0] and 65535 in raw[:, 1]  # the wraps really happened
    unwrapped = unwrap_ticks(raw)
    assert unwrapped[:, 0].tolist() == (3 * steps).tolist()
    assert unwrapped[:, 1].tolist() == (-3 * steps).tolist()
