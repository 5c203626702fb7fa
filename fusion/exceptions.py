"""Exceptions of the fusion package.

Each subclasses the matching builtin (and, where one exists, the core
package's class), so callers may catch the specific class, the core class or
plain ``ValueError``.

Examples
--------
>>> issubclass(MeasurementShapeError, ValueError), issubclass(UnknownLandmarkError, ValueError)
(True, True)
"""

from __future__ import annotations

from lti_motion.exceptions import NonFiniteError, ShapeError

__all__ = [
    "FilterOptionError",
    "FusionError",
    "LandmarkGeometryError",
    "LandmarkIdError",
    "MeasurementShapeError",
    "NonFiniteInputError",
    "UnknownLandmarkError",
]


class FusionError(ValueError):
    """Base class of the fusion package's input errors."""


class MeasurementShapeError(FusionError, ShapeError):
    """A measurement, command or covariance has the wrong shape; the message gives both shapes."""


class UnknownLandmarkError(FusionError):
    """A landmark id is not in the map (raised only where the caller asked for it)."""


class NonFiniteInputError(FusionError, NonFiniteError):
    """A command or an option holds NaN or infinity (measurements with NaN are skipped instead)."""


class FilterOptionError(FusionError):
    """A filter option is out of range (a negative noise level, a gate probability >= 1)."""


class LandmarkGeometryError(FusionError):
    """Range-bearing geometry is degenerate: the robot stands on the landmark (range ~ 0)."""


class LandmarkIdError(FusionError):
    """Landmark ids repeat, or are not integers where the factor graph keys them (``L(id)``)."""
