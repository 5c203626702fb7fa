"""Exceptions of the fusion package.

Each subclasses the matching builtin (and, where one exists, the core
package's class), so callers may catch the specific class, the core class or
plain ``ValueError``. A model without an encoder scale raises the core's own
:class:`lti_motion.exceptions.MissingEncoderScaleError` here too: the model is the
core's, and one class serves every layer.

Examples
--------
>>> issubclass(MeasurementShapeError, ValueError), issubclass(UnknownLandmarkError, ValueError)
(True, True)
"""

from __future__ import annotations

from lti_motion.exceptions import NonFiniteError, ShapeError

__all__ = [
    "CameraOptionError",
    "CameraShapeError",
    "CovarianceNotPositiveDefiniteError",
    "EmptyIntervalError",
    "FilterOptionError",
    "FusionError",
    "GraphInputError",
    "ImageDtypeError",
    "ImageFormatError",
    "ImageShapeError",
    "KeyframeOrderError",
    "LandmarkGeometryError",
    "LandmarkIdError",
    "MarkerMapError",
    "MarkerPoseError",
    "MeasurementShapeError",
    "NonFiniteInputError",
    "NotAModelError",
    "TimeOrderError",
    "UnknownLandmarkError",
    "UnknownPoseError",
]


class FusionError(ValueError):
    """Base class of the fusion package's input errors."""


class MeasurementShapeError(FusionError, ShapeError):
    """A measurement, command or covariance has the wrong shape; the message gives both shapes."""


class UnknownLandmarkError(FusionError):
    """A landmark id is not in the map (raised only where the caller asked for it)."""


class NonFiniteInputError(FusionError, NonFiniteError):
    """A command, an option or a sighting (:class:`fusion.range_bearing.RangeBearing`) holds NaN
    or infinity (a single reading with NaN given to a filter's update is skipped instead)."""


class NotAModelError(FusionError, TypeError):
    """A filter was given something other than a :class:`~lti_motion.model.MotionModel` (a
    model file's path, say); the message says to load the file with ``MotionModel.load``."""


class FilterOptionError(FusionError):
    """A filter option is out of range (a negative noise level, a gate probability >= 1)."""


class LandmarkGeometryError(FusionError):
    """Range-bearing geometry is degenerate: the robot stands on the landmark (range ~ 0)."""


class LandmarkIdError(FusionError):
    """Landmark ids repeat, are not hashable, or are not integers where the factor graph keys
    them (``L(id)``)."""


class CovarianceNotPositiveDefiniteError(FusionError):
    """A covariance (an innovation's, a sighting's) is not symmetric positive definite (no
    Cholesky factor)."""


class TimeOrderError(FusionError):
    """Innovations or encoder counts arrived with a time earlier than one already seen."""


class CameraShapeError(FusionError, ShapeError):
    """A camera matrix, distortion vector or pose has the wrong shape; the message gives
    the expected and the actual shape."""


class CameraOptionError(FusionError):
    """A camera parameter or rendering option is out of range (non-positive focal length,
    a ``K`` whose last row is not ``(0, 0, 1)``, negative noise, non-finite values)."""


class MarkerMapError(FusionError):
    """A marker map or its file is malformed (duplicate ids, ids outside the dictionary,
    a bad size or dictionary name, missing keys); the message says which and how to fix it."""


class ImageFormatError(FusionError):
    """An image has the wrong dtype or shape for marker detection."""


class ImageDtypeError(ImageFormatError):
    """An image is not a ``uint8`` numpy array; the message gives what was found."""


class ImageShapeError(ImageFormatError, ShapeError):
    """An image is not ``(H, W)``, ``(H, W, 1)`` or ``(H, W, 3)``, or its size differs from
    the intrinsics' (or corners are not (4, 2)); the message gives expected and actual shapes."""


class MarkerPoseError(FusionError):
    """The pose of a marker cannot be estimated from its corners (degenerate quadrilateral,
    or the marker centre right above the robot centre)."""


class GraphInputError(FusionError):
    """Bad input to preintegration or a factor graph (base class).

    A :class:`fusion.exceptions.FusionError`, hence a ``ValueError``. Shape and
    non-finite input raise :class:`fusion.exceptions.MeasurementShapeError` and
    :class:`fusion.exceptions.NonFiniteInputError` (also the core package's
    ``ShapeError`` and ``NonFiniteError``).
    """


class KeyframeOrderError(GraphInputError):
    """Keyframes are not strictly increasing, or motion does not start at the last keyframe."""


class EmptyIntervalError(GraphInputError):
    """An interval between two keyframes holds no speed samples."""


class UnknownPoseError(GraphInputError):
    """An observation refers to a pose (keyframe) that is not in the graph."""
