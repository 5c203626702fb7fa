"""The calibrated motion model inside a filterpy Extended Kalman Filter.

:class:`ModelEKF` subclasses :class:`filterpy.kalman.ExtendedKalmanFilter`
(filterpy 2.0 or later: 1.4.5's ``update`` never set ``SI``). Its state is
the pose stacked on the model's state and the period's body speeds; the maths
and the treatment of the correlated model noise are in
:mod:`fusion.ekf.functions`, which this class only calls.

One sensor period ``k`` (frame ``k`` closes period ``k``, whose command
``u[k]`` went out at its start)::

    ekf.predict(u_k)                   # model + kinematics: pose at frame k
    ekf.update_encoders(ticks_k)       # raw 16-bit counts of frame k
    ekf.update_landmarks(sightings_k)  # the landmarks seen at frame k (a RangeBearing)
    ekf.update_pose(pose, cov)         # optional absolute fix
    ekf.update_gyro(yaw_rate_k)        # optional gyro (EKFOptions(gyro=...)), fusion.ekf.gyro

Every update returns an :class:`~fusion.ekf.UpdateRecord` (innovation,
its covariance, NIS, accepted flag, kind, time, reason) and appends it to
:attr:`ModelEKF.records`; the gate, the records and the landmark updates are
:class:`fusion.ekf.GatedUpdates`, which :class:`fusion.ekf.VelocityModelEKF`
shares.
A reading is fused only if its NIS is inside the chi-square gate; otherwise it
is counted and the state is left alone. A reading with NaN is skipped and
counted, never fused. Encoder counts are cumulative: after a gated, NaN or lost
reading the next counts are compared with the last fused ones, so the motion
of the skipped periods is recovered (:mod:`fusion.ekf.functions`, *Gated
readings*). Shapes that are wrong raise
:class:`~fusion.exceptions.MeasurementShapeError`; unknown landmark ids are
counted rejections (``unknown_landmarks="count"``, the default, with the ids
kept in :attr:`ModelEKF.stats`) or raise
:class:`~fusion.exceptions.UnknownLandmarkError` (``"raise"``).

After every fused update the scale-error states are bounded and tested for
plausibility, and a run of absolute readings outside the gate is judged
(:mod:`fusion.ekf.resets`): an implausible scale or a diverged filter is
reset, logged, counted in :attr:`ModelEKF.n_resets` and kept in
:attr:`ModelEKF.resets` (:class:`fusion.monitoring.MonitoredFilter` turns
each into a ``"filter_reset"`` alarm).

filterpy's attributes stay meaningful: ``x`` (n,), ``P``, ``F``, ``Q`` of
the last prediction, ``R`` (the encoder reading's noise), ``y``, ``S``,
``SI``, ``K``, ``z`` of the last update, ``x_prior``/``P_prior`` and
``x_post``/``P_post``. filterpy's generic ``update(z, HJacobian, Hx, ...)``
still works (no gate, no record, no bound); ``predict_update`` is disabled.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Hashable, Mapping

import filterpy
import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.encoder_counts import EncoderCounts
from fusion.ekf.functions import (
    GYRO_BIAS,
    SCALES,
    FilterModel,
    encoder_speeds,
    initial_covariance,
    initial_state,
    pose_jacobian,
    pose_residual,
    predict_step,
    span_verdict,
    state_transition,
)
from fusion.ekf.gyro import (
    clone_heading,
    gyro_cov,
    gyro_jacobian,
    gyro_measurement,
    rest_cov,
    rest_jacobian,
    rest_measurement,
)
from fusion.ekf.resets import (
    MAX_SCALE_ERROR,
    DivergenceWatch,
    FilterReset,
    ResetCause,
    ScaleBound,
    discrepancy,
    reset_scales,
    scale_statistic,
    widen_pose,
)
from fusion.ekf.updates import GatedUpdates, UpdateKind, UpdateReason, UpdateRecord
from fusion.exceptions import FilterOptionError, MeasurementShapeError
from fusion.landmark_map import LandmarkMap
from fusion.noise import ScaleErrors, SlipNoise
from fusion.scale_errors import IntrinsicsEstimate, intrinsics_estimate
from lti_motion.exceptions import MissingEncoderScaleError
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.ticks import tick_deltas

__all__ = ["ModelEKF"]

_log = logging.getLogger(__name__)

if int(filterpy.__version__.split(".")[0]) < 2:     # 1.4.5's EKF.update never set SI
    raise ImportError(f"fusion.ekf.model_ekf needs filterpy >= 2.0, found {filterpy.__version__}; "
                      "upgrade it (pip install 'filterpy>=2.0')")

class ModelEKF(GatedUpdates, ExtendedKalmanFilter):
    """filterpy EKF with a calibrated :class:`~lti_motion.model.MotionModel` inside.

    Parameters
    ----------
    model : MotionModel
        The calibrated model (its :attr:`~lti_motion.model.MotionModel.encoder_intrinsics`,
        each wheel's scale and the wheel base, map the encoder counts).
    initial_pose : array_like, shape (3,)
        Start pose ``(x [m], y [m], theta [rad])``.
    pose_std : tuple of 3 float
        Its standard deviations [m, m, rad].
    z0 : ndarray, shape (nz,), optional
        Start model state (default zeros: at rest; from a moving start use
        :meth:`MotionModel.state_from_data`).
    z_cov : ndarray, optional
        Covariance of ``z0`` (default the model's ``Q``).
    options : EKFOptions, optional
        How the filter filters (:class:`~fusion.ekf.EKFOptions`: noise, gate,
        span and divergence judgement, counter width, records, gyro); default
        ``EKFOptions()``.
    m_per_tick : float, optional
        Encoder scale of both wheels [m/tick], if the model has none (it
        replaces the model's intrinsics).
    landmarks : LandmarkMap or mapping, optional
        Known landmark positions, for :meth:`update_landmark` and
        :meth:`update_landmarks`.
    initial_ticks : array_like, shape (2,), optional
        Raw encoder counts at the start; otherwise the first
        :meth:`update_encoders` call only sets the reference.
    t0_s : float
        Filter time at the start [s]; each :meth:`predict` adds ``dt_s``.

    Attributes
    ----------
    options : EKFOptions
        The filter's options.
    encoder_counts : EncoderCounts
        The raw counts it holds: the reference (last fused frame), the last
        frame and its step (the frame delta) on the counters' ring.
    resets : collections.deque of FilterReset
        The latest resets (up to 1,000), oldest first.
    n_resets : int
        Resets so far.
    n_rest_updates : int
        Gyro windows fused as zero-angular-rate updates (the robot still).

    Raises
    ------
    FilterOptionError, MeasurementShapeError
        For invalid options (a scale prior whose plausibility bound reaches
        the physical one, :data:`fusion.ekf.resets.MAX_SCALE_ERROR` or
        :data:`~fusion.ekf.resets.MAX_RATIO_ERROR`, too; a negative ``history``
        is refused by :class:`EKFOptions` itself).
    NotAModelError
        If ``model`` is not a :class:`~lti_motion.model.MotionModel`: a model
        file's path is loaded with ``MotionModel.load(path)`` first.

    Examples
    --------
    >>> from lti_motion.model.fir import FirFit
    >>> model = MotionModel.from_fir(
    ...     FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
    ...            residual_cov=np.eye(2) * 1e-4, n_samples=100, source="steps"),
    ...     dt_s=0.015, wheel_base_m=0.25, m_per_tick=5e-4,
    ...     calibrated_at="2026-01-01T00:00:00+00:00")
    >>> ekf = ModelEKF(model, initial_ticks=(65530, 100))
    >>> u = np.array([0.2, 0.2])
    >>> ekf.predict(u)                      # one period of delay: no motion yet
    >>> ekf.update_encoders(np.array([65530, 100])).accepted
    True
    >>> ekf.predict(u)
    >>> rec = ekf.update_encoders(np.array([0, 106]))      # 6 ticks each, left wrapped
    >>> speeds, pose = ekf.speeds.round(3) + 0.0, ekf.pose.round(4) + 0.0
    >>> rec.kind, rec.accepted, speeds.tolist(), pose.tolist()
    ('encoders', True, [0.2, 0.0], [0.003, 0.0, 0.0])
    >>> ekf.predict(u)
    >>> ekf.update_encoders(np.array([400, 500])).reason   # a spike: rejected, counted
    'gated'
    >>> ekf.update_encoders(np.array([np.nan, 110.0])).reason
    'non_finite'
    """

    def __init__(
        self,
        model: MotionModel,
        *,
        options: EKFOptions | None = None,
        initial_pose: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0),
        pose_std: tuple[float, float, float] = (0.01, 0.01, 0.01),
        z0: np.ndarray | None = None,
        z_cov: np.ndarray | None = None,
        m_per_tick: float | None = None,
        landmarks: LandmarkMap | Mapping[Hashable, tuple[float, float]] | None = None,
        initial_ticks: np.ndarray | tuple[int, int] | None = None,
        t0_s: float = 0.0,
    ) -> None:
        opts = EKFOptions() if options is None else options
        if not isinstance(opts, EKFOptions):
            raise FilterOptionError(f"options must be an EKFOptions, got {type(opts).__name__}")
        gyro = opts.gyro
        fm = FilterModel(model, slip=opts.slip or SlipNoise(), scales=opts.scales or ScaleErrors(),
                         encoder_std=opts.encoder_std, m_per_tick=m_per_tick, gyro=gyro)
        super().__init__(dim_x=fm.n, dim_z=2, dim_u=2)
        self._init_updates(gate_probability=opts.gate_probability, landmarks=landmarks,
                           landmark_noise=opts.landmark_noise,
                           unknown_landmarks=opts.unknown_landmarks, history=opts.history)
        self.fm = fm
        self.options = opts
        self._bound = ScaleBound.from_scales(
            fm.scales, wheel_base_m=model.wheel_base_m if fm.intrinsics is None
            else fm.intrinsics.wheel_base_m)
        self._inv_prior_var = tuple(1.0 / v for v in self._bound.prior_var)
        self._watch = DivergenceWatch(opts.diverged_after)
        self.resets: deque[FilterReset] = deque(maxlen=1000)
        self.n_resets = 0
        self._scales_since_s = float(t0_s)        # start of the scales' prior spread
        self.x = initial_state(fm, initial_pose, z=z0)
        self.P = initial_covariance(fm, pose_std=pose_std, z_cov=z_cov)
        self.F = np.array(fm.F_template)
        self.Q = np.array(fm.Q_const)
        self.R = np.array(fm.encoder_cov)
        self.K = np.zeros((fm.n, 2))
        self.y = np.zeros(2)
        self.z = np.full(2, np.nan)
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()
        self.x_post, self.P_post = self.x.copy(), self.P.copy()
        self._I = np.eye(fm.n)
        self.t_s = float(t0_s)
        self._dt_s = fm.dt_s
        self._speed_at = fm.n - 2
        self._t2s = None if fm.ticks_to_speeds is None else fm.ticks_to_speeds.tolist()
        self._n_predicts = 0
        self._gyro_read_at = -1         # the prediction of the last gyro reading
        self._gyro_window = (0.0, 0, 0)     # (sum of y dt [rad], predictions at start, count)
        # the robot standing still (fusion.ekf.gyro, "At rest"): periods in a row with zero
        # commands and unchanged counts, the prediction of the last one, and those needed
        # before a window to settle; windows fused as zero-angular-rate updates
        self._gyro_rules = gyro is not None and (gyro.rest_update or gyro.drop_settling)
        self._cmd_zero = True           # a filter starting with zero commands: settled
        self._still_run, self._still_at = 0, -1
        self._settle_periods = 0 if gyro is None else math.ceil(
            gyro.rest_settle_s / fm.dt_s - 1e-9)
        # settling after a stop (fusion.ekf.gyro): on, and the prediction it was last on at
        self._window_periods = 1 if gyro is None else max(1, math.ceil(
            gyro.window_s / fm.dt_s - 0.5 - 1e-9))
        self._settling, self._settling_at = False, -(1 << 62)
        self.n_rest_updates = 0
        first = None
        if initial_ticks is not None:
            first = self._check_ticks(initial_ticks)
            if not np.all(np.isfinite(first)):
                raise FilterOptionError(f"initial_ticks must be finite, got {initial_ticks}")
        # the reference (last fused) and the last frame's counts, and the frame delta
        self.encoder_counts = EncoderCounts(counter_bits=opts.counter_bits, initial_ticks=first)
        # F buffers must hold the constant blocks (predict_terms writes only the pose rows)
        self._buffers = (np.array(fm.F_template), np.empty((fm.n, fm.n)))

    # -- views ---------------------------------------------------------------------------------
    @property
    def pose(self) -> np.ndarray:
        """Estimated pose ``(x [m], y [m], theta [rad])`` (heading continuous), (3,)."""
        return self.x[:3].copy()

    @property
    def pose_cov(self) -> np.ndarray:
        """Covariance of :attr:`pose`, (3, 3)."""
        return self.P[:3, :3].copy()

    @property
    def speeds(self) -> np.ndarray:
        """Estimated body speeds ``(v [m/s], w [rad/s])`` of the last period, (2,).

        Summed over the periods since the last fused encoder counts while
        readings are gated or missing.
        """
        return self.x[self.fm.n - 2:].copy()

    @property
    def model_state(self) -> np.ndarray:
        """Estimated model state ``z`` for the next period, (nz,)."""
        return self.x[self.fm.model_slice].copy()

    @property
    def scale_errors(self) -> np.ndarray:
        """Estimated scale errors ``(k_v, k_w, kappa [rad/m])`` of ground against encoder
        motion, (3,) (:mod:`fusion.ekf.functions`, *Pose noise*)."""
        return self.x[SCALES].copy()

    @property
    def gyro_bias(self) -> float:
        """Estimated gyro bias [rad/s] (NaN without a gyro)."""
        return float(self.x[GYRO_BIAS]) if self.fm.gyro is not None else math.nan

    @property
    def scale_bound(self) -> ScaleBound:
        """The plausibility bound of the scale errors (:mod:`fusion.ekf.resets`)."""
        return self._bound

    def intrinsics_estimate(self) -> IntrinsicsEstimate:
        """The odometry intrinsics the current scale errors say the robot has.

        Returns
        -------
        IntrinsicsEstimate
            ``fm.intrinsics.corrected(k_v, k_w, kappa)``
            (:meth:`lti_motion.intrinsics.OdometryIntrinsics.corrected`) with
            the standard deviation of its diameter ratio from ``P``. Write it
            into a model with :meth:`lti_motion.model.MotionModel.with_intrinsics`.

        Raises
        ------
        lti_motion.exceptions.MissingEncoderScaleError
            If the filter has no encoder scale.
        ValueError
            If the estimate is not a possible robot (a non-positive scale).
        """
        if self.fm.intrinsics is None:
            raise MissingEncoderScaleError.needed_by(
                "estimating the odometry intrinsics", keyword="m_per_tick=... to ModelEKF")
        return intrinsics_estimate(self.fm.intrinsics, self.x[SCALES], self.P[SCALES, SCALES],
                                   t_s=self.t_s)

    # -- predict ---------------------------------------------------------------------------------
    def predict_x(self, cmd_m_s: np.ndarray = 0) -> None:
        """filterpy's hook: ``x = f(x, u)`` (:func:`~fusion.ekf.state_transition`)."""
        self.x = state_transition(self.x, cmd_m_s, self.fm)

    def predict(self, cmd_m_s: np.ndarray) -> None:
        """Advance one sensor period with wheel commands ``u = (L, R)`` [m/s], shape (2,).

        Sets ``x``, ``P``, ``F``, ``Q``, ``x_prior``, ``P_prior`` and adds
        ``dt_s`` to :attr:`t_s` (:func:`~fusion.ekf.predict_step`: the
        arithmetic of :func:`~fusion.ekf.predict_terms` and
        :func:`~fusion.ekf.propagate_covariance`, compiled).

        Raises
        ------
        MeasurementShapeError, NonFiniteInputError
            If ``cmd_m_s`` is not two finite numbers.
        """
        f_buf, q_buf = self._buffers
        # after a gated or missing encoder reading the speed state sums the periods since the
        # last fused counts (fusion.ekf.functions, "Gated readings")
        counts = self.encoder_counts
        accumulate = counts.accumulating
        x, P = predict_step(self.x, self.P, cmd_m_s, self.fm, accumulate=accumulate,
                            out_F=f_buf, out_Q=q_buf)
        # swap buffers so self.F / self.Q keep this step's matrices
        self._buffers = (self.F, self.Q)
        self.F, self.Q = f_buf, q_buf
        # the filter never modifies x or P in place: prior/post alias them (no copies)
        self.x = self.x_prior = x
        self.P = self.P_prior = P
        self.t_s += self._dt_s
        counts.advance()
        self._n_predicts += 1
        if self._gyro_rules:                    # rest and settling (fusion.ekf.gyro)
            zero = bool(cmd_m_s[0] == 0.0 and cmd_m_s[1] == 0.0)   # checked by predict_step
            self._settling = zero and (self._settling or not self._cmd_zero)   # a stop settles
            if self._settling:
                self._settling_at = self._n_predicts
            self._cmd_zero = zero

    def predict_update(self, *args: object, **kwargs: object) -> None:
        """Disabled: filterpy's combined step uses a linear ``F x``; call predict, then update."""
        raise NotImplementedError("ModelEKF.predict_update is not supported; call predict(u) "
                                  "and then the update methods")

    # -- bounds and resets (fusion.ekf.resets) ----------------------------------------------------
    def _gated(self, kind: UpdateKind, t: float, zmeas: np.ndarray, innovation: np.ndarray,
               H: np.ndarray, R: np.ndarray, landmark_id: Hashable | None, *,
               PHt: np.ndarray | None = None, force: bool = False) -> UpdateRecord:
        """The shared gated update, then the scale bound and the divergence watch."""
        record = GatedUpdates._gated(self, kind, t, zmeas, innovation, H, R, landmark_id,
                                     PHt=PHt, force=force)
        if record.accepted:
            # d^2 at the prior's own spread is the largest over time: below the threshold there,
            # the scales are plausible (and inside the physical bounds); three products a step
            k_v, k_w, kappa = self.x[SCALES].tolist()
            iv, iw, ik = self._inv_prior_var
            if k_v * k_v * iv + k_w * k_w * iw + kappa * kappa * ik > self._bound.threshold:
                self._bound_scales(t)
        # a pose fix counts as a landmark of its own (each a new source): it places the robot
        if kind in ("landmark", "pose") and self._watch.observe(
                record.accepted, landmark_id if kind == "landmark" else object()):
            range_m = None if kind == "pose" else float(zmeas[0] - innovation[0])
            e, b = discrepancy(innovation, range_m)
            self._reset(t, "diverged", float(self._watch.readings),
                        float(self._watch.readings))
            self.P = self.P_post = widen_pose(self.P, position_m=e, heading_rad=b)
        return record

    def _bound_scales(self, t: float) -> None:
        """Reset implausible scale errors; clip them to the physical bound."""
        k_v, k_w, kappa = self.x[SCALES].tolist()
        d2 = scale_statistic(k_v, k_w, kappa, self._bound, t - self._scales_since_s)
        k_max = self._bound.max_kappa_rad_per_m
        if d2 > self._bound.threshold:
            self._reset(t, "scale_implausible", d2, self._bound.threshold)
        elif abs(k_v) > MAX_SCALE_ERROR or abs(k_w) > MAX_SCALE_ERROR or abs(kappa) > k_max:
            x = self.x.copy()
            x[SCALES] = np.clip(x[SCALES], (-MAX_SCALE_ERROR, -MAX_SCALE_ERROR, -k_max),
                                (MAX_SCALE_ERROR, MAX_SCALE_ERROR, k_max))
            self.x = self.x_post = x

    def _reset(self, t: float, cause: ResetCause, statistic: float, threshold: float) -> None:
        k_v, k_w, kappa = self.x[SCALES].tolist()
        self.x, self.P = reset_scales(self.x, self.P, self._bound)
        self.x_post, self.P_post = self.x, self.P
        self._scales_since_s = t
        event = FilterReset(t, cause, statistic, threshold, (k_v, k_w, kappa))
        self.resets.append(event)
        self.n_resets += 1
        _log.warning("filter reset at t=%.3f s: %s (%.3g > %.3g), scale errors were "
                     "(%.4f, %.4f, %.4f rad/m)", t, cause, statistic, threshold, k_v, k_w, kappa)

    # -- updates ---------------------------------------------------------------------------------
    @staticmethod
    def _check_ticks(ticks: np.ndarray) -> np.ndarray:
        arr = np.asarray(ticks)
        if arr.shape != (2,):
            raise MeasurementShapeError(f"expected raw encoder counts of shape (2,) (left, "
                                        f"right), got {arr.shape}")
        return arr

    def update_encoders(self, ticks: np.ndarray, *, t_s: float | None = None) -> UpdateRecord:
        """Fuse the encoder counts of the frame that closes the period just predicted.

        Parameters
        ----------
        ticks : array_like, shape (2,)
            Raw (16-bit, wrapping) counts ``(left, right)``; floats with NaN
            mark a missing reading.
        t_s : float, optional
            Time for the record (default the filter time).

        Returns
        -------
        UpdateRecord
            ``kind="encoders"``. The first counts only set the reference
            (``"anchor"``). Counts are taken against those of the last fused
            frame: after a gated reading, a NaN reading (``"non_finite"``,
            skipped) or lost frames, the next reading measures the speeds
            summed over all the periods since, so no motion is lost. A
            reading rejected while spanning ``options.reanchor_periods`` periods
            or more renews the reference (a stuck encoder's lost ticks are
            gone), as do a second reading without a :meth:`predict` between
            and more than ``options.max_periods`` periods without a fused one
            (``"gap"``).

        Raises
        ------
        MeasurementShapeError
            If ``ticks`` is not (2,).
        lti_motion.exceptions.MissingEncoderScaleError
            If neither the model nor ``m_per_tick`` gives an encoder scale.
        """
        ticks = self._check_ticks(ticks)
        t = self.t_s if t_s is None else float(t_s)
        if ticks.dtype.kind not in "iu":
            if not (math.isfinite(ticks[0]) and math.isfinite(ticks[1])):
                if self._gyro_rules:
                    self._mark_still(still=False)
                return self._skip("encoders", t, "non_finite", 2)
        counts, opts = self.encoder_counts, self.options
        left, right = ticks.tolist()
        left, right = int(left), int(right)
        if self._gyro_rules:
            self._mark_still(still=counts.frame is not None and left == counts.frame[0]
                             and right == counts.frame[1])
        periods = counts.periods
        if counts.reference is None or periods == 0 or periods > opts.max_periods:
            reason: UpdateReason = "anchor" if counts.reference is None else "gap"
            counts.observe(left, right)
            counts.rebase()
            return self._skip("encoders", t, reason, 2)
        jump = counts.observe(left, right)          # this frame's counts and step
        speeds = self.x[self._speed_at:]
        y = self._span_speeds()                     # summed over `periods` periods
        verdict = "young"
        if periods >= opts.reanchor_periods:
            verdict = span_verdict(tick_deltas(counts.pair(), axis=0,
                                               counter_bits=counts.counter_bits)[0],
                                   np.linalg.solve(self.fm.ticks_to_speeds, speeds),
                                   jump, counts.span_jump_ticks, periods=periods,
                                   max_jump_ticks=float(opts.max_jump_ticks))
        record = self._gated("encoders", t, y, y - speeds, self.fm.H_encoders, self.R, None,
                             PHt=self.P[:, self._speed_at:], force=verdict == "consistent")
        if record.accepted or verdict == "broken":
            counts.rebase()
        else:
            counts.hold(jump)
        return record

    def _mark_still(self, *, still: bool) -> None:
        """Count the periods in a row in which the robot stood still: zero commands and a
        wheel reading that did not change (the first reading of a period counts)."""
        if self._still_at == self._n_predicts:
            return
        if still and self._cmd_zero:
            self._still_run = self._still_run + 1 if self._still_at == self._n_predicts - 1 else 1
        else:
            self._still_run = 0
        self._still_at = self._n_predicts
        if self._settling and self._still_run >= self._window_periods:
            self._settling = False          # a whole window still: the stop has settled

    def _span_speeds(self) -> np.ndarray:
        """:func:`~fusion.ekf.encoder_speeds` of the counts from the reference to the last
        frame, in scalar arithmetic (it runs at every reading): rollover-safe increments
        (:meth:`EncoderCounts.span <fusion.ekf.EncoderCounts.span>`), times
        ``fm.ticks_to_speeds``."""
        if self._t2s is None:
            return encoder_speeds(self.encoder_counts.pair(), self.fm)   # raises: no scale
        dl, dr = self.encoder_counts.span()
        (a, b), (c, d) = self._t2s
        return np.array((a * dl + b * dr, c * dl + d * dr))

    def update_speeds(self, speeds: np.ndarray, *, t_s: float | None = None) -> UpdateRecord:
        """Fuse measured body speeds ``(v [m/s], w [rad/s])`` of the period just predicted.

        The linear measurement ``y = s = C z + D u + e`` (gated; NaN skipped),
        one period at a time: a gated reading's motion is lost (counts, with
        :meth:`update_encoders`, recover it).

        Raises
        ------
        MeasurementShapeError
            If ``speeds`` is not (2,).
        FilterOptionError
            If the filter already fuses encoder counts.
        """
        if self.encoder_counts.reference is not None:
            raise FilterOptionError("this filter fuses encoder counts (update_encoders); "
                                    "use one of update_encoders and update_speeds, not both")
        y = np.array(speeds, dtype=float)
        if y.shape != (2,):
            raise MeasurementShapeError(f"expected body speeds of shape (2,) (v, w), got "
                                        f"{y.shape}")
        t = self.t_s if t_s is None else float(t_s)
        y0, y1 = y.tolist()
        if not (math.isfinite(y0) and math.isfinite(y1)):
            if self._gyro_rules:
                self._mark_still(still=False)
            return self._skip("encoders", t, "non_finite", 2)
        if self._gyro_rules:
            self._mark_still(still=y0 == 0.0 and y1 == 0.0)
        # H = [0 0 I] selects the speed state: P H^T is a slice, no product
        return self._gated("encoders", t, y, y - self.x[self._speed_at:], self.fm.H_encoders,
                           self.R, None, PHt=self.P[:, self._speed_at:])

    def update_pose(self, pose: np.ndarray, cov: np.ndarray, *, t_s: float | None = None
                    ) -> UpdateRecord:
        """Fuse an absolute pose fix ``(x [m], y [m], theta [rad])`` with covariance ``cov``.

        The heading residual is wrapped; gated with 3 degrees of freedom.

        Raises
        ------
        MeasurementShapeError
            If ``pose`` is not (3,) or ``cov`` not (3, 3).
        FilterOptionError
            If ``cov`` is not symmetric positive definite.
        """
        zmeas = np.asarray(pose, dtype=float)
        R = np.asarray(cov, dtype=float)
        if zmeas.shape != (3,) or R.shape != (3, 3):
            raise MeasurementShapeError(f"expected a pose (3,) and covariance (3, 3), got "
                                        f"{zmeas.shape} and {R.shape}")
        t = self.t_s if t_s is None else float(t_s)
        if not (np.all(np.isfinite(zmeas)) and np.all(np.isfinite(R))):
            return self._skip("pose", t, "non_finite", 3)
        if not np.allclose(R, R.T) or np.linalg.eigvalsh(0.5 * (R + R.T)).min() <= 0:
            raise FilterOptionError("the pose fix covariance must be symmetric positive definite")
        return self._gated("pose", t, zmeas, pose_residual(zmeas, self.x[:3]),
                           pose_jacobian(self.x), R, None)

    def update_gyro(self, yaw_rate_rad_s: float, *, t_s: float | None = None) -> UpdateRecord:
        """Add a gyro's yaw-rate reading of the period just predicted; fuse each full window.

        The readings are summed over ``gyro.window_s``; the sum times ``dt``
        measures the heading change since the window began, ``theta -
        theta_c``, plus the bias times the window (:mod:`fusion.ekf.gyro`):
        gated with 1 degree of freedom, Joseph form, then the bias clipped to
        ``+-gyro.max_bias_rad_s`` and a new window started (the heading
        cloned). A window in which the robot stood still (commands exactly zero
        and counts unchanged in each of its periods and ``gyro.rest_settle_s``
        before) measures the bias alone, ``T b`` (a zero-angular-rate update,
        Groves 2013, section 15.3.2; counted in :attr:`n_rest_updates`). A window
        overlapping the settling after a stop (commands gone to zero, the counts
        not yet still for a whole window) is dropped (``gyro.drop_settling``;
        :mod:`fusion.ekf.gyro`, *Settling after a stop*). Call it
        once per :meth:`predict`, after :meth:`update_encoders` (or
        :meth:`update_speeds`) of the same frame.

        Parameters
        ----------
        yaw_rate_rad_s : float
            The reading [rad/s]; NaN or inf (``"non_finite"``) drops the window
            so far and starts a new one.
        t_s : float, optional
            Time for the record (default the filter time).

        Returns
        -------
        UpdateRecord
            ``kind="gyro"``: ``reason`` ``"pending"`` while the window fills,
            ``"fused"`` or ``"gated"`` when it closes (innovation in rad),
            ``"gap"`` for a second reading without a :meth:`predict` between
            (ignored), ``"settling"`` for a window dropped while the robot
            settles after a stop.

        Raises
        ------
        FilterOptionError
            If the filter was built without ``gyro=``.
        MeasurementShapeError
            If the reading is not one number.
        """
        gyro = self.fm.gyro
        if gyro is None:
            raise FilterOptionError("this filter has no gyro; give "
                                    "options=EKFOptions(gyro=GyroNoise(...)) to ModelEKF")
        arr = np.asarray(yaw_rate_rad_s, dtype=float)
        if arr.size != 1:
            raise MeasurementShapeError(f"expected one yaw rate [rad/s], got shape {arr.shape}")
        y = float(arr.reshape(()))
        t = self.t_s if t_s is None else float(t_s)
        if self._gyro_read_at == self._n_predicts:
            return self._skip("gyro", t, "gap", 1)
        self._gyro_read_at = self._n_predicts
        if not math.isfinite(y):
            self._start_gyro_window()
            return self._skip("gyro", t, "non_finite", 1)
        # the window starts at the clone: the readings of the periods since, in order
        if self._n_predicts - self._gyro_window[1] != self._gyro_window[2] + 1:
            self._start_gyro_window()               # a period without a reading: start anew
            return self._skip("gyro", t, "gap", 1)
        turn, _, count = self._gyro_window
        turn += y * self._dt_s
        count += 1
        window = count * self._dt_s
        if window < gyro.window_s - 0.5 * self._dt_s:
            self._gyro_window = (turn, self._gyro_window[1], count)
            return self._skip("gyro", t, "pending", 1)
        return self._close_gyro_window(turn, count, t)

    def _close_gyro_window(self, turn: float, count: int, t: float) -> UpdateRecord:
        """Fuse a full window: the heading change, or the bias alone while still."""
        gyro, window = self.fm.gyro, count * self._dt_s
        if gyro.drop_settling and self._n_predicts - self._settling_at < count:
            self._start_gyro_window()               # fusion.ekf.gyro, "Settling after a stop"
            return self._skip("gyro", t, "settling", 1)
        still = (gyro.rest_update and self._still_at == self._n_predicts
                 and self._still_run >= count + self._settle_periods)
        if still:                                   # fusion.ekf.gyro, "At rest"
            H, R = rest_jacobian(self.x, self.fm, window), rest_cov(self.fm, window)
            predicted = rest_measurement(self.x, self.fm, window)
        else:
            H, R = gyro_jacobian(self.x, self.fm, window), gyro_cov(self.fm, window)
            predicted = gyro_measurement(self.x, self.fm, window)
        record = self._gated("gyro", t, np.array([turn]), np.array([turn]) - predicted, H, R,
                             None)
        self.n_rest_updates += int(still and record.accepted)
        if record.accepted and abs(self.x[GYRO_BIAS]) > gyro.max_bias_rad_s:
            x = self.x.copy()
            x[GYRO_BIAS] = math.copysign(gyro.max_bias_rad_s, x[GYRO_BIAS])
            self.x = self.x_post = x
        self._start_gyro_window()
        return record

    def _start_gyro_window(self) -> None:
        """Clone the heading and empty the sum (:func:`fusion.ekf.clone_heading`)."""
        self.x, self.P = clone_heading(self.x, self.P)
        self.x_post, self.P_post = self.x, self.P
        # (sum of y dt [rad], predictions at the clone, readings summed)
        self._gyro_window = (0.0, self._n_predicts, 0)
