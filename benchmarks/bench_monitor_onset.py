"""Faults that come together, and when the monitor says they began (docs/monitor.md).

``lti-motion monitor --sim`` as :mod:`benchmarks.bench_live_monitor` runs it (the
command's model and Phase I, the monitor route, 60 s drives, the simulated
landmark sensor), with three dynamics faults: a 20% weaker motor, a command
delay of +3 periods, and both at once (same onset). 20 drives per fault and
block; onsets uniform in 20-40 s.

- **Rule block** (seeds 300-319, onsets seed 7): the posterior change time's
  settings (:class:`~fusion.monitoring.ChangeTimeRule`: the
  likelihood's temperature ``kappa`` and the interval's level) are chosen here, on the dynamics
  monitor's own alarms (:class:`~fusion.monitoring.DynamicsMonitor`
  fed the drives' commands and counts): of the candidates whose interval held
  every fault onset (``lo <= onset <= hi``) for the first alarm after it, the
  one with the narrowest median interval.
- **Report block** (seeds 400-419, onsets seed 8): the live monitor
  (:func:`~lti_motion.app.monitor.monitor_frames`) with the chosen rule (the
  default of :class:`ChangeTimeRule`): per fault ``detected_pct``,
  ``median_delay_s``, ``p90_delay_s``; the first alarm's onset error (its
  ``onset_s`` minus the true onset: median and minimum), the runs whose true
  onset falls outside the stated interval (``onset_outside_interval``: before it
  or after it), the median interval width, and the old CUSUM onset's minimum
  error for comparison.

Run ``python -m benchmarks monitor_onset`` (about 6 minutes on a quiet machine).
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Sequence

import numpy as np

from benchmarks.bench_live_monitor import _setup, drives, monitored
from benchmarks.harness import Figure, benchmark
from drivers.sim.config import Fault
from fusion.monitoring.change_time import ChangeTimeRule
from fusion.monitoring.dynamics import DynamicsAlarm, DynamicsMonitor
from fusion.monitoring.phase_one import NominalFit
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.ticks import tick_deltas

N_RUNS = 20
MIXES: dict[str, tuple[tuple[str, dict], ...]] = {
    "motor": (("motor", {"weakening": 0.2}),),
    "delay": (("delay", {"extra_periods": 3.0}),),
    "motor+delay": (("motor", {"weakening": 0.2}), ("delay", {"extra_periods": 3.0})),
}
RULE_BLOCK = (300, 7)
REPORT_BLOCK = (400, 8)
CANDIDATES = tuple(ChangeTimeRule(temperature=kappa, level=lv)
                   for kappa in (1.0, 0.5, 0.25) for lv in (0.9, 0.95, 0.99))


def faulty_drives(model: MotionModel, mix: str, seed0: int, onset_seed: int,
                  n: int = N_RUNS) -> tuple[list, np.ndarray]:
    """``n`` monitor-route drives with the faults of ``mix`` from each run's onset."""
    onsets = np.random.default_rng(onset_seed).uniform(20.0, 40.0, n)
    faults = [dataclasses.replace(Fault(kind, t_s=float(onsets[i]), **params), robots=(i,))
              for i in range(n) for kind, params in MIXES[mix]]
    return drives(model, range(seed0, seed0 + n), faults), onsets


def dynamics_alarms(model: MotionModel, nominal: NominalFit, logs: Sequence,
                    rule: ChangeTimeRule) -> list[list[tuple[float, DynamicsAlarm]]]:
    """The dynamics monitor alone over the drives (one batch): (time [s], alarm) per drive."""
    cmd = np.stack([log.cmd_m_s[1:] for log in logs])
    deltas = np.stack([tick_deltas(log.ticks) for log in logs]).astype(float)
    mon = DynamicsMonitor(model, nominal.null, n_robots=len(logs), change_time=rule)
    out: list[list[tuple[float, DynamicsAlarm]]] = [[] for _ in logs]
    for k in range(cmd.shape[1]):
        for a in mon.update((k + 1) * model.dt_s, cmd[:, k], deltas[:, k]):
            out[a.robot].append(((k + 1) * model.dt_s, a))
    return out


def first_after(alarms: Sequence, onset_s: float, t_of=lambda a: a.t_s):
    """The first alarm at or after the onset, or None."""
    return next((a for a in alarms if t_of(a) >= onset_s), None)


def choose_rule(model: MotionModel, nominal: NominalFit) -> tuple[ChangeTimeRule, list[str]]:
    """The rule block: the narrowest candidate whose intervals held every onset."""
    runs = [faulty_drives(model, mix, *RULE_BLOCK) for mix in MIXES]
    lines, best = [], None
    for rule in CANDIDATES:
        held, widths = 0, []
        total = 0
        for logs, onsets in runs:
            per = dynamics_alarms(model, nominal, logs, rule)
            for alarms, on in zip(per, onsets, strict=True):
                hit = first_after(alarms, on, t_of=lambda pair: pair[0])
                if hit is None:
                    continue
                first = hit[1]
                total += 1
                held += first.onset_lo_s <= on <= first.onset_hi_s
                widths.append(first.onset_hi_s - first.onset_lo_s)
        width = float(np.median(widths)) if widths else float("inf")
        lines.append(f"rule kappa={rule.temperature:g} level={rule.level:g}: onset held "
                     f"in {held} of {total}, median interval {width:.2f} s")
        if held == total and (best is None or width < best[1]):
            best = (rule, width)
    return (best[0] if best else ChangeTimeRule()), lines


@benchmark("monitor_onset")
def bench_monitor_onset() -> list[Figure]:
    model, nominal = _setup()
    rule, lines = choose_rule(model, nominal)
    print("\n".join(lines) + f"\nchosen: {rule}", file=sys.stderr, flush=True)
    # the report runs the live monitor, whose rule is ChangeTimeRule's default
    figures = [Figure("monitor_onset.chosen_temperature", rule.temperature, ""),
               Figure("monitor_onset.chosen_level", rule.level, ""),
               Figure("monitor_onset.chosen_is_the_default", float(rule == ChangeTimeRule()),
                      "", 1.0)]
    rows = []
    seed0, onset_seed = REPORT_BLOCK
    for mix in MIXES:
        logs, onsets = faulty_drives(model, mix, seed0, onset_seed)
        delays, errors, cusum_errors, widths, outside = [], [], [], [], 0
        for i, log in enumerate(logs):
            events = [e for e in monitored(model, nominal, log, seed0 + i)
                      if e.kind == "dynamics_changed"]
            e = first_after(events, onsets[i])
            if e is None:
                continue
            delays.append(e.t_s - onsets[i])
            errors.append(e.onset_s - onsets[i])
            cusum_errors.append(e.dynamics.cusum_onset_s - onsets[i])
            widths.append(e.dynamics.onset_hi_s - e.dynamics.onset_lo_s)
            outside += not e.dynamics.onset_lo_s <= onsets[i] <= e.dynamics.onset_hi_s
        d = np.array(delays)
        med = float(np.median(d)) if d.size else float("nan")
        p90 = float(np.quantile(d, 0.9)) if d.size else float("nan")
        err = np.array(errors) if errors else np.array([np.nan])
        cerr = np.array(cusum_errors) if cusum_errors else np.array([np.nan])
        rows.append(f"| {mix} | {d.size} of {N_RUNS} | {med:.2f} s | {p90:.2f} s | "
                    f"{np.median(err):+.2f} s | {err.min():+.2f} s | {outside} | "
                    f"{np.median(widths) if widths else np.nan:.2f} s | {cerr.min():+.2f} s |")
        figures += [Figure(f"monitor_onset.{mix}.detected_pct", 100.0 * d.size / N_RUNS, "%",
                           95.0),
                    Figure(f"monitor_onset.{mix}.median_delay_s", med, "s"),
                    Figure(f"monitor_onset.{mix}.p90_delay_s", p90, "s"),
                    Figure(f"monitor_onset.{mix}.median_onset_error_s", float(np.median(err)),
                           "s"),
                    Figure(f"monitor_onset.{mix}.min_onset_error_s", float(err.min()), "s"),
                    Figure(f"monitor_onset.{mix}.onset_outside_interval", float(outside),
                           "runs", 0.0, better="lower"),
                    Figure(f"monitor_onset.{mix}.median_interval_s",
                           float(np.median(widths)) if widths else float("nan"), "s"),
                    Figure(f"monitor_onset.{mix}.min_cusum_onset_error_s", float(cerr.min()),
                           "s")]
    print("| faults | detected | median delay | p90 delay | onset error, median | "
          "onset error, min | onset outside the interval | interval, median | "
          "old CUSUM onset error, min |\n"
          "| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n" + "\n".join(rows),
          file=sys.stderr)
    return figures
