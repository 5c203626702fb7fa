"""Factor-graph smoothing with a self-calibrating motion model, on the simulator.

A Create 2 drives for two minutes among ArUco-like landmarks with known
positions; halfway through it rolls from hard floor onto carpet, which shrinks
the ground travelled per encoder tick by about 4%. An iSAM2 smoother with the
calibration-aware model factors (:mod:`fusion.graph.smoother`) estimates the pose
and the model's speed scale ``s`` and yaw-rate gain ``g`` online. The figure
shows the true path, the smoother's, sensor-less dead reckoning with the same
model, and the calibration estimates over time against the truth.

Run ``python examples/factor_graph.py --out out/factor_graph.png``
(``--short`` for a quick look); it prints a summary and writes a PNG.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from drivers.sim import Fault, RobotParams, Room, Simulator, calibrate_simulator, get_preset
from fusion.graph import (
    IncrementalSmoother,
    SmootherOptions,
    TransientSpeedCovariance,
    compose_motions,
    fit_calibration,
    log_keyframes,
    observe_landmarks,
    preintegrate_model,
    transient_speed_covariance_from_data,
)
from fusion.landmark_map import LandmarkMap
from fusion.range_bearing import RangeBearing
from lti_motion.calibration import CalibrationPlan, speeds_from_log
from lti_motion.metrics import ate
from lti_motion.model import MotionModel
from lti_motion.recordings import FrameLog

#: Camera model of the landmark observations: noise, reach and field of view.
BEARING_SIGMA_RAD = 0.02
RANGE_SIGMA_M = 0.03
MAX_RANGE_M = 3.5
FIELD_OF_VIEW_RAD = np.deg2rad(120.0)
#: Samples between keyframes (0.5 s at the Create 2's 15 ms period).
KEYFRAME_EVERY = 33
START_POSE = (0.0, -2.0, 0.0)


def landmark_grid(*, half_width_m: float = 5.0, spacing_m: float = 2.0) -> LandmarkMap:
    """Markers on a square grid centred on the origin, offset by half a spacing."""
    axis = np.arange(-half_width_m, half_width_m + 1e-9, spacing_m)
    gx, gy = np.meshgrid(axis, axis)
    return LandmarkMap.from_arrays(np.arange(gx.size), np.column_stack([gx.ravel(), gy.ravel()]))


def _concat(parts: Sequence[FrameLog]) -> FrameLog:
    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(p, name) for p in parts], axis=1)

    return FrameLog(t_s=cat("t_s"), ticks=cat("ticks"), light_bump=cat("light_bump"),
                    bumps=cat("bumps"), cmd_m_s=cat("cmd_m_s"), valid=cat("valid"),
                    dt_s=parts[0].dt_s, true_pose=cat("true_pose"),
                    true_body_m_s=cat("true_body_m_s"), meta=dict(parts[0].meta))


def drive(robot: RobotParams, *, n_robots: int, seed: int, duration_s: float,
          faults: Sequence[Fault] = (), field_half_width_m: float = 3.0,
          hold_periods: int = 33) -> FrameLog:
    """Drive ``n_robots`` from waypoint to waypoint inside the landmark field.

    The steering plays a person with a remote control: every ``hold_periods``
    it reads the simulator's *true* pose (never the estimator's) and sends
    wheel commands toward a random waypoint, with a random cruise speed.
    Starts with one second at rest at :data:`START_POSE`.

    Returns
    -------
    FrameLog
        A batch log, robots along axis 0.
    """
    rng = np.random.default_rng(seed)
    sim = Simulator(robot, n_robots=n_robots, seed=seed, room=Room.empty(),
                    initial_pose=START_POSE, faults=faults)
    b, dt = robot.wheel_base_m, robot.period_s
    parts = [sim.run(np.zeros((n_robots, round(1.0 / dt), 2)))]
    goal = rng.uniform(-field_half_width_m, field_half_width_m, (n_robots, 2))
    cruise = np.full(n_robots, 0.25)
    for chunk in range(round(duration_s / dt) // hold_periods):
        pose = parts[-1].true_pose[:, -1]
        to_goal = goal - pose[:, :2]
        reached = np.hypot(to_goal[:, 0], to_goal[:, 1]) < 0.5
        goal[reached] = rng.uniform(-field_half_width_m, field_half_width_m, (reached.sum(), 2))
        if chunk % 3 == 0:
            cruise = np.clip(0.25 + 0.08 * rng.standard_normal(n_robots), 0.08, 0.4)
        err = np.arctan2(to_goal[:, 1], to_goal[:, 0]) - pose[:, 2]
        err = np.arctan2(np.sin(err), np.cos(err))
        w = np.clip(1.5 * err + 0.2 * rng.standard_normal(n_robots), -1.5, 1.5)
        v = cruise * np.clip(np.cos(err), 0.2, 1.0)
        cmd = np.clip(np.stack([v - 0.5 * b * w, v + 0.5 * b * w], axis=-1), -0.5, 0.5)
        parts.append(sim.run(np.repeat(cmd[:, None, :], hold_periods, axis=1)))
    return _concat(parts)


def observe(log: FrameLog, landmarks: LandmarkMap, *, rng: np.random.Generator,
            every: int = KEYFRAME_EVERY) -> RangeBearing:
    """Camera observations every ``every`` frames of one robot (``index`` = frame)."""
    frames = np.arange(0, len(log) - 1, every)
    return observe_landmarks(log.true_pose[frames], landmarks, rng=rng,
                             bearing_sigma_rad=BEARING_SIGMA_RAD, range_sigma_m=RANGE_SIGMA_M,
                             max_range_m=MAX_RANGE_M, field_of_view_rad=FIELD_OF_VIEW_RAD,
                             index=frames)


@dataclass(frozen=True)
class Track:
    """What the smoother produced on one log.

    Attributes
    ----------
    keyframes : ndarray of int, shape (n,)
        Frame index of each keyframe.
    poses : ndarray, shape (n, 3)
        Smoothed ``wTb`` at the end of the log.
    online_calibration, online_sigma : ndarray, shape (n, 2)
        ``(s, g)`` and its standard deviation as the smoother knew them when
        each keyframe was added (filtering, no hindsight).
    smoothed_calibration : ndarray, shape (n, 2)
        ``(s, g)`` in force at each keyframe, with hindsight.
    dead_reckoning : ndarray, shape (n, 3)
        The same model's speeds integrated from the start pose.
    """

    keyframes: np.ndarray
    poses: np.ndarray
    online_calibration: np.ndarray
    online_sigma: np.ndarray
    smoothed_calibration: np.ndarray
    dead_reckoning: np.ndarray


def run_smoother(model: MotionModel, log: FrameLog, observations: RangeBearing,
                 landmarks: LandmarkMap, *, initial_pose: np.ndarray,
                 speed_covariance: np.ndarray | TransientSpeedCovariance | None = None,
                 options: SmootherOptions | None = None) -> Track:
    """iSAM2 over one log, one update per keyframe, recording the online calibration.

    ``speed_covariance``: the long-run speed covariance measured on the calibration
    logs (:func:`calibrated_model_and_noise`); ``None`` uses the model's own.
    """
    u, _ = speeds_from_log(log, m_per_tick=model.m_per_tick, wheel_base_m=model.wheel_base_m)
    kf = log_keyframes(len(u), every=KEYFRAME_EVERY, extra=observations.index)
    pre = preintegrate_model(model, u, keyframes=kf, speed_covariance=speed_covariance)
    obs = observations.with_index(np.searchsorted(kf, observations.index))
    bounds = np.searchsorted(obs.index, np.arange(len(kf) + 1))
    sm = IncrementalSmoother(initial_pose=initial_pose, options=options, landmarks=landmarks)
    cal, sig = np.empty((len(kf), 2)), np.empty((len(kf), 2))
    for k in range(len(kf)):
        if k > 0:
            sm.add_motion(pre[k - 1])
        sm.add_observations(obs.select(slice(bounds[k], bounds[k + 1])))
        sm.update()
        cal[k] = sm.calibration(k)
        sig[k] = np.sqrt(np.diag(sm.calibration_covariance(k)))
    res = sm.result(covariances=False)
    return Track(kf, res.poses, cal, sig, res.calibrations,
                 compose_motions(pre.delta_pose, initial_pose=initial_pose))


def true_calibration(model: MotionModel, log: FrameLog, keyframes: np.ndarray, *,
                     change_s: float, settle_s: float = 10.0
                     ) -> list[tuple[float, float, np.ndarray]]:
    """The calibration the true poses imply before and after the floor change.

    :func:`~fusion.graph.fit_calibration` on the true keyframe poses
    of each span (the first ``settle_s`` after the change left out).
    """
    u, _ = speeds_from_log(log, m_per_tick=model.m_per_tick, wheel_base_m=model.wheel_base_m)
    pre = preintegrate_model(model, u, keyframes=keyframes)
    t = keyframes * log.dt_s
    truth = log.true_pose[keyframes]
    spans = []
    for t0, t1 in ((1.0, change_s), (change_s + settle_s, t[-1])):
        a, b = int(np.searchsorted(t, t0)), int(np.searchsorted(t, t1, side="right")) - 1
        if b - a >= 4:
            spans.append((float(t[a]), float(t[b]), fit_calibration(pre[a:b], truth[a:b + 1])[0]))
    return spans


def plot(track: Track, true_poses: np.ndarray, landmarks: LandmarkMap, *, path: Path,
         dt_s: float, floor_change_s: float | None = None,
         true_calibration: Sequence[tuple[float, float, np.ndarray]] = (),
         ekf_poses: np.ndarray | None = None) -> Path:
    """Paths (truth, smoother, dead reckoning, optional EKF) and calibration over time.

    ``true_calibration`` holds ``(t_start_s, t_end_s, (s, g))`` spans drawn as
    the truth; ``ekf_poses`` (keyframe-aligned or per frame, ``(n, 3)``) adds an
    EKF path for comparison.
    """
    fig = Figure(figsize=(16, 5.2))     # no pyplot: no GUI backend, no global state
    ax, ax_s, ax_g = fig.subplots(1, 3)
    ax.plot(landmarks.xy_m[:, 0], landmarks.xy_m[:, 1], "ks", ms=5, label="landmarks")
    ax.plot(true_poses[:, 0], true_poses[:, 1], "k-", lw=2.0, label="truth")
    ax.plot(track.dead_reckoning[:, 0], track.dead_reckoning[:, 1], color="tab:gray", lw=1.0,
            label="dead reckoning (same model)")
    ax.plot(track.poses[:, 0], track.poses[:, 1], color="tab:blue", lw=1.2, label="iSAM2")
    if ekf_poses is not None:
        ax.plot(ekf_poses[:, 0], ekf_poses[:, 1], color="tab:orange", lw=1.0, label="EKF")
    ax.set(xlabel="x [m]", ylabel="y [m]", title="paths", aspect="equal")
    ax.legend(loc="upper right", fontsize=8)
    t = track.keyframes * dt_s
    for col, axc, name in ((0, ax_s, "speed scale s"), (1, ax_g, "yaw-rate gain g")):
        est, sd = track.online_calibration[:, col], track.online_sigma[:, col]
        axc.fill_between(t, est - 2 * sd, est + 2 * sd, color="tab:blue", alpha=0.2,
                         label="online +- 2 sigma")
        axc.plot(t, est, color="tab:blue", lw=1.2, label="online (iSAM2)")
        axc.plot(t, track.smoothed_calibration[:, col], color="tab:green", lw=1.2,
                 label="smoothed")
        for i, (t0, t1, value) in enumerate(true_calibration):
            axc.plot([t0, t1], [value[col]] * 2, "k--", lw=1.5,
                     label="truth (fit to true poses)" if i == 0 else None)
        if floor_change_s is not None:
            axc.axvline(floor_change_s, color="k", ls=":", label="hard -> carpet")
        settled = est[t > 5.0] if np.any(t > 5.0) else est
        axc.set(xlabel="time [s]", title=name,
                ylim=(settled.min() - 0.04, settled.max() + 0.04))
        axc.legend(loc="best", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def calibrated_model_and_noise(*, seed: int = 1
                               ) -> tuple[MotionModel, TransientSpeedCovariance]:
    """The ARX model of the nominal Create 2, calibrated on hard floor by driving, and the
    long-run covariance of its sensor-less speed errors measured on its own three
    calibration logs (rotation, steps, excitation) against the encoders, conditioned on
    the model's wheel tracking error
    (:func:`fusion.graph.transient_speed_covariance_from_data`: Newey-West, 5 s
    bandwidth, 0.15 s window): the covariance to preintegrate with, no hand factor."""
    p = get_preset("create2")
    cal = calibrate_simulator(p, seed=seed, plan=CalibrationPlan(seed=3))
    runs = [speeds_from_log(cal.logs[name], m_per_tick=cal.m_per_tick,
                            wheel_base_m=p.wheel_base_m)
            for name in ("rotation", "steps", "excitation")]
    return cal.arx, transient_speed_covariance_from_data(cal.arx, runs)


def calibrated_model(*, seed: int = 1) -> MotionModel:
    """The ARX model of :func:`calibrated_model_and_noise` alone."""
    return calibrated_model_and_noise(seed=seed)[0]


def run(*, seed: int = 0, duration_s: float = 120.0, out: Path = Path("out/factor_graph.png"),
        model: MotionModel | None = None,
        speed_covariance: np.ndarray | TransientSpeedCovariance | None = None
        ) -> dict[str, float]:
    """Calibrate (unless given a model and its speed covariance), drive, smooth, plot;
    return summary figures."""
    if model is None:
        model, speed_covariance = calibrated_model_and_noise()
    p = get_preset("create2")
    floor_change_s = 0.5 * duration_s
    log = drive(p, n_robots=1, seed=seed, duration_s=duration_s,
                faults=[Fault("floor", t_s=floor_change_s, floor="carpet")]).robot(0)
    landmarks = landmark_grid()
    obs = observe(log, landmarks, rng=np.random.default_rng(seed + 1000))
    track = run_smoother(model, log, obs, landmarks, initial_pose=log.true_pose[0],
                         speed_covariance=speed_covariance)
    truth = log.true_pose[track.keyframes]
    plot(track, log.true_pose, landmarks, path=out, dt_s=p.period_s,
         floor_change_s=floor_change_s,
         true_calibration=true_calibration(model, log, track.keyframes,
                                           change_s=floor_change_s))
    return {"ate_smoother_m": float(ate(truth, track.poses)),
            "ate_dead_reckoning_m": float(ate(truth, track.dead_reckoning)),
            "s_before": float(track.online_calibration[len(track.keyframes) // 2 - 1, 0]),
            "s_after": float(track.online_calibration[-1, 0])}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--duration", type=float, default=120.0, help="seconds of driving")
    parser.add_argument("--short", action="store_true", help="20 s of driving (smoke test)")
    parser.add_argument("--out", type=Path, default=Path("out/factor_graph.png"))
    args = parser.parse_args(argv)
    summary = run(seed=args.seed, duration_s=20.0 if args.short else args.duration, out=args.out)
    for name, value in summary.items():
        print(f"{name:24s} {value:.4f}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
