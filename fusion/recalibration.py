"""Recalibration policy: what to do with a monitor alarm (:mod:`fusion.monitor`).

:class:`Recalibrator` buffers commands and measured body speeds and answers
each :class:`~fusion.monitor.AlarmEvent`:

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
- ``"scale_changed"``: the application's ``request_rotation`` callback is
  called (the robot decides when a rotation manoeuvre is safe).
- sensor alarms (``"glitch_burst"``, ``"stuck_encoder"``): no recalibration;
  recorded as ``"ignored"``.

Every decision is a frozen :class:`RecalibrationRecord` in
:attr:`Recalibrator.history`: what, when, the fits before and after.

Measured on the simulator with the monitor's own alarms and an excitation
manoeuvre on request (``benchmarks/bench_monitor.py``, ``recalibration``;
``docs/monitor.md``). Not done: a recursive-least-squares model in use while
waiting (:class:`lti_motion.arx.RecursiveARX` exists), a landmark-based scale
re-estimate.
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
    request_excitation : callable, optional
        Called with the alarm, once, when a dynamics refit has to wait for
        data that excites the model.
    retry_samples : int, optional
        New samples between automatic retries while waiting (default
        ``min_samples // 4``).
    dc_gain : {"wheel_servo", "free"}, optional
        Steady-state gain of the refit (:func:`lti_motion.model.fit_arx`);
        default: as the model in use was fitted (``"wheel_servo"`` when its
        diagnostics hold ``dc_gain_scale``).
    """

    def __init__(self, model: MotionModel, *, buffer_s: float = 120.0, min_samples: int = 2000,
                 validation_fraction: float = 0.3, min_gain_pp: float = 0.0,
                 orders: tuple[int, ...] | None = None, delays: tuple[int, ...] | None = None,
                 save_path: str | os.PathLike | None = None,
                 request_rotation: Callable[[AlarmEvent], None] | None = None,
                 request_excitation: Callable[[AlarmEvent], None] | None = None,
                 retry_samples: int | None = None,
                 dc_gain: Literal["wheel_servo", "free"] | None = None) -> None:
        if not (0.0 < validation_fraction < 1.0 and buffer_s > 0 and min_samples > 0):
            raise FilterOptionError(
                f"need 0 < validation_fraction < 1, buffer_s > 0, min_samples > 0; got "
                f"{validation_fraction}, {buffer_s}, {min_samples}")
        if dc_gain not in (None, "wheel_servo", "free"):
            raise FilterOptionError(f"dc_gain must be 'wheel_servo' or 'free', got {dc_gain!r}")
        self.model = model
        self.min_samples = int(min_samples)
        self.validation_fraction = float(validation_fraction)
        self.min_gain_pp = float(min_gain_pp)
        na = int(model.orders.get("na", 4))
        self.orders = orders or tuple(range(max(1, na - 2), na + 3))
        self.delays = delays or tuple(range(0, 9))
        self.save_path = None if save_path is None else Path(save_path)
        self.request_rotation = request_rotation
        self.request_excitation = request_excitation
        self.retry_samples = max(1, int(retry_samples if retry_samples is not None
                                        else self.min_samples // 4))
        self.dc_gain = dc_gain or ("wheel_servo" if "dc_gain_scale" in model.diagnostics
                                   else "free")
        self._n_added = 0                         # samples added so far
        self._next_try = 0                        # _n_added at which a waiting refit retries
        self._excitation_asked = False
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
            self._n_added += 1
        if self._pending is not None and self._n_added >= self._next_try:
            self.retry()

    @property
    def waiting(self) -> bool:
        """Whether a dynamics refit waits for data."""
        return self._pending is not None

    def on_alarm(self, event: AlarmEvent) -> RecalibrationRecord:
        """Answer an alarm (usable as the monitor's ``on_alarm`` callback)."""
        if event.kind == "dynamics_changed":
            if self._pending is not None:          # still waiting: keep the earliest onset
                event = min(event, self._pending, key=lambda e: e.onset_s)
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
        _log.info("recalibration retry: %s %s", record.action, record.reason)
        return record

    def _segments(self, onset_s: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """Contiguous runs of buffered ``(u, y)`` since ``onset_s`` (split at time gaps)."""
        rows = [(t, u, y) for t, u, y in self._buf if t >= onset_s]
        runs: list[list[tuple[float, np.ndarray, np.ndarray]]] = []
        for row in rows:
            if not runs or row[0] - runs[-1][-1][0] > 1.5 * self.model.dt_s:
                runs.append([])
            runs[-1].append(row)
        return [(np.stack([r[1] for r in run]), np.stack([r[2] for r in run])) for run in runs]

    def _wait(self, event: AlarmEvent, n: int, reason: str) -> RecalibrationRecord:
        self._pending = event
        self._next_try = self._n_added + self.retry_samples
        if self.request_excitation is not None and not self._excitation_asked:
            self._excitation_asked = True
            self.request_excitation(event)
        return RecalibrationRecord(event.t_s, event, "waiting", n, reason=reason)

    def _refit(self, event: AlarmEvent) -> RecalibrationRecord:
        # the shortest run fit_arx can use: the longest regressor of the grid, and some more
        shortest = 10 * (max(self.orders) + max(self.delays) + 1)
        runs = [r for r in self._segments(event.onset_s) if len(r[0]) >= shortest]
        n = sum(len(r[0]) for r in runs)
        if n < self.min_samples:
            return self._wait(event, n, f"{n} samples since the onset, need {self.min_samples}")
        n_val = max(shortest, round(self.validation_fraction * n))
        u_last, y_last = runs[-1]
        if len(u_last) - n_val < shortest:            # the newest run is all validation
            train, val = runs[:-1], [runs[-1]]
        else:
            train = [*runs[:-1], (u_last[:-n_val], y_last[:-n_val])]
            val = [(u_last[-n_val:], y_last[-n_val:])]
        if not train:
            return self._wait(event, n, "one short run since the onset: nothing to train on")
        try:
            new = fit_arx(train, dt_s=self.model.dt_s, wheel_base_m=self.model.wheel_base_m,
                          orders=self.orders, delays=self.delays,
                          m_per_tick=self.model.m_per_tick, floor=self.model.floor,
                          dc_gain=self.dc_gain)
        except CalibrationError as exc:      # not excited enough, too short, unstable
            return self._wait(event, n, str(exc))
        self._pending = None
        self._excitation_asked = False
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
