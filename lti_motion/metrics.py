"""Accuracy metrics: model fit (NRMSE %), closure offset, ATE and RPE.

Trajectories are arrays of planar poses ``(..., n, 3)`` = ``(x [m], y [m],
theta [rad])`` sampled at the same instants (positions ``(..., n, 2)`` are
accepted where headings are not needed). Leading axes are batch axes (for
example ``N`` simulated robots); a metric over an unbatched trajectory returns
a Python ``float``.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lti_motion.exceptions import NonFiniteError, ShapeError
from lti_motion.kinematics import wrap_angle

__all__ = [
    "RelativePoseError",
    "TrajectoryError",
    "ate",
    "ate_stats",
    "closure_error",
    "closure_offset_m",
    "fit_percent",
    "rpe",
]


def _finite(arr: np.ndarray, name: str) -> np.ndarray:
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0].tolist()
        raise NonFiniteError(f"{name} contains NaN or infinite values (first at index {bad})")
    return arr


def _scalar_or_array(arr: np.ndarray) -> float | np.ndarray:
    return float(arr) if arr.ndim == 0 else arr


def fit_percent(y_true: np.ndarray, y_pred: np.ndarray, *, axis: int = 0) -> float | np.ndarray:
    """Normalised-RMSE fit in percent, per output channel.

    Parameters
    ----------
    y_true : array_like, shape (n,) or (n, n_outputs)
        Measured outputs (time along ``axis``).
    y_pred : array_like, same shape
        Model outputs.
    axis : int
        The time axis.

    Returns
    -------
    float or ndarray
        ``100 * (1 - ||y - yhat|| / ||y - mean(y)||)`` over ``axis``, one value
        per remaining element (per channel). 100 is a perfect fit, 0 is as good
        as the mean, negative is worse than the mean.

    Raises
    ------
    ShapeError
        If the shapes differ.
    NonFiniteError
        If an input is NaN or infinite (a ``ValueError``).
    ValueError
        If a channel of ``y_true`` is constant (the fit is undefined: excite
        that output, or drop it).

    Notes
    -----
    The fit that MATLAB's ``compare`` reports, ``100 (1 - NRMSE)``, with the
    NRMSE cost of ``goodnessOfFit``: ``||y - yhat|| / ||y - mean(y)||``.

    References
    ----------
    MathWorks, System Identification Toolbox reference, ``compare`` and
    ``goodnessOfFit`` (cost function 'NRMSE').

    Examples
    --------
    >>> round(fit_percent(np.array([0.0, 1.0, 2.0, 3.0]), np.array([0.0, 1.0, 2.0, 4.0])), 6)
    55.27864
    """
    y = np.asarray(y_true, dtype=float)
    yhat = np.asarray(y_pred, dtype=float)
    if y.shape != yhat.shape or y.ndim == 0:
        raise ShapeError(
            f"expected y_true and y_pred of the same shape (n,) or (n, n_outputs), got "
            f"{y.shape} and {yhat.shape}"
        )
    _finite(y, "y_true")
    _finite(yhat, "y_pred")
    err = np.linalg.norm(y - yhat, axis=axis)
    spread = np.linalg.norm(y - y.mean(axis=axis, keepdims=True), axis=axis)
    scale = np.linalg.norm(y, axis=axis)
    constant = spread <= 1e-12 * scale
    if np.any(constant):
        raise ValueError(
            f"y_true is constant along axis {axis} in channel(s) "
            f"{np.argwhere(np.atleast_1d(constant)).ravel().tolist()}; the fit is undefined "
            "(excite that output or leave it out)"
        )
    return _scalar_or_array(100.0 * (1.0 - err / spread))


def closure_offset_m(start_xy: np.ndarray, end_xy: np.ndarray) -> float | np.ndarray:
    """Distance between a start point and a stop point.

    Parameters
    ----------
    start_xy, end_xy : array_like, shape (..., 2)
        Positions ``(x, y)`` [m]; extra trailing pose components are not
        accepted.

    Returns
    -------
    float or ndarray, shape (...)
        Euclidean distance [m].

    Raises
    ------
    ShapeError
        If the shapes are not ``(..., 2)`` or do not broadcast.
    NonFiniteError
        If an input is NaN or infinite (a ``ValueError``).

    Notes
    -----
    The paper's evaluation (Table II): the robot drives a closed route on its
    own estimate and stops where it believes it started; the error is the
    distance between the true start and stop points.

    Examples
    --------
    >>> round(closure_offset_m(np.array([0.0, 0.0]), np.array([0.3, 0.4])), 12)
    0.5
    """
    start = _finite(np.asarray(start_xy, dtype=float), "start_xy")
    end = _finite(np.asarray(end_xy, dtype=float), "end_xy")
    if start.shape[-1:] != (2,) or end.shape[-1:] != (2,):
        raise ShapeError(
            f"expected start_xy and end_xy of shape (..., 2), got {start.shape} and {end.shape}"
        )
    try:
        diff = end - start
    except ValueError:
        raise ShapeError(
            f"start_xy {start.shape} and end_xy {end.shape} do not broadcast"
        ) from None
    return _scalar_or_array(np.hypot(diff[..., 0], diff[..., 1]))


def closure_error(poses: np.ndarray) -> float | np.ndarray:
    """Closure offset of a trajectory: distance from its first to its last position.

    Parameters
    ----------
    poses : array_like, shape (..., n, 2) or (..., n, 3)
        The *true* trajectory of a closed route [m, m(, rad)].

    Returns
    -------
    float or ndarray, shape (...)
        ``|p[-1] - p[0]|`` [m] (see :func:`closure_offset_m`).

    Raises
    ------
    ShapeError
        If ``poses`` is not ``(..., n, 2|3)`` with ``n >= 1``.

    Examples
    --------
    >>> round(closure_error(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.1, 3.1]])), 12)
    0.1
    """
    p = _positions(poses, "poses")
    return closure_offset_m(p[..., 0, :], p[..., -1, :])


def _positions(poses: np.ndarray, name: str) -> np.ndarray:
    p = np.asarray(poses, dtype=float)
    if p.ndim < 2 or p.shape[-1] not in (2, 3) or p.shape[-2] < 1:
        raise ShapeError(f"expected {name} of shape (..., n, 2) or (..., n, 3), got {p.shape}")
    return _finite(p, name)[..., :2]


def _pair(
    true_poses: np.ndarray, est_poses: np.ndarray, *, headings: bool
) -> tuple[np.ndarray, ...]:
    t = np.asarray(true_poses, dtype=float)
    e = np.asarray(est_poses, dtype=float)
    widths = (3,) if headings else (2, 3)
    if t.shape != e.shape or t.ndim < 2 or t.shape[-1] not in widths or t.shape[-2] < 1:
        want = "(..., n, 3)" if headings else "(..., n, 2) or (..., n, 3)"
        raise ShapeError(
            f"expected true_poses and est_poses of the same shape {want}, got {t.shape} and "
            f"{e.shape}"
        )
    return _finite(t, "true_poses"), _finite(e, "est_poses")


@dataclass(frozen=True)
class TrajectoryError:
    """Absolute trajectory error statistics (positions only).

    Attributes
    ----------
    rmse_m, mean_m, median_m, max_m : float or ndarray, shape (...)
        Statistics of the per-sample position error norms [m].
    rotation_rad : float or ndarray
        Rotation applied to the estimate by the alignment (0 without it) [rad].
    translation_m : ndarray, shape (..., 2)
        Translation applied after the rotation (zeros without alignment) [m].
    """

    rmse_m: float | np.ndarray
    mean_m: float | np.ndarray
    median_m: float | np.ndarray
    max_m: float | np.ndarray
    rotation_rad: float | np.ndarray
    translation_m: np.ndarray


def ate_stats(
    true_poses: np.ndarray, est_poses: np.ndarray, *, align: bool = False
) -> TrajectoryError:
    """Absolute trajectory error with its statistics and the alignment used.

    Parameters
    ----------
    true_poses, est_poses : array_like, shape (..., n, 2) or (..., n, 3)
        Ground-truth and estimated trajectories at the same instants [m (, rad)].
    align : bool
        If true, first move the estimate by the rigid SE(2) motion (rotation
        and translation, no scale) that best fits it to the truth in the
        least-squares sense; needs ``n >= 2``.

    Returns
    -------
    TrajectoryError

    Raises
    ------
    ShapeError
        If the shapes differ or are not ``(..., n, 2|3)``, or ``align`` with ``n < 2``.
    NonFiniteError
        If an input is NaN or infinite (a ``ValueError``).

    Notes
    -----
    ATE after Sturm et al. (2012): ``F_i = Q_i^-1 S P_i``, RMSE of the
    translational parts. The alignment ``S`` is Umeyama's (1991) closed form
    without scale; in 2-D it reduces to the rotation angle
    ``atan2(sum(e_c x q_c), sum(e_c . q_c))`` of the centred point sets and
    the translation between their centroids.

    References
    ----------
    J. Sturm et al., "A benchmark for the evaluation of RGB-D SLAM systems",
    IROS 2012, pp. 573-580, eq. 4-5 (ATE).
    S. Umeyama, "Least-squares estimation of transformation parameters
    between two point patterns", IEEE TPAMI 13(4), 1991, eq. 40-42.

    Examples
    --------
    >>> truth = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    >>> round(ate_stats(truth, truth + [0.3, -0.4]).rmse_m, 12)
    0.5
    """
    t, e = _pair(true_poses, est_poses, headings=False)
    q, p = t[..., :2], e[..., :2]
    batch = q.shape[:-2]
    angle = np.zeros(batch)
    trans = np.zeros((*batch, 2))
    if align:
        if q.shape[-2] < 2:
            raise ShapeError(f"align=True needs at least 2 samples per trajectory, got {q.shape}")
        q_mean = q.mean(axis=-2)
        p_mean = p.mean(axis=-2)
        qc = q - q_mean[..., None, :]
        pc = p - p_mean[..., None, :]
        # Umeyama 1991 eq. 40-42 for 2-D rotations: maximise tr(R^T Sigma)
        cross = np.sum(pc[..., 0] * qc[..., 1] - pc[..., 1] * qc[..., 0], axis=-1)
        dot = np.sum(pc[..., 0] * qc[..., 0] + pc[..., 1] * qc[..., 1], axis=-1)
        angle = np.arctan2(cross, dot)
        c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
        rot_p_mean = np.stack(
            [
                c[..., 0] * p_mean[..., 0] - s[..., 0] * p_mean[..., 1],
                s[..., 0] * p_mean[..., 0] + c[..., 0] * p_mean[..., 1],
            ],
            axis=-1,
        )
        trans = q_mean - rot_p_mean
        p = np.stack([c * p[..., 0] - s * p[..., 1], s * p[..., 0] + c * p[..., 1]], axis=-1)
        p = p + trans[..., None, :]
    err = np.hypot(q[..., 0] - p[..., 0], q[..., 1] - p[..., 1])  # Sturm 2012 eq. 4
    return TrajectoryError(
        rmse_m=_scalar_or_array(np.sqrt(np.mean(err * err, axis=-1))),  # Sturm 2012 eq. 5
        mean_m=_scalar_or_array(err.mean(axis=-1)),
        median_m=_scalar_or_array(np.median(err, axis=-1)),
        max_m=_scalar_or_array(err.max(axis=-1)),
        rotation_rad=_scalar_or_array(angle),
        translation_m=trans,
    )


def ate(
    true_poses: np.ndarray, est_poses: np.ndarray, *, align: bool = False
) -> float | np.ndarray:
    """Absolute trajectory error: RMSE of the position errors [m].

    Parameters
    ----------
    true_poses, est_poses : array_like, shape (..., n, 2) or (..., n, 3)
        Ground-truth and estimated trajectories at the same instants.
    align : bool
        Rigidly align the estimate to the truth first (SE(2), no scale).

    Returns
    -------
    float or ndarray, shape (...)
        ``ate_stats(...).rmse_m`` [m].

    Raises
    ------
    ShapeError, NonFiniteError
        As :func:`ate_stats`.

    Notes
    -----
    Sturm et al. 2012, eq. 5; alignment after Umeyama 1991 (see :func:`ate_stats`).

    Examples
    --------
    A rotated and shifted copy has no error once aligned:

    >>> truth = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]])
    >>> moved = truth @ np.array([[0.0, 1.0], [-1.0, 0.0]]) + [5.0, 1.0]
    >>> round(ate(truth, moved, align=True), 12) + 0.0
    0.0
    """
    return ate_stats(true_poses, est_poses, align=align).rmse_m


@dataclass(frozen=True)
class RelativePoseError:
    """Relative pose error over a fixed step.

    Attributes
    ----------
    trans_rmse_m : float or ndarray, shape (...)
        RMSE of the translational parts of the error motions [m].
    rot_rmse_rad : float or ndarray, shape (...)
        RMSE of their rotation angles, wrapped into (-pi, pi] [rad].
    n_pairs : int
        Number of motions compared, ``n - delta``.
    """

    trans_rmse_m: float | np.ndarray
    rot_rmse_rad: float | np.ndarray
    n_pairs: int


def _relative_motion(poses: np.ndarray, delta: int) -> tuple[np.ndarray, np.ndarray]:
    """Relative SE(2) motions ``P_i^-1 P_{i+delta}``: translation (..., m, 2), angle (..., m)."""
    d = poses[..., delta:, :] - poses[..., :-delta, :]
    th = poses[..., :-delta, 2]
    c, s = np.cos(th), np.sin(th)
    return np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], axis=-1), d[
        ..., 2
    ]


def rpe(true_poses: np.ndarray, est_poses: np.ndarray, *, delta: int) -> RelativePoseError:
    """Relative pose error (drift) over a fixed number of samples.

    Parameters
    ----------
    true_poses, est_poses : array_like, shape (..., n, 3)
        Ground-truth and estimated poses ``(x [m], y [m], theta [rad])``.
    delta : int
        Step between the compared poses [samples], ``1 <= delta < n``.

    Returns
    -------
    RelativePoseError

    Raises
    ------
    ShapeError
        If the shapes differ or are not ``(..., n, 3)``.
    NonFiniteError
        If an input is NaN or infinite (a ``ValueError``).
    ValueError
        If ``delta`` is out of range.

    Notes
    -----
    ``E_i = (Q_i^-1 Q_{i+delta})^-1 (P_i^-1 P_{i+delta})`` (Sturm et al. 2012,
    eq. 1), RMSE of ``trans(E_i)`` over ``i`` (eq. 2) and of ``angle(E_i)``.
    RPE is independent of any global alignment.

    References
    ----------
    J. Sturm et al., IROS 2012, pp. 573-580, eq. 1-2 (RPE).

    Examples
    --------
    An estimate that turns 0.1 rad too far per step:

    >>> truth = np.column_stack([np.arange(4.0), np.zeros(4), np.zeros(4)])
    >>> est = truth + np.column_stack([np.zeros(4), np.zeros(4), 0.1 * np.arange(4)])
    >>> err = rpe(truth, est, delta=1)
    >>> round(err.rot_rmse_rad, 12), err.n_pairs
    (0.1, 3)
    """
    q, p = _pair(true_poses, est_poses, headings=True)
    n = q.shape[-2]
    if isinstance(delta, bool) or not isinstance(delta, (int, np.integer)) or not 1 <= delta < n:
        raise ValueError(f"delta must be an integer with 1 <= delta < n = {n}, got {delta!r}")
    dq, dq_th = _relative_motion(q, int(delta))
    dp, dp_th = _relative_motion(p, int(delta))
    # Sturm 2012 eq. 1: E = dQ^-1 dP
    c, s = np.cos(dq_th), np.sin(dq_th)
    diff = dp - dq
    ex = c * diff[..., 0] + s * diff[..., 1]
    ey = -s * diff[..., 0] + c * diff[..., 1]
    e_th = wrap_angle(dp_th - dq_th)
    return RelativePoseError(
        trans_rmse_m=_scalar_or_array(np.sqrt(np.mean(ex * ex + ey * ey, axis=-1))),  # eq. 2
        rot_rmse_rad=_scalar_or_array(np.sqrt(np.mean(e_th * e_th, axis=-1))),
        n_pairs=n - int(delta),
    )
