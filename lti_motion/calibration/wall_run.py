"""The wheels' diameter ratio without any external reference: straight runs beside a wall
(docs/intrinsics.md, "Without a reference").

A robot whose wheels differ in diameter curves while both encoders count alike: a straight
run of equal counts bends with the curvature ``kappa = (k_R - k_L) / (b k)`` [rad/m]
(:mod:`lti_motion.intrinsics`, "Scale errors"). Beside a straight wall the side light-bump
sensor watches that bend. With the along-track travel ``x`` [m] (signed, from the counts),
the lateral gap to a wall on the robot's left is

.. math::

    g(x) = g_0 - y_{enc}(x) - \\theta_0 x - \\kappa x^2 / 2,              (1)

where ``y_enc`` is the lateral drift the counts themselves explain (unequal counts, with
the intrinsics in use), ``theta_0`` the unknown heading of the run against the wall and
``kappa`` the curvature the intrinsics miss (``dtheta_g = dtheta + kappa ds``; for a wall
on the right the signs of ``y_enc``, ``theta_0``, ``kappa`` flip). The IR signal ``S`` of
a surface falls with the inverse square of its distance, ``S = A / (g - c)^2``, with the
wall's reflectance and the sensor's gain in the unknown ``A`` and its mounting in ``c``;
so ``z = S^{-1/2}`` is affine in the gap, ``z = a + b g``. Each pass starts a measured
distance ``g_0 = r + e`` from the wall: the robot backs off ``e`` (encoder travel) from
touching it (the bumper's unknown radius ``r`` goes into ``a``). Two passes at different
``e`` fix the slope ``b``; per pass, the linear model

.. math::

    z_i = a + b (e_p - y_{enc}(x_i)) + \\gamma_p x_i - \\beta_p x_i^2 / 2,
    \\qquad \\kappa_p = \\beta_p / b,                                          (2)

with ``gamma_p = -b theta_0`` free, is solved by weighted least squares (weights from the
signal's constant noise in counts: ``var z = var S / (4 S^3)``). The straight-line
curvature ``kappa`` then gives the ratio through
:meth:`lti_motion.intrinsics.OdometryIntrinsics.corrected` ``(0, 0, kappa)``: the travel
and the turn scales stay those of the intrinsics in use (the rotation manoeuvre's).

What the law assumes: the inverse-square fall of the signal and a wall that is straight
and equally reflective along the run. The heading's effect on the sensor's incidence and
ray length is left out of eq. 2; it biases ``kappa_p`` in two ways: by a relative ``~2
theta_0`` for a run started at ``theta_0`` [rad] to the wall (so the robot squares up
before each run, :func:`mirror_heading_rad`), and through a term odd in the travel
(``~kappa^2 x^3``) that biases a forward run's ``x^2`` coefficient one way and a backward
run's the other (+14% and -17% on the simulated Create 2 of ``docs/intrinsics.md``): so
``kappa`` is the mean of the forward runs' mean and the backward runs' mean. No sensor
constant is needed: only what a robot builder knows.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Literal

import numpy as np

from lti_motion.exceptions import (
    CalibrationShapeError,
    NoSignalError,
    SaturatedSignalError,
    UnidentifiableError,
)
from lti_motion.intrinsics import OdometryIntrinsics
from lti_motion.recordings.ticks import tick_deltas

__all__ = ["MIN_RUN_M", "WallPass", "WallRunCalibration", "calibrate_wall_run",
           "mirror_heading_rad", "run_path"]

_log = logging.getLogger(__name__)

#: Largest light-bump signal of the Open Interface (packets 46-51, 0-4095).
SIGNAL_MAX = 4095
#: Shortest straight run :func:`calibrate_wall_run` accepts by default [m].
MIN_RUN_M = 0.8


@dataclass(frozen=True)
class WallPass:
    """One straight run beside the wall.

    Parameters
    ----------
    ticks : ndarray of int, shape (n, 2)
        Raw encoder counts (left, right) over the run (16-bit, wrapping allowed).
    signal : ndarray, shape (n,)
        The wall-side light-bump signal of the same frames [counts, 0-4095].
    gap_start_m : float
        How far the robot backed off from touching the wall before the run [m], measured
        with the encoders (the gap less the bumper's radius).
    """

    ticks: np.ndarray
    signal: np.ndarray
    gap_start_m: float

    def __post_init__(self) -> None:
        ticks = np.asarray(self.ticks)
        signal = np.asarray(self.signal, dtype=float)
        if ticks.ndim != 2 or ticks.shape[1] != 2 or signal.shape != (len(ticks),):
            raise CalibrationShapeError(
                f"a wall pass needs ticks of shape (n, 2) and signal of shape (n,), got "
                f"{ticks.shape} and {signal.shape}")
        if not (np.all(np.isfinite(signal)) and np.isfinite(self.gap_start_m)):
            raise CalibrationShapeError("a wall pass's signal and gap_start_m must be finite")
        object.__setattr__(self, "ticks", ticks)
        object.__setattr__(self, "signal", signal)
        object.__setattr__(self, "gap_start_m", float(self.gap_start_m))


@dataclass(frozen=True)
class WallRunCalibration:
    """The result of :func:`calibrate_wall_run`.

    Attributes
    ----------
    intrinsics : OdometryIntrinsics
        The intrinsics in use, corrected by ``kappa`` (travel and turn scales kept).
    kappa_rad_per_m, kappa_std_rad_per_m : float
        Curvature of a straight run of equal counts under the intrinsics in use [rad/m]
        (inverse-variance mean of the passes) and its standard deviation.
    pass_kappa_rad_per_m : tuple of float
        Each pass's curvature [rad/m].
    heading_rad : tuple of float
        Each run's heading against the wall at its start (``theta_0`` of eq. 1) [rad].
    law_slope_per_m : float
        ``b`` of ``S^{-1/2} = a + b g`` [counts^-1/2 per m].
    residual_rms_m : float
        Root-mean-square residual of eq. 2, expressed as a gap [m].
    notes : tuple of str
        What the fit noticed (samples dropped, passes that disagree).
    """

    intrinsics: OdometryIntrinsics
    kappa_rad_per_m: float
    kappa_std_rad_per_m: float
    pass_kappa_rad_per_m: tuple[float, ...]
    heading_rad: tuple[float, ...]
    law_slope_per_m: float
    residual_rms_m: float
    notes: tuple[str, ...]

    @property
    def diameter_ratio(self) -> float:
        """Left over right scale of the corrected intrinsics."""
        return self.intrinsics.diameter_ratio

    @property
    def diameter_ratio_std(self) -> float:
        """Standard deviation of :attr:`diameter_ratio` from :attr:`kappa_std_rad_per_m`.

        With ``u = kappa b / 2``, the ratio is ``r_0 (1 - u) / (1 + u)``
        (:meth:`~lti_motion.intrinsics.OdometryIntrinsics.corrected`), so to first order
        ``std r = r b std kappa / (1 - u^2)``.
        """
        b = self.intrinsics.wheel_base_m
        u = 0.5 * self.kappa_rad_per_m * b
        return float(self.diameter_ratio * b * self.kappa_std_rad_per_m / (1.0 - u * u))


def run_path(ticks: np.ndarray, intrinsics: OdometryIntrinsics) -> tuple[np.ndarray, np.ndarray]:
    """Along-track travel ``x`` and lateral drift ``y`` (left positive) [m] the counts give.

    Dead reckoning with ``intrinsics`` from the run's first frame (pose ``(0, 0, 0)``,
    headings at mid-step; Siegwart & Nourbakhsh, "Autonomous Mobile Robots", 2004,
    eq. 5.7), shape (n,) each; ``x`` is negative for a backward run.

    Examples
    --------
    >>> k = OdometryIntrinsics.symmetric(m_per_tick=1e-3, wheel_base_m=0.2)
    >>> x, y = run_path(np.array([[0, 0], [100, 100], [200, 200]]), k)
    >>> (x.round(12) + 0.0).tolist(), (y.round(12) + 0.0).tolist()
    ([0.0, 0.1, 0.2], [0.0, 0.0, 0.0])
    """
    motion = intrinsics.body_motion(tick_deltas(ticks, axis=0))
    theta = np.concatenate([[0.0], np.cumsum(motion[:, 1])])
    mid = 0.5 * (theta[:-1] + theta[1:])
    x = np.concatenate([[0.0], np.cumsum(motion[:, 0] * np.cos(mid))])
    y = np.concatenate([[0.0], np.cumsum(motion[:, 0] * np.sin(mid))])
    return x, y


def _pass_rows(wp: WallPass, index: int, intrinsics: OdometryIntrinsics, side: float, *,
               min_signal: float, min_run_m: float, max_saturated: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """One pass's columns of eq. 2 ``(1, e - side y, x, -side x^2 / 2)``, ``z``, the row
    weights and the number of samples dropped."""
    name = f"pass {index + 1}"
    x, y = run_path(wp.ticks, intrinsics)
    if abs(x[-1]) < min_run_m:
        raise UnidentifiableError(f"{name} runs {abs(x[-1]):.2f} m beside the wall; drive "
                                  f"straight runs of at least {min_run_m} m")
    saturated = wp.signal >= SIGNAL_MAX
    if saturated.mean() > max_saturated:
        raise SaturatedSignalError(
            f"{name}: the wall-side signal is saturated ({SIGNAL_MAX}) in "
            f"{100 * saturated.mean():.0f}% of the run; back off further from the wall")
    keep = ~saturated & (wp.signal >= min_signal)
    if keep.mean() < 0.5:
        raise NoSignalError(
            f"{name}: the wall-side signal is below {min_signal:g} counts in "
            f"{100 * (1 - keep.mean()):.0f}% of the run: no wall seen; run closer to the "
            "wall, on the side of the sensor given")
    s = wp.signal[keep]
    cols = np.column_stack([np.ones(keep.sum()), wp.gap_start_m - side * y[keep], x[keep],
                            -side * 0.5 * x[keep] ** 2])
    # var z = var S / (4 S^3) for z = S^-1/2 (first-order error propagation)
    return cols, s ** -0.5, s ** 3, int((~keep).sum())


def calibrate_wall_run(passes: list[WallPass], intrinsics: OdometryIntrinsics, *,
                       wall_side: Literal["left", "right"] = "left",
                       min_signal: float = 20.0, min_run_m: float = MIN_RUN_M,
                       min_level_gap_m: float = 0.05, max_saturated: float = 0.2
                       ) -> WallRunCalibration:
    """The diameter ratio from straight runs beside a wall (module docstring, eq. 1-2).

    Parameters
    ----------
    passes : list of WallPass
        At least two runs beside one wall, started at back-offs at least
        ``min_level_gap_m`` apart, watched by the same side sensor.
    intrinsics : OdometryIntrinsics
        The intrinsics in use (e.g. the rotation manoeuvre's symmetric scale).
    wall_side : {"left", "right"}
        Side of the robot the wall is on during the runs.
    min_signal : float
        Samples below this signal [counts] are dropped (noise floor).
    min_run_m : float
        Shortest run accepted [m].
    min_level_gap_m : float
        Smallest spread of the passes' back-offs that fixes the signal's distance law [m].
    max_saturated : float
        Largest fraction of a run whose signal may be saturated.

    Returns
    -------
    WallRunCalibration

    Raises
    ------
    UnidentifiableError
        Fewer than two passes, back-offs too alike, a run too short, or a law without slope.
    NoSignalError
        A pass whose signal stays below ``min_signal`` (no wall seen).
    SaturatedSignalError
        A pass whose signal is saturated for more than ``max_saturated`` of it.

    Notes
    -----
    Eq. 2 is linear in ``(a, b, gamma_p, beta_p)``; weighted least squares with
    the covariance ``s^2 (A^T W A)^-1`` (reduced chi-square ``s^2``), and
    ``var kappa_p`` by first-order propagation through ``beta_p / b``.

    References
    ----------
    J. Borenstein, L. Feng, "Measurement and correction of systematic odometry errors in
    mobile robots", IEEE T-RA 12(6), 1996 (the type B error a straight run shows).

    Examples
    --------
    Two synthetic passes of a robot that curves 0.03 rad/m to the right:

    >>> k = OdometryIntrinsics.symmetric(m_per_tick=4.4e-4, wheel_base_m=0.235)
    >>> def one(e, sign):
    ...     x = sign * np.linspace(0.0, 2.0, 400)
    ...     gap = 0.17 + e + 0.015 * x ** 2          # wall on the left: -kappa x^2 / 2
    ...     counts = np.round(np.outer(x / 4.4e-4, [1, 1])).astype(int)
    ...     return WallPass(counts, 4095 * 0.9 * (0.04 / (gap - 0.14)) ** 2, e)
    >>> cal = calibrate_wall_run([one(0.04, 1), one(0.16, -1)], k)
    >>> round(cal.kappa_rad_per_m, 4)
    -0.03
    """
    if len(passes) < 2:
        raise UnidentifiableError(f"the wall run needs two passes at different back-offs, "
                                  f"got {len(passes)}")
    levels = [wp.gap_start_m for wp in passes]
    if max(levels) - min(levels) < min_level_gap_m:
        raise UnidentifiableError(
            f"the passes started {min(levels):.3f}-{max(levels):.3f} m from the wall; back "
            f"off by distances at least {min_level_gap_m} m apart to fix the signal's law")
    if wall_side not in ("left", "right"):
        raise ValueError(f"wall_side must be 'left' or 'right', got {wall_side!r}")
    side = 1.0 if wall_side == "left" else -1.0
    blocks, zs, ws, signs, notes = [], [], [], [], []
    for i, wp in enumerate(passes):
        cols, z, w, dropped = _pass_rows(wp, i, intrinsics, side, min_signal=min_signal,
                                            min_run_m=min_run_m, max_saturated=max_saturated)
        blocks.append(cols)
        signs.append(int(np.sign(cols[-1, 2])))
        zs.append(z)
        ws.append(w)
        if dropped:
            notes.append(f"pass {i + 1}: {dropped} of {len(wp.signal)} samples dropped "
                         "(saturated or below the noise floor)")
    n_p = len(passes)
    design = np.zeros((sum(len(z) for z in zs), 2 + 2 * n_p))
    row = 0
    for i, cols in enumerate(blocks):                 # (a, b, gamma_1, beta_1, gamma_2, ...)
        design[row:row + len(cols), :2] = cols[:, :2]
        design[row:row + len(cols), 2 + 2 * i:4 + 2 * i] = cols[:, 2:]
        row += len(cols)
    z, sw = np.concatenate(zs), np.sqrt(np.concatenate(ws))
    coef, cov, resid = _weighted_lstsq(design, z, sw)
    b = coef[1]
    # the back-offs must change the signal clearly: S^-1/2 by 5% of its typical value
    if not (b > 3.0 * np.sqrt(cov[1, 1])
            and b * (max(levels) - min(levels)) > 0.05 * np.median(z)):
        raise UnidentifiableError(
            f"the signal does not fall with the back-off (law slope {b:.3g} +- "
            f"{np.sqrt(cov[1, 1]):.2g}); is the sensor the one facing the wall?")
    kappas, variances, headings = [], [], []
    for i in range(n_p):
        gamma, beta = coef[2 + 2 * i], coef[3 + 2 * i]
        grad = np.zeros(len(coef))
        grad[1], grad[3 + 2 * i] = -beta / b ** 2, 1.0 / b
        kappas.append(beta / b)
        variances.append(float(grad @ cov @ grad))
        headings.append(float(-side * gamma / b))
    kappa, kappa_var, directions = _direction_mean(kappas, variances, signs)
    if len(directions) < 2:
        notes.append("all runs in one direction: the sensor's incidence biases kappa by up "
                     "to ~10%; drive one run forwards and one backwards")
    for d in directions:
        same = [k for k, sg in zip(kappas, signs, strict=True) if sg == d]
        if len(same) > 1 and np.ptp(same) > 0.2 * abs(np.mean(same)) + 0.002:
            notes.append(f"runs in one direction disagree: {', '.join(f'{k:.4f}' for k in same)} "
                         "rad/m (a wall that is not straight?)")
    _log.debug("wall run: kappa %.5f rad/m from passes %s", kappa, kappas)
    return WallRunCalibration(
        intrinsics=intrinsics.corrected(0.0, 0.0, kappa), kappa_rad_per_m=kappa,
        kappa_std_rad_per_m=float(np.sqrt(kappa_var)),
        pass_kappa_rad_per_m=tuple(float(k) for k in kappas), heading_rad=tuple(headings),
        law_slope_per_m=float(b), residual_rms_m=float(np.sqrt(np.mean(resid ** 2)) / b),
        notes=tuple(notes))


def _direction_mean(kappas: list[float], variances: list[float], signs: list[int]
                    ) -> tuple[float, float, list[int]]:
    """Mean of the forward runs' and of the backward runs' curvature, then of the two:
    terms odd in the travel (the heading's effect on the sensor's incidence, ``~kappa^2
    x^3``) bias a forward and a backward run's ``x^2`` coefficient oppositely."""
    k, v, sg = np.array(kappas), np.array(variances), np.array(signs)
    directions = sorted(set(signs))
    means = [k[sg == d].mean() for d in directions]
    var = [v[sg == d].sum() / np.sum(sg == d) ** 2 for d in directions]
    return float(np.mean(means)), float(np.sum(var) / len(directions) ** 2), directions


def _weighted_lstsq(design: np.ndarray, z: np.ndarray, sw: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted least squares (row weights ``sw^2``): coefficients, covariance
    ``s^2 (A^T W A)^-1`` and the unweighted residuals."""
    a_w = design * sw[:, None]
    coef, *_ = np.linalg.lstsq(a_w, z * sw, rcond=None)
    resid = z - design @ coef
    dof = max(len(z) - design.shape[1], 1)
    s2 = float(np.sum((resid * sw) ** 2)) / dof
    normal = a_w.T @ a_w
    if np.linalg.cond(normal) > 1e14:
        raise UnidentifiableError("the wall run's normal matrix is singular: the passes do "
                                  "not separate the signal's law from the curvature")
    return coef, s2 * np.linalg.inv(normal), resid


def mirror_heading_rad(angle_rad: np.ndarray, left: np.ndarray, right: np.ndarray, *,
                       span_rad: float = 0.25, step_rad: float = 0.001) -> float:
    """The heading at which a mirrored pair of sensors sees a flat wall alike.

    A robot turning in place in front of a wall records a left and a right sensor mounted
    as mirror images; facing the wall square on, ``S_left(phi* + d)`` equals
    ``g S_right(phi* - d)`` for every ``d`` (``g`` the sensors' unknown gain ratio).
    ``phi*`` minimises the variance over ``d`` of ``ln S_left(phi* + d) - ln S_right(phi*
    - d)``, searched in steps of ``step_rad`` within the recorded angles.

    Parameters
    ----------
    angle_rad : ndarray, shape (n,)
        Heading of each frame from the encoders [rad] (any origin).
    left, right : ndarray, shape (n,)
        The pair's signals [counts], positive.
    span_rad : float
        Half-width of the window of ``d`` compared [rad].
    step_rad : float
        Resolution of the search [rad].

    Returns
    -------
    float
        ``phi*`` [rad], on the scale of ``angle_rad``.

    Raises
    ------
    UnidentifiableError
        If the angles do not cover ``phi* +- span_rad`` for any candidate.

    Examples
    --------
    >>> phi = np.linspace(-0.6, 0.6, 601)
    >>> signal = lambda a: 1000.0 * np.cos(a) ** 4        # a sensor looking ``a`` off square
    >>> round(mirror_heading_rad(phi, signal(phi + 0.23 - 0.1), 0.8 * signal(phi - 0.23 - 0.1)), 3)
    0.1
    """
    order = np.argsort(angle_rad, kind="stable")
    a = np.asarray(angle_rad, float)[order]
    a, first = np.unique(a, return_index=True)
    log_l = np.log(np.maximum(np.asarray(left, float)[order][first], 1.0))
    log_r = np.log(np.maximum(np.asarray(right, float)[order][first], 1.0))
    d = np.arange(-span_rad, span_rad + 0.5 * step_rad, step_rad)
    centres = np.arange(a[0] + span_rad, a[-1] - span_rad, step_rad)
    if len(centres) == 0:
        raise UnidentifiableError(f"the scan covers {a[-1] - a[0]:.2f} rad; turn at least "
                                  f"{2 * span_rad:.2f} rad past the wall's square to find it")
    diff = (np.interp(centres[:, None] + d, a, log_l)
            - np.interp(centres[:, None] - d, a, log_r))
    return float(centres[np.argmin(diff.var(axis=1))])
