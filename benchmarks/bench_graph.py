"""Factor-graph speed (docs/factor_graph.md): preintegration, and iSAM2 with model factors.

- ``graph.preintegrate_msamples_s``: :func:`fusion.graph.preintegrate`
  on one million speed samples in 0.5 s intervals (mean, covariance and
  calibration Jacobian); ``graph.preintegrate_model_msamples_s`` includes the
  model's sensor-less prediction of the speeds.
- ``graph.isam2_model_s``: a 10,000-keyframe drive (0.5 s keyframes, 83 min of
  simulated driving) with landmark observations, through
  :class:`fusion.graph.IncrementalSmoother`, one iSAM2 update per keyframe,
  plain model factors (native ``BetweenFactorPose2``). Baseline: the same
  graph built from encoder odometry (the encoder speeds integrated between
  keyframes, a distance-proportional diagonal covariance), same smoother,
  same run. Timed: odometry or preintegration, factor building, updates.
- ``graph.isam2_calibrated_s``: the same with the calibration-aware factors
  and a calibration variable (random walk) every 10 keyframes: each complete
  group of 10 intervals is one ``CustomFactor``
  (:func:`fusion.graph.factors.calibrated_motion_group_factor`), the newest, still
  open group native between-factors at the current calibration estimate
  until it completes (:mod:`fusion.graph.builder`).
- ``graph.isam2_curvature_s``: the same with the curvature ``kappa`` of a wheel
  diameter ratio in the calibration variable (``(s, g, kappa)``, a ``Point3``;
  :meth:`fusion.graph.SmootherOptions.with_curvature`), the intervals
  preintegrated with its third Jacobian column.

One repeat of each iSAM2 variant, after a warm-up on 300 keyframes; the
whole benchmark takes under a minute.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable

import numpy as np

from benchmarks.harness import Figure, benchmark, load_example, median_seconds
from drivers.sim.config import get_preset
from fusion.graph.factors import observe_landmarks
from fusion.graph.preintegration import Preintegrated, preintegrate, preintegrate_model
from fusion.graph.smoother import IncrementalSmoother, SmootherOptions, log_keyframes
from fusion.range_bearing import RangeBearing
from lti_motion.calibration.manoeuvres import speeds_from_log
from lti_motion.kinematics import integrate_poses

#: Keyframes of the iSAM2 drive; ``BENCH_GRAPH_KEYFRAMES`` overrides it for a quick look.
N_KEYFRAMES = int(os.environ.get("BENCH_GRAPH_KEYFRAMES", "10000"))
EVERY = 33
#: A 30 m x 30 m hall with a marker every 3 m (121 markers).
FIELD_HALF_WIDTH_M = 15.0


def _encoder_odometry(y: np.ndarray, dt_s: float, keyframes: np.ndarray) -> Preintegrated:
    """Encoder speeds integrated between keyframes, as a plain odometry user would."""
    poses = integrate_poses(y[keyframes[0]:keyframes[-1]], dt_s)[keyframes - keyframes[0]]
    c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
    d = poses[1:] - poses[:-1]
    delta = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
    dist = np.hypot(delta[:, 0], delta[:, 1]) + 1e-3
    sig = np.column_stack([0.02 * dist, 0.02 * dist, 0.05 * dist + 0.01 * np.abs(d[:, 2])])
    cov = np.zeros((len(delta), 3, 3))
    cov[:, [0, 1, 2], [0, 1, 2]] = sig**2 + 1e-8
    return Preintegrated(keyframes, np.diff(keyframes) * dt_s, delta, cov,
                         np.zeros((len(delta), 3, 2)), np.ones(2))


def _smooth(pre: Preintegrated, obs: RangeBearing, landmarks, start: np.ndarray,
            options: SmootherOptions) -> np.ndarray:
    bounds = np.searchsorted(obs.index, np.arange(len(pre) + 2))
    sm = IncrementalSmoother(initial_pose=start, options=options, landmarks=landmarks)
    for k in range(len(pre) + 1):
        if k > 0:
            sm.add_motion(pre[k - 1])
        if bounds[k + 1] > bounds[k]:
            sm.add_observations(obs.select(slice(bounds[k], bounds[k + 1])))
        sm.update()
    return sm.pose(len(pre))


def _timed(fn: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


@benchmark("graph")
def graph() -> list[Figure]:
    ex = load_example("factor_graph")
    rng = np.random.default_rng(0)
    n = 1_000_000
    speeds = np.column_stack([0.25 + 0.05 * rng.standard_normal(n), rng.standard_normal(n)])
    kf = np.arange(0, n + 1, EVERY)
    t_pre = median_seconds(lambda: preintegrate(speeds, 0.015, keyframes=kf,
                                                speed_covariance=np.eye(2) * 1e-4), repeat=5)
    model, phi = ex.calibrated_model_and_noise()
    u_long = np.tile(rng.uniform(-0.3, 0.3, (1000, 2)).repeat(50, axis=0), (20, 1))
    t_model = median_seconds(lambda: preintegrate_model(model, u_long, keyframes=kf), repeat=3)

    p = get_preset("create2")
    log = ex.drive(p, n_robots=1, seed=5, duration_s=N_KEYFRAMES * EVERY * p.period_s,
                   field_half_width_m=FIELD_HALF_WIDTH_M - 1.0).robot(0)
    landmarks = ex.landmark_grid(half_width_m=FIELD_HALF_WIDTH_M, spacing_m=3.0)
    frames = np.arange(0, len(log) - 1, EVERY)[:N_KEYFRAMES + 1]
    obs_frames = observe_landmarks(
        log.true_pose[frames], landmarks, rng=np.random.default_rng(1),
        bearing_sigma_rad=ex.BEARING_SIGMA_RAD, range_sigma_m=ex.RANGE_SIGMA_M,
        max_range_m=ex.MAX_RANGE_M, field_of_view_rad=ex.FIELD_OF_VIEW_RAD, index=frames)
    u, y = speeds_from_log(log, m_per_tick=model.m_per_tick, wheel_base_m=model.wheel_base_m)
    kf = log_keyframes(int(frames[-1]), every=EVERY)
    obs = obs_frames.with_index(np.searchsorted(kf, obs_frames.index))
    start = log.true_pose[0]
    plain, calibrated = SmootherOptions(calibrate=False), SmootherOptions(calibrate=True)
    curvature = calibrated.with_curvature(wheel_base_m=model.wheel_base_m)

    def encoder(n_kf: int) -> None:
        _smooth(_encoder_odometry(y, p.period_s, kf[:n_kf + 1]), obs, landmarks, start, plain)

    def model_plain(n_kf: int) -> None:
        pre = preintegrate_model(model, u[:kf[n_kf]], keyframes=kf[:n_kf + 1],
                                 speed_covariance=phi)
        _smooth(pre, obs, landmarks, start, plain)

    def model_calibrated(n_kf: int) -> None:
        pre = preintegrate_model(model, u[:kf[n_kf]], keyframes=kf[:n_kf + 1],
                                 speed_covariance=phi)
        _smooth(pre, obs, landmarks, start, calibrated)

    def model_curvature(n_kf: int) -> None:
        pre = preintegrate_model(model, u[:kf[n_kf]], keyframes=kf[:n_kf + 1],
                                 speed_covariance=phi, calibration=curvature.calibration_prior)
        _smooth(pre, obs, landmarks, start, curvature)

    for fn in (encoder, model_plain, model_calibrated, model_curvature):     # warm-up
        fn(300)
    t_enc = _timed(lambda: encoder(N_KEYFRAMES))
    t_plain = _timed(lambda: model_plain(N_KEYFRAMES))
    t_cal = _timed(lambda: model_calibrated(N_KEYFRAMES))
    t_kappa = _timed(lambda: model_curvature(N_KEYFRAMES))
    baseline = "encoder-odometry BetweenFactorPose2, same graph, iSAM2"
    return [
        Figure("graph.preintegrate_msamples_s", n / t_pre / 1e6, "Msamples/s", target=1.0),
        Figure("graph.preintegrate_model_msamples_s", n / t_model / 1e6, "Msamples/s",
               target=1.0),
        Figure("graph.isam2_model_s", t_plain, "s", target=1.2 * t_enc, better="lower",
               baseline=baseline, baseline_value=t_enc),
        Figure("graph.isam2_calibrated_s", t_cal, "s", target=3.0 * t_enc, better="lower",
               baseline=baseline, baseline_value=t_enc),
        Figure("graph.isam2_curvature_s", t_kappa, "s", target=3.0 * t_enc, better="lower",
               baseline=baseline, baseline_value=t_enc),
    ]
