"""A gyro through a ROS bag (docs/replay.md): ``replay --bag`` with its Imu, without, from memory.

The drive (``tests/lti_motion/app/test_bag_gyro.py``'s): the create2 simulator on
carpet (the ground turns about 5% short of the encoders) with a gyro (0.005
rad/s/sqrt(Hz), bias 0.006 rad/s), 5 s at rest, then 20 s of curves that keep
turning left (0.34 rad/s on average), 5% of frames lost after 6 s; drive seeds
``SEED0 .. SEED0 + N_RUNS - 1``. Each drive is written to a ROS 1 bag with
``/imu/data`` (:func:`drivers.bags.write_drive_bag`) and read back the way
``lti-motion replay --bag`` reads it (:func:`lti_motion.app.bag_commands.replay_source`
on the model's period); the ``ekf`` estimator runs on it with the Imu and with
no ``--gyro``, and on the in-memory log (the simulator's own readings, no bag).
One ARX model (``calibrate_simulator("create2", seed=4)``, 40 s of excitation). The
truth is read afterwards.

Figures (means over the runs): ``bag_gyro.heading_final_rad`` (|heading error| at
the end, with the bag's Imu; baseline the same bags with no ``--gyro``),
``bag_gyro.memory_gap_rad`` (largest |bag - in-memory| difference of that error:
what the bag and the resampling cost), ``bag_gyro.worse_runs`` (runs where the Imu
made the heading worse). The spread is printed.

Run ``python -m benchmarks bag_gyro --json out/bench-bag-gyro.json``.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.harness import Figure, benchmark
from drivers.bags.writer import write_drive_bag
from drivers.sim.calibration import calibrate_simulator
from drivers.sim.config import Fault, Room, get_preset
from drivers.sim.simulator import Simulator
from lti_motion.app.bag_commands import BagOptions, replay_source
from lti_motion.app.replay import estimate
from lti_motion.app.replay_sources import source_from_frame_log
from lti_motion.calibration.manoeuvres import CalibrationPlan
from lti_motion.kinematics import wrap_angle
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.frames import FrameLog

N_RUNS, SEED0 = 10, 21
DENSITY = 0.005                   # rad/s/sqrt(Hz)


def carpet_drive(seed: int, *, rest_s: float = 5.0, curves_s: float = 20.0,
                 wave_s: float = 10.0, lost_from_s: float = 6.0) -> FrameLog:
    """The module docstring's drive: ``rest_s`` at rest, then ``curves_s`` of curves turning
    left (the turn a sine of period ``wave_s`` [s]), 5% of frames lost from ``lost_from_s``."""
    robot = get_preset("create2").replace(floor="carpet", gyro_noise_density_rad_s_sqrt_hz=DENSITY,
                                          gyro_bias_rad_s=0.006)
    sim = Simulator(robot, seed=seed, room=Room.empty(), initial_pose=(0.0, 0.0, 0.0),
                    faults=[Fault("lost_frames", t_s=lost_from_s, probability=0.05)])
    k = np.arange(round(curves_s / sim.dt_s))
    turn = 0.04 + 0.04 * np.sin(k * sim.dt_s * 2 * np.pi / wave_s)
    cmd = np.concatenate([np.zeros((round(rest_s / sim.dt_s), 2)),
                          np.stack([0.2 - turn, 0.2 + turn], axis=1)])
    return sim.run(cmd)


def heading_errors(model: MotionModel, log: FrameLog, folder: Path) -> dict[str, float]:
    """Final |heading error| of the ekf: bag with Imu, bag without, in-memory log."""
    bag = write_drive_bag(folder / "drive.bag", log, gyro_noise_density_rad_s_sqrt_hz=DENSITY)
    out = {}
    for name, gyro in (("imu", True), ("no_gyro", False)):
        _, src = replay_source(bag, model, options=BagOptions(dt_s=model.dt_s, gyro=gyro))
        sources = {name: src}
        if gyro:
            sources["memory"] = source_from_frame_log(log, "memory")
        for key, src in sources.items():
            poses, _ = estimate(src, model, ["ekf"])
            out[key] = abs(float(wrap_angle(poses["ekf"][-1, 2] - src.truth[-1, 2])))
    return out


@benchmark("bag_gyro")
def bag_gyro() -> list[Figure]:
    model = calibrate_simulator("create2", seed=4,
                                plan=CalibrationPlan(seed=4, excitation_s=40.0)).arx
    runs: dict[str, list[float]] = {}
    for seed in range(SEED0, SEED0 + N_RUNS):
        with tempfile.TemporaryDirectory() as tmp:
            for key, value in heading_errors(model, carpet_drive(seed), Path(tmp)).items():
                runs.setdefault(key, []).append(value)
        print(f"  seed {seed}: " + ", ".join(f"{k} {v[-1]:.4f} rad" for k, v in runs.items()),
              file=sys.stderr)
    for key, values in runs.items():
        print(f"  bag_gyro {key:8s} mean {statistics.fmean(values):.4f}  sd "
              f"{statistics.stdev(values):.4f}  max {max(values):.4f} rad ({len(values)} runs)",
              file=sys.stderr)
    gap = max(abs(a - b) for a, b in zip(runs["imu"], runs["memory"], strict=True))
    worse = sum(a > b for a, b in zip(runs["imu"], runs["no_gyro"], strict=True))
    return [Figure("bag_gyro.heading_final_rad", statistics.fmean(runs["imu"]), "rad",
                   better="lower", baseline="without --gyro, same bags",
                   baseline_value=statistics.fmean(runs["no_gyro"])),
            Figure("bag_gyro.memory_gap_rad", gap, "rad", better="lower"),
            Figure("bag_gyro.worse_runs", float(worse), "runs", target=0.0, better="lower")]
