"""Offline calibration from any recording, with an excitation report.

Any drive with enough excitation will do, not only the paper's manoeuvres:
:func:`excitation_report` says how well a recording determines the model
(condition of the regression, frequency content of the commands, time at
rest, which parameters the data leave unidentified) and why it refuses data
that cannot identify one; :func:`calibrate_recording` fits the ARX model
(paper section II.C) on it. A Roomba recording that holds a rotation in place beside
a wall measures the encoder scale (paper eq. 13, :func:`rotation_scale`);
without one the scale comes from the robot description the caller gives,
and the result says so.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from lti_motion.calibration.encoder_scale import (
    RotationPeriod,
    encoder_scale_m_per_tick,
    rotation_period_ticks,
)
from lti_motion.exceptions import CalibrationError, NotExcitedError
from lti_motion.kinematics import body_from_wheel
from lti_motion.model.excitation import DEFAULT_MAX_CONDITION, excitation_condition_number
from lti_motion.model.motion_model import MotionModel, fit_arx
from lti_motion.recordings.recording import Recording
from lti_motion.recordings.resample import MAX_WHEEL_SPEED_M_S, GridSignals, on_grid

__all__ = ["MIN_FIT_SAMPLES", "ExcitationReport", "OfflineCalibration", "calibrate_recording",
           "excitation_report", "rotation_scale"]

_log = logging.getLogger(__name__)

#: A wheel command below this counts as zero, for the time at rest [m/s].
_REST_M_S = 0.005


@dataclass(frozen=True)
class ExcitationReport:
    """How well a recording determines the motion model.

    Attributes
    ----------
    duration_s, moving_s : float
        Length of the recording on the model grid, and time with a non-zero
        command or measured motion [s].
    rest_fraction : float
        Fraction of the periods at rest (no command, no motion).
    condition : float
        Condition number of the column-scaled lagged-command matrix of the
        regression (:func:`~lti_motion.model.excitation_condition_number`,
        ``n_lags`` lags); ``inf`` when singular.
    n_lags : int
        Lags of that matrix (the largest input order tried).
    cmd_std : tuple of float
        Standard deviation of the commanded (v [m/s], w [rad/s]).
    bandwidth_hz : tuple of float
        Frequency below which 90% of the power of the commanded v and w
        (mean removed) lies [Hz].
    lr_correlation : float
        Correlation of the left and right wheel commands (+1: only straight
        lines, -1: only turns in place).
    not_identified : tuple of str
        Parameters the data leave to the robot description or cannot give.
    refusals : tuple of str
        Why the data cannot identify a model (empty: they can).
    clock : str
        The clock summary (sensor period, drift, lost / late / merged frames).
    """

    duration_s: float
    moving_s: float
    rest_fraction: float
    condition: float
    n_lags: int
    cmd_std: tuple[float, float]
    bandwidth_hz: tuple[float, float]
    lr_correlation: float
    not_identified: tuple[str, ...]
    refusals: tuple[str, ...]
    clock: str

    @property
    def identifiable(self) -> bool:
        """Whether the data can identify a model."""
        return not self.refusals

    def lines(self) -> list[str]:
        """The report as printable lines."""
        out = [f"recording: {self.duration_s:.1f} s on the model grid, {self.moving_s:.1f} s "
               f"moving ({100 * self.rest_fraction:.0f}% at rest)",
               f"clock: {self.clock}",
               f"condition of the regression ({self.n_lags} command lags): {self.condition:.3g}"
               f" (limit {DEFAULT_MAX_CONDITION:.0e})",
               f"commands: std v {self.cmd_std[0]:.3f} m/s, w {self.cmd_std[1]:.3f} rad/s; 90% "
               f"of their power below {self.bandwidth_hz[0]:.2f} Hz (v), "
               f"{self.bandwidth_hz[1]:.2f} Hz (w); left-right correlation "
               f"{self.lr_correlation:+.2f}"]
        out += [f"not identified: {item}" for item in self.not_identified]
        out += [f"refused: {item}" for item in self.refusals]
        return out


def _bandwidth_hz(x: np.ndarray, period_s: float) -> float:
    """Frequency below which 90% of the power of ``x`` (mean removed) lies [Hz]."""
    power = np.abs(np.fft.rfft(x - x.mean())) ** 2
    if power.sum() == 0:
        return 0.0
    freq = np.fft.rfftfreq(x.size, d=period_s)
    return float(freq[np.searchsorted(np.cumsum(power) / power.sum(), 0.9)])


def excitation_report(grid: GridSignals, *, wheel_base_m: float, n_lags: int = 12,
                      min_moving_s: float = 30.0, min_std_m_s: float = 0.02,
                      scale_from: str | None = None) -> ExcitationReport:
    """How well a recording on the model grid determines the ARX model.

    Parameters
    ----------
    grid : GridSignals
        From :func:`lti_motion.recordings.on_grid`.
    wheel_base_m : float
        Wheel base [m] (turns the commands into v and w).
    n_lags : int
        Command lags of the regression checked (the largest input order tried).
    min_moving_s : float
        Least time in motion that can identify a model [s].
    min_std_m_s : float
        Least standard deviation of the commanded v, and of the commanded w
        times half the wheel base (wheel-speed units) [m/s].
    scale_from : str, optional
        Where the encoder scale comes from when the recording has no rotation
        in place (listed under ``not_identified``).

    Returns
    -------
    ExcitationReport

    Notes
    -----
    Persistent excitation of order ``n_lags`` (Ljung 1999, section 13.2):
    the lagged-command matrix must be well conditioned. A drive that never
    turns leaves the yaw dynamics unidentified, one that only turns in place
    the forward dynamics: both are refused.
    """
    u = grid.cmd_m_s
    cmd_body = body_from_wheel(u, wheel_base_m=wheel_base_m)
    moving = (np.abs(u).max(axis=1) > _REST_M_S) | (np.abs(grid.speeds[:, 0]) > _REST_M_S)
    moving_s = float(moving.sum() * grid.period_s)
    std = (float(cmd_body[:, 0].std()), float(cmd_body[:, 1].std()))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = float(np.corrcoef(u[:, 0], u[:, 1])[0, 1]) if np.all(u.std(axis=0) > 0) else 1.0
    cond = excitation_condition_number([u], n_lags=n_lags)
    not_identified, refusals = [], []
    if scale_from is not None:
        not_identified.append(f"encoder scale: no rotation in place; taken from {scale_from}")
    if std[0] < min_std_m_s:
        refusals.append(f"the commands hardly change the forward speed v (std {std[0]:.3f} "
                        f"m/s < {min_std_m_s:g}): its dynamics are not identified")
    if std[1] * wheel_base_m / 2 < min_std_m_s:
        refusals.append(f"the commands hardly turn the robot (std of w {std[1]:.3f} rad/s): the "
                        "yaw dynamics are not identified")
    if moving_s < min_moving_s:
        refusals.append(f"only {moving_s:.1f} s in motion; at least {min_moving_s:g} s needed")
    if not cond < DEFAULT_MAX_CONDITION:
        refusals.append(f"the commands are not persistently exciting (condition {cond:.3g} > "
                        f"{DEFAULT_MAX_CONDITION:.0e}): vary both wheels, not in lock step")
    return ExcitationReport(
        duration_s=float(u.shape[0] * grid.period_s), moving_s=moving_s,
        rest_fraction=float(1.0 - moving.mean()), condition=float(cond), n_lags=n_lags,
        cmd_std=std, bandwidth_hz=(_bandwidth_hz(cmd_body[:, 0], grid.period_s),
                                   _bandwidth_hz(cmd_body[:, 1], grid.period_s)),
        lr_correlation=corr, not_identified=tuple(not_identified), refusals=tuple(refusals),
        clock=grid.assignment.summary())


#: Shortest rotation in place searched for an encoder scale [s].
_MIN_ROTATION_S = 4.0


def rotation_scale(rec: Recording, *, wheel_base_m: float
                   ) -> tuple[float, RotationPeriod] | str:
    """The encoder scale from a rotation in place inside a recording, or why there is none.

    The longest stretch of wheel commands turning in place (opposite signs,
    ``|L + R| < 0.1 |L - R|``, at least 0.05 m/s) lasting ``_MIN_ROTATION_S``
    or more, in a recording of counts with light-bump signals, gives the
    period of the signals in ticks and the scale ``2 pi b / D`` (paper eq. 13,
    :func:`~lti_motion.calibration.rotation_period_ticks`).

    Returns
    -------
    (float, RotationPeriod) or str
        The scale [m/tick] and its period estimate, or the reason there is none.
    """
    if rec.wheel_kind != "counts" or rec.light_bump is None or not rec.cmd_per_frame:
        return "the recording has no light-bump signals beside per-frame counts"
    cmd = body_from_wheel(rec.cmd.values, wheel_base_m=wheel_base_m)
    left, right = rec.cmd.values[:, 0], rec.cmd.values[:, 1]
    turning = ((left * right < 0) & (np.abs(left + right) < 0.1 * np.abs(left - right))
               & (np.abs(cmd[:, 1]) * wheel_base_m / 2 >= 0.05) & rec.wheel_valid)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], turning.astype(int), [0]])))
    starts, stops = edges[::2], edges[1::2]
    if starts.size == 0:
        return "no rotation in place in the recording"
    j = int(np.argmax(stops - starts))
    seg = slice(int(starts[j]), int(stops[j]))
    if np.ptp(rec.wheel.t_s[seg]) < _MIN_ROTATION_S:
        return f"no rotation in place of {_MIN_ROTATION_S:g} s or more"
    counts = rec.wheel.values[seg].astype(np.int64)
    steps = np.diff(counts, axis=0)
    if rec.counter_bits is not None and rec.counter_bits < 64:
        mod = 1 << rec.counter_bits
        steps = (steps + mod // 2) % mod - mod // 2
    travel = np.vstack([np.zeros((1, 2), np.int64), np.cumsum(steps, axis=0)])
    try:
        rotation = rotation_period_ticks(rec.light_bump[seg], travel[:, 1] - travel[:, 0])
    except CalibrationError as exc:
        return f"the rotation in place gives no period ({exc})"
    return encoder_scale_m_per_tick(rotation.period_ticks, wheel_base_m=wheel_base_m), rotation


@dataclass(frozen=True)
class OfflineCalibration:
    """An ARX model fitted on a recording, and how well the data determined it.

    Attributes
    ----------
    model : MotionModel
        The ARX model (``m_per_tick`` as given or measured; ``None`` when none was).
    report : ExcitationReport
    fit_percent : ndarray, shape (2,)
        Free-run fit [%] of (v, w) on the held-out tail (also used to choose
        the order and delay, so slightly optimistic).
    grid : GridSignals
        The signals the model was fitted on.
    m_per_tick : float or None
        The encoder scale [m/tick]: the one the counts were scaled with, or for
        other wheel kinds the one given (the counts behind wheel angles:
        wheel radius over ticks per radian); ``None`` when none was.
    scale_from : str
        Where it came from: the rotation in place found in the recording, or
        the robot description.
    scale_measured : bool
        Whether the recording's rotation in place measured it.
    held_out_s : tuple of float or None
        The time span [s from the grid's start] kept out of the fit (``None``:
        none was; then ``fit_percent`` is the only measure).
    held_out_fit_percent : ndarray, shape (2,), or None
        Free-run fit [%] of (v, w) on that span, which neither fitted the model
        nor chose its order and delay: the honest measure of the model.
    at_edge : tuple of str
        An order or delay chosen at the top of its search range after the range
        was widened once (empty: none); such a model is not to be trusted.
    widened : str
        How the search range was widened because the first choice was at its
        edge (empty: it was not).
    """

    model: MotionModel
    report: ExcitationReport
    fit_percent: np.ndarray
    grid: GridSignals
    m_per_tick: float | None = None
    scale_from: str = ""
    scale_measured: bool = False
    held_out_s: tuple[float, float] | None = None
    held_out_fit_percent: np.ndarray | None = None
    at_edge: tuple[str, ...] = ()
    widened: str = ""


def calibrate_recording(
    rec: Recording, *, wheel_base_m: float, m_per_tick: float | None = None,
    wheel_radius_m: float | None = None,
    encoders: Literal["quadrature", "commanded"] = "quadrature",
    scale_from: str = "the robot description", validation: float = 0.3,
    dc_gain: Literal["wheel_servo", "free"] = "wheel_servo", floor: str | None = None,
    orders: Sequence[int] = range(1, 13), delays: Sequence[int] = range(0, 9),
    grid: GridSignals | None = None, dt_s: float | None = None,
    held_out_s: tuple[float, float] | None = None,
    max_wheel_speed_m_s: float = MAX_WHEEL_SPEED_M_S,
) -> OfflineCalibration:
    """Fit the ARX motion model on any recording with enough excitation.

    Parameters
    ----------
    rec : Recording
        Any drive (any wheel and command kind).
    wheel_base_m : float
        Wheel base from the robot description [m].
    m_per_tick, wheel_radius_m : float, optional
        Encoder scale [m/tick] (counts) or wheel radius [m] (angles, rad/s),
        from the robot description. A recording of counts with light bumps
        that holds a rotation in place measures the scale instead
        (:func:`rotation_scale`). For another wheel kind a ``m_per_tick`` given
        is the scale of the counts behind its readings (wheel angles from
        encoders: wheel radius over ticks per radian), kept in the model for
        the EKF's encoder updates.
    encoders : {"quadrature", "commanded"}
        ``"commanded"`` for Roomba / Create 2 counters.
    scale_from : str
        Where the scale came from, for the report.
    validation : float
        Held-out tail choosing the ARX order and delay.
    dc_gain : {"wheel_servo", "free"}
        Steady-state gain structure (:func:`lti_motion.model.fit_arx`).
    floor : str, optional
        Floor name recorded in the model.
    orders, delays : sequence of int
        ARX order and delay grid (:func:`lti_motion.model.fit_arx`).
    grid : GridSignals, optional
        ``rec`` already on the model's grid (:func:`lti_motion.recordings.on_grid`
        with the same scale), when the caller needs the grid's own options (a ROS
        bag's ``periods_by``) or reuses it; default: ``on_grid`` of ``rec`` here.
    dt_s : float, optional
        The model's sample period [s], e.g. the fitted period as the robot is
        configured (:func:`lti_motion.recordings.snap_period_s`); default the grid's
        fitted period.
    held_out_s : tuple of float, optional
        ``(start, end)`` [s from the grid's start]: a time span left out of the
        fit and of the choice of order and delay, on which the model's free-run
        fit is measured (``held_out_fit_percent``); the fit uses the drive
        before and after it, each piece with its own ``validation`` tail.
        Default: none (the fit on the validation tail is the only measure).
    max_wheel_speed_m_s : float
        A wheel or wheel command faster than this [m/s] is refused as impossible
        (:func:`lti_motion.recordings.on_grid`; used when ``grid`` is not given).

    Returns
    -------
    OfflineCalibration
        With ``at_edge`` / ``widened``: an order or delay chosen at the top of
        its range widens that range to twice its top and fits again; a choice
        still at the (new) top is reported in ``at_edge``.

    Raises
    ------
    NotExcitedError
        If the data cannot identify a model; the message gives every reason.
    ValueError
        For bad input (:func:`lti_motion.recordings.on_grid`); a held-out span
        outside the drive or leaving less than :data:`MIN_FIT_SAMPLES` to fit.
    """
    found = rotation_scale(rec, wheel_base_m=wheel_base_m)
    measured = not isinstance(found, str)
    if measured:
        m_per_tick = found[0]
        scale_from = (f"the rotation in place in the recording (period {found[1].period_ticks:.1f}"
                      f" ticks, confidence {found[1].confidence:.2f}; paper eq. 13)")
    elif rec.wheel_kind == "counts":
        scale_from = f"{scale_from} ({found})"
    if grid is None:
        grid = on_grid(rec, wheel_base_m=wheel_base_m, m_per_tick=m_per_tick,
                       wheel_radius_m=wheel_radius_m, encoders=encoders,
                       max_wheel_speed_m_s=max_wheel_speed_m_s)
    report = excitation_report(grid, wheel_base_m=wheel_base_m,
                               scale_from=None if measured else scale_from)
    if report.refusals:
        raise NotExcitedError("this recording cannot identify a model: "
                              + "; ".join(report.refusals))
    u, y = grid.cmd_m_s, grid.speeds
    runs, span = _fit_runs(u, y, grid.period_s, held_out_s)

    def fit(orders_: Sequence[int], delays_: Sequence[int]) -> MotionModel:
        return fit_arx(runs, dt_s=grid.period_s if dt_s is None else dt_s,
                       wheel_base_m=wheel_base_m, validation=validation, dc_gain=dc_gain,
                       orders=orders_, delays=delays_, m_per_tick=m_per_tick, floor=floor)

    model = fit(orders, delays)
    wider = _widened(model, orders, delays)
    widened = ""
    if wider is not None:
        widened = (f"order {model.orders['na']} / delay {model.orders['delay']} was at the "
                   f"top of orders {min(orders)}-{max(orders)}, delays "
                   f"{min(delays)}-{max(delays)}: searched orders {min(wider[0])}-"
                   f"{max(wider[0])}, delays {min(wider[1])}-{max(wider[1])}")
        orders, delays = wider
        model = fit(orders, delays)
    at_edge = _at_edge(model, orders, delays)
    fits = [model.fit_percent([(ru[round(len(ru) * (1 - validation)):],
                                ry[round(len(ru) * (1 - validation)):])]) for ru, ry in runs]
    lengths = [len(ru) for ru, _ in runs]
    tail_fit = np.average(fits, axis=0, weights=lengths)
    held = None
    if span is not None:
        held = model.fit_percent([(u[span[0]:span[1]], y[span[0]:span[1]])])
        _log.info("offline ARX fit %.1f%% (v), %.1f%% (w) on the held-out span", *held)
    _log.info("offline ARX fit %.1f%% (v), %.1f%% (w) on the validation tail", *tail_fit)
    return OfflineCalibration(model=model, report=report, fit_percent=tail_fit, grid=grid,
                              m_per_tick=m_per_tick,
                              scale_from=scale_from, scale_measured=measured,
                              held_out_s=None if span is None else
                              (span[0] * grid.period_s, span[1] * grid.period_s),
                              held_out_fit_percent=held, at_edge=at_edge, widened=widened)


#: Fewest grid samples a piece of the drive needs to take part in the fit.
MIN_FIT_SAMPLES = 200


def _fit_runs(u: np.ndarray, y: np.ndarray, period_s: float,
              held_out_s: tuple[float, float] | None
              ) -> tuple[list[tuple[np.ndarray, np.ndarray]], tuple[int, int] | None]:
    """The pieces of the drive to fit (before and after the held-out span) and that span
    in grid samples ``[a, b)``."""
    if held_out_s is None:
        return [(u, y)], None
    start_s, end_s = held_out_s
    n = len(u)
    a, b = round(start_s / period_s), min(n, round(end_s / period_s))
    if not (0 <= a < b <= n) or b - a < 2:
        raise ValueError(f"the held-out span {start_s:.3g}-{end_s:.3g} s is not inside the "
                         f"drive (0-{n * period_s:.3g} s)")
    runs = [(u[i:j], y[i:j]) for i, j in ((0, a), (b, n)) if j - i >= MIN_FIT_SAMPLES]
    if not runs:
        raise ValueError(f"holding out {start_s:.3g}-{end_s:.3g} s leaves less than "
                         f"{MIN_FIT_SAMPLES * period_s:.3g} s of the {n * period_s:.3g} s "
                         "drive in one piece to fit; hold out a shorter span")
    return runs, (a, b)


def _widened(model: MotionModel, orders: Sequence[int],
             delays: Sequence[int]) -> tuple[range, range] | None:
    """Twice the top of the order and delay ranges when the choice is at a top, else
    ``None``."""
    if not _at_edge(model, orders, delays):
        return None
    top_na, top_d = max(orders), max(delays)
    return (range(min(orders), 2 * top_na + 1) if model.orders["na"] == top_na
            else range(min(orders), top_na + 1),
            range(min(delays), 2 * top_d + 1) if model.orders["delay"] == top_d
            else range(min(delays), top_d + 1))


def _at_edge(model: MotionModel, orders: Sequence[int], delays: Sequence[int]) -> tuple[str, ...]:
    """The order or delay chosen at the top of its search range (several values tried)."""
    out = []
    if len(orders) > 1 and model.orders["na"] == max(orders):
        out.append(f"order {model.orders['na']} is the top of the orders tried "
                   f"({min(orders)}-{max(orders)})")
    if len(delays) > 1 and model.orders["delay"] == max(delays):
        out.append(f"delay {model.orders['delay']} is the top of the delays tried "
                   f"({min(delays)}-{max(delays)})")
    return tuple(out)
