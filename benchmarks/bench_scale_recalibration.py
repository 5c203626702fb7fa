"""Scale recalibration from landmarks after a carpet alarm (docs/monitor.md).

The carpet runs of ``benchmarks/bench_scale.py`` (the route, landmarks at
2 Hz, the floor turning to carpet at an onset uniform in 15-40 s), streamed
through one batched :class:`~fusion.monitoring.ScaleMonitor`; each robot's
alarms go to its own :class:`~fusion.monitoring.Recalibrator`, fed the
monitor's running estimate every period while a scale alarm waits
(:meth:`~fusion.monitoring.Recalibrator.update_scale`). The monitor and the
policy see counts and sightings only; the simulator's truth scores them:

- the adopted encoder scale against the true carpet ground travel per tick,
  ``m_per_tick * r_v`` with ``r_v`` the along-track ground travel per encoder
  travel from the onset to the end of the route (``bench_scale.true_ratio``);
- the adopted wheel base against the effective one, ``b r_v / r_w``, ``r_w``
  the true heading change per encoder heading change over the turns in place
  after the onset (periods turning faster than 0.4 rad/s by the encoders:
  quantisation noise on straight driving would bias a regression).

Figures: ``scale_recalibration.adopted_pct`` (runs with a scale adopted after
the onset), ``median_abs_error_pct`` and ``max_abs_error_pct`` of the adopted
``m_per_tick``, ``median_wait_s`` from the onset to the adoption, and the
median error of the adopted wheel base. Run
``python -m benchmarks scale_recalibration``; the table is printed too.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

from benchmarks.bench_monitor import calibrated_model
from benchmarks.bench_scale import Drives, route_drives, true_ratio
from benchmarks.harness import Figure, benchmark
from drivers.sim.config import Fault, get_preset
from fusion.monitoring.recalibration import Recalibrator
from fusion.monitoring.recalibration_options import RecalibrationOptions
from fusion.monitoring.residual import AlarmEvent
from fusion.monitoring.scale import ScaleMonitor
from lti_motion.app.route import ROUTE_LANDMARKS, ROUTE_M
from lti_motion.kinematics import body_from_wheel
from lti_motion.model.motion_model import MotionModel


def true_turn_ratio(model: MotionModel, drives: Drives, robot: int, from_s: float) -> float:
    """Truth for scoring: heading change per encoder heading change in turns after ``from_s``."""
    dt = model.dt_s
    k0 = int(np.ceil(from_s / dt))
    heading = np.unwrap(drives.true_poses[robot, :, 2])
    d_true = np.diff(heading[k0:])
    d = drives.deltas[robot, k0:k0 + len(d_true)]
    d_enc = model.m_per_tick * body_from_wheel(d, wheel_base_m=model.wheel_base_m)[:, 1]
    turning = np.abs(d_enc) > 0.4 * dt
    return float(d_true[: len(d_enc)][turning].sum() / d_enc[turning].sum())


@dataclass(frozen=True)
class ScaleRecalibrationResult:
    """Per run (NaN: nothing adopted after the onset): errors [%] of the adopted encoder
    scale and wheel base against the truth, wait [s] from the onset, and the actions."""

    m_error_pct: np.ndarray
    b_error_pct: np.ndarray
    wait_s: np.ndarray
    actions: list[list[str]]
    adopted_before_onset: int

    @property
    def adopted(self) -> int:
        return int(np.isfinite(self.m_error_pct).sum())


def scale_recalibration_runs(model: MotionModel, *, n: int = 20, seed0: int = 300,
                             onset_seed: int = 7, max_scale_std: float = 0.004,
                             scale_settle_s: float = 30.0) -> ScaleRecalibrationResult:
    """``n`` carpet runs (module doc); the policy's scale decisions scored against the truth."""
    p = get_preset("create2")
    onsets = np.random.default_rng(onset_seed).uniform(15.0, 40.0, n)
    faults = [Fault("floor", t_s=float(onsets[i]), robots=(i,), floor="carpet")
              for i in range(n)]
    drives = route_drives(model.m_per_tick, range(seed0, seed0 + n), faults)
    mon = ScaleMonitor(model.m_per_tick, model.wheel_base_m, ROUTE_LANDMARKS,
                       initial_pose=np.tile([*ROUTE_M[0], 0.0], (n, 1)),
                       pose_std=(0.005, 0.005, 0.005))
    rotations: list[int] = [0] * n
    policies = [Recalibrator(model, request_rotation=lambda e, i=i: rotations.__setitem__(i, 1),
                             options=RecalibrationOptions(max_scale_std=max_scale_std,
                                                          scale_settle_s=scale_settle_s))
                for i in range(n)]
    for k in range(drives.deltas.shape[1]):
        t = (k + 1) * p.period_s
        for a in mon.update(t, drives.deltas[:, k], drives.sightings[k]):
            kind = "wheel_drift" if a.change == "curvature" else "scale_changed"
            policies[a.robot].on_alarm(AlarmEvent(t, kind, "scale_glr", a.statistic,
                                                  a.threshold, a.onset_s, scale=a))
        for i in (i for i, rc in enumerate(policies) if rc.scale_waiting):
            policies[i].update_scale(t, mon.scale_ratio[i], mon.scale_ratio_std[i],
                                     mon.yaw_ratio[i], mon.yaw_ratio_std[i])
    m_err, b_err, wait = (np.full(n, np.nan) for _ in range(3))
    before = 0
    for i, rc in enumerate(policies):
        adopted = [r for r in rc.history if r.action == "adopted"]
        before += sum(r.t_s < onsets[i] for r in adopted)
        after = [r for r in adopted if r.t_s >= onsets[i]]
        if not after:
            continue
        r_v = true_ratio(model.m_per_tick, drives, i, onsets[i])
        r_w = true_turn_ratio(model, drives, i, onsets[i])
        m_err[i] = 100.0 * (after[0].m_per_tick[1] / (model.m_per_tick * r_v) - 1.0)
        b_err[i] = 100.0 * (after[0].wheel_base_m[1] / (model.wheel_base_m * r_v / r_w) - 1.0)
        wait[i] = after[0].t_s - onsets[i]
    return ScaleRecalibrationResult(m_err, b_err, wait,
                                    [[r.action for r in rc.history] for rc in policies], before)


@benchmark("scale_recalibration")
def bench_scale_recalibration() -> list[Figure]:
    model = calibrated_model()
    res = scale_recalibration_runs(model)
    n = len(res.wait_s)
    m_abs = np.abs(res.m_error_pct[np.isfinite(res.m_error_pct)])
    b_abs = np.abs(res.b_error_pct[np.isfinite(res.b_error_pct)])
    med = float(np.median(m_abs)) if m_abs.size else float("nan")
    worst = float(m_abs.max()) if m_abs.size else float("nan")
    wait = float(np.nanmedian(res.wait_s)) if m_abs.size else float("nan")
    b_med = float(np.median(b_abs)) if b_abs.size else float("nan")
    print("| runs | adopted after the onset | m_per_tick error: median, p90, max | wait from the "
          "onset: median, max | wheel base error: median, max | rotations requested |\n"
          "| --- | --- | --- | --- | --- | --- |\n"
          f"| {n} | {res.adopted} | {med:.2f}%, {np.quantile(m_abs, 0.9):.2f}%, {worst:.2f}% | "
          f"{wait:.1f} s, {np.nanmax(res.wait_s):.1f} s | {b_med:.2f}%, {b_abs.max():.2f}% | "
          f"{sum('rotation_requested' in a for a in res.actions)} |", file=sys.stderr)
    return [Figure("scale_recalibration.adopted_pct", 100.0 * res.adopted / n, "%", 95.0),
            Figure("scale_recalibration.median_abs_error_pct", med, "%", better="lower"),
            Figure("scale_recalibration.max_abs_error_pct", worst, "%", better="lower"),
            Figure("scale_recalibration.median_wait_s", wait, "s", better="lower"),
            Figure("scale_recalibration.wheel_base_median_abs_error_pct", b_med, "%",
                   better="lower")]
