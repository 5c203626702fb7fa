"""Scale-change test from landmarks: does the ground still move as far as the encoders count?

Encoders count wheel rotation and cannot see the ground. On a new floor (a
carpet compresses under the wheels and slips more) the robot covers a
different distance per tick, whatever the manoeuvre: a *scale* change,
invisible to the encoder innovations and to the dynamics test. Landmarks see
it as an along-track error of the encoder odometry that grows with distance.

**Filters.** :class:`ScaleMonitor` runs, per robot, an extended Kalman filter
of landmark-aided odometry with the scale errors in the state,
``x = (x, y, theta, k_v, k_w, kappa)``: the ground travel and turn are ``(1 + k_v)``
and ``(1 + k_w)`` times the encoders', and the heading turns ``kappa`` [rad/m] more
per metre driven (one wheel's scale against the other's, :mod:`lti_motion.intrinsics`;
:mod:`fusion.monitoring.scale_odometry`; the scale states of :class:`fusion.ekf.ModelEKF`).
Batched over robots, it costs a few small matrix products a period, far less
than the full model filter.

**Test: window-limited mixture likelihood ratios.** Beside each *main*
filter run ``n_shadows`` *shadows*. Shadow ``j`` restarts from the main filter
at every ``restart_every_s`` in turn (so their start times ``t0`` are
staggered over the last ``n_shadows * restart_every_s`` seconds) with the
prior of ``(k_v, k_w)`` widened to ``restart_std`` and its cross-covariances
dropped: a shadow is the alternative "the scales changed at ``t0`` by an
amount drawn from N(0, restart_std^2)", the main filter the null "no
change". All see the same landmarks; the log-likelihood ratio of a shadow's
innovations against the main filter's since its ``t0``::

    L = sum_i [ln N(nu_s,i; 0, S_s,i) - ln N(nu_m,i; 0, S_m,i)]        (eq. 1)
      = sum_i 0.5 [min(q_m,i, gate) - q_s,i + ln det S_m,i - ln det S_s,i]

is the log of a mixture (weighted) likelihood ratio of the data since
``t0`` (Basseville & Nikiforov 1993, section 2.4; the window-limited GLR of
Lai 1998 with a mixture over the change size): ``q`` are the NISs, the main
filter's clipped at the gate so one outlier adds at most ``gate / 2``; a
sighting a shadow gates adds nothing. Under the null ``exp(L)`` is a
non-negative martingale with mean 1 (exactly for a linear-Gaussian model), so
by Ville's inequality it ever exceeds ``exp(h)`` with probability at most
``exp(-h)``. With ``3600 / restart_every_s`` shadow starts an hour, a
threshold::

    h = ln(3600 / (restart_every_s F))                                (eq. 2)

keeps false alarms below ``F`` an hour (the union bound, as Lorden 1971's
for the CUSUM in :mod:`fusion.monitoring.dynamics`): 1,800 starts an hour and
``F = 0.1`` give ``h = 9.8``. The default ``F`` is 10 times below the target
of 1 an hour because the simulated robot is not the filter's linear-Gaussian
model (measured: ``docs/monitor.md``).

**Scale or curvature.** Each restart starts two shadows: a *scale* shadow,
``(k_v, k_w)`` widened to ``restart_std`` (a floor), and a *curvature* shadow,
``kappa`` widened to ``restart_curvature_std_rad_per_m`` (one wheel's diameter:
hair wound on it, a soft tyre), each with its own eq. 1 and its own threshold
from eq. 2 (budgets ``F`` and ``F_kappa``; both 0.1 an hour by default). Both
are mixture likelihood ratios of the same data against the same null, so their
difference is the log Bayes factor between the two alternatives. Rule: at a
landmark update, of the shadows whose ``L`` exceeds their threshold ``h``, the one
with the largest ``L - h`` raises the alarm, and its family names the change::

    change = argmax over shadows s of (L_s - h_family(s)),  alarm if > 0      (eq. 3)

(a ``"curvature"`` alarm is ``"wheel_drift"`` in :class:`~fusion.monitoring.ResidualMonitor`).
On the route the two separate well: a floor changes travel and turns in place,
which ``kappa`` cannot explain (it acts per metre driven), and a wheel curves
the straights, which ``k_v, k_w`` cannot (``docs/monitor.md``). A 0.5% larger
wheel also changes ``k_v`` and ``k_w`` by 0.25%, far below ``restart_std``; the
curvature shadow keeps the main filter's ``k_v, k_w`` with their covariance.

**Onset and new scale.** The alarm carries the alarming shadow's ``t0`` as
the onset and its ``1 + k_v`` and ``1 + k_w``: the ground travel and turn per
encoder travel and turn estimated from the data since ``t0`` alone (the new
encoder scale is ``m_per_tick`` times it). The main filter then adopts that
shadow's state, so the monitor follows the new floor and can see the next
change. The alarm carries the shadow's ``kappa`` and the intrinsics its
``(k_v, k_w, kappa)`` say the robot has now
(:meth:`lti_motion.intrinsics.OdometryIntrinsics.corrected` of
:attr:`ScaleMonitor.intrinsics`). A floor change shows first in turns
(``k_w``, bearings move fast) and in travel (``k_v``) a few seconds of driving
later; an alarm raised by a turn carries a ``k_v`` whose standard deviation is
still near ``restart_std``.

References
----------
Basseville, M., Nikiforov, I. (1993). Detection of Abrupt Changes. Prentice
Hall, section 2.4 (weighted CUSUM and GLR for an unknown change size).
Lai, T. L. (1998). Information bounds and quick detection of parameter
changes in stochastic systems. IEEE Trans. Inf. Theory 44, 2917-2929
(window-limited GLR).
Ville, J. (1939). Etude critique de la notion de collectif. Gauthier-Villars
(the maximal inequality for non-negative martingales).
Lorden, G. (1971). Procedures for reacting to a change in distribution.
Annals of Mathematical Statistics 42, 1897-1908.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.stats import chi2

from fusion.ekf.kernel import kernel_array
from fusion.exceptions import FilterOptionError, FusionError, MeasurementShapeError
from fusion.landmark_map import LandmarkMap
from fusion.monitoring.scale_odometry import KAPPA as _KAPPA
from fusion.monitoring.scale_odometry import KV as _KV
from fusion.monitoring.scale_odometry import KW as _KW
from fusion.monitoring.scale_odometry import (
    N_STATE,
    landmark_update_compiled,
    odometry_predict_into,
)
from fusion.noise import LandmarkNoise, ScaleErrors, SlipNoise
from fusion.range_bearing import RangeBearing
from lti_motion.intrinsics import OdometryIntrinsics

__all__ = ["ScaleAlarm", "ScaleMonitor", "ScaleOptions"]


@dataclass(frozen=True)
class ScaleOptions:
    """Design of the scale test.

    Attributes
    ----------
    dt_s : float
        Encoder sample period [s].
    false_alarms_per_hour : float
        Budget ``F`` of this test, per robot (eq. 2).
    restart_std : tuple of 2 float
        Prior standard deviations of ``(k_v, k_w)`` in a restarted shadow: the
        size of scale change the test is tuned to (a carpet: about 0.04). A
        zero ``k_w`` entry leaves the yaw scale out of the alternative.
    restart_every_s : float
        Time between shadow starts [s] (eq. 2).
    n_shadows : int
        Shadows per robot; the test looks back ``n_shadows * restart_every_s``
        seconds at most.
    gate_probability : float
        Chi-square gate of the landmark updates (2 dof).
    slip : SlipNoise
        Ground-versus-encoder speed noise of the odometry.
    scales : ScaleErrors
        Prior and random walk of ``(k_v, k_w)`` in the main filters.
    missing_speed_m_s, missing_turn_rad_s : float
        Speeds a period with missing counts may have had (its travel is unknown).
    curvature_prior_std_rad_per_m : float
        Prior standard deviation of the curvature error ``kappa`` [rad/m] in the main
        filters (0.01: a 0.24% diameter ratio on a Create 2).
    curvature_walk_rad_per_m_sqrt_s : float
        Random-walk rate of ``kappa`` [rad/m/sqrt(s)] (4e-4: ``ScaleErrors``' 1e-4
        over a 0.235 m wheel base).
    restart_curvature_std_rad_per_m : float
        Prior standard deviation of ``kappa`` in a restarted *curvature* shadow
        [rad/m]: the size of one wheel's change the wheel-drift test is tuned to
        (0.04: 0.9% of a Create 2's wheel). 0 leaves the curvature shadows out.
    curvature_false_alarms_per_hour : float
        Budget ``F_kappa`` of the curvature shadows (eq. 2 with it).
    """

    dt_s: float = 0.015
    false_alarms_per_hour: float = 0.1
    restart_std: tuple[float, float] = (0.05, 0.05)
    restart_every_s: float = 2.0
    n_shadows: int = 8
    gate_probability: float = 0.999
    slip: SlipNoise = field(default_factory=SlipNoise)
    scales: ScaleErrors = field(default_factory=ScaleErrors)
    missing_speed_m_s: float = 0.5
    missing_turn_rad_s: float = 4.0
    curvature_prior_std_rad_per_m: float = 0.01
    curvature_walk_rad_per_m_sqrt_s: float = 4e-4
    restart_curvature_std_rad_per_m: float = 0.04
    curvature_false_alarms_per_hour: float = 0.1

    def __post_init__(self) -> None:
        checks = {"dt_s": self.dt_s > 0, "false_alarms_per_hour": self.false_alarms_per_hour > 0,
                  "restart_std": len(self.restart_std) == 2 and 0 < self.restart_std[0] < 1
                  and 0 <= self.restart_std[1] < 1,
                  "restart_every_s": self.restart_every_s > 0, "n_shadows": self.n_shadows >= 1,
                  "gate_probability": 0.0 < self.gate_probability < 1.0,
                  "missing_speed_m_s": self.missing_speed_m_s > 0,
                  "missing_turn_rad_s": self.missing_turn_rad_s > 0,
                  "curvature_prior_std_rad_per_m": 0 < self.curvature_prior_std_rad_per_m < 1,
                  "curvature_walk_rad_per_m_sqrt_s": self.curvature_walk_rad_per_m_sqrt_s >= 0,
                  "restart_curvature_std_rad_per_m":
                      0 <= self.restart_curvature_std_rad_per_m < 1,
                  "curvature_false_alarms_per_hour": self.curvature_false_alarms_per_hour > 0}
        bad = [name for name, ok in checks.items() if not ok]
        if bad:
            raise FilterOptionError(f"ScaleOptions out of range: {', '.join(bad)} "
                                    f"(got {', '.join(f'{b}={getattr(self, b)!r}' for b in bad)})")

    @property
    def threshold(self) -> float:
        """Threshold ``h = ln(3600 / (restart_every_s F))`` on the log-likelihood ratio (eq. 2).

        Examples
        --------
        >>> round(ScaleOptions().threshold, 2)          # 1,800 restarts an hour, F = 0.1
        9.8
        """
        return math.log(3600.0 / (self.restart_every_s * self.false_alarms_per_hour))

    @property
    def curvature_threshold(self) -> float:
        """Threshold of the curvature shadows, ``ln(3600 / (restart_every_s F_kappa))`` (eq. 2).

        Examples
        --------
        >>> round(ScaleOptions().curvature_threshold, 2)
        9.8
        """
        return math.log(3600.0 / (self.restart_every_s * self.curvature_false_alarms_per_hour))

    @property
    def with_curvature(self) -> bool:
        """Whether the curvature shadows run (``restart_curvature_std_rad_per_m > 0``)."""
        return self.restart_curvature_std_rad_per_m > 0


@dataclass(frozen=True)
class ScaleAlarm:
    """One scale alarm of one robot.

    Attributes
    ----------
    robot : int
        Robot index in the batch.
    t_s : float
        Time of the landmark update that raised it [s].
    statistic, threshold : float
        Log-likelihood ratio ``L`` (eq. 1) and ``h``.
    onset_s : float
        Estimated start of the change, ``t0`` [s].
    scale_ratio, scale_ratio_std : float
        Ground travel per encoder travel since the onset (``1 + k_v`` of the
        shadow) and its standard deviation; the new encoder scale is
        ``m_per_tick * scale_ratio``. Right after a turn (little travel since
        the onset) the standard deviation stays near ``restart_std``.
    yaw_ratio, yaw_ratio_std : float
        The same for the yaw rate, ``1 + k_w`` (the effective wheel base is
        ``wheel_base_m / yaw_ratio``).
    change : {"scale", "curvature"}
        Which alternative raised it (module notes, "Scale or curvature"):
        ``"scale"`` (travel and turn, a floor) or ``"curvature"`` (one wheel's
        scale against the other's: the wheel-drift alarm).
    curvature_rad_per_m, curvature_std_rad_per_m : float
        The shadow's curvature error ``kappa`` [rad/m] (the curvature a straight run of
        equal counts drives) and its standard deviation.
    intrinsics : OdometryIntrinsics or None
        The intrinsics the shadow's ``(k_v, k_w, kappa)`` say the robot has now:
        :meth:`OdometryIntrinsics.corrected` of the monitor's :attr:`ScaleMonitor.intrinsics`.
    """

    robot: int
    t_s: float
    statistic: float
    threshold: float
    onset_s: float
    scale_ratio: float
    scale_ratio_std: float
    yaw_ratio: float
    yaw_ratio_std: float
    change: Literal["scale", "curvature"] = "scale"
    curvature_rad_per_m: float = 0.0
    curvature_std_rad_per_m: float = math.nan
    intrinsics: OdometryIntrinsics | None = None


class ScaleMonitor:
    """Landmark-aided odometry with scale states and a mixture GLR on the scale (module notes).

    Parameters
    ----------
    m_per_tick : float
        Calibrated encoder scale [m/tick].
    wheel_base_m : float
        Wheel base [m].
    landmarks : LandmarkMap
        Known landmark positions.
    initial_pose : array_like, shape (3,) or (n_robots, 3)
        Start poses ``(x [m], y [m], theta [rad])``; one row per robot fed together.
    pose_std : tuple of 3 float
        Standard deviations of the start poses [m, m, rad].
    landmark_noise : LandmarkNoise, optional
        The landmark sensor's noise, for sightings without a covariance of their
        own (default 2% of range, 1 degree).
    options : ScaleOptions, optional
        Test design.
    intrinsics : OdometryIntrinsics, optional
        Each wheel's scale and the wheel base the counts are converted with, in
        place of ``m_per_tick`` and ``wheel_base_m`` (both wheels at ``m_per_tick``
        by default); the alarms' ratios and curvature refer to them.

    Attributes
    ----------
    threshold : float
        ``h`` (eq. 2) of the scale shadows.
    curvature_threshold : float
        ``h`` of the curvature shadows (eq. 2 with ``F_kappa``).
    intrinsics : OdometryIntrinsics
        The counts' mapping in use.
    statistic : ndarray, shape (n_robots,)
        Current log-likelihood ratios ``L`` (eq. 1).
    counts : dict of str to int
        ``"updates"`` (landmark updates fused by the main filters),
        ``"gated"``, ``"missing"`` (NaN counts), ``"unknown_landmark"``.

    Raises
    ------
    FilterOptionError, MeasurementShapeError
        For a bad scale, wheel base, start pose or standard deviation.

    Examples
    --------
    A robot drives at 0.25 m/s along x past two landmarks (noise-free
    sightings, one each 0.12 s); after 6 s it covers 4% less ground than its
    encoders count:

    >>> from fusion.range_bearing import range_bearing
    >>> lm = LandmarkMap({1: (2.0, 1.0), 2: (4.0, -1.0)})
    >>> mon = ScaleMonitor(5e-4, 0.235, lm, initial_pose=(0.0, 0.0, 0.0))
    >>> x_m, alarms = 0.0, []
    >>> for k in range(1, 1000):
    ...     x_m += (1.0 if k < 400 else 0.96) * 7.5 * 5e-4           # ground travel
    ...     j = 1 + k // 8 % 2
    ...     r, b = range_bearing(np.array([x_m, 0.0, 0.0]), lm.position(j))
    ...     seen = RangeBearing.empty() if k % 8 else RangeBearing(k, [j], [r], [b])
    ...     alarms += mon.update(0.015 * k, np.array([7.5, 7.5]), [seen])
    >>> a = alarms[0]
    >>> a.onset_s, round(a.scale_ratio, 3), a.t_s < 16.0
    (6.0, 0.96, True)
    """

    def __init__(self, m_per_tick: float, wheel_base_m: float, landmarks: LandmarkMap, *,
                 initial_pose: np.ndarray | Sequence[float],
                 pose_std: Sequence[float] = (0.01, 0.01, 0.01),
                 landmark_noise: LandmarkNoise | None = None,
                 options: ScaleOptions | None = None,
                 intrinsics: OdometryIntrinsics | None = None) -> None:
        if not (m_per_tick > 0 and wheel_base_m > 0):
            raise FilterOptionError(f"m_per_tick and wheel_base_m must be positive, got "
                                    f"{m_per_tick} and {wheel_base_m}")
        pose0 = np.asarray(initial_pose, dtype=float)
        pose0 = pose0.reshape(1, 3) if pose0.shape == (3,) else pose0
        std = np.asarray(pose_std, dtype=float)
        if pose0.ndim != 2 or pose0.shape[1] != 3 or std.shape != (3,):
            raise MeasurementShapeError(f"expected initial_pose (3,) or (n_robots, 3) and "
                                        f"pose_std (3,), got {np.shape(initial_pose)} and "
                                        f"{std.shape}")
        if not (np.all(np.isfinite(pose0)) and np.all(std > 0)):
            raise FilterOptionError(f"initial_pose must be finite and pose_std positive, got "
                                    f"{pose0.tolist()} and {std.tolist()}")
        self.options = opt = options or ScaleOptions()
        self.intrinsics = intrinsics or OdometryIntrinsics.symmetric(
            m_per_tick=float(m_per_tick), wheel_base_m=float(wheel_base_m))
        self.m_per_tick, self.wheel_base_m = self.intrinsics.m_per_tick, \
            self.intrinsics.wheel_base_m
        self.landmarks = landmarks
        self.landmark_noise = landmark_noise or LandmarkNoise()
        self.threshold = opt.threshold
        self.curvature_threshold = opt.curvature_threshold
        self._gate = float(chi2.ppf(opt.gate_probability, 2))
        n = self.n_robots = len(pose0)
        # shadows: n_shadows scale ones, then (with_curvature) n_shadows curvature ones
        w = self._n_alt = opt.n_shadows * (2 if opt.with_curvature else 1)
        self._h = np.repeat([opt.threshold, opt.curvature_threshold],
                            opt.n_shadows)[:w, None]
        # rows 0..n-1: main filters; then n rows per shadow j = 0..w-1
        self._x = np.zeros(((1 + w) * n, N_STATE))
        self._x[:, :3] = np.tile(pose0, (1 + w, 1))
        p0 = np.diag([*(std ** 2), *(np.asarray(opt.scales.prior_std) ** 2),
                      opt.curvature_prior_std_rad_per_m ** 2])
        self._P = np.tile(p0, ((1 + w) * n, 1, 1))
        self._spare = np.empty_like(self._x), np.empty_like(self._P)
        self._q_c = np.array([*opt.scales.walk_per_sqrt_s,
                              opt.curvature_walk_rad_per_m_sqrt_s]) ** 2 * opt.dt_s
        self._llr = np.zeros((w, n))                         # eq. 1 per shadow
        self._onset = np.full((w, n), math.nan)
        self._slot = -1                                      # last restart slot
        self._t_last = -math.inf
        self.counts = {"updates": 0, "gated": 0, "missing": 0, "unknown_landmark": 0}

    @property
    def statistic(self) -> np.ndarray:
        """Largest log-likelihood ratio ``L`` (eq. 1) over the shadows, (n_robots,)."""
        return self._llr.max(axis=0)

    @property
    def scale_ratio(self) -> np.ndarray:
        """Main filters' ground travel per encoder travel ``1 + k_v``, (n_robots,)."""
        return 1.0 + self._x[:self.n_robots, _KV]

    @property
    def scale_ratio_std(self) -> np.ndarray:
        """Standard deviation of :attr:`scale_ratio` (the main filters' ``k_v``), (n_robots,)."""
        return np.sqrt(self._P[:self.n_robots, _KV, _KV])

    @property
    def yaw_ratio(self) -> np.ndarray:
        """Main filters' ground turn per encoder turn ``1 + k_w``, (n_robots,)."""
        return 1.0 + self._x[:self.n_robots, _KW]

    @property
    def yaw_ratio_std(self) -> np.ndarray:
        """Standard deviation of :attr:`yaw_ratio`, (n_robots,)."""
        return np.sqrt(self._P[:self.n_robots, _KW, _KW])

    @property
    def curvature_rad_per_m(self) -> np.ndarray:
        """Main filters' curvature error ``kappa`` [rad/m], (n_robots,)."""
        return self._x[:self.n_robots, _KAPPA].copy()

    @property
    def curvature_std_rad_per_m(self) -> np.ndarray:
        """Standard deviation of :attr:`curvature_rad_per_m`, (n_robots,)."""
        return np.sqrt(self._P[:self.n_robots, _KAPPA, _KAPPA])

    def intrinsics_estimate(self, robot: int = 0) -> OdometryIntrinsics:
        """The intrinsics robot ``robot``'s main filter says it has now:
        :attr:`intrinsics` corrected by its ``(k_v, k_w, kappa)``
        (:meth:`OdometryIntrinsics.corrected`)."""
        x = self._x[robot]
        return self.intrinsics.corrected(float(x[_KV]), float(x[_KW]), float(x[_KAPPA]))

    @property
    def pose(self) -> np.ndarray:
        """Main filters' poses ``(x [m], y [m], theta [rad])``, (n_robots, 3)."""
        return self._x[:self.n_robots, :3].copy()

    # -- filter ----------------------------------------------------------------------------------
    def _predict(self, tick_deltas: np.ndarray) -> None:
        """One period of encoder travel for the main filters and the shadows."""
        opt = self.options
        x_out, P_out = self._spare          # the compiled step writes into the spare buffers
        odometry_predict_into(
            self._x, self._P, kernel_array(tick_deltas), x_out, P_out,   # shadows: the robot's
            intrinsics=self.intrinsics, dt_s=opt.dt_s, slip=opt.slip, walk_var=self._q_c,
            missing_std=(opt.missing_speed_m_s, opt.missing_turn_rad_s))
        self._spare = self._x, self._P
        self._x, self._P = x_out, P_out

    def _restart(self, shadow: int, robots: np.ndarray, t: float) -> None:
        """Shadow slot ``shadow`` of ``robots`` restarts from the main filters: its scale
        shadow with ``(k_v, k_w)`` widened, its curvature shadow with ``kappa`` widened."""
        opt = self.options
        sv, sw = opt.restart_std
        families = [{_KV: sv, _KW: sw} if sw > 0 else {_KV: sv}]
        if opt.with_curvature:
            families.append({_KAPPA: opt.restart_curvature_std_rad_per_m})
        for f, widened in enumerate(families):
            j = f * opt.n_shadows + shadow
            rows = (1 + j) * self.n_robots + robots
            self._x[rows] = self._x[robots]
            P = self._P[robots].copy()
            free = list(widened)
            P[:, free, :] = 0.0
            P[:, :, free] = 0.0
            for k, sd in widened.items():
                P[:, k, k] = sd * sd
            self._P[rows] = P
            self._llr[j, robots] = 0.0
            self._onset[j, robots] = t

    # -- input -----------------------------------------------------------------------------------
    def update(self, t_s: float, tick_deltas: np.ndarray,
               observations: Sequence[RangeBearing] | None = None) -> list[ScaleAlarm]:
        """Feed one period of every robot: encoder counts, then the frame's landmark sightings.

        Parameters
        ----------
        t_s : float
            Time of the frame closing the period [s].
        tick_deltas : array_like, shape (n_robots, 2) or (2,)
            Count changes of (left, right) over the period (unwrapped) [ticks];
            NaN: missing (the travel is unknown and the pose uncertainty grows).
        observations : sequence of RangeBearing, optional
            Each robot's sightings at this frame, one :class:`RangeBearing` per
            robot (their ``index`` is not read); ids not in the map count as
            ``unknown_landmark``, rows without a covariance take
            :attr:`landmark_noise`, each robot's ``sensor_pose`` is the mount
            of its sensor (:mod:`fusion.range_bearing`, eq. 1). The ``k``-th
            sightings of all robots are fused together.

        Returns
        -------
        list of ScaleAlarm
            Robots whose ``L`` crossed ``h`` at this frame.

        Raises
        ------
        MeasurementShapeError
            For tick deltas of the wrong shape, or observations not one per robot.
        FusionError
            If ``t_s`` is not finite or earlier than the last one.
        """
        t = float(t_s)
        if not (math.isfinite(t) and t >= self._t_last):
            raise FusionError(f"time must be finite and not decrease: got t={t_s} after "
                              f"t={self._t_last}; deliver periods in time order")
        self._t_last = t
        n = self.n_robots
        d = np.asarray(tick_deltas, dtype=float)
        if d.size != 2 * n:
            raise MeasurementShapeError(f"expected tick deltas ({n}, 2), got {d.shape}")
        d = d.reshape(n, 2)
        slot = math.floor(t / self.options.restart_every_s)
        if slot != self._slot:                               # staggered restarts
            self._slot = slot
            self._restart(slot % self.options.n_shadows, np.arange(n), t)
        self.counts["missing"] += sum(not (math.isfinite(left) and math.isfinite(right))
                                      for left, right in d.tolist())
        self._predict(d)
        if observations is None:
            return []
        if len(observations) != n:
            raise MeasurementShapeError(f"expected observations for {n} robots, got "
                                        f"{len(observations)}")
        if not any(len(obs) for obs in observations):       # most frames see no landmark
            return []
        alarms: list[ScaleAlarm] = []
        per_robot = [list(obs) for obs in observations]
        mounts = [obs.sensor_pose for obs in observations]
        for k in range(max((len(o) for o in per_robot), default=0)):
            robots, lxy, zs, covs = [], [], [], []
            for i, rows in enumerate(per_robot):
                if k >= len(rows):
                    continue
                landmark_id, rb, cov = rows[k]
                if landmark_id not in self.landmarks:
                    self.counts["unknown_landmark"] += 1
                else:
                    robots.append(i)
                    lxy.append(self.landmarks.position(landmark_id))
                    zs.append(rb)
                    covs.append(cov)
            if robots:
                sensor = np.array([(mounts[i].x_m, mounts[i].y_m, mounts[i].yaw_rad)
                                   for i in robots])
                alarms += self._test(t, np.array(robots), np.array(lxy), np.array(zs), covs,
                                     sensor)
        return alarms

    def _test(self, t: float, robots: np.ndarray, lxy: np.ndarray, zs: np.ndarray,
              covs: list[np.ndarray | None], sensor: np.ndarray) -> list[ScaleAlarm]:
        """Main and shadow updates, eq. 1, alarms; ``covs`` the sightings' own covariances,
        ``sensor`` the robots' sensor mounts ``(x_m, y_m, yaw_rad)``, (m, 3)."""
        n, m, w = self.n_robots, len(robots), self._n_alt
        rows = (np.arange(1 + w)[:, None] * n + robots[None, :]).ravel()
        cov = None
        if any(c is not None for c in covs):             # NaN: the sensor's noise
            cov = np.tile([np.full((2, 2), np.nan) if c is None else c for c in covs],
                          (1 + w, 1, 1))
        x, P, ok, ll = landmark_update_compiled(
            self._x[rows], self._P[rows], np.tile(lxy, (1 + w, 1)), np.tile(zs, (1 + w, 1)),
            self.landmark_noise, self._gate, cov=cov, sensor=np.tile(sensor, (1 + w, 1)))
        self._x[rows], self._P[rows] = x, P
        ok, ll = ok.reshape(1 + w, m), ll.reshape(1 + w, m)
        self.counts["updates"] += int(ok[0].sum())
        self.counts["gated"] += int((~ok[0]).sum())
        # a sighting a shadow gates (an outlier for both) is no evidence
        self._llr[:, robots] += np.where(ok[1:], ll[1:] - ll[0], 0.0)          # eq. 1
        alarms = []
        excess = self._llr[:, robots] - self._h          # scale or curvature: eq. 3
        best = excess.argmax(axis=0)
        for j, i in enumerate(robots):
            s = best[j]
            if excess[s, j] <= 0.0:
                continue
            alarms.append(self._alarm(int(i), int(s), t))
            # the main filter adopts the new scale and goes on from the shadow
            row = (1 + s) * n + i
            self._x[i], self._P[i] = self._x[row], self._P[row]
            for shadow in range(self.options.n_shadows):
                self._restart(shadow, np.array([i]), t)
        return alarms

    def _alarm(self, robot: int, shadow: int, t: float) -> ScaleAlarm:
        """The alarm of shadow ``shadow`` of ``robot`` (before the main filter adopts it)."""
        x, P = self._x[(1 + shadow) * self.n_robots + robot], \
            self._P[(1 + shadow) * self.n_robots + robot]
        curvature = shadow >= self.options.n_shadows
        return ScaleAlarm(robot, t, float(self._llr[shadow, robot]), float(self._h[shadow, 0]),
                          float(self._onset[shadow, robot]), 1.0 + float(x[_KV]),
                          math.sqrt(float(P[_KV, _KV])), 1.0 + float(x[_KW]),
                          math.sqrt(float(P[_KW, _KW])),
                          change="curvature" if curvature else "scale",
                          curvature_rad_per_m=float(x[_KAPPA]),
                          curvature_std_rad_per_m=math.sqrt(float(P[_KAPPA, _KAPPA])),
                          intrinsics=self.intrinsics.corrected(float(x[_KV]), float(x[_KW]),
                                                               float(x[_KAPPA])))
