"""``lti-motion monitor --sim`` measured: its route, its Phase I, every fault it injects.

The model the command fits without ``--model`` (``calibrate_simulator``, seed
0, 60 s of excitation). Phase I as the command's: 20 nominal drives of the
monitor route (:func:`~lti_motion.app.monitor_setup.monitor_route`),
60 s each, seeds 1000-1019. Each drive then goes through
:func:`~lti_motion.app.monitor.monitor_frames` with the dynamics
tests and the simulated landmark sensor, as the command runs it.

- ``live_monitor.false_alarms_per_h``: nominal drives of 60 s (seeds
  5000-5059, one hour); target 1 an hour.
- ``live_monitor.<fault>.detected_pct`` and ``median_delay_s``: 20 drives of
  60 s per ``--fault`` choice (seeds 300-319), onset uniform in 20-40 s (seed
  7); the first alarm of the expected kind at or after the onset.

Run ``python -m benchmarks live_monitor`` (about 4 minutes); the table is
printed too.

``python -m benchmarks live_monitor_nominal`` (about 13 minutes): the same
monitor, Phase I and landmarks over ``NOMINAL_H`` hours of nominal drives
(seeds 5000 onwards, batches of 60; the first hour is the one above):
``live_monitor_nominal.<kind>_per_h`` per alarm kind and ``.all_per_h``
(every alarm counted, from the first frame); target 1 an hour in all.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Sequence

import numpy as np

from benchmarks.harness import Figure, benchmark
from drivers.sim.calibration import calibrate_simulator
from drivers.sim.config import Fault, Room
from drivers.sim.simulator import Simulator
from fusion.monitoring.phase_one import NominalFit
from fusion.monitoring.residual import AlarmEvent
from lti_motion.app.monitor import FAULTS, fault_for, monitor_frames
from lti_motion.app.monitor_setup import (
    MONITOR_LANDMARKS,
    monitor_route,
    nominal_on_simulator,
    sightings,
)
from lti_motion.calibration.manoeuvres import CalibrationPlan
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.frames import SensorFrame

DURATION_S = 60.0
NOMINAL_H = 10.0
BATCH = 60
KINDS = ("glitch_burst", "stuck_encoder", "stalled_wheel", "dynamics_changed", "scale_changed",
         "wheel_drift")


def drives(model: MotionModel, seeds: Sequence[int], faults: Sequence[Fault] = ()) -> list:
    """Monitor-route drives, one per seed, in one batch (per-robot frame logs)."""
    sim = Simulator("create2", seed=list(seeds), room=Room.empty(),
                    initial_pose=np.zeros((len(seeds), 3)), faults=faults)
    cmds = np.stack([monitor_route(DURATION_S, dt_s=model.dt_s, wheel_base_m=model.wheel_base_m,
                                   rng=np.random.default_rng(s)) for s in seeds])
    log = sim.run(cmds)
    return [log.robot(i) for i in range(len(seeds))]


def monitored(model: MotionModel, nominal: NominalFit, log, seed: int) -> list[AlarmEvent]:
    """One drive through ``monitor_frames``, sightings from the true pose (the sensor)."""
    rng = np.random.default_rng([seed, 0x5E45])

    def frames():
        for k in range(len(log.t_s)):
            frame = SensorFrame(float(log.t_s[k]), log.ticks[k], log.light_bump[k],
                                log.bumps[k], log.cmd_m_s[k], valid=bool(log.valid[k]),
                                motor_current_a=log.motor_current_a[k],
                                wheel_overcurrent=log.wheel_overcurrent[k])
            yield frame, sightings(log.true_pose[k], k, rng, dt_s=model.dt_s)

    return monitor_frames(model, frames(), nominal=nominal, landmarks=MONITOR_LANDMARKS).events


def _setup() -> tuple[MotionModel, NominalFit]:
    """The command's model (seed 0, 60 s of excitation) and its Phase I (20 drives)."""
    model = calibrate_simulator("create2", seed=0,
                                plan=CalibrationPlan(seed=0, excitation_s=60.0)).arx
    return model, nominal_on_simulator(model, n_drives=20, duration_s=DURATION_S, seed=0)


@benchmark("live_monitor_nominal")
def bench_live_monitor_nominal() -> list[Figure]:
    model, nominal = _setup()
    counts = dict.fromkeys(KINDS, 0)
    n_drives = round(NOMINAL_H * 3600.0 / DURATION_S)
    lines = []
    for seed0 in range(5000, 5000 + n_drives, BATCH):
        seeds = range(seed0, min(seed0 + BATCH, 5000 + n_drives))
        for i, log in enumerate(drives(model, seeds)):
            for e in monitored(model, nominal, log, seeds[i]):
                counts[e.kind] += 1
                lines.append(f"seed {seeds[i]}: {e.kind} ({e.test}) at {e.t_s:.2f} s")
        print(f"seeds {seeds[0]}-{seeds[-1]}: {counts}", file=sys.stderr, flush=True)
    hours = n_drives * DURATION_S / 3600.0
    print("\n".join(lines) or "no alarm", file=sys.stderr)
    rates = {f"{kind}_per_h": counts[kind] / hours for kind in KINDS}
    rates["all_per_h"] = sum(counts.values()) / hours
    return [*(Figure(f"live_monitor_nominal.{name}", rate, "1/h", 1.0, better="lower")
              for name, rate in rates.items()),
            Figure("live_monitor_nominal.hours", hours, "h", 10.0)]


@benchmark("live_monitor")
def bench_live_monitor() -> list[Figure]:
    model, nominal = _setup()
    counts: dict[str, int] = {}
    seeds = range(5000, 5060)
    for i, log in enumerate(drives(model, seeds)):
        for e in monitored(model, nominal, log, seeds[i]):
            counts[e.kind] = counts.get(e.kind, 0) + 1
    hours = len(seeds) * DURATION_S / 3600.0
    rate = sum(counts.values()) / hours
    rows = [f"| nominal, {hours:.1f} h | | {counts or 'no alarm'} | {rate:.2f} an hour | |"]
    figures = [Figure("live_monitor.false_alarms_per_h", rate, "1/h", 1.0, better="lower")]
    n = 20
    onsets = np.random.default_rng(7).uniform(20.0, 40.0, n)
    for choice in FAULTS:
        faults, expected = [], None
        for i in range(n):
            fault, expected = fault_for(choice, float(onsets[i]))
            faults.append(dataclasses.replace(fault, robots=(i,)))
        delays = np.full(n, np.inf)
        for i, log in enumerate(drives(model, range(300, 300 + n), faults)):
            hits = [e.t_s - onsets[i] for e in monitored(model, nominal, log, 300 + i)
                    if e.kind == expected and e.t_s >= onsets[i]]
            if hits:
                delays[i] = hits[0]
        found = delays[np.isfinite(delays)]
        med = float(np.median(found)) if found.size else float("nan")
        p90 = float(np.quantile(found, 0.9)) if found.size else float("nan")
        rows.append(f"| {choice} | {n} | {found.size} ({expected}) | {med:.2f} s | {p90:.2f} s |")
        figures += [Figure(f"live_monitor.{choice}.detected_pct", 100.0 * found.size / n, "%",
                           95.0),
                    Figure(f"live_monitor.{choice}.median_delay_s", med, "s")]
    print("| fault | runs | detected | median delay | p90 delay |\n"
          "| --- | --- | --- | --- | --- |\n" + "\n".join(rows), file=sys.stderr)
    return figures
