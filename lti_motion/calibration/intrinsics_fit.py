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
   (translation and rotation of the sensor's displacement) with
   :func:`scipy.optimize.least_squares`, in parameters scaled by the closed form's so
   that any count unit gives the same result; the covariance is ``s^2 (J^T J)^-1`` at
   the optimum, ``s^2`` the reduced chi-square.
4. Censi et al.'s outlier rounds (four, 1% each, gated by a robust scale; for a pose
   reference each interval's translation residual against its own noise), the weights
   and the covariance from the kept residuals
   (:mod:`lti_motion.calibration.intrinsics_solver`).

The same solver takes interval samples (:func:`calibrate_intrinsics_intervals`: Censi
et al.'s own data format) and runs localised only at their ends
(:func:`lti_motion.calibration.calibrate_intrinsics_runs`). The drive is judged in the
robot's own terms (:class:`IdentifiabilityReport`) before anything is fitted.

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

import dataclasses
import logging
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from lti_motion.calibration.intrinsics_solver import (
    Intervals,
    closed_form,
    noise_from_residuals,
    refine,
    residuals,
    rotation_step_precision,
    trim,
)
from lti_motion.calibration.odometry_walk import WALK_LENGTHS_S, fit_wheel_walk
from lti_motion.exceptions import CalibrationError, PoseReferenceError, UnidentifiableError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.odometry_errors import OdometryErrors
from lti_motion.recordings.ticks import tick_deltas, unfold_commanded_direction

__all__ = ["IdentifiabilityReport", "IntrinsicsCalibration", "calibrate_intrinsics",
           "calibrate_intrinsics_intervals"]

_log = logging.getLogger(__name__)

#: The report looks at the drive in windows of about this length [s] (a time series) or
#: at the samples themselves (interval samples).
_WINDOW_S = 1.0
#: A window moves when its larger wheel increment is at least this fraction of the
#: recording's typical one (90th percentile over the windows): the robot's own speeds.
_MOVING = 0.1
#: ``|dn_R - dn_L| / (|dn_L| + |dn_R|)``: below _STRAIGHT a straight run, from _TURN a
#: turn (from _IN_PLACE a turn in place, between the two an arc).
_STRAIGHT = 0.05
_TURN = 0.05
_IN_PLACE = 0.8
#: A pose reference resolves rotations of about a degree: a window whose counts turn but
#: whose reference turns less than this [rad] does not count as a turn.
_REFERENCE_TURN_RAD = 0.02
#: Above this condition number the rotation cannot separate the two wheels.
_MAX_CONDITION = 1e3
#: Above this relative standard error of the rotation step's ``J21, J22`` the wheels
#: moved in too nearly one proportion to separate them (measured: 1.5% on Censi's l90,
#: 0.03% on a drive of straight runs and turns; 30-500% on constant arcs).
_MAX_ROTATION_ERROR = 0.05
#: After the fit, residuals above these fractions of the reference's own rotation and of
#: the wheels' travel per interval (medians
#: per interval) mean the reference does not follow the counts.
_MAX_ROTATION_RESIDUAL = 0.5
_MAX_TRANSLATION_RESIDUAL = 0.5
#: A reference fitted without the mount whose translation residual the mount would cut
#: below this fraction is taken as a sensor off the axle.
_MOUNT_GAIN = 0.5
#: Floor of the noise estimated from the residuals [m, m, rad] (a perfect reference).
_NOISE_FLOOR = np.array([1e-7, 1e-7, 1e-8])
_NOISE_FLOOR.flags.writeable = False

_Encoders = Literal["quadrature", "commanded"]


@dataclass(frozen=True)
class IdentifiabilityReport:
    """What the calibration drive showed, and what it could not determine.

    Windows are about 1 s of a time series, or the samples themselves for interval
    samples; each is judged in the robot's own terms: it moves when its larger wheel
    increment is at least a tenth of the recording's typical one (90th percentile),
    and the wheels' imbalance ``|dn_R - dn_L| / (|dn_L| + |dn_R|)`` says whether it runs
    straight (below 0.05), arcs, or turns in place (from 0.8).

    Attributes
    ----------
    turns_left, turns_right : int
        Moving windows whose wheels turn the robot (imbalance from 0.05) and whose
        reference turns counter-clockwise / clockwise by more than 0.02 rad.
    straight_runs : int
        Moving windows of imbalance below 0.05.
    rotation_condition : float
        Condition number of the rotation step's design matrix (tick increments,
        columns scaled to unit norm); large means the wheels are not separated.
    undetermined : tuple of str
        Plain-language notes on what the motion left weakly determined.
    arcs : int
        Turning windows that also travel (imbalance below 0.8).
    windows : int
        Windows judged.
    """

    turns_left: int
    turns_right: int
    straight_runs: int
    rotation_condition: float
    undetermined: tuple[str, ...]
    arcs: int = 0
    windows: int = 0


@dataclass(frozen=True)
class IntrinsicsCalibration:
    """Result of :func:`calibrate_intrinsics` and :func:`calibrate_intrinsics_intervals`.

    Attributes
    ----------
    intrinsics : OdometryIntrinsics
        The refined estimate, on the intervals kept.
    closed_form : OdometryIntrinsics
        Censi et al.'s closed-form estimate on the intervals kept.
    sensor_pose : ndarray, shape (3,)
        Pose of the reference's frame in the robot frame ``(x [m], y [m], theta [rad])``
        (zeros when not estimated).
    covariance : ndarray, shape (p, p)
        Covariance of ``(k_L [m/count], k_R [m/count], b [m])`` and, when estimated,
        ``(l_x [m], l_y [m], l_theta [rad])``, on the intervals kept, with the reference's
        noise estimated from their residuals.
    std : ndarray, shape (p,)
        Square roots of the covariance's diagonal, same order and units.
    residual_rms : tuple of 2 float
        RMS of the kept intervals' translation [m] and rotation [rad] residuals.
    n_intervals : int
        Intervals used (kept).
    report : IdentifiabilityReport
    n_rejected : int
        Intervals rejected as outliers.
    noise : ndarray, shape (3,)
        The reference's noise per interval estimated from the kept residuals
        ``(x [m], y [m], theta [rad])``: the weights of the final fit.
    odometry_errors : OdometryErrors or None
        Encoder odometry's error model measured on the drive (a time series against a
        pose reference: the random walk per metre of wheel travel over intervals of 1-16
        s, :mod:`lti_motion.calibration.odometry_walk`, and the intrinsics' covariance);
        None for interval samples and end-pose runs, which do not measure it.
    """

    intrinsics: OdometryIntrinsics
    closed_form: OdometryIntrinsics
    sensor_pose: np.ndarray
    covariance: np.ndarray
    std: np.ndarray
    residual_rms: tuple[float, float]
    n_intervals: int
    report: IdentifiabilityReport
    n_rejected: int = 0
    noise: np.ndarray | None = None
    odometry_errors: OdometryErrors | None = None


def _check_options(*, interval_s: float, overlap: int, position_std_m: float,
                   heading_std_rad: float, encoders: str, outlier_rounds: int,
                   outlier_fraction: float) -> None:
    """One-line ``ValueError`` naming the argument, its value and what it must be."""
    def positive(name: str, value: float) -> None:
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not (
                math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive finite number, got {value!r}")

    positive("interval_s", interval_s)
    positive("position_std_m", position_std_m)
    positive("heading_std_rad", heading_std_rad)
    for name, value, low in (("overlap", overlap, 1), ("outlier_rounds", outlier_rounds, 0)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise ValueError(f"{name} must be an integer of at least {low}, got {value!r}")
    if encoders not in ("quadrature", "commanded"):
        raise ValueError(f"encoders must be 'quadrature' or 'commanded', got {encoders!r}")
    if isinstance(outlier_fraction, bool) or not (
            isinstance(outlier_fraction, (int, float, np.number))
            and 0.0 < outlier_fraction <= 0.5):
        raise ValueError(f"outlier_fraction must be in (0, 0.5] (0.01: 1% per round), got "
                         f"{outlier_fraction!r}")


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
            "need at least 3: are both on the same clock? (shift the reference's times: "
            "ref_t_s + offset; --reference-offset S; for runs localised only at their ends, "
            "calibrate_intrinsics_runs)")
    if not np.all(np.isfinite(n)):
        raise PoseReferenceError("the encoder counts hold NaN or infinite values; drop those "
                                 "frames first")
    counts = n.astype(float) if np.issubdtype(n.dtype, np.floating) else n.astype(np.int64)
    return t, counts, rt[inside], rp[inside]


def _intervals_from(t, counts, rt, rp, knots: np.ndarray) -> Intervals:
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
    return Intervals(dn=dn, seg=seg, starts=starts, ref_motion=motion,
                     dn_total=np.add.reduceat(dn, starts, axis=0))


def _intervals(t, counts, rt, rp, interval_s: float, *, overlap: int) -> Intervals:
    """Intervals of about ``interval_s``, starting ``overlap`` times per interval (each
    reference sample then enters several intervals, so all samples are used)."""
    stride = max(1, round(interval_s / float(np.median(np.diff(rt)))))
    stride = min(stride, len(rt) - 1)
    offsets = np.unique(np.linspace(0, stride, max(1, overlap), endpoint=False).astype(int))
    parts = [_intervals_from(t, counts, rt, rp, np.arange(o, len(rt), stride))
             for o in offsets if len(rt) - o > stride]
    shift = np.cumsum([0] + [len(p.dn) for p in parts[:-1]])
    seg_shift = np.cumsum([0] + [len(p.starts) for p in parts[:-1]])
    return Intervals(
        dn=np.concatenate([p.dn for p in parts]),
        seg=np.concatenate([p.seg + k for p, k in zip(parts, seg_shift, strict=True)]),
        starts=np.concatenate([p.starts + k for p, k in zip(parts, shift, strict=True)]),
        ref_motion=np.concatenate([p.ref_motion for p in parts]),
        dn_total=np.concatenate([p.dn_total for p in parts]))


def _causes(*, sensor_pose: bool, encoders: str | None) -> str:
    """The likely causes of a reference that does not follow the counts, most likely
    first, each with the argument and the command-line option that fixes it."""
    causes = []
    if not sensor_pose:
        causes.append("if the reference tracks a sensor off the axle centre, estimate its "
                      "mount (sensor_pose=True; --sensor-pose)")
    if encoders == "quadrature":
        causes.append("a Roomba / Create 2 counts in the commanded direction "
                      "(encoders='commanded'; --encoders commanded)")
    elif encoders == "commanded":
        causes.append("encoders that know their direction are quadrature "
                      "(encoders='quadrature'; --encoders quadrature)")
    causes += ["a clock offset between the counts and the reference (shift the reference's "
               "times onto the counts' clock: ref_t_s + offset; --reference-offset S)",
               "left and right wheel counts swapped",
               "or the reference is not this robot's trajectory"]
    return "likely causes: " + "; ".join(causes)


def _imbalance(dn: np.ndarray) -> np.ndarray:
    """``|dn_R - dn_L| / (|dn_L| + |dn_R|)`` over the last axis: 0 straight, 1 in place."""
    return np.abs(dn[..., 1] - dn[..., 0]) / np.maximum(np.abs(dn).sum(axis=-1), 1e-300)


def _report(dn_w: np.ndarray, rot_w: np.ndarray, iv: Intervals,
            halves: np.ndarray | None = None) -> IdentifiabilityReport:
    """Turns, arcs and straight runs over the windows ``dn_w`` (count increments, (W, 2))
    with the reference's rotation ``rot_w`` [rad], judged against the recording's own
    wheel increments; and the rotation step's condition number. ``halves`` (W, 2, 2),
    the windows' two halves: a straight run is balanced in both (a left arc followed by
    a right one balances over the window but is no straight run)."""
    mag = np.max(np.abs(dn_w), axis=1)
    typical = float(np.quantile(mag, 0.9)) if len(mag) else 0.0
    moving = (mag >= _MOVING * typical) & (mag > 0)
    imbalance = _imbalance(dn_w)
    turning = moving & (imbalance >= _TURN) & (np.abs(rot_w) > _REFERENCE_TURN_RAD)
    left, right = int(np.sum(turning & (rot_w > 0))), int(np.sum(turning & (rot_w < 0)))
    balanced = imbalance if halves is None else np.max(_imbalance(halves), axis=1)
    straight = int(np.sum(moving & (balanced < _STRAIGHT)))
    arcs = int(np.sum(turning & (imbalance < _IN_PLACE)))
    x = iv.dn_total / np.maximum(np.linalg.norm(iv.dn_total, axis=0), 1e-300)
    cond = float(np.linalg.cond(x)) if np.all(np.any(iv.dn_total, axis=0)) else float("inf")
    notes = []
    if left + right == 0:
        notes.append("no turns: the wheel base and the left/right scale ratio")
    elif min(left, right) == 0:
        notes.append(f"turns {'counter-clockwise' if left else 'clockwise'} only: the scale "
                     "ratio rests on the straight runs")
    if straight == 0 and arcs == 0 and left + right > 0:
        notes.append("turns in place only: the wheel base rests on the turns' small "
                     "imbalances (the little the robot travelled)")
    elif straight == 0:
        notes.append("no straight runs: the left/right scale ratio rests on the turns alone")
    if cond > _MAX_CONDITION:
        notes.append("the two wheels always moved in the same proportion, so their scales "
                     "cannot be told apart")
    return IdentifiabilityReport(left, right, straight, cond, tuple(notes), arcs=arcs,
                                 windows=len(dn_w))


def _check_identifiable(report: IdentifiabilityReport, dn_w: np.ndarray, iv: Intervals, *,
                        interval_hint: str) -> None:
    """The documented ``UnidentifiableError`` (or, for a reference that does not turn
    with the counts, ``PoseReferenceError``) before anything is fitted."""
    mag = np.max(np.abs(dn_w), axis=1)
    moving = mag >= _MOVING * float(np.quantile(mag, 0.9))
    imbalance = _imbalance(dn_w)
    counts_turn = int(np.sum(moving & (imbalance >= _TURN)))
    if counts_turn == 0:
        raise UnidentifiableError("the drive has no turns (the wheels always moved alike): "
                                  "the wheel base and the left/right scale ratio are not "
                                  "determined; turn the robot (both ways) during the drive")
    if report.turns_left + report.turns_right == 0:
        raise PoseReferenceError(
            f"the reference shows no turns while the wheel counts turn the robot in "
            f"{counts_turn} windows; {_causes(sensor_pose=True, encoders=None)}")
    precision = rotation_step_precision(iv)
    if report.rotation_condition > _MAX_CONDITION or not precision < _MAX_ROTATION_ERROR:
        raise UnidentifiableError(
            f"{interval_hint}the wheels always moved in one proportion "
            f"(condition {report.rotation_condition:.3g}, the wheels' turn rates "
            f"{precision:.0%} uncertain): add straight runs to the turns or "
            "turns to the straight runs" + (
                ", or give a shorter interval_s if the manoeuvres alternate faster than that"
                if interval_hint else ""))


def _check_mount(iv: Intervals, rms_xy: float) -> None:
    """A reference fitted as the axle centre's that a sensor off the axle explains far
    better (the closed form with the mount estimated leaves under half the translation
    residual): the mount is the likely cause, named with its option."""
    n = len(iv.starts)
    if n < 10:                       # too few intervals to tell a mount from noise
        return
    try:
        k, pose = closed_form(iv, sensor_pose=True, causes="")
    except CalibrationError:
        return
    r = residuals(iv, np.array([*k.as_dict().values(), *pose]))
    # per degree of freedom: 2n translation equations, 2 more unknowns with the mount
    free = float(np.sqrt(np.sum(r[:, :2] ** 2) / (2 * n - 3)))
    if free < _MOUNT_GAIN * rms_xy * np.sqrt(2 * n / (2 * n - 1)):
        raise PoseReferenceError(
            f"the reference moves as a sensor off the axle centre would: its travel differs "
            f"from the wheel counts' by {rms_xy:.3g} m RMS per interval, {free:.3g} m with "
            f"a mount of x {pose[0]:.3f} m, y {pose[1]:.3f} m, {np.rad2deg(pose[2]):.1f} deg "
            "estimated; estimate the mount (sensor_pose=True; --sensor-pose)")


def _solve(iv: Intervals, report: IdentifiabilityReport, *, sensor_pose: bool,
           sigma0: np.ndarray, rounds: int, fraction: float, causes: str,
           pose_reference: bool, mean_scale: float | None = None) -> IntrinsicsCalibration:
    """Closed form, refinement and Censi et al.'s outlier rounds
    (:mod:`lti_motion.calibration.intrinsics_solver`); ``pose_reference``: the intervals'
    motions are differences of poses (a trajectory, runs' ends), whose start heading's
    error grows with the displacement (:func:`~lti_motion.calibration.intrinsics_solver.
    trim`), not a sensor's own motions (interval samples)."""
    keep = np.ones(len(iv.starts), bool)
    sigma = sigma0
    p = None
    for round_ in range(rounds + 1):
        sub = iv.subset(keep)
        closed, pose = closed_form(sub, sensor_pose=sensor_pose, causes=causes,
                                   mean_scale=mean_scale)
        if p is None:                          # later rounds start where the last ended
            p = np.array([closed.m_per_tick_left, closed.m_per_tick_right,
                          closed.wheel_base_m, *(pose if sensor_pose else ())])
        p, cov = refine(sub, p, sigma, mean_scale=mean_scale)
        r = residuals(sub, p)
        sigma = noise_from_residuals(r, _NOISE_FLOOR)
        if round_ < rounds:
            kept = np.flatnonzero(keep)
            travel = sub.ref_motion[:, :2] if pose_reference else None
            keep[kept[~trim(r, fraction, travel=travel)]] = False
    p, cov = refine(sub, p, sigma, mean_scale=mean_scale)   # weights from the residuals
    r = residuals(sub, p)
    if not (np.all(np.isfinite(p)) and np.all(p[:3] > 0)):
        raise UnidentifiableError(f"the refinement left the physical range ({p[:3]}); "
                                  "the drive does not determine the intrinsics")
    rms_xy = float(np.sqrt(np.mean(np.sum(r[:, :2] ** 2, axis=1))))
    rms_th = float(np.sqrt(np.mean(r[:, 2] ** 2)))
    # medians: a few outliers left (outlier_rounds=0) must not trip the check
    med_th, ref_th = np.median(np.abs(r[:, 2])), np.median(np.abs(sub.ref_motion[:, 2]))
    med_xy = np.median(np.hypot(r[:, 0], r[:, 1]))
    # the wheels' travel (a run that returns to its start still travelled)
    wheels = 0.5 * (np.abs(p[0] * sub.dn[:, 0]) + np.abs(p[1] * sub.dn[:, 1]))
    ref_xy = np.median(np.add.reduceat(wheels, sub.starts))
    if not sensor_pose and mean_scale is None:
        _check_mount(sub, rms_xy)
    if med_th > _MAX_ROTATION_RESIDUAL * ref_th:
        raise PoseReferenceError(
            f"the reference's turns differ from the wheel counts' by {med_th:.3g} rad per "
            f"interval (median) after calibration ({med_th / ref_th:.0%} of its own); {causes}")
    if med_xy > _MAX_TRANSLATION_RESIDUAL * ref_xy:
        raise PoseReferenceError(
            f"the reference's travel differs from the wheel counts' by {med_xy:.3g} m per "
            f"interval (median) after calibration ({med_xy / ref_xy:.0%} of the wheels' "
            f"travel); {causes}")
    n_kept = int(keep.sum())
    _log.info("intrinsics: %s (closed form %s), %d intervals kept, %d rejected, residual RMS "
              "%.4g m, %.4g rad", p[:3], closed.as_dict(), n_kept, len(keep) - n_kept,
              rms_xy, rms_th)
    return IntrinsicsCalibration(
        intrinsics=OdometryIntrinsics(*p[:3]), closed_form=closed,
        sensor_pose=np.asarray(p[3:] if sensor_pose else np.zeros(3)),
        covariance=cov, std=np.sqrt(np.diag(cov)), residual_rms=(rms_xy, rms_th),
        n_intervals=n_kept, report=report, n_rejected=len(keep) - n_kept, noise=sigma)


def _windows(t, counts, rt, rp) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Count increments, reference rotations and the windows' halves' count increments
    over about 1 s windows of the reference."""
    step = max(1, round(_WINDOW_S / float(np.median(np.diff(rt)))))
    tk = rt[::step]
    mid = 0.5 * (tk[:-1] + tk[1:])
    cum, half = (np.stack([np.interp(x, t, counts[:, i]) for i in range(2)], axis=1)
                 for x in (tk, mid))
    halves = np.stack([half - cum[:-1], cum[1:] - half], axis=1)
    return np.diff(cum, axis=0), np.diff(np.unwrap(rp[:, 2])[::step]), halves


def calibrate_intrinsics(
    t_s: np.ndarray,
    ticks: np.ndarray,
    ref_t_s: np.ndarray,
    ref_poses: np.ndarray,
    *,
    interval_s: float = 6.0,
    overlap: int = 10,
    sensor_pose: bool = False,
    position_std_m: float = 0.005,
    heading_std_rad: float = 0.01,
    encoders: _Encoders = "quadrature",
    outlier_rounds: int = 4,
    outlier_fraction: float = 0.01,
) -> IntrinsicsCalibration:
    """Both wheels' scale, the wheel base and the reference sensor's pose from a drive.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Encoder frame times [s], on the reference's clock.
    ticks : ndarray of int or float, shape (n, 2)
        Encoder counts ``(left, right)``: integers are raw 16-bit counts (wrapping);
        floats are cumulative counts in any unit that never wrap (wheel angles in
        radians, say). The result's scales are metres per that count.
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
        (default, as the command line's ``--sensor-pose`` left out) when the reference
        tracks the wheel axle's centre itself.
    position_std_m, heading_std_rad : float
        Noise of one reference pose [m], [rad]: the weights of the first outlier round
        only; later rounds and the covariance weigh by the noise the kept residuals show.
    encoders : {"quadrature", "commanded"}
        As :func:`lti_motion.recordings.body_speeds_from_ticks` ("commanded": a Roomba /
        Create 2, whose encoders count in the commanded direction).
    outlier_rounds : int
        Rounds of Censi et al.'s outlier rule (4, as their published results; 0: none),
        each rejecting only intervals also beyond 3 robust standard deviations (the
        scale from the residuals' median; docs/intrinsics.md, "Outliers"); each
        interval's translation residual is judged against its own noise, the start
        pose's heading error growing with the interval's displacement.
    outlier_fraction : float
        Fraction of intervals each round rejects by their largest rotation or
        translation residual (0.01: those above the 99th percentile of either).

    Returns
    -------
    IntrinsicsCalibration
        With the intervals kept and rejected counted.

    Raises
    ------
    ValueError
        An option out of range (one line naming it and its value).
    PoseReferenceError
        Wrong shapes, non-finite poses, no time overlap, or a reference whose motion
        does not follow the wheel counts; the message lists the likely causes (the
        sensor's mount, the encoder kind, a clock offset) with the option that fixes each.
    UnidentifiableError
        The drive cannot determine the intrinsics (no turns; turns in place only; the
        wheels always in the same proportion); the message says what to add. Never NaN.

    Notes
    -----
    Censi et al. 2013, sec. V-A and V-B (closed form), then a nonlinear refinement in
    scaled parameters and the authors' outlier rounds
    (:mod:`lti_motion.calibration.intrinsics_solver`); see the module docstring.

    References
    ----------
    A. Censi, A. Franchi, L. Marchionni, G. Oriolo, "Simultaneous calibration of odometry
    and sensor parameters for mobile robots", IEEE T-RO 29(2):475-492, 2013, sec. V.
    P. J. Huber, E. M. Ronchetti, "Robust Statistics", 2nd ed., Wiley 2009, sec. 1.4
    (the median-based scale, Hampel's rejection rule) and sec. 3.3 (trimming).

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
    _check_options(interval_s=interval_s, overlap=overlap, position_std_m=position_std_m,
                   heading_std_rad=heading_std_rad, encoders=encoders,
                   outlier_rounds=outlier_rounds, outlier_fraction=outlier_fraction)
    t, n, rt, rp = _check_inputs(t_s, ticks, ref_t_s, ref_poses)
    if np.issubdtype(n.dtype, np.floating):
        d = np.diff(n, axis=0)               # counts in any unit that never wrap
    else:
        d = tick_deltas(n, axis=0)
    if encoders == "commanded":
        d = unfold_commanded_direction(d)
    counts = np.vstack([[0, 0], np.cumsum(d, axis=0)]).astype(float)
    if not np.any(d):
        raise UnidentifiableError("the encoders did not move: nothing to calibrate")
    iv = _intervals(t, counts, rt, rp, interval_s, overlap=overlap)
    dn_w, rot_w, halves = _windows(t, counts, rt, rp)
    report = _report(dn_w, rot_w, iv, halves)
    _check_identifiable(report, dn_w, iv, interval_hint=f"over intervals of {interval_s:g} s ")
    sigma = np.array([position_std_m, position_std_m, heading_std_rad]) * np.sqrt(2.0)
    cal = _solve(iv, report, sensor_pose=sensor_pose, sigma0=sigma, rounds=outlier_rounds,
                 fraction=outlier_fraction, pose_reference=True,
                 causes=_causes(sensor_pose=sensor_pose, encoders=encoders))
    return _with_odometry_errors(cal, t, counts, rt, rp, overlap=overlap)


def _with_odometry_errors(cal: IntrinsicsCalibration, t, counts, rt, rp, *, overlap: int
                          ) -> IntrinsicsCalibration:
    """``cal`` with the drive's odometry error model (:mod:`lti_motion.calibration.
    odometry_walk`) over the interval lengths the drive holds."""
    span = float(rt[-1] - rt[0])
    lengths = [s for s in WALK_LENGTHS_S if 4 * s <= span] or [min(WALK_LENGTHS_S)]
    p = np.array([*cal.intrinsics.as_dict().values(), *(cal.sensor_pose if np.any(
        cal.sensor_pose) else ())])
    ivs = [_intervals(t, counts, rt, rp, s, overlap=overlap) for s in lengths]
    ivs = [iv for iv in ivs if len(iv.starts) >= 2]
    if not ivs:
        return cal
    k, k_std, ref = fit_wheel_walk(ivs, p)
    source = (f"intrinsics calibration against a pose reference: {len(rt)} reference poses "
              f"over {span:.0f} s, intervals of {lengths[0]:g}-{lengths[-1]:g} s; reference "
              f"noise seen {np.sqrt(ref[0] / 2) * 1e3:.2g} mm, "
              f"{np.rad2deg(np.sqrt(ref[1] / 2)):.2g} deg per pose")
    errors = OdometryErrors(k, cal.covariance[:3, :3], k_std, source)
    return dataclasses.replace(cal, odometry_errors=errors)


def calibrate_intrinsics_intervals(
    counts: np.ndarray,
    sensor_motion: np.ndarray,
    *,
    sensor_pose: bool = False,
    position_std_m: float = 0.005,
    heading_std_rad: float = 0.01,
    outlier_rounds: int = 4,
    outlier_fraction: float = 0.01,
) -> IntrinsicsCalibration:
    """Both wheels' scale, the wheel base and the sensor's pose from interval samples.

    Each sample is one interval: the wheels' count increments over it and the sensor's
    own motion over it in its start frame (a scan matcher's, a visual odometry's), as
    Censi et al.'s data (:func:`lti_motion.recordings.read_motion_intervals`). Within
    an interval the wheels are taken to turn at constant speeds (the chord form).

    Parameters
    ----------
    counts : ndarray, shape (K, 2)
        Count increments ``(left, right)`` per interval, in any unit (ticks, or wheel
        angle in radians: the scales are then metres per radian, the wheel radii).
    sensor_motion : ndarray, shape (K, 3)
        The sensor's displacement ``(x [m], y [m], theta [rad])`` over each interval,
        in its frame at the interval's start.
    sensor_pose : bool
        Estimate the sensor's pose on the robot (``--sensor-pose``); ``False`` (default)
        when it sits on the axle centre, facing forward.
    position_std_m, heading_std_rad : float
        Noise of one sample's motion [m], [rad]: the weights of the first outlier round
        only; later rounds and the covariance weigh by the kept residuals' noise.
    outlier_rounds : int
        Rounds of Censi et al.'s outlier rule (4, as their published results; 0: none),
        each rejecting only intervals also beyond 3 robust standard deviations (the
        scale from the residuals' median; docs/intrinsics.md, "Outliers").
    outlier_fraction : float
        Fraction each round rejects by the largest rotation or translation residual.

    Returns
    -------
    IntrinsicsCalibration

    Raises
    ------
    ValueError
        An option out of range.
    PoseReferenceError
        Wrong shapes, non-finite samples, or motion that does not follow the counts.
    UnidentifiableError
        The samples cannot determine the intrinsics.

    References
    ----------
    A. Censi, A. Franchi, L. Marchionni, G. Oriolo, "Simultaneous calibration of odometry
    and sensor parameters for mobile robots", IEEE T-RO 29(2):475-492, 2013, sec. V.

    Examples
    --------
    Wheel radii 21 and 21.1 mm, axle 88 mm, counts in radians, a sensor at the centre:

    >>> from lti_motion.calibration.intrinsics_solver import Intervals, odometry_motion
    >>> rng = np.random.default_rng(0)
    >>> angles = rng.uniform(-0.4, 0.8, (300, 2))
    >>> motion = odometry_motion(Intervals.from_samples(angles, np.zeros((300, 3))),
    ...                          0.021, 0.0211, 0.088)
    >>> cal = calibrate_intrinsics_intervals(angles, motion, sensor_pose=False)
    >>> [round(v * 1e3, 3) for v in cal.intrinsics.as_dict().values()]
    [21.0, 21.1, 88.0]
    """
    _check_options(interval_s=1.0, overlap=1, position_std_m=position_std_m,
                   heading_std_rad=heading_std_rad, encoders="quadrature",
                   outlier_rounds=outlier_rounds, outlier_fraction=outlier_fraction)
    dn = np.asarray(counts, float)
    sm = np.asarray(sensor_motion, float)
    if dn.ndim != 2 or dn.shape[1] != 2 or sm.shape != (len(dn), 3):
        raise PoseReferenceError(f"expected counts of shape (K, 2) and sensor motion of shape "
                                 f"(K, 3), got {dn.shape} and {sm.shape}")
    bad = np.flatnonzero(~(np.all(np.isfinite(dn), axis=1) & np.all(np.isfinite(sm), axis=1)))
    if bad.size:
        raise PoseReferenceError(f"sample {bad[0]} holds NaN or infinite values; drop it first")
    if not np.any(dn):
        raise UnidentifiableError("the encoders did not move: nothing to calibrate")
    iv = Intervals.from_samples(dn, sm)
    report = _report(dn, sm[:, 2], iv)
    _check_identifiable(report, dn, iv, interval_hint="")
    sigma = np.array([position_std_m, position_std_m, heading_std_rad])
    return _solve(iv, report, sensor_pose=sensor_pose, sigma0=sigma, rounds=outlier_rounds,
                  fraction=outlier_fraction, pose_reference=False,
                  causes=_causes(sensor_pose=sensor_pose, encoders=None))
