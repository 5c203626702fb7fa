"""Record frames from any driver to a log file, and replay a log as frames.

:class:`Recorder` collects :class:`~lti_motion.recordings.SensorFrame` objects
from a :class:`~drivers.roomba.Roomba`, a :class:`~drivers.sim.Simulator` or
anything else that yields them, and writes them with
:func:`lti_motion.recordings.save_log`; :func:`replay` reads such a file back
as frames, so recorded drives can be fed to the same code as live ones.

Examples
--------
>>> import tempfile, pathlib
>>> from drivers.sim.simulator import Simulator
>>> sim, rec = Simulator("create2", seed=0), Recorder()
>>> rec.extend(sim.step([0.1, 0.1]) for _ in range(5))
>>> path = rec.save(pathlib.Path(tempfile.mkdtemp()) / "drive.npz")
>>> [f.ticks.tolist() for f in replay(path)][-1] == rec.frames[-1].ticks.tolist()
True
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from drivers.roomba.oi import STREAM_PERIOD_S
from lti_motion.recordings.frames import FrameLog, SensorFrame
from lti_motion.recordings.logfile import load_log, save_log

__all__ = ["Recorder", "replay"]


class Recorder:
    """Collect single-robot frames in arrival order and turn them into a log.

    Parameters
    ----------
    dt_s : float
        Nominal sensor period [s] written to the log (15 ms for a Create 2).
    meta : dict, optional
        Free-form JSON-serialisable description stored with the log.

    Attributes
    ----------
    frames : list of SensorFrame
        The frames added so far.
    """

    def __init__(self, *, dt_s: float = STREAM_PERIOD_S, meta: dict | None = None) -> None:
        if not (np.isfinite(dt_s) and dt_s > 0):
            raise ValueError(f"dt_s must be a positive period in s, got {dt_s!r}")
        self.dt_s = float(dt_s)
        self.meta = dict(meta or {})
        self.frames: list[SensorFrame] = []

    def __len__(self) -> int:
        """Number of frames recorded."""
        return len(self.frames)

    def add(self, frame: SensorFrame) -> SensorFrame:
        """Record one frame and return it, so ``rec.add(robot.step(cmd))`` reads naturally.

        Raises
        ------
        TypeError
            If ``frame`` is not a :class:`SensorFrame`.
        ValueError
            If it is a batch frame (one per robot); record ``robot(i)`` logs instead.
        """
        if not isinstance(frame, SensorFrame):
            raise TypeError(f"Recorder.add expects a SensorFrame, got {type(frame).__name__}")
        if np.shape(frame.ticks) != (2,):
            raise ValueError(f"Recorder holds one robot: frame.ticks must have shape (2,), "
                             f"got {np.shape(frame.ticks)}")
        self.frames.append(frame)
        return frame

    def extend(self, frames: Iterable[SensorFrame]) -> None:
        """Record several frames (e.g. ``rec.extend(log.frames())``)."""
        for frame in frames:
            self.add(frame)

    def to_log(self, dt_s: float | None = None) -> FrameLog:
        """The recorded frames as a :class:`FrameLog`, ``valid`` flags kept.

        Parameters
        ----------
        dt_s : float, optional
            Nominal period [s]; defaults to the recorder's.

        Raises
        ------
        ValueError
            If nothing was recorded.
        """
        if not self.frames:
            raise ValueError("Recorder holds no frames; add() some before making a log")
        modes = [f.oi_mode for f in self.frames]
        meta = {**self.meta, "n_frames": len(self.frames)}
        if any(m is not None for m in modes):
            meta["oi_mode"] = [None if m is None else int(m) for m in modes]
        log = FrameLog.from_frames(self.frames, dt_s=self.dt_s if dt_s is None else dt_s,
                                   meta=meta)
        valid = np.array([bool(f.valid) for f in self.frames], dtype=bool)
        return dataclasses.replace(log, valid=valid)

    def save(self, path: str | os.PathLike, *, dt_s: float | None = None) -> Path:
        """Write the recorded frames atomically with :func:`lti_motion.recordings.save_log`.

        Returns
        -------
        Path
            The file written.
        """
        return save_log(path, self.to_log(dt_s))


def replay(path: str | os.PathLike) -> Iterator[SensorFrame]:
    """Yield the valid frames of a log file written by :func:`save_log`, in order.

    The OI mode, if the recorder stored it in the log's ``meta``, is restored
    on each frame. No pacing: frames come as fast as they are consumed.

    Raises
    ------
    LogFileError
        If the file is damaged or of another format.
    FileNotFoundError
        If there is no such file.
    """
    log = load_log(path)
    modes = log.meta.get("oi_mode")
    if not isinstance(modes, list) or len(modes) != len(log):
        yield from log.frames()
        return
    for k, frame in zip(np.flatnonzero(log.valid), log.frames(), strict=True):
        yield dataclasses.replace(frame, oi_mode=modes[k])
