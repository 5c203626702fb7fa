"""The recordings wing: what a drive leaves behind, and its clocks.

- :mod:`lti_motion.recordings.recording`: :class:`Recording`, the one recorded-drive type of
  any differential drive (commands, wheel counts, angles or speeds, optional IMU, reference
  poses, sightings), with its time base;
- :mod:`lti_motion.recordings.frames`: :class:`SensorFrame`, one live sensor period of a
  Roomba or the simulator, and :class:`FrameLog`, a run of them;
- :mod:`lti_motion.recordings.logfile`: the versioned NPZ log file of either;
- :mod:`lti_motion.recordings.clocks`: the robot's sensor period, offset and drift from its
  stamps, frames assigned to periods;
- :mod:`lti_motion.recordings.resample`: any recording onto the model's grid of periods;
- :mod:`lti_motion.recordings.ticks`: encoder-count arithmetic (the ring step of a wrapping
  counter, unwrapping, speeds from counts);
- :mod:`lti_motion.recordings.tum`: planar trajectories in the TUM text format.

The names below load with their module on first use (:mod:`lti_motion.lazy`), so
importing the door costs nothing until a name is read.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from lti_motion.lazy import lazy_exports

__all__ = [
    "COMMAND_KINDS",
    "LOG_FORMAT",
    "LOG_VERSION",
    "MAX_WHEEL_SPEED_M_S",
    "N_LIGHT_BUMPS",
    "RECORDING_VERSION",
    "STREAMS",
    "TICK_MODULUS",
    "TUM_HEADER",
    "WHEEL_KINDS",
    "ClockFit",
    "FrameLog",
    "GridSignals",
    "PeriodAssignment",
    "Recording",
    "RecordingSource",
    "SensorFrame",
    "Stream",
    "assign_periods",
    "body_speeds_from_ticks",
    "commands_at",
    "fit_clock",
    "frame_stamps",
    "load_log",
    "load_recording",
    "median_period_s",
    "on_grid",
    "poses_at",
    "poses_from_tum",
    "read_tum",
    "save_log",
    "save_recording",
    "snap_period_s",
    "stream_clock",
    "tick_deltas",
    "tick_step",
    "tum_rows",
    "unfold_commanded_direction",
    "unwrap_ticks",
    "wheel_periods",
    "write_tum",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "lti_motion.recordings.clocks": (
            "ClockFit",
            "PeriodAssignment",
            "assign_periods",
            "fit_clock",
            "median_period_s",
            "snap_period_s",
        ),
        "lti_motion.recordings.frames": (
            "FrameLog",
            "N_LIGHT_BUMPS",
            "SensorFrame",
        ),
        "lti_motion.recordings.logfile": (
            "LOG_FORMAT",
            "LOG_VERSION",
            "RECORDING_VERSION",
            "load_log",
            "load_recording",
            "save_log",
            "save_recording",
        ),
        "lti_motion.recordings.recording": (
            "COMMAND_KINDS",
            "Recording",
            "RecordingSource",
            "STREAMS",
            "Stream",
            "WHEEL_KINDS",
        ),
        "lti_motion.recordings.resample": (
            "GridSignals",
            "MAX_WHEEL_SPEED_M_S",
            "commands_at",
            "frame_stamps",
            "on_grid",
            "poses_at",
            "wheel_periods",
        ),
        "lti_motion.recordings.ticks": (
            "TICK_MODULUS",
            "body_speeds_from_ticks",
            "stream_clock",
            "tick_deltas",
            "tick_step",
            "unfold_commanded_direction",
            "unwrap_ticks",
        ),
        "lti_motion.recordings.tum": (
            "TUM_HEADER",
            "poses_from_tum",
            "read_tum",
            "tum_rows",
            "write_tum",
        ),
    },
    __all__,
)

if TYPE_CHECKING:
    from lti_motion.recordings.clocks import (
        ClockFit,
        PeriodAssignment,
        assign_periods,
        fit_clock,
        median_period_s,
        snap_period_s,
    )
    from lti_motion.recordings.frames import N_LIGHT_BUMPS, FrameLog, SensorFrame
    from lti_motion.recordings.logfile import (
        LOG_FORMAT,
        LOG_VERSION,
        RECORDING_VERSION,
        load_log,
        load_recording,
        save_log,
        save_recording,
    )
    from lti_motion.recordings.recording import (
        COMMAND_KINDS,
        STREAMS,
        WHEEL_KINDS,
        Recording,
        RecordingSource,
        Stream,
    )
    from lti_motion.recordings.resample import (
        MAX_WHEEL_SPEED_M_S,
        GridSignals,
        commands_at,
        frame_stamps,
        on_grid,
        poses_at,
        wheel_periods,
    )
    from lti_motion.recordings.ticks import (
        TICK_MODULUS,
        body_speeds_from_ticks,
        stream_clock,
        tick_deltas,
        tick_step,
        unfold_commanded_direction,
        unwrap_ticks,
    )
    from lti_motion.recordings.tum import TUM_HEADER, poses_from_tum, read_tum, tum_rows, write_tum
