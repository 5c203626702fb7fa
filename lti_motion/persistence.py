"""Versioned JSON documents, written atomically and checked on reading.

A saved calibration must survive a crash in the middle of a write and must
never be read back silently wrong. So a document is

- JSON (no pickle: readable, diffable, safe to load), with a ``"format"``
  name, an integer ``"version"`` and a ``"sha256"`` of its canonical content;
- written to a temporary file in the target's directory, flushed and
  ``fsync``-ed, then moved over the target with ``os.replace`` (atomic on
  POSIX and Windows), and the directory entry synced (:func:`atomic_write`,
  which :mod:`lti_motion.recordings.logfile` uses too), with the permissions a plain
  ``open`` would give under the process umask;
- read back with every failure (truncation, damage, another format or
  version, a hand edit) turned into a :class:`ModelFileError` that says what
  is wrong.

Floats are written with Python's shortest round-trip representation, so
arrays come back bit for bit. The schema of a document (which keys it holds)
belongs to its owner, e.g. :mod:`lti_motion.model.motion_model`.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import secrets
import stat
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np

from lti_motion.exceptions import ModelFileError

__all__ = ["atomic_write", "decode_array", "encode_array", "read_document", "write_document"]


def encode_array(arr: np.ndarray) -> dict[str, Any]:
    """``{"shape": [...], "data": [...]}`` for a float array (any shape, also empty).

    Examples
    --------
    >>> encode_array(np.eye(2))
    {'shape': [2, 2], 'data': [1.0, 0.0, 0.0, 1.0]}
    """
    arr = np.asarray(arr, dtype=float)
    return {"shape": list(arr.shape), "data": arr.ravel().tolist()}


def decode_array(obj: Any, name: str) -> np.ndarray:
    """Inverse of :func:`encode_array`.

    Raises
    ------
    ModelFileError
        If ``obj`` is not an encoded array or its data does not fill its shape.
    """
    try:
        shape = tuple(int(s) for s in obj["shape"])
        data = np.array(obj["data"], dtype=float)
        return data.reshape(shape)
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelFileError(f"array {name!r} is damaged ({exc})") from None


def _digest(payload: Mapping[str, Any]) -> str:
    canonical = json.dumps(payload, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(canonical.encode("utf-8")).hexdigest()


def write_document(path: str | os.PathLike, payload: Mapping[str, Any], *, fmt: str,
                   version: int) -> Path:
    """Write ``payload`` as a versioned, checksummed JSON document, atomically.

    Parameters
    ----------
    path : path-like
        Target file; its directory must exist.
    payload : mapping
        JSON-serialisable content (finite floats only); must not use the keys
        ``"format"``, ``"version"`` or ``"sha256"``.
    fmt : str
        Format name.
    version : int
        Format version.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    ValueError
        If the payload holds NaN or infinity or is not serialisable.
    OSError
        If the file cannot be written; the previous file, if any, is intact
        and no temporary file is left behind.
    """
    path = Path(path)
    doc = {**payload, "format": fmt, "version": int(version)}
    doc["sha256"] = _digest(doc)
    text = json.dumps(doc, indent=1, sort_keys=True, allow_nan=False) + "\n"
    with atomic_write(path, text=True) as f:
        f.write(text)
    return path


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, *, text: bool = False) -> Iterator[IO]:
    """A file object whose content replaces ``path`` atomically when the block ends.

    Writes go to a temporary file in ``path``'s directory; on leaving the
    block without an exception it is flushed and ``fsync``-ed, moved over
    ``path`` with ``os.replace`` (atomic on POSIX and Windows) and, on POSIX,
    the directory entry is synced. On an exception the temporary file is
    removed and ``path`` is untouched.

    The file ends with the permissions a plain ``open(path, "w")`` gives: a
    new file ``0o666`` less the process umask (the kernel applies it, as for
    any ``open``), an existing file its own mode.

    Parameters
    ----------
    path : path-like
        Target file; its directory must exist.
    text : bool
        Keyword-only: a text file (UTF-8) instead of a binary one.

    Yields
    ------
    file object
        Open for writing (``"w"`` or ``"wb"``).

    Examples
    --------
    >>> import tempfile
    >>> target = Path(tempfile.mkdtemp()) / "note.txt"
    >>> with atomic_write(target, text=True) as f:
    ...     _ = f.write("written whole or not at all")
    >>> target.read_text()
    'written whole or not at all'
    """
    path = Path(path)
    fd, tmp = _create_beside(path)
    try:
        with os.fdopen(fd, "w" if text else "wb", **({"encoding": "utf-8"} if text else {})) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    if os.name == "posix":  # make the rename itself durable
        dir_fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)


def _create_beside(path: Path) -> tuple[int, Path]:
    """Create a new, uniquely named temporary file beside ``path``; its descriptor and name.

    Created with mode ``0o666`` so that the umask applies as to a plain
    ``open`` (``tempfile.mkstemp`` would give ``0o600`` whatever the umask);
    an existing target's mode is copied, as writing over it with ``open`` keeps it.
    """
    try:
        keep = stat.S_IMODE(os.stat(path).st_mode)
    except FileNotFoundError:
        keep = None
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    for _ in range(100):
        tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"
        try:
            fd = os.open(tmp, flags, 0o666)
        except FileExistsError:
            continue
        if keep is not None and hasattr(os, "fchmod"):
            os.fchmod(fd, keep)
        return fd, tmp
    raise FileExistsError(f"no free temporary name beside {path}")


#: Files a user may give where a document is expected, known by their first bytes: said as
#: what they are, not as a damaged document.
_OTHER_KINDS = (
    (b"PK\x03\x04", "a NumPy .npz archive (a recorded log?)"),
    (b"#ROSBAG", "a ROS 1 bag"),
    (b"\x89MCAP", "an MCAP (ROS 2) bag"),
    (b"SQLite format 3\x00", "an SQLite (ROS 2) bag"),
)


def read_document(path: str | os.PathLike, *, fmt: str, versions: tuple[int, ...]) -> dict:
    """Read a document written by :func:`write_document` and check it.

    Parameters
    ----------
    path : path-like
        The file.
    fmt : str
        Expected format name.
    versions : tuple of int
        Versions this reader understands.

    Returns
    -------
    dict
        The document (including ``"format"``, ``"version"``, ``"sha256"``).

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    ModelFileError
        If the file is not valid UTF-8 JSON (damaged or truncated), is of
        another format or an unknown version, or its checksum does not match
        (damaged or edited by hand).
    """
    path = Path(path)
    raw = path.read_bytes()
    kind = next((what for magic, what in _OTHER_KINDS if raw.startswith(magic)), None)
    if kind is not None:
        raise ModelFileError(f"{path} is {kind}, not a {fmt!r} file: give the JSON file "
                             "lti-motion wrote (a model: model_arx.json)")
    try:
        doc = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelFileError(f"{path} is damaged or truncated: not valid JSON ({exc}); "
                             "restore it from a backup or calibrate again") from None
    except RecursionError:
        raise ModelFileError(f"{path} is damaged: not a model file (JSON nested too deeply)"
                             ) from None
    if not isinstance(doc, dict) or doc.get("format") != fmt:
        found = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise ModelFileError(f"{path} is not a {fmt!r} file (format {found!r})")
    version = doc.get("version")
    if isinstance(version, bool) or not isinstance(version, int) or version not in versions:
        raise ModelFileError(f"{path} has {fmt!r} version {version!r}; this lti-motion reads "
                             f"version(s) {list(versions)}: upgrade lti-motion or calibrate again")
    stored = doc.get("sha256")
    body = {k: v for k, v in doc.items() if k != "sha256"}
    try:
        digest = _digest(body)
    except ValueError as exc:
        raise ModelFileError(f"{path} is damaged: {exc}") from None
    if stored != digest:
        raise ModelFileError(f"{path} is damaged or was edited: its checksum does not match its "
                             "content; restore it from a backup or calibrate again")
    return doc
