"""Real clocks: calibration on drives with host jitter, lost frames and clock drift.

``N_DRIVES`` simulated create2 drives (seeds 0-49, batch simulation, an empty
room: calibration drives are on open floor, wall contact ruins any fit), each
``DRIVE_S`` seconds of held random commands (``random_held_normal``, std
0.2 m/s, held 0.5-2 s, correlation 0.85; commands seeded per drive) between
1 s rests, recorded twice from the same physics (the simulator's physics and
event noise are separate streams):

- *clean*: no host latency jitter (``latency_jitter_s = 0``), no lost frames,
  no drift;
- *faulty*: host latency jitter of 5 ms (standard deviation of the one-sided
  latency, mean 2 ms), 2% of the frames lost (removed from the log, as a
  driver never sees them) and the robot's clock 100 ppm slow against the
  host's (host stamps scaled by 1 + 1e-4).

Each drive is calibrated offline (:func:`lti_motion.calibration.calibrate_recording`
from its :class:`~lti_motion.recordings.Recording`, the preset's nominal
encoder scale, ARX orders 1-4 and delays 2-6 to keep the run to a few
minutes), and both models are scored by their free-run fit [%] of (v, w) on
one common clean validation drive (seed 1000, 60 s, other commands).

Figures:

- ``clocks.completed``: faulty drives that calibrate (target 50 of 50);
- ``clocks.completed`` baseline ``nearest_period``: the previous rule
  (nearest whole period from the first frame, raising when two frames fall
  on one period) on the same faulty drives;
- ``clocks.fit_loss_mean_points`` / ``fit_loss_worst_points``: fit of the
  clean drive's model minus the faulty drive's, mean over drives and worst
  drive, worst of v and w [points] (target: worst within 1 point);
- ``clocks.period_lost_detected_pct``: lost periods the clock assignment
  found, against the frames removed.

Run ``python -m benchmarks clocks``.
"""

from __future__ import annotations

import dataclasses
import sys

import numpy as np

from benchmarks.harness import Figure, benchmark
from drivers.sim.config import Fault, Room, get_preset
from drivers.sim.simulator import Simulator
from lti_motion.calibration.manoeuvres import speeds_from_log
from lti_motion.calibration.recorded import calibrate_recording
from lti_motion.model.excitation import random_held_normal
from lti_motion.recordings.frames import FrameLog
from lti_motion.recordings.recording import Recording

N_DRIVES = 50
DRIVE_S = 60.0
JITTER_S = 0.005
LOST = 0.02
DRIFT_PPM = 100.0
ORDERS, DELAYS = range(1, 5), range(2, 7)


def _commands(seed: int, dt_s: float) -> np.ndarray:
    rest = np.zeros((round(1.0 / dt_s), 2))
    cmd = random_held_normal(n=round(DRIVE_S / dt_s), dt_s=dt_s,
                             rng=np.random.default_rng(seed), std_m_s=0.2, mean_m_s=0.0,
                             hold_s=(0.5, 2.0), correlation=0.85)
    return np.concatenate([rest, cmd, rest])


def _drives(*, faulty: bool) -> FrameLog:
    params = get_preset("create2", latency_jitter_s=JITTER_S if faulty else 0.0)
    faults = [Fault("lost_frames", t_s=0.0, duration_s=1e9, probability=LOST)] if faulty else []
    sim = Simulator(params, seed=list(range(N_DRIVES)), faults=faults, room=Room.empty())
    cmd = np.stack([_commands(s, params.period_s) for s in range(N_DRIVES)])
    return sim.run(cmd)


def _as_received(log: FrameLog) -> FrameLog:
    """What a driver logs: lost frames absent, stamps on a host clock 100 ppm fast."""
    keep = log.valid
    kw = {f.name: getattr(log, f.name) for f in dataclasses.fields(log)}
    for name, value in kw.items():                 # every per-frame array
        if isinstance(value, np.ndarray) and value.shape[:1] == keep.shape:
            kw[name] = value[keep]
    kw["t_s"] = kw["t_s"] * (1.0 + DRIFT_PPM * 1e-6)
    kw["true_pose"] = kw["true_body_m_s"] = None
    return FrameLog(**kw)


def _nearest_period_completes(t_s: np.ndarray, dt_s: float) -> bool:
    """The previous rule: nearest whole period from the first frame, two on one period fail."""
    k = np.rint((t_s - t_s[0]) / dt_s)
    return bool(np.all(np.diff(k) >= 1))


@benchmark("clocks")
def clocks() -> list[Figure]:
    params = get_preset("create2")
    calib = {"wheel_base_m": params.wheel_base_m, "m_per_tick": params.m_per_tick,
             "encoders": "commanded", "orders": ORDERS, "delays": DELAYS}
    val_log = Simulator(get_preset("create2", latency_jitter_s=0.0), seed=1000,
                        room=Room.empty()).run(_commands(1000, params.period_s))
    val = [speeds_from_log(val_log, m_per_tick=params.m_per_tick,
                           wheel_base_m=params.wheel_base_m)]
    clean, faulty = _drives(faulty=False), _drives(faulty=True)
    completed = baseline = 0
    losses, found, removed = [], 0, 0
    for i in range(N_DRIVES):
        print(f"  drive {i + 1}/{N_DRIVES}", file=sys.stderr, end="\r", flush=True)
        bad = _as_received(faulty.robot(i))
        removed += int((~faulty.robot(i).valid).sum())
        baseline += _nearest_period_completes(bad.t_s, bad.dt_s)
        ref = calibrate_recording(Recording.from_frame_log(clean.robot(i)), **calib)
        try:
            got = calibrate_recording(Recording.from_frame_log(bad), **calib)
        except ValueError as exc:
            print(f"  drive {i}: {exc}", file=sys.stderr)
            continue
        completed += 1
        found += got.grid.assignment.n_missing
        losses.append(ref.model.fit_percent(val) - got.model.fit_percent(val))
    losses = np.array(losses)
    worst = losses.max(axis=1)
    print(f"fit loss [points] v: {losses[:, 0].mean():.2f} +- {losses[:, 0].std():.2f}, "
          f"w: {losses[:, 1].mean():.2f} +- {losses[:, 1].std():.2f}; worst drive "
          f"{worst.max():.2f}", file=sys.stderr)
    return [
        Figure("clocks.completed", float(completed), "drives", target=float(N_DRIVES),
               baseline="nearest_period", baseline_value=float(baseline)),
        Figure("clocks.fit_loss_mean_points", float(worst.mean()), "points", better="lower"),
        Figure("clocks.fit_loss_worst_points", float(worst.max()), "points", target=1.0,
               better="lower"),
        Figure("clocks.period_lost_detected_pct", 100.0 * found / max(removed, 1), "%"),
    ]
