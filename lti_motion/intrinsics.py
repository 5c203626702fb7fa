"""Odometry intrinsics of a differential-drive robot: each wheel's travel per tick and the
wheel base.

A robot whose wheels differ in diameter curves while both encoders count alike
(UMBmark "type B" error, Borenstein & Feng 1996); one symmetric encoder scale
cannot represent it. :class:`OdometryIntrinsics` holds the three numbers that
can, and maps tick increments to body motion with them:

.. math::

    \\begin{pmatrix} \\Delta s \\\\ \\Delta\\theta \\end{pmatrix} = J
    \\begin{pmatrix} \\Delta n_L \\\\ \\Delta n_R \\end{pmatrix}, \\qquad
    J = \\begin{pmatrix} k_L / 2 & k_R / 2 \\\\ -k_L / b & k_R / b \\end{pmatrix},

with ``k_L, k_R`` [m/tick] and ``b`` [m] (Censi et al. 2013, section III, with
the wheel radii times the angle per tick written as metres per tick).

**Scale errors.** The filters do not carry the three numbers themselves but the
relative errors of the ground motion against the motion the intrinsics in use
compute from the counts, ``(ds, dtheta)``::

    ds_g     = (1 + k_v) ds + kappa b' b dtheta / 4
    dtheta_g = (1 + k_w) dtheta + kappa ds,        b' = b (1 + k_v) / (1 + k_w)

``k_v`` the travel's, ``k_w`` the turn's and ``kappa`` [rad/m] the curvature a
straight run of equal counts drives (the type B error: half a percent between the
wheels of a Create 2 curves it by 0.021 rad per metre). This is exact for per-wheel
scale factors ``rho_L, rho_R`` and a wheel base ``b'`` (derivation: with
``n_L = (ds - b dtheta / 2) / k_L``, ``n_R = (ds + b dtheta / 2) / k_R``, the new
intrinsics give ``ds_g = (rho_L + rho_R) ds / 2 + (rho_R - rho_L) b dtheta / 4`` and
``dtheta_g = ((rho_R - rho_L) ds + (rho_R + rho_L) b dtheta / 2) / b'``);
:meth:`OdometryIntrinsics.corrected` and :meth:`OdometryIntrinsics.scale_errors_to`
map between the two forms. The ``dtheta`` term of ``ds_g`` is second order (a
1% ratio moves a Create 2 0.6 mm per radian turned) and filters may drop it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lti_motion.exceptions import ShapeError

__all__ = ["OdometryIntrinsics"]


@dataclass(frozen=True)
class OdometryIntrinsics:
    """Each wheel's ground travel per encoder tick and the wheel base.

    Parameters
    ----------
    m_per_tick_left, m_per_tick_right : float
        Ground travel of the left / right wheel per encoder tick [m/tick].
    wheel_base_m : float
        Distance between the wheels' contact points [m].

    Raises
    ------
    ValueError
        If a value is not a positive finite number.

    References
    ----------
    A. Censi, A. Franchi, L. Marchionni, G. Oriolo, "Simultaneous calibration of
    odometry and sensor parameters for mobile robots", IEEE T-RO 29(2), 2013, sec. III.

    Examples
    --------
    >>> k = OdometryIntrinsics(m_per_tick_left=4.5e-4, m_per_tick_right=4.4e-4,
    ...                        wheel_base_m=0.235)
    >>> round(k.diameter_ratio, 6), round(k.m_per_tick, 7)
    (1.022727, 0.000445)
    """

    m_per_tick_left: float
    m_per_tick_right: float
    wheel_base_m: float

    def __post_init__(self) -> None:
        for name in ("m_per_tick_left", "m_per_tick_right", "wheel_base_m"):
            value = float(getattr(self, name))
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"OdometryIntrinsics.{name} must be a positive finite number, "
                                 f"got {value}")
            object.__setattr__(self, name, value)

    @classmethod
    def symmetric(cls, *, m_per_tick: float, wheel_base_m: float) -> OdometryIntrinsics:
        """Both wheels with today's one encoder scale ``m_per_tick`` [m/tick].

        Examples
        --------
        >>> OdometryIntrinsics.symmetric(m_per_tick=4e-4, wheel_base_m=0.2).diameter_ratio
        1.0
        """
        return cls(m_per_tick, m_per_tick, wheel_base_m)

    @property
    def m_per_tick(self) -> float:
        """Mean of the wheels' scales [m/tick]: the symmetric scale of a straight run."""
        return 0.5 * (self.m_per_tick_left + self.m_per_tick_right)

    @property
    def diameter_ratio(self) -> float:
        """Left over right scale (1 for equal wheels)."""
        return self.m_per_tick_left / self.m_per_tick_right

    def jacobian(self) -> np.ndarray:
        """``J`` with ``(ds [m], dtheta [rad]) = J (dn_L, dn_R)``, shape (2, 2) (module docstring).

        Examples
        --------
        >>> OdometryIntrinsics(2e-4, 4e-4, 0.2).jacobian().round(12).tolist()
        [[0.0001, 0.0002], [-0.001, 0.002]]
        """
        kl, kr, b = self.m_per_tick_left, self.m_per_tick_right, self.wheel_base_m
        return np.array([[0.5 * kl, 0.5 * kr], [-kl / b, kr / b]])

    def wheel_travel_m(self, tick_deltas: np.ndarray) -> np.ndarray:
        """Wheel travel ``(left, right)`` [m] from tick increments, shape (..., 2)."""
        d = np.asarray(tick_deltas, dtype=float)
        if d.ndim < 1 or d.shape[-1] != 2:
            raise ShapeError(f"expected tick_deltas of shape (..., 2) (left, right), got {d.shape}")
        return d * np.array([self.m_per_tick_left, self.m_per_tick_right])

    def body_motion(self, tick_deltas: np.ndarray) -> np.ndarray:
        """Travel ``ds`` [m] and turn ``dtheta`` [rad] from tick increments, shape (..., 2).

        Examples
        --------
        >>> OdometryIntrinsics(1e-3, 1e-3, 0.25).body_motion(np.array([100, 200])).tolist()
        [0.15, 0.4]
        """
        d = np.asarray(tick_deltas, dtype=float)
        if d.ndim < 1 or d.shape[-1] != 2:
            raise ShapeError(f"expected tick_deltas of shape (..., 2) (left, right), got {d.shape}")
        return d @ self.jacobian().T

    def corrected(self, k_v: float, k_w: float, kappa_rad_per_m: float) -> OdometryIntrinsics:
        """The intrinsics the scale errors ``(k_v, k_w, kappa)`` say the robot has.

        Parameters
        ----------
        k_v, k_w : float
            Relative errors of the ground travel and turn against these intrinsics'.
        kappa_rad_per_m : float
            Curvature of a straight run of equal counts [rad/m] (module docstring).

        Returns
        -------
        OdometryIntrinsics
            ``rho_L = 1 + k_v - kappa b' / 2``, ``rho_R = 1 + k_v + kappa b' / 2`` times
            these wheels' scales and ``b' = b (1 + k_v) / (1 + k_w)``.

        Raises
        ------
        ValueError
            If the errors give a non-positive scale or wheel base.

        Examples
        --------
        >>> k = OdometryIntrinsics.symmetric(m_per_tick=4.4e-4, wheel_base_m=0.235)
        >>> new = k.corrected(0.0, 0.0, 0.01 / 0.235)        # right wheel 1% larger
        >>> round(new.m_per_tick_right / new.m_per_tick_left, 6)
        1.01005
        >>> [round(e, 12) for e in k.scale_errors_to(new)] == [0.0, 0.0, round(0.01 / 0.235, 12)]
        True
        """
        b_new = self.wheel_base_m * (1.0 + k_v) / (1.0 + k_w)
        half = 0.5 * kappa_rad_per_m * b_new
        return OdometryIntrinsics(self.m_per_tick_left * (1.0 + k_v - half),
                                  self.m_per_tick_right * (1.0 + k_v + half), b_new)

    def scale_errors_to(self, other: OdometryIntrinsics) -> tuple[float, float, float]:
        """``(k_v, k_w, kappa [rad/m])`` with ``self.corrected(*errors) == other``."""
        rho_l = other.m_per_tick_left / self.m_per_tick_left
        rho_r = other.m_per_tick_right / self.m_per_tick_right
        k_v = 0.5 * (rho_l + rho_r) - 1.0
        k_w = (1.0 + k_v) * self.wheel_base_m / other.wheel_base_m - 1.0
        return k_v, k_w, (rho_r - rho_l) / other.wheel_base_m

    def as_dict(self) -> dict[str, float]:
        """The three numbers by name (for model files and reports)."""
        return {"m_per_tick_left": self.m_per_tick_left,
                "m_per_tick_right": self.m_per_tick_right, "wheel_base_m": self.wheel_base_m}
