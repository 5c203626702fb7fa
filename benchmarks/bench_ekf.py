"""EKF plug-in speed (docs/ekf.md): the model inside filterpy against the textbook filter.

- ``ekf.predict_update_us``: one :meth:`fusion.ekf.ModelEKF.predict` plus one
  :meth:`~fusion.ekf.ModelEKF.update_encoders` (raw counts, rollover-safe
  increments, chi-square gate, Joseph-form update, record), per sensor period,
  with the ARX model calibrated on the simulator (``nz = 12``; 20 states).
  Baseline, run in the same process and interleaved with ours: a stock
  ``filterpy.kalman.ExtendedKalmanFilter`` with the textbook 3-state velocity
  motion model (Thrun, Burgard & Fox 2005, table 5.3: ``G``, ``V``, ``M``,
  ``Q = V M V^T``; the mean by overriding ``predict_x``, filterpy's documented
  hook) and one 2-D linear update through filterpy's own ``update(z,
  HJacobian, Hx, R)``. Target: at most 1.5 times the baseline.
- ``ekf.steps_per_s``: the same loop as sensor periods per second (target 10,000).
- ``ekf.landmark_update_us``: one range-bearing update (no target).
- ``ekf.stock_plain_functions_us``: a stock filterpy EKF driven by
  :mod:`fusion.ekf.functions` (predict and encoder update, no gate or record),
  for users who keep their own filter (no target).
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from benchmarks.harness import Figure, benchmark
from drivers.sim.calibration import calibrate_simulator
from drivers.sim.config import Room, get_preset
from drivers.sim.simulator import Simulator
from fusion.ekf import functions as ef
from fusion.ekf.ekf_options import EKFOptions
from fusion.ekf.model_ekf import ModelEKF
from fusion.landmark_map import LandmarkMap
from lti_motion.calibration.manoeuvres import CalibrationPlan
from lti_motion.model.motion_model import MotionModel

N_STEPS = 2000
REPEAT = 15
ALPHAS = (0.01, 0.001, 0.001, 0.01)     # Thrun table 5.3 motion noise parameters


def _model_and_drive() -> tuple[MotionModel, np.ndarray, np.ndarray, np.ndarray]:
    """The simulator-calibrated ARX model and a drive: commands, counts, encoder (v, w)."""
    p = get_preset("create2")
    cal = calibrate_simulator(p, seed=1, plan=CalibrationPlan(seed=3))
    k = np.arange(N_STEPS + 1)
    cmd = np.stack([0.2 + 0.05 * np.sin(k / 80.0), 0.2 + 0.05 * np.cos(k / 80.0)], axis=1)
    log = Simulator(p, seed=2, room=Room.empty()).run(cmd)
    fm = ef.FilterModel(cal.arx)
    vw = np.array([ef.encoder_speeds(log.ticks[i:i + 2], fm) for i in range(N_STEPS)])
    return cal.arx, log.cmd_m_s, log.ticks, vw


class _VelocityModelEKF(ExtendedKalmanFilter):
    """Stock filterpy EKF; only ``predict_x`` (filterpy's documented hook) is overridden."""

    dt_s = 0.015

    def predict_x(self, u: np.ndarray = 0) -> None:
        v, w = u
        theta = self.x[2]
        if abs(w) > 1e-9:                   # Thrun et al. 2005, table 5.3, line 7
            r = v / w
            self.x = self.x + np.array([-r * math.sin(theta) + r * math.sin(theta + w * self.dt_s),
                                        r * math.cos(theta) - r * math.cos(theta + w * self.dt_s),
                                        w * self.dt_s])
        else:
            self.x = self.x + np.array([v * self.dt_s * math.cos(theta),
                                        v * self.dt_s * math.sin(theta), 0.0])


def _baseline_step(ekf: _VelocityModelEKF) -> Callable[[np.ndarray, np.ndarray], None]:
    H = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    R = np.eye(2) * 1e-4
    dt = ekf.dt_s
    a1, a2, a3, a4 = ALPHAS

    def hjacobian(x: np.ndarray) -> np.ndarray:
        return H

    def hx(x: np.ndarray) -> np.ndarray:
        return H @ x

    def step(u: np.ndarray, z: np.ndarray) -> None:
        v, w = u
        w = w if abs(w) > 1e-9 else 1e-9
        theta = ekf.x[2]
        s0, c0 = math.sin(theta), math.cos(theta)
        s1, c1 = math.sin(theta + w * dt), math.cos(theta + w * dt)
        r = v / w
        ekf.F = np.array([[1.0, 0.0, -r * c0 + r * c1],        # G_t, table 5.3 line 3
                          [0.0, 1.0, -r * s0 + r * s1],
                          [0.0, 0.0, 1.0]])
        V = np.array([[(-s0 + s1) / w, v * (s0 - s1) / w ** 2 + v * c1 * dt / w],   # line 4
                      [(c0 - c1) / w, -v * (c0 - c1) / w ** 2 + v * s1 * dt / w],
                      [0.0, dt]])
        M = np.diag([a1 * v * v + a2 * w * w, a3 * v * v + a4 * w * w])                # line 5
        ekf.Q = V @ M @ V.T
        ekf.predict(u)
        ekf.update(z, hjacobian, hx, R=R)

    return step


def _interleaved(fns: dict[str, Callable[[], None]]) -> dict[str, float]:
    """Median seconds of each function, the runs interleaved (one warm-up round)."""
    times: dict[str, list[float]] = {k: [] for k in fns}
    for r in range(REPEAT + 1):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            if r:
                times[name].append(time.perf_counter() - t0)
    return {k: statistics.median(v) for k, v in times.items()}


@benchmark("ekf")
def ekf() -> list[Figure]:
    model, cmd, ticks, vw = _model_and_drive()
    z_meas = np.zeros(2)

    def ours() -> None:
        f = ModelEKF(model, initial_ticks=ticks[0], options=EKFOptions(history=1000))
        for k in range(1, N_STEPS + 1):
            f.predict(cmd[k])
            f.update_encoders(ticks[k])

    def baseline() -> None:
        f = _VelocityModelEKF(dim_x=3, dim_z=2, dim_u=2)
        f.x, f.P = np.zeros(3), np.eye(3) * 1e-4
        step = _baseline_step(f)
        for k in range(N_STEPS):
            step(vw[k], z_meas)

    fm = ef.FilterModel(model)

    class Stock(ExtendedKalmanFilter):
        def predict_x(self, u: np.ndarray = 0) -> None:
            self.x = self._x_next

    def stock_plain() -> None:
        f = Stock(dim_x=fm.n, dim_z=2, dim_u=2)
        f.x, f.P = ef.initial_state(fm, (0.0, 0.0, 0.0)), ef.initial_covariance(fm)
        for k in range(1, N_STEPS + 1):
            f._x_next, f.F, f.Q = ef.predict_terms(f.x, cmd[k], fm)
            f.predict(cmd[k])
            f.update(vw[k - 1], ef.encoder_jacobian, ef.encoder_measurement, R=fm.encoder_cov,
                     args=(fm,), hx_args=(fm,))

    lm = LandmarkMap({0: (3.0, 1.0)})
    lekf = ModelEKF(model, landmarks=lm, options=EKFOptions(gate_probability=None))
    obs = np.array([math.hypot(3.0, 1.0), math.atan2(1.0, 3.0)])

    def landmark() -> None:
        for _ in range(N_STEPS):
            lekf.update_landmark(0, obs)

    t = _interleaved({"ours": ours, "baseline": baseline, "stock": stock_plain,
                      "landmark": landmark})
    us = {k: v / N_STEPS * 1e6 for k, v in t.items()}
    base = "stock filterpy EKF, Thrun table 5.3 velocity model + 2-D linear update"
    return [
        Figure("ekf.predict_update_us", us["ours"], "us", target=1.5 * us["baseline"],
               better="lower", baseline=base, baseline_value=us["baseline"]),
        Figure("ekf.steps_per_s", 1e6 / us["ours"], "steps/s", target=10_000.0),
        Figure("ekf.landmark_update_us", us["landmark"], "us", better="lower"),
        Figure("ekf.stock_plain_functions_us", us["stock"], "us", better="lower",
               baseline=base, baseline_value=us["baseline"]),
    ]
