"""Offline calibration of the odometry intrinsics against a pose reference.

Encoder counts plus a reference trajectory (motion capture, landmark sightings run
through a filter or smoother, another odometry such as a scan matcher) give both
wheels' travel per tick, the wheel base and, where the reference is a sensor on the
robot, that sensor's pose in the robot frame. The method is Censi et al.'s (2013):

1. The reference's rotation over each interval is linear in the tick increments,
   ``dtheta_k = J21 dn_L,k + J22 dn_R,k`` (sec. V-A, the first step of the closed
   form): ordinary least squares gives ``J21 = -k_L / b`` and ``J22 = k_R / b``.
2. With ``J21, J22`` known, the robot's translation over an interval is ``b a_k``
   with ``a_k`` computed from the counts, and the sensor equation
   ``l (+) s_k = o_k (+) l`` is linear in ``phi = (b, l_x, l_y, cos l_th, sin l_th)``
   under the constraint ``phi_4^2 + phi_5^2 = 1`` (sec. V-B, the constrained
   quadratic problem). The linear unknowns are eliminated and the constrained pair
   is the eigenvector of the smallest eigenvalue of a 2x2 matrix; this is the
   minimiser Censi et al. find with a Lagrange multiplier.
3. A nonlinear refinement of all parameters over the intervals' full residual
   (translation and rotation of the sensor's displacement, weighted by the
   reference's noise) with :func:`scipy.optimize.least_squares`; the covariance is
   ``s^2 (J^T J)^-1`` at the optimum, ``s^2`` the reduced chi-square.

The reference's displacements over neighbouring intervals share a pose sample, so
their errors correlate; the covariance treats them as independent and is an
approximation (of the right order, not exact).

References
----------
The paper: ``docs/architecture.md``, "The paper".
A. Censi, A. Franchi, L. Marchionni, G. Oriolo, "Simultaneous calibration of odometry
and sensor parameters for mobile robots", IEEE T-RO 29(2):475-492, 2013, sec. V.
J. Borenstein, L. Feng, "Measurement and correction of systematic odometry errors in
mobile robots", IEEE T-RA 12(6), 1996 (UMBmark; type A and type B errors).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.optimize import least_squares

from lti_motion.exceptions import PoseReferenceError, UnidentifiableError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import wrap_angle
from lti_motion.recordings.ticks import tick_deltas, unfold_commanded_direction

__all__ = ["IdentifiabilityReport", "IntrinsicsCalibration", "calibrate_intrinsics"]

_log = logging.getLogger(__name__)

#: The report looks at the reference in windows of this length [s]: a window counts as
#: a turn above _TURN_RAD [rad], as a straight run below _STRAIGHT_RAD [rad] over at
#: least _STRAIGHT_M [m].
_WINDOW_S = 1.0
_TURN_RAD = 0.1
_STRAIGHT_RAD = 0.03
_STRAIGHT_M = 0.05
#: Above this condition number the rotation cannot separate the two wheels.
_MAX_CONDITION = 1e3


@dataclass(frozen=True)
class IdentifiabilityReport:
    """What the calibration drive showed, and what it could not determine.

    Attributes
    ----------
    turns_left, turns_right : int
        1 s windows of the reference turning counter-clockwise / clockwise by more
        than 0.1 rad.
    straight_runs : int
        1 s windows turning less than 0.03 rad while travelling at least 0.05 m.
    rotation_condition : float
        Condition number of the rotation step's design matrix (tick increments,
        columns scaled to unit norm); large means the wheels are not separated.
    undetermined : tuple of str
        Plain-language notes on what the motion left weakly determined.
    """

    turns_left: int
    turns_right: int
    straight_runs: int
    rotation_condition: float
    undetermined: tuple[str, ...]


@dataclass(frozen=True)
class IntrinsicsCalibration:
    """Result of :func:`calibrate_intrinsics`.

    Attributes
    ----------
    intrinsics : OdometryIntrinsics
        The refined estimate.
    closed_form : OdometryIntrinsics
        Censi et al.'s closed-form estimate the refinement started from.
    sensor_pose : ndarray, shape (3,)
        Pose of the reference's frame in the robot frame ``(x [m], y [m], theta [rad])``
        (zeros when not estimated).
    covariance : ndarray, shape (p, p)
        Covariance of ``(k_L [m/tick], k_R [m/tick], b [m])`` and, when estimated,
        ``(l_x [m], l_y [m], l_theta [rad])``.
    std : ndarray, shape (p,)
        Square roots of the covariance's diagonal, same order and units.
    residual_rms : tuple of 2 float
        RMS of the intervals' translation [m] and rotation [rad] residuals.
    n_intervals : int
        Reference intervals used.
    report : IdentifiabilityReport
    """

    intrinsics: OdometryIntrinsics
    closed_form: OdometryIntrinsics
    sensor_pose: np.ndarray
    covariance: np.ndarray
    std: np.ndarray
    residual_rms: tuple[float, float]
    n_intervals: int
    report: IdentifiabilityReport


@dataclass(frozen=True)
class _Intervals:
    """Encoder sub-steps grouped into reference intervals."""

    dn: np.ndarray            # (m, 2) tick increments of the sub-steps
    seg: np.ndarray           # (m,) interval index of each sub-step
    starts: np.ndarray        # (K,) first sub-step of each interval
    ref_motion: np.ndarray    # (K, 3) reference displacement in its own start frame
    dn_total: np.ndarray      # (K, 2) tick increments per interval


def _check_inputs(t_s, ticks, ref_t_s, ref_poses):
    t = np.asarray(t_s, float)
    n = np.asarray(ticks)
    rt = np.asarray(ref_t_s, float)
    rp = np.asarray(ref_poses, float)
    if n.ndim != 2 or n.shape[1] != 2 or t.shape != (n.shape[0],):
        raise PoseReferenceError(f"expected encoder ticks of shape (n, 2) with n timestamps, "
                                 f"got ticks {n.shape} and times {t.shape}")
    if rp.ndim != 2 or rp.shape[1] != 3 or rt.shape != (rp.shape[0],):
        raise PoseReferenceError(f"expected reference poses of shape (m, 3) (x, y, theta) with "
                                 f"m timestamps, got poses {rp.shape} and times {rt.shape}")
    if not (np.all(np.isfinite(rp)) and np.all(np.isfinite(rt)) and np.all(np.isfinite(t))):
        bad = np.flatnonzero(~np.all(np.isfinite(rp), axis=1))
        where = f" (first bad pose at sample {bad[0]})" if bad.size else ""
        raise PoseReferenceError(f"the reference holds NaN or infinite poses or times{where}; "
                                 "drop those samples first")
    if np.any(np.diff(t) <= 0) or np.any(np.diff(rt) <= 0):
        raise PoseReferenceError("encoder and reference timestamps must both increase")
    inside = (rt >= t[0]) & (rt <= t[-1])
    if inside.sum() < 3:
        raise PoseReferenceError(
            f"the reference ({rt[0]:.3f}..{rt[-1]:.3f} s) and the encoder record "
            f"({t[0]:.3f}..{t[-1]:.3f} s) overlap in {int(inside.sum())} reference samples; "
            "need at least 3: are both on the same clock?")
    return t, n.astype(np.int64), rt[inside], rp[inside]


def _intervals_from(t, counts, rt, rp, knots: np.ndarray) -> _Intervals:
    """Intervals between consecutive reference samples ``knots`` and the encoder
    sub-steps inside them (counts interpolated at the reference times)."""
    tk = rt[knots]
    grid = np.union1d(t[(t > tk[0]) & (t < tk[-1])], tk)
    cum = np.stack([np.interp(grid, t, counts[:, i]) for i in range(2)], axis=1)
    dn = np.diff(cum, axis=0)
    seg = np.searchsorted(tk, grid[:-1], side="right") - 1
    starts = np.searchsorted(seg, np.arange(len(tk) - 1))
    p0, p1 = rp[knots[:-1]], rp[knots[1:]]
    c, s = np.cos(p0[:, 2]), np.sin(p0[:, 2])
    d = p1[:, :2] - p0[:, :2]
    heading = np.unwrap(rp[:, 2])
    motion = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1],
                       heading[knots[1:]] - heading[knots[:-1]]], axis=1)
    return _Intervals(dn=dn, seg=seg, starts=starts, ref_motion=motion,
                      dn_total=np.add.reduceat(dn, starts, axis=0))


def _intervals(t, counts, rt, rp, interval_s: float, *, overlap: int) -> _Intervals:
    """Intervals of about ``interval_s``, starting ``overlap`` times per interval (each
    reference sample then enters several intervals, so all samples are used)."""
    stride = max(1, round(interval_s / float(np.median(np.diff(rt)))))
    stride = min(stride, len(rt) - 1)
    offsets = np.unique(np.linspace(0, stride, max(1, overlap), endpoint=False).astype(int))
    parts = [_intervals_from(t, counts, rt, rp, np.arange(o, len(rt), stride))
             for o in offsets if len(rt) - o > stride]
    shift = np.cumsum([0] + [len(p.dn) for p in parts[:-1]])
    seg_shift = np.cumsum([0] + [len(p.starts) for p in parts[:-1]])
    return _Intervals(
        dn=np.concatenate([p.dn for p in parts]),
        seg=np.concatenate([p.seg + k for p, k in zip(parts, seg_shift, strict=True)]),
        starts=np.concatenate([p.starts + k for p, k in zip(parts, shift, strict=True)]),
        ref_motion=np.concatenate([p.ref_motion for p in parts]),
        dn_total=np.concatenate([p.dn_total for p in parts]))


def _odometry_motion(iv: _Intervals, kl: float, kr: float, b: float) -> np.ndarray:
    """Robot displacement ``(x, y, theta)`` over each interval in its start frame, the
    sub-steps integrated with the chord form of paper eq. 11."""
    ds = 0.5 * (kl * iv.dn[:, 0] + kr * iv.dn[:, 1])
    dth = (kr * iv.dn[:, 1] - kl * iv.dn[:, 0]) / b
    cum = np.cumsum(dth)
    before = cum - dth
    theta0 = (before - np.concatenate([[0.0], cum])[iv.starts][iv.seg])
    mid = theta0 + 0.5 * dth
    chord = ds * np.sinc(0.5 * dth / np.pi)
    xy = np.stack([chord * np.cos(mid), chord * np.sin(mid)], axis=1)
    out = np.empty((len(iv.starts), 3))
    out[:, :2] = np.add.reduceat(xy, iv.starts, axis=0)
    out[:, 2] = np.add.reduceat(dth, iv.starts)
    return out


def _sensor_motion(o: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """``l^-1 (+) o (+) l``: the sensor's displacement for robot displacements ``o``."""
    lx, ly, lt = pose
    c, s = np.cos(o[:, 2]), np.sin(o[:, 2])
    # o (+) l, then l^-1 (+) that
    px = o[:, 0] + c * lx - s * ly - lx
    py = o[:, 1] + s * lx + c * ly - ly
    cl, sl = np.cos(lt), np.sin(lt)
    return np.stack([cl * px + sl * py, -sl * px + cl * py, o[:, 2]], axis=1)


def _report(iv: _Intervals, rt: np.ndarray, rp: np.ndarray) -> IdentifiabilityReport:
    """Turns and straight runs counted over 1 s windows of the reference (independent of
    the interval length), and the rotation step's condition number."""
    step = max(1, round(_WINDOW_S / float(np.median(np.diff(rt)))))
    rot = np.diff(np.unwrap(rp[:, 2])[::step])
    dist = np.hypot(*np.diff(rp[::step, :2], axis=0).T)
    left, right = int(np.sum(rot > _TURN_RAD)), int(np.sum(rot < -_TURN_RAD))
    straight = int(np.sum((np.abs(rot) < _STRAIGHT_RAD) & (dist >= _STRAIGHT_M)))
    x = iv.dn_total / np.maximum(np.linalg.norm(iv.dn_total, axis=0), 1e-12)
    cond = float(np.linalg.cond(x)) if np.any(iv.dn_total) else float("inf")
    notes = []
    if left + right == 0:
        notes.append("no turns: the wheel base and the left/right scale ratio")
    elif min(left, right) == 0:
        notes.append(f"turns {'counter-clockwise' if left else 'clockwise'} only: the scale "
                     "ratio rests on the straight runs")
    if straight == 0:
        notes.append("no straight runs: the left/right scale ratio rests on the turns alone")
    if cond > _MAX_CONDITION:
        notes.append("the two wheels always moved in the same proportion, so their scales "
                     "cannot be told apart")
    return IdentifiabilityReport(left, right, straight, cond, tuple(notes))


def _closed_form(iv: _Intervals, *, sensor_pose: bool) -> tuple[OdometryIntrinsics, np.ndarray]:
    """Censi et al. 2013 sec. V-A (rotation) and V-B (translation, constrained LS)."""
    # V-A: dtheta_k = J21 dn_L + J22 dn_R, linear least squares
    (j21, j22), *_ = np.linalg.lstsq(iv.dn_total, iv.ref_motion[:, 2], rcond=None)
    # V-B: robot translation = b a_k, with a_k the odometry of (k_L, k_R, b) = (-J21, J22, 1)
    if not (j21 < 0 < j22):
        raise PoseReferenceError(
            "the reference's rotation does not follow the wheel counts (a wheel would turn "
            f"the robot the wrong way: J21={j21:.3g}, J22={j22:.3g}); is it this robot's "
            "trajectory, and are left and right the right way round?")
    a = _odometry_motion(iv, -j21, j22, 1.0)
    s = iv.ref_motion
    c, sn = np.cos(a[:, 2]), np.sin(a[:, 2])
    k = len(a)
    lin = np.zeros((2 * k, 3 if sensor_pose else 1))          # unknowns b (, l_x, l_y)
    lin[0::2, 0], lin[1::2, 0] = -a[:, 0], -a[:, 1]
    if sensor_pose:
        lin[0::2, 1], lin[0::2, 2] = 1.0 - c, sn               # (I - R(o_theta)) l_t
        lin[1::2, 1], lin[1::2, 2] = -sn, 1.0 - c
    rot = np.zeros((2 * k, 2))                                  # R(l_theta) s_t
    rot[0::2, 0], rot[0::2, 1] = s[:, 0], -s[:, 1]
    rot[1::2, 0], rot[1::2, 1] = s[:, 1], s[:, 0]
    if not sensor_pose:
        b = float(np.sum(lin[:, 0] * rot[:, 0]) / -np.sum(lin[:, 0] ** 2))
        pose = np.zeros(3)
    else:
        pinv = np.linalg.pinv(lin)
        resid = rot - lin @ (pinv @ rot)                        # eliminate (b, l_x, l_y)
        _, vecs = np.linalg.eigh(resid.T @ resid)
        w = vecs[:, 0]                                          # unit-norm minimiser
        u = -pinv @ rot @ w
        if u[0] < 0:
            w, u = -w, -u
        b, pose = float(u[0]), np.array([u[1], u[2], np.arctan2(w[1], w[0])])
    if not b > 0:
        raise PoseReferenceError("the reference's travel does not follow the wheel counts "
                                 f"(wheel base estimate {b:.3g} m); is it this robot's trajectory?")
    return OdometryIntrinsics(-j21 * b, j22 * b, b), pose


def _residuals(p: np.ndarray, iv: _Intervals, sigma: np.ndarray) -> np.ndarray:
    pose = p[3:] if len(p) == 6 else np.zeros(3)
    pred = _sensor_motion(_odometry_motion(iv, *p[:3]), pose)
    r = pred - iv.ref_motion
    r[:, 2] = wrap_angle(r[:, 2])
    return (r / sigma).ravel()


def _refine(iv: _Intervals, start: OdometryIntrinsics, pose: np.ndarray, *, sensor_pose: bool,
            sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gauss-Newton (trust region) over all parameters; covariance s^2 (J^T J)^-1."""
    p0 = np.array([start.m_per_tick_left, start.m_per_tick_right, start.wheel_base_m,
                   *(pose if sensor_pose else ())])
    scale = np.abs(p0) + np.array([0, 0, 0, 0.01, 0.01, 0.01])[:len(p0)]
    fit = least_squares(_residuals, p0, args=(iv, sigma), x_scale=scale, method="trf",
                        jac="3-point")
    dof = max(fit.fun.size - len(p0), 1)
    s2 = 2.0 * fit.cost / dof
    jtj = fit.jac.T @ fit.jac
    if np.linalg.cond(jtj) > 1e14:
        raise UnidentifiableError("the refinement's normal matrix is singular: the drive does "
                                  "not determine all parameters; add turns both ways and "
                                  "straight runs")
    cov = s2 * np.linalg.inv(jtj)
    r = (fit.fun.reshape(-1, 3) * sigma)
    rms = np.sqrt(np.mean(r ** 2, axis=0))
    return fit.x, cov, np.array([np.hypot(rms[0], rms[1]), rms[2]])


def calibrate_intrinsics(
    t_s: np.ndarray,
    ticks: np.ndarray,
    ref_t_s: np.ndarray,
    ref_poses: np.ndarray,
    *,
    interval_s: float = 6.0,
    overlap: int = 10,
    sensor_pose: bool = True,
    position_std_m: float = 0.005,
    heading_std_rad: float = 0.01,
    encoders: Literal["quadrature", "commanded"] = "quadrature",
) -> IntrinsicsCalibration:
    """Both wheels' scale, the wheel base and the reference sensor's pose from a drive.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Encoder frame times [s], on the reference's clock.
    ticks : ndarray of int, shape (n, 2)
        Raw 16-bit encoder counts ``(left, right)``.
    ref_t_s : ndarray, shape (m,)
        Reference pose times [s].
    ref_poses : ndarray, shape (m, 3)
        Reference poses ``(x [m], y [m], theta [rad])`` of the reference's frame in
        its world frame.
    interval_s : float
        Length of the reference intervals compared with the odometry [s]. Long
        intervals average the reference's noise down (its pose errors do not add up
        over an interval, the travel does); too long ones let the robot's slip in.
    overlap : int
        Interval start points per interval length: ``overlap`` interleaved sets of
        intervals, so every reference sample counts.
    sensor_pose : bool
        Estimate the reference frame's pose on the robot (Censi et al.); ``False``
        when the reference tracks the wheel axle's centre itself.
    position_std_m, heading_std_rad : float
        Noise of one reference pose [m], [rad]: the residuals' weights.
    encoders : {"quadrature", "commanded"}
        As :func:`lti_motion.recordings.body_speeds_from_ticks`.

    Returns
    -------
    IntrinsicsCalibration

    Raises
    ------
    PoseReferenceError
        Wrong shapes, non-finite poses, no time overlap, or a reference whose motion
        does not follow the wheel counts (another robot's trajectory).
    UnidentifiableError
        The drive cannot determine the intrinsics (no turns; the wheels always in the
        same proportion); the message says what to add. Never NaN.

    Notes
    -----
    Censi et al. 2013, sec. V-A and V-B (closed form), then a nonlinear refinement;
    see the module docstring.

    Examples
    --------
    A robot with a 1% larger left wheel, driven straight, turning both ways, then
    straight again; a noise-free reference:

    >>> from lti_motion.kinematics import integrate_poses
    >>> true = OdometryIntrinsics(4.49e-4, 4.4455e-4, 0.236)
    >>> rate = np.array([[400, 400]] * 40 + [[-300, 300]] * 30 + [[300, -300]] * 20
    ...                 + [[500, 400]] * 30, float)          # ticks per step
    >>> dn = np.repeat(rate, 10, axis=0) * 0.01               # 0.01 s steps
    >>> ticks = np.vstack([[0, 0], np.cumsum(dn, axis=0)]).round().astype(int)
    >>> t = np.arange(len(ticks)) * 0.01
    >>> poses = integrate_poses(true.body_motion(np.diff(ticks, axis=0)), 1.0)
    >>> cal = calibrate_intrinsics(t, ticks, t[::10], poses[::10], interval_s=0.5, overlap=2)
    >>> [round(x, 4) for x in (cal.intrinsics.m_per_tick_left / true.m_per_tick_left,
    ...  cal.intrinsics.m_per_tick_right / true.m_per_tick_right,
    ...  cal.intrinsics.wheel_base_m / true.wheel_base_m)]
    [1.0, 1.0, 1.0]
    """
    t, n, rt, rp = _check_inputs(t_s, ticks, ref_t_s, ref_poses)
    d = tick_deltas(n, axis=0)
    if encoders == "commanded":
        d = unfold_commanded_direction(d)
    counts = np.vstack([[0, 0], np.cumsum(d, axis=0)]).astype(float)
    if not np.any(d):
        raise UnidentifiableError("the encoders did not move: nothing to calibrate")
    iv = _intervals(t, counts, rt, rp, interval_s, overlap=overlap)
    report = _report(iv, rt, rp)
    if report.turns_left + report.turns_right == 0:
        raise UnidentifiableError("the reference shows no turns: the wheel base and the "
                                  "left/right scale ratio are not determined; turn the robot "
                                  "(both ways) during the drive")
    if report.rotation_condition > _MAX_CONDITION:
        raise UnidentifiableError(
            f"over intervals of {interval_s:g} s the wheels always moved in one proportion "
            f"(condition {report.rotation_condition:.3g}): add straight runs to the turns or "
            "turns to the straight runs, or give a shorter interval_s if the manoeuvres "
            "alternate faster than that")
    closed, pose = _closed_form(iv, sensor_pose=sensor_pose)
    sigma = np.array([position_std_m, position_std_m, heading_std_rad]) * np.sqrt(2.0)
    p, cov, rms = _refine(iv, closed, pose, sensor_pose=sensor_pose, sigma=sigma)
    if not (np.all(np.isfinite(p)) and np.all(p[:3] > 0)):
        raise UnidentifiableError(f"the refinement left the physical range ({p[:3]}); "
                                  "the drive does not determine the intrinsics")
    if rms[1] > max(10.0 * sigma[2], 0.05):
        raise PoseReferenceError(
            f"the reference turns differ from the wheel counts' by {rms[1]:.3g} rad RMS per "
            "interval after calibration; is it this robot's trajectory, on the same clock?")
    _log.info("intrinsics: %s (closed form %s), residual RMS %.4g m, %.4g rad",
              p[:3], closed.as_dict(), *rms)
    return IntrinsicsCalibration(
        intrinsics=OdometryIntrinsics(*p[:3]), closed_form=closed,
        sensor_pose=np.asarray(p[3:] if sensor_pose else np.zeros(3)),
        covariance=cov, std=np.sqrt(np.diag(cov)), residual_rms=(float(rms[0]), float(rms[1])),
        n_intervals=len(iv.starts), report=report)
