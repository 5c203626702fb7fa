"""Exceptions of the core package.

Each subclasses the matching builtin, so callers may catch either the
specific class or ``ValueError`` / ``RuntimeError``.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

__all__ = [
    "CalibrationError",
    "CalibrationNonFiniteError",
    "CalibrationShapeError",
    "CurvedIntoWallError",
    "LogFileError",
    "MissingEncoderScaleError",
    "ModelFileError",
    "NoSignalError",
    "NonFiniteError",
    "NotExcitedError",
    "NotPeriodicError",
    "PoseReferenceError",
    "RobotMismatchError",
    "SaturatedSignalError",
    "ShapeError",
    "UnidentifiableError",
    "UnstableModelError",
    "WallRunError",
    "WheelSpeedError",
]


class ShapeError(ValueError):
    """An array has the wrong shape; the message gives expected and actual shapes."""


class CalibrationError(ValueError):
    """Calibration data cannot give a trustworthy model."""


class NotExcitedError(CalibrationError):
    """The commands do not excite the system enough to identify it."""


class UnstableModelError(CalibrationError):
    """A fitted model has poles on or outside the unit circle."""


class WheelSpeedError(ValueError):
    """A wheel (measured or commanded) moves faster than can be right: wrong field, unit or
    scale. Besides the message, it says where, for a reader to name the source.

    Attributes
    ----------
    field : str
        The recording's stream kind (e.g. ``"wheel_angles_rad"``, ``"cmd_body"``).
    side : int
        The wheel: 0 left, 1 right.
    sample : int
        Index, in that stream, of the sample behind the speed (the wheel frame closing
        the period, or the command held in it).
    speed_m_s, limit_m_s : float
        The wheel's speed and the limit [m/s].
    t_s : float
        End of the period [s].
    """

    def __init__(self, message: str, *, field: str, side: int, sample: int,
                 speed_m_s: float, t_s: float, limit_m_s: float) -> None:
        super().__init__(message)
        self.field, self.side, self.sample = field, side, sample
        self.speed_m_s, self.t_s, self.limit_m_s = speed_m_s, t_s, limit_m_s


class ModelFileError(ValueError):
    """A saved model file is damaged or of an unknown version."""


class NonFiniteError(ValueError):
    """An input holds NaN or infinite samples; the message names the array, sample and channel."""


class NotPeriodicError(CalibrationError):
    """A rotation recording shows no repeating pattern (under two turns, or no clear period)."""


class NoSignalError(CalibrationError):
    """Every range-like sensor channel is flat: nothing was in range during the manoeuvre."""


class SaturatedSignalError(CalibrationError):
    """A range-like sensor stayed at its largest reading: the target is too close to measure."""


class CalibrationShapeError(ShapeError, CalibrationError):
    """Calibration inputs have the wrong shape; both a ``ShapeError`` and a ``CalibrationError``."""


class CalibrationNonFiniteError(NonFiniteError, CalibrationError):
    """Calibration inputs hold NaN or infinite samples; both a ``NonFiniteError`` and a
    ``CalibrationError``."""


class UnidentifiableError(CalibrationError):
    """The motion cannot determine the odometry intrinsics (e.g. no turns, or turns one way
    only with no straight runs); the message says what the drive lacks."""


class WallRunError(CalibrationError):
    """The wall-run manoeuvre cannot be driven as planned: no wall ahead, or runs that came at
    the wall on both sides (:mod:`lti_motion.calibration.wall_run_drive`)."""


class CurvedIntoWallError(WallRunError):
    """The wall run's straight runs came at the wall on both sides: the intrinsics in use
    turn the robot wrongly (calibrate the encoder scale first)."""


class PoseReferenceError(CalibrationError):
    """A pose reference does not fit the encoder record (no time overlap, non-finite poses,
    another robot's trajectory)."""


class RobotMismatchError(ValueError):
    """A recording (or the flags) describe another robot than the model's: another sensor
    period, geometry or encoder kind beyond the stated tolerances
    (:meth:`lti_motion.robot_description.RobotDescription.disagreement`); the message names
    both values."""


class LogFileError(ModelFileError):
    """A log file that is damaged, of another format, or of an unknown version."""


class MissingEncoderScaleError(ValueError):
    """A model without an encoder scale (``m_per_tick`` is None) where counts must become
    distances: odometry, the encoder update of a filter, the monitor, the smoother.

    Every place that needs the scale raises this one class, with a message that says what
    needed it and what to do: calibrate with the rotation in place
    (:func:`lti_motion.calibration.calibrate` measures ``m_per_tick``, paper eq. 13), or
    pass ``m_per_tick=`` where the function takes it. Build it with :meth:`needed_by`.

    Examples
    --------
    >>> raise MissingEncoderScaleError.needed_by("the monitor")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    lti_motion.exceptions.MissingEncoderScaleError: the monitor needs the encoder scale and ...
    """

    @classmethod
    def needed_by(cls, what: str, *, keyword: str | None = None) -> MissingEncoderScaleError:
        """The error for ``what`` needing the scale; ``keyword`` names where a user can give
        it instead of calibrating (e.g. ``"ModelEKF(m_per_tick=...)"``)."""
        give = f"pass {keyword}, or " if keyword else ""
        return cls(f"{what} needs the encoder scale and has none (m_per_tick is None): "
                   f"{give}calibrate the model with the rotation in place "
                   "(lti_motion.calibration.calibrate measures m_per_tick, paper eq. 13)")
