"""Smoothing with preintegrated model factors and landmarks: iSAM2 online, LM in batch.

:class:`IncrementalSmoother` wraps ``gtsam.ISAM2`` (Kaess et al. 2012): add the
preintegrated motion up to each new keyframe, add the landmark observations
made there, :meth:`~IncrementalSmoother.update`, and read the estimate and
marginal covariances. :func:`smooth_batch` builds the same graph for a whole
log and solves it with Levenberg-Marquardt. Both build their factors through
one private graph builder, so the two paths cannot drift apart.

The graph: a prior on the first pose; one motion factor per keyframe interval
(:func:`~fusion.factors.motion_factor`, or with ``calibrate=True``
:func:`~fusion.factors.calibrated_motion_factor` on a calibration variable
``(s, g)`` shared by ``calibration_every`` consecutive intervals, with a prior
on the first and a random walk :func:`~fusion.factors.calibration_walk_factor`
between them); range-bearing factors to landmark variables, known landmarks
held by a prior (:class:`~fusion.factors.LandmarkMap`), unknown ones
initialised from their first observation.

:func:`smooth_log` and :func:`smoother_ates` run the whole chain on a recorded
:class:`~lti_motion.frames.FrameLog` (commands and encoder ticks in,
keyframe poses out), for experiments and comparisons with other estimators.

References
----------
M. Kaess, H. Johannsson, R. Roberts, V. Ila, J. J. Leonard, F. Dellaert,
"iSAM2: Incremental smoothing and mapping using the Bayes tree", Int. J.
Robotics Research 31(2), 2012, pp. 216-235 (algorithms 1-3: fluid
relinearisation, partial re-elimination).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import gtsam
import numpy as np

from fusion.factors import (
    CONSTANT_SIGMA_M,
    LandmarkMap,
    RangeBearing,
    calibrated_motion_factor,
    calibration_key,
    calibration_walk_factor,
    landmark_key,
    motion_factor,
    pose_key,
    range_bearing_factor,
)
from fusion.preintegration import (
    KeyframeOrderError,
    Preintegrated,
    SpeedMode,
    UnknownPoseError,
    preintegrate_model,
)
from lti_motion.calibration import speeds_from_log
from lti_motion.frames import FrameLog
from lti_motion.metrics import ate
from lti_motion.model import MotionModel

__all__ = [
    "IncrementalSmoother",
    "SmootherOptions",
    "SmootherResult",
    "log_keyframes",
    "smooth_batch",
    "smooth_log",
    "smoother_ates",
]


def _positive_tuple(value: Sequence[float], n: int, name: str) -> tuple[float, ...]:
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"{name} must be {n} positive numbers, got {value!r}")
    return tuple(float(a) for a in arr)


@dataclass(frozen=True)
class SmootherOptions:
    """How the graph is built and solved.

    Attributes
    ----------
    initial_pose_sigmas : (float, float, float)
        Prior standard deviations on the first pose (x [m], y [m], theta [rad]).
    calibrate : bool
        Use the calibration-aware motion factor and estimate ``(s, g)``.
    calibration_prior : (float, float)
        Prior mean of ``(s, g)``.
    calibration_prior_sigmas : (float, float)
        Prior standard deviations of ``(s, g)``: wide (0.2) by default, the
        robot may have changed since calibration.
    calibration_walk_sigmas : (float, float)
        Random-walk diffusion of ``(s, g)`` [1/sqrt(s)]: ``1e-3`` lets them
        move by 0.8% (1 sigma) a minute. On the simulator with landmarks this
        follows a floor change (4%) within about a minute and still pins a
        constant scale to 0.5% in a minute; ``3e-3`` follows faster but
        forgets faster (about 1% scatter at 60 s).
    calibration_every : int
        Consecutive keyframe intervals that share one calibration variable.
        Fewer variables keep iSAM2 fast (benchmark ``graph``); at 0.5 s
        keyframes, 10 means a new calibration every 5 s.
    relinearize_threshold : float
        iSAM2 relinearises a pose or landmark whose update exceeds this
        (tangent units, m and rad); calibrations never need it (the factor
        is linear in them). GTSAM's default; 0.01 gave the same accuracy on
        the acceptance runs at up to 1.6x the time.
    relinearize_skip : int
        iSAM2 checks for relinearisation every this many updates.
    landmark_huber_k : float or None
        Huber threshold (in standard deviations of the whitened error) of a
        robust kernel on the range-bearing factors (``gtsam.noiseModel.Robust``
        with ``mEstimator.Huber``; Huber 1964): beyond ``k`` sigma a detection
        weighs as if its error grew linearly, not quadratically, so outliers
        (the EKF gates them) cannot drag the path. ``None``: plain Gaussian.
        The kernel's weights follow the linearisation point, so use it with a
        small ``relinearize_threshold`` (1e-3 with ``relinearize_skip=1``).
    reinitialize_every : int
        Every this many updates, the newest pose and calibration are read
        back from iSAM2 to start the next keyframes from (in between, new
        poses start from dead reckoning off the last read-back). Reading an
        estimate back solves the Bayes tree; doing it at every update
        doubles the cost of a long smoothing run (benchmark ``graph``).
    """

    initial_pose_sigmas: tuple[float, float, float] = (1e-3, 1e-3, 1e-3)
    calibrate: bool = True
    calibration_prior: tuple[float, float] = (1.0, 1.0)
    calibration_prior_sigmas: tuple[float, float] = (0.2, 0.2)
    calibration_walk_sigmas: tuple[float, float] = (1e-3, 1e-3)
    calibration_every: int = 10
    relinearize_threshold: float = 0.1
    relinearize_skip: int = 10
    landmark_huber_k: float | None = None
    reinitialize_every: int = 10

    def __post_init__(self) -> None:
        setf = object.__setattr__
        setf(self, "initial_pose_sigmas",
             _positive_tuple(self.initial_pose_sigmas, 3, "initial_pose_sigmas"))
        setf(self, "calibration_prior",
             _positive_tuple(self.calibration_prior, 2, "calibration_prior"))
        for name in ("calibration_prior_sigmas", "calibration_walk_sigmas"):
            setf(self, name, _positive_tuple(getattr(self, name), 2, name))
        for name in ("calibration_every", "relinearize_skip", "reinitialize_every"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        k = self.landmark_huber_k
        if k is not None and not (np.isfinite(k) and k > 0):
            raise ValueError(f"landmark_huber_k must be positive or None, got {k}")
        if not (np.isfinite(self.relinearize_threshold) and self.relinearize_threshold > 0):
            raise ValueError(f"relinearize_threshold must be positive, got "
                             f"{self.relinearize_threshold}")


@dataclass(frozen=True, eq=False)
class SmootherResult:
    """The smoothed estimate at the keyframes.

    Attributes
    ----------
    keyframes : ndarray of int, shape (n,)
        Sample index of each keyframe pose.
    poses : ndarray, shape (n, 3)
        ``wTb`` per keyframe ``(x [m], y [m], theta [rad])``, theta in (-pi, pi].
    pose_covariances : ndarray, shape (n, 3, 3), or None
        Marginal covariances in gtsam ``Pose2`` local coordinates (body frame).
    calibrations : ndarray, shape (n, 2), or None
        ``(s, g)`` in force at each keyframe (``None`` without ``calibrate``).
    calibration_covariances : ndarray, shape (n, 2, 2), or None
        Their marginal covariances.
    landmark_ids : ndarray of int, shape (k,)
        Landmarks in the graph.
    landmarks_xy : ndarray, shape (k, 2)
        Their estimated positions [m].
    """

    keyframes: np.ndarray
    poses: np.ndarray
    pose_covariances: np.ndarray | None
    calibrations: np.ndarray | None
    calibration_covariances: np.ndarray | None
    landmark_ids: np.ndarray
    landmarks_xy: np.ndarray


class _Graph:
    """Keys, initial guesses and the factors not yet handed to an optimiser."""

    def __init__(self, *, initial_pose: np.ndarray, first_keyframe: int,
                 options: SmootherOptions, landmarks: LandmarkMap | None) -> None:
        self.opts = options
        pose0 = gtsam.Pose2(*np.asarray(initial_pose, dtype=float).reshape(3))
        self.keyframes: list[int] = [int(first_keyframe)]
        self.guess: list[gtsam.Pose2] = [pose0]
        self.pending = gtsam.NonlinearFactorGraph()
        self.values = gtsam.Values()
        self.known: dict[int, np.ndarray] = {} if landmarks is None else dict(
            zip(landmarks.ids.tolist(), landmarks.xy_m, strict=True))
        self.known_sigma = (landmarks.sigma_m if landmarks is not None and landmarks.sigma_m
                            else CONSTANT_SIGMA_M)
        self.landmarks: dict[int, None] = {}            # ids in the graph, in insertion order
        self.cal_guess = np.array(options.calibration_prior)
        self.group_duration_s = 0.0
        self.pending.add(gtsam.PriorFactorPose2(
            pose_key(0), pose0, gtsam.noiseModel.Diagonal.Sigmas(options.initial_pose_sigmas)))
        self.values.insert(pose_key(0), pose0)
        if options.calibrate:
            self.pending.add(gtsam.PriorFactorPoint2(
                calibration_key(0), self.cal_guess,
                gtsam.noiseModel.Diagonal.Sigmas(options.calibration_prior_sigmas)))
            self.values.insert(calibration_key(0), self.cal_guess)

    @property
    def n_poses(self) -> int:
        return len(self.keyframes)

    def calibration_index(self, pose: int) -> int:
        """Calibration variable in force at ``pose`` (that of its outgoing interval)."""
        last_interval = max(self.n_poses - 2, 0)
        return min(pose, last_interval) // self.opts.calibration_every

    def add_motion(self, pre: Preintegrated) -> None:
        if int(pre.keyframes[0]) != self.keyframes[-1]:
            raise KeyframeOrderError(
                f"motion starts at sample {int(pre.keyframes[0])} but the last keyframe is at "
                f"sample {self.keyframes[-1]}; add intervals in order, without gaps")
        opts = self.opts
        for k in range(len(pre)):
            i = self.n_poses - 1
            key_i, key_j = pose_key(i), pose_key(i + 1)
            delta = gtsam.Pose2(*pre.delta_pose[k])
            if opts.calibrate:
                group = i // opts.calibration_every
                if i > 0 and i % opts.calibration_every == 0:
                    self.pending.add(calibration_walk_factor(
                        calibration_key(group - 1), calibration_key(group),
                        sigma_per_sqrt_s=opts.calibration_walk_sigmas,
                        duration_s=self.group_duration_s))
                    self.values.insert(calibration_key(group), self.cal_guess)
                    self.group_duration_s = 0.0
                self.group_duration_s += float(pre.duration_s[k])
                self.pending.add(calibrated_motion_factor(pre, k, key_i=key_i, key_j=key_j,
                                                          key_c=calibration_key(group)))
                # start the new pose where the current calibration puts it (first order)
                correction = pre.calibration_jacobian[k] @ (self.cal_guess - pre.calibration)
                delta = delta.compose(gtsam.Pose2.Expmap(correction))
            else:
                self.pending.add(motion_factor(pre, k, key_i=key_i, key_j=key_j))
            guess = self.guess[i].compose(delta)
            self.guess.append(guess)
            self.values.insert(key_j, guess)
            self.keyframes.append(int(pre.keyframes[k + 1]))

    def add_observations(self, obs: RangeBearing) -> None:
        bad = (obs.pose_index < 0) | (obs.pose_index >= self.n_poses)
        if np.any(bad):
            first = int(obs.pose_index[np.argmax(bad)])
            raise UnknownPoseError(
                f"observation of pose {first}, but the graph holds poses 0 .. "
                f"{self.n_poses - 1}; add the motion up to that keyframe first")
        noise = gtsam.noiseModel.Diagonal.Sigmas([obs.bearing_sigma_rad, obs.range_sigma_m])
        if self.opts.landmark_huber_k is not None:
            noise = gtsam.noiseModel.Robust.Create(
                gtsam.noiseModel.mEstimator.Huber.Create(self.opts.landmark_huber_k), noise)
        for p, lid, b, r in zip(obs.pose_index.tolist(), obs.landmark_id.tolist(),
                                obs.bearing_rad.tolist(), obs.range_m.tolist(), strict=True):
            key = landmark_key(lid)
            if lid not in self.landmarks:
                if lid in self.known:
                    xy = self.known[lid]
                    self.pending.add(gtsam.PriorFactorPoint2(
                        key, xy, gtsam.noiseModel.Isotropic.Sigma(2, self.known_sigma)))
                else:   # unknown landmark: where its first observation puts it
                    xy = self.guess[p].transformFrom(np.array([r * np.cos(b), r * np.sin(b)]))
                self.values.insert(key, np.asarray(xy, dtype=float))
                self.landmarks[lid] = None
            self.pending.add(range_bearing_factor(b, r, key_pose=pose_key(p), key_landmark=key,
                                                  noise=noise))

    def take_pending(self) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        out = self.pending, self.values
        self.pending, self.values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        return out

    def result(self, values: gtsam.Values,
               covariance: Callable[[int], np.ndarray] | None) -> SmootherResult:
        """Read poses, calibrations and landmarks; ``covariance(key)`` gives marginals."""
        n = self.n_poses
        poses = np.array([[p.x(), p.y(), p.theta()]
                          for p in (values.atPose2(pose_key(i)) for i in range(n))])
        cal_idx = np.array([self.calibration_index(i) for i in range(n)])
        cals = cal_cov = pose_cov = None
        if self.opts.calibrate:
            table = np.array([values.atPoint2(calibration_key(g))
                              for g in range(cal_idx.max() + 1)])
            cals = table[cal_idx]
        if covariance is not None:
            pose_cov = np.array([covariance(pose_key(i)) for i in range(n)])
            if self.opts.calibrate:
                cov_table = np.array([covariance(calibration_key(g))
                                      for g in range(cal_idx.max() + 1)])
                cal_cov = cov_table[cal_idx]
        ids = np.array(list(self.landmarks), dtype=np.int64)
        xy = np.array([values.atPoint2(landmark_key(i)) for i in ids]).reshape(-1, 2)
        return SmootherResult(np.array(self.keyframes), poses, pose_cov, cals, cal_cov, ids, xy)


class IncrementalSmoother:
    """Online smoothing with iSAM2 (Kaess et al. 2012) and the model's motion factors.

    Parameters
    ----------
    initial_pose : array_like, shape (3,)
        ``wTb`` of keyframe 0 ``(x [m], y [m], theta [rad])``.
    options : SmootherOptions, optional
        Graph and solver settings.
    landmarks : LandmarkMap, optional
        Landmarks with known positions; others observed become variables.
    first_keyframe : int
        Sample index of keyframe 0 (the motions added must continue from it).

    Examples
    --------
    >>> from fusion.preintegration import preintegrate
    >>> pre = preintegrate(np.tile([0.2, 0.0], (100, 1)), 0.01, keyframes=[0, 50, 100],
    ...                    speed_covariance=np.eye(2) * 1e-4)
    >>> sm = IncrementalSmoother(initial_pose=np.zeros(3),
    ...                          options=SmootherOptions(calibrate=False))
    >>> sm.add_motion(pre)
    2
    >>> sm.update()
    >>> sm.result().poses[-1].round(6).tolist()
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
        for char, size, value in (("x", 3, thr), ("l", 2, thr), ("c", 2, np.inf)):
            thresholds.insert((char, np.full(size, value)))
        params.setRelinearizeThreshold(thresholds)
        params.relinearizeSkip = self.options.relinearize_skip
        self._isam = gtsam.ISAM2(params)
        self._updates = 0
        self._graph = _Graph(initial_pose=initial_pose, first_keyframe=first_keyframe,
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
        """Add range-bearing observations (``pose_index`` = keyframe index).

        Raises
        ------
        UnknownPoseError
            If an observation names a pose not (yet) in the graph.
        """
        self._graph.add_observations(observations)

    def update(self, *, iterations: int = 1) -> None:
        """Hand the new factors to iSAM2 and take ``iterations`` incremental steps."""
        graph, values = self._graph.take_pending()
        self._isam.update(graph, values)
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
            self._graph.cal_guess = np.asarray(self._isam.calculateEstimatePoint2(key))

    def _flush(self) -> None:
        if self._graph.pending.size() or self._graph.values.size():
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

    def calibration(self, index: int) -> np.ndarray:
        """Estimate of ``(s, g)`` in force at keyframe ``index``, shape (2,)."""
        key = self._calibration_key(index)
        self._flush()
        return np.asarray(self._isam.calculateEstimatePoint2(key))

    def calibration_covariance(self, index: int) -> np.ndarray:
        """Marginal covariance of ``(s, g)`` at keyframe ``index``, (2, 2)."""
        key = self._calibration_key(index)
        self._flush()
        return self._isam.marginalCovariance(key)

    def result(self, *, covariances: bool = True) -> SmootherResult:
        """The whole current estimate (marginals cost one Bayes-tree query per variable)."""
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
        ``pose_index`` = keyframe index.
    landmarks : LandmarkMap, optional
        Known landmarks.
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
    g = _Graph(initial_pose=initial_pose, first_keyframe=int(motion.keyframes[0]), options=opts,
               landmarks=landmarks)
    g.add_motion(motion)
    if observations is not None:
        g.add_observations(observations)
    graph, values = g.take_pending()
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
               covariance_scale: float = 1.0, speed_covariance: np.ndarray | None = None,
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
        With ``pose_index`` = *frame* index; a keyframe is placed at each.
    landmarks : LandmarkMap, optional
        Known landmarks.
    keyframe_every : int
        Samples between regular keyframes (33 is 0.5 s on a Create 2).
    mode : {"free_run", "one_step", "filtered"}
        Sensor-less speeds, the one-step predictor with the encoders, or the
        model's Kalman-filtered speeds (:func:`~fusion.preintegration.preintegrate_model`).
    covariance_scale : float
        Factor on the speed-error covariance.
    speed_covariance : array_like, shape (2, 2), optional
        Speed-error covariance instead of the model's own, e.g. measured on
        the calibration log (:func:`fusion.graph_noise.speed_covariance_from_data`).
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
    ValueError
        If the model has no encoder scale or ``method`` is unknown.
    UnknownPoseError
        If an observation's frame is beyond the log.
    """
    if model.m_per_tick is None:
        raise ValueError("the model has no encoder scale (m_per_tick); calibrate it first")
    if method not in ("isam2", "batch"):
        raise ValueError(f"method must be 'isam2' or 'batch', got {method!r}")
    u, y = speeds_from_log(log, m_per_tick=model.m_per_tick, wheel_base_m=model.wheel_base_m)
    frames = np.zeros(0, np.int64) if observations is None else observations.pose_index
    kf = log_keyframes(len(u), every=keyframe_every, extra=frames)
    pre = preintegrate_model(model, u, keyframes=kf, mode=mode, y_measured=y,
                             covariance_scale=covariance_scale,
                             speed_covariance=speed_covariance)
    obs = None if observations is None else observations.with_pose_index(
        np.searchsorted(kf, observations.pose_index))
    if method == "batch":
        return smooth_batch(pre, initial_pose=initial_pose, observations=obs, landmarks=landmarks,
                            options=options, covariances=covariances)
    sm = IncrementalSmoother(initial_pose=initial_pose, options=options, landmarks=landmarks)
    bounds = np.zeros(len(kf) + 1, np.int64)
    if obs is not None:
        order = np.argsort(obs.pose_index, kind="stable")
        obs = obs.select(order)
        bounds = np.searchsorted(obs.pose_index, np.arange(len(kf) + 1))
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
        Per log, with ``pose_index`` = frame index (the same observations an
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
