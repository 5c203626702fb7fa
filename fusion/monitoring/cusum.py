"""CUSUM arithmetic shared by the residual and dynamics tests: run lengths and thresholds.

A one-sided CUSUM ``g_k = max(0, g_(k-1) + x_k - k)`` on N(0, 1) samples alarms
when ``g_k > h``. Its in-control average run length (ARL) follows Siegmund's
approximation (Siegmund 1985, eq. 2.56; Basseville & Nikiforov 1993, eq.
5.2.44); the thresholds below solve it, or the log-likelihood-ratio CUSUM's
Wald bound, for a false-alarm budget per hour.

References
----------
Siegmund, D. (1985). Sequential Analysis. Springer, eq. 2.56.
Basseville, M., Nikiforov, I. (1993). Detection of Abrupt Changes, sections 5.2 and 7.2.1.
"""

from __future__ import annotations

import math

from scipy.optimize import brentq

from fusion.exceptions import FilterOptionError

__all__ = [
    "cusum_arl",
    "cusum_llr_threshold",
    "cusum_threshold",
    "lag_cusum_threshold",
]


_SIEGMUND_OFFSET = 1.166          # Siegmund 1985, eq. 2.56: b = h + 1.166


def cusum_arl(k: float, h: float) -> float:
    """In-control average run length of a one-sided CUSUM on N(0, 1) samples.

    Siegmund's approximation (Siegmund 1985, eq. 2.56):
    ``ARL0 = (exp(2 k b) - 2 k b - 1) / (2 k^2)`` with ``b = h + 1.166``.

    Examples
    --------
    >>> round(cusum_arl(0.5, 5.0))         # "about 930 samples"
    938
    """
    b = h + _SIEGMUND_OFFSET
    x = 2.0 * k * b
    return (math.exp(x) - x - 1.0) / (2.0 * k * k)


def cusum_threshold(k: float, arl0: float) -> float:
    """The threshold ``h`` whose in-control ARL (:func:`cusum_arl`) is ``arl0`` samples.

    Examples
    --------
    >>> round(cusum_threshold(0.5, 938.0), 2)
    5.0
    """
    # ARL0 grows like exp(2 k h): bracket h so that 2 k b stays below 700 (no overflow)
    return float(brentq(lambda h: cusum_arl(k, h) - arl0, 0.0, 300.0 / k))


def cusum_llr_threshold(windows_per_hour: float, false_alarms_per_hour: float) -> float:
    """``h = ln(N_w / F)``: Lorden's bound ``ARL0 >= exp(h)`` meets ``F`` alarms an hour.

    Examples
    --------
    >>> round(cusum_llr_threshold(3600 / (30 * 0.015), 0.05), 2)
    11.98
    """
    if not (windows_per_hour > 0 and false_alarms_per_hour > 0):
        raise FilterOptionError(f"need windows_per_hour > 0 and false_alarms_per_hour > 0, got "
                                f"{windows_per_hour} and {false_alarms_per_hour}")
    return math.log(windows_per_hour / false_alarms_per_hour)


def lag_cusum_threshold(informative_windows_per_hour: float, false_alarms_per_hour: float, *,
                        shift_sigma: float) -> float:
    """Threshold ``h`` [nats] of the lag CUSUM (eq. 3) for ``F`` false alarms an hour.

    Parameters
    ----------
    informative_windows_per_hour : float
        ``N_inf``, windows an hour that carry lag information.
    false_alarms_per_hour : float
        ``F_lag``.
    shift_sigma : float
        ``mu = theta1 sqrt(b)``, the tuned lag in standard deviations of a
        typical informative window.

    Returns
    -------
    float
        ``h`` such that Siegmund's in-control run length of the equivalent
        normal CUSUM (reference ``mu / 2``, threshold ``h / mu``) is
        ``N_inf / F`` windows (module docstring).

    Examples
    --------
    >>> round(lag_cusum_threshold(3000.0, 0.5, shift_sigma=2.5), 2)
    6.92
    """
    if not (informative_windows_per_hour > 0 and false_alarms_per_hour > 0 and shift_sigma > 0):
        raise FilterOptionError(
            f"need informative_windows_per_hour, false_alarms_per_hour and shift_sigma > 0, "
            f"got {informative_windows_per_hour}, {false_alarms_per_hour}, {shift_sigma}")

    arl0 = informative_windows_per_hour / false_alarms_per_hour
    return shift_sigma * cusum_threshold(0.5 * shift_sigma, arl0)
