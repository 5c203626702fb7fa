"""Scale monitor (docs/monitor.md): the floor changes to carpet; landmarks at 2 Hz see it.

The closed route (:func:`lti_motion.app.route.drive_route`),
many robots in lock step, steering on encoder odometry, with the route's four
landmarks (:data:`~lti_motion.app.route.ROUTE_LANDMARKS`) each seen at
2 Hz (2% of range, 1 degree). The monitor (:class:`fusion.monitoring.ScaleMonitor`)
sees encoder counts and landmark sightings only; the simulator's truth scores it.

- The encoder scale of one calibration (``examples/ekf_plugin.py``'s, seed 1).
- ``scale.carpet.detected_pct``, ``median_delay_s``, ``p90_delay_s``: 20 runs
  (seeds 300-319), the floor turning to carpet at an onset drawn uniform in
  15-40 s per run (seed 7); targets 95% and 10 s. A run counts as detected
  by its first alarm at or after the onset, if that is a scale alarm (not the
  curvature shadows' ``wheel_drift``).
- ``scale.carpet.ratio_error_pct``: median absolute error of the alarm's new
  scale (ground travel per encoder travel) against the truth after the onset
  (from the simulator's true poses); ``ratio_error_10s_pct``: the same for the
  monitor's running estimate 10 s after the alarm (runs still driving then).
- ``scale.false_alarms_per_h``: nominal runs (seeds 2000 onwards, batches of
  100) until ``NOMINAL_H`` hours of driving, plus the fault runs before their
  onsets; target 1 an hour.

Run ``python -m benchmarks scale``; the detection table is printed too.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from benchmarks.bench_monitor import calibrated_model, delay_quantile
from benchmarks.harness import Figure, benchmark
from drivers.sim.config import Fault, get_preset
from fusion.monitoring.scale import ScaleAlarm, ScaleMonitor
from lti_motion.app.route import ROUTE_LANDMARKS, ROUTE_M, RecordingOdometry, drive_route

NOMINAL_H = 10.0
N_FAULT_RUNS = 20
BATCH = 100


@dataclass(frozen=True)
class Drives:
    """Route drives of a batch: what the robot reported, and the truth for scoring.

    ``deltas`` (N, n, 2) count changes of periods 1..n, ``sightings`` the
    landmark sightings of frames 1..n (one ``RangeBearing`` per robot each),
    ``driving_s`` (N,) time until the last non-zero command, ``true_poses``
    (N, n + 1, 3).
    """

    deltas: np.ndarray
    sightings: list
    driving_s: np.ndarray
    true_poses: np.ndarray


def route_drives(m_per_tick: float, seeds: Sequence[int], faults: Sequence[Fault] = ()
                 ) -> Drives:
    """Drive the route once per seed with the landmark sensor on."""
    p = get_preset("create2")
    rec = RecordingOdometry(m_per_tick=m_per_tick, wheel_base_m=p.wheel_base_m)
    res = drive_route(p, rec, seeds=list(seeds), faults=faults, landmarks=ROUTE_LANDMARKS)
    deltas = rec.tick_deltas()
    moving = np.any(np.stack(rec.cmd, axis=1) != 0.0, axis=2)
    last = np.array([np.flatnonzero(mv)[-1] + 1 if mv.any() else 0 for mv in moving])
    return Drives(deltas, rec.sightings[1:], last * p.period_s, res.true_poses)


def alarms(m_per_tick: float, drives: Drives) -> tuple[list[list[ScaleAlarm]], np.ndarray]:
    """Stream the drives through one batched :class:`ScaleMonitor`.

    Returns the alarms per robot and the main filters' scale ratio after each
    period, (N, n).
    """
    p = get_preset("create2")
    n, steps = drives.deltas.shape[:2]
    pose0 = np.tile([*ROUTE_M[0], 0.0], (n, 1))
    mon = ScaleMonitor(m_per_tick, p.wheel_base_m, ROUTE_LANDMARKS, initial_pose=pose0,
                       pose_std=(0.005, 0.005, 0.005))
    out: list[list[ScaleAlarm]] = [[] for _ in range(n)]
    ratios = np.empty((n, steps))
    for k in range(steps):
        for a in mon.update((k + 1) * p.period_s, drives.deltas[:, k], drives.sightings[k]):
            out[a.robot].append(a)
        ratios[:, k] = mon.scale_ratio
    return out, ratios


def true_ratio(m_per_tick: float, drives: Drives, robot: int, from_s: float) -> float:
    """Truth for scoring: along-track ground travel per encoder travel after ``from_s``."""
    dt = get_preset("create2").period_s
    pose = drives.true_poses[robot]
    k0 = int(np.ceil(from_s / dt))
    step = np.diff(pose[k0:, :2], axis=0)
    heading = pose[k0:-1, 2] + 0.5 * np.diff(pose[k0:, 2])
    ground = float(np.sum(step[:, 0] * np.cos(heading) + step[:, 1] * np.sin(heading)))
    enc = float(m_per_tick * drives.deltas[robot, k0:k0 + len(step)].mean(axis=1).sum())
    return ground / enc


@dataclass(frozen=True)
class CarpetResult:
    """Carpet runs: delays [s] from the onset (inf: missed), false alarms before the onsets,
    relative errors [%] of the alarms' new scales and of the monitor's scale 10 s later
    (runs still driving then)."""

    delays_s: np.ndarray
    false_before: int
    hours_before: float
    ratio_errors_pct: np.ndarray
    later_errors_pct: np.ndarray

    @property
    def detected(self) -> int:
        return int(np.isfinite(self.delays_s).sum())


def carpet_runs(m_per_tick: float, *, n: int = N_FAULT_RUNS, seed0: int = 300,
                onset_seed: int = 7) -> CarpetResult:
    """``n`` route runs, each turning to carpet at its own onset (uniform 15-40 s)."""
    onsets = np.random.default_rng(onset_seed).uniform(15.0, 40.0, n)
    faults = [Fault("floor", t_s=float(onsets[i]), robots=(i,), floor="carpet")
              for i in range(n)]
    drives = route_drives(m_per_tick, range(seed0, seed0 + n), faults)
    found, ratios = alarms(m_per_tick, drives)
    dt = get_preset("create2").period_s
    delays, errors, later, before = np.full(n, np.inf), [], [], 0
    for i, (events, onset) in enumerate(zip(found, onsets, strict=True)):
        before += sum(a.t_s < onset for a in events)
        first = next((a for a in events if a.t_s >= onset), None)
        if first is not None and first.change == "scale":     # a wheel_drift: wrong kind
            delays[i] = first.t_s - onset
            truth = true_ratio(m_per_tick, drives, i, onset)
            errors.append(100.0 * abs(first.scale_ratio / truth - 1.0))
            k = round((first.t_s + 10.0) / dt) - 1
            if first.t_s + 10.0 <= drives.driving_s[i]:
                later.append(100.0 * abs(ratios[i, k] / truth - 1.0))
    return CarpetResult(delays, before, float(onsets.sum() / 3600.0), np.array(errors),
                        np.array(later))


def nominal_false_alarms(m_per_tick: float, *, hours: float = NOMINAL_H, seed0: int = 2000,
                         batch: int = BATCH) -> tuple[int, float]:
    """Alarms and hours of nominal route driving (whole runs, batches of ``batch``)."""
    count, seconds, seed = 0, 0.0, seed0
    while seconds < hours * 3600.0:
        drives = route_drives(m_per_tick, range(seed, seed + batch))
        seed += batch
        count += sum(len(a) for a in alarms(m_per_tick, drives)[0])
        seconds += float(drives.driving_s.sum())
    return count, seconds / 3600.0


@benchmark("scale")
def bench_scale() -> list[Figure]:
    m_per_tick = calibrated_model().m_per_tick
    res = carpet_runs(m_per_tick)
    n = len(res.delays_s)
    med, p90 = delay_quantile(res.delays_s, 0.5), delay_quantile(res.delays_s, 0.9)
    count, hours = nominal_false_alarms(m_per_tick)
    count += res.false_before
    hours += res.hours_before
    err, later = (float(np.median(e)) if e.size else float("nan")
                  for e in (res.ratio_errors_pct, res.later_errors_pct))
    rate = float(count / hours)
    print("| fault | runs | detected (scale_changed) | median delay | p90 delay | new-scale "
          "error at the alarm, 10 s later (median) |\n| --- | --- | --- | --- | --- | --- |\n"
          f"| floor to carpet | {n} | {res.detected} | {med:.2f} s | {p90:.2f} s | {err:.2f}%, "
          f"{later:.2f}% ({res.later_errors_pct.size} runs) |\n"
          f"| nominal | {hours:.1f} h | {count} alarms | {rate:.2f} / h | | |",
          file=sys.stderr)
    return [Figure("scale.carpet.detected_pct", 100.0 * res.detected / n, "%", 95.0),
            Figure("scale.carpet.median_delay_s", med, "s", 10.0, better="lower"),
            Figure("scale.carpet.p90_delay_s", p90, "s"),
            Figure("scale.carpet.ratio_error_pct", err, "%", better="lower"),
            Figure("scale.carpet.ratio_error_10s_pct", later, "%", better="lower"),
            Figure("scale.false_alarms_per_h", rate, "1/h", 1.0, better="lower")]
