"""Residual monitor (fault-detection issue): dynamics faults and false alarms on the route.

The experiments issue's closed route (:func:`lti_motion.experiments.route.drive_route`:
stop, turn in place, drive at 0.25 m/s, slow down at each checkpoint), many
robots in lock step, steering on encoder odometry; the monitor sees commands
and encoder counts only (the route strips the simulator's truth).

- One ARX calibration (``examples/ekf_plugin.py``'s, seed 1).
- The null of :mod:`fusion.dynamics_monitor` fitted on 30 nominal runs
  (seeds 1000-1029, about 30 minutes of driving).
- ``monitor.false_alarms_per_h``: nominal runs (seeds 2000 onwards) until
  ``NOMINAL_H`` hours; target 1 an hour.
- ``monitor.<fault>.detected_pct`` and ``median_delay_s``: 20 runs per fault
  (seeds 300-319), onset drawn uniform in 15-40 s per run (seed 7), the fault
  lasting to the end; targets 95% and 2 s.

Run ``python -m benchmarks monitor``; the detection table is printed too.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from benchmarks.harness import Figure, benchmark
from drivers.sim import Simulator
from drivers.sim_config import Fault, Room, get_preset
from fusion.dynamics_monitor import DynamicsMonitor, DynamicsNull, fit_dynamics_null
from lti_motion.calibration import CalibrationPlan, calibrate
from lti_motion.experiments.route import Odometry, drive_route
from lti_motion.model import MotionModel
from lti_motion.odometry import TICK_MODULUS

NOMINAL_H = 10.0
N_FAULT_RUNS = 20
BATCH = 50
DYNAMICS_FAULTS = {
    "payload +1.8 kg (+50%)": ("payload", {"payload_kg": 1.8}),
    "motor weakened 20%": ("motor", {"weakening": 0.2}),
    "command delay +3 periods": ("delay", {"extra_periods": 3.0}),
}


def calibrated_model(*, seed: int = 1) -> MotionModel:
    """The ARX model of ``examples/ekf_plugin.py`` (rotation, steps, 180 s excitation)."""
    p = get_preset("create2")
    sim = Simulator(p, seed=seed, room=Room.cluttered(), initial_pose=Room.CALIBRATION_SPOT)

    def to_open_floor(stage: str) -> None:
        if stage != "rotation":
            sim.place((30.0, 30.0, 0.0))

    return calibrate(sim, wheel_base_m=p.wheel_base_m, floor="hard",
                     plan=CalibrationPlan(seed=seed + 2, excitation_s=180.0),
                     before_stage=to_open_floor).arx


class _Recorder(Odometry):
    """Encoder odometry that also keeps what the robot reported: commands and counts."""

    def reset(self, n_robots: int, pose0: np.ndarray) -> None:
        super().reset(n_robots, pose0)
        self.cmd: list[np.ndarray] = []
        self.ticks: list[np.ndarray] = []

    def step(self, frame, cmd_m_s, observations=None):
        self.cmd.append(np.array(cmd_m_s, float))
        self.ticks.append(np.asarray(frame.ticks, np.int64))
        return super().step(frame, cmd_m_s, observations)


def route_drives(model: MotionModel, seeds: Sequence[int], faults: Sequence[Fault] = ()
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Drive the route once per seed; commands and count changes of periods 1.., ``(N, n, 2)``."""
    p = get_preset("create2")
    rec = _Recorder(m_per_tick=model.m_per_tick, wheel_base_m=p.wheel_base_m)
    drive_route(p, rec, seeds=list(seeds), faults=faults)
    ticks = np.stack(rec.ticks, axis=1)
    half = TICK_MODULUS // 2
    deltas = (np.diff(ticks, axis=1) + half) % TICK_MODULUS - half
    return np.stack(rec.cmd, axis=1)[:, 1:], deltas.astype(float)


def fit_route_null(model: MotionModel, *, seeds: Sequence[int] = range(1000, 1030)
                   ) -> DynamicsNull:
    """The dynamics null fitted on nominal route drives (commands and counts only)."""
    return fit_dynamics_null(model, [route_drives(model, seeds)])


def alarm_times(model: MotionModel, null: DynamicsNull, cmd: np.ndarray, deltas: np.ndarray
                ) -> list[list[float]]:
    """Stream the drives through one batched :class:`DynamicsMonitor`; alarm times per robot."""
    mon = DynamicsMonitor(model, null, n_robots=len(cmd))
    out: list[list[float]] = [[] for _ in range(len(cmd))]
    for k in range(cmd.shape[1]):
        for robot, *_ in mon.update((k + 1) * model.dt_s, cmd[:, k], deltas[:, k]):
            out[robot].append((k + 1) * model.dt_s)
    return out


@dataclass(frozen=True)
class FaultResult:
    """Detections of one fault over its runs (delays [s] from the onset; inf: missed)."""

    name: str
    delays_s: np.ndarray
    false_before: int
    hours_before: float

    @property
    def detected(self) -> int:
        return int(np.isfinite(self.delays_s).sum())


def fault_runs(model: MotionModel, null: DynamicsNull, kind: str, params: dict, *,
               n: int = N_FAULT_RUNS, seed0: int = 300, onset_seed: int = 7) -> FaultResult:
    """``n`` route runs, each with the fault from its own onset (uniform 15-40 s)."""
    onsets = np.random.default_rng(onset_seed).uniform(15.0, 40.0, n)
    faults = [Fault(kind, t_s=float(onsets[i]), robots=(i,), **params) for i in range(n)]
    cmd, deltas = route_drives(model, range(seed0, seed0 + n), faults)
    times = alarm_times(model, null, cmd, deltas)
    delays = np.array([next((t - on for t in ts if t >= on), np.inf)
                       for ts, on in zip(times, onsets, strict=True)])
    before = sum(sum(t < on for t in ts) for ts, on in zip(times, onsets, strict=True))
    return FaultResult(kind, delays, int(before), float(onsets.sum() / 3600.0))


def nominal_false_alarms(model: MotionModel, null: DynamicsNull, *, hours: float = NOMINAL_H,
                         seed0: int = 2000, batch: int = BATCH) -> tuple[int, float]:
    """Alarms and hours of nominal route driving (whole runs, batches of ``batch``)."""
    alarms, seconds, seed = 0, 0.0, seed0
    while seconds < hours * 3600.0:
        cmd, deltas = route_drives(model, range(seed, seed + batch))
        seed += batch
        # a robot that finished the route stands still: count only the time it drove
        moving = np.any(cmd != 0.0, axis=2)
        last = np.array([np.flatnonzero(m)[-1] + 1 if m.any() else 0 for m in moving])
        times = alarm_times(model, null, cmd, deltas)
        alarms += sum(len(ts) for ts in times)
        seconds += float(last.sum() * model.dt_s)
    return alarms, seconds / 3600.0


def _pct(delays: np.ndarray, q: float) -> float:
    finite = delays[np.isfinite(delays)]
    return float(np.quantile(finite, q)) if finite.size else float("nan")


@benchmark("monitor")
def bench_monitor() -> list[Figure]:
    model = calibrated_model()
    null = fit_route_null(model)
    figures = []
    rows = []
    for label, (kind, params) in DYNAMICS_FAULTS.items():
        res = fault_runs(model, null, kind, params)
        n = len(res.delays_s)
        med, p90 = _pct(res.delays_s, 0.5), _pct(res.delays_s, 0.9)
        rows.append(f"| {label} | {n} | {res.detected} | {med:.2f} s | {p90:.2f} s |")
        figures += [Figure(f"monitor.{kind}.detected_pct", 100.0 * res.detected / n, "%", 95.0),
                    Figure(f"monitor.{kind}.median_delay_s", med, "s", 2.0, better="lower")]
    alarms, hours = nominal_false_alarms(model, null)
    rows.append(f"| nominal | {hours:.1f} h | {alarms} alarms | {alarms / hours:.2f} / h | |")
    figures.append(Figure("monitor.false_alarms_per_h", alarms / hours, "1/h", 1.0,
                          better="lower"))
    print("| fault | runs | detected (dynamics_changed) | median delay | p90 delay |\n"
          "| --- | --- | --- | --- | --- |\n" + "\n".join(rows), file=sys.stderr)
    return figures
