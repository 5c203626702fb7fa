"""Calibrate from a ROS bag, replay against a reference, monitor, and look at the plots.

The steps of ``docs/guide_ros_bags.md`` on the library's public API:

1. record: ``ros2 bag record /cmd_vel /joint_states /odom /imu/data`` on the robot
   (and a reference pose topic, e.g. motion capture, for the replay). Without
   ``--bag``, the script records stand-ins on the simulator instead: a 3-minute
   random excitation and a 1-minute drive with its true poses as ``/ground_truth``,
   by a Create 2 carrying a MEMS gyro (``/imu/data``, ``sensor_msgs/Imu``);
2. calibrate: the ARX model from the excitation bag (commands against the speeds
   from the wheel angles);
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

from drivers.bags.reader import read_bag
from drivers.bags.to_log import bag_to_log
from drivers.bags.writer import BagAlarm, write_drive_bag, write_estimates_bag
from drivers.sim.config import Fault, Room, get_preset
from drivers.sim.simulator import Simulator
from fusion.ekf import ModelEKF
from fusion.ekf.ekf_options import EKFOptions
from fusion.monitoring import MonitoredFilter
from fusion.noise import GyroNoise
from lti_motion.calibration.manoeuvres import CalibrationPlan, speeds_from_log
from lti_motion.kinematics import body_from_wheel, integrate_poses
from lti_motion.metrics import ate_stats, fit_percent
from lti_motion.model.excitation import random_held_normal
from lti_motion.model.motion_model import MotionModel, fit_arx
from lti_motion.recordings.frames import FrameLog
from lti_motion.recordings.ticks import tick_deltas

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


def calibrate_from_bag(path: Path) -> tuple[MotionModel, FrameLog]:
    """The ARX model of the drive in a bag, and the drive (the nominal encoder scale)."""
    log = bag_to_log(read_bag(path), wheel_base_m=WHEEL_BASE_M)
    cmd_m_s, speeds = speeds_from_log(log, m_per_tick=log.meta["m_per_tick"],
                                      wheel_base_m=WHEEL_BASE_M)
    model = fit_arx([(cmd_m_s, speeds)], dt_s=log.dt_s, wheel_base_m=WHEEL_BASE_M,
                    m_per_tick=log.meta["m_per_tick"], dc_gain="wheel_servo")
    return model, log


def _gyro_readings(log: FrameLog) -> np.ndarray | None:
    """Each frame's Imu yaw rate [rad/s], NaN at lost frames (a new gyro window); None
    without an Imu."""
    if log.yaw_rate_rad_s is None:
        return None
    return np.where(log.valid, log.yaw_rate_rad_s, np.nan)


def _ekf_poses(model: MotionModel, log: FrameLog, start: np.ndarray,
               gyro: np.ndarray | None) -> np.ndarray:
    """The model's EKF over the frames: encoders, and the gyro's readings when given."""
    ekf = ModelEKF(model, initial_pose=start, pose_std=(0.005, 0.005, 0.005),
                   initial_ticks=log.ticks[0],
                   options=EKFOptions(history=0, gyro=None if gyro is None else GyroNoise()))
    poses = np.empty((len(log), 3))
    poses[0] = ekf.pose
    for k in range(1, len(log)):
        ekf.predict(log.cmd_m_s[k])
        if log.valid[k]:
            ekf.update_encoders(log.ticks[k])
        if gyro is not None:
            ekf.update_gyro(gyro[k])
        poses[k] = ekf.pose
    return poses


def replay(path: Path, model: MotionModel) -> tuple[FrameLog, dict[str, np.ndarray]]:
    """Encoder odometry and the model's EKF (and with an Imu, the EKF fusing its yaw rate)
    over a bag, from its first reference pose."""
    log = bag_to_log(read_bag(path), wheel_base_m=model.wheel_base_m, dt_s=model.dt_s)
    start = log.true_pose[0] if log.has_truth else np.zeros(3)
    rows = np.flatnonzero(log.valid)
    travel = tick_deltas(log.ticks[rows], axis=0) * model.m_per_tick
    odometry = integrate_poses(body_from_wheel(travel, wheel_base_m=model.wheel_base_m), 1.0,
                               initial_pose=start)
    held = np.searchsorted(rows, np.arange(len(log)), side="right") - 1
    poses = {"encoder odometry": odometry[held],
             "EKF, model and encoders": _ekf_poses(model, log, start, None)}
    gyro = _gyro_readings(log)
    if gyro is not None:
        poses["EKF, model, encoders and gyro"] = _ekf_poses(model, log, start, gyro)
    return log, poses


def monitor(path: Path, model: MotionModel, out_bag: Path) -> list[str]:
    """The EKF and the residual monitor over a bag; alarms with bag time into a new bag."""
    log = bag_to_log(read_bag(path), wheel_base_m=model.wheel_base_m, dt_s=model.dt_s)
    start_ns = log.meta["bag_start_ns"] + round(log.t_s[0] * 1e9)
    mf = MonitoredFilter(model, pose_std=(0.005, 0.005, 0.005),
                         ekf_options=EKFOptions(history=0, gyro=None if log.yaw_rate_rad_s is None
                                                else GyroNoise()))
    poses, covs = np.zeros((len(log), 3)), np.zeros((len(log), 3, 3))
    for k in range(len(log)):
        result = mf.step(log.frame(k))          # a lost frame's gyro reading is not used
        poses[k], covs[k] = result.pose, mf.ekf.P[:3, :3]
    alarms = [BagAlarm(start_ns + round(e.t_s * 1e9), f"lti_motion/{e.kind}",
                       f"{e.kind}: {e.test} statistic {e.statistic:.3g} > {e.threshold:.3g}",
                       (("onset_s", f"{e.onset_s:.3f}"),)) for e in mf.events]
    t_ns = log.meta["bag_start_ns"] + np.rint(log.t_s * 1e9).astype(np.int64)
    write_estimates_bag(out_bag, t_ns, poses, covs, alarms=alarms)
    return [f"{a.name} at bag time {a.t_ns // 10**9}.{a.t_ns % 10**9:09d}: {a.message}"
            for a in alarms]


def plot_fit(model: MotionModel, log: FrameLog, path: Path, *, seconds: float = 20.0) -> None:
    """Measured speeds of the calibration drive against the model's free run."""
    cmd_m_s, speeds = speeds_from_log(log, m_per_tick=model.m_per_tick,
                                      wheel_base_m=model.wheel_base_m)
    predicted = model.simulate(cmd_m_s)
    n = round(seconds / log.dt_s)
    fig = Figure(figsize=(10, 5))
    axes = fig.subplots(2, 1, sharex=True)
    for ax, j, unit in ((axes[0], 0, "v [m/s]"), (axes[1], 1, "w [rad/s]")):
        ax.plot(np.arange(n) * log.dt_s, speeds[:n, j], lw=0.8, label="wheel angles")
        ax.plot(np.arange(n) * log.dt_s, predicted[:n, j], lw=0.8, label="model, free run")
        ax.set(ylabel=unit)
        ax.legend(fontsize=8)
    axes[1].set(xlabel="time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_trajectories(log: FrameLog, poses: dict[str, np.ndarray], path: Path) -> None:
    """The estimates and the reference poses in the plane."""
    fig = Figure(figsize=(6, 6))
    ax = fig.subplots()
    if log.has_truth:
        ax.plot(log.true_pose[:, 0], log.true_pose[:, 1], "k-", lw=2, label="reference")
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
    model, cal_log = calibrate_from_bag(args.bag)
    cmd_m_s, speeds = speeds_from_log(cal_log, m_per_tick=model.m_per_tick,
                                      wheel_base_m=model.wheel_base_m)
    fit = fit_percent(speeds, model.simulate(cmd_m_s), axis=0)
    saved = model.save(args.out / "model_arx.json")
    print(f"calibrated: ARX order {model.orders['na']}, delay {model.orders['delay']}; "
          f"free-run fit v {fit[0]:.1f} %, w {fit[1]:.1f} %; saved {saved}")
    plot_fit(model, cal_log, args.out / "fit.png")
    if args.drive is not None:
        log, poses = replay(args.drive, model)
        for name, p in poses.items():
            if log.has_truth:
                ok = np.all(np.isfinite(log.true_pose), axis=1)
                err = ate_stats(log.true_pose[ok], p[ok])
                print(f"{name}: ATE rmse {err.rmse_m:.3f} m, max {err.max_m:.3f} m")
        plot_trajectories(log, poses, args.out / "trajectories.png")
        for line in monitor(args.drive, model, args.out / "estimates.bag"):
            print(line)
        print(f"wrote {args.out / 'estimates.bag'}, fit.png and trajectories.png to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
