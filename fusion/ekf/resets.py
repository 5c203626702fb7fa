"""Bounds on the model EKF's scale-error states, and the resets that stop a filter running away.

:class:`fusion.ekf.ModelEKF` carries the scale errors ``c = (k_v, k_w,
kappa)`` of ground against encoder speeds as random walks
(:mod:`fusion.ekf.functions`, *Pose noise*). Nothing in the Kalman update
keeps them physical: an encoder that reads motion while landmarks say the
robot stands still (a bias at rest) is best explained by ``k_v -> -1``, a
ground speed of zero for any encoder speed, after which the filter believes
the robot stands still when it drives and gates every landmark. Two tests run
after every fused update of :class:`~fusion.ekf.ModelEKF`; both are cheap
scalar arithmetic.

**Plausibility of the scale errors** (:func:`scale_statistic`). Under the
filter's own model the scale errors are ``c(t) ~ N(0, diag(sigma(t)^2))``
with ``sigma_i(t)^2 = p_i^2 + q_i^2 (t - t_0)`` (prior ``p``, walk rate ``q``,
time since the start or the last reset ``t - t_0``). The estimate has at most
that spread (its covariance is the prior's minus the information gained), so
``d^2 = sum_i (k_i / sigma_i(t))^2`` over ``(k_v, k_w, kappa)`` is at most
chi-square with 3 degrees of freedom (Bar-Shalom, Li & Kirubarajan 2001,
section 5.4.2, the NEES test on a part of the state). ``d^2`` above the
``plausible_probability`` quantile (:class:`~fusion.noise.ScaleErrors`,
default ``1 - 1e-6``: ``d^2 > 30.7``, 5.5 sigma, 5.5% at the 1% prior, a
diameter ratio 5.5% off for ``kappa`` alone) is implausible: the scale states
are reset to their prior (:func:`reset_scales`), counted, logged, and reported
as a :class:`FilterReset`. Besides, the states are clipped to what a robot
can be: ``|k_v|, |k_w|`` to :data:`~fusion.scale_errors.MAX_SCALE_ERROR` (0.5: a ground speed
between half and one and a half times the encoder speed; ``k = -1`` would be
wheels turning on the spot without moving the robot) and ``|kappa|`` to
:data:`~fusion.scale_errors.MAX_RATIO_ERROR` over the wheel base (0.1: wheels whose diameters
differ by 10%, more than any tyre wear or hair; 0.43 rad/m on a Create 2).
With the default prior the reset comes first; the clip is the bound for a
wide prior. Clipping moves the mean only, so the covariance stays as it was,
positive semi-definite.

**Divergence** (:class:`DivergenceWatch`). When ``n`` absolute readings in a
row (landmark sightings, pose fixes) of at least two different landmarks (a
pose fix counts as a landmark of its own) are outside the gate, the pose and
its covariance disagree with the world, not one landmark with the map: the
filter has diverged and its gate now keeps out the readings that would bring
it back. The scale states are reset and the pose covariance is widened by the
last rejected sighting's discrepancy (:func:`discrepancy`,
:func:`widen_pose`), so the next sightings are fused again.

**The covariance stays positive semi-definite.** A reset sets ``c = 0``, its
covariance block to ``diag(p^2)`` and its cross-covariances to zero:
``blkdiag(P_rest, diag(p^2))``, with ``P_rest`` a principal block of a
positive semi-definite matrix, is positive semi-definite. Widening adds a
positive semi-definite matrix to the pose block.

References
----------
Y. Bar-Shalom, X. R. Li, T. Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, Wiley 2001, section 5.4.2 (NEES and NIS chi-square
tests) and section 11.6 (filter divergence, covariance inflation).
"""

from __future__ import annotations

import math
from collections.abc import Hashable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from fusion.ekf.functions import POSE, SCALES
from fusion.exceptions import FilterOptionError
from fusion.noise import ScaleErrors, gate_threshold
from fusion.scale_errors import MAX_RATIO_ERROR, MAX_SCALE_ERROR

__all__ = [
    "DivergenceWatch",
    "FilterReset",
    "ResetCause",
    "ScaleBound",
    "discrepancy",
    "reset_scales",
    "scale_statistic",
    "widen_pose",
]

ResetCause = Literal["scale_implausible", "diverged"]


@dataclass(frozen=True)
class FilterReset:
    """One reset of the filter (module notes).

    Attributes
    ----------
    t_s : float
        Filter time of the reset [s].
    cause : {"scale_implausible", "diverged"}
        ``"scale_implausible"``: the scale errors failed the plausibility
        test; ``"diverged"``: absolute readings stayed outside the gate.
    statistic, threshold : float
        The evidence: ``d^2`` of the scale errors and its chi-square bound,
        or the number of readings gated in a row and the number that means
        divergence.
    scale_errors : tuple of 3 float
        ``(k_v, k_w, kappa [rad/m])`` just before the reset.
    """

    t_s: float
    cause: ResetCause
    statistic: float
    threshold: float
    scale_errors: tuple[float, float, float]


@dataclass(frozen=True)
class ScaleBound:
    """The plausibility bound of the scale errors, precomputed for one :class:`ScaleErrors`.

    Attributes
    ----------
    prior_var : tuple of 3 float
        ``p_i^2``, the prior variances of ``(k_v, k_w, kappa)``.
    walk_var_per_s : tuple of 3 float
        ``q_i^2`` [1/s, 1/s, (rad/m)^2/s].
    threshold : float
        ``chi2.ppf(plausible_probability, 3)``.
    max_kappa_rad_per_m : float
        The physical bound of ``|kappa|``, ``MAX_RATIO_ERROR / b`` [rad/m].

    Raises
    ------
    FilterOptionError
        If the bound reaches :data:`~fusion.scale_errors.MAX_SCALE_ERROR` or
        :data:`~fusion.scale_errors.MAX_RATIO_ERROR`
        at the prior (the test could never fire before the clip).

    Examples
    --------
    >>> b = ScaleBound.from_scales(ScaleErrors(), wheel_base_m=0.235)
    >>> round(b.threshold, 2), round(math.sqrt(b.threshold * b.prior_var[0]), 4)
    (30.66, 0.0554)
    >>> round(b.max_kappa_rad_per_m, 3)
    0.426
    """

    prior_var: tuple[float, float, float]
    walk_var_per_s: tuple[float, float, float]
    threshold: float
    max_kappa_rad_per_m: float

    @classmethod
    def from_scales(cls, scales: ScaleErrors, *, wheel_base_m: float) -> ScaleBound:
        """The bound of ``scales`` (its priors, walks and ``plausible_probability``) for a
        robot of wheel base ``wheel_base_m`` [m] (the unit of ``kappa``'s prior)."""
        if not (math.isfinite(wheel_base_m) and wheel_base_m > 0):
            raise FilterOptionError(f"wheel_base_m must be positive, got {wheel_base_m}")
        threshold = gate_threshold(scales.plausible_probability, 3)
        widest = math.sqrt(threshold) * max(scales.prior_std)
        widest_ratio = math.sqrt(threshold) * scales.ratio_prior_std
        if widest >= MAX_SCALE_ERROR or widest_ratio >= MAX_RATIO_ERROR:
            raise FilterOptionError(
                f"the scale-error priors {scales.prior_std} and ratio prior "
                f"{scales.ratio_prior_std} at plausible_probability "
                f"{scales.plausible_probability} allow |k| up to {widest:.3g} and a ratio error "
                f"up to {widest_ratio:.3g}, not below the physical bounds {MAX_SCALE_ERROR} and "
                f"{MAX_RATIO_ERROR}; give smaller priors")
        p = scales.prior_stds(wheel_base_m)
        q = scales.walk_rates(wheel_base_m)
        return cls(tuple(v * v for v in p), tuple(v * v for v in q), threshold,
                   MAX_RATIO_ERROR / wheel_base_m)


def scale_statistic(k_v: float, k_w: float, kappa: float, bound: ScaleBound,
                    elapsed_s: float) -> float:
    """``d^2 = sum_i k_i^2 / (p_i^2 + q_i^2 t)``: the scale errors against their prior spread.

    Parameters
    ----------
    k_v, k_w : float
        Estimated relative scale errors.
    kappa : float
        Estimated curvature error [rad/m].
    bound : ScaleBound
        Prior and walk variances.
    elapsed_s : float
        Time since the start or the last reset [s].

    Returns
    -------
    float
        At most chi-square with 3 degrees of freedom under the filter's model
        (module notes); compare with ``bound.threshold``.

    Examples
    --------
    >>> b = ScaleBound.from_scales(ScaleErrors(), wheel_base_m=0.25)
    >>> round(scale_statistic(0.01, -0.02, 0.08, b, 0.0), 6)
    9.0
    """
    (pv, pw, pk), (qv, qw, qk) = bound.prior_var, bound.walk_var_per_s
    t = max(elapsed_s, 0.0)
    return k_v * k_v / (pv + qv * t) + k_w * k_w / (pw + qw * t) + kappa * kappa / (pk + qk * t)


def reset_scales(x: np.ndarray, P: np.ndarray, bound: ScaleBound) -> tuple[np.ndarray, np.ndarray]:
    """The state and covariance with the scale errors back at their prior (module notes).

    Parameters
    ----------
    x : ndarray, shape (n,)
        Model-EKF state (:mod:`fusion.ekf.functions` layout).
    P : ndarray, shape (n, n)
        Its covariance.
    bound : ScaleBound
        Prior variances.

    Returns
    -------
    x, P : ndarray
        New arrays: ``c = 0``, ``P_cc = diag(p^2)``, cross-covariances of ``c``
        zero; the rest unchanged.
    """
    x = x.copy()
    P = P.copy()
    x[SCALES] = 0.0
    P[SCALES, :] = 0.0
    P[:, SCALES] = 0.0
    P[SCALES, SCALES] = np.diag(bound.prior_var)
    return x, P


def discrepancy(innovation: np.ndarray, range_m: float | None) -> tuple[float, float]:
    """Position and heading discrepancy ``(e [m], b [rad])`` a rejected reading implies.

    Parameters
    ----------
    innovation : ndarray, shape (2,) or (3,)
        A sighting's ``(range [m], bearing [rad])`` residual, or a pose fix's
        ``(x [m], y [m], theta [rad])`` residual.
    range_m : float or None
        The sighting's predicted range [m]; ``None`` for a pose fix.

    Returns
    -------
    tuple of 2 float
        ``e = hypot(nu_r, r nu_b)`` and ``b = nu_b`` for a sighting,
        ``e = hypot(nu_x, nu_y)`` and ``b = nu_theta`` for a pose fix.

    Examples
    --------
    >>> discrepancy(np.array([0.3, 0.1]), 4.0)
    (0.5, 0.1)
    """
    if range_m is None:
        return math.hypot(float(innovation[0]), float(innovation[1])), float(innovation[2])
    nu_r, nu_b = float(innovation[0]), float(innovation[1])
    return math.hypot(nu_r, range_m * nu_b), nu_b


def widen_pose(P: np.ndarray, *, position_m: float, heading_rad: float) -> np.ndarray:
    """The covariance with the pose block widened by a discrepancy (module notes).

    Parameters
    ----------
    P : ndarray, shape (n, n)
        Covariance (pose first).
    position_m, heading_rad : float
        The discrepancy ``(e, b)`` of :func:`discrepancy`.

    Returns
    -------
    ndarray, shape (n, n)
        ``P + blkdiag(diag(e^2, e^2, b^2), 0)``: the rejected sighting would
        then have a normalised innovation squared of at most about 2, inside
        any usual gate (its range residual against a variance of at least
        ``e^2``, its bearing residual against at least ``b^2``).
    """
    out = P.copy()
    e2 = position_m * position_m
    out[POSE, POSE] += np.diag((e2, e2, heading_rad * heading_rad))
    return out


class DivergenceWatch:
    """Counts absolute readings gated in a row; judges divergence (module notes).

    Parameters
    ----------
    readings : int or None
        Readings outside the gate in a row, of at least two landmarks, that
        mean divergence; ``None`` never judges.

    Raises
    ------
    FilterOptionError
        If ``readings`` is not a positive int or None.

    Examples
    --------
    >>> w = DivergenceWatch(4)
    >>> [w.observe(False, lid) for lid in (1, 1, 1, 2)]
    [False, False, False, True]
    >>> w.observe(False, 1), w.observe(True, 1), w.in_a_row
    (False, False, 0)
    """

    def __init__(self, readings: int | None) -> None:
        if readings is not None and not (isinstance(readings, int) and readings >= 1):
            raise FilterOptionError(f"diverged_after must be a positive int or None, got "
                                    f"{readings!r}")
        self.readings = readings
        self.in_a_row = 0
        self._ids: set[Hashable] = set()

    def observe(self, accepted: bool, landmark_id: Hashable) -> bool:
        """Take one compared reading; True when it completes a diverged run (which restarts)."""
        if accepted or self.readings is None:
            self.in_a_row = 0
            self._ids.clear()
            return False
        self.in_a_row += 1
        if len(self._ids) < 2:
            self._ids.add(landmark_id)
        if self.in_a_row >= self.readings and len(self._ids) >= 2:
            self.in_a_row = 0
            self._ids.clear()
            return True
        return False
