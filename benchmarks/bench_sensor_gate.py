"""Sensor tests on the route: the chi-square encoder gate against the Phase-I gate.

The closed route (``benchmarks/bench_monitor.py``'s drives and
calibration); per run a :class:`~fusion.ekf.ModelEKF` on the encoders and a
:class:`~fusion.monitoring.ResidualMonitor` with the gate, glitch bursts and the
stuck check (no dynamics or scale test). Two gates: the chi-square default
(NIS 55.3) and the Phase-I gate
(:func:`fusion.monitoring.fit_nominal`, 10 times the
largest encoder NIS of 30 nominal runs, seeds 1000-1029: the runs that fit
the dynamics null).

- ``sensor_gate.<gate>.bursts_per_h``, ``stuck_per_h``: glitch bursts and
  stuck alarms after the first 2 s of nominal runs (seeds 2000 onwards,
  batches of 50) until ``NOMINAL_H`` hours; target 1 an hour for the monitor.
- ``sensor_gate.<gate>.spikes_detected_pct``, ``spikes_median_delay_s``: 20
  runs (seeds 300-319), 1 s of 20 Hz 150-tick spikes on the left wheel at an
  onset uniform in 15-40 s (seed 7); the first ``glitch_burst`` at or after
  the onset; targets 95% and 0.2 s. ``stuck_*``: the same with the left
  encoder stuck from the onset, the first ``stuck_encoder`` alarm.

Run ``python -m benchmarks sensor_gate`` (about 10 minutes); the table is
printed too.
"""

from __future__ import annotations

import sys
from dataclasses import replace

import numpy as np

from benchmarks.bench_monitor import calibrated_model, route_drives
from benchmarks.harness import Figure, benchmark
from drivers.sim.config import Fault
from fusion.monitoring.monitored_filter import MonitoredFilter
from fusion.monitoring.phase_one import fit_nominal
from fusion.monitoring.residual import AlarmEvent, MonitorOptions
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings import TICK_MODULUS, SensorFrame

NOMINAL_H = 10.0
BATCH = 50


def _ticks(deltas: np.ndarray) -> np.ndarray:
    """Raw 16-bit counts of frames 0..n from count changes (n, 2)."""
    return (np.concatenate([np.zeros((1, 2)), np.cumsum(deltas, axis=0)])
            % TICK_MODULUS).astype(np.int64)


def sensor_alarms(model: MotionModel, cmd: np.ndarray, deltas: np.ndarray,
                  options: MonitorOptions) -> list[AlarmEvent]:
    """The EKF and the monitor over one run (until its last non-zero command)."""
    moving = np.flatnonzero(np.any(cmd != 0.0, axis=1))
    last = moving[-1] + 1 if moving.size else 0
    ticks = _ticks(deltas)
    mf = MonitoredFilter(model, options=options, initial_ticks=ticks[0], t0_s=model.dt_s)
    for k in range(last):
        mf.step(SensorFrame.of_counts(0.0, ticks[k + 1], cmd[k]))   # the filter keeps time
    return mf.events


def phase_one_gate(model: MotionModel, *, seeds: range = range(1000, 1030)) -> float:
    """The Phase-I encoder gate from nominal route runs."""
    cmd, deltas = route_drives(model, seeds)
    return fit_nominal(model, [(cmd[i], _ticks(deltas[i])) for i in range(len(seeds))],
                       skip_s=3.0).encoder_gate_nis


def nominal_rates(model: MotionModel, options: MonitorOptions, *, hours: float = NOMINAL_H,
                  seed0: int = 2000) -> tuple[int, int, float]:
    """Glitch bursts and stuck alarms after the first 2 s, and the hours driven."""
    bursts = stuck = 0
    seconds, seed = 0.0, seed0
    while seconds < hours * 3600.0:
        cmd, deltas = route_drives(model, range(seed, seed + BATCH))
        seed += BATCH
        for i in range(BATCH):
            events = [e for e in sensor_alarms(model, cmd[i], deltas[i], options) if e.t_s >= 2]
            bursts += sum(e.kind == "glitch_burst" for e in events)
            stuck += sum(e.kind == "stuck_encoder" for e in events)
            moving = np.flatnonzero(np.any(cmd[i] != 0.0, axis=1))
            seconds += float(moving[-1] + 1 if moving.size else 0) * model.dt_s
    return bursts, stuck, seconds / 3600.0


def fault_delays(model: MotionModel, options: MonitorOptions, fault: Fault, kind: str, *,
                 n: int = 20) -> np.ndarray:
    """Delays [s] of the first ``kind`` alarm after ``fault``'s onset (inf: missed).

    ``n`` runs (seeds 300 onwards), onsets uniform in 15-40 s (seed 7).
    """
    onsets = np.random.default_rng(7).uniform(15.0, 40.0, n)
    faults = [replace(fault, t_s=float(onsets[i]), robots=(i,)) for i in range(n)]
    cmd, deltas = route_drives(model, range(300, 300 + n), faults)
    out = np.full(n, np.inf)
    for i in range(n):
        hits = [e.t_s - onsets[i] for e in sensor_alarms(model, cmd[i], deltas[i], options)
                if e.kind == kind and e.t_s >= onsets[i]]
        if hits:
            out[i] = hits[0]
    return out


def _summary(delays: np.ndarray) -> tuple[int, float, float, float]:
    found = delays[np.isfinite(delays)]
    if not found.size:
        return 0, float("nan"), float("nan"), float("nan")
    return (found.size, float(np.median(found)), float(np.quantile(found, 0.9)),
            float(found.max()))


@benchmark("sensor_gate")
def bench_sensor_gate() -> list[Figure]:
    model = calibrated_model()
    gates = {"chi2": None, "phase1": phase_one_gate(model)}
    spikes = Fault("encoder_spikes", t_s=0.0, duration_s=1.0, rate_hz=20.0, wheel="left")
    stuck = Fault("stuck_encoder", t_s=0.0, wheel="left")
    figures, rows = [], []
    for name, gate in gates.items():
        options = MonitorOptions(dt_s=model.dt_s, encoder_gate_nis=gate)
        bursts, n_stuck, hours = nominal_rates(model, options)
        sp = _summary(fault_delays(model, options, spikes, "glitch_burst"))
        st = _summary(fault_delays(model, options, stuck, "stuck_encoder"))
        label = "NIS 55.3 (chi-square)" if gate is None else f"NIS {gate:.0f} (Phase I)"
        rows.append(f"| {label} | {bursts} in {hours:.2f} h | {n_stuck} in {hours:.2f} h | "
                    f"{sp[0]} of 20, {sp[1]:.3f} s, {sp[2]:.3f} s | "
                    f"{st[0]} of 20, {st[1]:.3f} s, {st[3]:.2f} s |")
        figures += [Figure(f"sensor_gate.{name}.bursts_per_h", bursts / hours, "1/h", 1.0,
                           better="lower"),
                    Figure(f"sensor_gate.{name}.stuck_per_h", n_stuck / hours, "1/h", 1.0,
                           better="lower"),
                    Figure(f"sensor_gate.{name}.spikes_detected_pct", 5.0 * sp[0], "%", 95.0),
                    Figure(f"sensor_gate.{name}.spikes_median_delay_s", sp[1], "s", 0.2,
                           better="lower"),
                    Figure(f"sensor_gate.{name}.stuck_detected_pct", 5.0 * st[0], "%", 95.0),
                    Figure(f"sensor_gate.{name}.stuck_median_delay_s", st[1], "s", 0.2,
                           better="lower")]
    print("| encoder gate | nominal glitch bursts after 2 s | nominal stuck alarms | spikes: "
          "detected, median, p90 delay | stuck left: detected, median, max delay |\n"
          "| --- | --- | --- | --- | --- |\n" + "\n".join(rows), file=sys.stderr)
    return figures
