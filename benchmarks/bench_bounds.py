"""Filters that cannot run away (docs/ekf.md, bounds and resets): the' accuracy and their cost.

The scenario of ``tests/fusion/ekf/test_resets.py``, over more seeds: a robot at
rest for 30 s while its odometry reads -0.022 m/s (an encoder bias at rest),
then 25 s of ``examples/ekf_plugin.py``'s rounded-square route; four corner
landmarks, each seen at 10 Hz (2% range, 1 degree bearing noise, drawn from the
simulator's true pose); the odometry (count increments times the calibrated
scale, plus the bias at rest) fused as speeds (``update_speeds``: a speeds-only
recording). One ARX calibration (the example's, seed 1); drives seeds
``100 .. 100 + N_RUNS - 1`` (simulator and route), sightings seeds ``500 + seed``.
The filters read commands, speeds and sightings only; the truth is read
afterwards, for the position RMS error (ATE without alignment).

- ``bounds.ate_bounded_m``: :class:`~fusion.ekf.ModelEKF` as shipped (scale
  bound, plausibility reset, divergence watch), mean over the runs (the record's
  name carries the spread in the printed table, ``docs/benchmarks.md``).
- ``bounds.ate_unbounded_m``: the same filter with the bounds bypassed (the
  shared gated update only: the filter before the bounds), in the same process.
- ``bounds.ate_odometry_m``: the biased odometry integrated (dead reckoning).
- ``bounds.ate_landmarks_only_m``: the same filter fed no speeds (model and
  landmarks).
- ``bounds.scale_d2_max_bounded`` and ``..._unbounded``: the largest scale
  plausibility statistic ``d^2`` over all frames and runs (bound 27.6).
- ``bounds.resets_per_run``: resets of the bounded filter, mean.
- ``bounds.step_cost_ratio``: one ``predict`` plus ``update_encoders`` with the
  bounds, against the same filter with them bypassed, interleaved in one
  process (the cost of the bound test after every fused update). Target 1.05.

Run ``python -m benchmarks bounds --json out/bench-bounds.json``.
"""

from __future__ import annotations

import statistics
import sys
import time

import numpy as np

from benchmarks.harness import Figure, benchmark, load_example
from drivers.sim.config import Room
from drivers.sim.simulator import Simulator
from fusion.ekf import EKFOptions, ModelEKF
from fusion.ekf.resets import ScaleBound, scale_statistic
from fusion.ekf.updates import GatedUpdates
from fusion.landmark_map import LandmarkMap
from fusion.landmarks.synthetic import synthetic_observations
from fusion.noise import ScaleErrors
from fusion.range_bearing import RangeBearing
from lti_motion.kinematics import body_from_wheel, integrate_poses
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.frames import FrameLog
from lti_motion.recordings.ticks import tick_deltas

N_RUNS = 10
REST_S, DRIVE_S, BIAS_M_S = 30.0, 25.0, -0.022
LANDMARKS = LandmarkMap({0: (0.5, 0.5), 1: (4.5, 0.5), 2: (4.5, 4.5), 3: (0.5, 4.5)})
START = (2.5, 1.3, 0.0)
N_STEPS, REPEAT = 2000, 15


class _Unbounded(ModelEKF):
    """The model EKF with the bounds bypassed: the shared gated update alone (as before)."""

    _gated = GatedUpdates._gated


def _run(cls: type[ModelEKF], model: MotionModel, log, speeds: np.ndarray | None,
         sightings: RangeBearing) -> tuple[np.ndarray, float, int]:
    """Poses, the largest scale d^2 and the resets of one filter over one drive."""
    ekf = cls(model, initial_pose=START, pose_std=(0.005,) * 3, landmarks=LANDMARKS,
              options=EKFOptions(history=0))
    bound = ekf.scale_bound
    by_frame, none = sightings.by_index(), RangeBearing.empty()
    poses = np.empty((len(log.t_s), 3))
    poses[0] = ekf.pose
    d2 = 0.0
    for k in range(1, len(log.t_s)):
        ekf.predict(log.cmd_m_s[k])
        if speeds is not None:
            ekf.update_speeds(speeds[k - 1])
        ekf.update_landmarks(by_frame.get(k, none))
        poses[k] = ekf.pose
        d2 = max(d2, scale_statistic(*ekf.scale_errors.tolist(), bound, ekf.t_s))
    return poses, d2, ekf.n_resets


def biased_drive(example, model: MotionModel, *, seed: int, rest_s: float, bias_m_s: float,
                 duration_s: float = DRIVE_S) -> tuple[FrameLog, np.ndarray, RangeBearing]:
    """The scenario of test_resets.py on the simulator: rest, then ``examples/ekf_plugin.py``'s
    rounded-square route; the odometry's body speeds [m/s, rad/s] biased by ``bias_m_s`` on
    both wheels while at rest; sightings of the four corner landmarks at 10 Hz."""
    sim = Simulator("create2", n_robots=1, seed=seed, room=Room.box(5.0, 5.0),
                    initial_pose=START)
    log = example.drive_route(sim, duration_s=duration_s, rng=np.random.default_rng(seed),
                              rest_s=rest_s).robot(0)
    dt = log.dt_s
    wheel = tick_deltas(log.ticks, axis=0) * model.m_per_tick / dt
    wheel[:round(rest_s / dt) - 1] += bias_m_s
    speeds = body_from_wheel(wheel, wheel_base_m=model.wheel_base_m)
    sightings = synthetic_observations(log.true_pose, LANDMARKS, dt_s=dt, rate_hz=10.0,
                                       rng=np.random.default_rng(500 + seed))
    return log, speeds, sightings


def _ate(truth: np.ndarray, poses: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((poses[:, :2] - truth[:, :2]) ** 2, axis=1))))


def _accuracy(example, model: MotionModel) -> dict[str, list[float]]:
    out: dict[str, list[float]] = {k: [] for k in (
        "bounded", "unbounded", "odometry", "landmarks_only", "d2_bounded", "d2_unbounded",
        "resets")}
    for seed in range(100, 100 + N_RUNS):
        log, speeds, sightings = biased_drive(example, model, seed=seed, rest_s=REST_S,
                                              bias_m_s=BIAS_M_S)
        poses, d2, resets = _run(ModelEKF, model, log, speeds, sightings)
        out["bounded"].append(_ate(log.true_pose, poses))
        out["d2_bounded"].append(d2)
        out["resets"].append(float(resets))
        poses, d2, _ = _run(_Unbounded, model, log, speeds, sightings)
        out["unbounded"].append(_ate(log.true_pose, poses))
        out["d2_unbounded"].append(d2)
        out["landmarks_only"].append(_ate(log.true_pose,
                                          _run(ModelEKF, model, log, None, sightings)[0]))
        out["odometry"].append(_ate(log.true_pose,
                                    integrate_poses(speeds, log.dt_s, initial_pose=START)))
    return out


def _step_cost(model: MotionModel) -> tuple[float, float]:
    """Median seconds per step of predict + update_encoders, bounded and bypassed."""
    k = np.arange(N_STEPS + 1)
    cmd = np.stack([0.2 + 0.05 * np.sin(k / 80.0), 0.2 + 0.05 * np.cos(k / 80.0)], axis=1)
    log = Simulator("create2", seed=2, room=Room.empty()).run(cmd)
    times: dict[type, list[float]] = {ModelEKF: [], _Unbounded: []}
    for r in range(REPEAT + 1):
        for cls in times:
            f = cls(model, initial_ticks=log.ticks[0], options=EKFOptions(history=1000))
            t0 = time.perf_counter()
            for i in range(1, N_STEPS + 1):
                f.predict(log.cmd_m_s[i])
                f.update_encoders(log.ticks[i])
            if r:
                times[cls].append((time.perf_counter() - t0) / N_STEPS)
    return statistics.median(times[ModelEKF]), statistics.median(times[_Unbounded])


def _mean_spread(values: list[float]) -> tuple[float, float]:
    return statistics.fmean(values), statistics.pstdev(values)


@benchmark("bounds")
def bounds() -> list[Figure]:
    example = load_example("ekf_plugin")
    model = example.calibrate_model()
    acc = _accuracy(example, model)
    for name, values in acc.items():
        mean, spread = _mean_spread(values)
        print(f"  {name:16s} mean {mean:8.4f}  std {spread:8.4f}  min {min(values):8.4f}  "
              f"max {max(values):8.4f}  ({N_RUNS} runs)", file=sys.stderr)
    bounded_s, bypassed_s = _step_cost(model)
    base = "the same ModelEKF with the bounds bypassed, same process"
    mean = {k: statistics.fmean(v) for k, v in acc.items()}
    return [
        Figure("bounds.ate_bounded_m", mean["bounded"], "m", better="lower",
               baseline="dead reckoning (biased odometry)", baseline_value=mean["odometry"]),
        Figure("bounds.ate_unbounded_m", mean["unbounded"], "m", better="lower",
               baseline="dead reckoning (biased odometry)", baseline_value=mean["odometry"]),
        Figure("bounds.ate_odometry_m", mean["odometry"], "m", better="lower"),
        Figure("bounds.ate_landmarks_only_m", mean["landmarks_only"], "m", better="lower"),
        Figure("bounds.scale_d2_max_bounded", max(acc["d2_bounded"]), "", better="lower",
               target=ScaleBound.from_scales(ScaleErrors(),
                                             wheel_base_m=model.wheel_base_m).threshold),
        Figure("bounds.scale_d2_max_unbounded", max(acc["d2_unbounded"]), "", better="lower"),
        Figure("bounds.resets_per_run", mean["resets"], "resets", better="lower"),
        Figure("bounds.step_cost_ratio", bounded_s / bypassed_s, "x", target=1.05,
               better="lower"),
        Figure("bounds.step_us", bounded_s * 1e6, "us", better="lower", baseline=base,
               baseline_value=bypassed_s * 1e6),
    ]
