"""Issue 17 item 3, the smoother's side: the iSAM2 smoother learns the diameter ratio from
landmarks through its curvature calibration ``kappa``
(:meth:`fusion.graph.SmootherOptions.with_curvature`,
:meth:`lti_motion.app.route_smoother.SmootherEstimator.intrinsics_estimates`).

``python -m benchmarks intrinsics_smoother``: the robot, floor, ARX model, route, landmarks
(four, 2 Hz), truth and route seeds (0-29) of ``intrinsics_online``
(:mod:`benchmarks.bench_intrinsics`); the route's smoother
(:data:`~lti_motion.app.route_smoother.ROUTE_SMOOTHER_OPTIONS`) with ``(s, g, kappa)``
against the same smoother with ``(s, g)``:

``intrinsics.smoother_ratio_converged_s`` / ``..._worst_s`` / ``smoother_ratio_unconverged``
    As ``online_ratio_converged_s``: the time after which the ratio of the calibration the
    smoother dead-reckons with (read back at each keyframe) stays within 0.2% of the truth,
    median and worst over the seeds, and how many end outside.
``intrinsics.smoother_ratio_error_pct`` / ``..._worst_pct``
    ``|ratio / truth - 1|`` [%] of :meth:`SmootherEstimator.intrinsics_estimates` at the
    end of the route (the newest calibration variable's estimate), median / worst.
``intrinsics.smoother_landmarks_closure_m``
    Closure with landmarks all the way; baseline the ``(s, g)`` smoother.
``intrinsics.smoother_half_landmarks_closure_m``
    Closure with landmarks for the first half of the route's median time only; baseline the
    ``(s, g)`` smoother.
``intrinsics.smoother_writeback_closure_m``
    The route EKF without landmarks, the model moved to the intrinsics each full-landmark
    smoother run ended with (:meth:`lti_motion.model.MotionModel.with_intrinsics`), route
    seed + 100; baseline the same filter with the symmetric model.
``intrinsics.smoother_default_closure_m``
    The default (symmetric) robot on its own floor, its own ARX model (the same calibration
    recipe), with ``(s, g, kappa)``; baseline the ``(s, g)`` smoother on the same seeds:
    the third variable must not make a symmetric robot worse.
``intrinsics.smoother_{landmarks,half_landmarks,default}_route_rmse_m``
    The estimate's own error: root mean square of ``|estimated - true position|`` over
    each run's periods up to its end (:func:`benchmarks.bench_intrinsics._route_end`), mean
    over the seeds; baseline the ``(s, g)`` smoother. The closure is mostly the follower's
    3 cm arrival tolerance (README), which hides millimetres of estimation error.
``intrinsics.smoother_{landmarks,half_landmarks,default}_{closure,route_rmse}_paired_m``
    Mean over the seeds of the paired difference (with ``kappa`` minus without) of the
    closure and of the route RMSE; ``..._paired_std_m`` its standard deviation (the
    standard error of the mean is that over sqrt(30)).
``intrinsics.smoother_*_closure_std_m``, ``intrinsics.smoother_*_baseline_std_m``
    Standard deviations over the seeds of those closures and of their baselines.
"""

from __future__ import annotations

import numpy as np

from benchmarks.bench_intrinsics import (
    FLOOR,
    REPEATS,
    ROUTE_SEEDS,
    _route_end,
    asymmetric_robot,
    online_scores,
    straight_line_truth,
    writeback_closures,
)
from benchmarks.harness import Figure, benchmark
from drivers.sim.calibration import calibrate_simulator
from drivers.sim.config import Room, get_preset
from drivers.sim.motion_capture import intrinsics_drive
from drivers.sim.simulator import Simulator
from lti_motion.app.route import ROUTE_LANDMARKS, drive_route
from lti_motion.app.route_smoother import ROUTE_SMOOTHER_OPTIONS, SmootherEstimator
from lti_motion.calibration.manoeuvres import CalibrationPlan

ONLINE_BAND = 0.002


class LearningSmoother(SmootherEstimator):
    """:class:`SmootherEstimator` that keeps every robot's calibration per period, as
    ``(k_v, k_w, kappa) = (s - 1, g - 1, kappa)``, and stops reading landmarks after
    ``landmarks_until_s``."""

    def __init__(self, model, *, landmarks_until_s: float = np.inf, **kwargs) -> None:
        super().__init__(model, **kwargs)
        self.landmarks_until_s = landmarks_until_s

    def reset(self, n_robots: int, initial_pose: np.ndarray) -> None:
        super().reset(n_robots, initial_pose)
        self.k = 0
        self.errors: list[np.ndarray] = []

    def step(self, frame, cmd_m_s, observations=None):
        if self.smoothers is None:
            return super().step(frame, cmd_m_s, observations)
        self.k += 1
        if self.k * self.model.dt_s > self.landmarks_until_s:
            observations = None
        pose = super().step(frame, cmd_m_s, observations)
        cal = self._cal
        kappa = cal[:, 2] if cal.shape[1] == 3 else np.zeros(len(cal))
        self.errors.append(np.column_stack([cal[:, 0] - 1.0, cal[:, 1] - 1.0, kappa]))
        return pose


def _route_rmse(res) -> np.ndarray:
    """Per run, the RMS position error [m] of the estimate over the route (scoring only)."""
    ends = _route_end(res)
    err = np.linalg.norm(res.est_poses[..., :2] - res.true_poses[..., :2], axis=-1)
    return np.array([np.sqrt(np.mean(e[:n + 1] ** 2)) for e, n in zip(err, ends, strict=True)])


def _model(params, floor):
    return calibrate_simulator(params, seed=0, floor=floor,
                               plan=CalibrationPlan(seed=2, excitation_s=60.0)).arx


def _truth(params, seeds):
    """The straight-line diameter ratio per seed (scoring only)."""
    cmd = intrinsics_drive(params.period_s, repeats=REPEATS)
    out = []
    for seed in seeds:
        log = Simulator(params, seed=seed, floor=FLOOR, room=Room.empty(),
                        initial_pose=(0, 0, 0)).run(cmd)
        left, right, _ = straight_line_truth(params, log, cmd)
        out.append(left / right)
    return np.array(out)


@benchmark("intrinsics_smoother")
def run() -> list[Figure]:
    return smoother_figures(list(ROUTE_SEEDS))


def smoother_figures(seeds: list[int]) -> list[Figure]:
    """The ``intrinsics_smoother`` figures over the route seeds ``seeds``."""
    params = asymmetric_robot()
    model = _model(params, FLOOR)
    truth = _truth(params, seeds)
    sg = ROUTE_SMOOTHER_OPTIONS
    kappa = sg.with_curvature(wheel_base_m=model.wheel_base_m)

    def route(est, p=params, floor=FLOOR):
        return drive_route(p, est, seeds=seeds, floor=floor, landmarks=ROUTE_LANDMARKS)

    full = LearningSmoother(model, landmarks=ROUTE_LANDMARKS, options=kappa)
    res = route(full)
    ends = _route_end(res)
    conv, _ = online_scores(np.stack(full.errors), model.encoder_intrinsics, truth,
                            params.period_s, ends)
    learned = [e.intrinsics for e in full.intrinsics_estimates()]
    final = 100.0 * np.abs(np.array([k.diameter_ratio for k in learned]) / truth - 1.0)
    full_sg = route(SmootherEstimator(model, landmarks=ROUTE_LANDMARKS, options=sg))
    half_s = 0.5 * float(np.median(ends)) * params.period_s
    half = route(LearningSmoother(model, landmarks=ROUTE_LANDMARKS, options=kappa,
                                  landmarks_until_s=half_s))
    half_sg = route(LearningSmoother(model, landmarks=ROUTE_LANDMARKS, options=sg,
                                     landmarks_until_s=half_s))
    written, symmetric = writeback_closures(params, model, learned, seeds)
    default = get_preset("create2")
    own = str(default.floor)
    d_model = _model(default, own)
    d_opts = sg.with_curvature(wheel_base_m=d_model.wheel_base_m)
    d_kappa = route(SmootherEstimator(d_model, landmarks=ROUTE_LANDMARKS, options=d_opts),
                    p=default, floor=own)
    d_sg = route(SmootherEstimator(d_model, landmarks=ROUTE_LANDMARKS, options=sg), p=default,
                 floor=own)
    pairs = {"landmarks": (res, full_sg), "half_landmarks": (half, half_sg),
             "default": (d_kappa, d_sg)}
    closures = {"landmarks": (res.closure_offset_m, full_sg.closure_offset_m),
                "half_landmarks": (half.closure_offset_m, half_sg.closure_offset_m),
                "writeback": (written, symmetric),
                "default": (d_kappa.closure_offset_m, d_sg.closure_offset_m)}
    baselines = {"landmarks": "the same smoother with (s, g)",
                 "half_landmarks": "the same smoother with (s, g)",
                 "writeback": "the same EKF, the symmetric model",
                 "default": "the same smoother with (s, g), default robot"}
    figures = [
        Figure("intrinsics.smoother_ratio_converged_s", float(np.median(conv)), "s",
               target=60.0, better="lower"),
        Figure("intrinsics.smoother_ratio_converged_worst_s", float(conv.max()), "s",
               better="lower"),
        Figure("intrinsics.smoother_ratio_unconverged",
               float(np.sum(final > 100 * ONLINE_BAND)), "seeds", better="lower"),
        Figure("intrinsics.smoother_ratio_error_pct", float(np.median(final)), "%",
               target=100 * ONLINE_BAND, better="lower"),
        Figure("intrinsics.smoother_ratio_error_worst_pct", float(final.max()), "%",
               better="lower"),
    ]
    for key, (value, base) in closures.items():
        figures.append(Figure(f"intrinsics.smoother_{key}_closure_m", float(value.mean()), "m",
                              better="lower", baseline=baselines[key],
                              baseline_value=float(base.mean())))
    for key, (with_kappa, without) in pairs.items():
        rmse, rmse_base = _route_rmse(with_kappa), _route_rmse(without)
        figures.append(Figure(f"intrinsics.smoother_{key}_route_rmse_m", float(rmse.mean()),
                              "m", better="lower", baseline=baselines[key],
                              baseline_value=float(rmse_base.mean())))
        for name, diff in (("closure", closures[key][0] - closures[key][1]),
                           ("route_rmse", rmse - rmse_base)):
            figures.append(Figure(f"intrinsics.smoother_{key}_{name}_paired_m",
                                  float(diff.mean()), "m", better="lower"))
            figures.append(Figure(f"intrinsics.smoother_{key}_{name}_paired_std_m",
                                  float(diff.std()), "m", better="lower"))
    for key, (value, base) in closures.items():      # spreads over the seeds
        figures.append(Figure(f"intrinsics.smoother_{key}_closure_std_m", float(value.std()),
                              "m", better="lower"))
        figures.append(Figure(f"intrinsics.smoother_{key}_baseline_std_m", float(base.std()),
                              "m", better="lower"))
    return figures
