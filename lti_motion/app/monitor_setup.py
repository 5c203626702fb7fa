"""Phase I of the residual monitor: what it learns from nominal driving before it watches.

Two parts of :class:`~fusion.monitoring.ResidualMonitor` are set from drives of
the robot in its normal state, on the kind of route it will drive, as a
control chart's Phase I (Montgomery 2009, section 5.3.5):

- the dynamics null of :class:`~fusion.monitoring.DynamicsMonitor`
  (:func:`fusion.monitoring.dynamics_null.fit_dynamics_null`, commands and counts only):
  the linear model's misfit depends on the manoeuvre, so the null is fitted on
  the route itself (``docs/monitor.md``);
- the encoder stream's per-sample gate (``MonitorOptions.encoder_gate_nis``):
  the chi-square gate (NIS 55.3, a 1e-12 tail) assumes Gaussian innovations,
  but a linear model misses every start from rest by tens of standard
  deviations. Rule: ``gate_factor`` (10) times the largest encoder NIS of
  :class:`~fusion.ekf.ModelEKF` over the nominal drives, never below the
  chi-square gate. Measured on the experiments route (``docs/monitor.md``):
  nominal maximum 583 over 32 minutes, so a gate of 5,830; 150-tick spikes
  give NIS above 10^4 (above 10^5 for most).

The simulated landmark sensor of ``lti-motion monitor --sim`` is here too
(:data:`MONITOR_LANDMARKS`, :func:`sightings`): it reads the simulator's true
pose, as a camera sees the world; the monitor sees only its noisy output.

References
----------
Montgomery, D. C. (2009). Introduction to Statistical Quality Control, 6th
ed., Wiley, section 5.3.5 (Phase I and Phase II of control chart use).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fusion.ekf.model_ekf import ModelEKF
from fusion.landmark_map import LandmarkMap
from fusion.monitoring.dynamics import DynamicsNull, fit_dynamics_null
from fusion.monitoring.residual import MonitorOptions, design_thresholds
from fusion.noise import LandmarkNoise
from fusion.range_bearing import RangeBearing, range_bearing
from lti_motion.kinematics import wheel_from_body, wrap_angle
from lti_motion.model import MotionModel
from lti_motion.odometry import TICK_MODULUS

__all__ = ["MONITOR_LANDMARKS", "NominalFit", "encoder_nis", "fit_nominal", "monitor_route",
           "nominal_from_logs", "nominal_on_simulator", "sightings"]

#: Four landmarks around the monitor's rounded rectangle (x in -0.4..1.6 m, y in 0..2 m).
MONITOR_LANDMARKS = LandmarkMap({1: (-1.5, -1.0), 2: (2.7, -1.0), 3: (2.7, 3.0),
                                 4: (-1.5, 3.0)})


def monitor_route(duration_s: float, *, dt_s: float, wheel_base_m: float,
                  rng: np.random.Generator, rest_s: float = 1.0, side_m: float = 1.2,
                  radius_m: float = 0.4, speeds_m_s: tuple[float, float] = (0.12, 0.3)
                  ) -> np.ndarray:
    """Wheel commands ``(n, 2)`` [m/s] of the monitor's drive: rest, then rounded-rectangle laps.

    Each straight is driven at a speed drawn uniformly from ``speeds_m_s``; each
    corner is a quarter arc of ``radius_m`` at 0.15 m/s. Open loop: the path
    drifts as the robot does.
    """
    n = round(duration_s / dt_s)
    rows = [np.zeros((round(rest_s / dt_s), 2))]
    total = len(rows[0])
    while total < n:
        v = rng.uniform(*speeds_m_s)
        straight = np.tile([v, 0.0], (max(1, round(side_m / v / dt_s)), 1))
        v_arc = 0.15
        arc = np.tile([v_arc, v_arc / radius_m],
                      (max(1, round(0.5 * math.pi * radius_m / v_arc / dt_s)), 1))
        for body in (straight, arc):
            rows.append(wheel_from_body(body, wheel_base_m=wheel_base_m))
            total += len(body)
    return np.concatenate(rows)[:n]


@dataclass(frozen=True)
class NominalFit:
    """What the monitor learnt from nominal driving.

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
        """Monitor options with this gate (everything else default)."""
        return MonitorOptions(dt_s=dt_s, encoder_gate_nis=self.encoder_gate_nis)


def _unwrapped_deltas(ticks: np.ndarray) -> np.ndarray:
    half = TICK_MODULUS // 2
    return ((np.diff(np.asarray(ticks, np.int64), axis=0) + half) % TICK_MODULUS
            - half).astype(float)


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
    ekf = ModelEKF(model, initial_ticks=np.asarray(ticks[0], np.int64), history=0)
    out = np.full(len(cmd_m_s), math.nan)
    for k, u in enumerate(np.asarray(cmd_m_s, float)):
        ekf.predict(u)
        out[k] = ekf.update_encoders(np.asarray(ticks[k + 1], np.int64)).nis
    return out


def fit_nominal(model: MotionModel, drives: Sequence[tuple[np.ndarray, np.ndarray]], *,
                gate_factor: float = 10.0, skip_s: float = 0.5) -> NominalFit:
    """Fit the dynamics null and the encoder gate on nominal drives (module notes).

    Parameters
    ----------
    model : MotionModel
        The model the monitor will use.
    drives : sequence of (cmd_m_s (n, 2), ticks (n + 1, 2))
        Nominal drives: the commands of periods ``1 .. n`` and the raw counts
        of frames ``0 .. n`` (what a robot reports).
    gate_factor : float
        The gate is this many times the largest nominal NIS.
    skip_s : float
        Start of each drive left out of the null [s]. The drives start at
        rest, where the predictor's state is exact, so the default keeps the
        start from rest in the null: with ``fit_dynamics_null``'s 3 s, 13 of
        30 nominal drives of ``lti-motion monitor --sim`` raised a dynamics
        alarm in their first 3 s (``docs/guide_alarms.md``).

    Returns
    -------
    NominalFit

    Raises
    ------
    ValueError
        Without drives, with a factor below 1, or with too little driving for
        the null (:class:`~fusion.exceptions.FilterOptionError`).
    """
    if not drives:
        raise ValueError("fit_nominal needs at least one nominal drive")
    if not gate_factor >= 1.0:
        raise ValueError(f"gate_factor must be >= 1, got {gate_factor}")
    runs, peak, n = [], 0.0, 0
    for cmd, ticks in drives:
        cmd = np.asarray(cmd, float)
        ticks = np.asarray(ticks)
        if cmd.ndim != 2 or ticks.shape != (len(cmd) + 1, 2):
            raise ValueError(f"expected commands (n, 2) and ticks (n + 1, 2), got "
                             f"{cmd.shape} and {ticks.shape}")
        runs.append((cmd, _unwrapped_deltas(ticks)))
        peak = max(peak, float(np.nanmax(encoder_nis(model, cmd, ticks), initial=0.0)))
        n += len(cmd)
    chi2_gate = design_thresholds(MonitorOptions(dt_s=model.dt_s)).gate
    return NominalFit(null=fit_dynamics_null(model, runs, skip_s=skip_s),
                      encoder_gate_nis=max(chi2_gate, gate_factor * peak),
                      max_nominal_nis=peak, duration_s=n * model.dt_s, n_drives=len(runs))


def sightings(true_pose: np.ndarray, k: int, rng: np.random.Generator, *,
              landmarks: LandmarkMap = MONITOR_LANDMARKS, rate_hz: float = 2.0,
              dt_s: float = 0.015, noise: LandmarkNoise | None = None) -> RangeBearing:
    """The simulated landmark sensor at frame ``k``: each landmark at ``rate_hz``, in turn.

    Reads the true pose (the world's side); returns the frame's sightings (``index`` =
    ``k``, no covariance) with range noise ``max(range_std_m, range_std_frac r)`` and
    bearing noise ``bearing_std_rad`` (default 2% of range, 1 degree).
    """
    noise = noise or LandmarkNoise()
    stride = max(1, round(1.0 / (rate_hz * dt_s)))
    ids = landmarks.ids
    rows = []
    for j, landmark_id in enumerate(ids):
        if (k + j * stride // len(ids)) % stride:
            continue
        r, b = range_bearing(np.asarray(true_pose, float), landmarks.position(landmark_id))
        sr = max(noise.range_std_m, noise.range_std_frac * r)
        rows.append((landmark_id, r + sr * rng.standard_normal(),
                     wrap_angle(b + noise.bearing_std_rad * rng.standard_normal())))
    return RangeBearing(k, *zip(*rows, strict=True)) if rows else RangeBearing.empty()


def nominal_on_simulator(model: MotionModel, *, preset: str = "create2", n_drives: int = 20,
                         duration_s: float = 30.0, seed: int = 0, floor: str = "hard"
                         ) -> NominalFit:
    """Phase I on the simulator: ``n_drives`` nominal drives of :func:`monitor_route`.

    Seeds ``seed + 1000 .. seed + 1000 + n_drives - 1`` (route and simulator), no
    fault, all in one batch; commands and counts only go to
    :func:`~lti_motion.app.monitor_setup.fit_nominal`.
    """
    from drivers.sim.config import Room
    from drivers.sim.simulator import Simulator

    seeds = [seed + 1000 + i for i in range(n_drives)]
    sim = Simulator(preset, seed=seeds, floor=floor, room=Room.empty(),
                    initial_pose=np.zeros((n_drives, 3)))
    cmds = np.stack([monitor_route(duration_s, dt_s=sim.dt_s, wheel_base_m=model.wheel_base_m,
                                   rng=np.random.default_rng(s)) for s in seeds])
    log = sim.run(cmds)
    drives = [(r.cmd_m_s[1:], r.ticks) for r in (log.robot(i) for i in range(n_drives))]
    return fit_nominal(model, drives)


def nominal_from_logs(model: MotionModel, paths: Sequence[str]) -> NominalFit:
    """Phase I from logs of nominal drives (``lti-motion monitor --record`` on the robot)."""
    from lti_motion.logfile import load_log

    drives = []
    for path in paths:
        log = load_log(path)
        drives.append((log.cmd_m_s[1:], log.ticks))
    return fit_nominal(model, drives)
