"""Benchmark ``oi``: stream-frame parsing throughput of :class:`drivers.roomba.StreamParser`.

The input is a seeded stream of valid frames for :data:`drivers.roomba.DEFAULT_STREAM_IDS`
(random values over each packet's full range, so 19s occur inside the data),
fed in 1024-byte chunks as a serial read loop would. The in-process baseline
is a straightforward byte-at-a-time state machine implementing the same
resync rule (spec §4.1), written here.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from benchmarks.harness import Figure, benchmark, median_seconds
from drivers.roomba.oi import (
    DEFAULT_STREAM_IDS,
    PACKETS,
    STREAM_HEADER,
    PacketLayout,
    StreamFrame,
    StreamParser,
    encode_stream_frame,
    expand_ids,
)

__all__ = ["NaiveStreamParser", "bench_oi", "make_stream"]

_CHUNK_BYTES = 1024
_SEED = 20261123


def make_stream(n_frames: int, *, seed: int = _SEED) -> bytes:
    """``n_frames`` valid frames of the default stream with seeded random values."""
    rng = np.random.default_rng(seed)
    fields = expand_ids(DEFAULT_STREAM_IDS)
    out = []
    for _ in range(n_frames):
        values = {p: int(rng.integers(PACKETS[p].min_value, PACKETS[p].max_value + 1))
                  for p in fields}
        out.append(encode_stream_frame(DEFAULT_STREAM_IDS, values))
    return b"".join(out)


class NaiveStreamParser:
    """Byte-at-a-time state machine (header -> n -> body), the baseline.

    Same acceptance rule as :class:`drivers.roomba.StreamParser`: on a failed
    candidate only the header byte is dropped and the following bytes are
    scanned again.
    """

    def __init__(self, ids: tuple[int, ...]) -> None:
        layout = PacketLayout.from_ids(ids)
        self._ids = layout.ids
        self._n = layout.n
        self._fields = layout.field_ids
        # (id, [(size, signed), ...]) per requested id
        self._plan = [(pid, [(PACKETS[m].size, PACKETS[m].signed) for m in expand_ids([pid])])
                      for pid in layout.ids]
        self._state = "header"
        self._frame: list[int] = []
        self._pending: deque[int] = deque()

    def feed(self, chunk: bytes) -> list[StreamFrame]:
        """Add bytes; return completed frames."""
        frames: list[StreamFrame] = []
        pending = self._pending
        pending.extend(chunk)
        while pending:
            byte = pending.popleft()
            if self._state == "header":
                if byte == STREAM_HEADER:
                    self._frame = [byte]
                    self._state = "length"
            elif self._state == "length":
                self._frame.append(byte)
                if byte == self._n:
                    self._state = "body"
                else:
                    self._reject()
            else:
                self._frame.append(byte)
                if len(self._frame) == self._n + 3:
                    frame = self._decode(self._frame)
                    if frame is None:
                        self._reject()
                    else:
                        frames.append(frame)
                        self._state = "header"
        return frames

    def _reject(self) -> None:
        # drop the header byte, rescan the rest
        self._pending.extendleft(reversed(self._frame[1:]))
        self._state = "header"

    def _decode(self, frame: list[int]) -> StreamFrame | None:
        if sum(frame) % 256:
            return None
        values: list[int] = []
        k = 2
        for pid, members in self._plan:
            if frame[k] != pid:
                return None
            k += 1
            for size, signed in members:
                values.append(int.from_bytes(bytes(frame[k:k + size]), "big", signed=signed))
                k += size
        return StreamFrame(self._fields, tuple(values))


def _throughput_mb_s(parser_cls: type, data: bytes, *, repeat: int) -> float:
    def run() -> None:
        parser = parser_cls(DEFAULT_STREAM_IDS)
        for k in range(0, len(data), _CHUNK_BYTES):
            parser.feed(data[k:k + _CHUNK_BYTES])

    return len(data) / median_seconds(run, repeat=repeat) / 1e6


@benchmark("oi")
def bench_oi() -> list[Figure]:
    """Parse throughput of the stream parser, MB/s (1 MB = 10**6 bytes)."""
    frame_bytes = PacketLayout.from_ids(DEFAULT_STREAM_IDS).n + 3   # header, n, checksum
    data = make_stream(20_000)  # about 1.2 MB
    small = data[: frame_bytes * 2_000]  # the baseline is slow; 2,000 frames are plenty
    # the baseline must return the same frames, or the comparison means nothing
    fast_frames = StreamParser(DEFAULT_STREAM_IDS).feed(small)
    naive_frames = NaiveStreamParser(DEFAULT_STREAM_IDS).feed(small)
    if fast_frames != naive_frames or len(fast_frames) != 2_000:
        raise RuntimeError("the naive baseline and StreamParser disagree")
    fast = _throughput_mb_s(StreamParser, data, repeat=7)
    naive = _throughput_mb_s(NaiveStreamParser, small, repeat=3)
    return [Figure(name="oi.parse_throughput", value=fast, unit="MB/s", target=5.0,
                   better="higher", baseline="naive byte-loop parser", baseline_value=naive)]
