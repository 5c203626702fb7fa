"""The one graph builder behind :mod:`fusion.graph.smoother`'s incremental and batch smoothers.

:class:`GraphBuilder` holds the keys, the initial guesses, and the factors not
yet handed to an optimiser; :class:`~fusion.graph.IncrementalSmoother` and
:func:`~fusion.graph.smooth_batch` both build through it, so the two paths
cannot drift apart. Not public API: use :mod:`fusion.graph.smoother`.

The graph: a prior on the first pose; one motion factor per keyframe interval;
range-bearing factors (:func:`~fusion.graph.range_bearing_factors`, a
full Gaussian noise model per sighting: its own covariance, or
``options.landmark_noise``) to landmark variables, known landmarks held by a
prior of ``options.landmark_sigma_m``, unknown ones initialised from their
first observation. With ``options.calibrate`` the calibration variables are
``(s, g)`` (``Point2``) or, with ``kappa`` (:meth:`SmootherOptions.with_curvature
<fusion.graph.smoother_options.SmootherOptions.with_curvature>`), ``(s, g, kappa)``
(``Point3``), and the intervals are grouped by calibration variable
(``calibration_every`` consecutive intervals share ``C(g)``, with a prior on
``C(0)`` and a random walk between successive ones):

- a *closed* group (all its intervals added) is one
  :func:`~fusion.graph.factors.calibrated_motion_group_factor` on its poses and ``C(g)``;
- the *open* group (the newest, still growing) stands as native
  ``BetweenFactorPose2`` factors, the preintegrated motion corrected to the
  current calibration estimate (the same first-order correction, Forster et
  al. 2017, eq. 44, with ``c`` held at its estimate). When the group closes
  they are removed (``removeFactorIndices``) and replaced by its group factor;
  :meth:`GraphBuilder.close_open_group` does the same early (a partial group
  factor, replaced again when the group grows).

A closed group's factor is exactly the sum of its intervals' calibration-aware
factors; the open group only defers, by at most ``calibration_every``
intervals, what its intervals tell about the calibration. Python factors are
kept few because each call of one inside a gtsam optimiser copies the
optimiser's whole ``Values`` (:mod:`fusion.graph.calibrated_factors`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import gtsam
import numpy as np

from fusion.exceptions import GraphInputError, KeyframeOrderError, UnknownPoseError
from fusion.graph.factors import (
    calibrated_motion_group_factor,
    calibration_key,
    calibration_walk_factor,
    landmark_key,
    motion_factor,
    pose_key,
    range_bearing_factors,
)
from fusion.graph.preintegration import Preintegrated
from fusion.graph.smoother_options import SmootherOptions, SmootherResult
from fusion.landmark_map import LandmarkMap
from fusion.range_bearing import RangeBearing

__all__ = ["GraphBuilder"]


@dataclass
class _Ref:
    """Where a factor standing for open-group intervals is: pending list, graph handed out,
    or iSAM2 (``index`` is a position in the list, in the graph, or iSAM2's factor index)."""

    state: str              # "pending", "taken" or "solver"
    index: int


class GraphBuilder:
    """Keys, initial guesses and the factors not yet handed to an optimiser.

    Parameters
    ----------
    initial_pose : array_like, shape (3,)
        ``wTb`` of keyframe 0 ``(x [m], y [m], theta [rad])``.
    first_keyframe : int
        Sample index of keyframe 0.
    options : SmootherOptions
        Graph settings.
    landmarks : LandmarkMap or None
        Known landmarks (integer ids).

    Raises
    ------
    fusion.exceptions.LandmarkIdError
        If a known landmark's id is not an integer.
    """

    def __init__(self, *, initial_pose: np.ndarray, first_keyframe: int,
                 options: SmootherOptions, landmarks: LandmarkMap | None) -> None:
        self.opts = options
        pose0 = gtsam.Pose2(*np.asarray(initial_pose, dtype=float).reshape(3))
        self.keyframes: list[int] = [int(first_keyframe)]
        self.guess: list[gtsam.Pose2] = [pose0]
        self._pending: list[gtsam.NonlinearFactor | None] = []
        self._values = gtsam.Values()
        self._remove: list[int] = []                    # solver factor indices to drop
        self._taken: list[_Ref] = []
        self.known: dict[int, np.ndarray] = {} if landmarks is None else dict(
            zip(landmarks.integer_ids.tolist(), landmarks.xy_m, strict=True))
        self.landmarks: dict[int, None] = {}            # ids in the graph, in insertion order
        self.cal_guess = np.array(options.calibration_prior)
        self.group_duration_s = 0.0
        self._open: list[Preintegrated] = []            # intervals of the open group
        self._open_refs: list[_Ref] = []                # factors standing for them
        self._open_calibrated = 0                       # of them, under a group factor
        self._add(gtsam.PriorFactorPose2(
            pose_key(0), pose0, gtsam.noiseModel.Diagonal.Sigmas(options.initial_pose_sigmas)))
        self._values.insert(pose_key(0), pose0)
        if options.calibrate:
            prior = gtsam.PriorFactorPoint2 if options.n_calibration == 2 else (
                gtsam.PriorFactorPoint3)
            self._add(prior(
                calibration_key(0), self.cal_guess,
                gtsam.noiseModel.Diagonal.Sigmas(options.calibration_prior_sigmas)))
            self._values.insert(calibration_key(0), self.cal_guess)

    @property
    def n_poses(self) -> int:
        return len(self.keyframes)

    def calibration_index(self, pose: int | np.ndarray) -> int | np.ndarray:
        """Calibration variable in force at ``pose`` (that of its outgoing interval); for an
        integer array of poses, an array of them."""
        last_interval = max(self.n_poses - 2, 0)
        if isinstance(pose, np.ndarray):
            return np.minimum(pose, last_interval) // self.opts.calibration_every
        return min(pose, last_interval) // self.opts.calibration_every

    def _add(self, factor: gtsam.NonlinearFactor) -> _Ref:
        self._pending.append(factor)
        return _Ref("pending", len(self._pending) - 1)

    def _drop(self, ref: _Ref) -> None:
        if ref.state == "pending":
            self._pending[ref.index] = None
        elif ref.state == "solver":
            self._remove.append(ref.index)
        else:
            raise RuntimeError("a graph was taken but not committed; call commit() first")

    def add_motion(self, pre: Preintegrated) -> None:
        """Add preintegrated intervals continuing from the last keyframe (module doc)."""
        if int(pre.keyframes[0]) != self.keyframes[-1]:
            raise KeyframeOrderError(
                f"motion starts at sample {int(pre.keyframes[0])} but the last keyframe is at "
                f"sample {self.keyframes[-1]}; add intervals in order, without gaps")
        opts = self.opts
        if opts.calibrate and len(pre.calibration) != opts.n_calibration:
            names = "(s, g)" if opts.n_calibration == 2 else "(s, g, kappa)"
            raise GraphInputError(
                f"the smoother estimates {names} but the motion was preintegrated with "
                f"calibration {pre.calibration.tolist()}; preintegrate with a calibration of "
                f"{opts.n_calibration} entries, e.g. options.calibration_prior")
        for k in range(len(pre)):
            i = self.n_poses - 1
            key_i, key_j = pose_key(i), pose_key(i + 1)
            if not opts.calibrate:
                self._add(motion_factor(pre, k, key_i=key_i, key_j=key_j))
                delta = gtsam.Pose2(*pre.delta_pose[k].tolist())
            else:
                group = i // opts.calibration_every
                if i > 0 and i % opts.calibration_every == 0:
                    self._add(calibration_walk_factor(
                        calibration_key(group - 1), calibration_key(group),
                        sigma_per_sqrt_s=opts.calibration_walk_sigmas,
                        duration_s=self.group_duration_s))
                    self._values.insert(calibration_key(group), self.cal_guess)
                    self.group_duration_s = 0.0
                self.group_duration_s += float(pre.duration_s[k])
                # the motion at the current calibration, first order (Forster et al. eq. 44)
                correction = pre.calibration_jacobian[k] @ (self.cal_guess - pre.calibration)
                delta = gtsam.Pose2(*pre.delta_pose[k].tolist()).compose(
                    gtsam.Pose2.Expmap(correction))
                self._open.append(pre if len(pre) == 1 else pre[k])
                self._open_refs.append(self._add(gtsam.BetweenFactorPose2(
                    key_i, key_j, delta,
                    gtsam.noiseModel.Gaussian.Covariance(pre.covariance[k]))))
            guess = self.guess[i].compose(delta)
            self.guess.append(guess)
            self._values.insert(key_j, guess)
            self.keyframes.append(int(pre.keyframes[k + 1]))
            if opts.calibrate and (i + 1) % opts.calibration_every == 0:
                self.close_open_group()                 # the group is complete: final
                self._open, self._open_refs, self._open_calibrated = [], [], 0

    def close_open_group(self) -> None:
        """Put the open group's intervals under one calibration-aware group factor now."""
        if len(self._open) == self._open_calibrated:
            return
        for ref in self._open_refs:
            self._drop(ref)
        first = self.n_poses - 1 - len(self._open)
        factor = calibrated_motion_group_factor(
            self._open, pose_keys=[pose_key(first + m) for m in range(len(self._open) + 1)],
            key_c=calibration_key(first // self.opts.calibration_every))
        self._open_refs = [self._add(factor)]
        self._open_calibrated = len(self._open)

    def add_observations(self, obs: RangeBearing) -> None:
        """Add range-bearing factors (``obs.index`` = keyframe index), one per row, in order."""
        bad = (obs.index < 0) | (obs.index >= self.n_poses)
        if np.any(bad):
            first = int(obs.index[np.argmax(bad)])
            raise UnknownPoseError(
                f"observation of pose {first}, but the graph holds poses 0 .. "
                f"{self.n_poses - 1}; add the motion up to that keyframe first")
        factors = range_bearing_factors(obs, landmark_noise=self.opts.landmark_noise,
                                        huber_k=self.opts.landmark_huber_k)
        mount = obs.sensor_pose
        for p, lid, r, b, factor in zip(obs.index.tolist(), obs.landmark_id.tolist(),
                                        obs.range_m.tolist(), obs.bearing_rad.tolist(), factors,
                                        strict=True):
            if lid not in self.landmarks:
                key = landmark_key(lid)
                if lid in self.known:
                    xy = self.known[lid]
                    self._add(gtsam.PriorFactorPoint2(key, xy, gtsam.noiseModel.Isotropic.Sigma(
                        2, self.opts.landmark_sigma_m)))
                else:   # unknown landmark: where its first observation puts it
                    bTs = gtsam.Pose2(mount.x_m, mount.y_m, mount.yaw_rad)     # sensor in body
                    xy = self.guess[p].compose(bTs).transformFrom(
                        np.array([r * np.cos(b), r * np.sin(b)]))
                self._values.insert(key, np.asarray(xy, dtype=float))
                self.landmarks[lid] = None
            self._add(factor)

    @property
    def has_pending(self) -> bool:
        """Whether factors, values or removals wait for the optimiser."""
        return bool(self._remove or self._values.size()
                    or any(f is not None for f in self._pending))

    def take_pending(self) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values, list[int]]:
        """New factors, new values and solver factor indices to remove; then :meth:`commit`."""
        graph, position = gtsam.NonlinearFactorGraph(), {}
        for m, factor in enumerate(self._pending):
            if factor is not None:
                position[m] = graph.size()
                graph.add(factor)
        self._taken = [ref for ref in self._open_refs if ref.state == "pending"]
        for ref in self._taken:
            ref.state, ref.index = "taken", position[ref.index]
        out = graph, self._values, self._remove
        self._pending, self._values, self._remove = [], gtsam.Values(), []
        return out

    def commit(self, new_factor_indices: list[int]) -> None:
        """Record the solver's indices of the factors last taken (``ISAM2Result``)."""
        for ref in self._taken:
            ref.state, ref.index = "solver", int(new_factor_indices[ref.index])
        self._taken = []

    def result(self, values: gtsam.Values,
               covariance: Callable[[int], np.ndarray] | None) -> SmootherResult:
        """Read poses, calibrations and landmarks; ``covariance(key)`` gives marginals."""
        n = self.n_poses
        poses = gtsam.utilities.extractPose2(values)    # X(0) .. X(n - 1): keys sort by index
        if poses.shape != (n, 3):
            raise RuntimeError(f"the solution holds {len(poses)} poses, the graph {n}")
        cal_idx = self.calibration_index(np.arange(n))
        cals = cal_cov = pose_cov = None
        if self.opts.calibrate:
            at = gtsam.Values.atPoint2 if self.opts.n_calibration == 2 else gtsam.Values.atPoint3
            table = np.array([at(values, calibration_key(g))
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
