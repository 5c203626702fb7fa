"""Residual monitor (docs/monitor.md): dynamics faults and false alarms on the route.

The closed route (:func:`lti_motion.app.route.drive_route`:
stop, turn in place, drive at 0.25 m/s, slow down at each checkpoint), many
robots in lock step, steering on encoder odometry; the monitor sees commands
and encoder counts only (the route strips the simulator's truth).

- One ARX calibration (``examples/ekf_plugin.py``'s, seed 1).
- The null of :mod:`fusion.monitoring.dynamics` fitted on 30 nominal runs
  (seeds 1000-1029, about 30 minutes of driving).
- ``monitor.false_alarms_per_h``: nominal runs (seeds 2000 onwards) until
  ``NOMINAL_H`` hours; target 1 an hour.
- ``monitor.<fault>.detected_pct`` and ``median_delay_s``: 20 runs per fault
  (seeds 300-319), onset drawn uniform in 15-40 s per run (seed 7), the fault
  lasting to the end; targets 95% and 2 s. The route takes about 60 s, so
  every run drives at least 19 s after its onset; the table also gives the
  detections within ``HORIZON_S`` of the onset and the wait from the onset to
  the first drive start from rest (where a payload shows).

Run ``python -m benchmarks monitor``; the detection table is printed too.

``python -m benchmarks monitor_threshold`` (about 40 s): the start test's
threshold from the per-run maxima of its CUSUM on 10.8 h of nominal route
driving (seeds 5000-5649, a design set used for nothing else), for 0.1 false
alarms an hour (:data:`fusion.monitoring.START_THRESHOLD` holds the value).

``python -m benchmarks recalibration`` (the recalibration that follows a
dynamics alarm, about 40 s): per dynamics fault the same 20 route runs,
each streamed through a :class:`~fusion.monitoring.ResidualMonitor` whose own
first ``dynamics_changed`` alarm after the onset goes to a
:class:`~fusion.monitoring.Recalibrator` (fed the route's commands and
encoder speeds). The route since the onset does not excite an ARX refit, so
the policy waits and calls ``request_excitation``; the application answers
with ``EXCITATION_S`` of the calibration's random excitation (fault in
place, seed ``900 + run``), and the policy refits, validates and adopts or
keeps. Fits [%] (mean of v and w, free run) on ``VALIDATION_S`` of fresh
random excitation (seed ``5000 + run``): the nominal model on the nominal
robot (before the fault), the nominal model and the model in use after the
recalibration on the faulty robot. Target: in use after minus before
the fault >= -2 percentage points. Alarms before the onset are false alarms
(counted by ``monitor``) and are not passed on here.
"""

from __future__ import annotations

import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.harness import Figure, benchmark
from drivers.sim.calibration import calibrate_simulator
from drivers.sim.config import Fault, Room, get_preset
from drivers.sim.simulator import Simulator
from fusion.monitoring.dynamics import (
    DynamicsMonitor,
    DynamicsNull,
    fit_dynamics_null,
    integrated_residuals,
    start_scores,
)
from fusion.monitoring.dynamics_start import (
    start_cusum_maxima,
    start_threshold_from_maxima,
)
from fusion.monitoring.recalibration import Recalibrator
from fusion.monitoring.recalibration_options import RecalibrationOptions
from fusion.monitoring.residual import MonitorOptions, ResidualMonitor
from lti_motion.app.route import RecordingOdometry, drive_route
from lti_motion.calibration.manoeuvres import CalibrationPlan, speeds_from_log
from lti_motion.kinematics import body_from_wheel
from lti_motion.model.excitation import random_held_normal
from lti_motion.model.motion_model import MotionModel

NOMINAL_H = 10.0
N_FAULT_RUNS = 20
HORIZON_S = 15.0
BATCH = 50
DYNAMICS_FAULTS = {
    "payload +1.8 kg (+50%)": ("payload", {"payload_kg": 1.8}),
    "motor weakened 20%": ("motor", {"weakening": 0.2}),
    "command delay +3 periods": ("delay", {"extra_periods": 3.0}),
}


def calibrated_model(*, seed: int = 1) -> MotionModel:
    """The ARX model of ``examples/ekf_plugin.py`` (rotation, steps, 180 s excitation)."""
    return calibrate_simulator("create2", seed=seed,
                               plan=CalibrationPlan(seed=seed + 2, excitation_s=180.0)).arx


def route_drives(model: MotionModel, seeds: Sequence[int], faults: Sequence[Fault] = ()
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Drive the route once per seed; commands and count changes of periods 1.., ``(N, n, 2)``."""
    p = get_preset("create2")
    rec = RecordingOdometry(m_per_tick=model.m_per_tick, wheel_base_m=p.wheel_base_m)
    drive_route(p, rec, seeds=list(seeds), faults=faults)
    return np.stack(rec.cmd, axis=1)[:, 1:], rec.tick_deltas()


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
        for robot in (a.robot for a in mon.update((k + 1) * model.dt_s, cmd[:, k],
                                                   deltas[:, k])):
            out[robot].append((k + 1) * model.dt_s)
    return out


@dataclass(frozen=True)
class FaultResult:
    """Detections of one fault over its runs (delays [s] from the onset; inf: missed).

    ``first_start_s``: from the onset to the first drive start from rest
    after it; ``left_s``: from the onset to the end of the route.
    """

    name: str
    delays_s: np.ndarray
    false_before: int
    hours_before: float
    first_start_s: np.ndarray
    left_s: np.ndarray

    @property
    def detected(self) -> int:
        return int(np.isfinite(self.delays_s).sum())

    def detected_within(self, horizon_s: float) -> int:
        """Runs detected at most ``horizon_s`` after the onset."""
        return int(np.sum(self.delays_s <= horizon_s))


def _first_starts(cmd: np.ndarray, dt_s: float, onsets: np.ndarray) -> np.ndarray:
    """From each onset to the first drive start from rest after it [s] (inf: none)."""
    rest = np.all(cmd == 0.0, axis=2)
    start = np.zeros_like(rest)
    start[:, 1:] = rest[:, :-1] & (cmd[:, 1:, 0] * cmd[:, 1:, 1] > 0.0)
    out = []
    for i, on in enumerate(onsets):
        t = (np.flatnonzero(start[i]) + 1) * dt_s
        out.append(float(t[t >= on][0] - on) if np.any(t >= on) else np.inf)
    return np.array(out)


def _driving_periods(cmd: np.ndarray) -> np.ndarray:
    """Periods until each robot's last command (a robot at the goal stands still)."""
    moving = np.any(cmd != 0.0, axis=2)
    return np.array([np.flatnonzero(m)[-1] + 1 if m.any() else 0 for m in moving])


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
    return FaultResult(kind, delays, int(before), float(onsets.sum() / 3600.0),
                       _first_starts(cmd, model.dt_s, onsets),
                       _driving_periods(cmd) * model.dt_s - onsets)


def nominal_false_alarms(model: MotionModel, null: DynamicsNull, *, hours: float = NOMINAL_H,
                         seed0: int = 2000, batch: int = BATCH) -> tuple[int, float]:
    """Alarms and hours of nominal route driving (whole runs, batches of ``batch``)."""
    alarms, seconds, seed = 0, 0.0, seed0
    while seconds < hours * 3600.0:
        cmd, deltas = route_drives(model, range(seed, seed + batch))
        seed += batch
        # a robot that finished the route stands still: count only the time it drove
        last = _driving_periods(cmd)
        times = alarm_times(model, null, cmd, deltas)
        alarms += sum(len(ts) for ts in times)
        seconds += float(last.sum() * model.dt_s)
    return alarms, seconds / 3600.0


def delay_quantile(delays: np.ndarray, q: float) -> float:
    """Quantile ``q`` of the detection delays [s] of the detected runs (NaN if none)."""
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
        med, p90 = delay_quantile(res.delays_s, 0.5), delay_quantile(res.delays_s, 0.9)
        rows.append(f"| {label} | {n} | {res.detected} | {med:.2f} s | {p90:.2f} s | "
                    f"{res.detected_within(HORIZON_S)} | {np.median(res.first_start_s):.2f} s | "
                    f"{np.min(res.left_s):.1f} s |")
        figures += [Figure(f"monitor.{kind}.detected_pct", 100.0 * res.detected / n, "%", 95.0),
                    Figure(f"monitor.{kind}.median_delay_s", med, "s", 2.0, better="lower")]
    alarms, hours = nominal_false_alarms(model, null)
    rows.append(f"| nominal | {hours:.1f} h | {alarms} alarms | {alarms / hours:.2f} / h | | | | |")
    figures.append(Figure("monitor.false_alarms_per_h", alarms / hours, "1/h", 1.0,
                          better="lower"))
    print(f"| fault | runs | detected (dynamics_changed) | median delay | p90 delay | "
          f"within {HORIZON_S:g} s | onset to first drive start (median) | least driving "
          f"after onset |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n" + "\n".join(rows),
          file=sys.stderr)
    return figures


def start_threshold_design(model: MotionModel, null: DynamicsNull, *,
                           seeds: Sequence[int] = range(5000, 5650),
                           false_alarms_per_hour: float = 0.1, shift_sigma: float = 3.0,
                           batch: int = BATCH) -> tuple[float, np.ndarray, float]:
    """The start test's threshold from nominal design drives (module docstring).

    Returns the threshold, the per-run maxima of the start CUSUM and the hours
    driven.
    """
    maxima, periods = [], 0
    seeds = list(seeds)
    for i in range(0, len(seeds), batch):
        cmd, deltas = route_drives(model, seeds[i:i + batch])
        w = integrated_residuals(model, cmd, deltas, window_periods=null.window_periods)
        maxima.append(start_cusum_maxima(start_scores(null, w, cmd), shift_sigma=shift_sigma))
        periods += int(_driving_periods(cmd).sum())
    m = np.concatenate(maxima)
    hours = periods * model.dt_s / 3600.0
    h = start_threshold_from_maxima(m, runs_per_hour=len(m) / hours,
                                    false_alarms_per_hour=false_alarms_per_hour)
    return h, m, hours


@benchmark("monitor_threshold")
def bench_monitor_threshold() -> list[Figure]:
    model = calibrated_model()
    null = fit_route_null(model)
    h, m, hours = start_threshold_design(model, null)
    top = ", ".join(f"{x:.2f}" for x in np.sort(m)[-5:])
    print(f"start CUSUM on {len(m)} design runs, {hours:.2f} h: largest per-run maxima {top}; "
          f"runs above the threshold {h:.2f}: {int(np.sum(m > h))} "
          f"({np.sum(m > h) / hours:.2f} an hour); start null {null.start}", file=sys.stderr)
    return [Figure("monitor.start_threshold", h, "nats"),
            Figure("monitor.start_design_false_alarms_per_h", float(np.sum(m > h) / hours),
                   "1/h", 0.1, better="lower")]


# -- recalibration after a dynamics alarm ------------------------------------------------------
EXCITATION_S = 60.0
VALIDATION_S = 90.0


def excitation_speeds(model: MotionModel, faults: Sequence[Fault], *, seed: int,
                      duration_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The calibration's random excitation on open floor: commands and encoder body speeds."""
    plan = CalibrationPlan()
    sim = Simulator("create2", seed=seed, room=Room.empty(), initial_pose=(0.0, 0.0, 0.0),
                    faults=faults)
    u = random_held_normal(n=round(duration_s / model.dt_s), dt_s=model.dt_s,
                           rng=np.random.default_rng(seed), std_m_s=plan.excitation_std_m_s,
                           correlation=plan.excitation_correlation, hold_s=plan.hold_s)
    return speeds_from_log(sim.run(u), m_per_tick=model.m_per_tick,
                           wheel_base_m=model.wheel_base_m)


def _route_speeds(model: MotionModel, deltas: np.ndarray) -> np.ndarray:
    """Encoder body speeds ``(v, w)`` [m/s, rad/s] from count changes ``(n, 2)``."""
    return body_from_wheel(deltas * model.m_per_tick / model.dt_s,
                           wheel_base_m=model.wheel_base_m)


@dataclass(frozen=True)
class RecalibrationResult:
    """Fits [%] per run (NaN: no alarm after the onset) and the policy's final actions."""

    name: str
    actions: list[str]
    fit_before: np.ndarray
    fit_old: np.ndarray
    fit_in_use: np.ndarray


def _one_recalibration(model: MotionModel, null: DynamicsNull, cmd: np.ndarray,
                       deltas: np.ndarray, onset_s: float, fault: Fault, *, run: int,
                       save_path: Path) -> tuple[str, MotionModel]:
    """Stream one route run until the first alarm after the onset; answer it (module doc)."""
    asked = []
    rc = Recalibrator(model, save_path=save_path, request_excitation=asked.append,
                      options=RecalibrationOptions(min_samples=3000))
    mon = ResidualMonitor(MonitorOptions(dt_s=model.dt_s), m_per_tick=model.m_per_tick,
                          dynamics=DynamicsMonitor(model, null))
    y = _route_speeds(model, deltas)
    t = 0.0
    for k in range(cmd.shape[0]):
        t = (k + 1) * model.dt_s
        rc.add(t, cmd[k], y[k])
        alarms = [e for e in mon.update_commands(t, cmd[k], deltas[k]) if t >= onset_s]
        if alarms:
            rc.on_alarm(alarms[0])
            break
    else:
        return "no alarm", model
    if asked:                       # the application drives the excitation, fault in place
        u_x, y_x = excitation_speeds(model, [replace_onset(fault)], seed=900 + run,
                                     duration_s=EXCITATION_S)
        t0 = t + 1.0                # a gap: a new segment
        for k in range(len(u_x)):
            rc.add(t0 + k * model.dt_s, u_x[k], y_x[k])
        rc.retry()
    return rc.history[-1].action, rc.model


def replace_onset(fault: Fault) -> Fault:
    """The fault from the start (already in place when the excitation begins)."""
    return Fault(fault.kind, t_s=0.0, payload_kg=fault.payload_kg, weakening=fault.weakening,
                 extra_periods=fault.extra_periods)


def recalibration_runs(model: MotionModel, null: DynamicsNull, kind: str, params: dict, *,
                       n: int = N_FAULT_RUNS, seed0: int = 300, onset_seed: int = 7
                       ) -> RecalibrationResult:
    """``n`` route runs with the fault; the recalibration after the monitor's alarm (module doc)."""
    onsets = np.random.default_rng(onset_seed).uniform(15.0, 40.0, n)
    faults = [Fault(kind, t_s=float(onsets[i]), robots=(i,), **params) for i in range(n)]
    cmd, deltas = route_drives(model, range(seed0, seed0 + n), faults)
    actions, fits = [], np.full((n, 3), np.nan)
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(n):
            action, in_use = _one_recalibration(model, null, cmd[i], deltas[i],
                                                float(onsets[i]), faults[i], run=i,
                                                save_path=Path(tmp) / f"{kind}_{i}.json")
            actions.append(action)
            if action == "no alarm":
                continue
            nominal = excitation_speeds(model, [], seed=5000 + i, duration_s=VALIDATION_S)
            faulty = excitation_speeds(model, [replace_onset(faults[i])], seed=5000 + i,
                                       duration_s=VALIDATION_S)
            fits[i] = [np.mean(m.fit_percent([run])) for m, run in
                       ((model, nominal), (model, faulty), (in_use, faulty))]
    return RecalibrationResult(kind, actions, *fits.T)


@benchmark("recalibration")
def bench_recalibration() -> list[Figure]:
    model = calibrated_model()
    null = fit_route_null(model)
    figures, rows = [], []
    for label, (kind, params) in DYNAMICS_FAULTS.items():
        res = recalibration_runs(model, null, kind, params)
        diff = res.fit_in_use - res.fit_before
        ok = np.isfinite(diff)
        counts = {a: res.actions.count(a) for a in sorted(set(res.actions))}
        rows.append(f"| {label} | {ok.sum()} | {np.nanmean(res.fit_before):.1f} | "
                    f"{np.nanmean(res.fit_old):.1f} | {np.nanmean(res.fit_in_use):.1f} | "
                    f"{np.nanmedian(diff):+.2f} / {np.nanmin(diff):+.2f} | {counts} |")
        figures += [Figure(f"recalibration.{kind}.worst_fit_change_pp", float(np.nanmin(diff)),
                           "pp", -2.0),
                    Figure(f"recalibration.{kind}.runs_within_2pp_pct",
                           100.0 * float(np.mean(diff[ok] >= -2.0)), "%", 100.0)]
    print("| fault | runs recalibrated | fit before fault | old model after | in use after | "
          "in use - before (median / worst) [pp] | actions |\n"
          "| --- | --- | --- | --- | --- | --- | --- |\n" + "\n".join(rows), file=sys.stderr)
    return figures
