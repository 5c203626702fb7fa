"""Alarms and recalibration on one simulated drive: an encoder glitch, carpet, then a payload.

A Create 2 drives the closed route (stop, turn in place,
drive at 0.25 m/s, slow down at each checkpoint; steering on its encoder
odometry) with four landmarks seen at 2 Hz. On the way its left encoder
spikes for a second (20 Hz of 150-tick spikes), the floor turns to carpet
(3.5% less ground per tick, invisible to the encoders) and it takes on a
+1.8 kg payload (+50%). One :class:`~fusion.monitoring.MonitoredFilter` watches
everything, fed one frame at a time with what a robot reports (commands, counts,
sightings; never the simulator's truth):

- the per-sample gate and glitch bursts on the innovations of the model's
  EKF (:class:`~fusion.ekf.ModelEKF`, encoders only), and the stuck-encoder check;
- the dynamics tests (:class:`~fusion.monitoring.DynamicsMonitor`: lag
  and covariance CUSUMs on integrated residuals), their null fitted at start
  on nominal route drives (a Phase-I fit, as ``benchmarks/bench_monitor.py``);
- the scale test (:class:`~fusion.monitoring.ScaleMonitor`, landmarks).

A :class:`~fusion.monitoring.Recalibrator` answers the alarms: a glitch
burst is ignored; a scale alarm is answered from the landmarks (the running
scale estimate is adopted once precise: new encoder scale and wheel base,
the model's outputs rescaled), and from then on the robot steers with the
adopted scale; a dynamics alarm asks for an excitation manoeuvre, which this
application drives once the route is done (the calibration's random
excitation, on the carpet with the payload), and the refit replaces the
model only if it validates better. The simulator's truth is used only to
mark the fault onsets and to score.

Writes to ``--out``: ``monitor.png`` (residuals, each test's statistic
against its threshold, the scale estimate, alarms and fault onsets over
time) and ``fit.png`` (the old model and the model in use on a fresh drive
with both faults, against the measured speeds); prints the alarms (time,
kind, test, onset, delay from the true onset) and the recalibration records.

Run ``python examples/recalibration_alarm.py --out out/recalibration_alarm``
(about 30 s).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from drivers.sim import Fault, Room, Simulator, calibrate_simulator, get_preset
from fusion.monitoring import (
    AlarmEvent,
    MonitoredFilter,
    NominalFit,
    RecalibrationOptions,
    RecalibrationRecord,
    Recalibrator,
    fit_nominal,
    output_scaling,
)
from lti_motion.app.route import (
    ROUTE_LANDMARKS,
    ROUTE_M,
    Odometry,
    RecordingOdometry,
    drive_route,
)
from lti_motion.calibration import CalibrationPlan, speeds_from_log
from lti_motion.kinematics import body_from_wheel
from lti_motion.model import MotionModel, random_held_normal
from lti_motion.recordings import FrameLog, SensorFrame

#: Which fault each alarm kind answers (for the delay column).
FAULT_OF_KIND = {"glitch_burst": "encoder_spikes", "stuck_encoder": "stuck_encoder",
                 "scale_changed": "floor", "dynamics_changed": "payload"}
KIND_COLOURS = {"glitch_burst": "tab:red", "stuck_encoder": "tab:purple",
                "dynamics_changed": "tab:orange", "scale_changed": "tab:green"}


def calibrated_model(*, seed: int = 1, excitation_s: float = 180.0) -> MotionModel:
    """An ARX calibration of the simulated Create 2 (rotation in clutter, then open floor)."""
    return calibrate_simulator("create2", seed=seed,
                               plan=CalibrationPlan(seed=seed + 2, excitation_s=excitation_s)).arx


def phase_one(model: MotionModel, *, runs: int, seed0: int = 1000) -> NominalFit:
    """The dynamics null and the encoder gate from ``runs`` nominal route drives.

    Commands and counts only (:func:`~fusion.monitoring.fit_nominal`);
    the null leaves out each drive's first 3 s, as the benchmark's
    (``benchmarks/bench_monitor.py``, whose false-alarm rate it measured).
    """
    p = get_preset("create2")
    rec = RecordingOdometry(m_per_tick=model.m_per_tick, wheel_base_m=p.wheel_base_m)
    drive_route(p, rec, seeds=list(range(seed0, seed0 + runs)))
    cmd, ticks = np.stack(rec.cmd, axis=1), np.stack(rec.ticks, axis=1)
    return fit_nominal(model, [(cmd[i, 1:], ticks[i]) for i in range(runs)], skip_s=3.0)


@dataclass
class Trace:
    """Per period, what the plots show (all from what the robot reports)."""

    t_s: list = field(default_factory=list)
    deltas: list = field(default_factory=list)          # count changes (left, right)
    innovation: list = field(default_factory=list)      # encoder innovation (v, w)
    nis: list = field(default_factory=list)
    dynamics: list = field(default_factory=list)        # CUSUMs (lag, covariance) [nats]
    scale_llr: list = field(default_factory=list)
    scale: list = field(default_factory=list)           # (ratio, std, yaw ratio, std)

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v, dtype=float) for k, v in self.__dict__.items()}


class MonitoredDrive(Odometry):
    """The application: steers on encoder odometry, runs the monitors, answers their alarms.

    An :class:`~lti_motion.app.route.Estimator` for one robot: each
    period it feeds the EKF, the monitor's four inputs and the policy, and
    after a scale adoption it steers with the adopted encoder scale and wheel
    base.
    """

    def __init__(self, model: MotionModel, nominal: NominalFit, *, save_path: Path) -> None:
        super().__init__(m_per_tick=model.m_per_tick, wheel_base_m=model.wheel_base_m)
        self.model = model
        self.excitation_requests: list[AlarmEvent] = []
        self.recal = Recalibrator(model, save_path=save_path,
                                  request_excitation=self.excitation_requests.append,
                                  request_rotation=lambda event: None,
                                  options=RecalibrationOptions(min_samples=3000))
        # the model EKF, the sensor tests, the dynamics tests (Phase I) and the scale test
        # (landmarks), one call per frame; the landmarks feed the scale test only
        self.filter = MonitoredFilter(model, nominal=nominal, landmarks=ROUTE_LANDMARKS,
                                      fuse_landmarks=False, initial_pose=(*ROUTE_M[0], 0.0),
                                      pose_std=(0.005,) * 3, t0_s=model.dt_s,
                                      on_alarm=self.recal.on_alarm)
        self.dynamics, self.scale = self.filter.dynamics, self.filter.scale
        self.trace = Trace()

    def step(self, frame, cmd_m_s, observations=None):
        pose = super().step(frame, cmd_m_s, observations)       # steering odometry
        cmd = np.asarray(cmd_m_s, float)[0]
        # the first robot's frame, with the command as steered
        own = SensorFrame.of_counts(float(np.ravel(frame.t_s)[0]), np.asarray(frame.ticks)[0],
                                    cmd)
        res = self.filter.step(own, sightings=None if observations is None else observations[0])
        if res.encoders is None:                                 # the first frame anchors
            return pose
        t, d, record = res.t_s, res.tick_deltas, res.encoders
        # the policy's data: commands and encoder speeds in the model in use's scale
        rm = self.recal.model
        wheel = d * rm.m_per_tick / rm.dt_s
        self.recal.add(t, cmd, body_from_wheel(wheel, wheel_base_m=rm.wheel_base_m))
        if self.recal.scale_waiting:
            sc = self.scale
            self.recal.update_scale(t, sc.scale_ratio[0], sc.scale_ratio_std[0],
                                    sc.yaw_ratio[0], sc.yaw_ratio_std[0])
        # steer with the scale in use (adopted from landmarks after a scale alarm)
        self.m_per_tick, self.wheel_base_m = rm.m_per_tick, rm.wheel_base_m
        tr = self.trace
        tr.t_s.append(t)
        tr.deltas.append(d)
        tr.innovation.append(record.innovation)
        tr.nis.append(record.nis)
        tr.dynamics.append(self.dynamics.statistic[0].copy())
        tr.scale_llr.append(float(self.scale.statistic[0]))
        tr.scale.append([self.scale.scale_ratio[0], self.scale.scale_ratio_std[0],
                         self.scale.yaw_ratio[0], self.scale.yaw_ratio_std[0]])
        return pose


def excitation(model: MotionModel, faults: Sequence[Fault], *, seed: int, duration_s: float,
               floor: str) -> tuple[np.ndarray, FrameLog]:
    """The calibration's random excitation on open floor: commands and the frame log."""
    plan = CalibrationPlan()
    sim = Simulator("create2", seed=seed, room=Room.empty(), initial_pose=(0.0, 0.0, 0.0),
                    floor=floor, faults=faults)
    u = random_held_normal(n=round(duration_s / model.dt_s), dt_s=model.dt_s,
                           rng=np.random.default_rng(seed), std_m_s=plan.excitation_std_m_s,
                           correlation=plan.excitation_correlation, hold_s=plan.hold_s)
    return u, sim.run(u)


def _speeds(log: FrameLog, model: MotionModel) -> tuple[np.ndarray, np.ndarray]:
    return speeds_from_log(log, m_per_tick=model.m_per_tick, wheel_base_m=model.wheel_base_m)


@dataclass
class Result:
    """What :func:`run` gives: the alarms, the policy's records, traces and scores."""

    events: list[AlarmEvent]
    records: list[RecalibrationRecord]
    onsets: dict[str, float]
    trace: dict[str, np.ndarray]
    true_ratio: float                   # carpet ground per encoder travel (truth, scoring)
    original: MotionModel
    in_use: MotionModel
    fits: dict[str, float]
    validation: dict[str, np.ndarray]
    route_s: float
    thresholds: dict[str, float]


def _true_ratio(model: MotionModel, true_poses: np.ndarray, deltas: np.ndarray,
                from_s: float) -> float:
    """Scoring only: along-track ground travel per encoder travel after ``from_s``.

    ``true_poses[k]`` is the pose after period ``k`` (0-based), ``deltas[k - 1]``
    the count change over period ``k``, which ends at ``(k + 1) dt``.
    """
    k0 = max(1, int(np.ceil(from_s / model.dt_s)) - 1)
    n = min(len(true_poses) - 1, len(deltas))
    step = np.diff(true_poses[k0 - 1:n + 1, :2], axis=0)
    th = np.unwrap(true_poses[k0 - 1:n + 1, 2])
    heading = th[:-1] + 0.5 * np.diff(th)
    ground = float(np.sum(step[:, 0] * np.cos(heading) + step[:, 1] * np.sin(heading)))
    enc = float(model.m_per_tick * deltas[k0 - 1:n].mean(axis=1).sum())
    return ground / enc if enc > 0 else float("nan")


def run(*, seed: int = 0, spikes_at_s: float = 8.0, carpet_at_s: float = 18.0,
        payload_at_s: float = 33.0, max_s: float = 150.0, nominal_runs: int = 30,
        calibration_s: float = 180.0, excitation_s: float = 60.0, validation_s: float = 30.0,
        out: Path | None = None, print_fn: Callable[[str], object] = print) -> Result:
    """Calibrate, Phase I, drive the route with the faults, answer the alarms, validate.

    Seeds: calibration 1 (as ``benchmarks/bench_monitor.py``), Phase I 1000 onwards,
    the route ``seed``, the excitation manoeuvre ``900 + seed``, validation ``5000 + seed``.
    """
    t_wall = time.perf_counter()
    p = get_preset("create2")
    print_fn(f"calibrating the simulated Create 2 ({calibration_s:g} s of excitation) ...")
    model = calibrated_model(excitation_s=calibration_s)
    print_fn(f"phase I: the dynamics null and the encoder gate from {nominal_runs} nominal route "
             "drives ...")
    nominal = phase_one(model, runs=nominal_runs)
    onsets = {"encoder_spikes": spikes_at_s, "floor": carpet_at_s, "payload": payload_at_s}
    faults = [Fault("encoder_spikes", t_s=spikes_at_s, duration_s=1.0, rate_hz=20.0,
                    wheel="left"),
              Fault("floor", t_s=carpet_at_s, floor="carpet"),
              Fault("payload", t_s=payload_at_s, payload_kg=1.8)]
    with tempfile.TemporaryDirectory() as tmp:
        save = (out or Path(tmp)) / "model_in_use.json"
        app = MonitoredDrive(model, nominal, save_path=save)
        print_fn(f"driving the route (seed {seed}): spikes at {spikes_at_s:g} s, carpet at "
                 f"{carpet_at_s:g} s, payload at {payload_at_s:g} s ...")
        res = drive_route(p, app, seeds=[seed], faults=faults, landmarks=ROUTE_LANDMARKS,
                          max_s=max_s)
        route_s = app.filter.ekf.t_s if app.filter.ekf is not None else 0.0
        if app.excitation_requests and app.recal.waiting:
            # the application drives the excitation once the route is done (its choice of a
            # safe time and place): the same robot, on the carpet with the payload
            print_fn(f"the policy asked for an excitation manoeuvre: driving {excitation_s:g} s "
                     "of the calibration's random excitation ...")
            u_x, log_x = excitation(app.recal.model, [Fault("payload", t_s=0.0, payload_kg=1.8)],
                                    seed=900 + seed, duration_s=excitation_s, floor="carpet")
            _, y_x = _speeds(log_x, app.recal.model)
            t0 = route_s + 1.0                                   # a gap: a new segment
            for k in range(len(y_x)):
                app.recal.add(t0 + k * model.dt_s, u_x[k + 1], y_x[k])
            if app.recal.waiting:
                app.recal.retry()
        in_use = app.recal.model
    # validation: a fresh drive with both faults (and, for the pre-fault fit, without)
    _, log_v = excitation(model, [Fault("payload", t_s=0.0, payload_kg=1.8)],
                          seed=5000 + seed, duration_s=validation_s, floor="carpet")
    _, log_n = excitation(model, [], seed=5000 + seed, duration_s=validation_s, floor="hard")
    y_old, y_new = _speeds(log_v, model)[1], _speeds(log_v, in_use)[1]
    u_fit = log_v.cmd_m_s[1:]
    fits = {"before the faults (original model, hard floor)":
            float(np.mean(model.fit_percent([_speeds(log_n, model)]))),
            "original model, carpet + payload": float(np.mean(model.fit_percent([(u_fit, y_old)]))),
            "model in use, carpet + payload": float(np.mean(in_use.fit_percent([(u_fit, y_new)])))}
    result = Result(
        events=list(app.filter.events), records=list(app.recal.history), onsets=onsets,
        trace=app.trace.arrays(),
        true_ratio=_true_ratio(model, res.true_poses[0], np.asarray(app.trace.deltas),
                               carpet_at_s),
        original=model, in_use=in_use, fits=fits,
        validation={"u": u_fit, "y_old": y_old, "y_new": y_new,
                    "pred_old": model.simulate(u_fit), "pred_new": in_use.simulate(u_fit),
                    # the original model's predicted counts, in the new scale (for the plot)
                    "s": output_scaling(model, m_per_tick=in_use.m_per_tick,
                                        wheel_base_m=in_use.wheel_base_m)},
        route_s=route_s,
        thresholds={"gate": app.filter.monitor.thresholds().gate, "lag": app.dynamics.lag_threshold,
                    "covariance": app.dynamics.covariance_threshold,
                    "scale": app.scale.threshold})
    print_fn(f"done in {time.perf_counter() - t_wall:.0f} s")
    return result


def alarm_rows(result: Result) -> list[str]:
    """The alarm table: time, kind, test, onset, delay from the true onset of its fault.

    An alarm answers a fault of its kind while that fault acts (the spikes for
    their second and 1 s more); any other alarm is a false alarm.
    """
    rows = ["| t [s] | kind | test | statistic / threshold | onset [s] | true onset [s] "
            "| delay [s] |",
            "| --- | --- | --- | --- | --- | --- | --- |"]
    for e in result.events:
        test = e.test
        if e.dynamics is not None:     # the dynamics sub-test
            test = f"integrated ({e.dynamics.test})"
        fault = FAULT_OF_KIND.get(e.kind, "")
        true_onset = result.onsets.get(fault, float("nan"))
        end = true_onset + 2.0 if fault == "encoder_spikes" else float("inf")
        late = (f"{e.t_s - true_onset:.2f}" if true_onset <= e.t_s <= end
                else "false alarm (no such fault acting)")
        rows.append(f"| {e.t_s:.2f} | {e.kind} | {test} | {e.statistic:.3g} / "
                    f"{e.threshold:.3g} | {e.onset_s:.2f} | {true_onset:.2f} | {late} |")
    return rows


def record_rows(result: Result) -> list[str]:
    """The recalibration records: when, which alarm, what was done, fits or scales."""
    rows = ["| t [s] | alarm | action | samples | fit before -> after [%] (v, w) | "
            "m_per_tick [um/tick], wheel base [mm] | reason |",
            "| --- | --- | --- | --- | --- | --- | --- |"]
    for r in result.records:
        fit = ""
        if r.fit_before is not None and r.fit_after is not None:
            fit = (f"{r.fit_before[0]:.1f}, {r.fit_before[1]:.1f} -> {r.fit_after[0]:.1f}, "
                   f"{r.fit_after[1]:.1f}")
        scale = ""
        if r.m_per_tick is not None:
            scale = (f"{1e6 * r.m_per_tick[0]:.2f} -> {1e6 * r.m_per_tick[1]:.2f}, "
                     f"{1e3 * r.wheel_base_m[0]:.1f} -> {1e3 * r.wheel_base_m[1]:.1f}")
        rows.append(f"| {r.t_s:.2f} | {r.alarm.kind} at {r.alarm.t_s:.2f} | {r.action} | "
                    f"{r.n_samples} | {fit} | {scale} | {r.reason} |")
    return rows


def summary_lines(result: Result) -> list[str]:
    """Scores (the truth only here): the adopted scale against the carpet's, and the fits."""
    lines = []
    m0 = result.original.m_per_tick
    truth = m0 * result.true_ratio
    lines.append(f"carpet ground per tick (truth, scoring only): {1e6 * truth:.2f} um/tick "
                 f"(calibrated on hard floor: {1e6 * m0:.2f}, ratio {result.true_ratio:.4f})")
    adopted = [r for r in result.records if r.m_per_tick is not None and r.action == "adopted"]
    if adopted:
        m_new = adopted[-1].m_per_tick[1]
        lines.append(f"adopted from landmarks: {1e6 * m_new:.2f} um/tick, error "
                     f"{100 * (m_new / truth - 1):+.2f}% (the old scale's: "
                     f"{100 * (m0 / truth - 1):+.2f}%)")
    lines.append("free-run fit [%] (mean of v and w) on fresh random excitation:")
    for name, fit in result.fits.items():
        lines.append(f"  {name}: {fit:.1f}%")
    return lines


def plot_monitor(result: Result, path: Path) -> None:
    """Residuals, each test's statistic against its threshold, the scale, alarms and onsets."""
    gate, lag_h, cov_h, scale_h = (result.thresholds[k]
                                   for k in ("gate", "lag", "covariance", "scale"))
    tr = result.trace
    t = tr["t_s"]
    fig = Figure(figsize=(12, 13))      # no pyplot: no GUI backend, no global state
    ax = fig.subplots(5, 1, sharex=True)
    ax[0].plot(t, tr["innovation"][:, 0], lw=0.6, label="v [m/s]")
    ax[0].plot(t, tr["innovation"][:, 1], lw=0.6, label="w [rad/s]")
    ax[0].set_ylabel("encoder innovation")
    lim = np.nanquantile(np.abs(tr["innovation"]), 0.999)
    ax[0].set_ylim(-3 * lim, 3 * lim)
    ax[1].semilogy(t, np.maximum(tr["nis"], 1e-3), lw=0.6, color="tab:blue", label="NIS")
    ax[1].axhline(gate, color="k", ls="--", lw=1, label=f"gate {gate:.1f}")
    ax[1].set_ylabel("encoder NIS")
    ax[2].plot(t, tr["dynamics"][:, 0], color="tab:orange", label="lag CUSUM")
    ax[2].axhline(lag_h, color="tab:orange", ls="--", lw=1, label=f"lag threshold {lag_h:.2f}")
    ax[2].plot(t, tr["dynamics"][:, 1], color="tab:brown", label="covariance CUSUM")
    ax[2].axhline(cov_h, color="tab:brown", ls="--", lw=1,
                  label=f"covariance threshold {cov_h:.1f}")
    ax[2].set_ylabel("dynamics [nats]")
    ax[3].plot(t, tr["scale_llr"], color="tab:green", label="scale GLR (best shadow)")
    ax[3].axhline(scale_h, color="tab:green", ls="--", lw=1, label=f"threshold {scale_h:.1f}")
    ax[3].set_ylabel("scale [nats]")
    sc = tr["scale"]
    for j, (name, colour) in enumerate((("travel", "tab:green"), ("turn", "tab:olive"))):
        ax[4].plot(t, sc[:, 2 * j], color=colour, label=f"{name} ratio (landmarks)")
        ax[4].fill_between(t, sc[:, 2 * j] - 2 * sc[:, 2 * j + 1],
                           sc[:, 2 * j] + 2 * sc[:, 2 * j + 1], color=colour, alpha=0.2)
    on = result.onsets["floor"]
    ax[4].hlines(result.true_ratio, on, t[-1], colors="k", linestyles=":",
                 label="true travel ratio on carpet (scoring)")
    ax[4].set_ylim(0.9, 1.06)
    ax[4].set_ylabel("ground / encoder")
    ax[4].set_xlabel("time [s]")
    for a in ax:
        for t_on in result.onsets.values():
            a.axvline(t_on, color="0.4", ls=":", lw=1)
        for e in result.events:
            a.axvline(e.t_s, color=KIND_COLOURS.get(e.kind, "k"), lw=1.2, alpha=0.8)
        a.legend(loc="upper left", fontsize=7)
        a.grid(alpha=0.3)
    for name, t_on in result.onsets.items():
        ax[0].annotate(f"{name} onset", (t_on, 1.0), xycoords=("data", "axes fraction"),
                       rotation=90, va="top", ha="right", fontsize=7)
    for e in result.events:
        ax[0].annotate(e.kind, (e.t_s, 0.0), xycoords=("data", "axes fraction"), rotation=90,
                       va="bottom", ha="left", fontsize=7, color=KIND_COLOURS.get(e.kind, "k"))
    fig.suptitle("Alarms on one route drive: encoder spikes, carpet, payload (dotted: true "
                 "fault onsets; solid: alarms)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def plot_fit(result: Result, path: Path, *, window_s: float = 12.0) -> None:
    """Measured speeds of a fresh drive with both faults against the old and the new model."""
    val = result.validation
    dt = result.original.dt_s
    n = min(len(val["u"]), round(window_s / dt))
    t = np.arange(n) * dt
    fig = Figure(figsize=(12, 6))
    ax = fig.subplots(2, 1, sharex=True)
    fit_old = result.original.fit_percent([(val["u"], val["y_old"])])
    fit_new = result.in_use.fit_percent([(val["u"], val["y_new"])])
    for j, unit in enumerate(("v [m/s]", "w [rad/s]")):
        ax[j].plot(t, val["y_new"][:n, j], color="k", lw=0.8,
                   label="measured (encoders, the scale in use)")
        ax[j].plot(t, val["s"][j] * val["pred_old"][:n, j], color="tab:red", lw=1,
                   label=f"original model, free run: fit {fit_old[j]:.1f}% (its counts, "
                         "shown in the new scale)")
        ax[j].plot(t, val["pred_new"][:n, j], color="tab:blue", lw=1,
                   label=f"model in use, free run: fit {fit_new[j]:.1f}%")
        ax[j].set_ylabel(unit)
        ax[j].legend(loc="upper right", fontsize=8)
        ax[j].grid(alpha=0.3)
    ax[1].set_xlabel("time [s]")
    fig.suptitle("Fit before and after the recalibration: fresh random excitation on carpet with "
                 "the payload (fits: each model against the counts in its own encoder scale)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/recalibration_alarm"))
    parser.add_argument("--seed", type=int, default=0, help="route drive seed (default 0)")
    parser.add_argument("--spikes-at", type=float, default=8.0, help="encoder spikes onset [s]")
    parser.add_argument("--carpet-at", type=float, default=18.0, help="carpet onset [s]")
    parser.add_argument("--payload-at", type=float, default=33.0, help="payload onset [s]")
    parser.add_argument("--max-s", type=float, default=150.0,
                        help="route time limit [s] (the route takes about 60 s)")
    parser.add_argument("--nominal-runs", type=int, default=30,
                        help="nominal route drives for Phase I: the dynamics null and the "
                             "encoder gate (default 30)")
    parser.add_argument("--calibration-s", type=float, default=180.0,
                        help="calibration excitation [s]")
    parser.add_argument("--excitation-s", type=float, default=60.0,
                        help="excitation manoeuvre driven on the policy's request [s]")
    parser.add_argument("--validation-s", type=float, default=30.0,
                        help="fresh drive for the fits before/after [s]")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    result = run(seed=args.seed, spikes_at_s=args.spikes_at, carpet_at_s=args.carpet_at,
                 payload_at_s=args.payload_at, max_s=args.max_s, nominal_runs=args.nominal_runs,
                 calibration_s=args.calibration_s, excitation_s=args.excitation_s,
                 validation_s=args.validation_s, out=args.out)
    report(result, args.out)
    return 0


def report(result: Result, out: Path, print_fn: Callable[[str], object] = print) -> None:
    """Print the tables and the scores; write ``monitor.png`` and ``fit.png`` to ``out``."""
    print_fn(f"\nroute driven for {result.route_s:.1f} s; alarms:")
    for line in alarm_rows(result):
        print_fn(line)
    print_fn("\nrecalibration records:")
    for line in record_rows(result):
        print_fn(line)
    print_fn("")
    for line in summary_lines(result):
        print_fn(line)
    plot_monitor(result, out / "monitor.png")
    plot_fit(result, out / "fit.png")
    print_fn(f"wrote monitor.png, fit.png and the model in use to {out}")


if __name__ == "__main__":
    sys.exit(main())
