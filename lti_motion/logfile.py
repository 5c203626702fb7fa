"""The project's recorded-log format: a :class:`~lti_motion.frames.FrameLog` in one NPZ file.

Format ``lti-motion-log``, version 1: a NumPy ``.npz`` archive (no pickle)
with one array per :class:`FrameLog` field (``t_s``, ``ticks``, ``light_bump``,
``bumps``, ``cmd_m_s``, ``valid``, and ``true_pose`` / ``true_body_m_s`` when
the log has ground truth) and a ``header`` array holding a JSON string:
``{"format": "lti-motion-log", "version": 1, "dt_s": ..., "meta": {...}}``.
Units are those of :class:`FrameLog` (s, raw 16-bit ticks, m/s, rad).

Files are written atomically: to a temporary file in the same folder, flushed
to disk, then renamed over the target, so a crash never leaves half a log.
"""

from __future__ import annotations

import json
import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from lti_motion.exceptions import LogFileError
from lti_motion.frames import FrameLog

__all__ = [
    "LOG_FORMAT",
    "LOG_VERSION",
    "load_log",
    "save_log",
]

LOG_FORMAT = "lti-motion-log"
LOG_VERSION = 1
_ARRAYS = ("t_s", "ticks", "light_bump", "bumps", "cmd_m_s", "valid")
_TRUTH = ("true_pose", "true_body_m_s")




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
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez_compressed(fh, header=np.array(json.dumps(header)), **arrays)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def load_log(path: str | os.PathLike) -> FrameLog:
    """Read a log written by :func:`save_log`.

    Raises
    ------
    LogFileError
        If the file is not a readable archive, is of another format or an
        unknown version, or lacks a field.
    FileNotFoundError
        If there is no such file.
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as npz:
            header = json.loads(str(npz["header"]))
            if header.get("format") != LOG_FORMAT:
                raise LogFileError(f"{path} is not an {LOG_FORMAT} file "
                                   f"(format {header.get('format')!r})")
            if header.get("version") != LOG_VERSION:
                raise LogFileError(f"{path} has log version {header.get('version')!r}; "
                                   f"this lti-motion reads version {LOG_VERSION}")
            arrays = {name: npz[name] for name in _ARRAYS}
            truth = {name: npz[name] for name in _TRUTH if name in npz.files}
    except FileNotFoundError:
        raise
    except LogFileError:
        raise
    except (KeyError, ValueError, OSError, zipfile.BadZipFile, json.JSONDecodeError) as exc:
        raise LogFileError(f"{path} is damaged or not a log file: {exc}") from exc
    return FrameLog(dt_s=float(header["dt_s"]), meta=header.get("meta", {}), **arrays, **truth)
