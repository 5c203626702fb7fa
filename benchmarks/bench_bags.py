"""ROS bags: calibrating from a bag against from memory, reading speed, calibration time.

- ``bags.fit_gap_pp``: a simulated 3-minute excitation at 50 Hz (create2 with a 20 ms
  period, no host jitter of its own) is calibrated twice: from its in-memory log, and from
  a ROS 2 bag written from it with 4 ms (standard deviation) of host jitter added to the
  stamps and 2 % of the frames lost (the simulator's lost-frame fault: the bag lacks
  them, the in-memory log keeps their counts). Both models run free on a fresh 1-minute
  drive; the figure is the largest difference of their fit percentages (v and w) over
  five seeds (target: within 1 percentage point).
- ``bags.read_*_msgs_per_s``: :func:`drivers.bags.read_topics` on a 10-minute 50 Hz drive
  (commands, wheel angles, odometry, reference poses: 120,000 messages) in each format.
- ``bags.calibrate_10min_s``: :func:`lti_motion.app.bag_commands.calibrate_from_bag` on
  that drive (ROS 2 MCAP), against the same fit from its in-memory log (baseline);
  ``bags.calibrate_10min_ros1_s`` and ``bags.calibrate_10min_db3_s`` the same from the
  ROS 1 and SQLite 3 bags.
"""

from __future__ import annotations

import dataclasses
import shutil
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.harness import Figure, benchmark, median_seconds
from drivers.bags.reader import CREATE2_TICKS_PER_RAD, CREATE2_WHEEL_RADIUS_M
from drivers.bags.topics import read_topics
from drivers.bags.writer import write_drive_bag
from drivers.sim.config import PRESETS, Fault
from drivers.sim.simulator import Simulator
from lti_motion.app.bag_commands import calibrate_from_bag
from lti_motion.app.recorded_health import HeldOut, held_out_span
from lti_motion.calibration import calibrate_recording
from lti_motion.calibration.manoeuvres import CalibrationPlan, speeds_from_log
from lti_motion.metrics import fit_percent
from lti_motion.model.excitation import random_held_normal
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings import Recording
from lti_motion.recordings.frames import FrameLog

DT_S = 0.02
WHEEL_BASE_M = 0.235
M_PER_TICK = CREATE2_WHEEL_RADIUS_M / CREATE2_TICKS_PER_RAD
SEEDS = (0, 1, 2, 3, 4)
JITTER_S = 0.004


def _params():
    return dataclasses.replace(PRESETS["create2"], period_s=DT_S, latency_jitter_s=0.0)


def _excitation(seed: int, duration_s: float) -> np.ndarray:
    plan = CalibrationPlan()
    return random_held_normal(n=round(duration_s / DT_S), dt_s=DT_S,
                              rng=np.random.default_rng(seed), std_m_s=plan.excitation_std_m_s,
                              hold_s=plan.hold_s, correlation=plan.excitation_correlation)


def _drive(seed: int, duration_s: float, *, lost: float = 0.02) -> FrameLog:
    faults = [Fault("lost_frames", t_s=0.0, probability=lost)] if lost else []
    return Simulator(_params(), seed=seed, faults=faults).run(_excitation(seed, duration_s))


def _memory_model(log: FrameLog) -> MotionModel:
    """The fit from the log in memory the way ``calibrate_from_bag`` fits: the drive before
    its held-out last 20 % (:func:`~lti_motion.app.recorded_health.held_out_span`), an order
    or delay at the top of its range widened (:func:`calibrate_recording`)."""
    rec = Recording.from_frame_log(log)
    t = rec.wheel.t_s
    return calibrate_recording(rec, wheel_base_m=WHEEL_BASE_M, m_per_tick=M_PER_TICK,
                               encoders="commanded", dt_s=DT_S,
                               held_out_s=held_out_span(HeldOut(), float(t[-1] - t[0]))).model


def _jittered(log: FrameLog, seed: int) -> FrameLog:
    rng = np.random.default_rng([seed, 4])
    t_s = log.t_s + rng.normal(0.0, JITTER_S, len(log))
    return dataclasses.replace(log, t_s=np.maximum.accumulate(t_s))     # never backwards


def fit_gaps(folder: Path, seeds=SEEDS, *, excitation_s: float = 180.0,
             fresh_s: float = 60.0) -> np.ndarray:
    """Per seed, fit from the bag minus fit from memory on a fresh drive, (v, w) [pp]."""
    gaps = []
    for seed in seeds:
        log = _drive(seed, excitation_s)
        bag = write_drive_bag(folder / f"cal_{seed}", _jittered(log, seed))
        from_bag = calibrate_from_bag(bag, wheel_base_m=WHEEL_BASE_M)[0].model
        memory = _memory_model(log)
        fresh = _drive(1000 + seed, fresh_s, lost=0.0)
        cmd_m_s, speeds = speeds_from_log(fresh, m_per_tick=M_PER_TICK,
                                          wheel_base_m=WHEEL_BASE_M)
        gaps.append(np.asarray(fit_percent(speeds, from_bag.simulate(cmd_m_s), axis=0))
                    - np.asarray(fit_percent(speeds, memory.simulate(cmd_m_s), axis=0)))
    return np.array(gaps)


@benchmark("bags")
def bags() -> list[Figure]:
    folder = Path(tempfile.mkdtemp(prefix="bench-bags-"))
    try:
        gaps = fit_gaps(folder)
        for seed, (v, w) in zip(SEEDS, gaps, strict=True):
            print(f"  seed {seed}: fit from the bag - fit from memory: v {v:+.2f} pp, "
                  f"w {w:+.2f} pp")
        print(f"  mean v {gaps[:, 0].mean():+.2f} pp (sd {gaps[:, 0].std(ddof=1):.2f}), "
              f"w {gaps[:, 1].mean():+.2f} pp (sd {gaps[:, 1].std(ddof=1):.2f})")
        figures = [Figure("bags.fit_gap_pp", float(np.abs(gaps).max()), "pp", target=1.0,
                          better="lower")]
        long = _drive(7, 600.0)
        n_msgs = 0
        for fmt, name, storage in (("ros1", "long.bag", "mcap"), ("db3", "long_db3", "sqlite3"),
                                   ("mcap", "long_mcap", "mcap")):
            path = write_drive_bag(folder / name, _jittered(long, 7), storage=storage)
            rec = read_topics(path)
            n_msgs = sum(len(s) for s in (rec.cmd, rec.wheels, rec.odom, rec.truth))
            t = median_seconds(lambda p=path: read_topics(p), repeat=3)
            figures.append(Figure(f"bags.read_{fmt}_msgs_per_s", n_msgs / t, "msg/s",
                                  target=200_000.0))
        print(f"  the 10-minute bag holds {n_msgs} messages")
        t_mem = median_seconds(lambda: _memory_model(long), repeat=3)
        for name, bag in (("calibrate_10min_s", "long_mcap"),
                          ("calibrate_10min_ros1_s", "long.bag"),
                          ("calibrate_10min_db3_s", "long_db3")):
            t_bag = median_seconds(lambda p=folder / bag: calibrate_from_bag(
                p, wheel_base_m=WHEEL_BASE_M), repeat=3)
            figures.append(Figure(f"bags.{name}", t_bag, "s", target=1.5 * t_mem,
                                  better="lower",
                                  baseline="the same fit from the in-memory log",
                                  baseline_value=t_mem))
        return figures
    finally:
        shutil.rmtree(folder, ignore_errors=True)
