"""Self-calibrating LTI motion models for differential-drive robots (numpy and scipy only).

The core: sensor frames and logs, encoder odometry, kinematics (paper eq. 11), the
encoder scale from a rotation (eq. 13), FIR and ARX identification, one state-space
:class:`MotionModel`, calibration by driving, and trajectory metrics.

Importing the package loads none of its modules: each name below loads with its
module the first time it is used (:mod:`lti_motion.lazy`), so a program pays only
for what it uses.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from lti_motion.lazy import lazy_exports

__all__ = [
    "Calibration",
    "CalibrationPlan",
    "FrameLog",
    "MotionModel",
    "RobotDescription",
    "SensorFrame",
    "ate",
    "calibrate",
    "drive",
    "fit_arx",
    "fit_fir_from_steps",
    "fit_percent",
    "integrate_poses",
    "pose_step",
    "rpe",
    "wrap_angle",
]

__getattr__, __dir__ = lazy_exports(__name__, {
    "lti_motion.calibration.manoeuvres": ("Calibration", "CalibrationPlan", "calibrate", "drive"),
    "lti_motion.recordings.frames": ("FrameLog", "SensorFrame"),
    "lti_motion.kinematics": ("integrate_poses", "pose_step", "wrap_angle"),
    "lti_motion.metrics": ("ate", "fit_percent", "rpe"),
    "lti_motion.model.motion_model": ("MotionModel", "fit_arx", "fit_fir_from_steps"),
    "lti_motion.robot_description": ("RobotDescription",),
}, __all__)

if TYPE_CHECKING:
    from lti_motion.calibration.manoeuvres import Calibration, CalibrationPlan, calibrate, drive
    from lti_motion.kinematics import integrate_poses, pose_step, wrap_angle
    from lti_motion.metrics import ate, fit_percent, rpe
    from lti_motion.model.motion_model import MotionModel, fit_arx, fit_fir_from_steps
    from lti_motion.recordings.frames import FrameLog, SensorFrame
    from lti_motion.robot_description import RobotDescription
