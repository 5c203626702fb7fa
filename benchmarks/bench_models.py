"""Model calibration and prediction speed (docs/calibration.md).

- ``models.arx_fit_ms``: an order-9 ARX fit (2 inputs, 2 outputs, delay 4) on
  10,000 samples, regression matrix included; baseline: the same least-squares
  system solved with ``cv2.solve(..., cv2.DECOMP_SVD)``, as the paper did on its
  robot (it reports almost 2 s there).
- ``models.predict_msamples_s``: sensor-less prediction of speeds and poses.
- ``models.rls_samples_s``: recursive least squares, order 9, one
  ``update(u, y)`` call per sample (as an online loop uses it), and
  ``models.rls_update_many_samples_s`` for a buffered block.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import cv2
import numpy as np

from benchmarks.harness import Figure, benchmark, median_seconds
from drivers.sim.config import Room, get_preset
from drivers.sim.simulator import Simulator
from lti_motion.calibration.manoeuvres import speeds_from_log
from lti_motion.model.arx import RecursiveARX, arx_regression, estimate_arx
from lti_motion.model.excitation import random_held_normal
from lti_motion.model.motion_model import MotionModel

ORDER, DELAY, N = 9, 4, 10_000


def _data() -> tuple[np.ndarray, np.ndarray, float, float]:
    p = get_preset("create2")
    u = random_held_normal(n=N + 1, dt_s=p.period_s, rng=np.random.default_rng(0),
                           std_m_s=0.15, hold_s=(0.5, 2.0))
    log = Simulator(p, seed=0, room=Room.empty()).run(u)
    u_s, y_s = speeds_from_log(log, m_per_tick=p.m_per_tick, wheel_base_m=p.wheel_base_m)
    return u_s, y_s, p.period_s, p.wheel_base_m


@benchmark("models")
def models() -> list[Figure]:
    u, y, dt, b = _data()
    runs = [(u, y)]

    def ours() -> None:
        estimate_arx(runs, na=ORDER, nb=ORDER, delay=DELAY)

    def opencv() -> None:
        phi, rhs = arx_regression(runs, na=ORDER, nb=ORDER, delay=DELAY)
        cv2.solve(phi.astype(np.float64), rhs.astype(np.float64), flags=cv2.DECOMP_SVD)

    t_ours = median_seconds(ours, repeat=21, warmup=3)
    t_cv = median_seconds(opencv, repeat=7, warmup=1)

    model = MotionModel.from_arx(estimate_arx(runs, na=ORDER, nb=ORDER, delay=DELAY),
                                 dt_s=dt, wheel_base_m=b)
    long_u = np.tile(u, (100, 1))                        # one million samples

    def predict() -> None:
        model.predict_poses(long_u)

    t_pred = median_seconds(predict, repeat=5)

    rls = RecursiveARX.from_fit(estimate_arx(runs, na=ORDER, nb=ORDER, delay=DELAY), lam=0.999)
    n_rls = 2000

    def rls_run() -> None:
        for k in range(n_rls):
            rls.update(u[k], y[k])

    t_rls = median_seconds(rls_run, repeat=5)

    def rls_batch() -> None:
        rls.update_many(u[:n_rls], y[:n_rls])

    t_rls_batch = median_seconds(rls_batch, repeat=5)
    return [
        Figure("models.arx_fit_ms", t_ours * 1e3, "ms", target=5.0, better="lower",
               baseline="cv2.solve DECOMP_SVD on the same system", baseline_value=t_cv * 1e3),
        Figure("models.predict_msamples_s", len(long_u) / t_pred / 1e6, "Msamples/s",
               target=5.0),
        Figure("models.rls_samples_s", n_rls / t_rls, "samples/s", target=50_000.0),
        Figure("models.rls_update_many_samples_s", n_rls / t_rls_batch, "samples/s",
               target=50_000.0, baseline="one update() call per sample",
               baseline_value=n_rls / t_rls),
    ]
