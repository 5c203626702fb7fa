"""Numeric fields of ROS messages, decoded from a topic's raw messages into one array.

A *field path* names a number inside a message, as attribute names joined by dots
and an optional index into an array field: ``"twist.linear.x"``,
``"header.stamp.sec"``, ``"position[1]"``. :func:`decode_fields` turns the raw
(serialized) messages of one topic into an array of shape ``(n, len(paths))``.

Two ways, one answer:

- vectorised: when every message of the topic has the same length and every byte
  outside the wanted numbers is the same (fixed strings such as joint names and
  frame ids, fixed-length arrays), the numbers sit at the same offsets in every
  message. The offsets are found once, by serializing a copy of the first message
  with sentinel values in the wanted fields and finding the sentinels' bytes
  (rosbags' own serializer, so no byte layout is written here); then the messages
  are stacked as one ``(n, length)`` byte array, the constant bytes are checked
  against the first message, and each number is read as a column;
- per message: otherwise (strings or arrays that change length, a big-endian
  bag), each message is deserialized with rosbags and the fields are read.

``decode_fields(..., vectorise=False)`` forces the second way; the tests check
that both give the same numbers.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Sequence

import numpy as np

__all__ = ["decode_fields", "field_value"]

_PATH = re.compile(r"^(?P<attrs>[A-Za-z_][A-Za-z0-9_.]*?)(?:\[(?P<index>\d+)\])?$")
#: Sentinels: one float64 and one 32-bit integer pattern per field, unlikely in real data.
_FLOAT_SENTINEL = 1.2345678901234567e300
_INT_SENTINEL = 0x5A3C1E00


def _split(path: str) -> tuple[list[str], int | None]:
    match = _PATH.match(path)
    if match is None:
        raise ValueError(f"bad field path {path!r}; expected e.g. 'twist.linear.x' or "
                         "'position[0]'")
    index = match["index"]
    return match["attrs"].split("."), None if index is None else int(index)


def field_value(msg: object, path: str) -> float:
    """The number at ``path`` in a deserialized message.

    Raises
    ------
    IndexError
        If an indexed array is too short.
    """
    attrs, index = _split(path)
    value = msg
    for name in attrs:
        value = getattr(value, name)
    return float(value if index is None else value[index])


def _with_value(msg: object, attrs: list[str], index: int | None, value: float) -> object:
    """A copy of ``msg`` with the field ``attrs[index]`` set to ``value``."""
    head = attrs[0]
    current = getattr(msg, head)
    if len(attrs) > 1:
        new = _with_value(current, attrs[1:], index, value)
    elif index is None:
        new = type(current)(value) if isinstance(current, int) else float(value)
    else:
        new = np.array(current, copy=True)
        new[index] = value
    return dataclasses.replace(msg, **{head: new})


def _offsets(first: object, paths: Sequence[str], length: int,
             serialize: Callable[[object], bytes]) -> list[tuple[int, np.dtype]] | None:
    """Byte offset and type of each field in every message of the topic, or None."""
    probe, patterns = first, []
    for i, path in enumerate(paths):
        attrs, index = _split(path)
        current = field_value(first, path)
        leaf = getattr(_parent(first, attrs), attrs[-1])
        is_int = index is None and isinstance(leaf, int)
        value = _INT_SENTINEL + i if is_int else _FLOAT_SENTINEL * (1 + i / 64)
        probe = _with_value(probe, attrs, index, value)
        dtype = np.dtype("<u4") if is_int else np.dtype("<f8")
        patterns.append((np.array([value], dtype=dtype).tobytes(), dtype, current))
    raw = bytes(serialize(probe))
    if len(raw) != length:
        return None
    out = []
    for pattern, dtype, _ in patterns:
        at = raw.find(pattern)
        if at < 0 or raw.find(pattern, at + 1) >= 0:
            return None
        out.append((at, dtype))
    return out


def _parent(msg: object, attrs: list[str]) -> object:
    for name in attrs[:-1]:
        msg = getattr(msg, name)
    return msg


def _vectorised(raws: Sequence[bytes], paths: Sequence[str], first: object,
                serialize: Callable[[object], bytes]) -> np.ndarray | None:
    length = len(raws[0])
    if len(set(map(len, raws))) != 1:
        return None
    try:
        where = _offsets(first, paths, length, serialize)
    except (TypeError, ValueError, IndexError, OverflowError):
        return None
    if where is None:
        return None
    block = np.frombuffer(b"".join(raws), dtype=np.uint8).reshape(len(raws), length)
    numeric = np.zeros(length, bool)
    for at, dtype in where:
        numeric[at:at + dtype.itemsize] = True
    varies = np.bitwise_or.reduce(block ^ block[0], axis=0) != 0     # bytes that change
    if np.any(varies & ~numeric):
        return None
    out = np.empty((len(raws), len(paths)))
    for j, (at, dtype) in enumerate(where):
        out[:, j] = np.ascontiguousarray(block[:, at:at + dtype.itemsize]).view(dtype)[:, 0]
    return out


def decode_fields(raws: Sequence[bytes], paths: Sequence[str], *,
                  deserialize: Callable[[bytes], object],
                  serialize: Callable[[object], bytes],
                  paths_of: Callable[[object], Sequence[str]] | None = None,
                  vectorise: bool = True) -> np.ndarray:
    """The numbers at ``paths`` in each raw message of one topic.

    Parameters
    ----------
    raws : sequence of bytes
        Serialized messages of one topic (one message type), ``n >= 1``.
    paths : sequence of str
        Field paths (module docstring); 32-bit integer fields (header stamps) and
        float64 fields.
    deserialize, serialize : callable
        rosbags' deserializer and serializer of this topic's type and format
        (CDR for ROS 2, ROS 1 otherwise).
    paths_of : callable, optional
        ``paths_of(msg)``: the paths in one deserialized message, where they
        depend on it (a joint's index by its name); default ``paths``. The
        vectorised way uses the first message's, and holds only when the bytes
        that decide them (the names) are the same in every message.
    vectorise : bool
        Try the vectorised way first (module docstring).

    Returns
    -------
    ndarray of float, shape (n, len(paths))

    Raises
    ------
    IndexError
        If an indexed array field is too short in some message.
    """
    first = deserialize(raws[0])
    paths_of = paths_of or (lambda _: paths)
    if vectorise:
        out = _vectorised(raws, paths_of(first), first, serialize)
        if out is not None:
            return out
    out = np.empty((len(raws), len(paths)))
    for i, raw in enumerate(raws):
        msg = first if i == 0 else deserialize(raw)
        out[i] = [field_value(msg, p) for p in paths_of(msg)]
    return out
