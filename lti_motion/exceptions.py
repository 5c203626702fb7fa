"""Exceptions of the core package.

Each subclasses the matching builtin, so callers may catch either the
specific class or ``ValueError`` / ``RuntimeError``.
"""

from __future__ import annotations

__all__ = [
    "CalibrationError",
    "CalibrationNonFiniteError",
    "CalibrationShapeError",
    "LogFileError",
    "ModelFileError",
    "NoSignalError",
    "NonFiniteError",
    "NotExcitedError",
    "NotPeriodicError",
    "ShapeError",
    "UnstableModelError",
]


class ShapeError(ValueError):
    """An array has the wrong shape; the message gives expected and actual shapes."""


class CalibrationError(ValueError):
    """Calibration data cannot give a trustworthy model."""


class NotExcitedError(CalibrationError):
    """The commands do not excite the system enough to identify it."""


class UnstableModelError(CalibrationError):
    """A fitted model has poles on or outside the unit circle."""


class ModelFileError(ValueError):
    """A saved model file is damaged or of an unknown version."""


class NonFiniteError(ValueError):
    """An input holds NaN or infinite samples; the message names the array, sample and channel."""


class NotPeriodicError(CalibrationError):
    """A rotation recording shows no repeating pattern (under two turns, or no clear period)."""


class NoSignalError(CalibrationError):
    """Every range-like sensor channel is flat: nothing was in range during the manoeuvre."""


class CalibrationShapeError(ShapeError, CalibrationError):
    """Calibration inputs have the wrong shape; both a ``ShapeError`` and a ``CalibrationError``."""


class CalibrationNonFiniteError(NonFiniteError, CalibrationError):
    """Calibration inputs hold NaN or infinite samples; both a ``NonFiniteError`` and a
    ``CalibrationError``."""


class LogFileError(ModelFileError):
    """A log file that is damaged, of another format, or of an unknown version."""
