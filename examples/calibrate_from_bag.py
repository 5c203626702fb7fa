"""Calibrate from a ROS bag, replay against a reference, monitor, and look at the plots.

The steps of ``docs/guide_ros_bags.md`` on the library's public API:

1. record: ``ros2 bag record /cmd_vel /joint_states /odom /imu/data`` on the robot
   (and a reference pose topic, e.g. motion capture, for the replay). Without
   ``--bag``, the script records stand-ins on the simulator instead: a 3-minute
   random excitation and a 1-minute drive with its true poses as ``/ground_truth``,
   by a Create 2 carrying a MEMS gyro (``/imu/data``, ``sensor_msgs/Imu``);
2. calibrate: the bag read once as one ``Recording`` (wheel angles, twist commands),
   put on the model's grid once, the ARX model fitted on that grid (commands against
   the speeds from the wheel angles), the same grid plotted;
3. replay: encoder odometry and the model's EKF on the second bag (and, when it has
   an Imu, the EKF that also fuses its yaw rate), their error against its
   reference poses;
4. monitor: the EKF (with the Imu's yaw rate, when there is one) and the residual
   monitor over the second bag, each alarm with its bag time; the estimates
   (``nav_msgs/Odometry`` with covariance) and alarms
   (``diagnostic_msgs/DiagnosticArray``) written into a new bag;
5. plots: ``fit.png`` (measured speeds against the model's free run) and
   ``trajectories.png``.

Run: ``python examples/calibrate_from_bag.py --out out/bag_example`` (the simulator), or
``python examples/calibrate_from_bag.py --bag CAL_BAG --drive DRIVE_BAG --out OUT``.
``lti-motion calibrate / replay / monitor --bag`` do the same from the command line.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from drivers.bags import (
    CREATE2_TICKS_PER_RAD,
    CREATE2_WHEEL_RADIUS_M,
    BagAlarm,
    bag_grid,
    read_bag,
    write_drive_bag,
    write_estimates_bag,
)
from drivers.sim import Fault, Room, Simulator, get_preset
from fusion.ekf import ModelEKF
from fusion.monitoring import MonitoredFilter
from fusion.noise import GyroNoise
from lti_motion.calibration import CalibrationPlan, calibrate_recording
from lti_motion.kinematics import body_from_wheel, integrate_poses, wheel_from_body
from lti_motion.metrics import ate_stats, fit_percent
from lti_motion.model import MotionModel, random_held_normal
from lti_motion.recordings import GridSignals, frame_stamps, poses_at, snap_period_s

WHEEL_BASE_M = 0.235                   # the Create 2's; give your robot's
GYRO_DENSITY = 0.005                   # the stand-ins' gyro: a MEMS one [rad/s/sqrt(Hz)]


def record_stand_ins(folder: Path, *, seed: int = 0, excitation_s: float = 180.0,
                     drive_s: float = 60.0) -> tuple[Path, Path]:
    """Two simulator drives on open floor (no walls to hit), written as a robot running ROS
    records them (ROS 2, MCAP).

    The second has encoder spikes from 70 % of its length on, for the monitor to find.
    """
    plan = CalibrationPlan()
    rng = np.random.default_rng(seed)
    excitation = random_held_normal(n=round(excitation_s / 0.015), dt_s=0.015, rng=rng,
                                    std_m_s=plan.excitation_std_m_s, hold_s=plan.hold_s,
                                    correlation=plan.excitation_correlation)
    drive = random_held_normal(n=round(drive_s / 0.015), dt_s=0.015, rng=rng, std_m_s=0.1,
                               mean_m_s=0.15, hold_s=(1.0, 3.0), correlation=0.8)
    lost = Fault("lost_frames", t_s=0.0, probability=0.02)
    spikes = Fault("encoder_spikes", t_s=0.7 * drive_s, duration_s=1.0, rate_hz=20.0)
    room = Room.empty()
    # a gyro changes none of the simulator's other outputs (its noise has its own stream)
    robot = get_preset("create2").replace(gyro_noise_density_rad_s_sqrt_hz=GYRO_DENSITY,
                                          gyro_bias_rad_s=0.004)
    cal = write_drive_bag(folder / "calibration_drive", Simulator(
        robot, seed=seed, room=room, faults=[lost]).run(excitation),
        gyro_noise_density_rad_s_sqrt_hz=GYRO_DENSITY)
    ref = write_drive_bag(folder / "reference_drive", Simulator(
        robot, seed=seed + 1, room=room, faults=[lost, spikes]).run(drive),
        gyro_noise_density_rad_s_sqrt_hz=GYRO_DENSITY)
    return cal, ref


def calibrate_from_bag(path: Path) -> tuple[MotionModel, GridSignals]:
    """The ARX model of the drive in a bag, and the drive on its grid (the nominal encoder
    scale: a bag holds no rotation in place beside a wall)."""
    rec = read_bag(path, imu=False, truth=False)
    grid = bag_grid(rec, wheel_base_m=WHEEL_BASE_M, wheel_radius_m=CREATE2_WHEEL_RADIUS_M,
                    encoders="commanded")                    # a Create 2's encoders
    cal = calibrate_recording(rec, wheel_base_m=WHEEL_BASE_M, grid=grid,
                              m_per_tick=CREATE2_WHEEL_RADIUS_M / CREATE2_TICKS_PER_RAD,
                              scale_from="the nominal wheel radius / ticks per radian",
                              dt_s=snap_period_s(grid.period_s))
    return cal.model, grid


class Frames:
    """A bag's drive on the model's grid as the robot's stream would give it: frame ``k``
    closes period ``k`` (0 .. P), its counts the wheels' travel in the model's ticks."""

    def __init__(self, path: Path, model: MotionModel) -> None:
        rec = read_bag(path, dt_s=model.dt_s)
        grid = bag_grid(rec, wheel_base_m=model.wheel_base_m,
                        wheel_radius_m=CREATE2_WHEEL_RADIUS_M)
        clock = grid.assignment.clock
        self.t_s = clock.times_s(np.arange(len(grid.closed))) + clock.latency_median_s
        self.start_ns = rec.source.start_ns
        travel = np.cumsum(wheel_from_body(grid.speeds, wheel_base_m=model.wheel_base_m)
                           * grid.period_s, axis=0)
        self.ticks = np.vstack([np.zeros((1, 2), np.int64),
                                np.rint(travel / model.m_per_tick).astype(np.int64)])
        self.cmd_m_s = np.vstack([grid.cmd_m_s[:1], grid.cmd_m_s])
        self.valid = grid.closed
        self.true_pose = (None if rec.true_pose is None else poses_at(
            rec.true_pose, frame_stamps(rec, grid.assignment), max_gap_s=0.25))
        self.yaw_rate_rad_s = (None if grid.yaw_rate_rad_s is None else np.where(
            self.valid, np.concatenate([[np.nan], grid.yaw_rate_rad_s]), np.nan))

    def __len__(self) -> int:
        return len(self.t_s)


def _ekf_poses(model: MotionModel, frames: Frames, start: np.ndarray,
               gyro: np.ndarray | None) -> np.ndarray:
    """The model's EKF over the frames: encoders, and the gyro's readings when given."""
    ekf = ModelEKF(model, initial_pose=start, pose_std=(0.005, 0.005, 0.005),
                   initial_ticks=frames.ticks[0], history=0, counter_bits=64,
                   gyro=None if gyro is None else GyroNoise())
    poses = np.empty((len(frames), 3))
    poses[0] = ekf.pose
    for k in range(1, len(frames)):
        ekf.predict(frames.cmd_m_s[k])
        if frames.valid[k]:
            ekf.update_encoders(frames.ticks[k])
        if gyro is not None:
            ekf.update_gyro(gyro[k])
        poses[k] = ekf.pose
    return poses


def replay(path: Path, model: MotionModel) -> tuple[Frames, dict[str, np.ndarray]]:
    """Encoder odometry and the model's EKF (and with an Imu, the EKF fusing its yaw rate)
    over a bag, from its first reference pose."""
    frames = Frames(path, model)
    start = frames.true_pose[0] if frames.true_pose is not None else np.zeros(3)
    travel = np.diff(frames.ticks, axis=0) * model.m_per_tick       # each period's [m]
    odometry = integrate_poses(body_from_wheel(travel, wheel_base_m=model.wheel_base_m), 1.0,
                               initial_pose=start)
    poses = {"encoder odometry": odometry,
             "EKF, model and encoders": _ekf_poses(model, frames, start, None)}
    if frames.yaw_rate_rad_s is not None:
        poses["EKF, model, encoders and gyro"] = _ekf_poses(model, frames, start,
                                                           frames.yaw_rate_rad_s)
    return frames, poses


def monitor(path: Path, model: MotionModel, out_bag: Path) -> list[str]:
    """The EKF and the residual monitor over a bag; alarms with bag time into a new bag."""
    frames = Frames(path, model)
    start_ns = frames.start_ns + round(frames.t_s[0] * 1e9)
    gyro = frames.yaw_rate_rad_s
    mf = MonitoredFilter(model, pose_std=(0.005, 0.005, 0.005), counter_bits=64,
                         gyro=None if gyro is None else GyroNoise())
    poses, covs = np.zeros((len(frames), 3)), np.zeros((len(frames), 3, 3))
    for k in range(len(frames)):
        result = mf.step(frames.ticks[k], frames.cmd_m_s[k], valid=bool(frames.valid[k]),
                         yaw_rate_rad_s=None if gyro is None else float(gyro[k]))
        poses[k], covs[k] = result.pose, mf.ekf.P[:3, :3]
    alarms = [BagAlarm(start_ns + round(e.t_s * 1e9), f"lti_motion/{e.kind}",
                       f"{e.kind}: {e.test} statistic {e.statistic:.3g} > {e.threshold:.3g}",
                       (("onset_s", f"{e.onset_s:.3f}"),)) for e in mf.events]
    t_ns = frames.start_ns + np.rint(frames.t_s * 1e9).astype(np.int64)
    write_estimates_bag(out_bag, t_ns, poses, covs, alarms=alarms)
    return [f"{a.name} at bag time {a.t_ns // 10**9}.{a.t_ns % 10**9:09d}: {a.message}"
            for a in alarms]


def plot_fit(model: MotionModel, grid: GridSignals, path: Path, *,
             seconds: float = 20.0) -> None:
    """Measured speeds of the calibration drive against the model's free run."""
    speeds = grid.speeds
    predicted = model.simulate(grid.cmd_m_s)
    n = round(seconds / model.dt_s)
    fig = Figure(figsize=(10, 5))
    axes = fig.subplots(2, 1, sharex=True)
    for ax, j, unit in ((axes[0], 0, "v [m/s]"), (axes[1], 1, "w [rad/s]")):
        ax.plot(np.arange(n) * model.dt_s, speeds[:n, j], lw=0.8, label="wheel angles")
        ax.plot(np.arange(n) * model.dt_s, predicted[:n, j], lw=0.8, label="model, free run")
        ax.set(ylabel=unit)
        ax.legend(fontsize=8)
    axes[1].set(xlabel="time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_trajectories(frames: Frames, poses: dict[str, np.ndarray], path: Path) -> None:
    """The estimates and the reference poses in the plane."""
    fig = Figure(figsize=(6, 6))
    ax = fig.subplots()
    if frames.true_pose is not None:
        ax.plot(frames.true_pose[:, 0], frames.true_pose[:, 1], "k-", lw=2, label="reference")
    for name, p in poses.items():
        ax.plot(p[:, 0], p[:, 1], lw=1, label=name)
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bag", type=Path, help="calibration bag (default: simulator)")
    parser.add_argument("--drive", type=Path, help="bag to replay and monitor")
    parser.add_argument("--out", type=Path, default=Path("out/bag_example"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--excitation-s", type=float, default=180.0)
    parser.add_argument("--drive-s", type=float, default=60.0)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.bag is None:
        args.bag, args.drive = record_stand_ins(args.out, seed=args.seed,
                                                excitation_s=args.excitation_s,
                                                drive_s=args.drive_s)
        print(f"recorded stand-ins on the simulator: {args.bag}, {args.drive}")
    model, grid = calibrate_from_bag(args.bag)           # the grid computed once
    fit = fit_percent(grid.speeds, model.simulate(grid.cmd_m_s), axis=0)
    saved = model.save(args.out / "model_arx.json")
    print(f"calibrated: ARX order {model.orders['na']}, delay {model.orders['delay']}; "
          f"free-run fit v {fit[0]:.1f} %, w {fit[1]:.1f} %; saved {saved}")
    plot_fit(model, grid, args.out / "fit.png")
    if args.drive is not None:
        frames, poses = replay(args.drive, model)
        for name, p in poses.items():
            if frames.true_pose is not None:
                ok = np.all(np.isfinite(frames.true_pose), axis=1)
                err = ate_stats(frames.true_pose[ok], p[ok])
                print(f"{name}: ATE rmse {err.rmse_m:.3f} m, max {err.max_m:.3f} m")
        plot_trajectories(frames, poses, args.out / "trajectories.png")
        for line in monitor(args.drive, model, args.out / "estimates.bag"):
            print(line)
        print(f"wrote {args.out / 'estimates.bag'}, fit.png and trajectories.png to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
