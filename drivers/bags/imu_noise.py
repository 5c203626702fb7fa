"""A ``sensor_msgs/Imu``'s yaw-rate noise, from its ``angular_velocity_covariance``.

The covariance is a row-major 3 x 3 matrix of the angular velocity [rad^2/s^2];
its ``zz`` entry (index 8) is the variance of one message's yaw rate. The message
definition gives two conventions (REP 145, "Data Sources"; ``sensor_msgs/msg/Imu``):

- all zeros: the covariance is unknown;
- element 0 is ``-1``: the message has no angular velocity at all.

So, per message: ``covariance[0] == -1`` means no reading (the message is dropped
from the yaw rate); otherwise a positive, finite ``zz`` is the reading's variance,
and ``zz == 0`` (the all-zero matrix, or a zero yaw entry) is unknown.

**To the filter's units.** The EKF's gyro noise is a white-noise density ``q``
[rad/s/sqrt(Hz)] (:class:`fusion.noise.GyroNoise`); a message's rate at the Imu's
period ``tau`` has variance ``sigma^2 = q^2 / tau`` (Woodman 2007, section
3.2.1), so ``q = sqrt(sigma^2 tau)``. The resampling rule of
:func:`lti_motion.recordings.on_grid` integrates the messages over their stamps (trapezoid rule),
and the EKF sums the periods over its window ``T``: the window's integral of
``T / tau`` messages, each weighted ``tau``, has variance ``(T / tau) tau^2
sigma^2 = q^2 T``, the window's noise of :func:`fusion.ekf.gyro_cov`, for an
Imu of any rate faster than the window. ``sigma^2`` is the median of the messages'
known variances and ``tau`` the median spacing of their stamps.

References
----------
REP 145, "Conventions for IMU sensor drivers", section "Data Sources".
O. J. Woodman, "An introduction to inertial navigation", University of Cambridge,
UCAM-CL-TR-696, 2007, section 3.2.1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from drivers.bags.topics import StampedSeries
from drivers.exceptions import BagError

__all__ = ["ImuRateNoise", "imu_rate_noise", "with_rate_data"]

#: Columns of an Imu series (drivers.bags.reader.COLUMNS["imu"]): rate, covariance[0], zz.
RATE, COV0, COV_ZZ = 0, 1, 2


@dataclass(frozen=True)
class ImuRateNoise:
    """What an Imu topic says of its yaw rate's noise.

    Attributes
    ----------
    variance_rad2_s2 : float or None
        Median ``zz`` of the messages that give one [rad^2/s^2]; ``None``: unknown.
    period_s : float
        Median spacing of the messages with a rate [s].
    n_known, n_unknown, n_no_data : int
        Messages with a variance, with an unknown one (zeros), without a rate (-1).
    """

    variance_rad2_s2: float | None
    period_s: float
    n_known: int
    n_unknown: int
    n_no_data: int

    @property
    def density_rad_s_sqrt_hz(self) -> float | None:
        """``sqrt(sigma^2 tau)`` [rad/s/sqrt(Hz)] (module notes), ``None`` when unknown."""
        if self.variance_rad2_s2 is None:
            return None
        return math.sqrt(self.variance_rad2_s2 * self.period_s)

    def describe(self, topic: str) -> str:
        """One line for people: which noise the gyro's readings get."""
        if self.variance_rad2_s2 is None:
            return (f"{topic} gives no yaw-rate covariance (all zeros: unknown); the gyro "
                    f"noise is the default density")
        return (f"{topic}'s angular_velocity_covariance zz {self.variance_rad2_s2:.3g} "
                f"rad^2/s^2 at {1.0 / self.period_s:.4g} Hz: gyro noise density "
                f"{self.density_rad_s_sqrt_hz:.3g} rad/s/sqrt(Hz)")


def _no_data(imu: StampedSeries) -> np.ndarray:
    return imu.values[:, COV0] == -1.0


def with_rate_data(imu: StampedSeries) -> StampedSeries:
    """The messages that carry an angular velocity (``covariance[0] != -1``).

    Raises
    ------
    BagError
        If none does (the Imu gives no angular velocity: it cannot be a gyro).
    """
    keep = ~_no_data(imu)
    if not keep.any():
        raise BagError(f"topic {imu.topic}: every message's angular_velocity_covariance[0] is "
                       f"-1 (no angular velocity); choose another --imu-topic or drop --gyro")
    if keep.all():
        return imu
    return replace(imu, t_ns=imu.t_ns[keep], values=imu.values[keep])


def imu_rate_noise(imu: StampedSeries) -> ImuRateNoise:
    """The yaw-rate variance an Imu topic gives (module notes), per-message conventions.

    Parameters
    ----------
    imu : StampedSeries
        An Imu topic read by :func:`drivers.bags.read_bag` (columns rate,
        ``covariance[0]``, ``covariance[8]``).

    Raises
    ------
    BagError
        If no message has an angular velocity, or a variance is negative.

    Examples
    --------
    >>> t = np.arange(4, dtype=np.int64) * 10_000_000             # 100 Hz
    >>> v = np.array([[0.1, 1e6, 0.0025], [0.1, 1e6, 0.0025], [0.1, 0.0, 0.0],
    ...               [0.1, -1.0, 0.0]])
    >>> noise = imu_rate_noise(StampedSeries("/imu", "sensor_msgs/msg/Imu", t, v))
    >>> noise.n_known, noise.n_unknown, noise.n_no_data, round(noise.density_rad_s_sqrt_hz, 4)
    (2, 1, 1, 0.005)
    """
    no_data = _no_data(imu)
    rate = with_rate_data(imu)
    zz = rate.values[:, COV_ZZ]
    if np.any(zz < 0):
        i = int(np.flatnonzero(zz < 0)[0])
        raise BagError(f"topic {imu.topic}: a message's angular_velocity_covariance zz is "
                       f"{zz[i]:.3g}, a variance must not be negative")
    known = zz > 0
    spacing = np.diff(rate.t_ns)
    period_s = float(np.median(spacing)) / 1e9 if spacing.size else math.nan
    variance = float(np.median(zz[known])) if known.any() and spacing.size else None
    return ImuRateNoise(variance, period_s, int(known.sum()), int((~known).sum()),
                        int(no_data.sum()))
