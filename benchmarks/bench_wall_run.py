"""Issue 17 item 4: the wheels' diameter ratio without any external reference, from two
straight runs beside a wall (:mod:`lti_motion.calibration.wall_run`, driven by
:func:`lti_motion.calibration.drive_wall_run`).

The robot of the intrinsics benchmark (a Create 2 with a 1% larger left wheel and a 10%
weaker right motor, on tile) starts 0.5 m in front of a straight white wall, facing it
within +-3 degrees (drawn from the seed). It knows only what it measured alone: the
rotation manoeuvre's symmetric encoder scale on that floor
(:func:`benchmarks.bench_intrinsics.rotation_scale`) and the spec's wheel base; the
estimate reads its counts and light bumps.

Figures (the error is ``|estimated / true - 1|`` [%] of the diameter ratio ``k_L / k_R``;
the truth is :func:`benchmarks.bench_intrinsics.straight_line_truth`, each wheel's
contact-point travel per tick over the drive's steady straight periods, scoring only):

``intrinsics.no_reference_ratio_error_pct``
    Worst over 20 seeds. Baseline: the rotation-calibrated symmetric intrinsics' worst
    error over the same drives (they say 1).
``intrinsics.no_reference_ratio_error_mean_pct`` / ``..._std_pct``
    Mean and standard deviation of the signed error over the same seeds.
``intrinsics.no_reference_ratio_error_<case>_pct``
    Worst over 10 seeds of each case of :data:`CASES`: the mirrored robot (the *right*
    wheel 1% larger, the right motor weaker; it curves towards a wall on its left, stops
    its first run and drives the manoeuvre with the wall on its right), runs of other
    lengths, darker walls, other floors, and the spec's intrinsics instead of the
    rotation manoeuvre's.

:func:`table` prints mean, standard deviation and worst of every case (the table of
``docs/intrinsics.md``); :func:`pty_table` the same drive through the serial driver over a
pseudo-terminal.
"""

from __future__ import annotations

import functools

import numpy as np

from benchmarks.bench_intrinsics import (
    FLOOR,
    asymmetric_robot,
    rotation_scale,
    straight_line_truth,
)
from benchmarks.harness import Figure, benchmark
from drivers.sim.config import RobotParams, Room
from drivers.sim.simulator import Simulator
from lti_motion.calibration.wall_run import WallRunCalibration, calibrate_wall_run
from lti_motion.calibration.wall_run_drive import drive_wall_run, wall_passes
from lti_motion.intrinsics import OdometryIntrinsics

SEEDS = range(20)
CASE_SEEDS = range(10)
MIRRORED = (0.0, 0.01)
#: name -> options of :func:`ratio_errors_pct` (10 seeds each).
CASES = {
    "mirrored": {"wheel_diameter_errors": MIRRORED},
    "run_1m": {"run_m": 1.0},
    "run_1.5m": {"run_m": 1.5},
    "run_3m": {"run_m": 3.0},
    "reflectance_0.6": {"reflectance": 0.6},
    "reflectance_0.3": {"reflectance": 0.3},
    "mirrored_reflectance_0.3": {"wheel_diameter_errors": MIRRORED, "reflectance": 0.3},
    "hard_floor": {"floor": "hard"},
    "carpet": {"floor": "carpet"},
    "spec_intrinsics": {"spec": True},
}


@functools.cache
def known_intrinsics(params: RobotParams, floor: str, *, spec: bool = False
                     ) -> OdometryIntrinsics:
    """What the robot knows before the wall run: the rotation manoeuvre's symmetric scale
    on ``floor`` (or the spec's) and the spec's wheel base."""
    scale = params.m_per_tick if spec else rotation_scale(params, floor=floor)
    return OdometryIntrinsics.symmetric(m_per_tick=scale, wheel_base_m=params.wheel_base_m)


def wall_run_trial(params: RobotParams, seed: int, *, run_m: float = 2.0,
                   reflectance: float = 1.0, floor: str = FLOOR, spec: bool = False
                   ) -> tuple[WallRunCalibration, float]:
    """Drive and calibrate once; the estimate and the true ratio (for scoring only)."""
    heading = -np.pi / 2 + np.random.default_rng([seed, 0x3A11]).uniform(-1, 1) * np.deg2rad(3)
    room = Room(np.array([[-6.0, 0.0, 6.0, 0.0, reflectance]]))
    sim = Simulator(params, seed=seed, floor=floor, room=room, initial_pose=(2.5, 0.5, heading))
    known = known_intrinsics(params, floor, spec=spec)
    drive = drive_wall_run(sim, known, run_m=run_m)
    cal = calibrate_wall_run(wall_passes(drive, known), known, wall_side=drive.wall_side)
    truth = straight_line_truth(params, drive.log, drive.log.cmd_m_s)
    return cal, float(truth[0] / truth[1])


def ratio_errors_pct(seeds: range, *, wheel_diameter_errors: tuple[float, float] | None = None,
                     **options: object) -> tuple[np.ndarray, np.ndarray]:
    """Signed relative errors [%] of the estimated diameter ratio and the true ratios, one
    per seed, for the benchmark's robot (or one with other ``wheel_diameter_errors``)."""
    params = asymmetric_robot()
    if wheel_diameter_errors is not None:
        params = params.replace(wheel_diameter_errors=wheel_diameter_errors)
    out = []
    for seed in seeds:
        cal, truth = wall_run_trial(params, seed, **options)
        out.append((100.0 * (cal.diameter_ratio / truth - 1.0), truth))
    return np.array(out).T


def table() -> None:
    """Print mean, standard deviation and worst of the signed error of every case."""
    rows = {"default (20 seeds)": (SEEDS, {})} | {k: (CASE_SEEDS, v) for k, v in CASES.items()}
    for name, (seeds, options) in rows.items():
        err = ratio_errors_pct(seeds, **options)[0]
        print(f"{name:28s} mean {err.mean():+.3f}%  sd {err.std():.3f}%  "
              f"worst {np.abs(err).max():.3f}%")


def pty_table(seeds: range = range(10), *, speed: float = 10.0) -> None:
    """Print, per seed, the ratio error of the wall run driven through the serial driver
    over a pseudo-terminal against the virtual Roomba (``speed`` x real time), next to the
    same seed driven on the simulator directly (:func:`wall_run_trial`), and both summaries.

    The truth of the pty drive is the emulator's applied commands run again through a
    simulator of the same seed (bit for bit the streamed values; scoring only).
    """
    import math

    from drivers.roomba.driver import Roomba, RoombaOptions
    from drivers.roomba.virtual import VirtualRoomba, VirtualRoombaOptions

    params = asymmetric_robot()
    known = known_intrinsics(params, FLOOR)
    errors: dict[str, list[float]] = {"pty": [], "direct": []}
    for seed in seeds:
        heading = (-np.pi / 2
                   + np.random.default_rng([seed, 0x3A11]).uniform(-1, 1) * np.deg2rad(3))
        scene = {"seed": seed, "floor": FLOOR, "initial_pose": (2.5, 0.5, heading),
                 "room": Room(np.array([[-6.0, 0.0, 6.0, 0.0, 1.0]]))}
        virtual = VirtualRoomba(params, **scene, options=VirtualRoombaOptions(speed=speed))
        options = RoombaOptions(clock_rate=speed, open_timeout_s=3.0,
                                latency_tolerance_s=math.inf, write_timeout_s=2.0)
        with virtual, Roomba(virtual.device_path, options=options) as robot:
            drive = drive_wall_run(robot, known)
        cal = calibrate_wall_run(wall_passes(drive, known), known, wall_side=drive.wall_side)
        replay = Simulator(params, **scene).run(virtual.applied_commands_m_s)
        truth = straight_line_truth(params, replay, replay.cmd_m_s)
        errors["pty"].append(100.0 * (cal.diameter_ratio * truth[1] / truth[0] - 1.0))
        direct, direct_truth = wall_run_trial(params, seed)
        errors["direct"].append(100.0 * (direct.diameter_ratio / direct_truth - 1.0))
        print(f"seed {seed}: pty {errors['pty'][-1]:+.3f}% (overruns "
              f"{virtual.stats.overruns}), direct {errors['direct'][-1]:+.3f}%")
    for name, values in errors.items():
        err = np.array(values)
        print(f"{name:6s} mean {err.mean():+.3f}%  sd {err.std():.3f}%  "
              f"worst {np.abs(err).max():.3f}% over {len(err)} seeds")


@benchmark("wall_run")
def run() -> list[Figure]:
    errors, truths = ratio_errors_pct(SEEDS)
    before = float(np.max(np.abs(100.0 * (1.0 / truths - 1.0))))
    figures = [
        Figure("intrinsics.no_reference_ratio_error_pct", float(np.abs(errors).max()), "%",
               target=0.2, better="lower", baseline="rotation-calibrated intrinsics (ratio 1)",
               baseline_value=before),
        Figure("intrinsics.no_reference_ratio_error_mean_pct", float(errors.mean()), "%",
               better="lower"),
        Figure("intrinsics.no_reference_ratio_error_std_pct", float(errors.std()), "%",
               better="lower"),
    ]
    for name, options in CASES.items():
        worst = np.abs(ratio_errors_pct(CASE_SEEDS, **options)[0]).max()
        figures.append(Figure(f"intrinsics.no_reference_ratio_error_{name}_pct", float(worst),
                              "%", better="lower"))
    return figures
