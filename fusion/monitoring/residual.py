"""Residual monitor: glitch gate, windowed NIS, CUSUM and stuck-encoder check, as alarms.

:class:`ResidualMonitor` reads innovations -- from :class:`fusion.ekf.ModelEKF`
update records (:meth:`ResidualMonitor.update_record`) or, standalone, from a
model's hybrid one-step predictions with the model's ``R``
(:func:`one_step_innovations`, :meth:`ResidualMonitor.update_innovation`) --
and raises :class:`AlarmEvent` objects through a callback and into
:attr:`ResidualMonitor.events`.

Tests on the residual stream, per stream ("encoders" or "landmark"):

1. **Per-sample gate.** ``nis = nu^T S^-1 nu > gate``: a glitch, counted and
   left out of the other tests, never an alarm on its own.
2. **Glitch burst.** ``burst_count`` glitches within ``burst_window``
   samples: alarm ``"glitch_burst"``.
3. **Whitening and decimation.** ``w = L^-1 nu`` with ``S = L L^T``
   (Cholesky), then block sums of ``decimation`` samples scaled by
   ``1/sqrt(n)``: one N(0, I) value per block for white residuals.
4. **Windowed NIS.** The sum of the NIS of ``nis_window`` good samples,
   chi-square with ``m * nis_window`` degrees of freedom, against its
   ``1 - alpha`` quantile (non-overlapping windows).
5. **Two-sided CUSUM** (Page 1954) per channel on the decimated whitened
   residuals, reference ``k``, threshold ``h``; the onset estimate is the
   start of the block at which the tripping statistic last left zero.
6. **Stuck encoder** (:meth:`ResidualMonitor.update_counts`): a wheel's count
   stays flat while the wheel travel that the command and the model's
   prediction agree on (the smaller speed when both point the same way; the
   prediction alone without commands) adds up to ``stuck_ticks`` ticks over
   at least ``stuck_periods`` periods. With the motor currents, the alarm is
   ``"stalled_wheel"`` when they say the wheel is blocked
   (:mod:`fusion.monitoring.wheel_check`).

Tests 4 and 5 raise ``"dynamics_changed"`` on the encoder stream and
``"scale_changed"`` on the landmark stream. Optional replacements:
:mod:`fusion.monitoring.dynamics` for the encoder stream
(:meth:`ResidualMonitor.update_commands`) and :mod:`fusion.monitoring.scale`
(landmark-aided odometry with a likelihood-ratio test on the scale) for the
landmark stream (:meth:`ResidualMonitor.update_landmarks`).

Threshold arithmetic (:func:`design_thresholds`)
-------------------------------------------------
The target is a false-alarm rate ``F`` per hour for the whole monitor, split
in equal shares ``F/3`` between the glitch-burst test, the windowed NIS and
the CUSUMs (the stuck check cannot fire on moving wheels whose encoders
count). Raw-sample thresholds cry wolf: a 99% gate at 67 Hz rejects a good
sample every 1.5 s, and a CUSUM with ``k = 0.5, h = 5`` on raw samples has an
in-control average run length (ARL) of about 940 samples, 14 s at 67 Hz.

- Samples per hour ``N = 3600 / dt_s`` (240,000 at 15 ms).
- Gate: a good sample is a glitch with probability ``p = 1 - gate_probability``.
  ``b`` glitches among ``n`` consecutive samples by chance occur about
  ``N C(n-1, b-1) p^b`` times an hour (a burst ending at each sample). With
  ``p = 1e-4``, ``b = 3``, ``n = 20``: ``240000 * 171 * 1e-12 = 4e-5`` per hour.
  The default gate is ``p = 1e-12`` (NIS 55.3), not 1e-4 (18.4): nominal
  encoder innovations have a heavy tail at speed changes (``docs/monitor.md``).
- Windowed NIS: ``N / W`` windows an hour, each a false alarm with
  probability ``alpha = (F/3) / (N / W)``; ``F = 1``, ``W = 67``: ``alpha =
  9.3e-5`` and the bound is ``chi2.ppf(1 - alpha, 2 W)`` = 204.0 (mean 134).
- CUSUM: ``N / d`` blocks an hour and ``2 m`` one-sided CUSUMs (``m``
  channels, two sides), so each needs an ARL of ``ARL0 = 2 m (N / d) / (F/3)``
  blocks. Siegmund's approximation for N(0, 1) inputs (Siegmund 1985,
  eq. 2.56; Basseville & Nikiforov 1993, eq. 5.2.44),
  ``ARL0 = (exp(2 k b) - 2 k b - 1) / (2 k^2)``, ``b = h + 1.166``, is solved
  for ``h``. ``F = 1``, ``d = 8``, ``m = 2``, ``k = 0.5``: 30,000 blocks an
  hour, ``ARL0 = 360,000`` blocks and ``h = 10.9``.

These figures hold for white Gaussian residuals whose covariance is the one
the filter reports. The calibrated models' covariances are conservative on
nominal drives (whitened variance 0.7 to 0.9, negative lag-one correlation
from tick quantisation), which lowers the real false-alarm rate; the
simulator measurements are in ``docs/monitor.md``.

References
----------
Page, E. S. (1954). Continuous inspection schemes. Biometrika 41, 100-115.
Siegmund, D. (1985). Sequential Analysis. Springer, eq. 2.56.
Basseville, M., Nikiforov, I. (1993). Detection of Abrupt Changes, section 5.2.
Bar-Shalom, Y. et al. (2001). Estimation with Applications to Tracking and
Navigation, section 5.4 (NIS and its chi-square bounds).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.special import comb
from scipy.stats import chi2

from fusion.ekf.updates import UpdateRecord
from fusion.exceptions import (
    CovarianceNotPositiveDefiniteError,
    FilterOptionError,
    MeasurementShapeError,
    TimeOrderError,
)
from fusion.monitoring.cusum import cusum_threshold
from fusion.monitoring.dynamics import DynamicsAlarm, DynamicsMonitor
from fusion.monitoring.scale import ScaleAlarm, ScaleMonitor
from fusion.monitoring.wheel_check import WheelCheck, WheelCheckOptions, WheelVerdict
from fusion.range_bearing import RangeBearing
from lti_motion.exceptions import MissingEncoderScaleError
from lti_motion.model.motion_model import MotionModel

__all__ = [
    "AlarmEvent",
    "AlarmKind",
    "MonitorOptions",
    "ResidualMonitor",
    "Thresholds",
    "design_thresholds",
    "one_step_innovations",
    "whiten",
]

_log = logging.getLogger(__name__)

AlarmKind = Literal["glitch_burst", "stuck_encoder", "stalled_wheel", "dynamics_changed",
                    "scale_changed", "filter_reset", "wheel_drift"]
StreamKind = Literal["encoders", "landmark"]






@dataclass(frozen=True)
class AlarmEvent:
    """One alarm: what, when, on what evidence, since when.

    Attributes
    ----------
    t_s : float
        Time of the sample that raised it [s].
    kind : str
        What changed: ``"glitch_burst"``, ``"stuck_encoder"``, ``"stalled_wheel"``,
        ``"dynamics_changed"``, ``"scale_changed"``, ``"wheel_drift"`` or ``"filter_reset"``
        (``"wheel_drift"``: the scale test's curvature shadows, one wheel's scale
        changed against the other's, the new intrinsics in ``scale.intrinsics``;
        ``"stalled_wheel"``: a stuck check whose wheel's motor current says the
        wheel is blocked, :mod:`fusion.monitoring.wheel_check`; ``"filter_reset"``:
        the EKF reset itself, :mod:`fusion.ekf.resets`, raised by
        :class:`~fusion.monitoring.MonitoredFilter`).
    test : str
        The test that fired: ``"burst"``, ``"stuck"``, ``"nis_window"``,
        ``"cusum+"``, ``"cusum-"``, ``"integrated"`` (dynamics),
        ``"scale_glr"`` (scale and wheel drift), or the reset's cause ``"scale_implausible"``
        or ``"diverged"``.
    statistic, threshold : float
        The evidence: the test statistic and the threshold it crossed.
    onset_s : float
        Estimated start of the change [s].
    channel : int or None
        Channel (CUSUM) or wheel (stuck check, 0 left, 1 right).
    scale : ScaleAlarm or None
        For ``"scale_glr"``: the scale test's alarm, with the new scale
        estimated from the landmarks since the onset (``scale.scale_ratio``:
        ground travel per encoder travel, with its standard deviation).
    dynamics : DynamicsAlarm or None
        For ``"integrated"``: the dynamics test's alarm, with its sub-test
        (lag, covariance or start) and lag estimate.
    wheel : WheelVerdict or None
        For ``"stuck"``: what the motor current said (stalled wheel or stuck
        encoder, and on what evidence).
    """

    t_s: float
    kind: AlarmKind
    test: str
    statistic: float
    threshold: float
    onset_s: float
    channel: int | None = None
    scale: ScaleAlarm | None = None
    dynamics: DynamicsAlarm | None = None
    wheel: WheelVerdict | None = None


@dataclass(frozen=True)
class MonitorOptions:
    """Design targets of the monitor (:func:`design_thresholds` turns them into thresholds).

    Attributes
    ----------
    dt_s : float
        Encoder sample period [s].
    false_alarms_per_hour : float
        Target false-alarm rate of the whole monitor, split in three equal shares.
    gate_probability : float
        Per-sample gate: a good sample is a glitch with probability ``1 - gate_probability``.
    encoder_gate_nis : float, optional
        The encoder stream's per-sample gate as a NIS value, set from measured
        nominal driving instead of the chi-square law (a model miss at a start
        from rest exceeds its 1e-12 tail); ``gate_probability`` then applies to
        the landmark stream only.
    burst_count, burst_window : int
        ``burst_count`` glitches within ``burst_window`` samples make a burst.
    decimation : int
        Whitened samples summed into one CUSUM input.
    cusum_k : float
        CUSUM reference value (half the mean shift to detect, in sigma of a block).
    clip_sigma : float
        Whitened components are clipped to ``+-clip_sigma`` before the block
        sums (Huber's robust clipping: a model miss at a speed change moves a
        block by at most ``clip_sigma sqrt(d)``, not by the miss).
    nis_window : int
        Samples per windowed-NIS test.
    landmark_rate_hz : float
        Rate of landmark innovations, for the landmark stream's share.
    stuck_ticks : float
        Wheel travel [ticks] with a flat count that makes an encoder stuck (the
        travel the command and the prediction agree on, :meth:`ResidualMonitor.update_counts`).
    stuck_periods : int
        Least number of flat periods before a stuck alarm.
    refractory_s : float
        After an alarm, the same kind on the same stream is not raised again
        for this long (its statistics restart) [s].
    startup_s : float
        Start-up handling of the chi-square gate: encoder innovations within
        this long after a start from rest (a period whose wheel commands leave
        zero, :meth:`ResidualMonitor.update_counts`) are counted as
        ``"startup"`` and tested by none of the innovation tests (gate, bursts,
        windowed NIS, CUSUM) when the encoder gate is the chi-square one: a
        linear model misses a start from rest by more than the chi-square tail
        allows (``docs/monitor.md``). A Phase-I gate (``encoder_gate_nis``)
        already holds nominal starts; then the option does nothing [s].
    """

    dt_s: float = 0.015
    false_alarms_per_hour: float = 1.0
    gate_probability: float = 1.0 - 1e-12
    encoder_gate_nis: float | None = None
    burst_count: int = 3
    burst_window: int = 20
    decimation: int = 8
    cusum_k: float = 0.5
    clip_sigma: float = 3.0
    nis_window: int = 67
    landmark_rate_hz: float = 8.0
    stuck_ticks: float = 6.0
    stuck_periods: int = 3
    refractory_s: float = 5.0
    startup_s: float = 1.0

    def __post_init__(self) -> None:
        checks = {"dt_s": self.dt_s > 0, "false_alarms_per_hour": self.false_alarms_per_hour > 0,
                  "gate_probability": 0.0 < self.gate_probability < 1.0,
                  "encoder_gate_nis": self.encoder_gate_nis is None
                  or self.encoder_gate_nis > 0,
                  "burst_count": self.burst_count >= 2,
                  "burst_window": self.burst_window >= self.burst_count,
                  "decimation": self.decimation >= 1, "cusum_k": self.cusum_k > 0,
                  "clip_sigma": self.clip_sigma > 0,
                  "nis_window": self.nis_window >= 1,
                  "landmark_rate_hz": self.landmark_rate_hz > 0,
                  "stuck_ticks": self.stuck_ticks > 0, "stuck_periods": self.stuck_periods >= 1,
                  "refractory_s": self.refractory_s >= 0, "startup_s": self.startup_s >= 0}
        bad = [name for name, ok in checks.items() if not ok]
        if bad:
            raise FilterOptionError(f"MonitorOptions out of range: {', '.join(bad)} "
                                    f"(got {', '.join(f'{b}={getattr(self, b)!r}' for b in bad)})")


@dataclass(frozen=True)
class Thresholds:
    """Thresholds of one stream, with the arithmetic's intermediate figures.

    Attributes
    ----------
    gate : float
        Per-sample NIS gate.
    burst_rate_per_hour : float
        Chance glitch bursts an hour, ``N C(n-1, b-1) p^b``.
    nis_bound : float
        Windowed-NIS bound ``chi2.ppf(1 - alpha, m W)``.
    nis_alpha : float
        Per-window false-alarm probability.
    cusum_h : float
        CUSUM threshold.
    cusum_arl0 : float
        In-control ARL [blocks] each one-sided CUSUM must reach.
    """

    gate: float
    burst_rate_per_hour: float
    nis_bound: float
    nis_alpha: float
    cusum_h: float
    cusum_arl0: float






def design_thresholds(options: MonitorOptions, *, n_channels: int = 2,
                      samples_per_hour: float | None = None,
                      stream: StreamKind = "encoders") -> Thresholds:
    """Thresholds that meet ``options.false_alarms_per_hour`` (module docstring arithmetic).

    Parameters
    ----------
    options : MonitorOptions
        Design targets.
    n_channels : int
        Residual dimension ``m``.
    samples_per_hour : float, optional
        Innovations an hour (default ``3600 / dt_s``).
    stream : {"encoders", "landmark"}
        The stream (``encoder_gate_nis`` applies to the encoders only).

    Examples
    --------
    >>> th = design_thresholds(MonitorOptions())
    >>> round(th.cusum_h, 1), round(th.nis_bound, 1), round(th.gate, 1)
    (10.9, 204.0, 55.3)
    """
    n_hour = 3600.0 / options.dt_s if samples_per_hour is None else float(samples_per_hour)
    share = options.false_alarms_per_hour / 3.0
    p = 1.0 - options.gate_probability
    gate = float(chi2.ppf(options.gate_probability, n_channels))
    if stream == "encoders" and options.encoder_gate_nis is not None:
        gate = float(options.encoder_gate_nis)       # measured gate; its chi-square tail
        p = float(chi2.sf(gate, n_channels))
    b, n = options.burst_count, options.burst_window
    burst_rate = n_hour * float(comb(n - 1, b - 1)) * p ** b
    windows = n_hour / options.nis_window
    alpha = min(0.5, share / windows)
    nis_bound = float(chi2.ppf(1.0 - alpha, n_channels * options.nis_window))
    arl0 = 2 * n_channels * (n_hour / options.decimation) / share
    return Thresholds(gate=gate, burst_rate_per_hour=burst_rate, nis_bound=nis_bound,
                      nis_alpha=alpha, cusum_h=cusum_threshold(options.cusum_k, arl0),
                      cusum_arl0=arl0)


def whiten(innovation: np.ndarray, innovation_cov: np.ndarray) -> np.ndarray:
    """Whitened innovation ``L^-1 nu`` with ``S = L L^T`` (Cholesky), shape (m,).

    Raises
    ------
    MeasurementShapeError
        If the shapes are not (m,) and (m, m).
    CovarianceNotPositiveDefiniteError
        If ``S`` is not symmetric positive definite.

    Examples
    --------
    >>> (whiten(np.array([2.0, 0.0]), np.diag([4.0, 1.0])).round(12) + 0.0).tolist()
    [1.0, 0.0]
    """
    nu = np.asarray(innovation, dtype=float)
    S = np.asarray(innovation_cov, dtype=float)
    if nu.ndim != 1 or S.shape != (nu.size, nu.size):
        raise MeasurementShapeError(f"expected an innovation (m,) and covariance (m, m), got "
                                    f"{nu.shape} and {S.shape}")
    if not _symmetric(S):
        raise CovarianceNotPositiveDefiniteError(f"innovation covariance is not symmetric: {S}")
    if nu.size == 2:                        # scalar arithmetic: it runs at every reading
        w = _whiten_2(nu, S)
        if w is not None:
            return w
    try:
        L = np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        raise CovarianceNotPositiveDefiniteError(
            f"innovation covariance is not positive definite (eigenvalues "
            f"{np.linalg.eigvalsh(0.5 * (S + S.T))}); check the filter's P and R") from None
    # forward substitution with the lower-triangular factor
    return np.linalg.solve(L, nu)


def _whiten_2(nu: np.ndarray, S: np.ndarray) -> np.ndarray | None:
    """:func:`whiten` for m = 2: the Cholesky factor in closed form (Golub & Van Loan 2013,
    alg. 4.2.1, lower triangle of ``S``) and forward substitution; None if ``S`` is not
    positive definite (the caller raises with the eigenvalues)."""
    (a, _), (c, d) = S.tolist()
    if not a > 0.0:
        return None
    l11 = math.sqrt(a)
    l21 = c / l11
    e = d - l21 * l21
    if not e > 0.0:
        return None
    n0, n1 = nu.tolist()
    w0 = n0 / l11
    return np.array((w0, (n1 - l21 * w0) / math.sqrt(e)))


def _finite(a: np.ndarray) -> bool:
    """``numpy.isfinite(a).all()`` for the few values of one reading, in scalar arithmetic
    (it runs at every reading)."""
    return all(map(math.isfinite, a.ravel().tolist()))


def _symmetric(S: np.ndarray) -> bool:
    """``numpy.allclose(S, S.T, rtol=1e-9, atol=1e-15)``; for a finite 2 x 2 ``S`` the same
    comparisons in scalar arithmetic (:func:`whiten` runs at every reading)."""
    if S.shape == (2, 2):
        (a, b), (c, d) = S.tolist()
        if math.isfinite(a) and math.isfinite(b) and math.isfinite(c) and math.isfinite(d):
            # numpy.isclose(x, y): |x - y| <= atol + rtol |y|, both ways round off the diagonal
            return abs(b - c) <= 1e-15 + 1e-9 * abs(c) and abs(c - b) <= 1e-15 + 1e-9 * abs(b)
    return bool(np.allclose(S, S.T, rtol=1e-9, atol=1e-15))


def one_step_innovations(model: MotionModel, cmd_m_s: np.ndarray, speeds: np.ndarray
                         ) -> np.ndarray:
    """Standalone residuals ``y - yhat[n | n-1]`` of the model's hybrid predictor, (n, 2).

    Their covariance is the model's ``R`` (:class:`~lti_motion.model.MotionModel`, Notes);
    feed them to :meth:`ResidualMonitor.update_innovation` with ``model.R``.
    """
    y = np.asarray(speeds, dtype=float)
    return y - model.predict_one_step(cmd_m_s, y)


@dataclass
class _Stream:
    """Running statistics of one innovation stream (encoders or landmarks)."""

    thresholds: Thresholds
    alarm_kind: AlarmKind
    glitch_idx: deque = field(default_factory=deque)     # sample indices of recent glitches
    glitch_t: deque = field(default_factory=deque)
    n_samples: int = 0
    block_sum: list[float] | None = None
    block_n: int = 0
    block_t0: float = math.nan
    g_pos: np.ndarray | None = None
    g_neg: np.ndarray | None = None
    left_pos: np.ndarray | None = None
    left_neg: np.ndarray | None = None
    nis_sum: float = 0.0
    nis_n: int = 0
    nis_t0: float = math.nan
    last_alarm: dict = field(default_factory=dict)

    def reset_cusum(self, m: int) -> None:
        self.g_pos, self.g_neg = np.zeros(m), np.zeros(m)
        self.left_pos, self.left_neg = np.full(m, math.nan), np.full(m, math.nan)


class ResidualMonitor:
    """Alarms from a stream of innovations (EKF update records or one-step residuals).

    Parameters
    ----------
    options : MonitorOptions, optional
        Design targets; thresholds follow from them (:func:`design_thresholds`).
    m_per_tick : float, optional
        Encoder scale [m/tick], for :meth:`update_counts`.
    on_alarm : callable, optional
        Called with each :class:`AlarmEvent` as it is raised.
    dynamics : DynamicsMonitor, optional
        The integrated-residual dynamics test (:mod:`fusion.monitoring.dynamics`,
        one robot), fed by :meth:`update_commands`. When given, it replaces the
        windowed NIS and CUSUM on the *encoder* innovations, which cry wolf on
        real drives (``docs/monitor.md``); the glitch gate and bursts stay.
    scale : ScaleMonitor, optional
        The landmark scale test (:mod:`fusion.monitoring.scale`, one robot), fed
        by :meth:`update_landmarks`. When given, it replaces the windowed NIS
        and CUSUM on the *landmark* innovations; their gate and bursts stay.
    wheel_check : WheelCheckOptions, optional
        Settings of the stalled-wheel / stuck-encoder call on motor currents
        (:mod:`fusion.monitoring.wheel_check`; default settings).

    Attributes
    ----------
    events : list of AlarmEvent
        Every alarm so far, in time order.
    counts : dict of str to int
        ``"samples"``, ``"glitches"``, ``"missing"`` (NaN innovations),
        ``"skipped"`` (records of readings never compared: anchors, gaps) and
        ``"startup"`` (encoder innovations left out after a start from rest,
        :attr:`MonitorOptions.startup_s`).

    Examples
    --------
    >>> mon = ResidualMonitor(MonitorOptions(dt_s=0.015))
    >>> R = np.eye(2)
    >>> for n in range(100):
    ...     _ = mon.update_innovation(0.015 * n, np.zeros(2), R)
    >>> _ = mon.update_innovation(1.5, np.array([50.0, 0.0]), R)      # one glitch
    >>> mon.counts["glitches"], mon.events
    (1, [])
    >>> for n in range(3):
    ...     _ = mon.update_innovation(1.515 + 0.015 * n, np.array([50.0, 0.0]), R)
    >>> [e.kind for e in mon.events]
    ['glitch_burst']
    """

    def __init__(self, options: MonitorOptions | None = None, *, m_per_tick: float | None = None,
                 on_alarm: Callable[[AlarmEvent], None] | None = None,
                 dynamics: DynamicsMonitor | None = None,
                 scale: ScaleMonitor | None = None,
                 wheel_check: WheelCheckOptions | None = None) -> None:
        self.options = options or MonitorOptions()
        self.dynamics = dynamics
        if scale is not None and scale.n_robots != 1:
            raise FilterOptionError(f"scale must watch one robot, got a ScaleMonitor of "
                                    f"{scale.n_robots}")
        self.scale = scale
        if m_per_tick is not None and not m_per_tick > 0:
            raise FilterOptionError(f"m_per_tick must be positive, got {m_per_tick}")
        self.m_per_tick = m_per_tick
        self.on_alarm = on_alarm
        opt = self.options
        self._streams = {
            "encoders": _Stream(design_thresholds(opt), "dynamics_changed"),
            "landmark": _Stream(design_thresholds(opt, stream="landmark",
                                                  samples_per_hour=3600.0
                                                  * opt.landmark_rate_hz), "scale_changed"),
        }
        self.events: list[AlarmEvent] = []
        self.counts = {"samples": 0, "glitches": 0, "missing": 0, "skipped": 0, "startup": 0}
        self._t_last = -math.inf
        self._flat = np.zeros(2)             # predicted ticks while the count stayed flat
        self._flat_n = np.zeros(2, dtype=int)
        self._flat_t0 = np.full(2, math.nan)
        self._last_ticks: np.ndarray | None = None
        self._stuck_alarm_t = -math.inf
        self._wheel_check = WheelCheck(wheel_check)
        self._at_rest = True                 # the last period's wheel commands were both zero
        self._start_t = -math.inf            # time of the last start from rest [s]

    def thresholds(self, stream: StreamKind = "encoders") -> Thresholds:
        """The thresholds of ``stream``."""
        return self._streams[stream].thresholds

    # -- inputs --------------------------------------------------------------------------------
    def _check_time(self, t_s: float) -> float:
        t = float(t_s)
        if not math.isfinite(t):
            raise TimeOrderError(f"time must be finite, got {t_s}")
        if t < self._t_last:
            raise TimeOrderError(f"input at t={t:.6f} s arrived after one at "
                                 f"t={self._t_last:.6f} s; deliver records in time order")
        self._t_last = t
        return t

    def update_record(self, record: UpdateRecord) -> list[AlarmEvent]:
        """Feed one :class:`~fusion.ekf.UpdateRecord`; returns the alarms it raised.

        Encoder and landmark records are monitored; pose records are ignored.
        Records of readings never compared (``anchor``, ``gap``,
        ``unknown_landmark``, ``degenerate``) are counted as skipped.
        """
        if record.kind not in ("encoders", "landmark"):
            return []
        if record.reason in ("anchor", "gap", "unknown_landmark", "degenerate"):
            self._check_time(record.t_s)
            self.counts["skipped"] += 1
            return []
        return self.update_innovation(record.t_s, record.innovation, record.innovation_cov,
                                      stream=record.kind)

    def update_innovation(self, t_s: float, innovation: np.ndarray, innovation_cov: np.ndarray,
                          *, stream: StreamKind = "encoders") -> list[AlarmEvent]:
        """Feed one innovation ``nu`` (m,) with covariance ``S`` (m, m) at time ``t_s`` [s].

        NaN or infinite values count as missing. Returns the alarms raised.

        Raises
        ------
        TimeOrderError
            If ``t_s`` is earlier than an input already seen.
        CovarianceNotPositiveDefiniteError, MeasurementShapeError
            For a bad covariance or shapes (:func:`whiten`).
        """
        t = self._check_time(t_s)
        if stream not in self._streams:
            raise FilterOptionError(f"stream must be 'encoders' or 'landmark', got {stream!r}")
        nu = np.asarray(innovation, dtype=float)
        S = np.asarray(innovation_cov, dtype=float)
        if not (_finite(nu) and _finite(S)):
            self.counts["missing"] += 1
            return []
        w = whiten(nu, S)
        st = self._streams[stream]
        if stream == "encoders" and self._in_startup(t):
            self.counts["startup"] += 1
            return []
        self.counts["samples"] += 1
        st.n_samples += 1
        if st.g_pos is None or st.g_pos.size != w.size:
            st.reset_cusum(w.size)
            st.block_sum = [0.0] * w.size
        value = float(w @ w)                       # NIS = nu^T S^-1 nu = |L^-1 nu|^2
        raised: list[AlarmEvent] = []
        if value > st.thresholds.gate:
            self.counts["glitches"] += 1
            raised += self._glitch(st, stream, t)
            return self._emit(raised)
        if (self.dynamics if stream == "encoders" else self.scale) is not None:
            return self._emit(raised)
        raised += self._nis_window(st, t, value, w.size)
        raised += self._cusum(st, t, w)
        return self._emit(raised)

    def _in_startup(self, t: float) -> bool:
        """Within ``startup_s`` of a start from rest, with the chi-square encoder gate."""
        return (self.options.encoder_gate_nis is None
                and t - self._start_t < self.options.startup_s)

    def update_commands(self, t_s: float, cmd_m_s: np.ndarray, tick_deltas: np.ndarray
                        ) -> list[AlarmEvent]:
        """Feed the dynamics test one period: commands and count changes (:attr:`dynamics`).

        Parameters
        ----------
        t_s : float
            Time of the frame closing the period [s].
        cmd_m_s : array_like, shape (2,)
            Wheel commands in effect over the period [m/s].
        tick_deltas : array_like, shape (2,)
            Count changes of (left, right) over the period [ticks]; NaN: missing.

        Returns
        -------
        list of AlarmEvent
            A ``"dynamics_changed"`` alarm (test ``"integrated"``) when the
            CUSUM crosses its threshold; none within ``refractory_s`` of a
            sensor alarm (a stuck or spiking encoder explains the residuals).
        """
        if self.dynamics is None:
            raise FilterOptionError("update_commands needs a DynamicsMonitor: pass dynamics=...")
        t = self._check_time(t_s)
        hits = self.dynamics.update(t, cmd_m_s, tick_deltas)
        st = self._streams["encoders"]
        raised = []
        for a in hits:
            if self._sensor_alarm_recent(t) or not self._allowed(st, "dynamics_changed", t):
                continue
            st.last_alarm["dynamics_changed"] = t
            raised.append(AlarmEvent(t, "dynamics_changed", "integrated", a.statistic,
                                     a.threshold, a.onset_s, dynamics=a))
        return self._emit(raised)

    def _sensor_alarm_recent(self, t: float) -> bool:
        """A stuck-encoder or glitch-burst alarm within ``refractory_s`` before ``t``: it
        explains residuals and odometry errors, so model alarms are held off."""
        sensor_t = max(self._stuck_alarm_t,
                       self._streams["encoders"].last_alarm.get("glitch_burst", -math.inf))
        return t - sensor_t < self.options.refractory_s

    def update_landmarks(self, t_s: float, tick_deltas: np.ndarray,
                         sightings: RangeBearing | None = None) -> list[AlarmEvent]:
        """Feed the scale test one period: count changes and the frame's landmark sightings.

        Parameters
        ----------
        t_s : float
            Time of the frame closing the period [s].
        tick_deltas : array_like, shape (2,)
            Count changes of (left, right) over the period [ticks]; NaN: missing.
        sightings : RangeBearing, optional
            Landmarks seen at this frame (:meth:`ScaleMonitor.update`); none if
            ``None``.

        Returns
        -------
        list of AlarmEvent
            A ``"scale_changed"`` alarm (test ``"scale_glr"``, the new scale in
            :attr:`AlarmEvent.scale`), or ``"wheel_drift"`` when the scale test's
            curvature shadow raised it (the new intrinsics in ``scale.intrinsics``);
            none within ``refractory_s`` of a sensor alarm (a stuck or spiking
            encoder explains the odometry error).
        """
        if self.scale is None:
            raise FilterOptionError("update_landmarks needs a ScaleMonitor: pass scale=...")
        t = self._check_time(t_s)
        hits = self.scale.update(t, np.asarray(tick_deltas, dtype=float).reshape(1, 2),
                                 None if sightings is None else [sightings])
        raised = [AlarmEvent(t, "wheel_drift" if a.change == "curvature" else "scale_changed",
                             "scale_glr", a.statistic, a.threshold, a.onset_s, scale=a)
                  for a in hits if not self._sensor_alarm_recent(t)]
        return self._emit(raised)

    def update_counts(self, t_s: float, tick_deltas: np.ndarray,
                      predicted_wheel_m_s: np.ndarray, *,
                      cmd_m_s: np.ndarray | None = None,
                      motor_current_a: np.ndarray | None = None,
                      wheel_overcurrent: np.ndarray | None = None) -> list[AlarmEvent]:
        """Stuck-encoder check on one period's count changes, predicted speeds and commands.

        Parameters
        ----------
        t_s : float
            Time of the frame [s].
        tick_deltas : array_like, shape (2,)
            Count change of (left, right) over the period (unwrapped); NaN: missing.
        predicted_wheel_m_s : array_like, shape (2,)
            Model-predicted (left, right) wheel speeds of the period [m/s]
            (``v -/+ w b / 2`` from the predicted body speeds).
        cmd_m_s : array_like, shape (2,), optional
            (left, right) wheel commands in effect over the period [m/s]. With
            them a period's evidence is the travel that the command and the
            prediction agree on (Notes); without them, the predicted travel
            alone, which raises false alarms where a stop command meets a
            model that lags the real stop (``docs/monitor.md``). They also
            mark starts from rest (:attr:`MonitorOptions.startup_s`).
        motor_current_a : array_like, shape (2,), optional
            (left, right) wheel motor currents of the period [A], where the
            robot reports them: a flat count with a blocked wheel's current
            is a ``"stalled_wheel"`` (:mod:`fusion.monitoring.wheel_check`).
        wheel_overcurrent : array_like of bool, shape (2,), optional
            (left, right) overcurrent flags of the period (Open Interface packet 14).

        Returns
        -------
        list of AlarmEvent
            A ``"stuck_encoder"`` or ``"stalled_wheel"`` alarm (test
            ``"stuck"``) when a wheel's count stayed flat while the evidence
            reached ``stuck_ticks`` over at least ``stuck_periods`` periods and
            the motor current decided which (:attr:`AlarmEvent.wheel`; a
            blocked wheel's current is awaited up to ``decide_periods``).

        Raises
        ------
        MissingEncoderScaleError
            If the monitor was given no ``m_per_tick``.

        Notes
        -----
        A wheel servo without overshoot moves its speed monotonically from
        the current speed towards the command, so the wheel surely turns only
        while the command and the model's prediction point the same way, and
        at least at the smaller of the two speeds: the command bounds a
        slowing wheel from below, the prediction a speeding-up one. The
        period's evidence is therefore
        ``min(|v_pred|, |v_cmd|) dt / m_per_tick`` ticks when
        ``sign(v_pred) = sign(v_cmd)``, else 0 (a wheel commanded to stop, or
        to reverse, may honestly keep a flat count whatever a lagging linear
        model says).
        """
        if self.m_per_tick is None:
            raise MissingEncoderScaleError.needed_by(
                "update_counts", keyword="ResidualMonitor(m_per_tick=...)")
        t = self._check_time(t_s)
        d = np.asarray(tick_deltas, dtype=float)
        v = np.asarray(predicted_wheel_m_s, dtype=float)
        if d.shape != (2,) or v.shape != (2,):
            raise MeasurementShapeError(f"expected tick deltas (2,) and wheel speeds (2,), got "
                                        f"{d.shape} and {v.shape}")
        c = v if cmd_m_s is None else np.asarray(cmd_m_s, dtype=float)
        if c.shape != (2,):
            raise MeasurementShapeError(f"expected wheel commands (2,), got {c.shape}")
        (d_l, d_r), (v_l, v_r), (c_l, c_r) = d.tolist(), v.tolist(), c.tolist()
        if not all(map(math.isfinite, (d_l, d_r, v_l, v_r, c_l, c_r))):
            self.counts["missing"] += 1
            return []
        if cmd_m_s is not None:
            moving = c_l != 0.0 or c_r != 0.0
            if moving and self._at_rest:
                self._start_t = t - self.options.dt_s     # the period began a frame ago
            self._at_rest = not moving
        opt = self.options
        flat = [self._flat_wheel(0, t, d_l, v_l, c_l), self._flat_wheel(1, t, d_r, v_r, c_r)]
        self._wheel_check.update(np.array(flat), d, motor_current_a, wheel_overcurrent)
        raised = []
        if t - self._stuck_alarm_t >= opt.refractory_s:
            for wheel in range(2):
                if not (self._flat[wheel] >= opt.stuck_ticks
                        and self._flat_n[wheel] >= opt.stuck_periods):
                    continue
                verdict = self._wheel_check.verdict(int(wheel))
                if verdict is None:                 # a high current: wait for a stall
                    continue
                raised.append(AlarmEvent(t, verdict.kind, "stuck", float(self._flat[wheel]),
                                         opt.stuck_ticks, float(self._flat_t0[wheel]),
                                         int(wheel), wheel=verdict))
                self._stuck_alarm_t = t
                break
        return self._emit(raised)

    def _flat_wheel(self, wheel: int, t: float, d: float, v: float, c: float) -> bool:
        """One wheel's period of :meth:`update_counts`: whether its count stood while the
        wheel surely turned, and the flat stretch's evidence [ticks] (scalar arithmetic: it
        runs at every frame)."""
        # the speed the command and the prediction agree on (Notes); v itself without commands
        agreed = min(abs(v), abs(c)) if _sign(v) == _sign(c) else 0.0
        predicted_ticks = agreed * self.options.dt_s / self.m_per_tick
        # evidence only while the wheel is predicted to turn (half a tick a period or more):
        # a wheel at rest keeps a flat count honestly
        flat = d == 0 and predicted_ticks >= 0.5
        if not flat:
            self._flat[wheel], self._flat_n[wheel] = 0.0, 0
            return False
        if self._flat_n[wheel] == 0:
            self._flat_t0[wheel] = t - self.options.dt_s   # the flat period began a frame ago
        self._flat[wheel] += predicted_ticks
        self._flat_n[wheel] += 1
        return True

    # -- tests ---------------------------------------------------------------------------------
    def _allowed(self, st: _Stream, kind: AlarmKind, t: float) -> bool:
        return t - st.last_alarm.get(kind, -math.inf) >= self.options.refractory_s

    def _glitch(self, st: _Stream, stream: str, t: float) -> list[AlarmEvent]:
        opt = self.options
        st.glitch_idx.append(st.n_samples)
        st.glitch_t.append(t)
        while st.glitch_idx and st.n_samples - st.glitch_idx[0] >= opt.burst_window:
            st.glitch_idx.popleft()
            st.glitch_t.popleft()
        if len(st.glitch_idx) < opt.burst_count or not self._allowed(st, "glitch_burst", t):
            return []
        # a stuck encoder or a stalled wheel explains its own glitches: one alarm, not two
        # (also while the stuck check awaits the motor current's verdict)
        stuck_now = np.any((self._flat >= opt.stuck_ticks) & (self._flat_n >= opt.stuck_periods))
        if stream == "encoders" and (t - self._stuck_alarm_t < opt.refractory_s or stuck_now):
            return []
        st.last_alarm["glitch_burst"] = t
        onset = st.glitch_t[0]
        st.glitch_idx.clear()
        st.glitch_t.clear()
        return [AlarmEvent(t, "glitch_burst", "burst", float(opt.burst_count),
                           float(opt.burst_count), onset)]

    def _nis_window(self, st: _Stream, t: float, value: float, m: int) -> list[AlarmEvent]:
        if st.nis_n == 0:
            st.nis_t0 = t
        st.nis_sum += value
        st.nis_n += 1
        if st.nis_n < self.options.nis_window:
            return []
        total, t0 = st.nis_sum, st.nis_t0
        st.nis_sum, st.nis_n = 0.0, 0
        bound = st.thresholds.nis_bound
        if total <= bound or not self._allowed(st, st.alarm_kind, t):
            return []
        st.last_alarm[st.alarm_kind] = t
        return [AlarmEvent(t, st.alarm_kind, "nis_window", total, bound, t0)]

    def _cusum(self, st: _Stream, t: float, w: np.ndarray) -> list[AlarmEvent]:
        if st.block_n == 0:
            st.block_t0 = t
        clip = self.options.clip_sigma     # np.clip's values, in scalar arithmetic (per sample)
        st.block_sum = [b + min(max(v, -clip), clip)
                        for b, v in zip(st.block_sum, w.tolist(), strict=True)]
        st.block_n += 1
        if st.block_n < self.options.decimation:
            return []
        z = np.array(st.block_sum) / math.sqrt(st.block_n)   # N(0, I) per block if white
        st.block_sum = [0.0] * z.size
        st.block_n = 0
        k, h = self.options.cusum_k, st.thresholds.cusum_h
        # Page 1954: g+ = max(0, g+ + z - k), g- = max(0, g- - z - k)
        new_pos = np.maximum(0.0, st.g_pos + z - k)
        new_neg = np.maximum(0.0, st.g_neg - z - k)
        st.left_pos = np.where((st.g_pos == 0) & (new_pos > 0), st.block_t0, st.left_pos)
        st.left_neg = np.where((st.g_neg == 0) & (new_neg > 0), st.block_t0, st.left_neg)
        st.g_pos, st.g_neg = new_pos, new_neg
        over = [(g[c], c, name, left[c]) for g, name, left in
                ((new_pos, "cusum+", st.left_pos), (new_neg, "cusum-", st.left_neg))
                for c in range(z.size) if g[c] > h]
        if not over:
            return []
        stat, c, name, onset = max(over)
        st.reset_cusum(z.size)
        if not self._allowed(st, st.alarm_kind, t):
            return []
        st.last_alarm[st.alarm_kind] = t
        return [AlarmEvent(t, st.alarm_kind, name, float(stat), h, float(onset), int(c))]

    def report(self, raised: list[AlarmEvent]) -> list[AlarmEvent]:
        """Record alarms raised outside the monitor's own tests (the filter's resets).

        They go to ``on_alarm`` and :attr:`events` as the monitor's own do;
        returns them.
        """
        return self._emit(list(raised))

    def _emit(self, raised: list[AlarmEvent]) -> list[AlarmEvent]:
        for event in raised:
            _log.info("alarm %s at t=%.3f s (%s %.3g > %.3g, onset %.3f s)", event.kind,
                      event.t_s, event.test, event.statistic, event.threshold, event.onset_s)
            self.events.append(event)
            if self.on_alarm is not None:
                self.on_alarm(event)
        return raised


def _sign(x: float) -> int:
    """``numpy.sign`` of a finite float, as an int."""
    return (x > 0) - (x < 0)
