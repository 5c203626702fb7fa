"""The calibrated motion model inside a filterpy EKF, fusing encoders and landmarks.

1. Calibrate on the simulator (rotation beside the boxes, then steps and
   random excitation on open floor): an ARX :class:`~lti_motion.model.MotionModel`.
2. Drive a rounded square in a 5 m x 5 m room, with encoder spikes and a
   stuck-encoder episode injected, and four landmarks at the corners seen at
   2 Hz each (range 2%, bearing 1 degree).
3. Run :class:`fusion.ekf.ModelEKF` on the frames and the observations, and
   integrate the encoders alone (odometry) for comparison.
4. Plot truth, odometry and filter into ``OUT/ekf_plugin.png``.

Run::

    python examples/ekf_plugin.py --out out/ekf_plugin [--duration-s 120] [--seed 0]

The robot's path follower steers on the simulator's true pose (as a perfect
localiser would); the filter never reads it. Landmark observations are drawn
from the true pose with seeded noise. Wheel commands stay positive, because
the Create 2's encoders count in the *commanded* direction (a causal filter
cannot unfold reversals; the gate would reject those periods).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from drivers.sim import Fault, Room, Simulator, calibrate_simulator
from fusion.ekf import EKFOptions, FilterStats, ModelEKF
from fusion.landmark_map import LandmarkMap
from fusion.landmarks import synthetic_observations
from fusion.range_bearing import RangeBearing
from lti_motion.calibration import CalibrationPlan
from lti_motion.kinematics import integrate_poses, wrap_angle
from lti_motion.model import MotionModel
from lti_motion.recordings import FrameLog, body_speeds_from_ticks, stream_clock

__all__ = [
    "LANDMARKS",
    "START_POSE",
    "FilterRun",
    "calibrate_model",
    "concat_logs",
    "drive_route",
    "main",
    "odometry_poses",
    "plot_run",
    "rounded_square",
    "run_filter",
]

#: Four landmarks near the corners of the 5 m x 5 m room [m].
LANDMARKS = LandmarkMap({0: (0.5, 0.5), 1: (4.5, 0.5), 2: (4.5, 4.5), 3: (0.5, 4.5)})
#: Start of the route: middle of the square's bottom edge, heading along it.
START_POSE = (2.5, 1.3, 0.0)


def calibrate_model(*, preset: str = "create2", seed: int = 1, excitation_s: float = 180.0
                    ) -> MotionModel:
    """Calibrate the ARX model on the simulator (as
    ``tests/lti_motion/calibration/test_calibration_sim.py`` does)."""
    return calibrate_simulator(preset, seed=seed, plan=CalibrationPlan(
        seed=seed + 2, excitation_s=excitation_s)).arx


def rounded_square(*, center: tuple[float, float] = (2.5, 2.5), half_side_m: float = 1.2,
                   corner_radius_m: float = 0.5, step_m: float = 0.01) -> np.ndarray:
    """A closed, counter-clockwise rounded square as points ``(m, 2)`` about ``step_m`` apart.

    The first point is the middle of the bottom edge, ``(cx, cy - half_side_m)``.
    """
    a, r = half_side_m, corner_radius_m
    pts = []
    straight = 2.0 * (a - r)
    corners = ((a - r, -(a - r)), (a - r, a - r), (-(a - r), a - r), (-(a - r), -(a - r)))
    starts = ((-a + r, -a), (a, -a + r), (a - r, a), (-a, a - r))
    dirs = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))
    for i in range(4):
        n_s = max(2, round(straight / step_m))
        s = np.arange(n_s)[:, None] * (straight / n_s)
        pts.append(np.array(starts[i]) + s * np.array(dirs[i]))
        phi0 = -math.pi / 2 + i * math.pi / 2
        n_c = max(2, round(r * math.pi / 2 / step_m))
        phi = phi0 + np.arange(n_c) * (math.pi / 2 / n_c)
        pts.append(np.array(corners[i]) + r * np.stack([np.cos(phi), np.sin(phi)], axis=1))
    path = np.concatenate(pts)
    # start at the middle of the bottom edge
    start = int(np.argmin(np.hypot(path[:, 0], path[:, 1] + a)))
    return np.roll(path, -start, axis=0) + np.array(center)


def concat_logs(logs: Sequence[FrameLog]) -> FrameLog:
    """Join batch logs along time (axis 1)."""
    def cat(name: str) -> np.ndarray | None:
        parts = [getattr(lg, name) for lg in logs]
        return None if parts[0] is None else np.concatenate(parts, axis=1)

    return FrameLog(t_s=cat("t_s"), ticks=cat("ticks"), light_bump=cat("light_bump"),
                    bumps=cat("bumps"), cmd_m_s=cat("cmd_m_s"), valid=cat("valid"),
                    dt_s=logs[0].dt_s, true_pose=cat("true_pose"),
                    true_body_m_s=cat("true_body_m_s"), meta=dict(logs[0].meta),
                    yaw_rate_rad_s=cat("yaw_rate_rad_s"))


def drive_route(sim: Simulator, *, duration_s: float, rng: np.random.Generator,
                path: np.ndarray | None = None, speed_m_s: tuple[float, float] = (0.12, 0.3),
                hold_s: tuple[float, float] = (2.0, 6.0), lookahead_m: float = 0.35,
                control_every: int = 4, rest_s: float = 1.0) -> FrameLog:
    """Drive a batch simulator around a closed path with a pure-pursuit follower.

    Parameters
    ----------
    sim : Simulator
        A *batch* simulator (``n_robots=...``), robots placed on the path.
    duration_s : float
        Driving time after ``rest_s`` at rest [s].
    rng : numpy.random.Generator
        Draws each robot's speed profile: targets uniform in ``speed_m_s``,
        held for uniform ``hold_s``.
    path : ndarray, shape (m, 2), optional
        Closed path, points about 1 cm apart (default :func:`rounded_square`).
    lookahead_m : float
        Pure-pursuit look-ahead [m] (curvature ``2 sin(alpha) / L``).
    control_every : int
        Periods between steering updates (the simulator runs blocks).
    rest_s : float
        Time at rest before driving [s].

    Returns
    -------
    FrameLog
        Batch log ``(N, n, ...)``. Wheel commands stay in ``[0.02, 0.45]`` m/s.
    """
    path = rounded_square() if path is None else path
    n_robots, dt = sim.n, sim.dt_s
    b = sim.params[0].wheel_base_m
    n_drive = round(duration_s / dt)
    targets = np.empty((n_robots, n_drive))
    for i in range(n_robots):
        k = 0
        while k < n_drive:
            hold = max(1, round(rng.uniform(*hold_s) / dt))
            targets[i, k:k + hold] = rng.uniform(*speed_m_s)
            k += hold
    logs = [sim.run(np.zeros((n_robots, max(1, round(rest_s / dt)), 2)))]
    pose = logs[0].true_pose[:, -1]
    m = len(path)
    ds = float(np.mean(np.hypot(*np.diff(path, axis=0).T)))
    ahead = max(1, round(lookahead_m / ds))
    idx = np.argmin(np.hypot(path[None, :, 0] - pose[:, None, 0],
                             path[None, :, 1] - pose[:, None, 1]), axis=1)
    window = np.arange(-10, 60)
    for k0 in range(0, n_drive, control_every):
        cand = (idx[:, None] + window[None, :]) % m
        d = np.hypot(path[cand, 0] - pose[:, None, 0], path[cand, 1] - pose[:, None, 1])
        idx = cand[np.arange(n_robots), np.argmin(d, axis=1)]
        goal = path[(idx + ahead) % m]
        alpha = wrap_angle(np.arctan2(goal[:, 1] - pose[:, 1], goal[:, 0] - pose[:, 0])
                           - pose[:, 2])
        v = targets[:, k0]
        w = v * 2.0 * np.sin(alpha) / lookahead_m
        wheels = np.clip(np.stack([v - 0.5 * b * w, v + 0.5 * b * w], axis=1), 0.02, 0.45)
        steps = min(control_every, n_drive - k0)
        log = sim.run(np.repeat(wheels[:, None, :], steps, axis=1))
        logs.append(log)
        pose = log.true_pose[:, -1]
    return concat_logs(logs)


def odometry_poses(log: FrameLog, *, m_per_tick: float, wheel_base_m: float,
                   initial_pose: Sequence[float]) -> np.ndarray:
    """Poses ``(n, 3)`` from the encoders alone (calibrated scale, nominal wheel base)."""
    t = stream_clock(log.t_s, log.dt_s)
    speeds = body_speeds_from_ticks(log.ticks, t, m_per_tick=m_per_tick,
                                    wheel_base_m=wheel_base_m)
    return integrate_poses(speeds, np.diff(t), initial_pose=np.asarray(initial_pose, float))


@dataclass(frozen=True)
class FilterRun:
    """A filter run over one robot's log.

    Attributes
    ----------
    poses : ndarray, shape (n, 3)
        Estimated pose at each frame (frame 0: the start).
    pose_covs : ndarray, shape (n, 3, 3)
        Their covariances.
    encoder_nis, encoder_accepted : ndarray, shape (n,)
        NIS and acceptance of each frame's encoder update (frame 0: NaN, False).
    landmark_nis : ndarray
        NIS of every landmark update.
    stats : FilterStats
        Counts of fused and rejected readings.
    """

    poses: np.ndarray
    pose_covs: np.ndarray
    encoder_nis: np.ndarray
    encoder_accepted: np.ndarray
    landmark_nis: np.ndarray
    stats: FilterStats


def run_filter(model: MotionModel, log: FrameLog, *, initial_pose: Sequence[float],
               observations: RangeBearing | None = None, landmarks: LandmarkMap | None = None,
               pose_std: tuple[float, float, float] = (0.005, 0.005, 0.005),
               options: EKFOptions | None = None) -> FilterRun:
    """Run :class:`ModelEKF` over one robot's frames (and landmark observations).

    ``options`` are the filter's (:class:`~fusion.ekf.EKFOptions`: ``slip``,
    ``gate_probability`` ...); it keeps no update records.
    """
    ekf = ModelEKF(model, initial_pose=initial_pose, pose_std=pose_std,
                   initial_ticks=log.ticks[0], landmarks=landmarks,
                   options=replace(options or EKFOptions(), history=0))
    n = len(log.t_s)
    poses = np.empty((n, 3))
    covs = np.empty((n, 3, 3))
    enc_nis = np.full(n, np.nan)
    enc_ok = np.zeros(n, bool)
    lm_nis = []
    poses[0], covs[0] = ekf.x[:3], ekf.P[:3, :3]
    by_frame = observations.by_index() if observations is not None else {}
    none = RangeBearing.empty()
    cmd, ticks = log.cmd_m_s, log.ticks
    for k in range(1, n):
        ekf.predict(cmd[k])
        rec = ekf.update_encoders(ticks[k])
        enc_nis[k], enc_ok[k] = rec.nis, rec.accepted
        lm_nis += [r.nis for r in ekf.update_landmarks(by_frame.get(k, none))]
        poses[k] = ekf.x[:3]
        covs[k] = ekf.P[:3, :3]
    return FilterRun(poses, covs, enc_nis, enc_ok, np.array(lm_nis), ekf.stats)


def plot_run(path: Path, *, truth: np.ndarray, odometry: np.ndarray, run: FilterRun,
             dt_s: float, landmarks: LandmarkMap | None = None) -> Path:
    """Trajectories and position errors of truth, odometry and filter, as a PNG."""
    fig = Figure(figsize=(12, 5.5))     # no pyplot: no GUI backend, no global state
    ax, ax_err = fig.subplots(1, 2)
    ax.plot(truth[:, 0], truth[:, 1], "k-", lw=1.0, label="truth")
    ax.plot(odometry[:, 0], odometry[:, 1], "C3-", lw=0.8, label="encoders only")
    ax.plot(run.poses[:, 0], run.poses[:, 1], "C0-", lw=0.8, label="EKF")
    if landmarks is not None:
        xy = np.array([landmarks.position(k) for k in landmarks.ids])
        ax.plot(xy[:, 0], xy[:, 1], "k^", ms=8, label="landmarks")
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal", title="trajectories")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=4, fontsize=8)
    t = np.arange(len(truth)) * dt_s
    for est, style, name in ((odometry, "C3-", "encoders only"), (run.poses, "C0-", "EKF")):
        ax_err.plot(t, np.hypot(*(est[:, :2] - truth[:, :2]).T), style, lw=0.8, label=name)
    rejected = np.flatnonzero(~run.encoder_accepted[1:]) + 1
    ax_err.plot(t[rejected], np.zeros(len(rejected)), "k|", ms=8, label="encoder reading gated")
    ax_err.set_yscale("symlog", linthresh=0.01)
    ax_err.set(xlabel="time [s]", ylabel="position error [m]", title="position error")
    ax_err.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/ekf_plugin"))
    parser.add_argument("--duration-s", type=float, default=120.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--short", action="store_true",
                        help="smoke test: 60 s of calibration excitation")
    args = parser.parse_args(argv)
    model = calibrate_model(excitation_s=60.0 if args.short else 180.0)
    print(f"calibrated ARX model: {model.n_states} states, m_per_tick {model.m_per_tick:.6g}")
    d = args.duration_s
    faults = [Fault("encoder_spikes", t_s=1.0, rate_hz=0.5, wheel="right"),
              Fault("stuck_encoder", t_s=0.3 * d, duration_s=min(3.0, 0.1 * d), wheel="left")]
    sim = Simulator("create2", n_robots=1, seed=args.seed, room=Room.box(5.0, 5.0),
                    initial_pose=START_POSE, faults=faults)
    log = drive_route(sim, duration_s=d, rng=np.random.default_rng(args.seed)).robot(0)
    obs = synthetic_observations(log.true_pose, LANDMARKS, dt_s=log.dt_s,
                                 rng=np.random.default_rng(args.seed + 1000))
    run = run_filter(model, log, initial_pose=START_POSE, observations=obs, landmarks=LANDMARKS)
    odo = odometry_poses(log, m_per_tick=model.m_per_tick, wheel_base_m=model.wheel_base_m,
                         initial_pose=START_POSE)
    err_f = np.hypot(*(run.poses[:, :2] - log.true_pose[:, :2]).T)
    err_o = np.hypot(*(odo[:, :2] - log.true_pose[:, :2]).T)
    png = plot_run(args.out / "ekf_plugin.png", truth=log.true_pose, odometry=odo, run=run,
                   dt_s=log.dt_s, landmarks=LANDMARKS)
    print(f"{d:.0f} s drive: position RMS error EKF {np.sqrt(np.mean(err_f ** 2)):.3f} m, "
          f"encoders only {np.sqrt(np.mean(err_o ** 2)):.3f} m; final {err_f[-1]:.3f} m vs "
          f"{err_o[-1]:.3f} m")
    print(f"encoder readings gated: {run.stats.count('encoders', 'gated')}, landmark "
          f"observations fused: {run.stats.count('landmark', 'fused')}")
    print(f"wrote {png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
