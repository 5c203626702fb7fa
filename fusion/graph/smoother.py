"""Smoothing with preintegrated model factors and landmarks: iSAM2 online, LM in batch.

:class:`IncrementalSmoother` wraps ``gtsam.ISAM2`` (Kaess et al. 2012): add the
preintegrated motion up to each new keyframe, add the landmark observations
made there, :meth:`~IncrementalSmoother.update`, and read the estimate and
marginal covariances. :func:`smooth_batch` builds the same graph for a whole
log and solves it with Levenberg-Marquardt. Both build their factors through
one graph builder (:class:`fusion.graph.GraphBuilder`, which describes
the graph), so the two paths cannot drift apart. Their settings and results
are :class:`SmootherOptions` and :class:`SmootherResult`
(:mod:`fusion.graph.smoother_options`, re-exported here).

:func:`smooth_log` and :func:`smoother_ates` run the whole chain on a recorded
:class:`~lti_motion.recordings.FrameLog` (commands and encoder ticks in,
keyframe poses out), for experiments and comparisons with other estimators.

References
----------
M. Kaess, H. Johannsson, R. Roberts, V. Ila, J. J. Leonard, F. Dellaert,
"iSAM2: Incremental smoothing and mapping using the Bayes tree", Int. J.
Robotics Research 31(2), 2012, pp. 216-235 (algorithms 1-3: fluid
relinearisation, partial re-elimination).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import gtsam
import numpy as np

from fusion.exceptions import UnknownPoseError
from fusion.graph.builder import GraphBuilder
from fusion.graph.factors import calibration_key, pose_key
from fusion.graph.preintegration import Preintegrated, SpeedMode, preintegrate_model
from fusion.graph.smoother_options import (
    SmootherOptions,
    SmootherResult,
    calibration_intrinsics_estimate,
)
from fusion.graph.transient_noise import TransientSpeedCovariance
from fusion.landmark_map import LandmarkMap
from fusion.range_bearing import RangeBearing
from fusion.scale_errors import IntrinsicsEstimate
from lti_motion.calibration.manoeuvres import speeds_from_log
from lti_motion.exceptions import MissingEncoderScaleError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.metrics import ate
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.frames import FrameLog

__all__ = [
    "IncrementalSmoother",
    "SmootherOptions",
    "SmootherResult",
    "calibration_intrinsics_estimate",
    "log_keyframes",
    "smooth_batch",
    "smooth_log",
    "smoother_ates",
]


class IncrementalSmoother:
    """Online smoothing with iSAM2 (Kaess et al. 2012) and the model's motion factors.

    Parameters
    ----------
    initial_pose : array_like, shape (3,)
        ``wTb`` of keyframe 0 ``(x [m], y [m], theta [rad])``.
    options : SmootherOptions, optional
        Graph and solver settings.
    landmarks : fusion.landmark_map.LandmarkMap, optional
        Landmarks with known positions (integer ids), held by a prior of
        ``options.landmark_sigma_m``; others observed become variables.
    first_keyframe : int
        Sample index of keyframe 0 (the motions added must continue from it).

    Raises
    ------
    fusion.exceptions.LandmarkIdError
        If a known landmark's id is not an integer.

    Notes
    -----
    With ``calibrate`` the newest calibration group (up to
    ``options.calibration_every`` intervals) stands as native between-factors
    at the current calibration estimate until it completes; then one
    calibration-aware group factor replaces them (:mod:`fusion.graph.builder`).
    Reads of poses and calibrations between updates see that graph;
    :meth:`result` first puts the open group under its calibration-aware factor.

    Examples
    --------
    >>> from fusion.graph.preintegration import preintegrate
    >>> pre = preintegrate(np.tile([0.2, 0.0], (100, 1)), 0.01, keyframes=[0, 50, 100],
    ...                    speed_covariance=np.eye(2) * 1e-4)
    >>> sm = IncrementalSmoother(initial_pose=np.zeros(3),
    ...                          options=SmootherOptions(calibrate=False))
    >>> sm.add_motion(pre)
    2
    >>> sm.update()
    >>> (sm.result().poses[-1].round(6) + 0.0).tolist()
    [0.2, 0.0, 0.0]
    """

    def __init__(self, *, initial_pose: np.ndarray, options: SmootherOptions | None = None,
                 landmarks: LandmarkMap | None = None, first_keyframe: int = 0) -> None:
        self.options = options or SmootherOptions()
        params = gtsam.ISAM2Params()
        # per variable type; the calibrated factor is linear in (s, g), so the
        # calibrations never need relinearising (Kaess et al. 2012, alg. 3)
        thresholds = gtsam.ISAM2ThresholdMap()
        thr = self.options.relinearize_threshold
        for char, size, value in (("x", 3, thr), ("l", 2, thr),
                                  ("c", self.options.n_calibration, np.inf)):
            thresholds.insert((char, np.full(size, value)))
        params.setRelinearizeThreshold(thresholds)
        params.relinearizeSkip = self.options.relinearize_skip
        self._isam = gtsam.ISAM2(params)
        self._updates = 0
        self._graph = GraphBuilder(initial_pose=initial_pose, first_keyframe=first_keyframe,
                                   options=self.options, landmarks=landmarks)

    @property
    def n_poses(self) -> int:
        """Number of keyframe poses, including any not yet updated."""
        return self._graph.n_poses

    @property
    def keyframes(self) -> np.ndarray:
        """Sample index of each keyframe pose, shape ``(n_poses,)``."""
        return np.array(self._graph.keyframes)

    def add_motion(self, motion: Preintegrated) -> int:
        """Add preintegrated intervals that continue from the last keyframe.

        Returns
        -------
        int
            Index of the newest pose.

        Raises
        ------
        KeyframeOrderError
            If ``motion`` does not start at the last keyframe's sample.
        """
        self._graph.add_motion(motion)
        return self.n_poses - 1

    def add_observations(self, observations: RangeBearing) -> None:
        """Add range-bearing observations (``observations.index`` = keyframe index).

        Rows without a covariance take ``options.landmark_noise`` at their measured range.

        Raises
        ------
        UnknownPoseError
            If an observation names a pose not (yet) in the graph.
        LandmarkIdError
            If a landmark id is not an integer (gtsam keys landmarks as ``L(id)``).
        """
        self._graph.add_observations(observations)

    def update(self, *, iterations: int = 1) -> None:
        """Hand the new factors to iSAM2 and take ``iterations`` incremental steps."""
        graph, values, remove = self._graph.take_pending()
        self._graph.commit(self._isam.update(graph, values, remove).getNewFactorsIndices())
        for _ in range(int(iterations) - 1):
            self._isam.update()
        self._updates += 1
        if self._updates % self.options.reinitialize_every:
            return
        # later keyframes start from the newest estimate, not from dead reckoning
        last = self.n_poses - 1
        self._graph.guess[last] = self._isam.calculateEstimatePose2(pose_key(last))
        if self.options.calibrate:
            key = calibration_key(self._graph.calibration_index(last))
            self._graph.cal_guess = self.options.bounded_calibration(self._calibration_at(key))

    def _flush(self) -> None:
        if self._graph.has_pending:
            self.update()

    def pose(self, index: int) -> np.ndarray:
        """Estimate ``wTb`` of keyframe ``index``, shape (3,)."""
        self._flush()
        p = self._isam.calculateEstimatePose2(pose_key(self._check(index)))
        return np.array([p.x(), p.y(), p.theta()])

    def pose_covariance(self, index: int) -> np.ndarray:
        """Marginal covariance of keyframe ``index`` (Pose2 local coordinates), (3, 3)."""
        self._flush()
        return self._isam.marginalCovariance(pose_key(self._check(index)))

    def _calibration_at(self, key: int) -> np.ndarray:
        if self.options.n_calibration == 2:
            return np.asarray(self._isam.calculateEstimatePoint2(key))
        return np.asarray(self._isam.calculateEstimatePoint3(key))

    def calibration(self, index: int) -> np.ndarray:
        """Estimate of ``(s, g)`` (or ``(s, g, kappa)``) in force at keyframe ``index``, (nc,)."""
        key = self._calibration_key(index)
        self._flush()
        return self._calibration_at(key)

    def calibration_covariance(self, index: int) -> np.ndarray:
        """Marginal covariance of the calibration at keyframe ``index``, (nc, nc)."""
        key = self._calibration_key(index)
        self._flush()
        return self._isam.marginalCovariance(key)

    def intrinsics_estimate(self, intrinsics: OdometryIntrinsics, *, index: int = -1,
                            t_s: float = math.nan) -> IntrinsicsEstimate:
        """The odometry intrinsics the calibration at keyframe ``index`` says the robot has.

        Parameters
        ----------
        intrinsics : OdometryIntrinsics
            The intrinsics the encoder speeds of the preintegrated motion were
            computed with (the calibration is relative to them).
        index : int
            Keyframe (negative counts from the newest).
        t_s : float
            Time of the estimate [s], for the record.

        Returns
        -------
        IntrinsicsEstimate
            As :meth:`fusion.ekf.ModelEKF.intrinsics_estimate`, from the scale errors
            ``(s - 1, g - 1, kappa)`` and their marginal covariance
            (:func:`fusion.graph.calibration_intrinsics_estimate`); write it into a
            model with :meth:`lti_motion.model.MotionModel.with_intrinsics`.

        Raises
        ------
        ValueError
            Without ``calibrate``, or if the estimate is not a possible robot.
        UnknownPoseError
            For a keyframe not in the graph.
        """
        i = self.n_poses + int(index) if int(index) < 0 else int(index)
        return calibration_intrinsics_estimate(intrinsics, self.calibration(i),
                                               self.calibration_covariance(i), t_s=t_s)

    def result(self, *, covariances: bool = True) -> SmootherResult:
        """The whole current estimate (marginals cost one Bayes-tree query per variable).

        First puts the open calibration group under its calibration-aware
        factor (one Python linearisation; the group is replaced again when it grows).
        """
        if self.options.calibrate:
            self._graph.close_open_group()
        self._flush()
        return self._graph.result(self._isam.calculateEstimate(),
                                  self._isam.marginalCovariance if covariances else None)

    def _check(self, index: int) -> int:
        if not 0 <= int(index) < self.n_poses:
            raise UnknownPoseError(f"no keyframe {index}; the graph holds 0 .. {self.n_poses - 1}")
        return int(index)

    def _calibration_key(self, index: int) -> int:
        if not self.options.calibrate:
            raise ValueError("this smoother does not estimate the calibration "
                             "(SmootherOptions(calibrate=False))")
        return calibration_key(self._graph.calibration_index(self._check(index)))


def smooth_batch(motion: Preintegrated, *, initial_pose: np.ndarray,
                 observations: RangeBearing | None = None, landmarks: LandmarkMap | None = None,
                 options: SmootherOptions | None = None,
                 initial_guess: SmootherResult | None = None, covariances: bool = True,
                 max_iterations: int = 100) -> SmootherResult:
    """Smooth a whole log at once with Levenberg-Marquardt.

    Parameters
    ----------
    motion : Preintegrated
        All keyframe intervals (pose ``k`` is ``motion.keyframes[k]``).
    initial_pose : array_like, shape (3,)
        ``wTb`` of the first keyframe (held by the prior).
    observations : RangeBearing, optional
        ``index`` = keyframe index.
    landmarks : fusion.landmark_map.LandmarkMap, optional
        Known landmarks (integer ids).
    options : SmootherOptions, optional
        Graph settings (the iSAM2 ones are ignored).
    initial_guess : SmootherResult, optional
        Start poses (and calibrations) instead of dead reckoning, e.g. an
        :class:`IncrementalSmoother` result for a long log.
    covariances : bool
        Compute marginal covariances (``gtsam.Marginals``).
    max_iterations : int
        Levenberg-Marquardt iteration limit.

    Returns
    -------
    SmootherResult

    Raises
    ------
    UnknownPoseError
        For an observation of a pose beyond the last keyframe.
    """
    opts = options or SmootherOptions()
    g = GraphBuilder(initial_pose=initial_pose, first_keyframe=int(motion.keyframes[0]),
                     options=opts, landmarks=landmarks)
    g.add_motion(motion)
    if observations is not None:
        g.add_observations(observations)
    if opts.calibrate:
        g.close_open_group()
    graph, values, _ = g.take_pending()
    if initial_guess is not None:
        for i, p in enumerate(initial_guess.poses[:g.n_poses]):
            values.update(pose_key(i), gtsam.Pose2(*p))
        if opts.calibrate and initial_guess.calibrations is not None:
            for i, c in enumerate(initial_guess.calibrations[:g.n_poses]):
                values.update(calibration_key(g.calibration_index(i)), np.asarray(c))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(int(max_iterations))
    solution = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    marginals = gtsam.Marginals(graph, solution) if covariances else None
    return g.result(solution, marginals.marginalCovariance if marginals else None)


def log_keyframes(n_samples: int, *, every: int, extra: np.ndarray | Sequence[int] = ()
                  ) -> np.ndarray:
    """Keyframe sample indices: every ``every`` samples, the end, and ``extra`` ones.

    Examples
    --------
    >>> log_keyframes(10, every=4, extra=[5]).tolist()
    [0, 4, 5, 8, 10]
    """
    if int(every) < 1 or int(n_samples) < 1:
        raise ValueError(f"need n_samples >= 1 and every >= 1, got {n_samples} and {every}")
    extra = np.asarray(extra, dtype=np.int64).reshape(-1)
    if extra.size and (extra.min() < 0 or extra.max() > n_samples):
        raise UnknownPoseError(f"keyframes requested at samples {extra.min()} .. {extra.max()}, "
                               f"outside 0 .. {n_samples}")
    return np.unique(np.concatenate([np.arange(0, n_samples, int(every)), [n_samples], extra]))


def smooth_log(model: MotionModel, log: FrameLog, *, initial_pose: np.ndarray,
               observations: RangeBearing | None = None, landmarks: LandmarkMap | None = None,
               keyframe_every: int = 33, mode: SpeedMode = "free_run",
               covariance_scale: float = 1.0,
               speed_covariance: np.ndarray | TransientSpeedCovariance | None = None,
               options: SmootherOptions | None = None,
               method: Literal["isam2", "batch"] = "isam2", covariances: bool = False
               ) -> SmootherResult:
    """Run the model and the smoother over a recorded single-robot log.

    Parameters
    ----------
    model : MotionModel
        Calibrated model with its encoder scale (``m_per_tick``).
    log : FrameLog
        One robot's frames; frame ``k``'s pose is keyframe sample ``k``.
    initial_pose : array_like, shape (3,)
        ``wTb`` at frame 0.
    observations : RangeBearing, optional
        With ``index`` = *frame* index; a keyframe is placed at each.
    landmarks : fusion.landmark_map.LandmarkMap, optional
        Known landmarks (integer ids).
    keyframe_every : int
        Samples between regular keyframes (33 is 0.5 s on a Create 2).
    mode : {"free_run", "one_step", "filtered"}
        Sensor-less speeds, the one-step predictor with the encoders, or the
        model's Kalman-filtered speeds (:func:`~fusion.graph.preintegrate_model`).
    covariance_scale : float
        Factor on the speed-error covariance.
    speed_covariance : array_like, shape (2, 2), or TransientSpeedCovariance, optional
        Speed-error covariance instead of the model's own, e.g. measured on
        the calibration logs (:func:`fusion.graph.speed_covariance_from_data`,
        or conditioned on the model's transients:
        :func:`fusion.graph.transient_speed_covariance_from_data`).
    options : SmootherOptions, optional
        Graph settings.
    method : {"isam2", "batch"}
        One iSAM2 update per keyframe, or Levenberg-Marquardt on the whole log.
    covariances : bool
        Compute marginal covariances.

    Returns
    -------
    SmootherResult
        ``keyframes`` are frame indices.

    Raises
    ------
    MissingEncoderScaleError
        If the model has no encoder scale.
    ValueError
        If ``method`` is unknown.
    UnknownPoseError
        If an observation's frame is beyond the log.
    """
    if model.m_per_tick is None:
        raise MissingEncoderScaleError.needed_by("smoothing a log (speeds from its counts)")
    if method not in ("isam2", "batch"):
        raise ValueError(f"method must be 'isam2' or 'batch', got {method!r}")
    if model.intrinsics is None:
        u, y = speeds_from_log(log, m_per_tick=model.m_per_tick, wheel_base_m=model.wheel_base_m)
    else:                                   # each wheel's own scale (docs/intrinsics.md)
        u, y = speeds_from_log(log, intrinsics=model.intrinsics)
    frames = np.zeros(0, np.int64) if observations is None else observations.index
    kf = log_keyframes(len(u), every=keyframe_every, extra=frames)
    opts = options or SmootherOptions()
    pre = preintegrate_model(model, u, keyframes=kf, mode=mode, measured_speeds=y,
                             covariance_scale=covariance_scale,
                             speed_covariance=speed_covariance,
                             calibration=(1.0, 1.0, 0.0)[:opts.n_calibration])
    obs = None if observations is None else observations.with_index(
        np.searchsorted(kf, observations.index))
    if method == "batch":
        return smooth_batch(pre, initial_pose=initial_pose, observations=obs, landmarks=landmarks,
                            options=options, covariances=covariances)
    sm = IncrementalSmoother(initial_pose=initial_pose, options=options, landmarks=landmarks)
    bounds = np.zeros(len(kf) + 1, np.int64)
    if obs is not None:
        order = np.argsort(obs.index, kind="stable")
        obs = obs.select(order)
        bounds = np.searchsorted(obs.index, np.arange(len(kf) + 1))
    for k in range(len(kf)):
        if k > 0:
            sm.add_motion(pre[k - 1])
        if obs is not None and bounds[k + 1] > bounds[k]:
            sm.add_observations(obs.select(slice(bounds[k], bounds[k + 1])))
        sm.update()
    return sm.result(covariances=covariances)


def smoother_ates(model: MotionModel, logs: Sequence[FrameLog],
                  observations: Sequence[RangeBearing | None], **options: object) -> np.ndarray:
    """Absolute trajectory error of the smoother on each of several simulated runs.

    Parameters
    ----------
    model : MotionModel
        Calibrated model.
    logs : sequence of FrameLog
        Single-robot logs with ground truth (``true_pose``).
    observations : sequence of RangeBearing or None
        Per log, with ``index`` = frame index (the same observations an
        EKF would be given, for a like-for-like comparison).
    **options
        Passed to :func:`smooth_log` (``landmarks``, ``mode``, ``options`` ...).
        The start pose is the true pose at frame 0, as any estimator compared
        on these runs is given.

    Returns
    -------
    ndarray, shape (len(logs),)
        ATE [m] (RMSE of keyframe positions, no alignment: landmarks fix the frame).
    """
    if len(logs) != len(observations):
        raise ValueError(f"{len(logs)} logs but {len(observations)} observation sets")
    out = np.empty(len(logs))
    for r, (log, obs) in enumerate(zip(logs, observations, strict=True)):
        if log.true_pose is None:
            raise ValueError(f"log {r} has no ground truth (true_pose)")
        res = smooth_log(model, log, initial_pose=log.true_pose[0], observations=obs,
                         **options)
        out[r] = ate(log.true_pose[res.keyframes], res.poses)
    return out
