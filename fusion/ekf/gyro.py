"""A yaw-rate gyro in the model EKF: the integrated reading, its Jacobian and noise.

The gyro reads the body's yaw rate over each sensor period: the *ground* yaw
rate, slip included, plus a bias and white noise. Summed over a window of
``N`` periods, ``T = N dt``, the readings measure the heading change the pose
carries (paper eq. 11 turns the heading by ``dt g_w`` a period)::

    Y = dt sum_k y_k = theta - theta_c + T b + n,
    n ~ N(0, density^2 T + 2 sigma_q^2)

with ``theta_c`` the heading at the start of the window, a clone in the state
(:data:`~fusion.ekf.HEADING_CLONE`; stochastic cloning, Roumeliotis &
Burdick 2002), and ``b`` the bias, a random-walk state
(:data:`~fusion.ekf.GYRO_BIAS`; the bias state of robot_localization
and of visual-inertial filters, Mourikis & Roumeliotis 2007, section III-A),
constant over the window. ``H`` is constant::

    H = [0 0 1 | 0 0 0 | T  -1 | 0 ... 0]
         pose    scales  b  theta_c  model z and speeds

**Why a window, not each period.** The heading's slip reaches the pose as process
noise (:mod:`fusion.ekf.functions`, *Pose noise*); the state's ``theta`` holds it,
so ``theta - theta_c`` is what the gyro sees, and its error ``n`` is independent
of the state, as a Kalman update needs (Bar-Shalom et al. 2001, section 5.2.1).
A per-period comparison of the reading with the encoders' yaw rate
``(1 + k_w) w + kappa v`` would leave that slip out, and the encoders' yaw rate of
one period carries a difference of rounding errors that the filter's speed state
takes as exact: ``(m / b) sqrt(4 / 12)`` ticks, 0.07 rad/s on a 15 ms Create 2
period, more than the gyro's own 0.041 rad/s. In the integrated heading the
rounding does not accumulate: at any instant ``theta`` is off by
``(r_R m_R - r_L m_L) / b`` with the two counts' rounding errors ``r`` uniform in
half a tick, variance ``sigma_q^2 = (m_L^2 + m_R^2) / (12 b^2)`` (0.00077 rad on a
Create 2), so the window's heading change carries ``2 sigma_q^2``: a fixed term,
4% of the gyro's ``density^2 T`` over 0.5 s. (Adjacent windows share one instant,
a correlation of -2%, neglected.)

**At rest: a zero-angular-rate update.** While the robot stands still (commands
zero and encoder counts unchanged over the window and a settling time before it)
the ground yaw rate is zero, so the summed reading measures the bias alone
(Groves 2013, section 15.3.2, the zero-angular-rate update)::

    Y = T b + n,   n ~ N(0, density^2 T),   H = [0 ... 0 | T | 0 ... 0]

No heading difference and no encoder rounding enter it (unchanged counts round the
same at both ends): ``2 sigma_q^2`` leaves ``R``, and the update cannot move the
heading through ``theta - theta_c``. Nothing but the bias is asked of the reading, so a
robot turned by hand with its wheels still (the one way to fool the rest test) gives
an innovation ``T`` times the turn rate: gated at 1 degree of freedom.

**Settling after a stop.** When the commands drop to zero the robot brakes, and
then creeps: its encoders count on for seconds (2.3-2.9 s after a stop from 0.2-0.3
m/s on the simulator's hard floor) while its ground heading moves unlike them
(ground minus encoder turn -0.0015 to -0.011 rad in the first 0.5 s window after
the stop, 12 stops of 4 drives all negative, mostly negative in the next two windows;
the window's standard deviation is 0.0037 rad).
The slip noise the pose carries is white and proportional to the encoder speeds
(:mod:`fusion.ekf.functions`, *Pose noise*), so such a window's error is neither
small nor independent of the state, as the update needs (Bar-Shalom et al. 2001,
section 5.2.1): fused, its skid went into the bias (a mean bias error of -0.0011
rad/s after three 3 s stops, 10 drives, heading NEES 3.1). So a window that overlaps
the settling, from the period the commands go to zero until the counts have stood
still for a whole window (or the commands resume), is dropped (reason
``"settling"``); the robot starting the filter with zero commands counts as settled.
The heading keeps the encoders' account of the stop.

References
----------
The paper: ``docs/architecture.md``, "The paper".
Y. Bar-Shalom, X. R. Li, T. Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, Wiley 2001, section 5.2.1. S. I. Roumeliotis, J. W.
Burdick, "Stochastic cloning: a generalized framework for processing relative
state measurements", ICRA 2002, section III. A. I. Mourikis, S. I. Roumeliotis,
"A multi-state constraint Kalman filter for vision-aided inertial navigation",
ICRA 2007, section III-A. O. J. Woodman, "An introduction to inertial
navigation", UCAM-CL-TR-696, 2007, section 3.2. P. D. Groves, *Principles of GNSS,
Inertial, and Multisensor Integrated Navigation Systems*, 2nd ed., Artech House 2013,
section 15.3.2 (zero-angular-rate update).
"""

from __future__ import annotations

import numpy as np

from fusion.ekf.functions import GYRO_BIAS, HEADING_CLONE, FilterModel
from fusion.exceptions import FilterOptionError

__all__ = ["clone_heading", "gyro_cov", "gyro_jacobian", "gyro_measurement",
           "heading_quantization_var", "rest_cov", "rest_jacobian", "rest_measurement"]


def _check_gyro(fm: FilterModel) -> None:
    if fm.gyro is None:
        raise FilterOptionError("this filter has no gyro states; give gyro=GyroNoise(...) to "
                                "FilterModel, or options=EKFOptions(gyro=GyroNoise(...)) to "
                                "ModelEKF")


def gyro_measurement(x: np.ndarray, fm: FilterModel, window_s: float) -> np.ndarray:
    """Predicted integrated reading ``theta - theta_c + T b`` [rad], shape (1,).

    Parameters
    ----------
    x : ndarray, shape (n,)
        State of a filter with a gyro.
    fm : FilterModel
        Its layout (``fm.gyro`` set).
    window_s : float
        ``T``, the time the readings were summed over [s].

    Raises
    ------
    FilterOptionError
        If ``fm`` has no gyro.
    """
    _check_gyro(fm)
    return np.array([x[2] - x[HEADING_CLONE] + window_s * x[GYRO_BIAS]])


def gyro_jacobian(x: np.ndarray, fm: FilterModel, window_s: float) -> np.ndarray:
    """``H = d h / d x`` of :func:`gyro_measurement`, shape (1, n) (module notes)."""
    _check_gyro(fm)
    H = np.zeros((1, fm.n))
    H[0, 2], H[0, HEADING_CLONE], H[0, GYRO_BIAS] = 1.0, -1.0, window_s
    return H


def heading_quantization_var(fm: FilterModel) -> float:
    """``sigma_q^2 = (m_L^2 + m_R^2) / (12 b^2)`` [rad^2]: the encoders' rounding in the
    heading at one instant (module notes); 0 without an encoder scale."""
    if fm.intrinsics is None:
        return 0.0
    i = fm.intrinsics
    return (i.m_per_tick_left ** 2 + i.m_per_tick_right ** 2) / (12.0 * i.wheel_base_m ** 2)


def gyro_cov(fm: FilterModel, window_s: float) -> np.ndarray:
    """The integrated reading's noise ``[[density^2 T + 2 sigma_q^2]]`` [rad^2], (1, 1).

    Raises
    ------
    FilterOptionError
        If ``fm`` has no gyro.
    """
    _check_gyro(fm)
    return np.array([[fm.gyro.noise_density_rad_s_sqrt_hz ** 2 * window_s
                      + 2.0 * heading_quantization_var(fm)]])


def rest_measurement(x: np.ndarray, fm: FilterModel, window_s: float) -> np.ndarray:
    """Predicted integrated reading at rest, ``T b`` [rad], shape (1,) (module notes,
    *At rest*; Groves 2013, section 15.3.2).

    Raises
    ------
    FilterOptionError
        If ``fm`` has no gyro.
    """
    _check_gyro(fm)
    return np.array([window_s * x[GYRO_BIAS]])


def rest_jacobian(x: np.ndarray, fm: FilterModel, window_s: float) -> np.ndarray:
    """``H = d h / d x`` of :func:`rest_measurement`: ``T`` at the bias, shape (1, n)."""
    _check_gyro(fm)
    H = np.zeros((1, fm.n))
    H[0, GYRO_BIAS] = window_s
    return H


def rest_cov(fm: FilterModel, window_s: float) -> np.ndarray:
    """The integrated reading's noise at rest, ``[[density^2 T]]`` [rad^2], (1, 1): white
    rate noise summed over ``T`` (Woodman 2007, section 3.2.1), no encoder rounding.

    Raises
    ------
    FilterOptionError
        If ``fm`` has no gyro.
    """
    _check_gyro(fm)
    return np.array([[fm.gyro.noise_density_rad_s_sqrt_hz ** 2 * window_s]])


def clone_heading(x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start a window: ``theta_c = theta`` with its covariance rows (a stochastic clone).

    Returns new arrays ``x`` (n,) and ``P`` (n, n): the clone's row and column of
    ``P`` are the heading's, ``P[c, c] = P[theta, theta]`` (Roumeliotis & Burdick
    2002, eq. 7): the covariance stays positive semi-definite.
    """
    x, P = x.copy(), P.copy()
    x[HEADING_CLONE] = x[2]
    P[HEADING_CLONE, :] = P[2, :]
    P[:, HEADING_CLONE] = P[:, 2]
    P[HEADING_CLONE, HEADING_CLONE] = P[2, 2]
    return x, P
