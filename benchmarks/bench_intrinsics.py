"""Issue 17: odometry intrinsics (both wheels' scale and the wheel base) of a robot with
unequal wheels, calibrated against a motion-capture reference.

The robot: a Create 2 whose left wheel is 1% larger and whose right motor is 10% weaker,
on tile. The calibration sees encoder counts and the motion capture's noisy poses
(5 mm, 0.5 deg, 10 Hz) of one calibration drive (:func:`drivers.sim.motion_capture.
intrinsics_drive`, six repeats, about 225 s); never the simulator's parameters.

Figures:

``intrinsics.wheel_scale_error_pct`` / ``intrinsics.wheel_base_error_pct``
    Worst over 20 calibration seeds of the relative error [%] of each wheel's metres
    per tick against the ground travel per tick on a straight line (measured on the
    simulator's true contact-point speeds over the drive's steady straight runs; the
    tyres slip about 0.25% at cruise on tile, so this is not the geometric value),
    and of the wheel base against the contact wheel base.
``intrinsics.asymmetric_odometry_closure_m``
    Mean closure offset of encoder odometry on the demo's route, 30 route seeds, after
    each of 5 intrinsics calibrations (calibration seeds 0-4; ``..._std_m`` the spread
    over all 150 runs, ``..._worst_cal_m`` the worst calibration's mean); baseline: the
    default robot's odometry row of the demo (rotation-calibrated scale, its own hard
    floor), the same route seeds, this process.
``intrinsics.asymmetric_odometry_before_m``
    The same robot and route with the demo's rotation-calibrated scale (no target).
``intrinsics.default_odometry_tile_m``
    The default robot's odometry row on tile (no target): what the floor alone costs.
``intrinsics.landmarks_*``
    The same calibration drive with the reference the EKF with landmarks instead of
    motion capture (an ARX model calibrated on this robot, the route's four landmarks
    at 2 Hz): worst errors over 10 seeds, and the route closure of 5 of them (no targets).

``python -m benchmarks intrinsics_online`` (docs/intrinsics.md: the model EKF learns the
diameter ratio from landmarks; :meth:`fusion.ekf.ModelEKF.intrinsics_estimate`). The same robot and
floor, the ARX model of the ``landmarks_*`` figures (calibrated symmetric: the rotation
scale, no intrinsics), the demo's route with its four landmarks at 2 Hz, 30 route seeds:

``intrinsics.online_ratio_converged_s``
    Time from the start after which the filter's diameter ratio (left over right) stays
    within 0.2% of the truth (the straight-line truth above, from a calibration drive of
    the same simulator seed; scoring only), median over the seeds (target 60 s);
    ``..._worst_s`` the worst seed (a seed that ends outside the band counts its whole
    route), ``online_ratio_unconverged`` how many ended outside.
``intrinsics.online_ratio_error_pct``
    ``|ratio / truth - 1|`` at the end of the route [%], median (``..._worst_pct``: worst).
``intrinsics.online_closure_landmarks_m``
    Closure of the EKF with landmarks all the way (the default robot's row is 0.024 m);
    baseline the same filter with the ratio state held at zero.
``intrinsics.online_closure_half_landmarks_m``
    Closure of the EKF with landmarks only for the first half of the route's time (the
    median route length of the full-landmark runs), with the ratio state; baseline the same
    filter with the ratio state held at zero (the 2-state filter before this change).
``intrinsics.online_writeback_closure_m``
    The EKF with the model and encoders alone (no landmarks) on the route, the model moved
    to the intrinsics each full-landmark run ended with
    (:meth:`lti_motion.model.MotionModel.with_intrinsics`), driven with route seed + 100
    (another slip realisation than the one it learned on); baseline the same filter with
    the symmetric model on the same seeds (the 0.908 m row of docs/intrinsics.md).
``intrinsics.online_*_std_m``
    The standard deviations over the seeds of those closures.
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from benchmarks.harness import Figure, benchmark
from drivers.sim.calibration import calibrate_simulator
from drivers.sim.config import RobotParams, Room, get_preset
from drivers.sim.motion_capture import intrinsics_drive, motion_capture
from drivers.sim.simulator import Simulator
from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.functions import SCALES
from fusion.ekf.model_ekf import ModelEKF
from fusion.noise import LandmarkNoise, ScaleErrors
from lti_motion.app.route import ROUTE_LANDMARKS, EkfEstimator, Odometry, _observe, drive_route
from lti_motion.calibration.encoder_scale import encoder_scale_m_per_tick, rotation_period_ticks
from lti_motion.calibration.intrinsics_fit import calibrate_intrinsics
from lti_motion.calibration.manoeuvres import CalibrationPlan
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.model.excitation import rotation_in_place
from lti_motion.recordings.ticks import tick_deltas, unwrap_ticks

FLOOR = "tile"
ROUTE_SEEDS = range(30)
ONLINE_BAND = 0.002                  # the target 0.2% on the diameter ratio
WRITEBACK_SEED_OFFSET = 100          # the write-back's second drive: other seeds, other slip
#: The ratio state held at zero: the filter as it was before kappa (scale errors k_v, k_w)
HELD_RATIO = ScaleErrors(ratio_prior_std=1e-9, ratio_walk_per_sqrt_s=0.0)
CAL_SEEDS = range(20)
CLOSURE_CAL_SEEDS = range(5)
LANDMARK_SEEDS = range(10)
REPEATS = 6


def asymmetric_robot() -> RobotParams:
    """The asymmetric robot: left wheel 1% larger, right motor 10% weaker (docs/intrinsics.md)."""
    return get_preset("create2", wheel_diameter_errors=(0.01, 0.0), motor_balance=0.90)


def rotation_scale(params: RobotParams, *, floor: str = FLOOR, seed: int = 0) -> float:
    """The demo's encoder scale: three turns beside the furniture (the rotation stage of
    :func:`lti_motion.calibration.calibrate`)."""
    sim = Simulator(params, seed=seed, floor=floor, room=Room.cluttered(),
                    initial_pose=Room.CALIBRATION_SPOT)
    rest = np.zeros((round(1.0 / params.period_s), 2))
    cmd = np.concatenate([rest, rotation_in_place(turns=3.0, wheel_speed_m_s=0.15,
                                                  wheel_base_m=params.wheel_base_m,
                                                  dt_s=params.period_s), rest])
    log = sim.run(cmd)
    ticks = unwrap_ticks(log.ticks[log.valid])
    period = rotation_period_ticks(log.light_bump[log.valid], ticks[:, 1] - ticks[:, 0])
    return encoder_scale_m_per_tick(period.period_ticks, wheel_base_m=params.wheel_base_m)


def calibration_run(params: RobotParams, seed: int) -> tuple[OdometryIntrinsics, np.ndarray]:
    """Calibrate from one drive; the estimate and the truth it is scored against
    ``(left, right [m/tick], wheel base [m])`` (the truth from the simulator, for scoring)."""
    cmd = intrinsics_drive(params.period_s, repeats=REPEATS)
    sim = Simulator(params, seed=seed, floor=FLOOR, room=Room.empty(), initial_pose=(0, 0, 0))
    log = sim.run(cmd)
    t_ref, poses = motion_capture(log, rng=np.random.default_rng([seed, 0x40CA]))
    cal = calibrate_intrinsics(log.t_s, log.ticks, t_ref, poses, sensor_pose=False,
                               encoders="commanded", heading_std_rad=np.deg2rad(0.5))
    return cal.intrinsics, straight_line_truth(params, log, cmd)


def straight_line_truth(params: RobotParams, log, cmd: np.ndarray) -> np.ndarray:
    """The simulator's truth, for scoring only: each wheel's contact-point travel per
    tick over every steady straight period of the drive (equal, unchanged commands for
    the last second), and the contact wheel base ``(left, right [m/tick], base [m])``."""
    straight = (cmd[:, 0] == cmd[:, 1]) & (cmd[:, 0] > 0)
    same = np.all(cmd == np.roll(cmd, 1, axis=0), axis=1)
    hold = round(1.0 / params.period_s)
    steady = straight & (np.convolve(same, np.ones(hold), "full")[:len(same)] == hold)
    b = params.true_wheel_base_m
    v, w = log.true_body_m_s.T
    travel = np.abs(np.stack([v - 0.5 * b * w, v + 0.5 * b * w], 1))[steady].sum(0)
    counts = np.vstack([[0, 0], tick_deltas(log.ticks, axis=0)])[steady].sum(0)
    return np.array([*(travel * params.period_s / counts), b])


def landmark_calibration_run(params: RobotParams, seed: int, model
                             ) -> tuple[OdometryIntrinsics, np.ndarray]:
    """As :func:`calibration_run`, the reference the EKF with landmarks (the route's four
    landmarks, range-bearing at 2 Hz, the route's sensor noise) over the same drive."""
    cmd = intrinsics_drive(params.period_s, repeats=REPEATS)
    start = np.array([[0.5, 0.5, 0.0]])
    sim = Simulator(params, seed=[seed], floor=FLOOR, room=Room.empty(), initial_pose=start)
    ekf = EkfEstimator(model, landmarks=ROUTE_LANDMARKS)
    ekf.reset(1, start)
    rng = np.random.default_rng([seed, 0x1A4D])
    stride = round(1.0 / (2.0 * params.period_s))
    t_s, ticks, body, poses = [], [], [], []
    for k in range(len(cmd)):
        frame = sim.step(cmd[k:k + 1])
        # the landmark sensor is the physical world's side: it reads the truth
        obs = _observe(ROUTE_LANDMARKS, frame.true_pose, k + 1, stride=stride,
                       noise=LandmarkNoise(), rng=rng)
        seen = replace(frame, true_pose=None, true_body_m_s=None)
        poses.append(ekf.step(seen, np.round(cmd[k:k + 1] * 1000.0) / 1000.0, obs)[0].copy())
        t_s.append(frame.t_s[0])
        ticks.append(frame.ticks[0])
        body.append(frame.true_body_m_s[0])             # for scoring only
    t_s, ticks, poses = np.array(t_s), np.array(ticks), np.array(poses)
    cal = calibrate_intrinsics(t_s, ticks, t_s[::7], poses[::7], sensor_pose=False,
                               encoders="commanded", position_std_m=0.02, heading_std_rad=0.02)
    truth_log = SimpleNamespace(true_body_m_s=np.array(body), ticks=ticks)
    return cal.intrinsics, straight_line_truth(params, truth_log, cmd)


def closure(params: RobotParams, odometry: Odometry, *, floor: str = FLOOR) -> np.ndarray:
    """Closure offsets [m] of encoder odometry on the route, one per route seed."""
    res = drive_route(params, odometry, seeds=list(ROUTE_SEEDS), floor=floor)
    return res.closure_offset_m


@benchmark("intrinsics")
def run() -> list[Figure]:
    params = asymmetric_robot()
    errors = []
    for seed in CAL_SEEDS:
        est, truth = calibration_run(params, seed)
        got = np.array([est.m_per_tick_left, est.m_per_tick_right, est.wheel_base_m])
        errors.append(100.0 * (got / truth - 1.0))
    errors = np.abs(np.array(errors))
    # every calibration of CLOSURE_CAL_SEEDS drives the 30 route seeds
    after = np.stack([closure(params, Odometry(intrinsics=calibration_run(params, s)[0]))
                      for s in CLOSURE_CAL_SEEDS])
    before = closure(params, Odometry(m_per_tick=rotation_scale(params),
                                      wheel_base_m=params.wheel_base_m))
    default = get_preset("create2")                    # the demo's row: its own floor
    own = str(default.floor)
    base = closure(default, Odometry(m_per_tick=rotation_scale(default, floor=own),
                                     wheel_base_m=default.wheel_base_m), floor=own)
    base_tile = closure(default, Odometry(m_per_tick=rotation_scale(default),
                                          wheel_base_m=default.wheel_base_m))
    model = calibrate_simulator(params, seed=0, floor=FLOOR,
                                plan=CalibrationPlan(seed=2, excitation_s=60.0)).arx
    lm_errors, lm_closure = [], []
    for seed in LANDMARK_SEEDS:
        est, truth = landmark_calibration_run(params, seed, model)
        got = np.array([est.m_per_tick_left, est.m_per_tick_right, est.wheel_base_m])
        lm_errors.append(np.abs(100.0 * (got / truth - 1.0)))
        if seed in CLOSURE_CAL_SEEDS:
            lm_closure.append(closure(params, Odometry(intrinsics=est)))
    lm_errors = np.array(lm_errors)
    return [
        Figure("intrinsics.landmarks_wheel_scale_error_pct", float(lm_errors[:, :2].max()), "%",
               better="lower"),
        Figure("intrinsics.landmarks_wheel_base_error_pct", float(lm_errors[:, 2].max()), "%",
               better="lower"),
        Figure("intrinsics.landmarks_odometry_closure_m", float(np.mean(lm_closure)), "m",
               better="lower"),
        Figure("intrinsics.wheel_scale_error_pct", float(errors[:, :2].max()), "%",
               target=0.1, better="lower"),
        Figure("intrinsics.wheel_base_error_pct", float(errors[:, 2].max()), "%",
               target=0.3, better="lower"),
        Figure("intrinsics.asymmetric_odometry_closure_m", float(after.mean()), "m",
               target=min(0.10, 1.2 * float(base.mean())), better="lower",
               baseline="default robot, rotation-calibrated odometry",
               baseline_value=float(base.mean())),
        Figure("intrinsics.asymmetric_odometry_before_m", float(before.mean()), "m",
               better="lower"),
        Figure("intrinsics.asymmetric_odometry_closure_std_m", float(after.std()), "m",
               better="lower"),
        Figure("intrinsics.asymmetric_odometry_closure_worst_cal_m",
               float(after.mean(axis=1).max()), "m", better="lower"),
        Figure("intrinsics.default_odometry_tile_m", float(base_tile.mean()), "m",
               better="lower"),
    ]


class LearningEkf(EkfEstimator):
    """:class:`~lti_motion.app.route.EkfEstimator` that keeps every filter's scale errors
    ``(k_v, k_w, kappa)`` per period and stops reading landmarks after ``landmarks_until_s``."""

    def __init__(self, model, *, landmarks_until_s: float = np.inf,
                 scales: ScaleErrors | None = None, **kwargs) -> None:
        super().__init__(model, **kwargs)
        self.landmarks_until_s = landmarks_until_s
        self.scales = scales or ScaleErrors()

    def reset(self, n_robots: int, initial_pose: np.ndarray) -> None:
        super().reset(n_robots, initial_pose)
        self.k = 0
        self.errors: list[np.ndarray] = []

    def step(self, frame, cmd_m_s, observations=None):
        if self.filters is None:            # as EkfEstimator, with this estimator's scales
            ticks = np.asarray(frame.ticks, np.int64).reshape(len(self.pose), 2)
            valid = np.broadcast_to(np.asarray(frame.valid, bool), (len(ticks),))
            self.filters = [
                ModelEKF(self.model, initial_pose=pose, pose_std=(0.005, 0.005, 0.005),
                         initial_ticks=t if ok else None, landmarks=self.landmarks,
                         options=EKFOptions(landmark_noise=self.landmark_noise, history=0,
                                            scales=self.scales))
                for pose, t, ok in zip(self.pose, ticks, valid, strict=True)]
            return self.pose
        self.k += 1
        if self.k * self.model.dt_s > self.landmarks_until_s:
            observations = None
        pose = super().step(frame, cmd_m_s, observations)
        self.errors.append(np.array([f.x[SCALES] for f in self.filters]))
        return pose


def online_scores(errors: np.ndarray, intrinsics: OdometryIntrinsics, truth_ratio: np.ndarray,
                  dt_s: float, finished_step: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per seed: the time [s] after which the ratio stays within :data:`ONLINE_BAND` of the
    truth (the route's end if it ends outside), and the relative error at the end [%].

    ``errors`` (periods, seeds, 3) are the filters' scale errors, ``finished_step`` each
    seed's last period of the route; ratios through ``intrinsics.corrected``."""
    conv, final = [], []
    for i, truth in enumerate(truth_ratio):
        n = int(finished_step[i])
        ratio = np.array([intrinsics.corrected(*c).diameter_ratio for c in errors[:n, i]])
        rel = ratio / truth - 1.0
        outside = np.flatnonzero(np.abs(rel) > ONLINE_BAND)
        # sample j is the estimate at (j + 1) dt_s (the first frame only anchors the counts)
        conv.append(0.0 if outside.size == 0 else (outside[-1] + 1) * dt_s)
        final.append(100.0 * abs(rel[-1]))
    return np.array(conv), np.array(final)


def writeback_closures(params: RobotParams, model, learned: list[OdometryIntrinsics],
                       seeds: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Closure offsets [m] of the EKF without landmarks on the route again, on seeds
    ``seed + WRITEBACK_SEED_OFFSET`` (new slip): each run's learned intrinsics written into
    the model (``MotionModel.with_intrinsics``), and the model as it was."""
    written = np.array([drive_route(params, EkfEstimator(model.with_intrinsics(k)),
                                    seeds=[seed + WRITEBACK_SEED_OFFSET],
                                    floor=FLOOR).closure_offset_m[0]
                        for seed, k in zip(seeds, learned, strict=True)])
    symmetric = drive_route(params, EkfEstimator(model), floor=FLOOR,
                            seeds=[s + WRITEBACK_SEED_OFFSET for s in seeds]).closure_offset_m
    return written, symmetric


def _route_end(res) -> np.ndarray:
    """Each seed's periods of the route after the anchoring frame, up to where its true pose
    stopped changing (the length of its :attr:`LearningEkf.errors`)."""
    moved = np.any(np.abs(np.diff(res.true_poses, axis=1)) > 1e-9, axis=2)
    return np.array([np.flatnonzero(m)[-1] + 1 if m.any() else m.size for m in moved])


@benchmark("intrinsics_online")
def online() -> list[Figure]:
    return online_figures(list(ROUTE_SEEDS))


def online_figures(seeds: list[int]) -> list[Figure]:
    """The ``intrinsics_online`` figures over the route seeds ``seeds``."""
    params = asymmetric_robot()
    model = calibrate_simulator(params, seed=0, floor=FLOOR,
                                plan=CalibrationPlan(seed=2, excitation_s=60.0)).arx
    cmd = intrinsics_drive(params.period_s, repeats=REPEATS)
    truth = []
    for seed in seeds:                                  # scoring only
        log = Simulator(params, seed=seed, floor=FLOOR, room=Room.empty(),
                        initial_pose=(0, 0, 0)).run(cmd)
        left, right, _ = straight_line_truth(params, log, cmd)
        truth.append(left / right)
    truth = np.array(truth)

    def route(est, landmarks=ROUTE_LANDMARKS):
        return drive_route(params, est, seeds=seeds, floor=FLOOR, landmarks=landmarks)

    full = LearningEkf(model, landmarks=ROUTE_LANDMARKS)
    res = route(full)
    errors = np.stack(full.errors)
    ends = _route_end(res)
    conv, final = online_scores(errors, model.encoder_intrinsics, truth, params.period_s, ends)
    full_held = route(LearningEkf(model, landmarks=ROUTE_LANDMARKS, scales=HELD_RATIO))
    half_s = 0.5 * float(np.median(ends)) * params.period_s
    half = route(LearningEkf(model, landmarks=ROUTE_LANDMARKS, landmarks_until_s=half_s))
    half_held = route(LearningEkf(model, landmarks=ROUTE_LANDMARKS, landmarks_until_s=half_s,
                                  scales=HELD_RATIO))
    learned = [model.encoder_intrinsics.corrected(*errors[ends[i] - 1, i])
               for i in range(len(seeds))]
    written, symmetric = writeback_closures(params, model, learned, seeds)
    return [
        Figure("intrinsics.online_ratio_converged_s", float(np.median(conv)), "s", target=60.0,
               better="lower"),
        Figure("intrinsics.online_ratio_converged_worst_s", float(conv.max()), "s",
               better="lower"),
        Figure("intrinsics.online_ratio_unconverged", float(np.sum(final > 100 * ONLINE_BAND)),
               "seeds", better="lower"),
        Figure("intrinsics.online_ratio_error_pct", float(np.median(final)), "%",
               target=100 * ONLINE_BAND, better="lower"),
        Figure("intrinsics.online_ratio_error_worst_pct", float(final.max()), "%",
               better="lower"),
        Figure("intrinsics.online_route_s", float(np.median(ends)) * params.period_s, "s",
               better="lower"),
        Figure("intrinsics.online_closure_landmarks_m", float(res.closure_offset_m.mean()), "m",
               better="lower", baseline="the same filter, ratio state held at zero",
               baseline_value=float(full_held.closure_offset_m.mean())),
        Figure("intrinsics.online_closure_half_landmarks_m", float(half.closure_offset_m.mean()),
               "m", better="lower", baseline="the same filter, ratio state held at zero",
               baseline_value=float(half_held.closure_offset_m.mean())),
        Figure("intrinsics.online_writeback_closure_m", float(written.mean()), "m",
               better="lower", baseline="the same filter, the symmetric model",
               baseline_value=float(symmetric.mean())),
        # spreads over the seeds (standard deviations) of the closures above
        Figure("intrinsics.online_closure_landmarks_std_m", float(res.closure_offset_m.std()),
               "m", better="lower"),
        Figure("intrinsics.online_closure_half_landmarks_std_m",
               float(half.closure_offset_m.std()), "m", better="lower"),
        Figure("intrinsics.online_closure_half_landmarks_held_std_m",
               float(half_held.closure_offset_m.std()), "m", better="lower"),
        Figure("intrinsics.online_writeback_closure_std_m", float(written.std()), "m",
               better="lower"),
        Figure("intrinsics.online_writeback_symmetric_std_m", float(symmetric.std()), "m",
               better="lower"),
    ]
