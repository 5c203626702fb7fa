"""Phase I of the monitor: what it learns from nominal driving before it watches.

Two parts of the monitor are set from drives of the robot in its normal state,
on the kind of route it will drive, as a control chart's Phase I (Montgomery
2009, section 5.3.5):

- the dynamics null of :class:`~fusion.monitoring.DynamicsMonitor`
  (:func:`~fusion.monitoring.fit_dynamics_null`, commands and
  counts only): the linear model's misfit depends on the manoeuvre, so the null
  is fitted on the drives the robot will do;
- the encoder stream's per-sample gate (``MonitorOptions.encoder_gate_nis``):
  the chi-square gate assumes Gaussian innovations, but a linear model misses
  every start from rest by tens of standard deviations. Rule: ``gate_factor``
  (10) times the largest encoder NIS of :class:`~fusion.ekf.ModelEKF` over the
  nominal drives, never below the chi-square gate. What this gives on the
  simulator's routes is measured in ``docs/monitor.md``.

:func:`fit_nominal` does both from what a robot reports (commands and raw
counts); :class:`~fusion.monitoring.MonitoredFilter` takes its result.

References
----------
Montgomery, D. C. (2009). Introduction to Statistical Quality Control, 6th
ed., Wiley, section 5.3.5 (Phase I and Phase II of control chart use).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.model_ekf import ModelEKF
from fusion.exceptions import FilterOptionError, MeasurementShapeError
from fusion.monitoring.dynamics_null import DynamicsNull, fit_dynamics_null
from fusion.monitoring.residual import MonitorOptions, design_thresholds
from lti_motion.model.motion_model import MotionModel
from lti_motion.recordings.ticks import tick_deltas

__all__ = ["NominalFit", "encoder_nis", "fit_nominal"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class NominalFit:
    """What the monitor learnt from nominal driving (:func:`fit_nominal`).

    Attributes
    ----------
    null : DynamicsNull
        The dynamics tests' null.
    encoder_gate_nis : float
        Per-sample gate of the encoder innovations (module rule).
    max_nominal_nis : float
        The largest encoder NIS of the nominal drives.
    duration_s : float
        Nominal driving used [s].
    n_drives : int
        Drives used.
    """

    null: DynamicsNull
    encoder_gate_nis: float
    max_nominal_nis: float
    duration_s: float
    n_drives: int

    def options(self, dt_s: float) -> MonitorOptions:
        """Monitor options with this gate and period ``dt_s`` [s], everything else default."""
        return MonitorOptions(dt_s=dt_s, encoder_gate_nis=self.encoder_gate_nis)


def encoder_nis(model: MotionModel, cmd_m_s: np.ndarray, ticks: np.ndarray) -> np.ndarray:
    """NIS of the :class:`~fusion.ekf.ModelEKF` encoder updates of one drive.

    Parameters
    ----------
    model : MotionModel
        The model; needs ``m_per_tick``.
    cmd_m_s : ndarray, shape (n, 2)
        Wheel commands of periods ``1 .. n`` [m/s].
    ticks : ndarray, shape (n + 1, 2)
        Raw counts of frames ``0 .. n`` (frame 0 anchors).

    Returns
    -------
    ndarray, shape (n,)
        NaN where a reading was not compared.
    """
    ekf = ModelEKF(model, initial_ticks=np.asarray(ticks[0], np.int64),
                   options=EKFOptions(history=0))
    out = np.full(len(cmd_m_s), math.nan)
    for k, cmd in enumerate(np.asarray(cmd_m_s, float)):
        ekf.predict(cmd)
        out[k] = ekf.update_encoders(np.asarray(ticks[k + 1], np.int64)).nis
    return out


def fit_nominal(model: MotionModel, drives: Sequence[tuple[np.ndarray, np.ndarray]], *,
                gate_factor: float = 10.0, skip_s: float = 0.5,
                progress: Callable[[str, int, int], None] | None = None) -> NominalFit:
    """Fit the dynamics null and the encoder gate on nominal drives (module notes).

    Parameters
    ----------
    model : MotionModel
        The model the monitor will use.
    drives : sequence of (cmd_m_s (n, 2), ticks (n + 1, 2))
        Nominal drives: the commands of periods ``1 .. n`` [m/s] and the raw
        counts of frames ``0 .. n`` (what a robot reports).
    gate_factor : float
        The gate is this many times the largest nominal NIS.
    skip_s : float
        Start of each drive left out of the null [s]. Drives that start at
        rest start where the predictor's state is exact, so the default keeps
        the start from rest in the null (with ``fit_dynamics_null``'s own 3 s,
        nominal drives raise dynamics alarms at their starts:
        ``docs/guide_alarms.md``).
    progress : callable, optional
        Called as ``progress(stage, done, total)``: ``("encoder NIS", i, n_drives)``
        after each drive's filter run, then ``("dynamics null", 0, 1)`` before the
        null's maximum-likelihood fit (the longest step: tens of seconds for 20 drives
        of 30 s) and ``("dynamics null", 1, 1)`` after it. The same steps are logged
        (``logging``, INFO) with their wall time.

    Returns
    -------
    NominalFit

    Raises
    ------
    FilterOptionError
        Without drives, with a factor below 1, or with too little driving for
        the null.
    MeasurementShapeError
        If a drive's commands and counts do not pair up.
    """
    if not drives:
        raise FilterOptionError("fit_nominal needs at least one nominal drive")
    if not gate_factor >= 1.0:
        raise FilterOptionError(f"gate_factor must be >= 1, got {gate_factor}")
    def report(stage: str, done: int, total: int) -> None:
        if progress is not None:
            progress(stage, done, total)

    runs, peak, n = [], 0.0, 0
    started = time.perf_counter()
    for cmd, ticks in drives:
        cmd = np.asarray(cmd, float)
        ticks = np.asarray(ticks)
        if cmd.ndim != 2 or ticks.shape != (len(cmd) + 1, 2):
            raise MeasurementShapeError(f"expected commands (n, 2) and ticks (n + 1, 2), got "
                                        f"{cmd.shape} and {ticks.shape}")
        runs.append((cmd, tick_deltas(ticks.astype(np.int64), axis=0).astype(float)))
        peak = max(peak, float(np.nanmax(encoder_nis(model, cmd, ticks), initial=0.0)))
        n += len(cmd)
        report("encoder NIS", len(runs), len(drives))
    _log.info("phase I: encoder NIS of %d nominal drives (%.1f s of driving) in %.1f s",
              len(runs), n * model.dt_s, time.perf_counter() - started)
    chi2_gate = design_thresholds(MonitorOptions(dt_s=model.dt_s)).gate
    report("dynamics null", 0, 1)
    started = time.perf_counter()
    null = fit_dynamics_null(model, runs, skip_s=skip_s)
    _log.info("phase I: dynamics null fitted in %.1f s", time.perf_counter() - started)
    report("dynamics null", 1, 1)
    return NominalFit(null=null, encoder_gate_nis=max(chi2_gate, gate_factor * peak),
                      max_nominal_nis=peak, duration_s=n * model.dt_s, n_drives=len(runs))
