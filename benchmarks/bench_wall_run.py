"""Issue 17 item 4: the wheels' diameter ratio without any external reference, from two
straight runs beside a wall (:mod:`lti_motion.wall_run`, driven by
:func:`drivers.sim.wall_run.drive_wall_run`).

The robot of the intrinsics benchmark (a Create 2 with a 1% larger left wheel and a 10%
weaker right motor, on tile) starts 0.5 m in front of a straight white wall, facing it
within +-3 degrees (drawn from the seed). It knows only its nominal intrinsics (the
spec's metres per tick and wheel base); the estimate reads its counts and light bumps.

Figures:

``intrinsics.no_reference_ratio_error_pct``
    Worst over 20 seeds of ``|estimated / true - 1|`` [%] of the diameter ratio ``k_L / k_R``;
    the truth is :func:`benchmarks.bench_intrinsics.straight_line_truth` (each wheel's
    contact-point travel per tick over the drive's steady straight periods, scoring only).
    Baseline: the nominal intrinsics' worst ratio error over the same seeds (they say 1.0).
``intrinsics.no_reference_ratio_error_mean_pct`` / ``..._std_pct``
    Mean and standard deviation of the signed error over the same seeds.
``intrinsics.no_reference_ratio_error_mirrored_pct``
    Worst over 10 seeds for the mirrored robot (the *right* wheel 1% larger, the right motor
    10% weaker): it curves towards a wall on its left, stops its first run and drives the
    manoeuvre with the wall on its right.
``intrinsics.no_reference_ratio_error_run_<L>m_pct``
    Worst over 10 seeds for runs of ``L`` m (the default is 2 m).
``intrinsics.no_reference_ratio_error_reflectance_<r>_pct``
    Worst over 10 seeds beside a wall of reflectance ``r`` (white = 1).
"""

from __future__ import annotations

import numpy as np

from benchmarks.bench_intrinsics import FLOOR, asymmetric_robot, straight_line_truth
from benchmarks.harness import Figure, benchmark
from drivers.sim.config import RobotParams, Room
from drivers.sim.simulator import Simulator
from drivers.sim.wall_run import drive_wall_run, wall_passes
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.wall_run import WallRunCalibration, calibrate_wall_run

SEEDS = range(20)
SWEEP_SEEDS = range(10)
RUN_LENGTHS_M = (1.0, 1.5, 3.0)
REFLECTANCES = (0.3, 0.6)


def wall_run_trial(params: RobotParams, seed: int, *, run_m: float = 2.0,
                   reflectance: float = 1.0) -> tuple[WallRunCalibration, float]:
    """Drive and calibrate once; the estimate and the true ratio (for scoring only)."""
    heading = -np.pi / 2 + np.random.default_rng([seed, 0x3A11]).uniform(-1, 1) * np.deg2rad(3)
    room = Room(np.array([[-6.0, 0.0, 6.0, 0.0, reflectance]]))
    sim = Simulator(params, seed=seed, floor=FLOOR, room=room, initial_pose=(2.5, 0.5, heading))
    nominal = OdometryIntrinsics.symmetric(m_per_tick=params.m_per_tick,
                                           wheel_base_m=params.wheel_base_m)
    drive = drive_wall_run(sim, nominal, run_m=run_m)
    cal = calibrate_wall_run(wall_passes(drive, nominal), nominal, wall_side=drive.wall_side)
    truth = straight_line_truth(params, drive.log, drive.log.cmd_m_s)
    return cal, float(truth[0] / truth[1])


def ratio_errors_pct(params: RobotParams, seeds: range, **options: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Signed relative errors [%] of the estimated diameter ratio and the true ratios, one
    per seed."""
    out = []
    for seed in seeds:
        cal, truth = wall_run_trial(params, seed, **options)
        out.append((100.0 * (cal.diameter_ratio / truth - 1.0), truth))
    return np.array(out).T


@benchmark("wall_run")
def run() -> list[Figure]:
    params = asymmetric_robot()
    errors, truths = ratio_errors_pct(params, SEEDS)
    nominal = float(np.max(np.abs(100.0 * (1.0 / truths - 1.0))))
    figures = [
        Figure("intrinsics.no_reference_ratio_error_pct", float(np.abs(errors).max()), "%",
               target=0.2, better="lower", baseline="nominal intrinsics (ratio 1)",
               baseline_value=nominal),
        Figure("intrinsics.no_reference_ratio_error_mean_pct", float(errors.mean()), "%",
               better="lower"),
        Figure("intrinsics.no_reference_ratio_error_std_pct", float(errors.std()), "%",
               better="lower"),
    ]
    mirrored = params.replace(wheel_diameter_errors=(0.0, 0.01))
    worst = np.abs(ratio_errors_pct(mirrored, SWEEP_SEEDS)[0]).max()
    figures.append(Figure("intrinsics.no_reference_ratio_error_mirrored_pct", float(worst), "%",
                          better="lower"))
    for run_m in RUN_LENGTHS_M:
        worst = np.abs(ratio_errors_pct(params, SWEEP_SEEDS, run_m=run_m)[0]).max()
        figures.append(Figure(f"intrinsics.no_reference_ratio_error_run_{run_m:g}m_pct",
                              float(worst), "%", better="lower"))
    for refl in REFLECTANCES:
        worst = np.abs(ratio_errors_pct(params, SWEEP_SEEDS, reflectance=refl)[0]).max()
        figures.append(Figure(f"intrinsics.no_reference_ratio_error_reflectance_{refl:g}_pct",
                              float(worst), "%", better="lower"))
    return figures
