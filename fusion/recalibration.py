"""Recalibration policy: what to do with a monitor alarm (:mod:`fusion.monitor`).

:class:`Recalibrator` buffers commands and measured body speeds and answers
each :class:`~fusion.monitor.AlarmEvent`:

- ``"dynamics_changed"``: refit an ARX model (:func:`lti_motion.model.fit_arx`)
  on the data since the alarm's estimated onset, when there is enough of it
  and it excites the model enough (``fit_arx`` raises
  :class:`~lti_motion.exceptions.NotExcitedError` or
  :class:`~lti_motion.exceptions.CalibrationError` otherwise: the policy then
  waits and tries again at the next alarm or :meth:`Recalibrator.retry`).
  The newest ``validation_fraction`` of that data is held out; the new model
  replaces the old only if its free-run fit there (mean of the two channels,
  :meth:`MotionModel.fit_percent`) beats the old model's by at least
  ``min_gain_pp`` percentage points. An adopted model is saved atomically
  (:meth:`MotionModel.save`) when a path is given.
- ``"scale_changed"``: the application's ``request_rotation`` callback is
  called (the robot decides when a rotation manoeuvre is safe).
- sensor alarms (``"glitch_burst"``, ``"stuck_encoder"``): no recalibration;
  recorded as ``"ignored"``.

Every decision is a frozen :class:`RecalibrationRecord` in
:attr:`Recalibrator.history`: what, when, the fits before and after.

Status: the policy works on simulator data with an alarm given to it
(``tests/fusion/test_monitor.py``); the monitor's own dynamics alarms are not
yet reliable (``docs/monitor.md``).
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

from fusion.exceptions import FilterOptionError, MeasurementShapeError
from fusion.monitor import AlarmEvent, TimeOrderError
from lti_motion.exceptions import CalibrationError
from lti_motion.model import MotionModel, fit_arx

__all__ = ["RecalibrationAction", "RecalibrationRecord", "Recalibrator"]

_log = logging.getLogger(__name__)

RecalibrationAction = Literal["adopted", "kept_old", "waiting", "rotation_requested", "ignored"]


@dataclass(frozen=True)
class RecalibrationRecord:
    """One answer of the policy to an alarm.

    Attributes
    ----------
    t_s : float
        Time of the decision (the alarm's time) [s].
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
    """

    t_s: float
    alarm: AlarmEvent
    action: RecalibrationAction
    n_samples: int = 0
    fit_before: tuple[float, float] | None = None
    fit_after: tuple[float, float] | None = None
    reason: str = ""
    saved_to: str | None = None


class Recalibrator:
    """Keeps the current model and replaces it after a dynamics alarm when a refit validates better.

    Parameters
    ----------
    model : MotionModel
        The model in use.
    buffer_s : float
        Seconds of ``(t, u, y)`` kept [s].
    min_samples : int
        Fewest samples since the onset for a refit attempt.
    validation_fraction : float
        Newest share of the data since the onset held out for validation.
    min_gain_pp : float
        Percentage points the new model's held-out fit must gain to replace the old.
    orders, delays : sequence of int
        Selection grid of the refit (default: around the current model's order).
    save_path : path-like, optional
        Where an adopted model is saved (atomically).
    request_rotation : callable, optional
        Called with the alarm on ``"scale_changed"``.
    """

    def __init__(self, model: MotionModel, *, buffer_s: float = 120.0, min_samples: int = 2000,
                 validation_fraction: float = 0.3, min_gain_pp: float = 0.0,
                 orders: tuple[int, ...] | None = None, delays: tuple[int, ...] | None = None,
                 save_path: str | os.PathLike | None = None,
                 request_rotation: Callable[[AlarmEvent], None] | None = None) -> None:
        if not (0.0 < validation_fraction < 1.0 and buffer_s > 0 and min_samples > 0):
            raise FilterOptionError(
                f"need 0 < validation_fraction < 1, buffer_s > 0, min_samples > 0; got "
                f"{validation_fraction}, {buffer_s}, {min_samples}")
        self.model = model
        self.min_samples = int(min_samples)
        self.validation_fraction = float(validation_fraction)
        self.min_gain_pp = float(min_gain_pp)
        na = int(model.orders.get("na", 4))
        self.orders = orders or tuple(range(max(1, na - 2), na + 3))
        self.delays = delays or tuple(range(0, 9))
        self.save_path = None if save_path is None else Path(save_path)
        self.request_rotation = request_rotation
        self._buf: deque[tuple[float, np.ndarray, np.ndarray]] = deque(
            maxlen=max(1, round(buffer_s / model.dt_s)))
        self._pending: AlarmEvent | None = None
        self.history: list[RecalibrationRecord] = []

    def add(self, t_s: float, u: np.ndarray, y: np.ndarray) -> None:
        """Buffer one period: commands ``u`` (2,) [m/s], measured speeds ``y`` (2,) [m/s, rad/s].

        Periods with NaN in ``y`` are dropped (a refit needs contiguous data;
        the gap is short next to the buffer).
        """
        u_arr, y_arr = np.asarray(u, float), np.asarray(y, float)
        if u_arr.shape != (2,) or y_arr.shape != (2,):
            raise MeasurementShapeError(f"expected u (2,) and y (2,), got {u_arr.shape} and "
                                        f"{y_arr.shape}")
        if self._buf and t_s < self._buf[-1][0]:
            raise TimeOrderError(f"sample at t={t_s} s after one at t={self._buf[-1][0]} s")
        if np.all(np.isfinite(u_arr)) and np.all(np.isfinite(y_arr)):
            self._buf.append((float(t_s), u_arr, y_arr))

    def on_alarm(self, event: AlarmEvent) -> RecalibrationRecord:
        """Answer an alarm (usable as the monitor's ``on_alarm`` callback)."""
        if event.kind == "dynamics_changed":
            record = self._refit(event)
        elif event.kind == "scale_changed":
            if self.request_rotation is not None:
                self.request_rotation(event)
            record = RecalibrationRecord(event.t_s, event, "rotation_requested")
        else:
            record = RecalibrationRecord(event.t_s, event, "ignored",
                                         reason="sensor fault: the model is not at fault")
        self.history.append(record)
        _log.info("recalibration at t=%.2f s: %s %s", event.t_s, record.action, record.reason)
        return record

    def retry(self) -> RecalibrationRecord | None:
        """Try the refit again for an alarm that was left waiting (more data since)."""
        if self._pending is None:
            return None
        record = self._refit(self._pending)
        self.history.append(record)
        return record

    def _refit(self, event: AlarmEvent) -> RecalibrationRecord:
        since = [(u, y) for t, u, y in self._buf if t >= event.onset_s]
        n = len(since)
        if n < self.min_samples:
            self._pending = event
            return RecalibrationRecord(event.t_s, event, "waiting", n,
                                       reason=f"{n} samples since the onset, need "
                                              f"{self.min_samples}")
        u = np.stack([s[0] for s in since])
        y = np.stack([s[1] for s in since])
        n_val = max(1, round(self.validation_fraction * n))
        train, val = [(u[:-n_val], y[:-n_val])], [(u[-n_val:], y[-n_val:])]
        try:
            new = fit_arx(train, dt_s=self.model.dt_s, wheel_base_m=self.model.wheel_base_m,
                          orders=self.orders, delays=self.delays,
                          m_per_tick=self.model.m_per_tick, floor=self.model.floor)
        except CalibrationError as exc:      # not excited enough, too short, unstable
            self._pending = event
            return RecalibrationRecord(event.t_s, event, "waiting", n, reason=str(exc))
        self._pending = None
        before = self.model.fit_percent(val)
        after = new.fit_percent(val)
        fits = (float(before[0]), float(before[1])), (float(after[0]), float(after[1]))
        gain = float(np.mean(after) - np.mean(before))
        if not (math.isfinite(gain) and gain >= self.min_gain_pp):
            return RecalibrationRecord(event.t_s, event, "kept_old", n, *fits,
                                       reason=f"held-out fit gain {gain:.2f} pp")
        self.model = new
        saved = None if self.save_path is None else str(new.save(self.save_path))
        return RecalibrationRecord(event.t_s, event, "adopted", n, *fits,
                                   reason=f"held-out fit gain {gain:.2f} pp", saved_to=saved)
