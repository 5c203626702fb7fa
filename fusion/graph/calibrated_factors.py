"""The calibration-aware motion factor: preintegrated motion corrected to first order in ``(s, g)``.

The preintegrated relative pose for another calibration ``c = (s, g)`` (or
``(s, g, kappa)``, with the curvature ``kappa`` [rad/m] of a left/right wheel
diameter ratio; :mod:`fusion.graph.preintegration`) is, to first order,
``iTj(c) = iTj_hat Exp(J_c (c - c_bar))`` (Forster et al. 2017, eq. 44, the
first-order bias update of IMU preintegration). The factor on (pose ``i``,
pose ``j``, calibration) returns the unwhitened 3-vector

.. math::

    e = \\operatorname{Log}(\\hat T^{-1}\\, {}^wT_i^{-1}\\, {}^wT_j) - J_c (c - \\bar c),

which equals ``Log(iTj(c)^-1 wTi^-1 wTj)`` to first order. The math lives once,
vectorised over ``K`` intervals, in :func:`calibrated_motion_errors`; the
factors are thin ``gtsam.CustomFactor`` adapters around it:

- :func:`calibrated_motion_factor`: one interval, keys (pose ``i``, pose
  ``j``, calibration), for users adding our factors to their own graphs.
- :func:`calibrated_motion_group_factor`: ``K`` consecutive intervals that share
  one calibration variable, one factor (a ``3K``-dimensional error with a
  block-diagonal covariance, so the same cost as ``K`` separate factors).

Why a group: inside ``gtsam.ISAM2`` (and ``LevenbergMarquardtOptimizer``) every
call of a Python ``CustomFactor`` receives the optimiser's *whole* ``Values``,
which the gtsam 4.3 Python wrapper copies (pybind11 casts the ``const
Values&`` argument by value): about 0.5 us per variable in the graph, 5 ms per
call at 10,000 keyframes, against 0.1 ms for the factor's own arithmetic. The
copy, not the factor's math or the elimination, is what made the per-interval
factor cost 3x the native graph (docs/factor_graph.md, "Speed"); one factor
per group makes ``K`` times fewer calls.

Pose2 formulas (gtsam conventions, right perturbations ``wT Exp(xi)``):
``Log(x, y, w) = (a x + w/2 y, -w/2 x + a y, w)`` with ``a = (w/2) cot(w/2)``
(the inverse of the left Jacobian ``V(w)`` of SE(2); Barfoot 2017, section 7.1);
``Ad(x, y, w) = [[R(w), (y, -x)^T], [0, 1]]``; the inverse right Jacobian
``J_r^-1`` is gtsam's ``Pose2::LogmapDerivative``.

References
----------
C. Forster, L. Carlone, F. Dellaert, D. Scaramuzza, "On-Manifold Preintegration for
Real-Time Visual-Inertial Odometry", IEEE Trans. Robotics 33(1), 2017, eq. 44-45.
T. D. Barfoot, *State Estimation for Robotics*, Cambridge University Press, 2017,
section 7.1 (exponential map, adjoint and Jacobians of the matrix Lie groups).
"""

from __future__ import annotations

from collections.abc import Sequence

import gtsam
import numpy as np

from fusion.graph.preintegration import Preintegrated
from lti_motion.exceptions import ShapeError

__all__ = [
    "calibrated_motion_error",
    "calibrated_motion_errors",
    "calibrated_motion_factor",
    "calibrated_motion_group_factor",
    "pose2_log",
    "pose2_log_derivative",
]

#: Below this turn [rad] ``Log`` and its derivative use their Taylor series.
_SMALL_ANGLE_RAD = 1e-5
_TWO_PI = 2.0 * np.pi


def _wrap(a_rad: np.ndarray) -> np.ndarray:
    """Angles into (-pi, pi], as gtsam's ``Rot2`` keeps them (two ufunc calls)."""
    return np.pi - np.remainder(np.pi - a_rad, _TWO_PI)


def _half_cot(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a = (w/2) cot(w/2)`` and ``h = a / w = sin w / (2 (1 - cos w))`` (``h`` only where
    ``|w|`` is not small; there ``a = 1 - w^2/12``, ``h`` unused), and the small mask."""
    small = np.abs(w) < _SMALL_ANGLE_RAD
    ws = np.where(small, 1.0, w)
    h = 0.5 * np.sin(ws) / (1.0 - np.cos(ws))
    return np.where(small, 1.0 - w * w / 12.0, ws * h), h, small


def _inverse(pose: np.ndarray) -> np.ndarray:
    """``T^-1`` for rows of Pose2 parameters: ``(-R^T t, -theta)``, shape (K, 3)."""
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    x, y = pose[:, 0], pose[:, 1]
    return np.stack([-(c * x + s * y), -(c * y - s * x), _wrap(-pose[:, 2])], axis=1)


def _log_columns(x: np.ndarray, y: np.ndarray, w: np.ndarray) -> np.ndarray:
    a, _, _ = _half_cot(w)
    h = 0.5 * w
    return np.stack([a * x + h * y, -h * x + a * y, w], axis=1)


def pose2_log(pose: np.ndarray) -> np.ndarray:
    """``Pose2.Logmap`` of rows ``(x [m], y [m], theta [rad])``, vectorised.

    Parameters
    ----------
    pose : array_like, shape (K, 3)
        Poses, ``theta`` in (-pi, pi].

    Returns
    -------
    ndarray, shape (K, 3)
        Tangent vectors ``(v_x, v_y, w)``: ``v = V(w)^-1 t``,
        ``V(w)^-1 = [[a, w/2], [-w/2, a]]``, ``a = (w/2) cot(w/2)`` (module Notes).

    Examples
    --------
    >>> (pose2_log(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, np.pi / 2]])).round(6) + 0.0).tolist()
    [[1.0, 0.0, 0.0], [0.785398, 0.785398, 1.570796]]
    """
    p = np.asarray(pose, dtype=float).reshape(-1, 3)
    return _log_columns(p[:, 0], p[:, 1], p[:, 2])


def pose2_log_derivative(xi: np.ndarray) -> np.ndarray:
    """Inverse right Jacobian ``J_r^-1(xi)`` of ``Pose2.Expmap``, vectorised.

    Parameters
    ----------
    xi : array_like, shape (K, 3)
        Tangent vectors ``(v_x, v_y, w)``.

    Returns
    -------
    ndarray, shape (K, 3, 3)
        gtsam's ``Pose2.LogmapDerivative`` row by row: ``[[a, -w/2, v_x/w - v_x h
        + v_y/2], [w/2, a, v_y/w - v_x/2 - v_y h], [0, 0, 1]]`` with
        ``h = sin(w) / (2 (1 - cos w))``, ``a = w h``; ``[[1, 0, v_y/2], [0, 1, -v_x/2],
        [0, 0, 1]]`` for ``|w| < 1e-5``.
    """
    v = np.asarray(xi, dtype=float).reshape(-1, 3)
    vx, vy, w = v[:, 0], v[:, 1], v[:, 2]
    a, h, small = _half_cot(w)
    ws = np.where(small, 1.0, w)
    out = np.zeros((len(v), 3, 3))
    out[:, 0, 0] = out[:, 1, 1] = np.where(small, 1.0, a)
    out[:, 0, 1] = np.where(small, 0.0, -0.5 * w)
    out[:, 1, 0] = -out[:, 0, 1]
    out[:, 0, 2] = np.where(small, 0.5 * vy, vx / ws - vx * h + 0.5 * vy)
    out[:, 1, 2] = np.where(small, -0.5 * vx, vy / ws - 0.5 * vx - vy * h)
    out[:, 2, 2] = 1.0
    return out


def calibrated_motion_errors(wTi: np.ndarray, wTj: np.ndarray, calibration: np.ndarray, *,
                             measured_inverse: np.ndarray, calibration_jacobian: np.ndarray,
                             calibration_offset: np.ndarray, jacobians: bool = False
                             ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Errors of ``K`` calibration-aware motion factors, with pose Jacobians on request.

    Parameters
    ----------
    wTi, wTj : ndarray, shape (K, 3)
        Start and end poses ``(x [m], y [m], theta [rad])`` in the world.
    calibration : ndarray, shape (nc,)
        Current ``(s, g)`` or ``(s, g, kappa)``.
    measured_inverse : ndarray, shape (K, 3)
        ``iTj_hat^-1`` of each interval, as Pose2 parameters.
    calibration_jacobian : ndarray, shape (K, 3, nc)
        ``J_c`` of each interval.
    calibration_offset : ndarray, shape (K, 3)
        ``J_c c_bar`` of each interval (``c_bar`` the calibration it was integrated with).
    jacobians : bool
        Also return ``d e / d wTi`` and ``d e / d wTj``.

    Returns
    -------
    error : ndarray, shape (K, 3)
        ``e = Log(iTj_hat^-1 wTi^-1 wTj) - J_c c + J_c c_bar`` (unwhitened).
    d_wTi, d_wTj : ndarray, shape (K, 3, 3), or None
        ``-J_r^-1(Log D) Ad(B^-1)`` and ``J_r^-1(Log D)``, with ``B = wTi^-1 wTj``,
        ``D = iTj_hat^-1 B``, right perturbations ``wT Exp(xi)``. ``d e / d c`` is
        ``-J_c``, constant.
    """
    # B = wTi^-1 wTj: rotate the position difference into frame i
    ci, si = np.cos(wTi[:, 2]), np.sin(wTi[:, 2])
    dx, dy = wTj[:, 0] - wTi[:, 0], wTj[:, 1] - wTi[:, 1]
    bx, by, bt = ci * dx + si * dy, ci * dy - si * dx, wTj[:, 2] - wTi[:, 2]
    # D = iTj_hat^-1 B (Pose2 composition), then its Log
    cm, sm = np.cos(measured_inverse[:, 2]), np.sin(measured_inverse[:, 2])
    log_d = _log_columns(measured_inverse[:, 0] + cm * bx - sm * by,
                         measured_inverse[:, 1] + sm * bx + cm * by,
                         _wrap(measured_inverse[:, 2] + bt))
    err = log_d - calibration_jacobian @ calibration + calibration_offset
    if not jacobians:
        return err, None, None
    jr_inv = pose2_log_derivative(log_d)
    # Ad(B^-1) = [[R(-b_t), (t_y, -t_x)], [0, 1]] with t = -R(-b_t) (b_x, b_y)
    cb, sb = np.cos(bt), np.sin(bt)
    tx, ty = -(cb * bx + sb * by), -(cb * by - sb * bx)
    ad = np.zeros((len(bt), 3, 3))
    ad[:, 0, 0], ad[:, 0, 1], ad[:, 1, 0], ad[:, 1, 1] = cb, sb, -sb, cb
    ad[:, 0, 2], ad[:, 1, 2], ad[:, 2, 2] = ty, -tx, 1.0
    return err, -jr_inv @ ad, jr_inv


def _pose_row(p: gtsam.Pose2) -> np.ndarray:
    return np.array([p.x(), p.y(), p.theta()])


def calibrated_motion_error(wTi: gtsam.Pose2, wTj: gtsam.Pose2, calibration: np.ndarray, *,
                            measured_inverse: gtsam.Pose2, calibration_jacobian: np.ndarray,
                            linearization_point: np.ndarray,
                            jacobians: list[np.ndarray] | None = None) -> np.ndarray:
    """Error of one calibration-aware motion factor, with its Jacobians on request.

    Parameters
    ----------
    wTi, wTj : gtsam.Pose2
        Poses of keyframes ``i`` and ``j`` in the world.
    calibration : ndarray, shape (nc,)
        Current ``(s, g)`` or ``(s, g, kappa)``.
    measured_inverse : gtsam.Pose2
        ``iTj_hat^-1``, the inverse of the preintegrated relative pose.
    calibration_jacobian : ndarray, shape (3, nc)
        ``J_c`` of the preintegration.
    linearization_point : ndarray, shape (nc,)
        ``c_bar``, the calibration the speeds were integrated with.
    jacobians : list of 3 ndarray, optional
        Filled with ``d e / d wTi``, ``d e / d wTj`` (3, 3, right perturbations
        ``wT Exp(xi)``) and ``d e / d c`` (3, nc) when given.

    Returns
    -------
    ndarray, shape (3,)
        ``e = Log(iTj_hat^-1 wTi^-1 wTj) - J_c (c - c_bar)`` (unwhitened).

    Notes
    -----
    :func:`calibrated_motion_errors` for one interval. The error equals
    ``Log(iTj(c)^-1 wTi^-1 wTj)`` to first order in the error and in
    ``c - c_bar`` (Baker-Campbell-Hausdorff); it is exact in ``s`` (positions
    scale linearly with ``s``) when ``kappa`` is not estimated.
    """
    jc = np.asarray(calibration_jacobian, dtype=float).reshape(1, 3, -1)
    err, d_i, d_j = calibrated_motion_errors(
        _pose_row(wTi)[None], _pose_row(wTj)[None], np.asarray(calibration, dtype=float),
        measured_inverse=_pose_row(measured_inverse)[None], calibration_jacobian=jc,
        calibration_offset=(jc[0] @ np.asarray(linearization_point, dtype=float))[None],
        jacobians=jacobians is not None)
    if jacobians is not None:
        jacobians[0], jacobians[1], jacobians[2] = d_i[0], d_j[0], -jc[0]
    return err[0]


def calibrated_motion_group_factor(pre: Preintegrated | Sequence[Preintegrated], *,
                                   pose_keys: Sequence[int], key_c: int) -> gtsam.CustomFactor:
    """One ``gtsam.CustomFactor`` for ``K`` consecutive intervals sharing a calibration.

    Parameters
    ----------
    pre : Preintegrated or sequence of Preintegrated
        The intervals, in order (their ``len`` sum to ``K``); they may have been
        preintegrated at different calibrations.
    pose_keys : sequence of int, length K + 1
        Keys of the poses at the interval ends (``Pose2``).
    key_c : int
        Key of the calibration: ``(s, g)`` as a ``Point2``, or ``(s, g, kappa)`` as a
        ``Point3`` when the intervals were preintegrated with a curvature.

    Returns
    -------
    gtsam.CustomFactor
        On ``pose_keys + [key_c]``; error: the ``K`` errors of
        :func:`calibrated_motion_errors` stacked (``3K``), noise: their
        preintegrated covariances on the block diagonal, so the factor costs
        exactly what ``K`` single-interval factors cost. Jacobians only when
        gtsam asks (linearisation).

    Raises
    ------
    ShapeError
        If ``pose_keys`` does not hold one key more than there are intervals, or
        the intervals disagree on the calibration's size.

    Notes
    -----
    Per call: ``K + 1`` pose look-ups and a few dozen numpy operations on
    (K,)-arrays, whatever ``K``: about 35 us for the error and 80 us with the
    Jacobians at ``K = 10`` (25 and 50 us at ``K = 1``; a native
    ``BetweenFactorPose2`` takes 1 us), before the ``Values`` copy (module Notes).
    """
    parts = [pre] if isinstance(pre, Preintegrated) else list(pre)
    sizes = sorted({len(p.calibration) for p in parts})
    if len(sizes) != 1:
        raise ShapeError(f"the intervals of one group need calibrations of one size, got sizes "
                         f"{sizes}; preintegrate them all with (s, g) or all with (s, g, kappa)")
    m_inv = _inverse(np.concatenate([p.delta_pose for p in parts]))
    jc = np.concatenate([p.calibration_jacobian for p in parts])
    offset = np.concatenate([np.einsum("kij,j->ki", p.calibration_jacobian, p.calibration)
                             for p in parts])
    n, nc = len(jc), sizes[0]
    cov = np.zeros((n, 3, n, 3))                      # block diagonal (scipy's block_diag,
    cov[np.arange(n), :, np.arange(n), :] = np.concatenate([p.covariance for p in parts])
    cov = cov.reshape(3 * n, 3 * n)                   # without its per-block Python loop)
    keys = [int(k) for k in pose_keys]
    if len(keys) != n + 1:
        raise ShapeError(f"{n} intervals need {n + 1} pose keys, got {len(keys)}")
    neg_jc = -jc.reshape(3 * n, nc)
    rows = np.arange(n)
    calibration_at = gtsam.Values.atPoint2 if nc == 2 else gtsam.Values.atPoint3

    def error(_: gtsam.CustomFactor, values: gtsam.Values,
              jacobians: list[np.ndarray] | None) -> np.ndarray:
        poses = np.array([[p.x(), p.y(), p.theta()] for p in map(values.atPose2, keys)])
        err, d_i, d_j = calibrated_motion_errors(
            poses[:-1], poses[1:], np.asarray(calibration_at(values, key_c)),
            measured_inverse=m_inv,
            calibration_jacobian=jc, calibration_offset=offset, jacobians=jacobians is not None)
        if jacobians is not None:
            full = np.zeros((n, 3, n + 1, 3))         # (interval, row, pose, column)
            full[rows, :, rows, :] = d_i
            full[rows, :, rows + 1, :] = d_j
            full = full.reshape(3 * n, n + 1, 3)
            for m in range(n + 1):
                jacobians[m] = full[:, m, :]
            jacobians[n + 1] = neg_jc
        return err.reshape(-1)

    return gtsam.CustomFactor(gtsam.noiseModel.Gaussian.Covariance(cov), [*keys, int(key_c)],
                              error)


def calibrated_motion_factor(pre: Preintegrated, k: int, *, key_i: int, key_j: int,
                             key_c: int) -> gtsam.CustomFactor:
    """The calibration-aware motion factor of interval ``k`` (a ``gtsam.CustomFactor``).

    Parameters
    ----------
    pre : Preintegrated
        Preintegrated intervals (with their calibration Jacobians).
    k : int
        Which interval.
    key_i, key_j, key_c : int
        Keys of the start pose, end pose (``Pose2``) and calibration (``Point2``, or
        ``Point3`` for ``(s, g, kappa)``).

    Returns
    -------
    gtsam.CustomFactor
        Three-dimensional error :func:`calibrated_motion_error`, Gaussian noise
        ``pre.covariance[k]``; Jacobians only when gtsam asks for them.

    Notes
    -----
    :func:`calibrated_motion_group_factor` for one interval. In a large graph
    prefer the group factor: each call of a Python factor inside a gtsam
    optimiser copies the optimiser's whole ``Values`` (module Notes).
    """
    return calibrated_motion_group_factor(pre[k], pose_keys=[key_i, key_j], key_c=key_c)
