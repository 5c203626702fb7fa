"""The project's recorded-log format: a :class:`~lti_motion.recordings.FrameLog` in one NPZ file.

Format ``lti-motion-log``, version 1: a NumPy ``.npz`` archive (no pickle)
with one array per :class:`FrameLog` field (``t_s``, ``ticks``, ``light_bump``,
``bumps``, ``cmd_m_s``, ``valid``, and ``true_pose`` / ``true_body_m_s`` when
the log has ground truth) and a ``header`` array holding a JSON string:
``{"format": "lti-motion-log", "version": 1, "dt_s": ..., "meta": {...}}``.
Units are those of :class:`FrameLog` (s, raw 16-bit ticks, m/s, rad).

Files are written atomically: to a temporary file in the same folder, flushed
to disk, then renamed over the target, so a crash never leaves half a log
(:func:`lti_motion.persistence.atomic_write`); a new file gets the mode a plain
``open`` gives under the process umask.
"""

from __future__ import annotations

import json
import math
import os
import struct
import zipfile
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from types import MappingProxyType

import numpy as np

from lti_motion.exceptions import LogFileError
from lti_motion.persistence import atomic_write
from lti_motion.recordings.frames import FrameLog
from lti_motion.recordings.recording import Recording, RecordingSource

__all__ = [
    "LOG_FORMAT",
    "LOG_VERSION",
    "RECORDING_VERSION",
    "load_log",
    "load_recording",
    "save_log",
    "save_recording",
]

LOG_FORMAT = "lti-motion-log"
LOG_VERSION = 1
#: Version 2 holds a :class:`~lti_motion.recordings.Recording` (any differential drive).
RECORDING_VERSION = 2
_ARRAYS = ("t_s", "ticks", "light_bump", "bumps", "cmd_m_s", "valid")
_TRUTH = ("true_pose", "true_body_m_s")
_OPTIONAL = ("yaw_rate_rad_s",)         # a gyro's reading per frame, when the robot has one




def save_log(path: str | os.PathLike, log: FrameLog) -> Path:
    """Write ``log`` to ``path`` atomically.

    Parameters
    ----------
    path : str or path-like
        Target file; ``.npz`` is the customary suffix.
    log : FrameLog
        One robot or a batch.

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    header = {"format": LOG_FORMAT, "version": LOG_VERSION, "dt_s": log.dt_s,
              "meta": log.meta}
    arrays = {name: getattr(log, name) for name in _ARRAYS}
    if log.has_truth:
        arrays.update({name: getattr(log, name) for name in _TRUTH})
    arrays.update({name: getattr(log, name) for name in _OPTIONAL
                   if getattr(log, name) is not None})
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path) as fh:
        np.savez_compressed(fh, header=np.array(json.dumps(header)), **arrays)
    return path


def load_log(path: str | os.PathLike) -> FrameLog:
    """Read a log written by :func:`save_log`, checking everything it reads.

    Parameters
    ----------
    path : str or path-like
        The ``.npz`` log.

    Returns
    -------
    FrameLog
        One robot or a batch, as saved.

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    LogFileError
        If the file is empty, is not an NPZ archive (a text file, a single
        ``.npy`` array), is damaged or truncated, is of another format or an
        unknown version, has a header that is not a JSON object with a
        positive ``dt_s``, lacks an array or holds one of the wrong shape or
        type, holds no frames, has a frame time that is not finite or that
        goes backwards (the message gives the frame index and both times), or
        has landmark sightings in ``meta`` that are not the documented rows
        (``docs/log_format.md``). The message names the file and the problem;
        it never suggests loading pickled data.
    """
    path = Path(path)
    with _archive(path) as (npz, header):
        if header["version"] == RECORDING_VERSION:
            return _frame_log_of_recording(path, _read_recording(path, npz, header))
        missing = [name for name in _ARRAYS if name not in npz.files]
        if missing:
            raise LogFileError(f"{path} lacks the arrays {missing}; it is not a complete "
                               f"{LOG_FORMAT} file")
        arrays = {name: _array(path, npz, name)
                  for name in (*_ARRAYS, *(n for n in (*_TRUTH, *_OPTIONAL)
                                           if n in npz.files))}
    _check_arrays(path, arrays)
    _check_times(path, arrays["t_s"])
    meta = header.get("meta", {})
    _check_sightings(path, meta)
    return FrameLog(dt_s=float(header["dt_s"]), meta=meta, **arrays)


@contextmanager
def _archive(path: Path) -> Iterator[tuple[np.lib.npyio.NpzFile, dict]]:
    """The open archive and its checked header; what reading a damaged archive raises
    (inside the ``with`` block too) becomes one :class:`LogFileError` naming the file."""
    _check_npz(path)
    try:
        with np.load(path, allow_pickle=False) as npz:
            yield npz, _header(path, npz)
    except (FileNotFoundError, LogFileError):
        raise
    except _READ_ERRORS as exc:                     # the zip directory itself is damaged
        raise LogFileError(f"{path} is damaged or not a log file: {_reason(exc)}") from exc


#: What reading a damaged archive raises (zipfile, zlib and numpy's .npy reader).
_READ_ERRORS = (OSError, EOFError, ValueError, KeyError, OverflowError, NotImplementedError,
                RuntimeError, zipfile.BadZipFile, zlib.error, struct.error)

#: The shape of one frame of each array, format version 1 (``docs/log_format.md``).
_FRAME_SHAPES = MappingProxyType({
    "t_s": (), "ticks": (2,), "light_bump": (6,), "bumps": (2,), "cmd_m_s": (2,), "valid": (),
    "true_pose": (3,), "true_body_m_s": (2,), "yaw_rate_rad_s": ()})
_FLAGS = ("bumps", "valid")


def _reason(exc: BaseException) -> str:
    """What went wrong, on one line, in words that never invite loading pickles."""
    text = " ".join(str(exc).split())
    if isinstance(exc, EOFError) or not text:
        return "it ends too early (truncated)"
    if "pickle" in text.lower() or "object arrays" in text.lower():
        return "it holds Python objects, which a log never does"
    return text


def _check_npz(path: Path) -> None:
    """Refuse, by its first bytes, a file that is not a zip archive (what an NPZ file is)."""
    with open(path, "rb") as fh:              # FileNotFoundError for a missing file
        magic = fh.read(6)
    if not magic:
        raise LogFileError(f"{path} is empty (0 bytes): not an {LOG_FORMAT} file")
    if magic == b"\x93NUMPY":
        raise LogFileError(f"{path} is a single NumPy array (.npy), not an {LOG_FORMAT} file "
                           "(an .npz archive)")
    if magic[:4] not in (b"PK\x03\x04", b"PK\x05\x06"):
        raise LogFileError(f"{path} is not an {LOG_FORMAT} file: not an NPZ (zip) archive")


def _array(path: Path, npz: np.lib.npyio.NpzFile, name: str) -> np.ndarray:
    try:
        return npz[name]
    except _READ_ERRORS as exc:
        raise LogFileError(f"{path} is damaged or not a log file: its array {name!r} cannot be "
                           f"read ({_reason(exc)})") from exc


def _header(path: Path, npz: np.lib.npyio.NpzFile,
            versions: tuple[int, ...] = (LOG_VERSION, RECORDING_VERSION)) -> dict:
    """The header as a dict with a known format, version and a positive ``dt_s``."""
    if "header" not in npz.files:
        raise LogFileError(f"{path} is an NPZ archive but not an {LOG_FORMAT} file (it has no "
                           "header)")
    raw = _array(path, npz, "header")
    if raw.shape != () or raw.dtype.kind not in "US":
        raise LogFileError(f"{path} is not an {LOG_FORMAT} file: its header is not a JSON text")
    try:
        header = json.loads(str(raw))
    except json.JSONDecodeError as exc:
        raise LogFileError(f"{path} is damaged or not a log file: its header is not valid JSON "
                           f"({exc.msg} at character {exc.pos})") from exc
    except RecursionError as exc:
        raise LogFileError(f"{path} is damaged or not a log file: its header is nested too "
                           "deeply") from exc
    if not isinstance(header, dict):
        raise LogFileError(f"{path} is not an {LOG_FORMAT} file: its header is a JSON "
                           f"{_json_type(header)}, not an object")
    if header.get("format") != LOG_FORMAT:
        raise LogFileError(f"{path} is not an {LOG_FORMAT} file "
                           f"(format {header.get('format')!r})")
    if header.get("version") not in versions:
        raise LogFileError(f"{path} has log version {header.get('version')!r}; "
                           f"this lti-motion reads version {LOG_VERSION} and "
                           f"{RECORDING_VERSION}")
    if "dt_s" not in header:
        raise LogFileError(f"{path} is damaged: its header lacks dt_s, the sensor period [s]")
    dt_s = header["dt_s"]
    if (isinstance(dt_s, bool) or not isinstance(dt_s, int | float) or not math.isfinite(dt_s)
            or dt_s <= 0):
        raise LogFileError(f"{path} is damaged: its header has dt_s = {dt_s!r}; expected the "
                           "sensor period, a positive number of seconds")
    if not isinstance(header.get("meta", {}), dict):
        raise LogFileError(f"{path} is damaged: its header's meta is a JSON "
                           f"{_json_type(header['meta'])}; expected an object")
    return header


def _json_type(value: object) -> str:
    return {dict: "object", list: "list", str: "string", bool: "boolean", type(None): "null"
            }.get(type(value), "number")


def _check_arrays(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Shapes and types as format version 1 has them; 0/1 flags become booleans in place."""
    lead = arrays["t_s"].shape
    if len(lead) not in (1, 2):
        raise LogFileError(f"{path} is damaged: its array t_s has shape {lead}; expected (n,) "
                           "frames, or (N, n) for N robots")
    for name, arr in arrays.items():
        expected = lead + _FRAME_SHAPES[name]
        if arr.shape != expected:
            raise LogFileError(f"{path} is damaged: its array {name} has shape {arr.shape}; "
                               f"expected {expected}")
        if name in _FLAGS and arr.dtype.kind in "iu" and np.all((arr == 0) | (arr == 1)):
            arrays[name] = arr.astype(bool)
        elif name in _FLAGS and arr.dtype.kind != "b":
            raise LogFileError(f"{path} is damaged: its array {name} holds {arr.dtype} values; "
                               "expected flags (booleans)")
        elif name not in _FLAGS and arr.dtype.kind not in "iuf":
            raise LogFileError(f"{path} is damaged: its array {name} holds {arr.dtype} values; "
                               "expected numbers")
    if lead[-1] == 0:
        raise LogFileError(f"{path} holds no frames")


def _check_times(path: Path, t_s: np.ndarray) -> None:
    """Every frame time finite, and none earlier than the one before it."""
    for i, t in enumerate(np.atleast_2d(t_s)):
        robot = f"robot {i}'s " if t_s.ndim == 2 else ""
        bad = np.flatnonzero(~np.isfinite(t))
        if bad.size:
            k = int(bad[0])
            more = f"; {bad.size} frames have none" if bad.size > 1 else ""
            raise LogFileError(f"{path} is damaged: {robot}frame {k} has no valid time "
                               f"(t_s = {t[k]}){more}")
        back = np.flatnonzero(np.diff(t) < 0)
        if back.size:
            k = int(back[0]) + 1
            more = f"; it goes back {back.size} times" if back.size > 1 else ""
            raise LogFileError(f"{path} is damaged: time goes backwards at {robot}frame {k}, "
                               f"t_s = {t[k]:.6f} s after {t[k - 1]:.6f} s at frame {k - 1}"
                               f"{more}")


def _check_sightings(path: Path, meta: dict) -> None:
    """``meta.landmarks`` and ``meta.observations``, when present, as the rows the format has."""
    layouts = {"landmarks": ("id", "x_m", "y_m"),
               "observations": ("frame_index", "id", "range_m", "bearing_rad")}
    for key, columns in layouts.items():
        if key not in meta:
            continue
        rows, form = meta[key], f"a list of [{', '.join(columns)}] rows"
        if not isinstance(rows, list):
            raise LogFileError(f"{path} is damaged: its meta.{key} is a JSON "
                               f"{_json_type(rows)}; expected {form}")
        for r, row in enumerate(rows):
            if not (isinstance(row, list) and len(row) == len(columns)
                    and all(_is_cell(v, c) for v, c in zip(row, columns, strict=True))):
                raise LogFileError(f"{path} is damaged: row {r} of its meta.{key} is "
                                   f"{json.dumps(row)[:60]}; expected {form}")


def _is_cell(value: object, column: str) -> bool:
    if column == "id":
        return isinstance(value, str) or (isinstance(value, int | float)
                                          and not isinstance(value, bool)
                                          and math.isfinite(value))
    number = (isinstance(value, int | float) and not isinstance(value, bool)
              and math.isfinite(value))
    if column == "frame_index":
        return number and float(value).is_integer() and value >= 0
    return number


# -- version 2: a Recording of any differential drive (docs/log_format.md) ------------------

#: Streams of a version-2 file: name -> (stamps array, values array, columns).
_V2_STREAMS = MappingProxyType({
    "wheel": ("wheel_t_s", "wheel", 2), "cmd": ("cmd_t_s", "cmd", 2),
    "yaw_rate": ("yaw_rate_t_s", "yaw_rate_rad_s", 1),
    "true_pose": ("true_pose_t_s", "true_pose", 3),
    "sightings": ("sightings_t_s", "sightings", 3)})


def save_recording(path: str | os.PathLike, rec: Recording) -> Path:
    """Write a :class:`~lti_motion.recordings.Recording` atomically (format version 2).

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    header = {"format": LOG_FORMAT, "version": RECORDING_VERSION, "dt_s": rec.dt_s,
              "wheel_kind": rec.wheel_kind, "cmd_kind": rec.cmd_kind,
              "cmd_per_frame": rec.cmd_per_frame, "counter_bits": rec.counter_bits,
              "sensor_pose": list(rec.sensor_pose), "meta": rec.meta, "rates": rec.rates,
              "gyro_density_rad_s_sqrt_hz": rec.gyro_density_rad_s_sqrt_hz,
              "source": None if rec.source is None else _source_json(rec.source)}
    arrays = {"wheel_valid": rec.wheel_valid}
    for name, (t_key, v_key, _) in _V2_STREAMS.items():
        stream = getattr(rec, name)
        if stream is not None and not (name == "cmd" and rec.cmd_per_frame):
            arrays[t_key] = stream.t_s
        if stream is not None:
            arrays[v_key] = stream.values
    for name in ("light_bump", "bumps"):
        if getattr(rec, name) is not None:
            arrays[name] = getattr(rec, name)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path) as fh:
        np.savez_compressed(fh, header=np.array(json.dumps(header)), **arrays)
    return path


def _source_json(src: RecordingSource) -> dict:
    return {"path": src.path, "kind": src.kind, "start_ns": src.start_ns,
            "topics": dict(src.topics), "wheel_names": list(src.wheel_names),
            "truth_frames": list(src.truth_frames)}


def _source_of(doc: object) -> RecordingSource | None:
    """The header's ``source`` (optional) as a :class:`RecordingSource`; ``ValueError`` when
    it is not one."""
    if doc is None:
        return None
    if not isinstance(doc, dict) or not isinstance(doc.get("path"), str) \
            or not isinstance(doc.get("kind"), str) or not isinstance(doc.get("start_ns"), int) \
            or not isinstance(doc.get("topics", {}), dict) \
            or not all(isinstance(v, str) for v in doc.get("topics", {}).values()):
        raise ValueError(f"source: expected path, kind, start_ns and topics, got {doc!r}")
    return RecordingSource(path=doc["path"], kind=doc["kind"], start_ns=doc["start_ns"],
                           topics=doc.get("topics", {}),
                           wheel_names=tuple(doc.get("wheel_names", ())),
                           truth_frames=tuple(doc.get("truth_frames", ())))


def load_recording(path: str | os.PathLike) -> Recording:
    """Read a log of either version as a :class:`~lti_motion.recordings.Recording`.

    Version 1 (Roomba / simulator frames) converts with
    :meth:`Recording.from_frame_log`; version 2 is read as written. Every
    check of :func:`load_log` applies, and every stream's stamps must be
    finite and never decrease.

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    LogFileError
        If the file is damaged, of another format or version, a batch of
        robots (version 1), or an array, stamp or value is wrong; one line
        naming the file and the field.
    """
    path = Path(path)
    with _archive(path) as (npz, header):
        if header["version"] == RECORDING_VERSION:
            return _read_recording(path, npz, header)
    log = load_log(path)
    if log.n_robots is not None:
        raise LogFileError(f"{path} holds a batch of {log.n_robots} robots; save one robot's "
                           "log (log.robot(i)) to read it as a recording")
    return Recording.from_frame_log(log)


def _read_recording(path: Path, npz: np.lib.npyio.NpzFile, header: dict) -> Recording:
    """The Recording of a version-2 archive, every field checked by the constructor."""
    kinds = {"wheel_kind": ("counts", "wheel_angles_rad", "wheel_speeds_rad_s",
                            "wheel_speeds_m_s", "body_speeds"),
             "cmd_kind": ("cmd_wheel_m_s", "cmd_body")}
    for key, allowed in kinds.items():
        if header.get(key) not in allowed:
            raise LogFileError(f"{path} is damaged: its header has {key} = "
                               f"{header.get(key)!r}; expected one of {', '.join(allowed)}")
    per_frame = header.get("cmd_per_frame") is True
    needed = ["wheel_t_s", "wheel", "cmd"] + ([] if per_frame else ["cmd_t_s"])
    missing = [name for name in needed if name not in npz.files]
    if missing:
        raise LogFileError(f"{path} lacks the arrays {missing}; it is not a complete "
                           f"{LOG_FORMAT} version {RECORDING_VERSION} file")
    arrays = {name: _array(path, npz, name) for name in npz.files if name != "header"}
    for name, arr in arrays.items():
        if arr.dtype.kind not in "biuf":
            raise LogFileError(f"{path} is damaged: its array {name} holds {arr.dtype} "
                               "values; expected numbers")
    kw = {"wheel_t_s": arrays["wheel_t_s"], header["wheel_kind"]: arrays["wheel"],
          header["cmd_kind"]: arrays["cmd"], "cmd_t_s": arrays.get("cmd_t_s"),
          "valid": arrays.get("wheel_valid"), "meta": header.get("meta", {})}
    for t_key, v_key, _ in list(_V2_STREAMS.values())[2:]:
        if v_key in arrays or t_key in arrays:
            kw[t_key], kw[v_key] = arrays.get(t_key), arrays.get(v_key)
    bits = header.get("counter_bits")
    try:
        rec = Recording.from_streams(dt_s=float(header["dt_s"]), counter_bits=bits,
                                     sensor_pose=tuple(header.get("sensor_pose", (0, 0, 0))),
                                     rates=header.get("rates", "samples"),
                                     gyro_density_rad_s_sqrt_hz=header.get(
                                         "gyro_density_rad_s_sqrt_hz"),
                                     source=_source_of(header.get("source")), **kw)
        n = len(rec)
        extras = {}
        for name, cols in (("light_bump", 6), ("bumps", 2)):
            if name in arrays:
                if arrays[name].shape != (n, cols):
                    raise ValueError(f"{name} must have shape ({n}, {cols}), got "
                                     f"{arrays[name].shape}")
                extras[name] = arrays[name]
    except (ValueError, TypeError) as exc:
        raise LogFileError(f"{path} is damaged: {' '.join(str(exc).split())}") from exc
    return replace(rec, **extras)


def _frame_log_of_recording(path: Path, rec: Recording) -> FrameLog:
    try:
        return rec.to_frame_log()
    except ValueError as exc:
        raise LogFileError(f"{path} is a version-{RECORDING_VERSION} recording that is not "
                           f"Roomba frames ({exc}); read it with load_recording") from exc
