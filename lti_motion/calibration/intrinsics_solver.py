"""The numerical core of the odometry-intrinsics calibration: intervals, Censi et al.'s
closed form, the refinement in scaled parameters, and the outlier rule.

Used by :mod:`lti_motion.calibration.intrinsics_fit`, which validates the input, builds
the intervals and judges the drive; nothing here is public.

Units. The refinement works on the parameters divided by the closed form's values
(``k_L / k_L0``, ``k_R / k_R0``, ``b / b0``, ``l_x / b0``, ``l_y / b0``, ``l_theta``), all
of order one whatever unit the counts are in; the residuals are in metres and radians.
Counts ten times finer change ``k_L0, k_R0`` tenfold and nothing else, so the result is
the same physical one to rounding (the former fixed absolute finite-difference step was
far larger than parameters of 1e-5 to 1e-6 m per count).

Outliers. Censi et al.'s rule (the solver published with the paper,
``src/solver2.cpp`` of github.com/AndreaCensi/calibration, run with ``-outliers_iterations
4`` and its default ``-outliers_percentage 0.01``): solve, compute each interval's residual,
drop every interval whose rotation residual ``|e_theta|`` or translation residual
``|(e_x, e_y)|`` is above that residual's ``1 - fraction`` quantile of the intervals
kept, and solve again; ``rounds`` times. An interval is rejected only if it also lies
beyond 3 robust standard deviations (scale from the residuals' median): on clean data
the largest residuals are kept (:func:`trim`). For a pose reference each interval's
translation residual is judged against its own noise: the start pose's heading error
turns the interval's displacement, so a long straight interval's residual is larger
than a turn's without being an outlier. The weights of the translation and rotation
residuals then come from the kept residuals themselves (their RMS), as Censi et al.
estimate the scan matcher's noise from the residuals (their ``estimate_noise``), so the
user's noise figures only weigh the first round.

References
----------
A. Censi, A. Franchi, L. Marchionni, G. Oriolo, "Simultaneous calibration of odometry and
sensor parameters for mobile robots", IEEE T-RO 29(2):475-492, 2013, sec. V (closed
form); their solver (``src/solver2.cpp``, reference-output/version_string): outlier
rounds, noise estimated from the residuals, covariance as the inverse Fisher information.
P. J. Huber, E. M. Ronchetti, "Robust Statistics", 2nd ed., Wiley 2009, sec. 1.4 (the
median-based scale and Hampel's rejection rule) and sec. 3.3 (trimmed estimates).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from lti_motion.exceptions import PoseReferenceError, UnidentifiableError
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.kinematics import wrap_angle

__all__: list[str] = []

#: Above this the refinement's normal matrix is taken as singular.
_MAX_NORMAL_CONDITION = 1e12


@dataclass(frozen=True)
class Intervals:
    """Encoder sub-steps grouped into reference intervals."""

    dn: np.ndarray            # (m, 2) count increments of the sub-steps
    seg: np.ndarray           # (m,) interval index of each sub-step
    starts: np.ndarray        # (K,) first sub-step of each interval
    ref_motion: np.ndarray    # (K, 3) reference displacement in its own start frame
    dn_total: np.ndarray      # (K, 2) count increments per interval

    @classmethod
    def from_samples(cls, dn: np.ndarray, ref_motion: np.ndarray) -> Intervals:
        """One sub-step per interval (interval samples such as Censi et al.'s)."""
        k = np.arange(len(dn))
        return cls(dn=dn, seg=k, starts=k, ref_motion=ref_motion, dn_total=dn)

    def subset(self, keep: np.ndarray) -> Intervals:
        """The intervals where ``keep`` (bool, shape (K,)) holds, with their sub-steps."""
        rows = keep[self.seg]
        new_index = np.cumsum(keep) - 1
        seg = new_index[self.seg[rows]]
        starts = np.searchsorted(seg, np.arange(int(keep.sum())))
        return Intervals(dn=self.dn[rows], seg=seg, starts=starts,
                         ref_motion=self.ref_motion[keep], dn_total=self.dn_total[keep])


def odometry_motion(iv: Intervals, kl: float, kr: float, b: float) -> np.ndarray:
    """Robot displacement ``(x, y, theta)`` over each interval in its start frame, the
    sub-steps integrated with the chord form (Censi et al. 2013 eq. 11)."""
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


def sensor_motion(o: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """``l^-1 (+) o (+) l``: the sensor's displacement for robot displacements ``o``."""
    lx, ly, lt = pose
    c, s = np.cos(o[:, 2]), np.sin(o[:, 2])
    px = o[:, 0] + c * lx - s * ly - lx          # o (+) l, then l^-1 (+) that
    py = o[:, 1] + s * lx + c * ly - ly
    cl, sl = np.cos(lt), np.sin(lt)
    return np.stack([cl * px + sl * py, -sl * px + cl * py, o[:, 2]], axis=1)


def rotation_step(iv: Intervals) -> tuple[float, float]:
    """Censi et al. 2013 sec. V-A: ``dtheta_k = J21 dn_L + J22 dn_R`` by least squares."""
    (j21, j22), *_ = np.linalg.lstsq(iv.dn_total, iv.ref_motion[:, 2], rcond=None)
    return float(j21), float(j22)


def rotation_step_precision(iv: Intervals) -> float:
    """The larger relative standard error of ``J21, J22`` (sec. V-A's least squares,
    ``s^2 (X^T X)^-1``): large when the wheels always moved in one proportion, whatever
    the counts' noise or unit; ``inf`` if singular."""
    x, y = iv.dn_total, iv.ref_motion[:, 2]
    j, *_ = np.linalg.lstsq(x, y, rcond=None)
    s2 = float(np.sum((y - x @ j) ** 2)) / max(len(y) - 2, 1)
    info = x.T @ x
    if not np.linalg.cond(info) < 1e14 or not np.all(j != 0):
        return float("inf")
    return float(np.max(np.sqrt(np.diag(s2 * np.linalg.inv(info))) / np.abs(j)))


def closed_form(iv: Intervals, *, sensor_pose: bool, causes: str,
                mean_scale: float | None = None) -> tuple[OdometryIntrinsics, np.ndarray]:
    """Censi et al. 2013 sec. V-A (rotation) and V-B (translation, constrained LS).

    ``causes`` ends the error messages: the likely causes in the caller's words. With
    ``mean_scale`` (the wheels' mean scale known, as UMBmark takes it) the wheel base
    follows from the rotation step alone: ``k_L + k_R = b (J22 - J21) = 2 mean_scale``.
    """
    j21, j22 = rotation_step(iv)
    if not (j21 < 0 < j22):
        raise PoseReferenceError(
            "the reference's rotation does not follow the wheel counts (one wheel would turn "
            f"the robot the wrong way: J21={j21:.3g}, J22={j22:.3g}); {causes}")
    if mean_scale is not None:
        b = 2.0 * mean_scale / (j22 - j21)
        return OdometryIntrinsics(-j21 * b, j22 * b, b), np.zeros(3)
    # V-B: robot translation = b a_k, with a_k the odometry of (k_L, k_R, b) = (-J21, J22, 1)
    a = odometry_motion(iv, -j21, j22, 1.0)
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
    se_b = _wheel_base_error(lin, rot, b, pose[2])
    if not b > 3.0 * se_b:
        if abs(b) > 3.0 * se_b:
            raise PoseReferenceError("the reference's travel does not follow the wheel counts "
                                     f"(wheel base estimate {b:.3g} m); {causes}")
        mount = ("" if sensor_pose else "; if the reference is a sensor off the axle centre "
                 "or turned on the robot, estimate its mount (sensor_pose=True; --sensor-pose)")
        raise UnidentifiableError(
            f"the drive does not determine the wheel base ({b:.3g} +- {se_b:.2g} m): the "
            f"robot barely travelled (turns in place only?); add straight runs or arcs{mount}")
    return OdometryIntrinsics(-j21 * b, j22 * b, b), pose


def _wheel_base_error(lin: np.ndarray, rot: np.ndarray, b: float, l_theta: float) -> float:
    """Standard error of the closed form's wheel base [m] (linear least squares with the
    rotation ``l_theta`` fixed): large when the robot barely travelled."""
    w = np.array([np.cos(l_theta), np.sin(l_theta)])
    y = -rot @ w
    u, *_ = np.linalg.lstsq(lin, y, rcond=None)
    dof = max(len(y) - lin.shape[1] - 1, 1)
    s2 = float(np.sum((y - lin @ u) ** 2)) / dof
    info = lin.T @ lin
    if not np.linalg.cond(info) < 1e14:
        return float("inf")
    return float(np.sqrt(max(s2 * np.linalg.inv(info)[0, 0], 0.0)))


def residuals(iv: Intervals, params: np.ndarray) -> np.ndarray:
    """Predicted minus reference sensor displacement per interval, shape (K, 3) [m, rad];
    ``params`` = ``(k_L, k_R, b[, l_x, l_y, l_theta])``."""
    pose = params[3:] if len(params) == 6 else np.zeros(3)
    r = sensor_motion(odometry_motion(iv, *params[:3]), pose) - iv.ref_motion
    r[:, 2] = wrap_angle(r[:, 2])
    return r


def refine(iv: Intervals, p0: np.ndarray, sigma: np.ndarray, *,
           mean_scale: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Newton (trust region) in scaled parameters; returns the parameters and the
    covariance ``s^2 (J^T J)^-1`` (the inverse Fisher information with the noise
    estimated from the residuals, as Censi et al.'s solver computes it). With
    ``mean_scale`` the parameters are ``k_L = m (1 + d)``, ``k_R = m (1 - d)`` and ``b``."""
    if mean_scale is not None:
        m, b0 = mean_scale, p0[2]
        t = np.array([[m, 0.0], [-m, 0.0], [0.0, b0]])     # dp/dx

        def to_p(x: np.ndarray) -> np.ndarray:
            return np.array([m * (1 + x[0]), m * (1 - x[0]), b0 * x[1]])

        x0 = np.array([(p0[0] - p0[1]) / (p0[0] + p0[1]), 1.0])
    else:
        unit = np.concatenate([p0[:3], [p0[2], p0[2], 1.0][:len(p0) - 3]])
        t = np.diag(unit)

        def to_p(x: np.ndarray) -> np.ndarray:
            return x * unit

        x0 = np.concatenate([np.ones(3), p0[3:] / unit[3:]])

    def scaled(x: np.ndarray) -> np.ndarray:
        return (residuals(iv, to_p(x)) / sigma).ravel()

    fit = least_squares(scaled, x0, method="trf", jac="3-point", x_scale=1.0)
    dof = max(fit.fun.size - len(x0), 1)
    s2 = 2.0 * fit.cost / dof
    jtj = fit.jac.T @ fit.jac
    if not np.linalg.cond(jtj) < _MAX_NORMAL_CONDITION:
        raise UnidentifiableError("the refinement's normal matrix is singular: the drive does "
                                  "not determine all parameters; add turns both ways and "
                                  "straight runs")
    cov_x = s2 * np.linalg.inv(jtj)
    return to_p(fit.x), t @ cov_x @ t.T


def trim(r: np.ndarray, fraction: float, *, robust: bool = True,
         travel: np.ndarray | None = None) -> np.ndarray:
    """Censi et al.'s rule on the residuals ``r`` (K, 3) of the intervals kept: True for
    those at or below both the rotation's and the translation's ``1 - fraction``
    quantile (their solver: the sorted errors' element ``round((1 - fraction) K)``).

    With ``robust``, an interval is rejected only if it also lies beyond 3 robust
    standard deviations (scale from the median, Hampel's rule): ``|e_theta| > 3 sigma``
    with ``sigma = median |e_theta| / 0.6745`` (half-normal), ``|e_xy| > 3.44 sigma`` with
    ``sigma = median |e_xy| / 1.1774`` (Rayleigh; the same 0.27% tail), so residuals
    that are merely the largest of clean data are kept.

    ``travel`` (K, 2), the reference's displacement over each interval in its start frame,
    is given when the reference is a pose trajectory: the interval's motion is then
    ``R(-theta_0) (p_1 - p_0)``, so the start pose's heading error turns the displacement
    and adds ``sigma_h |d|`` across it, more on a long straight interval than on a turn in
    place. The translation residual is then judged against its own interval's noise,
    ``m^2 = e_along^2 / s^2 + e_across^2 / (s^2 + sigma_h^2 |d|^2)`` (``s`` the two
    positions' noise, ``median e_along^2 / 0.4549``, the chi-square median with one
    degree of freedom; ``sigma_h^2 = (median |e_theta| / 0.6745)^2 / 2``, one pose's heading
    variance, the rotation residual holding two), and ``m`` goes through the rule and the
    gate in place of ``|e_xy|`` (Rayleigh of unit scale when the model holds)."""
    e_th = np.abs(r[:, 2])
    e_xy = np.hypot(r[:, 0], r[:, 1]) if travel is None else _standardised_xy(r, travel)
    index = min(max(int(np.round((1.0 - fraction) * len(r))), 0), len(r) - 1)
    lim_th, lim_xy = np.sort(e_th)[index], np.sort(e_xy)[index]
    if robust:
        lim_th = max(lim_th, 3.0 * np.median(e_th) / 0.6745)
        lim_xy = max(lim_xy, 3.44 * np.median(e_xy) / 1.1774)
    return (e_th <= lim_th) & (e_xy <= lim_xy)


def _standardised_xy(r: np.ndarray, travel: np.ndarray) -> np.ndarray:
    """The translation residual over its own interval's noise for a pose reference
    (:func:`trim`): along the displacement the two positions' noise, across it that plus
    the start heading's error times the displacement's length."""
    d = np.hypot(travel[:, 0], travel[:, 1])
    u = travel / np.maximum(d, 1e-300)[:, None]           # unit along (0 when d = 0)
    along = r[:, 0] * u[:, 0] + r[:, 1] * u[:, 1]
    across = u[:, 0] * r[:, 1] - u[:, 1] * r[:, 0]
    still = d == 0                                         # no direction: both ways alike
    along = np.where(still, r[:, 0], along)
    across = np.where(still, r[:, 1], across)
    s2 = max(float(np.median(along ** 2)) / 0.4549, 1e-300)
    h2 = (float(np.median(np.abs(r[:, 2]))) / 0.6745) ** 2 / 2.0
    return np.sqrt(along ** 2 / s2 + across ** 2 / (s2 + h2 * d ** 2))


def noise_from_residuals(r: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """Per-channel noise ``(sigma_x, sigma_y, sigma_theta)`` of the kept residuals: the
    translation pooled over x and y (RMS), the rotation alone; never below ``floor``."""
    s_xy = np.sqrt(np.mean(r[:, :2] ** 2))
    s_th = np.sqrt(np.mean(r[:, 2] ** 2))
    return np.maximum(np.array([s_xy, s_xy, s_th]), floor)
