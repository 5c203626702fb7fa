"""The calibration wing: manoeuvres driven and recorded drives fitted.

- :mod:`lti_motion.calibration.manoeuvres`: the paper's three manoeuvres run through any
  robot with ``step()`` (:func:`calibrate`, :func:`drive`), then fitted;
- :mod:`lti_motion.calibration.encoder_scale`: the encoder scale from a rotation in place
  (paper eq. 13);
- :mod:`lti_motion.calibration.recorded`: the ARX model from any recorded drive, with an
  excitation report;
- :mod:`lti_motion.calibration.intrinsics_fit`: both wheels' scale and the wheel base
  against a pose reference or interval samples (Censi et al. 2013), with
  :mod:`lti_motion.calibration.intrinsics_solver` its numerical core and
  :mod:`lti_motion.calibration.intrinsics_runs` runs localised only at their ends, and
  :mod:`lti_motion.calibration.odometry_walk` the random walk of encoder odometry measured
  on the same drive;
- :mod:`lti_motion.calibration.wall_run`, :mod:`lti_motion.calibration.wall_run_drive`: the
  wheels' diameter ratio from straight runs beside a wall, and the manoeuvre.

The names below load with their module on first use (:mod:`lti_motion.lazy`), so
importing the door costs nothing until a name is read.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from lti_motion.lazy import lazy_exports

__all__ = [
    "MIN_FIT_SAMPLES",
    "MIN_RUN_M",
    "Calibration",
    "CalibrationPlan",
    "ExcitationReport",
    "IdentifiabilityReport",
    "IntrinsicsCalibration",
    "OfflineCalibration",
    "Robot",
    "RotationPeriod",
    "WallPass",
    "WallRunCalibration",
    "WallRunDrive",
    "calibrate",
    "calibrate_intrinsics",
    "calibrate_intrinsics_intervals",
    "calibrate_intrinsics_runs",
    "calibrate_recording",
    "calibrate_wall_run",
    "drive",
    "drive_wall_run",
    "encoder_scale_m_per_tick",
    "excitation_report",
    "mirror_heading_rad",
    "phases_as_applied",
    "rotation_period_ticks",
    "rotation_scale",
    "run_path",
    "speeds_from_log",
    "wall_passes",
]

__getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "lti_motion.calibration.encoder_scale": (
            "RotationPeriod",
            "encoder_scale_m_per_tick",
            "rotation_period_ticks",
        ),
        "lti_motion.calibration.intrinsics_fit": (
            "IdentifiabilityReport",
            "IntrinsicsCalibration",
            "calibrate_intrinsics",
            "calibrate_intrinsics_intervals",
        ),
        "lti_motion.calibration.intrinsics_runs": ("calibrate_intrinsics_runs",),
        "lti_motion.calibration.manoeuvres": (
            "Calibration",
            "CalibrationPlan",
            "Robot",
            "calibrate",
            "drive",
            "phases_as_applied",
            "speeds_from_log",
        ),
        "lti_motion.calibration.recorded": (
            "ExcitationReport",
            "MIN_FIT_SAMPLES",
            "OfflineCalibration",
            "calibrate_recording",
            "excitation_report",
            "rotation_scale",
        ),
        "lti_motion.calibration.wall_run": (
            "MIN_RUN_M",
            "WallPass",
            "WallRunCalibration",
            "calibrate_wall_run",
            "mirror_heading_rad",
            "run_path",
        ),
        "lti_motion.calibration.wall_run_drive": (
            "WallRunDrive",
            "drive_wall_run",
            "wall_passes",
        ),
    },
    __all__,
)

if TYPE_CHECKING:
    from lti_motion.calibration.encoder_scale import (
        RotationPeriod,
        encoder_scale_m_per_tick,
        rotation_period_ticks,
    )
    from lti_motion.calibration.intrinsics_fit import (
        IdentifiabilityReport,
        IntrinsicsCalibration,
        calibrate_intrinsics,
        calibrate_intrinsics_intervals,
    )
    from lti_motion.calibration.intrinsics_runs import calibrate_intrinsics_runs
    from lti_motion.calibration.manoeuvres import (
        Calibration,
        CalibrationPlan,
        Robot,
        calibrate,
        drive,
        phases_as_applied,
        speeds_from_log,
    )
    from lti_motion.calibration.recorded import (
        MIN_FIT_SAMPLES,
        ExcitationReport,
        OfflineCalibration,
        calibrate_recording,
        excitation_report,
        rotation_scale,
    )
    from lti_motion.calibration.wall_run import (
        MIN_RUN_M,
        WallPass,
        WallRunCalibration,
        calibrate_wall_run,
        mirror_heading_rad,
        run_path,
    )
    from lti_motion.calibration.wall_run_drive import WallRunDrive, drive_wall_run, wall_passes
