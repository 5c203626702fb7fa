"""The model EKF and the residual monitor as one object: one call per frame.

:class:`MonitoredFilter` owns the order of the per-frame steps that make the
monitor's tests valid; a frame goes in, the estimate and the alarms it raised
come out. For frame ``k`` (it closes period ``k``, whose command ``u[k]`` went
out at its start):

1. the first frame anchors the encoder counts (no prediction);
2. :meth:`ModelEKF.predict <fusion.ekf.ModelEKF.predict>` with ``u[k]``: the
   model's speeds for the period;
3. a lost frame (``valid=False``) stops here: the next valid frame's counts
   span the gap;
4. the stuck-encoder check gets the count changes and the *predicted* wheel
   speeds (:meth:`ResidualMonitor.update_counts
   <fusion.monitoring.ResidualMonitor.update_counts>`), before the encoders
   correct them;
5. the encoder counts are fused (gated) and the update record goes to the
   per-sample gate and glitch-burst tests;
6. with a Phase-I fit (:func:`~fusion.monitoring.fit_nominal`), the
   dynamics tests get the command and the count changes;
7. with a gyro (``gyro=``), the frame's yaw-rate reading goes to
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

from fusion.ekf.model_ekf import ModelEKF
from fusion.ekf.resets import FilterReset
from fusion.ekf.updates import UpdateRecord
from fusion.exceptions import FilterOptionError, MeasurementShapeError
from fusion.landmark_map import LandmarkMap
from fusion.monitoring.dynamics import DynamicsMonitor
from fusion.monitoring.phase_one import NominalFit
from fusion.monitoring.residual import AlarmEvent, MonitorOptions, ResidualMonitor
from fusion.monitoring.scale import ScaleMonitor
from fusion.noise import GyroNoise, LandmarkNoise
from fusion.range_bearing import RangeBearing
from lti_motion.exceptions import MissingEncoderScaleError
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.ticks import tick_deltas

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
    landmarks : LandmarkMap, optional
        Known landmarks: runs the scale test on the sightings given to
        :meth:`step`, and fuses them into the EKF unless ``fuse_landmarks`` is
        false.
    fuse_landmarks : bool
        Whether the EKF fuses the sightings (the scale test runs its own
        filters either way).
    landmark_noise : LandmarkNoise, optional
        Range-bearing noise of the sightings (default 2% of range, 1 degree).
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
    counter_bits : int
        Width of the encoder counters [bits] (16: the Open Interface's;
        :class:`~fusion.ekf.ModelEKF`).
    gyro : GyroNoise, optional
        A yaw-rate gyro's noise: the EKF fuses the readings given to
        :meth:`step` (:mod:`fusion.ekf.gyro`); without it they are refused.

    Attributes
    ----------
    ekf : ModelEKF or None
        The filter (None until the first frame anchors it).
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
    ...     result = mf.step(np.array([left, right]), cmd)
    ...     if result.alarms:
    ...         print(k, [(e.kind, e.channel) for e in result.alarms])
    102 [('stuck_encoder', 0)]
    """

    def __init__(self, model: MotionModel, *, nominal: NominalFit | None = None,
                 options: MonitorOptions | None = None, landmarks: LandmarkMap | None = None,
                 fuse_landmarks: bool = True, landmark_noise: LandmarkNoise | None = None,
                 initial_pose: Sequence[float] = (0.0, 0.0, 0.0),
                 pose_std: tuple[float, float, float] = (0.01, 0.01, 0.01),
                 initial_ticks: np.ndarray | Sequence[int] | None = None, t0_s: float = 0.0,
                 on_alarm: Callable[[AlarmEvent], None] | None = None,
                 counter_bits: int = 16, gyro: GyroNoise | None = None) -> None:
        if model.m_per_tick is None:
            raise MissingEncoderScaleError.needed_by("the monitor")
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
                                      landmark_noise=landmark_noise,
                                      intrinsics=model.encoder_intrinsics)
        self.monitor = ResidualMonitor(options, m_per_tick=model.m_per_tick, on_alarm=on_alarm,
                                       dynamics=self.dynamics, scale=self.scale)
        self._fuse = landmarks is not None and bool(fuse_landmarks)
        self._ekf_args = {"initial_pose": initial_pose, "pose_std": pose_std, "t0_s": t0_s,
                          "history": 0, "landmarks": landmarks if self._fuse else None,
                          "landmark_noise": landmark_noise, "counter_bits": counter_bits,
                          "gyro": gyro}
        self.ekf: ModelEKF | None = None
        self._last_ticks: np.ndarray | None = None
        if initial_ticks is not None:
            self._anchor(initial_ticks)

    @property
    def events(self) -> list[AlarmEvent]:
        """Every alarm so far, in time order."""
        return self.monitor.events

    def _anchor(self, ticks: np.ndarray | Sequence[int]) -> np.ndarray:
        first = _counts(ticks)
        self.ekf = ModelEKF(self.model, initial_ticks=first, **self._ekf_args)
        self._last_ticks = first
        return first

    def _result(self, deltas: np.ndarray, record: UpdateRecord | None,
                alarms: list[AlarmEvent]) -> FrameResult:
        ekf = self.ekf
        return FrameResult(ekf.t_s, ekf.pose, ekf.speeds, deltas, record, tuple(alarms))

    def _deltas(self, now: np.ndarray) -> np.ndarray:
        """Count changes since the last valid frame [ticks], (2,) floats:
        :func:`lti_motion.recordings.tick_deltas`, in scalar arithmetic below 63-bit counters
        (the filter's ring step; int64 and Python integers agree there). Runs every frame."""
        ekf = self.ekf
        if ekf.counter_bits >= 63:
            return tick_deltas(np.stack([self._last_ticks, now]), axis=0,
                               counter_bits=ekf.counter_bits)[0].astype(float)
        (l0, r0), (l1, r1) = self._last_ticks.tolist(), now.tolist()
        return np.array(ekf._steps(l1 - l0, r1 - r0), dtype=float)

    def _predicted_wheels(self) -> np.ndarray:
        """The filter's predicted (left, right) wheel speeds [m/s], (2,):
        :func:`lti_motion.kinematics.wheel_from_body` of its speeds, ``v -/+ (b / 2) w``,
        in scalar arithmetic (it runs every frame)."""
        v, w = self.ekf.x[-2:].tolist()
        half_base = 0.5 * self._wheel_base_m
        return np.array((v - half_base * w, v + half_base * w))

    def step(self, ticks: np.ndarray | Sequence[int], cmd_m_s: np.ndarray | Sequence[float], *,
             valid: bool = True, sightings: RangeBearing | None = None,
             motor_current_a: np.ndarray | Sequence[float] | None = None,
             wheel_overcurrent: np.ndarray | Sequence[bool] | None = None,
             yaw_rate_rad_s: float | None = None) -> FrameResult:
        """Take one frame: predict, test, fuse, in the module's order.

        Parameters
        ----------
        ticks : array_like, shape (2,)
            Raw (16-bit, wrapping) encoder counts ``(left, right)`` of the frame.
        cmd_m_s : array_like, shape (2,)
            Wheel commands ``(left, right)`` [m/s] of the period the frame closes.
        valid : bool
            False for a lost frame: the filter only advances.
        sightings : RangeBearing, optional
            Landmarks seen at this frame (used with a landmark map; rows without
            a covariance take ``landmark_noise``).
        motor_current_a : array_like, shape (2,), optional
            Wheel motor currents (left, right) [A] where the robot reports them.
        wheel_overcurrent : array_like of bool, shape (2,), optional
            Wheel overcurrent flags (left, right) where the robot reports them.
            With either, a flat count is called a ``"stalled_wheel"`` or a
            ``"stuck_encoder"`` (:mod:`fusion.monitoring.wheel_check`).
        yaw_rate_rad_s : float, optional
            The gyro's reading over the period [rad/s] (needs ``gyro=``); ``None``
            or NaN: no reading, the gyro window starts again.

        Returns
        -------
        FrameResult

        Raises
        ------
        FilterOptionError
            For a reading given to a filter built without ``gyro=``.
        MeasurementShapeError
            For counts that are not two numbers.
        """
        if yaw_rate_rad_s is not None and self._ekf_args["gyro"] is None:
            raise FilterOptionError("a yaw rate was given, but this monitored filter has no "
                                    "gyro; give gyro=GyroNoise(...)")
        if self.ekf is None:
            self._anchor(ticks)
            return self._result(np.zeros(2), None, [])
        ekf, mon = self.ekf, self.monitor
        cmd = np.asarray(cmd_m_s, dtype=float)
        ekf.predict(cmd)
        gyro = ekf.fm.gyro is not None
        if not valid:
            if gyro:
                ekf.update_gyro(math.nan)           # a lost frame: the window starts again
            return self._result(np.zeros(2), None, [])
        now = _counts(ticks)
        deltas = self._deltas(now)
        t = ekf.t_s
        # the stuck check compares the counts with the model's prediction, before the update
        alarms = mon.update_counts(t, deltas, self._predicted_wheels(), cmd_m_s=cmd,
                                   motor_current_a=motor_current_a,
                                   wheel_overcurrent=wheel_overcurrent)
        resets = ekf.n_resets
        record = ekf.update_encoders(now)
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
        self._last_ticks = now
        return self._result(deltas, record, alarms)


def _reset_alarm(reset: FilterReset) -> AlarmEvent:
    """The ``"filter_reset"`` alarm of one EKF reset."""
    return AlarmEvent(reset.t_s, "filter_reset", reset.cause, reset.statistic, reset.threshold,
                      reset.t_s)
