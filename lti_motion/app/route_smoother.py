"""The smoother row of the route (Table II): an online iSAM2 smoother per robot, in lock step.

:class:`SmootherEstimator` satisfies the route's
:class:`~lti_motion.app.route.Estimator` protocol for ``N`` robots. Per robot it
keeps one :class:`fusion.graph.IncrementalSmoother` (iSAM2, Kaess et al. 2012) whose
keyframes are placed every ``keyframe_s`` seconds and at every period with landmark
observations. The motion between keyframes is the model's encoder-filtered speeds,
preintegrated (:func:`fusion.graph.preintegrate_model` with ``mode="filtered"``,
as ``examples/aruco_end_to_end.py`` does); each observation is a range-bearing factor to a
known landmark. One iSAM2 update per keyframe.

Between keyframes the route still needs a pose every period: the newest keyframe's
smoothed pose, advanced by the encoder speeds (paper eq. 11,
:func:`lti_motion.kinematics.pose_step`; the filtered speeds equal them to within
``1 - W``, about 2e-6) corrected by the newest calibration estimate: ``(s v, g w)``, or
``(s v, g w + kappa v)`` when the options estimate the curvature ``kappa`` of a wheel
diameter ratio (:meth:`fusion.graph.SmootherOptions.with_curvature`; then
:meth:`SmootherEstimator.intrinsics_estimates` gives the intrinsics it implies, as the
model EKF's :meth:`~fusion.ekf.ModelEKF.intrinsics_estimate` does).
At a keyframe the pose jumps to the smoother's estimate. The estimator sees what the robot
reports (commands, encoder counts) and the landmark sensor, never the simulator's truth.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from fusion.graph import IncrementalSmoother, SmootherOptions, preintegrate_model
from fusion.landmark_map import LandmarkMap
from fusion.noise import LandmarkNoise
from fusion.range_bearing import RangeBearing
from fusion.scale_errors import IntrinsicsEstimate
from lti_motion.exceptions import MissingEncoderScaleError, ShapeError
from lti_motion.kinematics import body_from_wheel, pose_step
from lti_motion.model import MotionModel
from lti_motion.recordings import SensorFrame, tick_deltas

__all__ = ["ROUTE_SMOOTHER_OPTIONS", "SmootherEstimator"]

_log = logging.getLogger(__name__)

#: Graph settings, like for like with the route's EKF (:class:`fusion.ekf.ModelEKF`
#: defaults): start pose prior 5 mm / 5 mm / 5 mrad (the EKF's ``pose_std``), a calibration
#: ``(s, g)`` of ground against encoder speeds with the EKF's scale-error prior (1%) and
#: random walk (1e-4 per sqrt(s), :class:`fusion.ekf.functions.ScaleErrors`). Plain Gaussian
#: range-bearing factors: the route's sensor noise is Gaussian with known spread (the
#: ArUco example's Huber kernel is for real detections' outliers).
ROUTE_SMOOTHER_OPTIONS = SmootherOptions(initial_pose_sigmas=(0.005, 0.005, 0.005),
                                         calibration_prior_sigmas=(0.01, 0.01),
                                         calibration_walk_sigmas=(1e-4, 1e-4))


class SmootherEstimator:
    """One :class:`~fusion.graph.IncrementalSmoother` per robot, keyframed, in lock step.

    Parameters
    ----------
    model : MotionModel
        Calibrated model with its encoder scale (``m_per_tick``).
    landmarks : LandmarkMap, optional
        Known landmarks (integer ids); observations of other ids are dropped and counted
        in :attr:`dropped_observations`. Without a map, observations are ignored.
    landmark_noise : LandmarkNoise, optional
        The range-bearing sensor's noise (the route's default :class:`LandmarkNoise`);
        it replaces ``options.landmark_noise`` when given.
    keyframe_s : float
        Longest time between keyframes [s] (0.5 s: 33 periods of 15 ms, as
        ``examples/factor_graph.py``); periods with observations are keyframes as well.
    options : SmootherOptions, optional
        Graph and iSAM2 settings (:data:`ROUTE_SMOOTHER_OPTIONS`), the sighting noise
        included; ``ROUTE_SMOOTHER_OPTIONS.with_curvature(wheel_base_m=...)`` estimates
        the wheels' diameter ratio as well (module notes).

    Raises
    ------
    MissingEncoderScaleError
        If the model has no encoder scale.
    ValueError
        If ``keyframe_s`` is shorter than one period.
    TypeError
        If ``landmarks`` or ``landmark_noise`` has the wrong type.

    Notes
    -----
    Sample ``j`` of a robot is the period closed by its ``j``-th frame after the first
    (which anchors the encoder counts); keyframe ``k`` is the pose after sample
    ``keyframes[k]``. Encoder body speeds as :class:`~lti_motion.app.route.ArxHybrid`
    reads them (tick increments times the scale, over the model's period; through the
    model's per-wheel :attr:`~lti_motion.model.MotionModel.intrinsics` when it has
    them, e.g. written back from :meth:`intrinsics_estimates`). Each interval
    is preintegrated from the filtered speeds ``s+ = s- + W (y - s-)``
    (:func:`fusion.graph.filtered_speeds`, Simon 2006 eq. 5.19), starting from the
    model state its predecessor ended in (:meth:`MotionModel.state_from_data`, the
    one-step predictor, Ljung 1999 sec. 4.3), so consecutive intervals continue one
    another. A range-bearing factor's range sigma is the sensor's at the *measured*
    range (the EKF takes the predicted one; 2% of 2% apart).

    Examples
    --------
    One robot driving straight, 3 ticks of 1 mm per 15 ms period, keyframes every 4 periods:

    >>> from lti_motion.model.fir import FirFit
    >>> model = MotionModel.from_fir(
    ...     FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
    ...            residual_cov=np.eye(2) * 1e-6, n_samples=100, source="steps"),
    ...     dt_s=0.015, wheel_base_m=0.25, m_per_tick=0.001,
    ...     calibrated_at="2026-01-01T00:00:00+00:00")
    >>> est = SmootherEstimator(model, keyframe_s=0.06)
    >>> est.reset(1, np.zeros((1, 3)))
    >>> for k in range(11):
    ...     frame = SensorFrame(t_s=0.015 * k, ticks=np.full((1, 2), 3 * k),
    ...                         light_bump=np.zeros((1, 6), int), bumps=np.zeros((1, 2), bool),
    ...                         cmd_m_s=np.full((1, 2), 0.2))
    ...     pose = est.step(frame, np.full((1, 2), 0.2))
    >>> (pose.round(4) + 0.0).tolist(), est.smoothers[0].keyframes.tolist()
    ([[0.03, 0.0, 0.0]], [0, 4, 8])

    References
    ----------
    M. Kaess et al., "iSAM2: Incremental smoothing and mapping using the Bayes tree",
    IJRR 31(2), 2012, pp. 216-235.
    """

    def __init__(self, model: MotionModel, *, landmarks: LandmarkMap | None = None,
                 landmark_noise: LandmarkNoise | None = None, keyframe_s: float = 0.5,
                 options: SmootherOptions | None = None) -> None:
        if not isinstance(model, MotionModel):
            raise TypeError(f"model must be a MotionModel, got {type(model).__name__}")
        if model.m_per_tick is None:
            raise MissingEncoderScaleError.needed_by("the smoother's encoder keyframes")
        if landmarks is not None and not isinstance(landmarks, LandmarkMap):
            raise TypeError(f"landmarks must be a fusion.landmark_map.LandmarkMap, got "
                            f"{type(landmarks).__name__}")
        if landmark_noise is not None and not isinstance(landmark_noise, LandmarkNoise):
            raise TypeError(f"landmark_noise must be a LandmarkNoise, got "
                            f"{type(landmark_noise).__name__}")
        if not (math.isfinite(keyframe_s) and keyframe_s >= model.dt_s):
            raise ValueError(f"keyframe_s must be at least one period ({model.dt_s} s), got "
                             f"{keyframe_s}")
        self.model = model
        self.landmarks = landmarks
        self.keyframe_every = round(keyframe_s / model.dt_s)
        self.options = options or ROUTE_SMOOTHER_OPTIONS
        if landmark_noise is not None:
            self.options = replace(self.options, landmark_noise=landmark_noise)
        self.smoothers: list[IncrementalSmoother] | None = None

    def reset(self, n_robots: int, initial_pose: np.ndarray) -> None:
        """Start ``n_robots`` estimates at ``initial_pose`` (N, 3); the first frame anchors
        the counts."""
        pose = np.array(initial_pose, dtype=float)
        if pose.shape != (n_robots, 3):
            raise ShapeError(f"expected initial_pose of shape ({n_robots}, 3), got {pose.shape}")
        self.pose = pose
        self.smoothers = None
        self.dropped_observations = 0
        self._ticks: np.ndarray | None = None

    def step(self, frame: SensorFrame, cmd_m_s: np.ndarray,
             observations: Sequence[RangeBearing] | None = None) -> np.ndarray:
        """Take the frame closing the period of ``cmd_m_s`` (N, 2) [m/s] and the landmark
        observations of that period; return the poses (N, 3).

        Raises
        ------
        RuntimeError
            Before :meth:`reset`.
        ShapeError
            If the commands, counts or observations do not match the robots.
        """
        if not hasattr(self, "pose"):
            raise RuntimeError("call reset(n_robots, initial_pose) before step()")
        n = len(self.pose)
        ticks = np.asarray(frame.ticks, np.int64).reshape(-1, 2)
        cmd = np.asarray(cmd_m_s, dtype=float)
        if cmd.shape != (n, 2) or ticks.shape != (n, 2):
            raise ShapeError(f"expected commands and counts of shape ({n}, 2), got "
                             f"{cmd.shape} and {ticks.shape}")
        if observations is not None and len(observations) != n:
            raise ShapeError(f"expected observations for {n} robots, got {len(observations)}")
        if self._ticks is None:             # the first frame anchors the encoder counts
            self._start(ticks)
            return self.pose
        m = self.model
        counts = tick_deltas(np.stack([self._ticks, ticks]))[0]
        self._ticks = ticks
        if m.intrinsics is None:
            y = body_from_wheel(counts * (m.m_per_tick / m.dt_s), wheel_base_m=m.wheel_base_m)
        else:                               # each wheel's own scale (docs/intrinsics.md)
            y = m.intrinsics.body_motion(counts) / m.dt_s
        self._u.append(cmd)
        self._y.append(y)
        self._n += 1
        # between keyframes: the encoder speeds, which the filtered ones equal to within
        # 1 - W = R_enc (R + R_enc)^-1 (about 2e-6 for the create2 model)
        cal = self._cal
        kappa_v = cal[:, 2] * y[:, 0] if cal.shape[1] == 3 else 0.0
        self.pose = pose_step(self.pose, cal[:, 0] * y[:, 0], cal[:, 1] * y[:, 1] + kappa_v,
                              m.dt_s)
        none = RangeBearing.empty()
        for i in range(n):
            seen = none if observations is None or self.landmarks is None else observations[i]
            if len(seen) or self._n - self._kf_sample[i] >= self.keyframe_every:
                self._keyframe(i, seen)
        return self.pose

    def _start(self, ticks: np.ndarray) -> None:
        n = len(self.pose)
        self._ticks = ticks
        self._z_kf = np.zeros((n, self.model.n_states))   # model state at each keyframe
        self._u: list[np.ndarray] = []             # per sample, (N, 2) each
        self._y: list[np.ndarray] = []
        self._n = 0                                # samples so far
        self._kf_sample = np.zeros(n, np.int64)    # sample of each robot's newest keyframe
        self._cal = np.tile(np.asarray(self.options.calibration_prior, float), (n, 1))
        self.smoothers = [IncrementalSmoother(initial_pose=p, options=self.options,
                                              landmarks=self.landmarks) for p in self.pose]

    def _keyframe(self, i: int, seen: RangeBearing) -> None:
        """Close robot ``i``'s interval at the current sample: motion, observations, update."""
        start = int(self._kf_sample[i])
        first = len(self._u) - (self._n - start)
        u = np.array([c[i] for c in self._u[first:]])
        y = np.array([c[i] for c in self._y[first:]])
        pre = preintegrate_model(self.model, u, keyframes=[0, len(u)], mode="filtered",
                                 measured_speeds=y, z0=self._z_kf[i],
                                 calibration=(1.0, 1.0, 0.0)[:self.options.n_calibration])
        sm = self.smoothers[i]
        k = sm.add_motion(replace(pre, keyframes=pre.keyframes + start))
        if len(seen):
            known = np.array([lid in self.landmarks for lid in seen.landmark_id.tolist()])
            self.dropped_observations += int(np.count_nonzero(~known))
            sm.add_observations(seen.select(known).with_index(k))
        sm.update()
        self.pose[i] = sm.pose(k)
        if self.options.calibrate:
            self._cal[i] = self.options.bounded_calibration(sm.calibration(k))
        self._kf_sample[i] = self._n
        self._z_kf[i] = self.model.state_from_data(u, y, z0=self._z_kf[i])
        self._trim()

    def intrinsics_estimates(self) -> list[IntrinsicsEstimate]:
        """Per robot, the odometry intrinsics its newest calibration says the robot has.

        Returns
        -------
        list of IntrinsicsEstimate
            :meth:`fusion.graph.IncrementalSmoother.intrinsics_estimate` at the newest
            keyframe, relative to the model's
            :attr:`~lti_motion.model.MotionModel.encoder_intrinsics` (what the encoder
            speeds are computed with); write one into a model with
            :meth:`lti_motion.model.MotionModel.with_intrinsics`.

        Raises
        ------
        RuntimeError
            Before the first frame.
        ValueError
            If the options do not estimate the calibration.
        """
        if not self.smoothers:
            raise RuntimeError("no smoother yet: call reset() and step() first")
        t_s = self._n * self.model.dt_s
        return [sm.intrinsics_estimate(self.model.encoder_intrinsics, t_s=t_s)
                for sm in self.smoothers]

    def _trim(self) -> None:
        """Forget the samples every robot's newest keyframe has passed."""
        drop = len(self._u) - (self._n - int(self._kf_sample.min()))
        if drop > 0:
            del self._u[:drop], self._y[:drop]
