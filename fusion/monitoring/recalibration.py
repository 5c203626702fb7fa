"""Recalibration policy: what to do with a monitor alarm (:mod:`fusion.monitoring.residual`).

:class:`Recalibrator` buffers commands and measured body speeds and answers
each :class:`~fusion.monitoring.AlarmEvent`:

- ``"dynamics_changed"``: refit an ARX model (:func:`lti_motion.model.fit_arx`)
  on the data since the alarm's estimated onset, when there is enough of it
  and it excites the model enough (``fit_arx`` raises
  :class:`~lti_motion.exceptions.NotExcitedError` or
  :class:`~lti_motion.exceptions.CalibrationError` otherwise). Normal driving
  rarely excites an ARX model enough (a route of starts, stops and turns
  repeats a few manoeuvres), so while the policy waits it calls the
  application's ``request_excitation(alarm)`` once: the application decides
  when and where a random-excitation manoeuvre (the calibration's) is safe
  and drives it. Every :meth:`Recalibrator.add` while waiting retries the
  refit once ``retry_samples`` more samples have come (also
  :meth:`Recalibrator.retry`). Samples more than 1.5 periods apart start a
  new segment (a refit never runs across a gap). The newest
  ``validation_fraction`` of the data since the onset is held out; the new
  model replaces the old only if its free-run fit there (mean of the two
  channels, :meth:`MotionModel.fit_percent`) beats the old model's by at
  least ``min_gain_pp`` percentage points. An adopted model is saved
  atomically (:meth:`MotionModel.save`) when a path is given.
- ``"scale_changed"``: re-estimate the scale from landmarks, else ask for a
  rotation. The scale test's alarm (:class:`~fusion.monitoring.ScaleAlarm`
  in :attr:`AlarmEvent.scale`) carries the ground travel and turn per encoder
  travel and turn since the onset, ``scale_ratio`` and ``yaw_ratio``, with
  standard deviations. Rule: a ratio is *precise enough* when its standard
  deviation is at most ``max_scale_std`` (default 0.4%, the size of the
  rotation calibration's own error on the simulator's hard floor, true ratio
  1.004). When ``scale_ratio`` is, the policy adopts at once a copy of the
  model with ``m_per_tick' = m_ref scale_ratio`` and, when ``yaw_ratio`` is
  precise too, the effective wheel base ``b' = b_ref scale_ratio /
  yaw_ratio`` (else ``b' = b_ref``: turns are taken to scale as travel),
  ``(m_ref, b_ref)`` being the scale the monitor's ratios refer to
  (``scale_reference``); its outputs are rescaled so that it predicts the
  same counts (:func:`fusion.monitoring.rescaled_model`). Otherwise it
  waits: the application feeds the monitor's running estimate
  (:meth:`Recalibrator.update_scale` with :attr:`ScaleMonitor.scale_ratio`
  and its standard deviation, which keep improving after the alarm) and the
  policy adopts as soon as the rule holds. If it has not held
  ``scale_settle_s`` after the alarm (few landmarks in view), or the alarm
  carries no estimate (the landmark NIS/CUSUM tests), the application's
  ``request_rotation(alarm)`` is called (the robot decides when a rotation
  manoeuvre is safe). The old scale is kept until then: the scale test's
  alarm is itself the evidence that the new scale explains the landmarks
  better. The encoder-speed fit [%] of a rescaled model is the old one's
  (both measured and predicted speeds scale), so the record holds the scale
  and wheel base before and after instead.
- ``"wheel_drift"``: write the new odometry intrinsics into the model. The
  scale test's curvature alarm carries them (``AlarmEvent.scale.intrinsics``,
  :meth:`lti_motion.intrinsics.OdometryIntrinsics.corrected` of the monitor's
  intrinsics by the shadow's ``(k_v, k_w, kappa)``) with the curvature's
  standard deviation. Rule: adopted at once when that standard deviation is at
  most ``max_curvature_std_rad_per_m`` (default 0.004 rad/m, a 0.09% diameter
  ratio on a Create 2, a fifth of the 0.5% change the alarm is tuned to): a copy
  of the model with ``intrinsics`` the new ones, its ``m_per_tick`` and wheel base
  their mean scale and wheel base, its outputs transformed to predict the same
  counts (:meth:`lti_motion.model.MotionModel.with_intrinsics`). Otherwise it waits
  for the monitor's running estimate (:meth:`Recalibrator.update_intrinsics` with
  :meth:`ScaleMonitor.intrinsics_estimate`) up to ``scale_settle_s``, then keeps
  the old intrinsics (``"kept_old"``: a rotation cannot tell the wheels apart).
- sensor alarms (``"glitch_burst"``, ``"stuck_encoder"``, ``"stalled_wheel"``) and the
  filter's own resets (``"filter_reset"``): no recalibration; recorded as ``"ignored"``.

Every decision is a frozen :class:`RecalibrationRecord` in
:attr:`Recalibrator.history`: what, when, the fits before and after.

Measured on the simulator with the monitor's own alarms and an excitation
manoeuvre on request (``benchmarks/bench_monitor.py``, ``recalibration``;
``docs/monitor.md``); the landmark scale re-estimate on carpet runs of the
route (``benchmarks/bench_scale_recalibration.py``). Not done: a
recursive-least-squares model in use while waiting
(:class:`lti_motion.model.RecursiveARX` exists).
"""

from __future__ import annotations

import logging
import math
import os
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from fusion.exceptions import FilterOptionError, MeasurementShapeError, TimeOrderError
from fusion.monitoring.recalibration_options import RecalibrationOptions
from fusion.monitoring.rescale import output_scaling, rescaled_model
from fusion.monitoring.residual import AlarmEvent
from lti_motion.exceptions import CalibrationError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.model.motion_model import MotionModel, fit_arx

__all__ = ["RecalibrationAction", "RecalibrationRecord", "Recalibrator"]

_log = logging.getLogger(__name__)

RecalibrationAction = Literal["adopted", "kept_old", "waiting", "rotation_requested", "ignored"]


@dataclass(frozen=True)
class RecalibrationRecord:
    """One answer of the policy to an alarm.

    Attributes
    ----------
    t_s : float
        Time of the decision [s]: the alarm's, or that of the sample or
        scale estimate that ended a wait.
    alarm : AlarmEvent
        The alarm answered.
    action : {"adopted", "kept_old", "waiting", "rotation_requested", "ignored"}
        What was done.
    n_samples : int
        Buffered samples since the onset used for the refit (0 if none).
    fit_before, fit_after : tuple of 2 float or None
        Held-out free-run fit [%] ``(v, w)`` of the old and the new model.
    reason : str
        Why (the calibration error's message when waiting).
    saved_to : str or None
        Where the adopted model was written.
    m_per_tick, wheel_base_m : tuple of 2 float or None
        For a scale decision: the encoder scale [m/tick] and wheel base [m]
        before and after.
    intrinsics : tuple of 2 OdometryIntrinsics or None
        For a wheel-drift decision: the model's encoder intrinsics before and after.
    """

    t_s: float
    alarm: AlarmEvent
    action: RecalibrationAction
    n_samples: int = 0
    fit_before: tuple[float, float] | None = None
    fit_after: tuple[float, float] | None = None
    reason: str = ""
    saved_to: str | None = None
    m_per_tick: tuple[float, float] | None = None
    wheel_base_m: tuple[float, float] | None = None
    intrinsics: tuple[OdometryIntrinsics, OdometryIntrinsics] | None = None


class Recalibrator:
    """Keeps the current model; refits it after a dynamics alarm, rescales it after a scale alarm.

    Parameters
    ----------
    model : MotionModel
        The model in use.
    options : RecalibrationOptions, optional
        What the policy decides with (:class:`~fusion.monitoring.RecalibrationOptions`:
        the refit's data, grid and validation, the precision a landmark scale or a
        curvature needs to be adopted); default ``RecalibrationOptions()``.
    save_path : path-like, optional
        Where an adopted model is saved (atomically).
    request_rotation : callable, optional
        Called with a ``"scale_changed"`` alarm whose scale could not be
        re-estimated from landmarks (module notes).
    request_excitation : callable, optional
        Called with the alarm, once, when a dynamics refit has to wait for
        data that excites the model.

    Attributes
    ----------
    model : MotionModel
        The model in use.
    options : RecalibrationOptions
        The policy's options.
    history : list of RecalibrationRecord
        Every decision.

    Examples
    --------
    A scale alarm whose ratio is precise enough (0.3% against 0.4%) is adopted
    at once:

    >>> from fusion.monitoring.scale import ScaleAlarm
    >>> m = MotionModel(kind="arx", A=0.5 * np.eye(2), B=np.eye(2), C=np.eye(2),
    ...                 D=np.zeros((2, 2)), K=0.5 * np.eye(2), Q=np.eye(2), R=np.eye(2),
    ...                 dt_s=0.015, wheel_base_m=0.235, m_per_tick=5e-4,
    ...                 coefficients={}, orders={}, calibrated_at="2026-01-01T00:00:00")
    >>> rc = Recalibrator(m)
    >>> scale = ScaleAlarm(0, 30.0, 10.2, 9.8, 24.0, 0.965, 0.003, 0.95, 0.003)
    >>> r = rc.on_alarm(AlarmEvent(30.0, "scale_changed", "scale_glr", 10.2, 9.8, 24.0,
    ...                            scale=scale))
    >>> r.action, round(r.m_per_tick[1] * 1e6, 2), round(r.wheel_base_m[1], 4)
    ('adopted', 482.5, 0.2387)
    """

    def __init__(self, model: MotionModel, *, options: RecalibrationOptions | None = None,
                 save_path: str | os.PathLike | None = None,
                 request_rotation: Callable[[AlarmEvent], None] | None = None,
                 request_excitation: Callable[[AlarmEvent], None] | None = None) -> None:
        opts = RecalibrationOptions() if options is None else options
        if not isinstance(opts, RecalibrationOptions):
            raise FilterOptionError(f"options must be a RecalibrationOptions, got "
                                    f"{type(opts).__name__}")
        reference = opts.scale_reference or (model.m_per_tick, model.wheel_base_m)
        if reference[0] is None or not all(math.isfinite(v) and v > 0 for v in reference):
            raise FilterOptionError(f"scale_reference (m_per_tick, wheel_base_m) must be "
                                    f"positive, got {reference}; the model needs m_per_tick")
        self.model = model
        self.options = opts
        # the options the model in use completes: the refit's grid, retries and gain
        na = int(model.orders.get("na", 4))
        self._orders = opts.orders or tuple(range(max(1, na - 2), na + 3))
        self._delays = opts.delays or tuple(range(0, 9))
        self._retry_samples = max(1, int(opts.retry_samples if opts.retry_samples is not None
                                         else int(opts.min_samples) // 4))
        self._dc_gain = opts.dc_gain or ("wheel_servo" if "dc_gain_scale" in model.diagnostics
                                         else "free")
        self._scale_reference = (float(reference[0]), float(reference[1]))
        self.save_path = None if save_path is None else Path(save_path)
        self.request_rotation = request_rotation
        self.request_excitation = request_excitation
        self._n_added = 0                         # samples added so far
        self._next_try = 0                        # _n_added at which a waiting refit retries
        self._excitation_asked = False
        self._buf: deque[tuple[float, np.ndarray, np.ndarray]] = deque(
            maxlen=max(1, round(opts.buffer_s / model.dt_s)))
        self._pending: AlarmEvent | None = None
        self._scale_pending: AlarmEvent | None = None
        self._drift_pending: AlarmEvent | None = None
        self.history: list[RecalibrationRecord] = []

    @property
    def dc_gain(self) -> Literal["wheel_servo", "free"]:
        """Steady-state gain of a refit: the options', else as the model in use was fitted."""
        return self._dc_gain

    def add(self, t_s: float, cmd_m_s: np.ndarray, speeds: np.ndarray) -> None:
        """Buffer one period: wheel commands ``cmd_m_s`` (2,) [m/s] and measured body speeds
        ``speeds`` (2,) [m/s, rad/s].

        ``speeds`` are the encoder body speeds computed with the model in use's
        ``m_per_tick`` and wheel base (:attr:`model`; after a scale
        adoption the buffered ones are rescaled to the new values). Periods
        with NaN in ``speeds`` are dropped (a refit needs contiguous data; the gap
        is short next to the buffer). A scale alarm that has waited
        ``scale_settle_s`` ends in a rotation request here too.
        """
        u_arr, y_arr = np.asarray(cmd_m_s, float), np.asarray(speeds, float)
        if u_arr.shape != (2,) or y_arr.shape != (2,):
            raise MeasurementShapeError(f"expected u (2,) and y (2,), got {u_arr.shape} and "
                                        f"{y_arr.shape}")
        if self._buf and t_s < self._buf[-1][0]:
            raise TimeOrderError(f"sample at t={t_s} s after one at t={self._buf[-1][0]} s")
        if np.all(np.isfinite(u_arr)) and np.all(np.isfinite(y_arr)):
            self._buf.append((float(t_s), u_arr, y_arr))
            self._n_added += 1
        if self._pending is not None and self._n_added >= self._next_try:
            self.retry()
        if (self._scale_pending is not None
                and t_s - self._scale_pending.t_s >= self.options.scale_settle_s):
            self._record(self._rotation(float(t_s), "no precise landmark scale within "
                                                    f"{self.options.scale_settle_s:g} s"))
        if (self._drift_pending is not None
                and t_s - self._drift_pending.t_s >= self.options.scale_settle_s):
            self._record(self._drift_unsettled(float(t_s)))

    @property
    def waiting(self) -> bool:
        """Whether a dynamics refit waits for data."""
        return self._pending is not None

    @property
    def scale_waiting(self) -> bool:
        """Whether a scale alarm waits for a precise landmark estimate (:meth:`update_scale`)."""
        return self._scale_pending is not None

    def _record(self, record: RecalibrationRecord) -> RecalibrationRecord:
        self.history.append(record)
        _log.info("recalibration at t=%.2f s: %s %s", record.t_s, record.action, record.reason)
        return record

    def on_alarm(self, event: AlarmEvent) -> RecalibrationRecord:
        """Answer an alarm (usable as the monitor's ``on_alarm`` callback)."""
        if event.kind == "dynamics_changed":
            t_s = event.t_s
            if self._pending is not None:          # still waiting: keep the earliest onset
                event = min(event, self._pending, key=lambda e: e.onset_s)
            record = self._refit(event, t_s)
        elif event.kind == "scale_changed":
            record = self._scale_alarm(event)
        elif event.kind == "wheel_drift":
            record = self._drift_alarm(event)
        elif event.kind == "filter_reset":
            record = RecalibrationRecord(event.t_s, event, "ignored",
                                         reason="the filter reset itself; the model is kept")
        else:
            record = RecalibrationRecord(event.t_s, event, "ignored",
                                         reason="sensor fault: the model is not at fault")
        return self._record(record)

    def retry(self) -> RecalibrationRecord | None:
        """Try the refit again for an alarm that was left waiting (more data since)."""
        if self._pending is None:
            return None
        t_s = self._buf[-1][0] if self._buf else self._pending.t_s
        return self._record(self._refit(self._pending, t_s))

    # -- scale -----------------------------------------------------------------------------------
    def update_scale(self, t_s: float, scale_ratio: float, scale_ratio_std: float,
                     yaw_ratio: float = math.nan, yaw_ratio_std: float = math.inf
                     ) -> RecalibrationRecord | None:
        """Offer the scale monitor's running estimate to a waiting scale alarm.

        Parameters
        ----------
        t_s : float
            Time of the estimate [s].
        scale_ratio, scale_ratio_std : float
            Ground travel per encoder travel and its standard deviation
            (:attr:`ScaleMonitor.scale_ratio`, :attr:`~ScaleMonitor.scale_ratio_std`),
            relative to ``scale_reference``.
        yaw_ratio, yaw_ratio_std : float, optional
            The same for turns (NaN: not estimated).

        Returns
        -------
        RecalibrationRecord or None
            The decision (``"adopted"`` or ``"rotation_requested"``) if this
            estimate ended the wait; None if nothing waits or it goes on.
        """
        if self._scale_pending is None:
            return None
        if math.isfinite(scale_ratio) and scale_ratio_std <= self.options.max_scale_std:
            return self._record(self._adopt_scale(float(t_s), self._scale_pending, scale_ratio,
                                                  scale_ratio_std, yaw_ratio, yaw_ratio_std))
        if t_s - self._scale_pending.t_s >= self.options.scale_settle_s:
            return self._record(self._rotation(float(t_s), "no precise landmark scale within "
                                                           f"{self.options.scale_settle_s:g} s"))
        return None

    def _scale_alarm(self, event: AlarmEvent) -> RecalibrationRecord:
        self._scale_pending = event            # a later alarm replaces one still waiting
        a = event.scale
        if a is None:
            return self._rotation(event.t_s, "the alarm carries no scale estimate")
        if math.isfinite(a.scale_ratio) and a.scale_ratio_std <= self.options.max_scale_std:
            return self._adopt_scale(event.t_s, event, a.scale_ratio, a.scale_ratio_std,
                                     a.yaw_ratio, a.yaw_ratio_std)
        if self.options.scale_settle_s <= 0.0:
            return self._rotation(event.t_s, f"scale std {a.scale_ratio_std:.4f} > "
                                             f"{self.options.max_scale_std:g}")
        return RecalibrationRecord(
            event.t_s, event, "waiting",
            reason=f"scale {a.scale_ratio:.4f} +- {a.scale_ratio_std:.4f} (need std <= "
                   f"{self.options.max_scale_std:g}): waiting up to "
                   f"{self.options.scale_settle_s:g} s for the landmark estimate")

    def _rotation(self, t_s: float, reason: str) -> RecalibrationRecord:
        event, self._scale_pending = self._scale_pending, None
        if self.request_rotation is None:
            return RecalibrationRecord(t_s, event, "kept_old",
                                       reason=reason + "; no request_rotation callback")
        self.request_rotation(event)
        return RecalibrationRecord(t_s, event, "rotation_requested", reason=reason)

    def _adopt_scale(self, t_s: float, event: AlarmEvent, ratio: float, ratio_std: float,
                     yaw: float, yaw_std: float) -> RecalibrationRecord:
        m_ref, b_ref = self._scale_reference
        with_yaw = math.isfinite(yaw) and yaw > 0 and yaw_std <= self.options.max_scale_std
        m_new = m_ref * ratio
        b_new = b_ref * ratio / yaw if with_yaw else b_ref     # fusion.monitoring.rescale eq. 1
        old = self.model
        s = output_scaling(old, m_per_tick=m_new, wheel_base_m=b_new)
        self.model = rescaled_model(old, m_per_tick=m_new, wheel_base_m=b_new)
        self._buf = deque(((t, u, y * s) for t, u, y in self._buf), maxlen=self._buf.maxlen)
        self._scale_pending = None
        saved = None if self.save_path is None else str(self.model.save(self.save_path))
        yaw_note = (f", yaw {yaw:.4f} +- {yaw_std:.4f}" if with_yaw
                    else ", yaw not precise: wheel base kept")
        return RecalibrationRecord(
            t_s, event, "adopted", reason=f"landmark scale {ratio:.4f} +- {ratio_std:.4f}"
            + yaw_note, saved_to=saved, m_per_tick=(float(old.m_per_tick), m_new),
            wheel_base_m=(old.wheel_base_m, b_new))

    # -- wheel drift -------------------------------------------------------------------------
    @property
    def drift_waiting(self) -> bool:
        """Whether a wheel-drift alarm waits for a precise curvature (:meth:`update_intrinsics`)."""
        return self._drift_pending is not None

    def update_intrinsics(self, t_s: float, intrinsics: OdometryIntrinsics,
                          curvature_std_rad_per_m: float) -> RecalibrationRecord | None:
        """Offer the scale monitor's running intrinsics to a waiting wheel-drift alarm.

        Parameters
        ----------
        t_s : float
            Time of the estimate [s].
        intrinsics : OdometryIntrinsics
            :meth:`ScaleMonitor.intrinsics_estimate`.
        curvature_std_rad_per_m : float
            Its curvature's standard deviation (:attr:`ScaleMonitor.curvature_std_rad_per_m`).

        Returns
        -------
        RecalibrationRecord or None
            The decision if this estimate ended the wait (``"adopted"`` or
            ``"kept_old"``); None if nothing waits or it goes on.
        """
        if self._drift_pending is None:
            return None
        if curvature_std_rad_per_m <= self.options.max_curvature_std_rad_per_m:
            return self._record(self._adopt_intrinsics(float(t_s), self._drift_pending,
                                                       intrinsics, curvature_std_rad_per_m))
        if t_s - self._drift_pending.t_s >= self.options.scale_settle_s:
            return self._record(self._drift_unsettled(float(t_s)))
        return None

    def _drift_alarm(self, event: AlarmEvent) -> RecalibrationRecord:
        a = event.scale
        if a is None or a.intrinsics is None:
            return RecalibrationRecord(event.t_s, event, "kept_old",
                                       reason="the alarm carries no intrinsics estimate")
        if a.curvature_std_rad_per_m <= self.options.max_curvature_std_rad_per_m:
            return self._adopt_intrinsics(event.t_s, event, a.intrinsics,
                                          a.curvature_std_rad_per_m)
        self._drift_pending = event            # a later alarm replaces one still waiting
        return RecalibrationRecord(
            event.t_s, event, "waiting",
            reason=f"curvature {a.curvature_rad_per_m:.4f} +- {a.curvature_std_rad_per_m:.4f} "
                   f"rad/m (need std <= {self.options.max_curvature_std_rad_per_m:g}): waiting "
                   f"up to {self.options.scale_settle_s:g} s for the landmark estimate")

    def _drift_unsettled(self, t_s: float) -> RecalibrationRecord:
        event, self._drift_pending = self._drift_pending, None
        return RecalibrationRecord(t_s, event, "kept_old",
                                   reason="no precise curvature within "
                                          f"{self.options.scale_settle_s:g} "
                                          "s: drive past landmarks and recalibrate the "
                                          "intrinsics (docs/intrinsics.md)")

    def _adopt_intrinsics(self, t_s: float, event: AlarmEvent, new: OdometryIntrinsics,
                          curvature_std: float) -> RecalibrationRecord:
        """The model with ``new`` intrinsics, its outputs transformed so that it predicts the
        same counts (:meth:`lti_motion.model.MotionModel.with_intrinsics`, ``T = J' J^-1``)."""
        old = self.model
        before = old.encoder_intrinsics
        T = new.jacobian() @ np.linalg.inv(before.jacobian())
        self.model = old.with_intrinsics(new)
        self._buf = deque(((t, u, T @ y) for t, u, y in self._buf), maxlen=self._buf.maxlen)
        self._drift_pending = None
        saved = None if self.save_path is None else str(self.model.save(self.save_path))
        return RecalibrationRecord(
            t_s, event, "adopted", reason=f"diameter ratio (left / right) "
            f"{before.diameter_ratio:.5f} -> {new.diameter_ratio:.5f}, curvature std "
            f"{curvature_std:.4f} rad/m", saved_to=saved,
            m_per_tick=(float(old.m_per_tick), new.m_per_tick),
            wheel_base_m=(old.wheel_base_m, new.wheel_base_m), intrinsics=(before, new))

    def _segments(self, onset_s: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """Contiguous runs of buffered ``(u, y)`` since ``onset_s`` (split at time gaps)."""
        rows = [(t, u, y) for t, u, y in self._buf if t >= onset_s]
        runs: list[list[tuple[float, np.ndarray, np.ndarray]]] = []
        for row in rows:
            if not runs or row[0] - runs[-1][-1][0] > 1.5 * self.model.dt_s:
                runs.append([])
            runs[-1].append(row)
        return [(np.stack([r[1] for r in run]), np.stack([r[2] for r in run])) for run in runs]

    def _wait(self, event: AlarmEvent, t_s: float, n: int, reason: str) -> RecalibrationRecord:
        self._pending = event
        self._next_try = self._n_added + self._retry_samples
        if self.request_excitation is not None and not self._excitation_asked:
            self._excitation_asked = True
            self.request_excitation(event)
        return RecalibrationRecord(t_s, event, "waiting", n, reason=reason)

    def _refit(self, event: AlarmEvent, t_s: float) -> RecalibrationRecord:
        # the shortest run fit_arx can use: the longest regressor of the grid, and some more
        shortest = 10 * (max(self._orders) + max(self._delays) + 1)
        runs = [r for r in self._segments(event.onset_s) if len(r[0]) >= shortest]
        n = sum(len(r[0]) for r in runs)
        if n < self.options.min_samples:
            return self._wait(event, t_s, n,
                              f"{n} samples since the onset, need {self.options.min_samples}")
        n_val = max(shortest, round(self.options.validation_fraction * n))
        u_last, y_last = runs[-1]
        if len(u_last) - n_val < shortest:            # the newest run is all validation
            train, val = runs[:-1], [runs[-1]]
        else:
            train = [*runs[:-1], (u_last[:-n_val], y_last[:-n_val])]
            val = [(u_last[-n_val:], y_last[-n_val:])]
        if not train:
            return self._wait(event, t_s, n, "one short run since the onset: nothing to train on")
        try:
            new = fit_arx(train, dt_s=self.model.dt_s, wheel_base_m=self.model.wheel_base_m,
                          orders=self._orders, delays=self._delays,
                          m_per_tick=self.model.m_per_tick, floor=self.model.floor,
                          dc_gain=self._dc_gain)
        except CalibrationError as exc:      # not excited enough, too short, unstable
            return self._wait(event, t_s, n, str(exc))
        self._pending = None
        self._excitation_asked = False
        before = self.model.fit_percent(val)
        after = new.fit_percent(val)
        fits = (float(before[0]), float(before[1])), (float(after[0]), float(after[1]))
        gain = float(np.mean(after) - np.mean(before))
        if not (math.isfinite(gain) and gain >= self.options.min_gain_pp):
            return RecalibrationRecord(t_s, event, "kept_old", n, *fits,
                                       reason=f"held-out fit gain {gain:.2f} pp")
        new = new.updated(robot=self.model.robot)     # the same robot, refitted
        self.model = new
        saved = None if self.save_path is None else str(new.save(self.save_path))
        return RecalibrationRecord(t_s, event, "adopted", n, *fits,
                                   reason=f"held-out fit gain {gain:.2f} pp", saved_to=saved)
