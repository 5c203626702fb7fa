"""Encoder odometry's random walk per metre of wheel travel, measured on a calibration drive.

After :func:`lti_motion.calibration.calibrate_intrinsics` has fitted the intrinsics, the
drive's odometry is compared with the pose reference over intervals of several lengths
(1 to 16 s by default). Each interval's residual ``r`` (odometry minus reference
displacement, in the interval's start frame) holds the reference's noise, the same
whatever the length, and the odometry's non-systematic error, which grows with the wheels'
travel (:mod:`lti_motion.odometry_errors`, eq. 1-2: Chong & Kleeman 1997, eq. 4):

.. math::  E[r r^T] = N + k\\, M_i, \\qquad M_i = \\sum_j A_j \\Sigma_j A_j^T             (1)

``Sigma_j`` the step's ``(ds, dtheta)`` covariance for ``k = 1`` (eq. 2 there), ``A_j =
[[cos phi_j, -(y_e - y_j)], [sin phi_j, x_e - x_j], [0, 1]]`` how a step's travel and turn
errors move the interval's end ``(x_e, y_e)`` (first order, Chong & Kleeman eq. 8-9). The
squared residuals' expectations are linear in ``(n_xy, n_theta, k)``:

.. math::  E[r_x^2 + r_y^2] = 2 n_{xy} + k (M_{xx} + M_{yy}), \\qquad
           E[r_\\theta^2] = n_\\theta + k M_{\\theta\\theta}                              (2)

solved by non-negative least squares (Lawson & Hanson 1974, ch. 23), each row weighed by
its predicted standard deviation (a squared Gaussian's is its mean, times sqrt 2 for one
component, times 1 for the sum of two), twice re-weighted. Intervals of one length
overlap, so their rows correlate; the standard error of ``k`` treats them as independent
and is an approximation. Longer intervals let systematic errors the intrinsics do not
explain into the residuals: they count as growth, on the safe side.

References
----------
K. S. Chong, L. Kleeman, "Accurate odometry and error modelling for a mobile robot",
ICRA 1997, eq. 4, 8-9.
C. L. Lawson, R. J. Hanson, *Solving Least Squares Problems*, Prentice-Hall 1974, ch. 23.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.optimize import nnls

from lti_motion.calibration.intrinsics_solver import Intervals, residuals

__all__: list[str] = []

#: Interval lengths [s] the walk is measured over.
WALK_LENGTHS_S = (1.0, 2.0, 4.0, 8.0, 16.0)


def _unit_growth(iv: Intervals, kl: float, kr: float, b: float) -> np.ndarray:
    """``M_i`` of eq. (1) per interval, shape (K, 3, 3), for ``k = 1``."""
    s_l, s_r = kl * iv.dn[:, 0], kr * iv.dn[:, 1]
    ds, dth = 0.5 * (s_l + s_r), (s_r - s_l) / b
    cum = np.cumsum(dth)
    before = cum - dth
    start_heading = np.concatenate([[0.0], cum])[iv.starts][iv.seg]
    mid = before - start_heading + 0.5 * dth                 # heading in the start frame
    xy = np.stack([ds * np.cos(mid), ds * np.sin(mid)], axis=1)
    cxy = np.cumsum(xy, axis=0)
    base = np.concatenate([[[0.0, 0.0]], cxy])[iv.starts][iv.seg]
    pos = cxy - base                                         # each step's end, start frame
    ends = np.add.reduceat(xy, iv.starts, axis=0)[iv.seg]
    a = np.zeros((len(ds), 3, 2))
    a[:, 0, 0], a[:, 1, 0] = np.cos(mid), np.sin(mid)
    a[:, 0, 1], a[:, 1, 1] = -(ends[:, 1] - pos[:, 1]), ends[:, 0] - pos[:, 0]
    a[:, 2, 1] = 1.0
    al, ar = np.abs(s_l), np.abs(s_r)
    sig = np.empty((len(ds), 2, 2))                          # odometry_errors eq. (2)
    sig[:, 0, 0] = 0.25 * (al + ar)
    sig[:, 0, 1] = sig[:, 1, 0] = 0.5 * (ar - al) / b
    sig[:, 1, 1] = (al + ar) / b**2
    per_step = a @ sig @ np.swapaxes(a, 1, 2)
    return np.add.reduceat(per_step, iv.starts, axis=0)


def fit_wheel_walk(intervals: Sequence[Intervals], params: np.ndarray
                   ) -> tuple[float, float, np.ndarray]:
    """``k`` [m^2/m] of eq. (1), its standard error and the reference noise ``(n_xy [m^2],
    n_theta [rad^2])``, from intervals of several lengths and the calibrated ``params``
    ``(k_L, k_R, b[, l_x, l_y, l_theta])``."""
    rows_y, rows_x, kind = [], [], []
    for iv in intervals:
        r = residuals(iv, params)
        m = _unit_growth(iv, *params[:3])
        k = len(r)
        rows_y += [r[:, 0] ** 2 + r[:, 1] ** 2, r[:, 2] ** 2]
        rows_x += [np.column_stack([np.full(k, 2.0), np.zeros(k), m[:, 0, 0] + m[:, 1, 1]]),
                   np.column_stack([np.zeros(k), np.ones(k), m[:, 2, 2]])]
        kind += [np.zeros(k, bool), np.ones(k, bool)]
    y, x, heading = np.concatenate(rows_y), np.vstack(rows_x), np.concatenate(kind)
    # first weights: each component's typical size; then the predicted standard deviations
    sd = np.where(heading, np.median(y[heading]), np.median(y[~heading]))
    for _ in range(3):
        sd = np.maximum(sd, 1e-300)
        theta, _ = nnls(x / sd[:, None], y / sd)
        pred = x @ theta
        sd = np.where(heading, np.sqrt(2.0), 1.0) * np.maximum(pred, 1e-3 * np.median(pred))
    xw = x / sd[:, None]
    resid = (y - x @ theta) / sd
    dof = max(len(y) - 3, 1)
    try:
        cov = np.linalg.inv(xw.T @ xw) * float(resid @ resid) / dof
        k_std = float(np.sqrt(max(cov[2, 2], 0.0)))
    except np.linalg.LinAlgError:
        k_std = float("inf")
    return float(theta[2]), k_std, theta[:2]
