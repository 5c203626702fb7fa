"""Is the bag whole? A walk over an MCAP file's records before any message is read.

``rosbags`` trusts an MCAP file's chunk index and checks a chunk's CRC only when the
writer stored one (``rosbags``' own writer stores 0: none), so a file with a few
kilobytes zeroed or overwritten mid-file is either read as fine, with wrong numbers, or
fails deep inside a message decoder. :func:`mcap_damage` walks every record of the
file by its opcode and length (MCAP specification, "Records"), and inside each
uncompressed chunk every record again, checking lengths against the chunk's, opcodes
against the specification's, the chunk's CRC-32 when it has one, and message records
against the channels declared. :func:`check_bag` turns the first damage found into a
one-line :class:`~drivers.exceptions.BagError` naming the byte offset and the bag
time span of the damaged chunk.

References
----------
MCAP file format specification, https://mcap.dev/spec (records, chunk, message).
"""

from __future__ import annotations

import os
import struct
import zlib
from dataclasses import dataclass, replace
from pathlib import Path

from drivers.bags.messages import bag_paths
from drivers.exceptions import BagError

__all__ = ["Damage", "check_bag", "mcap_damage"]

_MAGIC = b"\x89MCAP0\r\n"
#: Opcodes the MCAP specification defines (0x01 header ... 0x0F data end).
_OPCODES = frozenset(range(0x01, 0x10))
_CHUNK, _MESSAGE, _CHANNEL, _DATA_END, _FOOTER = 0x06, 0x05, 0x04, 0x0F, 0x02


@dataclass(frozen=True)
class Damage:
    """One damaged place of a bag file.

    Attributes
    ----------
    offset : int
        Byte offset in the file where the damage was found.
    what : str
        What is wrong there, for people.
    span_ns : tuple of int or None
        The (first, last) log time [ns] of the damaged chunk's messages, from its
        header, when the header itself is intact.
    start_ns : int or None
        The first log time [ns] of the file's first chunk (times in messages count
        from it), when one was read.
    """

    offset: int
    what: str
    span_ns: tuple[int, int] | None = None
    start_ns: int | None = None


def _records(data: bytes | memoryview, start: int, end: int, base: int,
             channels: set[int] | None) -> Damage | None:
    """Walk records ``(opcode u8, length u64, body)`` in ``data[start:end]``; the first
    damage (offsets reported as ``base + i``)."""
    i = start
    while i < end:
        if end - i < 9:
            return Damage(base + i, f"{end - i} stray bytes where a record should start")
        op = data[i]
        (length,) = struct.unpack_from("<Q", data, i + 1)
        if op not in _OPCODES:
            return Damage(base + i, f"invalid record opcode 0x{op:02x} (zeroed or "
                                    "overwritten bytes)")
        if length > end - i - 9:
            return Damage(base + i, f"a record of {length} bytes runs past the end of its "
                                    f"{'chunk' if channels is not None else 'file'}")
        body = i + 9
        if op == _CHANNEL and channels is not None and length >= 2:
            channels.add(struct.unpack_from("<H", data, body)[0])
        if op == _MESSAGE and channels is not None:
            if length < 22:
                return Damage(base + i, f"a message record of {length} bytes, shorter than "
                                        "its fixed fields")
            channel = struct.unpack_from("<H", data, body)[0]
            if channel not in channels:
                return Damage(base + i, f"a message on channel {channel}, which the file "
                                        "never declares")
        if op == _FOOTER and channels is None:
            return None
        i = body + length
    return None


def _chunk(data: memoryview, i: int, length: int, channels: set[int]) -> Damage | None:
    """Check one chunk record whose body starts at ``i``."""
    if length < 40:
        return Damage(i - 9, f"a chunk record of {length} bytes, shorter than its header")
    first, last, size, crc, name_len = struct.unpack_from("<QQQII", data, i)
    span = (first, last)
    at = i + 32
    if name_len > length - 40:
        return Damage(i - 9, "a chunk whose compression name runs past the chunk", span)
    compression = bytes(data[at:at + name_len]).decode("ascii", "replace")
    at += name_len
    (records_len,) = struct.unpack_from("<Q", data, at)
    at += 8
    if records_len != length - (at - i):
        return Damage(i - 9, f"a chunk whose records length {records_len} disagrees with its "
                             f"record length", span)
    if compression:                   # compressed: the decompressor and the CRC check it
        return None
    if records_len != size:
        return Damage(i - 9, f"an uncompressed chunk of {records_len} bytes that says it "
                             f"holds {size}", span)
    records = data[at:at + records_len]
    if crc and zlib.crc32(records) != crc:
        return Damage(i - 9, "a chunk whose CRC-32 does not match its bytes", span)
    found = _records(records, 0, records_len, at, channels)
    return None if found is None else Damage(found.offset, found.what, span)


def mcap_damage(path: str | os.PathLike) -> Damage | None:
    """The first damage in an MCAP file (``None``: every record is whole).

    Parameters
    ----------
    path : str or path-like
        An ``.mcap`` file.

    Returns
    -------
    Damage or None
    """
    raw = Path(path).read_bytes()
    data = memoryview(raw)
    if not raw.startswith(_MAGIC):
        return Damage(0, "the file does not start with the MCAP magic bytes")
    if not raw.endswith(_MAGIC):
        return Damage(len(raw), "the file does not end with the MCAP magic bytes (truncated)")
    channels: set[int] = set()
    start_ns = None
    i, end = len(_MAGIC), len(raw) - len(_MAGIC)
    while i < end:
        if end - i < 9:
            return Damage(i, f"{end - i} stray bytes where a record should start")
        op = raw[i]
        (length,) = struct.unpack_from("<Q", raw, i + 1)
        if op not in _OPCODES:
            return Damage(i, f"invalid record opcode 0x{op:02x} (zeroed or overwritten bytes)")
        if length > end - i - 9:
            return Damage(i, f"a record of {length} bytes runs past the end of the file")
        if op == _CHANNEL and length >= 2:
            channels.add(struct.unpack_from("<H", raw, i + 9)[0])
        if op == _CHUNK:
            found = _chunk(data, i + 9, length, channels)
            if found is not None:
                return replace(found, start_ns=start_ns)
            if start_ns is None:
                start_ns = struct.unpack_from("<Q", raw, i + 9)[0]
        if op == _FOOTER:
            return None
        i += 9 + length
    return None


def check_bag(path: str | os.PathLike) -> None:
    """Refuse a damaged bag in one line; a whole one (or a storage without a walk here: ROS 1
    ``.bag``, SQLite 3) passes.

    Raises
    ------
    BagError
        Naming the file, the byte offset, what is wrong and the damaged chunk's bag time
        span (first and last log time [s from the file's first message]).
    """
    folder = bag_paths(path)[0]
    files = sorted(folder.glob("*.mcap")) if folder.is_dir() else []
    for file in files:
        found = mcap_damage(file)
        if found is None:
            continue
        t0 = found.start_ns if found.start_ns is not None else 0
        span = ("" if found.span_ns is None else
                f", in the chunk of messages logged {(found.span_ns[0] - t0) / 1e9:.3f}-"
                f"{(found.span_ns[1] - t0) / 1e9:.3f} s"
                f"{' into the bag' if found.start_ns is not None else ' since the epoch'}")
        raise BagError(f"{file.name} is damaged at byte {found.offset:,}: {found.what}{span}; "
                       "its messages cannot be trusted: copy the bag again from the robot, or "
                       "recover the whole chunks with 'mcap recover' and give the result")
