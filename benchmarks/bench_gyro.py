"""A yaw-rate gyro in the model EKF (docs/ekf.md): heading and position, encoders alone and with it.

``examples/ekf_plugin.py``'s rounded-square route in a 5 m room, no landmarks, 60 s
after a rest (10 s, or 1 s); the simulated Create 2 with a MEMS-like gyro (noise
density 0.005 rad/s/sqrt(Hz), i.e. 0.041 rad/s per 15 ms reading) and a constant bias,
on the hard floor, on carpet (ground turns about 5% short of the encoders), and with
a 0.5% larger left wheel, and with the scale priors of calibrated intrinsics
(``SCENARIOS``, ``CALIBRATED``). One ARX calibration (the example's, seed 1);
drive seeds ``SEED0 .. SEED0 + N_RUNS - 1`` (simulator and route, one batch per
scenario; ``BENCH_GYRO_SEED0`` and ``BENCH_GYRO_RUNS`` in the environment change
them, e.g. 310 and 20 for the held-out seeds). One scenario stops three times
(``stops``): the drive in four legs, 3 s at rest before each but the first. Each
drive is filtered three times from the same frames: ModelEKF with encoder counts
only, with ``update_gyro`` of every frame (``GyroNoise()`` defaults: bias prior 0.01
rad/s, the zero-angular-rate update at rest), and with the gyro but every window the
heading update (``rest_update=False``, ``gyro.<scenario>.window_only_heading_final_rad``).
The filters read commands, counts and the gyro; the truth is read afterwards.

Figures, per scenario (``gyro.<scenario>.<what>``), means over the runs:
``heading_final_rad`` (|error| at the end), ``heading_rms_rad`` (over the drive),
``position_final_m`` (end-point error), ``heading_nees`` (time average of the
heading's NEES, chi-square(1) for a consistent filter: 1), ``heading_nees_final``
(the NEES at the end, averaged over the runs: chi-square(N) / N for N consistent
runs, 95% interval [0.32, 2.05] for 10, [0.48, 1.71] for 20), ``worse_runs`` (runs whose
final heading error with the gyro exceeds the encoders-only one by more than 3 mrad),
``bias_error_rad_s`` (final bias estimate minus the simulator's). The baseline of each
is the encoders-only filter on the same drives; the printed table gives the spread.

Run ``python -m benchmarks gyro --json out/bench-gyro.json``.
"""

from __future__ import annotations

import dataclasses
import os
import statistics
import sys

import numpy as np

from benchmarks.harness import Figure, benchmark, load_example
from drivers.sim.config import Fault, Room, get_preset
from drivers.sim.simulator import Simulator
from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.model_ekf import ModelEKF
from fusion.noise import GyroNoise, ScaleErrors
from lti_motion.kinematics import wrap_angle
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.frames import FrameLog

N_RUNS = int(os.environ.get("BENCH_GYRO_RUNS", "10"))
SEED0 = int(os.environ.get("BENCH_GYRO_SEED0", "300"))
DURATION_S, REST_S, STOP_S = 60.0, 1.0, 3.0
DENSITY = 0.005                   # rad/s/sqrt(Hz)
START = (2.5, 1.3, 0.0)
WORSE_RAD = 0.003


def gyro_drives(example, *, floor: str, bias_rad_s: float, seed0: int = SEED0,
                n_runs: int = N_RUNS, duration_s: float = DURATION_S, rest_s: float = REST_S,
                faults: tuple[Fault, ...] = (), stops: int = 0) -> FrameLog:
    """The route driven by ``n_runs`` robots with a gyro (a batch log); with ``stops``, in
    ``stops + 1`` legs of equal time with ``STOP_S`` at rest before each but the first."""
    robot = get_preset("create2").replace(gyro_noise_density_rad_s_sqrt_hz=DENSITY,
                                          gyro_bias_rad_s=bias_rad_s, floor=floor)
    sim = Simulator(robot, n_robots=n_runs, seed=seed0, room=Room.box(5.0, 5.0),
                    initial_pose=START, faults=faults)
    rng = np.random.default_rng(seed0)
    legs = [example.drive_route(sim, duration_s=duration_s / (stops + 1), rng=rng,
                                rest_s=rest_s if i == 0 else STOP_S) for i in range(stops + 1)]
    return legs[0] if stops == 0 else example.concat_logs(legs)


def filter_run(model: MotionModel, log: FrameLog, *, gyro: GyroNoise | None,
               scales: ScaleErrors | None = None) -> dict[str, float | np.ndarray]:
    """One filter over one robot's frames: poses, heading variances, final bias."""
    ekf = ModelEKF(model, initial_pose=START, pose_std=(0.005,) * 3,
                   initial_ticks=log.ticks[0],
                   options=EKFOptions(history=0, gyro=gyro, counter_bits=log.counter_bits,
                                      scales=scales))
    n = len(log.t_s)
    poses, var = np.empty((n, 3)), np.empty(n)
    poses[0], var[0] = ekf.pose, ekf.P[2, 2]
    for k in range(1, n):
        ekf.predict(log.cmd_m_s[k])
        ekf.update_encoders(log.ticks[k])
        if gyro is not None:
            ekf.update_gyro(log.yaw_rate_rad_s[k])
        poses[k], var[k] = ekf.x[:3], ekf.P[2, 2]
    return {"poses": poses, "var": var, "bias": ekf.gyro_bias,
            "gyro_gated": ekf.stats.count("gyro", "gated"), "rest_updates": ekf.n_rest_updates,
            "gyro_span": ekf.stats.count("gyro", "span")}


def scores(truth: np.ndarray, run: dict) -> dict[str, float]:
    """Final and RMS heading error, final position error, time-average heading NEES."""
    e = wrap_angle(truth[:, 2] - run["poses"][:, 2])
    return {"heading_final_rad": float(abs(e[-1])),
            "heading_rms_rad": float(np.sqrt(np.mean(e ** 2))),
            "position_final_m": float(np.hypot(*(truth[-1, :2] - run["poses"][-1, :2]))),
            "heading_nees": float(np.mean(e ** 2 / run["var"])),
            "heading_nees_final": float(e[-1] ** 2 / run["var"][-1])}


def compare(model: MotionModel, logs: FrameLog, *, bias_rad_s: float,
            scales: ScaleErrors | None = None, gyro: GyroNoise | None = None
            ) -> dict[str, dict[str, list[float]]]:
    """Scores of the encoders-only and the gyro filter on every robot of ``logs``."""
    gyro = gyro or GyroNoise(noise_density_rad_s_sqrt_hz=DENSITY)
    out: dict[str, dict[str, list[float]]] = {"encoders": {}, "gyro": {}, "window_only": {}}
    for i in range(logs.n_robots):
        log = logs.robot(i)
        for name, option in (("encoders", None), ("gyro", gyro),
                             ("window_only", dataclasses.replace(gyro, rest_update=False))):
            run = filter_run(model, log, gyro=option, scales=scales)
            for key, value in scores(log.true_pose, run).items():
                out[name].setdefault(key, []).append(value)
            if option is not None:
                out[name].setdefault("bias_error_rad_s", []).append(run["bias"] - bias_rad_s)
                out[name].setdefault("gyro_gated", []).append(run["gyro_gated"])
                out[name].setdefault("rest_updates", []).append(run["rest_updates"])
    return out


def _print(tag: str, res: dict[str, dict[str, list[float]]]) -> None:
    for name, table in res.items():
        for key, values in table.items():
            print(f"  {tag:18s} {name:8s} {key:18s} mean {statistics.fmean(values):9.5f}  "
                  f"std {statistics.pstdev(values):9.5f}  max {max(values):9.5f}  "
                  f"({len(values)} runs)", file=sys.stderr)


#: Scale priors of a robot whose intrinsics were calibrated on its floor (turn 0.3%,
#: diameter ratio 0.1%), for both filters of the ``calibrated`` scenario.
CALIBRATED = ScaleErrors(prior_std=(0.01, 0.003), ratio_prior_std=0.001)

#: (tag, floor, bias [rad/s], rest at the start [s], left wheel diameter change, scale priors,
#: stops)
SCENARIOS = (
    ("hard.bias0.rest10", "hard", 0.0, 10.0, 0.0, None, 0),
    ("hard.bias8.rest10", "hard", 0.008, 10.0, 0.0, None, 0),
    ("hard.bias8.rest1", "hard", 0.008, 1.0, 0.0, None, 0),
    ("hard.bias8.rest10.calibrated", "hard", 0.008, 10.0, 0.0, CALIBRATED, 0),
    ("hard.bias8.rest10.stops3", "hard", 0.008, 10.0, 0.0, None, 3),
    ("carpet.bias8.rest10", "carpet", 0.008, 10.0, 0.0, None, 0),
    ("wheel05.bias8.rest10", "hard", 0.008, 10.0, 0.005, None, 0),
)


@benchmark("gyro")
def gyro() -> list[Figure]:
    example = load_example("ekf_plugin")
    model = example.calibrate_model()
    figures = []
    for tag, floor, bias, rest_s, diameter, scales, stops in SCENARIOS:
        faults = (Fault("wheel_diameter", t_s=0.0, diameter_change=diameter, wheel="left"),
                  ) if diameter else ()
        res = compare(model, gyro_drives(example, floor=floor, bias_rad_s=bias, rest_s=rest_s,
                                         faults=faults, stops=stops),
                      bias_rad_s=bias, scales=scales)
        tag = f"gyro.{tag}"
        _print(tag, res)
        enc, gyr = res["encoders"], res["gyro"]
        for key, unit in (("heading_final_rad", "rad"), ("heading_rms_rad", "rad"),
                          ("position_final_m", "m"), ("heading_nees", ""),
                          ("heading_nees_final", "")):
            figures.append(Figure(f"{tag}.{key}", statistics.fmean(gyr[key]), unit,
                                  better="lower", baseline="encoders only, same drives",
                                  baseline_value=statistics.fmean(enc[key])))
        worse = sum(g > e + WORSE_RAD for g, e in zip(gyr["heading_final_rad"],
                                                    enc["heading_final_rad"], strict=True))
        figures.append(Figure(f"{tag}.worse_runs", float(worse), "runs", target=0.0,
                              better="lower"))
        figures.append(Figure(f"{tag}.window_only_heading_final_rad",
                              statistics.fmean(res["window_only"]["heading_final_rad"]), "rad",
                              better="lower", baseline="gyro with the rest update",
                              baseline_value=statistics.fmean(gyr["heading_final_rad"])))
        figures.append(Figure(f"{tag}.bias_error_rad_s",
                              statistics.fmean(gyr["bias_error_rad_s"]), "rad/s",
                              better="lower"))
    return figures
