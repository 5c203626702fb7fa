"""A known linear plant for identification tests: two second-order wheels behind a
4-sample delay, body speeds v = (vR + vL) / 2, w = (vR - vL) / b, with measurement noise.

Shared by tests/lti_motion/model/test_arx.py, test_fir.py and test_model.py.
"""
import numpy as np
from scipy.signal import lfilter

from lti_motion.kinematics import body_from_wheel
from lti_motion.model.excitation import random_held_normal

DT, BASE, DELAY = 0.015, 0.235, 4
NOISE = (0.003, 0.02)  # std of v [m/s] and w [rad/s]


def wheel_filters():
    """(numerator, denominator) of the left and right wheel, unit DC gain times the wheel gain."""
    out = []
    for poles, gain in (((0.8 + 0.15j, 0.8 - 0.15j), 1.0), ((0.75 + 0.2j, 0.75 - 0.2j), 0.95)):
        den = np.poly(poles).real
        out.append((np.array([1.0, 0.3]) * gain * den.sum() / 1.3, den))
    return out


def plant(u, rng=None, *, saturation=None, dead_zone=None):
    """Body speeds for commands u (n, 2); noisy when rng is given; optional input
    saturation [m/s] and dead zone [m/s] make it non-linear."""
    if saturation is not None:
        u = np.clip(u, -saturation, saturation)
    if dead_zone is not None:
        u = np.where(np.abs(u) < dead_zone, 0.0, u)
    delayed = np.zeros_like(u)
    delayed[DELAY:] = u[:-DELAY]
    wheels = np.column_stack([lfilter(b, a, delayed[:, i]) for i, (b, a) in
                              enumerate(wheel_filters())])
    y = body_from_wheel(wheels, wheel_base_m=BASE)
    return y if rng is None else y + rng.normal(size=y.shape) * NOISE


def commands(rng, n, std=0.2):
    """Random held normal wheel commands (n, 2) [m/s]."""
    return random_held_normal(n=n, dt_s=DT, rng=rng, std_m_s=std)
