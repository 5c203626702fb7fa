"""Property-based tests of the stream parser (drivers.roomba.oi.StreamParser, spec §4.1).

Strategy: an independent, deliberately simple reference parser
(:func:`reference_parse`) follows the five resync steps of spec §4.1 byte by
byte over the whole input and also reports *where* each accepted frame
starts. The fast parser must agree with it exactly for any bytes and any
chunking; the recovery properties are then stated on the reference offsets.

Why "every true frame is recovered" needs care: a stretch of arbitrary
garbage may itself look like a frame (a 19, the right n, ids in place and a
zero checksum) and may even overlap the start of a real frame, which is then
skipped because the spurious frame was accepted first. That cannot be ruled
out by any parser that accepts frames without lookahead, so the exact
statements are:

* with garbage that contains no 19 (no candidate headers outside the real
  frames), the output is exactly the real frames, in order;
* with arbitrary garbage, every real frame is recovered unless an accepted
  frame that starts earlier overlaps it; every extra frame passed all four
  checks (it re-encodes to the very bytes it was parsed from).
"""

from __future__ import annotations

from itertools import pairwise

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.roomba.oi import (
    DEFAULT_STREAM_IDS,
    GROUPS,
    PACKETS,
    STREAM_HEADER,
    PacketLayout,
    StreamFrame,
    StreamParser,
    data_size,
    decode_packet_value,
    encode_stream_frame,
    expand_ids,
)

SETTINGS = settings(max_examples=150, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])
LAYOUT = PacketLayout.from_ids(DEFAULT_STREAM_IDS)
FRAME_SIZE = LAYOUT.frame_size


# --------------------------------------------------------------- reference parser


def reference_parse(data: bytes, ids: tuple[int, ...]) -> tuple[list[tuple[int, StreamFrame]],
                                                               dict[str, int]]:
    """Spec §4.1 resync, one byte at a time, on a complete input; no structs.

    Returns the accepted ``(offset, frame)`` pairs and the counters, with
    ``buffered`` the bytes of an undecided candidate left at the end.
    """
    n = sum(1 + data_size(pid) for pid in ids)
    size = n + 3
    accepted: list[tuple[int, StreamFrame]] = []
    counts = dict(bad_length=0, checksum_failures=0, bad_id=0, bytes_dropped=0, buffered=0)
    i = 0
    while i < len(data):
        if data[i] != STREAM_HEADER:  # step 1
            counts["bytes_dropped"] += 1
            i += 1
            continue
        if i + 1 >= len(data) or (data[i + 1] == n and i + size > len(data)):
            counts["buffered"] = len(data) - i  # undecided: needs more bytes
            break
        reason = None
        if data[i + 1] != n:  # step 2
            reason = "bad_length"
        elif sum(data[i:i + size]) % 256 != 0:  # step 3
            reason = "checksum_failures"
        else:  # step 4: walk the payload
            k, fields, values = i + 2, [], []
            for pid in ids:
                if data[k] != pid:
                    reason = "bad_id"
                    break
                k += 1
                for member in expand_ids([pid]):
                    width = PACKETS[member].size
                    fields.append(member)
                    values.append(decode_packet_value(member, data[k:k + width]))
                    k += width
        if reason is None:
            accepted.append((i, StreamFrame(tuple(fields), tuple(values))))
            i += size
        else:  # step 5: drop only the candidate header byte
            counts[reason] += 1
            counts["bytes_dropped"] += 1
            i += 1
    return accepted, counts


def parser_counts(parser: StreamParser) -> dict[str, int]:
    return dict(bad_length=parser.bad_length, checksum_failures=parser.checksum_failures,
                bad_id=parser.bad_id, bytes_dropped=parser.bytes_dropped,
                buffered=parser.buffered)


def feed_in_chunks(parser: StreamParser, data: bytes, cuts: list[int]) -> list[StreamFrame]:
    frames: list[StreamFrame] = []
    edges = [0, *sorted(c % (len(data) + 1) for c in cuts), len(data)]
    for a, b in pairwise(edges):
        frames += parser.feed(data[a:b])
    return frames


# ---------------------------------------------------------------------- strategies


def values_for(ids: tuple[int, ...]) -> st.SearchStrategy[dict[int, int]]:
    fields = expand_ids(ids)
    return st.tuples(*(st.integers(PACKETS[p].min_value, PACKETS[p].max_value)
                       for p in fields)).map(lambda vs: dict(zip(fields, vs, strict=True)))


default_frames = st.lists(values_for(DEFAULT_STREAM_IDS), max_size=6).map(
    lambda vals: [encode_stream_frame(DEFAULT_STREAM_IDS, v) for v in vals])
cut_points = st.lists(st.integers(0, 10_000), max_size=20)
garbage_no_header = st.binary(max_size=120).map(lambda b: b.replace(b"\x13", b"\x14"))
# Garbage rich in headers and plausible n bytes, to exercise every rejection path.
nasty_garbage = st.lists(st.one_of(st.binary(max_size=40),
                                   st.sampled_from([b"\x13", bytes([19, LAYOUT.n]),
                                                    b"\x13\x13", b"Roomba by iRobot!\r\n"])),
                         max_size=8).map(b"".join)


@st.composite
def frames_in_garbage(draw: st.DrawFn, garbage: st.SearchStrategy[bytes]
                      ) -> tuple[bytes, list[bytes], list[int]]:
    """Real frames with garbage around them: (stream, frames, true offsets)."""
    frames = draw(default_frames)
    data, offsets = bytearray(), []
    for frame in frames:
        data += draw(garbage)
        offsets.append(len(data))
        data += frame
    data += draw(garbage)
    return bytes(data), frames, offsets


# ------------------------------------------------------------------------ properties


@SETTINGS
@given(data=st.one_of(st.binary(max_size=400), nasty_garbage,
                      frames_in_garbage(nasty_garbage).map(lambda t: t[0])),
       cuts=cut_points)
def test_any_bytes_any_chunking_never_raises_and_matches_reference(data: bytes,
                                                                    cuts: list[int]) -> None:
    parser = StreamParser(DEFAULT_STREAM_IDS)
    got = feed_in_chunks(parser, data, cuts)
    accepted, counts = reference_parse(data, DEFAULT_STREAM_IDS)
    assert got == [f for _, f in accepted]
    assert parser_counts(parser) == counts
    assert parser.frames_ok == len(got)
    # byte accounting and bounded buffer
    assert len(data) == parser.frames_ok * FRAME_SIZE + parser.bytes_dropped + parser.buffered
    assert parser.buffered < FRAME_SIZE


@SETTINGS
@given(case=frames_in_garbage(nasty_garbage))
def test_byte_by_byte_equals_all_at_once(case: tuple[bytes, list[bytes], list[int]]) -> None:
    data = case[0]
    whole, single = StreamParser(DEFAULT_STREAM_IDS), StreamParser(DEFAULT_STREAM_IDS)
    at_once = whole.feed(data)
    one_by_one = [f for k in range(len(data)) for f in single.feed(data[k:k + 1])]
    assert one_by_one == at_once
    assert parser_counts(single) == parser_counts(whole)


@SETTINGS
@given(case=frames_in_garbage(garbage_no_header), cuts=cut_points)
def test_frames_in_header_free_garbage_are_all_recovered_exactly(
        case: tuple[bytes, list[bytes], list[int]], cuts: list[int]) -> None:
    # Garbage without 19 holds no candidate header, and a real frame's inner 19s are
    # never scanned because each real frame is accepted as soon as it is reached.
    data, frames, _ = case
    parser = StreamParser(DEFAULT_STREAM_IDS)
    got = feed_in_chunks(parser, data, cuts)
    expected = StreamParser(DEFAULT_STREAM_IDS).feed(b"".join(frames))
    assert got == expected and len(got) == len(frames)
    assert parser.bytes_dropped == len(data) - len(frames) * FRAME_SIZE
    assert parser.checksum_failures == parser.bad_length == parser.bad_id == 0


def assert_recovered_unless_overlapped(data: bytes, offsets: list[int],
                                       skip: frozenset[int] = frozenset()) -> None:
    """Every true frame (not in ``skip``) is accepted unless an accepted spurious
    frame starting earlier overlaps it; every accepted frame passed all checks."""
    accepted, _ = reference_parse(data, DEFAULT_STREAM_IDS)
    starts = {a for a, _ in accepted}
    for a, frame in accepted:  # a spurious frame is a genuine-looking frame
        assert encode_stream_frame(DEFAULT_STREAM_IDS, frame.as_dict()) == data[a:a + FRAME_SIZE]
    for j in offsets:
        if j in skip:
            continue
        swallowed = any(a < j < a + FRAME_SIZE and a not in offsets for a in starts)
        assert j in starts or swallowed, f"lost the real frame at offset {j}"


@SETTINGS
@given(case=frames_in_garbage(nasty_garbage), cuts=cut_points)
def test_frames_in_arbitrary_garbage_are_recovered(case: tuple[bytes, list[bytes], list[int]],
                                                   cuts: list[int]) -> None:
    data, frames, offsets = case
    assert_recovered_unless_overlapped(data, offsets)
    # and the fast parser returns exactly what the reference accepted
    got = feed_in_chunks(StreamParser(DEFAULT_STREAM_IDS), data, cuts)
    assert got == [f for _, f in reference_parse(data, DEFAULT_STREAM_IDS)[0]]
    # in practice (no spurious frame) that is exactly the real frames
    if len(got) == len(frames):
        assert [encode_stream_frame(DEFAULT_STREAM_IDS, f.as_dict()) for f in got] == frames


@SETTINGS
@given(frames=st.lists(values_for(DEFAULT_STREAM_IDS), min_size=2, max_size=5).map(
           lambda vals: [encode_stream_frame(DEFAULT_STREAM_IDS, v) for v in vals]),
       where=st.integers(0, 10_000), mask=st.integers(1, 255), cuts=cut_points)
def test_one_corrupted_byte_loses_at_most_its_frame(frames: list[bytes], where: int, mask: int,
                                                    cuts: list[int]) -> None:
    data = bytearray(b"".join(frames))
    where %= len(data)
    data[where] ^= mask
    hit = where // FRAME_SIZE
    offsets = [k * FRAME_SIZE for k in range(len(frames))]
    # A changed byte changes the 8-bit sum, so the hit frame itself is never accepted
    # as-is; the other frames survive unless swallowed by a spurious frame, which can
    # only start inside the hit frame.
    assert_recovered_unless_overlapped(bytes(data), offsets, skip=frozenset({offsets[hit]}))
    got = feed_in_chunks(StreamParser(DEFAULT_STREAM_IDS), bytes(data), cuts)
    accepted = reference_parse(bytes(data), DEFAULT_STREAM_IDS)[0]
    assert got == [f for _, f in accepted]
    assert offsets[hit] not in {a for a, _ in accepted}
    if all(a in offsets for a, _ in accepted):  # no spurious frame: exact statement
        expected = [f for k, f in enumerate(frames) if k != hit]
        assert [encode_stream_frame(DEFAULT_STREAM_IDS, f.as_dict()) for f in got] == expected


streamable_ids = st.lists(st.sampled_from(sorted(PACKETS) + sorted(GROUPS)),
                          min_size=1, max_size=12).map(tuple).filter(
    lambda ids: sum(1 + data_size(p) for p in ids) <= 255)


@SETTINGS
@given(ids=streamable_ids, data=st.data())
def test_any_id_list_round_trips(ids: tuple[int, ...], data: st.DataObject) -> None:
    values = [data.draw(values_for(ids)) for _ in range(3)]
    stream = b"".join(encode_stream_frame(ids, v) for v in values)
    got = StreamParser(ids).feed(stream)
    assert [f.ids for f in got] == [expand_ids(ids)] * 3
    # as_dict keeps the first of repeated packets; compare value tuples instead
    assert [f.values for f in got] == [tuple(v[p] for p in expand_ids(ids)) for v in values]
