"""The recalibration policy's options as one frozen object.

:class:`RecalibrationOptions` holds what :class:`~fusion.monitoring.Recalibrator`
decides with: how much data a dynamics refit needs and how it is selected and
validated, and how precise a landmark scale or a wheel-drift curvature must be
before it is adopted. Where an adopted model goes and whom the policy asks for
a rotation or for excitation stay the policy's own keyword arguments.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from fusion.exceptions import FilterOptionError

__all__ = ["RecalibrationOptions"]


@dataclass(frozen=True, kw_only=True)
class RecalibrationOptions:
    """What :class:`~fusion.monitoring.Recalibrator` decides with (defaults:
    ``RecalibrationOptions()``).

    Attributes
    ----------
    buffer_s : float
        Seconds of ``(t, u, y)`` kept [s].
    min_samples : int
        Fewest samples since the onset for a refit attempt.
    validation_fraction : float
        Newest share of the data since the onset held out for validation, in (0, 1).
    min_gain_pp : float
        Percentage points the new model's held-out fit must gain to replace the old.
    orders, delays : tuple of int, optional
        Selection grid of the refit (default: around the model in use's order,
        and delays 0..8).
    retry_samples : int, optional
        New samples between automatic retries while waiting (default
        ``min_samples // 4``).
    dc_gain : {"wheel_servo", "free"}, optional
        Steady-state gain of the refit (:func:`lti_motion.model.fit_arx`);
        default: as the model in use was fitted (``"wheel_servo"`` when its
        diagnostics hold ``dc_gain_scale``).
    max_scale_std : float
        Largest standard deviation of a landmark scale (or yaw) ratio that is
        adopted, in (0, 1) (:mod:`fusion.monitoring.recalibration`).
    scale_settle_s : float
        Longest wait [s] after a scale alarm for a precise running estimate
        before the rotation is requested (0: request it at once).
    scale_reference : tuple of 2 float, optional
        ``(m_per_tick [m/tick], wheel_base_m [m])`` the scale monitor's ratios
        refer to (the values its :class:`~fusion.monitoring.ScaleMonitor`
        was built with); default the model's when the policy is made.
    max_curvature_std_rad_per_m : float
        Largest standard deviation [rad/m] of a wheel-drift alarm's curvature whose
        intrinsics are adopted, in (0, 1).

    Raises
    ------
    FilterOptionError
        For an option out of its range (the message names it and its value).

    Examples
    --------
    >>> RecalibrationOptions(min_samples=3000).retry_samples is None
    True
    >>> RecalibrationOptions(dc_gain="servo")
    Traceback (most recent call last):
    ...
    fusion.exceptions.FilterOptionError: dc_gain must be 'wheel_servo' or 'free', got 'servo'
    """

    buffer_s: float = 120.0
    min_samples: int = 2000
    validation_fraction: float = 0.3
    min_gain_pp: float = 0.0
    orders: tuple[int, ...] | None = None
    delays: tuple[int, ...] | None = None
    retry_samples: int | None = None
    dc_gain: Literal["wheel_servo", "free"] | None = None
    max_scale_std: float = 0.004
    scale_settle_s: float = 30.0
    scale_reference: tuple[float, float] | None = None
    max_curvature_std_rad_per_m: float = 0.004

    def __post_init__(self) -> None:
        if not (0.0 < self.validation_fraction < 1.0 and self.buffer_s > 0
                and self.min_samples > 0):
            raise FilterOptionError(
                f"need 0 < validation_fraction < 1, buffer_s > 0, min_samples > 0; got "
                f"{self.validation_fraction}, {self.buffer_s}, {self.min_samples}")
        if self.dc_gain not in (None, "wheel_servo", "free"):
            raise FilterOptionError(f"dc_gain must be 'wheel_servo' or 'free', got "
                                    f"{self.dc_gain!r}")
        if not (0.0 < self.max_scale_std < 1.0 and self.scale_settle_s >= 0.0
                and 0.0 < self.max_curvature_std_rad_per_m < 1.0):
            raise FilterOptionError(f"need 0 < max_scale_std < 1, scale_settle_s >= 0 and "
                                    f"0 < max_curvature_std_rad_per_m < 1; got "
                                    f"{self.max_scale_std}, {self.scale_settle_s} and "
                                    f"{self.max_curvature_std_rad_per_m}")
        reference = self.scale_reference
        if reference is not None and not all(math.isfinite(v) and v > 0 for v in reference):
            raise FilterOptionError(f"scale_reference (m_per_tick, wheel_base_m) must be "
                                    f"positive, got {reference}")
