"""The model EKF and the residual monitor as one object: one call per frame.

:class:`MonitoredFilter` owns the order of the per-frame steps that make the
monitor's tests valid; a frame goes in, the estimate and the alarms it raised
come out. The frame is a :class:`~lti_motion.recordings.SensorFrame` (a
driver's, the simulator's, or one built from a recording's row with
:meth:`SensorFrame.of_counts <lti_motion.recordings.SensorFrame.of_counts>`);
the filter reads its counts, its command, its ``valid`` flag, its wheel currents
and overcurrent flags and its gyro reading. For frame ``k`` (it closes period
``k``, whose command ``u[k]`` went out at its start):

1. the first frame anchors the encoder counts (no prediction);
2. :meth:`ModelEKF.predict <fusion.ekf.ModelEKF.predict>` with ``u[k]``: the
   model's speeds for the period;
3. a lost frame (``valid=False``) stops here: the next valid frame's counts
   span the gap;
4. the *predicted* wheel speeds are taken for the stuck-encoder check, before
   the encoders correct them;
5. the encoder counts are fused (gated) by the EKF, which holds the counts
   (:class:`~fusion.ekf.EncoderCounts`) and takes the frame's count change
   once; the stuck-encoder check gets that change and the predicted speeds
   (:meth:`ResidualMonitor.update_counts
   <fusion.monitoring.ResidualMonitor.update_counts>`), then the update record
   goes to the per-sample gate and glitch-burst tests;
6. with a Phase-I fit (:func:`~fusion.monitoring.fit_nominal`), the
   dynamics tests get the command and the count changes;
7. with a gyro (``EKFOptions(gyro=...)``), the frame's yaw-rate reading goes to
   :meth:`ModelEKF.update_gyro <fusion.ekf.ModelEKF.update_gyro>` after the
   encoders (a lost frame or a missing reading gives it NaN: the window so far
   is dropped and a new one starts); its innovations are not monitored;
8. with a landmark map, the frame's sightings go to the scale test and, unless
   ``fuse_landmarks=False``, are fused into the EKF (their records to the
   landmark stream's gate);
9. each reset the EKF made during the frame (an implausible scale error or a
   divergence, :mod:`fusion.ekf.resets`) becomes a ``"filter_reset"`` alarm
   (its ``test`` the cause, its statistic and threshold the reset's).

Alarms go to ``on_alarm`` as they are raised and come back in each
:class:`FrameResult`; :attr:`MonitoredFilter.events` keeps them all.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.model_ekf import ModelEKF
from fusion.ekf.resets import FilterReset
from fusion.ekf.updates import UpdateRecord
from fusion.exceptions import FilterOptionError, MeasurementShapeError
from fusion.landmark_map import LandmarkMap
from fusion.monitoring.dynamics import DynamicsMonitor
from fusion.monitoring.phase_one import NominalFit
from fusion.monitoring.residual import AlarmEvent, MonitorOptions, ResidualMonitor
from fusion.monitoring.scale import ScaleMonitor
from fusion.range_bearing import RangeBearing
from lti_motion.exceptions import MissingEncoderScaleError
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.frames import SensorFrame

__all__ = ["FrameResult", "MonitoredFilter"]


def _counts(ticks: np.ndarray | Sequence[int]) -> np.ndarray:
    """A frame's raw counts as int64 ``(left, right)``, or a :class:`MeasurementShapeError`."""
    counts = np.asarray(ticks, np.int64)
    if counts.shape != (2,):
        raise MeasurementShapeError(f"expected raw encoder counts of shape (2,) (left, "
                                    f"right), got {counts.shape}")
    return counts


@dataclass(frozen=True)
class FrameResult:
    """What one frame gave.

    Attributes
    ----------
    t_s : float
        Filter time at the frame [s].
    pose : ndarray, shape (3,)
        Estimated pose ``(x [m], y [m], theta [rad])`` (heading not wrapped).
    speeds : ndarray, shape (2,)
        Estimated body speeds ``(v [m/s], w [rad/s])`` of the period.
    tick_deltas : ndarray, shape (2,)
        Count changes of (left, right) since the last valid frame [ticks]
        (zeros at the anchoring frame and at lost frames).
    encoders : UpdateRecord or None
        The encoder update; None at the anchoring frame and at lost frames.
    alarms : tuple of AlarmEvent
        Alarms this frame raised.
    """

    t_s: float
    pose: np.ndarray
    speeds: np.ndarray
    tick_deltas: np.ndarray
    encoders: UpdateRecord | None
    alarms: tuple[AlarmEvent, ...]


class MonitoredFilter:
    """A :class:`~fusion.ekf.ModelEKF` watched by a :class:`~fusion.monitoring.ResidualMonitor`.

    Parameters
    ----------
    model : MotionModel
        The calibrated model; needs ``m_per_tick``.
    nominal : NominalFit, optional
        Phase I (:func:`~fusion.monitoring.fit_nominal`): runs the
        dynamics tests with its null and the encoder gate it set. Without it
        the windowed NIS and CUSUM on the encoder innovations run instead
        (they cry wolf on real drives, ``docs/guide_alarms.md``).
    options : MonitorOptions, optional
        Monitor settings (default: the model's period and, with ``nominal``,
        its encoder gate).
    ekf_options : EKFOptions, optional
        The EKF's options (:class:`~fusion.ekf.EKFOptions`; default
        ``EKFOptions(history=0)``: no update records kept). Its
        ``landmark_noise`` is the sightings' noise for the scale test too, its
        ``counter_bits`` the width of the encoder counters, and with its
        ``gyro`` the EKF fuses the frames' yaw-rate readings
        (:mod:`fusion.ekf.gyro`); without one they are refused.
    landmarks : LandmarkMap, optional
        Known landmarks: runs the scale test on the sightings given to
        :meth:`step`, and fuses them into the EKF unless ``fuse_landmarks`` is
        false.
    fuse_landmarks : bool
        Whether the EKF fuses the sightings (the scale test runs its own
        filters either way).
    initial_pose : array_like, shape (3,)
        Start pose ``(x [m], y [m], theta [rad])`` of the filter and the scale test.
    pose_std : tuple of 3 float
        Its standard deviations [m, m, rad].
    initial_ticks : array_like, shape (2,), optional
        Raw counts at the start; otherwise the first :meth:`step` anchors.
    t0_s : float
        Filter time at the anchoring frame [s].
    on_alarm : callable, optional
        Called with each :class:`~fusion.monitoring.AlarmEvent` as it is raised.

    Attributes
    ----------
    ekf : ModelEKF or None
        The filter (None until the first frame anchors it); it holds the
        encoder counts (:attr:`ModelEKF.encoder_counts
        <fusion.ekf.ModelEKF.encoder_counts>`).
    ekf_options : EKFOptions
        Its options.
    monitor : ResidualMonitor
        The residual monitor, with :attr:`dynamics` and :attr:`scale` plugged in.
    dynamics : DynamicsMonitor or None
        The dynamics tests (with ``nominal``).
    scale : ScaleMonitor or None
        The scale test (with ``landmarks``).

    Raises
    ------
    MissingEncoderScaleError
        If the model has no encoder scale.

    Examples
    --------
    >>> from lti_motion.model.fir import FirFit
    >>> model = MotionModel.from_fir(
    ...     FirFit(taps=np.stack([np.zeros((2, 2)), [[0.5, 0.5], [-4.0, 4.0]]]),
    ...            residual_cov=np.eye(2) * 1e-4, n_samples=100, source="steps"),
    ...     dt_s=0.015, wheel_base_m=0.25, m_per_tick=5e-4,
    ...     calibrated_at="2026-01-01T00:00:00+00:00")
    >>> mf = MonitoredFilter(model)
    >>> cmd = np.array([0.2, 0.2])            # 6 ticks a period at 0.2 m/s, after one period
    >>> for k in range(200):
    ...     right = 6 * max(k - 1, 0)
    ...     left = right if k < 100 else 588    # the left encoder freezes at frame 100
    ...     frame = SensorFrame.of_counts(0.015 * k, np.array([left, right]), cmd)
    ...     result = mf.step(frame)
    ...     if result.alarms:
    ...         print(k, [(e.kind, e.channel) for e in result.alarms])
    102 [('stuck_encoder', 0)]
    """

    def __init__(self, model: MotionModel, *, nominal: NominalFit | None = None,
                 options: MonitorOptions | None = None, ekf_options: EKFOptions | None = None,
                 landmarks: LandmarkMap | None = None, fuse_landmarks: bool = True,
                 initial_pose: Sequence[float] = (0.0, 0.0, 0.0),
                 pose_std: tuple[float, float, float] = (0.01, 0.01, 0.01),
                 initial_ticks: np.ndarray | Sequence[int] | None = None, t0_s: float = 0.0,
                 on_alarm: Callable[[AlarmEvent], None] | None = None) -> None:
        if model.m_per_tick is None:
            raise MissingEncoderScaleError.needed_by("the monitor")
        ekf_options = EKFOptions(history=0) if ekf_options is None else ekf_options
        if not isinstance(ekf_options, EKFOptions):
            raise FilterOptionError(f"ekf_options must be an EKFOptions, got "
                                    f"{type(ekf_options).__name__}")
        self.ekf_options = ekf_options
        self.model = model
        self._wheel_base_m = float(model.wheel_base_m)
        if options is None:
            options = (nominal.options(model.dt_s) if nominal is not None
                       else MonitorOptions(dt_s=model.dt_s))
        self.nominal = nominal
        self.dynamics = None if nominal is None else DynamicsMonitor(model, nominal.null)
        self.scale = None
        if landmarks is not None:
            self.scale = ScaleMonitor(model.m_per_tick, model.wheel_base_m, landmarks,
                                      initial_pose=initial_pose, pose_std=pose_std,
                                      landmark_noise=ekf_options.landmark_noise,
                                      intrinsics=model.encoder_intrinsics)
        self.monitor = ResidualMonitor(options, m_per_tick=model.m_per_tick, on_alarm=on_alarm,
                                       dynamics=self.dynamics, scale=self.scale)
        self._fuse = landmarks is not None and bool(fuse_landmarks)
        # where the EKF starts, and the map it fuses
        self._start = (initial_pose, pose_std, float(t0_s))
        self._ekf_landmarks = landmarks if self._fuse else None
        self.ekf: ModelEKF | None = None
        if initial_ticks is not None:
            self._anchor(initial_ticks)

    @property
    def events(self) -> list[AlarmEvent]:
        """Every alarm so far, in time order."""
        return self.monitor.events

    def _anchor(self, ticks: np.ndarray | Sequence[int]) -> None:
        initial_pose, pose_std, t0_s = self._start
        self.ekf = ModelEKF(self.model, options=self.ekf_options, initial_pose=initial_pose,
                            pose_std=pose_std, t0_s=t0_s, landmarks=self._ekf_landmarks,
                            initial_ticks=_counts(ticks))

    def _result(self, deltas: np.ndarray, record: UpdateRecord | None,
                alarms: list[AlarmEvent]) -> FrameResult:
        ekf = self.ekf
        return FrameResult(ekf.t_s, ekf.pose, ekf.speeds, deltas, record, tuple(alarms))

    def _predicted_wheels(self) -> np.ndarray:
        """The filter's predicted (left, right) wheel speeds [m/s], (2,):
        :func:`lti_motion.kinematics.wheel_from_body` of its speeds, ``v -/+ (b / 2) w``,
        in scalar arithmetic (it runs every frame)."""
        v, w = self.ekf.x[-2:].tolist()
        half_base = 0.5 * self._wheel_base_m
        return np.array((v - half_base * w, v + half_base * w))

    def step(self, frame: SensorFrame, *, sightings: RangeBearing | None = None
             ) -> FrameResult:
        """Take one frame: predict, test, fuse, in the module's order.

        Parameters
        ----------
        frame : SensorFrame
            The frame of one robot: its raw (wrapping) encoder counts ``ticks``
            ``(left, right)`` [ticks], the wheel commands ``cmd_m_s`` ``(left,
            right)`` [m/s] of the period it closes, ``valid`` (false for a lost
            frame: the filter only advances), and where the robot reports them
            ``motor_current_a`` [A] and ``wheel_overcurrent`` (with either, a flat
            count is called a ``"stalled_wheel"`` or a ``"stuck_encoder"``,
            :mod:`fusion.monitoring.wheel_check`) and ``yaw_rate_rad_s``, the
            gyro's reading over the period [rad/s] (needs ``EKFOptions(gyro=...)``;
            ``None`` or NaN: no reading, the gyro window starts again). Its light
            bumps, bumpers and truth are not read.
        sightings : RangeBearing, optional
            Landmarks seen at this frame (used with a landmark map; rows without
            a covariance take ``ekf_options.landmark_noise``).

        Returns
        -------
        FrameResult

        Raises
        ------
        FilterOptionError
            For a frame with a gyro reading given to a filter without a gyro.
        MeasurementShapeError
            For counts that are not two numbers.
        """
        yaw_rate_rad_s = frame.yaw_rate_rad_s
        if yaw_rate_rad_s is not None and self.ekf_options.gyro is None:
            raise FilterOptionError("the frame has a yaw rate, but this monitored filter has no "
                                    "gyro; give ekf_options=EKFOptions(gyro=GyroNoise(...)), or "
                                    "frames without yaw_rate_rad_s")
        if self.ekf is None:
            self._anchor(frame.ticks)
            return self._result(np.zeros(2), None, [])
        ekf, mon = self.ekf, self.monitor
        cmd = np.asarray(frame.cmd_m_s, dtype=float)
        ekf.predict(cmd)
        gyro = ekf.fm.gyro is not None
        if not frame.valid:
            if gyro:
                ekf.update_gyro(math.nan)           # a lost frame: the window starts again
            return self._result(np.zeros(2), None, [])
        now = _counts(frame.ticks)
        t = ekf.t_s
        # the stuck check compares the counts with the model's prediction, before the update
        predicted = self._predicted_wheels()
        resets = ekf.n_resets
        record = ekf.update_encoders(now)
        # the count changes since the last valid frame, as the EKF took them (its frame step)
        deltas = np.array(ekf.encoder_counts.step, dtype=float)
        alarms = mon.update_counts(t, deltas, predicted, cmd_m_s=cmd,
                                   motor_current_a=frame.motor_current_a,
                                   wheel_overcurrent=frame.wheel_overcurrent)
        alarms += mon.update_record(record)
        if gyro:
            ekf.update_gyro(math.nan if yaw_rate_rad_s is None else yaw_rate_rad_s)
        if self.dynamics is not None:
            alarms += mon.update_commands(t, cmd, deltas)
        if self.scale is not None:
            alarms += mon.update_landmarks(t, deltas, sightings)
        if self._fuse and sightings is not None:
            for record in ekf.update_landmarks(sightings):
                alarms += mon.update_record(record)
        if ekf.n_resets > resets:
            alarms += mon.report([_reset_alarm(r) for r in
                                  list(ekf.resets)[resets - ekf.n_resets:]])
        return self._result(deltas, record, alarms)


def _reset_alarm(reset: FilterReset) -> AlarmEvent:
    """The ``"filter_reset"`` alarm of one EKF reset."""
    return AlarmEvent(reset.t_s, "filter_reset", reset.cause, reset.statistic, reset.threshold,
                      reset.t_s)
