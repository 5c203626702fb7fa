"""Noise types and chi-square tests that every estimator wing shares.

- :class:`SlipNoise`: white ground-versus-encoder speed noise (the EKF's and the
  graph's slip model).
- :class:`ScaleErrors`: prior and random walk of the scale errors
  ``(k_v, k_w, kappa)`` of ground against encoder speeds.
- :class:`LandmarkNoise`: standard deviations of a range-bearing sensor.
- :class:`GyroNoise`: white noise and random-walk bias of a yaw-rate gyro.
- :func:`nis`, :func:`inverse_covariance`, :func:`gate_threshold`: the
  normalised innovation squared and its chi-square gate (Bar-Shalom, Li &
  Kirubarajan 2001, section 5.4.2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusion.exceptions import FilterOptionError

__all__ = [
    "GyroNoise",
    "LandmarkNoise",
    "ScaleErrors",
    "SlipNoise",
    "gate_threshold",
    "inverse_covariance",
    "nis",
]


@dataclass(frozen=True)
class SlipNoise:
    """White noise between encoder speeds and ground speeds, per sensor period.

    ``sigma_v = v_floor_m_s + v_frac |v|`` [m/s] and
    ``sigma_w = w_floor_rad_s + w_frac |w| + w_per_v_rad_m |v|`` [rad/s].

    Attributes
    ----------
    v_frac, w_frac : float
        Relative slip of the linear speed and of the yaw rate.
    w_per_v_rad_m : float
        Yaw-rate noise per metre per second of travel [rad/m]: uneven floor
        and traction. On the simulator's hard floor, ground minus encoder yaw
        rate averaged over 1 s scatters by 0.0013 rad/s at 0.2 m/s, i.e.
        0.011 rad/s per 15 ms period.
    v_floor_m_s, w_floor_rad_s : float
        Floors [m/s], [rad/s].

    Raises
    ------
    FilterOptionError
        If a value is negative or not finite.
    """

    v_frac: float = 0.01
    w_frac: float = 0.01
    w_per_v_rad_m: float = 0.05
    v_floor_m_s: float = 1e-4
    w_floor_rad_s: float = 1e-3

    def __post_init__(self) -> None:
        values = (self.v_frac, self.w_frac, self.w_per_v_rad_m, self.v_floor_m_s,
                  self.w_floor_rad_s)
        if not all(math.isfinite(v) and v >= 0 for v in values):
            raise FilterOptionError(f"SlipNoise needs finite, non-negative values, got {self}")

    def stds(self, v_m_s: float, w_rad_s: float) -> tuple[float, float]:
        """``(sigma_v [m/s], sigma_w [rad/s])`` at body speeds ``(v, w)``."""
        av = abs(v_m_s)
        return (self.v_floor_m_s + self.v_frac * av,
                self.w_floor_rad_s + self.w_frac * abs(w_rad_s) + self.w_per_v_rad_m * av)


@dataclass(frozen=True)
class ScaleErrors:
    """Scale errors ``(k_v, k_w, kappa)`` of ground against encoder motion, as random walks.

    ``k_v``, ``k_w`` are the relative errors of the travel and of the turn,
    ``kappa`` [rad/m] the curvature a straight run of equal counts drives (a
    left/right diameter ratio; :mod:`lti_motion.intrinsics`, *Scale errors*).

    Attributes
    ----------
    prior_std : tuple of 2 float
        Start standard deviations of ``(k_v, k_w)``: the encoder scale from
        three turns is within 1% (``docs/calibration.md``).
    walk_per_sqrt_s : tuple of 2 float
        Random-walk rates of ``(k_v, k_w)`` [1/sqrt(s)]: how fast the scales
        may wander (floor, load, tyre wear); 1e-4 is 0.1% in 100 s.
    plausible_probability : float
        Chi-square probability (3 degrees of freedom) of the plausibility
        test of the estimated scale errors against their prior spread: beyond
        it the filter resets them (:mod:`fusion.ekf.resets`; the default
        ``1 - 1e-6`` is 5.5 standard deviations, 5.5% at the 1% prior).
    ratio_prior_std : float
        Start standard deviation of the wheels' diameter ratio (relative),
        which sets ``kappa``'s: ``ratio_prior_std / b`` [rad/m] for wheel base
        ``b`` (a ratio ``1 + r`` curves a straight run of equal counts by
        ``r / b``). The rotation manoeuvre measures the wheels' *mean* scale
        and says nothing of their ratio, so the prior is the tyres' own
        tolerance: 1%, i.e. 0.043 rad/m on a Create 2's 0.235 m wheel base
        (the asymmetric robot of docs/intrinsics.md has exactly that).
    ratio_walk_per_sqrt_s : float
        Random-walk rate of the diameter ratio [1/sqrt(s)] (``kappa``'s is
        this over ``b``); 1e-4, as for ``(k_v, k_w)``: 0.1% in 100 s.

    Raises
    ------
    FilterOptionError
        If a value is negative or not finite, a prior is zero, or
        ``plausible_probability`` is not in (0, 1).

    """

    prior_std: tuple[float, float] = (0.01, 0.01)
    walk_per_sqrt_s: tuple[float, float] = (1e-4, 1e-4)
    plausible_probability: float = 1.0 - 1e-6
    ratio_prior_std: float = 0.01
    ratio_walk_per_sqrt_s: float = 1e-4

    def __post_init__(self) -> None:
        values = (*self.prior_std, *self.walk_per_sqrt_s)
        if len(values) != 4 or not all(math.isfinite(v) and v >= 0 for v in values) or \
                min(self.prior_std) <= 0:
            raise FilterOptionError(f"ScaleErrors needs positive priors and non-negative walk "
                                    f"rates, two of each, got {self}")
        kp, kq = self.ratio_prior_std, self.ratio_walk_per_sqrt_s
        if not (math.isfinite(kp) and kp > 0 and math.isfinite(kq) and kq >= 0):
            raise FilterOptionError(f"ScaleErrors needs a positive ratio prior and a non-negative "
                                    f"ratio walk rate, got {kp} and {kq}")
        p = self.plausible_probability
        if not (isinstance(p, (int, float)) and 0.0 < p < 1.0):
            raise FilterOptionError(f"ScaleErrors.plausible_probability must be in (0, 1), got "
                                    f"{self.plausible_probability}")

    def prior_stds(self, wheel_base_m: float) -> tuple[float, float, float]:
        """Prior standard deviations of ``(k_v, k_w, kappa [rad/m])`` for wheel base ``b`` [m].

        Examples
        --------
        >>> [round(p, 4) for p in ScaleErrors().prior_stds(0.235)]
        [0.01, 0.01, 0.0426]
        """
        return (*self.prior_std, self.ratio_prior_std / wheel_base_m)

    def walk_rates(self, wheel_base_m: float) -> tuple[float, float, float]:
        """Random-walk rates of ``(k_v, k_w, kappa)`` [1/sqrt(s), 1/sqrt(s), rad/m/sqrt(s)]."""
        return (*self.walk_per_sqrt_s, self.ratio_walk_per_sqrt_s / wheel_base_m)


@dataclass(frozen=True)
class GyroNoise:
    """A yaw-rate gyro as the model EKF fuses it: white noise and a random-walk bias.

    The reading of a sensor period is ``y = g_w + b + n`` with ``g_w`` the
    period's mean ground yaw rate, ``b`` the bias (a state: random walk) and
    ``n`` white, ``sigma = noise_density / sqrt(dt)`` (the period's mean of
    white rate noise; Woodman 2007, section 3.2.1).

    Attributes
    ----------
    noise_density_rad_s_sqrt_hz : float
        White-noise density [rad/s/sqrt(Hz)] (angle random walk); MEMS gyros
        0.002-0.01, default 0.005.
    bias_prior_std_rad_s : float
        Start standard deviation of the bias [rad/s]; default 0.01 (a MEMS
        gyro's turn-on bias is within about 0.01 rad/s).
    bias_walk_rad_s_per_sqrt_s : float
        Random-walk rate of the bias [rad/s/sqrt(s)] (rate random walk);
        default 1e-4, 0.001 rad/s in 100 s.
    max_bias_rad_s : float
        The filter clips the bias estimate to ``+-max_bias_rad_s``; default
        0.05 rad/s (5 prior standard deviations; no MEMS bias is larger).
    window_s : float
        The filter integrates the readings over this time [s] and fuses the
        heading change once per window (:mod:`fusion.ekf.gyro`: the encoders'
        quantisation is about 0.07 rad/s on one 15 ms period of a Create 2, a
        fixed 0.0011 rad on the heading change of any window); default 0.5 s.
    rest_update : bool
        A window during which the robot stood still fuses the bias alone, a
        zero-angular-rate update (:mod:`fusion.ekf.gyro`, *At rest*; Groves
        2013, section 15.3.2); default ``True``. ``False``: every window is the
        heading-change update.
    rest_settle_s : float
        Still means: commands exactly zero and encoder counts unchanged in every
        period of the window and for this long before it [s], so a robot that
        still coasts on delayed commands with its encoders stuck is not taken as
        still; default 0.5 s (a Create 2 step settles within 15 periods, 0.23 s).
    drop_settling : bool
        A window in which the robot settles after a stop (from the period its
        commands go to zero until its counts have stood still for a whole
        window) is not fused (:mod:`fusion.ekf.gyro`, *Settling after a stop*);
        default ``True``.

    Raises
    ------
    FilterOptionError
        For a non-positive density, prior or bound, a negative walk rate or
        settling time, or a bound within 3 prior standard deviations.

    References
    ----------
    O. J. Woodman, "An introduction to inertial navigation", University of
    Cambridge, UCAM-CL-TR-696, 2007, sections 3.2.1-3.2.3. P. D. Groves,
    *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
    Systems*, 2nd ed., Artech House 2013, section 15.3.2.

    Examples
    --------
    >>> round(GyroNoise().std_rad_s(0.015), 4)
    0.0408
    """

    noise_density_rad_s_sqrt_hz: float = 0.005
    bias_prior_std_rad_s: float = 0.01
    bias_walk_rad_s_per_sqrt_s: float = 1e-4
    max_bias_rad_s: float = 0.05
    window_s: float = 0.5
    rest_update: bool = True
    rest_settle_s: float = 0.5
    drop_settling: bool = True

    def __post_init__(self) -> None:
        pos = (self.noise_density_rad_s_sqrt_hz, self.bias_prior_std_rad_s, self.max_bias_rad_s,
               self.window_s)
        walk, settle = self.bias_walk_rad_s_per_sqrt_s, self.rest_settle_s
        if not (all(math.isfinite(v) and v > 0 for v in pos) and math.isfinite(walk)
                and walk >= 0 and math.isfinite(settle) and settle >= 0):
            raise FilterOptionError(f"GyroNoise needs a positive density, bias prior, bias "
                                    f"bound and window and a non-negative walk rate and "
                                    f"settling time, got {self}")
        if self.max_bias_rad_s < 3.0 * self.bias_prior_std_rad_s:
            raise FilterOptionError(f"GyroNoise.max_bias_rad_s ({self.max_bias_rad_s}) must be at "
                                    f"least 3 bias prior standard deviations "
                                    f"({3.0 * self.bias_prior_std_rad_s:.4g})")

    def std_rad_s(self, dt_s: float) -> float:
        """Standard deviation of one reading averaged over ``dt_s`` [s]: ``density / sqrt(dt)``."""
        return self.noise_density_rad_s_sqrt_hz / math.sqrt(dt_s)


def nis(innovation: np.ndarray, SI: np.ndarray) -> float:
    """Normalised innovation squared ``nu^T S^-1 nu`` (Bar-Shalom et al. 2001, section 5.4.2)."""
    if len(innovation) == 2:
        (a, b), (c, d) = SI.tolist()
        n0, n1 = innovation.tolist()
        return a * n0 * n0 + (b + c) * n0 * n1 + d * n1 * n1
    return float(innovation @ SI @ innovation)


def inverse_covariance(S: np.ndarray) -> np.ndarray:
    """``S^-1`` of an innovation covariance (closed form for 2 x 2), shape (m, m).

    Raises
    ------
    numpy.linalg.LinAlgError
        If ``S`` is singular.

    Examples
    --------
    >>> inverse_covariance(np.array([[4.0, 1.0], [1.0, 0.5]])).tolist()
    [[0.5, -1.0], [-1.0, 4.0]]
    """
    if S.shape == (2, 2):
        (a, b), (c, d) = S.tolist()
        det = a * d - b * c
        if det > 0.0 and math.isfinite(det):
            f = 1.0 / det
            return np.array(((d * f, -b * f), (-c * f, a * f)))
    return np.linalg.inv(S)


def gate_threshold(probability: float, dof: int) -> float:
    """Chi-square gate: the ``probability`` quantile with ``dof`` degrees of freedom.

    Raises
    ------
    FilterOptionError
        If ``probability`` is not in (0, 1).

    Examples
    --------
    >>> round(gate_threshold(0.999, 2), 3)
    13.816
    """
    if not 0.0 < probability < 1.0:
        raise FilterOptionError(f"gate probability must be in (0, 1), got {probability}")
    # imported here: scipy.stats costs 1 s to import, and the rest of the base never needs it
    from scipy.stats import chi2

    return float(chi2.ppf(probability, dof))


@dataclass(frozen=True)
class LandmarkNoise:
    """Standard deviations of a range-bearing sensor.

    Attributes
    ----------
    range_std_frac : float
        Range noise as a fraction of the range (0.02 = 2%).
    range_std_m : float
        Floor of the range noise [m]; the standard deviation is
        ``max(range_std_m, range_std_frac * r)``.
    bearing_std_rad : float
        Bearing noise [rad].

    Raises
    ------
    FilterOptionError
        If a value is negative or not finite, or the range noise is zero.

    Examples
    --------
    >>> (LandmarkNoise(range_std_frac=0.02, bearing_std_rad=0.01).cov(2.0).round(8) + 0.0).tolist()
    [[0.0016, 0.0], [0.0, 0.0001]]
    """

    range_std_frac: float = 0.02
    range_std_m: float = 0.005
    bearing_std_rad: float = math.radians(1.0)

    def __post_init__(self) -> None:
        values = (self.range_std_frac, self.range_std_m, self.bearing_std_rad)
        if not all(math.isfinite(v) and v >= 0 for v in values):
            raise FilterOptionError(f"LandmarkNoise needs finite, non-negative values, got {self}")
        if self.range_std_m == 0 and self.range_std_frac == 0:
            raise FilterOptionError("LandmarkNoise needs range_std_m > 0 or range_std_frac > 0")
        if self.bearing_std_rad == 0:
            raise FilterOptionError("LandmarkNoise needs bearing_std_rad > 0")

    def cov(self, range_m: float) -> np.ndarray:
        """Measurement covariance ``diag(sigma_r^2, sigma_b^2)`` at a range [m, rad]^2, (2, 2)."""
        sr = max(self.range_std_m, self.range_std_frac * abs(range_m))
        return np.array([[sr * sr, 0.0], [0.0, self.bearing_std_rad ** 2]])
